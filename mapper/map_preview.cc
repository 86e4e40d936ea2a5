#include "mapper/map_preview.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <utility>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "core/common/error.h"

namespace evloc::mapper {

namespace fs = std::filesystem;

cv::Mat ReadImage(const fs::path& path, int flags) {
  cv::Mat image = cv::imread(path.string(), flags);
  if (image.empty()) throw IoError("cannot read image " + path.string());
  return image;
}

cv::Mat RenderPreview(const Map& map, const fs::path& image_dir, int num_keyframes) {
  std::vector<size_t> chosen;
  const size_t count = std::min<size_t>(map.keyframes.size(), num_keyframes);
  for (size_t i = 0; i < count; ++i) {
    chosen.push_back(count == 1 ? 0 : i * (map.keyframes.size() - 1) / (count - 1));
  }
  std::vector<cv::Mat> tiles;
  for (const size_t index : chosen) {
    const Keyframe& keyframe = map.keyframes[index];
    cv::Mat image = ReadImage(image_dir / keyframe.image_name, cv::IMREAD_COLOR);
    cv::Mat gray;
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
    cv::cvtColor(gray, image, cv::COLOR_GRAY2BGR);
    const Camera& camera = map.cameras[keyframe.camera_index];
    std::vector<std::pair<Eigen::Vector2d, double>> projected;
    for (const uint32_t point : keyframe.visible_points) {
      const Eigen::Vector3d in_cam = keyframe.cam_from_world * map.positions[point].cast<double>();
      Eigen::Vector2d pixel;
      if (camera.Project(in_cam, &pixel) && camera.IsInside(pixel)) {
        projected.emplace_back(pixel, in_cam.z());
      }
    }
    if (!projected.empty()) {
      std::vector<double> depths;
      for (const auto& [pixel, depth] : projected) depths.push_back(depth);
      std::sort(depths.begin(), depths.end());
      const double near = depths[depths.size() / 20];
      const double far = std::max(depths[depths.size() * 19 / 20], near * (1.0 + 1e-6));
      cv::Mat levels(1, static_cast<int>(projected.size()), CV_8U);
      for (size_t i = 0; i < projected.size(); ++i) {
        const double t = std::clamp((projected[i].second - near) / (far - near), 0.0, 1.0);
        levels.at<uint8_t>(0, static_cast<int>(i)) = static_cast<uint8_t>(255.0 * (1.0 - t));
      }
      cv::Mat colors;
      cv::applyColorMap(levels, colors, cv::COLORMAP_JET);
      for (size_t i = 0; i < projected.size(); ++i) {
        const cv::Point at(static_cast<int>(std::lround(projected[i].first.x())),
                           static_cast<int>(std::lround(projected[i].first.y())));
        image.at<cv::Vec3b>(at) = colors.at<cv::Vec3b>(0, static_cast<int>(i));
      }
    }
    cv::putText(image, keyframe.image_name, cv::Point(5, 15), cv::FONT_HERSHEY_SIMPLEX, 0.45,
                cv::Scalar(255, 255, 255), 1);
    tiles.push_back(image);
  }
  if (tiles.empty()) return cv::Mat(1, 1, CV_8UC3, cv::Scalar(0, 0, 0));
  const int columns = tiles.size() > 1 ? 2 : 1;
  const int rows = static_cast<int>((tiles.size() + columns - 1) / columns);
  const int width = tiles[0].cols;
  const int height = tiles[0].rows;
  cv::Mat canvas(rows * height, columns * width, CV_8UC3, cv::Scalar(0, 0, 0));
  for (size_t i = 0; i < tiles.size(); ++i) {
    const int row = static_cast<int>(i) / columns;
    const int column = static_cast<int>(i) % columns;
    tiles[i].copyTo(canvas(cv::Rect(column * width, row * height, width, height)));
  }
  return canvas;
}

}  // namespace evloc::mapper
