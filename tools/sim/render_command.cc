#include "tools/sim/render_command.h"

#include <chrono>
#include <cmath>
#include <memory>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"
#include "core/dataset/dataset.h"
#include "core/events/ecd_text.h"
#include "core/events/evb.h"
#include "core/trajectory/tum_io.h"
#include "maps/map.h"
#include "maps/ply.h"
#include "tools/sim/ground_truth_map.h"
#include "tools/sim/renderer.h"
#include "tools/sim/scene.h"
#include "tools/sim/simulate.h"

namespace evloc::sim {
namespace fs = std::filesystem;
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// events.evb, and events.txt when asked, written as batches arrive.
class EventFiles {
 public:
  EventFiles(const fs::path& dir, const Camera& camera, bool with_text)
      : evb_(dir / dataset_files::kEventsEvb, SensorSize{camera.width, camera.height}) {
    if (with_text) text_ = std::make_unique<EcdTextWriter>(dir / dataset_files::kEventsTxt);
  }
  void Write(const EventBuffer& events) {
    evb_.Write(events);
    if (text_) text_->Write(events);
  }
  void Close() {
    evb_.Close();
    if (text_) text_->Close();
  }

 private:
  EvbWriter evb_;
  std::unique_ptr<EcdTextWriter> text_;
};

nlohmann::json CameraJson(const Camera& camera) {
  return {{"model", CameraModelName(camera.model)},
          {"width", camera.width},
          {"height", camera.height},
          {"fx", camera.fx},
          {"fy", camera.fy},
          {"cx", camera.cx},
          {"cy", camera.cy},
          {"distortion", camera.distortion}};
}

nlohmann::json EsimJson(const EsimOptions& esim) {
  return {{"contrast_threshold_on", esim.contrast_threshold_on},
          {"contrast_threshold_off", esim.contrast_threshold_off},
          {"threshold_mismatch_sigma", esim.threshold_mismatch_sigma},
          {"refractory_period_ns", esim.refractory_period_ns},
          {"noise_rate_hz_per_pixel", esim.noise_rate_hz_per_pixel},
          {"noise_half_intensity", esim.noise_half_intensity},
          {"photoreceptor_cutoff_hz", esim.photoreceptor_cutoff_hz},
          {"leak_rate_hz", esim.leak_rate_hz},
          {"leak_rate_spread_decades", esim.leak_rate_spread_decades},
          {"hot_pixel_fraction", esim.hot_pixel_fraction},
          {"hot_pixel_rate_hz", esim.hot_pixel_rate_hz},
          {"readout_rate_eps", esim.readout_rate_eps},
          {"readout_max_delay_ns", esim.readout_max_delay_ns},
          {"log_epsilon", esim.log_epsilon},
          {"seed", esim.seed}};
}

// The viewpoint a motion is centred on: the camera region's centre, looking at the scene's centre
// (or horizontally along +x when they nearly coincide), world z up.
Viewpoint DefaultViewpoint(const Scene& scene) {
  Viewpoint viewpoint;
  viewpoint.position = scene.camera_region.center();
  viewpoint.up = Eigen::Vector3d::UnitZ();
  Eigen::Vector3d direction = scene.bounds.center() - viewpoint.position;
  if (direction.head<2>().norm() < 0.3) direction = Eigen::Vector3d(1, 0, -0.2);
  viewpoint.look_at = viewpoint.position + direction;
  return viewpoint;
}

}  // namespace

Camera CameraPreset(const std::string& name) {
  if (name == "default") return Camera::Pinhole(640, 480, 500, 500, 319.5, 239.5);
  if (name == "davis240") {
    Camera camera;
    camera.model = CameraModel::kRadialTangential;
    camera.width = 240;
    camera.height = 180;
    camera.fx = 199.092366542;
    camera.fy = 198.82882047;
    camera.cx = 132.192071378;
    camera.cy = 110.712660011;
    camera.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241,
                         0.0};
    camera.Check();
    return camera;
  }
  throw InvalidArgumentError("Unknown camera preset '" + name + "'; expected default or davis240.");
}

EsimOptions RenderCommandOptions::PixelOptions() const {
  EsimOptions esim = SensorPreset(sensor);
  if (noise_rate_hz) esim.noise_rate_hz_per_pixel = *noise_rate_hz;
  if (hot_pixel_fraction) esim.hot_pixel_fraction = *hot_pixel_fraction;
  if (photoreceptor_cutoff_hz) esim.photoreceptor_cutoff_hz = *photoreceptor_cutoff_hz;
  esim.seed = seed;
  if (clean) esim = esim.Clean();
  return esim;
}

