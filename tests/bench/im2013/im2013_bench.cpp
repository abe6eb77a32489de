// Rime against the Im et al. 2013 baseline it improves on. Two procedural scenes, each run twice
// with the same setup, once with `[scene] method = "rime"` (anisotropic growth, He 2014 surface
// tension, wall stickiness) and once with `method = "im2013"` (isotropic growth, Akinci 2013
// surface tension, no wall stickiness):
//   drop:  a sphere of water dropped onto a solid sphere standing above a ground plane;
//   throw: a block of water thrown sideways at the same sphere.
// Measures (definitions in RESULTS.md and below): ice count; specks (ice not connected to a solid
// through other ice); water lost to splashing; roughness of the ice on the sphere, of the particles
// and of the surface rime-surface reconstructs from them. Prints a table, writes results.json /
// results.csv, and top/side PNG views of the final particles and of the reconstructed ice.
//
// Usage: rime-bench-im2013 [--full] [--out DIR] [--scene drop|throw] [--frames] [--ablation]
//   --frames also writes each run's final particle frame (.h5part) and its ice mesh (.obj).
//   --ablation adds rime with one switch of the im2013 preset each: isotropic growth (rime+iso),
//   Akinci 2013 surface tension (rime+ak13), no wall stickiness (rime-wall).
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

#ifdef RIME_HAVE_ZLIB
#include <zlib.h>
#endif

#include "rime/test/scene_solids.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/exec/device.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/sph/simulation.h"
#include "rime/surface/frame_input.h"
#include "rime/surface/reconstruct.h"
#include "rime/test/measure.h"

namespace fs = std::filesystem;

namespace rime::compare {
namespace {

constexpr double kSphereRadius = 0.2;
constexpr std::size_t kBitSize = 3;
const Vec3d kSphereCenter{0, 0, 0.35};

// Both scenes share the ground, the sphere and the freezing thresholds (a block dropped on a sphere).
// One run: a method preset plus, for the ablation, single switches of the im2013 preset on top of "rime".
struct Variant {
  std::string label, method;
  std::string freezing, surface_tension, viscosity;  // extra TOML lines for those tables
};

const std::vector<Variant>& Variants(bool ablation) {
  static const std::vector<Variant> pair{{"rime", "rime", "", "", ""}, {"im2013", "im2013", "", "", ""}};
  static const std::vector<Variant> all{pair[0],
                                        pair[1],
                                        {"rime+iso", "rime", "growth = \"isotropic\"\n", "", ""},
                                        {"rime+ak13", "rime", "", "model = \"akinci2013\"\n", ""},
                                        {"rime-wall", "rime", "", "", "wall_beta0 = 0.0\n"}};
  return ablation ? all : pair;
}

std::string SceneText(const std::string& which, const Variant& v, bool full) {
  const double dp = full ? 0.0125 : 0.02;
  const double end = full ? 1.5 : 1.0;
  std::string water;
  if (which == "drop") {
    // A ball of water 12 cm in radius (about 900 particles at 2 cm), released 15 cm above the sphere's top.
    water = "[[water_block]]\nshape = \"sphere\"\ncenter = [0.0, 0.0, 0.82]\nradius = 0.12\n";
  } else {
    // A 16 cm cube of water (512 particles at 2 cm) thrown at 3 m/s towards the sphere's side, slightly upwards.
    water = "[[water_block]]\nshape = \"box\"\nmin = [-0.62, -0.08, 0.30]\nmax = [-0.46, 0.08, 0.46]\nvelocity = [3.0, 0.0, 0.5]\n";
  }
  return fmt::format(R"([scene]
name = "{0}"
end_time = {1}
method = "{2}"

[water]
spacing = {3}

[sim]
modules = ["gravity", "viscosity", "surface_tension", "freezing"]

[freezing]
glaze_threshold = 0.05
icicle_threshold = 0.01
{9}
[surface_tension]
{10}
[viscosity]
{11}
[domain]
min = [-0.8, -0.8, -0.05]
max = [0.8, 0.8, 1.0]

[[solid]]
name = "ground"
shape = "plane"
size = [1.6, 1.6, 1.0]

[[solid]]
name = "sphere"
shape = "sphere"
radius = {4}
translate = [{5}, {6}, {7}]

{8})",
                     which, end, v.method, dp, kSphereRadius, kSphereCenter.x, kSphereCenter.y, kSphereCenter.z, water, v.freezing,
                     v.surface_tension, v.viscosity);
}

// Uniform hash grid over points, for fixed-radius queries (radius <= cell).
class Grid {
 public:
  Grid(const std::vector<Vec3d>& p, double cell) : p_(p), cell_(cell) {
    for (std::size_t i = 0; i < p.size(); ++i) cells_[Key(Cell(p[i]))].push_back(int(i));
  }
  template <class F>
  void ForNear(const Vec3d& x, double r, F&& f) const {
    const auto c = Cell(x);
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const auto it = cells_.find(Key({c[0] + dx, c[1] + dy, c[2] + dz}));
          if (it == cells_.end()) continue;
          for (int j : it->second)
            if (SquaredNorm(p_[j] - x) <= r * r) f(j);
        }
  }
  bool AnyNear(const Vec3d& x, double r) const {
    bool any = false;
    ForNear(x, r, [&](int) { any = true; });
    return any;
  }

