/// @file scene.h
/// @brief The scene file (TOML): every stage's settings, in SI units, with defaults and checks.
///
/// Each settings struct declares its fields once (param.h); docs/scene-reference.md shows them. Loading validates everything at once
/// (ranges, enum values, unknown keys) and throws rime::Error naming `file:line: field`.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <numbers>
#include <set>
#include <span>
#include <string>
#include <vector>

#include "rime/core/anisotropy.h"
#include "rime/core/math.h"
#include "rime/io/param.h"
#include "rime/io/scene_cleanup.h"
#include "rime/io/scene_surface.h"

namespace rime::io {

enum class Quality { kPreview, kProduction, kReference };
inline std::span<const std::string_view> Names(Quality) {
  static constexpr std::string_view names[] = {"preview", "production", "reference"};
  return names;
}
enum class Method { kRime, kIm2013 };
inline std::span<const std::string_view> Names(Method) {
  static constexpr std::string_view names[] = {"rime", "im2013"};
  return names;
}

struct SceneInfo {
  std::string name = "scene";  // set to the scene file's name before loading
  double fps = 24;
  double end_time = 2.0;
  Quality quality = Quality::kProduction;
  Method method = Method::kRime;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "name", .help = "scene name (output folder of `rime-bake`)", .default_doc = "file name"}, s.name);
    f(Param{.name = "fps",
            .unit = "1/s",
            .range = Range::OpenClosed(0, 10000),
            .help = "output frames per second; frame k is at t = k/fps exactly"},
      s.fps);
    f(Param{.name = "end_time",
            .unit = "s",
            .range = Range::Positive(),
            .help = "simulated time",
            .doc = "(end_time × fps at most 1,000,000 frames)",
            .flag = "--end-time"},
      s.end_time);
    f(Param{.name = "quality",
            .help = "accuracy preset, applied before explicit values (which win):",
            .doc = "preview = η 1 %, CFL 0.6, dt_max 10 ms, 2–50 iterations; production = the defaults; reference = η 0.01 %, "
                   "CFL 0.2, dt_max 2 ms, ≤ 500 iterations, double precision. Chosen from the speed/accuracy study "
                   "([performance.md](performance.md#speed-and-accuracy))"},
      s.quality);
    f(Param{.name = "method",
            .help = "`im2013` stands for the method the paper improves on (Im et al. 2013):",
            .doc = "isotropic ice growth, Akinci 2013 surface tension instead of He 2014, no wall stickiness "
                   "(`viscosity.wall_beta0 = 0`). A preset like `quality`: explicit values win"},
      s.method);
  }
};

enum class Precision { kFloat, kDouble };
inline std::span<const std::string_view> Names(Precision) {
  static constexpr std::string_view names[] = {"float", "double"};
  return names;
}

struct FluidSettings {
  double spacing = 0.02;
  double rest_density = 1000;
  double smoothing_ratio = 1.0;  // spec §1: 1
  Precision precision = Precision::kFloat;
  double particle_mass() const { return rest_density * spacing * spacing * spacing; }
  double smoothing_length() const { return smoothing_ratio * spacing; }

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "spacing",
            .unit = "m",
            .range = Range::OpenClosed(0, 10),
            .help = "particle spacing d_p; mass m = ρ0 d_p³",
            .flag = "--spacing"},
      s.spacing);
    f(Param{.name = "rest_density", .unit = "kg/m³", .range = Range::Positive(), .help = "ρ0"}, s.rest_density);
    f(Param{.name = "smoothing_ratio",
            .unit = "d_p",
            .range = Range::Closed(0.8, 2.0),
            .help = "h / d_p (support 2h)",
            .flag = "--smoothing-ratio"},
      s.smoothing_ratio);
    f(Param{.name = "precision", .help = "arithmetic of the solver (double for reference runs)"}, s.precision);
  }
};

enum class TimeStep { kCfl, kFixed };
inline std::span<const std::string_view> Names(TimeStep) {
  static constexpr std::string_view names[] = {"cfl", "fixed"};
  return names;
}
enum class AiiBoundary { kSplishSplash, kConsistent };
inline std::span<const std::string_view> Names(AiiBoundary) {
  static constexpr std::string_view names[] = {"splishsplash", "consistent"};
  return names;
}

