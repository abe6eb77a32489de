// Shared checks for the boundary tests: random surface points and nearest-particle distances.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "rime/exec/parallel.h"
#include "rime/io/mesh.h"
#include "rime/neighbors/grid.h"

namespace rime::boundary::test_support {

/// Uniformly distributed points on the mesh surface (area-weighted triangle choice).
inline std::vector<Vec3f> RandomSurfacePoints(const io::TriMesh& mesh, std::size_t count, unsigned seed = 7) {
  std::vector<double> cumulative;
  double total = 0;
  for (const auto& t : mesh.triangles) {
    const Vec3d a(mesh.positions[t[0]]), b(mesh.positions[t[1]]), c(mesh.positions[t[2]]);
    total += 0.5 * Norm(Cross(b - a, c - a));
    cumulative.push_back(total);
  }
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<Vec3f> points;
  for (std::size_t k = 0; k < count; ++k) {
    const std::size_t t = std::min<std::size_t>(std::lower_bound(cumulative.begin(), cumulative.end(), u(rng) * total) - cumulative.begin(),
                                                mesh.triangles.size() - 1);
    double r1 = u(rng), r2 = u(rng);
    if (r1 + r2 > 1) r1 = 1 - r1, r2 = 1 - r2;
    const auto& tri = mesh.triangles[t];
    const Vec3d a(mesh.positions[tri[0]]), b(mesh.positions[tri[1]]), c(mesh.positions[tri[2]]);
    points.push_back(Vec3f(a + (b - a) * r1 + (c - a) * r2));
  }
  return points;
}

/// For every query, the distance to the nearest particle (inf when none within `radius`).
inline std::vector<float> DistanceToNearestParticle(const std::vector<Vec3f>& particles, const std::vector<Vec3f>& queries, float radius) {
  const exec::Device cpu = exec::Device::Cpu();
  neighbors::UniformGrid<float> grid(cpu);
  grid.Build(particles.data(), Index(particles.size()), radius);
  const auto view = grid.view();
  std::vector<float> out(queries.size());
  for (std::size_t i = 0; i < queries.size(); ++i) {
    float best = std::numeric_limits<float>::infinity();
    view.ForEachNeighbor(queries[i], radius, [&](std::uint32_t, const Vec3f&, float r2) { best = std::min(best, r2); });
    out[i] = std::sqrt(best);
  }
  return out;
}

/// The 12-triangle cube [0,1]^3 with shared vertices, counter-clockwise seen from outside.
inline io::TriMesh UnitCube() {
  io::TriMesh m;
  for (int i = 0; i < 8; ++i) m.positions.push_back(Vec3f(float(i & 1), float((i >> 1) & 1), float((i >> 2) & 1)));
  const std::uint32_t quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m.triangles.push_back({q[0], q[1], q[2]});
    m.triangles.push_back({q[0], q[2], q[3]});
  }
  return m;
}

}  // namespace rime::boundary::test_support
