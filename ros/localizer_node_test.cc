// The ROS side of the node (C++17, Debian's ROS 1 headers): the headers generated from ros/msg
// carry the upstream packages' MD5 sums (roscpp refuses a publisher whose sum differs), and the
// messages convert to NodeCore's fields and back.
#include "ros/localizer_node.h"

#include <gtest/gtest.h>

#include "core/common/error.h"

namespace evloc::ros_node {
namespace {

TEST(RosMessages, GeneratedHeadersCarryTheUpstreamMd5Sums) {
  // rpg_dvs_ros' dvs_msgs/EventArray and event_camera_msgs/EventPacket (ROS 1), as their drivers
  // publish and their bags record.
  EXPECT_STREQ(ros::message_traits::MD5Sum<dvs_msgs::EventArray>::value(),
               "5e8beee5a6c107e504c2e78903c224b8");
  EXPECT_STREQ(ros::message_traits::MD5Sum<event_camera_msgs::EventPacket>::value(),
               "8a6101b351a64529ac77bd8b71074e52");
  EXPECT_STREQ(ros::message_traits::DataType<evloc_msgs::TrackingStatus>::value(),
               "evloc_msgs/TrackingStatus");
}

TEST(RosMessages, EventArraysBecomeColumns) {
  dvs_msgs::EventArray message;
  message.events.resize(2);
  message.events[0].ts = ros::Time(10, 5);
  message.events[0].x = 3;
  message.events[0].y = 4;
  message.events[0].polarity = true;
  message.events[1].ts = ros::Time(4294967295u, 999999999);
  const EventColumns columns = ToColumns(message);
  ASSERT_EQ(columns.t_ns.size(), 2u);
  EXPECT_EQ(columns.t_ns[0], 10000000005);
  EXPECT_EQ(columns.x[0], 3);
  EXPECT_EQ(columns.y[0], 4);
  EXPECT_EQ(columns.polarity[0], 1);
  EXPECT_EQ(columns.t_ns[1], 4294967295999999999);
  EXPECT_EQ(columns.polarity[1], -1);
}

TEST(RosMessages, StepsBecomePoseTransformAndTimes) {
  StepOutput step;
  step.t_ns = 1700000000123456789;
  step.pose.position = {1, 2, 3};
  step.pose.orientation = {0, 0, 0.6, 0.8};
  for (size_t i = 0; i < step.covariance.size(); ++i) step.covariance[i] = static_cast<double>(i);
  const auto pose = ToPoseMessage(step, "map");
  EXPECT_EQ(pose.header.frame_id, "map");
  EXPECT_EQ(pose.header.stamp.sec, 1700000000u);
  EXPECT_EQ(pose.header.stamp.nsec, 123456789u);
  EXPECT_EQ(pose.pose.pose.position.y, 2.0);
  EXPECT_EQ(pose.pose.pose.orientation.z, 0.6);
  EXPECT_EQ(pose.pose.covariance[35], 35.0);
  const auto transform = ToTransform(step, "map", "dvs");
  EXPECT_EQ(transform.child_frame_id, "dvs");
  EXPECT_EQ(transform.transform.rotation.w, 0.8);
  EXPECT_THROW(ToRosTime(-1), InvalidArgumentError);
  EXPECT_THROW(ToRosTime(int64_t{5000000000} * 1000000000), InvalidArgumentError);
  sensor_msgs::CameraInfo info;
  info.width = 240;
  info.distortion_model = "plumb_bob";
  info.D = {1, 2, 3, 4, 5};
  info.K[4] = 7;
  const CameraInfoFields fields = ToFields(info);
  EXPECT_EQ(fields.width, 240u);
  EXPECT_EQ(fields.d.size(), 5u);
  EXPECT_EQ(fields.k[4], 7.0);
}

}  // namespace
}  // namespace evloc::ros_node
