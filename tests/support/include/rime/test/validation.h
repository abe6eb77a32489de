// Shared plumbing of the validation programs: fast/full variant selection, run information
// (threads, load average, wall time) and a least-squares line fit.
#pragma once

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "rime/core/log.h"
#include "rime/test/measure.h"

namespace rime::validation {

struct Options {
  bool full = false;       // the variant a user runs for the figures (minutes); CI runs the fast one
  bool viscosity = false;  // dam break only: also switch on the spec's default viscosity modules
  bool cfl = false;        // hydrostatic only: the spec §7 default adaptive step instead of fixed 2 ms
  bool trace = false;      // print every step's solver figures
};

/// `--full` or RIME_VALIDATION_FULL=1 selects the full variant; `--help` prints `usage` and exits.
inline Options ParseOptions(int argc, char** argv, const char* usage) {
  Options o;
  if (const char* env = std::getenv("RIME_VALIDATION_FULL")) o.full = std::strcmp(env, "0") != 0 && *env != '\0';
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--full")) {
      o.full = true;
    } else if (!std::strcmp(argv[i], "--fast")) {
      o.full = false;
    } else if (!std::strcmp(argv[i], "--viscosity")) {
      o.viscosity = true;
    } else if (!std::strcmp(argv[i], "--cfl")) {
      o.cfl = true;
    } else if (!std::strcmp(argv[i], "--trace")) {
      o.trace = true;
    } else {
      std::printf("%s\n", usage);
      std::exit(std::strcmp(argv[i], "--help") && std::strcmp(argv[i], "-h") ? 2 : 0);
    }
  }
  log::SetLevel(log::Level::kWarning);  // the solver's start-up messages would bury the tables
  return o;
}

/// One line with the variant, the hardware threads and the load, so timings can be judged.
inline void PrintRunInfo(const char* name, const Options& o) {
  std::printf("%s (%s variant; %u hardware threads; load average %s)\n", name, o.full ? "full" : "fast",
              std::thread::hardware_concurrency(), test::LoadAverages().c_str());
}

using test::Stopwatch;

/// How long a hydrostatic column started on a lattice settles, and then how long its pressures
/// are averaged (rime_validation_hydrostatic and the speed/accuracy study). A lattice is no
/// equilibrium: after 1.5 s the column still moved at 0.11 m/s, after 3 s at a few cm/s; 3 s of
/// averaging spans several periods of its sloshing (about 0.5 s in a 0.2 m tank).
constexpr double kHydrostaticSettle = 3.0, kHydrostaticAverage = 3.0;

struct Line {
  double slope = 0, intercept = 0;
};

/// Least-squares y = slope x + intercept (needs two distinct x at least).
inline Line FitLine(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = double(x.size());
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) sx += x[i], sy += y[i], sxx += x[i] * x[i], sxy += x[i] * y[i];
  Line l;
  l.slope = (n * sxy - sx * sy) / (n * sxx - sx * sx);
  l.intercept = (sy - l.slope * sx) / n;
  return l;
}

/// Prints PASS/FAIL for one criterion and returns whether it held.
inline bool Check(bool ok, const std::string& what) {
  std::printf("  [%s] %s\n", ok ? "PASS" : "FAIL", what.c_str());
  return ok;
}

}  // namespace rime::validation
