/// @file entry_points.h
/// @brief One function per fuzzed reader, shared by the libFuzzer targets (fuzz_*.cpp, preset
/// "fuzz") and the regression test that replays tests/fuzz/regressions/ and corpus/ (preset "test").
///
/// Each takes the raw bytes of one input file and runs it through the reader as the tool does.
/// Returns normally or throws rime::Error for bad input; anything else (another exception, a
/// crash, a sanitizer report, a hang) is a finding.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace rime::fuzz {

using EntryPoint = void (*)(std::string_view bytes);

/// TOML text -> io::Scene with every check (io::ParseScene, as every tool loads its scene).
void Scene(std::string_view bytes);
/// A particle frame (H5Part) of any kind, header and datasets, as rime-surface and rime-inspect read it.
void ParticleFrame(std::string_view bytes);
/// A boundary file, read and unpacked as rime-sim does for each solid.
void BoundaryFile(std::string_view bytes);
/// An OBJ, PLY or STL file (chosen by its first bytes) imported and sampled as rime-boundary does.
void MeshImport(std::string_view bytes);
/// An OBJ or PLY file read by rime-clean's reader (io::ReadMesh), written back and read again.
void CleanMesh(std::string_view bytes);
/// A rime-bake state.json: loaded, saved and loaded again.
void BakeState(std::string_view bytes);

struct Target {
  const char* name;  // folder under tests/fuzz/corpus/ and tests/fuzz/regressions/
  EntryPoint run;
};
const std::vector<Target>& Targets();

/// Runs `entry` on the bytes, swallowing rime::Error (the expected refusal); for LLVMFuzzerTestOneInput.
int RunOne(EntryPoint entry, const unsigned char* data, std::size_t size);

}  // namespace rime::fuzz
