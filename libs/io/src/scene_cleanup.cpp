#include "rime/io/scene_cleanup.h"

#include "rime/io/toml_reader.h"

namespace rime::io {

void ParseCleanupSettings(TomlReader& t, CleanupSettings& s) {
  s.repair = t.String("repair", s.repair, {"auto", "always", "never"});

  s.remove_degenerate = t.Bool("remove_degenerate", s.remove_degenerate);
  s.remove_almost_degenerate = t.Bool("remove_almost_degenerate", s.remove_almost_degenerate);
  s.cap_angle_deg = t.Number("cap_angle_deg", s.cap_angle_deg, Range{90, 180, true, true});
  s.needle_ratio = t.Number("needle_ratio", s.needle_ratio, Range{1, 1e300, true, false});

  s.remove_components = t.Bool("remove_components", s.remove_components);
  s.min_component_faces = int(t.Integer("min_component_faces", s.min_component_faces, Range::Closed(0, 1e9)));
  s.min_component_area = t.Number("min_component_area", s.min_component_area, Range::NonNegative());
  s.min_component_volume = t.Number("min_component_volume", s.min_component_volume, Range::NonNegative());

  s.fill_holes = t.Bool("fill_holes", s.fill_holes);
  s.max_hole_edges = int(t.Integer("max_hole_edges", s.max_hole_edges, Range::Closed(3, 1e9)));
  s.fair_holes = t.Bool("fair_holes", s.fair_holes);

  s.remesh = t.Bool("remesh", s.remesh);
  s.target_edge = t.Number("target_edge", s.target_edge, Range::NonNegative());
  s.target_edge_factor = t.Number("target_edge_factor", s.target_edge_factor, Range{0, 100, true, false});
  s.remesh_iterations = int(t.Integer("remesh_iterations", s.remesh_iterations, Range::Closed(1, 100)));

  s.smooth = t.String("smooth", s.smooth, {"tangential", "angle", "none"});
  s.smooth_iterations = int(t.Integer("smooth_iterations", s.smooth_iterations, Range::Closed(0, 1000)));
  s.shape_smooth_iterations = int(t.Integer("shape_smooth_iterations", s.shape_smooth_iterations, Range::Closed(0, 1000)));
  s.shape_smooth_time = t.Number("shape_smooth_time", s.shape_smooth_time, Range::Positive());

  s.decimate = t.Bool("decimate", s.decimate);
  s.decimate_method = t.String("decimate_method", s.decimate_method, {"batch", "cgal"});
  s.decimate_ratio = t.Number("decimate_ratio", s.decimate_ratio, Range{0, 1, true, false});
  s.decimate_faces = t.Integer("decimate_faces", s.decimate_faces, Range::Closed(0, 1e15));
  s.decimate_max_error = t.Number("decimate_max_error", s.decimate_max_error, Range::NonNegative());

  s.self_intersections = t.String("self_intersections", s.self_intersections, {"report", "remove", "off"});
  s.transfer_velocity = t.Bool("transfer_velocity", s.transfer_velocity);
}

}  // namespace rime::io