/// `[sim]` (its `modules` list is Scene::modules).
struct SolverSettings {
  TimeStep time_step = TimeStep::kCfl;
  double dt = 0.001;
  double cfl = 0.4;  // lambda_CFL (spec §7)
  double dt_min = 1e-5, dt_max = 0.006;
  double omega = 0.5;  // relaxed Jacobi weight (spec §6)
  bool omega_fallback = true;
  double eta = 0.001;
  // At least 3, not Ihmsen's 2: after 2 the solve lets settled water breathe (the whole body in
  // phase at a few mm/s), since a body that sinks as a whole compresses only its bottom layer,
  // which the average error hardly sees (Iisph.SettledBlockBreathesWithTwoPressureIterations).
  int min_iterations = 3, max_iterations = 100;
  double warm_start = 0.5;
  AiiBoundary aii_boundary = AiiBoundary::kSplishSplash;
  double divergence_density_error = 0.05;
  Vec3d gravity{0, 0, -9.81};

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "time_step",
            .help = "Δt rule ([physics](physics.md#time-step)).",
            .doc = "Either way the steps up to each output frame are made equal (the frame's time span divided by the "
                   "fewest steps no longer than the rule's Δt), so Δt does not jump at frame times: a shortened last step "
                   "kicked water at rest at every frame"},
      s.time_step);
    f(Param{.name = "dt",
            .unit = "s",
            .range = Range::OpenClosed(0, 1),
            .help = "fixed Δt",
            .doc = "(an upper bound: 2 ms at 24 fps steps 1.984 ms)"},
      s.dt);
    f(Param{.name = "cfl",
            .range = Range::OpenClosed(0, 0.7),
            .help = "λ in Δt = λ d_p / max(‖v‖, √(2 g H)),",
            .doc = "H the water's extent along gravity (the speed its own weight can give it: deep water at rest would "
                   "otherwise step at `dt_max` and diverge, e.g. a 0.5 m column at d_p = 12.5 mm at 6 ms), also capped by "
                   "the explicit limits of viscosity, surface tension and air pressure (a scene whose limit falls below `dt_min` is "
                   "refused, naming the parameter). Above 0.7 particles tunnel through single-layer walls; a step that "
                   "moves a particle more than 0.8 spacings stops the run as diverged"},
      s.cfl);
    f(Param{.name = "dt_min", .unit = "s", .range = Range::OpenClosed(0, 1), .help = "lower clamp of the CFL step"}, s.dt_min);
    f(Param{.name = "dt_max",
            .unit = "s",
            .range = Range::OpenClosed(0, 1),
            .help = "upper clamp of the CFL step",
            .doc = "(at least `dt_min`)"},
      s.dt_max);
    f(Param{.name = "omega", .range = Range::OpenClosed(0, 1), .help = "relaxed-Jacobi weight (the paper's 0.8 diverges with Jacobi)"},
      s.omega);
    f(Param{.name = "omega_fallback", .help = "restart a step's solve with ω = 0.5 when the error grows 3 iterations in a row"},
      s.omega_fallback);
    f(Param{.name = "eta", .range = Range::OpenClosed(0, 1), .help = "target average density error (0.1 %)"}, s.eta);
    f(Param{.name = "min_iterations",
            .range = Range::Closed(1, 10000),
            .help = "fewest pressure iterations per step.",
            .doc = "3, not Ihmsen's 2: after only 2 the solve lets settled water breathe, the whole body in phase, at a "
                   "few mm/s (an 8³ block at d_p = 2 cm: 2.6 mm/s, against 0.3–0.7 mm/s with 3), because a body that "
                   "sinks as a whole compresses only its bottom layer, which the average error hardly sees. The third "
                   "iteration costs where 2 would do: 11 % per step on the 50k dam break at Δt = 1 ms "
                   "(`rime-bench-sim`); the preview preset keeps 2. Water starting on the lattice of a `water_block` "
                   "needs about 25–30 s to settle that far (the 8³ block): a regular lattice is no equilibrium of SPH"},
      s.min_iterations);
    f(Param{.name = "max_iterations",
            .range = Range::Closed(1, 10000),
            .help = "most pressure iterations per step (at least `min_iterations`)"},
      s.max_iterations);
    f(Param{.name = "warm_start", .range = Range::Closed(0, 1), .help = "p⁰ = warm_start · p_previous"}, s.warm_start);
    f(Param{.name = "aii_boundary", .help = "boundary term of a_ii ([physics](physics.md#pressure-iisph-eqs-124-ihmsen-et-al-2014))"},
      s.aii_boundary);
    f(Param{.name = "divergence_density_error",
            .range = Range::OpenClosed(0, 10),
            .help = "stop when the average density error exceeds this (5 %)"},
      s.divergence_density_error);
    f(Param{.name = "gravity", .unit = "m/s²", .help = "(Rime is z-up)"}, s.gravity);
  }
};

