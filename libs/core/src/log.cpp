#include "rime/core/log.h"

#include <cstdio>
#include <mutex>

namespace rime::log {
namespace {
Level g_level = Level::kInfo;
std::string g_program = "rime";
std::mutex g_mutex;
}  // namespace

void SetLevel(Level level) { g_level = level; }
Level GetLevel() { return g_level; }
void SetProgramName(std::string name) { g_program = std::move(name); }
const std::string& ProgramName() { return g_program; }

void Write(Level level, std::string_view message) {
  if (level < g_level) return;
  const char* tag = level == Level::kError ? "error: " : level == Level::kWarning ? "warning: " : level == Level::kDebug ? "debug: " : "";
  std::lock_guard lock(g_mutex);
  std::fprintf(stderr, "%s: %s%.*s\n", g_program.c_str(), tag, static_cast<int>(message.size()), message.data());
}

}  // namespace rime::log
