// The C++ half of the Python package `evloc` (python/, docs/python.md): pybind11 bindings of the
// offline library. Maps, cameras, event readers, datasets and the tracker, with NumPy arrays in
// and out; evloc's errors become the package's exceptions with the same messages. The Python
// half (python/evloc/*.py) builds the public API on top of this module, `evloc._evloc`.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "core/camera/calibration_file.h"
#include "core/camera/camera.h"
#include "core/common/error.h"
#include "core/dataset/dataset.h"
#include "core/events/event.h"
#include "core/events/event_reader.h"
#include "core/geometry/rigid3.h"
#include "core/trajectory/trajectory.h"
#include "core/trajectory/tum_io.h"
#include "localizer/offline/offline_tracking.h"
#include "localizer/offline/track_command.h"
#include "localizer/tracking/tracker.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/visibility.h"

namespace py = pybind11;

namespace evloc::python {
namespace {

// ---------------------------------------------------------------------------------------------
// Poses: NumPy (7,) arrays "tx ty tz qx qy qz qw" (the TUM order) in and out.

// Writes `pose` as 7 values tx ty tz qx qy qz qw to `out`.
void WritePoseValues(const Rigid3d& pose, double* out) {
  const double values[7] = {pose.translation.x(), pose.translation.y(), pose.translation.z(),
                            pose.rotation.x(),    pose.rotation.y(),    pose.rotation.z(),
                            pose.rotation.w()};
  std::copy(values, values + 7, out);
}

py::array_t<double> PoseToArray(const Rigid3d& pose) {
  py::array_t<double> out(7);
  WritePoseValues(pose, out.mutable_data());
  return out;
}

// A pose from 7 values (tx ty tz qx qy qz qw) or a 4x4 / 3x4 matrix [R|t]. The quaternion is
// kept bit for bit when its norm is 1 to within 1e-12 (so a pose read back from evloc gives the
// same run), normalised when within 1e-3, refused otherwise.
Rigid3d PoseFromArray(const py::array_t<double, py::array::c_style | py::array::forcecast>& array,
                      const std::string& what) {
  if (array.ndim() == 2 && (array.shape(0) == 4 || array.shape(0) == 3) && array.shape(1) == 4) {
    Eigen::Matrix4d matrix = Eigen::Matrix4d::Identity();
    for (int r = 0; r < array.shape(0); ++r) {
      for (int c = 0; c < 4; ++c) matrix(r, c) = array.at(r, c);
    }
    if (!matrix.allFinite()) throw InvalidArgumentError(what + ": the matrix is not finite");
    return Rigid3d::FromMatrix(matrix);
  }
  if (array.ndim() != 1 || array.shape(0) != 7) {
    throw InvalidArgumentError(what + ": expected 7 values (tx ty tz qx qy qz qw) or a 4x4 matrix");
  }
  const double* v = array.data();
  for (int i = 0; i < 7; ++i) {
    if (!std::isfinite(v[i])) throw InvalidArgumentError(what + ": a value is not finite");
  }
  Rigid3d pose;
  pose.translation = Eigen::Vector3d(v[0], v[1], v[2]);
  pose.rotation = Eigen::Quaterniond(v[6], v[3], v[4], v[5]);
  const double norm = pose.rotation.norm();
  if (std::abs(norm - 1.0) > 1e-3) {
    std::ostringstream message;
    message << what << ": the quaternion (qx qy qz qw) has norm " << norm
            << ", not 1 (give a unit quaternion)";
    throw InvalidArgumentError(message.str());
  }
  if (std::abs(norm - 1.0) > 1e-12) pose.rotation.normalize();
  return pose;
}

// ---------------------------------------------------------------------------------------------
// Events: the structured dtype (t, x, y, p) and the copy from four arrays.

py::dtype EventDtype() {
  // Field names and types of evloc's event (core/events/event.h), packed.
  py::list fields;
  fields.append(py::make_tuple("t", "<i8"));
  fields.append(py::make_tuple("x", "<u2"));
  fields.append(py::make_tuple("y", "<u2"));
  fields.append(py::make_tuple("p", "i1"));
  return py::dtype::from_args(fields);
}

py::array EventsToStructured(const EventBuffer& events) {
  py::array out(EventDtype(), std::vector<py::ssize_t>{static_cast<py::ssize_t>(events.size())});
  auto* base = static_cast<char*>(out.mutable_data());
  const size_t stride = 13;  // 8 + 2 + 2 + 1, packed (numpy's default for this list)
  for (size_t i = 0; i < events.size(); ++i) {
    char* record = base + i * stride;
    std::memcpy(record, &events.t_ns[i], 8);
    std::memcpy(record + 8, &events.x[i], 2);
    std::memcpy(record + 10, &events.y[i], 2);
    std::memcpy(record + 12, &events.polarity[i], 1);
  }
  return out;
}

using Int64Array = py::array_t<int64_t, py::array::c_style | py::array::forcecast>;
using Uint16Array = py::array_t<uint16_t, py::array::c_style | py::array::forcecast>;
using Int8Array = py::array_t<int8_t, py::array::c_style | py::array::forcecast>;

// Copies four equally long arrays into an EventBuffer; polarity 1 is ON, 0 or -1 OFF.
EventBuffer EventsFromArrays(const Int64Array& t_ns, const Uint16Array& x, const Uint16Array& y,
                             const Int8Array& polarity) {
  if (t_ns.ndim() != 1 || x.ndim() != 1 || y.ndim() != 1 || polarity.ndim() != 1) {
    throw InvalidArgumentError("events: t, x, y and p must be one-dimensional arrays");
  }
  const size_t count = static_cast<size_t>(t_ns.shape(0));
  if (static_cast<size_t>(x.shape(0)) != count || static_cast<size_t>(y.shape(0)) != count ||
      static_cast<size_t>(polarity.shape(0)) != count) {
    throw InvalidArgumentError("events: t, x, y and p must have the same length (got " +
                               std::to_string(count) + ", " + std::to_string(x.shape(0)) + ", " +
                               std::to_string(y.shape(0)) + ", " +
                               std::to_string(polarity.shape(0)) + ")");
  }
  EventBuffer events;
  events.reserve(count);
  events.Append(t_ns.data(), x.data(), y.data(), polarity.data(), count);
  for (size_t i = 0; i < count; ++i) {
    const int8_t p = events.polarity[i];
    if (p != 1 && p != 0 && p != -1) {
      throw InvalidArgumentError("events: polarity of event " + std::to_string(i) + " is " +
                                 std::to_string(p) + "; expected 1 (ON), 0 or -1 (OFF)");
    }
    if (p == 0) events.polarity[i] = -1;
    if (i > 0 && events.t_ns[i] < events.t_ns[i - 1]) {
      throw InvalidArgumentError("events: time goes back at event " + std::to_string(i) + " (" +
                                 std::to_string(events.t_ns[i]) + " ns after " +
                                 std::to_string(events.t_ns[i - 1]) + " ns); sort them by time");
    }
  }
  return events;
}

// An event file or a dataset's events, read in chunks.
class PyEventReader {
 public:
  PyEventReader(std::unique_ptr<EventReader> reader, std::string format, size_t chunk_events)
      : reader_(std::move(reader)), format_(std::move(format)), chunk_events_(chunk_events) {
    if (chunk_events_ == 0) throw InvalidArgumentError("chunk_events must be at least 1");
  }
  // The next chunk (at most chunk_events events) as a structured array; empty at the end.
  py::array Read(std::optional<size_t> max_events) {
    const size_t limit = max_events.value_or(chunk_events_);
    if (limit == 0) throw InvalidArgumentError("max_events must be at least 1");
    EventBuffer events;
    {
      py::gil_scoped_release release;
      reader_->Read(limit, &events);
    }
    return EventsToStructured(events);
  }
  py::object SensorSizeTuple() const {
    const auto size = reader_->sensor_size();
    if (!size) return py::none();
    return py::make_tuple(size->width, size->height);
  }
  uint64_t dropped() const { return reader_->dropped_event_count(); }
  const std::string& format() const { return format_; }
  size_t chunk_events() const { return chunk_events_; }

