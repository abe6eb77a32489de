#include "farm_settings.h"

#include <fmt/format.h>

#include <fstream>
#include <regex>
#include <sstream>
#include <toml++/toml.h>

#include "rime/core/error.h"
#include "rime/io/toml_reader.h"

namespace fs = std::filesystem;

namespace rime::bake {
namespace {

toml::table ParseFile(const fs::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError("cannot read the farm settings file", file.string());
  std::stringstream text;
  text << in.rdbuf();
  try {
    return toml::parse(text.str(), file.string());
  } catch (const toml::parse_error& e) {
    throw InputError(fmt::format("TOML syntax error: {}", e.description()), fmt::format("{}:{}", file.string(), e.source().begin.line));
  }
}

// A string the scheduler parses: checked here so a typo fails before anything is submitted.
std::string Checked(io::TomlReader& t, const std::string& key, const std::string& fallback, const std::regex& pattern, const char* what) {
  const std::string value = t.String(key, fallback);
  if (!value.empty() && !std::regex_match(value, pattern)) t.Fail(key, fmt::format("'{}' is not {}", value, what));
  return value;
}

// `[farm.time]` / `[farm.memory]`: per-stage values; `default` replaces every stage this table
// does not name (the scene's table over the site file's).
void ParsePerStage(io::TomlReader t, std::array<std::string, kStageCount>& values, const std::regex& pattern, const char* what) {
  const bool has_default = t.Has("default");
  const std::string fallback = Checked(t, "default", "", pattern, what);
  for (int s = 0; s < kStageCount; ++s)
    values[s] = Checked(t, StageName(static_cast<Stage>(s)), has_default ? fallback : values[s], pattern, what);
  t.RejectUnknownKeys();
}

void ParseFarmTable(io::TomlReader t, FarmSettings& f) {
  static const std::regex kName("[A-Za-z0-9_.,:+-]+");
  // Slurm's --time formats: M, M:S, H:M:S, D-H, D-H:M, D-H:M:S.
  static const std::regex kTime("[0-9]+(:[0-9]+){0,2}|[0-9]+-[0-9]+(:[0-9]+){0,2}");
  static const std::regex kMemory("[0-9]+[KMGT]?");
  static const std::regex kGres("[A-Za-z0-9_]+(:[A-Za-z0-9_.-]+)*(:[0-9]+)?");
  f.partition = Checked(t, "partition", f.partition, kName, "a partition name (or comma-separated list)");
  f.sim_partition = Checked(t, "sim_partition", f.sim_partition, kName, "a partition name (or comma-separated list)");
  f.account = Checked(t, "account", f.account, kName, "an account name");
  f.qos = Checked(t, "qos", f.qos, kName, "a QOS name");
  ParsePerStage(t.Table("time"), f.time, kTime, "a Slurm time limit (minutes, H:M:S or D-H:M:S)");
  ParsePerStage(t.Table("memory"), f.memory, kMemory, "a Slurm memory size (e.g. 4000M or 16G)");
  f.chunk = static_cast<int>(t.Integer("chunk", f.chunk, io::Range::Closed(1, 100000)));
  f.stream_tasks = static_cast<int>(t.Integer("stream_tasks", f.stream_tasks, io::Range::Closed(0, 100000)));
  f.cpus_per_task = static_cast<int>(t.Integer("cpus_per_task", f.cpus_per_task, io::Range::Closed(1, 4096)));
  f.sim_cpus_per_task = static_cast<int>(t.Integer("sim_cpus_per_task", f.sim_cpus_per_task, io::Range::Closed(0, 4096)));
  f.gpus = t.Bool("gpus", f.gpus);
  f.gpu_gres = Checked(t, "gpu_gres", f.gpu_gres, kGres, "a GRES request such as gpu:1 or gpu:a100:1");
  if (t.Has("sbatch")) {
    f.sbatch_lines = t.StringList("sbatch");
    for (const auto& line : f.sbatch_lines)
      if (line.rfind("-", 0) != 0 || line.find_first_of("\n\r") != std::string::npos)
        t.Fail("sbatch", fmt::format("'{}' is not one sbatch option (each entry is one line such as \"--constraint=avx2\")", line));
  }
  f.bin_dir = t.String("bin_dir", f.bin_dir);
  if (!f.bin_dir.empty() && fs::path(f.bin_dir).is_relative()) t.Fail("bin_dir", "must be an absolute path as the nodes see it");
  t.RejectUnknownKeys();
}

}  // namespace

FarmSettings LoadFarmSettings(const std::optional<fs::path>& site_file, const fs::path& scene_file) {
  FarmSettings settings;
  if (site_file) {
    const toml::table root = ParseFile(*site_file);
    io::TomlReader top(root, site_file->string(), "");
    ParseFarmTable(top.Table("farm"), settings);
    top.RejectUnknownKeys();
    settings.sources.push_back(site_file->string());
  }
  const toml::table root = ParseFile(scene_file);
  io::TomlReader top(root, scene_file.string(), "");
  if (top.Has("farm")) settings.sources.push_back(scene_file.string() + " [farm]");
  ParseFarmTable(top.Table("farm"), settings);
  return settings;
}

}  // namespace rime::bake
