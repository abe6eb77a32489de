/// @file temp_folder.h
/// @brief A fresh folder under the system's temporary directory that removes itself with
/// everything in it, so that tests leave nothing behind.
///
/// Set RIME_KEEP_TEST_FILES=1 to keep the folders for debugging; each kept folder is named on
/// stderr. Under CTest, TMPDIR points into the build tree and a final test fails if anything is
/// left there (tests/support/CMakeLists.txt).
#pragma once

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <stdexcept>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>

namespace rime::test {

/// True when RIME_KEEP_TEST_FILES=1: temporary test files stay for inspection.
inline bool KeepTestFiles() {
  const char* keep = std::getenv("RIME_KEEP_TEST_FILES");
  return keep != nullptr && std::string_view(keep) == "1";
}

/// Owns `<parent>/rime_<label>_XXXXXX` (unique per process and call, made by mkdtemp; the parent
/// is the system's temporary directory unless given) and removes it on destruction. Only the
/// creating process removes it, so a forked child that unwinds cannot delete its parent's files.
class TempFolder {
 public:
  explicit TempFolder(std::string_view label, const std::filesystem::path& parent = std::filesystem::temp_directory_path()) {
    std::string pattern = (parent / ("rime_" + std::string(label) + "_XXXXXX")).string();
    if (::mkdtemp(pattern.data()) == nullptr) throw std::runtime_error("cannot create a temporary folder from " + pattern);
    path_ = pattern;
  }
  ~TempFolder() { Remove(); }

  TempFolder(const TempFolder&) = delete;
  TempFolder& operator=(const TempFolder&) = delete;
  TempFolder(TempFolder&& other) noexcept : path_(std::exchange(other.path_, {})), owner_(other.owner_) {}
  TempFolder& operator=(TempFolder&& other) noexcept {
    if (this != &other) {
      Remove();
      path_ = std::exchange(other.path_, {});
      owner_ = other.owner_;
    }
    return *this;
  }

  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::filesystem::path& name) const { return path_ / name; }
  operator const std::filesystem::path&() const { return path_; }

 private:
  void Remove() {
    if (path_.empty() || ::getpid() != owner_) return;
    if (KeepTestFiles()) {
      std::cerr << "RIME_KEEP_TEST_FILES=1: kept " << path_.string() << "\n";
      return;
    }
    std::error_code ignored;  // a destructor must not throw; the suite's litter check reports what stays
    std::filesystem::remove_all(path_, ignored);
    path_.clear();
  }

  std::filesystem::path path_;
  pid_t owner_ = ::getpid();
};

}  // namespace rime::test
