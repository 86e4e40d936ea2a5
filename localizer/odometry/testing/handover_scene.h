// A synthetic scene for the hand-over tests (map tracking -> Canny-DEVO -> map tracking): painted
// rectangles in front of the camera (the mapped part) and others to its right (not in the map),
// a camera that turns to the right, stays there and turns back, ideal edge events of every
// rectangle, and the depth frames of a separate depth camera (the rectangles' planes).
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/events/event.h"
#include "core/geometry/rigid3.h"
#include "localizer/tracking/testing/synthetic_scene.h"
#include "maps/map.h"

namespace evloc::odometry::testing {

// The path: on the map until kLeaveNs, turning right by kTurnDeg until kAwayNs, away until
// kReturnNs, turning back until kBackNs, on the map until kEndNs.
inline constexpr int64_t kLeaveNs = 300'000'000;
inline constexpr int64_t kAwayNs = 1'200'000'000;
inline constexpr int64_t kReturnNs = 1'700'000'000;
inline constexpr int64_t kBackNs = 2'600'000'000;
inline constexpr int64_t kEndNs = 3'000'000'000;
inline constexpr double kTurnDeg = 55.0;
// The tracked part starts here (earlier events prime the time surfaces), ns.
inline constexpr int64_t kStartNs = 20'000'000;

// The rectangles in the map (ahead at the start).
std::vector<tracking::testing::Rectangle> MappedRectangles();
// The rectangles to the right, seen while away (not in the map).
std::vector<tracking::testing::Rectangle> AwayRectangles();
// The map: the outlines of MappedRectangles() every centimetre.
Map HandoverMap();
// The event camera: 320x240 pinhole, f = 250.
Camera HandoverEventCamera();
// The depth camera: 240x180 pinhole, f = 190.
Camera HandoverDepthCamera();
// p_event = event_from_depth * p_depth: 4 cm to the right, turned by 2 degrees.
Rigid3d HandoverEventFromDepth();
// world_from_cam of the event camera at t_ns.
Rigid3d HandoverMotion(int64_t t_ns);
// Ideal edge events of every rectangle over [0, kEndNs].
EventBuffer HandoverEvents();
// The depth camera's frame at t_ns (CV_32FC1 metres, 0 = none): every rectangle painted on a
// plane 0.2 m wider on every side, quantised to millimetres.
cv::Mat HandoverDepthFrame(int64_t t_ns);
// The depth frame times: 30 Hz from 10 ms.
std::vector<int64_t> HandoverDepthTimes();

// Writes the scene as a dataset folder root/dataset (calib.yaml, events.evb, groundtruth.txt,
// the depth camera: depth_camchain.yaml, depth_camera.txt) and the map as root/map/map.evmap;
// returns root/dataset.
std::filesystem::path WriteHandoverDataset(const std::filesystem::path& root);

}  // namespace evloc::odometry::testing
