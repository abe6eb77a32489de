#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <random>

#include "rime/core/error.h"
#include "rime/io/scene.h"
#include "rime/clean/clean.h"
#include "rime/clean/decimate.h"
#include "rime/clean/procedural.h"

namespace rime::clean {
namespace {

/// Distance from each point to `surface`: TransferVelocities with velocity = position returns
/// the nearest surface point itself (barycentric interpolation of a linear field is exact).
std::vector<double> DistancesTo(const io::TriMesh& surface, const std::vector<Vec3f>& points) {
  io::TriMesh with_positions = surface;
  with_positions.velocities = surface.positions;
  const std::vector<Vec3f> nearest = TransferVelocities(with_positions, points);
  std::vector<double> d(points.size());
  for (std::size_t i = 0; i < points.size(); ++i) d[i] = Norm(Vec3d(points[i]) - Vec3d(nearest[i]));
  return d;
}

/// Vertices plus edge midpoints and face centroids: a denser sample of the surface than vertices.
std::vector<Vec3f> SurfaceSamples(const io::TriMesh& m) {
  std::vector<Vec3f> s = m.positions;
  for (const auto& t : m.triangles) {
    const Vec3f a = m.positions[t[0]], b = m.positions[t[1]], c = m.positions[t[2]];
    s.push_back((a + b + c) / 3.0f);
    s.push_back((a + b) * 0.5f);
  }
  return s;
}

/// Symmetric Hausdorff distance estimated on vertices, edge midpoints and centroids of both meshes.
double HausdorffDistance(const io::TriMesh& a, const io::TriMesh& b) {
  double h = 0;
  for (double d : DistancesTo(b, SurfaceSamples(a))) h = std::max(h, d);
  for (double d : DistancesTo(a, SurfaceSamples(b))) h = std::max(h, d);
  return h;
}

TEST(Clean, TransferVelocitiesIsExactAtInputVerticesAndLinearInside) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 3);
  for (const Vec3f& p : sphere.positions) sphere.velocities.push_back(Vec3f(2 * p.x + 1, -p.z, 0.5f));
  const std::vector<Vec3f> at_vertices = TransferVelocities(sphere, sphere.positions);
  for (std::size_t i = 0; i < sphere.positions.size(); ++i) {
    EXPECT_LT(Norm(at_vertices[i] - sphere.velocities[i]), 1e-5f) << i;
  }
  // The centroid of a face (pushed outward a bit) gets the mean of its corners' velocities.
  const auto& t = sphere.triangles[17];
  const Vec3f centroid = (sphere.positions[t[0]] + sphere.positions[t[1]] + sphere.positions[t[2]]) / 3.0f;
  const Vec3f v = TransferVelocities(sphere, {centroid * 1.001f})[0];
  const Vec3f expected = (sphere.velocities[t[0]] + sphere.velocities[t[1]] + sphere.velocities[t[2]]) / 3.0f;
  EXPECT_NEAR(v.x, expected.x, 1e-5);
  EXPECT_NEAR(v.y, expected.y, 1e-5);
  EXPECT_NEAR(v.z, expected.z, 1e-5);
}

/// Squared distance from p to triangle abc, written independently of TransferVelocities: the
/// projection on the plane when it falls inside, else the nearest of the three edges.
double BruteDistance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
  auto segment = [&](const Vec3d& s, const Vec3d& e) {
    const Vec3d d = e - s;
    const double t = SquaredNorm(d) > 0 ? std::clamp(Dot(p - s, d) / SquaredNorm(d), 0.0, 1.0) : 0.0;
    return SquaredNorm(s + d * t - p);
  };
  double best = std::min({segment(a, b), segment(b, c), segment(c, a)});
  const Vec3d n = Cross(b - a, c - a);
  if (SquaredNorm(n) > 0) {
    const Vec3d x = p - n * (Dot(p - a, n) / SquaredNorm(n));
    const bool inside = Dot(Cross(b - a, x - a), n) >= 0 && Dot(Cross(c - b, x - b), n) >= 0 && Dot(Cross(a - c, x - c), n) >= 0;
    if (inside) best = std::min(best, SquaredNorm(x - p));
  }
  return best;
}

