// Velocity transfer from the input surface (see TransferVelocities in rime/meshfix/clean.h).
// A separate translation unit from the cleanup chain so the two CGAL-heavy files compile in parallel.
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/AABB_triangle_primitive.h>
#include <CGAL/Simple_cartesian.h>

#include <algorithm>

#include "rime/exec/parallel.h"
#include "rime/meshfix/clean.h"

namespace rime::meshfix {
namespace {

// Closest-point queries need no exact predicates: plain double arithmetic is faster.
using Kernel = CGAL::Simple_cartesian<double>;
using Point = Kernel::Point_3;
using Triangle = Kernel::Triangle_3;
using TriangleIterator = std::vector<Triangle>::const_iterator;
using Primitive = CGAL::AABB_triangle_primitive<Kernel, TriangleIterator>;
using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;

/// Barycentric coordinates of p (already on the triangle's plane, or its projection) in abc,
/// clamped to the triangle.
std::array<double, 3> Barycentric(const Point& p, const Triangle& t) {
  const Kernel::Vector_3 v0 = t[1] - t[0], v1 = t[2] - t[0], v2 = p - t[0];
  const double d00 = v0 * v0, d01 = v0 * v1, d11 = v1 * v1, d20 = v2 * v0, d21 = v2 * v1;
  const double denominator = d00 * d11 - d01 * d01;
  if (!(denominator > 0)) return {1.0 / 3, 1.0 / 3, 1.0 / 3};  // degenerate triangle: average
  double v = (d11 * d20 - d01 * d21) / denominator, w = (d00 * d21 - d01 * d20) / denominator;
  v = std::clamp(v, 0.0, 1.0), w = std::clamp(w, 0.0, 1.0 - v);
  return {1 - v - w, v, w};
}

}  // namespace

std::vector<Vec3f> TransferVelocities(const io::TriMesh& source, const std::vector<Vec3f>& targets) {
  std::vector<Vec3f> out(targets.size(), Vec3f(0, 0, 0));
  if (source.triangles.empty() || source.velocities.size() != source.positions.size()) return out;
  std::vector<Triangle> triangles;
  triangles.reserve(source.triangles.size());
  auto point = [&](std::uint32_t v) { return Point(source.positions[v].x, source.positions[v].y, source.positions[v].z); };
  for (const auto& t : source.triangles) triangles.emplace_back(point(t[0]), point(t[1]), point(t[2]));
  Tree tree(triangles.cbegin(), triangles.cend());
  tree.build();
  // A k-d tree of hints gives each query a close first guess: the input vertices (about half as
  // many as the triangles' reference points CGAL would use by default), each with a triangle of its own.
  std::vector<std::uint32_t> face_of_vertex(source.positions.size(), UINT32_MAX);
  for (std::uint32_t f = 0; f < source.triangles.size(); ++f)
    for (std::uint32_t v : source.triangles[f]) face_of_vertex[v] = f;
  std::vector<Tree::Point_and_primitive_id> hints;
  hints.reserve(source.positions.size());
  for (std::uint32_t v = 0; v < source.positions.size(); ++v)
    if (face_of_vertex[v] != UINT32_MAX) hints.emplace_back(point(v), triangles.cbegin() + face_of_vertex[v]);
  tree.accelerate_distance_queries(hints.begin(), hints.end());

  exec::cpu::ParallelFor(Index(targets.size()), [&](Index i) {
    const Point query(targets[i].x, targets[i].y, targets[i].z);
    const auto [closest, primitive] = tree.closest_point_and_primitive(query);
    const std::size_t f = std::size_t(primitive - triangles.cbegin());
    const auto weights = Barycentric(closest, triangles[f]);
    Vec3d v(0, 0, 0);
    for (int k = 0; k < 3; ++k) v += Vec3d(source.velocities[source.triangles[f][k]]) * weights[k];
    out[i] = Vec3f(v);
  });
  return out;
}

}  // namespace rime::meshfix
