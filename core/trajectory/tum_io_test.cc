#include "core/trajectory/tum_io.h"

#include <fstream>
#include <limits>
#include <string>

#include <gtest/gtest.h>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

// Expects `text` to fail to parse with a message containing every string in `needles`.
void ExpectParseErrorMentioning(const std::string& text, const std::vector<std::string>& needles) {
  try {
    ParseTumTrajectory(text, "test.txt");
    ADD_FAILURE() << "no ParseError for:\n" << text;
  } catch (const ParseError& error) {
    for (const std::string& needle : needles) {
      EXPECT_NE(std::string(error.what()).find(needle), std::string::npos)
          << "'" << error.what() << "' does not mention '" << needle << "'";
    }
  }
}

TEST(ParseSecondsAsNanoseconds, ParsesDecimalsExactly) {
  EXPECT_EQ(ParseSecondsAsNanoseconds("1305031102.175304"), 1305031102175304000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("1305031098.6659"), 1305031098665900000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("12"), 12000000000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("12."), 12000000000);
  EXPECT_EQ(ParseSecondsAsNanoseconds(".5"), 500000000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("-0.5"), -500000000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("+3.000000001"), 3000000001);
  EXPECT_EQ(ParseSecondsAsNanoseconds("0.000000001"), 1);
}

TEST(ParseSecondsAsNanoseconds, RoundsBeyondNanosecondsToNearest) {
  EXPECT_EQ(ParseSecondsAsNanoseconds("1.0000000004"), 1000000000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("1.0000000005"), 1000000001);
  EXPECT_EQ(ParseSecondsAsNanoseconds("1.9999999999"), 2000000000);
  EXPECT_EQ(ParseSecondsAsNanoseconds("-1.0000000005"), -1000000001);
}

TEST(ParseSecondsAsNanoseconds, RejectsMalformedAndOutOfRange) {
  for (const char* text : {"", "-", ".", "abc", "1e9", "1.2.3", "nan", "inf", "1,5", " 1", "0x10",
                           "9223372037", "-9223372037"}) {
    EXPECT_THROW(ParseSecondsAsNanoseconds(text), InvalidArgumentError) << text;
  }
}

TEST(FormatNanosecondsAsSeconds, FormatsNineDecimalsAndRoundTrips) {
  EXPECT_EQ(FormatNanosecondsAsSeconds(1305031102175304000), "1305031102.175304000");
  EXPECT_EQ(FormatNanosecondsAsSeconds(0), "0.000000000");
  EXPECT_EQ(FormatNanosecondsAsSeconds(-500000000), "-0.500000000");
  EXPECT_EQ(FormatNanosecondsAsSeconds(-1), "-0.000000001");
  for (const int64_t t_ns :
       {int64_t{0}, int64_t{1}, int64_t{-1}, int64_t{1305031102175304123}, int64_t{-987654321012},
        std::numeric_limits<int64_t>::max(), std::numeric_limits<int64_t>::min()}) {
    EXPECT_EQ(ParseSecondsAsNanoseconds(FormatNanosecondsAsSeconds(t_ns)), t_ns) << t_ns;
  }
}

TEST(TumTrajectory, ParsesCommentsBlankLinesHeaderAndSeparators) {
  const Trajectory trajectory = ParseTumTrajectory(
      "# comment\n"
      "timestamp tx ty tz qx qy qz qw\n"
      "\n"
      "1.5 1 2 3 0 0 0 1\r\n"
      "  2.25\t4,5 6 0 0 0 2\n",
      "test.txt");
  ASSERT_EQ(trajectory.size(), 2u);
  EXPECT_EQ(trajectory.poses()[0].t_ns, 1500000000);
  EXPECT_EQ(trajectory.poses()[1].t_ns, 2250000000);
  EXPECT_EQ(trajectory.poses()[1].world_from_cam.translation, Eigen::Vector3d(4, 5, 6));
  // The quaternion is normalised.
  EXPECT_DOUBLE_EQ(trajectory.poses()[1].world_from_cam.rotation.w(), 1.0);
}

