#include <algorithm>

#include "rime/surface/reconstruct.h"

namespace rime::surface {

const io::SurfaceSettings& SceneDefaults() {
  static const io::SurfaceSettings defaults;
  return defaults;
}

Settings FromScene(const io::SurfaceSettings& scene, Field field) {
  const auto has = [&](const char* format) { return std::find(scene.formats.begin(), scene.formats.end(), format) != scene.formats.end(); };
  Settings s;
  s.field = field;
  s.voxel_size = scene.voxel_size;
  s.voxel_ratio = scene.voxel_ratio;
  s.resolution = scene.resolution;
  s.r_iso = scene.r_iso;
  s.lambda = scene.lambda;
  s.anisotropy.k_r = scene.k_r;
  s.anisotropy.k_s = scene.k_s;
  s.anisotropy.k_n = scene.k_n;
  s.anisotropy.n_eps = scene.n_eps;
  s.iso = scene.iso;
  s.half_band = scene.half_band;
  s.close_radius = scene.close;
  s.smooth_iterations = scene.smooth;
  s.smooth_limit = scene.smooth_limit;
  s.velocity_grid = scene.velocity && has("vdb");
  s.density_grid = scene.density && has("vdb");
  s.mesh = has("obj") || has("ply");
  s.mesh_velocities = has("ply");
  return s;
}

}  // namespace rime::surface
