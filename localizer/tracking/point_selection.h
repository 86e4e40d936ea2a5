// Point selection (docs/tracking.md, "Registration"): the map points visible from the predicted
// pose, within a depth range and the image, subsampled to a budget with even image coverage
// (buckets).
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <span>
#include <vector>

#include "core/geometry/rigid3.h"
#include "localizer/tracking/registration.h"

namespace evloc::tracking {

// Options of SelectEvenly.
struct PointSelectionOptions {
  // Maximum number of points returned.
  int max_points = 2500;
  // Side of the square buckets, pixels.
  int bucket_size_px = 16;
  // Points nearer than this (camera z) are rejected, metres.
  double min_depth_m = 0.1;
  // Points farther than this are rejected, metres.
  double max_depth_m = 50.0;
  // Points projecting closer than this to the border are rejected, pixels.
  double image_margin_px = 2.0;
};

// From `candidates` (indices into `positions`, p_world), the points in front of the camera within
// the depth range that project inside the width x height image, subsampled to max_points: every
// non-empty bucket gets the same share (round robin over buckets, in a fixed pseudo-random order
// inside each bucket so that one bucket's points spread along its curves). Deterministic; the
// result is sorted ascending.
std::vector<uint32_t> SelectEvenly(std::span<const Eigen::Vector3f> positions,
                                   const std::vector<uint32_t>& candidates,
                                   const PinholeIntrinsics& intrinsics, int width, int height,
                                   const Rigid3d& cam_from_world,
                                   const PointSelectionOptions& options);

// Options of SelectInformative.
struct InformativeSelectionOptions {
  // Number of points returned.
  int count = 1000;
  // The share of `count` taken at even intervals before the rest by leverage, in (0, 1].
  double seed_fraction = 0.5;
  // The gradient probe P + s g that gives a point's edge normal in the image: s is this fraction
  // of the point's depth (the polarity prediction's probe), in (0, 1).
  double gradient_probe_depth_fraction = 0.01;
};

// From `selected` (indices into `positions` and `gradients`, p_world and its unit 3D gradient,
// e.g. SelectEvenly's result), the options.count points that constrain the pose at
// `cam_from_world` most (docs/tracking.md, "Point selection"). Each point's row j of the
// registration's Jacobian is predicted from its edge normal in the image (the projected gradient
// probe; the field's slope taken as the same for every point). seed_fraction of the count is
// taken first, at even intervals over `selected` (even coverage, so that no part of the image is
// left to a few points), the rest by leverage j^T H^-1 j (H: the information of all of
// `selected`), highest first. Points whose gradient does not project have no leverage and come
// last. Deterministic; the result is sorted ascending. All of `selected` when the count covers
// it.
std::vector<uint32_t> SelectInformative(std::span<const Eigen::Vector3f> positions,
                                        std::span<const Eigen::Vector3f> gradients,
                                        const std::vector<uint32_t>& selected,
                                        const PinholeIntrinsics& intrinsics,
                                        const Rigid3d& cam_from_world,
                                        const InformativeSelectionOptions& options);

}  // namespace evloc::tracking
