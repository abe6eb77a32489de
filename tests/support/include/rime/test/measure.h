/// @file measure.h
/// @brief What benchmarks and validation programs print beside a timing: the median of repeated
/// runs, wall-clock and CPU seconds and the machine's load (on a shared machine, timings mean little
/// without it).
#pragma once

#include <stdlib.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "rime/core/cpu_time.h"

namespace rime::test {

/// The median (the mean of the two middle values for an even count); 0 for no values.
inline double Median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const std::size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

/// Wall-clock seconds since construction (or the last Restart), on the monotonic clock.
class Stopwatch {
 public:
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  void Restart() { start_ = std::chrono::steady_clock::now(); }

 private:
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

using ::rime::ProcessCpuSeconds;  // rime/core/cpu_time.h

/// CPU seconds (user and system) in a resource usage, e.g. a child's from wait4.
inline double CpuSeconds(const rusage& usage) {
  return double(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) + 1e-6 * double(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
}

/// The 1-minute load average, or -1 where the system does not report it.
inline double LoadAverage() {
  double load[1] = {-1};
  return getloadavg(load, 1) == 1 ? load[0] : -1;
}

/// The 1-, 5- and 15-minute load averages as "a b c", or "?" where the system does not report them.
inline std::string LoadAverages() {
  double load[3] = {0, 0, 0};
  if (getloadavg(load, 3) != 3) return "?";
  char text[64];
  std::snprintf(text, sizeof text, "%.2f %.2f %.2f", load[0], load[1], load[2]);
  return text;
}

/// The CPU model and the hardware threads, e.g. "AMD EPYC 9R14 (2 hardware threads)": a result
/// file says which machine it was measured on.
inline std::string MachineDescription() {
  std::ifstream cpuinfo("/proc/cpuinfo");
  std::string model = "unknown CPU";
  for (std::string line; std::getline(cpuinfo, line);)
    if (line.rfind("model name", 0) == 0 && line.find(':') != std::string::npos) {
      model = line.substr(line.find(':') + 2);
      break;
    }
  return model + " (" + std::to_string(std::thread::hardware_concurrency()) + " hardware threads)";
}

/// The commit checked out in `source_dir` when the benchmark runs, with "-dirty" when the tree has
/// uncommitted changes; "unknown" outside a git checkout. A result file names the code it measured.
inline std::string SourceCommit(const std::string& source_dir) {
  const std::string git = "git -C '" + source_dir + "' ";
  const auto first_line = [](const std::string& command) {
    std::string line;
    if (FILE* pipe = popen((command + " 2>/dev/null").c_str(), "r")) {
      std::array<char, 256> buffer{};
      if (std::fgets(buffer.data(), buffer.size(), pipe)) line = buffer.data();
      pclose(pipe);
    }
    while (!line.empty() && (line.back() == '\n' || line.back() == '\r')) line.pop_back();
    return line;
  };
  const std::string commit = first_line(git + "rev-parse --short HEAD");
  if (commit.empty()) return "unknown";
  return first_line(git + "status --porcelain --untracked-files=no").empty() ? commit : commit + "-dirty";
}

}  // namespace rime::test
