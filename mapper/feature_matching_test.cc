#include "mapper/feature_matching.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <set>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "core/common/test_data.h"
#include "core/dataset/testing/middlebury.h"
#include "mapper/colmap_model.h"
#include "mapper/colmap_runner.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

// Runs COLMAP's feature_extractor on `names` of `image_dir` into `<workspace>/database.db`.
fs::path ExtractFeatures(const fs::path& workspace, const fs::path& image_dir,
                         const std::vector<std::string>& names,
                         const std::optional<Camera>& camera) {
  ColmapOptions options;
  options.camera = camera;
  const ColmapRunner runner(options, workspace, image_dir);
  runner.ExtractFeatures(names);
  return runner.DatabasePath();
}

// A unit-normalised random SIFT-like descriptor scaled to 512 as COLMAP stores it.
std::vector<uint8_t> RandomDescriptor(std::mt19937* random) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::vector<double> values(kSiftDescriptorSize);
  double norm = 0.0;
  for (double& value : values) {
    value = uniform(*random);
    norm += value * value;
  }
  std::vector<uint8_t> bytes(kSiftDescriptorSize);
  for (int i = 0; i < kSiftDescriptorSize; ++i) {
    bytes[i] =
        static_cast<uint8_t>(std::min(255.0, std::round(512.0 * values[i] / std::sqrt(norm))));
  }
  return bytes;
}

// `descriptor` with +-`amplitude` uniform noise per byte.
std::vector<uint8_t> Perturbed(const std::vector<uint8_t>& descriptor, int amplitude,
                               std::mt19937* random) {
  std::uniform_int_distribution<int> noise(-amplitude, amplitude);
  std::vector<uint8_t> result = descriptor;
  for (uint8_t& byte : result)
    byte = static_cast<uint8_t>(std::clamp(byte + noise(*random), 0, 255));
  return result;
}

TEST(FeatureMatching, SequentialPairsAreColmapsLinearAndQuadraticWindow) {
  // COLMAP 3.8: i with i+1 .. i+overlap-1 and i + 2^k while i + k is in range.
  const std::vector<std::pair<size_t, size_t>> pairs = SequentialPairs(20, 3);
  const std::set<std::pair<size_t, size_t>> set(pairs.begin(), pairs.end());
  EXPECT_EQ(set.size(), pairs.size());
  EXPECT_TRUE(std::is_sorted(pairs.begin(), pairs.end()));
  for (size_t i = 0; i < 20; ++i) {
    for (size_t j = i + 1; j < 20; ++j) {
      const bool expected = (j - i <= 2) || (j - i == 4 && i + 2 < 20);
      EXPECT_EQ(set.count({i, j}), expected ? 1u : 0u) << i << " " << j;
    }
  }
  EXPECT_EQ(ExhaustivePairs(16).size(), 120u);
  EXPECT_EQ(SequentialPairs(87, 10).size(), 887u);
}

TEST(FeatureMatching, RetrievalPairsLinkTheImagesOfOnePlace) {
  // Three places, five images each (given in a shuffled order): the images of one place share
  // most of their descriptors (each seen with noise), the places none.
  std::mt19937 random(11);
  std::vector<std::vector<std::vector<uint8_t>>> places(3);
  for (auto& place : places) {
    for (int k = 0; k < 200; ++k) place.push_back(RandomDescriptor(&random));
  }
  std::vector<size_t> place_of;
  for (size_t p = 0; p < places.size(); ++p) place_of.insert(place_of.end(), 5, p);
  std::shuffle(place_of.begin(), place_of.end(), random);
  std::vector<ImageFeatures> images;
  std::bernoulli_distribution seen(0.7);
  for (size_t i = 0; i < place_of.size(); ++i) {
    ImageFeatures image;
    image.image_id = static_cast<uint32_t>(i + 1);
    image.name = "image" + std::to_string(i) + ".png";
    for (const std::vector<uint8_t>& descriptor : places[place_of[i]]) {
      if (!seen(random)) continue;
      const std::vector<uint8_t> observed = Perturbed(descriptor, 6, &random);
      image.descriptors.insert(image.descriptors.end(), observed.begin(), observed.end());
      image.keypoints.emplace_back(static_cast<float>(image.keypoints.size()), 10.0f);
    }
    images.push_back(std::move(image));
  }
  images.push_back(ImageFeatures{99, "blank.png", {}, {}});  // no features: no pair
  const std::vector<std::pair<size_t, size_t>> pairs = RetrievalPairs(images, 4);
  // Each image with its 4 most similar: the other four images of its place, and no other.
  EXPECT_EQ(pairs.size(), 3u * 10u);
  EXPECT_TRUE(std::is_sorted(pairs.begin(), pairs.end()));
  for (const auto& [a, b] : pairs) {
    EXPECT_LT(a, b);
    ASSERT_LT(b, place_of.size());
    EXPECT_EQ(place_of[a], place_of[b]) << a << " " << b;
  }
  EXPECT_EQ(RetrievalPairs(images, 4), pairs);  // deterministic
  EXPECT_THROW(RetrievalPairs(images, 0), InvalidArgumentError);
  EXPECT_TRUE(RetrievalPairs({ImageFeatures{1, "a.png", {}, {}}}, 3).empty());
  EXPECT_EQ(ParseMatcherType("retrieval"), MatcherType::kRetrieval);
  EXPECT_EQ(MatcherTypeName(MatcherType::kRetrieval), "retrieval");
  ColmapOptions colmap;
  colmap.matcher = MatcherType::kRetrieval;
  colmap.Check();
  colmap.deterministic = false;  // COLMAP's vocab_tree_matcher needs a vocabulary file
  EXPECT_THROW(colmap.Check(), InvalidArgumentError);
}

