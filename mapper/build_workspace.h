// The COLMAP workspace of `evloc-mapper build` and its staging (docs/mapper.md, "Outputs"): the
// fingerprints that decide whether a previous run's features, matches and model are reused, the
// per-stage markers, and the staging directory the map is assembled in before it is renamed.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "mapper/build_inputs.h"
#include "mapper/map_builder.h"

namespace evloc::mapper {

// CRC32C of a file's bytes as 8 hex digits; throws IoError when it cannot be read.
std::string FileContentHash(const std::filesystem::path& path);

// Fingerprint of the inputs that determine the COLMAP features and matches (the workspace's
// fingerprint.txt): the COLMAP version, the image folder, each image's name, size and content
// hash (a re-rendered image of the same size invalidates the features), the camera, the matcher
// and the feature count.
std::string WorkspaceFingerprint(const MapBuilderOptions& options,
                                 const std::vector<InputImage>& images,
                                 const std::optional<Camera>& camera, MatcherType matcher,
                                 const std::string& colmap_version);

// Fingerprint of the model stage (mapper or triangulation) on top of the workspace's: its options
// and the known poses. Known and estimated poses keep separate models, so one workspace serves
// both without matching twice.
std::string ModelFingerprint(const MapBuilderOptions& options,
                             const std::string& workspace_fingerprint);

// True when the stage marker `marker` exists and holds `fingerprint`.
bool MarkerMatches(const std::filesystem::path& marker, const std::string& fingerprint);

// Prepares the workspace: a fresh folder, or a previous one of the same inputs (reused), or a
// previous one of other inputs (emptied). Throws InvalidArgumentError for a folder that is not a
// mapper workspace, IoError when it cannot be cleared or created.
void PrepareWorkspace(const std::filesystem::path& workspace, const std::string& fingerprint);

// Copies `source` into `directory` under its file name; throws IoError.
void CopyFileInto(const std::filesystem::path& source, const std::filesystem::path& directory);

// A staging directory, removed on destruction unless committed.
class StagingDirectory {
 public:
  // Creates `path` afresh; throws IoError when it cannot.
  explicit StagingDirectory(std::filesystem::path path);
  // Removes the directory unless CommitTo succeeded.
  ~StagingDirectory();
  StagingDirectory(const StagingDirectory&) = delete;
  StagingDirectory& operator=(const StagingDirectory&) = delete;
  // The directory.
  const std::filesystem::path& path() const { return path_; }
  // Renames the staging directory to `target` (an absent or empty directory); throws IoError.
  void CommitTo(const std::filesystem::path& target);

 private:
  std::filesystem::path path_;
  bool committed_ = false;
};

}  // namespace evloc::mapper
