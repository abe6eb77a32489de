/// @file scene.h
/// @brief The scene file (TOML): every stage's settings, in SI units, with defaults and checks.
///
/// README.md "Scene file reference" documents every field. Loading validates everything at once
/// (ranges, enum values, unknown keys) and throws rime::Error naming `file:line: field`.
#pragma once

#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "rime/core/math.h"
#include "rime/io/scene_cleanup.h"
#include "rime/io/scene_surface.h"

namespace rime::io {

struct SceneInfo {
  std::string name = "scene";
  double fps = 24;         // output frames per second
  double end_time = 2.0;   // s
  std::string quality;     // "", "preview", "production", "reference" (presets, set before explicit values)
  std::string method = "rime";  // | "im2013": the baseline the paper improves on (preset, set before explicit values)
};

struct FluidSettings {
  double spacing = 0.02;          // d_p, m
  double rest_density = 1000;     // rho0, kg/m^3
  double smoothing_ratio = 1.0;   // h / d_p (spec §1: 1)
  std::string precision = "float";  // "float" | "double"
  double particle_mass() const { return rest_density * spacing * spacing * spacing; }
  double smoothing_length() const { return smoothing_ratio * spacing; }
};

struct SolverSettings {
  std::string time_step = "cfl";  // "cfl" | "fixed"
  double dt = 0.001;              // fixed step, s
  double cfl = 0.4;               // lambda_CFL (spec §7)
  double dt_min = 1e-5, dt_max = 0.006;
  double omega = 0.5;             // relaxed Jacobi weight (spec §6)
  bool omega_fallback = true;     // restart the solve with 0.5 when the error grows 3 times
  double eta = 0.001;             // average density error target (0.1 %)
  // At least 3, not Ihmsen's 2: after 2 the solve lets settled water breathe (the whole body in
  // phase at a few mm/s), since a body that sinks as a whole compresses only its bottom layer,
  // which the average error hardly sees (Iisph.SettledBlockStaysAtRest).
  int min_iterations = 3, max_iterations = 100;
  double warm_start = 0.5;        // p0 = warm_start * p_prev
  std::string aii_boundary = "splishsplash";  // | "consistent"
  double divergence_density_error = 0.05;     // stop when the average density error exceeds this
  Vec3d gravity{0, 0, -9.81};
};

struct ViscositySettings {
  double mu = 1e-3;       // Morris dynamic viscosity, Pa s (spec §5.1)
  double beta0 = 0.1;     // Monaghan alpha (spec §5.2)
  double beta1 = 10;      // Monaghan c_s, m/s
  double wall_beta0 = 1.0;  // beta0b of the wall term (spec §5.4)
  double epsilon = 0.01;
  bool limiter = false;
};

struct SurfaceTensionSettings {
  std::string model = "he2014";  // | "akinci2013" (the Im et al. 2013 baseline)
  double kappa = 0.02;           // N (He 2014, spec §5.3)
  double kappa_boundary = 0.02;  // adhesion to solids and ice
  double gamma = 0.05;           // Akinci 2013 cohesion and curvature coefficient
  double beta = 0.05;            // Akinci 2013 adhesion to solids and ice
};

struct AirPressureSettings {
  double p_atm = 5000;  // Pa (spec §5.5)
};

/// Spec §12 freezing parameters (dimensionless ce thresholds, spec §9.6).
struct FreezingSettings {
  double glaze_threshold = 0.004;     // gzth
  double icicle_threshold = 0.0001;   // icth
  double film_max_ratio = 1.0;        // Gamma_max / m
  double alpha_solid = 1.0, alpha_ice = 1.0;
  double dt_ref = 0.006;              // s
  double film_diffusion = 0.15;       // D_Gamma in d_p^2 / dt_ref
  double drying_rate = 0;             // k_dry, 1/s
  // Water freezes only after its nucleation energy stayed above a threshold this long; 0 freezes at
  // once, as the paper does (docs/physics.md "Nucleation delay").
  double freeze_delay = 0;            // s
  // Ice grows downstream, with the flow (−1), and not where fr < 0 ("clamp"): the paper's pictures
  // and text (docs/physics.md "Freezing fraction"); +1 grows against the flow, a column into falling water.
  int growth_sign = -1;               // −1: with the flow, +1: against it (Eq. 31 as printed)
  // Weight of gravity's direction added to the flow's growth direction: ice grows downwards too,
  // so water dripping off ice freezes onto it (docs/physics.md "Freezing fraction").
  double gravity_growth = 0;
  std::string fr_mode = "clamp";      // "clamp": max(0, dot) | "map": (dot + 1) / 2
  std::string ce_mode = "dimensionless";  // | "raw"
  std::string ce_aggregation = "max";     // | "sum"
  std::string pca = "w2h";            // "w2h" (W weights, 2h) | "yu_turk" (4h)
  std::string pca_center = "mean";    // | "particle"
  std::string growth = "anisotropic"; // | "isotropic" (baseline: G = I/h)
  double k_r = 4, k_n = 0.5;
  double k_s = 0;                     // 0: automatic 1/sigma_iso
  int n_eps = 6;
  double s_min = 0.125, s_max = 1.0;
};

struct Transform {
  Vec3d translate{0, 0, 0};
  Vec3d rotate_deg{0, 0, 0};  // Euler angles applied X, then Y, then Z
  Vec3d scale{1, 1, 1};
  std::string up_axis = "z";  // "y": the source is y-up (most meshes); rotated to Rime's z-up
};

struct Keyframe {
  double time = 0;
  Vec3d translate{0, 0, 0};
  Vec3d rotate_deg{0, 0, 0};
};

/// A solid the water collides with, sticks to and freezes on.
struct SolidObject {
  std::string name;
  std::string shape = "box";  // box | plane | sphere | cylinder | torus | mesh
  std::filesystem::path mesh; // for shape = "mesh" (relative to the scene file)
  Vec3d size{1, 1, 1};        // box / plane extents (plane: x, y), m
  double radius = 0.5;        // sphere / cylinder, torus major radius
  double minor_radius = 0.1;  // torus tube radius
  double height = 1.0;        // cylinder
  bool container = false;     // box: open-top tank with inward normals
  bool merge_meshes = true;
  Transform transform;
  double spacing_ratio = 0.5;  // boundary spacing d_b / d_p (spec §3)
  // Motion (kinematic): constant spin about an axis through spin_center, and/or keyframes.
  Vec3d spin_axis{0, 0, 1};
  double spin_rate = 0;        // rad/s
  Vec3d spin_center{0, 0, 0};
  std::vector<Keyframe> keyframes;
  bool animated() const { return spin_rate != 0 || !keyframes.empty(); }
};

struct FluidBlock {
  std::string shape = "box";  // box | sphere
  Vec3d min{0, 0, 0}, max{0.1, 0.1, 0.1};
  Vec3d center{0, 0, 0};
  double radius = 0.1;
  Vec3d velocity{0, 0, 0};
};

struct Emitter {
  std::string shape = "disc";  // disc | rectangle
  Vec3d center{0, 0, 0};
  Vec3d direction{0, 0, -1};
  double radius = 0.05;        // disc
  double width = 0.1, height = 0.1;  // rectangle
  double speed = 1.0;          // m/s
  double start = 0, stop = 1e30;  // s
};

struct Domain {
  bool set = false;
  Vec3d min{-1e30, -1e30, -1e30}, max{1e30, 1e30, 1e30};
};

struct Scene {
  std::filesystem::path file;
  std::string hash;  // content hash of the scene file
  SceneInfo info;
  FluidSettings fluid;
  SolverSettings solver;
  std::set<std::string> modules;
  ViscositySettings viscosity;
  SurfaceTensionSettings surface_tension;
  AirPressureSettings air_pressure;
  FreezingSettings freezing;
  std::vector<SolidObject> solids;
  std::vector<FluidBlock> fluid_blocks;
  std::vector<Emitter> emitters;
  Domain domain;
  SurfaceSettings surface;
  CleanupSettings cleanup;

  bool Enabled(const std::string& module) const { return modules.count(module) != 0; }
  /// Resolves a path written in the scene relative to the scene file's folder.
  std::filesystem::path Resolve(const std::filesystem::path& p) const;
  std::int64_t FrameCount() const;  // output frames after frame 0
};

/// Bounds far beyond any bake this project runs, so that a typo (spacing 1e-9, end_time 1e9) is
/// refused at load time instead of exhausting memory or disk hours later.
inline constexpr double kMaxSceneParticles = 1e9;      // per water block or emitter, at [water] spacing
inline constexpr std::int64_t kMaxSceneFrames = 1'000'000;  // end_time * fps
inline constexpr std::uintmax_t kMaxSceneFileBytes = std::uintmax_t(1) << 28;  // 256 MiB

/// Names accepted in `[simulation] modules = [...]`.
const std::vector<std::string>& KnownModules();

Scene LoadScene(const std::filesystem::path& file);
/// Parses scene text (for tests); `file` is used in messages and to resolve relative paths.
Scene ParseScene(const std::string& text, const std::filesystem::path& file);

}  // namespace rime::io
