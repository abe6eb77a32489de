#include "rime/io/scene_reference.h"

#include <fmt/format.h>

#include <algorithm>

#include "rime/core/error.h"
#include "rime/io/scene.h"
#include "rime/io/scene_bake.h"
#include "rime/io/scene_farm.h"

namespace rime::io {

namespace {

// What a field accepts, in words: a range, or the names of an enum or a list.
std::string DescribeAccepted(const Param& p, std::span<const std::string_view> names) {
  if (!names.empty()) {
    std::string out;
    for (std::size_t k = 0; k < names.size(); ++k) out += fmt::format("{}`{}`", k ? ", " : "", names[k]);
    return out;
  }
  return p.range.IsAny() ? std::string() : p.range.Describe();
}

template <class T>
std::string DescribeAccepted(const Param& p, const T&) {
  if (!p.accepted.empty()) return std::string(p.accepted);
  if constexpr (NamedEnum<T>) return DescribeAccepted(p, Names(T{}));
  else if constexpr (std::is_same_v<T, std::vector<std::string>>) return DescribeAccepted(p, p.choices);
  else if constexpr (std::is_same_v<T, bool> || std::is_same_v<T, std::string> || std::is_same_v<T, std::filesystem::path>) return "";
  else return DescribeAccepted(p, std::span<const std::string_view>());
}

// The markdown table of one settings struct: key, unit, default, accepted values, meaning.
template <class Settings>
std::string MarkdownTable() {
  std::string out = "| key | unit | default | accepted | meaning |\n|---|---|---|---|---|\n";
  const Settings defaults{};
  Settings::Visit(defaults, [&](const Param& p, const auto& value) {
    const std::string meaning = p.doc.empty() ? std::string(p.help) : fmt::format("{} {}", p.help, p.doc);
    out += fmt::format("| `{}` | {} | {} | {} | {} |\n", p.name, p.unit,
                       p.default_doc.empty() ? FormatValue(value) : std::string(p.default_doc), DescribeAccepted(p, value), meaning);
  });
  return out;
}

constexpr std::string_view kFlagTableHeader = "| flag | scene key | default | accepted | meaning |\n|---|---|---|---|---|\n";

// Rows of a markdown table (kFlagTableHeader) of the command-line flags a settings struct declares.
template <class Settings>
std::string FlagRows() {
  std::string out;
  const Settings defaults{};
  Settings::Visit(defaults, [&](const Param& p, const auto& value) {
    if (p.flag.empty()) return;
    std::string flags;  // "--remesh,!--no-remesh" -> `--remesh`, `--no-remesh`
    for (std::size_t start = 0; start <= p.flag.size();) {
      const std::size_t comma = std::min(p.flag.find(',', start), p.flag.size());
      std::string_view name = p.flag.substr(start, comma - start);
      if (!name.empty() && name.front() == '!') name.remove_prefix(1);
      flags += fmt::format("{}`{}`", flags.empty() ? "" : ", ", name);
      start = comma + 1;
    }
    // A default in words ("0 (= use the ratio)") stands without the unit.
    const std::string shown = !p.default_doc.empty() ? std::string(p.default_doc)
                              : p.unit.empty()       ? FormatValue(value)
                                                     : fmt::format("{} {}", FormatValue(value), p.unit);
    out += fmt::format("| {} | `{}` | {} | {} | {} |\n", flags, p.name, shown, DescribeAccepted(p, value), p.help);
  });
  return out;
}

}  // namespace

std::vector<ReferenceTable> SceneReferenceTables() {
  const std::string scenes = "scene-reference.md", tools = "tools.md", farm = "farm.md", header(kFlagTableHeader);
  return {
      {scenes, "scene", MarkdownTable<SceneInfo>()},
      {scenes, "water", MarkdownTable<FluidSettings>()},
      {scenes, "sim", MarkdownTable<SolverSettings>()},
      {scenes, "viscosity", MarkdownTable<ViscositySettings>()},
      {scenes, "surface_tension", MarkdownTable<SurfaceTensionSettings>()},
      {scenes, "air_pressure", MarkdownTable<AirPressureSettings>()},
      {scenes, "freezing", MarkdownTable<FreezingSettings>()},
      {scenes, "water_block", MarkdownTable<FluidBlock>()},
      {scenes, "emitter", MarkdownTable<Emitter>()},
      {scenes, "solid", MarkdownTable<SolidObject>()},
      {scenes, "solid.keyframe", MarkdownTable<Keyframe>()},
      {scenes, "domain", MarkdownTable<Domain>()},
      {scenes, "surface", MarkdownTable<SurfaceSettings>()},
      {scenes, "clean", MarkdownTable<CleanupSettings>()},
      {scenes, "bake", MarkdownTable<BakeSettings>()},
      {farm, "farm", MarkdownTable<FarmSettings>()},
      {farm, "farm.time", MarkdownTable<FarmTimes>()},
      {farm, "farm.memory", MarkdownTable<FarmMemory>()},
      {tools, "flags: boundary", header + FlagRows<FluidSettings>() + FlagRows<SolidObject>()},
      {tools, "flags: sim", header + FlagRows<SceneInfo>()},
      {tools, "flags: surface", header + FlagRows<SurfaceSettings>()},
      {tools, "flags: clean", header + FlagRows<CleanupSettings>()},
  };
}

std::string UpdateReferenceTables(const std::string& page) {
  static constexpr std::string_view kOpen = "<!-- generated: [", kEnd = "<!-- end generated -->";
  const std::vector<ReferenceTable> tables = SceneReferenceTables();
  std::string out;
  std::size_t at = 0;
  for (std::size_t open; (open = page.find(kOpen, at)) != std::string::npos;) {
    const std::size_t name_end = page.find("] -->\n", open);
    if (name_end == std::string::npos) throw Error(ExitCode::kBadInput, "unterminated table marker", page.substr(open, 40));
    const std::string section = page.substr(open + kOpen.size(), name_end - open - kOpen.size());
    const std::size_t body = name_end + 6;
    const std::size_t end = page.find(kEnd, body);
    if (end == std::string::npos) throw Error(ExitCode::kBadInput, "generated table without its end marker", section);
    const auto it = std::find_if(tables.begin(), tables.end(), [&](const ReferenceTable& t) { return t.section == section; });
    if (it == tables.end()) throw Error(ExitCode::kBadInput, "no declared section of this name", section);
    out += page.substr(at, body - at);
    out += it->markdown;
    at = end;
  }
  return out + page.substr(at);
}

}  // namespace rime::io
