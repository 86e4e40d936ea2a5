#include "mapper/georeference.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <set>
#include <sstream>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "mapper/testing/mapper_cli_runner.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/synthetic_map.h"

namespace evloc::mapper {
namespace {

// The true anchor of the test site.
GeoAnchor TrueAnchor() {
  GeoAnchor anchor;
  anchor.origin = {46.5191, 6.5668, 372.0};
  anchor.enu_from_map =
      Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(2.1, Eigen::Vector3d::UnitZ()) *
                                 Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitX())),
              Eigen::Vector3d(4.0, -7.0, 1.2));
  return anchor;
}

// A small map whose 12 keyframes (frame_K.jpg) stand on a 40 m x 30 m survey loop, 1.5 m up:
// their centres are not collinear, so they determine an alignment.
Map SurveyMap() {
  CorridorMapOptions options;
  options.num_points = 500;
  options.num_keyframes = 12;
  Map map = MakeCorridorMap(options);
  for (size_t k = 0; k < map.keyframes.size(); ++k) {
    const double angle = 2.0 * M_PI * static_cast<double>(k) / 12.0;
    const Eigen::Vector3d centre(20.0 * std::cos(angle), 15.0 * std::sin(angle),
                                 1.5 + 0.3 * std::sin(3 * angle));
    const Rigid3d world_from_cam(
        Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitY())), centre);
    map.keyframes[k].cam_from_world = world_from_cam.Inverse();
    map.keyframes[k].image_name = "frame_" + std::to_string(k) + ".jpg";
  }
  map.provenance = {"evloc-test", "0", "2026-11-25T00:00:00Z", "test", {}};
  return map;
}

Eigen::Vector3d Centre(const Keyframe& keyframe) {
  return keyframe.cam_from_world.Inverse().translation;
}

// Largest distance over the keyframe centres between where two anchors put them, metres.
double WorstDisagreement(const GeoAnchor& estimate, const GeoAnchor& truth, const Map& map) {
  const GeoReference a(estimate), b(truth);
  double worst = 0.0;
  for (const Keyframe& keyframe : map.keyframes) {
    const Eigen::Vector3d p = Centre(keyframe);
    worst = std::max(worst, (b.MapFromGeodetic(a.GeodeticFromMap(p)) - p).norm());
  }
  return worst;
}

using testing::CliResult;
using testing::RunCli;

class GeoreferenceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = testing::MakeTempDir("georeference_test");
    map_ = SurveyMap();
    WriteMapDirectory(directory_ / "map", map_, {});
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }

  // Writes a 64x48 JPEG per keyframe into directory_/images, tagged with the keyframe centre's
  // WGS84 position through TrueAnchor() plus Gaussian noise (sigma per axis, metres); keyframes
  // in `untagged` get no tags.
  void WriteTaggedImages(double sigma, uint64_t seed, const std::set<size_t>& untagged = {}) {
    const std::filesystem::path images = directory_ / "images";
    std::filesystem::create_directories(images);
    const GeoReference truth(TrueAnchor());
    std::mt19937_64 random(seed);
    std::normal_distribution<double> noise(0.0, sigma);
    for (size_t k = 0; k < map_.keyframes.size(); ++k) {
      const std::filesystem::path path = images / map_.keyframes[k].image_name;
      cv::Mat image(48, 64, CV_8UC3, cv::Scalar(40, 90, 160));
      ASSERT_TRUE(cv::imwrite(path.string(), image));
      if (untagged.count(k)) continue;
      const Eigen::Vector3d enu = TrueAnchor().enu_from_map * Centre(map_.keyframes[k]) +
                                  Eigen::Vector3d(noise(random), noise(random), noise(random));
      WriteExifGnssPosition(path, truth.enu_frame().ToGeodetic(enu));
    }
  }

  std::filesystem::path directory_;
  Map map_;
};

