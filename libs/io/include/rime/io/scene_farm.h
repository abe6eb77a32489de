/// @file scene_farm.h
/// @brief `[farm]`: settings for baking on a Slurm cluster (docs/farm.md), in a site file and/or the
/// scene. LoadScene skips the table; `rime-bake --farm` loads it, the scene's keys over the site file's.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "rime/io/param.h"

namespace rime::io {

struct FarmSettings {
  std::string partition;
  std::string sim_partition;
  std::string account;
  std::string qos;
  int chunk = 1;
  int stream_tasks = 4;
  int cpus_per_task = 1;
  int sim_cpus_per_task = 0;
  bool gpus = false;
  std::string gpu_gres = "gpu:1";
  std::vector<std::string> sbatch_lines;
  std::string bin_dir;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    static constexpr std::string_view kName = "[A-Za-z0-9_.,:+-]+";
    f(Param{.name = "partition",
            .help = "`--partition` of every job; empty: the cluster's default",
            .pattern = kName,
            .accepted = "a partition name (or comma-separated list)"},
      s.partition);
    f(Param{.name = "sim_partition",
            .help = "`--partition` of the simulation job (often a GPU partition); empty: `partition`",
            .pattern = kName,
            .accepted = "a partition name (or comma-separated list)"},
      s.sim_partition);
    f(Param{.name = "account", .help = "`--account` of every job", .pattern = kName, .accepted = "an account name"}, s.account);
    f(Param{.name = "qos", .help = "`--qos` of every job", .pattern = kName, .accepted = "a QOS name"}, s.qos);
    f(Param{.name = "chunk", .unit = "frames", .range = Range::Closed(1, 100000), .help = "frames per array task of the per-frame stages"},
      s.chunk);
    f(Param{.name = "stream_tasks",
            .range = Range::Closed(0, 100000),
            .help = "surface tasks that may start while the simulation runs, each waiting for its frames; 0: the surface array "
                    "waits for the simulation to succeed"},
      s.stream_tasks);
    f(Param{.name = "cpus_per_task",
            .range = Range::Closed(1, 4096),
            .help = "`--cpus-per-task` of the per-frame and boundary tasks; the tools use exactly these CPUs"},
      s.cpus_per_task);
    f(Param{.name = "sim_cpus_per_task",
            .range = Range::Closed(0, 4096),
            .help = "`--cpus-per-task` of the simulation when it runs on CPUs; 0: `cpus_per_task`"},
      s.sim_cpus_per_task);
    f(Param{.name = "gpus", .help = "the simulation's partition has GPUs: request one when `--device` is `cuda` or `auto`"}, s.gpus);
    f(Param{.name = "gpu_gres",
            .help = "the simulation's GPU request (`--gres`)",
            .pattern = "[A-Za-z0-9_]+(:[A-Za-z0-9_.-]+)*(:[0-9]+)?",
            .accepted = "a GRES request such as gpu:1 or gpu:a100:1"},
      s.gpu_gres);
    f(Param{.name = "sbatch",
            .help = "extra `#SBATCH` options of every task, e.g. `[\"--constraint=avx2\"]`",
            .pattern = "-.*",
            .accepted = "one sbatch option (each entry is one line such as \"--constraint=avx2\")"},
      s.sbatch_lines);
    f(Param{.name = "bin_dir",
            .help = "folder of `rime-bake` and the stage tools as the nodes see it; empty: `rime-bake`'s own folder",
            .pattern = "/.*",
            .accepted = "an absolute path as the nodes see it"},
      s.bin_dir);
  }
};

/// `[farm.time]` and `[farm.memory]`: one Slurm value per stage; `default` replaces every stage
/// that the same table does not name (the scene's table over the site file's). Empty: the
/// partition's default.
template <class SlurmValue>
struct FarmPerStage {
  std::string all;
  std::string boundary;
  std::string sim;
  std::string surface;
  std::string clean;
  std::string preview;

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    const auto param = [](std::string_view name, std::string_view help) {
      return Param{.name = name, .help = help, .pattern = SlurmValue::kPattern, .accepted = SlurmValue::kAccepted};
    };
    f(param("default", "every stage this table does not name"), s.all);
    f(param("boundary", "the boundary job"), s.boundary);
    f(param("sim", "the simulation job"), s.sim);
    f(param("surface", "each surface task"), s.surface);
    f(param("clean", "each clean task"), s.clean);
    f(param("preview", "the preview job"), s.preview);
  }
};

struct SlurmTime {
  // Slurm's --time formats: M, M:S, H:M:S, D-H, D-H:M, D-H:M:S.
  static constexpr std::string_view kPattern = "[0-9]+(:[0-9]+){0,2}|[0-9]+-[0-9]+(:[0-9]+){0,2}";
  static constexpr std::string_view kAccepted = "a Slurm time limit (minutes, H:M:S or D-H:M:S)";
};
struct SlurmMemory {
  static constexpr std::string_view kPattern = "[0-9]+[KMGT]?";
  static constexpr std::string_view kAccepted = "a Slurm memory size (e.g. 4000M or 16G)";
};
using FarmTimes = FarmPerStage<SlurmTime>;     // [farm.time]: `--time`
using FarmMemory = FarmPerStage<SlurmMemory>;  // [farm.memory]: `--mem`

}  // namespace rime::io