 private:
  std::array<std::int64_t, 3> Cell(const Vec3d& x) const {
    return {std::int64_t(std::floor(x.x / cell_)), std::int64_t(std::floor(x.y / cell_)), std::int64_t(std::floor(x.z / cell_))};
  }
  static std::int64_t Key(const std::array<std::int64_t, 3>& c) {
    return ((c[0] & 0x1FFFFF) << 42) | ((c[1] & 0x1FFFFF) << 21) | (c[2] & 0x1FFFFF);
  }
  const std::vector<Vec3d>& p_;
  double cell_;
  std::unordered_map<std::int64_t, std::vector<int>> cells_;
};

struct Result {
  std::string scene, method;
  bool ok = true;
  std::string error;
  double sim_time = 0, wall_s = 0;
  std::int64_t steps = 0, water_initial = 0;
  std::int64_t ice = 0, ice_components = 0, speck_components = 0, specks = 0;
  std::int64_t ice_on_sphere = 0;  // attached ice within 6 d_p of the sphere's surface (roughness input)
  // The same roughness measured on the mesh rime-surface reconstructs from the ice on the sphere
  // (default ice settings: ellipsoids with the stored anisotropy, voxel d_p / 2).
  double surface_roughness_mm = 0, surface_thickness_mm = 0;
  std::uint64_t surface_triangles = 0;
  io::TriMesh ice_mesh;
  std::int64_t ice_sphere_attached = 0, ice_ground_only = 0;  // by what the component touches
  std::int64_t bits = 0;  // ice in components of at most kBitSize particles, attached or not (scattered ice)
  std::int64_t fluid_end = 0, removed = 0, airborne = 0, off_object = 0;
  double roughness_mm = 0, mean_thickness_mm = 0;
  int covered_bins = 0, bins = 0;
  double max_average_density_error = 0;
  bool finite = true;
  std::vector<Vec3d> fluid, ice_attached, ice_specks, solid;
};

// Roughness of the ice on the sphere: directions from the sphere's centre are binned on a
// Fibonacci sphere with bins about 2 d_p apart on the surface; a bin's ice height is the largest
// distance beyond the sphere's radius of the ice particles in it (the outer ice surface). The
// roughness is the RMS difference between each covered bin's height and the mean height of its
// covered neighbour bins (within 1.6 bin spacings): a high-pass measure, 0 for a uniform coat,
// d_p-sized for ice standing up in isolated particles or spikes.
struct Roughness {
  double rms_mm = 0, mean_height_mm = 0;
  int covered_bins = 0, bins = 0;
  std::int64_t points = 0;  // points within 6 d_p of the sphere's surface
};

