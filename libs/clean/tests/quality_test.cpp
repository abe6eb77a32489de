#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "rime/clean/procedural.h"
#include "rime/clean/quality.h"

namespace rime::clean {
namespace {

io::TriMesh UnitCube() {
  io::TriMesh m;
  for (int i = 0; i < 8; ++i) m.positions.push_back(Vec3f(float(i & 1), float((i >> 1) & 1), float((i >> 2) & 1)));
  // Outward, two triangles per face.
  m.triangles = {{0, 2, 3}, {0, 3, 1}, {4, 5, 7}, {4, 7, 6}, {0, 1, 5}, {0, 5, 4},
                 {2, 6, 7}, {2, 7, 3}, {0, 4, 6}, {0, 6, 2}, {1, 3, 7}, {1, 7, 5}};
  return m;
}

TEST(Quality, CubeIsClosedManifoldWithUnitVolume) {
  const MeshStats s = ComputeStats(UnitCube());
  EXPECT_EQ(s.faces, 12u);
  EXPECT_EQ(s.vertices, 8u);
  EXPECT_EQ(s.components, 1u);
  EXPECT_EQ(s.boundary_edges, 0u);
  EXPECT_EQ(s.non_manifold_edges, 0u);
  EXPECT_EQ(s.non_manifold_vertices, 0u);
  EXPECT_TRUE(s.closed());
  EXPECT_NEAR(s.volume, 1.0, 1e-12);
  EXPECT_NEAR(s.area, 6.0, 1e-12);
  EXPECT_NEAR(s.min_angle_deg, 45.0, 1e-9);
}

TEST(Quality, OpenNonManifoldAndDisconnected) {
  io::TriMesh m = UnitCube();
  m.triangles.pop_back();  // opens one face: 3 boundary edges
  MeshStats s = ComputeStats(m);
  EXPECT_EQ(s.boundary_edges, 3u);
  EXPECT_FALSE(s.closed());
  EXPECT_TRUE(s.manifold());

  // A fin on edge 0-3 (already shared by two triangles): one non-manifold edge.
  io::TriMesh fin = UnitCube();
  fin.positions.push_back({-1, -1, 2});
  fin.triangles.push_back({0, 3, 8});
  s = ComputeStats(fin);
  EXPECT_EQ(s.non_manifold_edges, 1u);
  EXPECT_FALSE(s.manifold());

  // Two cubes sharing only vertex 7 of the first: a non-manifold (bow-tie) vertex, one component.
  io::TriMesh pair = UnitCube();
  io::TriMesh second = UnitCube();
  for (Vec3f& p : second.positions) p += Vec3f(1, 1, 1);
  procedural::Append(pair, second);
  for (auto& t : pair.triangles)
    for (auto& v : t)
      if (v == 8) v = 7;  // weld second cube's vertex 0 (at (1,1,1)) to the first's vertex 7
  s = ComputeStats(pair);
  EXPECT_EQ(s.non_manifold_vertices, 1u);
  EXPECT_EQ(s.non_manifold_edges, 0u);
  EXPECT_EQ(s.components, 1u);

  io::TriMesh apart = UnitCube();
  second = UnitCube();
  for (Vec3f& p : second.positions) p += Vec3f(3, 0, 0);
  procedural::Append(apart, second);
  s = ComputeStats(apart);
  EXPECT_EQ(s.components, 2u);
  EXPECT_NEAR(s.volume, 2.0, 1e-9);
}

TEST(Quality, IcosphereConvergesToSphere) {
  const MeshStats s = ComputeStats(procedural::Icosphere(2.0, 5));
  EXPECT_EQ(s.faces, 20u * 1024u);
  EXPECT_TRUE(s.closed());
  EXPECT_TRUE(s.manifold());
  EXPECT_NEAR(s.volume, 4.0 / 3.0 * std::numbers::pi * 8, 4.0 / 3.0 * std::numbers::pi * 8 * 0.005);
  EXPECT_NEAR(s.area, 4 * std::numbers::pi * 4, 4 * std::numbers::pi * 4 * 0.005);
}

TEST(Quality, SurfaceNetsBallIsClosedOutward) {
  const io::TriMesh ball = procedural::NoisyBall(20000, 3);
  const MeshStats s = ComputeStats(ball);
  EXPECT_GT(s.faces, 14000u);
  EXPECT_LT(s.faces, 28000u);
  // Like marching cubes, surface nets leave an occasional non-manifold edge where two sheets of
  // the surface pass through one cell; the mesh is otherwise closed.
  EXPECT_LE(s.non_manifold_edges, s.faces / 1000);
  EXPECT_LE(s.boundary_edges, 4 * s.non_manifold_edges);
  EXPECT_EQ(s.components, 1u);
  // Outward: positive volume near the (noisy) sphere of radius 0.5.
  EXPECT_NEAR(s.volume, 4.0 / 3.0 * std::numbers::pi * 0.125, 4.0 / 3.0 * std::numbers::pi * 0.125 * 0.1);
}

}  // namespace
}  // namespace rime::clean
