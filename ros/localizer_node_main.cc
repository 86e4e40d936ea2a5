// evloc_ros_node: the ROS 1 node of evloc (docs/ros.md).
#include <iostream>

#include <ros/ros.h>

#include "core/common/cli.h"
#include "ros/localizer_node.h"

int main(int argc, char** argv) {
  // ros::init takes the remappings (events:=/dvs/events) and the __name, __ns arguments.
  ros::init(argc, argv, "evloc");
  return evloc::RunGuarded("evloc_ros_node", std::cerr, [] {
    ros::NodeHandle node;
    ros::NodeHandle private_node("~");
    evloc::ros_node::NodeCoreOptions core_options;
    evloc::ros_node::NodeRosOptions ros_options;
    evloc::ros_node::ReadNodeParameters(private_node, &core_options, &ros_options);
    evloc::ros_node::LocalizerNode localizer(node, core_options, ros_options);
    ros::spin();
    const evloc::ros_node::NodeCounters& counters = localizer.counters();
    ROS_INFO("evloc: %llu event messages (%llu rejected), %llu events, %llu steps",
             static_cast<unsigned long long>(counters.messages),
             static_cast<unsigned long long>(counters.rejected_messages),
             static_cast<unsigned long long>(counters.events),
             static_cast<unsigned long long>(counters.steps));
    return 0;
  });
}