// The tree search returns the closest surface point: same distance as a scan of every triangle,
// for points near the surface (the transfer's use) and far from it.
TEST(Clean, TransferVelocitiesFindsTheClosestPointOfABruteForceScan) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 3);
  procedural::AddRadialNoise(sphere, 0.05, 5);
  sphere.velocities = sphere.positions;  // the transferred "velocity" is the closest point itself
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> box(-1.6f, 1.6f), jitter(-0.02f, 0.02f);
  std::vector<Vec3f> queries;
  for (int i = 0; i < 500; ++i) queries.push_back(Vec3f(box(rng), box(rng), box(rng)));
  for (std::size_t v = 0; v < sphere.positions.size(); v += 3)
    queries.push_back(sphere.positions[v] + Vec3f(jitter(rng), jitter(rng), jitter(rng)));
  const std::vector<Vec3f> closest = TransferVelocities(sphere, queries);
  for (std::size_t i = 0; i < queries.size(); ++i) {
    const Vec3d q(queries[i]);
    double brute = std::numeric_limits<double>::infinity();
    for (const auto& t : sphere.triangles)
      brute =
          std::min(brute, BruteDistance2(q, Vec3d(sphere.positions[t[0]]), Vec3d(sphere.positions[t[1]]), Vec3d(sphere.positions[t[2]])));
    EXPECT_NEAR(Norm(Vec3d(closest[i]) - q), std::sqrt(brute), 1e-5) << i;
  }
}

// Acceptance: a noisy sphere with specks and a hole comes out as one closed manifold component
// whose volume is within 1% of the input sphere's.
TEST(Clean, NoisySphereWithSpecksAndHoleBecomesOneClosedComponent) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 5);  // 20480 faces, edge ~0.035 m
  procedural::AddRadialNoise(sphere, 0.004, 42);
  const double sphere_volume = ComputeStats(sphere).volume;
  ASSERT_NEAR(sphere_volume, 4.0 / 3.0 * std::numbers::pi, 0.02 * 4.0 / 3.0 * std::numbers::pi);

  io::TriMesh input = sphere;
  procedural::PunchHole(input, {0, 0, 1}, 0.12);                                         // a hole of about 40 border edges
  for (int i = 0; i < 6; ++i) {                                                          // ice specks: tiny separate spheres
    io::TriMesh speck = procedural::Icosphere(0.02, 0, {1.3 + 0.1 * i, 0.2 * i, -0.3});  // 20 faces
    procedural::Append(input, speck);
  }
  const MeshStats in = ComputeStats(input);
  ASSERT_EQ(in.components, 7u);
  ASSERT_GT(in.boundary_edges, 20u);

  const CleanResult r = Clean(input, io::CleanupSettings{});
  const MeshStats& out = r.report.after;
  EXPECT_EQ(out.components, 1u);
  EXPECT_EQ(out.boundary_edges, 0u);
  EXPECT_EQ(out.non_manifold_edges, 0u);
  EXPECT_EQ(out.non_manifold_vertices, 0u);
  EXPECT_TRUE(r.report.closed());
  EXPECT_TRUE(r.report.manifold());
  EXPECT_EQ(r.report.components_removed, 6u);
  EXPECT_EQ(r.report.holes_filled, 1u);
  EXPECT_EQ(r.report.repair_path, "direct");
  EXPECT_NEAR(out.volume, sphere_volume, 0.01 * sphere_volume);
  // Default decimation halves the faces.
  EXPECT_NEAR(double(out.faces), 0.5 * double(in.faces - 6 * 20), 0.02 * double(in.faces));
  EXPECT_GE(r.report.self_intersecting_pairs, 0);
  // The report's own check agrees with a recount of the returned mesh.
  EXPECT_EQ(ComputeStats(r.mesh).faces, out.faces);
  EXPECT_TRUE(r.report.warnings.empty()) << r.report.warnings.front();
  EXPECT_FALSE(SummaryLine(r.report).empty());
  EXPECT_EQ(ToJson(r.report)["after"]["components"], 1);
}