TEST(FeatureMatching, RatioTestAndCrossCheck) {
  std::mt19937 random(3);
  const std::vector<uint8_t> a = RandomDescriptor(&random);
  const std::vector<uint8_t> b = RandomDescriptor(&random);
  const std::vector<uint8_t> c = RandomDescriptor(&random);
  // Image 1: a, b, c. Image 2: a twice (ambiguous: the ratio test drops it), a near copy of c,
  // and b.
  std::vector<uint8_t> first;
  for (const auto* d : {&a, &b, &c}) first.insert(first.end(), d->begin(), d->end());
  std::vector<uint8_t> second;
  const std::vector<uint8_t> c_near = Perturbed(c, 2, &random);
  for (const auto* d : {&a, &a, &c_near, &b}) second.insert(second.end(), d->begin(), d->end());
  FeatureMatchingOptions options;
  const FeatureMatches matches = MatchDescriptors(first, second, options);
  const FeatureMatches expected = {{1, 3}, {2, 2}};
  EXPECT_EQ(matches, expected);
  // Without the cross-check a one-way match that is not mutual is kept: image 1 has b twice.
  std::vector<uint8_t> doubled = first;
  doubled.insert(doubled.end(), b.begin(), b.end());
  options.cross_check = false;
  options.max_ratio = 1.0;
  const FeatureMatches one_way = MatchDescriptors(doubled, second, options);
  EXPECT_NE(std::find(one_way.begin(), one_way.end(), std::make_pair(3u, 3u)), one_way.end());
  options.cross_check = true;
  const FeatureMatches mutual = MatchDescriptors(doubled, second, options);
  EXPECT_EQ(std::find(mutual.begin(), mutual.end(), std::make_pair(3u, 3u)), mutual.end());
}

