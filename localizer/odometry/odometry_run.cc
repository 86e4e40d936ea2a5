#include "localizer/odometry/odometry_run.h"

#include <algorithm>
#include <chrono>
#include <memory>
#include <string>

#include "core/common/error.h"
#include "core/dataset/tum_rgbd.h"
#include "core/events/event_reader.h"
#include "localizer/odometry/devo_reference_map.h"

namespace evloc::odometry {

const char* OdometryModeName(OdometryMode mode) {
  switch (mode) {
    case OdometryMode::kVo:
      return "vo";
    case OdometryMode::kDevo:
      return "devo";
  }
  return "unknown";
}

void VoRunOptions::Check() const {
  vo.Check();
  if (association_tolerance_ns < 0) {
    throw InvalidArgumentError("VoRunOptions: association_tolerance_ns must be >= 0");
  }
}

Rigid3d OdometryStartPose(const Dataset& dataset, const std::optional<Rigid3d>& given,
                          int64_t t_ns) {
  if (given) return *given;
  if (dataset.ground_truth) {
    if (const std::optional<Rigid3d> pose = dataset.ground_truth->Lookup(t_ns)) return *pose;
  }
  throw InvalidArgumentError("dataset '" + dataset.root.string() +
                             "' has no ground truth at the odometry's first frame (" +
                             std::to_string(static_cast<double>(t_ns) * 1e-9) +
                             " s): give the start pose with --init-pose");
}

VoRunResult RunCannyVo(const Dataset& dataset, const std::optional<Rigid3d>& initial_world_from_cam,
                       int64_t initial_t_ns, const VoRunOptions& options,
                       const std::function<void(const VoEstimate&)>& on_step) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  // A depth camera of its own is preferred to depth.txt (a simulator's depth registered to the
  // frames: exact); its frames are registered to the frame camera, which is the dataset's camera.
  const bool own_depth_camera = options.use_depth_camera && dataset.depth_camera.has_value() &&
                                !dataset.depth_camera->frames.empty();
  const std::vector<TimedFile>& depth_files =
      own_depth_camera ? dataset.depth_camera->frames : dataset.depth;
  if (dataset.images.empty() || depth_files.empty()) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "' needs images and depth maps for Canny-VO (images.txt and "
                               "depth.txt or a depth camera, or rgb.txt and depth.txt in the TUM "
                               "RGB-D layout)");
  }
  const std::vector<TimeAssociation> pairs =
      AssociateByTime(dataset.images, depth_files, options.association_tolerance_ns);
  CannyVo vo(dataset.camera, options.vo);
  VoRunResult result;
  bool started = false;
  for (const TimeAssociation& pair : pairs) {
    const TimedFile& image = dataset.images[pair.first];
    if (image.t_ns < initial_t_ns) continue;
    if (!started) {
      vo.Reset(OdometryStartPose(dataset, initial_world_from_cam, image.t_ns), image.t_ns);
      started = true;
    }
    cv::Mat gray;
    ReadGrayImage(image.path).convertTo(gray, CV_8UC1, 255.0);
    const cv::Mat depth =
        own_depth_camera
            ? RegisterDepth(dataset.camera, dataset.depth_camera->camera,
                            ReadDepthPng(depth_files[pair.second].path,
                                         dataset.depth_camera->units_per_metre),
                            dataset.depth_camera->event_from_depth, ReferenceMapOptions())
            : ReadDepthPng(depth_files[pair.second].path, dataset.depth_units_per_metre);
    if (gray.cols != dataset.camera.width || gray.rows != dataset.camera.height ||
        depth.cols != dataset.camera.width || depth.rows != dataset.camera.height) {
      throw InvalidArgumentError("dataset '" + dataset.root.string() + "': image '" +
                                 image.path.string() + "' or its depth map is not of the " +
                                 std::to_string(dataset.camera.width) + "x" +
                                 std::to_string(dataset.camera.height) + " camera size");
    }
    const VoEstimate estimate = vo.AddFrame(image.t_ns, gray, depth);
    result.trajectory.Append({estimate.t_ns, estimate.world_from_cam});
    if (!estimate.tracked) ++result.untracked_frames;
    if (estimate.new_keyframe) ++result.keyframes;
    result.steps.push_back(estimate);
    if (on_step) on_step(estimate);
  }
  if (!started) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "': no image has a depth map within the association tolerance at "
                               "or after the start time");
  }
  result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