Roughness MeasureRoughness(const std::vector<Vec3d>& points, double dp) {
  Roughness out;
  const double bin_arc = 2 * dp / kSphereRadius;  // rad
  const int n = std::max(12, int(std::lround(4 * M_PI / (bin_arc * bin_arc))));
  std::vector<Vec3d> dir(n);
  const double golden = M_PI * (3 - std::sqrt(5.0));
  for (int k = 0; k < n; ++k) {
    const double z = 1 - 2 * (k + 0.5) / n, s = std::sqrt(1 - z * z);
    dir[k] = {s * std::cos(golden * k), s * std::sin(golden * k), z};
  }
  std::vector<double> height(n, -1);
  double thickness = 0;
  for (const Vec3d& p : points) {
    const Vec3d d = p - kSphereCenter;
    const double len = Norm(d);
    if (len > kSphereRadius + 6 * dp) continue;  // icicles hanging off and ice on the ground are not the coat
    int best = 0;
    double best_dot = -2;
    for (int k = 0; k < n; ++k)
      if (const double c = Dot(dir[k], d) / len; c > best_dot) best_dot = c, best = k;
    height[best] = std::max(height[best], len - kSphereRadius);
    ++out.points;
  }
  const double neighbor_cos = std::cos(1.6 * std::sqrt(4 * M_PI / n));
  double sum2 = 0;
  int counted = 0, covered = 0;
  for (int k = 0; k < n; ++k) {
    if (height[k] < 0) continue;
    ++covered, thickness += height[k];
    double mean = 0;
    int m = 0;
    for (int j = 0; j < n; ++j)
      if (j != k && height[j] >= 0 && Dot(dir[j], dir[k]) > neighbor_cos) mean += height[j], ++m;
    if (m == 0) continue;
    const double dev = height[k] - mean / m;
    sum2 += dev * dev, ++counted;
  }
  out.bins = n, out.covered_bins = covered;
  out.rms_mm = counted ? 1e3 * std::sqrt(sum2 / counted) : 0;
  out.mean_height_mm = covered ? 1e3 * thickness / covered : 0;
  return out;
}

// The ice of the components on the sphere, reconstructed as the surface stage does by default;
// the mesh's vertices go through the same roughness measure as the particles.
void MeasureSurfaceRoughness(const io::ParticleFrame& frame, const std::vector<char>& on_sphere, double dp, Result& r) {
  std::vector<std::string> warnings;
  const surface::ParticleSet all = surface::SelectPhase(frame, io::Phase::kIce, {}, warnings);
  if (all.size() != on_sphere.size()) throw Error(ExitCode::kFailure, "ice selection differs from the frame's ice");
  surface::ParticleSet coat;
  coat.spacing = all.spacing, coat.smoothing_length = all.smoothing_length, coat.particle_volume = all.particle_volume;
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (!on_sphere[i]) continue;
    coat.positions.push_back(all.positions[i]);
    if (!all.stored_anisotropy.empty()) coat.stored_anisotropy.push_back(all.stored_anisotropy[i]);
  }
  if (coat.size() == 0) return;
  surface::Result surf = surface::Reconstruct(coat, surface::Settings{});
  std::vector<Vec3d> vertices(surf.mesh.positions.begin(), surf.mesh.positions.end());
  const Roughness rough = MeasureRoughness(vertices, dp);
  r.surface_roughness_mm = rough.rms_mm, r.surface_thickness_mm = rough.mean_height_mm;
  r.surface_triangles = surf.mesh.triangle_count();
  r.ice_mesh = std::move(surf.mesh);
}

