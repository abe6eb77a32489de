#include "process.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fmt/format.h>
#include <fstream>

#include "rime/core/error.h"

namespace fs = std::filesystem;

namespace rime::bake {
namespace {

// Pids of running tools, for forwarding signals from an async-signal-safe handler.
constexpr int kMaxChildren = 256;
std::array<std::atomic<pid_t>, kMaxChildren> g_children{};
std::atomic<bool> g_interrupted{false};
std::atomic<int> g_inherited_fd{-1};

void ForwardSignal(int signal) {
  g_interrupted = true;
  for (auto& pid : g_children) {
    const pid_t p = pid.load();
    if (p > 0) kill(-p, SIGTERM);  // the tool's process group: a shell's children too
  }
}

int RegisterChild(pid_t pid) {
  for (int k = 0; k < kMaxChildren; ++k) {
    pid_t expected = 0;
    if (g_children[k].compare_exchange_strong(expected, pid)) return k;
  }
  return -1;
}

std::string Quote(const std::string& s) {
  if (!s.empty() && s.find_first_of(" \t\n'\"\\$`*?[]{}()<>|&;#~") == std::string::npos) return s;
  std::string out = "'";
  for (char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return out + "'";
}

}  // namespace

void InstallSignalHandlers() {
  struct sigaction action {};
  action.sa_handler = ForwardSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

bool Interrupted() { return g_interrupted.load(); }

ToolsInherit::ToolsInherit(int fd) { g_inherited_fd = fd; }
ToolsInherit::~ToolsInherit() { g_inherited_fd = -1; }

std::string CommandLine(const fs::path& program, const std::vector<std::string>& args) {
  std::string line = Quote(program.string());
  for (const auto& a : args) {
    line += ' ';
    line += Quote(a);
  }
  return line;
}

int RunProcess(const fs::path& program, const std::vector<std::string>& args, const fs::path& log) {
  fs::create_directories(log.parent_path());
  {
    std::ofstream header(log, std::ios::trunc);
    if (!header) throw IoError("cannot write log file", log.string());
    header << "$ " << CommandLine(program, args) << "\n";
    // On a full disk the tool's own error message could not be logged either: stop here.
    if (!header.flush()) throw IoError("cannot write log file (disk full?)", log.string());
  }
  // Everything the child needs is prepared before fork: only async-signal-safe calls after it.
  std::vector<std::string> storage{program.string()};
  storage.insert(storage.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& s : storage) argv.push_back(s.data());
  argv.push_back(nullptr);
  const int log_fd = open(log.c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (log_fd < 0) throw IoError("cannot open log file", log.string());
  const pid_t parent = getpid();
  const int inherited_fd = g_inherited_fd.load();

  const pid_t pid = fork();
  if (pid < 0) {
    close(log_fd);
    throw Error(ExitCode::kFailure, fmt::format("cannot start {}: {}", program.string(), std::strerror(errno)));
  }
  if (pid == 0) {
    // A bake killed with SIGKILL must not leave tools running: they die with their parent.
    prctl(PR_SET_PDEATHSIG, SIGTERM);
    if (getppid() != parent) _exit(130);
    setpgid(0, 0);  // a group of its own, so that stopping it reaches whatever it starts
    dup2(log_fd, STDOUT_FILENO);
    dup2(log_fd, STDERR_FILENO);
    const int null_fd = open("/dev/null", O_RDONLY);
    if (null_fd >= 0) dup2(null_fd, STDIN_FILENO);
    signal(SIGINT, SIG_DFL);
    signal(SIGTERM, SIG_DFL);
    if (inherited_fd >= 0) fcntl(inherited_fd, F_SETFD, 0);  // clears FD_CLOEXEC in this child only
    execv(argv[0], argv.data());
    const char message[] = "rime-bake: error: cannot execute the tool\n";
    [[maybe_unused]] auto n = write(STDERR_FILENO, message, sizeof(message) - 1);
    _exit(127);
  }
  close(log_fd);
  setpgid(pid, pid);  // also here, so that the group exists before any signal is forwarded to it
  const int slot = RegisterChild(pid);
  if (Interrupted()) kill(-pid, SIGTERM);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
  if (slot >= 0) g_children[slot] = 0;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  if (WIFSIGNALED(status)) return 128 + WTERMSIG(status);
  return 1;
}

Captured CaptureProcess(const fs::path& program, const std::vector<std::string>& args) {
  std::vector<std::string> storage{program.string()};
  storage.insert(storage.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& s : storage) argv.push_back(s.data());
  argv.push_back(nullptr);
  int out_pipe[2], err_pipe[2];
  if (pipe2(out_pipe, O_CLOEXEC) != 0)
    throw Error(ExitCode::kFailure, fmt::format("cannot start {}: {}", program.string(), std::strerror(errno)));
  if (pipe2(err_pipe, O_CLOEXEC) != 0) {
    close(out_pipe[0]), close(out_pipe[1]);
    throw Error(ExitCode::kFailure, fmt::format("cannot start {}: {}", program.string(), std::strerror(errno)));
  }
  const pid_t pid = fork();
  if (pid < 0) {
    for (int fd : {out_pipe[0], out_pipe[1], err_pipe[0], err_pipe[1]}) close(fd);
    throw Error(ExitCode::kFailure, fmt::format("cannot start {}: {}", program.string(), std::strerror(errno)));
  }
  if (pid == 0) {
    dup2(out_pipe[1], STDOUT_FILENO);
    dup2(err_pipe[1], STDERR_FILENO);
    const int null_fd = open("/dev/null", O_RDONLY);
    if (null_fd >= 0) dup2(null_fd, STDIN_FILENO);
    execv(argv[0], argv.data());
    _exit(127);
  }
  close(out_pipe[1]);
  close(err_pipe[1]);
  Captured result;
  pollfd fds[2] = {{out_pipe[0], POLLIN, 0}, {err_pipe[0], POLLIN, 0}};
  std::string* sinks[2] = {&result.out, &result.err};
  int open_fds = 2;
  char buffer[4096];
  while (open_fds > 0) {
    if (poll(fds, 2, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    for (int k = 0; k < 2; ++k) {
      if (fds[k].fd < 0 || !(fds[k].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      const ssize_t n = read(fds[k].fd, buffer, sizeof buffer);
      if (n > 0) {
        sinks[k]->append(buffer, static_cast<std::size_t>(n));
      } else if (n == 0 || errno != EINTR) {
        close(fds[k].fd);
        fds[k].fd = -1;
        --open_fds;
      }
    }
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {}
  result.code = WIFEXITED(status) ? WEXITSTATUS(status) : WIFSIGNALED(status) ? 128 + WTERMSIG(status) : 1;
  return result;
}

std::optional<fs::path> FindOnPath(const std::string& name) {
  const char* path = std::getenv("PATH");
  if (!path) return std::nullopt;
  std::string all(path);
  std::size_t start = 0;
  while (start <= all.size()) {
    const std::size_t end = std::min(all.find(':', start), all.size());
    const fs::path candidate = fs::path(all.substr(start, end - start)) / name;
    if (end > start && access(candidate.c_str(), X_OK) == 0 && fs::is_regular_file(candidate)) return candidate;
    start = end + 1;
  }
  return std::nullopt;
}

fs::path ExecutableFolder() {
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::current_path() : self.parent_path();
}

}  // namespace rime::bake