// Acceptance: decimation to half the faces keeps the Hausdorff distance under a stated bound:
// 0.25 x the mean input edge length (here about 9 mm on a 1 m sphere with 35 mm edges).
TEST(Clean, DecimationToHalfKeepsHausdorffDistanceSmall) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 5);
  procedural::AddRadialNoise(sphere, 0.002, 7);
  io::CleanupSettings only_decimate;
  only_decimate.smooth = io::MeshSmoothing::kNone;
  only_decimate.self_intersections = io::SelfIntersections::kOff;
  only_decimate.decimate_ratio = 0.5;
  ASSERT_EQ(only_decimate.decimate_method, io::DecimateMethod::kBatch);  // the default
  const CleanResult r = Clean(sphere, only_decimate);
  const double mean_edge = r.report.before.mean_edge_length;
  EXPECT_NEAR(double(r.mesh.triangle_count()), 0.5 * double(sphere.triangle_count()), 0.01 * double(sphere.triangle_count()));
  const double hausdorff = HausdorffDistance(sphere, r.mesh);
  EXPECT_LT(hausdorff, 0.25 * mean_edge) << "mean edge " << mean_edge;
  EXPECT_GT(hausdorff, 0.0);
  EXPECT_TRUE(r.report.closed());
  EXPECT_TRUE(r.report.manifold());
  EXPECT_NEAR(r.report.after.volume, r.report.before.volume, 1e-3 * r.report.before.volume);
  std::printf("decimation to half (batch): Hausdorff %.5f m = %.3f mean edges\n", hausdorff, hausdorff / mean_edge);

  // Against CGAL's edge_collapse with the same quadrics (strictly greedy): no worse than 1.5x.
  io::CleanupSettings with_cgal = only_decimate;
  with_cgal.decimate_method = io::DecimateMethod::kCgal;
  const CleanResult c = Clean(sphere, with_cgal);
  EXPECT_EQ(c.mesh.triangle_count(), r.mesh.triangle_count());
  const double hausdorff_cgal = HausdorffDistance(sphere, c.mesh);
  std::printf("decimation to half (cgal):  Hausdorff %.5f m = %.3f mean edges\n", hausdorff_cgal, hausdorff_cgal / mean_edge);
  EXPECT_LT(hausdorff, 1.5 * hausdorff_cgal);

  // An error bound stops the collapse earlier: fewer faces removed, smaller distance.
  io::CleanupSettings bounded = only_decimate;
  bounded.decimate_ratio = 0.1;
  bounded.decimate_max_error = 0.0005;
  const CleanResult b = Clean(sphere, bounded);
  EXPECT_GT(b.mesh.triangle_count(), std::size_t(0.1 * double(sphere.triangle_count())));
  EXPECT_LT(b.mesh.triangle_count(), sphere.triangle_count());
}

// Acceptance: a linear velocity field v = A x + b survives remeshing within 1%.
TEST(Clean, LinearVelocityFieldSurvivesRemeshing) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 4);
  const auto field = [](const Vec3f& x) { return Vec3f(0.5f * x.x - 2 * x.y + 3, x.z + 1, -x.x + 0.25f * x.y - 2); };
  for (const Vec3f& p : sphere.positions) sphere.velocities.push_back(field(p));
  io::CleanupSettings s;
  s.remesh = true;
  s.target_edge_factor = 0.7;  // creates many new vertices
  s.remesh_iterations = 2;
  const CleanResult r = Clean(sphere, s);
  ASSERT_EQ(r.mesh.velocities.size(), r.mesh.positions.size());
  EXPECT_TRUE(r.report.velocities);
  double max_error = 0, max_speed = 0;
  for (std::size_t i = 0; i < r.mesh.positions.size(); ++i) {
    max_error = std::max(max_error, double(Norm(r.mesh.velocities[i] - field(r.mesh.positions[i]))));
    max_speed = std::max(max_speed, double(Norm(field(r.mesh.positions[i]))));
  }
  EXPECT_LT(max_error, 0.01 * max_speed) << "max error " << max_error << " of " << max_speed;
  EXPECT_GT(r.report.target_edge, 0.0);
  // The remeshed mesh really has new vertices (not just the input ones).
  EXPECT_NE(r.mesh.positions.size(), sphere.positions.size());
}