TEST(TumTrajectory, ReportsMalformedLinesWithFileAndLineNumber) {
  ExpectParseErrorMentioning("# c\n1 0 0 0 0 0 0 1\n2 0 0 0 0 0 1\n", {"test.txt", "line 3", "8"});
  ExpectParseErrorMentioning("1 0 0 0 0 0 0 1 7\n", {"test.txt", "line 1", "found 9"});
  ExpectParseErrorMentioning("1 0 0 0 0 0 0 1\n\n2 0 x 0 0 0 0 1\n", {"line 3", "'x'"});
  ExpectParseErrorMentioning("1 0 0 nan 0 0 0 1\n", {"line 1", "nan"});
  ExpectParseErrorMentioning("1 0 0 inf 0 0 0 1\n", {"line 1", "inf"});
  ExpectParseErrorMentioning("abc 0 0 0 0 0 0 1\n", {"line 1", "abc"});
  ExpectParseErrorMentioning("1 0 0 0 0 0 0 0\n", {"line 1", "zero norm"});
  ExpectParseErrorMentioning("1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n#\n1.5 0 0 0 0 0 0 1\n",
                             {"line 4", "line 2", "before"});
  // A header after the first pose is an error too.
  ExpectParseErrorMentioning("1 0 0 0 0 0 0 1\ntimestamp tx ty tz qx qy qz qw\n", {"line 2"});
}

TEST(TumTrajectory, DuplicateTimeNamesBothLines) {
  ExpectParseErrorMentioning("# x\n1.0 0 0 0 0 0 0 1\n\n1.000000000 1 0 0 0 0 0 1\n",
                             {"test.txt", "line 4", "duplicate", "line 2"});
}

TEST(TumTrajectory, MissingFileThrowsIoError) {
  EXPECT_THROW(ReadTumTrajectory("/nonexistent/evloc/trajectory.txt"), IoError);
}

TEST(TumTrajectory, WriteThenReadIsExact) {
  Trajectory trajectory;
  const Eigen::Quaterniond rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()));
  trajectory.Append({1305031102175304123, Rigid3d(rotation, {0.1, -2.0 / 3.0, 1e-7})});
  trajectory.Append({1305031102175304124, Rigid3d(rotation.inverse(), {1e3, M_PI, -M_E})});
  trajectory.Append({1305031103000000000, Rigid3d()});
  const std::filesystem::path directory = testing::MakeTempDir("tum_round_trip");
  const std::filesystem::path path = directory / "trajectory.txt";
  WriteTumTrajectory(path, trajectory);
  const Trajectory read = ReadTumTrajectory(path);
  ASSERT_EQ(read.size(), trajectory.size());
  for (size_t i = 0; i < read.size(); ++i) {
    EXPECT_EQ(read.poses()[i].t_ns, trajectory.poses()[i].t_ns);
    EXPECT_EQ(read.poses()[i].world_from_cam.translation,
              trajectory.poses()[i].world_from_cam.translation);
    EXPECT_LT((read.poses()[i].world_from_cam.rotation.coeffs() -
               trajectory.poses()[i].world_from_cam.rotation.coeffs())
                  .norm(),
              1e-15);
  }
  // Writing what was read reproduces the file byte for byte.
  EXPECT_EQ(FormatTumTrajectory(read), ReadFileToString(path));
  std::filesystem::remove_all(directory);
}

TEST(TumTrajectory, ReadsRealTumGroundTruth) {
  EVLOC_REQUIRE_SHARED_DATA(path, "tum-trajectories/fr1_xyz_groundtruth.txt");
  // Count the pose lines independently: lines that start with a digit.
  std::ifstream stream(path);
  std::string line;
  size_t pose_lines = 0;
  std::string first_time;
  while (std::getline(stream, line)) {
    if (!line.empty() && line[0] >= '0' && line[0] <= '9') {
      if (pose_lines == 0) first_time = line.substr(0, line.find(' '));
      ++pose_lines;
    }
  }
  ASSERT_GT(pose_lines, 1000u);
  const Trajectory trajectory = ReadTumTrajectory(path);
  EXPECT_EQ(trajectory.size(), pose_lines);
  EXPECT_EQ(trajectory.start_ns(), ParseSecondsAsNanoseconds(first_time));
  EXPECT_EQ(trajectory.start_ns(), 1305031098665900000);
  // About 30 s of motion capture.
  EXPECT_NEAR(static_cast<double>(trajectory.duration_ns()) * 1e-9, 30.0, 0.5);
  for (const TimedPose& pose : trajectory.poses()) {
    EXPECT_NEAR(pose.world_from_cam.rotation.norm(), 1.0, 1e-12);
  }
  // Formatting and re-parsing keeps every timestamp bit-exact.
  const Trajectory reread = ParseTumTrajectory(FormatTumTrajectory(trajectory), "formatted");
  ASSERT_EQ(reread.size(), trajectory.size());
  for (size_t i = 0; i < reread.size(); ++i) {
    ASSERT_EQ(reread.poses()[i].t_ns, trajectory.poses()[i].t_ns);
  }
}

}  // namespace
}  // namespace evloc
