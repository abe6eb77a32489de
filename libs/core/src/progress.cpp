#include "rime/core/progress.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <fmt/format.h>
#include <optional>

#include "rime/core/log.h"

namespace rime {
namespace {
std::optional<bool> g_force_terminal;
constexpr auto kTerminalRedraw = std::chrono::milliseconds(100);
constexpr auto kPlainLineInterval = std::chrono::seconds(5);
}  // namespace

void Progress::ForceTerminal(bool terminal) { g_force_terminal = terminal; }

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) return "?";
  if (seconds < 1) return fmt::format("{:.0f}ms", seconds * 1e3);
  if (seconds < 60) return fmt::format("{:.1f}s", seconds);
  const auto s = static_cast<long>(seconds + 0.5);
  if (s < 3600) return fmt::format("{}m{:02}s", s / 60, s % 60);
  return fmt::format("{}h{:02}m", s / 3600, (s % 3600) / 60);
}

Progress::Progress(std::string label, std::int64_t total)
    : label_(std::move(label)),
      total_(total),
      terminal_(g_force_terminal.value_or(isatty(STDERR_FILENO) != 0)),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_) {}

Progress::~Progress() { Finish(); }

void Progress::Update(std::int64_t done, const std::string& status) {
  std::lock_guard lock(mutex_);
  done_ = done;
  status_ = status;
  const auto now = std::chrono::steady_clock::now();
  if (now - last_draw_ >= (terminal_ ? kTerminalRedraw : kPlainLineInterval)) {
    last_draw_ = now;
    Draw(false);
  }
}

void Progress::Advance(std::int64_t delta) {
  std::int64_t done;
  {
    std::lock_guard lock(mutex_);
    done = done_ + delta;
  }
  Update(done, status_);
}

void Progress::Finish() {
  std::lock_guard lock(mutex_);
  if (finished_) return;
  finished_ = true;
  Draw(true);
}

void Progress::Draw(bool final_line) {
  if (log::GetLevel() > log::Level::kInfo) return;
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  const double fraction = total_ > 0 ? std::min(1.0, double(done_) / double(total_)) : 0.0;
  const double eta = fraction > 0 ? elapsed * (1 - fraction) / fraction : NAN;
  std::string counts = total_ > 0 ? fmt::format("{}/{} {}", done_, total_, label_) : fmt::format("{} {}", done_, label_);
  std::string timing = final_line ? fmt::format("in {}", FormatDuration(elapsed))
                                  : fmt::format("{} elapsed, ETA {}", FormatDuration(elapsed), FormatDuration(eta));
  std::string tail = status_.empty() ? timing : status_ + ", " + timing;
  if (terminal_) {
    constexpr int kWidth = 28;
    const int filled = static_cast<int>(fraction * kWidth);
    std::string bar(filled, '#');
    bar.resize(kWidth, '.');
    std::fprintf(stderr, "\r\033[K%s: [%s] %3.0f%% %s  %s%s", log::ProgramName().c_str(), bar.c_str(), fraction * 100, counts.c_str(),
                 tail.c_str(), final_line ? "\n" : "");
  } else {
    std::fprintf(stderr, "%s: %s%s (%s)\n", log::ProgramName().c_str(), total_ > 0 ? fmt::format("{:.0f}% ", fraction * 100).c_str() : "",
                 counts.c_str(), tail.c_str());
  }
  std::fflush(stderr);
}

}  // namespace rime