void RenderCommandOptions::Check() const {
  if (out_dir.empty()) throw InvalidArgumentError("render: --out is required.");
  SensorPreset(sensor);
  if (noise_rate_hz && (!std::isfinite(*noise_rate_hz) || *noise_rate_hz < 0)) {
    throw InvalidArgumentError("render: --noise-rate must be a rate >= 0 in Hz per pixel.");
  }
  if (hot_pixel_fraction && (!std::isfinite(*hot_pixel_fraction) || *hot_pixel_fraction < 0 ||
                             *hot_pixel_fraction >= 1)) {
    throw InvalidArgumentError(
        "render: --hot-pixels must be a fraction of the pixels in [0, 1), e.g. 0.001.");
  }
  if (photoreceptor_cutoff_hz &&
      (!std::isfinite(*photoreceptor_cutoff_hz) || *photoreceptor_cutoff_hz < 0)) {
    throw InvalidArgumentError("render: --cutoff must be a frequency >= 0 in Hz (0: no low-pass).");
  }
  if (clean && (noise_rate_hz || hot_pixel_fraction || photoreceptor_cutoff_hz)) {
    throw InvalidArgumentError(
        "render: --clean switches noise, hot pixels and the low-pass off; drop --noise-rate, "
        "--hot-pixels and --cutoff.");
  }
  if (duration_s && (!std::isfinite(*duration_s) || *duration_s <= 0)) {
    throw InvalidArgumentError("render: --duration must be a positive number of seconds.");
  }
  if (!std::isfinite(fps) || fps <= 0) {
    throw InvalidArgumentError("render: --fps must be positive.");
  }
  if (!(ground_truth_rate_hz >= 200)) {
    throw InvalidArgumentError("render: the ground-truth rate must be at least 200 Hz.");
  }
  if (carpark && scene_json) {
    throw InvalidArgumentError("render: --scene takes one scene: carpark or a JSON file.");
  }
  if (!carpark && (time_of_day || path)) {
    throw InvalidArgumentError(
        "render: --time-of-day and --path need --scene carpark (a JSON scene sets its daylight, "
        "sky and point_lights itself).");
  }
  if (path && trajectory_file) {
    throw InvalidArgumentError("render: --path and --trajectory exclude each other.");
  }
  if (path && *path != "vehicle" && *path != "pedestrian") {
    throw InvalidArgumentError("render: unknown --path '" + *path +
                               "'; expected vehicle or pedestrian.");
  }
  if (!(speed_m_per_s > 0) || !std::isfinite(speed_m_per_s)) {
    throw InvalidArgumentError("render: --speed must be a positive speed in m/s.");
  }
  if (!(path_start_m >= 0) || !std::isfinite(path_start_m)) {
    throw InvalidArgumentError("render: --path-start must be a distance >= 0 in metres.");
  }
  if (!(map_spacing_m > 0) || !std::isfinite(map_spacing_m)) {
    throw InvalidArgumentError("render: --map-spacing must be a positive distance in metres.");
  }
  if (carpark) site.Check();
  if (depth_camera) depth_camera->Check();
  if (map_until_s && !(*map_until_s >= 0 && std::isfinite(*map_until_s))) {
    throw InvalidArgumentError("render: --map-until must be a time >= 0 in seconds.");
  }
  if (!(keyframe_interval_s > 0) || !(max_pixel_motion_px > 0)) {
    throw InvalidArgumentError(
        "render: keyframe interval and pixel motion bound must be positive.");
  }
}

