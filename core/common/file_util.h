// Small file helpers shared by every module that writes files.
#pragma once

#include <filesystem>
#include <functional>
#include <istream>
#include <memory>
#include <ostream>
#include <string>
#include <string_view>

namespace evloc {

// Writes a file atomically and durably: `write` fills a stream on a temporary file next to
// `path` (a name unique to this process and call), which is flushed, closed, fsync'ed and renamed
// over `path` only if `write` returns without throwing; the parent directory is then fsync'ed so
// that the rename survives a power loss. A crash or an error never leaves a half-written `path`.
// Throws IoError naming the file when any write, close, fsync or rename fails.
void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write);

// Same, for content already in memory.
void WriteFileAtomically(const std::filesystem::path& path, std::string_view content);

// A name for a temporary file next to `path`: ".NAME.<tag>-<pid>-<counter>-<random>", unique
// among the calls of every process on the host.
std::filesystem::path UniqueSiblingName(const std::filesystem::path& path, std::string_view tag);

// fsyncs a file or directory. Throws IoError naming it when it cannot be opened or synced.
void SyncPath(const std::filesystem::path& path);

// Reads a whole (small) file into a string. Throws IoError when it cannot.
std::string ReadFileToString(const std::filesystem::path& path);

// Opens a file for binary reading (the streaming readers' input). Throws IoError naming it and
// the reason when it cannot be opened.
std::unique_ptr<std::istream> OpenInputFile(const std::filesystem::path& path);

// True when the file starts with the bytes `magic` (format detection). Throws IoError when it
// cannot be opened.
bool FileStartsWith(const std::filesystem::path& path, std::string_view magic);

// An exclusive advisory lock (flock) on `path`, created when missing, held until destruction.
// Serialises writers of the same file across processes and threads (each lock opens its own
// file description). Throws IoError when the lock file cannot be created or locked.
class ScopedFileLock {
 public:
  explicit ScopedFileLock(const std::filesystem::path& path);
  ~ScopedFileLock();
  ScopedFileLock(const ScopedFileLock&) = delete;
  ScopedFileLock& operator=(const ScopedFileLock&) = delete;

 private:
  int fd_ = -1;
};

// A folder made for this process only (mode 0700, `TMPDIR/PREFIX-XXXXXX` by mkdtemp, TMPDIR
// being std::filesystem::temp_directory_path()), removed with everything in it on destruction.
class PrivateTempFolder {
 public:
  // Throws IoError naming the temporary directory and `purpose` (what the folder is for) when the
  // folder cannot be made.
  PrivateTempFolder(std::string_view prefix, std::string_view purpose);
  ~PrivateTempFolder();
  PrivateTempFolder(const PrivateTempFolder&) = delete;
  PrivateTempFolder& operator=(const PrivateTempFolder&) = delete;

  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

}  // namespace evloc
