#include "core/common/file_util.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "core/common/error.h"

namespace evloc {
namespace {

std::string ErrnoText() { return std::strerror(errno); }

// Closes `fd`, throwing IoError naming `path` when close fails (NFS and some file systems report
// write errors only there).
void CloseOrThrow(int fd, const std::filesystem::path& path) {
  if (::close(fd) != 0) {
    throw IoError("cannot close '" + path.string() + "': " + ErrnoText() +
                  " (the data may not be on disk; check the file system)");
  }
}

}  // namespace

std::filesystem::path UniqueSiblingName(const std::filesystem::path& path, std::string_view tag) {
  static std::atomic<uint64_t> counter{0};
  std::random_device device;
  std::ostringstream name;
  name << "." << path.filename().string() << "." << tag << "-" << ::getpid() << "-"
       << counter.fetch_add(1) << "-" << std::hex << device();
  return path.parent_path() / name.str();
}

void SyncPath(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    throw IoError("cannot open '" + path.string() + "' to sync it: " + ErrnoText());
  }
  if (::fsync(fd) != 0) {
    const std::string reason = ErrnoText();
    ::close(fd);
    throw IoError("cannot fsync '" + path.string() + "': " + reason +
                  " (the data may not be on disk; check the file system)");
  }
  CloseOrThrow(fd, path);
}

void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write) {
  const std::filesystem::path temporary = UniqueSiblingName(path, "tmp");
  try {
    {
      std::ofstream stream(temporary, std::ios::binary | std::ios::trunc);
      if (!stream) {
        throw IoError("cannot create '" + temporary.string() + "': " + ErrnoText() +
                      " (does the directory exist and is it writable?)");
      }
      write(stream);
      stream.flush();
      if (!stream) {
        throw IoError("cannot write '" + temporary.string() + "' (disk full?)");
      }
      stream.close();
      if (!stream) {
        throw IoError("cannot close '" + temporary.string() + "' (disk full?)");
      }
    }
    SyncPath(temporary);
    std::error_code error;
    std::filesystem::rename(temporary, path, error);
    if (error) {
      throw IoError("cannot rename '" + temporary.string() + "' to '" + path.string() +
                    "': " + error.message());
    }
  } catch (...) {
    std::error_code ignored;
    std::filesystem::remove(temporary, ignored);
    throw;
  }
  const std::filesystem::path parent = path.parent_path();
  SyncPath(parent.empty() ? std::filesystem::path(".") : parent);
}

void WriteFileAtomically(const std::filesystem::path& path, std::string_view content) {
  WriteFileAtomically(path, [&](std::ostream& stream) {
    stream.write(content.data(), static_cast<std::streamsize>(content.size()));
  });
}

std::unique_ptr<std::istream> OpenInputFile(const std::filesystem::path& path) {
  auto stream = std::make_unique<std::ifstream>(path, std::ios::binary);
  if (!*stream) throw IoError(path.string() + ": cannot open: " + ErrnoText());
  return stream;
}

bool FileStartsWith(const std::filesystem::path& path, std::string_view magic) {
  const auto stream = OpenInputFile(path);
  std::string start(magic.size(), '\0');
  stream->read(start.data(), static_cast<std::streamsize>(start.size()));
  return stream->gcount() == static_cast<std::streamsize>(magic.size()) && start == magic;
}

std::string ReadFileToString(const std::filesystem::path& path) {
  std::ifstream stream(path, std::ios::binary);
  if (!stream) {
    throw IoError("cannot open '" + path.string() + "': " + ErrnoText());
  }
  std::ostringstream content;
  content << stream.rdbuf();
  if (stream.bad()) {
    throw IoError("cannot read '" + path.string() + "'");
  }
  return content.str();
}

ScopedFileLock::ScopedFileLock(const std::filesystem::path& path) {
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) {
    throw IoError("cannot create the lock file '" + path.string() + "': " + ErrnoText() +
                  " (is the directory writable?)");
  }
  int result;
  do {
    result = ::flock(fd_, LOCK_EX);
  } while (result != 0 && errno == EINTR);
  if (result != 0) {
    const std::string reason = ErrnoText();
    ::close(fd_);
    throw IoError("cannot lock '" + path.string() + "': " + reason);
  }
}

ScopedFileLock::~ScopedFileLock() {
  if (fd_ >= 0) ::close(fd_);  // Closing the last descriptor releases the flock.
}

PrivateTempFolder::PrivateTempFolder(std::string_view prefix, std::string_view purpose) {
  std::error_code no_temp;
  const std::filesystem::path temp = std::filesystem::temp_directory_path(no_temp);
  std::string pattern = (temp / (std::string(prefix) + "-XXXXXX")).string();
  if (no_temp || ::mkdtemp(pattern.data()) == nullptr) {
    throw IoError("cannot make a private folder for " + std::string(purpose) + " under '" +
                  temp.string() +
                  "' (set TMPDIR to a writable folder; in Kubernetes mount an emptyDir at /tmp)");
  }
  path_ = pattern;
}

PrivateTempFolder::~PrivateTempFolder() {
  std::error_code ignored;
  std::filesystem::remove_all(path_, ignored);
}

}  // namespace evloc
