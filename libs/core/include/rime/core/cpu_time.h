/// @file cpu_time.h
/// @brief CPU time of this process, for reports that show what work cost beside its wall time.
#pragma once

#include <ctime>

namespace rime {

/// CPU seconds (user and system, all threads) of this process so far: on a machine shared with
/// other work wall time overstates the cost; CPU time divided by threads is the per-core figure.
inline double ProcessCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

}  // namespace rime
