#include "rime/io/scene_reference.h"

#include <fmt/format.h>

#include <algorithm>

#include "rime/core/error.h"
#include "rime/io/scene.h"
#include "rime/io/scene_bake.h"

namespace rime::io {

std::string DescribeAccepted(const Param& p, std::span<const std::string_view> names) {
  if (!names.empty()) {
    std::string out;
    for (std::size_t k = 0; k < names.size(); ++k) out += fmt::format("{}`{}`", k ? ", " : "", names[k]);
    return out;
  }
  return p.range.IsAny() ? std::string() : p.range.Describe();
}

std::vector<ReferenceTable> SceneReferenceTables() {
  const std::string scenes = "scene-reference.md", tools = "tools.md", header(kFlagTableHeader);
  return {
      {scenes, "scene", MarkdownTable<SceneInfo>()},
      {scenes, "water", MarkdownTable<FluidSettings>()},
      {scenes, "simulation", MarkdownTable<SolverSettings>()},
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
      {scenes, "cleanup", MarkdownTable<CleanupSettings>()},
      {scenes, "bake", MarkdownTable<BakeSettings>()},
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