struct ViscositySettings {
  double mu = 1e-3;    // spec §5.1
  double beta0 = 0.1;  // spec §5.2
  double beta1 = 10;
  double wall_beta0 = 1.0;  // spec §5.4
  double epsilon = 0.01;
  bool limiter = false;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "mu", .unit = "Pa·s", .range = Range::NonNegative(), .help = "Morris dynamic viscosity"}, s.mu);
    f(Param{.name = "beta0", .range = Range::NonNegative(), .help = "Monaghan α of the sticky fluid–fluid term"}, s.beta0);
    f(Param{.name = "beta1", .unit = "m/s", .range = Range::NonNegative(), .help = "Monaghan c_s of the sticky fluid–fluid term"}, s.beta1);
    f(Param{.name = "wall_beta0",
            .range = Range::NonNegative(),
            .help = "β0b of the fluid–solid stickiness,",
            .doc = "integrated implicitly on the velocity the particle will have after the pressure solve (the previous "
                   "step's pressure acceleration as a predictor): applied to v + Δt g alone, the literal reading, it held "
                   "water at rest up along the walls and kept a block circulating"},
      s.wall_beta0);
    f(Param{.name = "epsilon", .range = Range::OpenClosed(0, 1), .help = "regulariser of the Monaghan term"}, s.epsilon);
    f(Param{.name = "limiter", .help = "apply the Monaghan term only to approaching pairs"}, s.limiter);
  }
};

enum class SurfaceTensionModel { kHe2014, kAkinci2013 };
inline std::span<const std::string_view> Names(SurfaceTensionModel) {
  static constexpr std::string_view names[] = {"he2014", "akinci2013"};
  return names;
}

struct SurfaceTensionSettings {
  SurfaceTensionModel model = SurfaceTensionModel::kHe2014;
  double kappa = 0.02;           // spec §5.3
  double kappa_boundary = 0.02;  // follows kappa when the scene does not set it
  double gamma = 0.05;
  double beta = 0.05;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "model", .help = "He 2014 colour-field energy, or Akinci et al. 2013 (cohesion + curvature + adhesion)"}, s.model);
    f(Param{.name = "kappa", .unit = "N", .range = Range::NonNegative(), .help = "He 2014 κ"}, s.kappa);
    f(Param{.name = "kappa_boundary",
            .unit = "N",
            .range = Range::NonNegative(),
            .help = "He 2014 adhesion to solids and ice",
            .default_doc = "`kappa`"},
      s.kappa_boundary);
    f(Param{.name = "gamma",
            .range = Range::NonNegative(),
            .help = "Akinci 2013 cohesion and curvature coefficient",
            .doc = "(model akinci2013 only)"},
      s.gamma);
    f(Param{.name = "beta",
            .range = Range::NonNegative(),
            .help = "Akinci 2013 adhesion to solids and ice",
            .doc = "(model akinci2013 only)"},
      s.beta);
  }
};

struct AirPressureSettings {
  double p_atm = 5000;  // spec §5.5

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "p_atm", .unit = "Pa", .range = Range::NonNegative(), .help = "air pressure on the free surface"}, s.p_atm);
  }
};

enum class FrMode { kMap, kClamp };
inline std::span<const std::string_view> Names(FrMode) {
  static constexpr std::string_view names[] = {"map", "clamp"};
  return names;
}
enum class CeMode { kDimensionless, kRaw };
inline std::span<const std::string_view> Names(CeMode) {
  static constexpr std::string_view names[] = {"dimensionless", "raw"};
  return names;
}
enum class CeAggregation { kMax, kSum };
inline std::span<const std::string_view> Names(CeAggregation) {
  static constexpr std::string_view names[] = {"max", "sum"};
  return names;
}
enum class PcaCenter { kMean, kParticle };
inline std::span<const std::string_view> Names(PcaCenter) {
  static constexpr std::string_view names[] = {"mean", "particle"};
  return names;
}
enum class Growth { kAnisotropic, kIsotropic };
inline std::span<const std::string_view> Names(Growth) {
  static constexpr std::string_view names[] = {"anisotropic", "isotropic"};
  return names;
}

