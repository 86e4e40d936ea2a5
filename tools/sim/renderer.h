// Exact ray-cast rendering of a sim::Scene through a camera model: linear irradiance, depth and
// colour, anti-aliased by adaptive supersampling near edges, occlusion-correct. See
// docs/sim-scene.md, "Rendering".
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera/camera.h"
#include "core/geometry/rigid3.h"
#include "tools/sim/scene.h"

namespace evloc::sim {

// How a Renderer samples pixels.
struct RenderOptions {
  // Samples per pixel and axis (ss x ss box-filter samples) where a pixel straddles an edge;
  // 1 disables anti-aliasing.
  int supersampling = 3;
  // Render tiles in parallel on OpenCV's thread pool (cv::parallel_for_; its size is set by
  // cv::setNumThreads); false renders serially in the calling thread.
  bool parallel = true;
  // Rays hitting a surface closer than this to the camera centre are ignored, metres.
  double near_clip_m = 1e-3;
  // Irradiance of pixels whose ray hits nothing, in [0, 1], added to the scene's sky
  // (Scene::sky * Scene::daylight; the sum clamped to 1).
  float background = 0.0f;

  // Throws InvalidArgumentError when supersampling is outside [1, 8], near_clip_m is not positive
  // or background is outside [0, 1].
  void Check() const;
};

// Figures about one Render call, for benchmarks.
struct RenderStats {
  // Fraction of pixels that were supersampled, in [0, 1].
  double supersampled_fraction = 0;
  // Mean number of candidate surfaces per tile after culling.
  double mean_candidates_per_tile = 0;
};

// What a single ray hits.
struct RayHit {
  // Index into Scene::surfaces.
  int surface_index = -1;
  // Ray parameter: the hit is at origin + distance * direction (direction as passed; unit
  // direction gives metres).
  double distance = 0;
  // Surface coordinates of the hit, metres.
  Eigen::Vector2d uv = Eigen::Vector2d::Zero();
};

// The nearest hit of the ray origin + t * direction (t > min_distance) with the scene's surfaces,
// or nullopt. Brute force over all surfaces; for occlusion queries and tests.
std::optional<RayHit> CastRay(const Scene& scene, const Eigen::Vector3d& origin,
                              const Eigen::Vector3d& direction, double min_distance = 0);

// A bounding-volume hierarchy over a scene's surfaces for ray queries at site scale (thousands of
// surfaces): the same nearest hit as CastRay, visiting only the surfaces whose boxes the ray
// meets.
class SurfaceIndex {
 public:
  // Indexes `scene`, which must outlive the index and stay unchanged.
  explicit SurfaceIndex(const Scene& scene);
  // The nearest hit of origin + t * direction with t > min_distance (as CastRay).
  std::optional<RayHit> CastRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                                double min_distance = 0) const;
  // The scene indexed.
  const Scene& scene() const { return scene_; }

 private:
  struct Node {
    Eigen::AlignedBox3d box;
    // Leaves: [first, first + count) in order_; inner nodes: children left and left + 1... the
    // right child's index is `right`.
    int first = 0, count = 0, right = -1;
  };
  int Build(int first, int count);

  const Scene& scene_;
  std::vector<Eigen::AlignedBox3d> boxes_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
};

// Renders one scene through one camera. Construction precomputes every sample ray through the
// lens model (Camera::Unproject), so each Render only intersects rays with surfaces. Render is
// const and may be called from several threads.
class Renderer {
 public:
  // Keeps a copy of the scene and the camera (not copyable: it indexes its own scene copy). Throws
  // InvalidArgumentError when the scene, the camera or the options fail Check().
  Renderer(const Scene& scene, const Camera& camera, RenderOptions options = {});

  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  // Renders the view from `world_from_cam`: linear irradiance in [0, 1] as gray CV_32FC1
  // (required), rgb CV_32FC3 in R, G, B channel order (optional), depth = z of the nearest hit in
  // the camera frame, metres, CV_32FC1, 0 where nothing is hit (optional; taken at the pixel
  // centre, not averaged). Pixels whose ray cannot be unprojected through the lens are 0.
  // Fills `stats` when it is not null. Throws InvalidArgumentError when `gray` is null or the
  // pose is not finite.
  void Render(const Rigid3d& world_from_cam, cv::Mat* gray, cv::Mat* rgb = nullptr,
              cv::Mat* depth = nullptr, RenderStats* stats = nullptr) const;

  // The scene being rendered.
  const Scene& scene() const { return scene_; }
  // The camera.
  const Camera& camera() const { return camera_; }
  // The options.
  const RenderOptions& options() const { return options_; }

 private:
  // A square block of pixels with the cone that contains all its sample rays (camera frame).
  struct Tile {
    // Pixel range [x0, x1) x [y0, y1).
    int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
    // Unit cone axis.
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
    // Cone half-angle, radians (below 90 degrees).
    double half_angle = 0;
    // Largest angle between neighbouring pixel-centre rays in the tile, radians.
    double angle_per_pixel = 0;
    // False when no ray of the tile could be unprojected.
    bool valid = false;
  };

  Scene scene_;
  // One index per surface texture (pointing into scene_).
  std::vector<IndexedTexture> textures_;
  Camera camera_;
  RenderOptions options_;
  // Unit-z ray (x/z, y/z) per pixel centre, row-major; NaN when the pixel cannot be unprojected.
  std::vector<Eigen::Vector2f> center_rays_;
  // Unit-z rays of the ss x ss sub-samples, (width * ss) x (height * ss) row-major.
  std::vector<Eigen::Vector2f> sample_rays_;
  // Tiles covering the image, row-major.
  std::vector<Tile> tiles_;
  // A block of 4 x 4 tiles with a cone containing its tiles' cones: surfaces are culled per
  // block first, then per tile from the block's list (the cost grows with the surfaces a block
  // sees, not with the scene).
  struct Block {
    // Unit cone axis.
    Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();
    // Cone half-angle, radians.
    double half_angle = 0;
    // False when no tile of the block is valid.
    bool valid = false;
  };
  std::vector<Block> blocks_;
  // The block of each tile.
  std::vector<int> tile_block_;
};

}  // namespace evloc::sim
