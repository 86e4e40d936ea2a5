// The figures of docs/accuracy.md, "Relocalization from one image": the temple map of the even
// views (in memory, with the calibrated poses), every odd view located `repeats` times, and photos
// of other scenes; accuracy against the calibrated poses and the time per locate.
//   taskset -c 1 build/localizer/relocalization/evloc_locate_benchmark [repeats (default 5)]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <string>
#include <vector>

#include "core/common/thread_cpu_time.h"
#include "localizer/relocalization/image_locator.h"
#include "localizer/relocalization/testing/temple_map.h"

namespace evloc::relocalization {
namespace {

// The value below which `fraction` of the sorted values lie.
double Percentile(std::vector<double> values, double fraction) {
  std::sort(values.begin(), values.end());
  const size_t index = std::min(values.size() - 1, static_cast<size_t>(fraction * values.size()));
  return values[index];
}

// CPU time of this thread, milliseconds.
double ThreadCpuMs() { return static_cast<double>(ThreadCpuTimeNs()) * 1e-6; }

// CPU times of every locate, milliseconds.
std::vector<double>& CpuTimes() {
  static std::vector<double> times;
  return times;
}

// Locates once and returns the wall time, milliseconds (the CPU time goes to CpuTimes()).
double TimedLocate(const Map& map, const Camera& camera, const cv::Mat& image,
                   LocateResult* result) {
  const double cpu_start = ThreadCpuMs();
  const auto start = std::chrono::steady_clock::now();
  *result = LocateImage(map, camera, image, LocateOptions());
  CpuTimes().push_back(ThreadCpuMs() - cpu_start);
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

int Run(int repeats) {
  const testing::TempleFixture* fixture = testing::SharedTemple();
  if (fixture == nullptr) {
    std::printf("%s\n", evloc::testing::MissingDataReason(testing::kTempleParameters).c_str());
    return 1;
  }
  const Map& map = fixture->map;
  std::printf("map: %zu keyframes, %zu edge points, %zu landmarks\n", map.keyframes.size(),
              map.size(), map.relocalization->landmarks.size());
  std::vector<double> times;
  int queries = 0, found = 0, found_within = 0, found_far = 0;
  double worst_translation = 0, worst_rotation = 0, worst_relative = 0;
  for (int view = 1; view < 16; view += 2) {
    const Rigid3d truth = fixture->temple.views[view].cam_from_world.Inverse();
    // Distance from the camera to the temple: the median depth of the landmarks it sees.
    std::vector<double> depths;
    for (const Eigen::Vector3f& landmark : map.relocalization->landmarks) {
      const double z = (fixture->temple.views[view].cam_from_world * landmark.cast<double>()).z();
      if (z > 0) depths.push_back(z);
    }
    const double distance = Percentile(depths, 0.5);
    LocateResult result;
    for (int r = 0; r < repeats; ++r) {
      times.push_back(
          TimedLocate(map, fixture->temple.camera, fixture->temple.images[view], &result));
    }
    ++queries;
    const double translation = (result.world_from_cam.translation - truth.translation).norm();
    const double rotation =
        AngleBetween(result.world_from_cam.rotation, truth.rotation) * 180 / M_PI;
    const bool is_found = result.status == LocateStatus::kFound;
    // The PnP pose exists when the verification ran (score set), FOUND or not.
    const double pnp_error =
        (result.pnp_world_from_cam.translation - truth.translation).norm() * 1000;
    std::printf(
        "%s: %s, %d inliers of %d, score %.3f, error %.2f mm (%.3f %% of %.3f m) %.3f deg; PnP "
        "pose error %.2f mm\n",
        fixture->temple.views[view].name.c_str(), LocateStatusName(result.status), result.inliers,
        result.correspondences, result.score, is_found ? translation * 1000 : NAN,
        is_found ? translation / distance * 100 : NAN, distance, is_found ? rotation : NAN,
        result.score != 0 ? pnp_error : NAN);
    if (!is_found) continue;
    ++found;
    found_within += translation <= 0.02 && rotation <= 1.0;
    found_far += translation > 0.10;
    worst_translation = std::max(worst_translation, translation);
    worst_rotation = std::max(worst_rotation, rotation);
    worst_relative = std::max(worst_relative, translation / distance);
  }
  std::printf(
      "temple: %d/%d FOUND, %d within 2 cm / 1 deg, %d farther than 10 cm; worst FOUND %.2f mm "
      "(%.3f %% of the object distance), %.3f deg\n",
      found, queries, found_within, found_far, worst_translation * 1000, worst_relative * 100,
      worst_rotation);
  int others = 0, others_found = 0;
  for (const char* photo :
       {"strecha/fountain-P11/images/0000.jpg", "strecha/fountain-P11/images/0003.jpg",
        "strecha/fountain-P11/images/0005.jpg", "strecha/fountain-P11/images/0007.jpg",
        "strecha/fountain-P11/images/0010.jpg", "middlebury/dinoSparseRing/dinoSR0001.png",
        "middlebury/dinoSparseRing/dinoSR0004.png", "middlebury/dinoSparseRing/dinoSR0007.png",
        "middlebury/dinoSparseRing/dinoSR0010.png", "middlebury/dinoSparseRing/dinoSR0013.png"}) {
    const auto path = evloc::testing::SharedDataFile(photo);
    if (!path) continue;
    const cv::Mat image = features::testing::ReadGrey(*path, 640);
    cv::Mat query(480, 640, CV_8UC1, cv::Scalar(0));
    const int rows = std::min(480, image.rows);
    image(cv::Rect(0, 0, 640, rows)).copyTo(query(cv::Rect(0, 0, 640, rows)));
    LocateResult result;
    times.push_back(TimedLocate(map, fixture->temple.camera, query, &result));
    ++others;
    others_found += result.status == LocateStatus::kFound;
    std::printf("%s: %s; %s\n", photo, LocateStatusName(result.status), result.reason.c_str());
  }
  std::printf("other scenes: %d/%d FOUND\n", others_found, others);
  std::printf(
      "time per locate over %zu locates: wall median %.1f ms, p99 %.1f ms; CPU median %.1f ms, "
      "p99 %.1f ms\n",
      times.size(), Percentile(times, 0.5), Percentile(times, 0.99), Percentile(CpuTimes(), 0.5),
      Percentile(CpuTimes(), 0.99));
  return 0;
}

}  // namespace
}  // namespace evloc::relocalization

int main(int argc, char** argv) {
  return evloc::relocalization::Run(argc > 1 ? std::atoi(argv[1]) : 5);
}