/// Spec §12 freezing parameters (dimensionless ce thresholds, spec §9.6).
struct FreezingSettings {
  double glaze_threshold = 0.004;
  double icicle_threshold = 0.0001;
  double film_max_ratio = 1.0;
  double alpha_solid = 1.0, alpha_ice = 1.0;
  double dt_ref = 0.006;
  double film_diffusion = 0.15;
  double drying_rate = 0;
  // Water freezes only after its nucleation energy stayed above a threshold this long; 0 freezes at
  // once, as the paper does (docs/physics.md "Nucleation delay").
  double freeze_delay = 0;
  // Ice grows downstream, with the flow (−1), and not where fr < 0 ("clamp"): the paper's pictures
  // and text (docs/physics.md "Freezing fraction"); +1 grows against the flow, a column into falling water.
  int growth_sign = -1;
  // Weight of gravity's direction added to the flow's growth direction: ice grows downwards too,
  // so water dripping off ice freezes onto it (docs/physics.md "Freezing fraction").
  double gravity_growth = 0;
  // Power of the freezing fraction of water meeting ice: above 1, water beside an icicle runs on and
  // freezes below its tip, so icicles grow long and slender (docs/physics.md "Freezing fraction").
  double tip_growth = 1;
  FrMode fr_mode = FrMode::kClamp;
  CeMode ce_mode = CeMode::kDimensionless;
  CeAggregation ce_aggregation = CeAggregation::kMax;
  PcaCenter pca_center = PcaCenter::kMean;
  Growth growth = Growth::kAnisotropic;
  // Yu & Turk's constants: one declaration, anisotropy::Params (spec §8); k_s = 0 is automatic.
  double k_r = anisotropy::Params<double>{}.k_r, k_n = anisotropy::Params<double>{}.k_n, k_s = anisotropy::Params<double>{}.k_s;
  int n_eps = anisotropy::Params<double>{}.n_eps;
  double s_min = anisotropy::Params<double>{}.s_min, s_max = anisotropy::Params<double>{}.s_max;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "glaze_threshold", .range = Range::NonNegative(), .help = "gzth on the dimensionless nucleation energy"},
      s.glaze_threshold);
    f(Param{.name = "icicle_threshold", .range = Range::NonNegative(), .help = "icth"}, s.icicle_threshold);
    f(Param{.name = "film_max_ratio", .range = Range::Positive(), .help = "Γ_max / m"}, s.film_max_ratio);
    f(Param{.name = "alpha_solid", .range = Range::Closed(0, 1), .help = "film transfer fraction α onto solids"}, s.alpha_solid);
    f(Param{.name = "alpha_ice", .range = Range::Closed(0, 1), .help = "film transfer fraction α onto ice"}, s.alpha_ice);
    f(Param{.name = "dt_ref", .unit = "s", .range = Range::Positive(), .help = "the step the paper's per-step rates refer to"}, s.dt_ref);
    f(Param{.name = "film_diffusion", .unit = "d_p²/dt_ref", .range = Range::NonNegative(), .help = "D_Γ (0 disables)"}, s.film_diffusion);
    f(Param{.name = "drying_rate", .unit = "1/s", .range = Range::NonNegative(), .help = "k_dry"}, s.drying_rate);
    f(Param{.name = "freeze_delay",
            .unit = "s",
            .range = Range::Closed(0, 60),
            .help = "*Freeze slower*: water freezes only once its nucleation energy has stayed above a threshold this long,",
            .doc = "so running water stays liquid and what lingers freezes (thinner glaze that follows the surface, longer "
                   "icicles under edges); 0 freezes at the first step, as the paper ([physics.md](physics.md#phase-shift))"},
      s.freeze_delay);
    f(Param{.name = "growth_sign",
            .range = Range::Closed(-1, 1),
            .help = "−1: ice grows with the flow, downstream (the paper's figures); +1: against it,",
            .doc = "as Eq. 31 is printed ([physics.md](physics.md#freezing-fraction-eq-31)); 0 is refused"},
      s.growth_sign);
    f(Param{.name = "gravity_growth",
            .range = Range::Closed(0, 10),
            .help = "*Icicles grow down*: weight of gravity's direction added to the flow's growth direction of ice,",
            .doc = "so water below ice freezes onto it first and water arriving from above does not pile up into a mound; "
                   "glaze on solids is unaffected. 0 is the paper's Eq. 26 alone "
                   "([physics.md](physics.md#freezing-fraction-eq-31))"},
      s.gravity_growth);
    f(Param{.name = "tip_growth",
            .range = Range::Closed(1, 16),
            .help = "*Longer icicles*: power of the freezing fraction of water meeting ice, so water beside an icicle",
            .doc = "runs down and freezes below its tip instead of thickening its sides; 1 is the paper's Eq. 31 "
                   "([physics.md](physics.md#freezing-fraction-eq-31))"},
      s.tip_growth);
    f(Param{.name = "fr_mode",
            .help = "clamp: max(0, dot), no growth where the flow points away (the paper's text);",
            .doc = "map: (dot+1)/2 as printed"},
      s.fr_mode);
    f(Param{.name = "ce_mode", .help = "raw for the literal kg/m³ nucleation energy"}, s.ce_mode);
    f(Param{.name = "ce_aggregation", .help = "sum over boundary neighbours instead of their maximum"}, s.ce_aggregation);
    f(Param{.name = "pca_center", .help = "particle: the paper's literal Eq. 28 centring"}, s.pca_center);
    f(Param{.name = "growth", .help = "isotropic = the Im et al. 2013 baseline (G = I/h)"}, s.growth);
    f(Param{.name = "k_r",
            .range = Range::Closed(1, 1e6),
            .help = "largest ratio of the fluid PCA's stretches",
            .doc = "([physics](physics.md#fluid-anisotropy-eqs-2730-yu--turk-2013))"},
      s.k_r);
    f(Param{.name = "k_n", .range = Range::Positive(), .help = "stretch of particles with fewer than `n_eps` neighbours"}, s.k_n);
    f(Param{.name = "k_s", .unit = "1/m²", .range = Range::NonNegative(), .help = "stretch scale", .default_doc = "0 (automatic 1/σ_iso)"},
      s.k_s);
    f(Param{.name = "n_eps", .range = Range::Closed(0, 1000), .help = "fewest neighbours for a trusted PCA"}, s.n_eps);
    f(Param{.name = "s_min", .range = Range::Positive(), .help = "smallest stretch"}, s.s_min);
    f(Param{.name = "s_max", .range = Range::Positive(), .help = "largest stretch (at least `s_min`)"}, s.s_max);
  }
};

