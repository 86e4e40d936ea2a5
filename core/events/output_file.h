// A file written under a temporary name and renamed into place on Commit(), for the streaming
// event writers (whole-content writes use WriteFileAtomically from core/common/file_util.h).
#pragma once

#include <filesystem>
#include <fstream>

namespace evloc {

// An output file that appears at its final path only when complete.
class TemporaryOutputFile {
 public:
  // Opens a temporary file beside `path`. Throws IoError when it cannot be created.
  explicit TemporaryOutputFile(std::filesystem::path path);
  // Removes the temporary file unless Commit() succeeded.
  ~TemporaryOutputFile();
  TemporaryOutputFile(const TemporaryOutputFile&) = delete;
  TemporaryOutputFile& operator=(const TemporaryOutputFile&) = delete;

  // The stream to write to (binary mode).
  std::ofstream& stream() { return stream_; }
  // Flushes, syncs and renames the temporary file to the final path. Throws IoError.
  void Commit();
  // True after a successful Commit().
  bool committed() const { return committed_; }
  // The final path.
  const std::filesystem::path& path() const { return path_; }
  // The temporary path (exists until Commit() or destruction).
  const std::filesystem::path& temporary_path() const { return temporary_path_; }

 private:
  std::filesystem::path path_;
  std::filesystem::path temporary_path_;
  std::ofstream stream_;
  bool committed_ = false;
};

}  // namespace evloc