/// V - E + F for a closed triangle mesh (E = 3F/2): 2 for a sphere, 0 for a torus.
long long EulerCharacteristic(const io::TriMesh& m) {
  const MeshStats s = ComputeStats(m);
  return (long long)s.vertices - (long long)s.faces / 2;
}

io::TriMesh Decimated(const io::TriMesh& in, std::size_t target, double max_error, DecimateResult* result = nullptr) {
  std::vector<Vec3d> points;
  for (const Vec3f& p : in.positions) points.push_back(Vec3d(p));
  io::TriMesh out;
  out.triangles = in.triangles;
  const DecimateResult r = DecimateQuadric(points, out.triangles, target, max_error);
  if (result) *result = r;
  for (const Vec3d& p : points) out.positions.push_back(Vec3f(p));
  return out;
}

// The batched collapse keeps a closed manifold of the same genus, down to very few faces.
TEST(Decimate, KeepsTopologyOfSphereAndTorus) {
  const io::TriMesh torus = procedural::NoisyTorus(20000, 3);
  const MeshStats in = ComputeStats(torus);
  ASSERT_TRUE(in.closed() && in.manifold());
  ASSERT_EQ(EulerCharacteristic(torus), 0);
  DecimateResult r;
  const io::TriMesh small = Decimated(torus, in.faces / 10, 0, &r);
  const MeshStats out = ComputeStats(small);
  EXPECT_TRUE(r.reached_target);
  EXPECT_LE(out.faces, in.faces / 10);
  EXPECT_GE(out.faces + 2, in.faces / 10);
  EXPECT_TRUE(out.closed() && out.manifold());
  EXPECT_EQ(out.components, 1u);
  EXPECT_EQ(EulerCharacteristic(small), 0);
  EXPECT_NEAR(out.volume, in.volume, 0.02 * in.volume);

  // An icosahedron asked for 2 faces: collapses stop where one more would break the surface.
  const io::TriMesh ico = procedural::Icosphere(1.0, 0);
  const io::TriMesh tiny = Decimated(ico, 2, 0, &r);
  EXPECT_FALSE(r.reached_target);
  const MeshStats t = ComputeStats(tiny);
  EXPECT_GE(t.faces, 4u);
  EXPECT_TRUE(t.closed() && t.manifold());
  EXPECT_EQ(EulerCharacteristic(tiny), 2);
  EXPECT_GT(t.volume, 0);  // still outward
}

// Border vertices never move, so an open mesh keeps its border exactly.
TEST(Decimate, KeepsBordersFixed) {
  io::TriMesh open = procedural::Icosphere(1.0, 4);
  procedural::PunchHole(open, {0, 0, 1}, 0.4);
  const MeshStats in = ComputeStats(open);
  ASSERT_GT(in.boundary_edges, 10u);
  std::vector<Vec3f> border;
  for (const auto& t : open.triangles)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = t[k], b = t[(k + 1) % 3];
      bool twin = false;
      for (const auto& u : open.triangles)
        for (int j = 0; j < 3 && !twin; ++j) twin = u[j] == b && u[(j + 1) % 3] == a;
      if (!twin) border.push_back(open.positions[a]);
    }
  const io::TriMesh out = Decimated(open, in.faces / 4, 0);
  const MeshStats s = ComputeStats(out);
  EXPECT_EQ(s.boundary_edges, in.boundary_edges);
  EXPECT_TRUE(s.manifold());
  EXPECT_LT(s.faces, in.faces / 2);
  for (const Vec3f& p : border) EXPECT_NE(std::find(out.positions.begin(), out.positions.end(), p), out.positions.end());
}

