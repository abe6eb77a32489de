/// @file bake_graph.h
/// @brief The bake as a graph of jobs: boundary → sim → surface → clean (→ preview), one job
/// per frame for the per-frame stages. Each job knows its command, the scene sections it reads and
/// its input and output files; bake_runner.h decides which are stale and runs them.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "scene_document.h"

namespace rime::bake {

/// In pipeline order: a target runs every stage up to and including it.
enum class Stage { kBoundary = 0, kSim = 1, kSurface = 2, kClean = 3, kPreview = 4 };
constexpr int kStageCount = 5;
const char* StageName(Stage stage);
/// A stage by its name; nullopt for an unknown name. A former name (cleanup, simulate, simulation)
/// is a usage error naming the current one.
std::optional<Stage> ParseStage(const std::string& name);

struct Job {
  Stage stage = Stage::kBoundary;
  std::int64_t frame = -1;        // -1 for whole-scene jobs
  std::string id;                 // "sim", "surface.0012": state key and log name
  std::filesystem::path program;  // resolved executable
  std::string tool_name;          // "rime-surface", "blender"
  std::vector<std::string> args;  // argv after the program
  /// Arguments that do not change results (-j, --device, --resume) are left out of the key.
  std::vector<std::string> key_args;
  std::vector<std::string> sections;                   // scene sections (dotted names) the tool reads
  std::vector<std::filesystem::path> inputs;           // must exist; their content is part of the key
  std::vector<std::filesystem::path> optional_inputs;  // part of the key when present (water meshes)
  std::vector<std::filesystem::path> outputs;          // must exist after success
  std::vector<std::string> dependencies;               // ids of jobs that produce the inputs
  std::filesystem::path log;
  bool exclusive = false;  // runs alone (the simulation uses every core itself)
  bool resumable = false;  // the simulation: `--resume` continues an interrupted run
  /// Cleanup: a frame whose mesh has no triangles (no ice yet) has nothing to clean; the tool is
  /// not run (rime-clean refuses empty meshes) and the frame gets no cleaned mesh.
  bool skip_when_input_mesh_empty = false;
  std::filesystem::path resume_folder;  // cleared before a non-resumed rerun
};

struct BakeLayout {
  std::filesystem::path scene_file;
  std::filesystem::path output;  // out/<scene name>
  std::filesystem::path cache() const { return output / "cache"; }
  std::filesystem::path state_folder() const { return cache() / ".rime-bake"; }
  std::filesystem::path logs() const { return cache() / "logs"; }
  std::filesystem::path boundary() const { return cache() / "boundary"; }
  std::filesystem::path sim() const { return cache() / "sim"; }
  std::filesystem::path surface() const { return output / "surface"; }
  std::filesystem::path clean() const { return output / "clean"; }
  std::filesystem::path preview() const { return output / "preview"; }
};

struct GraphOptions {
  std::filesystem::path tools_folder;                    // where rime-boundary, rime-sim, ... live
  std::int64_t first_frame = 0, last_frame = INT64_MAX;  // --frames, for per-frame stages
  int cpu_threads = 0;                                   // threads given to each per-frame tool (0: all cores)
  std::string device = "auto";
  std::optional<std::filesystem::path> blender, ffmpeg;  // preview tools, when found
  /// --memory-budget in bytes (0: not given; each tool then uses the memory available when it
  /// starts). Per-frame tools get their share: the budget divided by the frames run at once.
  std::uint64_t memory_budget = 0;
  int parallel_frames = 1;
  std::filesystem::path sandbox;  // --sandbox, passed to every stage tool ("" = off)
};

/// All jobs of stages up to `target`, in an order where dependencies come first. Preview jobs are
/// only added when Blender was found. Throws rime::Error (exit 3) when a needed stage tool is missing.
std::vector<Job> BuildGraph(const SceneDocument& doc, const BakeLayout& layout, const GraphOptions& options, Stage target);

/// Scene sections (dotted names) each stage's tool reads; the simulation reads every section except
/// those that only later stages read. One place for this table: README.md documents it.
std::vector<std::string> SectionsReadBy(Stage stage, const SceneDocument& doc);

}  // namespace rime::bake