// A synthetic pair with known geometry: 170 true correspondences with noisy descriptors and
// 0.3 px keypoint noise, 30 whose second keypoint is moved to a random place (matched by
// descriptor, wrong geometry), 100 unmatched features per image.
TEST(FeatureMatching, SyntheticPairRecoversTheTrueCorrespondencesAndEssentialMatrix) {
  std::mt19937 random(7);
  const Camera camera = Camera::Pinhole(640, 480, 500, 500, 319.5, 239.5);
  const Rigid3d cam2_from_cam1(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.15, Eigen::Vector3d(0.2, 1.0, 0.1).normalized())),
      Eigen::Vector3d(-0.5, 0.05, 0.1));
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  std::normal_distribution<double> pixel_noise(0.0, 0.3);
  ImageFeatures image1;
  ImageFeatures image2;
  image1.image_id = 1;
  image2.image_id = 2;
  constexpr int kTrue = 170;
  constexpr int kMoved = 30;
  std::vector<uint32_t> second_index;  // image 2's feature index of image 1's feature i
  while (static_cast<int>(second_index.size()) < kTrue + kMoved) {
    const Eigen::Vector3d point(2.0 * uniform(random), 1.5 * uniform(random),
                                5.0 + 2.0 * uniform(random));
    Eigen::Vector2d pixel1;
    Eigen::Vector2d pixel2;
    if (!camera.Project(point, &pixel1) || !camera.Project(cam2_from_cam1 * point, &pixel2) ||
        !camera.IsInside(pixel1) || !camera.IsInside(pixel2)) {
      continue;
    }
    if (static_cast<int>(second_index.size()) >= kTrue) {
      pixel2 = Eigen::Vector2d(320 + 310 * uniform(random), 240 + 230 * uniform(random));
    }
    const std::vector<uint8_t> descriptor = RandomDescriptor(&random);
    image1.keypoints.push_back(
        (pixel1 + Eigen::Vector2d(pixel_noise(random), pixel_noise(random))).cast<float>() +
        Eigen::Vector2f::Constant(static_cast<float>(kColmapPixelOffset)));
    image1.descriptors.insert(image1.descriptors.end(), descriptor.begin(), descriptor.end());
    second_index.push_back(static_cast<uint32_t>(image2.keypoints.size()));
    image2.keypoints.push_back(
        (pixel2 + Eigen::Vector2d(pixel_noise(random), pixel_noise(random))).cast<float>() +
        Eigen::Vector2f::Constant(static_cast<float>(kColmapPixelOffset)));
    const std::vector<uint8_t> noisy = Perturbed(descriptor, 6, &random);
    image2.descriptors.insert(image2.descriptors.end(), noisy.begin(), noisy.end());
    // An unmatched feature in each image.
    for (ImageFeatures* image : {&image1, &image2}) {
      image->keypoints.emplace_back(320 + 310 * uniform(random), 240 + 230 * uniform(random));
      const std::vector<uint8_t> other = RandomDescriptor(&random);
      image->descriptors.insert(image->descriptors.end(), other.begin(), other.end());
    }
  }
  FeatureMatchingOptions options;
  PairGeometry pair;
  pair.image_id1 = 1;
  pair.image_id2 = 2;
  pair.matches = MatchDescriptors(image1.descriptors, image2.descriptors, options);
  // Every planted correspondence is matched, nothing else (image 1's features alternate
  // planted/unmatched: planted ones have even indices).
  ASSERT_EQ(pair.matches.size(), static_cast<size_t>(kTrue + kMoved));
  for (size_t i = 0; i < pair.matches.size(); ++i) {
    EXPECT_EQ(pair.matches[i].first, 2 * i);
    EXPECT_EQ(pair.matches[i].second, second_index[i]);
  }
  VerifyPair(image1, image2, camera, options, &pair);
  EXPECT_EQ(pair.config, TwoViewConfig::kCalibrated);
  size_t true_inliers = 0;
  size_t moved_inliers = 0;
  for (const auto& [first, second] : pair.inlier_matches) {
    (first / 2 < static_cast<uint32_t>(kTrue) ? true_inliers : moved_inliers) += 1;
  }
  std::cout << "synthetic pair: " << true_inliers << " of " << kTrue << " true and "
            << moved_inliers << " of " << kMoved << " moved correspondences kept\n";
  EXPECT_GE(true_inliers, 165u);
  EXPECT_LE(moved_inliers, 2u);
  // E agrees with [t]x R of the true pose (up to scale and sign).
  const Eigen::Vector3d t = cam2_from_cam1.translation;
  Eigen::Matrix3d t_cross;
  t_cross << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  Eigen::Matrix3d truth = t_cross * cam2_from_cam1.RotationMatrix();
  truth.normalize();
  Eigen::Matrix3d estimated = pair.E.normalized();
  if ((estimated - truth).norm() > (estimated + truth).norm()) estimated = -estimated;
  EXPECT_LT((estimated - truth).norm(), 0.02);
  // F = K^-T E K^-1 in COLMAP pixels: the true correspondences are on their epipolar lines.
  const Eigen::Vector3d x1(image1.keypoints[0].x(), image1.keypoints[0].y(), 1.0);
  const Eigen::Vector3d x2(image2.keypoints[second_index[0]].x(),
                           image2.keypoints[second_index[0]].y(), 1.0);
  const Eigen::Vector3d line = pair.F * x1;
  EXPECT_LT(std::abs(x2.dot(line)) / line.head<2>().norm(), 2.0);
  // Too few matches: not verified.
  PairGeometry few = pair;
  few.matches.resize(10);
  VerifyPair(image1, image2, camera, options, &few);
  EXPECT_EQ(few.config, TwoViewConfig::kUndefined);
  EXPECT_TRUE(few.inlier_matches.empty());
}

