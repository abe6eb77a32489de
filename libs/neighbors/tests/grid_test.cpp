// Neighbor lists against an O(n^2) brute-force search (spec §2).
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "rime/core/error.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"

namespace rime::neighbors {
namespace {

template <class T>
std::vector<Vec3<T>> RandomCloud(std::size_t n, bool clustered, T offset, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> g(0, 0.02);
  std::vector<Vec3<T>> p(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (clustered) {  // a few dense blobs, duplicates and a far outlier
      const int c = i % 4;
      p[i] = Vec3<T>(T(offset + 0.3 * c + g(rng)), T(offset + g(rng)), T(offset + 0.1 * c + g(rng)));
      if (i % 97 == 0 && i > 0) p[i] = p[i - 1];
    } else {
      p[i] = Vec3<T>(T(offset + u(rng)), T(offset + u(rng)), T(offset + 0.5 * u(rng)));
    }
  }
  if (clustered && n > 10) p[n - 1] = Vec3<T>(T(offset + 3), T(offset + 3), T(offset + 3));
  return p;
}

template <class T>
void CheckAgainstBruteForce(std::size_t n, std::size_t m, bool clustered, T radius, T offset, bool self) {
  std::mt19937 rng(1234 + n);
  const exec::Device device = exec::Device::Cpu();
  const auto points = RandomCloud<T>(n, clustered, offset, rng);
  const auto queries = self ? points : RandomCloud<T>(m, clustered, offset, rng);
  exec::DeviceArray<Vec3<T>> d_points(device, points), d_queries(device, queries);
  UniformGrid<T> grid(device);
  grid.Build(d_points.data(), points.size(), radius);
  NeighborList list(device);
  grid.Query(d_queries.data(), queries.size(), radius, self, list);
  const auto offsets = list.offsets.ToHost();
  const auto indices = list.indices.ToHost();
  std::uint64_t pairs = 0;
  for (std::size_t i = 0; i < queries.size(); ++i) {
    std::vector<std::uint32_t> expected;
    for (std::size_t j = 0; j < points.size(); ++j) {
      if (self && i == j) continue;
      const Vec3<T> r = queries[i] - points[j];
      if (Dot(r, r) < radius * radius) expected.push_back(std::uint32_t(j));
    }
    std::vector<std::uint32_t> got(indices.begin() + offsets[i], indices.begin() + offsets[i + 1]);
    std::sort(got.begin(), got.end());
    ASSERT_EQ(got, expected) << "query " << i << " (n=" << n << ", clustered=" << clustered << ")";
    pairs += expected.size();
  }
  EXPECT_EQ(list.pairs(), pairs);
}

TEST(UniformGrid, MatchesBruteForceOnRandomClouds) {
  for (std::size_t n : {0, 1, 2, 500, 5000}) CheckAgainstBruteForce<float>(n, 0, false, 0.06f, 0.0f, true);
  CheckAgainstBruteForce<double>(3000, 0, false, 0.05, 0.0, true);
}

TEST(UniformGrid, MatchesBruteForceOnClusteredClouds) {
  CheckAgainstBruteForce<float>(4000, 0, true, 0.03f, 0.0f, true);
  CheckAgainstBruteForce<double>(4000, 0, true, 0.01, -5.0, true);
}

TEST(UniformGrid, SeparateQuerySetAndFarFromOrigin) {
  CheckAgainstBruteForce<float>(3000, 2000, false, 0.07f, 0.0f, false);
  CheckAgainstBruteForce<double>(3000, 2000, false, 0.07, 10000.0, false);  // 10 km away
}

TEST(UniformGrid, OrderIsAPermutationAlongTheCurve) {
  std::mt19937 rng(9);
  const exec::Device device = exec::Device::Cpu();
  const auto points = RandomCloud<float>(1000, false, 0, rng);
  exec::DeviceArray<Vec3f> d(device, points);
  UniformGrid<float> grid(device);
  grid.Build(d.data(), points.size(), 0.1f);
  std::vector<std::uint32_t> order(grid.order(), grid.order() + points.size());
  std::sort(order.begin(), order.end());
  for (std::uint32_t i = 0; i < order.size(); ++i) ASSERT_EQ(order[i], i);
  EXPECT_GT(grid.cell_count(), 10u);
}

TEST(UniformGrid, RejectsNaNAndHugeExtents) {
  const exec::Device device = exec::Device::Cpu();
  std::vector<Vec3f> bad{{0, 0, 0}, {NAN, 0, 0}};
  exec::DeviceArray<Vec3f> d(device, bad);
  UniformGrid<float> grid(device);
  EXPECT_THROW(grid.Build(d.data(), 2, 0.1f), Error);
  std::vector<Vec3f> far{{0, 0, 0}, {1e6f, 0, 0}};
  exec::DeviceArray<Vec3f> f(device, far);
  EXPECT_THROW(grid.Build(f.data(), 2, 0.01f), Error);
}

}  // namespace
}  // namespace rime::neighbors

