// Surface sampling (spec §3): spacing bounds, coverage, no duplicates, normals,
// degenerate and badly shaped input, bad input.
#include <gtest/gtest.h>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "rime/boundary/sampler.h"
#include "rime/boundary/shapes.h"
#include "rime/boundary/volumes.h"
#include "rime/core/error.h"
#include "test_helpers.h"

namespace rime::boundary {
namespace {

using test_support::DistanceToNearestParticle;
using test_support::RandomSurfacePoints;
using test_support::UnitCube;

SurfaceSamples Sample(const io::TriMesh& mesh, double spacing) {
  SampleOptions options;
  options.spacing = spacing;
  return SampleSurface(mesh, options);
}

// Nearest-neighbour distances within [lo, hi]·s and every surface point within cover·s of a particle.
void ExpectSpacingAndCoverage(const io::TriMesh& mesh, const SurfaceSamples& s, double spacing, double lo, double hi, double cover,
                              std::size_t probes = 20000) {
  ASSERT_GT(s.size(), 0u);
  const auto nearest = NearestNeighborDistances(s.positions, float(3 * spacing));
  float min_nn = INFINITY, max_nn = 0;
  for (float r : nearest) min_nn = std::min(min_nn, r), max_nn = std::max(max_nn, r);
  EXPECT_GE(min_nn, lo * spacing * (1 - 1e-5)) << "particles closer than " << lo << " s";
  EXPECT_LE(max_nn, hi * spacing) << "a particle without a neighbour within " << hi << " s";
  const auto probe_points = RandomSurfacePoints(mesh, probes);
  const auto gaps = DistanceToNearestParticle(s.positions, probe_points, float(3 * spacing));
  float worst = 0;
  for (float g : gaps) worst = std::max(worst, g);
  EXPECT_LE(worst, cover * spacing) << "a surface point is " << worst / spacing << " s from every particle";
}

TEST(SampleSurface, UnitCubeSpacingAndCoverage) {
  for (double s : {0.1, 0.07, 0.13, 0.045}) {
    SCOPED_TRACE(::testing::Message() << "spacing " << s);
    const io::TriMesh cube = UnitCube();
    const SurfaceSamples samples = Sample(cube, s);
    ExpectSpacingAndCoverage(cube, samples, s, 0.5, 1.5, 1.0);
    EXPECT_EQ(samples.stats.vertex_samples, 8u);
    EXPECT_EQ(samples.stats.edges, 18u);  // 12 cube edges + 6 face diagonals, each sampled once
    EXPECT_EQ(samples.stats.degenerate_skipped, 0u);
    // Particle count near area / s^2 (6 m^2 of surface): rows and edges are fitted with spacings
    // of at most s, so coarse spacings on small faces give up to ~1.6 times more.
    const double density = double(samples.size()) * s * s / 6.0;
    EXPECT_GT(density, 0.9);
    EXPECT_LT(density, 1.7);
  }
}

TEST(SampleSurface, NormalsPointOutOfTheCube) {
  const SurfaceSamples s = Sample(UnitCube(), 0.1);
  const Vec3f center(0.5f, 0.5f, 0.5f);
  for (std::size_t i = 0; i < s.size(); ++i) {
    EXPECT_NEAR(Norm(s.normals[i]), 1.0f, 1e-5f);
    EXPECT_GT(Dot(s.normals[i], s.positions[i] - center), 0.0f) << "particle " << i;
  }
  // A particle in the middle of the bottom face has the face normal (0, 0, -1).
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Vec3f& p = s.positions[i];
    if (p.z == 0 && p.x > 0.2f && p.x < 0.8f && p.y > 0.2f && p.y < 0.8f) {
      EXPECT_NEAR(s.normals[i].z, -1.0f, 1e-6f);
    }
  }
}

TEST(SampleSurface, SharedEdgesAndUnweldedCopiesAreNotDuplicated) {
  const io::TriMesh cube = UnitCube();
  const SurfaceSamples once = Sample(cube, 0.1);
  // The same cube twice with its own vertices (as a file without shared vertices would give).
  io::TriMesh twice = cube;
  for (const auto& t : cube.triangles) twice.triangles.push_back({t[0] + 8, t[1] + 8, t[2] + 8});
  twice.positions.insert(twice.positions.end(), cube.positions.begin(), cube.positions.end());
  const SurfaceSamples s = Sample(twice, 0.1);
  EXPECT_EQ(s.size(), once.size());
  // Every triangle with its own three vertices ("triangle soup").
  io::TriMesh soup;
  for (const auto& t : cube.triangles) {
    const auto base = std::uint32_t(soup.positions.size());
    for (int k = 0; k < 3; ++k) soup.positions.push_back(cube.positions[t[k]]);
    soup.triangles.push_back({base, base + 1, base + 2});
  }
  EXPECT_EQ(Sample(soup, 0.1).size(), once.size());
}

TEST(SampleSurface, DegenerateTrianglesAreSkippedAndCounted) {
  io::TriMesh cube = UnitCube();
  const std::size_t clean = Sample(cube, 0.1).size();
  cube.triangles.push_back({0, 0, 1});  // repeated vertex
  cube.positions.push_back(Vec3f(0.5f, 0, 0));
  cube.triangles.push_back({0, 1, 8});  // collinear: zero area
  cube.positions.push_back(Vec3f(0, 0, 0));
  cube.triangles.push_back({9, 0, 2});  // a vertex duplicated by position
  const SurfaceSamples s = Sample(cube, 0.1);
  EXPECT_EQ(s.stats.degenerate_skipped, 3u);
  EXPECT_EQ(s.stats.triangles, 15u);
  EXPECT_EQ(s.size(), clean);
}

TEST(SampleSurface, LongThinAndTinyTriangles) {
  // A 1 m x 0.05 m strip cut into needles that all meet at the strip's ends (fans), plus a
  // region of triangles much smaller than the spacing.
  io::TriMesh strip;
  const int n = 200;
  strip.positions.push_back(Vec3f(0, 0, 0));
  strip.positions.push_back(Vec3f(1, 0.05f, 0));
  for (int i = 0; i <= n; ++i) strip.positions.push_back(Vec3f(float(i) / n, 0.05f * (i % 2), 0));
  for (int i = 0; i < n; ++i) strip.triangles.push_back({std::uint32_t(2 + i), std::uint32_t(3 + i), i % 2 ? 0u : 1u});
  const SurfaceSamples s = Sample(strip, 0.02);
  const auto nearest = NearestNeighborDistances(s.positions, 0.06f);
  for (float r : nearest) EXPECT_GE(r, 0.5f * 0.02f * (1 - 1e-5f));

  const io::TriMesh fine = MakePlane(1.0, 1.0, 0.004);  // edges 10x shorter than the spacing
  const SurfaceSamples f = Sample(fine, 0.04);
  EXPECT_GT(f.stats.near_duplicates_removed, 0u);
  ExpectSpacingAndCoverage(fine, f, 0.04, 0.5, 1.5, 1.0);
  EXPECT_LT(double(f.size()), 4.0 / (0.04 * 0.04 * 0.25));  // thinned: far fewer than the 63k vertices
}

TEST(SampleSurface, IntersectingPartsAndOpenBorders) {
  io::TriMesh mesh = UnitCube();
  for (const auto& p : UnitCube().positions) mesh.positions.push_back(p * 0.6f + Vec3f(0.7f, 0.2f, 0.3f));
  for (const auto& t : UnitCube().triangles) mesh.triangles.push_back({t[0] + 8, t[1] + 8, t[2] + 8});
  const SurfaceSamples s = Sample(mesh, 0.05);
  EXPECT_GT(s.stats.near_duplicates_removed, 0u);  // where the two surfaces cross
  ExpectSpacingAndCoverage(mesh, s, 0.05, 0.5, 1.5, 1.5);

  io::TriMesh square;  // one open quad: every edge is a border
  square.positions = {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(1, 1, 0), Vec3f(0, 1, 0)};
  square.triangles = {{0, 1, 2}, {0, 2, 3}};
  ExpectSpacingAndCoverage(square, Sample(square, 0.06), 0.06, 0.5, 1.5, 1.0);
}

void ExpectBadInput(const io::TriMesh& mesh, double spacing, const std::string& fragment, std::uint64_t max_particles = 50'000'000) {
  SampleOptions options;
  options.spacing = spacing;
  options.max_particles = max_particles;
  options.source = "thing.obj";
  try {
    SampleSurface(mesh, options);
    ADD_FAILURE() << "expected an error containing '" << fragment << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("thing.obj"), std::string::npos) << e.what();
  }
}

