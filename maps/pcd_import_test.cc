#include "maps/pcd_import.h"

#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

const char kAsciiHeader[] =
    "# .PCD v0.7 - Point Cloud Data file format\n"
    "VERSION 0.7\n"
    "FIELDS x y z normal_x normal_y normal_z\n"
    "SIZE 4 4 4 4 4 4\n"
    "TYPE F F F F F F\n"
    "COUNT 1 1 1 1 1 1\n"
    "WIDTH 4\n"
    "HEIGHT 1\n"
    "VIEWPOINT 0 0 0 1 0 0 0\n"
    "POINTS 4\n"
    "DATA ascii\n";  // data starts on line 12

class PcdImportTest : public ::testing::Test {
 protected:
  void SetUp() override { directory_ = testing::MakeTempDir("pcd_import_test"); }
  void TearDown() override { std::filesystem::remove_all(directory_); }

  std::filesystem::path Write(const std::string& content) {
    const std::filesystem::path path = directory_ / "map.pcd";
    WriteFileAtomically(path, content);
    return path;
  }

  // Expects ImportCannyEvtPcd to throw ParseError containing every fragment.
  void ExpectParseError(const std::string& content, std::initializer_list<std::string> fragments) {
    const std::filesystem::path path = Write(content);
    try {
      ImportCannyEvtPcd(path);
      ADD_FAILURE() << "no ParseError for:\n" << content;
    } catch (const ParseError& error) {
      for (const std::string& fragment : fragments) {
        EXPECT_NE(std::string(error.what()).find(fragment), std::string::npos)
            << "message: " << error.what() << "\nexpected to contain: " << fragment;
      }
    }
  }

  std::filesystem::path directory_;
};

TEST_F(PcdImportTest, AsciiGradientIsTheNormalisedOffset) {
  const PcdImport result =
      ImportCannyEvtPcd(Write(std::string(kAsciiHeader) + "1 2 3 1.02 2 3\n"
                                                          "0 0 1 0 0.03 1.04\n"
                                                          "0.5 0.5 0.5 0.5 0.5 0.5\n"
                                                          "nan 0 0 0 0 0\n"));
  const Map& map = result.map;
  ASSERT_EQ(map.size(), 2u);
  EXPECT_EQ(map.positions[0], Eigen::Vector3f(1, 2, 3));
  EXPECT_TRUE(map.gradients[0].isApprox(Eigen::Vector3f(1, 0, 0), 1e-5f));
  EXPECT_TRUE(map.gradients[1].isApprox(Eigen::Vector3f(0, 0.6f, 0.8f), 1e-5f));
  EXPECT_EQ(map.source_keyframe[0], kNoKeyframe);
  EXPECT_EQ(map.inverse_depth_sigma[1], 0.0f);
  EXPECT_TRUE(map.keyframes.empty());
  EXPECT_NO_THROW(map.Check());
  EXPECT_EQ(result.report.num_points_in_file, 4u);
  EXPECT_EQ(result.report.num_imported, 2u);
  EXPECT_EQ(result.report.num_dropped_zero_gradient, 1u);
  EXPECT_EQ(result.report.num_dropped_non_finite, 1u);
  EXPECT_EQ(result.report.first_dropped_points, (std::vector<size_t>{2, 3}));
  EXPECT_NEAR(result.report.median_gradient_offset_m, 0.05, 1e-6);
}