 private:
  std::unique_ptr<EventReader> reader_;
  std::string format_;
  size_t chunk_events_;
};

// ---------------------------------------------------------------------------------------------
// Maps.

struct PyMap {
  std::shared_ptr<const Map> map;
  std::string source;
  // Built on first use by a tracker, then shared.
  std::shared_ptr<const VisibilityIndex> visibility;

  const VisibilityIndex* Visibility() {
    if (!visibility) visibility = std::make_shared<const VisibilityIndex>(*map);
    return visibility.get();
  }
};

// `map` with its visibility index built (in the Python object too, for the next tracker).
PyMap WithVisibility(PyMap& map) {
  map.Visibility();
  return map;
}

template <typename Vector>
py::array_t<float> Vector3Array(const std::vector<Vector>& values) {
  py::array_t<float> out({static_cast<py::ssize_t>(values.size()), py::ssize_t{3}});
  float* data = out.mutable_data();
  for (size_t i = 0; i < values.size(); ++i) {
    for (int k = 0; k < 3; ++k) data[3 * i + k] = values[i][k];
  }
  return out;
}

template <typename T>
py::array_t<T> VectorArray(const std::vector<T>& values) {
  py::array_t<T> out(static_cast<py::ssize_t>(values.size()));
  if (!values.empty()) std::memcpy(out.mutable_data(), values.data(), values.size() * sizeof(T));
  return out;
}

py::dict CameraToDict(const Camera& camera) {
  py::dict out;
  out["model"] = CameraModelName(camera.model);
  out["width"] = camera.width;
  out["height"] = camera.height;
  out["fx"] = camera.fx;
  out["fy"] = camera.fy;
  out["cx"] = camera.cx;
  out["cy"] = camera.cy;
  out["distortion"] = camera.distortion;
  return out;
}

Camera CameraFromDict(const py::dict& values) {
  static const char* const kKeys[] = {"model", "width", "height", "fx",
                                      "fy",    "cx",    "cy",     "distortion"};
  for (const auto& item : values) {
    const std::string key = py::str(item.first);
    if (std::find_if(std::begin(kKeys), std::end(kKeys),
                     [&](const char* name) { return key == name; }) == std::end(kKeys)) {
      throw InvalidArgumentError("camera: unknown key '" + key +
                                 "' (expected model, width, height, fx, fy, cx, cy, distortion)");
    }
  }
  for (const char* key : {"width", "height", "fx", "fy", "cx", "cy"}) {
    if (!values.contains(key))
      throw InvalidArgumentError(std::string("camera: '") + key + "' is missing");
  }
  Camera camera;
  camera.model = values.contains("model") ? ParseCameraModel(py::cast<std::string>(values["model"]))
                                          : CameraModel::kPinhole;
  camera.width = py::cast<int>(values["width"]);
  camera.height = py::cast<int>(values["height"]);
  camera.fx = py::cast<double>(values["fx"]);
  camera.fy = py::cast<double>(values["fy"]);
  camera.cx = py::cast<double>(values["cx"]);
  camera.cy = py::cast<double>(values["cy"]);
  if (values.contains("distortion")) {
    camera.distortion = py::cast<std::vector<double>>(values["distortion"]);
  }
  camera.Check();
  return camera;
}

py::dict SummaryOf(const PyMap& wrapped) {
  const MapInfo info = SummarizeMap(*wrapped.map);
  py::dict out;
  out["source"] = wrapped.source;
  out["num_points"] = info.num_points;
  out["num_keyframes"] = info.num_keyframes;
  out["num_cameras"] = wrapped.map->cameras.size();
  out["bounding_box_min"] =
      std::vector<float>(info.bounding_box_min.data(), info.bounding_box_min.data() + 3);
  out["bounding_box_max"] =
      std::vector<float>(info.bounding_box_max.data(), info.bounding_box_max.data() + 3);
  out["content_crc32c"] = info.content_crc32c;
  out["has_relocalization"] = info.has_relocalization;
  out["num_landmarks"] = info.num_landmarks;
  out["format_version"] = info.format_version;
  out["first_keyframe_t_ns"] = info.first_keyframe_t_ns;
  out["last_keyframe_t_ns"] = info.last_keyframe_t_ns;
  py::dict provenance;
  provenance["tool"] = info.provenance.tool;
  provenance["tool_version"] = info.provenance.tool_version;
  provenance["created_utc"] = info.provenance.created_utc;
  provenance["command_line"] = info.provenance.command_line;
  provenance["inputs"] = info.provenance.inputs;
  out["provenance"] = provenance;
  out["cameras"] = info.camera_descriptions;
  return out;
}

// ---------------------------------------------------------------------------------------------
// Tracking.

// The offline run's options from evloc-track's flags (one parser: the flags mean the same as on
// the command line, and a bad value gives evloc-track's message).
tracking::OfflineTrackingOptions TrackingOptionsFromFlags(const std::vector<std::string>& flags) {
  std::vector<std::string> arguments = {"--map",    "(python)", "--dataset",
                                        "(python)", "--out",    "(python)"};
  arguments.insert(arguments.end(), flags.begin(), flags.end());
  const tracking::TrackCommandOptions options = tracking::ParseTrackCommandLine(arguments);
  if (options.start_s || options.blackout_begin_s || options.stats_path || options.debug_dir ||
      options.odometry || options.initial_world_from_cam || options.no_initial_pose ||
      options.initial_velocity || options.initial_velocity_from_truth) {
    throw InvalidArgumentError(
        "tracker options: --start, --blackout, --stats, --debug-dir, --mode vo/devo, "
        "--init-pose and --initial-velocity belong to evloc.track_dataset, not to a tracker");
  }
  tracking::OfflineTrackingOptions tracking = options.tracking;
  // The per-step columns include the surface age, which the tracker measures only on request.
  tracking.tracker.measure_surface_age = true;
  return tracking;
}

// Per-step results as NumPy arrays: the columns of evloc-track --stats.
py::dict StepsToArrays(const std::vector<tracking::PoseEstimate>& steps) {
  const auto n = static_cast<py::ssize_t>(steps.size());
  py::array_t<int64_t> t_ns(n);
  py::array_t<int8_t> status(n);
  py::array_t<double> pose({n, py::ssize_t{7}});
  py::array_t<double> covariance({n, py::ssize_t{6}, py::ssize_t{6}});
  py::array_t<int32_t> points_selected(n), points_used(n), iterations(n), recovery_attempts(n);
  py::array_t<double> on_edge_fraction(n), chance_on_edge_fraction(n), alignment(n),
      mean_residual(n), decay_time_ms(n), surface_age_ms(n), surface_ms(n), selection_ms(n),
      solve_ms(n), total_ms(n);
  double* pose_data = pose.mutable_data();
  double* covariance_data = covariance.mutable_data();
  for (py::ssize_t i = 0; i < n; ++i) {
    const tracking::PoseEstimate& step = steps[i];
    t_ns.mutable_data()[i] = step.t_ns;
    status.mutable_data()[i] = static_cast<int8_t>(step.status);
    WritePoseValues(step.world_from_cam, pose_data + 7 * i);
    for (int r = 0; r < 6; ++r) {
      for (int c = 0; c < 6; ++c) covariance_data[36 * i + 6 * r + c] = step.covariance(r, c);
    }
    points_selected.mutable_data()[i] = step.quality.points_selected;
    points_used.mutable_data()[i] = step.quality.points_used;
    iterations.mutable_data()[i] = step.quality.iterations;
    recovery_attempts.mutable_data()[i] = step.quality.recovery_attempts;
    on_edge_fraction.mutable_data()[i] = step.quality.on_edge_fraction;
    chance_on_edge_fraction.mutable_data()[i] = step.quality.chance_on_edge_fraction;
    alignment.mutable_data()[i] = step.quality.alignment;
    mean_residual.mutable_data()[i] = step.quality.mean_residual;
    decay_time_ms.mutable_data()[i] = step.quality.decay_time_ms;
    surface_age_ms.mutable_data()[i] = step.quality.surface_age_ms;
    surface_ms.mutable_data()[i] = step.timings.surface_ms;
    selection_ms.mutable_data()[i] = step.timings.selection_ms;
    solve_ms.mutable_data()[i] = step.timings.solve_ms;
    total_ms.mutable_data()[i] = step.timings.total_ms;
  }
  py::dict out;
  out["t_ns"] = t_ns;
  out["status"] = status;
  out["pose"] = pose;
  out["covariance"] = covariance;
  out["points_selected"] = points_selected;
  out["points_used"] = points_used;
  out["iterations"] = iterations;
  out["recovery_attempts"] = recovery_attempts;
  out["on_edge_fraction"] = on_edge_fraction;
  out["chance_on_edge_fraction"] = chance_on_edge_fraction;
  out["alignment"] = alignment;
  out["mean_residual"] = mean_residual;
  out["decay_time_ms"] = decay_time_ms;
  out["surface_age_ms"] = surface_age_ms;
  out["surface_ms"] = surface_ms;
  out["selection_ms"] = selection_ms;
  out["solve_ms"] = solve_ms;
  out["total_ms"] = total_ms;
  return out;
}

py::tuple TrajectoryToArrays(const Trajectory& trajectory) {
  const auto n = static_cast<py::ssize_t>(trajectory.size());
  py::array_t<int64_t> t_ns(n);
  py::array_t<double> pose({n, py::ssize_t{7}});
  for (py::ssize_t i = 0; i < n; ++i) {
    const TimedPose& timed = trajectory.poses()[i];
    t_ns.mutable_data()[i] = timed.t_ns;
    WritePoseValues(timed.world_from_cam, pose.mutable_data() + 7 * i);
  }
  return py::make_tuple(t_ns, pose);
}

Trajectory TrajectoryFromArrays(
    const Int64Array& t_ns,
    const py::array_t<double, py::array::c_style | py::array::forcecast>& poses) {
  if (t_ns.ndim() != 1 || poses.ndim() != 2 || poses.shape(1) != 7 ||
      poses.shape(0) != t_ns.shape(0)) {
    throw InvalidArgumentError(
        "trajectory: expected t_ns of shape (N,) and poses of shape (N, 7) (tx ty tz qx qy qz "
        "qw)");
  }
  std::vector<TimedPose> timed;
  timed.reserve(static_cast<size_t>(t_ns.shape(0)));
  for (py::ssize_t i = 0; i < t_ns.shape(0); ++i) {
    py::array_t<double> row(7, poses.data() + 7 * i);
    timed.push_back({t_ns.data()[i], PoseFromArray(row, "trajectory pose " + std::to_string(i))});
  }
  return Trajectory(std::move(timed));
}

py::dict ResultToDict(const tracking::OfflineTrackingResult& result) {
  py::dict out;
  out["steps"] = StepsToArrays(result.steps);
  out["trajectory"] = TrajectoryToArrays(result.trajectory);
  out["measurements"] = result.measurements;
  out["lost_steps"] = result.lost_steps;
  out["wall_s"] = result.wall_s;
  py::list episodes;
  for (const tracking::RelocalizationEpisode& episode : result.relocalizations) {
    py::dict item;
    item["start_t_ns"] = episode.start_t_ns;
    item["end_t_ns"] = episode.end_t_ns;
    item["outcome"] = episode.outcome;
    item["steps"] = episode.steps;
    item["rounds"] = episode.rounds;
    item["total_ms"] = episode.total_ms;
    item["max_step_ms"] = episode.max_step_ms;
    episodes.append(item);
  }
  out["relocalizations"] = episodes;
  return out;
}

// A live tracker over a map, fed events chunk by chunk.
class PyTracker {
 public:
  // `map` is the Python object's: its visibility index is built once and shared.
  PyTracker(PyMap& map, const py::dict& camera, const std::vector<std::string>& flags)
      : map_(WithVisibility(map)),
        camera_(CameraFromDict(camera)),
        options_(TrackingOptionsFromFlags(flags)) {
    tracker_ = std::make_unique<tracking::Tracker>(*map_.map, map_.Visibility(), camera_,
                                                   options_.tracker);
  }
  void Reset(const py::array_t<double, py::array::c_style | py::array::forcecast>& pose,
             int64_t t_ns) {
    tracker_->Reset(PoseFromArray(pose, "initial pose"), t_ns);
  }
  void StartWithoutPose(int64_t t_ns) { tracker_->StartWithoutPose(t_ns); }
  py::dict AddEvents(const Int64Array& t_ns, const Uint16Array& x, const Uint16Array& y,
                     const Int8Array& polarity) {
    const EventBuffer events = EventsFromArrays(t_ns, x, y, polarity);
    std::vector<tracking::PoseEstimate> steps;
    {
      py::gil_scoped_release release;
      steps = tracker_->AddEvents(events);
    }
    return StepsToArrays(steps);
  }
  py::dict AdvanceTo(int64_t t_ns) {
    std::vector<tracking::PoseEstimate> steps;
    {
      py::gil_scoped_release release;
      steps = tracker_->AdvanceTo(t_ns);
    }
    return StepsToArrays(steps);
  }
  std::string status() const { return tracking::TrackingStatusName(tracker_->status()); }