Result Run(const std::string& which, const Variant& v, bool full, const fs::path& out, bool frames) {
  Result r;
  r.scene = which, r.method = v.label;
  const io::Scene scene = io::ParseScene(SceneText(which, v, full), "compare_" + which + ".toml");
  const double dp = scene.fluid.spacing;
  sph::Simulation<float> sim(scene, exec::Device::Cpu());
  test::AddSceneSolids(sim, scene);
  sim.Initialize();
  r.water_initial = sim.fluid_count();
  const auto start = std::chrono::steady_clock::now();
  try {
    while (sim.time() < scene.info.end_time - 1e-9) {
      const sph::StepStats st = sim.Step(sim.NextTimeStep(scene.info.end_time));
      r.max_average_density_error = std::max(r.max_average_density_error, st.average_density_error);
    }
  } catch (const Error& e) {
    r.ok = false, r.error = e.what();
  }
  r.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  r.sim_time = sim.time(), r.steps = sim.step_count();
  r.ice = sim.ice_count(), r.removed = sim.removed_total(), r.fluid_end = sim.fluid_count();

  const io::ParticleFrame f = sim.Snapshot(1);
  if (frames) io::WriteParticleFrame(out / fmt::format("{}_{}.h5part", which, v.label), f);
  const auto x = f.GetPositions<double>();
  const auto& phase = f.Get<std::uint8_t>("phase");
  std::vector<Vec3d> ice, solid, sphere_solid;
  const auto& object = f.Get<std::uint32_t>("object_id");
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i].x) || !std::isfinite(x[i].y) || !std::isfinite(x[i].z)) r.finite = false;
    if (phase[i] == std::uint8_t(io::Phase::kFluid)) r.fluid.push_back(x[i]);
    if (phase[i] == std::uint8_t(io::Phase::kIce)) ice.push_back(x[i]);
    if (phase[i] == std::uint8_t(io::Phase::kBoundary)) {
      solid.push_back(x[i]);
      if (object[i] == 1) sphere_solid.push_back(x[i]);
    }
  }
  if (std::int64_t(ice.size()) != r.ice) r.ok = false, r.error += fmt::format(" frame has {} ice, ice_count() {}", ice.size(), r.ice);
  r.solid = solid;

  // Specks: connected components of ice with links up to 1.5 d_p; a component is attached when
  // one of its particles lies within 1.5 d_p of a solid boundary particle (water freezes at
  // 0.5-1.1 d_p from the wall particles, so attached ice always has one that close).
  const double link = 1.5 * dp;
  const Grid ice_grid(ice, link), solid_grid(solid, link), sphere_solid_grid(sphere_solid, link);
  std::vector<int> comp(ice.size(), -1);
  std::vector<char> ice_on_sphere_component(ice.size(), 0);
  std::vector<int> stack;
  for (std::size_t s = 0; s < ice.size(); ++s) {
    if (comp[s] >= 0) continue;
    const int c = int(r.ice_components++);
    std::vector<int> members;
    bool attached = false, on_sphere = false;
    comp[s] = c, stack.push_back(int(s));
    while (!stack.empty()) {
      const int i = stack.back();
      stack.pop_back();
      members.push_back(i);
      attached = attached || solid_grid.AnyNear(ice[i], link);
      on_sphere = on_sphere || sphere_solid_grid.AnyNear(ice[i], link);
      ice_grid.ForNear(ice[i], link, [&](int j) {
        if (comp[j] < 0) comp[j] = c, stack.push_back(j);
      });
    }
    auto& dest = attached ? r.ice_attached : r.ice_specks;
    for (int i : members) dest.push_back(ice[i]);
    if (!attached) ++r.speck_components, r.specks += std::int64_t(members.size());
    if (members.size() <= kBitSize) r.bits += std::int64_t(members.size());
    if (on_sphere) {
      r.ice_sphere_attached += std::int64_t(members.size());
      for (int i : members) ice_on_sphere_component[i] = 1;
    } else if (attached) r.ice_ground_only += std::int64_t(members.size());
  }

  // Water lost to splashing: removed by the domain, or at the end farther than 3 d_p from every
  // solid and ice particle (in the air). Off the object: farther than 3 d_p from the sphere and
  // its ice (on the ground or in the air): water that did not stay on the object.
  std::vector<Vec3d> near_all = solid;
  near_all.insert(near_all.end(), ice.begin(), ice.end());
  std::vector<Vec3d> near_sphere = sphere_solid;
  for (const Vec3d& p : ice)
    if (Norm(p - kSphereCenter) < kSphereRadius + 6 * dp) near_sphere.push_back(p);
  const double far = 3 * dp;
  const Grid all_grid(near_all, far), sphere_grid(near_sphere, far);
  for (const Vec3d& p : r.fluid) {
    if (!all_grid.AnyNear(p, far)) ++r.airborne;
    if (!sphere_grid.AnyNear(p, far)) ++r.off_object;
  }
  const Roughness rough = MeasureRoughness(r.ice_attached, dp);
  r.roughness_mm = rough.rms_mm, r.mean_thickness_mm = rough.mean_height_mm;
  r.covered_bins = rough.covered_bins, r.bins = rough.bins, r.ice_on_sphere = rough.points;
  if (r.finite) {
    try {
      MeasureSurfaceRoughness(f, ice_on_sphere_component, dp, r);
    } catch (const Error& e) {  // a failed reconstruction fails this run, not the comparison
      r.ok = false, r.error += std::string(" reconstruction: ") + e.what();
    }
  }
  return r;
}

// ---- Pictures: orthographic point views written as PNG (deflated with zlib when it was found).