// Tags written with exiv2 read back within their resolution (1e-6 s of arc: 3 cm; 1 mm of
// altitude), in every hemisphere and below sea level; the exiv2 command line (an independent
// reader) shows them.
TEST_F(GeoreferenceTest, ExifGnssTagsRoundTrip) {
  const std::filesystem::path path = directory_ / "photo.jpg";
  ASSERT_TRUE(cv::imwrite(path.string(), cv::Mat(16, 16, CV_8UC1, cv::Scalar(128))));
  EXPECT_FALSE(ReadExifGnssPosition(path).has_value());
  for (const GeodeticPoint& point :
       {GeodeticPoint{46.519123456, 6.566812345, 372.125},
        GeodeticPoint{-33.856784, -151.215297, -12.5}, GeodeticPoint{0.000001, 179.999999, 0.0}}) {
    WriteExifGnssPosition(path, point);
    const std::optional<GeodeticPoint> read = ReadExifGnssPosition(path);
    ASSERT_TRUE(read.has_value());
    EXPECT_NEAR(read->latitude_deg, point.latitude_deg, 1e-6 / 3600 + 1e-12);
    EXPECT_NEAR(read->longitude_deg, point.longitude_deg, 1e-6 / 3600 + 1e-12);
    EXPECT_NEAR(read->altitude_m, point.altitude_m, 0.0005 + 1e-12);
  }
  if (std::system("exiv2 --version > /dev/null 2>&1") != 0) {
    GTEST_SKIP() << "the exiv2 command line is not installed (scripts/install-deps.sh)";
  }
  const std::string listing = (directory_ / "listing.txt").string();
  ASSERT_EQ(
      std::system(
          ("exiv2 -Pkv -g GPSLatitude -g GPSLongitude " + path.string() + " > " + listing).c_str()),
      0);
  const std::string text = ReadFileToString(listing);
  EXPECT_NE(text.find("Exif.GPSInfo.GPSLatitudeRef"), std::string::npos) << text;
  EXPECT_NE(text.find("0/1 0/1 3600/1000000"), std::string::npos) << text;  // 0.000001 degrees
  EXPECT_NE(text.find("179/1 59/1 59996400/1000000"), std::string::npos) << text;
}

TEST_F(GeoreferenceTest, GeorefFromExactExifTagsRecoversTheAnchor) {
  WriteTaggedImages(0.0, 1, {3});
  const CliResult result = RunCli({"georef", "--map", (directory_ / "map").string(), "--geo-exif",
                                   "--images", (directory_ / "images").string()});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("11 of 12 keyframe images with GNSS tags"), std::string::npos)
      << result.out;
  const Map map = LoadMap(directory_ / "map" / kMapFileName);
  ASSERT_TRUE(map.geo_anchor.has_value());
  EXPECT_EQ(map.geo_anchor->source, "exif");
  // The tags' resolution (3 cm, 1 mm) is the only error.
  EXPECT_LT(WorstDisagreement(*map.geo_anchor, TrueAnchor(), map), 0.05);
  EXPECT_EQ(ComputeMapContentChecksum(map), ComputeMapContentChecksum(map_));
  // A second georef is refused without --force, and replaces the anchor with it.
  const std::vector<std::string> given = {"georef", "--map", (directory_ / "map").string(),
                                          "--geo-anchor", "46.5,6.5,400,90"};
  CliResult again = RunCli(given);
  EXPECT_EQ(again.exit_code, 1);
  EXPECT_NE(again.err.find("already has a geo anchor (source exif); pass --force"),
            std::string::npos)
      << again.err;
  std::vector<std::string> forced = given;
  forced.push_back("--force");
  again = RunCli(forced);
  ASSERT_EQ(again.exit_code, 0) << again.err;
  const Map replaced = LoadMap(directory_ / "map" / kMapFileName);
  EXPECT_EQ(replaced.geo_anchor->source, "given");
  // Heading 90: the map's +y axis points east, so its +x axis points south.
  const GeoReference reference(*replaced.geo_anchor);
  const Eigen::Vector3d x_axis = reference.anchor().enu_from_map * Eigen::Vector3d::UnitX();
  EXPECT_NEAR((x_axis - Eigen::Vector3d(0, -1, 0)).norm(), 0.0, 1e-12);
}

