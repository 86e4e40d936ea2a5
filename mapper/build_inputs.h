// The inputs of `evloc-mapper build` (docs/mapper.md, "Command line"): the image list (`t_s path`
// lines or the image files of a folder) and the pose files (TUM trajectories interpolated at the
// image times, or `IMAGE_NAME tx ty tz qx qy qz qw` lines).
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/geometry/rigid3.h"

namespace evloc::mapper {

// One input image.
struct InputImage {
  // Name relative to the image folder (COLMAP's image name).
  std::string name;
  // Capture time, nanoseconds (0 without an image list).
  int64_t t_ns = 0;
  // Whether t_ns came from an image list.
  bool has_time = false;
};

// The input images: from the list (`t_s path` lines, read by core/dataset's ReadTimedFileList;
// a path relative to the folder or to the list's folder) or all image files of the folder, sorted
// by name. Throws InvalidArgumentError when the folder is missing or holds no images, or a listed
// file is outside the folder; IoError when a listed file is missing; ParseError naming the line
// for a malformed list or a time that does not increase.
std::vector<InputImage> ListInputImages(const std::filesystem::path& image_dir,
                                        const std::optional<std::filesystem::path>& image_list);

// world_from_cam poses for the images from a pose file (TUM lines interpolated at the image
// times, or `IMAGE_NAME tx ty tz qx qy qz qw` lines); images without a pose are absent from the
// result. Throws IoError / ParseError for unreadable or malformed files, InvalidArgumentError for
// TUM files when the images have no times.
std::map<std::string, Rigid3d> ReadPosesForImages(const std::filesystem::path& path,
                                                  const std::vector<InputImage>& images);

// True when the pose file's first data line starts with a time (TUM layout `t tx ty tz qx qy qz
// qw`) rather than an image name. Throws IoError when it cannot be read.
bool IsTimeKeyedPoseFile(const std::filesystem::path& path);

// The images that have a pose in `poses`, in input order. Images without one are an error
// (InvalidArgumentError naming them and `source`), except when the poses come from a time-keyed
// trajectory (`time_keyed`) that starts after or ends before some images: those are left out and
// named in `*left_out` (may be null), provided at least `min_fraction` of the images (and at
// least one) keep a pose.
std::vector<InputImage> ImagesWithKnownPoses(const std::vector<InputImage>& images,
                                             const std::map<std::string, Rigid3d>& poses,
                                             bool time_keyed, double min_fraction,
                                             const std::string& source,
                                             std::vector<std::string>* left_out);

}  // namespace evloc::mapper
