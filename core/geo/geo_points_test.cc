#include "core/geo/geo_points.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "core/common/error.h"

namespace evloc {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseGeoPoints(text, "points.txt");
  } catch (const ParseError& error) {
    return error.what();
  }
  return "";
}

TEST(GeoPointsTest, ReadsImageAndPointRecordsWithCommentsAndBlankLines) {
  const auto records = ParseGeoPoints(
      "# surveyed 2026-11-25\n"
      "image IMG_0001.JPG 47.3769 8.5417 408.25\n"
      "\n"
      "point 1.5 -2 0.25\t47.37695 8.54175 409\r\n"
      "   # indented comment\n",
      "points.txt");
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].kind, GeoPointRecord::Kind::kImage);
  EXPECT_EQ(records[0].image_name, "IMG_0001.JPG");
  EXPECT_DOUBLE_EQ(records[0].geodetic.latitude_deg, 47.3769);
  EXPECT_DOUBLE_EQ(records[0].geodetic.altitude_m, 408.25);
  EXPECT_EQ(records[0].line, 2);
  EXPECT_EQ(records[1].kind, GeoPointRecord::Kind::kPoint);
  EXPECT_EQ(records[1].p_map, Eigen::Vector3d(1.5, -2, 0.25));
  EXPECT_DOUBLE_EQ(records[1].geodetic.longitude_deg, 8.54175);
  EXPECT_EQ(records[1].line, 4);
}

TEST(GeoPointsTest, ErrorsNameTheFileTheLineAndTheProblem) {
  EXPECT_NE(ErrorOf("image a 1 2\n").find("points.txt: line 1"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 1 2\n").find("5 fields"), std::string::npos);
  EXPECT_NE(ErrorOf("\npoint 1 2 3 4 5\n").find("line 2"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 1 2 3\nimage a 1 2 3\n").find("listed twice"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 91 2 3\n").find("latitude 91"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 1 181 3\n").find("longitude"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 1 2 nan\n").find("altitude 'nan'"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 1 2 3m\n").find("'3m' is not a finite number"), std::string::npos);
  EXPECT_NE(ErrorOf("point 1 2 inf 4 5 6\n").find("z 'inf'"), std::string::npos);
  EXPECT_NE(ErrorOf("gcp 1 2 3\n").find("unknown record 'gcp'"), std::string::npos);
  EXPECT_NE(ErrorOf("# nothing\n\n").find("no 'image' or 'point' record"), std::string::npos);
  EXPECT_NE(ErrorOf(std::string("image a\0b 1 2 3\n", 16)).find("NUL"), std::string::npos);
  EXPECT_NE(ErrorOf("image a 1 2 " + std::string(5000, '3') + "\n").find("bytes"),
            std::string::npos);
}

TEST(GeoPointsTest, ReadsAFileAndReportsAMissingOne) {
  const auto path = std::filesystem::temp_directory_path() / "evloc_geo_points_test.txt";
  {
    std::ofstream file(path);
    file << "point 0 0 0 10 20 30\n";
  }
  const auto records = ReadGeoPoints(path);
  ASSERT_EQ(records.size(), 1u);
  EXPECT_DOUBLE_EQ(records[0].geodetic.altitude_m, 30.0);
  std::filesystem::remove(path);
  EXPECT_THROW(ReadGeoPoints(path), IoError);
}

}  // namespace
}  // namespace evloc
