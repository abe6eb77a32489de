/// @file scene_surface.h
/// @brief `[surface]` section of the scene file (rime-surface settings; docs/tools.md "rime-surface").
#pragma once

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "rime/core/anisotropy.h"
#include "rime/io/param.h"

namespace rime::io {

class TomlReader;

enum class SurfacePhases { kIce, kWater, kBoth };
inline std::span<const std::string_view> Names(SurfacePhases) {
  static constexpr std::string_view names[] = {"ice", "water", "both"};
  return names;
}
/// The implicit function a phase is surfaced with (rime::surface::Field).
enum class SurfaceField { kEllipsoids, kKernelSum, kIsotropic };
inline std::span<const std::string_view> Names(SurfaceField) {
  static constexpr std::string_view names[] = {"ellipsoids", "kernel_sum", "isotropic"};
  return names;
}

inline constexpr std::string_view kSurfaceFormats[] = {"obj", "ply", "vdb"};

/// Defaults follow spec §10/§12. rime-surface flags override these values.
struct SurfaceSettings {
  SurfacePhases phase = SurfacePhases::kBoth;
  SurfaceField ice_field = SurfaceField::kEllipsoids;
  SurfaceField water_field = SurfaceField::kKernelSum;
  double voxel_ratio = 0.5;
  double voxel_size = 0;
  int resolution = 0;
  double r_iso = 0.75;
  double lambda = 0.9;
  // Yu & Turk's constants: one declaration, anisotropy::Params (spec §8).
  double k_r = anisotropy::Params<double>{}.k_r, k_s = anisotropy::Params<double>{}.k_s, k_n = anisotropy::Params<double>{}.k_n;
  int n_eps = anisotropy::Params<double>{}.n_eps;
  double iso = 0.5;
  double half_band = 3;
  double close = 0.5;
  int smooth = 10;
  double smooth_limit = 0;
  bool velocity = false;
  bool density = false;
  std::vector<std::string> formats{"obj", "vdb"};
  double memory_budget_gb = 0;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "phase", .help = "which particles to surface", .flag = "--phase"}, s.phase);
    f(Param{.name = "ice_field",
            .help = "field of the ice: ellipsoids (union of anisotropic ellipsoids, Eq. 41), kernel_sum (Yu & Turk sum of "
                    "anisotropic kernels at `iso`) or isotropic (spheres of radius `r_iso`)"},
      s.ice_field);
    f(Param{.name = "water_field", .help = "field of the water, as `ice_field`"}, s.water_field);
    f(Param{.name = "voxel_ratio",
            .unit = "d_p",
            .range = Range::Closed(0.02, 4),
            .help = "voxel size / particle spacing (unless `voxel_size` or `resolution` is set)"},
      s.voxel_ratio);
    f(Param{.name = "voxel_size",
            .unit = "m",
            .range = Range::NonNegative(),
            .help = "voxel size",
            .flag = "--voxel-size",
            .default_doc = "0 (use `voxel_ratio`)"},
      s.voxel_size);
    f(Param{.name = "resolution",
            .unit = "nodes",
            .range = Range::Closed(0, 4096),
            .help = "the paper's fixed grid: voxel = longest side of the padded bounding box / (N − 1), e.g. 200; 0 is off, 1 refused",
            .flag = "--resolution"},
      s.resolution);
    f(Param{.name = "r_iso", .unit = "d_p", .range = Range::OpenClosed(0, 4), .help = "ellipsoid level r_iso", .flag = "--r-iso"}, s.r_iso);
    f(Param{.name = "lambda", .range = Range::Closed(0, 1), .help = "Yu & Turk centre smoothing, 0 = off", .flag = "--lambda"}, s.lambda);
    f(Param{.name = "k_r", .range = Range::Closed(1, 1000), .help = "largest stretch ratio k_r", .flag = "--kr"}, s.k_r);
    f(Param{.name = "k_s",
            .unit = "1/m²",
            .range = Range::NonNegative(),
            .help = "stretch scale k_s; 0 = automatic 1/(0.2994 h²)",
            .flag = "--ks"},
      s.k_s);
    f(Param{.name = "k_n",
            .range = Range::OpenClosed(0, 10),
            .help = "stretch of particles with fewer than N_eps neighbours (kernel_sum only: ellipsoids are scaled to the "
                    "r_iso sphere volume)",
            .flag = "--kn"},
      s.k_n);
    f(Param{.name = "n_eps", .range = Range::Closed(0, 1000), .help = "fewest neighbours N_eps for a trusted PCA", .flag = "--neps"},
      s.n_eps);
    f(Param{.name = "iso", .range = Range::Positive(), .help = "iso value of the kernel_sum field", .flag = "--iso"}, s.iso);
    f(Param{.name = "half_band", .unit = "voxels", .range = Range::Closed(3, 64), .help = "narrow band half width"}, s.half_band);
    f(Param{.name = "close",
            .unit = "d_p",
            .range = Range::Closed(0, 4),
            .help = "closing radius: dilates, then erodes the level set, filling gaps narrower than twice it",
            .doc = "(OpenVDB); real sheets keep their thickness",
            .flag = "--close"},
      s.close);
    f(Param{.name = "smooth",
            .unit = "iterations",
            .range = Range::Closed(0, 100),
            .help = "OpenVDB level-set mean-curvature smoothing after the closing, for the ellipsoids and isotropic fields",
            .doc = "(ice); removes particle-sized bumps and lets lone beads shrink away, while more steps thin sheets one "
                   "particle thick ([ice-look.md](ice-look.md))",
            .flag = "--smooth"},
      s.smooth);
    f(Param{.name = "smooth_limit",
            .unit = "d_p",
            .range = Range::Closed(0, 4),
            .help = "the smoothing moves the surface at most this far from the closed particle surface (0 = no limit)",
            .doc = "so thin icicles and sheets keep a neck instead of coming loose (mean-curvature flow pinches thin necks away; "
                   "[ice-look.md](ice-look.md))",
            .flag = "--smooth-limit"},
      s.smooth_limit);
    f(Param{.name = "velocity", .help = "add a `vel` vec3 grid (particle velocities, for motion blur) to the VDB", .flag = "--vel"},
      s.velocity);
    f(Param{.name = "density", .help = "add a `density` fog grid (Blender's volume shader shows it without setup)", .flag = "--density"},
      s.density);
    f(Param{.name = "formats",
            .help = "outputs, at least one (on the command line: comma-separated)",
            .flag = "--format",
            .choices = kSurfaceFormats},
      s.formats);
    f(Param{.name = "memory_budget_gb",
            .unit = "GB (10⁹ bytes)",
            .range = Range::NonNegative(),
            .help = "rime-surface's memory budget when `--memory-budget` is not given",
            .doc = "([tools.md](tools.md#common-conventions-of-every-tool))",
            .default_doc = "0 (the memory available)"},
      s.memory_budget_gb);
  }
};

/// Reads the `[surface]` table into `settings` (fields absent from the table keep their defaults).
void ParseSurfaceSettings(TomlReader& table, SurfaceSettings& settings);

}  // namespace rime::io