nlohmann::json RunRenderCommand(const RenderCommandOptions& options) {
  options.Check();
  const auto total_start = Clock::now();
  std::vector<std::string> calibration_notes;
  const Camera camera = options.camera_yaml
                            ? ReadCalibrationFile(*options.camera_yaml, 0, 0, &calibration_notes)
                            : CameraPreset(options.camera_preset);
  std::optional<CarPark> park;
  Scene scene;
  if (options.carpark) {
    park = MakeCarPark(options.site);
    if (options.time_of_day) ApplyTimeOfDay(*options.time_of_day, park->lamps, &park->scene);
    scene = park->scene;
  } else {
    scene = options.scene_json ? LoadSceneJson(*options.scene_json) : MakeDefaultRoom();
  }
  scene.Check();
  const Viewpoint viewpoint = DefaultViewpoint(scene);

  std::unique_ptr<CameraMotion> motion;
  if (options.path) {
    PathMotionOptions path_options =
        *options.path == "vehicle"
            ? VehiclePathOptions(park->drive_route, options.speed_m_per_s, options.seed)
            : PedestrianPathOptions(park->walk_route, options.seed);
    path_options.start_m = options.path_start_m;
    path_options.duration_s = options.duration_s;
    motion = std::make_unique<PathMotion>(path_options);
  } else if (options.trajectory_file) {
    const Trajectory recorded = ReadTumTrajectory(*options.trajectory_file);
    std::optional<int64_t> duration_ns;
    if (options.duration_s)
      duration_ns = static_cast<int64_t>(std::llround(*options.duration_s * 1e9));
    const Rigid3d anchor(LookAtRotation(viewpoint.position, viewpoint.look_at, viewpoint.up),
                         viewpoint.position);
    motion = std::make_unique<RecordedMotion>(recorded, anchor, duration_ns);
  } else {
    SmoothMotionOptions motion_options;
    motion_options.profile = options.motion;
    motion_options.duration_s = options.duration_s.value_or(10.0);
    motion_options.seed = options.seed;
    motion_options.camera_region = scene.camera_region;
    motion_options.viewpoint = viewpoint;
    motion = std::make_unique<SmoothMotion>(motion_options);
  }

  const LightingPreset lighting = MakeLightingPreset(options.lighting, scene.bounds);
  SequenceOptions sequence;
  sequence.esim = options.PixelOptions();
  sequence.frames = lighting.frames;
  sequence.frames.fps = options.fps;
  sequence.frames.seed = options.seed;
  if (sequence.frames.exposure_s >= 0.9 / options.fps)
    sequence.frames.exposure_s = 0.9 / options.fps;
  sequence.illumination = lighting.illumination;
  sequence.max_pixel_motion_px = options.max_pixel_motion_px;
  sequence.max_render_motion_px = options.max_render_motion_px;
  sequence.Check();

  DatasetWriter writer(options.out_dir, DatasetWriterOptions{options.force});
  writer.WriteCamera(camera);
  const Renderer renderer(scene, camera);
  EventFiles event_files(writer.staging_dir(), camera, options.events_txt);
  std::optional<int64_t> first_frame_t_ns;
  const SequenceStats stats = SimulateSequence(
      [&](const Rigid3d& pose, cv::Mat* gray, cv::Mat* rgb, cv::Mat* depth) {
        renderer.Render(pose, gray, rgb, depth);
      },
      camera, *motion, sequence, [&](const EventBuffer& events) { event_files.Write(events); },
      [&](int64_t t_ns, const cv::Mat& image, const cv::Mat& depth_m) {
        if (!first_frame_t_ns) first_frame_t_ns = t_ns;
        writer.AddImage(t_ns, image);
        writer.AddDepth(t_ns, depth_m);
      });
  event_files.Close();

  // The depth camera: its own frames from its own pose, triggered with the frame camera.
  nlohmann::json depth_camera_info = nullptr;
  if (options.depth_camera) {
    const auto depth_start = Clock::now();
    DepthSensorOptions depth_options = *options.depth_camera;
    depth_options.first_frame_t_ns = first_frame_t_ns.value_or(0);
    depth_options.seed = options.seed;
    const DepthSensor sensor(scene, depth_options);
    writer.WriteDepthCamera(camera, depth_options.camera, depth_options.event_from_depth);
    DepthModelCounts counts;
    int64_t frames = 0;
    for (int64_t index = 0; sensor.FrameTimeNs(index) <= motion->duration_ns(); ++index) {
      const int64_t t_ns = sensor.FrameTimeNs(index);
      writer.AddDepthCameraFrame(t_ns, sensor.Capture(motion->WorldFromCam(t_ns), index, &counts));
      ++frames;
    }
    depth_camera_info = {{"camera", CameraJson(depth_options.camera)},
                         {"fps", depth_options.fps},
                         {"event_from_depth",
                          {{"translation",
                            {depth_options.event_from_depth.translation.x(),
                             depth_options.event_from_depth.translation.y(),
                             depth_options.event_from_depth.translation.z()}},
                           {"rotation_xyzw",
                            {depth_options.event_from_depth.rotation.x(),
                             depth_options.event_from_depth.rotation.y(),
                             depth_options.event_from_depth.rotation.z(),
                             depth_options.event_from_depth.rotation.w()}}}},
                         {"noise_at_1m_m", depth_options.noise_at_1m_m},
                         {"quantization_m", depth_options.quantization_m},
                         {"frames", frames},
                         {"pixels_hit", counts.exact},
                         {"holes_out_of_range", counts.out_of_range},
                         {"holes_discontinuity", counts.discontinuity},
                         {"holes_dark", counts.dark},
                         {"holes_specular", counts.specular},
                         {"pixels_measured", counts.measured},
                         {"seconds", SecondsSince(depth_start)}};
  }

  const Trajectory ground_truth = SampleMotion(*motion, options.ground_truth_rate_hz);
  writer.WriteGroundTruth(ground_truth);

  const auto map_start = Clock::now();
  std::vector<Rigid3d> keyframes;
  const auto keyframe_step = static_cast<int64_t>(std::llround(options.keyframe_interval_s * 1e9));
  const int64_t map_end_ns =
      options.map_until_s ? std::min(motion->duration_ns(),
                                     static_cast<int64_t>(std::llround(*options.map_until_s * 1e9)))
                          : motion->duration_ns();
  for (int64_t t = 0; t <= map_end_ns; t += keyframe_step) {
    keyframes.push_back(motion->WorldFromCam(t));
  }
  GroundTruthMapOptions map_options;
  map_options.point_spacing_m = options.map_spacing_m;
  const Map map = BuildGroundTruthMap(scene, camera, keyframes, map_options);
  SaveMap(writer.staging_dir() / dataset_files::kGroundTruthMap, map);
  WritePly(writer.staging_dir() / dataset_files::kGroundTruthPly, map);
  const double map_seconds = SecondsSince(map_start);

  const PeakSpeeds peak = MeasurePeakSpeeds(*motion);
  const double duration_s = motion->duration_ns() * 1e-9;
  nlohmann::json info = {
      {"tool", "evloc-sim render"},
      {"options",
       {{"camera", options.camera_yaml ? options.camera_yaml->string() : options.camera_preset},
        {"scene", options.carpark      ? "carpark"
                  : options.scene_json ? options.scene_json->string()
                                       : "default room"},
        {"site_seed", options.site.seed},
        {"ground_marks_per_m2", options.site.ground_marks_per_m2},
        {"time_of_day", options.time_of_day ? TimeOfDayName(*options.time_of_day) : ""},
        {"motion", options.path              ? *options.path
                   : options.trajectory_file ? "trajectory"
                                             : MotionProfileName(options.motion)},
        {"speed_m_per_s", options.path == "vehicle" ? options.speed_m_per_s
                          : options.path            ? 1.4
                                                    : 0.0},
        {"path_start_m", options.path_start_m},
        {"map_spacing_m", options.map_spacing_m},
        {"trajectory_file", options.trajectory_file ? options.trajectory_file->string() : ""},
        {"duration_s", duration_s},
        {"fps", options.fps},
        {"lighting", LightingConditionName(options.lighting)},
        {"seed", options.seed},
        {"sensor", options.sensor},
        {"clean", options.clean},
        {"max_pixel_motion_px", options.max_pixel_motion_px},
        {"max_render_motion_px", options.max_render_motion_px},
        {"ground_truth_rate_hz", options.ground_truth_rate_hz},
        {"keyframe_interval_s", options.keyframe_interval_s},
        {"map_until_s", options.map_until_s ? *options.map_until_s : -1.0}}},
      {"camera", CameraJson(camera)},
      {"esim", EsimJson(sequence.esim)},
      {"frames",
       {{"exposure_s", sequence.frames.exposure_s},
        {"gain_dn_per_electron", sequence.frames.gain_dn_per_electron},
        {"read_noise_electrons", sequence.frames.read_noise_electrons},
        {"illumination_lit", sequence.illumination.lit_factor},
        {"illumination_shadow", sequence.illumination.shadow_factor}}},
      {"counts",
       {{"events", stats.num_events},
        {"signal_events", stats.esim_counts.signal},
        {"noise_events", stats.esim_counts.noise},
        {"leak_events", stats.esim_counts.leak},
        {"hot_pixel_events", stats.esim_counts.hot_pixel},
        {"refractory_suppressed_events", stats.esim_counts.refractory_suppressed},
        {"readout_dropped_events", stats.esim_counts.readout_dropped},
        {"readout_delayed_events", stats.esim_counts.readout_delayed},
        {"readout_max_delay_ns", stats.esim_counts.readout_max_delay_ns},
        {"event_rate_per_s", stats.num_events / duration_s},
        {"renders", stats.num_renders},
        {"interpolated_images", stats.num_interpolated},
        {"frames", stats.num_frames},
        {"ground_truth_poses", ground_truth.size()},
        {"map_points", map.size()},
        {"map_keyframes", keyframes.size()}}},
      {"motion_measured",
       {{"peak_linear_m_per_s", peak.linear_m_per_s},
        {"peak_angular_deg_per_s", peak.angular_rad_per_s * 180 / M_PI},
        {"max_image_motion_between_esim_images_px", stats.max_measured_motion_px}}},
      {"timings_s",
       {{"render", stats.render_seconds},
        {"interpolation", stats.interpolation_seconds},
        {"esim", stats.esim_seconds},
        {"frames", stats.frame_seconds},
        {"ground_truth_map", map_seconds}}}};
  if (!depth_camera_info.is_null()) info["depth_camera"] = depth_camera_info;
  if (!calibration_notes.empty()) info["calibration_notes"] = calibration_notes;
  info["timings_s"]["total"] = SecondsSince(total_start);
  writer.WriteInfo(info);
  writer.Commit();
  return info;
}

