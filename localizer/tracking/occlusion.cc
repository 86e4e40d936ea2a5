#include "localizer/tracking/occlusion.h"

#include <algorithm>
#include <cmath>
#include <tuple>

#include "core/common/error.h"

namespace evloc::tracking {

void NearestEdgeField::Build(const cv::Mat& edge_mask) {
  if (edge_mask.type() != CV_8UC1 || edge_mask.empty()) {
    throw InvalidArgumentError("NearestEdgeField needs a non-empty CV_8UC1 edge mask.");
  }
  mask_image_ = edge_mask.isContinuous() ? edge_mask : edge_mask.clone();
  mask_ = mask_image_.ptr<uint8_t>(0);
  last_t_ns_ = nullptr;
  width_ = edge_mask.cols;
  height_ = edge_mask.rows;
}

void NearestEdgeField::Build(const TimeSurface& surface, SurfaceChannel channel, int64_t t_ns,
                             const SurfaceDecay& decay) {
  mask_image_.release();
  mask_ = nullptr;
  last_t_ns_ = surface.LastTimestamps(channel);
  // Active <=> age <= the largest active age (events after t_ns count as fired at t_ns). Never
  // fired pixels hold kNeverFired, below any threshold.
  min_active_t_ns_ = t_ns - decay.MaxActiveAgeExactNs();
  width_ = surface.width();
  height_ = surface.height();
}

const NearestEdgeField::Window& NearestEdgeField::FindOrMakeWindow(double radius_px) const {
  for (size_t i = 0; i < windows_.size(); ++i) {
    if (windows_[i].radius_px == radius_px && windows_[i].width == width_) {
      last_window_ = i;
      return windows_[i];
    }
  }
  Window window;
  window.radius_px = radius_px;
  window.width = width_;
  const int reach = static_cast<int>(std::floor(radius_px));
  for (int dy = -reach; dy <= reach; ++dy) {
    for (int dx = -reach; dx <= reach; ++dx) {
      const int squared = dx * dx + dy * dy;
      if (squared <= radius_px * radius_px) {
        window.offsets.push_back({dx, dy, std::sqrt(static_cast<float>(squared))});
      }
    }
  }
  // Nearest first; at equal distance, the lower row-major index first.
  std::sort(window.offsets.begin(), window.offsets.end(), [](const Offset& a, const Offset& b) {
    const int squared_a = a.dx * a.dx + a.dy * a.dy;
    const int squared_b = b.dx * b.dx + b.dy * b.dy;
    return std::tie(squared_a, a.dy, a.dx) < std::tie(squared_b, b.dy, b.dx);
  });
  for (const Offset& offset : window.offsets) {
    window.index_offsets.push_back(static_cast<std::ptrdiff_t>(offset.dy) * width_ + offset.dx);
  }
  // A handful of radii at most; keep the cache from growing without bound.
  if (windows_.size() >= 4) windows_.erase(windows_.begin());
  windows_.push_back(std::move(window));
  last_window_ = windows_.size() - 1;
  return windows_.back();
}

template <typename IsEdgeAt>
int NearestEdgeField::FirstEdge(const Window& window, size_t centre, IsEdgeAt&& is_edge,
                                size_t* position) {
  const std::ptrdiff_t* index_offsets = window.index_offsets.data();
  const size_t count = window.index_offsets.size();
  for (size_t i = 0; i < count; ++i) {
    const size_t index = centre + index_offsets[i];
    if (is_edge(index)) {
      *position = i;
      return static_cast<int>(index);
    }
  }
  return -1;
}

bool NearestEdgeField::Nearest(int x, int y, double radius_px, int* edge_pixel_index,
                               float* distance_px) const {
  if ((mask_ == nullptr && last_t_ns_ == nullptr) || x < 0 || y < 0 || x >= width_ ||
      y >= height_ || !(radius_px >= 0)) {
    return false;
  }
  const Window& window = WindowFor(radius_px);
  const bool inside = x >= radius_px && y >= radius_px && x + radius_px <= width_ - 1 &&
                      y + radius_px <= height_ - 1;
  if (inside) {
    // The whole window lies in the image: walk it by index differences.
    const size_t centre = static_cast<size_t>(y) * width_ + x;
    size_t position = 0;
    int found;
    if (mask_ != nullptr) {
      const uint8_t* mask = mask_;
      found = FirstEdge(
          window, centre, [mask](size_t index) { return mask[index] != 0; }, &position);
    } else {
      const int64_t* last_t_ns = last_t_ns_;
      const int64_t min_active_t_ns = min_active_t_ns_;
      found = FirstEdge(
          window, centre,
          [last_t_ns, min_active_t_ns](size_t index) {
            return last_t_ns[index] >= min_active_t_ns;
          },
          &position);
    }
    if (found < 0) return false;
    *edge_pixel_index = found;
    *distance_px = window.offsets[position].distance;
    return true;
  }
  for (const Offset& offset : window.offsets) {
    const int xx = x + offset.dx;
    const int yy = y + offset.dy;
    if (xx < 0 || yy < 0 || xx >= width_ || yy >= height_) continue;
    if (IsEdge(xx, yy)) {
      *edge_pixel_index = yy * width_ + xx;
      *distance_px = offset.distance;
      return true;
    }
  }
  return false;
}

void EdgeZBuffer::Cull(const std::vector<Eigen::Vector2d>& pixels,
                       const std::vector<double>& depths, const NearestEdgeField& annf,
                       double radius_px, std::vector<uint8_t>* keep) {
  if (pixels.size() != depths.size()) {
    throw InvalidArgumentError("EdgeZBuffer::Cull: pixels and depths differ in size.");
  }
  const size_t num_pixels = static_cast<size_t>(annf.width()) * annf.height();
  if (owner_.size() != num_pixels) owner_.assign(num_pixels, -1);
  keep->assign(pixels.size(), 0);
  claimed_.assign(pixels.size(), -1);
  for (size_t i = 0; i < pixels.size(); ++i) {
    int edge_pixel;
    float distance;
    if (!annf.Nearest(pixels[i], radius_px, &edge_pixel, &distance)) continue;
    claimed_[i] = edge_pixel;
    int32_t& owner = owner_[edge_pixel];
    // The comparison the reference implementation never made: the nearer point wins.
    if (owner < 0 || depths[i] < depths[owner]) owner = static_cast<int32_t>(i);
  }
  for (size_t i = 0; i < pixels.size(); ++i) {
    if (claimed_[i] >= 0 && owner_[claimed_[i]] == static_cast<int32_t>(i)) (*keep)[i] = 1;
  }
  // Reset only the entries this call touched.
  for (const int32_t edge_pixel : claimed_) {
    if (edge_pixel >= 0) owner_[edge_pixel] = -1;
  }
}

}  // namespace evloc::tracking
