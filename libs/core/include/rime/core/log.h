/// @file log.h
/// @brief Leveled logging to stderr. `--quiet` shows warnings and errors, `--verbose` adds debug.
#pragma once

#include <fmt/format.h>
#include <string>
#include <string_view>

namespace rime::log {

enum class Level { kDebug = 0, kInfo = 1, kWarning = 2, kError = 3, kSilent = 4 };

void SetLevel(Level level);
Level GetLevel();
/// Name printed before messages, e.g. "rime-sim".
void SetProgramName(std::string name);
const std::string& ProgramName();
void Write(Level level, std::string_view message);

template <class... Args>
void Debug(fmt::format_string<Args...> f, Args&&... a) {
  if (GetLevel() <= Level::kDebug) Write(Level::kDebug, fmt::format(f, std::forward<Args>(a)...));
}
template <class... Args>
void Info(fmt::format_string<Args...> f, Args&&... a) {
  if (GetLevel() <= Level::kInfo) Write(Level::kInfo, fmt::format(f, std::forward<Args>(a)...));
}
template <class... Args>
void Warn(fmt::format_string<Args...> f, Args&&... a) {
  if (GetLevel() <= Level::kWarning) Write(Level::kWarning, fmt::format(f, std::forward<Args>(a)...));
}
template <class... Args>
void Error(fmt::format_string<Args...> f, Args&&... a) {
  if (GetLevel() <= Level::kError) Write(Level::kError, fmt::format(f, std::forward<Args>(a)...));
}

}  // namespace rime::log
