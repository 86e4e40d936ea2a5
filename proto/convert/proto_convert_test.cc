#include "proto/convert/proto_convert.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "core/common/error.h"

namespace evloc {
namespace {

map_format::Camera RadTanProto() {
  map_format::Camera camera;
  camera.set_model(map_format::CAMERA_MODEL_RADIAL_TANGENTIAL);
  camera.set_width(640);
  camera.set_height(480);
  camera.set_fx(500);
  camera.set_fy(501);
  camera.set_cx(319.5);
  camera.set_cy(239.5);
  for (double value : {-0.1, 0.01, 0.001, -0.002, 0.0003}) camera.add_distortion(value);
  return camera;
}

// The message of the InvalidArgumentError that `function` throws; "" when it throws none.
template <typename Function>
std::string InvalidArgumentMessage(Function function) {
  try {
    function();
  } catch (const InvalidArgumentError& error) {
    return error.what();
  }
  return "";
}

// Expects `function` to throw InvalidArgumentError whose message contains every fragment.
template <typename Function>
void ExpectInvalid(Function function, std::initializer_list<std::string> fragments) {
  const std::string message = InvalidArgumentMessage(function);
  EXPECT_FALSE(message.empty()) << "no InvalidArgumentError";
  for (const std::string& fragment : fragments) {
    EXPECT_NE(message.find(fragment), std::string::npos) << message << " lacks " << fragment;
  }
}

TEST(ProtoConvert, CameraRoundTripsBitExact) {
  const map_format::Camera proto = RadTanProto();
  const Camera camera = CameraFromProto(proto, "camera");
  EXPECT_EQ(camera.model, CameraModel::kRadialTangential);
  EXPECT_EQ(camera.width, 640);
  EXPECT_EQ(camera.height, 480);
  EXPECT_EQ(camera.fy, 501);
  EXPECT_EQ(camera.distortion, (std::vector<double>{-0.1, 0.01, 0.001, -0.002, 0.0003}));
  EXPECT_EQ(CameraToProto(camera).SerializeAsString(), proto.SerializeAsString());
}

TEST(ProtoConvert, FourCoefficientRadialTangentialGetsZeroK3) {
  map_format::Camera proto = RadTanProto();
  proto.mutable_distortion()->RemoveLast();
  const Camera camera = CameraFromProto(proto, "camera");
  EXPECT_EQ(camera.distortion, (std::vector<double>{-0.1, 0.01, 0.001, -0.002, 0.0}));
  // Only radial-tangential is padded: an equidistant camera with 3 coefficients is refused.
  map_format::Camera fisheye = RadTanProto();
  fisheye.set_model(map_format::CAMERA_MODEL_EQUIDISTANT);
  fisheye.mutable_distortion()->RemoveLast();
  fisheye.mutable_distortion()->RemoveLast();
  ExpectInvalid([&] { CameraFromProto(fisheye, "SessionStart.camera"); },
                {"SessionStart.camera: ", "takes 4 distortion coefficients, got 3"});
}

TEST(ProtoConvert, InvalidCamerasNameTheProblem) {
  map_format::Camera proto = RadTanProto();
  proto.set_model(map_format::CAMERA_MODEL_UNSPECIFIED);
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"cam.model is not set", "code 0"});
  proto.set_model(static_cast<map_format::CameraModel>(9));
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"cam.model", "code 9"});
  proto = RadTanProto();
  proto.set_width(0);
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"cam: width and height", "0x480"});
  proto = RadTanProto();
  proto.set_height(65536);
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"640x65536"});
  proto = RadTanProto();
  proto.set_fx(-1);
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"cam: camera focal lengths"});
  proto = RadTanProto();
  proto.set_cy(std::numeric_limits<double>::quiet_NaN());
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"cam: camera cy is not finite"});
  proto = RadTanProto();
  proto.add_distortion(0.0);
  ExpectInvalid([&] { CameraFromProto(proto, "cam"); }, {"takes 5 distortion coefficients, got 6"});
}

map_format::Rigid3 PoseProto(double w, double x, double y, double z) {
  map_format::Rigid3 pose;
  pose.mutable_rotation()->set_w(w);
  pose.mutable_rotation()->set_x(x);
  pose.mutable_rotation()->set_y(y);
  pose.mutable_rotation()->set_z(z);
  pose.mutable_translation()->set_x(1.5);
  pose.mutable_translation()->set_y(-2.25);
  pose.mutable_translation()->set_z(3.125);
  return pose;
}

TEST(ProtoConvert, RigidIsNormalisedOrKeptBitForBit) {
  // Norm 1.0005: inside the tolerance.
  const double scale = 1.0005 / std::sqrt(0.5 * 0.5 * 4);
  const map_format::Rigid3 proto = PoseProto(0.5 * scale, 0.5 * scale, -0.5 * scale, 0.5 * scale);
  const Rigid3d normalised = RigidFromProto(proto, "pose");
  EXPECT_NEAR(normalised.rotation.norm(), 1.0, 1e-15);
  EXPECT_NEAR(normalised.rotation.w(), 0.5, 1e-15);
  EXPECT_EQ(normalised.translation, Eigen::Vector3d(1.5, -2.25, 3.125));
  const Rigid3d exact = RigidFromProtoExact(proto, "pose");
  EXPECT_EQ(exact.rotation.w(), proto.rotation().w());
  EXPECT_EQ(exact.rotation.z(), proto.rotation().z());
  EXPECT_EQ(RigidToProto(exact).SerializeAsString(), proto.SerializeAsString());
}

TEST(ProtoConvert, RigidChecksAreTheSameForBothConversions) {
  for (const auto convert : {&RigidFromProto, &RigidFromProtoExact}) {
    ExpectInvalid([&] { convert(PoseProto(2, 0, 0, 0), "PoseHint.world_from_cam"); },
                  {"PoseHint.world_from_cam: the rotation must be a unit quaternion"});
    ExpectInvalid([&] { convert(PoseProto(1.002, 0, 0, 0), "p"); }, {"unit quaternion"});
    ExpectInvalid([&] { convert(PoseProto(0, 0, 0, 0), "p"); }, {"unit quaternion"});
    map_format::Rigid3 infinite = PoseProto(1, 0, 0, 0);
    infinite.mutable_translation()->set_y(std::numeric_limits<double>::infinity());
    ExpectInvalid([&] { convert(infinite, "p"); }, {"p: the pose has a non-finite value"});
    EXPECT_NO_THROW(convert(PoseProto(1.0009, 0, 0, 0), "p"));
  }
}

}  // namespace
}  // namespace evloc
