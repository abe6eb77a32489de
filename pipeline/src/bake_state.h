/// @file bake_state.h
/// @brief What rime-bake remembers between runs (`<cache>/.rime-bake/state.json`): file stamps for
/// cheap checks and, per job, the key it ran with and the content hashes of what it wrote.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <mutex>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace rime::bake {

/// Size + modification time: when both match the recorded stamp the recorded content hash is
/// reused (doit's cheap check); otherwise the file is hashed again.
struct FileStamp {
  std::uint64_t size = 0;
  std::int64_t mtime_ns = 0;
  std::string hash;  // xxHash64 of the content, hex
};

/// One job's record: the key components it last succeeded with and the hashes of its outputs.
struct JobRecord {
  std::string key;
  std::map<std::string, std::string> components;  // "tool", "command", "scene:water", "input:<path>"
  std::map<std::string, std::string> outputs;     // path -> content hash
  double seconds = 0;
};

/// Thread-safe state of one output folder. Paths are stored relative to the output folder when they
/// lie inside it, so a moved output folder stays valid.
class BakeState {
 public:
  BakeState(std::filesystem::path output_dir, std::filesystem::path state_file);

  /// Reads the state file if it exists, then the per-job record files (see UsePerJobRecords), which
  /// are newer; a corrupt or foreign file is reported and ignored.
  void Load();
  /// Writes the state atomically. With per-job records: writes one file per job recorded since
  /// Load instead. Otherwise the per-job files read by Load are folded into the state file and
  /// removed (the caller holds the bake lock exclusively, so no farm task is writing them).
  void Save();
  /// Farm tasks run side by side on many nodes and must not rewrite each other's state file: each
  /// writes its own records to `<state folder>/records/<job>.json`, read back by every Load.
  void UsePerJobRecords() { per_job_records_ = true; }

  /// Content hash of a file, reusing the recorded one when size and mtime match; nullopt if missing.
  std::optional<std::string> ContentHash(const std::filesystem::path& file);

  std::optional<JobRecord> Record(const std::string& job_id) const;
  void SetRecord(const std::string& job_id, JobRecord record);
  void EraseRecord(const std::string& job_id);

  /// The name a path is stored under (relative to the output folder when inside it).
  std::string Name(const std::filesystem::path& file) const;

 private:
  std::filesystem::path RecordFolder() const;

  std::filesystem::path output_dir_;
  std::filesystem::path state_file_;
  mutable std::mutex mutex_;
  std::map<std::string, FileStamp> files_;
  std::map<std::string, JobRecord> jobs_;
  bool per_job_records_ = false;
  std::set<std::string> changed_;                      // jobs recorded since Load
  std::vector<std::filesystem::path> merged_records_;  // per-job files read by Load
};

}  // namespace rime::bake
