// Writes the seed inputs that only Rime's own writers make (HDF5 frames, boundary files, binary
// PLY, state.json) into tests/fuzz/corpus/<target>/; the text seeds there are written by hand.
//   rime_fuzz_seeds tests/fuzz/corpus
#include <cstdio>
#include <filesystem>

#include "bake_state.h"
#include "rime/boundary/object.h"
#include "rime/core/atomic_file.h"
#include "rime/io/mesh.h"
#include "rime/io/particles.h"

namespace fs = std::filesystem;
using namespace rime;

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s CORPUS_FOLDER\n", argv[0]);
    return 2;
  }
  const fs::path corpus(argv[1]);
  for (const char* t : {"particle_frame", "boundary_file", "mesh_import", "clean_mesh", "bake_state"}) fs::create_directories(corpus / t);

  // A simulation frame of three particles as rime-sim writes it, compressed and not.
  io::ParticleFrame frame;
  frame.time = 0.5;
  frame.frame = 12;
  frame.spacing = 0.02;
  frame.particle_radius = 0.01;
  frame.scene_hash = "0123456789abcdef";
  frame.numbers["ice_count"] = 1;
  frame.texts["scene_name"] = "seed";
  frame.SetPositions(std::vector<Vec3f>{{0, 0, 0}, {0.02f, 0, 0}, {0, 0.02f, 0.5f}});
  frame.SetVec3("v", std::vector<Vec3f>{{0, 0, -1}, {0, 0, 0}, {1, 0, 0}});
  frame.Set("phase", std::vector<std::uint8_t>{0, 0, 2});
  frame.Set("id", std::vector<std::int64_t>{0, 1, 2});
  frame.Set("density", std::vector<double>{1000, 1001, 999});
  io::WriteParticleFrame(corpus / "particle_frame" / "particles_3.h5part", frame, {.compression_level = 1});
  io::WriteParticleFrame(corpus / "particle_frame" / "particles_3_plain.h5part", frame, {.compression_level = 0});
  io::ParticleFrame empty;
  io::WriteParticleFrame(corpus / "particle_frame" / "particles_empty.h5part", empty);

  // A boundary file as rime-boundary writes it: a small procedural box.
  io::SolidObject box;
  box.name = "box";
  box.size = {0.1, 0.1, 0.1};
  boundary::BoundarySettings settings;
  settings.particle_spacing = 0.1;
  const boundary::BoundaryObject object = boundary::BuildBoundaryObject(box, 0, {}, settings);
  io::WriteParticleFrame(corpus / "boundary_file" / "box.h5part", boundary::ToParticleFrame(object, "0123456789abcdef"),
                         {.compression_level = 0});  // uncompressed: a smaller seed; particle_frame has a compressed one

  // A tetrahedron with normals and velocities, in both of Rime's mesh formats.
  io::TriMesh tetra;
  tetra.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tetra.velocities = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  tetra.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  for (const char* t : {"mesh_import", "clean_mesh"}) {
    io::WriteMesh(corpus / t / "tetra.ply", tetra);
    io::WriteMesh(corpus / t / "tetra.obj", tetra);
  }

  // A bake state with one job, as rime-bake saves it.
  const fs::path out = fs::temp_directory_path() / "rime-fuzz-seeds";
  fs::create_directories(out / "boundary");
  WriteFileAtomically(out / "boundary" / "box.h5part", "boundary particles");
  bake::BakeState state(out, out / ".rime-bake" / "state.json");
  bake::JobRecord record;
  record.key = "0123456789abcdef";
  record.components = {{"tool", "rime-boundary 0.1.0"}, {"scene:solid", "fedcba9876543210"}};
  record.outputs = {{state.Name(out / "boundary" / "box.h5part"), *state.ContentHash(out / "boundary" / "box.h5part")}};
  record.seconds = 1.5;
  state.SetRecord("boundary", record);
  state.Save();
  fs::copy_file(out / ".rime-bake" / "state.json", corpus / "bake_state" / "state.json", fs::copy_options::overwrite_existing);
  fs::remove_all(out);
  return 0;
}
