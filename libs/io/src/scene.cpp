#include "rime/io/scene.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <numbers>
#include <toml++/toml.h>

#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/io/toml_reader.h"

namespace fs = std::filesystem;

namespace rime::io {
namespace {

void ParseTransform(TomlReader& t, Transform& transform) {
  transform.translate = t.Vector("translate", transform.translate);
  transform.rotate_deg = t.Vector("rotate", transform.rotate_deg, Range::Closed(-3600, 3600));
  transform.scale = t.ScalarOrVector("scale", transform.scale, Range::Positive());
  transform.up_axis = t.String("up_axis", transform.up_axis, {"z", "y"});
}

// Scene and solid names become file and folder names (out/<scene>, <solid>.h5part): any
// character a filename can hold is fine, but a '/' or a name like ".." would leave the folder.
std::string FileNameSafe(TomlReader& t, const char* key, std::string value) {
  if (value.empty() || value == "." || value == ".." || value.find_first_of(std::string("/\0", 2)) != std::string::npos)
    t.Fail(key, fmt::format("'{}' cannot be used as a file name (it is empty, '.' or '..', or holds a '/')", value));
  return value;
}

SolidObject ParseSolid(TomlReader& t, std::size_t index) {
  SolidObject s;
  s.name = FileNameSafe(t, "name", t.String("name", fmt::format("solid{}", index)));
  s.shape = t.String("shape", s.shape, {"box", "plane", "sphere", "cylinder", "torus", "mesh"});
  if (s.shape == "mesh") {
    if (!t.Has("mesh")) t.Fail("mesh", "shape = \"mesh\" needs a mesh file path");
    s.mesh = t.String("mesh", "");
  } else if (t.Has("mesh")) {
    t.Fail("mesh", "a mesh path is only used with shape = \"mesh\"");
  }
  s.size = t.Vector("size", s.size, Range::Positive());
  s.radius = t.Number("radius", s.radius, Range::Positive());
  s.minor_radius = t.Number("minor_radius", s.minor_radius, Range::Positive());
  s.height = t.Number("height", s.height, Range::Positive());
  s.container = t.Bool("container", s.container);
  s.merge_meshes = t.Bool("merge_meshes", s.merge_meshes);
  s.spacing_ratio = t.Number("spacing_ratio", s.spacing_ratio, {0.1, 1.0, false, false});
  ParseTransform(t, s.transform);
  if (s.shape == "torus" && s.minor_radius >= s.radius) t.Fail("minor_radius", "torus minor_radius must be below radius");
  s.spin_axis = t.Vector("spin_axis", s.spin_axis);
  if (Norm(s.spin_axis) == 0) t.Fail("spin_axis", "spin axis must not be zero");
  s.spin_rate = t.Number("spin_rate", s.spin_rate);
  s.spin_center = t.Vector("spin_center", s.spin_center);
  double last_time = -1;
  for (TomlReader& k : t.TableArray("keyframe")) {
    Keyframe key;
    key.time = k.Number("time", 0, Range::NonNegative());
    if (key.time <= last_time) k.Fail("time", "keyframe times must increase");
    last_time = key.time;
    key.translate = k.Vector("translate", key.translate);
    key.rotate_deg = k.Vector("rotate", key.rotate_deg);
    k.RejectUnknownKeys();
    s.keyframes.push_back(key);
  }
  t.RejectUnknownKeys();
  return s;
}

// Particles at spacing d_p in `volume`; refused above kMaxSceneParticles naming `key`.
void CheckParticleCount(TomlReader& t, const std::string& key, double volume, double spacing, const char* what) {
  const double count = volume / (spacing * spacing * spacing);
  if (!(count <= kMaxSceneParticles))
    t.Fail(key, fmt::format("{} would hold about {:.3g} particles at [water] spacing {:g} m, more than {:g} (use a larger "
                            "spacing or a smaller {})", what, count, spacing, kMaxSceneParticles, what));
}

FluidBlock ParseBlock(TomlReader& t, double spacing) {
  FluidBlock b;
  b.shape = t.String("shape", b.shape, {"box", "sphere"});
  b.min = t.Vector("min", b.min);
  b.max = t.Vector("max", b.max);
  if (b.shape == "box" && (b.max.x <= b.min.x || b.max.y <= b.min.y || b.max.z <= b.min.z))
    t.Fail("max", "box max must exceed min on every axis");
  b.center = t.Vector("center", b.center);
  b.radius = t.Number("radius", b.radius, Range::Positive());
  b.velocity = t.Vector("velocity", b.velocity);
  if (b.shape == "box") {
    const Vec3d extent = b.max - b.min;
    CheckParticleCount(t, "max", extent.x * extent.y * extent.z, spacing, "water block");
  } else {
    CheckParticleCount(t, "radius", 4.0 / 3.0 * std::numbers::pi * b.radius * b.radius * b.radius, spacing, "water block");
  }
  t.RejectUnknownKeys();
  return b;
}

Emitter ParseEmitter(TomlReader& t, double spacing, double end_time) {
  Emitter e;
  e.shape = t.String("shape", e.shape, {"disc", "rectangle"});
  e.center = t.Vector("center", e.center);
  e.direction = t.Vector("direction", e.direction);
  if (Norm(e.direction) == 0) t.Fail("direction", "emitter direction must not be zero");
  e.radius = t.Number("radius", e.radius, Range::Positive());
  e.width = t.Number("width", e.width, Range::Positive());
  e.height = t.Number("height", e.height, Range::Positive());
  e.speed = t.Number("speed", e.speed, Range::Positive());
  e.start = t.Number("start", e.start, Range::NonNegative());
  e.stop = t.Number("stop", e.stop, Range::NonNegative());
  if (e.stop <= e.start) t.Fail("stop", "emitter stop time must be after its start time");
  // Water emitted until the stop time or the end of the scene, whichever comes first.
  const double area = e.shape == "disc" ? std::numbers::pi * e.radius * e.radius : e.width * e.height;
  const double duration = std::max(0.0, std::min(e.stop, end_time) - e.start);
  CheckParticleCount(t, e.shape == "disc" ? "radius" : "width", area * e.speed * duration, spacing, "emitter");
  t.RejectUnknownKeys();
  return e;
}

// Presets set the accuracy knobs before the explicit values are read, so explicit values win.
// Values from the speed/accuracy study (tests/bench/accuracy/RESULTS.md): on its dam break preview
// runs 1.7x faster than production for a 0.8 % surge-front error, reference 2.3x slower for 0.12 %
// (production 0.45 %), all against a run at η 1e-5, CFL 0.1.
void ApplyQualityPreset(const std::string& quality, Scene& scene) {
  SolverSettings& s = scene.solver;
  if (quality == "preview") {
    s.eta = 0.01;
    s.cfl = 0.6;
    s.dt_max = 0.01;
    s.min_iterations = 2;  // a preview does not mind millimetre-per-second breathing at rest
    s.max_iterations = 50;
  } else if (quality == "reference") {
    s.eta = 1e-4;
    s.cfl = 0.2;
    s.dt_max = 0.002;
    s.max_iterations = 500;
    scene.fluid.precision = "double";
  }
}

// The Im et al. 2013 baseline: isotropic ice growth, Akinci 2013 surface tension
// instead of He 2014, no wall stickiness. Like the quality presets, explicit values still win.
void ApplyMethodPreset(const std::string& method, Scene& scene) {
  if (method != "im2013") return;
  scene.freezing.growth = "isotropic";
  scene.surface_tension.model = "akinci2013";
  scene.viscosity.wall_beta0 = 0;
}

}  // namespace

const std::vector<std::string>& KnownModules() {
  static const std::vector<std::string> modules{"gravity", "viscosity", "surface_tension", "air_pressure", "freezing"};
  return modules;
}

fs::path Scene::Resolve(const fs::path& p) const {
  if (p.is_absolute() || file.empty()) return p;
  return file.parent_path() / p;
}

std::int64_t Scene::FrameCount() const { return static_cast<std::int64_t>(std::floor(info.end_time * info.fps + 1e-9)); }

Scene ParseScene(const std::string& text, const fs::path& file) {
  const std::string name = file.string();
  if (text.size() > kMaxSceneFileBytes)
    throw InputError(fmt::format("scene file of {} bytes, larger than the limit of {} bytes", text.size(), kMaxSceneFileBytes), name);
  CheckTomlLimits(text, name);
  toml::table root;
  try {
    root = toml::parse(text, name);
  } catch (const toml::parse_error& e) {
    throw InputError(fmt::format("TOML syntax error: {}", e.description()),
                     fmt::format("{}:{}", name, e.source().begin.line));
  }
  Scene scene;
  scene.file = file;
  scene.hash = HexHash(Hash64(text));
  TomlReader top(root, name, "");

  {
    TomlReader t = top.Table("scene");
    scene.info.name = FileNameSafe(t, "name", t.String("name", file.stem().string()));
    scene.info.fps = t.Number("fps", scene.info.fps, {0, 10000, true, false});
    scene.info.end_time = t.Number("end_time", scene.info.end_time, Range::Positive());
    scene.info.quality = t.String("quality", "", {"preview", "production", "reference"});
    scene.info.method = t.String("method", scene.info.method, {"rime", "im2013"});
    if (!(scene.info.end_time * scene.info.fps <= double(kMaxSceneFrames)))
      t.Fail("end_time", fmt::format("end_time {:g} s at {:g} fps makes {:.3g} frames, more than {}", scene.info.end_time,
                                     scene.info.fps, scene.info.end_time * scene.info.fps, kMaxSceneFrames));
    t.RejectUnknownKeys();
  }
  ApplyQualityPreset(scene.info.quality, scene);
  ApplyMethodPreset(scene.info.method, scene);
  {
    TomlReader t = top.Table("water");
    FluidSettings& f = scene.fluid;
    f.spacing = t.Number("spacing", f.spacing, {0, 10, true, false});
    f.rest_density = t.Number("rest_density", f.rest_density, Range::Positive());
    f.smoothing_ratio = t.Number("smoothing_ratio", f.smoothing_ratio, Range::Closed(0.8, 2.0));
    f.precision = t.String("precision", f.precision, {"float", "double"});
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = top.Table("simulation");
    SolverSettings& s = scene.solver;
    const auto modules = t.Has("modules") ? t.StringList("modules", KnownModules()) : std::vector<std::string>{"gravity"};
    scene.modules = {modules.begin(), modules.end()};
    s.time_step = t.String("time_step", s.time_step, {"cfl", "fixed"});
    s.dt = t.Number("dt", s.dt, {0, 1, true, false});
    s.cfl = t.Number("cfl", s.cfl, {0, 0.7, true, false});
    s.dt_min = t.Number("dt_min", s.dt_min, {0, 1, true, false});
    s.dt_max = t.Number("dt_max", s.dt_max, {0, 1, true, false});
    if (s.dt_max < s.dt_min) t.Fail("dt_max", "dt_max must be at least dt_min");
    s.omega = t.Number("omega", s.omega, {0, 1, true, false});
    s.omega_fallback = t.Bool("omega_fallback", s.omega_fallback);
    s.eta = t.Number("eta", s.eta, {0, 1, true, false});
    s.min_iterations = static_cast<int>(t.Integer("min_iterations", s.min_iterations, Range::Closed(1, 10000)));
    s.max_iterations = static_cast<int>(t.Integer("max_iterations", s.max_iterations, Range::Closed(1, 10000)));
    if (s.max_iterations < s.min_iterations) t.Fail("max_iterations", "max_iterations must be at least min_iterations");
    s.warm_start = t.Number("warm_start", s.warm_start, Range::Closed(0, 1));
    s.aii_boundary = t.String("aii_boundary", s.aii_boundary, {"splishsplash", "consistent"});
    s.divergence_density_error = t.Number("divergence_density_error", s.divergence_density_error, {0, 10, true, false});
    s.gravity = t.Vector("gravity", s.gravity);
    t.RejectUnknownKeys();
  }
  // Module parameter tables: each named after its module.
  const auto module_table = [&](const std::string& module) {
    if (top.Has(module) && !scene.Enabled(module))
      throw InputError(fmt::format("[{}] is set but the module is not enabled (add \"{}\" to simulation.modules)", module, module),
                       top.Where(module) + ": " + module);
    return top.Table(module);
  };
  {
    TomlReader t = module_table("viscosity");
    ViscositySettings& v = scene.viscosity;
    v.mu = t.Number("mu", v.mu, Range::NonNegative());
    v.beta0 = t.Number("beta0", v.beta0, Range::NonNegative());
    v.beta1 = t.Number("beta1", v.beta1, Range::NonNegative());
    v.wall_beta0 = t.Number("wall_beta0", v.wall_beta0, Range::NonNegative());
    v.epsilon = t.Number("epsilon", v.epsilon, {0, 1, true, false});
    v.limiter = t.Bool("limiter", v.limiter);
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = module_table("surface_tension");
    SurfaceTensionSettings& st = scene.surface_tension;
    st.model = t.String("model", st.model, {"he2014", "akinci2013"});
    st.kappa = t.Number("kappa", st.kappa, Range::NonNegative());
    st.kappa_boundary = t.Number("kappa_boundary", st.kappa, Range::NonNegative());
    st.gamma = t.Number("gamma", st.gamma, Range::NonNegative());
    st.beta = t.Number("beta", st.beta, Range::NonNegative());
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = module_table("air_pressure");
    scene.air_pressure.p_atm = t.Number("p_atm", scene.air_pressure.p_atm, Range::NonNegative());
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = module_table("freezing");
    FreezingSettings& f = scene.freezing;
    f.glaze_threshold = t.Number("glaze_threshold", f.glaze_threshold, Range::NonNegative());
    f.icicle_threshold = t.Number("icicle_threshold", f.icicle_threshold, Range::NonNegative());
    f.film_max_ratio = t.Number("film_max_ratio", f.film_max_ratio, Range::Positive());
    f.alpha_solid = t.Number("alpha_solid", f.alpha_solid, Range::Closed(0, 1));
    f.alpha_ice = t.Number("alpha_ice", f.alpha_ice, Range::Closed(0, 1));
    f.dt_ref = t.Number("dt_ref", f.dt_ref, Range::Positive());
    f.film_diffusion = t.Number("film_diffusion", f.film_diffusion, Range::NonNegative());
    f.drying_rate = t.Number("drying_rate", f.drying_rate, Range::NonNegative());
    f.freeze_delay = t.Number("freeze_delay", f.freeze_delay, Range::Closed(0, 60));
    f.growth_sign = static_cast<int>(t.Integer("growth_sign", f.growth_sign, Range::Closed(-1, 1)));
    f.gravity_growth = t.Number("gravity_growth", f.gravity_growth, Range::Closed(0, 10));
    if (f.growth_sign == 0) t.Fail("growth_sign", "growth_sign must be +1 or -1");
    f.fr_mode = t.String("fr_mode", f.fr_mode, {"map", "clamp"});
    f.ce_mode = t.String("ce_mode", f.ce_mode, {"dimensionless", "raw"});
    f.ce_aggregation = t.String("ce_aggregation", f.ce_aggregation, {"max", "sum"});
    f.pca = t.String("pca", f.pca, {"w2h", "yu_turk"});
    f.pca_center = t.String("pca_center", f.pca_center, {"mean", "particle"});
    f.growth = t.String("growth", f.growth, {"anisotropic", "isotropic"});
    f.k_r = t.Number("k_r", f.k_r, {1, 1e6, false, false});
    f.k_n = t.Number("k_n", f.k_n, Range::Positive());
    f.k_s = t.Number("k_s", f.k_s, Range::NonNegative());
    f.n_eps = static_cast<int>(t.Integer("n_eps", f.n_eps, Range::Closed(0, 1000)));
    f.s_min = t.Number("s_min", f.s_min, Range::Positive());
    f.s_max = t.Number("s_max", f.s_max, Range::Positive());
    if (f.s_max < f.s_min) t.Fail("s_max", "s_max must be at least s_min");
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = top.Table("domain");
    if (t.Has("min") || t.Has("max")) {
      scene.domain.set = true;
      scene.domain.min = t.Vector("min", scene.domain.min);
      scene.domain.max = t.Vector("max", scene.domain.max);
      if (scene.domain.max.x <= scene.domain.min.x || scene.domain.max.y <= scene.domain.min.y ||
          scene.domain.max.z <= scene.domain.min.z)
        t.Fail("max", "domain max must exceed min on every axis");
    }
    t.RejectUnknownKeys();
  }
  std::size_t index = 0;
  for (TomlReader& t : top.TableArray("solid")) scene.solids.push_back(ParseSolid(t, index++));
  for (std::size_t a = 0; a < scene.solids.size(); ++a)
    for (std::size_t b = a + 1; b < scene.solids.size(); ++b)
      if (scene.solids[a].name == scene.solids[b].name)
        throw InputError(fmt::format("two solids are named '{}'", scene.solids[a].name), name + ": solid.name");
  for (TomlReader& t : top.TableArray("water_block")) scene.fluid_blocks.push_back(ParseBlock(t, scene.fluid.spacing));
  for (TomlReader& t : top.TableArray("emitter"))
    scene.emitters.push_back(ParseEmitter(t, scene.fluid.spacing, scene.info.end_time));
  {
    TomlReader t = top.Table("surface");
    ParseSurfaceSettings(t, scene.surface);
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = top.Table("cleanup");
    ParseCleanupSettings(t, scene.cleanup);
    t.RejectUnknownKeys();
  }
  top.Skip("bake");  // read by rime-bake (pipeline/)
  top.Skip("farm");  // cluster settings, read by rime-bake --farm (pipeline/)
  top.RejectUnknownKeys();
  return scene;
}

Scene LoadScene(const fs::path& file) {
  std::error_code ec;
  if (!fs::exists(file, ec)) throw InputError("scene file not found", file.string());
  // Checked before reading, so that a huge file costs no memory.
  const std::uintmax_t size = fs::file_size(file, ec);
  if (ec) throw InputError("cannot read scene file", file.string());
  if (size > kMaxSceneFileBytes)
    throw InputError(fmt::format("scene file of {} bytes, larger than the limit of {} bytes", size, kMaxSceneFileBytes), file.string());
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError("cannot read scene file", file.string());
  std::string text(size, '\0');
  if (!in.read(text.data(), std::streamsize(size))) throw InputError("cannot read scene file", file.string());
  return ParseScene(text, file);
}

}  // namespace rime::io
