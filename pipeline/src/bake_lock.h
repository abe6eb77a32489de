/// @file bake_lock.h
/// @brief One bake per output folder: an flock on `<cache>/.rime-bake/lock`, which also names its
/// holder (pid, host, start time) so a refused bake can say who holds it and a lock left by a
/// killed bake is recognised and reported as recovered.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

namespace rime::bake {

/// Who took the lock, as written into the lock file: `pid=N host=H started=T`.
struct LockHolder {
  long pid = 0;
  std::string host, started;
  std::string StartTime() const;  // "2026-12-02 18:20:03 UTC"
  std::string Describe() const;   // "pid 123 on host node1, started 2026-12-02 18:20:03 UTC"
};
std::optional<LockHolder> ParseLockHolder(const std::string& text);

class BakeLock {
 public:
  /// Takes the lock (shared for farm tasks, which run side by side and write no holder line).
  /// Throws rime::Error (exit 5) naming the holder when it is taken, or when a holder line names
  /// another host: whether that bake still runs cannot be checked from here.
  BakeLock(const std::filesystem::path& lock_file, const std::filesystem::path& output, bool shared);
  ~BakeLock();
  BakeLock(const BakeLock&) = delete;
  BakeLock& operator=(const BakeLock&) = delete;
  int fd() const { return fd_; }

 private:
  int fd_ = -1;
  bool shared_ = false;
};

}  // namespace rime::bake