std::uint32_t Crc32(const std::uint8_t* data, std::size_t n, std::uint32_t crc = 0) {
  static std::array<std::uint32_t, 256> table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = c & 1 ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  crc = ~crc;
  for (std::size_t i = 0; i < n; ++i) crc = table[(crc ^ data[i]) & 0xFF] ^ (crc >> 8);
  return ~crc;
}

void WritePng(const fs::path& path, int w, int h, const std::vector<std::uint8_t>& rgb) {
  std::vector<std::uint8_t> raw;  // filter byte 0 per row
  for (int y = 0; y < h; ++y) {
    raw.push_back(0);
    raw.insert(raw.end(), rgb.begin() + std::ptrdiff_t(y) * w * 3, rgb.begin() + std::ptrdiff_t(y + 1) * w * 3);
  }
#ifdef RIME_HAVE_ZLIB
  uLongf size = compressBound(uLong(raw.size()));
  std::vector<std::uint8_t> z(size);
  compress2(z.data(), &size, raw.data(), uLong(raw.size()), 9);
  z.resize(size);
#else
  // Without zlib: stored (uncompressed) deflate blocks, about 1.4 MB a picture.
  std::vector<std::uint8_t> z{0x78, 0x01};
  std::uint32_t a = 1, b = 0;
  for (std::uint8_t v : raw) a = (a + v) % 65521, b = (b + a) % 65521;
  for (std::size_t pos = 0; pos < raw.size() || pos == 0;) {
    const std::size_t len = std::min<std::size_t>(65535, raw.size() - pos);
    const bool last = pos + len == raw.size();
    z.push_back(last ? 1 : 0);
    z.push_back(len & 0xFF), z.push_back(len >> 8), z.push_back(~len & 0xFF), z.push_back((~len >> 8) & 0xFF);
    z.insert(z.end(), raw.begin() + std::ptrdiff_t(pos), raw.begin() + std::ptrdiff_t(pos + len));
    pos += len;
    if (last) break;
  }
  const std::uint32_t adler = (b << 16) | a;
  for (int s = 24; s >= 0; s -= 8) z.push_back((adler >> s) & 0xFF);
#endif
  std::ofstream o(path, std::ios::binary);
  auto be32 = [&](std::uint32_t v) {
    for (int s = 24; s >= 0; s -= 8) o.put(char((v >> s) & 0xFF));
  };
  auto chunk = [&](const char* type, const std::vector<std::uint8_t>& data) {
    be32(std::uint32_t(data.size()));
    std::vector<std::uint8_t> td(type, type + 4);
    td.insert(td.end(), data.begin(), data.end());
    o.write(reinterpret_cast<const char*>(td.data()), std::streamsize(td.size()));
    be32(Crc32(td.data(), td.size()));
  };
  o.write("\x89PNG\r\n\x1a\n", 8);
  std::vector<std::uint8_t> ihdr;
  for (int v : {w, h})
    for (int s = 24; s >= 0; s -= 8) ihdr.push_back((v >> s) & 0xFF);
  ihdr.insert(ihdr.end(), {8, 2, 0, 0, 0});
  chunk("IHDR", ihdr);
  chunk("IDAT", z);
  chunk("IEND", {});
}

// Both pictures: two square panels (top view left, side view right) with a black gap between.
constexpr int kPanel = 480, kGap = 10, kH = kPanel, kW = 2 * kPanel + kGap;

std::vector<std::uint8_t> BlankPanels() { return std::vector<std::uint8_t>(std::size_t(kW) * kH * 3, 255); }

void WritePanels(const fs::path& path, std::vector<std::uint8_t>& img) {
  for (int y = 0; y < kH; ++y)
    for (int x = kPanel; x < kPanel + kGap; ++x) std::memset(&img[(std::size_t(y) * kW + x) * 3], 0, 3);
  WritePng(path, kW, kH, img);
}

