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

// Scene and solid names become file and folder names (out/<scene>, <solid>.h5part): any
// character a filename can hold is fine, but a '/' or a name like ".." would leave the folder.
std::string FileNameSafe(TomlReader& t, const char* key, std::string value) {
  if (value.empty() || value == "." || value == ".." || value.find_first_of(std::string("/\0", 2)) != std::string::npos)
    t.Fail(key, fmt::format("'{}' cannot be used as a file name (it is empty, '.' or '..', or holds a '/')", value));
  return value;
}

SolidObject ParseSolid(TomlReader& t, std::size_t index) {
  SolidObject s;
  s.name = fmt::format("solid{}", index);
  LoadSettings(t, s);
  FileNameSafe(t, "name", s.name);
  if (s.shape == SolidShape::kMesh && !t.Has("mesh")) t.Fail("mesh", "shape = \"mesh\" needs a mesh file path");
  if (s.shape != SolidShape::kMesh && t.Has("mesh")) t.Fail("mesh", "a mesh path is only used with shape = \"mesh\"");
  if (s.shape == SolidShape::kTorus && s.minor_radius >= s.radius) t.Fail("minor_radius", "torus minor_radius must be below radius");
  if (Norm(s.spin_axis) == 0) t.Fail("spin_axis", "spin axis must not be zero");
  double last_time = -1;
  for (TomlReader& k : t.TableArray("keyframe")) {
    Keyframe key;
    LoadSettings(k, key);
    if (key.time <= last_time) k.Fail("time", "keyframe times must increase");
    last_time = key.time;
    k.RejectUnknownKeys();
    s.keyframes.push_back(key);
  }
  t.RejectUnknownKeys();
  return s;
}

// Refused above kMaxSceneParticles naming `key`.
void CheckParticleCount(TomlReader& t, const std::string& key, double count, double spacing, const char* what) {
  if (!(count <= kMaxSceneParticles))
    t.Fail(key, fmt::format("{} would hold about {:.3g} particles at [water] spacing {:g} m, more than {:g} (use a larger "
                            "spacing or a smaller {})",
                            what, count, spacing, kMaxSceneParticles, what));
}

FluidBlock ParseBlock(TomlReader& t, double spacing) {
  FluidBlock b;
  LoadSettings(t, b);
  if (b.shape == BlockShape::kBox && (b.max.x <= b.min.x || b.max.y <= b.min.y || b.max.z <= b.min.z))
    t.Fail("max", "box max must exceed min on every axis");
  CheckParticleCount(t, b.shape == BlockShape::kBox ? "max" : "radius", b.Particles(spacing), spacing, "water block");
  t.RejectUnknownKeys();
  return b;
}

Emitter ParseEmitter(TomlReader& t, double spacing, double end_time) {
  Emitter e;
  LoadSettings(t, e);
  if (Norm(e.direction) == 0) t.Fail("direction", "emitter direction must not be zero");
  if (e.stop <= e.start) t.Fail("stop", "emitter stop time must be after its start time");
  CheckParticleCount(t, e.shape == EmitterShape::kDisc ? "radius" : "width", e.EmittedParticles(end_time, spacing), spacing, "emitter");
  t.RejectUnknownKeys();
  return e;
}

// Presets set the accuracy knobs before the explicit values are read, so explicit values win.
// Values from the speed/accuracy study (tests/bench/accuracy/RESULTS.md): on its dam break preview
// runs 1.7x faster than production for a 0.8 % surge-front error, reference 2.3x slower for 0.12 %
// (production 0.45 %), all against a run at η 1e-5, CFL 0.1.
void ApplyQualityPreset(Quality quality, Scene& scene) {
  SolverSettings& s = scene.solver;
  if (quality == Quality::kPreview) {
    s.eta = 0.01;
    s.cfl = 0.6;
    s.dt_max = 0.01;
    s.min_iterations = 2;  // a preview does not mind millimetre-per-second breathing at rest
    s.max_iterations = 50;
  } else if (quality == Quality::kReference) {
    s.eta = 1e-4;
    s.cfl = 0.2;
    s.dt_max = 0.002;
    s.max_iterations = 500;
    scene.fluid.precision = Precision::kDouble;
  }
}

