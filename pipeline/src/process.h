/// @file process.h
/// @brief Runs one stage tool with its output captured in a log file, and finds executables.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace rime::bake {

/// Runs `program args...`, stdout and stderr appended to `log` (after a header line with the
/// command). Returns the exit status, or 128 + signal number when the tool was killed.
/// Each tool runs in a process group of its own, which gets SIGTERM when rime-bake receives
/// SIGINT/SIGTERM (see InstallSignalHandlers), and the tool alone SIGTERM when rime-bake dies.
int RunProcess(const std::filesystem::path& program, const std::vector<std::string>& args, const std::filesystem::path& log);

/// What a client program (sbatch, squeue) printed, and how it ended.
struct Captured {
  int code = 0;  // exit status, 128 + signal, or 127 when it could not be started
  std::string out, err;
};
/// Runs `program args...` to completion with stdout and stderr captured (argument vector, no shell).
Captured CaptureProcess(const std::filesystem::path& program, const std::vector<std::string>& args);

/// While alive, tools started by RunProcess inherit `fd` (the bake lock) across exec.
class ToolsInherit {
 public:
  explicit ToolsInherit(int fd);
  ~ToolsInherit();
  ToolsInherit(const ToolsInherit&) = delete;
  ToolsInherit& operator=(const ToolsInherit&) = delete;
};

/// Forwards SIGINT/SIGTERM to running tools and records that the bake was interrupted.
void InstallSignalHandlers();
bool Interrupted();

/// First executable named `name` in $PATH.
std::optional<std::filesystem::path> FindOnPath(const std::string& name);
/// Folder of the running executable (where the stage tools are installed beside rime-bake).
std::filesystem::path ExecutableFolder();

/// Shell-quoted command line for display (--dry-run, logs, error messages).
std::string CommandLine(const std::filesystem::path& program, const std::vector<std::string>& args);

}  // namespace rime::bake