// Two neighbouring real temple photos (templeSR0001, templeSR0002) and a third: COLMAP's SIFT
// features, evloc's matching of the three pairs twice with 1 and with 2 threads (identical
// results), and the verified matches of the neighbours agree with the calibrated poses.
TEST(FeatureMatching, TempleMatchesAreDeterministicAndAgreeWithTheKnownPoses) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  const fs::path image_dir = parameters.parent_path();
  const std::vector<testing::MiddleburyView> views = testing::ReadMiddleburyParameters(parameters);
  ASSERT_GE(views.size(), 3u);
  const Camera camera = testing::MiddleburyCamera(views[0], 640, 480);
  const fs::path directory = evloc::testing::MakeTempDir("feature_matching_temple");
  const fs::path database = ExtractFeatures(directory / "workspace", image_dir,
                                            {views[0].name, views[1].name, views[2].name}, camera);
  const std::vector<ImageFeatures> images = ReadImageFeatures(database);
  ASSERT_EQ(images.size(), 3u);
  const std::vector<std::pair<size_t, size_t>> pairs = ExhaustivePairs(images.size());
  FeatureMatchingOptions options;
  const std::vector<PairGeometry> reference = MatchImagePairs(images, pairs, camera, options);
  ASSERT_EQ(reference.size(), 3u);
  for (const int threads : {1, 2, 2}) {
    options.num_threads = threads;
    const std::vector<PairGeometry> again = MatchImagePairs(images, pairs, camera, options);
    for (size_t k = 0; k < pairs.size(); ++k) {
      EXPECT_EQ(again[k].matches, reference[k].matches) << threads << " threads, pair " << k;
      EXPECT_EQ(again[k].inlier_matches, reference[k].inlier_matches) << threads;
      EXPECT_EQ(again[k].E, reference[k].E) << threads;
    }
  }
  // The first pair (templeSR0001, templeSR0002, neighbours on the ring): epipolar distances of
  // the inliers under the calibrated poses.
  const PairGeometry& neighbours = reference[0];
  ASSERT_EQ(images[0].name, views[0].name);
  ASSERT_EQ(images[1].name, views[1].name);
  const Rigid3d cam2_from_cam1 = views[1].cam_from_world * views[0].cam_from_world.Inverse();
  const Eigen::Vector3d t = cam2_from_cam1.translation;
  Eigen::Matrix3d t_cross;
  t_cross << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  const Eigen::Matrix3d k_inverse = views[0].calibration.inverse();
  const Eigen::Matrix3d f = views[1].calibration.inverse().transpose() * t_cross *
                            cam2_from_cam1.RotationMatrix() * k_inverse;
  std::vector<double> distances;
  for (const auto& [first, second] : neighbours.inlier_matches) {
    // Middlebury's calibration puts pixel centres at integers: COLMAP's keypoints minus 0.5.
    const Eigen::Vector2d p1 = images[0].keypoints[first].cast<double>().array() - 0.5;
    const Eigen::Vector2d p2 = images[1].keypoints[second].cast<double>().array() - 0.5;
    const Eigen::Vector3d line = f * p1.homogeneous();
    distances.push_back(std::abs(p2.homogeneous().dot(line)) / line.head<2>().norm());
  }
  std::sort(distances.begin(), distances.end());
  ASSERT_FALSE(distances.empty());
  const double median = distances[distances.size() / 2];
  std::cout << "templeSR0001/0002: " << neighbours.matches.size() << " matches, "
            << neighbours.inlier_matches.size() << " inliers, median epipolar distance " << median
            << " px, 90th percentile " << distances[distances.size() * 9 / 10] << " px\n";
  EXPECT_EQ(neighbours.config, TwoViewConfig::kCalibrated);
  EXPECT_GE(neighbours.inlier_matches.size(), 100u);
  EXPECT_LT(median, 1.0);

  // The whole database path with 1 and 2 threads writes the same tables.
  const fs::path copy = directory / "copy.db";
  fs::copy_file(database, copy);
  options.num_threads = 1;
  MatchDatabase(database, PairChoice{}, camera, options);
  options.num_threads = 2;
  MatchDatabase(copy, PairChoice{}, camera, options);
  const std::vector<PairGeometry> written = ReadPairGeometries(database);
  const std::vector<PairGeometry> written_copy = ReadPairGeometries(copy);
  ASSERT_EQ(written.size(), 3u);
  ASSERT_EQ(written_copy.size(), 3u);
  for (size_t k = 0; k < written.size(); ++k) {
    EXPECT_EQ(written[k].matches, written_copy[k].matches);
    EXPECT_EQ(written[k].inlier_matches, written_copy[k].inlier_matches);
    EXPECT_EQ(written[k].matches, reference[k].matches);
  }
  fs::remove_all(directory);
}

