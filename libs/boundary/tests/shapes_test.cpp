// Procedural solids and transforms: analytic surface, outward (or inward) normals, sampling quality.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <numbers>
#include <random>

#include "rime/boundary/sampler.h"
#include "rime/boundary/shapes.h"
#include "rime/core/error.h"
#include "test_helpers.h"

namespace rime::boundary {
namespace {

constexpr double kPi = std::numbers::pi;

Vec3d Normalized(const Vec3d& v) { return v / Norm(v); }

double SignedVolume(const io::TriMesh& m) {  // divergence theorem; > 0 for outward winding
  double v = 0;
  for (const auto& t : m.triangles) v += Dot(Vec3d(m.positions[t[0]]), Cross(Vec3d(m.positions[t[1]]), Vec3d(m.positions[t[2]]))) / 6;
  return v;
}
double Area(const io::TriMesh& m) {
  double a = 0;
  for (const auto& t : m.triangles)
    a += 0.5 * Norm(Cross(Vec3d(m.positions[t[1]] - m.positions[t[0]]), Vec3d(m.positions[t[2]] - m.positions[t[0]])));
  return a;
}

struct Analytic {
  std::function<double(const Vec3d&)> distance;  // signed distance to the exact surface
  std::function<Vec3d(const Vec3d&)> normal;     // outward unit normal at a surface point
};

// Particles lie on the exact surface, normals match it, spacing within [0.5, 1.5] d_b, and random
// points of the tessellated surface are within d_b of a particle.
void CheckSampledShape(const io::TriMesh& mesh, const Analytic& exact, double db, double area, double volume,
                       double min_normal_dot = 0.95) {
  EXPECT_NEAR(Area(mesh), area, 0.01 * area);
  if (volume > 0) {
    EXPECT_NEAR(SignedVolume(mesh), volume, 0.01 * volume);
  }
  SampleOptions options;
  options.spacing = db;
  const SurfaceSamples s = SampleSurface(mesh, options);
  EXPECT_EQ(s.stats.degenerate_skipped, 0u);
  double worst_distance = 0, worst_normal = 1;
  for (std::size_t i = 0; i < s.size(); ++i) {
    const Vec3d p(s.positions[i]);
    worst_distance = std::max(worst_distance, std::abs(exact.distance(p)));
    worst_normal = std::min(worst_normal, Dot(Vec3d(s.normals[i]), exact.normal(p)));
  }
  EXPECT_LT(worst_distance, 0.05 * db);
  EXPECT_GT(worst_normal, min_normal_dot);
  const auto nearest = NearestNeighborDistances(s.positions, float(3 * db));
  for (float r : nearest) {
    EXPECT_GE(r, 0.5 * db * (1 - 1e-5));
    EXPECT_LE(r, 1.5 * db);
  }
  const auto gaps = test_support::DistanceToNearestParticle(s.positions, test_support::RandomSurfacePoints(mesh, 20000), float(3 * db));
  float worst_gap = 0;
  for (float g : gaps) worst_gap = std::max(worst_gap, g);
  EXPECT_LE(worst_gap, db);
  // Close to one particle per d_b^2 of surface (tessellation spacing is at most d_b).
  EXPECT_GT(double(s.size()) * db * db / area, 0.9);
  EXPECT_LT(double(s.size()) * db * db / area, 1.6);
}

TEST(Shapes, Sphere) {
  const double r = 0.3, db = 0.01;
  CheckSampledShape(MakeSphere(r, db), {[&](const Vec3d& p) { return Norm(p) - r; }, [](const Vec3d& p) { return p / Norm(p); }}, db,
                    4 * kPi * r * r, 4.0 / 3 * kPi * r * r * r);
}

TEST(Shapes, Cylinder) {
  const double r = 0.2, height = 0.5, db = 0.012;
  const auto distance = [&](const Vec3d& p) {
    const double radial = std::hypot(p.x, p.y) - r, axial = std::abs(p.z) - 0.5 * height;
    return std::max(radial, axial);  // exact on and near the surface
  };
  const auto normal = [&](const Vec3d& p) {
    const double radial = std::hypot(p.x, p.y);
    const bool on_cap = std::abs(std::abs(p.z) - 0.5 * height) < 1e-6;
    const bool on_side = std::abs(radial - r) < 1e-4;
    if (on_cap && on_side) return Normalized(Vec3d(p.x / radial, p.y / radial, p.z > 0 ? 1 : -1));  // rim: average
    if (on_cap) return Vec3d(0, 0, p.z > 0 ? 1 : -1);
    return Vec3d(p.x / radial, p.y / radial, 0);
  };
  CheckSampledShape(MakeCylinder(r, height, db), {distance, normal}, db, 2 * kPi * r * (r + height), kPi * r * r * height);
}

TEST(Shapes, Torus) {
  const double R = 0.4, r = 0.1, db = 0.01;
  const auto distance = [&](const Vec3d& p) { return std::hypot(std::hypot(p.x, p.y) - R, p.z) - r; };
  const auto normal = [&](const Vec3d& p) {
    const double rho = std::hypot(p.x, p.y);
    const Vec3d center(p.x / rho * R, p.y / rho * R, 0);
    return Normalized(p - center);
  };
  CheckSampledShape(MakeTorus(R, r, db), {distance, normal}, db, 4 * kPi * kPi * R * r, 2 * kPi * kPi * R * r * r);
}

TEST(Shapes, BoxPlaneAndContainer) {
  const Vec3d size(0.6, 0.4, 0.3);
  const double db = 0.013;
  const auto box_distance = [&](const Vec3d& p) {
    double d = -1e30;
    for (int a = 0; a < 3; ++a) d = std::max(d, std::abs(p[a]) - 0.5 * size[a]);
    return d;
  };
  const auto box_normal = [&](const Vec3d& p) {
    Vec3d n(0, 0, 0);
    for (int a = 0; a < 3; ++a)
      if (std::abs(std::abs(p[a]) - 0.5 * size[a]) < 1e-6) n[a] = p[a] > 0 ? 1 : -1;
    return Normalized(n);
  };
  const double area = 2 * (size.x * size.y + size.y * size.z + size.z * size.x);
  // On box edges and corners the area-weighted vertex normal leans towards the face whose grid
  // triangles around that vertex are larger, so it is only close to the symmetric bisector.
  CheckSampledShape(MakeBox(size, false, db), {box_distance, box_normal}, db, area, size.x * size.y * size.z, 0.9);
  CheckSampledShape(MakePlane(0.5, 0.2, db), {[](const Vec3d& p) { return p.z; }, [](const Vec3d&) { return Vec3d(0, 0, 1); }}, db, 0.1, 0);

  // Container: no top face, every normal faces the inside.
  const io::TriMesh tank = MakeBox(size, true, db);
  EXPECT_NEAR(Area(tank), area - size.x * size.y, 1e-6);
  SampleOptions options;
  options.spacing = db;
  const SurfaceSamples s = SampleSurface(tank, options);
  for (std::size_t i = 0; i < s.size(); ++i) {
    EXPECT_LT(s.positions[i].z, 0.5f * float(size.z) + 1e-6f);
    EXPECT_GT(Dot(s.normals[i], -s.positions[i]), 0.0f) << "normal of particle " << i << " points out of the tank";
  }
}

TEST(Shapes, RejectsBadDimensions) {
  EXPECT_THROW(MakeSphere(0, 0.01), Error);
  EXPECT_THROW(MakeBox(Vec3d(1, -1, 1), false, 0.01), Error);
  EXPECT_THROW(MakeTorus(0.1, 0.2, 0.01), Error);
  io::SolidObject mesh_object;
  mesh_object.shape = rime::io::SolidShape::kMesh;
  EXPECT_THROW(MakeProceduralMesh(mesh_object, 0.01), Error);
}

TEST(Transform, OrderUpAxisAndMirror) {
  io::Transform t;
  t.up_axis = rime::io::UpAxis::kY;
  EXPECT_NEAR(Norm(MakeTransform(t).Apply(Vec3d(0, 1, 0)) - Vec3d(0, 0, 1)), 0, 1e-12);  // y-up source: y becomes z
  EXPECT_NEAR(Norm(MakeTransform(t).Apply(Vec3d(0, 0, 1)) - Vec3d(0, -1, 0)), 0, 1e-12);
  // Scale, then rotate X, Y, Z, then translate.
  io::Transform u;
  u.scale = Vec3d(2, 1, 1);
  u.rotate_deg = Vec3d(0, 0, 90);
  u.translate = Vec3d(0, 0, 5);
  EXPECT_NEAR(Norm(MakeTransform(u).Apply(Vec3d(1, 0, 0)) - Vec3d(0, 2, 5)), 0, 1e-12);
  io::Transform xy;
  xy.rotate_deg = Vec3d(90, 90, 0);  // X first: z -> -y, then Y: -y stays -y
  EXPECT_NEAR(Norm(MakeTransform(xy).Apply(Vec3d(0, 0, 1)) - Vec3d(0, -1, 0)), 0, 1e-12);
  // A mirror keeps the winding outward.
  io::TriMesh sphere = MakeSphere(1.0, 0.2);
  io::Transform mirror;
  mirror.scale = Vec3d(-1, 1, 1);
  ApplyTransform(sphere, mirror);
  EXPECT_GT(SignedVolume(sphere), 0);
  EXPECT_NE(DescribeTransform(u).find("rotate (0, 0, 90)"), std::string::npos);
}

}  // namespace
}  // namespace rime::boundary
