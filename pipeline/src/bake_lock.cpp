#include "bake_lock.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <ctime>
#include <fmt/format.h>
#include <sstream>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/log.h"

namespace fs = std::filesystem;

namespace rime::bake {
namespace {

std::string HostName() {
  char name[256] = {};
  if (gethostname(name, sizeof name - 1) != 0) return "unknown";
  return name;
}

std::string UtcNow() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

bool ProcessExists(long pid) { return pid > 0 && (kill(static_cast<pid_t>(pid), 0) == 0 || errno == EPERM); }

}  // namespace

std::string LockHolder::StartTime() const {
  if (started.size() == 20 && started[10] == 'T' && started.back() == 'Z')
    return started.substr(0, 10) + " " + started.substr(11, 8) + " UTC";
  return started;
}

std::string LockHolder::Describe() const { return fmt::format("pid {} on host {}, started {}", pid, host, StartTime()); }

std::optional<LockHolder> ParseLockHolder(const std::string& text) {
  LockHolder holder;
  std::istringstream words(text);
  for (std::string word; words >> word;) {
    const auto eq = word.find('=');
    if (eq == std::string::npos) continue;
    const std::string key = word.substr(0, eq), value = word.substr(eq + 1);
    if (key == "pid") holder.pid = std::atol(value.c_str());
    else if (key == "host") holder.host = value;
    else if (key == "started") holder.started = value;
  }
  if (holder.pid <= 0 || holder.host.empty()) return std::nullopt;
  return holder;
}

BakeLock::BakeLock(const fs::path& lock_file, const fs::path& output, bool shared) : shared_(shared) {
  fd_ = open(lock_file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw IoError(fmt::format("cannot open the bake lock: {}", std::strerror(errno)), lock_file.string());
  const bool taken = flock(fd_, (shared ? LOCK_SH : LOCK_EX) | LOCK_NB) == 0;
  const auto holder = ParseLockHolder(ReadFileOrEmpty(lock_file));
  const bool here = holder && holder->host == HostName();
  if (!taken) {
    close(fd_);
    std::string message;
    if (shared)
      message = fmt::format("a local rime-bake is baking into {}{}; farm tasks cannot run beside it", output.string(),
                            holder ? " (" + holder->Describe() + ")" : "");
    else if (holder && here && !ProcessExists(holder->pid))
      message = fmt::format("stage tools started by a killed rime-bake ({}) are still running in {}; rerun once they have exited",
                            holder->Describe(), output.string());
    else if (holder) message = fmt::format("another rime-bake is baking into {} ({})", output.string(), holder->Describe());
    else message = fmt::format("another rime-bake (or farm tasks of this bake) is baking into {}", output.string());
    throw IoError(message, lock_file.string());
  }
  if (holder) {
    // The lock is free, so its holder line was left by a bake that did not end normally. On this
    // host that is certain; a line from another host is only trusted when its pid can be checked
    // (flock may be node-local on shared filesystems, so that bake could still be running).
    if (!here) {
      close(fd_);
      throw IoError(fmt::format("the bake lock names {}, which cannot be checked from host {}; if no rime-bake runs there any more, "
                                "delete the lock file and rerun",
                                holder->Describe(), HostName()),
                    lock_file.string());
    }
    log::Warn("stale lock from pid {} ({}, started {}) recovered{}: that bake was killed or crashed; the jobs it left incomplete rerun",
              holder->pid, holder->host, holder->StartTime(),
              ProcessExists(holder->pid) ? fmt::format(" (pid {} is now another program)", holder->pid) : "");
  }
  if (!shared) {
    const std::string line = fmt::format("pid={} host={} started={}\n", getpid(), HostName(), UtcNow());
    if (ftruncate(fd_, 0) != 0 || pwrite(fd_, line.data(), line.size(), 0) != static_cast<ssize_t>(line.size())) {
      const std::string reason = std::strerror(errno);
      close(fd_);
      throw IoError("cannot write the bake lock: " + reason, lock_file.string());
    }
  } else if (holder) {
    [[maybe_unused]] const int ignored = ftruncate(fd_, 0);  // recovered: the stale line goes
  }
}

BakeLock::~BakeLock() {
  // A bake that ends normally clears its holder line: a line found later means it was killed.
  if (!shared_) {
    [[maybe_unused]] const int ignored = ftruncate(fd_, 0);
  }
  close(fd_);
}

}  // namespace rime::bake
