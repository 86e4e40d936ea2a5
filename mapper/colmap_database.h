// Reading and writing the tables of a COLMAP 3.8 database (SQLite) that evloc's matcher uses:
// `images`, `cameras`, `keypoints` and `descriptors` (written by COLMAP's feature_extractor),
// `matches` and `two_view_geometries` (written by evloc's matcher, read by COLMAP's mapper and
// point_triangulator). docs/mapper.md, "Reproducible maps".
#pragma once

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace evloc::mapper {

// Length of a SIFT descriptor in COLMAP's `descriptors` table.
inline constexpr int kSiftDescriptorSize = 128;

// COLMAP's TwoViewGeometry::ConfigurationType values used by evloc.
enum class TwoViewConfig : int {
  // Not verified (fewer raw matches than the minimum), as COLMAP writes it.
  kUndefined = 0,
  // Verified but with fewer inliers than the minimum.
  kDegenerate = 1,
  // Essential matrix of calibrated cameras.
  kCalibrated = 2,
  // Fundamental matrix of uncalibrated cameras (or calibrated ones whose essential matrix explains
  // too few of the fundamental matrix's inliers).
  kUncalibrated = 3,
  // A homography explains most of the epipolar inliers (planar scene or pure rotation).
  kPlanarOrPanoramic = 6,
};

// One image's SIFT features as COLMAP's feature_extractor stored them.
struct ImageFeatures {
  // COLMAP's image_id.
  uint32_t image_id = 0;
  // The image name relative to the image folder.
  std::string name;
  // Keypoint positions (pixels, COLMAP's convention: the centre of the top-left pixel is 0.5).
  std::vector<Eigen::Vector2f> keypoints;
  // keypoints.size() x kSiftDescriptorSize bytes, row-major.
  std::vector<uint8_t> descriptors;
};

// Feature index pairs (into the first and the second image of a pair).
using FeatureMatches = std::vector<std::pair<uint32_t, uint32_t>>;

// The matching result of one image pair, as stored in `matches` and `two_view_geometries`.
struct PairGeometry {
  // The smaller image id of the pair.
  uint32_t image_id1 = 0;
  // The larger image id of the pair.
  uint32_t image_id2 = 0;
  // Descriptor matches before verification (table `matches`).
  FeatureMatches matches;
  // The matches consistent with the estimated geometry (table `two_view_geometries`).
  FeatureMatches inlier_matches;
  // How the geometry was estimated.
  TwoViewConfig config = TwoViewConfig::kUndefined;
  // Fundamental matrix (pixels of image 1 to epipolar lines of image 2); zero when unknown.
  Eigen::Matrix3d F = Eigen::Matrix3d::Zero();
  // Essential matrix (normalised coordinates); zero when unknown.
  Eigen::Matrix3d E = Eigen::Matrix3d::Zero();
  // Homography; zero when unknown (evloc does not estimate one).
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
};

// COLMAP's pair id of two image ids (order-independent): min * 2147483647 + max.
uint64_t ColmapPairId(uint32_t image_id1, uint32_t image_id2);

// The features of every image of the database, in image name order. Throws IoError when the
// database cannot be opened or read, ParseError when a keypoint or descriptor blob does not have
// the layout COLMAP 3.8 writes (keypoints: rows x 2, 4 or 6 float32; descriptors: rows x 128
// uint8, as many rows as keypoints) or an image has no features row. The descriptor of a keypoint
// within half its scale of its image's border is returned as zeros (COLMAP computes it from memory
// outside the image, differently from run to run), which the matcher never matches.
std::vector<ImageFeatures> ReadImageFeatures(const std::filesystem::path& database_path);

// Replaces the `matches` and `two_view_geometries` tables' rows by `pairs` (one transaction,
// written in the given order). Throws IoError when the database cannot be written or lacks these
// tables, InvalidArgumentError when a pair's ids are not increasing.
void WritePairGeometries(const std::filesystem::path& database_path,
                         const std::vector<PairGeometry>& pairs);

// Every pair of `two_view_geometries` with its raw `matches`, by increasing pair id. Throws like
// ReadImageFeatures.
std::vector<PairGeometry> ReadPairGeometries(const std::filesystem::path& database_path);

// Image ids of a COLMAP database by image name (table `images`). Throws IoError when the database
// cannot be opened or read.
std::map<std::string, uint32_t> ReadDatabaseImageIds(const std::filesystem::path& database_path);

// Camera ids of a COLMAP database, in increasing order.
std::vector<uint32_t> ReadDatabaseCameraIds(const std::filesystem::path& database_path);

}  // namespace evloc::mapper
