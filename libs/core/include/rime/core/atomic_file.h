/// @file atomic_file.h
/// @brief Write to a temporary name, then rename: a crash never leaves a file that looks finished.
#pragma once

#include <filesystem>

namespace rime {

/// Usage: `AtomicFile f(final); write to f.temp_path(); f.Commit();`. Without Commit the temporary
/// file is deleted in the destructor. The temporary lives beside the final file (same filesystem,
/// so the rename is atomic) and is named `<name>.tmp.<pid>.<n>`.
class AtomicFile {
 public:
  explicit AtomicFile(std::filesystem::path final_path);
  ~AtomicFile();
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  const std::filesystem::path& temp_path() const { return temp_; }
  const std::filesystem::path& final_path() const { return final_; }
  /// fsyncs the temporary file and renames it over the final path; throws rime::Error on failure.
  void Commit();

 private:
  std::filesystem::path final_;
  std::filesystem::path temp_;
  bool committed_ = false;
};

/// Writes a whole text file atomically.
void WriteFileAtomically(const std::filesystem::path& path, const std::string& contents);

/// The whole contents of a file; empty when it is missing or unreadable (callers treat both alike).
std::string ReadFileOrEmpty(const std::filesystem::path& path);

}  // namespace rime
