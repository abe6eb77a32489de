#include "bake_state.h"

#include <fmt/format.h>

#include <fstream>
#include <stdexcept>
#include <type_traits>
#include <nlohmann/json.hpp>

#include "rime/core/atomic_file.h"
#include "rime/core/hash.h"
#include "rime/core/log.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace rime::bake {
namespace {
constexpr const char* kFormat = "rime.bake-state";
constexpr const char* kRecordFormat = "rime.bake-record";
constexpr int kVersion = 1;

json RecordJson(const JobRecord& r) {
  return {{"key", r.key}, {"components", r.components}, {"outputs", r.outputs}, {"seconds", r.seconds}};
}

JobRecord ParseRecord(const json& j) {
  JobRecord r;
  r.key = j.at("key").get<std::string>();
  r.components = j.at("components").get<std::map<std::string, std::string>>();
  r.outputs = j.at("outputs").get<std::map<std::string, std::string>>();
  r.seconds = j.value("seconds", 0.0);
  return r;
}

json StampJson(const FileStamp& s) { return {{"size", s.size}, {"mtime_ns", s.mtime_ns}, {"hash", s.hash}}; }
// get<integer>() casts a floating-point value, undefined behaviour when it is out of range.
template <class T>
T IntegerField(const json& j, const char* key) {
  const json& value = j.at(key);
  if (!value.is_number_integer() || (std::is_unsigned_v<T> && !value.is_number_unsigned()))
    throw std::runtime_error(fmt::format("'{}' is not an integer", key));
  return value.get<T>();
}

FileStamp ParseStamp(const json& f) {
  return FileStamp{IntegerField<std::uint64_t>(f, "size"), IntegerField<std::int64_t>(f, "mtime_ns"), f.at("hash").get<std::string>()};
}

}  // namespace

BakeState::BakeState(fs::path output_dir, fs::path state_file)
    : output_dir_(fs::absolute(output_dir).lexically_normal()), state_file_(std::move(state_file)) {}

std::string BakeState::Name(const fs::path& file) const {
  const fs::path absolute = fs::absolute(file).lexically_normal();
  const fs::path relative = absolute.lexically_relative(output_dir_);
  if (!relative.empty() && *relative.begin() != "..") return relative.generic_string();
  return absolute.generic_string();
}

fs::path BakeState::RecordFolder() const { return state_file_.parent_path() / "records"; }

void BakeState::Load() {
  std::lock_guard lock(mutex_);
  files_.clear();
  jobs_.clear();
  changed_.clear();
  merged_records_.clear();
  std::ifstream in(state_file_);
  if (in) {
    try {
      const json root = json::parse(in);
      if (root.value("format", "") != kFormat || root.value("version", 0) != kVersion) {
        log::Warn("ignoring {}: not a rime-bake state file of version {}; everything counts as stale", state_file_.string(), kVersion);
        return;
      }
      for (const auto& [name, f] : root.at("files").items()) files_[name] = ParseStamp(f);
      for (const auto& [id, j] : root.at("jobs").items()) jobs_[id] = ParseRecord(j);
    } catch (const std::exception& e) {
      log::Warn("ignoring corrupt state file {} ({}); everything counts as stale", state_file_.string(), e.what());
      files_.clear();
      jobs_.clear();
    }
  }
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(RecordFolder(), ec)) {
    if (entry.path().extension() != ".json") continue;  // skips temporaries of records being written
    try {
      std::ifstream record_in(entry.path());
      const json root = json::parse(record_in);
      if (root.value("format", "") != kRecordFormat || root.value("version", 0) != kVersion) throw std::runtime_error("unknown format");
      jobs_[root.at("job").get<std::string>()] = ParseRecord(root.at("record"));
      for (const auto& [name, f] : root.at("files").items()) files_[name] = ParseStamp(f);
      merged_records_.push_back(entry.path());
    } catch (const std::exception& e) {
      log::Warn("ignoring corrupt job record {} ({}); its job counts as stale", entry.path().string(), e.what());
    }
  }
}

void BakeState::Save() {
  if (per_job_records_) {
    std::map<std::string, std::string> texts;  // job id -> record file text
    {
      std::lock_guard lock(mutex_);
      for (const auto& id : changed_) {
        const JobRecord& r = jobs_.at(id);
        json files = json::object();
        for (const auto& [name, hash] : r.outputs)
          if (const auto it = files_.find(name); it != files_.end()) files[name] = StampJson(it->second);
        const json root = {{"format", kRecordFormat}, {"version", kVersion}, {"job", id}, {"record", RecordJson(r)}, {"files", files}};
        texts[id] = root.dump(1) + "\n";
      }
      changed_.clear();
    }
    fs::create_directories(RecordFolder());
    for (const auto& [id, text] : texts) WriteFileAtomically(RecordFolder() / (id + ".json"), text);
    return;
  }
  json root;
  std::vector<fs::path> merged;
  {
    std::lock_guard lock(mutex_);
    root["format"] = kFormat;
    root["version"] = kVersion;
    json files = json::object();
    for (const auto& [name, s] : files_) files[name] = StampJson(s);
    json jobs = json::object();
    for (const auto& [id, r] : jobs_) jobs[id] = RecordJson(r);
    root["files"] = std::move(files);
    root["jobs"] = std::move(jobs);
    merged.swap(merged_records_);
  }
  fs::create_directories(state_file_.parent_path());
  WriteFileAtomically(state_file_, root.dump(1) + "\n");
  for (const auto& file : merged) {
    std::error_code ec;
    fs::remove(file, ec);
  }
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
  changed_.insert(job_id);
}

void BakeState::EraseRecord(const std::string& job_id) {
  std::lock_guard lock(mutex_);
  jobs_.erase(job_id);
}

}  // namespace rime::bake