// The error bound stops the collapse: every removed vertex stays within about max_error of the
// surface (the quadric cost is a sum of squared plane distances, so it bounds each one).
TEST(Decimate, ErrorBoundLimitsTheDistance) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 5);
  procedural::AddRadialNoise(sphere, 0.002, 11);
  const double bound = 0.004;  // twice the noise amplitude: removes most faces, not all
  DecimateResult r;
  const io::TriMesh out = Decimated(sphere, 0, bound, &r);
  EXPECT_FALSE(r.reached_target);
  EXPECT_LT(out.triangle_count(), sphere.triangle_count());
  EXPECT_GT(out.triangle_count(), sphere.triangle_count() / 100);
  EXPECT_LT(out.triangle_count(), sphere.triangle_count() / 2);
  double largest = 0;
  for (double d : DistancesTo(out, sphere.positions)) largest = std::max(largest, d);
  // Plane distances bound the distance to the new surface only up to the triangles' curvature:
  // allow a factor of 2 (measured: 0.43 x the bound).
  EXPECT_LT(largest, 2 * bound);
  std::printf("error bound %.4f m: %zu -> %zu faces, largest distance of an input vertex %.5f m\n", bound, sphere.triangle_count(),
              out.triangle_count(), largest);
}

TEST(Clean, EveryOperationCanBeSwitchedOff) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 3);
  procedural::PunchHole(sphere, {0, 0, 1}, 0.2);
  io::CleanupSettings none;
  none.remove_degenerate = false;
  none.remove_components = false;
  none.fill_holes = false;
  none.smooth = io::MeshSmoothing::kNone;
  none.decimate = false;
  none.self_intersections = io::SelfIntersections::kOff;
  const CleanResult r = Clean(sphere, none);
  // Same triangles (the hole left one vertex unused, which is dropped, so compare positions).
  ASSERT_EQ(r.mesh.triangle_count(), sphere.triangle_count());
  for (std::size_t f = 0; f < sphere.triangle_count(); ++f) {
    std::array<Vec3f, 3> a, b;
    for (int k = 0; k < 3; ++k) a[k] = sphere.positions[sphere.triangles[f][k]], b[k] = r.mesh.positions[r.mesh.triangles[f][k]];
    const bool rotated = (a[0] == b[0] && a[1] == b[1]) || (a[0] == b[1] && a[1] == b[2]) || (a[0] == b[2] && a[1] == b[0]);
    EXPECT_TRUE(rotated) << f;
  }
  EXPECT_GT(r.report.after.boundary_edges, 0u);
  EXPECT_FALSE(r.report.warnings.empty());    // "not closed"
  EXPECT_EQ(r.report.operations.size(), 1u);  // only loading
}

TEST(Clean, SmoothingAndShapeSmoothingKeepVolume) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 4);
  procedural::AddRadialNoise(sphere, 0.01, 3);
  const double volume = ComputeStats(sphere).volume;
  for (const io::MeshSmoothing mode : {io::MeshSmoothing::kTangential, io::MeshSmoothing::kAngle}) {
    io::CleanupSettings s;
    s.smooth = mode;
    s.shape_smooth_iterations = 2;
    s.decimate = false;
    const CleanResult r = Clean(sphere, s);
    EXPECT_NEAR(r.report.after.volume, volume, 0.01 * volume) << io::EnumName(mode);
    EXPECT_TRUE(r.report.closed()) << io::EnumName(mode);
  }
}

/// Volume and centre of mass of the closed piece made of the triangles whose first vertex satisfies
/// `inside` (a sum of signed tetrahedra from the origin).
std::pair<double, Vec3d> PieceVolumeAndCentroid(const io::TriMesh& m, const std::function<bool(const Vec3d&)>& inside) {
  double volume = 0;
  Vec3d moment(0, 0, 0);
  for (const auto& t : m.triangles) {
    const Vec3d a(m.positions[t[0]]), b(m.positions[t[1]]), c(m.positions[t[2]]);
    if (!inside(a)) continue;
    const double v = Dot(a, Cross(b, c)) / 6;
    volume += v;
    moment += v * (a + b + c) / 4.0;
  }
  return {volume, volume != 0 ? moment / volume : moment};
}

