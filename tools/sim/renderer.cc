#include "tools/sim/renderer.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>

#include <opencv2/core/utility.hpp>

#include "core/common/error.h"

namespace evloc::sim {
namespace {

constexpr int kTileSize = 16;
// Tiles per side of a culling block.
constexpr int kBlockTiles = 4;
// Tiles whose cone is wider than this test every surface (the pyramid test needs < 90 degrees).
constexpr double kMaxTileHalfAngle = 1.4;

// A surface expressed in the camera frame for one render.
struct CameraSurface {
  Eigen::Vector3d origin, u_axis, v_axis, normal;
  double width = 0, height = 0;
  // normal . origin: the plane is normal . p = plane_offset.
  double plane_offset = 0;
  std::array<Eigen::Vector3d, 4> corners;
  const Surface* surface = nullptr;
  const IndexedTexture* texture = nullptr;
  int index = -1;
  // daylight * shading: the light factor when the scene has no point lights.
  float daylight_factor = 1;
};

// The nearest hit of the ray t * ray (t = z in the camera frame, since ray.z = 1) among
// `candidates`. Returns the candidate position or -1.
struct CameraHit {
  int candidate = -1;
  double z = std::numeric_limits<double>::infinity();
  double denominator = 0;
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();
};

inline CameraHit Intersect(const Eigen::Vector3d& ray, const std::vector<CameraSurface>& surfaces,
                           const std::vector<int>& candidates, double near_z) {
  CameraHit best;
  for (int candidate : candidates) {
    const CameraSurface& s = surfaces[candidate];
    const double denominator = s.normal.dot(ray);
    if (std::abs(denominator) < 1e-12) continue;
    const double z = s.plane_offset / denominator;
    if (z <= near_z || z >= best.z) continue;
    const Eigen::Vector3d offset = z * ray - s.origin;
    const double u = offset.dot(s.u_axis);
    if (u < 0 || u > s.width) continue;
    const double v = offset.dot(s.v_axis);
    if (v < 0 || v > s.height) continue;
    best.candidate = candidate;
    best.z = z;
    best.denominator = denominator;
    best.uv = Eigen::Vector2d(u, v);
  }
  return best;
}

double AngleBetweenRays(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// Appends to `kept` the surfaces of `input` that may meet a ray of the cone (axis, half_angle):
// a surface is culled when its four corners lie outside one plane of the square pyramid
// circumscribing the cone (conservative). A cone wider than kMaxTileHalfAngle keeps everything.
void CullToCone(const Eigen::Vector3d& axis, double half_angle,
                const std::vector<CameraSurface>& surfaces, const std::vector<int>& input,
                std::vector<int>* kept) {
  if (half_angle > kMaxTileHalfAngle) {
    kept->insert(kept->end(), input.begin(), input.end());
    return;
  }
  const Eigen::Vector3d b1 = axis.unitOrthogonal();
  const Eigen::Vector3d b2 = axis.cross(b1);
  const double c = std::cos(half_angle), s = std::sin(half_angle);
  const std::array<Eigen::Vector3d, 4> planes = {c * b1 - s * axis, -c * b1 - s * axis,
                                                 c * b2 - s * axis, -c * b2 - s * axis};
  for (int index : input) {
    const CameraSurface& surface = surfaces[index];
    bool culled = false;
    for (const Eigen::Vector3d& plane : planes) {
      bool all_outside = true;
      for (const Eigen::Vector3d& corner : surface.corners) {
        if (plane.dot(corner) <= 0) {
          all_outside = false;
          break;
        }
      }
      if (all_outside) {
        culled = true;
        break;
      }
    }
    if (!culled) kept->push_back(index);
  }
}

}  // namespace

void RenderOptions::Check() const {
  if (supersampling < 1 || supersampling > 8) {
    throw InvalidArgumentError("RenderOptions.supersampling must lie within [1, 8], got " +
                               std::to_string(supersampling));
  }
  if (!std::isfinite(near_clip_m) || near_clip_m <= 0) {
    throw InvalidArgumentError("RenderOptions.near_clip_m must be positive");
  }
  if (!std::isfinite(background) || background < 0 || background > 1) {
    throw InvalidArgumentError("RenderOptions.background must lie within [0, 1]");
  }
}

namespace {

// The ray-plane-rectangle test shared by CastRay and SurfaceIndex::CastRay: true (and `hit`
// filled) when the ray meets `surface` at a distance in (min_distance, max_distance).
bool HitSurface(const Surface& surface, int index, const Eigen::Vector3d& origin,
                const Eigen::Vector3d& direction, double min_distance, double max_distance,
                RayHit* hit) {
  const Eigen::Vector3d normal = surface.Normal();
  const double denominator = normal.dot(direction);
  if (std::abs(denominator) < 1e-15) return false;
  const double distance = normal.dot(surface.origin - origin) / denominator;
  if (!(distance > min_distance) || !(distance < max_distance)) return false;
  const Eigen::Vector3d offset = origin + distance * direction - surface.origin;
  const double u = offset.dot(surface.u_axis);
  const double v = offset.dot(surface.v_axis);
  if (u < 0 || u > surface.width || v < 0 || v > surface.height) return false;
  *hit = RayHit{index, distance, Eigen::Vector2d(u, v)};
  return true;
}

// The parameter interval (t_min, t_max) of the ray inside `box` intersected with the given one;
// false when empty.
bool RayBoxInterval(const Eigen::AlignedBox3d& box, const Eigen::Vector3d& origin,
                    const Eigen::Vector3d& inverse_direction, double* t_min, double* t_max) {
  for (int axis = 0; axis < 3; ++axis) {
    double t0 = (box.min()[axis] - origin[axis]) * inverse_direction[axis];
    double t1 = (box.max()[axis] - origin[axis]) * inverse_direction[axis];
    if (std::isnan(t0) || std::isnan(t1)) {
      // Direction 0 along this axis with the origin on a slab plane: inside when within.
      if (origin[axis] < box.min()[axis] || origin[axis] > box.max()[axis]) return false;
      continue;
    }
    if (t0 > t1) std::swap(t0, t1);
    *t_min = std::max(*t_min, t0);
    *t_max = std::min(*t_max, t1);
    if (*t_min > *t_max) return false;
  }
  return true;
}

constexpr int kLeafSurfaces = 4;

}  // namespace

std::optional<RayHit> CastRay(const Scene& scene, const Eigen::Vector3d& origin,
                              const Eigen::Vector3d& direction, double min_distance) {
  std::optional<RayHit> best;
  for (size_t i = 0; i < scene.surfaces.size(); ++i) {
    RayHit hit;
    const double limit = best ? best->distance : std::numeric_limits<double>::infinity();
    if (HitSurface(scene.surfaces[i], static_cast<int>(i), origin, direction, min_distance, limit,
                   &hit)) {
      best = hit;
    }
  }
  return best;
}

SurfaceIndex::SurfaceIndex(const Scene& scene) : scene_(scene) {
  boxes_.reserve(scene.surfaces.size());
  for (const Surface& surface : scene.surfaces) {
    Eigen::AlignedBox3d box;
    for (const Eigen::Vector3d& corner : surface.Corners()) box.extend(corner);
    // Padding: flat boxes must not lose a ray through rounding.
    const double pad = 1e-6 * (1 + box.max().cwiseAbs().maxCoeff());
    box.min().array() -= pad;
    box.max().array() += pad;
    boxes_.push_back(box);
  }
  order_.resize(scene.surfaces.size());
  for (size_t i = 0; i < order_.size(); ++i) order_[i] = static_cast<int>(i);
  nodes_.reserve(2 * order_.size() / kLeafSurfaces + 2);
  if (!order_.empty()) Build(0, static_cast<int>(order_.size()));
}

int SurfaceIndex::Build(int first, int count) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Eigen::AlignedBox3d box;
  for (int i = first; i < first + count; ++i) box.extend(boxes_[order_[i]]);
  nodes_[index].box = box;
  if (count <= kLeafSurfaces) {
    nodes_[index].first = first;
    nodes_[index].count = count;
    return index;
  }
  int axis = 0;
  box.sizes().maxCoeff(&axis);
  const int middle = first + count / 2;
  std::nth_element(order_.begin() + first, order_.begin() + middle, order_.begin() + first + count,
                   [&](int a, int b) {
                     const double ca = boxes_[a].center()[axis], cb = boxes_[b].center()[axis];
                     return ca < cb || (ca == cb && a < b);
                   });
  Build(first, middle - first);  // the left child is index + 1
  const int right = Build(middle, first + count - middle);
  nodes_[index].right = right;
  return index;
}

std::optional<RayHit> SurfaceIndex::CastRay(const Eigen::Vector3d& origin,
                                            const Eigen::Vector3d& direction,
                                            double min_distance) const {
  std::optional<RayHit> best;
  if (nodes_.empty()) return best;
  const Eigen::Vector3d inverse = direction.cwiseInverse();
  int stack[128];
  int size = 0;
  stack[size++] = 0;
  while (size > 0) {
    const Node& node = nodes_[stack[--size]];
    double t_min = -std::numeric_limits<double>::infinity();
    double t_max = best ? best->distance : std::numeric_limits<double>::infinity();
    if (!RayBoxInterval(node.box, origin, inverse, &t_min, &t_max)) continue;
    if (t_max < min_distance) continue;
    if (node.count > 0) {
      for (int i = node.first; i < node.first + node.count; ++i) {
        const int surface = order_[i];
        // Ties go to the lowest surface index, as in the brute-force CastRay.
        RayHit hit;
        const double limit =
            best ? std::nextafter(best->distance, std::numeric_limits<double>::infinity())
                 : std::numeric_limits<double>::infinity();
        if (HitSurface(scene_.surfaces[surface], surface, origin, direction, min_distance, limit,
                       &hit) &&
            (!best || hit.distance < best->distance || surface < best->surface_index)) {
          best = hit;
        }
      }
    } else {
      const int left = static_cast<int>(&node - nodes_.data()) + 1;
      stack[size++] = node.right;
      stack[size++] = left;
    }
  }
  return best;
}

Renderer::Renderer(const Scene& scene, const Camera& camera, RenderOptions options)
    : scene_(scene), camera_(camera), options_(options) {
  scene_.Check();
  camera_.Check();
  options_.Check();
  textures_.reserve(scene_.surfaces.size());
  for (const Surface& surface : scene_.surfaces) {
    textures_.emplace_back(surface.texture, surface.width, surface.height);
  }
  const int width = camera_.width, height = camera_.height, ss = options_.supersampling;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  auto unproject = [&](double x, double y) -> Eigen::Vector2f {
    Eigen::Vector3d ray;
    if (!camera_.Unproject(Eigen::Vector2d(x, y), &ray) || !ray.allFinite()) {
      return Eigen::Vector2f(nan, nan);
    }
    return Eigen::Vector2f(static_cast<float>(ray.x() / ray.z()),
                           static_cast<float>(ray.y() / ray.z()));
  };
  center_rays_.resize(static_cast<size_t>(width) * height);
  cv::parallel_for_(cv::Range(0, height), [&](const cv::Range& rows) {
    for (int y = rows.start; y < rows.end; ++y) {
      for (int x = 0; x < width; ++x)
        center_rays_[static_cast<size_t>(y) * width + x] = unproject(x, y);
    }
  });
  if (ss > 1) {
    const int sample_width = width * ss;
    sample_rays_.resize(static_cast<size_t>(sample_width) * height * ss);
    cv::parallel_for_(cv::Range(0, height * ss), [&](const cv::Range& rows) {
      for (int sy = rows.start; sy < rows.end; ++sy) {
        const double y = (sy / ss) + ((sy % ss) + 0.5) / ss - 0.5;
        for (int sx = 0; sx < sample_width; ++sx) {
          const double x = (sx / ss) + ((sx % ss) + 0.5) / ss - 0.5;
          sample_rays_[static_cast<size_t>(sy) * sample_width + sx] = unproject(x, y);
        }
      }
    });
  }
  // Tiles and their ray cones.
  auto unit_ray = [](const Eigen::Vector2f& ray) {
    return Eigen::Vector3d(ray.x(), ray.y(), 1.0).normalized();
  };
  for (int y0 = 0; y0 < height; y0 += kTileSize) {
    for (int x0 = 0; x0 < width; x0 += kTileSize) {
      Tile tile;
      tile.x0 = x0;
      tile.y0 = y0;
      tile.x1 = std::min(width, x0 + kTileSize);
      tile.y1 = std::min(height, y0 + kTileSize);
      std::vector<Eigen::Vector3d> rays;
      for (int y = tile.y0; y < tile.y1; ++y) {
        for (int x = tile.x0; x < tile.x1; ++x) {
          const Eigen::Vector2f& center = center_rays_[static_cast<size_t>(y) * width + x];
          if (!std::isnan(center.x())) {
            rays.push_back(unit_ray(center));
            // Neighbour spacing, for the footprint estimate.
            for (const auto& [dx, dy] :
                 {std::pair{1, 0}, std::pair{0, 1}, std::pair{-1, 0}, std::pair{0, -1}}) {
              const int nx = x + dx, ny = y + dy;
              if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
              const Eigen::Vector2f& neighbour = center_rays_[static_cast<size_t>(ny) * width + nx];
              if (std::isnan(neighbour.x())) continue;
              tile.angle_per_pixel = std::max(tile.angle_per_pixel,
                                              AngleBetweenRays(rays.back(), unit_ray(neighbour)));
            }
          }
          for (int j = 0; j < ss && ss > 1; ++j) {
            for (int i = 0; i < ss; ++i) {
              const Eigen::Vector2f& sample =
                  sample_rays_[static_cast<size_t>(y * ss + j) * width * ss + x * ss + i];
              if (!std::isnan(sample.x())) rays.push_back(unit_ray(sample));
            }
          }
        }
      }
      if (!rays.empty()) {
        Eigen::Vector3d mean = Eigen::Vector3d::Zero();
        for (const Eigen::Vector3d& ray : rays) mean += ray;
        tile.axis = mean.normalized();
        for (const Eigen::Vector3d& ray : rays) {
          tile.half_angle = std::max(tile.half_angle, AngleBetweenRays(tile.axis, ray));
        }
        tile.half_angle += 1e-6;
        tile.valid = true;
      }
      if (tile.angle_per_pixel == 0) tile.angle_per_pixel = 1.0 / std::min(camera_.fx, camera_.fy);
      tiles_.push_back(tile);
    }
  }
  // Blocks of kBlockTiles x kBlockTiles tiles, each with a cone containing its tiles' cones.
  const int tile_columns = (width + kTileSize - 1) / kTileSize;
  const int tile_rows = (height + kTileSize - 1) / kTileSize;
  tile_block_.assign(tiles_.size(), 0);
  for (int by = 0; by < tile_rows; by += kBlockTiles) {
    for (int bx = 0; bx < tile_columns; bx += kBlockTiles) {
      Block block;
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      std::vector<int> members;
      for (int ty = by; ty < std::min(tile_rows, by + kBlockTiles); ++ty) {
        for (int tx = bx; tx < std::min(tile_columns, bx + kBlockTiles); ++tx) {
          const int index = ty * tile_columns + tx;
          tile_block_[index] = static_cast<int>(blocks_.size());
          if (tiles_[index].valid) {
            members.push_back(index);
            sum += tiles_[index].axis;
          }
        }
      }
      if (!members.empty() && sum.norm() > 1e-9) {
        block.axis = sum.normalized();
        for (int index : members) {
          block.half_angle =
              std::max(block.half_angle,
                       AngleBetweenRays(block.axis, tiles_[index].axis) + tiles_[index].half_angle);
        }
        block.valid = true;
      } else if (!members.empty()) {
        block.half_angle = M_PI;  // keeps every surface
        block.valid = true;
      }
      blocks_.push_back(block);
    }
  }
}

void Renderer::Render(const Rigid3d& world_from_cam, cv::Mat* gray, cv::Mat* rgb, cv::Mat* depth,
                      RenderStats* stats) const {
  if (gray == nullptr) throw InvalidArgumentError("Renderer::Render needs a gray output image");
  if (!world_from_cam.IsFinite()) throw InvalidArgumentError("Renderer::Render: non-finite pose");
  const int width = camera_.width, height = camera_.height, ss = options_.supersampling;
  const Rigid3d cam_from_world = world_from_cam.Inverse();
  const Eigen::Matrix3d rotation = cam_from_world.RotationMatrix();

  std::vector<CameraSurface> surfaces(scene_.surfaces.size());
  for (size_t i = 0; i < scene_.surfaces.size(); ++i) {
    const Surface& surface = scene_.surfaces[i];
    CameraSurface& s = surfaces[i];
    s.origin = cam_from_world * surface.origin;
    s.u_axis = rotation * surface.u_axis;
    s.v_axis = rotation * surface.v_axis;
    s.normal = s.u_axis.cross(s.v_axis);
    s.width = surface.width;
    s.height = surface.height;
    s.plane_offset = s.normal.dot(s.origin);
    const std::array<Eigen::Vector3d, 4> corners = surface.Corners();
    for (int c = 0; c < 4; ++c) s.corners[c] = cam_from_world * corners[c];
    s.surface = &surface;
    s.texture = &textures_[i];
    s.index = static_cast<int>(i);
    s.daylight_factor = static_cast<float>(scene_.daylight * surface.shading);
  }
  // The irradiance of a hit: albedo times the light factor, clamped to 1.
  const bool lamps = !scene_.point_lights.empty();
  const Eigen::Vector3d camera_center = world_from_cam.translation;
  auto shade = [&](const CameraSurface& surface, const Eigen::Vector2d& uv, const Color& albedo) {
    const float factor =
        lamps ? scene_.LightFactorAt(*surface.surface, surface.surface->PointAt(uv.x(), uv.y()),
                                     camera_center)
              : surface.daylight_factor;
    return Color((albedo * factor).cwiseMin(1.0f));
  };

  gray->create(height, width, CV_32FC1);
  if (rgb != nullptr) rgb->create(height, width, CV_32FC3);
  if (depth != nullptr) depth->create(height, width, CV_32FC1);
  std::vector<int> hit_surface(static_cast<size_t>(width) * height, -1);
  std::vector<uint8_t> near_edge(static_cast<size_t>(width) * height, 0);
  std::vector<std::vector<int>> tile_candidates(tiles_.size());
  const double near_z = options_.near_clip_m;
  // Culling: the surfaces not wholly behind the near plane, then per block of tiles, then per
  // tile from its block's list.
  std::vector<int> in_front;
  in_front.reserve(surfaces.size());
  for (const CameraSurface& surface : surfaces) {
    bool all_behind = true;
    for (const Eigen::Vector3d& corner : surface.corners) all_behind &= corner.z() <= near_z;
    if (!all_behind) in_front.push_back(surface.index);
  }
  std::vector<std::vector<int>> block_candidates(blocks_.size());
  const Color background =
      Gray(std::min(1.0f, options_.background + static_cast<float>(scene_.sky * scene_.daylight)));

  auto run = [&](int count, const std::function<void(int)>& body) {
    if (options_.parallel) {
      cv::parallel_for_(cv::Range(0, count), [&](const cv::Range& range) {
        for (int i = range.start; i < range.end; ++i) body(i);
      });
    } else {
      for (int i = 0; i < count; ++i) body(i);
    }
  };

  auto write_pixel = [&](int x, int y, const Color& color) {
    gray->at<float>(y, x) = Luminance(color);
    if (rgb != nullptr) rgb->at<cv::Vec3f>(y, x) = cv::Vec3f(color[0], color[1], color[2]);
  };

  run(static_cast<int>(blocks_.size()), [&](int block_index) {
    const Block& block = blocks_[block_index];
    if (block.valid) {
      CullToCone(block.axis, block.half_angle, surfaces, in_front, &block_candidates[block_index]);
    }
  });

  // Pass 1: cull surfaces per tile, cast the pixel-centre rays.
  run(static_cast<int>(tiles_.size()), [&](int tile_index) {
    const Tile& tile = tiles_[tile_index];
    std::vector<int>& candidates = tile_candidates[tile_index];
    if (tile.valid) {
      CullToCone(tile.axis, tile.half_angle, surfaces, block_candidates[tile_block_[tile_index]],
                 &candidates);
    }
    for (int y = tile.y0; y < tile.y1; ++y) {
      for (int x = tile.x0; x < tile.x1; ++x) {
        const size_t pixel = static_cast<size_t>(y) * width + x;
        const Eigen::Vector2f& ray2 = center_rays_[pixel];
        if (std::isnan(ray2.x())) {
          write_pixel(x, y, Gray(0.0f));
          if (depth != nullptr) depth->at<float>(y, x) = 0.0f;
          continue;
        }
        const Eigen::Vector3d ray(ray2.x(), ray2.y(), 1.0);
        const CameraHit hit = Intersect(ray, surfaces, candidates, near_z);
        if (hit.candidate < 0) {
          write_pixel(x, y, background);
          if (depth != nullptr) depth->at<float>(y, x) = 0.0f;
          continue;
        }
        const CameraSurface& surface = surfaces[hit.candidate];
        // Footprint radius on the surface: (distance / cos incidence) * angle, with a margin
        // covering the half-diagonal of the pixel.
        const double ray_norm_squared = ray.squaredNorm();
        const double footprint = hit.z * ray_norm_squared /
                                 std::max(std::abs(hit.denominator), 1e-9) * tile.angle_per_pixel *
                                 1.1;
        bool near = false;
        const Color albedo = surface.texture->ColorAt(hit.uv, footprint, &near);
        near = near || hit.uv.x() < footprint || hit.uv.x() > surface.width - footprint ||
               hit.uv.y() < footprint || hit.uv.y() > surface.height - footprint;
        write_pixel(x, y, shade(surface, hit.uv, albedo));
        if (depth != nullptr) depth->at<float>(y, x) = static_cast<float>(hit.z);
        hit_surface[pixel] = surface.index;
        near_edge[pixel] = near ? 1 : 0;
      }
    }
  });

  // Pass 2: supersample pixels near an edge or next to a pixel that hit another surface.
  std::vector<int> supersampled_per_tile(tiles_.size(), 0);
  if (ss > 1) {
    const int sample_width = width * ss;
    run(static_cast<int>(tiles_.size()), [&](int tile_index) {
      const Tile& tile = tiles_[tile_index];
      const std::vector<int>& candidates = tile_candidates[tile_index];
      int count = 0;
      for (int y = tile.y0; y < tile.y1; ++y) {
        for (int x = tile.x0; x < tile.x1; ++x) {
          const size_t pixel = static_cast<size_t>(y) * width + x;
          if (std::isnan(center_rays_[pixel].x())) continue;
          bool needed = near_edge[pixel] != 0;
          for (int dy = -1; dy <= 1 && !needed; ++dy) {
            for (int dx = -1; dx <= 1 && !needed; ++dx) {
              const int nx = x + dx, ny = y + dy;
              if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
              needed = hit_surface[static_cast<size_t>(ny) * width + nx] != hit_surface[pixel];
            }
          }
          if (!needed) continue;
          ++count;
          Color sum = Color::Zero();
          int valid = 0;
          for (int j = 0; j < ss; ++j) {
            for (int i = 0; i < ss; ++i) {
              const Eigen::Vector2f& ray2 =
                  sample_rays_[static_cast<size_t>(y * ss + j) * sample_width + x * ss + i];
              if (std::isnan(ray2.x())) continue;
              ++valid;
              const CameraHit hit =
                  Intersect(Eigen::Vector3d(ray2.x(), ray2.y(), 1.0), surfaces, candidates, near_z);
              if (hit.candidate < 0) {
                sum += background;
              } else {
                const CameraSurface& surface = surfaces[hit.candidate];
                sum += shade(surface, hit.uv, surface.texture->ColorAt(hit.uv));
              }
            }
          }
          if (valid > 0) write_pixel(x, y, sum / static_cast<float>(valid));
        }
      }
      supersampled_per_tile[tile_index] = count;
    });
  }
  if (stats != nullptr) {
    size_t supersampled = 0, candidates = 0;
    for (size_t i = 0; i < tiles_.size(); ++i) {
      supersampled += supersampled_per_tile[i];
      candidates += tile_candidates[i].size();
    }
    stats->supersampled_fraction = static_cast<double>(supersampled) / (width * height);
    stats->mean_candidates_per_tile = static_cast<double>(candidates) / tiles_.size();
  }
}

}  // namespace evloc::sim