void EventsFromFramesCommandOptions::Check() const {
  if (in_dir.empty() || out_dir.empty()) {
    throw InvalidArgumentError("events-from-frames: --in and --out are required.");
  }
  std::error_code error;
  if (fs::weakly_canonical(in_dir, error) == fs::weakly_canonical(out_dir, error)) {
    throw InvalidArgumentError("events-from-frames: --in and --out must differ.");
  }
  if (ecd_width <= 0 || ecd_height <= 0) {
    throw InvalidArgumentError("events-from-frames: --ecd-size must be positive.");
  }
  conversion.Check();
}

void SurveyCommandOptions::Check() const {
  if (out_dir.empty()) throw InvalidArgumentError("survey: --out is required.");
  if (survey != "walk" && survey != "car") {
    throw InvalidArgumentError("survey: unknown --survey '" + survey + "'; expected walk or car.");
  }
  if (!(spacing_m > 0) || !std::isfinite(spacing_m)) {
    throw InvalidArgumentError("survey: --spacing must be a positive distance in metres.");
  }
  if (!(start_m >= 0) || !std::isfinite(start_m)) {
    throw InvalidArgumentError("survey: --path-start must be a distance >= 0 in metres.");
  }
  if (max_photos && *max_photos < 1) {
    throw InvalidArgumentError("survey: --max-photos must be at least 1.");
  }
  site.Check();
}

