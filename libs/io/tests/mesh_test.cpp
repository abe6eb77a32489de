#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <unistd.h>

#include "rime/core/error.h"
#include "rime/io/mesh.h"
#include "rime/test/files.h"
#include "rime/test/temp_folder.h"

namespace rime::io {
namespace {
namespace fs = std::filesystem;

/// One folder for the whole program, removed when it exits.
const fs::path& TempDir() {
  static const rime::test::TempFolder dir("mesh");
  return dir.path();
}

/// Runs ReadMesh and returns the error text (fails the test if it succeeds) and the exit code.
std::pair<std::string, ExitCode> ReadError(const fs::path& path) {
  try {
    ReadMesh(path);
  } catch (const Error& e) {
    return {e.what(), e.code()};
  }
  ADD_FAILURE() << "accepted " << path;
  return {"", ExitCode::kOk};
}

TriMesh Tetrahedron(bool with_velocity) {
  TriMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1.5f}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  if (with_velocity) m.velocities = {{1, 2, 3}, {-1, 0.5f, 0}, {0, 0, -9.81f}, {0.125f, 0.25f, 1e-3f}};
  return m;
}

void ExpectSameGeometry(const TriMesh& a, const TriMesh& b) {
  ASSERT_EQ(a.positions.size(), b.positions.size());
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (std::size_t i = 0; i < a.positions.size(); ++i) EXPECT_EQ(a.positions[i], b.positions[i]) << i;
  for (std::size_t i = 0; i < a.triangles.size(); ++i) EXPECT_EQ(a.triangles[i], b.triangles[i]) << i;
}

TEST(Mesh, ObjRoundTripKeepsPositionsAndWritesNormals) {
  const fs::path path = TempDir() / "tet.obj";
  const TriMesh in = Tetrahedron(false);
  WriteMesh(path, in);
  const TriMesh out = ReadMesh(path);
  ExpectSameGeometry(in, out);
  ASSERT_EQ(out.normals.size(), in.positions.size());
  // Vertex 3 (apex on +z) touches faces with outward normals -y, +(1,1,?), -x: its area-weighted
  // normal points away from the centroid.
  const Vec3f centroid(0.25f, 0.25f, 0.375f);
  for (std::size_t v = 0; v < out.positions.size(); ++v) {
    EXPECT_NEAR(Norm(out.normals[v]), 1.0f, 1e-5f);
    EXPECT_GT(Dot(out.normals[v], out.positions[v] - centroid), 0.0f) << v;
  }
}

TEST(Mesh, PlyRoundTripKeepsVelocityBitExact) {
  const fs::path path = TempDir() / "tet.ply";
  TriMesh in = Tetrahedron(true);
  in.normals = {{0, 0, 1}, {1, 0, 0}, {0, 1, 0}, {0.6f, 0.8f, 0}};
  WriteMesh(path, in);
  const TriMesh out = ReadMesh(path);
  ExpectSameGeometry(in, out);
  ASSERT_EQ(out.velocities.size(), in.velocities.size());
  ASSERT_EQ(out.normals.size(), in.normals.size());
  for (std::size_t i = 0; i < in.velocities.size(); ++i) {
    EXPECT_EQ(out.velocities[i], in.velocities[i]);
    EXPECT_EQ(out.normals[i], in.normals[i]);
  }
  // Without velocities no vx property is written.
  const fs::path plain = TempDir() / "plain.ply";
  WriteMesh(plain, Tetrahedron(false));
  EXPECT_TRUE(ReadMesh(plain).velocities.empty());
}

TEST(Mesh, EmptyMeshGivesValidEmptyFile) {
  for (const char* name : {"empty.obj", "empty.ply"}) {
    const fs::path path = TempDir() / name;
    WriteMesh(path, TriMesh{});
    ASSERT_TRUE(fs::exists(path));
    const TriMesh m = ReadMesh(path);
    EXPECT_TRUE(m.empty());
    EXPECT_EQ(m.vertex_count(), 0u);
  }
}

TEST(Mesh, ObjPolygonsCornerFormsAndNegativeIndices) {
  const fs::path path = TempDir() / "quad.obj";
  test::WriteFile(path,
                  "# a quad and a pentagon\n"
                  "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv +2 0.5 -1e-1\n"
                  "vt 0 0\nvn 0 0 1\nvn 0 0 -1\n"
                  "o thing\ng group\ns off\n"
                  "f 1/1/1 2/1/1 3/1/1 4/1/1\n"
                  "f -5//2 -4//2 -3//2 -2//2 -1//2\n"
                  "f 1/1 2/1 5/1\n");
  const TriMesh m = ReadMesh(path);
  ASSERT_EQ(m.vertex_count(), 5u);
  EXPECT_EQ(m.positions[4], Vec3f(2, 0.5f, -0.1f));
  // Quad -> 2 fan triangles, pentagon -> 3, triangle -> 1.
  ASSERT_EQ(m.triangle_count(), 6u);
  EXPECT_EQ(m.triangles[0], (std::array<std::uint32_t, 3>{0, 1, 2}));
  EXPECT_EQ(m.triangles[1], (std::array<std::uint32_t, 3>{0, 2, 3}));
  EXPECT_EQ(m.triangles[4], (std::array<std::uint32_t, 3>{0, 3, 4}));
  ASSERT_EQ(m.normals.size(), 5u);
  EXPECT_EQ(m.normals[4], Vec3f(0, 0, -1));  // last reference wins
}

TEST(Mesh, AsciiPlyWithQuadsAndExtraProperties) {
  const fs::path path = TempDir() / "ascii.ply";
  test::WriteFile(path,
                  "ply\nformat ascii 1.0\ncomment made by hand\n"
                  "element vertex 4\nproperty double x\nproperty double y\nproperty double z\n"
                  "property uchar red\nproperty float vx\nproperty float vy\nproperty float vz\n"
                  "element face 1\nproperty list uchar uint vertex_indices\nproperty int flags\n"
                  "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                  "end_header\n"
                  "0 0 0 255 1 0 0\n1 0 0 0 2 0 0\n1 1 0 0 3 0 0\n0 1 0 0 4 0 0\n"
                  "4 0 1 2 3 7\n"
                  "0 1\n");
  const TriMesh m = ReadMesh(path);
  ASSERT_EQ(m.vertex_count(), 4u);
  ASSERT_EQ(m.triangle_count(), 2u);
  ASSERT_EQ(m.velocities.size(), 4u);
  EXPECT_EQ(m.velocities[3], Vec3f(4, 0, 0));
  EXPECT_TRUE(m.normals.empty());
}

TEST(Mesh, MissingFileIsInputError) {
  const auto [what, code] = ReadError(TempDir() / "nope.obj");
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(what.find("nope.obj"), std::string::npos) << what;
  EXPECT_NE(what.find("not found"), std::string::npos) << what;
}

TEST(Mesh, NanCoordinateNamesFileAndLine) {
  const fs::path path = TempDir() / "nan.obj";
  test::WriteFile(path, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
  const auto [what, code] = ReadError(path);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(what.find("nan.obj:3"), std::string::npos) << what;
  EXPECT_NE(what.find("NaN"), std::string::npos) << what;
}

TEST(Mesh, NanInBinaryPlyNamesVertex) {
  const fs::path path = TempDir() / "nan.ply";
  TriMesh m = Tetrahedron(false);
  m.positions[2].y = std::nanf("");
  WriteMesh(path, m);  // the writer does not judge; the reader must
  const auto [what, code] = ReadError(path);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(what.find("vertex 2"), std::string::npos) << what;
}

TEST(Mesh, IndexOutOfRange) {
  const fs::path obj = TempDir() / "range.obj";
  test::WriteFile(obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n");
  auto [what, code] = ReadError(obj);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(what.find("range.obj:5"), std::string::npos) << what;
  EXPECT_NE(what.find("out of range"), std::string::npos) << what;

  const fs::path ply = TempDir() / "range.ply";
  test::WriteFile(ply,
                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  std::tie(what, code) = ReadError(ply);
  EXPECT_EQ(code, ExitCode::kBadInput);
  EXPECT_NE(what.find("face 0"), std::string::npos) << what;
}

TEST(Mesh, TruncatedBinaryPly) {
  const fs::path path = TempDir() / "cut.ply";
  WriteMesh(path, Tetrahedron(true));
  const auto full = fs::file_size(path);
  for (const std::uintmax_t cut : {std::uintmax_t(5), std::uintmax_t(30)}) {
    fs::resize_file(path, full - cut);
    const auto [what, code] = ReadError(path);
    EXPECT_EQ(code, ExitCode::kBadInput);
    EXPECT_NE(what.find("truncated"), std::string::npos) << what;
    EXPECT_NE(what.find("cut.ply"), std::string::npos) << what;
    WriteMesh(path, Tetrahedron(true));
  }
}

TEST(Mesh, GarbageAndUnsupported) {
  const fs::path junk = TempDir() / "junk.ply";
  test::WriteFile(junk, "this is not a ply file\n");
  EXPECT_EQ(ReadError(junk).second, ExitCode::kBadInput);
  const fs::path stl = TempDir() / "a.stl";
  test::WriteFile(stl, "solid x\n");
  EXPECT_NE(ReadError(stl).first.find("unsupported"), std::string::npos);
  const fs::path bad_face = TempDir() / "bad_face.obj";
  test::WriteFile(bad_face, "v 0 0 0\nv 1 0 0\nf 1 2\n");
  EXPECT_NE(ReadError(bad_face).first.find("bad_face.obj:3"), std::string::npos);
}

TEST(Mesh, LargeGridRoundTripsThroughBothFormats) {
  // A 200x200 grid (80k triangles) written and read back: same topology, positions within float
  // round trip (OBJ prints shortest round-trip decimal, so exact).
  TriMesh m;
  const int n = 200;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.positions.push_back({i * 0.013f, j * 0.017f, std::sin(i * 0.1f) * 0.3f});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const std::uint32_t a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      m.triangles.push_back({a, b, d});
      m.triangles.push_back({a, d, c});
    }
  for (const char* name : {"grid.obj", "grid.ply"}) {
    const fs::path path = TempDir() / name;
    WriteMesh(path, m);
    ExpectSameGeometry(m, ReadMesh(path));
  }
}

}  // namespace
}  // namespace rime::io
