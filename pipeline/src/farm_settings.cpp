#include "farm_settings.h"

#include <fmt/format.h>

#include <fstream>
#include <stdexcept>
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

// `[farm.time]` / `[farm.memory]` over `values`: a stage the table names takes its value, the
// others the table's `default` when it has one.
template <class PerStage>
void LoadPerStage(io::TomlReader t, std::array<std::string, kStageCount>& values) {
  const auto stage_of = [](std::string_view name) {
    const std::optional<Stage> stage = ParseStage(std::string(name));
    if (!stage) throw std::logic_error(fmt::format("[farm] per-stage key '{}' names no stage", name));
    return static_cast<int>(*stage);
  };
  PerStage table;
  io::LoadSettings(t, table);
  const bool has_default = t.Has("default");
  PerStage::Visit(table, [&](const io::Param& p, const std::string& value) {
    if (p.name == "default") return;
    if (t.Has(std::string(p.name))) values[stage_of(p.name)] = value;
    else if (has_default) values[stage_of(p.name)] = table.all;
  });
  t.RejectUnknownKeys();
}

void ParseFarmTable(io::TomlReader t, FarmSettings& f) {
  io::LoadSettings(t, f);
  LoadPerStage<io::FarmTimes>(t.Table("time"), f.time);
  LoadPerStage<io::FarmMemory>(t.Table("memory"), f.memory);
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
