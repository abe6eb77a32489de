#include "entry_points.h"

#include <unistd.h>

#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "bake_state.h"
#include "rime/boundary/object.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/io/mesh.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime::fuzz {
namespace {

// The readers take paths, so every input goes through a file in a folder of this process, removed
// when it exits: in memory under /dev/shm where it exists, unless TMPDIR names a folder (CTest's
// for the tests, where the suite checks that nothing is left).
const fs::path& Folder() {
  static const rime::test::TempFolder folder("fuzz", [] {
    std::error_code ec;
    const bool tmpdir_set = std::getenv("TMPDIR") != nullptr;
    return !tmpdir_set && fs::is_directory("/dev/shm", ec) ? fs::path("/dev/shm") : fs::temp_directory_path();
  }());
  return folder.path();
}

fs::path WriteInput(std::string_view bytes, const std::string& name) {
  log::SetLevel(log::Level::kSilent);  // refusals are expected; their warnings would flood the fuzzer's output
  const fs::path path = Folder() / name;
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), std::streamsize(bytes.size()));
  if (!out.flush()) throw std::runtime_error("cannot write the fuzz input " + path.string());
  return path;
}

[[noreturn]] void Finding(const std::string& what) { throw std::logic_error(what); }

}  // namespace

void Scene(std::string_view bytes) {
  log::SetLevel(log::Level::kSilent);
  const io::Scene scene = io::ParseScene(std::string(bytes), "fuzz/scene.toml");
  if (scene.FrameCount() < 0 || scene.FrameCount() > io::kMaxSceneFrames) Finding("frame count out of the checked range");
}

void ParticleFrame(std::string_view bytes) {
  const fs::path path = WriteInput(bytes, "frame.h5part");
  const io::ParticleFrame header = io::ReadParticleFrameHeader(path);
  const io::ParticleFrame frame = io::ReadParticleFrame(path);
  if (frame.kind != header.kind) Finding("header and full read disagree on the kind");
  const auto positions = frame.GetPositions<double>();
  if (positions.size() != frame.size()) Finding("positions and datasets disagree on the count");
}

void BoundaryFile(std::string_view bytes) {
  const fs::path path = WriteInput(bytes, "boundary.h5part");
  const io::ParticleFrame frame = io::ReadParticleFrame(path, "boundary");
  // What rime-sim takes from it (sph::Simulation::AddBoundaryObject).
  const auto positions = frame.GetPositions<float>();
  if (frame.HasVec3("normal")) {
    const bool single = std::holds_alternative<std::vector<float>>(frame.attributes.at("normal_0"));
    const std::size_t n = single ? frame.GetVec3<float>("normal").size() : frame.GetVec3<double>("normal").size();
    if (n != positions.size()) Finding("normals and positions disagree on the count");
  }
}

void MeshImport(std::string_view bytes) {
  // The first bytes tell the format, as they would for a file named after it.
  std::string extension = ".obj";
  if (bytes.starts_with("ply")) extension = ".ply";
  else if (bytes.starts_with("solid")) extension = ".stl";
  else if (bytes.size() >= 84) {
    std::uint32_t triangles = 0;
    std::memcpy(&triangles, bytes.data() + 80, 4);
    if (bytes.size() == 84 + 50 * std::uint64_t(triangles)) extension = ".stl";
  }
  const fs::path path = WriteInput(bytes, "mesh" + extension);
  io::SolidObject solid;
  solid.name = "fuzz";
  solid.shape = rime::io::SolidShape::kMesh;
  solid.mesh = path;
  boundary::BoundarySettings settings;
  settings.particle_spacing = 0.1;  // d_b = 0.05 m: a unit cube gets about 2400 particles
  settings.max_particles = 20'000;  // keeps every input fast; larger estimates are refused before sampling
  const boundary::BoundaryObject object = boundary::BuildBoundaryObject(solid, 0, path, settings);
  if (object.size() > settings.max_particles || object.volumes.size() != object.size()) Finding("boundary object out of its limits");
}

void CleanMesh(std::string_view bytes) {
  const fs::path path = WriteInput(bytes, bytes.starts_with("ply") ? "mesh.ply" : "mesh.obj");
  const io::TriMesh mesh = io::ReadMesh(path);
  for (const auto& t : mesh.triangles)
    for (std::uint32_t v : t)
      if (v >= mesh.vertex_count()) Finding("triangle index out of range after ReadMesh");
  // rime-clean writes what it read (after repairs); the writer must take whatever the reader accepts.
  const fs::path copy = Folder() / "copy.ply";
  io::WriteMesh(copy, mesh);
  const io::TriMesh again = io::ReadMesh(copy);
  if (again.vertex_count() != mesh.vertex_count() || again.triangle_count() != mesh.triangle_count())
    Finding("PLY round trip changed the mesh");
}

void BakeState(std::string_view bytes) {
  const fs::path out = Folder() / "bake";
  const fs::path state_file = out / ".rime-bake" / "state.json";
  fs::create_directories(state_file.parent_path());
  WriteInput(bytes, "state.json");
  fs::rename(Folder() / "state.json", state_file);
  bake::BakeState state(out, state_file);
  state.Load();  // a corrupt file is reported and ignored
  state.Save();
  bake::BakeState reloaded(out, state_file);
  reloaded.Load();
}

const std::vector<Target>& Targets() {
  static const std::vector<Target> targets{
      {"scene", Scene},          {"particle_frame", ParticleFrame}, {"boundary_file", BoundaryFile}, {"mesh_import", MeshImport},
      {"clean_mesh", CleanMesh}, {"bake_state", BakeState}};
  return targets;
}

int RunOne(EntryPoint entry, const unsigned char* data, std::size_t size) {
  try {
    entry({reinterpret_cast<const char*>(data), size});
  } catch (const Error&) {
    // A clear refusal of bad input: what every reader must do.
  }
  return 0;
}

}  // namespace rime::fuzz
