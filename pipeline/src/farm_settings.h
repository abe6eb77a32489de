/// @file farm_settings.h
/// @brief Site settings for baking on a Slurm cluster: a `[farm]` table in a site file (named by
/// --farm-config or $RIME_FARM_CONFIG) and/or in the scene, the scene's keys taking precedence.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "bake_graph.h"

namespace rime::bake {

struct FarmSettings {
  std::string partition;      // empty: the cluster's default partition
  std::string sim_partition;  // for the simulation job (often a GPU partition); empty: `partition`
  std::string account, qos;
  /// Per stage, Slurm's `--time` and `--mem` values; empty: the partition's defaults.
  std::array<std::string, kStageCount> time{}, memory{};
  int chunk = 1;  // frames per array task of the per-frame stages
  /// Surface tasks that may start while the simulation runs, each waiting for its frames (the
  /// rest start once the simulation has ended); 0: the surface array waits for it to succeed.
  int stream_tasks = 4;
  int cpus_per_task = 1;      // per-frame and boundary tasks
  int sim_cpus_per_task = 0;  // the simulation when it runs on CPUs; 0: cpus_per_task
  bool gpus = false;          // the simulation's partition has GPUs
  std::string gpu_gres = "gpu:1";
  std::vector<std::string> sbatch_lines;  // extra `#SBATCH` options, e.g. "--constraint=avx2"
  std::string bin_dir;                    // folder of the Rime binaries on the nodes; empty: rime-bake's own folder
  std::vector<std::string> sources;       // files the settings came from, for messages
};

/// Site file first (when given), then the scene's `[farm]` table over it. Errors name
/// `file:line: farm.key` like every other scene section.
FarmSettings LoadFarmSettings(const std::optional<std::filesystem::path>& site_file, const std::filesystem::path& scene_file);

}  // namespace rime::bake
