/// @file run_in_child.h
/// @brief Runs a piece of a benchmark in a forked child process and hands back the bytes it
/// produced and the child's resource usage: each case then starts from the parent's memory and
/// thread state, and its peak memory and CPU time are its own.
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <stdexcept>
#include <string>

namespace rime::test {

struct ChildResult {
  std::string output;  // what `work` returned; empty when the child died before sending it
  bool exited_cleanly = false;
  rusage usage{};  // the child's, from wait4: CPU time, peak resident memory (ru_maxrss, KiB)
};

/// Forks; the child runs `work` (returning its result as bytes), sends them through a pipe and
/// exits without running the parent's destructors. Throws when the pipe or the fork fails.
template <class Work>
ChildResult RunInChild(Work&& work) {
  int fd[2];
  if (pipe(fd) != 0) throw std::runtime_error("pipe failed");
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("fork failed");
  if (pid == 0) {
    close(fd[0]);
    const std::string bytes = work();
    for (std::size_t sent = 0; sent < bytes.size();) {
      const ssize_t n = write(fd[1], bytes.data() + sent, bytes.size() - sent);
      if (n <= 0) _exit(1);
      sent += std::size_t(n);
    }
    close(fd[1]);
    _exit(0);
  }
  close(fd[1]);
  ChildResult result;
  char buffer[1 << 16];
  for (ssize_t n; (n = read(fd[0], buffer, sizeof buffer)) != 0;) {
    if (n > 0) result.output.append(buffer, std::size_t(n));
    else if (errno != EINTR) break;
  }
  close(fd[0]);
  int status = 0;
  while (wait4(pid, &status, 0, &result.usage) < 0 && errno == EINTR) {}
  result.exited_cleanly = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  return result;
}

}  // namespace rime::test