// Writes a blurred random texture (features for SIFT).
void WriteTexture(const fs::path& path, int seed) {
  cv::Mat image(240, 320, CV_8UC1);
  cv::RNG rng(static_cast<uint64_t>(seed));
  rng.fill(image, cv::RNG::UNIFORM, 0, 255);
  cv::GaussianBlur(image, image, cv::Size(0, 0), 2.0);
  ASSERT_TRUE(cv::imwrite(path.string(), image));
}

// A database made by COLMAP's own feature_extractor: matches and two-view geometries written and
// read back; a database without the tables, and a keypoint blob of the wrong size, are refused.
TEST(ColmapDatabase, PairGeometriesRoundTripAndMalformedDatabasesAreRefused) {
  const fs::path directory = evloc::testing::MakeTempDir("colmap_database");
  const fs::path images = directory / "images";
  fs::create_directories(images);
  WriteTexture(images / "a.png", 1);
  WriteTexture(images / "b.png", 2);
  const fs::path database = ExtractFeatures(directory / "workspace", images, {"a.png", "b.png"},
                                            Camera::Pinhole(320, 240, 300, 300, 159.5, 119.5));
  const std::vector<ImageFeatures> features = ReadImageFeatures(database);
  ASSERT_EQ(features.size(), 2u);
  EXPECT_EQ(features[0].name, "a.png");
  EXPECT_GT(features[0].keypoints.size(), 50u);
  EXPECT_EQ(features[0].descriptors.size(), features[0].keypoints.size() * kSiftDescriptorSize);

  PairGeometry verified;
  verified.image_id1 = features[0].image_id;
  verified.image_id2 = features[1].image_id;
  verified.matches = {{0, 5}, {1, 7}, {4, 2}};
  verified.inlier_matches = {{0, 5}, {4, 2}};
  verified.config = TwoViewConfig::kCalibrated;
  verified.E << 0, -1, 0.5, 1, 0, -2, -0.5, 2, 0;
  verified.F << 1, 2, 3, 4, 5, 6, 7, 8, 9;
  PairGeometry unverified;
  unverified.image_id1 = 1;
  unverified.image_id2 = 3;
  unverified.matches = {{2, 2}};
  WritePairGeometries(database, {verified, unverified});
  const std::vector<PairGeometry> read = ReadPairGeometries(database);
  ASSERT_EQ(read.size(), 2u);
  EXPECT_EQ(read[0].image_id1, verified.image_id1);
  EXPECT_EQ(read[0].image_id2, verified.image_id2);
  EXPECT_EQ(read[0].matches, verified.matches);
  EXPECT_EQ(read[0].inlier_matches, verified.inlier_matches);
  EXPECT_EQ(read[0].config, TwoViewConfig::kCalibrated);
  EXPECT_EQ(read[0].E, verified.E);
  EXPECT_EQ(read[0].F, verified.F);
  EXPECT_EQ(read[0].H, Eigen::Matrix3d::Zero());
  EXPECT_EQ(read[1].image_id2, 3u);
  EXPECT_EQ(read[1].matches, unverified.matches);
  EXPECT_TRUE(read[1].inlier_matches.empty());
  EXPECT_EQ(read[1].config, TwoViewConfig::kUndefined);
  EXPECT_EQ(ColmapPairId(2, 1), 2147483647ull + 2);
  // Writing again replaces the rows.
  WritePairGeometries(database, {unverified});
  EXPECT_EQ(ReadPairGeometries(database).size(), 1u);
  PairGeometry reversed = unverified;
  std::swap(reversed.image_id1, reversed.image_id2);
  EXPECT_THROW(WritePairGeometries(database, {reversed}), InvalidArgumentError);

  // Not a COLMAP database: an SQLite file without the tables, a text file, a missing file.
  const fs::path empty = directory / "empty.db";
  sqlite3* handle = nullptr;
  ASSERT_EQ(sqlite3_open(empty.c_str(), &handle), SQLITE_OK);
  sqlite3_close(handle);
  EXPECT_THROW(ReadImageFeatures(empty), IoError);
  EXPECT_THROW(WritePairGeometries(empty, {verified}), IoError);
  std::ofstream(directory / "text.db") << "not a database\n";
  EXPECT_THROW(ReadImageFeatures(directory / "text.db"), IoError);
  EXPECT_THROW(ReadImageFeatures(directory / "missing.db"), IoError);
  // A keypoint blob one byte short.
  ASSERT_EQ(sqlite3_open(database.c_str(), &handle), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(handle, "UPDATE keypoints SET data = substr(data, 2) WHERE image_id = 1",
                         nullptr, nullptr, nullptr),
            SQLITE_OK);
  sqlite3_close(handle);
  EXPECT_THROW(ReadImageFeatures(database), ParseError);
  fs::remove_all(directory);
}