namespace rime::neighbors {
namespace {

// Cell-by-cell queries between grids on one lattice give exactly the per-point lists.
TEST(UniformGrid, QueryGridMatchesQuery) {
  std::mt19937 rng(77);
  const exec::Device device = exec::Device::Cpu();
  for (bool clustered : {false, true}) {
    const auto a = RandomCloud<float>(4000, clustered, 0.0f, rng);
    const auto b = RandomCloud<float>(3000, clustered, 0.0f, rng);
    exec::DeviceArray<Vec3f> da(device, a), db(device, b);
    const float cell = 0.05f;
    const Vec3f origin(-1.0f, -1.0f, -1.0f);
    for (bool aligned : {true, false}) {
      UniformGrid<float> ga(device), gb(device);
      ga.Build(da.data(), Index(a.size()), cell, origin);
      if (aligned) gb.Build(db.data(), Index(b.size()), cell, origin);
      else gb.Build(db.data(), Index(b.size()), cell);
      EXPECT_EQ(ga.aligned_with(gb), aligned);
      for (bool self : {true, false}) {
        const UniformGrid<float>& target = self ? ga : gb;
        NeighborList by_cell(device), by_point(device);
        target.QueryGrid(ga, cell, self, by_cell);
        target.Query(da.data(), Index(a.size()), cell, self, by_point);
        ASSERT_EQ(by_cell.offsets.ToHost(), by_point.offsets.ToHost());
        auto x = by_cell.indices.ToHost(), y = by_point.indices.ToHost();
        const auto off = by_cell.offsets.ToHost();
        for (std::size_t i = 0; i + 1 < off.size(); ++i) {  // same sets per row (order may differ across the two paths)
          std::sort(x.begin() + off[i], x.begin() + off[i + 1]);
          std::sort(y.begin() + off[i], y.begin() + off[i + 1]);
        }
        EXPECT_EQ(x, y) << "clustered=" << clustered << " aligned=" << aligned << " self=" << self;
        EXPECT_GT(by_cell.pairs(), 0u);
      }
    }
  }
}

}  // namespace
}  // namespace rime::neighbors

namespace rime::neighbors {
namespace {

// The CPU's vectorised cell-by-cell search gives the device kernels' lists in their order, and
// the pair values of kernels::PairValues bit for bit (the solver's results depend on both).
template <class T>
void CheckCpuPathAgainstKernels(bool clustered, bool self) {
  std::mt19937 rng(91);
  const exec::Device device = exec::Device::Cpu();
  const auto a = RandomCloud<T>(3000, clustered, T(0), rng);
  const auto b = RandomCloud<T>(4000, clustered, T(0), rng);
  exec::DeviceArray<Vec3<T>> da(device, a), db(device, b);
  const T cell = T(0.05);
  const Vec3<T> origin(T(-1), T(-1), T(-1));
  UniformGrid<T> queries(device), other(device);
  queries.Build(da.data(), Index(a.size()), cell, origin);
  other.Build(db.data(), Index(b.size()), cell, origin);
  const UniformGrid<T>& target = self ? queries : other;
  const T radius = cell * T(0.999);
  const CubicSpline<T> kernel(radius / 2);

  // Reference: the kernels the CUDA backend runs, on the CPU.
  const Index m = Index(a.size());
  exec::DeviceArray<std::uint32_t> counts(device, m + 1), offsets(device, m + 1);
  counts.SetZero();
  const Index cells = Index(queries.cell_count());
  exec::cpu::ParallelFor(cells, kernels::CountNeighborsByCell<T>{target.view(), queries.view(), radius, self, counts.data()});
  const std::uint64_t total = exec::ExclusiveScan(device, counts.data(), offsets.data(), m + 1);
  exec::DeviceArray<std::uint32_t> indices(device, total);
  exec::cpu::ParallelFor(cells,
                         kernels::FillNeighborsByCell<T>{target.view(), queries.view(), radius, self, offsets.data(), indices.data()});
  exec::DeviceArray<T> w(device, total);
  exec::DeviceArray<Vec3<T>> grad(device, total);
  exec::cpu::ParallelFor(m, kernels::PairValues<T>{.xi = da.data(),
                                                   .xj = target.view().points,
                                                   .offsets = offsets.data(),
                                                   .index = indices.data(),
                                                   .kernel = kernel,
                                                   .w = w.data(),
                                                   .grad = grad.data()});

  NeighborList plain(device), with_values(device);
  exec::DeviceArray<T> fused_w(device);
  exec::DeviceArray<Vec3<T>> fused_grad(device);
  target.QueryGrid(queries, radius, self, plain);
  target.QueryGrid(queries, radius, self, with_values, {.kernel = kernel, .w = fused_w, .grad = fused_grad});
  ASSERT_GT(total, 1000u);
  for (const NeighborList* list : {&plain, &with_values}) {
    ASSERT_EQ(list->offsets.ToHost(), offsets.ToHost());
    ASSERT_EQ(list->indices.ToHost(), indices.ToHost());
  }
  const auto w_expected = w.ToHost(), w_got = fused_w.ToHost();
  const auto g_expected = grad.ToHost(), g_got = fused_grad.ToHost();
  ASSERT_EQ(w_got.size(), total);
  ASSERT_EQ(g_got.size(), total);
  for (std::size_t k = 0; k < total; ++k) {
    ASSERT_EQ(w_got[k], w_expected[k]) << "pair " << k;
    ASSERT_EQ(g_got[k], g_expected[k]) << "pair " << k;
  }
}

TEST(UniformGrid, CpuQueryGridMatchesTheKernelsExactly) {
  for (bool clustered : {false, true})
    for (bool self : {true, false}) {
      CheckCpuPathAgainstKernels<float>(clustered, self);
      CheckCpuPathAgainstKernels<double>(clustered, self);
    }
}

}  // namespace
}  // namespace rime::neighbors