enum class UpAxis { kZ, kY };
inline std::span<const std::string_view> Names(UpAxis) {
  static constexpr std::string_view names[] = {"z", "y"};
  return names;
}

struct Transform {
  Vec3d translate{0, 0, 0};
  Vec3d rotate_deg{0, 0, 0};
  Vec3d scale{1, 1, 1};
  UpAxis up_axis = UpAxis::kZ;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "scale",
            .range = Range::Positive(),
            .help = "one number for all axes, or one per axis; applied after the up-axis turn",
            .flag = "--scale",
            .scalar_or_vector = true},
      s.scale);
    f(Param{.name = "rotate",
            .unit = "degree",
            .range = Range::Closed(-3600, 3600),
            .help = "Euler angles: X, then Y, then Z, after the scale",
            .flag = "--rotate"},
      s.rotate_deg);
    f(Param{.name = "translate", .unit = "m", .help = "applied last", .flag = "--translate"}, s.translate);
    f(Param{.name = "up_axis", .help = "up axis of the source; `y` (most meshes) is turned to Rime's z-up", .flag = "--up-axis"},
      s.up_axis);
  }
};

struct Keyframe {
  double time = 0;
  Vec3d translate{0, 0, 0};
  Vec3d rotate_deg{0, 0, 0};

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "time", .unit = "s", .range = Range::NonNegative(), .help = "increasing from one keyframe to the next"}, s.time);
    f(Param{.name = "translate", .unit = "m", .help = "offset at this time, linearly interpolated"}, s.translate);
    f(Param{.name = "rotate", .unit = "degree", .help = "Euler angles at this time, linearly interpolated"}, s.rotate_deg);
  }
};

