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
    // POSIX calls rather than a stream, so the message can say why (ENOSPC, EFBIG, EACCES).
    const int fd = ::open(file.temp_path().c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) throw IoError(std::string("cannot create file: ") + std::strerror(errno), path.string());
    std::size_t written = 0;
    while (written < contents.size()) {
      const ssize_t n = ::write(fd, contents.data() + written, contents.size() - written);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        const int error = n < 0 ? errno : ENOSPC;
        ::close(fd);
        throw IoError(std::string("cannot write file: ") + std::strerror(error), path.string());
      }
      written += static_cast<std::size_t>(n);
    }
    if (::close(fd) != 0) throw IoError(std::string("cannot write file: ") + std::strerror(errno), path.string());
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
