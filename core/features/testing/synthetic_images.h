// Helpers of the relocalization tests and benchmark: synthetic textured images (reproducible from
// a seed), a small homography, and reading images of the shared real data.
#pragma once

#include <cstdint>
#include <filesystem>
#include <stdexcept>
#include <string>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

namespace evloc::features::testing {

// A grey image of random overlapping discs, rectangles and lines on a random background, slightly
// blurred: rich in SIFT keypoints, the same for the same seed.
inline cv::Mat SyntheticTexture(int width, int height, uint64_t seed, int shapes = 300) {
  cv::RNG rng(seed);
  cv::Mat image(height, width, CV_8UC1, cv::Scalar(rng.uniform(60, 190)));
  for (int i = 0; i < shapes; ++i) {
    const cv::Scalar grey(rng.uniform(0, 256));
    const cv::Point centre(rng.uniform(0, width), rng.uniform(0, height));
    const int size = rng.uniform(3, std::max(4, width / 12));
    switch (rng.uniform(0, 3)) {
      case 0:
        cv::circle(image, centre, size, grey, cv::FILLED, cv::LINE_AA);
        break;
      case 1:
        cv::rectangle(image, centre, centre + cv::Point(size, rng.uniform(3, size + 4)), grey,
                      cv::FILLED, cv::LINE_AA);
        break;
      default:
        cv::line(
            image, centre,
            centre + cv::Point(rng.uniform(-2 * size, 2 * size), rng.uniform(-2 * size, 2 * size)),
            grey, rng.uniform(1, 4), cv::LINE_AA);
        break;
    }
  }
  cv::GaussianBlur(image, image, cv::Size(0, 0), 1.0);
  return image;
}

// A homography about the image centre: rotation by `degrees`, scaling, then a shift (pixels).
inline cv::Mat SmallHomography(const cv::Size& size, double degrees, double scale, double shift_x,
                               double shift_y) {
  cv::Mat affine = cv::getRotationMatrix2D(
      cv::Point2f((size.width - 1) * 0.5f, (size.height - 1) * 0.5f), degrees, scale);
  affine.at<double>(0, 2) += shift_x;
  affine.at<double>(1, 2) += shift_y;
  cv::Mat homography = cv::Mat::eye(3, 3, CV_64F);
  affine.copyTo(homography.rowRange(0, 2));
  homography.at<double>(2, 0) = 2e-5;  // A little perspective.
  return homography;
}

// `image` warped by `homography` (OpenCV's warps use integer pixel centres, as evloc does), with
// Gaussian noise of `noise_grey` grey levels.
inline cv::Mat Warp(const cv::Mat& image, const cv::Mat& homography, double noise_grey,
                    uint64_t seed) {
  cv::Mat warped;
  cv::warpPerspective(image, warped, homography, image.size(), cv::INTER_LINEAR,
                      cv::BORDER_REFLECT);
  cv::Mat noise(warped.size(), CV_16S);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 0, noise_grey);
  cv::Mat noisy;
  warped.convertTo(noisy, CV_16S);
  noisy += noise;
  noisy.convertTo(warped, CV_8U);
  return warped;
}

// Reads an image as grey, shrunk to at most `max_width` columns when that is positive; throws
// std::runtime_error when it cannot be read.
inline cv::Mat ReadGrey(const std::filesystem::path& path, int max_width = 0) {
  cv::Mat image = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
  if (image.empty()) throw std::runtime_error("cannot read " + path.string());
  if (max_width > 0 && image.cols > max_width) {
    const double factor = static_cast<double>(max_width) / image.cols;
    cv::resize(image, image, cv::Size(), factor, factor, cv::INTER_AREA);
  }
  return image;
}

}  // namespace evloc::features::testing