// Top view (x right, y up) and side view (x right, z up) side by side, 1.6 m x 1.6 m each.
// Grey: solids; light blue: water; dark blue: ice attached to a solid; red: specks.
void Picture(const Result& r, const fs::path& path) {
  std::vector<std::uint8_t> img = BlankPanels();
  const double scale = kPanel / 1.6;
  auto put = [&](double u, double v, int ox, std::array<std::uint8_t, 3> c, int rad) {  // u, v in [-0.8, 0.8] m
    const int px = ox + int((u + 0.8) * scale), py = kH - 1 - int((v + 0.8) * scale);
    for (int dy = -rad; dy <= rad; ++dy)
      for (int dx = -rad; dx <= rad; ++dx) {
        const int X = px + dx, Y = py + dy;
        if (X < ox || X >= ox + kPanel || Y < 0 || Y >= kH || dx * dx + dy * dy > rad * rad + 1) continue;
        std::memcpy(&img[(std::size_t(Y) * kW + X) * 3], c.data(), 3);
      }
  };
  auto layer = [&](const std::vector<Vec3d>& p, std::array<std::uint8_t, 3> c, int rad, bool side) {
    for (const Vec3d& q : p) {
      if (side && std::fabs(q.y) > 0.1) continue;                          // side view: a 20 cm slab through the sphere's centre
      if (!side && q.z < 0.01 && c[0] == 200) continue;                    // top view: leave the ground out
      put(q.x, side ? q.z - 0.7 : q.y, side ? kPanel + kGap : 0, c, rad);  // side: z from -0.1 m up
    }
  };
  for (bool side : {false, true}) {
    layer(r.solid, {200, 200, 200}, 0, side);
    layer(r.fluid, {150, 200, 255}, 1, side);
    layer(r.ice_attached, {20, 40, 160}, 2, side);
    layer(r.ice_specks, {220, 20, 20}, 2, side);
  }
  WritePanels(path, img);
}

// The reconstructed ice on the sphere, shaded, in two views 0.8 m wide around the sphere (top:
// looking down −z; side: looking along +y, z from 0 to 0.8 m), over the sphere (ray-cast) and
// the ground. Orthographic, z-buffered.
void SurfacePicture(const Result& r, const fs::path& path) {
  constexpr double kHalf = 0.4, kSideZ0 = 0.4;  // m: half width; the side view's centre height
  std::vector<std::uint8_t> img = BlankPanels();
  const double scale = kPanel / (2 * kHalf);
  const Vec3d light = Vec3d(-0.4, -0.5, 0.77) / Norm(Vec3d(-0.4, -0.5, 0.77));
  for (int view = 0; view < 2; ++view) {
    const int ox = view ? kPanel + kGap : 0;
    const Vec3d toward_viewer = view ? Vec3d(0, -1, 0) : Vec3d(0, 0, 1);
    // Panel coordinates: u = x; v = y (top) or z − kSideZ0 (side); depth towards the viewer.
    const auto project = [&](const Vec3d& p, double& px, double& py, double& depth) {
      px = (p.x + kHalf) * scale, py = kH - 1 - ((view ? p.z - kSideZ0 : p.y) + kHalf) * scale, depth = view ? -p.y : p.z;
    };
    std::vector<double> zbuf(std::size_t(kPanel) * kH, -1e30);
    const auto shade = [&](int X, int Y, double depth, const Vec3d& n, std::array<double, 3> base) {
      double& z = zbuf[std::size_t(Y) * kPanel + X];
      if (depth <= z) return;
      z = depth;
      const double lit = 0.25 + 0.75 * std::max(0.0, Dot(n, light));
      for (int c = 0; c < 3; ++c) img[(std::size_t(Y) * kW + ox + X) * 3 + c] = std::uint8_t(std::min(255.0, base[c] * lit));
    };
    for (int Y = 0; Y < kH; ++Y)
      for (int X = 0; X < kPanel; ++X) {
        const double u = X / scale - kHalf, v = (kH - 1 - Y) / scale - kHalf;
        const double a = u - kSphereCenter.x, b = view ? v + kSideZ0 - kSphereCenter.z : v - kSphereCenter.y;
        const double rest = kSphereRadius * kSphereRadius - a * a - b * b;
        if (rest >= 0) {  // the sphere, seen from the viewer's side
          const double c = std::sqrt(rest);
          const Vec3d n = view ? Vec3d(a, -c, b) / kSphereRadius : Vec3d(a, b, c) / kSphereRadius;
          shade(X, Y, view ? c - kSphereCenter.y : kSphereCenter.z + c, n, {200, 200, 200});
        } else if (view && v + kSideZ0 < 0) {
          shade(X, Y, -1e29, {0, -1, 0}, {235, 235, 235});  // below the ground
        }
      }
    for (const auto& t : r.ice_mesh.triangles) {
      const Vec3d p0(r.ice_mesh.positions[t[0]]), p1(r.ice_mesh.positions[t[1]]), p2(r.ice_mesh.positions[t[2]]);
      Vec3d n = Cross(p1 - p0, p2 - p0);
      if (Norm(n) == 0) continue;
      n = n / Norm(n);
      if (Dot(n, toward_viewer) < 0) n = -n;  // light the side that faces the viewer
      double x[3], y[3], d[3];
      project(p0, x[0], y[0], d[0]), project(p1, x[1], y[1], d[1]), project(p2, x[2], y[2], d[2]);
      const int x0 = std::max(0, int(std::floor(std::min({x[0], x[1], x[2]})))),
                x1 = std::min(kPanel - 1, int(std::ceil(std::max({x[0], x[1], x[2]}))));
      const int y0 = std::max(0, int(std::floor(std::min({y[0], y[1], y[2]})))),
                y1 = std::min(kH - 1, int(std::ceil(std::max({y[0], y[1], y[2]}))));
      const double area = (x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]);
      if (std::fabs(area) < 1e-12) continue;
      for (int Y = y0; Y <= y1; ++Y)
        for (int X = x0; X <= x1; ++X) {
          const double px = X + 0.5, py = Y + 0.5;
          const double w0 = ((x[1] - px) * (y[2] - py) - (x[2] - px) * (y[1] - py)) / area;
          const double w1 = ((x[2] - px) * (y[0] - py) - (x[0] - px) * (y[2] - py)) / area;
          const double w2 = 1 - w0 - w1;
          if (w0 < 0 || w1 < 0 || w2 < 0) continue;
          shade(X, Y, w0 * d[0] + w1 * d[1] + w2 * d[2], n, {120, 190, 255});
        }
    }
  }
  WritePanels(path, img);
}

