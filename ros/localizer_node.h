// evloc_ros_node's ROS side (docs/ros.md): subscribes to events (dvs_msgs/EventArray on `events`,
// event_camera_msgs/EventPacket on `event_packets`), the camera (sensor_msgs/CameraInfo on
// `camera_info`, unless ~calib names a file) and pose hints
// (geometry_msgs/PoseWithCovarianceStamped on `initialpose`); hands them to NodeCore, which tracks
// in-process; publishes each step as geometry_msgs/PoseWithCovarianceStamped on `pose`, the TF
// transform ~map_frame -> ~camera_frame, and evloc_msgs/TrackingStatus on `status`. Built as
// C++17 with Debian's ROS 1 headers and the message headers gencpp generates from ros/msg.
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <dvs_msgs/EventArray.h>
#include <event_camera_msgs/EventPacket.h>
#include <evloc_msgs/TrackingStatus.h>
#include <geometry_msgs/PoseWithCovarianceStamped.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <tf2_ros/transform_broadcaster.h>

#include "ros/node_core.h"

namespace evloc::ros_node {

// The ROS side's own parameters.
struct NodeRosOptions {
  // Frame of the map (~map_frame) and of the camera (~camera_frame).
  std::string map_frame = "map";
  std::string camera_frame = "camera";
  // Broadcast the TF transform map_frame -> camera_frame at every TRACKING step (~publish_tf).
  bool publish_tf = true;
  // Subscriber queue length of the event topics (~queue_size; 0: unbounded, so that a bag played
  // faster than tracking loses nothing).
  int queue_size = 0;
};

// Reads every private parameter. Throws InvalidArgumentError naming a parameter of the wrong type
// or out of range.
void ReadNodeParameters(const ros::NodeHandle& private_node, NodeCoreOptions* core,
                        NodeRosOptions* ros_options);

// A ROS time in nanoseconds.
int64_t ToNanoseconds(const ros::Time& time);
// Nanoseconds as a ROS time. Throws InvalidArgumentError outside 0 .. 2106.
ros::Time ToRosTime(int64_t t_ns);

// The plain fields of the messages (for NodeCore) and the messages of its steps.
EventColumns ToColumns(const dvs_msgs::EventArray& message);
CameraInfoFields ToFields(const sensor_msgs::CameraInfo& message);
PoseFields ToFields(const geometry_msgs::Pose& pose);
geometry_msgs::PoseWithCovarianceStamped ToPoseMessage(const StepOutput& step,
                                                       const std::string& map_frame);
geometry_msgs::TransformStamped ToTransform(const StepOutput& step, const std::string& map_frame,
                                            const std::string& camera_frame);

// The node. Its callbacks run on the thread that spins ros, one at a time.
class LocalizerNode {
 public:
  // Loads the map (NodeCore), advertises and subscribes. Throws what NodeCore throws.
  LocalizerNode(ros::NodeHandle& node, const NodeCoreOptions& core_options,
                const NodeRosOptions& options);

  const NodeCounters& counters() const { return core_.counters(); }

 private:
  using Clock = std::chrono::steady_clock;

  void OnEventArray(const dvs_msgs::EventArray::ConstPtr& message);
  void OnEventPacket(const event_camera_msgs::EventPacket::ConstPtr& message);
  void OnCameraInfo(const sensor_msgs::CameraInfo::ConstPtr& message);
  void OnInitialPose(const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& message);
  // Publishes the steps made due by a message that arrived at `arrival`.
  void Publish(const std::vector<StepOutput>& steps, Clock::time_point arrival);
  // Publishes one step: pose, TF (TRACKING), status (latency from `arrival` when known).
  void PublishStep(const StepOutput& step, const std::optional<Clock::time_point>& arrival);
  void PublishWaiting();

  NodeRosOptions options_;
  // Declared before core_: the publishers must exist when the server's first step arrives, and
  // outlive core_, whose destructor ends the stream and joins its reader.
  ros::Publisher pose_publisher_;
  ros::Publisher status_publisher_;
  std::unique_ptr<tf2_ros::TransformBroadcaster> tf_broadcaster_;
  NodeCore core_;
  ros::Subscriber events_subscriber_;
  ros::Subscriber packets_subscriber_;
  ros::Subscriber camera_info_subscriber_;
  ros::Subscriber initial_pose_subscriber_;
  // Service mode: sends the events held back while the server was behind (every 5 ms).
  ros::SteadyTimer flow_timer_;
  // Restarts already logged.
  uint64_t restarts_logged_ = 0;
};

}  // namespace evloc::ros_node
