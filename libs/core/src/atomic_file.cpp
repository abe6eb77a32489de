#include "rime/core/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "rime/core/error.h"

namespace rime {
namespace {
std::atomic<int> g_counter{0};
}

AtomicFile::AtomicFile(std::filesystem::path final_path) : final_(std::move(final_path)) {
  temp_ = final_;
  temp_ += ".tmp." + std::to_string(getpid()) + "." + std::to_string(g_counter++);
  if (final_.has_parent_path()) {
    std::error_code ec;
    std::filesystem::create_directories(final_.parent_path(), ec);
    if (ec) throw IoError("cannot create folder: " + ec.message(), final_.parent_path().string());
  }
}

AtomicFile::~AtomicFile() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove(temp_, ec);
  }
}

void AtomicFile::Commit() {
  const int fd = ::open(temp_.c_str(), O_RDONLY);
  if (fd < 0) throw IoError(std::string("temporary file vanished before commit: ") + std::strerror(errno), temp_.string());
  const int sync_result = ::fsync(fd);
  ::close(fd);
  if (sync_result != 0) throw IoError(std::string("cannot flush file: ") + std::strerror(errno), final_.string());
  std::error_code ec;
  std::filesystem::rename(temp_, final_, ec);
  if (ec) throw IoError("cannot rename temporary file into place: " + ec.message(), final_.string());
  committed_ = true;
}

void WriteFileAtomically(const std::filesystem::path& path, const std::string& contents) {
  AtomicFile file(path);
  {
    std::ofstream out(file.temp_path(), std::ios::binary);
    out << contents;
    out.flush();
    if (!out) throw IoError("cannot write file (disk full?)", path.string());
  }
  file.Commit();
}

std::string ReadFileOrEmpty(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

}  // namespace rime