TEST(Clean, ShapeSmoothingRestoresEachPieceWhereItStands) {
  // A noisy ball and, 3 m away, a pebble that one flow step of this size would collapse.
  io::TriMesh m = procedural::Icosphere(1.0, 4);
  procedural::AddRadialNoise(m, 0.01, 3);
  io::TriMesh pebble = procedural::Icosphere(0.05, 3, {3, 0, 0});
  procedural::AddRadialNoise(pebble, 0.001, 4, {3, 0, 0});
  procedural::Append(m, pebble);
  const auto is_ball = [](const Vec3d& p) { return p.x < 2; };
  const auto is_pebble = [](const Vec3d& p) { return p.x > 2; };
  const auto [ball_volume, ball_centre] = PieceVolumeAndCentroid(m, is_ball);
  const auto [pebble_volume, pebble_centre] = PieceVolumeAndCentroid(m, is_pebble);

  io::CleanupSettings s;
  s.decimate = false;
  s.smooth = io::MeshSmoothing::kNone;
  s.shape_smooth_iterations = 3;
  s.shape_smooth_time = 1e-3;
  const CleanResult r = Clean(m, s);
  const auto [ball_after, ball_centre_after] = PieceVolumeAndCentroid(r.mesh, is_ball);
  const auto [pebble_after, pebble_centre_after] = PieceVolumeAndCentroid(r.mesh, is_pebble);
  EXPECT_NEAR(ball_after, ball_volume, 2e-3 * ball_volume);
  EXPECT_NEAR(pebble_after, pebble_volume, 2e-3 * pebble_volume);
  EXPECT_LT(Norm(ball_centre_after - ball_centre), 1e-4);
  EXPECT_LT(Norm(pebble_centre_after - pebble_centre), 1e-4);  // rescaling about the whole mesh's centroid moves it
  // The ball was smoothed: its radius varies less than before.
  const auto radius_spread = [](const io::TriMesh& mesh) {
    double lo = 1e9, hi = 0;
    for (const Vec3f& p : mesh.positions)
      if (p.x < 2) lo = std::min(lo, double(Norm(p))), hi = std::max(hi, double(Norm(p)));
    return hi - lo;
  };
  EXPECT_LT(radius_spread(r.mesh), 0.5 * radius_spread(m));
  EXPECT_TRUE(r.report.closed());
  const auto op =
      std::find_if(r.report.operations.begin(), r.report.operations.end(), [](const auto& o) { return o.name == "shape_smooth"; });
  ASSERT_NE(op, r.report.operations.end());
  EXPECT_NE(op->detail.find("left as they were (a step halved them): 1"), std::string::npos) << op->detail;
}

TEST(Clean, ShapeSmoothingNeverMakesFacesCross) {
  // A wavy sheet 2.4 cells thick, closed and crossing-free: steps of this size push its two
  // sides through each other where it bends most, which the flow must undo.
  const auto sheet = [](const Vec3d& p) {
    const double mid = 0.02 * std::sin(40 * p.x) * std::cos(30 * p.y);
    return std::max({std::abs(p.z - mid) - 0.006, std::abs(p.x) - 0.2, std::abs(p.y) - 0.2});
  };
  const io::TriMesh m = procedural::SurfaceNets(sheet, {-0.25, -0.25, -0.05}, {0.25, 0.25, 0.05}, 0.005);
  io::CleanupSettings s;
  s.decimate = false;
  s.smooth = io::MeshSmoothing::kNone;
  ASSERT_EQ(Clean(m, s).report.self_intersecting_pairs, 0);
  s.shape_smooth_iterations = 3;
  s.shape_smooth_time = 3e-4;
  const CleanResult r = Clean(m, s);
  const auto op =
      std::find_if(r.report.operations.begin(), r.report.operations.end(), [](const auto& o) { return o.name == "shape_smooth"; });
  ASSERT_NE(op, r.report.operations.end());
  EXPECT_NE(op->detail.find("vertices put back where a step made faces cross"), std::string::npos) << op->detail;
  EXPECT_EQ(r.report.self_intersecting_pairs, 0);
  EXPECT_TRUE(r.report.closed());
}

