#include "mapper/build_workspace.h"

#include <cstdio>
#include <fstream>
#include <iomanip>
#include <sstream>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "mapper/colmap_model.h"
#include "maps/crc32c.h"

namespace evloc::mapper {

namespace fs = std::filesystem;

std::string FileContentHash(const fs::path& path) {
  std::ifstream stream(path, std::ios::binary);
  if (!stream) throw IoError("cannot read " + path.string());
  std::vector<char> buffer(1 << 16);
  uint32_t crc = 0;
  while (stream) {
    stream.read(buffer.data(), static_cast<std::streamsize>(buffer.size()));
    crc = ExtendCrc32c(crc, buffer.data(), static_cast<size_t>(stream.gcount()));
  }
  if (stream.bad()) throw IoError("cannot read " + path.string());
  std::ostringstream text;
  text << std::hex << std::setw(8) << std::setfill('0') << crc;
  return text.str();
}

std::string WorkspaceFingerprint(const MapBuilderOptions& options,
                                 const std::vector<InputImage>& images,
                                 const std::optional<Camera>& camera, MatcherType matcher,
                                 const std::string& colmap_version) {
  std::ostringstream text;
  // v3: content hashes instead of file sizes alone, and the COLMAP version; v4: the matcher
  // implementation (evloc's deterministic one or COLMAP's).
  text << "evloc-mapper colmap workspace v4\n";
  text << "colmap " << colmap_version << "\n";
  text << "images " << fs::absolute(options.image_dir).lexically_normal().string() << "\n";
  for (const InputImage& image : images) {
    const fs::path path = options.image_dir / image.name;
    std::error_code error;
    text << image.name << " " << fs::file_size(path, error) << " crc32c " << FileContentHash(path)
         << "\n";
  }
  if (camera) {
    const ColmapCamera colmap_camera = ColmapCameraFromCamera(*camera, 1);
    text << "camera " << colmap_camera.model_name << " " << FormatColmapParams(colmap_camera.params)
         << "\n";
  } else {
    text << "camera estimated\n";
  }
  text << "matcher " << MatcherTypeName(matcher) << " overlap "
       << options.colmap.sequential_overlap;
  if (matcher == MatcherType::kRetrieval) {
    text << " neighbours " << options.colmap.retrieval_neighbours;
  }
  text << " features " << options.colmap.max_num_features << "\n";
  text << (options.colmap.deterministic ? "matching evloc deterministic v2\n"
                                        : "matching colmap\n");
  return text.str();
}

std::string ModelFingerprint(const MapBuilderOptions& options,
                             const std::string& workspace_fingerprint) {
  std::ostringstream text;
  text << workspace_fingerprint;
  // v3: the estimated model with fixed intrinsics is filtered and adjusted after mapping, once
  // per bound.
  text << "model v3 mapper " << options.colmap.abs_pose_min_num_inliers << " "
       << options.colmap.abs_pose_min_inlier_ratio << " " << options.colmap.min_num_matches
       << " refinement";
  for (const double bound : options.colmap.fixed_camera_refinement_px) text << " " << bound;
  text << "\n";
  if (options.known_poses) {
    text << "known poses\n" << ReadFileToString(*options.known_poses) << "\n";
  }
  return text.str();
}

bool MarkerMatches(const fs::path& marker, const std::string& fingerprint) {
  std::error_code error;
  if (!fs::exists(marker, error)) return false;
  return ReadFileToString(marker) == fingerprint;
}

void PrepareWorkspace(const fs::path& workspace, const std::string& fingerprint) {
  std::error_code error;
  const fs::path fingerprint_file = workspace / "fingerprint.txt";
  if (fs::exists(workspace, error)) {
    if (!fs::is_directory(workspace, error)) {
      throw InvalidArgumentError("COLMAP workspace '" + workspace.string() +
                                 "' exists and is not a directory");
    }
    const bool is_empty = fs::is_empty(workspace, error);
    if (!is_empty && !fs::exists(fingerprint_file, error)) {
      throw InvalidArgumentError("COLMAP workspace '" + workspace.string() +
                                 "' is not empty and was not made by evloc-mapper; remove it or "
                                 "choose another with --colmap-workspace");
    }
    if (!is_empty && ReadFileToString(fingerprint_file) != fingerprint) {
      fs::remove_all(workspace, error);
      if (error) {
        throw IoError("cannot clear the stale COLMAP workspace " + workspace.string() + ": " +
                      error.message());
      }
    }
  }
  fs::create_directories(workspace, error);
  if (error) {
    throw IoError("cannot create the COLMAP workspace " + workspace.string() + ": " +
                  error.message());
  }
  WriteFileAtomically(fingerprint_file, fingerprint);
}

StagingDirectory::StagingDirectory(fs::path path) : path_(std::move(path)) {
  std::error_code error;
  fs::remove_all(path_, error);
  fs::create_directories(path_, error);
  if (error) throw IoError("cannot create " + path_.string() + ": " + error.message());
}

StagingDirectory::~StagingDirectory() {
  if (!committed_) {
    std::error_code error;
    fs::remove_all(path_, error);
  }
}

void StagingDirectory::CommitTo(const fs::path& target) {
  std::error_code error;
  if (fs::exists(target, error)) {
    fs::remove(target, error);  // only succeeds for an empty directory
    if (error) throw IoError("cannot replace " + target.string() + ": " + error.message());
  }
  fs::rename(path_, target, error);
  if (error) {
    throw IoError("cannot rename " + path_.string() + " to " + target.string() + ": " +
                  error.message());
  }
  committed_ = true;
}

void CopyFileInto(const fs::path& source, const fs::path& directory) {
  std::error_code error;
  fs::copy_file(source, directory / source.filename(), fs::copy_options::overwrite_existing, error);
  if (error) throw IoError("cannot copy " + source.string() + ": " + error.message());
}

}  // namespace evloc::mapper
