// The preview.png of a map directory (docs/mapper.md, "Outputs"): a few keyframe images in grey
// with the map points they see coloured by depth.
#pragma once

#include <filesystem>

#include <opencv2/core.hpp>

#include "maps/map.h"

namespace evloc::mapper {

// Reads an image with cv::imread `flags`; throws IoError when it cannot.
cv::Mat ReadImage(const std::filesystem::path& path, int flags);

// Up to `num_keyframes` keyframes of `map` (evenly spread, 2 x 2 tiles) read from `image_dir`,
// grey, with their visible points coloured by depth (JET: red near, blue far, 5th-95th
// percentile). Throws IoError when an image cannot be read.
cv::Mat RenderPreview(const Map& map, const std::filesystem::path& image_dir, int num_keyframes);

}  // namespace evloc::mapper