// Bad input: empty mesh and NaN vertices are errors naming the problem (the tool adds the file).
TEST(Clean, EmptyAndNanInputAreInputErrors) {
  try {
    Clean(io::TriMesh{}, io::CleanupSettings{});
    ADD_FAILURE() << "empty mesh accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("empty"), std::string::npos);
  }
  io::TriMesh nan = procedural::Icosphere(1.0, 1);
  nan.positions[5].z = std::nanf("");
  try {
    Clean(nan, io::CleanupSettings{});
    ADD_FAILURE() << "NaN accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("vertex 5"), std::string::npos) << e.what();
  }
}

// Bad input: non-manifold meshes are repaired through the polygon soup path, or flagged.
TEST(Clean, NonManifoldInputIsRepairedOrFlagged) {
  // Two spheres welded at one vertex (bow-tie) plus a fin on an edge.
  io::TriMesh a = procedural::Icosphere(1.0, 3);
  io::TriMesh b = procedural::Icosphere(1.0, 3, {2, 0, 0});
  const std::uint32_t touch_a = 0;  // find a's vertex nearest +x and b's nearest -x, weld them
  std::uint32_t ia = 0, ib = 0;
  for (std::uint32_t i = 0; i < a.positions.size(); ++i) {
    if (a.positions[i].x > a.positions[ia].x) ia = i;
    if (b.positions[i].x < b.positions[ib].x) ib = i;
  }
  (void)touch_a;
  io::TriMesh m = a;
  procedural::Append(m, b);
  const std::uint32_t welded = ib + std::uint32_t(a.positions.size());
  for (auto& t : m.triangles)
    for (auto& v : t)
      if (v == welded) v = ia;
  m.positions.push_back({0, 0, 3});
  m.triangles.push_back({m.triangles[0][0], m.triangles[0][1], std::uint32_t(m.positions.size() - 1)});
  const MeshStats in = ComputeStats(m);
  ASSERT_GT(in.non_manifold_edges + in.non_manifold_vertices, 0u);

  io::CleanupSettings s;
  s.decimate = false;
  s.repair = io::Repair::kAlways;
  const CleanResult r = Clean(m, s);
  EXPECT_EQ(r.report.repair_path, "soup");
  EXPECT_EQ(r.report.after.non_manifold_edges, 0u);
  EXPECT_EQ(r.report.after.non_manifold_vertices, 0u);
  EXPECT_EQ(r.report.before.non_manifold_edges, in.non_manifold_edges);

  // "auto" drops the few non-manifold faces, splits the bow-tie vertex and fills the holes.
  s.repair = io::Repair::kAuto;
  const CleanResult automatic = Clean(m, s);
  EXPECT_EQ(automatic.report.repair_path, "direct") << automatic.report.operations[0].detail;
  EXPECT_TRUE(automatic.report.manifold());
  EXPECT_EQ(automatic.report.after.components, 2u);

  // With repair = "never" the offending faces are dropped and the report says so.
  s.repair = io::Repair::kNever;
  const CleanResult never = Clean(m, s);
  EXPECT_GT(never.report.faces_dropped_on_load, 0u);
  EXPECT_FALSE(never.report.warnings.empty());
}

TEST(Clean, UnweldedTrianglesAreWeldedBySoupRepair) {
  const io::TriMesh sphere = procedural::Icosphere(1.0, 2);
  io::TriMesh soup;
  for (const auto& t : sphere.triangles) {
    const std::uint32_t base = std::uint32_t(soup.positions.size());
    for (std::uint32_t v : t) soup.positions.push_back(sphere.positions[v]);
    soup.triangles.push_back({base, base + 1, base + 2});
  }
  io::CleanupSettings s;
  s.decimate = false;
  s.remove_components = false;
  const CleanResult r = Clean(soup, s);
  EXPECT_EQ(r.report.repair_path, "soup");
  EXPECT_EQ(r.report.after.components, 1u);
  EXPECT_TRUE(r.report.closed());
}

