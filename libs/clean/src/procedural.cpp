// Procedural test meshes (see rime/clean/procedural.h).
#include "rime/clean/procedural.h"

#include <cmath>
#include <numbers>
#include <random>
#include <unordered_map>

namespace rime::clean::procedural {
io::TriMesh Icosphere(double radius, int subdivisions, Vec3d center) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  std::vector<Vec3d> unit = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                             {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (Vec3d& p : unit) p /= Norm(p);
  std::vector<std::array<std::uint32_t, 3>> faces = {{0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                                                     {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                                                     {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::unordered_map<std::uint64_t, std::uint32_t> midpoint;
    auto middle = [&](std::uint32_t a, std::uint32_t b) {
      const std::uint64_t key = (std::uint64_t(std::min(a, b)) << 32) | std::max(a, b);
      const auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      Vec3d m = (unit[a] + unit[b]) * 0.5;
      unit.push_back(m / Norm(m));
      return midpoint[key] = std::uint32_t(unit.size() - 1);
    };
    std::vector<std::array<std::uint32_t, 3>> finer;
    finer.reserve(faces.size() * 4);
    for (const auto& f : faces) {
      const std::uint32_t ab = middle(f[0], f[1]), bc = middle(f[1], f[2]), ca = middle(f[2], f[0]);
      finer.push_back({f[0], ab, ca});
      finer.push_back({f[1], bc, ab});
      finer.push_back({f[2], ca, bc});
      finer.push_back({ab, bc, ca});
    }
    faces.swap(finer);
  }
  io::TriMesh mesh;
  for (const Vec3d& p : unit) mesh.positions.push_back(Vec3f(center + p * radius));
  mesh.triangles = std::move(faces);
  return mesh;
}

void AddRadialNoise(io::TriMesh& mesh, double amplitude, std::uint64_t seed, Vec3d center) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uniform(-amplitude, amplitude);
  for (Vec3f& p : mesh.positions) {
    const Vec3d d = Vec3d(p) - center;
    const double r = Norm(d);
    if (r > 0) p = Vec3f(center + d * ((r + uniform(rng)) / r));
  }
}

io::TriMesh SurfaceNets(const std::function<double(const Vec3d&)>& sdf, Vec3d min, Vec3d max, double cell) {
  const int nx = int(std::ceil((max.x - min.x) / cell)), ny = int(std::ceil((max.y - min.y) / cell)),
            nz = int(std::ceil((max.z - min.z) / cell));
  auto node = [&](int i, int j, int k) { return Vec3d(min.x + i * cell, min.y + j * cell, min.z + k * cell); };
  // Two node slices (k, k+1) and two cell layers (k-1, k): memory grows with the cross-section only.
  const std::size_t slice = std::size_t(nx + 1) * std::size_t(ny + 1);
  std::vector<double> values[2] = {std::vector<double>(slice), std::vector<double>(slice)};
  std::vector<std::int32_t> cells[2] = {std::vector<std::int32_t>(std::size_t(nx) * ny, -1),
                                        std::vector<std::int32_t>(std::size_t(nx) * ny, -1)};
  auto fill_slice = [&](std::vector<double>& v, int k) {
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) v[std::size_t(j) * (nx + 1) + i] = sdf(node(i, j, k));
  };
  io::TriMesh mesh;
  auto quad = [&](std::int32_t a, std::int32_t b, std::int32_t c, std::int32_t d, bool flip) {
    if (a < 0 || b < 0 || c < 0 || d < 0) return;
    if (flip) std::swap(b, d);
    mesh.triangles.push_back({std::uint32_t(a), std::uint32_t(b), std::uint32_t(c)});
    mesh.triangles.push_back({std::uint32_t(a), std::uint32_t(c), std::uint32_t(d)});
  };
  fill_slice(values[0], 0);
  for (int k = 0; k < nz; ++k) {
    std::vector<double>& lower = values[k & 1];
    std::vector<double>& upper = values[(k + 1) & 1];
    fill_slice(upper, k + 1);
    std::vector<std::int32_t>& layer = cells[k & 1];
    const std::vector<std::int32_t>& below = cells[(k + 1) & 1];
    auto value = [&](int i, int j, int dk) { return (dk ? upper : lower)[std::size_t(j) * (nx + 1) + i]; };
    // Cell vertices of layer k: mean of the crossings on the cell's 12 edges.
    static const int kEdges[12][2][3] = {{{0, 0, 0}, {1, 0, 0}}, {{0, 1, 0}, {1, 1, 0}}, {{0, 0, 1}, {1, 0, 1}}, {{0, 1, 1}, {1, 1, 1}},
                                         {{0, 0, 0}, {0, 1, 0}}, {{1, 0, 0}, {1, 1, 0}}, {{0, 0, 1}, {0, 1, 1}}, {{1, 0, 1}, {1, 1, 1}},
                                         {{0, 0, 0}, {0, 0, 1}}, {{1, 0, 0}, {1, 0, 1}}, {{0, 1, 0}, {0, 1, 1}}, {{1, 1, 0}, {1, 1, 1}}};
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        Vec3d sum(0, 0, 0);
        int crossings = 0;
        for (const auto& e : kEdges) {
          const double fa = value(i + e[0][0], j + e[0][1], e[0][2]), fb = value(i + e[1][0], j + e[1][1], e[1][2]);
          if ((fa < 0) == (fb < 0)) continue;
          const double s = fa / (fa - fb);
          const Vec3d a = node(i + e[0][0], j + e[0][1], k + e[0][2]), b = node(i + e[1][0], j + e[1][1], k + e[1][2]);
          sum += a + (b - a) * s;
          ++crossings;
        }
        std::int32_t& id = layer[std::size_t(j) * nx + i];
        id = -1;
        if (crossings > 0) {
          id = std::int32_t(mesh.positions.size());
          mesh.positions.push_back(Vec3f(sum / double(crossings)));
        }
      }
    auto cell_at = [&](const std::vector<std::int32_t>& l, int i, int j) -> std::int32_t {
      return i < 0 || j < 0 || i >= nx || j >= ny ? -1 : l[std::size_t(j) * nx + i];
    };
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        const bool inside = value(i, j, 0) < 0;
        // z-edge (i,j,k)-(i,j,k+1): cells (i-1..i, j-1..j) of layer k, counter-clockwise seen from +z.
        if (inside != (value(i, j, 1) < 0))
          quad(cell_at(layer, i - 1, j - 1), cell_at(layer, i, j - 1), cell_at(layer, i, j), cell_at(layer, i - 1, j), !inside);
        if (k == 0) continue;  // x/y edges of node slice k need cell layer k-1
        // x-edge (i,j,k)-(i+1,j,k): cells (i, j-1..j, k-1..k), counter-clockwise in (y, z).
        if (i < nx && inside != (value(i + 1, j, 0) < 0))
          quad(cell_at(below, i, j - 1), cell_at(below, i, j), cell_at(layer, i, j), cell_at(layer, i, j - 1), !inside);
        // y-edge (i,j,k)-(i,j+1,k): cells (i-1..i, j, k-1..k), counter-clockwise in (z, x).
        if (j < ny && inside != (value(i, j + 1, 0) < 0))
          quad(cell_at(below, i - 1, j), cell_at(layer, i - 1, j), cell_at(layer, i, j), cell_at(below, i, j), !inside);
      }
  }
  return mesh;
}