// The Im et al. 2013 baseline: isotropic ice growth, Akinci 2013 surface tension
// instead of He 2014, no wall stickiness. Like the quality presets, explicit values still win.
void ApplyMethodPreset(Method method, Scene& scene) {
  if (method != Method::kIm2013) return;
  scene.freezing.growth = Growth::kIsotropic;
  scene.surface_tension.model = SurfaceTensionModel::kAkinci2013;
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
    throw InputError(fmt::format("TOML syntax error: {}", e.description()), fmt::format("{}:{}", name, e.source().begin.line));
  }
  Scene scene;
  scene.file = file;
  scene.hash = HexHash(Hash64(text));
  TomlReader top(root, name, "");
  // Each stage has one name (library, tool, section, bake stage); a scene written for the former
  // section names is told the current one instead of "unknown key".
  for (const auto& [former, current] : {std::pair{"simulation", "sim"}, {"cleanup", "clean"}})
    if (top.Has(former))
      throw InputError(fmt::format("[{}] is now called [{}]: rename the section", former, current), top.Where(former) + ": " + former);

  {
    TomlReader t = top.Table("scene");
    scene.info.name = file.stem().string();
    LoadSettings(t, scene.info);
    FileNameSafe(t, "name", scene.info.name);
    if (!(scene.info.end_time * scene.info.fps <= double(kMaxSceneFrames)))
      t.Fail("end_time", fmt::format("end_time {:g} s at {:g} fps makes {:.3g} frames, more than {}", scene.info.end_time, scene.info.fps,
                                     scene.info.end_time * scene.info.fps, kMaxSceneFrames));
    t.RejectUnknownKeys();
  }
  ApplyQualityPreset(scene.info.quality, scene);
  ApplyMethodPreset(scene.info.method, scene);
  {
    TomlReader t = top.Table("water");
    LoadSettings(t, scene.fluid);
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = top.Table("sim");
    SolverSettings& s = scene.solver;
    const auto modules = t.Has("modules") ? t.StringList("modules", KnownModules()) : std::vector<std::string>{"gravity"};
    scene.modules = {modules.begin(), modules.end()};
    LoadSettings(t, s);
    if (s.dt_max < s.dt_min) t.Fail("dt_max", "dt_max must be at least dt_min");
    if (s.max_iterations < s.min_iterations) t.Fail("max_iterations", "max_iterations must be at least min_iterations");
    t.RejectUnknownKeys();
  }
  // Module parameter tables: each named after its module.
  const auto module_table = [&](const std::string& module) {
    if (top.Has(module) && !scene.Enabled(module))
      throw InputError(fmt::format("[{}] is set but the module is not enabled (add \"{}\" to sim.modules)", module, module),
                       top.Where(module) + ": " + module);
    return top.Table(module);
  };
  {
    TomlReader t = module_table("viscosity");
    LoadSettings(t, scene.viscosity);
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = module_table("surface_tension");
    SurfaceTensionSettings& st = scene.surface_tension;
    LoadSettings(t, st);
    if (!t.Has("kappa_boundary")) st.kappa_boundary = st.kappa;
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = module_table("air_pressure");
    LoadSettings(t, scene.air_pressure);
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = module_table("freezing");
    FreezingSettings& f = scene.freezing;
    if (t.Has("pca"))
      t.Fail("pca", "freezing.pca was removed: the fluid PCA always weighs neighbours with the kernel over 2h; delete the line");
    LoadSettings(t, f);
    if (f.growth_sign == 0) t.Fail("growth_sign", "growth_sign must be +1 or -1");
    if (f.s_max < f.s_min) t.Fail("s_max", "s_max must be at least s_min");
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = top.Table("domain");
    Domain& d = scene.domain;
    LoadSettings(t, d);
    d.set = t.Has("min") || t.Has("max");
    if (d.set && (d.max.x <= d.min.x || d.max.y <= d.min.y || d.max.z <= d.min.z))
      t.Fail("max", "domain max must exceed min on every axis");
    t.RejectUnknownKeys();
  }
  std::size_t index = 0;
  for (TomlReader& t : top.TableArray("solid")) scene.solids.push_back(ParseSolid(t, index++));
  for (std::size_t a = 0; a < scene.solids.size(); ++a)
    for (std::size_t b = a + 1; b < scene.solids.size(); ++b)
      if (scene.solids[a].name == scene.solids[b].name)
        throw InputError(fmt::format("two solids are named '{}'", scene.solids[a].name), name + ": solid.name");
  for (TomlReader& t : top.TableArray("water_block")) scene.fluid_blocks.push_back(ParseBlock(t, scene.fluid.spacing));
  for (TomlReader& t : top.TableArray("emitter")) scene.emitters.push_back(ParseEmitter(t, scene.fluid.spacing, scene.info.end_time));
  {
    TomlReader t = top.Table("surface");
    ParseSurfaceSettings(t, scene.surface);
    t.RejectUnknownKeys();
  }
  {
    TomlReader t = top.Table("clean");
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
