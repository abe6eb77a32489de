#include "bake_state.h"

#include <fstream>
#include <nlohmann/json.hpp>

#include "rime/core/atomic_file.h"
#include "rime/core/hash.h"
#include "rime/core/log.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rime::bake {
namespace {
constexpr const char* kFormat = "rime.bake-state";
constexpr int kVersion = 1;
}  // namespace

BakeState::BakeState(fs::path output_dir, fs::path state_file)
    : output_dir_(fs::absolute(output_dir).lexically_normal()), state_file_(std::move(state_file)) {}

std::string BakeState::Name(const fs::path& file) const {
  const fs::path absolute = fs::absolute(file).lexically_normal();
  const fs::path relative = absolute.lexically_relative(output_dir_);
  if (!relative.empty() && *relative.begin() != "..") return relative.generic_string();
  return absolute.generic_string();
}

void BakeState::Load() {
  std::lock_guard lock(mutex_);
  files_.clear();
  jobs_.clear();
  std::ifstream in(state_file_);
  if (!in) return;
  try {
    const json root = json::parse(in);
    if (root.value("format", "") != kFormat || root.value("version", 0) != kVersion) {
      log::Warn("ignoring {}: not a rime-bake state file of version {}; everything counts as stale", state_file_.string(), kVersion);
      return;
    }
    for (const auto& [name, f] : root.at("files").items())
      files_[name] = FileStamp{f.at("size").get<std::uint64_t>(), f.at("mtime_ns").get<std::int64_t>(), f.at("hash").get<std::string>()};
    for (const auto& [id, j] : root.at("jobs").items()) {
      JobRecord r;
      r.key = j.at("key").get<std::string>();
      r.components = j.at("components").get<std::map<std::string, std::string>>();
      r.outputs = j.at("outputs").get<std::map<std::string, std::string>>();
      r.seconds = j.value("seconds", 0.0);
      jobs_[id] = std::move(r);
    }
  } catch (const std::exception& e) {
    log::Warn("ignoring corrupt state file {} ({}); everything counts as stale", state_file_.string(), e.what());
    files_.clear();
    jobs_.clear();
  }
}

void BakeState::Save() {
  json root;
  {
    std::lock_guard lock(mutex_);
    root["format"] = kFormat;
    root["version"] = kVersion;
    json files = json::object();
    for (const auto& [name, s] : files_) files[name] = {{"size", s.size}, {"mtime_ns", s.mtime_ns}, {"hash", s.hash}};
    json jobs = json::object();
    for (const auto& [id, r] : jobs_)
      jobs[id] = {{"key", r.key}, {"components", r.components}, {"outputs", r.outputs}, {"seconds", r.seconds}};
    root["files"] = std::move(files);
    root["jobs"] = std::move(jobs);
  }
  fs::create_directories(state_file_.parent_path());
  WriteFileAtomically(state_file_, root.dump(1) + "\n");
}

std::optional<std::string> BakeState::ContentHash(const fs::path& file) {
  std::error_code ec;
  const auto status = fs::status(file, ec);
  if (ec || !fs::is_regular_file(status)) return std::nullopt;
  FileStamp stamp;
  stamp.size = fs::file_size(file, ec);
  if (ec) return std::nullopt;
  const auto mtime = fs::last_write_time(file, ec);
  if (ec) return std::nullopt;
  stamp.mtime_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(mtime.time_since_epoch()).count();
  const std::string name = Name(file);
  {
    std::lock_guard lock(mutex_);
    const auto it = files_.find(name);
    if (it != files_.end() && it->second.size == stamp.size && it->second.mtime_ns == stamp.mtime_ns) return it->second.hash;
  }
  stamp.hash = HexHash(HashFile(file));  // outside the lock: hashing big frames must not serialise jobs
  std::lock_guard lock(mutex_);
  files_[name] = stamp;
  return stamp.hash;
}

std::optional<JobRecord> BakeState::Record(const std::string& job_id) const {
  std::lock_guard lock(mutex_);
  const auto it = jobs_.find(job_id);
  if (it == jobs_.end()) return std::nullopt;
  return it->second;
}

void BakeState::SetRecord(const std::string& job_id, JobRecord record) {
  std::lock_guard lock(mutex_);
  jobs_[job_id] = std::move(record);
}

void BakeState::EraseRecord(const std::string& job_id) {
  std::lock_guard lock(mutex_);
  jobs_.erase(job_id);
}

}  // namespace rime::bake