namespace {
/// Smooth bumps plus a finer ripple: the look of accreted ice, deterministic per seed.
double IceNoise(const Vec3d& p, std::uint64_t seed) {
  const double a = 0.37 * double(seed % 101), b = 0.53 * double(seed % 37);
  return 0.04 * std::sin(7 * p.x + a) * std::sin(6 * p.y + b) * std::sin(5 * p.z + a + b) +
         0.008 * std::sin(41 * p.x + 2 * b) * std::sin(37 * p.y + a) * std::sin(43 * p.z);
}
}  // namespace

io::TriMesh NoisyBall(std::size_t target_triangles, std::uint64_t seed) {
  const double radius = 0.5;
  // Surface nets give about 3 triangles per cell face of surface (1.5 crossed edges per h^2, 2 each).
  const double cell = std::sqrt(3 * 4 * std::numbers::pi * radius * radius / double(target_triangles));
  const double reach = radius * 1.1 + 2 * cell;
  return SurfaceNets([&](const Vec3d& p) { return Norm(p) - radius * (1 + IceNoise(p, seed)); }, Vec3d::Splat(-reach), Vec3d::Splat(reach),
                     cell);
}

io::TriMesh NoisyTorus(std::size_t target_triangles, std::uint64_t seed) {
  const double major = 0.35, minor = 0.12;
  const double cell = std::sqrt(3 * 4 * std::numbers::pi * std::numbers::pi * major * minor / double(target_triangles));
  const double reach_xy = major + minor * 1.2 + 2 * cell, reach_z = minor * 1.2 + 2 * cell;
  return SurfaceNets(
      [&](const Vec3d& p) {
        const double ring = std::sqrt(p.x * p.x + p.y * p.y) - major;
        return std::sqrt(ring * ring + p.z * p.z) - minor * (1 + 2 * IceNoise(p, seed));
      },
      Vec3d(-reach_xy, -reach_xy, -reach_z), Vec3d(reach_xy, reach_xy, reach_z), cell);
}

void Append(io::TriMesh& mesh, const io::TriMesh& other) {
  const std::uint32_t offset = std::uint32_t(mesh.positions.size());
  const bool velocities = !mesh.velocities.empty() && !other.velocities.empty();
  const bool normals = !mesh.normals.empty() && !other.normals.empty();
  mesh.positions.insert(mesh.positions.end(), other.positions.begin(), other.positions.end());
  if (velocities) mesh.velocities.insert(mesh.velocities.end(), other.velocities.begin(), other.velocities.end());
  else mesh.velocities.clear();
  if (normals) mesh.normals.insert(mesh.normals.end(), other.normals.begin(), other.normals.end());
  else mesh.normals.clear();
  for (const auto& t : other.triangles) mesh.triangles.push_back({t[0] + offset, t[1] + offset, t[2] + offset});
}

void PunchHole(io::TriMesh& mesh, Vec3d center, double radius) {
  std::erase_if(mesh.triangles, [&](const std::array<std::uint32_t, 3>& t) {
    const Vec3d c = (Vec3d(mesh.positions[t[0]]) + Vec3d(mesh.positions[t[1]]) + Vec3d(mesh.positions[t[2]])) / 3.0;
    return SquaredNorm(c - center) < radius * radius;
  });
}

}  // namespace rime::clean::procedural
