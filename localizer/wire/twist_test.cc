#include "localizer/wire/twist.h"

#include <cmath>
#include <limits>

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::wire {
namespace {

TEST(Twist, RoundTripsThroughTheMessage) {
  Vector6d twist;
  twist << 0.5, -1.25, 3.0, 0.1, -0.2, 0.3;
  const Vector6d back = TwistFromProto(TwistToProto(twist), "t");
  EXPECT_EQ(back, twist);
}

TEST(Twist, RefusesMissingPartsNonFiniteAndExcessiveValues) {
  api::Twist twist = TwistToProto(Vector6d::Zero());
  twist.clear_angular();
  EXPECT_THROW(TwistFromProto(twist, "t"), InvalidArgumentError);

  twist = TwistToProto(Vector6d::Zero());
  twist.mutable_linear()->set_y(std::numeric_limits<double>::quiet_NaN());
  EXPECT_THROW(TwistFromProto(twist, "t"), InvalidArgumentError);

  twist = TwistToProto(Vector6d::Zero());
  twist.mutable_angular()->set_z(std::numeric_limits<double>::infinity());
  EXPECT_THROW(TwistFromProto(twist, "t"), InvalidArgumentError);

  twist = TwistToProto(Vector6d::Zero());
  twist.mutable_linear()->set_x(kMaxTwistLinear * 1.001);
  try {
    TwistFromProto(twist, "SessionStart.initial_velocity");
    FAIL() << "a linear speed beyond the bound was accepted";
  } catch (const InvalidArgumentError& error) {
    EXPECT_NE(std::string(error.what()).find("SessionStart.initial_velocity.linear"),
              std::string::npos)
        << error.what();
  }
  twist = TwistToProto(Vector6d::Zero());
  twist.mutable_angular()->set_x(kMaxTwistAngular * 1.001);
  EXPECT_THROW(TwistFromProto(twist, "t"), InvalidArgumentError);

  // At the bounds: accepted.
  twist = TwistToProto(Vector6d::Zero());
  twist.mutable_linear()->set_x(kMaxTwistLinear);
  twist.mutable_angular()->set_y(-kMaxTwistAngular);
  EXPECT_NO_THROW(TwistFromProto(twist, "t"));
}

}  // namespace
}  // namespace evloc::wire
