/// @file scene_surface.h
/// @brief `[surface]` section of the scene file (rime-surface settings; README "rime-surface").
#pragma once

#include <string>
#include <vector>

namespace rime::io {

class TomlReader;

/// Defaults follow spec §10/§12. rime-surface flags override these values.
struct SurfaceSettings {
  std::string phase = "both";             // "ice" | "water" | "both"
  std::string ice_field = "ellipsoids";   // "ellipsoids" | "kernel_sum" | "isotropic"
  std::string water_field = "kernel_sum"; // same choices
  double voxel_ratio = 0.5;               // voxel size / particle spacing (ignored when voxel_size or resolution is set)
  double voxel_size = 0;                  // m; 0 = voxel_ratio * spacing
  int resolution = 0;                     // > 0: paper grid, nodes along the longest bounding-box side (200)
  double r_iso = 0.75;                    // ellipsoid level, particle spacings
  double lambda = 0.9;                    // centre smoothing
  double k_r = 4, k_s = 0, k_n = 0.5;     // k_s 0 = automatic 1/σ_iso
  int n_eps = 6;
  double iso = 0.5;                       // kernel_sum iso value
  double half_band = 3;                   // voxels, >= 3
  double close = 0.5;                     // closing radius, particle spacings: fills sampling gaps narrower than twice this
  int smooth = 10;                        // mean-curvature smoothing iterations of the level set (removes particle bumps)
  bool velocity = false;                  // `vel` grid in the VDB
  bool density = false;                   // `density` fog grid in the VDB
  std::vector<std::string> formats{"obj", "vdb"};  // any of obj, ply, vdb
  double memory_budget_gb = 0;            // 0 = no limit
};

/// Reads the `[surface]` table into `settings` (fields absent from the table keep their defaults).
void ParseSurfaceSettings(TomlReader& table, SurfaceSettings& settings);

}  // namespace rime::io