enum class SolidShape { kBox, kPlane, kSphere, kCylinder, kTorus, kMesh };
inline std::span<const std::string_view> Names(SolidShape) {
  static constexpr std::string_view names[] = {"box", "plane", "sphere", "cylinder", "torus", "mesh"};
  return names;
}

/// A solid the water collides with, sticks to and freezes on.
struct SolidObject {
  std::string name;  // set to solid<k> before loading
  SolidShape shape = SolidShape::kBox;
  std::filesystem::path mesh;  // relative to the scene file
  Vec3d size{1, 1, 1};
  double radius = 0.5;
  double minor_radius = 0.1;
  double height = 1.0;
  bool container = false;
  bool merge_meshes = true;
  double spacing_ratio = 0.5;  // spec §3
  Transform transform;
  // Motion (kinematic): constant spin about an axis through spin_center, and/or keyframes.
  Vec3d spin_axis{0, 0, 1};
  double spin_rate = 0;
  Vec3d spin_center{0, 0, 0};
  std::vector<Keyframe> keyframes;
  bool animated() const { return spin_rate != 0 || !keyframes.empty(); }

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "name", .help = "unique; the boundary file is `<name>.h5part`", .default_doc = "`solid<k>`"}, s.name);
    f(Param{.name = "shape", .help = "procedural shape, or a mesh file"}, s.shape);
    f(Param{.name = "mesh", .unit = "path", .help = "only with `shape = \"mesh\"`, relative to the scene file", .default_doc = "(none)"},
      s.mesh);
    f(Param{.name = "size", .unit = "m", .range = Range::Positive(), .help = "box extents; a plane uses x and y"}, s.size);
    f(Param{.name = "radius", .unit = "m", .range = Range::Positive(), .help = "sphere, cylinder, torus major radius"}, s.radius);
    f(Param{.name = "minor_radius", .unit = "m", .range = Range::Positive(), .help = "torus tube radius, below `radius`"}, s.minor_radius);
    f(Param{.name = "height", .unit = "m", .range = Range::Positive(), .help = "cylinder"}, s.height);
    f(Param{.name = "container", .help = "box only: open top, walls facing inward (a tank the water sits in)"}, s.container);
    f(Param{.name = "merge_meshes",
            .help = "sample all meshes of a multi-mesh file as one object; false: separately, with no welding or duplicate removal "
                    "between them",
            .flag = "!--separate-parts"},
      s.merge_meshes);
    f(Param{.name = "spacing_ratio",
            .unit = "d_p",
            .range = Range::Closed(0.1, 1.0),
            .help = "boundary spacing d_b / d_p",
            .flag = "--spacing-ratio"},
      s.spacing_ratio);
    Transform::Visit(s.transform, f);
    f(Param{.name = "spin_axis", .help = "axis of a constant spin (not zero)"}, s.spin_axis);
    f(Param{.name = "spin_rate", .unit = "rad/s", .help = "spin rate (0: no spin)"}, s.spin_rate);
    f(Param{.name = "spin_center", .unit = "m", .help = "a point on the spin axis"}, s.spin_center);
  }
};

enum class BlockShape { kBox, kSphere };
inline std::span<const std::string_view> Names(BlockShape) {
  static constexpr std::string_view names[] = {"box", "sphere"};
  return names;
}

/// Lattice points of spacing dp along an extent, both ends included when it is a multiple of dp
/// (as a double, so that a hostile extent cannot overflow).
inline double LatticeCount(double extent, double dp) { return std::floor(extent / dp + 1e-6) + 1; }
/// Lattice rows on one side of a centre row within `half`.
inline double HalfRows(double half, double dp) { return std::floor(half / dp + 1e-9); }
/// Lattice points of a row at squared distance `offset_sq` from the centre of a disc or sphere of
/// `radius` that lie within it (the seeding's 1e-9 m tolerance included).
inline double ChordPoints(double radius, double offset_sq, double dp) {
  const double half_sq = (radius + 1e-9) * (radius + 1e-9) - offset_sq;
  return half_sq < 0 ? 0 : 2 * HalfRows(std::sqrt(half_sq), dp) + 1;
}

