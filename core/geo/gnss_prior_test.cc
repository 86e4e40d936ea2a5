#include "core/geo/gnss_prior.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "core/common/error.h"

namespace evloc {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseGnssPrior("--gnss", text);
  } catch (const InvalidArgumentError& error) {
    return error.what();
  }
  return "";
}

TEST(GnssPrior, ParsesFourOrFiveValuesAndTheVerticalSigmaDefaultsToTheHorizontal) {
  const GnssPrior four = ParseGnssPrior("--gnss", "47.3769,8.5417,408.5,3");
  EXPECT_DOUBLE_EQ(four.position.latitude_deg, 47.3769);
  EXPECT_DOUBLE_EQ(four.position.longitude_deg, 8.5417);
  EXPECT_DOUBLE_EQ(four.position.altitude_m, 408.5);
  EXPECT_DOUBLE_EQ(four.horizontal_accuracy_m, 3.0);
  EXPECT_DOUBLE_EQ(four.vertical_accuracy_m, 3.0);
  const GnssPrior five = ParseGnssPrior("--gnss", "-33.9,151.2,10,2,6");
  EXPECT_DOUBLE_EQ(five.horizontal_accuracy_m, 2.0);
  EXPECT_DOUBLE_EQ(five.vertical_accuracy_m, 6.0);
}

TEST(GnssPrior, BadTextIsAnErrorNamingTheFlagAndTheField) {
  EXPECT_NE(ErrorOf("47.3,8.5,400").find("give LAT,LON,ALT,SIGMA"), std::string::npos);
  EXPECT_NE(ErrorOf("47.3,8.5,400,1,2,3").find("give LAT,LON,ALT,SIGMA"), std::string::npos);
  EXPECT_NE(ErrorOf("47.3,east,400,1").find("--gnss"), std::string::npos);
  EXPECT_NE(ErrorOf("95,8.5,400,1").find("--gnss"), std::string::npos);
  EXPECT_NE(ErrorOf("47.3,8.5,400,0").find("--gnss.horizontal_accuracy_m"), std::string::npos);
  EXPECT_NE(ErrorOf("47.3,8.5,400,1,-2").find("--gnss.vertical_accuracy_m"), std::string::npos);
  EXPECT_NE(ErrorOf("47.3,8.5,400,20000").find("outside (0,"), std::string::npos);
  EXPECT_NE(ErrorOf("47.3,8.5,400,nan").find("--gnss"), std::string::npos);
}

TEST(GnssPrior, TheSearchRadiusIsThreeSigmasOfTheFixAndTheAnchorCombined) {
  GnssPrior prior;
  prior.horizontal_accuracy_m = 3.0;
  prior.vertical_accuracy_m = 4.0;
  GeoAnchor anchor;
  EXPECT_DOUBLE_EQ(GnssSearchRadiusM(prior, anchor), 15.0);
  anchor.horizontal_sigma_m = 12.0;
  EXPECT_DOUBLE_EQ(GnssSearchRadiusM(prior, anchor), 39.0);
}

}  // namespace
}  // namespace evloc