TEST(Clean, InwardMeshIsReoriented) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 3);
  for (auto& t : sphere.triangles) std::swap(t[1], t[2]);
  ASSERT_LT(ComputeStats(sphere).volume, 0);
  io::CleanupSettings s;
  s.decimate = false;
  EXPECT_GT(Clean(sphere, s).report.after.volume, 0);
}

TEST(CleanupScene, ReadsFieldsAndChecksRanges) {
  const io::Scene scene = io::ParseScene(R"(
[clean]
remesh = true
target_edge = 0.004
decimate_ratio = 0.25
min_component_faces = 10
smooth = "angle"
self_intersections = "remove"
)",
                                         "clean.toml");
  EXPECT_TRUE(scene.cleanup.remesh);
  EXPECT_DOUBLE_EQ(scene.cleanup.target_edge, 0.004);
  EXPECT_DOUBLE_EQ(scene.cleanup.decimate_ratio, 0.25);
  EXPECT_EQ(scene.cleanup.min_component_faces, 10);
  EXPECT_EQ(scene.cleanup.smooth, io::MeshSmoothing::kAngle);
  EXPECT_EQ(scene.cleanup.self_intersections, io::SelfIntersections::kRemove);
  EXPECT_TRUE(scene.cleanup.fill_holes);  // default kept

  for (const char* bad : {"[clean]\ndecimate_ratio = 1.5\n", "[clean]\nsmooth = \"laplace\"\n", "[clean]\nmax_hole_edges = 2\n",
                          "[clean]\ndecimat = true\n"}) {
    try {
      io::ParseScene(bad, "clean.toml");
      ADD_FAILURE() << "accepted " << bad;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput);
      EXPECT_NE(std::string(e.what()).find("clean.toml"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace rime::clean

namespace rime::clean {
namespace {

// Two interpenetrating spheres in one mesh: the report counts the intersecting pairs; "remove"
// either removes them or says that CGAL's experimental removal could not.
TEST(Clean, SelfIntersectionsAreReportedAndRemovalIsHonest) {
  io::TriMesh m = procedural::Icosphere(1.0, 3);
  procedural::Append(m, procedural::Icosphere(1.0, 3, {1.0, 0.1, 0.05}));
  io::CleanupSettings s;
  s.decimate = false;
  s.remove_components = false;
  const CleanResult reported = Clean(m, s);
  EXPECT_GT(reported.report.self_intersecting_pairs, 0);

  s.self_intersections = io::SelfIntersections::kRemove;
  const CleanResult removed = Clean(m, s);
  ASSERT_GE(removed.report.self_intersecting_pairs, 0);
  if (removed.report.self_intersecting_pairs == 0) {
    EXPECT_TRUE(removed.report.self_intersections_removed);
  } else {
    EXPECT_FALSE(removed.report.self_intersections_removed);
    bool warned = false;
    for (const auto& w : removed.report.warnings) warned |= w.find("remove_self_intersections") != std::string::npos;
    EXPECT_TRUE(warned);
  }
  s.self_intersections = io::SelfIntersections::kOff;
  EXPECT_EQ(Clean(m, s).report.self_intersecting_pairs, -1);
}

TEST(Clean, HolesLargerThanTheLimitStayOpenWithAWarning) {
  io::TriMesh sphere = procedural::Icosphere(1.0, 4);
  procedural::PunchHole(sphere, {0, 0, 1}, 0.5);
  io::CleanupSettings s;
  s.decimate = false;
  s.max_hole_edges = 10;
  const CleanResult r = Clean(sphere, s);
  EXPECT_EQ(r.report.holes_filled, 0u);
  EXPECT_EQ(r.report.holes_left, 1u);
  EXPECT_FALSE(r.report.closed());
  EXPECT_GT(r.report.after.boundary_edges, 10u);
  ASSERT_FALSE(r.report.warnings.empty());
  EXPECT_NE(r.report.warnings.back().find("not closed"), std::string::npos);
}

}  // namespace
}  // namespace rime::clean
