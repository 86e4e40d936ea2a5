#include "ros/localizer_node.h"

#include <cmath>
#include <exception>
#include <limits>
#include <utility>

#include "core/common/error.h"

namespace evloc::ros_node {
namespace {

std::string StringParam(const ros::NodeHandle& node, const std::string& name,
                        const std::string& fallback) {
  std::string value = fallback;
  if (node.hasParam(name) && !node.getParam(name, value)) {
    throw InvalidArgumentError("parameter ~" + name + " must be a string");
  }
  return value;
}

double NumberParam(const ros::NodeHandle& node, const std::string& name, double fallback) {
  if (!node.hasParam(name)) return fallback;
  double value = 0;
  if (node.getParam(name, value)) return value;
  int integer = 0;
  if (node.getParam(name, integer)) return integer;
  throw InvalidArgumentError("parameter ~" + name + " must be a number");
}

bool BoolParam(const ros::NodeHandle& node, const std::string& name, bool fallback) {
  if (!node.hasParam(name)) return fallback;
  bool value = fallback;
  if (!node.getParam(name, value)) {
    throw InvalidArgumentError("parameter ~" + name + " must be true or false");
  }
  return value;
}

}  // namespace

void ReadNodeParameters(const ros::NodeHandle& private_node, NodeCoreOptions* core,
                        NodeRosOptions* ros_options) {
  core->map_path = StringParam(private_node, "map", core->map_path);
  core->calib_path = StringParam(private_node, "calib", core->calib_path);
  core->init_pose = StringParam(private_node, "init_pose", core->init_pose);
  core->init_stamp = StringParam(private_node, "init_stamp", core->init_stamp);
  core->step_rate_hz = NumberParam(private_node, "rate", core->step_rate_hz);
  core->buffer_s = NumberParam(private_node, "buffer_s", core->buffer_s);
  core->max_gap_s = NumberParam(private_node, "max_gap_s", core->max_gap_s);
  const double max_pixels =
      NumberParam(private_node, "max_camera_pixels", static_cast<double>(core->max_camera_pixels));
  if (max_pixels != std::floor(max_pixels) || max_pixels < 1 || max_pixels > 1e9) {
    throw InvalidArgumentError("parameter ~max_camera_pixels must be a whole number in 1..1e9");
  }
  core->max_camera_pixels = static_cast<int64_t>(max_pixels);
  core->server = StringParam(private_node, "server", core->server);
  core->map_name = StringParam(private_node, "map_name", core->map_name);
  core->token_file = StringParam(private_node, "token_file", core->token_file);
  core->tls_ca = StringParam(private_node, "tls_ca", core->tls_ca);
  core->thin_while_searching =
      BoolParam(private_node, "thin_while_searching", core->thin_while_searching);
  ros_options->map_frame = StringParam(private_node, "map_frame", ros_options->map_frame);
  ros_options->camera_frame = StringParam(private_node, "camera_frame", ros_options->camera_frame);
  if (ros_options->map_frame.empty() || ros_options->camera_frame.empty() ||
      ros_options->map_frame == ros_options->camera_frame) {
    throw InvalidArgumentError("parameters ~map_frame and ~camera_frame must be two names");
  }
  ros_options->publish_tf = BoolParam(private_node, "publish_tf", ros_options->publish_tf);
  const double queue_size = NumberParam(private_node, "queue_size", ros_options->queue_size);
  if (queue_size != std::floor(queue_size) || queue_size < 0 || queue_size > 1e7) {
    throw InvalidArgumentError("parameter ~queue_size must be a whole number in 0..10000000");
  }
  ros_options->queue_size = static_cast<int>(queue_size);
}

int64_t ToNanoseconds(const ros::Time& time) {
  return static_cast<int64_t>(time.sec) * 1000000000 + time.nsec;
}

ros::Time ToRosTime(int64_t t_ns) {
  if (t_ns < 0 || t_ns / 1000000000 > std::numeric_limits<uint32_t>::max()) {
    throw InvalidArgumentError("time " + std::to_string(t_ns) +
                               " ns is outside what a ROS time holds (0 to 2106)");
  }
  return ros::Time(static_cast<uint32_t>(t_ns / 1000000000),
                   static_cast<uint32_t>(t_ns % 1000000000));
}

EventColumns ToColumns(const dvs_msgs::EventArray& message) {
  EventColumns columns;
  const size_t count = message.events.size();
  columns.t_ns.resize(count);
  columns.x.resize(count);
  columns.y.resize(count);
  columns.polarity.resize(count);
  for (size_t i = 0; i < count; ++i) {
    const dvs_msgs::Event& event = message.events[i];
    columns.t_ns[i] = ToNanoseconds(event.ts);
    columns.x[i] = event.x;
    columns.y[i] = event.y;
    columns.polarity[i] = event.polarity ? 1 : -1;
  }
  return columns;
}

CameraInfoFields ToFields(const sensor_msgs::CameraInfo& message) {
  CameraInfoFields fields;
  fields.width = message.width;
  fields.height = message.height;
  fields.distortion_model = message.distortion_model;
  fields.d = message.D;
  for (size_t i = 0; i < fields.k.size(); ++i) fields.k[i] = message.K[i];
  return fields;
}

PoseFields ToFields(const geometry_msgs::Pose& pose) {
  PoseFields fields;
  fields.position = {pose.position.x, pose.position.y, pose.position.z};
  fields.orientation = {pose.orientation.x, pose.orientation.y, pose.orientation.z,
                        pose.orientation.w};
  return fields;
}

geometry_msgs::PoseWithCovarianceStamped ToPoseMessage(const StepOutput& step,
                                                       const std::string& map_frame) {
  geometry_msgs::PoseWithCovarianceStamped message;
  message.header.stamp = ToRosTime(step.t_ns);
  message.header.frame_id = map_frame;
  message.pose.pose.position.x = step.pose.position[0];
  message.pose.pose.position.y = step.pose.position[1];
  message.pose.pose.position.z = step.pose.position[2];
  message.pose.pose.orientation.x = step.pose.orientation[0];
  message.pose.pose.orientation.y = step.pose.orientation[1];
  message.pose.pose.orientation.z = step.pose.orientation[2];
  message.pose.pose.orientation.w = step.pose.orientation[3];
  for (size_t i = 0; i < step.covariance.size(); ++i) {
    message.pose.covariance[i] = step.covariance[i];
  }
  return message;
}

geometry_msgs::TransformStamped ToTransform(const StepOutput& step, const std::string& map_frame,
                                            const std::string& camera_frame) {
  geometry_msgs::TransformStamped transform;
  transform.header.stamp = ToRosTime(step.t_ns);
  transform.header.frame_id = map_frame;
  transform.child_frame_id = camera_frame;
  transform.transform.translation.x = step.pose.position[0];
  transform.transform.translation.y = step.pose.position[1];
  transform.transform.translation.z = step.pose.position[2];
  transform.transform.rotation.x = step.pose.orientation[0];
  transform.transform.rotation.y = step.pose.orientation[1];
  transform.transform.rotation.z = step.pose.orientation[2];
  transform.transform.rotation.w = step.pose.orientation[3];
  return transform;
}

LocalizerNode::LocalizerNode(ros::NodeHandle& node, const NodeCoreOptions& core_options,
                             const NodeRosOptions& options)
    : options_(options),
      core_(
          core_options,
          // Service mode: the server's steps arrive on the stream's reader thread (publishing is
          // thread-safe in roscpp).
          [this](const StepOutput& step) { PublishStep(step, std::nullopt); },
          [](const std::string& error) {
            if (error.empty()) {
              ROS_INFO("evloc: the localizer server ended the session");
            } else {
              ROS_ERROR("evloc: the localizer server ended the session: %s", error.c_str());
            }
          }) {
  pose_publisher_ = node.advertise<geometry_msgs::PoseWithCovarianceStamped>("pose", 1000);
  status_publisher_ = node.advertise<evloc_msgs::TrackingStatus>("status", 1000, true);
  if (options_.publish_tf) tf_broadcaster_ = std::make_unique<tf2_ros::TransformBroadcaster>();
  // TCP_NODELAY: a message's poses should not wait for Nagle's algorithm.
  const ros::TransportHints hints = ros::TransportHints().tcpNoDelay();
  const auto queue = static_cast<uint32_t>(options_.queue_size);
  events_subscriber_ = node.subscribe("events", queue, &LocalizerNode::OnEventArray, this, hints);
  packets_subscriber_ =
      node.subscribe("event_packets", queue, &LocalizerNode::OnEventPacket, this, hints);
  if (!core_.has_camera()) {
    camera_info_subscriber_ = node.subscribe("camera_info", 10, &LocalizerNode::OnCameraInfo, this);
  }
  initial_pose_subscriber_ = node.subscribe("initialpose", 10, &LocalizerNode::OnInitialPose, this);
  if (!core_options.server.empty()) {
    flow_timer_ =
        node.createSteadyTimer(ros::WallDuration(0.005), [this](const ros::SteadyTimerEvent&) {
          try {
            core_.Poll();
          } catch (const std::exception& error) {
            ROS_ERROR_THROTTLE(1.0, "evloc: sending to the localizer server failed: %s",
                               error.what());
          }
        });
  }
  for (const std::string& note : core_.calibration_notes()) {
    ROS_INFO("evloc: ~calib note: %s", note.c_str());
  }
  ROS_INFO("evloc: map %s; camera %s; first pose from %s", core_.map_description().c_str(),
           core_.has_camera() ? core_.camera_description().c_str() : "from camera_info",
           core_.initial_pose_mode() == InitialPoseMode::kParameter ? "~init_pose"
           : core_.initial_pose_mode() == InitialPoseMode::kSearch  ? "a search of the map"
                                                                    : "the initialpose topic");
  PublishWaiting();
}

void LocalizerNode::OnEventArray(const dvs_msgs::EventArray::ConstPtr& message) {
  const Clock::time_point arrival = Clock::now();
  std::vector<StepOutput> steps;
  try {
    steps = core_.AddEventArray(message->width, message->height, ToColumns(*message));
  } catch (const std::exception& error) {
    ROS_ERROR_THROTTLE(1.0, "evloc: rejected a dvs_msgs/EventArray on %s: %s",
                       events_subscriber_.getTopic().c_str(), error.what());
    return;
  }
  if (steps.empty() && !core_.waiting_for().empty()) PublishWaiting();
  Publish(steps, arrival);
}

void LocalizerNode::OnEventPacket(const event_camera_msgs::EventPacket::ConstPtr& message) {
  const Clock::time_point arrival = Clock::now();
  std::vector<StepOutput> steps;
  try {
    steps = core_.AddEventPacket(
        message->width, message->height, ToNanoseconds(message->header.stamp), message->encoding,
        message->is_bigendian != 0, message->events.data(), message->events.size());
  } catch (const std::exception& error) {
    ROS_ERROR_THROTTLE(1.0, "evloc: rejected an event_camera_msgs/EventPacket on %s: %s",
                       packets_subscriber_.getTopic().c_str(), error.what());
    return;
  }
  if (steps.empty() && !core_.waiting_for().empty()) PublishWaiting();
  Publish(steps, arrival);
}

void LocalizerNode::OnCameraInfo(const sensor_msgs::CameraInfo::ConstPtr& message) {
  const Clock::time_point arrival = Clock::now();
  std::vector<StepOutput> steps;
  try {
    if (!core_.SetCameraInfo(ToFields(*message), &steps)) return;
  } catch (const std::exception& error) {
    ROS_ERROR_THROTTLE(5.0,
                       "evloc: %s (sensor_msgs/CameraInfo): %s (fix the calibration, or "
                       "give ~calib)",
                       camera_info_subscriber_.getTopic().c_str(), error.what());
    return;
  }
  ROS_INFO("evloc: camera %s from %s", core_.camera_description().c_str(),
           camera_info_subscriber_.getTopic().c_str());
  camera_info_subscriber_.shutdown();
  Publish(steps, arrival);
}

void LocalizerNode::OnInitialPose(
    const geometry_msgs::PoseWithCovarianceStamped::ConstPtr& message) {
  const Clock::time_point arrival = Clock::now();
  std::vector<StepOutput> steps;
  try {
    core_.SetPoseHint(ToFields(message->pose.pose), ToNanoseconds(message->header.stamp), &steps);
  } catch (const std::exception& error) {
    ROS_ERROR("evloc: ignored a pose on %s: %s", initial_pose_subscriber_.getTopic().c_str(),
              error.what());
    return;
  }
  ROS_INFO("evloc: pose hint from %s", initial_pose_subscriber_.getTopic().c_str());
  Publish(steps, arrival);
}

void LocalizerNode::Publish(const std::vector<StepOutput>& steps, Clock::time_point arrival) {
  if (core_.counters().restarts != restarts_logged_) {
    restarts_logged_ = core_.counters().restarts;
    ROS_WARN(
        "evloc: the events jumped forward more than ~max_gap_s: tracking (re)started at the "
        "new events from the last good pose (%llu times so far)",
        static_cast<unsigned long long>(restarts_logged_));
  }
  for (const StepOutput& step : steps) PublishStep(step, arrival);
}

void LocalizerNode::PublishStep(const StepOutput& step,
                                const std::optional<Clock::time_point>& arrival) {
  pose_publisher_.publish(ToPoseMessage(step, options_.map_frame));
  if (tf_broadcaster_ && step.tracking) {
    tf_broadcaster_->sendTransform(ToTransform(step, options_.map_frame, options_.camera_frame));
  }
  evloc_msgs::TrackingStatus status;
  status.header.stamp = ToRosTime(step.t_ns);
  status.header.frame_id = options_.camera_frame;
  status.status = step.status;
  status.alignment = step.alignment;
  status.on_edge_fraction = step.on_edge_fraction;
  status.points_used = step.points_used;
  status.step_ms = step.step_ms;
  // In-process: from the message's arrival; from a server the message is not known (-1).
  status.latency_ms =
      arrival ? std::chrono::duration<double, std::milli>(Clock::now() - *arrival).count() : -1;
  if (arrival) {
    // The counters belong to the spinning thread: a server's step (on the stream's thread)
    // leaves them 0.
    status.events = core_.counters().events;
    status.dropped_events = core_.counters().decoder_dropped_events;
  }
  status_publisher_.publish(status);
}

void LocalizerNode::PublishWaiting() {
  evloc_msgs::TrackingStatus status;
  status.header.stamp = ros::Time::now();
  status.header.frame_id = options_.camera_frame;
  status.status = "WAITING";
  status.events = core_.counters().events;
  status.dropped_events = core_.counters().decoder_dropped_events;
  status_publisher_.publish(status);
  ROS_INFO_THROTTLE(5.0, "evloc: waiting for %s", core_.waiting_for().c_str());
}

}  // namespace evloc::ros_node