nlohmann::json RunSurveyCommand(const SurveyCommandOptions& options) {
  options.Check();
  const auto start = Clock::now();
  const Camera camera = options.camera_yaml ? ReadCameraYaml(*options.camera_yaml)
                                            : CameraPreset(options.camera_preset);
  CarPark park = MakeCarPark(options.site);
  if (options.time_of_day) ApplyTimeOfDay(*options.time_of_day, park.lamps, &park.scene);
  const bool walk = options.survey == "walk";
  PathMotionOptions path = walk ? PedestrianPathOptions(park.survey_walk_route, options.seed)
                                : VehiclePathOptions(park.drive_route, 3.0, options.seed);
  if (!walk) path.height_m = 2.0;
  path.start_m = options.start_m;
  const PathMotion motion(path);
  const double available_m = motion.length_m() - options.start_m;
  int photos = static_cast<int>(std::floor(available_m / options.spacing_m)) + 1;
  if (options.max_photos) photos = std::min(photos, *options.max_photos);

  DatasetWriter writer(options.out_dir, DatasetWriterOptions{options.force});
  writer.WriteCamera(camera);
  const Renderer renderer(park.scene, camera);
  Trajectory poses;
  cv::Mat gray, rgb, depth, bgr8;
  const double seconds_per_photo = options.spacing_m / path.speed_m_per_s;
  for (int k = 0; k < photos; ++k) {
    const auto t_ns = static_cast<int64_t>(std::llround(k * seconds_per_photo * 1e9));
    Rigid3d world_from_cam = motion.WorldFromCam(std::min(t_ns, motion.duration_ns()));
    if (walk) {
      // Looking left, ahead and right in turn (about world z).
      const double yaw = (k % 3 - 1) * -40.0 * M_PI / 180;
      world_from_cam.rotation =
          (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * world_from_cam.rotation).normalized();
    }
    renderer.Render(world_from_cam, &gray, &rgb, &depth);
    cv::Mat rgb8;
    rgb.convertTo(rgb8, CV_8UC3, 255.0);
    cv::cvtColor(rgb8, bgr8, cv::COLOR_RGB2BGR);
    writer.AddImage(t_ns, bgr8);
    writer.AddDepth(t_ns, depth);
    poses.Append(TimedPose{t_ns, world_from_cam});
  }
  writer.WriteGroundTruth(poses);
  const nlohmann::json info = {
      {"tool", "evloc-sim survey"},
      {"options",
       {{"survey", options.survey},
        {"camera", options.camera_yaml ? options.camera_yaml->string() : options.camera_preset},
        {"site_seed", options.site.seed},
        {"ground_marks_per_m2", options.site.ground_marks_per_m2},
        {"time_of_day", options.time_of_day ? TimeOfDayName(*options.time_of_day) : "day"},
        {"spacing_m", options.spacing_m},
        {"path_start_m", options.start_m},
        {"seed", options.seed}}},
      {"camera", CameraJson(camera)},
      {"counts", {{"photos", photos}, {"path_length_m", motion.length_m()}}},
      {"timings_s", {{"total", SecondsSince(start)}}}};
  writer.WriteInfo(info);
  writer.Commit();
  return info;
}