// One result's measures in the JSON's order, each written once for both files: CSV columns are
// the ones not marked json_only, in the same order; text values are quoted in the JSON.
struct Field {
  const char* name;
  std::string value;
  bool json_only = false, text = false;
};

std::vector<Field> Fields(const Result& r) {
  const auto n = [](auto v) { return fmt::format("{}", v); };
  return {{"scene", r.scene, false, true},
          {"method", r.method, false, true},
          {"ok", n(r.ok)},
          {"error", r.error, true, true},
          {"simulated_s", fmt::format("{:.4f}", r.sim_time), true},
          {"water_initial", n(r.water_initial)},
          {"ice", n(r.ice)},
          {"ice_components", n(r.ice_components)},
          {"speck_components", n(r.speck_components)},
          {"specks", n(r.specks)},
          {"ice_sphere_attached", n(r.ice_sphere_attached)},
          {"ice_ground_only", n(r.ice_ground_only)},
          {"bits", n(r.bits)},
          {"removed", n(r.removed)},
          {"airborne", n(r.airborne)},
          {"off_object", n(r.off_object)},
          {"fluid_end", n(r.fluid_end)},
          {"ice_on_sphere", n(r.ice_on_sphere)},
          {"covered_bins", n(r.covered_bins)},
          {"bins", n(r.bins)},
          {"roughness_mm", fmt::format("{:.3f}", r.roughness_mm)},
          {"mean_thickness_mm", fmt::format("{:.3f}", r.mean_thickness_mm)},
          {"surface_roughness_mm", fmt::format("{:.3f}", r.surface_roughness_mm)},
          {"surface_thickness_mm", fmt::format("{:.3f}", r.surface_thickness_mm)},
          {"surface_triangles", n(r.surface_triangles)},
          {"max_average_density_error", fmt::format("{:.5f}", r.max_average_density_error)},
          {"finite", n(r.finite), true},
          {"steps", n(r.steps)},
          {"wall_s", fmt::format("{:.1f}", r.wall_s)}};
}

}  // namespace
}  // namespace rime::compare