TEST(SampleSurface, BadInput) {
  const io::TriMesh cube = UnitCube();
  ExpectBadInput(cube, 0, "spacing");
  ExpectBadInput(cube, -0.1, "spacing");
  ExpectBadInput(cube, std::nan(""), "spacing");
  ExpectBadInput(io::TriMesh{}, 0.1, "no triangles");
  io::TriMesh nan_mesh = cube;
  nan_mesh.positions[3].y = std::nanf("");
  ExpectBadInput(nan_mesh, 0.1, "NaN");
  io::TriMesh inf_mesh = cube;
  inf_mesh.positions[5].x = INFINITY;
  ExpectBadInput(inf_mesh, 0.1, "infinite");
  io::TriMesh bad_index = cube;
  bad_index.triangles.push_back({0, 1, 99});
  ExpectBadInput(bad_index, 0.1, "vertex 99");
  // 1e-6 m on a 6 m^2 cube would be 6e12 particles: refused by the estimate, before any work.
  ExpectBadInput(cube, 1e-6, "more than the maximum");
  ExpectBadInput(cube, 0.1, "more than the maximum", 100);
  io::TriMesh flat;
  flat.positions = {Vec3f(0, 0, 0), Vec3f(1, 0, 0), Vec3f(2, 0, 0)};
  flat.triangles = {{0, 1, 2}};
  ExpectBadInput(flat, 0.1, "degenerate");
}

