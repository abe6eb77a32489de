// Whole objects: mesh files through assimp, procedural solids, the boundary file, bad input files,
// and the shared test meshes (bunny, teapot, armadillo).
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <assimp/Exporter.hpp>
#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>

#include "rime/boundary/object.h"
#include "rime/boundary/shapes.h"
#include "rime/core/error.h"
#include "rime/io/mesh.h"
#include "rime/test/files.h"
#include "rime/test/temp_folder.h"
#include "test_helpers.h"

namespace rime::boundary {
namespace {

namespace fs = std::filesystem;

io::SolidObject MeshObject(const fs::path& file) {
  io::SolidObject o;
  o.name = "thing";
  o.shape = rime::io::SolidShape::kMesh;
  o.mesh = file;
  return o;
}

TEST(BoundaryObject, ProceduralBoxWritesAReadableBoundaryFile) {
  io::SolidObject box;
  box.name = "tank";
  box.shape = rime::io::SolidShape::kBox;
  box.container = true;
  box.size = Vec3d(0.4, 0.3, 0.2);
  box.transform.translate = Vec3d(0, 0, 0.1);
  BoundarySettings settings;
  settings.particle_spacing = 0.02;
  const BoundaryObject object = BuildBoundaryObject(box, 3, {}, settings);
  ASSERT_GT(object.size(), 0u);
  EXPECT_DOUBLE_EQ(object.boundary_spacing, 0.01);
  EXPECT_NEAR(object.bounds_min.z, 0.0f, 1e-6f);
  EXPECT_NEAR(object.bounds_max.z, 0.2f, 1e-6f);
  EXPECT_GT(object.mean_spacing, 0.5 * 0.01);
  EXPECT_LE(object.mean_spacing, 0.01 * 1.0001);

  const rime::test::TempFolder dir("boundary_box");
  const fs::path file = dir / "tank.h5part";
  WriteBoundaryFile(file, object, "abc");
  const io::ParticleFrame frame = io::ReadParticleFrame(file, "boundary");
  ASSERT_EQ(frame.size(), object.size());
  EXPECT_DOUBLE_EQ(frame.spacing, 0.02);
  EXPECT_DOUBLE_EQ(frame.particle_radius, 0.01);
  EXPECT_DOUBLE_EQ(frame.numbers.at("boundary_spacing"), 0.01);
  EXPECT_DOUBLE_EQ(frame.numbers.at("smoothing_length"), 0.02);
  EXPECT_EQ(frame.texts.at("object_name"), "tank");
  EXPECT_EQ(frame.texts.at("shape"), "box");
  EXPECT_EQ(frame.texts.at("mesh_hash").size(), 16u);
  EXPECT_NE(frame.texts.at("transform").find("translate (0, 0, 0.1)"), std::string::npos);
  const auto& volume = frame.Get<float>("volume");
  const auto& phase = frame.Get<std::uint8_t>("phase");
  const auto& ids = frame.Get<std::uint32_t>("object_id");
  for (std::size_t i = 0; i < frame.size(); ++i) {
    ASSERT_GT(volume[i], 0.0f);
    ASSERT_LT(volume[i], 0.02f * 0.02f * 0.02f * 1.5f);  // far below pi h^3 for a particle with neighbours
    ASSERT_EQ(phase[i], 1);
    ASSERT_EQ(ids[i], 3u);
  }
  const auto normals = frame.GetVec3<float>("normal");
  EXPECT_NEAR(Norm(normals[7]), 1.0f, 1e-5f);
  EXPECT_EQ(frame.Get<std::int64_t>("id").back(), std::int64_t(frame.size() - 1));
}

TEST(BoundaryObject, MeshFileFormatsThroughAssimp) {
  const rime::test::TempFolder dir("boundary_formats");
  // One cube written as OBJ (quads), ASCII STL (triangle soup) and PLY; all give the same particles.
  test::WriteFile(dir / "cube.obj",
                  "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 1\n"
                  "f 1 3 4 2\nf 5 6 8 7\nf 1 2 6 5\nf 3 7 8 4\nf 1 5 7 3\nf 2 4 8 6\n");
  io::WriteMesh(dir / "cube.ply", test_support::UnitCube());
  std::string stl = "solid cube\n";
  const io::TriMesh cube = test_support::UnitCube();
  for (const auto& t : cube.triangles) {
    stl += " facet normal 0 0 0\n  outer loop\n";
    for (int k = 0; k < 3; ++k) {
      const Vec3f& p = cube.positions[t[k]];
      stl += "   vertex " + std::to_string(p.x) + " " + std::to_string(p.y) + " " + std::to_string(p.z) + "\n";
    }
    stl += "  endloop\n endfacet\n";
  }
  test::WriteFile(dir / "cube.stl", stl + "endsolid cube\n");
  BoundarySettings settings;
  settings.particle_spacing = 0.2;  // d_b = 0.1
  std::size_t expected = 0;
  // glTF, GLB, FBX and binary STL/PLY written by assimp's exporter from the OBJ.
  {
    Assimp::Importer importer;
    const aiScene* scene = importer.ReadFile((dir / "cube.obj").string(), aiProcess_Triangulate);
    ASSERT_NE(scene, nullptr) << importer.GetErrorString();
    Assimp::Exporter exporter;
    for (const auto& [format, name] : {std::pair{"gltf2", "cube.gltf"}, std::pair{"glb2", "cube.glb"}, std::pair{"fbxa", "cube.fbx"},
                                       std::pair{"stlb", "cube_binary.stl"}, std::pair{"plyb", "cube_binary.ply"}})
      ASSERT_EQ(exporter.Export(scene, format, (dir / name).string()), AI_SUCCESS) << format << ": " << exporter.GetErrorString();
  }
  for (const char* name : {"cube.obj", "cube.ply", "cube.stl", "cube.gltf", "cube.glb", "cube.fbx", "cube_binary.stl", "cube_binary.ply"}) {
    SCOPED_TRACE(name);
    const BoundaryObject o = BuildBoundaryObject(MeshObject(dir / name), 0, dir / name, settings);
    EXPECT_EQ(o.stats.triangles, 12u);
    EXPECT_EQ(o.stats.vertex_samples, 8u);
    if (expected == 0) expected = o.size();
    EXPECT_EQ(o.size(), expected);
    EXPECT_EQ(o.mesh_hash.size(), 16u);
  }
}

TEST(BoundaryObject, MultiMeshFilesMergeUnlessAskedOtherwise) {
  const rime::test::TempFolder dir("boundary_parts");
  // Two named objects with the same triangle, 1 mm apart: merged, the copy is removed as a
  // near-duplicate; kept apart, both layers stay.
  test::WriteFile(dir / "two.obj", "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\no b\nv 0 0 0.001\nv 1 0 0.001\nv 0 1 0.001\nf 4 5 6\n");
  io::SolidObject object = MeshObject(dir / "two.obj");
  BoundarySettings settings;
  settings.particle_spacing = 0.1;
  const BoundaryObject merged = BuildBoundaryObject(object, 0, dir / "two.obj", settings);
  object.merge_meshes = false;
  const BoundaryObject separate = BuildBoundaryObject(object, 0, dir / "two.obj", settings);
  EXPECT_EQ(merged.meshes, 2u);
  EXPECT_EQ(separate.meshes, 2u);
  EXPECT_EQ(separate.size(), 2 * merged.size());
  EXPECT_EQ(merged.stats.near_duplicates_removed, merged.size());
  EXPECT_EQ(separate.stats.near_duplicates_removed, 0u);
}

void ExpectBadFile(const fs::path& file, const std::string& fragment, double spacing = 0.02, std::uint64_t max_particles = 50'000'000) {
  BoundarySettings settings;
  settings.particle_spacing = spacing;
  settings.max_particles = max_particles;
  try {
    BuildBoundaryObject(MeshObject(file), 0, file, settings);
    ADD_FAILURE() << "expected an error for " << file;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(file.filename().string()), std::string::npos) << e.what();
  }
}

TEST(BoundaryObject, BadInputFiles) {
  const rime::test::TempFolder dir("boundary_bad");
  const std::string cube = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  test::WriteFile(dir / "good.obj", cube);
  ExpectBadFile(dir / "missing.obj", "not found");
  test::WriteFile(dir / "points.xyz", "1 2 3\n");
  ExpectBadFile(dir / "points.xyz", "unsupported mesh format");
  test::WriteFile(dir / "garbage.fbx", "this is not an fbx file");
  ExpectBadFile(dir / "garbage.fbx", "cannot read");
  test::WriteFile(dir / "vertices.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
  ExpectBadFile(dir / "vertices.obj", "no triangles");
  test::WriteFile(dir / "nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
  ExpectBadFile(dir / "nan.obj", "NaN or infinite");
  test::WriteFile(dir / "inf.obj", "v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n");
  ExpectBadFile(dir / "inf.obj", "NaN or infinite");
  ExpectBadFile(dir / "good.obj", "spacing", 0);
  ExpectBadFile(dir / "good.obj", "spacing", -0.1);
  ExpectBadFile(dir / "good.obj", "more than the maximum", 1e-5);
  ExpectBadFile(dir / "good.obj", "more than the maximum", 0.02, 1000);
}

// The shared test meshes sample without error at spacings tied to their size; the counts go to
// the test log.
TEST(BoundaryObject, SharedMeshes) {
  const fs::path meshes = fs::path(RIME_SHARED_DIR) / "meshes";
  if (!fs::exists(meshes)) GTEST_SKIP() << "shared test meshes not found at " << meshes << " (../shared/meshes beside the project)";
  struct Case {
    const char* file;
    double size;  // about the largest extent, m
  };
  for (const Case c : {Case{"stanford-bunny.obj", 0.16}, Case{"teapot.obj", 6.4}, Case{"armadillo-lowres.obj", 1.0}}) {
    SCOPED_TRACE(c.file);
    const fs::path file = meshes / c.file;
    if (!fs::exists(file)) GTEST_SKIP() << file << " is missing";
    io::SolidObject object = MeshObject(file);
    object.transform.up_axis = rime::io::UpAxis::kY;
    BoundarySettings settings;
    settings.particle_spacing = c.size / 100;  // about 200 boundary particles across the object
    const BoundaryObject o = BuildBoundaryObject(object, 0, file, settings);
    ASSERT_GT(o.size(), 1000u);
    const double db = o.boundary_spacing;
    const auto nearest = NearestNeighborDistances(o.positions, float(3 * db));
    float min_nn = INFINITY;
    for (float r : nearest) min_nn = std::min(min_nn, r);
    EXPECT_GE(min_nn, 0.5 * db * (1 - 1e-5));
    for (float v : o.volumes) ASSERT_TRUE(std::isfinite(v) && v > 0);
    std::printf(
        "%s: %zu triangles (%zu degenerate skipped), %zu vertex + %zu edge + %zu face samples, %zu near-duplicates "
        "removed -> %zu particles at d_b = %.4g m, mean spacing %.3f d_b\n",
        c.file, o.stats.triangles, o.stats.degenerate_skipped, o.stats.vertex_samples, o.stats.edge_samples, o.stats.face_samples,
        o.stats.near_duplicates_removed, o.size(), db, o.mean_spacing / db);
    RecordProperty(std::string(c.file) + "_particles", std::to_string(o.size()));
  }
}

}  // namespace
}  // namespace rime::boundary
