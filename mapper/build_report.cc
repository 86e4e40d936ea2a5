#include "mapper/build_report.h"

#include <sys/resource.h>

#include <algorithm>

#include <nlohmann/json.hpp>

namespace evloc::mapper {
namespace {

using Clock = std::chrono::steady_clock;

// CPU seconds (user + system) used so far by this process and its waited-for children.
double ProcessCpuSeconds() {
  double total = 0.0;
  for (const int who : {RUSAGE_SELF, RUSAGE_CHILDREN}) {
    rusage usage{};
    if (getrusage(who, &usage) != 0) continue;
    total += static_cast<double>(usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) +
             1e-6 * static_cast<double>(usage.ru_utime.tv_usec + usage.ru_stime.tv_usec);
  }
  return total;
}

}  // namespace

uint64_t PeakResidentBytes() {
  uint64_t peak = 0;
  for (const int who : {RUSAGE_SELF, RUSAGE_CHILDREN}) {
    rusage usage{};
    if (getrusage(who, &usage) != 0) continue;
    peak = std::max<uint64_t>(peak, static_cast<uint64_t>(usage.ru_maxrss) * 1024);  // KiB
  }
  return peak;
}

StageClock::StageClock(ProgressListener* listener, MapBuildReport* report)
    : listener_(listener), report_(report), start_(Clock::now()) {}

double StageClock::Elapsed() const {
  return std::chrono::duration<double>(Clock::now() - start_).count();
}

void StageClock::Progress(const std::string& stage, size_t done, size_t total) const {
  if (listener_ != nullptr) listener_->OnProgress({stage, done, total, Elapsed()});
}

void StageClock::Run(const std::string& stage, const std::function<bool()>& body) const {
  Progress(stage, 0, 1);
  const Clock::time_point begin = Clock::now();
  const double cpu_begin = ProcessCpuSeconds();
  const bool reused = body();
  report_->timings.push_back({stage, std::chrono::duration<double>(Clock::now() - begin).count(),
                              ProcessCpuSeconds() - cpu_begin, reused, PeakResidentBytes()});
  Progress(stage, 1, 1);
}

double MapBuildReport::TotalSeconds(const std::string& prefix) const {
  double total = 0.0;
  for (const StageTiming& timing : timings) {
    if (timing.stage.rfind(prefix, 0) == 0) total += timing.seconds;
  }
  return total;
}

double MapBuildReport::TotalCpuSeconds(const std::string& prefix) const {
  double total = 0.0;
  for (const StageTiming& timing : timings) {
    if (timing.stage.rfind(prefix, 0) == 0) total += timing.cpu_seconds;
  }
  return total;
}

namespace {

// The geo anchor and its alignment, or null.
nlohmann::json GeoReferenceToJson(const MapBuildReport& report) {
  if (!report.geo_anchor) return nullptr;
  const GeoAnchor& anchor = *report.geo_anchor;
  const Eigen::Quaterniond& q = anchor.enu_from_map.rotation;
  const Eigen::Vector3d& t = anchor.enu_from_map.translation;
  nlohmann::json json = {
      {"source", anchor.source},
      {"inputs", report.geo_inputs},
      {"latitude_deg", anchor.origin.latitude_deg},
      {"longitude_deg", anchor.origin.longitude_deg},
      {"altitude_m", anchor.origin.altitude_m},
      {"enu_from_map",
       {{"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}}, {"translation", {t.x(), t.y(), t.z()}}}},
      {"horizontal_sigma_m", anchor.horizontal_sigma_m},
      {"vertical_sigma_m", anchor.vertical_sigma_m}};
  if (report.geo_alignment) {
    const GeoAlignment& alignment = *report.geo_alignment;
    json["alignment"] = {{"points", alignment.inliers.size()},
                         {"inliers", alignment.num_inliers},
                         {"rms_m", alignment.rms_m},
                         {"horizontal_rms_m", alignment.horizontal_rms_m},
                         {"vertical_rms_m", alignment.vertical_rms_m},
                         {"median_m", alignment.median_m},
                         {"max_m", alignment.max_m},
                         {"similarity_scale", alignment.scale}};
  }
  return json;
}

}  // namespace

std::string MapBuildReportToJson(const MapBuildReport& report) {
  nlohmann::json json;
  json["images"] = report.num_images;
  json["images_registered"] = report.num_registered;
  json["images_without_pose"] = report.images_without_pose;
  json["calibration_notes"] = report.calibration_notes;
  json["keyframes"] = report.num_keyframes;
  json["sparse_points"] = report.num_sparse_points;
  json["keyframe_points"] = report.num_keyframe_points;
  json["surface_gradients"] = report.num_surface_gradients;
  json["points"] = report.num_points;
  json["voxel_size"] = report.voxel_size;
  json["colmap_mean_reprojection_error_px"] = report.colmap_mean_reprojection_error_px;
  json["pose_source"] = report.pose_source;
  json["matcher"] = report.matcher;
  json["colmap_version"] = report.colmap_version;
  if (report.alignment_rms_m) {
    nlohmann::json alignment;
    alignment["images"] = report.alignment_num_images;
    alignment["rms_m"] = *report.alignment_rms_m;
    alignment["max_m"] = *report.alignment_max_m;
    alignment["rotation_rms_deg"] = *report.alignment_rotation_rms_deg;
    alignment["rotation_max_deg"] = *report.alignment_rotation_max_deg;
    alignment["scale"] = *report.alignment_scale;
    alignment["reference_spread_m"] = *report.alignment_reference_spread_m;
    alignment["rms_fraction_of_spread"] =
        *report.alignment_reference_spread_m > 0.0
            ? nlohmann::json(*report.alignment_rms_m / *report.alignment_reference_spread_m)
            : nlohmann::json(nullptr);
    alignment["within_limits"] = report.alignment_warning.empty();
    alignment["warning"] = report.alignment_warning;
    const Eigen::Quaterniond& q = report.world_from_model.rotation;
    alignment["world_from_model"] = {
        {"scale", report.world_from_model.scale},
        {"rotation_wxyz", {q.w(), q.x(), q.y(), q.z()}},
        {"translation",
         {report.world_from_model.translation.x(), report.world_from_model.translation.y(),
          report.world_from_model.translation.z()}}};
    json["alignment"] = alignment;
  } else {
    json["alignment"] = nullptr;
  }
  if (report.relocalization) {
    const RelocalizationDataStatistics& relocalization = *report.relocalization;
    json["relocalization"] = {{"landmarks", relocalization.num_landmarks},
                              {"features_kept", relocalization.num_features_kept},
                              {"features_extracted", relocalization.num_features_extracted},
                              {"matched_pairs", relocalization.num_matched_pairs},
                              {"verified_matches", relocalization.num_verified_matches},
                              {"bytes_added", relocalization.bytes_added}};
  } else {
    json["relocalization"] = nullptr;
  }
  json["relocalization_warning"] = report.relocalization_warning;
  json["geo_reference"] = GeoReferenceToJson(report);
  nlohmann::json timings = nlohmann::json::array();
  for (const StageTiming& timing : report.timings) {
    timings.push_back({{"stage", timing.stage},
                       {"seconds", timing.seconds},
                       {"cpu_seconds", timing.cpu_seconds},
                       {"reused", timing.reused},
                       {"peak_rss_mb", static_cast<double>(timing.peak_rss_bytes) / (1 << 20)}});
  }
  json["timings"] = timings;
  json["colmap_seconds"] = report.TotalSeconds("colmap");
  json["semidense_seconds"] = report.TotalSeconds("semidense");
  json["colmap_cpu_seconds"] = report.TotalCpuSeconds("colmap");
  json["semidense_cpu_seconds"] = report.TotalCpuSeconds("semidense");
  return json.dump(2) + "\n";
}

}  // namespace evloc::mapper
