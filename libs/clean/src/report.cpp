// Cleanup report as JSON and as one human line (see rime/clean/clean.h).
#include <fmt/format.h>

#include "rime/clean/clean.h"

namespace rime::clean {

nlohmann::json ToJson(const MeshStats& s) {
  return {{"vertices", s.vertices},
          {"faces", s.faces},
          {"components", s.components},
          {"boundary_edges", s.boundary_edges},
          {"non_manifold_edges", s.non_manifold_edges},
          {"non_manifold_vertices", s.non_manifold_vertices},
          {"degenerate_faces", s.degenerate_faces},
          {"closed", s.closed()},
          {"manifold", s.manifold()},
          {"area_m2", s.area},
          {"volume_m3", s.volume},
          {"min_angle_deg", s.min_angle_deg},
          {"mean_edge_length_m", s.mean_edge_length}};
}

namespace {
double RelativeChange(double before, double after) { return before != 0 ? (after - before) / std::abs(before) : 0; }
}  // namespace

nlohmann::json ToJson(const CleanReport& r) {
  nlohmann::json operations = nlohmann::json::array();
  for (const auto& op : r.operations)
    operations.push_back({{"name", op.name}, {"seconds", op.seconds}, {"cpu_seconds", op.cpu_seconds}, {"detail", op.detail}});
  return {{"before", ToJson(r.before)},
          {"after", ToJson(r.after)},
          {"manifold", r.manifold()},
          {"closed", r.closed()},
          {"repair_path", r.repair_path},
          {"faces_dropped_on_load", r.faces_dropped_on_load},
          {"degenerate_faces_removed", r.degenerate_faces_removed},
          {"components_removed", r.components_removed},
          {"component_faces_removed", r.component_faces_removed},
          {"holes_filled", r.holes_filled},
          {"holes_left", r.holes_left},
          {"target_edge_m", r.target_edge},
          {"self_intersecting_pairs", r.self_intersecting_pairs},
          {"self_intersections_removed", r.self_intersections_removed},
          {"velocities", r.velocities},
          {"volume_change", RelativeChange(r.before.volume, r.after.volume)},
          {"area_change", RelativeChange(r.before.area, r.after.area)},
          {"operations", operations},
          {"warnings", r.warnings},
          {"seconds", r.seconds}};
}

namespace {
std::string Count(std::size_t n) {
  if (n >= 10'000'000) return fmt::format("{:.0f}M", n / 1e6);
  if (n >= 1'000'000) return fmt::format("{:.1f}M", n / 1e6);
  if (n >= 10'000) return fmt::format("{:.0f}k", n / 1e3);
  return fmt::format("{}", n);
}
}  // namespace

std::string SummaryLine(const CleanReport& r) {
  std::string shape =
      r.manifold() ? (r.closed() ? "closed manifold" : fmt::format("manifold, {} boundary edges", r.after.boundary_edges)) : "NOT MANIFOLD";
  std::string intersections = r.self_intersecting_pairs < 0 ? "" : fmt::format(", {} self-intersecting pairs", r.self_intersecting_pairs);
  return fmt::format("{} -> {} faces, {} -> {} components, {}{}, volume {:+.2f}%, area {:+.2f}%, min angle {:.1f}°, {:.2f} s",
                     Count(r.before.faces), Count(r.after.faces), r.before.components, r.after.components, shape, intersections,
                     100 * RelativeChange(r.before.volume, r.after.volume), 100 * RelativeChange(r.before.area, r.after.area),
                     r.after.min_angle_deg, r.seconds);
}

}  // namespace rime::clean
