// The local reference map of Canny-DEVO (docs/tracking.md, "Mapless odometry"; the paper's
// "Mapping for Canny-DEVO"): one depth frame warped into the event camera, its depth assigned to
// the pixels of the semi-dense region given by the time-surface edges at the same instant. A
// warped depth point lands between pixels and several may land near one pixel (occlusions under
// the depth-to-event baseline) while others leave holes; each semi-dense pixel therefore gathers
// the warped points within a radius, keeps the nearest depth cluster (the foreground), needs it
// around the pixel, and intersects its ray with the plane of that cluster (inverse depth is
// linear in the image over a plane): occluded depth never leaks across an edge.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"

namespace evloc::odometry {

// Options of BuildReferenceMap.
struct ReferenceMapOptions {
  // Warped depth points within this distance of a semi-dense pixel centre are its neighbours,
  // pixels (>= 0.75: a 1-pixel grid of points must reach every pixel).
  double neighbour_radius_px = 1.5;
  // Neighbours whose depth exceeds the nearest one's by more than this fraction of it belong to
  // a farther surface (the background) and are left out.
  double foreground_depth_fraction = 0.05;
  // The foreground cluster needs at least this many points...
  int min_cluster_points = 3;
  // ... and must surround the pixel: its points' offsets from the pixel centre must span both
  // signs along x and along y (within this tolerance, pixels), so that the depth is interpolated,
  // not extrapolated from one side of an edge.
  double surround_tolerance_px = 0.25;
  // Depths outside [min_depth_m, max_depth_m] are ignored, metres.
  double min_depth_m = 0.1;
  // Farthest depth used, metres.
  double max_depth_m = 10.0;

  // Throws InvalidArgumentError on a bad value.
  void Check() const;
};

// One point of a reference map, in the event camera frame at the reference time.
struct ReferencePoint {
  // The semi-dense pixel (ideal event camera).
  Eigen::Vector2i pixel = Eigen::Vector2i::Zero();
  // The 3D point on the pixel's ray, metres.
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  // Number of foreground points its depth came from.
  int support = 0;
};

// What a build did, for the statistics.
struct ReferenceMapStats {
  // Semi-dense pixels considered.
  int semi_dense_pixels = 0;
  // Depth pixels warped into the event image near the semi-dense region (within the neighbour
  // radius of one of its pixels: the only ones that can give depth).
  int warped_points = 0;
  // Pixels without enough foreground neighbours (holes, disocclusions).
  int without_depth = 0;
  // Pixels whose foreground does not surround them (edges of a surface).
  int not_surrounded = 0;
};

// Builds the reference map: `semi_dense` (CV_8UC1, non-zero = semi-dense pixel) on the image of
// the pinhole `event_camera`; `depth_m` (CV_32FC1, metres, 0 = none) of `depth_camera`;
// `event_from_depth` the extrinsic. Throws InvalidArgumentError for mismatched sizes or types.
std::vector<ReferencePoint> BuildReferenceMap(const Camera& event_camera, const cv::Mat& semi_dense,
                                              const Camera& depth_camera, const cv::Mat& depth_m,
                                              const Rigid3d& event_from_depth,
                                              const ReferenceMapOptions& options,
                                              ReferenceMapStats* stats = nullptr);
// The same into `points` (cleared first; its capacity is reused, so a caller that builds again
// and again keeps one vector). Scratch buffers are kept per thread between builds.
void BuildReferenceMap(const Camera& event_camera, const cv::Mat& semi_dense,
                       const Camera& depth_camera, const cv::Mat& depth_m,
                       const Rigid3d& event_from_depth, const ReferenceMapOptions& options,
                       std::vector<ReferencePoint>* points, ReferenceMapStats* stats = nullptr);

// Where an edge point is `age_s` seconds after it was seen at `pixel` (ideal pinhole `camera`)
// at `position` (camera frame), for a camera moving with `velocity` (body-frame twist (v, omega)
// per second, world_from_cam(t + dt) = world_from_cam(t) * ExpSE3(velocity * dt)): the pixel
// moved along its image flow (a static point: dP/dt = -(omega x P + v)) by age_s, at the same
// depth, in the camera frame at the later time. Canny-DEVO's reference points
// (CannyDevoOptions::edges_at_reference_time).
Eigen::Vector3d EdgeAfter(const Camera& camera, const Eigen::Vector2i& pixel,
                          const Eigen::Vector3d& position,
                          const Eigen::Matrix<double, 6, 1>& velocity, double age_s);

// The depth frame `depth_m` (CV_32FC1 metres of `depth_camera`, 0 = none) seen from `camera`:
// every depth pixel within the options' depth range warped through `camera_from_depth` and
// projected with `camera`'s model; each pixel of the result (CV_32FC1 metres, camera's size) keeps
// the nearest depth that lands on it (a z-buffer), 0 where none does. Canny-VO's depth when the
// depth camera is not the frame camera. Throws InvalidArgumentError for a mismatched depth frame.
cv::Mat RegisterDepth(const Camera& camera, const Camera& depth_camera, const cv::Mat& depth_m,
                      const Rigid3d& camera_from_depth, const ReferenceMapOptions& options);

}  // namespace evloc::odometry
