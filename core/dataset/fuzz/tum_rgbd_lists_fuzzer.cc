// libFuzzer target: the list parsers of the TUM RGB-D layout (docs/reliability.md): rgb.txt and
// depth.txt (ParseTimedFileList), groundtruth.txt (ParseTumTrajectory), and the association of
// the two lists (AssociateByTime). The input is split at its first NUL byte into the two lists;
// its first byte also chooses the tolerance. Checks: a list that parses has strictly increasing
// times; the association uses each entry at most once, within the tolerance, in the order of the
// first list; the trajectory is time-ordered with unit quaternions.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/common/error.h"
#include "core/dataset/dataset.h"
#include "core/dataset/tum_rgbd.h"
#include "core/trajectory/tum_io.h"

namespace {

// Parses a list; false when it is malformed (a ParseError, the only error allowed).
bool Parse(const std::string& text, std::vector<evloc::TimedFile>* files) {
  try {
    *files = evloc::ParseTimedFileList(text, "fuzz.txt", "/root");
  } catch (const evloc::ParseError&) {
    return false;
  }
  for (size_t i = 1; i < files->size(); ++i) {
    if ((*files)[i].t_ns <= (*files)[i - 1].t_ns) std::abort();
  }
  return true;
}

void CheckTrajectory(const std::string& text) {
  try {
    const evloc::Trajectory trajectory = evloc::ParseTumTrajectory(text, "fuzz_gt.txt");
    int64_t previous = 0;
    bool first = true;
    for (const evloc::TimedPose& pose : trajectory.poses()) {
      if (!first && pose.t_ns <= previous) std::abort();
      first = false;
      previous = pose.t_ns;
      const double norm = pose.world_from_cam.rotation.norm();
      if (!(std::abs(norm - 1.0) < 1e-9)) std::abort();
      if (!pose.world_from_cam.translation.allFinite()) std::abort();
    }
  } catch (const evloc::ParseError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const int64_t tolerance_ns = static_cast<int64_t>(data[0]) * 1'000'000;
  const std::string text(reinterpret_cast<const char*>(data) + 1, size - 1);
  const size_t split = text.find('\0');
  const std::string rgb = text.substr(0, split);
  const std::string depth = split == std::string::npos ? std::string() : text.substr(split + 1);
  CheckTrajectory(rgb);
  std::vector<evloc::TimedFile> rgb_files;
  std::vector<evloc::TimedFile> depth_files;
  if (!Parse(rgb, &rgb_files) || !Parse(depth, &depth_files)) return 0;
  const std::vector<evloc::TimeAssociation> pairs =
      evloc::AssociateByTime(rgb_files, depth_files, tolerance_ns);
  std::vector<bool> used(depth_files.size(), false);
  for (size_t k = 0; k < pairs.size(); ++k) {
    const auto& pair = pairs[k];
    if (pair.first >= rgb_files.size() || pair.second >= depth_files.size()) std::abort();
    if (k > 0 && pair.first <= pairs[k - 1].first) std::abort();
    if (used[pair.second]) std::abort();
    used[pair.second] = true;
    const __int128 difference = static_cast<__int128>(rgb_files[pair.first].t_ns) -
                                static_cast<__int128>(depth_files[pair.second].t_ns);
    if (difference > tolerance_ns || difference < -tolerance_ns) std::abort();
  }
  return 0;
}
