/// @file run_command.h
/// @brief Runs a command line through the shell, as a user types it, and returns its exit code
/// and what it printed: how the tool tests run a tool.
#pragma once

#include <stdio.h>
#include <sys/wait.h>

#include <array>
#include <string>

namespace rime::test {

struct CommandResult {
  int code = -1;       // the exit code; -1 when the command did not exit normally
  std::string output;  // what `Capture` kept
};

enum class Capture {
  kStderr,  // the error stream only (stdout discarded): a tool's one-line error
  kBoth,    // stdout and stderr interleaved, in the order written
};

inline CommandResult RunCommand(const std::string& command, Capture capture = Capture::kBoth) {
  const std::string redirect = capture == Capture::kStderr ? " 2>&1 >/dev/null" : " 2>&1";
  CommandResult result;
  FILE* pipe = popen((command + redirect).c_str(), "r");
  if (!pipe) return result;
  std::array<char, 4096> buffer{};
  for (std::size_t n; (n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0;) result.output.append(buffer.data(), n);
  const int status = pclose(pipe);
  result.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

}  // namespace rime::test