int main(int argc, char** argv) {
  using namespace rime::compare;
  bool full = false, frames = false, ablation = false;
  fs::path out = RIME_BENCH_OUTPUT_DIR;
  std::vector<std::string> scenes{"drop", "throw"};
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--full")) full = true;
    else if (!std::strcmp(argv[i], "--frames")) frames = true;
    else if (!std::strcmp(argv[i], "--ablation")) ablation = true;
    else if (!std::strcmp(argv[i], "--out") && i + 1 < argc) out = argv[++i];
    else if (!std::strcmp(argv[i], "--scene") && i + 1 < argc) scenes = {argv[++i]};
    else {
      std::printf("usage: rime-bench-im2013 [--full] [--out DIR] [--scene drop|throw] [--frames] [--ablation]\n");
      return std::strcmp(argv[i], "--help") ? 2 : 0;
    }
  }
  rime::log::SetLevel(rime::log::Level::kWarning);
  fs::create_directories(out);
  const std::string run_info = fmt::format("{} variant; {} hardware threads; load average at start {}", full ? "full" : "fast",
                                           std::thread::hardware_concurrency(), rime::test::LoadAverages());
  std::printf("Rime vs Im et al. 2013 baseline (%s)\n", run_info.c_str());
  std::vector<Result> results;
  for (const std::string& s : scenes)
    for (const Variant& v : Variants(ablation)) {
      results.push_back(Run(s, v, full, out, frames));
      Picture(results.back(), out / fmt::format("{}_{}.png", s, v.label));
      if (!results.back().ice_mesh.empty()) {
        SurfacePicture(results.back(), out / fmt::format("{}_{}_surface.png", s, v.label));
        if (frames) rime::io::WriteMesh(out / fmt::format("{}_{}_ice.obj", s, v.label), results.back().ice_mesh);
      }
      std::printf("  %s/%s done in %.0f s\n", s.c_str(), v.label.c_str(), results.back().wall_s);
      std::fflush(stdout);
    }
  std::printf("\n%-6s %-9s %6s %6s %7s %7s %7s %7s %7s %7s %7s %7s %7s %7s %7s %7s %6s\n", "scene", "method", "water", "ice", "on",
              "ground", "bits", "specks", "speck", "removed", "airborn", "off-obj", "rough", "thick", "s-rough", "s-thick", "wall");
  std::printf("%-6s %-9s %6s %6s %7s %7s %7s %7s %7s %7s %7s %7s %7s %7s %7s %7s %6s\n", "", "", "start", "", "sphere", "only", "<=3",
              "(ptcl)", "groups", "", "", "", "mm", "mm", "mm", "mm", "s");
  std::ofstream csv(out / "results.csv");
  std::string header;
  for (const Field& f : Fields(Result{}))
    if (!f.json_only) header += (header.empty() ? "" : ",") + std::string(f.name);
  csv << header << "\n";
  std::string json = fmt::format("{{\n  \"run\": \"{}\",\n  \"machine\": \"{}\",\n  \"commit\": \"{}\",\n  \"results\": [\n", run_info,
                                 rime::test::MachineDescription(), rime::test::SourceCommit(RIME_SOURCE_DIR));
  for (std::size_t k = 0; k < results.size(); ++k) {
    const Result& r = results[k];
    std::printf("%-6s %-9s %6lld %6lld %7lld %7lld %7lld %7lld %7lld %7lld %7lld %7lld %7.1f %7.1f %7.1f %7.1f %6.0f%s\n", r.scene.c_str(),
                r.method.c_str(), (long long)r.water_initial, (long long)r.ice, (long long)r.ice_sphere_attached,
                (long long)r.ice_ground_only, (long long)r.bits, (long long)r.specks, (long long)r.speck_components, (long long)r.removed,
                (long long)r.airborne, (long long)r.off_object, r.roughness_mm, r.mean_thickness_mm, r.surface_roughness_mm,
                r.surface_thickness_mm, r.wall_s, r.ok ? "" : "  FAILED");
    std::string row, object;
    for (const Field& f : Fields(r)) {
      if (!f.json_only) row += (row.empty() ? "" : ",") + f.value;
      object += fmt::format("{}\"{}\": ", object.empty() ? "" : ", ", f.name) + (f.text ? "\"" + f.value + "\"" : f.value);
    }
    csv << row << "\n";
    json += "    {" + object + "}" + (k + 1 < results.size() ? "," : "") + "\n";
  }
  json += "  ]\n}\n";
  std::ofstream(out / "results.json") << json;
  bool ok = true;
  for (const Result& r : results) ok = ok && r.ok && r.finite && r.ice + r.fluid_end + r.removed == r.water_initial;
  std::printf("\nload average at end %s; %s\n", rime::test::LoadAverages().c_str(),
              ok ? "every run finished, finite, water + ice + removed = initial water" : "SOME RUN FAILED (see above)");
  return ok ? 0 : 1;
}