DepthCameraStream DevoDepthStream(const Dataset& dataset) {
  if (dataset.depth_camera) {
    if (dataset.depth_camera->frames.empty()) {
      throw InvalidArgumentError("dataset '" + dataset.root.string() +
                                 "': its depth camera has no frames (depth_camera.txt is empty)");
    }
    return *dataset.depth_camera;
  }
  if (dataset.depth.empty()) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "' has no depth (neither a depth camera, depth_camchain.yaml with "
                               "depth_camera.txt, nor depth.txt): Canny-DEVO needs it");
  }
  DepthCameraStream stream;
  stream.camera = dataset.camera;
  stream.frames = dataset.depth;
  stream.units_per_metre = dataset.depth_units_per_metre;
  return stream;
}

void DevoRunOptions::Check() const {
  devo.Check();
  if (warm_up_ns < 0) throw InvalidArgumentError("DevoRunOptions: warm_up_ns must be >= 0");
  if (read_batch_events < 1) {
    throw InvalidArgumentError("DevoRunOptions: read_batch_events must be >= 1");
  }
}

DevoRunResult RunCannyDevo(const Dataset& dataset,
                           const std::optional<Rigid3d>& initial_world_from_cam,
                           int64_t initial_t_ns, const DevoRunOptions& options,
                           const std::function<void(const tracking::PoseEstimate&)>& on_step) {
  options.Check();
  const auto start = std::chrono::steady_clock::now();
  const DepthCameraStream depth_stream = DevoDepthStream(dataset);
  const std::vector<TimedFile>& depth_frames = depth_stream.frames;
  const std::unique_ptr<EventReader> reader = OpenDatasetEvents(dataset);
  CannyDevo devo(dataset.camera, depth_stream.camera, depth_stream.event_from_depth, options.devo);
  DevoRunResult result;
  auto record = [&](const std::vector<tracking::PoseEstimate>& steps) {
    for (const tracking::PoseEstimate& step : steps) {
      result.trajectory.Append({step.t_ns, step.world_from_cam});
      if (step.status == tracking::TrackingStatus::kLost) ++result.lost_steps;
      result.steps.push_back(step);
      if (on_step) on_step(step);
    }
  };
  size_t next_depth = 0;
  while (next_depth < depth_frames.size() &&
         depth_frames[next_depth].t_ns < initial_t_ns + options.warm_up_ns) {
    ++next_depth;
  }
  // Handles the depth frame `next_depth` (every event up to its time has been given).
  auto handle_depth = [&]() {
    const TimedFile& file = depth_frames[next_depth];
    // The first reference frame needs the events on the tracker's surface: while the hot-pixel
    // filter learns, it holds them back (event_filter.h), so the start waits for a later frame.
    if (!devo.started() && devo.tracker().event_filter().holding()) {
      ++next_depth;
      return;
    }
    const cv::Mat depth = ReadDepthPng(file.path, depth_stream.units_per_metre);
    if (!devo.started()) {
      devo.Start(OdometryStartPose(dataset, initial_world_from_cam, file.t_ns), file.t_ns, depth);
    } else {
      record(devo.AddDepthFrame(file.t_ns, depth));
    }
    ++next_depth;
  };
  EventBuffer batch;
  EventBuffer part;
  while (true) {
    batch.clear();  // Read appends
    if (reader->Read(options.read_batch_events, &batch) == 0) break;
    result.events += static_cast<int64_t>(batch.size());
    size_t begin = 0;
    while (begin < batch.size()) {
      // Events up to the next depth frame's time, then that frame.
      size_t end = batch.size();
      if (next_depth < depth_frames.size()) {
        const int64_t t_depth = depth_frames[next_depth].t_ns;
        end = static_cast<size_t>(
            std::upper_bound(batch.t_ns.begin() + begin, batch.t_ns.end(), t_depth) -
            batch.t_ns.begin());
      }
      part.clear();
      part.Append(batch, begin, end - begin);
      record(devo.AddEvents(part));
      begin = end;
      if (begin < batch.size() && next_depth < depth_frames.size()) handle_depth();
    }
  }
  if (!devo.started()) {
    throw InvalidArgumentError("dataset '" + dataset.root.string() +
                               "': no depth frame after the warm-up within the events");
  }
  result.reference_frames = devo.reference_frames();
  result.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

}  // namespace evloc::odometry
