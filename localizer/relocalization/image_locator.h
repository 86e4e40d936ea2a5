// Locating one grey image in a map from nothing (docs/relocalization.md, "Locating an image"):
// SIFT features of the image, VLAD retrieval of the map's most similar keyframes, 2D-3D matches
// against those keyframes' landmark features, the robust absolute pose (P3P RANSAC and Ceres
// refinement), then verification against the map's edges with the frame tracker (Canny-VT): a
// pose is FOUND only when one tracking step from it passes the tracking thresholds and stays near
// it. Expected failures are NOT_FOUND results with a reason, never exceptions.
#pragma once

#include <cstddef>
#include <memory>
#include <optional>
#include <string>

#include <opencv2/core/mat.hpp>

#include "core/camera/camera.h"
#include "core/features/features.h"
#include "core/geometry/rigid3.h"
#include "localizer/relocalization/absolute_pose.h"
#include "localizer/tracking/map_source.h"
#include "localizer/tracking/tiled_map_source.h"
#include "localizer/tracking/tracker.h"
#include "localizer/tracking/tracker_options.h"
#include "maps/map.h"
#include "maps/tile_cache.h"
#include "maps/visibility.h"

namespace evloc::relocalization {

// Options of LocateImage.
struct LocateOptions {
  // Local features of the query: the mapper's defaults, so that they match the map's.
  features::FeatureOptions features;
  // Matching of the query's features against each retrieved keyframe's.
  features::MatchOptions matching;
  // Keyframes retrieved by global descriptor and matched against.
  int top_k = 5;
  // When set, only keyframes whose camera centre lies within search_radius_m of this position
  // (map frame, metres) are retrieved: a GNSS prior (docs/geo.md).
  std::optional<Eigen::Vector3d> search_center;
  // Radius around search_center, metres (> 0 when it is set).
  double search_radius_m = 0.0;
  // A site locate loads the tiles that keep keyframes (those whose core square is within
  // search_radius_m of search_center when it is set) and their neighbours; more than this many
  // is an InvalidArgumentError asking for a search prior.
  size_t max_site_tiles = 64;
  // The absolute pose solver; its min_inliers and min_inlier_ratio are the acceptance thresholds
  // of the PnP stage (below: the measured defaults of docs/relocalization.md).
  AbsolutePoseOptions pose = DefaultPoseOptions();
  // Verify the PnP pose against the map's edges (off only for measurements of the PnP stage).
  bool verify = true;
  // The frame tracker that verifies (input kFrames); its quality thresholds decide.
  tracking::TrackerOptions verification = DefaultVerificationOptions();
  // Largest distance between the PnP pose and the edge-registered pose, as a fraction of the
  // median depth of the PnP inliers (scale-free: 0.03 is 3 cm at 1 m).
  double max_verification_shift = 0.03;
  // Largest rotation between the PnP pose and the edge-verified pose, degrees.
  double max_verification_rotation_deg = 2.0;

  // The absolute pose options with the acceptance thresholds measured for locating an image.
  static AbsolutePoseOptions DefaultPoseOptions();
  // The frame tracker options of the verification step.
  static tracking::TrackerOptions DefaultVerificationOptions();
  // Throws InvalidArgumentError when a field is outside its domain.
  void Check() const;
};

// Whether an image was located.
enum class LocateStatus {
  // A pose was found and verified against the map's edges.
  kFound,
  // No verified pose: the image is not of the mapped scene, or too little of it can be matched.
  kNotFound,
};

// The name of a status as the CLI and the service print it: "FOUND" or "NOT_FOUND".
const char* LocateStatusName(LocateStatus status);

// The outcome of LocateImage.
struct LocateResult {
  // FOUND or NOT_FOUND.
  LocateStatus status = LocateStatus::kNotFound;
  // The verified pose (meaningful when FOUND).
  Rigid3d world_from_cam;
  // Covariance of xi in world_from_cam * ExpSE3(xi), xi = (v, omega) in the camera frame (the
  // tracker's convention), of the PnP refinement over its inliers (meaningful when FOUND).
  Matrix6d covariance = Matrix6d::Identity();
  // The PnP pose before the edge verification (meaningful when the PnP stage succeeded).
  Rigid3d pnp_world_from_cam;
  // PnP inliers (0 when the solver found no pose).
  int inliers = 0;
  // 2D-3D correspondences pooled from the retrieved keyframes.
  int correspondences = 0;
  // Index into Map::keyframes of the retrieved keyframe that gave the most PnP inliers (the most
  // similar one when no pose was found); -1 when the map has no keyframe. In a site: among the
  // keyframes of `tile`.
  int keyframe = -1;
  // In a site: the position in the manifest of the tile `keyframe` indexes into (the tile owning
  // the keyframe's camera centre when it was loaded, else the first loaded tile keeping it); -1
  // otherwise.
  int tile = -1;
  // Chance-corrected edge alignment of the verification step (TrackingQuality::alignment, 0..1);
  // 0 when the verification did not run.
  double score = 0;
  // Cosine similarity of the query's global descriptor to the best retrieved keyframe's.
  double retrieval_similarity = 0;
  // Why the image was not found, or a short account of the verification when it was.
  std::string reason;
};

// Locates `gray` (CV_8UC1, query_camera's size) in `map`. Deterministic. Throws
// InvalidArgumentError when the map has no relocalization data (the message says how to upgrade
// it), when that data is inconsistent with the map, when the camera fails Check() or the image is
// not an 8-bit grey image of the camera's size, or when the options fail Check().
LocateResult LocateImage(const Map& map, const Camera& query_camera, const cv::Mat& gray,
                         const LocateOptions& options);

// The same with the map's visibility index (built on `map`), which selects the edge points the
// verification registers: those of the keyframes near the PnP pose. The overload above builds
// one per call; a service that keeps one per map passes it here.
LocateResult LocateImage(const Map& map, const VisibilityIndex& visibility,
                         const Camera& query_camera, const cv::Mat& gray,
                         const LocateOptions& options);

// Locates `gray` in a site of tiles (docs/relocalization.md, "Sites"): the tiles that keep
// keyframes (near the search prior when LocateOptions has one) and their neighbours (at most
// max_site_tiles in all) are loaded through `cache`, their keyframes are retrieved together
// (each once, its features pooled from every loaded tile that keeps some), and the PnP pose is
// verified against the tiles a session at that pose would track against (`verification_tiles`,
// loaded synchronously) and those around the point on its optical axis at the median depth of
// the PnP inliers (what it matched). Deterministic. Throws like LocateImage, InvalidArgumentError
// when too many tiles would be searched or the tiles' vocabularies differ, and the tile's IoError
// or ParseError when a tile cannot be loaded.
LocateResult LocateImageInSite(const std::shared_ptr<const Site>& site,
                               const std::shared_ptr<TileCache>& cache, const Camera& query_camera,
                               const cv::Mat& gray, const LocateOptions& options,
                               const tracking::TileSelectionOptions& verification_tiles = {});

// The InvalidArgumentError message of a map without relocalization data.
inline constexpr const char* kNoRelocalizationDataMessage =
    "the map has no relocalization data (a v1 or imported map): run `evloc-mapper upgrade --map "
    "MAP --images DIR` or rebuild it with evloc-mapper build";

}  // namespace evloc::relocalization
