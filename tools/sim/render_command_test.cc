// End-to-end renders of the default room (long: several seconds each on 2 cores).
#include "tools/sim/render_command.h"

#include <cmath>
#include <filesystem>

#include <gtest/gtest.h>

#include "core/common/test_data.h"

namespace evloc::sim {
namespace {

namespace fs = std::filesystem;

// Interpolating ESIM images along the depth-based flow between renders gives the same events as
// rendering every image, up to the errors near occlusion boundaries.
TEST(RenderCommand, InterpolatedImagesGiveTheEventCountOfRenderedOnes) {
  const fs::path dir = evloc::testing::MakeTempDir("render_interpolation");
  int64_t counts[2];
  int64_t renders[2];
  int index = 0;
  for (double render_motion : {0.5, 3.0}) {
    RenderCommandOptions options;
    options.out_dir = dir / ("out" + std::to_string(index));
    options.camera_preset = "davis240";
    options.motion = MotionProfile::kMid;
    options.duration_s = 0.3;
    options.clean = true;
    options.max_render_motion_px = render_motion;
    const nlohmann::json info = RunRenderCommand(options);
    counts[index] = info["counts"]["events"].get<int64_t>();
    renders[index] = info["counts"]["renders"].get<int64_t>();
    EXPECT_LE(info["motion_measured"]["max_image_motion_between_esim_images_px"].get<double>(),
              0.5 + 1e-9);
    ++index;
  }
  EXPECT_GT(renders[0], 2 * renders[1]);
  EXPECT_NEAR(static_cast<double>(counts[1]), static_cast<double>(counts[0]), 0.02 * counts[0]);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace evloc::sim
