/// @file progress.h
/// @brief Progress reporter: a bar with ETA on a terminal, plain periodic lines otherwise.
#pragma once

#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace rime {

class Progress {
 public:
  /// @param label  what is being counted ("frames", "triangles")
  /// @param total  number of units of work (0 = unknown)
  Progress(std::string label, std::int64_t total);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  /// Sets the absolute amount done, with an optional short status ("t=0.52 s, 3 it/step").
  void Update(std::int64_t done, const std::string& status = {});
  void Advance(std::int64_t delta = 1);
  /// Ends the bar (prints a final line). Called by the destructor if not called.
  void Finish();

  /// Forces terminal (true) or plain-line (false) mode; default detects whether stderr is a tty.
  static void ForceTerminal(bool terminal);

 private:
  void Draw(bool final_line);

  std::string label_;
  std::int64_t total_;
  std::int64_t done_ = 0;
  std::string status_;
  bool terminal_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  std::mutex mutex_;
};

/// Formats seconds as "1h02m", "3m05s", "12.3s" or "45ms".
std::string FormatDuration(double seconds);

}  // namespace rime
