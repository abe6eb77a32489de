/// @file memory_budget.h
/// @brief Memory budgets: sizes like `4G` on the command line, the memory this machine (or its
/// cgroup) can still give, and the one-line refusal every stage prints before allocating too much.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "rime/core/error.h"

namespace rime {

/// Bytes from `512M`, `4G`, `1.5GiB`, `100000`: a decimal number with an optional suffix K, M, G
/// or T (each may be followed by `i` and/or `B`, any case), all powers of 1024 as in Slurm's
/// --mem. Throws rime::Error (kUsage) naming `flag` for anything else, zero, or above 2^63.
std::uint64_t ParseByteSize(std::string_view text, std::string_view flag = "--memory-budget");

/// "14.2 GiB", "512 MiB", "900 B".
std::string FormatBytes(double bytes);
/// "310 M", "12.5 k", "800": counts in the refusal messages.
std::string FormatCount(double count);

struct MemoryBudget {
  std::uint64_t bytes = UINT64_MAX;  // UINT64_MAX: no limit known
  std::string source;                // "--memory-budget", "MemAvailable", "cgroup memory limit"
};

/// What this process may still allocate: /proc/meminfo's MemAvailable, lowered to the free part of
/// a cgroup memory limit (v1 or v2) when one is set. nullopt when neither can be read.
std::optional<MemoryBudget> AvailableMemory();

/// The budget for a flag's text: the parsed size when given, else AvailableMemory() (no limit if
/// that cannot be read).
MemoryBudget ResolveMemoryBudget(const std::string& flag_text);

/// Peak of jobs that run `at_once` at a time in any order: the sum of the `at_once` largest
/// estimates; `largest` receives the index of the largest one (0 when there is none).
double ConcurrentPeak(const std::vector<double>& estimates, std::size_t at_once, std::size_t* largest = nullptr);

/// Resident memory of this process now (/proc/self/statm), bytes; 0 when it cannot be read.
std::uint64_t ResidentBytes();

/// Throws rime::Error (ExitCode::kOverBudget) when this process's resident memory now plus
/// `estimate_bytes` (what the work will allocate on top of it) exceeds the budget, as one line:
/// `needs about 14.2 GiB for 310 M voxels (frame f.h5part, voxel 2 mm), budget 8 GiB (--memory-budget)`.
/// `driver` is what the estimate grows with, `context` the input that drives it.
void CheckMemoryBudget(const MemoryBudget& budget, double estimate_bytes, std::string_view driver, std::string_view context);

}  // namespace rime
