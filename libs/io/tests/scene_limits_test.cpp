// Hostile scene values: each is refused at load time, naming file:line: field, in bounded time.
#include <gtest/gtest.h>

#include <ctime>
#include <filesystem>
#include <fstream>
#include <string>

#include "rime/core/error.h"
#include "rime/io/scene.h"
#include "rime/io/toml_reader.h"
#include "rime/test/temp_folder.h"

namespace rime::io {
namespace {

::testing::AssertionResult Has(const std::string& message, const std::string& part) {
  if (message.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "'" << part << "' not in: " << message.substr(0, 300);
}

// The error message of parsing `text`, which must come within a second of processor time: the
// parser's work is bounded, while wall time also counts whatever else the loaded machine runs.
std::string Refusal(const std::string& text) {
  const std::clock_t start = std::clock();
  std::string message;
  try {
    ParseScene(text, "hostile.toml");
    ADD_FAILURE() << "accepted: " << text.substr(0, 200);
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    message = e.what();
  }
  const double seconds = double(std::clock() - start) / CLOCKS_PER_SEC;
  EXPECT_LT(seconds, 1.0) << message;
  return message;
}

std::string Repeat(const std::string& s, std::size_t n) {
  std::string out;
  out.reserve(s.size() * n);
  for (std::size_t i = 0; i < n; ++i) out += s;
  return out;
}

TEST(SceneLimits, BoxBlockOfTenToTheThirtyParticlesNamesItsMax) {
  const std::string m = Refusal("[water]\nspacing = 1e-9\n[[water_block]]\nmin = [0, 0, 0]\nmax = [1e3, 1, 1]\n");
  EXPECT_TRUE(Has(m, "hostile.toml:5: water_block[0].max"));
  EXPECT_TRUE(Has(m, "1e+30 particles"));
}

TEST(SceneLimits, HugeSphereBlockNamesItsRadius) {
  const std::string m = Refusal("[[water_block]]\nshape = \"sphere\"\nradius = 1e100\n");
  EXPECT_TRUE(Has(m, "hostile.toml:3: water_block[0].radius"));
}

TEST(SceneLimits, BlockWithOverflowingExtentsIsRefused) {
  const std::string m = Refusal("[[water_block]]\nmin = [-1e300, -1e300, -1e300]\nmax = [1e300, 1e300, 1e300]\n");
  EXPECT_TRUE(Has(m, "water_block[0].max"));
}

TEST(SceneLimits, EmitterPouringForAThousandYearsNamesItsSize) {
  const std::string disc = Refusal("[scene]\nend_time = 3e10\nfps = 1e-5\n[[emitter]]\nradius = 0.05\nspeed = 2\n");
  EXPECT_TRUE(Has(disc, "hostile.toml:5: emitter[0].radius"));
  const std::string rectangle = Refusal("[water]\nspacing = 1e-6\n[[emitter]]\nshape = \"rectangle\"\nwidth = 1\nheight = 1\n");
  EXPECT_TRUE(Has(rectangle, "hostile.toml:5: emitter[0].width"));
}

TEST(SceneLimits, EmitterStoppedBeforeTheEndCountsOnlyItsDuration) {
  const Scene s = ParseScene("[scene]\nend_time = 1e4\nfps = 1\n[[emitter]]\nradius = 0.05\nstop = 1\n", "ok.toml");
  EXPECT_EQ(s.emitters.size(), 1u);
}

TEST(SceneLimits, ABillionFramesNamesEndTime) {
  const std::string m = Refusal("[scene]\nfps = 1000\nend_time = 1e6\n");
  EXPECT_TRUE(Has(m, "hostile.toml:3: scene.end_time"));
  EXPECT_TRUE(Has(m, "1e+09 frames"));
  EXPECT_TRUE(Has(Refusal("[scene]\nend_time = 1e300\n"), "scene.end_time"));
}

TEST(SceneLimits, NanAndInfinityAreRefusedWhereverANumberIsRead) {
  struct Case {
    const char* text;
    const char* field;
  };
  const Case cases[] = {
      {"[scene]\nfps = nan\n", "hostile.toml:2: scene.fps"},
      {"[scene]\nend_time = inf\n", "hostile.toml:2: scene.end_time"},
      {"[water]\nspacing = -nan\n", "hostile.toml:2: water.spacing"},
      {"[sim]\ngravity = [0, 0, -inf]\n", "hostile.toml:2: sim.gravity"},
      {"[[water_block]]\nvelocity = [nan, 0, 0]\n", "hostile.toml:2: water_block[0].velocity"},
      {"[[water_block]]\nmin = [0, 0, nan]\n", "hostile.toml:2: water_block[0].min"},
      {"[[emitter]]\nspeed = +inf\n", "hostile.toml:2: emitter[0].speed"},
      {"[[solid]]\nscale = inf\n", "hostile.toml:2: solid[0].scale"},
      {"[[solid]]\ntranslate = [inf, 0, 0]\n", "hostile.toml:2: solid[0].translate"},
      {"[[solid]]\n[[solid.keyframe]]\ntime = nan\n", "hostile.toml:3: solid[0].keyframe[0].time"},
      {"[domain]\nmin = [nan, 0, 0]\nmax = [1, 1, 1]\n", "hostile.toml:2: domain.min"},
      {"[sim]\nmodules = [\"freezing\"]\n[freezing]\nk_n = nan\n", "hostile.toml:4: freezing.k_n"},
      {"[surface]\nlambda = nan\n", "hostile.toml:2: surface.lambda"},
  };
  for (const Case& c : cases) EXPECT_TRUE(Has(Refusal(c.text), c.field)) << c.text;
}

TEST(SceneLimits, AMillionDeepDottedKeyIsRefusedBeforeParsing) {
  const std::string m = Refusal("[scene]\nname = \"deep\"\n" + Repeat("a.", 1'000'000) + "a = 1\n");
  EXPECT_TRUE(Has(m, "nested deeper than"));
  EXPECT_TRUE(Has(m, "hostile.toml:3: scene.a.a.a"));
}

TEST(SceneLimits, AMillionDeepTableHeaderIsRefused) {
  EXPECT_TRUE(Has(Refusal("[" + Repeat("t.", 1'000'000) + "t]\nx = 1\n"), "hostile.toml:1: t.t.t"));
  EXPECT_TRUE(Has(Refusal("[[" + Repeat("t.", 1'000'000) + "t]]\nx = 1\n"), "nested deeper than"));
}

TEST(SceneLimits, AMillionDeepArraysAndInlineTablesAreRefused) {
  const std::size_t n = 1'000'000;
  EXPECT_TRUE(Has(Refusal("[scene]\nname = " + Repeat("[", n) + Repeat("]", n) + "\n"), "hostile.toml:2: scene.name"));
  EXPECT_TRUE(Has(Refusal("x = " + Repeat("{a = ", n) + "1" + Repeat("}", n) + "\n"), "nested deeper than"));
  EXPECT_TRUE(Has(Refusal("x = [" + Repeat("{a = [", n) + "\n"), "nested deeper than"));  // never closed
}

TEST(SceneLimits, NestingAScenesUsesIsAccepted) {
  const std::string text =
      "[[solid]]\nname = \"a\"\n[[solid.keyframe]]\ntime = 0\ntranslate = [0, 0, 0]\n"
      "x.y.z = 1\nv = [[1, 2], [3, [4, {p.q = \"]]\"}]]]\n# [[[[ a comment\ns = '''[[{{'''\n";
  EXPECT_NO_THROW(CheckTomlLimits(text, "nesting.toml"));
  EXPECT_NO_THROW(CheckTomlLimits(Repeat("a.", kMaxTomlDepth - 2) + "a = 1\n", "nesting.toml"));
  EXPECT_THROW(CheckTomlLimits(Repeat("a.", kMaxTomlDepth) + "a = 1\n", "nesting.toml"), Error);
}

TEST(SceneLimits, AHundredMegabyteStringNamesItsField) {
  const std::string m = Refusal("[scene]\nname = \"" + std::string(100'000'000, 'x') + "\"\n");
  EXPECT_TRUE(Has(m, "hostile.toml:2: scene.name"));
  EXPECT_TRUE(Has(m, "string of 100000000 bytes"));
  EXPECT_TRUE(Has(Refusal("[[solid]]\nmesh = '''\n" + std::string(2'000'000, 'y') + "'''\n"), "hostile.toml:2: solid.mesh"));
}

TEST(SceneLimits, AFileOverTheSizeLimitIsRefusedWithoutReadingIt) {
  const rime::test::TempFolder dir("scene_limits");
  const auto file = dir / "huge.toml";
  {
    std::ofstream out(file, std::ios::binary);
    out << "[scene]\n";
  }
  std::filesystem::resize_file(file, kMaxSceneFileBytes + 1);  // sparse: costs no disk
  try {
    LoadScene(file);
    ADD_FAILURE() << "accepted";
  } catch (const Error& e) {
    EXPECT_TRUE(Has(std::string(e.what()), "larger than the limit"));
  }
}

}  // namespace
}  // namespace rime::io
