#include "core/common/file_util.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "core/common/error.h"

namespace evloc {
namespace {

std::filesystem::path TemporaryNameFor(const std::filesystem::path& path) {
  std::random_device device;
  std::ostringstream name;
  name << "." << path.filename().string() << ".tmp-" << ::getpid() << "-" << std::hex << device();
  return path.parent_path() / name.str();
}

void SyncFile(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

}  // namespace

void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write) {
  const std::filesystem::path temporary = TemporaryNameFor(path);
  try {
    {
      std::ofstream stream(temporary, std::ios::binary | std::ios::trunc);
      if (!stream) {
        throw IoError("cannot create '" + temporary.string() + "': " + std::strerror(errno) +
                      " (does the directory exist and is it writable?)");
      }
      write(stream);
      stream.flush();
      if (!stream) {
        throw IoError("cannot write '" + temporary.string() + "' (disk full?)");
      }
    }
    SyncFile(temporary);
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
}

void WriteFileAtomically(const std::filesystem::path& path, std::string_view content) {
  WriteFileAtomically(path, [&](std::ostream& stream) {
    stream.write(content.data(), static_cast<std::streamsize>(content.size()));
  });
}

std::string ReadFileToString(const std::filesystem::path& path) {
  std::ifstream stream(path, std::ios::binary);
  if (!stream) {
    throw IoError("cannot open '" + path.string() + "': " + std::strerror(errno));
  }
  std::ostringstream content;
  content << stream.rdbuf();
  if (stream.bad()) {
    throw IoError("cannot read '" + path.string() + "'");
  }
  return content.str();
}

}  // namespace evloc
