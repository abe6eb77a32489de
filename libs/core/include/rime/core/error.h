/// @file error.h
/// @brief Errors that carry where they happened, so tools print one clear line.
///
/// Tools print `tool: error: <what> (<file>:<where>)` and exit with the code of the error's kind.
#pragma once

#include <stdexcept>
#include <string>

namespace rime {

/// Exit codes shared by every tool (documented in README.md).
enum class ExitCode : int {
  kOk = 0,
  kFailure = 1,      // unexpected internal failure
  kUsage = 2,        // bad command line
  kBadInput = 3,     // missing, corrupt, wrong-version or invalid input file / scene value
  kDiverged = 4,     // the simulation blew up (NaN, density error above the limit)
  kIo = 5,           // could not write output (disk full, permissions)
  kNoDevice = 6,     // requested device not usable (e.g. --device cuda without a GPU)
  kOverBudget = 10,  // estimated peak memory above --memory-budget (nothing written)
  kInterrupted = 130,
};

class Error : public std::runtime_error {
 public:
  /// @param what  what went wrong, in words a user understands
  /// @param where the file (and optionally ":line" or ":field") it concerns; may be empty
  Error(ExitCode code, std::string what, std::string where = {})
      : std::runtime_error(where.empty() ? what : what + " (" + where + ")"),
        code_(code),
        what_(std::move(what)),
        where_(std::move(where)) {}

  ExitCode code() const { return code_; }
  const std::string& message() const { return what_; }
  const std::string& where() const { return where_; }

 private:
  ExitCode code_;
  std::string what_;
  std::string where_;
};

inline Error InputError(std::string what, std::string where = {}) { return Error(ExitCode::kBadInput, std::move(what), std::move(where)); }
inline Error IoError(std::string what, std::string where = {}) { return Error(ExitCode::kIo, std::move(what), std::move(where)); }

}  // namespace rime
