#include "core/dataset/pose_text.h"

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/common/error.h"

namespace evloc {
namespace {

// The message of the InvalidArgumentError ParsePoseText throws for `text`, or "" when it parses.
std::string PoseTextError(const std::string& text) {
  try {
    ParsePoseText("--init-pose", text);
  } catch (const InvalidArgumentError& error) {
    return error.what();
  }
  return "";
}

TEST(PoseText, ParsesTumOrderAndNormalisesANearUnitQuaternion) {
  const Rigid3d pose = ParsePoseText("--init-pose", " 1 -2.5\t3e-1 0 0 0.7071 0.7071 ");
  EXPECT_EQ(pose.translation, Eigen::Vector3d(1, -2.5, 0.3));
  // qx qy qz qw = 0 0 0.7071 0.7071: 90 degrees about z, normalised to unit norm.
  EXPECT_NEAR(pose.rotation.norm(), 1.0, 1e-15);
  EXPECT_NEAR(pose.rotation.z(), std::sqrt(0.5), 1e-15);
  EXPECT_NEAR(pose.rotation.w(), std::sqrt(0.5), 1e-15);
  EXPECT_NEAR((pose.rotation * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 0.0,
              1e-12);
}

TEST(PoseText, RefusesWrongCountsNonFiniteNumbersAndNonUnitQuaternions) {
  EXPECT_NE(PoseTextError("1 2 3").find("expects 7 numbers"), std::string::npos);
  EXPECT_NE(PoseTextError("1 2 3 0 0 0 1 5").find("got 8"), std::string::npos);
  EXPECT_NE(PoseTextError("").find("got 0"), std::string::npos);
  EXPECT_NE(PoseTextError("nan 0 0 0 0 0 1").find("'nan'"), std::string::npos);
  EXPECT_NE(PoseTextError("0 inf 0 0 0 0 1").find("'inf'"), std::string::npos);
  EXPECT_NE(PoseTextError("0 0 1m 0 0 0 1").find("'1m'"), std::string::npos);
  // Zero, doubled and visibly wrong quaternions are mistakes, not rounding.
  EXPECT_NE(PoseTextError("0 0 0 0 0 0 0").find("norm 0"), std::string::npos);
  EXPECT_NE(PoseTextError("0 0 0 0 0 0 2").find("norm 2"), std::string::npos);
  EXPECT_NE(PoseTextError("0 0 0 0 0 0.71 0.71").find("unit quaternion"), std::string::npos);
  // Every message names what was parsed.
  EXPECT_EQ(PoseTextError("0 0 0 0 0 0 2").rfind("--init-pose", 0), 0u);
  // Within the tolerance: accepted.
  EXPECT_EQ(PoseTextError("0 0 0 0 0 0 1.0009"), "");
  EXPECT_NE(PoseTextError("0 0 0 0 0 0 1.0011"), "");
}

TEST(PoseText, TokensAndTextFollowTheSameRule) {
  const std::vector<std::string> tokens = {"4", "5", "6", "0.5", "0.5", "0.5", "0.5"};
  const Rigid3d from_tokens = ParsePoseTokens("pose", tokens);
  const Rigid3d from_text = ParsePoseText("pose", "4 5 6 0.5 0.5 0.5 0.5");
  EXPECT_EQ(from_tokens.translation, from_text.translation);
  EXPECT_EQ(from_tokens.rotation.coeffs(), from_text.rotation.coeffs());
  EXPECT_THROW(ParsePoseTokens("pose", std::vector<std::string>{"1", "2"}), InvalidArgumentError);
}

TEST(PoseText, ATwistIsSixNumbersByTheSameRule) {
  const Vector6d twist = ParseTwistText("--initial-velocity", " 5 0 0.1  0 0.2 -0.3 ");
  EXPECT_EQ(twist, (Vector6d() << 5, 0, 0.1, 0, 0.2, -0.3).finished());
  for (const std::string bad : {"", "1 2 3", "1 2 3 4 5 6 7", "1 2 3 4 5 nan", "1 2 3 4 5 1m"}) {
    try {
      ParseTwistText("--initial-velocity", bad);
      ADD_FAILURE() << "accepted '" << bad << "'";
    } catch (const InvalidArgumentError& error) {
      EXPECT_EQ(std::string(error.what()).rfind("--initial-velocity", 0), 0u) << error.what();
    }
  }
}

}  // namespace
}  // namespace evloc