namespace rime::neighbors {
namespace {

// `made` is the grid `built` is: the same slot order and cells, and the same lists (in their
// order) as the target of `other`'s points and as the queries into `other`.
void ExpectSameGrid(const UniformGrid<float>& made, const UniformGrid<float>& built, const UniformGrid<float>& other) {
  const exec::Device device = exec::Device::Cpu();
  ASSERT_EQ(made.size(), built.size());
  EXPECT_TRUE(made.aligned_with(built));
  EXPECT_EQ(made.cell_count(), built.cell_count());
  EXPECT_EQ(std::vector<std::uint32_t>(made.order(), made.order() + made.size()),
            std::vector<std::uint32_t>(built.order(), built.order() + built.size()));
  for (bool as_target : {true, false}) {
    NeighborList a(device), b(device);
    const float radius = built.cell_size();
    if (as_target) {
      made.QueryGrid(other, radius, false, a);
      built.QueryGrid(other, radius, false, b);
    } else {
      other.QueryGrid(made, radius, false, a);
      other.QueryGrid(built, radius, false, b);
    }
    EXPECT_EQ(a.offsets.ToHost(), b.offsets.ToHost()) << "as_target=" << as_target;
    EXPECT_EQ(a.indices.ToHost(), b.indices.ToHost()) << "as_target=" << as_target;
    EXPECT_GT(a.pairs(), std::min(made.size(), other.size())) << "as_target=" << as_target;
  }
}

// Appending points (new ice) to a grid gives the grid a full build makes. A point below the
// lattice's origin falls back to a full build.
TEST(UniformGrid, AppendMatchesBuildingAnew) {
  std::mt19937 rng(91);
  const exec::Device device = exec::Device::Cpu();
  const float cell = 0.05f;
  const Vec3f origin(-1.0f, -1.0f, -1.0f);
  for (bool clustered : {false, true}) {
    auto points = RandomCloud<float>(4000, clustered, 0.0f, rng);
    const std::size_t before = points.size();
    for (const Vec3f& p : RandomCloud<float>(300, clustered, 0.0f, rng)) points.push_back(p);
    points.push_back(points[7]);  // a duplicate of an old point: it goes after it in its cell
    for (bool below_origin : {false, true}) {
      if (below_origin) points.back() = Vec3f(-2.0f, 0.0f, 0.0f);
      SCOPED_TRACE(testing::Message() << "clustered=" << clustered << " below_origin=" << below_origin);
      exec::DeviceArray<Vec3f> d(device, points);
      UniformGrid<float> appended(device), built(device);
      appended.Build(d.data(), Index(before), cell, origin);
      appended.Append(d.data(), Index(points.size()), origin);
      built.Build(d.data(), Index(points.size()), cell, origin);
      ExpectSameGrid(appended, built, built);
    }
  }
}

// A grid of some of another grid's points, taken from its cells, is the grid a build of those
// points makes.
TEST(UniformGrid, BuildSubsetMatchesBuildingTheSubset) {
  std::mt19937 rng(17);
  const exec::Device device = exec::Device::Cpu();
  const float cell = 0.05f;
  const Vec3f origin(-1.0f, -1.0f, -1.0f);
  for (bool clustered : {false, true}) {
    SCOPED_TRACE(testing::Message() << "clustered=" << clustered);
    const auto points = RandomCloud<float>(4000, clustered, 0.0f, rng);
    std::vector<std::uint32_t> flags(points.size()), slot(points.size());
    std::vector<Vec3f> subset;
    for (std::size_t b = 0; b < points.size(); ++b) {
      flags[b] = rng() % 3 == 0;
      slot[b] = std::uint32_t(subset.size());
      if (flags[b]) subset.push_back(points[b]);
    }
    exec::DeviceArray<Vec3f> d(device, points), ds(device, subset);
    UniformGrid<float> parent(device), taken(device), built(device);
    parent.Build(d.data(), Index(points.size()), cell, origin);
    taken.BuildSubset(parent, flags.data(), slot.data(), ds.data(), Index(subset.size()), cell, origin);
    built.Build(ds.data(), Index(subset.size()), cell, origin);
    ExpectSameGrid(taken, built, parent);
  }
}

}  // namespace
}  // namespace rime::neighbors
