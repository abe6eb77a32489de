#include "tool.h"

#include <sys/resource.h>

#include <fmt/format.h>

#include <csignal>
#include <cstdio>
#include <regex>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/exec/device.h"
#include "rime/version.h"

namespace rime::tool {

void Setup(CLI::App& app, const std::string& name, CommonOptions& options, unsigned flags) {
  log::SetProgramName(name);
  app.name(name);
  app.set_version_flag("--version", std::string("Rime ") + RIME_VERSION_STRING);
  app.add_flag("-q,--quiet", options.quiet, "Print only warnings and errors");
  app.add_flag("-v,--verbose", options.verbose, "Print debug details");
  if (flags & kThreads) app.add_option("-j,--threads", options.threads, "CPU threads (default: all cores)")->check(CLI::NonNegativeNumber);
  if (flags & kDevice)
    app.add_option("--device", options.device, "Where to compute: auto (a GPU when usable, else CPU), cpu, cuda")
        ->check(CLI::IsMember({"auto", "cpu", "cuda"}))
        ->capture_default_str();
  if (flags & kFrames) app.add_option("--frames", options.frames, "Frame range A-B (or a single frame A); default: all");
  if (flags & kJsonSummary) app.add_option("--json-summary", options.json_summary, "Also write the end-of-run summary as JSON to FILE");
  if (flags & kMemoryBudget)
    app.add_option("--memory-budget", options.memory_budget,
                   "Refuse to start (exit 10, nothing written) when the peak memory estimated from the inputs exceeds SIZE: "
                   "512M, 4G, 1.5GiB or bytes (K, M, G, T are powers of 1024). Default: the memory available now "
                   "(MemAvailable, or less when a cgroup memory limit leaves less)")
        ->type_name("SIZE");
  if (flags & kSandbox)
    app.add_option("--sandbox", options.sandbox,
                   "Refuse (nothing written) any input or output path, scene paths included, that does not resolve inside "
                   "DIR after following symlinks")
        ->type_name("DIR");
  app.footer(
      "Exit codes: 0 ok, 1 internal failure, 2 bad command line, 3 bad input file or scene value, 4 simulation "
      "diverged, 5 cannot write output, 6 requested device unusable, 10 estimated memory above --memory-budget, "
      "130 interrupted.");
}

void Apply(const CommonOptions& options) {
  if (options.quiet) log::SetLevel(log::Level::kWarning);
  if (options.verbose) log::SetLevel(log::Level::kDebug);
  if (options.threads > 0) exec::SetCpuThreads(options.threads);
}

int Main(CLI::App& app, int argc, char** argv, const CommonOptions& options, const std::function<int()>& body) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version exit 0; every command-line error gets the documented code 2.
    return app.exit(e) == 0 ? 0 : static_cast<int>(ExitCode::kUsage);
  }
  // Past a file size limit (ulimit -f) a write then fails with EFBIG and the tool reports which
  // file it was writing, instead of being killed by SIGXFSZ with a half-written temporary.
  std::signal(SIGXFSZ, SIG_IGN);
  try {
    Apply(options);
    return body();
  } catch (const Error& e) {
    std::fprintf(stderr, "%s: error: %s\n", log::ProgramName().c_str(), e.what());
    return static_cast<int>(e.code());
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: error: out of memory\n", log::ProgramName().c_str());
    return static_cast<int>(ExitCode::kFailure);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: internal failure: %s\n", log::ProgramName().c_str(), e.what());
    return static_cast<int>(ExitCode::kFailure);
  }
}

FrameRange ParseFrames(const std::string& text) {
  FrameRange range;
  if (text.empty()) return range;
  std::smatch m;
  static const std::regex pattern(R"(^\s*(\d+)\s*(?:-\s*(\d+))?\s*$)");
  if (!std::regex_match(text, m, pattern)) throw Error(ExitCode::kUsage, "expected a frame range like 10-20 or 7", "--frames " + text);
  range.first = std::stoll(m[1]);
  range.last = m[2].matched ? std::stoll(m[2]) : range.first;
  if (range.last < range.first) throw Error(ExitCode::kUsage, "frame range ends before it starts", "--frames " + text);
  return range;
}

void WriteSummary(const CommonOptions& options, const nlohmann::json& summary) {
  if (!options.json_summary.empty()) WriteFileAtomically(options.json_summary, summary.dump(2) + "\n");
}

MemoryBudget Budget(const CommonOptions& options) { return ResolveMemoryBudget(options.memory_budget); }

Sandbox MakeSandbox(const CommonOptions& options) {
  if (options.sandbox.empty()) return {};
  Sandbox sandbox{std::filesystem::path(options.sandbox)};
  if (!options.json_summary.empty()) sandbox.Require(options.json_summary, "--json-summary", ExitCode::kUsage);
  return sandbox;
}

std::uint64_t PeakMemoryBytes() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<std::uint64_t>(usage.ru_maxrss) * 1024;
}

}  // namespace rime::tool