struct FluidBlock {
  BlockShape shape = BlockShape::kBox;
  Vec3d min{0, 0, 0}, max{0.1, 0.1, 0.1};
  Vec3d center{0, 0, 0};
  double radius = 0.1;
  Vec3d velocity{0, 0, 0};

  /// Calls f(p) for each lattice point of spacing `dp` that seeds the block: anchored at the box's
  /// `min` corner (its far faces included when the extent is a multiple of dp), or at the sphere's
  /// centre.
  template <class F>
  void ForEachLatticePoint(double dp, F&& f) const {
    if (shape == BlockShape::kBox) {
      const Vec3d e = max - min;
      const std::int64_t nx = std::int64_t(LatticeCount(e.x, dp)), ny = std::int64_t(LatticeCount(e.y, dp)),
                         nz = std::int64_t(LatticeCount(e.z, dp));
      for (std::int64_t k = 0; k < nz; ++k)
        for (std::int64_t j = 0; j < ny; ++j)
          for (std::int64_t i = 0; i < nx; ++i) f(min + Vec3d(double(i) * dp, double(j) * dp, double(k) * dp));
      return;
    }
    const std::int64_t r = std::int64_t(std::floor(radius / dp + 1e-6));
    for (std::int64_t k = -r; k <= r; ++k)
      for (std::int64_t j = -r; j <= r; ++j)
        for (std::int64_t i = -r; i <= r; ++i) {
          const Vec3d offset(double(i) * dp, double(j) * dp, double(k) * dp);
          if (Norm(offset) <= radius + 1e-9) f(center + offset);
        }
  }

  /// Points ForEachLatticePoint visits, in closed form (per row for a sphere) so that a hostile
  /// size costs no time; a sphere wider than 10^3 rows is counted by its volume.
  double Particles(double dp) const {
    if (shape == BlockShape::kBox) {
      const Vec3d e = max - min;
      return LatticeCount(e.x, dp) * LatticeCount(e.y, dp) * LatticeCount(e.z, dp);
    }
    const double rows = std::floor(radius / dp + 1e-6);
    if (rows > 1e3) return 4.0 / 3.0 * std::numbers::pi * radius * radius * radius / (dp * dp * dp);
    double count = 0;
    for (double k = -rows; k <= rows; ++k)
      for (double j = -rows; j <= rows; ++j) count += ChordPoints(radius, (k * k + j * j) * dp * dp, dp);
    return count;
  }

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "shape", .help = "a box, or a sphere"}, s.shape);
    f(Param{.name = "min", .unit = "m", .help = "box corner: the lattice of spacing d_p starts here"}, s.min);
    f(Param{.name = "max",
            .unit = "m",
            .help = "box corner, beyond `min` on every axis",
            .doc = "(included when the extent is a multiple of d_p: the sphere drop's 0.3 × 0.3 × 0.24 m block holds "
                   "16 × 16 × 13 = 3,328 particles)"},
      s.max);
    f(Param{.name = "center", .unit = "m", .help = "sphere centre"}, s.center);
    f(Param{.name = "radius", .unit = "m", .range = Range::Positive(), .help = "sphere: lattice points within it of `center`"}, s.radius);
    f(Param{.name = "velocity", .unit = "m/s", .help = "initial velocity"}, s.velocity);
  }
};

enum class EmitterShape { kDisc, kRectangle };
inline std::span<const std::string_view> Names(EmitterShape) {
  static constexpr std::string_view names[] = {"disc", "rectangle"};
  return names;
}

struct Emitter {
  EmitterShape shape = EmitterShape::kDisc;
  Vec3d center{0, 0, 0};
  Vec3d direction{0, 0, -1};
  double radius = 0.05;
  double width = 0.1, height = 0.1;
  double speed = 1.0;
  double start = 0, stop = 1e30;

  /// Calls f(a, b) for each particle of one emitted layer: the lattice at spacing `dp` in the
  /// nozzle plane (a along the width, b along the height), its edges included.
  template <class F>
  void ForEachLayerPoint(double dp, F&& f) const {
    const bool disc = shape == EmitterShape::kDisc;
    const std::int64_t nu = std::int64_t(HalfRows(disc ? radius : width / 2, dp));
    const std::int64_t nw = std::int64_t(HalfRows(disc ? radius : height / 2, dp));
    for (std::int64_t a = -nu; a <= nu; ++a)
      for (std::int64_t b = -nw; b <= nw; ++b)
        if (!disc || std::hypot(double(a) * dp, double(b) * dp) <= radius + 1e-9) f(double(a) * dp, double(b) * dp);
  }

