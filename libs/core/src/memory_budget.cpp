#include "rime/core/memory_budget.h"

#include <fmt/format.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "rime/core/error.h"

namespace fs = std::filesystem;

namespace rime {

std::uint64_t ParseByteSize(std::string_view text, std::string_view flag) {
  const auto fail = [&](const char* why) {
    return Error(ExitCode::kUsage, fmt::format("{}: expected a size like 512M, 4G, 1.5GiB or a number of bytes", why),
                 fmt::format("{} {}", flag, text));
  };
  std::size_t i = 0;
  std::string number;
  bool dot = false;
  for (; i < text.size() && (std::isdigit(static_cast<unsigned char>(text[i])) || (text[i] == '.' && !dot)); ++i) {
    dot = dot || text[i] == '.';
    number += text[i];
  }
  if (number.empty() || number == ".") throw fail("not a size");
  std::string suffix;
  for (; i < text.size(); ++i) suffix += char(std::toupper(static_cast<unsigned char>(text[i])));
  // K, M, G, T; each optionally followed by "I" and/or "B"; or a bare "B".
  double scale = 1;
  std::string_view rest = suffix;
  if (!rest.empty() && rest != "B") {
    const std::string_view units = "KMGT";
    const std::size_t power = units.find(rest[0]);
    if (power == std::string_view::npos) throw fail("unknown unit");
    scale = std::pow(1024.0, double(power + 1));
    rest.remove_prefix(1);
    if (!rest.empty() && rest[0] == 'I') rest.remove_prefix(1);
    if (!rest.empty() && rest[0] == 'B') rest.remove_prefix(1);
    if (!rest.empty()) throw fail("unknown unit");
  }
  const double bytes = std::strtod(number.c_str(), nullptr) * scale;
  if (!(bytes >= 1)) throw fail("a memory budget must be at least one byte");
  if (!(bytes < 9.2e18)) throw fail("too large");
  return static_cast<std::uint64_t>(bytes);
}

std::string FormatBytes(double bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB"};
  int u = 0;
  while (bytes >= 1024 && u < 5) bytes /= 1024, ++u;
  if (u == 0) return fmt::format("{:.0f} B", bytes);
  return bytes < 100 ? fmt::format("{:.3g} {}", bytes, units[u]) : fmt::format("{:.0f} {}", bytes, units[u]);
}

std::string FormatCount(double count) {
  const char* units[] = {"", " k", " M", " G", " T"};
  int u = 0;
  while (count >= 1000 && u < 4) count /= 1000, ++u;
  if (u == 0) return fmt::format("{:.0f}", count);
  return count < 100 ? fmt::format("{:.3g}{}", count, units[u]) : fmt::format("{:.0f}{}", count, units[u]);
}

namespace {

std::optional<std::uint64_t> ReadNumber(const fs::path& file) {
  std::ifstream in(file);
  std::string word;
  if (!(in >> word) || word.empty() || !std::isdigit(static_cast<unsigned char>(word[0]))) return std::nullopt;  // "max"
  return std::strtoull(word.c_str(), nullptr, 10);
}

// Free room under the tightest cgroup memory limit on the way from this process's cgroup to the
// root (v2 memory.max, v1 memory.limit_in_bytes); limits of 2^60 and more mean "none".
std::optional<std::uint64_t> CgroupRoom() {
  std::ifstream in("/proc/self/cgroup");
  std::optional<std::uint64_t> room;
  const auto consider = [&](const fs::path& limit_file, const fs::path& usage_file) {
    const auto limit = ReadNumber(limit_file);
    if (!limit || *limit >= (std::uint64_t(1) << 60)) return;
    const std::uint64_t used = ReadNumber(usage_file).value_or(0);
    const std::uint64_t free = *limit > used ? *limit - used : 0;
    room = room ? std::min(*room, free) : free;
  };
  for (std::string line; std::getline(in, line);) {
    const std::size_t a = line.find(':'), b = line.find(':', a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1);
    const fs::path path = fs::path(line.substr(b + 1)).relative_path();
    const bool v2 = controllers.empty() && line.compare(0, a, "0") == 0;
    const bool v1 = (',' + controllers + ',').find(",memory,") != std::string::npos;
    if (!v2 && !v1) continue;
    const fs::path mount = v2 ? fs::path("/sys/fs/cgroup") : fs::path("/sys/fs/cgroup/memory");
    const char* limit_name = v2 ? "memory.max" : "memory.limit_in_bytes";
    const char* usage_name = v2 ? "memory.current" : "memory.usage_in_bytes";
    // Inside a container the mount often shows the process's own cgroup at its root.
    for (fs::path p = path;; p = p.parent_path()) {
      consider(mount / p / limit_name, mount / p / usage_name);
      if (p.empty()) break;
    }
  }
  return room;
}

}  // namespace

std::optional<MemoryBudget> AvailableMemory() {
  std::optional<MemoryBudget> result;
  std::ifstream in("/proc/meminfo");
  for (std::string line; std::getline(in, line);) {
    std::istringstream fields(line);
    std::string key;
    std::uint64_t kib = 0;
    if (fields >> key >> kib && key == "MemAvailable:") result = MemoryBudget{kib * 1024, "MemAvailable"};
  }
  if (const auto room = CgroupRoom(); room && (!result || *room < result->bytes)) result = MemoryBudget{*room, "cgroup memory limit"};
  return result;
}

MemoryBudget ResolveMemoryBudget(const std::string& flag_text) {
  if (!flag_text.empty()) return {ParseByteSize(flag_text), "--memory-budget"};
  return AvailableMemory().value_or(MemoryBudget{});
}

double ConcurrentPeak(const std::vector<double>& estimates, std::size_t at_once, std::size_t* largest) {
  std::vector<std::size_t> order(estimates.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return estimates[a] > estimates[b]; });
  if (largest) *largest = order.empty() ? 0 : order.front();
  double sum = 0;
  for (std::size_t k = 0; k < std::min(at_once, order.size()); ++k) sum += estimates[order[k]];
  return sum;
}

std::uint64_t ResidentBytes() {
  std::ifstream in("/proc/self/statm");
  std::uint64_t size = 0, resident = 0;
  if (!(in >> size >> resident)) return 0;
  return resident * std::uint64_t(sysconf(_SC_PAGESIZE));
}

void CheckMemoryBudget(const MemoryBudget& budget, double estimate_bytes, std::string_view driver, std::string_view context) {
  // The libraries, the inputs read so far and the heap already held stay for the whole run.
  const double peak = double(ResidentBytes()) + estimate_bytes;
  if (!(peak > double(budget.bytes))) return;
  throw Error(ExitCode::kOverBudget, fmt::format("needs about {} for {} ({}), budget {} ({})", FormatBytes(peak), driver, context,
                                                 FormatBytes(double(budget.bytes)), budget.source));
}

}  // namespace rime
