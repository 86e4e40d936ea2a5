#include "mapper/semidense_depth.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <exception>
#include <limits>
#include <numbers>
#include <optional>
#include <thread>

#include <opencv2/imgproc.hpp>

#include "core/common/error.h"
#include "mapper/parallel_for.h"

namespace evloc::mapper {
namespace {

constexpr double kInfiniteCost = std::numeric_limits<double>::infinity();
// Half-width of the intensity pattern compared along the epipolar lines (5 samples).
constexpr int kPatternHalfWidth = 2;
constexpr int kPatternSize = 2 * kPatternHalfWidth + 1;

double Radians(double degrees) { return degrees * std::numbers::pi / 180.0; }

// Bilinear interpolation of a CV_32F image; false outside [0, w-1] x [0, h-1].
bool Sample(const cv::Mat& image, double x, double y, double* value) {
  if (!(x >= 0.0 && y >= 0.0 && x <= image.cols - 1 && y <= image.rows - 1)) return false;
  const int x0 = std::min(static_cast<int>(x), image.cols - 2);
  const int y0 = std::min(static_cast<int>(y), image.rows - 2);
  const double ax = x - x0;
  const double ay = y - y0;
  const float* row0 = image.ptr<float>(y0);
  const float* row1 = image.ptr<float>(y0 + 1);
  *value = (1.0 - ay) * ((1.0 - ax) * row0[x0] + ax * row0[x0 + 1]) +
           ay * ((1.0 - ax) * row1[x0] + ax * row1[x0 + 1]);
  return true;
}

// One stereo hypothesis for a pixel.
struct Hypothesis {
  double inverse_depth = 0.0;
  double variance = 0.0;
};

// Precomputed relation between the keyframe and one neighbour.
struct StereoPair {
  const DepthFrame* neighbour = nullptr;
  // neighbour_from_keyframe rotation and translation.
  Eigen::Matrix3d rotation;
  Eigen::Vector3d translation;
  // Neighbour's optical centre in keyframe coordinates.
  Eigen::Vector3d neighbour_center_in_keyframe;
};

// Epipolar search of one keyframe pixel in one neighbour (docs/mapper.md, "Semi-dense depth per
// keyframe").
bool SearchEpipolar(const DepthFrame& keyframe, const StereoPair& pair,
                    const Eigen::Vector2d& pixel, const Eigen::Vector3d& ray,
                    const Eigen::Vector2d& gradient_direction, double gradient_magnitude,
                    double min_inverse_depth, double max_inverse_depth,
                    const SemiDenseOptions& options, Hypothesis* hypothesis) {
  const Camera& neighbour_camera = pair.neighbour->camera;
  const Eigen::Matrix3d& rotation = pair.rotation;
  const Eigen::Vector3d& translation = pair.translation;
  const double mid_depth = 2.0 / (min_inverse_depth + max_inverse_depth);

  // Epipolar direction in the keyframe: move the mid-depth point towards the neighbour centre.
  const Eigen::Vector3d mid_point = ray * mid_depth;
  const Eigen::Vector3d towards = pair.neighbour_center_in_keyframe - mid_point;
  if (towards.norm() < 1e-12) return false;
  Eigen::Vector2d shifted;
  if (!keyframe.camera.Project(mid_point + 0.01 * mid_depth * towards.normalized(), &shifted)) {
    return false;
  }
  Eigen::Vector2d keyframe_direction = shifted - pixel;
  if (keyframe_direction.norm() < 1e-9) return false;
  keyframe_direction.normalize();
  const double gradient_along_line = std::abs(gradient_direction.dot(keyframe_direction));
  if (gradient_along_line < std::cos(Radians(options.max_gradient_epipolar_angle_deg))) {
    return false;
  }

  // The searched segment: inverse depth rho maps to the homogeneous point R r + t rho.
  const Eigen::Vector3d rotated_ray = rotation * ray;
  Eigen::Vector2d far_end;
  Eigen::Vector2d near_end;
  if (!neighbour_camera.Project(rotated_ray + translation * min_inverse_depth, &far_end) ||
      !neighbour_camera.Project(rotated_ray + translation * max_inverse_depth, &near_end)) {
    return false;
  }
  const double length = (near_end - far_end).norm();
  if (length < 1.0 || length > options.max_search_length_px) return false;
  const Eigen::Vector2d neighbour_direction = (near_end - far_end) / length;

  // Orient the keyframe direction like the neighbour's: a step along it at mid depth must move
  // the neighbour projection forward along the segment.
  Eigen::Vector3d stepped_ray;
  if (!keyframe.camera.Unproject(pixel + keyframe_direction, &stepped_ray)) return false;
  Eigen::Vector2d mid_projection;
  Eigen::Vector2d stepped_projection;
  if (!neighbour_camera.Project(rotation * (ray * mid_depth) + translation, &mid_projection) ||
      !neighbour_camera.Project(rotation * (stepped_ray * mid_depth) + translation,
                                &stepped_projection)) {
    return false;
  }
  if ((stepped_projection - mid_projection).dot(neighbour_direction) < 0.0) {
    keyframe_direction = -keyframe_direction;
  }

  // Gradient direction predicted in the neighbour by the relative rotation.
  Eigen::Vector3d gradient_ray;
  if (!keyframe.camera.Unproject(pixel + gradient_direction, &gradient_ray)) return false;
  Eigen::Vector2d rotated_pixel;
  Eigen::Vector2d rotated_gradient_pixel;
  if (!neighbour_camera.Project(rotated_ray, &rotated_pixel) ||
      !neighbour_camera.Project(rotation * gradient_ray, &rotated_gradient_pixel)) {
    return false;
  }
  Eigen::Vector2d predicted_gradient = rotated_gradient_pixel - rotated_pixel;
  if (predicted_gradient.norm() < 1e-9) return false;
  predicted_gradient.normalize();
  const double min_orientation_cos =
      std::cos(Radians(options.max_gradient_orientation_difference_deg));

  // The keyframe pattern, mean-free.
  std::array<double, kPatternSize> keyframe_pattern;
  double keyframe_mean = 0.0;
  for (int s = -kPatternHalfWidth; s <= kPatternHalfWidth; ++s) {
    const Eigen::Vector2d at = pixel + s * keyframe_direction;
    if (!Sample(keyframe.intensity, at.x(), at.y(), &keyframe_pattern[s + kPatternHalfWidth])) {
      return false;
    }
    keyframe_mean += keyframe_pattern[s + kPatternHalfWidth];
  }
  keyframe_mean /= kPatternSize;
  for (double& value : keyframe_pattern) value -= keyframe_mean;

  const int num_samples = static_cast<int>(std::ceil(length / options.search_step_px)) + 1;
  const double inverse_depth_step =
      (max_inverse_depth - min_inverse_depth) / static_cast<double>(num_samples - 1);
  std::vector<double> costs(num_samples, kInfiniteCost);
  std::vector<Eigen::Vector2d> positions(num_samples);
  std::vector<double> gradient_along_epipolar(num_samples, 0.0);
  const DepthFrame& neighbour = *pair.neighbour;
  for (int i = 0; i < num_samples; ++i) {
    const double inverse_depth = min_inverse_depth + i * inverse_depth_step;
    Eigen::Vector2d position;
    if (!neighbour_camera.Project(rotated_ray + translation * inverse_depth, &position)) continue;
    positions[i] = position;
    double gradient_x = 0.0;
    double gradient_y = 0.0;
    if (!Sample(neighbour.gradient_x, position.x(), position.y(), &gradient_x) ||
        !Sample(neighbour.gradient_y, position.x(), position.y(), &gradient_y)) {
      continue;
    }
    const Eigen::Vector2d neighbour_gradient(gradient_x, gradient_y);
    const double neighbour_magnitude = neighbour_gradient.norm();
    if (neighbour_magnitude * options.max_gradient_modulus_ratio < gradient_magnitude ||
        neighbour_magnitude > gradient_magnitude * options.max_gradient_modulus_ratio) {
      continue;
    }
    if (neighbour_gradient.dot(predicted_gradient) < min_orientation_cos * neighbour_magnitude) {
      continue;
    }
    std::array<double, kPatternSize> pattern;
    double mean = 0.0;
    bool inside = true;
    for (int s = -kPatternHalfWidth; s <= kPatternHalfWidth && inside; ++s) {
      const Eigen::Vector2d at = position + s * neighbour_direction;
      inside = Sample(neighbour.intensity, at.x(), at.y(), &pattern[s + kPatternHalfWidth]);
      mean += pattern[s + kPatternHalfWidth];
    }
    if (!inside) continue;
    mean /= kPatternSize;
    double cost = 0.0;
    for (int k = 0; k < kPatternSize; ++k) {
      const double difference = keyframe_pattern[k] - (pattern[k] - mean);
      cost += difference * difference;
    }
    const double modulus_difference = neighbour_magnitude - gradient_magnitude;
    costs[i] = cost / kPatternSize +
               options.gradient_cost_weight * modulus_difference * modulus_difference;
    gradient_along_epipolar[i] = std::abs(neighbour_gradient.dot(neighbour_direction));
  }

  int best = -1;
  for (int i = 0; i < num_samples; ++i) {
    if (costs[i] < kInfiniteCost && (best < 0 || costs[i] < costs[best])) best = i;
  }
  if (best < 0 || costs[best] > options.max_match_cost) return false;
  double second_best = kInfiniteCost;
  for (int i = 0; i < num_samples; ++i) {
    if (std::abs(i - best) > kPatternHalfWidth) second_best = std::min(second_best, costs[i]);
  }
  if (second_best < options.min_second_best_ratio * costs[best]) return false;

  // Sub-sample refinement by a parabola through the best cost and its two neighbours.
  double offset = 0.0;
  if (best > 0 && best + 1 < num_samples && costs[best - 1] < kInfiniteCost &&
      costs[best + 1] < kInfiniteCost) {
    const double curvature = costs[best - 1] - 2.0 * costs[best] + costs[best + 1];
    if (curvature > 0.0) {
      offset = std::clamp(0.5 * (costs[best - 1] - costs[best + 1]) / curvature, -0.5, 0.5);
    }
  }
  const double inverse_depth = min_inverse_depth + (best + offset) * inverse_depth_step;
  if (!(inverse_depth > 0.0)) return false;

  // Inverse depth per pixel along the segment at the match.
  const int lower = std::max(best - 1, 0);
  const int upper = std::min(best + 1, num_samples - 1);
  const double pixel_span = (positions[upper] - positions[lower]).norm();
  if (upper == lower || pixel_span < 1e-9) return false;
  const double inverse_depth_per_pixel = (upper - lower) * inverse_depth_step / pixel_span;

  const double geometric_variance = options.epipolar_sigma_px * options.epipolar_sigma_px /
                                    (gradient_along_line * gradient_along_line);
  const double photometric_gradient = std::max(gradient_along_epipolar[best], 1e-6);
  const double photometric_variance = 2.0 * options.intensity_sigma * options.intensity_sigma /
                                      (photometric_gradient * photometric_gradient);
  const double disparity_variance = geometric_variance + photometric_variance +
                                    options.disparity_sigma_px * options.disparity_sigma_px;
  hypothesis->inverse_depth = inverse_depth;
  hypothesis->variance = inverse_depth_per_pixel * inverse_depth_per_pixel * disparity_variance;
  return true;
}

// Step 4: the largest chi-square-compatible set, fused by inverse-variance weighting.
bool FuseHypotheses(const std::vector<Hypothesis>& hypotheses, const SemiDenseOptions& options,
                    Hypothesis* fused, int* count) {
  size_t best_size = 0;
  double best_inverse_depth = 0.0;
  double best_variance = 0.0;
  for (const Hypothesis& seed : hypotheses) {
    double weight_sum = 0.0;
    double weighted_sum = 0.0;
    size_t size = 0;
    for (const Hypothesis& other : hypotheses) {
      const double difference = seed.inverse_depth - other.inverse_depth;
      if (difference * difference <
          options.chi_square_threshold * (seed.variance + other.variance)) {
        ++size;
        weight_sum += 1.0 / other.variance;
        weighted_sum += other.inverse_depth / other.variance;
      }
    }
    // Larger sets win; among equal sets the more certain one.
    if (size > best_size || (size == best_size && 1.0 / weight_sum < best_variance)) {
      best_size = size;
      best_inverse_depth = weighted_sum / weight_sum;
      best_variance = 1.0 / weight_sum;
    }
  }
  if (best_size < static_cast<size_t>(options.min_compatible_hypotheses)) return false;
  fused->inverse_depth = best_inverse_depth;
  fused->variance = best_variance;
  *count = static_cast<int>(best_size);
  return true;
}

bool Compatible(double inverse_depth_a, double variance_a, double inverse_depth_b,
                double variance_b, double chi_square_threshold) {
  const double difference = inverse_depth_a - inverse_depth_b;
  return difference * difference < chi_square_threshold * (variance_a + variance_b);
}

// Step 5: reject unsupported pixels, smooth, and grow into candidate holes.
std::vector<DepthPixel> Regularize(const DepthFrame& keyframe, std::vector<DepthPixel> pixels,
                                   const std::vector<Eigen::Vector2i>& candidates,
                                   const SemiDenseOptions& options) {
  const int width = keyframe.intensity.cols;
  const int height = keyframe.intensity.rows;
  std::vector<int> index(static_cast<size_t>(width) * height, -1);
  for (size_t i = 0; i < pixels.size(); ++i) {
    index[static_cast<size_t>(pixels[i].pixel.y()) * width + pixels[i].pixel.x()] =
        static_cast<int>(i);
  }
  const auto at = [&](int x, int y) -> int {
    if (x < 0 || y < 0 || x >= width || y >= height) return -1;
    return index[static_cast<size_t>(y) * width + x];
  };
  std::vector<DepthPixel> regularized;
  regularized.reserve(pixels.size());
  for (const DepthPixel& pixel : pixels) {
    int support = 0;
    double weight_sum = 1.0 / pixel.inverse_depth_variance;
    double weighted_sum = pixel.inverse_depth / pixel.inverse_depth_variance;
    for (int dy = -1; dy <= 1; ++dy) {
      for (int dx = -1; dx <= 1; ++dx) {
        if (dx == 0 && dy == 0) continue;
        const int other = at(pixel.pixel.x() + dx, pixel.pixel.y() + dy);
        if (other < 0) continue;
        const DepthPixel& neighbour = pixels[other];
        if (Compatible(pixel.inverse_depth, pixel.inverse_depth_variance, neighbour.inverse_depth,
                       neighbour.inverse_depth_variance, options.chi_square_threshold)) {
          ++support;
          weight_sum += 1.0 / neighbour.inverse_depth_variance;
          weighted_sum += neighbour.inverse_depth / neighbour.inverse_depth_variance;
        }
      }
    }
    if (support < options.min_neighbour_support) continue;
    DepthPixel smoothed = pixel;
    smoothed.inverse_depth = weighted_sum / weight_sum;
    regularized.push_back(smoothed);
  }
  if (options.min_neighbours_to_grow > 0) {
    for (const Eigen::Vector2i& candidate : candidates) {
      if (at(candidate.x(), candidate.y()) >= 0) continue;
      std::vector<const DepthPixel*> around;
      for (int dy = -1; dy <= 1; ++dy) {
        for (int dx = -1; dx <= 1; ++dx) {
          const int other = at(candidate.x() + dx, candidate.y() + dy);
          if (other >= 0) around.push_back(&pixels[other]);
        }
      }
      if (around.size() < static_cast<size_t>(options.min_neighbours_to_grow)) continue;
      // All surrounding estimates must agree with their weighted mean.
      double weight_sum = 0.0;
      double weighted_sum = 0.0;
      double min_variance = kInfiniteCost;
      for (const DepthPixel* neighbour : around) {
        weight_sum += 1.0 / neighbour->inverse_depth_variance;
        weighted_sum += neighbour->inverse_depth / neighbour->inverse_depth_variance;
        min_variance = std::min(min_variance, neighbour->inverse_depth_variance);
      }
      const double mean = weighted_sum / weight_sum;
      bool agree = true;
      for (const DepthPixel* neighbour : around) {
        agree =
            agree && Compatible(mean, 0.0, neighbour->inverse_depth,
                                neighbour->inverse_depth_variance, options.chi_square_threshold);
      }
      if (!agree) continue;
      DepthPixel grown;
      grown.pixel = candidate;
      grown.inverse_depth = mean;
      grown.inverse_depth_variance = min_variance;
      const double gradient_x = keyframe.gradient_x.at<float>(candidate.y(), candidate.x());
      const double gradient_y = keyframe.gradient_y.at<float>(candidate.y(), candidate.x());
      grown.gradient_magnitude = std::hypot(gradient_x, gradient_y);
      grown.gradient_direction =
          Eigen::Vector2d(gradient_x, gradient_y) / std::max(grown.gradient_magnitude, 1e-12);
      grown.num_hypotheses = 0;
      regularized.push_back(grown);
    }
  }
  std::sort(regularized.begin(), regularized.end(), [](const DepthPixel& a, const DepthPixel& b) {
    return a.pixel.y() != b.pixel.y() ? a.pixel.y() < b.pixel.y() : a.pixel.x() < b.pixel.x();
  });
  return regularized;
}

}  // namespace

void SemiDenseOptions::Check() const {
  const auto require = [](bool condition, const char* message) {
    if (!condition) throw InvalidArgumentError(std::string("semi-dense option ") + message);
  };
  require(canny_low_threshold > 0.0 && canny_high_threshold >= canny_low_threshold,
          "canny thresholds must satisfy 0 < low <= high");
  require(min_gradient >= 0.0, "min_gradient must be >= 0");
  require(border_margin >= kPatternHalfWidth + 1, "border_margin must be at least 3");
  require(depth_range_margin >= 1.0, "depth_range_margin must be >= 1");
  require(max_gradient_epipolar_angle_deg > 0.0 && max_gradient_epipolar_angle_deg <= 90.0,
          "max_gradient_epipolar_angle_deg must be in (0, 90]");
  require(max_gradient_orientation_difference_deg > 0.0 &&
              max_gradient_orientation_difference_deg <= 180.0,
          "max_gradient_orientation_difference_deg must be in (0, 180]");
  require(max_gradient_modulus_ratio >= 1.0, "max_gradient_modulus_ratio must be >= 1");
  require(search_step_px > 0.0 && search_step_px <= 2.0, "search_step_px must be in (0, 2]");
  require(max_search_length_px > 1.0, "max_search_length_px must be > 1");
  require(gradient_cost_weight >= 0.0, "gradient_cost_weight must be >= 0");
  require(intensity_sigma > 0.0, "intensity_sigma must be > 0");
  require(epipolar_sigma_px > 0.0, "epipolar_sigma_px must be > 0");
  require(disparity_sigma_px >= 0.0, "disparity_sigma_px must be >= 0");
  require(max_match_cost > 0.0, "max_match_cost must be > 0");
  require(min_second_best_ratio >= 1.0, "min_second_best_ratio must be >= 1");
  require(chi_square_threshold > 0.0, "chi_square_threshold must be > 0");
  require(min_compatible_hypotheses >= 1, "min_compatible_hypotheses must be >= 1");
  require(min_neighbour_support >= 0 && min_neighbour_support <= 8,
          "min_neighbour_support must be in 0..8");
  require(min_neighbours_to_grow >= 0 && min_neighbours_to_grow <= 8,
          "min_neighbours_to_grow must be in 0..8");
  require(min_keyframe_confirmations >= 0, "min_keyframe_confirmations must be >= 0");
  require(refinement_iterations >= 0, "refinement_iterations must be >= 0");
  surface.Check();
  require(num_threads >= 1, "num_threads must be >= 1");
}

DepthFrame MakeDepthFrame(const cv::Mat& image, const Camera& camera, const Rigid3d& cam_from_world,
                          const SemiDenseOptions& options) {
  if (image.empty()) throw InvalidArgumentError("MakeDepthFrame: empty image");
  if (image.cols != camera.width || image.rows != camera.height) {
    throw InvalidArgumentError("image size " + std::to_string(image.cols) + " x " +
                               std::to_string(image.rows) + " differs from the camera's " +
                               std::to_string(camera.width) + " x " +
                               std::to_string(camera.height));
  }
  cv::Mat gray;
  if (image.channels() == 3) {
    cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  } else if (image.channels() == 4) {
    cv::cvtColor(image, gray, cv::COLOR_BGRA2GRAY);
  } else {
    gray = image;
  }
  DepthFrame frame;
  frame.camera = camera;
  frame.cam_from_world = cam_from_world;
  const double scale = gray.depth() == CV_16U ? 1.0 / 65535.0 : 1.0 / 255.0;
  gray.convertTo(frame.intensity, CV_32F, scale);
  cv::Sobel(frame.intensity, frame.gradient_x, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(frame.intensity, frame.gradient_y, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::Mat gray8;
  frame.intensity.convertTo(gray8, CV_8U, 255.0);
  cv::Canny(gray8, frame.edges, options.canny_low_threshold, options.canny_high_threshold, 3, true);
  return frame;
}

KeyframeDepth EstimateKeyframeDepth(const DepthFrame& keyframe,
                                    const std::vector<const DepthFrame*>& neighbours,
                                    double min_depth, double max_depth,
                                    const SemiDenseOptions& options) {
  options.Check();
  if (!(min_depth > 0.0 && max_depth > min_depth)) {
    throw InvalidArgumentError("EstimateKeyframeDepth: need 0 < min_depth < max_depth");
  }
  const int width = keyframe.intensity.cols;
  const int height = keyframe.intensity.rows;
  std::vector<Eigen::Vector2i> candidates;
  for (int y = options.border_margin; y < height - options.border_margin; ++y) {
    const uint8_t* edge_row = keyframe.edges.ptr<uint8_t>(y);
    const float* gradient_x_row = keyframe.gradient_x.ptr<float>(y);
    const float* gradient_y_row = keyframe.gradient_y.ptr<float>(y);
    for (int x = options.border_margin; x < width - options.border_margin; ++x) {
      if (edge_row[x] == 0) continue;
      if (std::hypot(gradient_x_row[x], gradient_y_row[x]) < options.min_gradient) continue;
      candidates.emplace_back(x, y);
    }
  }
  std::vector<StereoPair> pairs;
  const Rigid3d world_from_keyframe = keyframe.cam_from_world.Inverse();
  for (const DepthFrame* neighbour : neighbours) {
    const Rigid3d neighbour_from_keyframe = neighbour->cam_from_world * world_from_keyframe;
    StereoPair pair;
    pair.neighbour = neighbour;
    pair.rotation = neighbour_from_keyframe.RotationMatrix();
    pair.translation = neighbour_from_keyframe.translation;
    pair.neighbour_center_in_keyframe = neighbour_from_keyframe.Inverse().translation;
    pairs.push_back(pair);
  }
  const double min_inverse_depth = 1.0 / max_depth;
  const double max_inverse_depth = 1.0 / min_depth;

  std::vector<std::optional<DepthPixel>> estimates(candidates.size());
  ParallelFor(candidates.size(), options.num_threads, [&](size_t begin, size_t end) {
    std::vector<Hypothesis> hypotheses;
    for (size_t c = begin; c < end; ++c) {
      const Eigen::Vector2d pixel = candidates[c].cast<double>();
      Eigen::Vector3d ray;
      if (!keyframe.camera.Unproject(pixel, &ray)) continue;
      const double gradient_x = keyframe.gradient_x.at<float>(candidates[c].y(), candidates[c].x());
      const double gradient_y = keyframe.gradient_y.at<float>(candidates[c].y(), candidates[c].x());
      const double magnitude = std::hypot(gradient_x, gradient_y);
      const Eigen::Vector2d direction = Eigen::Vector2d(gradient_x, gradient_y) / magnitude;
      hypotheses.clear();
      for (const StereoPair& pair : pairs) {
        Hypothesis hypothesis;
        if (SearchEpipolar(keyframe, pair, pixel, ray, direction, magnitude, min_inverse_depth,
                           max_inverse_depth, options, &hypothesis)) {
          hypotheses.push_back(hypothesis);
        }
      }
      Hypothesis fused;
      int count = 0;
      if (!FuseHypotheses(hypotheses, options, &fused, &count)) continue;
      DepthPixel estimate;
      estimate.pixel = candidates[c];
      estimate.inverse_depth = fused.inverse_depth;
      estimate.inverse_depth_variance = fused.variance;
      estimate.gradient_direction = direction;
      estimate.gradient_magnitude = magnitude;
      estimate.num_hypotheses = count;
      estimates[c] = estimate;
    }
  });
  KeyframeDepth depth;
  depth.num_candidates = candidates.size();
  std::vector<DepthPixel> fused;
  for (const std::optional<DepthPixel>& estimate : estimates) {
    if (estimate) fused.push_back(*estimate);
  }
  depth.num_fused = fused.size();
  depth.pixels = Regularize(keyframe, std::move(fused), candidates, options);
  return depth;
}

void EnforceInterKeyframeConsistency(
    const std::vector<const DepthFrame*>& keyframes,
    const std::vector<std::vector<uint32_t>>& consistency_neighbours,
    const SemiDenseOptions& options, std::vector<KeyframeDepth>* depths) {
  options.Check();
  if (keyframes.size() != depths->size() || keyframes.size() != consistency_neighbours.size()) {
    throw InvalidArgumentError(
        "EnforceInterKeyframeConsistency: keyframes, neighbours and depths differ in size");
  }
  // Dense look-up of each keyframe's estimates.
  std::vector<std::vector<int>> lookup(keyframes.size());
  for (size_t k = 0; k < keyframes.size(); ++k) {
    const int width = keyframes[k]->intensity.cols;
    lookup[k].assign(static_cast<size_t>(width) * keyframes[k]->intensity.rows, -1);
    const std::vector<DepthPixel>& pixels = (*depths)[k].pixels;
    for (size_t i = 0; i < pixels.size(); ++i) {
      lookup[k][static_cast<size_t>(pixels[i].pixel.y()) * width + pixels[i].pixel.x()] =
          static_cast<int>(i);
    }
  }
  std::vector<KeyframeDepth> result(depths->size());
  for (size_t k = 0; k < keyframes.size(); ++k) {
    const DepthFrame& keyframe = *keyframes[k];
    const Rigid3d world_from_keyframe = keyframe.cam_from_world.Inverse();
    struct Link {
      uint32_t keyframe;
      Eigen::Matrix3d rotation;
      Eigen::Vector3d translation;
    };
    std::vector<Link> links;
    for (const uint32_t other : consistency_neighbours[k]) {
      if (other >= keyframes.size() || other == k) {
        throw InvalidArgumentError("EnforceInterKeyframeConsistency: bad neighbour index");
      }
      const Rigid3d other_from_keyframe = keyframes[other]->cam_from_world * world_from_keyframe;
      links.push_back(
          {other, other_from_keyframe.RotationMatrix(), other_from_keyframe.translation});
    }
    const std::vector<DepthPixel>& pixels = (*depths)[k].pixels;
    std::vector<std::optional<DepthPixel>> kept(pixels.size());
    ParallelFor(pixels.size(), options.num_threads, [&](size_t begin, size_t end) {
      for (size_t i = begin; i < end; ++i) {
        const DepthPixel& pixel = pixels[i];
        Eigen::Vector3d ray;
        if (!keyframe.camera.Unproject(pixel.pixel.cast<double>(), &ray)) continue;
        // Observations: (a, b, observed inverse depth, variance) with predicted
        // rho_other(rho) = rho / (a + b rho).
        struct Observation {
          double a, b, inverse_depth, variance;
        };
        std::vector<Observation> observations;
        DepthPixel refined = pixel;
        for (const Link& link : links) {
          const Eigen::Vector3d rotated_ray = link.rotation * ray;
          const double a = rotated_ray.z();
          const double b = link.translation.z();
          const Eigen::Vector3d point_in_other =
              rotated_ray / pixel.inverse_depth + link.translation;
          Eigen::Vector2d projection;
          const Camera& other_camera = keyframes[link.keyframe]->camera;
          if (!other_camera.Project(point_in_other, &projection)) continue;
          if (!other_camera.IsInside(projection)) continue;
          const double denominator = a + b * pixel.inverse_depth;
          if (!(denominator > 0.0)) continue;
          const double predicted = pixel.inverse_depth / denominator;
          const double derivative = a / (denominator * denominator);
          const double predicted_variance = derivative * derivative * pixel.inverse_depth_variance;
          const int x0 = static_cast<int>(std::lround(projection.x()));
          const int y0 = static_cast<int>(std::lround(projection.y()));
          const int width = other_camera.width;
          double best_distance = kInfiniteCost;
          const DepthPixel* best = nullptr;
          for (int dy = -1; dy <= 1; ++dy) {
            for (int dx = -1; dx <= 1; ++dx) {
              const int x = x0 + dx;
              const int y = y0 + dy;
              if (x < 0 || y < 0 || x >= width || y >= other_camera.height) continue;
              const int index = lookup[link.keyframe][static_cast<size_t>(y) * width + x];
              if (index < 0) continue;
              const DepthPixel& candidate = (*depths)[link.keyframe].pixels[index];
              const double difference = predicted - candidate.inverse_depth;
              const double distance =
                  difference * difference / (predicted_variance + candidate.inverse_depth_variance);
              if (distance < best_distance) {
                best_distance = distance;
                best = &candidate;
              }
            }
          }
          if (best == nullptr || best_distance >= options.chi_square_threshold) continue;
          observations.push_back({a, b, best->inverse_depth, best->inverse_depth_variance});
          refined.confirming_keyframes.push_back(link.keyframe);
        }
        if (static_cast<int>(observations.size()) < options.min_keyframe_confirmations) continue;
        // Gauss-Newton on the inverse-depth differences, with the keyframe's own estimate as a
        // prior.
        double inverse_depth = pixel.inverse_depth;
        double information = 1.0 / pixel.inverse_depth_variance;
        for (int iteration = 0; iteration < options.refinement_iterations; ++iteration) {
          double hessian = 1.0 / pixel.inverse_depth_variance;
          double gradient = (inverse_depth - pixel.inverse_depth) / pixel.inverse_depth_variance;
          for (const Observation& observation : observations) {
            const double denominator = observation.a + observation.b * inverse_depth;
            if (!(denominator > 0.0)) continue;
            const double residual = inverse_depth / denominator - observation.inverse_depth;
            const double jacobian = observation.a / (denominator * denominator);
            hessian += jacobian * jacobian / observation.variance;
            gradient += jacobian * residual / observation.variance;
          }
          const double step = -gradient / hessian;
          if (!(inverse_depth + step > 0.0)) break;
          inverse_depth += step;
          information = hessian;
        }
        refined.inverse_depth = inverse_depth;
        refined.inverse_depth_variance = 1.0 / information;
        kept[i] = std::move(refined);
      }
    });
    result[k].num_candidates = (*depths)[k].num_candidates;
    result[k].num_fused = (*depths)[k].num_fused;
    for (std::optional<DepthPixel>& pixel : kept) {
      if (pixel) result[k].pixels.push_back(std::move(*pixel));
    }
  }
  *depths = std::move(result);
}

std::vector<EdgeDepthPixel> EdgeDepthPixels(const KeyframeDepth& depth) {
  std::vector<EdgeDepthPixel> pixels;
  pixels.reserve(depth.pixels.size());
  for (const DepthPixel& pixel : depth.pixels) {
    pixels.push_back({pixel.pixel, pixel.inverse_depth, pixel.gradient_direction});
  }
  return pixels;
}

bool SparseDepthRange(const Rigid3d& cam_from_world, const std::vector<Eigen::Vector3d>& points,
                      double margin, double* min_depth, double* max_depth) {
  std::vector<double> depths;
  for (const Eigen::Vector3d& point : points) {
    const double depth = (cam_from_world * point).z();
    if (depth > 0.0) depths.push_back(depth);
  }
  if (depths.size() < 3) return false;
  std::sort(depths.begin(), depths.end());
  const size_t low = static_cast<size_t>(0.02 * static_cast<double>(depths.size() - 1));
  const size_t high = static_cast<size_t>(std::ceil(0.98 * static_cast<double>(depths.size() - 1)));
  *min_depth = depths[low] / margin;
  *max_depth = depths[high] * margin;
  return *max_depth > *min_depth;
}

}  // namespace evloc::mapper