  /// Particles emitted until its stop or the scene's end, whichever comes first: a layer each time
  /// the jet has advanced by `dp`. Counted per lattice row, in closed form, so a hostile size
  /// costs no time (a disc wider than 10^6 rows is counted by its area).
  double EmittedParticles(double end_time, double dp) const {
    const double layers = std::floor(speed * std::max(0.0, std::min(stop, end_time) - start) / dp + 1e-9);
    if (shape == EmitterShape::kRectangle) return layers * (2 * HalfRows(width / 2, dp) + 1) * (2 * HalfRows(height / 2, dp) + 1);
    const double rows = HalfRows(radius, dp);
    if (rows > 1e6) return layers * std::numbers::pi * radius * radius / (dp * dp);
    double layer = 0;
    for (double a = -rows; a <= rows; ++a) layer += ChordPoints(radius, a * dp * a * dp, dp);
    return layers * layer;
  }

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "shape", .help = "nozzle outline"}, s.shape);
    f(Param{.name = "center", .unit = "m", .help = "nozzle centre"}, s.center);
    f(Param{.name = "direction", .help = "direction of the jet (not zero)"}, s.direction);
    f(Param{.name = "radius", .unit = "m", .range = Range::Positive(), .help = "disc radius"}, s.radius);
    f(Param{.name = "width", .unit = "m", .range = Range::Positive(), .help = "rectangle, in the nozzle plane"}, s.width);
    f(Param{.name = "height", .unit = "m", .range = Range::Positive(), .help = "rectangle, in the nozzle plane"}, s.height);
    f(Param{.name = "speed", .unit = "m/s", .range = Range::Positive(), .help = "speed of the emitted water"}, s.speed);
    f(Param{.name = "start", .unit = "s", .range = Range::NonNegative(), .help = "when the nozzle opens"}, s.start);
    f(Param{.name = "stop", .unit = "s", .range = Range::NonNegative(), .help = "when it closes, after `start`", .default_doc = "never"},
      s.stop);
  }
};

struct Domain {
  bool set = false;  // the scene sets min or max
  Vec3d min{-1e30, -1e30, -1e30}, max{1e30, 1e30, 1e30};

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "min", .unit = "m", .help = "lower corner of the box water is kept in", .default_doc = "(none)"}, s.min);
    f(Param{.name = "max", .unit = "m", .help = "upper corner, beyond `min` on every axis", .default_doc = "(none)"}, s.max);
  }
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
  /// Water particles the scene can hold: its blocks' lattices plus what each emitter emits until
  /// it stops or the scene ends (particles leaving the domain are not subtracted).
  double WaterParticles() const {
    double count = 0;
    for (const FluidBlock& b : fluid_blocks) count += b.Particles(fluid.spacing);
    for (const Emitter& e : emitters) count += e.EmittedParticles(info.end_time, fluid.spacing);
    return count;
  }
  /// Resolves a path written in the scene relative to the scene file's folder.
  std::filesystem::path Resolve(const std::filesystem::path& p) const;
  std::int64_t FrameCount() const;  // output frames after frame 0
};

/// Bounds far beyond any bake this project runs, so that a typo (spacing 1e-9, end_time 1e9) is
/// refused at load time instead of exhausting memory or disk hours later.
inline constexpr double kMaxSceneParticles = 1e9;                              // per water block or emitter, at [water] spacing
inline constexpr std::int64_t kMaxSceneFrames = 1'000'000;                     // end_time * fps
inline constexpr std::uintmax_t kMaxSceneFileBytes = std::uintmax_t(1) << 28;  // 256 MiB

/// Names accepted in `[sim] modules = [...]`.
const std::vector<std::string>& KnownModules();

Scene LoadScene(const std::filesystem::path& file);
/// Parses scene text (for tests); `file` is used in messages and to resolve relative paths.
Scene ParseScene(const std::string& text, const std::filesystem::path& file);

}  // namespace rime::io
