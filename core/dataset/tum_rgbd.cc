#include "core/dataset/tum_rgbd.h"

#include <algorithm>
#include <string>
#include <tuple>

#include <opencv2/imgcodecs.hpp>

#include "core/camera/calibration_file.h"
#include "core/common/error.h"
#include "core/trajectory/tum_io.h"

namespace evloc {
namespace fs = std::filesystem;

bool IsTumRgbdFolder(const fs::path& root) {
  std::error_code error;
  return fs::is_directory(root, error) &&
         fs::is_regular_file(root / dataset_files::kRgbTxt, error) &&
         !fs::exists(root / dataset_files::kImagesTxt, error);
}

Dataset ReadTumRgbdDataset(const fs::path& root) {
  if (!IsTumRgbdFolder(root)) {
    throw InvalidArgumentError("'" + root.string() + "' is not a TUM RGB-D folder (it needs " +
                               dataset_files::kRgbTxt + " and no " + dataset_files::kImagesTxt +
                               ").");
  }
  Dataset dataset;
  dataset.root = root;
  dataset.layout = DatasetLayout::kTumRgbd;
  dataset.depth_units_per_metre = kTumDepthUnitsPerMetre;
  dataset.images = ReadTimedFileList(root / dataset_files::kRgbTxt, root);
  if (fs::exists(root / dataset_files::kDepthTxt)) {
    dataset.depth = ReadTimedFileList(root / dataset_files::kDepthTxt, root);
  }
  CheckListedFilesExist(dataset);
  if (fs::exists(root / dataset_files::kCalibYaml)) {
    dataset.camera = ReadCalibrationFile(root / dataset_files::kCalibYaml, 0, 0);
  } else if (fs::exists(root / dataset_files::kCalibTxt)) {
    if (dataset.images.empty()) {
      throw InvalidArgumentError("TUM RGB-D folder '" + root.string() +
                                 "' lists no colour image: the size of the camera of calib.txt "
                                 "is taken from the first one.");
    }
    const cv::Mat first = cv::imread(dataset.images.front().path.string(), cv::IMREAD_UNCHANGED);
    if (first.empty()) {
      throw IoError("cannot read image '" + dataset.images.front().path.string() + "'.");
    }
    dataset.camera = ReadEcdCalibration(root / dataset_files::kCalibTxt, first.cols, first.rows);
  } else {
    throw InvalidArgumentError(
        "TUM RGB-D folder '" + root.string() + "' has neither " + dataset_files::kCalibYaml +
        " nor " + dataset_files::kCalibTxt +
        ": write calib.txt as one line `fx fy cx cy k1 k2 p1 p2 k3` with the benchmark's "
        "intrinsics (freiburg1: 517.3 516.5 318.6 255.3 0.2624 -0.9531 -0.0054 0.0026 1.1633; "
        "freiburg2: 520.9 521.0 325.1 249.7 0.2312 -0.7849 -0.0033 -0.0001 0.9172; freiburg3: "
        "535.4 539.2 320.1 247.6 0 0 0 0 0).");
  }
  if (fs::exists(root / dataset_files::kGroundTruthTxt)) {
    dataset.ground_truth = ReadTumTrajectory(root / dataset_files::kGroundTruthTxt);
  }
  return dataset;
}

std::vector<TimeAssociation> AssociateByTime(const std::vector<TimedFile>& first,
                                             const std::vector<TimedFile>& second,
                                             int64_t max_difference_ns) {
  if (max_difference_ns < 0) {
    throw InvalidArgumentError("AssociateByTime: the tolerance must not be negative, got " +
                               std::to_string(max_difference_ns) + " ns");
  }
  // Candidates: for each entry of `first`, the entries of `second` within the tolerance (both
  // lists are time-ordered, so a sliding window finds them in linear time plus the candidates).
  std::vector<std::tuple<uint64_t, size_t, size_t>> candidates;
  size_t begin = 0;
  for (size_t i = 0; i < first.size(); ++i) {
    const int64_t t = first[i].t_ns;
    while (begin < second.size() &&
           second[begin]
               .t_ns<t&& static_cast<uint64_t>(t) -
                     static_cast<uint64_t>(
                         second[begin].t_ns)> static_cast<uint64_t>(max_difference_ns)) {
      ++begin;
    }
    for (size_t j = begin; j < second.size(); ++j) {
      const int64_t u = second[j].t_ns;
      const uint64_t difference = u >= t ? static_cast<uint64_t>(u) - static_cast<uint64_t>(t)
                                         : static_cast<uint64_t>(t) - static_cast<uint64_t>(u);
      if (u > t && difference > static_cast<uint64_t>(max_difference_ns)) break;
      if (difference <= static_cast<uint64_t>(max_difference_ns)) {
        candidates.emplace_back(difference, i, j);
      }
    }
  }
  std::sort(candidates.begin(), candidates.end());
  std::vector<bool> first_used(first.size(), false);
  std::vector<bool> second_used(second.size(), false);
  std::vector<TimeAssociation> pairs;
  for (const auto& [difference, i, j] : candidates) {
    if (first_used[i] || second_used[j]) continue;
    first_used[i] = true;
    second_used[j] = true;
    pairs.push_back({i, j});
  }
  std::sort(pairs.begin(), pairs.end(),
            [](const TimeAssociation& a, const TimeAssociation& b) { return a.first < b.first; });
  return pairs;
}

}  // namespace evloc
