#include "core/events/output_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <string>
#include <system_error>

#include "core/common/error.h"

namespace evloc {

TemporaryOutputFile::TemporaryOutputFile(std::filesystem::path path) : path_(std::move(path)) {
  static std::atomic<int> counter{0};
  temporary_path_ = path_;
  temporary_path_ += ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter++);
  stream_.open(temporary_path_, std::ios::binary | std::ios::trunc);
  if (!stream_) {
    throw IoError(path_.string() + ": cannot create temporary file " + temporary_path_.string());
  }
}

TemporaryOutputFile::~TemporaryOutputFile() {
  if (committed_) return;
  stream_.close();
  std::error_code ignored;
  std::filesystem::remove(temporary_path_, ignored);
}

void TemporaryOutputFile::Commit() {
  if (committed_) return;
  stream_.flush();
  const bool written = static_cast<bool>(stream_);
  stream_.close();
  if (!written || stream_.fail()) {
    throw IoError(path_.string() + ": writing " + temporary_path_.string() + " failed");
  }
  const int descriptor = ::open(temporary_path_.c_str(), O_RDONLY);
  if (descriptor < 0 || ::fsync(descriptor) != 0) {
    if (descriptor >= 0) ::close(descriptor);
    throw IoError(path_.string() + ": cannot sync " + temporary_path_.string());
  }
  ::close(descriptor);
  std::error_code error;
  std::filesystem::rename(temporary_path_, path_, error);
  if (error) {
    throw IoError(path_.string() +
                  ": cannot rename the temporary file into place: " + error.message());
  }
  committed_ = true;
}

}  // namespace evloc