nlohmann::json RunEventsFromFramesCommand(const EventsFromFramesCommandOptions& options) {
  options.Check();
  const auto total_start = Clock::now();
  const Dataset input =
      ReadDataset(options.in_dir, {options.ecd_width, options.ecd_height, {}, {}});
  if (input.images.size() < 2) {
    throw InvalidArgumentError("events-from-frames: '" + options.in_dir.string() +
                               "' lists fewer than 2 images in images.txt.");
  }
  DatasetWriter writer(options.out_dir, DatasetWriterOptions{options.force});
  writer.WriteCamera(input.camera);
  EventFiles event_files(writer.staging_dir(), input.camera, options.events_txt);
  const EventsFromFramesStats stats =
      EventsFromFrames(input.images, options.conversion,
                       [&](const EventBuffer& events) { event_files.Write(events); });
  event_files.Close();
  // Frames, depth and ground truth carried over.
  for (const TimedFile& image : input.images) {
    writer.AddImage(image.t_ns, cv::imread(image.path.string(), cv::IMREAD_UNCHANGED));
  }
  for (const TimedFile& depth : input.depth) writer.AddDepth(depth.t_ns, ReadDepthPng(depth.path));
  if (input.ground_truth) writer.WriteGroundTruth(*input.ground_truth);
  if (input.ground_truth_map_path) {
    fs::copy_file(*input.ground_truth_map_path,
                  writer.staging_dir() / dataset_files::kGroundTruthMap);
    const fs::path ply = input.root / dataset_files::kGroundTruthPly;
    if (fs::exists(ply)) fs::copy_file(ply, writer.staging_dir() / dataset_files::kGroundTruthPly);
  }
  const double duration_s = (input.images.back().t_ns - input.images.front().t_ns) * 1e-9;
  nlohmann::json info = {
      {"tool", "evloc-sim events-from-frames"},
      {"input", options.in_dir.string()},
      {"camera", CameraJson(input.camera)},
      {"esim", EsimJson(options.conversion.esim)},
      {"interpolation",
       {{"method", "DIS optical flow, bidirectional backward warping"},
        {"max_pixel_motion_px", options.conversion.max_pixel_motion_px},
        {"input_gamma", options.conversion.input_gamma}}},
      {"counts",
       {{"events", stats.num_events},
        {"event_rate_per_s", duration_s > 0 ? stats.num_events / duration_s : 0.0},
        {"input_frames", stats.num_input_frames},
        {"interpolated_frames", stats.num_interpolated_frames},
        {"max_flow_px", stats.max_flow_px}}},
      {"timings_s", {{"flow", stats.flow_seconds}, {"esim", stats.esim_seconds}}}};
  info["timings_s"]["total"] = SecondsSince(total_start);
  writer.WriteInfo(info);
  writer.Commit();
  return info;
}

}  // namespace evloc::sim
