#include "localizer/odometry/odometry_run.h"

#include <chrono>
#include <string>

#include "core/common/error.h"
#include "core/dataset/tum_rgbd.h"

namespace evloc::odometry {

const char* OdometryModeName(OdometryMode mode) {
  switch (mode) {
    case OdometryMode::kVo:
      return "vo";
    case OdometryMode::kDevo:
      return "devo";
  }
  return "unknown";
}

void VoRunOptions::Check() const {
  vo.Check();
  if (association_tolerance_ns < 0) {
    throw InvalidArgumentError("VoRunOptions: association_tolerance_ns must be >= 0");
  }
}

VoRunResult RunCannyVo(const Dataset& dataset, const Rigid3d& initial_world_from_cam,
                       int64_t initial_t_ns, const VoRunOptions& options,
                       const std::function<void(const VoEstimate&)>& on_step) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  if (dataset.images.empty() || dataset.depth.empty()) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "' needs images and depth maps for Canny-VO (images.txt and "
                               "depth.txt, or rgb.txt and depth.txt in the TUM RGB-D layout)");
  }
  const std::vector<TimeAssociation> pairs =
      AssociateByTime(dataset.images, dataset.depth, options.association_tolerance_ns);
  CannyVo vo(dataset.camera, options.vo);
  VoRunResult result;
  bool started = false;
  for (const TimeAssociation& pair : pairs) {
    const TimedFile& image = dataset.images[pair.first];
    if (image.t_ns < initial_t_ns) continue;
    if (!started) {
      vo.Reset(initial_world_from_cam, image.t_ns);
      started = true;
    }
    cv::Mat gray;
    ReadGrayImage(image.path).convertTo(gray, CV_8UC1, 255.0);
    const cv::Mat depth =
        ReadDepthPng(dataset.depth[pair.second].path, dataset.depth_units_per_metre);
    if (gray.cols != dataset.camera.width || gray.rows != dataset.camera.height ||
        depth.cols != dataset.camera.width || depth.rows != dataset.camera.height) {
      throw InvalidArgumentError("dataset '" + dataset.root.string() + "': image '" +
                                 image.path.string() + "' or its depth map is not of the " +
                                 std::to_string(dataset.camera.width) + "x" +
                                 std::to_string(dataset.camera.height) + " camera size");
    }
    const VoEstimate estimate = vo.AddFrame(image.t_ns, gray, depth);
    result.trajectory.Append({estimate.t_ns, estimate.world_from_cam});
    if (!estimate.tracked) ++result.untracked_frames;
    if (estimate.new_keyframe) ++result.keyframes;
    result.steps.push_back(estimate);
    if (on_step) on_step(estimate);
  }
  if (!started) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "': no image has a depth map within the association tolerance at "
                               "or after the start time");
  }
  result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace evloc::odometry
