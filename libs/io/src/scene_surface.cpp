#include "rime/io/scene_surface.h"

#include "rime/io/toml_reader.h"

namespace rime::io {

void ParseSurfaceSettings(TomlReader& t, SurfaceSettings& s) {
  const std::vector<std::string> fields{"ellipsoids", "kernel_sum", "isotropic"};
  s.phase = t.String("phase", s.phase, {"ice", "water", "both"});
  s.ice_field = t.String("ice_field", s.ice_field, fields);
  s.water_field = t.String("water_field", s.water_field, fields);
  s.voxel_ratio = t.Number("voxel_ratio", s.voxel_ratio, {0.02, 4, false, false});
  s.voxel_size = t.Number("voxel_size", s.voxel_size, Range::NonNegative());
  s.resolution = int(t.Integer("resolution", s.resolution, Range::Closed(0, 4096)));
  if (s.resolution == 1) t.Fail("resolution", "must be 0 (off) or at least 2");
  s.r_iso = t.Number("r_iso", s.r_iso, {0, 4, true, false});
  s.lambda = t.Number("lambda", s.lambda, Range::Closed(0, 1));
  s.k_r = t.Number("k_r", s.k_r, Range::Closed(1, 1000));
  s.k_s = t.Number("k_s", s.k_s, Range::NonNegative());
  s.k_n = t.Number("k_n", s.k_n, {0, 10, true, false});
  s.n_eps = int(t.Integer("n_eps", s.n_eps, Range::Closed(0, 1000)));
  s.iso = t.Number("iso", s.iso, Range::Positive());
  s.half_band = t.Number("half_band", s.half_band, Range::Closed(3, 64));
  s.close = t.Number("close", s.close, Range::Closed(0, 4));
  s.smooth = int(t.Integer("smooth", s.smooth, Range::Closed(0, 100)));
  s.velocity = t.Bool("velocity", s.velocity);
  s.density = t.Bool("density", s.density);
  if (t.Has("formats")) {
    s.formats = t.StringList("formats", {"obj", "ply", "vdb"});
    if (s.formats.empty()) t.Fail("formats", "needs at least one of obj, ply, vdb");
  }
  s.memory_budget_gb = t.Number("memory_budget_gb", s.memory_budget_gb, Range::NonNegative());
}

}  // namespace rime::io