TEST_F(PcdImportTest, BinaryWithExtraFieldsAndDoubles) {
  std::string content =
      "VERSION 0.7\n"
      "FIELDS intensity normal_x normal_y normal_z x y z curvature\n"
      "SIZE 4 4 4 4 8 8 8 4\n"
      "TYPE U F F F F F F F\n"
      "COUNT 1 1 1 1 1 1 1 1\n"
      "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n";
  const auto append = [&content](const auto& value) {
    content.append(reinterpret_cast<const char*>(&value), sizeof(value));
  };
  for (int i = 0; i < 2; ++i) {
    append(uint32_t{7});
    append(float{1.0f * i});
    append(float{0.0f});
    append(float{1.03f});
    append(double{1.0 * i});
    append(double{0.0});
    append(double{1.0});
    append(float{0.5f});
  }
  const PcdImport result = ImportCannyEvtPcd(Write(content));
  ASSERT_EQ(result.map.size(), 2u);
  EXPECT_EQ(result.map.positions[1], Eigen::Vector3f(1, 0, 1));
  EXPECT_TRUE(result.map.gradients[1].isApprox(Eigen::Vector3f(0, 0, 1), 1e-5f));
  EXPECT_NEAR(result.report.median_gradient_offset_m, 0.03, 1e-6);

  ExpectParseError(content.substr(0, content.size() - 5),
                   {"binary PCD data is truncated", "need 88 bytes", "has 83"});
}

TEST_F(PcdImportTest, MalformedFilesNameTheLine) {
  const std::string header = kAsciiHeader;
  ExpectParseError(header + "1 2 3 1 2 3.1\n1 2 x 1 2 3\n", {"map.pcd: line 13", "'x'"});
  ExpectParseError(header + "1 2 3 1 2 3.1\n1 2 3 1 2\n", {"line 13", "expected 6 values"});
  ExpectParseError(header + "1 2 3 1 2 3.1 7\n", {"line 12", "more than 6 values"});
  ExpectParseError(header + "1 2 3 1 2 3.1\n1 2 3 1 2 3.1\n",
                   {"file ends after 2 of 4 points", "truncated"});
  ExpectParseError(header + "0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n0 0 0 0 0 1\n",
                   {"line 16", "more data lines than POINTS 4"});
  std::string no_normals = header;
  no_normals.replace(no_normals.find("normal_z"), 8, "curvatur");
  ExpectParseError(no_normals, {"line 3", "no field 'normal_z'"});
  std::string compressed = header;
  compressed.replace(compressed.find("DATA ascii"), 10, "DATA binary_compressed");
  ExpectParseError(compressed, {"line 11", "binary_compressed is not supported"});
  ExpectParseError("hello world\n", {"line 1", "unknown PCD header key 'hello'"});
  ExpectParseError("VERSION 0.7\n", {"no DATA line"});
  std::string bad_type = header;
  bad_type.replace(bad_type.find("TYPE F F F"), 10, "TYPE F F I");
  ExpectParseError(bad_type, {"line 3", "field 'z' must be a single float"});
}

TEST_F(PcdImportTest, MissingFileIsAnIoError) {
  EXPECT_THROW(ImportCannyEvtPcd(directory_ / "missing.pcd"), IoError);
}

TEST(PcdImportRealData, CannyEvtVectorRobotFastMap) {
  EVLOC_REQUIRE_SHARED_DATA(path, "canny-evt-maps/vector_robot_fast.pcd");
  const PcdImport result = ImportCannyEvtPcd(path);
  EXPECT_EQ(result.report.num_points_in_file, 40946u);
  EXPECT_EQ(result.report.num_imported + result.report.num_dropped_zero_gradient +
                result.report.num_dropped_non_finite,
            40946u);
  EXPECT_EQ(result.report.num_dropped_non_finite, 0u);
  EXPECT_GT(result.report.num_imported, 40000u);
  // The Canny-EVT exporter puts the gradient end point 2-3 cm from the point.
  EXPECT_GT(result.report.median_gradient_offset_m, 0.015);
  EXPECT_LT(result.report.median_gradient_offset_m, 0.035);
  EXPECT_NO_THROW(result.map.Check());
  // The first line of the file: -0.337187 -0.070228 1.137192 -0.356292 -0.073958 1.13511
  const Eigen::Vector3f offset(-0.356292f + 0.337187f, -0.073958f + 0.070228f,
                               1.13511f - 1.137192f);
  EXPECT_EQ(result.map.positions[0], Eigen::Vector3f(-0.337187f, -0.070228f, 1.137192f));
  EXPECT_TRUE(result.map.gradients[0].isApprox(offset.normalized(), 1e-4f));
}

}  // namespace
}  // namespace evloc
