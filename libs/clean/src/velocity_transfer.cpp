// Velocity transfer from the input surface (see TransferVelocities in rime/clean/clean.h).
// Closest points through a bounding-box tree over the input triangles (median splits, nodes in
// depth-first order in one array, 4 triangles per leaf).
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "rime/exec/parallel.h"
#include "rime/clean/clean.h"

namespace rime::clean {
namespace {

struct Box {
  Vec3f lo{std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity()};
  Vec3f hi{-std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()};
  void Add(const Vec3f& p) { lo = Min(lo, p), hi = Max(hi, p); }
  void Add(const Box& b) { lo = Min(lo, b.lo), hi = Max(hi, b.hi); }
  /// Squared distance from q; infinite for an empty box.
  double Distance2(const Vec3d& q) const {
    if (lo.x > hi.x) return std::numeric_limits<double>::infinity();
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double below = double(lo[k]) - q[k], above = q[k] - double(hi[k]);
      const double d = std::max({below, above, 0.0});
      d2 += d * d;
    }
    return d2;
  }
};

/// Barycentric weights of the point of triangle abc closest to p (Voronoi regions of the corners,
/// edges and face; Ericson, Real-Time Collision Detection, 5.1.5).
std::array<double, 3> ClosestWeights(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  const Vec3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = Dot(ab, ap), d2 = Dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Vec3d bp = p - b;
  const double d3 = Dot(ab, bp), d4 = Dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return {1 - v, v, 0};
  }
  const Vec3d cp = p - c;
  const double d5 = Dot(ab, cp), d6 = Dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return {1 - w, 0, w};
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return {0, 1 - w, w};
  }
  const double sum = va + vb + vc;
  if (!(sum > 0)) return {1.0 / 3, 1.0 / 3, 1.0 / 3};  // zero-area triangle: its points coincide
  const double v = vb / sum, w = vc / sum;
  return {1 - v - w, v, w};
}

class TriangleTree {
 public:
  explicit TriangleTree(const io::TriMesh& mesh) : mesh_(mesh) {
    const std::size_t n = mesh.triangles.size();
    centroid_.resize(n);
    for (std::size_t f = 0; f < n; ++f) {
      const auto& t = mesh.triangles[f];
      centroid_[f] = (mesh.positions[t[0]] + mesh.positions[t[1]] + mesh.positions[t[2]]) / 3.0f;
    }
    order_.resize(n);
    for (std::size_t f = 0; f < n; ++f) order_[f] = std::uint32_t(f);
    nodes_.reserve(2 * (n / kLeaf + 1));
    Build(0, n);
    centroid_ = {};
  }

  struct Hit {
    std::uint32_t face = 0;
    std::array<double, 3> weights{1, 0, 0};
  };

  Hit Closest(const Vec3d& q) const {
    Hit hit;
    double best = std::numeric_limits<double>::infinity();
    struct Entry {
      std::uint32_t node;
      double d2;
    };
    Entry stack[128];
    int size = 0;
    stack[size++] = {0, nodes_[0].box.Distance2(q)};
    while (size > 0) {
      const Entry e = stack[--size];
      if (e.d2 >= best) continue;
      const Node& node = nodes_[e.node];
      if (node.count > 0) {
        for (std::uint32_t i = node.begin; i < node.begin + node.count; ++i) {
          const auto& t = mesh_.triangles[order_[i]];
          const Vec3d a(mesh_.positions[t[0]]), b(mesh_.positions[t[1]]), c(mesh_.positions[t[2]]);
          const auto w = ClosestWeights(q, a, b, c);
          const double d2 = SquaredNorm(a * w[0] + b * w[1] + c * w[2] - q);
          if (d2 < best) best = d2, hit = {order_[i], w};
        }
        continue;
      }
      const Entry left{e.node + 1, nodes_[e.node + 1].box.Distance2(q)}, right{node.right, nodes_[node.right].box.Distance2(q)};
      // The nearer child goes on top, so it is searched first and prunes the other.
      const bool left_first = left.d2 <= right.d2;
      const Entry& far = left_first ? right : left;
      const Entry& near = left_first ? left : right;
      if (far.d2 < best) stack[size++] = far;
      if (near.d2 < best) stack[size++] = near;
    }
    return hit;
  }

 private:
  struct Node {
    Box box;
    std::uint32_t right = 0;             // inner node: right child (the left one is the next node)
    std::uint32_t begin = 0, count = 0;  // leaf: triangles order_[begin, begin + count)
  };

  /// Median split of the centroids along their longest axis (depth about log2(n / kLeaf)).
  std::uint32_t Build(std::size_t begin, std::size_t end) {
    const std::uint32_t index = std::uint32_t(nodes_.size());
    nodes_.emplace_back();
    if (end - begin <= kLeaf) {
      Node& leaf = nodes_[index];
      leaf.begin = std::uint32_t(begin), leaf.count = std::uint32_t(end - begin);
      for (std::size_t i = begin; i < end; ++i)
        for (std::uint32_t v : mesh_.triangles[order_[i]]) leaf.box.Add(mesh_.positions[v]);
      return index;
    }
    Box centroids;
    for (std::size_t i = begin; i < end; ++i) centroids.Add(centroid_[order_[i]]);
    const Vec3f extent = centroids.hi - centroids.lo;
    const int axis = extent.x >= extent.y && extent.x >= extent.z ? 0 : (extent.y >= extent.z ? 1 : 2);
    const std::size_t mid = begin + (end - begin) / 2;
    std::nth_element(order_.begin() + std::ptrdiff_t(begin), order_.begin() + std::ptrdiff_t(mid), order_.begin() + std::ptrdiff_t(end),
                     [&](std::uint32_t a, std::uint32_t b) { return centroid_[a][axis] < centroid_[b][axis]; });
    Build(begin, mid);
    const std::uint32_t right = Build(mid, end);
    Node& node = nodes_[index];
    node.right = right;
    node.box = nodes_[index + 1].box;
    node.box.Add(nodes_[right].box);
    return index;
  }

  static constexpr std::size_t kLeaf = 4;
  const io::TriMesh& mesh_;
  std::vector<Vec3f> centroid_;       // during the build only
  std::vector<std::uint32_t> order_;  // triangles, grouped by leaf
  std::vector<Node> nodes_;           // depth-first order, root 0
};

}  // namespace

std::vector<Vec3f> TransferVelocities(const io::TriMesh& source, const std::vector<Vec3f>& targets) {
  std::vector<Vec3f> out(targets.size(), Vec3f(0, 0, 0));
  if (source.triangles.empty() || source.velocities.size() != source.positions.size()) return out;
  const TriangleTree tree(source);
  exec::cpu::ParallelFor(Index(targets.size()), [&](Index i) {
    const TriangleTree::Hit hit = tree.Closest(Vec3d(targets[i]));
    Vec3d v(0, 0, 0);
    for (int k = 0; k < 3; ++k) v += Vec3d(source.velocities[source.triangles[hit.face][k]]) * hit.weights[k];
    out[i] = Vec3f(v);
  });
  return out;
}

}  // namespace rime::clean