// A keypoint within half its scale of the image border has a descriptor COLMAP computed from
// memory outside the image (it differed between two runs on real frames): ReadImageFeatures
// returns it as zeros; moving one keypoint there zeroes its descriptor and no other.
TEST(ColmapDatabase, DescriptorsOfKeypointsAtTheBorderAreNotUsed) {
  const fs::path directory = evloc::testing::MakeTempDir("colmap_database_border");
  const fs::path images = directory / "images";
  fs::create_directories(images);
  WriteTexture(images / "a.png", 1);
  const fs::path database = ExtractFeatures(directory / "workspace", images, {"a.png"},
                                            Camera::Pinhole(320, 240, 300, 300, 159.5, 119.5));
  const std::vector<ImageFeatures> before = ReadImageFeatures(database);
  ASSERT_EQ(before.size(), 1u);
  ASSERT_GT(before[0].keypoints.size(), 10u);
  const auto is_zero = [](const ImageFeatures& image, size_t k) {
    return std::all_of(image.descriptors.begin() + k * kSiftDescriptorSize,
                       image.descriptors.begin() + (k + 1) * kSiftDescriptorSize,
                       [](uint8_t value) { return value == 0; });
  };
  ASSERT_FALSE(is_zero(before[0], 3)) << "keypoint 3 must start away from the border";
  // Move keypoint 3 to 0.1 px from the bottom border (its scale stays, and is larger than 0.2 px).
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(database.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* select = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT rows, cols, data FROM keypoints WHERE image_id = ?", -1,
                               &select, nullptr),
            SQLITE_OK);
  sqlite3_bind_int64(select, 1, before[0].image_id);
  ASSERT_EQ(sqlite3_step(select), SQLITE_ROW);
  const int64_t cols = sqlite3_column_int64(select, 1);
  ASSERT_GE(cols, 4);
  const auto* bytes = static_cast<const uint8_t*>(sqlite3_column_blob(select, 2));
  std::vector<uint8_t> blob(bytes, bytes + sqlite3_column_bytes(select, 2));
  sqlite3_finalize(select);
  float y = 239.9f;
  std::memcpy(blob.data() + (3 * cols + 1) * sizeof(float), &y, sizeof(y));
  sqlite3_stmt* update = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "UPDATE keypoints SET data = ? WHERE image_id = ?", -1, &update,
                               nullptr),
            SQLITE_OK);
  sqlite3_bind_blob(update, 1, blob.data(), static_cast<int>(blob.size()), SQLITE_TRANSIENT);
  sqlite3_bind_int64(update, 2, before[0].image_id);
  ASSERT_EQ(sqlite3_step(update), SQLITE_DONE);
  sqlite3_finalize(update);
  sqlite3_close(db);

  const std::vector<ImageFeatures> after = ReadImageFeatures(database);
  ASSERT_EQ(after[0].keypoints.size(), before[0].keypoints.size());
  for (size_t k = 0; k < after[0].keypoints.size(); ++k) {
    EXPECT_EQ(is_zero(after[0], k), k == 3 || is_zero(before[0], k)) << k;
  }
}

}  // namespace
}  // namespace evloc::mapper
