/// @file tool.h
/// @brief What every Rime executable shares: common flags, error reporting and exit codes.
///
/// A tool's main is thin: parse with CLI11, then `return rime::tool::Run([&] { ... });`, which
/// prints `tool: error: <what> (<file>:<where>)` and returns the documented exit code.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>

#include "rime/core/memory_budget.h"
#include "rime/core/sandbox.h"

namespace rime::tool {

struct CommonOptions {
  bool quiet = false;
  bool verbose = false;
  int threads = 0;  // -j: CPU threads (0 = all cores)
  std::string device = "auto";
  std::string frames;         // "A-B", "A" or "" (all)
  std::string json_summary;   // path or ""
  std::string memory_budget;  // --memory-budget SIZE, "" = the available memory
  std::string sandbox;        // --sandbox DIR, "" = off
};

enum CommonFlags : unsigned { kThreads = 1, kDevice = 2, kFrames = 4, kJsonSummary = 8, kMemoryBudget = 16, kSandbox = 32 };

/// Creates the app with --version, --quiet, --verbose and the selected common flags.
void Setup(CLI::App& app, const std::string& name, CommonOptions& options, unsigned flags);
/// Applies --quiet/--verbose/-j; call after parsing.
void Apply(const CommonOptions& options);

/// Parses argv (printing help/usage errors the CLI11 way) and runs `body`, mapping exceptions to
/// one error line and an exit code.
int Main(CLI::App& app, int argc, char** argv, const CommonOptions& options, const std::function<int()>& body);

struct FrameRange {
  std::int64_t first = 0;
  std::int64_t last = INT64_MAX;
  bool Contains(std::int64_t f) const { return f >= first && f <= last; }
};
/// "A-B" or "A"; throws rime::Error(kUsage) otherwise.
FrameRange ParseFrames(const std::string& text);

/// Writes the JSON summary atomically if --json-summary was given.
void WriteSummary(const CommonOptions& options, const nlohmann::json& summary);

/// The budget --memory-budget names, else what the machine can give now.
MemoryBudget Budget(const CommonOptions& options);
/// The --sandbox folder (off when not given); checks --json-summary against it.
Sandbox MakeSandbox(const CommonOptions& options);

/// Peak resident memory of this process, bytes.
std::uint64_t PeakMemoryBytes();

}  // namespace rime::tool