// Consumer GNSS (3 m per axis) on 12 photos: the anchor is within the noise's standard error,
// and the reported sigma says so.
TEST_F(GeoreferenceTest, NoisyExifTagsGiveAnAnchorWithinTheirStandardError) {
  WriteTaggedImages(3.0, 7);
  GeoReferenceOptions options;
  options.exif = true;
  const GeoReferenceResult result = GeoReferenceMap(map_, directory_ / "images", options);
  ASSERT_TRUE(result.alignment.has_value());
  EXPECT_EQ(result.alignment->num_inliers, 12u);
  // 12 fixes at 3 m: 0.87 m standard error of the centroid per axis, and a tilt of about
  // 3 / (12.5 * sqrt(12)) = 0.07 rad over the loop's 20 m radius (1.4 m): 3 sigma of both is 5 m.
  EXPECT_LT(WorstDisagreement(result.anchor, TrueAnchor(), map_), 5.0);
  EXPECT_GT(result.anchor.horizontal_sigma_m, 0.3);
  EXPECT_LT(result.anchor.horizontal_sigma_m, 2.5);
}

TEST_F(GeoreferenceTest, GeorefFromAPointsFileWithImagesAndPoints) {
  const GeoReference truth(TrueAnchor());
  std::ostringstream text;
  text.precision(12);
  text << "# survey of the test site\n";
  for (size_t k = 0; k < 4; ++k) {
    const GeodeticPoint p = truth.GeodeticFromMap(Centre(map_.keyframes[k * 3]));
    text << "image " << map_.keyframes[k * 3].image_name << " " << p.latitude_deg << " "
         << p.longitude_deg << " " << p.altitude_m << "\n";
  }
  const Eigen::Vector3d marker(3.0, 4.0, 0.0);
  const GeodeticPoint p = truth.GeodeticFromMap(marker);
  text << "point 3 4 0 " << p.latitude_deg << " " << p.longitude_deg << " " << p.altitude_m << "\n";
  const std::filesystem::path points = directory_ / "points.txt";
  WriteFileAtomically(points, text.str());
  const std::filesystem::path out = directory_ / "anchored.evmap";
  const CliResult result = RunCli({"georef", "--map", (directory_ / "map").string(), "--geo-points",
                                   points.string(), "--out", out.string()});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("4 images and 1 points"), std::string::npos) << result.out;
  const Map map = LoadMap(out);
  ASSERT_TRUE(map.geo_anchor.has_value());
  EXPECT_EQ(map.geo_anchor->source, "survey");
  EXPECT_LT(WorstDisagreement(*map.geo_anchor, TrueAnchor(), map), 1e-4);
  EXPECT_FALSE(LoadMap(directory_ / "map" / kMapFileName).geo_anchor.has_value());
  // evloc-mapper info shows the anchor.
  const CliResult info = RunCli({"info", out.string()});
  EXPECT_NE(info.out.find("geo anchor:       46.5"), std::string::npos) << info.out;

  // A name that is no keyframe is an error naming the file and line.
  WriteFileAtomically(points, text.str() + "image missing.jpg 46.5 6.5 300\n");
  const CliResult bad =
      RunCli({"georef", "--map", (directory_ / "map").string(), "--geo-points", points.string()});
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.err.find("points.txt: line 7: image 'missing.jpg' is not a keyframe"),
            std::string::npos)
      << bad.err;
  EXPECT_FALSE(LoadMap(directory_ / "map" / kMapFileName).geo_anchor.has_value());
}

TEST_F(GeoreferenceTest, BadCommandLinesAreUsageErrors) {
  const std::string map = (directory_ / "map").string();
  for (const std::vector<std::string>& arguments :
       {std::vector<std::string>{"georef", "--map", map},
        {"georef", "--map", map, "--geo-anchor", "91,0,0"},
        {"georef", "--map", map, "--geo-anchor", "1,2"},
        {"georef", "--map", map, "--geo-exif"},
        {"georef", "--map", map, "--geo-anchor", "1,2,3", "--geo-points", "p.txt"}}) {
    const CliResult result = RunCli(arguments);
    EXPECT_EQ(result.exit_code, 2) << result.err;
    EXPECT_NE(result.err.find("evloc-mapper georef: error:"), std::string::npos) << result.err;
  }
  WriteTaggedImages(0.0, 1, {0, 1, 2, 3, 4, 5, 6, 7, 8, 9});
  const CliResult too_few =
      RunCli({"georef", "--map", map, "--geo-exif", "--images", (directory_ / "images").string()});
  EXPECT_EQ(too_few.exit_code, 1);
  EXPECT_NE(too_few.err.find("2 of the 12 keyframe images"), std::string::npos) << too_few.err;
}

}  // namespace
}  // namespace evloc::mapper