// Runs f on exactly `threads` worker threads (more than the machine's cores is fine).
template <class F>
void WithThreads(int threads, F&& f) {
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
  tbb::task_arena arena(threads);
  arena.execute(f);
}

// Same particles in the same order, same statistics and bit-identical volumes for any number of
// threads: welding and the incidence lists use atomics, thinning decides in parallel rounds.
TEST(SampleSurface, DeterministicAcrossThreadCounts) {
  // Two intersecting tori as a shuffled triangle soup (every triangle with its own vertices, so
  // all of them are welded), with edges finer than the spacing so that thinning decides a lot.
  io::TriMesh soup;
  std::mt19937 rng(3);
  for (const Vec3f offset : {Vec3f(0, 0, 0), Vec3f(0.3f, 0.1f, 0.05f)}) {
    const io::TriMesh torus = MakeTorus(0.4, 0.12, 0.006);
    for (const auto& t : torus.triangles) {
      const auto base = std::uint32_t(soup.positions.size());
      for (int k = 0; k < 3; ++k) soup.positions.push_back(torus.positions[t[k]] + offset);
      soup.triangles.push_back({base, base + 1, base + 2});
    }
  }
  std::shuffle(soup.triangles.begin(), soup.triangles.end(), rng);
  for (double spacing : {0.015, 0.007}) {
    SCOPED_TRACE(::testing::Message() << "spacing " << spacing);
    SurfaceSamples reference;
    std::vector<float> reference_volumes;
    WithThreads(1, [&] {
      reference = Sample(soup, spacing);
      reference_volumes = ComputeBoundaryVolumes<float>(exec::Device::Cpu(), reference.positions, float(2 * spacing));
    });
    ASSERT_GT(reference.size(), 10000u);
    EXPECT_GT(reference.stats.near_duplicates_removed, 500u);
    for (int threads : {2, 3, 8}) {
      SCOPED_TRACE(::testing::Message() << threads << " threads");
      WithThreads(threads, [&] {
        const SurfaceSamples s = Sample(soup, spacing);
        ASSERT_EQ(s.size(), reference.size());
        EXPECT_EQ(s.stats.near_duplicates_removed, reference.stats.near_duplicates_removed);
        EXPECT_EQ(s.stats.edges, reference.stats.edges);
        EXPECT_EQ(s.stats.welded_vertices, reference.stats.welded_vertices);
        for (std::size_t i = 0; i < s.size(); ++i) {
          ASSERT_EQ(s.positions[i], reference.positions[i]) << "particle " << i;
          ASSERT_EQ(s.normals[i], reference.normals[i]) << "particle " << i;
        }
        const std::vector<float> volumes = ComputeBoundaryVolumes<float>(exec::Device::Cpu(), s.positions, float(2 * spacing));
        ASSERT_EQ(volumes, reference_volumes);
      });
    }
  }
}

TEST(NearestNeighborDistances, MatchesBruteForce) {
  const SurfaceSamples s = Sample(UnitCube(), 0.09);
  const auto fast = NearestNeighborDistances(s.positions, 0.3f);
  for (std::size_t i = 0; i < s.size(); i += 7) {
    float best = INFINITY;
    for (std::size_t j = 0; j < s.size(); ++j)
      if (j != i) best = std::min(best, Norm(s.positions[i] - s.positions[j]));
    EXPECT_FLOAT_EQ(fast[i], best);
  }
}

}  // namespace
}  // namespace rime::boundary