 private:
  PyMap map_;
  Camera camera_;
  tracking::OfflineTrackingOptions options_;
  std::unique_ptr<tracking::Tracker> tracker_;
};

std::optional<Rigid3d> OptionalPose(const py::object& pose) {
  if (pose.is_none()) return std::nullopt;
  return PoseFromArray(
      py::cast<py::array_t<double, py::array::c_style | py::array::forcecast>>(pose),
      "initial pose");
}

DatasetReaderOptions ReaderOptions(int ecd_width, int ecd_height) {
  DatasetReaderOptions options;
  options.ecd_width = ecd_width;
  options.ecd_height = ecd_height;
  options.Check();
  return options;
}

}  // namespace
}  // namespace evloc::python

PYBIND11_MODULE(_evloc, m) {
  using namespace evloc;
  using namespace evloc::python;
  m.doc() = "evloc's offline library (maps, events, datasets, tracking); see the evloc package.";

  // Errors: the messages are evloc's, unchanged. Every one is an evloc.Error, and also the
  // builtin a Python caller expects (ValueError for bad values and files, OSError for I/O).
  const auto new_exception = [&m](const char* name, std::vector<PyObject*> bases) {
    py::tuple base_tuple(bases.size());
    for (size_t i = 0; i < bases.size(); ++i) {
      base_tuple[i] = py::reinterpret_borrow<py::object>(bases[i]);
    }
    const std::string full_name = std::string("evloc._evloc.") + name;
    py::object type = py::reinterpret_steal<py::object>(
        PyErr_NewException(full_name.c_str(), base_tuple.ptr(), nullptr));
    if (!type) throw py::error_already_set();
    m.attr(name) = type;
    return type.release().ptr();  // kept for the module's lifetime
  };
  static PyObject* const error = new_exception("Error", {PyExc_RuntimeError});
  static PyObject* const invalid = new_exception("InvalidArgumentError", {error, PyExc_ValueError});
  static PyObject* const parse = new_exception("ParseError", {error, PyExc_ValueError});
  static PyObject* const io = new_exception("IoError", {error, PyExc_OSError});
  py::register_exception_translator([](std::exception_ptr pointer) {
    try {
      if (pointer) std::rethrow_exception(pointer);
    } catch (const InvalidArgumentError& e) {
      PyErr_SetString(invalid, e.what());
    } catch (const ParseError& e) {
      PyErr_SetString(parse, e.what());
    } catch (const IoError& e) {
      PyErr_SetString(io, e.what());
    } catch (const Error& e) {
      PyErr_SetString(error, e.what());
    }
  });

  // Maps.
  py::class_<PyMap>(m, "Map", "A loaded .evmap (evloc.load_map).")
      .def_property_readonly("source", [](const PyMap& self) { return self.source; })
      .def_property_readonly("num_points", [](const PyMap& self) { return self.map->size(); })
      .def_property_readonly("positions",
                             [](const PyMap& self) { return Vector3Array(self.map->positions); })
      .def_property_readonly("gradients",
                             [](const PyMap& self) { return Vector3Array(self.map->gradients); })
      .def_property_readonly(
          "inverse_depth_sigma",
          [](const PyMap& self) { return VectorArray(self.map->inverse_depth_sigma); })
      .def_property_readonly(
          "gradient_magnitude",
          [](const PyMap& self) { return VectorArray(self.map->gradient_magnitude); })
      .def_property_readonly(
          "source_keyframe",
          [](const PyMap& self) { return VectorArray(self.map->source_keyframe); })
      .def_property_readonly("keyframe_cam_from_world",
                             [](const PyMap& self) {
                               const auto n = static_cast<py::ssize_t>(self.map->keyframes.size());
                               py::array_t<double> out({n, py::ssize_t{4}, py::ssize_t{4}});
                               for (py::ssize_t i = 0; i < n; ++i) {
                                 const Eigen::Matrix4d matrix =
                                     self.map->keyframes[i].cam_from_world.ToMatrix4();
                                 for (int r = 0; r < 4; ++r) {
                                   for (int c = 0; c < 4; ++c) {
                                     out.mutable_data()[16 * i + 4 * r + c] = matrix(r, c);
                                   }
                                 }
                               }
                               return out;
                             })
      .def_property_readonly("keyframe_t_ns",
                             [](const PyMap& self) {
                               std::vector<int64_t> values;
                               for (const Keyframe& k : self.map->keyframes)
                                 values.push_back(k.t_ns);
                               return VectorArray(values);
                             })
      .def_property_readonly("keyframe_camera_index",
                             [](const PyMap& self) {
                               std::vector<uint32_t> values;
                               for (const Keyframe& k : self.map->keyframes) {
                                 values.push_back(k.camera_index);
                               }
                               return VectorArray(values);
                             })
      .def_property_readonly("keyframe_image_names",
                             [](const PyMap& self) {
                               std::vector<std::string> values;
                               for (const Keyframe& k : self.map->keyframes) {
                                 values.push_back(k.image_name);
                               }
                               return values;
                             })
      .def_property_readonly("cameras",
                             [](const PyMap& self) {
                               py::list out;
                               for (const Camera& c : self.map->cameras)
                                 out.append(CameraToDict(c));
                               return out;
                             })
      .def("summary", &SummaryOf, "The map's summary (evloc-mapper info's figures) as a dict.");

  m.def(
      "body_twist",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& older,
         const py::array_t<double, py::array::c_style | py::array::forcecast>& newer, double dt_s) {
        if (!(std::isfinite(dt_s) && dt_s > 0)) {
          throw InvalidArgumentError("body_twist: dt_s must be finite and positive");
        }
        const Vector6d twist = LogSE3(PoseFromArray(older, "body_twist: older").Inverse() *
                                      PoseFromArray(newer, "body_twist: newer")) /
                               dt_s;
        py::array_t<double> out(6);
        for (int i = 0; i < 6; ++i) out.mutable_data()[i] = twist[i];
        return out;
      },
      py::arg("older"), py::arg("newer"), py::arg("dt_s"),
      "The body-frame twist per second (vx vy vz wx wy wz, camera frame) that moves `older` to\n"
      "`newer` in dt_s seconds: newer = older * exp(dt_s * twist), as the tracker's motion model\n"
      "and SessionStart.initial_velocity define it.");
  m.def(
      "load_map",
      [](const std::filesystem::path& path) {
        std::filesystem::path file;
        Map map;
        {
          py::gil_scoped_release release;
          file = ResolveMapFile(path);
          map = LoadMap(file);
        }
        PyMap out;
        out.map = std::make_shared<const Map>(std::move(map));
        out.source = file.string();
        return out;
      },
      py::arg("path"), "Loads a .evmap file or a map directory holding map.evmap.");

  // Cameras.
  m.def(
      "read_camera",
      [](const std::filesystem::path& path, int width, int height) {
        return CameraToDict(ReadCalibrationFile(path, width, height));
      },
      py::arg("path"), py::arg("width") = 0, py::arg("height") = 0,
      "Reads a calibration file in any format --calib reads (evloc YAML, ECD calib.txt with width\n"
      "and height, Kalibr camchain FILE#camN, ROS camera_info, OpenCV FileStorage, COLMAP\n"
      "cameras.txt FILE#ID; docs/camera.md).");
  m.def(
      "check_camera", [](const py::dict& camera) { return CameraToDict(CameraFromDict(camera)); },
      py::arg("camera"), "Checks a camera dict as evloc does and returns it completed.");

  // Events.
  m.attr("event_dtype") = EventDtype();
  py::class_<PyEventReader>(m, "EventReader", "Events of a file or dataset, in chunks.")
      .def("read", &PyEventReader::Read, py::arg("max_events") = py::none(),
           "The next chunk as a structured array (t, x, y, p); empty at the end.")
      .def_property_readonly("sensor_size", &PyEventReader::SensorSizeTuple)
      .def_property_readonly("dropped_events", &PyEventReader::dropped)
      .def_property_readonly("format", &PyEventReader::format)
      .def_property_readonly("chunk_events", &PyEventReader::chunk_events);
  m.def(
      "open_events",
      [](const std::filesystem::path& path, size_t chunk_events) {
        const std::string format = EventFileFormatName(DetectEventFileFormat(path));
        return PyEventReader(OpenEventFile(path), format, chunk_events);
      },
      py::arg("path"), py::arg("chunk_events") = 1 << 16,
      "Opens an event file of any format evloc reads (docs/event-formats.md).");
  m.def(
      "detect_event_format",
      [](const std::filesystem::path& path) {
        return std::string(EventFileFormatName(DetectEventFileFormat(path)));
      },
      py::arg("path"));

  // Datasets.
  m.def(
      "read_dataset",
      [](const std::filesystem::path& path, int ecd_width, int ecd_height) {
        const Dataset dataset = ReadDataset(path, ReaderOptions(ecd_width, ecd_height));
        py::dict out;
        out["root"] = dataset.root.string();
        out["camera"] = CameraToDict(dataset.camera);
        std::vector<int64_t> image_t;
        std::vector<std::string> image_paths;
        for (const TimedFile& image : dataset.images) {
          image_t.push_back(image.t_ns);
          image_paths.push_back(image.path.string());
        }
        out["image_t_ns"] = VectorArray(image_t);
        out["image_paths"] = image_paths;
        out["ground_truth"] = dataset.ground_truth
                                  ? py::object(TrajectoryToArrays(*dataset.ground_truth))
                                  : py::none();
        out["events_path"] =
            dataset.events_path ? py::object(py::str(dataset.events_path->string())) : py::none();
        out["ground_truth_map_path"] =
            dataset.ground_truth_map_path
                ? py::object(py::str(dataset.ground_truth_map_path->string()))
                : py::none();
        return out;
      },
      py::arg("path"), py::arg("ecd_width") = 240, py::arg("ecd_height") = 180,
      "Reads a dataset folder, ROS1 bag or AEDAT4 file (docs/dataset-format.md).");
  m.def(
      "open_dataset_events",
      [](const std::filesystem::path& path, int ecd_width, int ecd_height, size_t chunk_events) {
        const Dataset dataset = ReadDataset(path, ReaderOptions(ecd_width, ecd_height));
        const std::string format =
            dataset.events_path ? EventFileFormatName(DetectEventFileFormat(*dataset.events_path))
                                : std::string();
        return PyEventReader(OpenDatasetEvents(dataset), format, chunk_events);
      },
      py::arg("path"), py::arg("ecd_width") = 240, py::arg("ecd_height") = 180,
      py::arg("chunk_events") = 1 << 16);
  m.def(
      "dataset_initial_pose",
      [](const std::filesystem::path& path, int ecd_width, int ecd_height) {
        const Dataset dataset = ReadDataset(path, ReaderOptions(ecd_width, ecd_height));
        int64_t first_t_ns = 0;
        if (dataset.events_path) {
          EventBuffer first;
          if (OpenDatasetEvents(dataset)->Read(1, &first) == 1) first_t_ns = first.t_ns[0];
        }
        const TimedPose initial = ResolveInitialPose(dataset, std::nullopt, first_t_ns);
        return py::make_tuple(initial.t_ns, PoseToArray(initial.world_from_cam));
      },
      py::arg("path"), py::arg("ecd_width") = 240, py::arg("ecd_height") = 180,
      "The pose evloc-track starts a dataset from (its first ground-truth pose) and its time.");

  // Trajectories (TUM files, evloc's reader and atomic writer).
  m.def(
      "read_tum",
      [](const std::filesystem::path& path) { return TrajectoryToArrays(ReadTumTrajectory(path)); },
      py::arg("path"));
  m.def(
      "write_tum",
      [](const std::filesystem::path& path, const Int64Array& t_ns,
         const py::array_t<double, py::array::c_style | py::array::forcecast>& poses) {
        WriteTumTrajectory(path, TrajectoryFromArrays(t_ns, poses));
      },
      py::arg("path"), py::arg("t_ns"), py::arg("poses"));
  m.def(
      "format_tum",
      [](const Int64Array& t_ns,
         const py::array_t<double, py::array::c_style | py::array::forcecast>& poses) {
        return FormatTumTrajectory(TrajectoryFromArrays(t_ns, poses));
      },
      py::arg("t_ns"), py::arg("poses"));

  // Tracking.
  m.attr("status_names") = py::make_tuple("TRACKING", "LOST", "INITIALIZING", "RELOCALIZING");
  m.def(
      "check_tracking_flags",
      [](const std::vector<std::string>& flags) { TrackingOptionsFromFlags(flags); },
      py::arg("flags"));
  py::class_<PyTracker>(m, "Tracker", "The tracker of evloc-track and the service.")
      .def(py::init<PyMap&, const py::dict&, const std::vector<std::string>&>(), py::arg("map"),
           py::arg("camera"), py::arg("flags"))
      .def("reset", &PyTracker::Reset, py::arg("pose"), py::arg("t_ns"))
      .def("start_without_pose", &PyTracker::StartWithoutPose, py::arg("t_ns"))
      .def("add_events", &PyTracker::AddEvents, py::arg("t"), py::arg("x"), py::arg("y"),
           py::arg("p"))
      .def("advance_to", &PyTracker::AdvanceTo, py::arg("t_ns"))
      .def_property_readonly("status", &PyTracker::status);
  m.def(
      "track_events",
      [](PyMap& map, const py::dict& camera, const Int64Array& t_ns, const Uint16Array& x,
         const Uint16Array& y, const Int8Array& polarity, const py::object& initial_pose,
         int64_t initial_t_ns, const std::vector<std::string>& flags) {
        const Camera checked_camera = CameraFromDict(camera);
        const tracking::OfflineTrackingOptions options = TrackingOptionsFromFlags(flags);
        const std::optional<Rigid3d> initial = OptionalPose(initial_pose);
        const EventBuffer events = EventsFromArrays(t_ns, x, y, polarity);
        BufferEventReader reader(events);
        const VisibilityIndex* visibility = map.Visibility();
        tracking::OfflineTrackingResult result;
        {
          py::gil_scoped_release release;
          result = tracking::TrackEventStream(reader, *map.map, visibility, checked_camera, initial,
                                              initial_t_ns, options);
        }
        return ResultToDict(result);
      },
      py::arg("map"), py::arg("camera"), py::arg("t"), py::arg("x"), py::arg("y"), py::arg("p"),
      py::arg("initial_pose"), py::arg("initial_t_ns"), py::arg("flags"));
  m.def(
      "track_command",
      [](const std::vector<std::string>& arguments) {
        const tracking::TrackCommandOptions options = tracking::ParseTrackCommandLine(arguments);
        tracking::OfflineTrackingResult result;
        std::ostringstream log;
        {
          py::gil_scoped_release release;
          result = tracking::RunTrackCommand(options, log);
        }
        py::dict out = ResultToDict(result);
        out["log"] = log.str();
        return out;
      },
      py::arg("arguments"),
      "Runs evloc-track with these arguments (the same parser, run and output files).");
}
