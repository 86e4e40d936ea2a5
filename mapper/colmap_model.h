// COLMAP sparse models in the TXT layout (cameras.txt, images.txt, points3D.txt) and the
// reader/writer of the camera parameters as COLMAP's command line takes them. A camera of
// cameras.txt and its conversion to an evloc camera are core/camera/colmap_camera.h.
// COLMAP places the centre of the top-left pixel at (0.5, 0.5); evloc places it at (0, 0). The
// readers here shift 2D observations by 0.5 (kColmapPixelOffset) so that every value leaving this
// file follows the evloc convention (docs/mapper.md, "COLMAP conventions").
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/camera/camera.h"
#include "core/camera/colmap_camera.h"
#include "core/geometry/rigid3.h"

namespace evloc::mapper {

// Marks a 2D observation of images.txt that is not part of any 3D point (COLMAP writes -1).
inline constexpr uint64_t kNoPoint3D = ~uint64_t{0};

// One registered image of images.txt.
struct ColmapImage {
  // COLMAP image id (the database id).
  uint32_t image_id = 0;
  // Pose: p_cam = cam_from_world * p_world.
  Rigid3d cam_from_world;
  // COLMAP camera id.
  uint32_t camera_id = 0;
  // Image name relative to the image folder.
  std::string name;
  // 2D keypoints in evloc pixel coordinates (top-left pixel centre at 0, 0).
  std::vector<Eigen::Vector2d> keypoints;
  // For each keypoint, the id of its 3D point or kNoPoint3D.
  std::vector<uint64_t> point3d_ids;
};

// One track element: which image observes a 3D point, and with which keypoint.
struct ColmapTrackElement {
  // COLMAP image id.
  uint32_t image_id = 0;
  // Index into ColmapImage::keypoints.
  uint32_t keypoint_index = 0;
};

// One 3D point of points3D.txt.
struct ColmapPoint3D {
  // COLMAP point id.
  uint64_t point3d_id = 0;
  // Position in the model frame.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Colour, 0..255 per channel.
  Eigen::Vector3i color = Eigen::Vector3i::Zero();
  // Mean reprojection error, pixels.
  double error = 0.0;
  // The images observing the point.
  std::vector<ColmapTrackElement> track;
};

// A sparse model: cameras, registered images and 3D points, keyed by their COLMAP ids.
struct ColmapModel {
  // Cameras by id.
  std::map<uint32_t, ColmapCamera> cameras;
  // Registered images by id.
  std::map<uint32_t, ColmapImage> images;
  // 3D points by id.
  std::map<uint64_t, ColmapPoint3D> points;

  // Mean over 3D points of their reprojection error, pixels; 0 without points.
  double MeanReprojectionError() const;
  // Id of the registered image with this name, or 0 when absent (COLMAP ids start at 1).
  uint32_t FindImageId(const std::string& name) const;
};

// Reads cameras.txt, images.txt and points3D.txt from `directory`. Throws IoError when a file
// cannot be read and ParseError naming the file and line when one is malformed or refers to an
// unknown camera, image or point.
ColmapModel ReadColmapTextModel(const std::filesystem::path& directory);

// Writes the three TXT files into `directory` (created if needed), each atomically. images.txt
// holds the pose line followed by the keypoint line (empty when the image has no keypoints), as
// point_triangulator expects. Throws IoError when a file cannot be written.
void WriteColmapTextModel(const std::filesystem::path& directory, const ColmapModel& model);

// The parameters as COLMAP's --ImageReader.camera_params expects them: comma-separated, full
// precision.
std::string FormatColmapParams(const std::vector<double>& params);

}  // namespace evloc::mapper
