// Scene values that a shell would execute, in the scene name, a solid's name, the scene file's
// name and the output folder: the bake works under those literal names and no injected command
// runs. Names that would leave their folder ('/', "..") are refused with a clear error.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fmt/format.h>

#include "rime/test/bake_outputs.h"
#include "rime/io/particles.h"
#include "rime/test/small_bake_scene.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime {
namespace {

// A TOML basic string holding `text`.
std::string TomlString(const std::string& text) {
  std::string out = "\"";
  for (char c : text) {
    if (c == '"' || c == '\\') out += '\\', out += c;
    else if (c == '\n') out += "\\n";
    else out += c;
  }
  return out + "\"";
}

// The small scene with its name and the ball's name replaced (both given as TOML strings).
std::string SceneNamed(const std::string& scene_name, const std::string& ball_name, int last_frame) {
  std::string text = test::SmallBakeScene("placeholder", last_frame);
  text.replace(text.find("\"placeholder\""), std::string("\"placeholder\"").size(), scene_name);
  text.replace(text.find("\"ball\""), std::string("\"ball\"").size(), ball_name);
  return text;
}

class HostileNames : public ::testing::Test {
 protected:
  void SetUp() override {
    previous_folder_ = fs::current_path();
    fs::current_path(root_);
  }
  void TearDown() override { fs::current_path(previous_folder_); }
  // Every shell metacharacter, quotes of both kinds, a newline and non-ASCII letters, and no '/'
  // (names with one are refused); each command would create a marker file in the working folder,
  // root_, if anything ran it through a shell.
  static std::string Hostile() { return "a;b $(touch p1) `touch p2` 'sq' \"dq\" \\ & | > < * ? ~ #{} é ❄ 冰\nline 2; touch p3"; }
  void ExpectNoInjectedCommandRan() const {
    for (int k = 1; k <= 3; ++k) EXPECT_FALSE(fs::exists(root_ / fmt::format("p{}", k))) << "an injected command ran";
    EXPECT_FALSE(fs::exists("/tmp/pwned"));
  }
  rime::test::TempFolder temp_{"hostile"};
  fs::path root_ = temp_.path(), previous_folder_;
};

TEST_F(HostileNames, BakeWorksUnderTheLiteralNamesAndRunsNothingInjected) {
  const std::string hostile = Hostile();
  const fs::path scene = root_ / (hostile + ".toml");
  std::ofstream(scene) << SceneNamed(TomlString(hostile), TomlString(hostile), 1);
  const fs::path out = root_ / ("out " + hostile);
  std::string output;
  const int code = test::Run({RIME_BINARY_DIR "/bin/rime-bake", scene.string(), "clean", "-o", out.string(), "-j", "2", "-q"},
                             root_ / "bake.txt", output);
  ASSERT_EQ(code, 0) << output;
  ExpectNoInjectedCommandRan();
  EXPECT_TRUE(fs::exists(out / "cache/boundary" / (hostile + ".h5part"))) << "the solid's boundary file goes under its literal name";
  for (int f = 0; f <= 1; ++f) {
    EXPECT_TRUE(fs::exists(io::FramePath(out / "cache/sim", "particles", f, "h5part"))) << f;
    EXPECT_GT(fs::file_size(io::FramePath(out / "clean", "water_clean", f, "obj")), 0u) << f;
  }
  // A dry run prints every command shell-quoted: pasted into a shell they run nothing else.
  ASSERT_EQ(test::Run({RIME_BINARY_DIR "/bin/rime-bake", scene.string(), "clean", "-o", (root_ / "dry").string(), "-n", "-q"},
                      root_ / "dry.txt", output),
            0)
      << output;
  // Each printed command (-q: nothing else is printed), its program replaced by a function that
  // prints its arguments.
  std::string script = "print_args() { printf '%s\\0' \"$@\"; printf '\\n'; }\n";
  int commands = 0;
  std::istringstream lines(output);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind(RIME_BINARY_DIR "/bin/rime-", 0) == 0) line = "print_args" + line.substr(line.find(' ')), ++commands;
    script += line + "\n";
  }
  ASSERT_EQ(commands, 1 + 1 + 2 * 2) << output;  // boundary, sim, surface and cleanup of frames 0 and 1
  std::ofstream(root_ / "commands.sh") << script;
  std::string printed;
  ASSERT_EQ(test::Run({"/bin/bash", (root_ / "commands.sh").string()}, root_ / "printed.txt", printed), 0) << printed;
  std::vector<std::string> args;
  for (std::size_t at = 0, end; (end = printed.find('\0', at)) != std::string::npos; at = end + 1)
    args.push_back(printed.substr(printed[at] == '\n' ? at + 1 : at, end - (printed[at] == '\n' ? at + 1 : at)));
  EXPECT_EQ(std::count(args.begin(), args.end(), scene.string()), commands) << "every tool gets the scene path literally:\n" << printed;
  EXPECT_EQ(std::count(args.begin(), args.end(), (root_ / "dry/cache/boundary").string()), 2) << printed;
  ExpectNoInjectedCommandRan();
}

TEST_F(HostileNames, NamesThatLeaveTheirFolderAreRefused) {
  const std::pair<std::string, std::string> cases[] = {{TomlString("../../escaped"), TomlString("ball")},
                                                       {TomlString("fine"), TomlString("../../escaped")},
                                                       {TomlString("fine"), TomlString("")}};
  for (const auto& [scene_name, ball_name] : cases) {
    const fs::path scene = root_ / "refused.toml";
    std::ofstream(scene) << SceneNamed(scene_name, ball_name, 1);
    std::string output;
    const int code = test::Run({RIME_BINARY_DIR "/bin/rime-bake", scene.string(), "clean", "-o", (root_ / "out").string(), "-q"},
                               root_ / "bake.txt", output);
    EXPECT_EQ(code, 3) << output;
    EXPECT_NE(output.find("cannot be used as a file name"), std::string::npos) << output;
    EXPECT_NE(output.find("refused.toml:"), std::string::npos) << "the message names file and line: " << output;
    EXPECT_FALSE(fs::exists(root_ / "escaped.h5part"));
    EXPECT_FALSE(fs::exists(root_ / "out")) << "nothing runs before the scene is accepted";
  }
}

}  // namespace
}  // namespace rime
