#include "localizer/tracking/time_surface.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "core/camera/testing/ecd_davis240.h"
#include "core/common/error.h"

namespace evloc::tracking {
namespace {

EventBuffer MakeEvents(std::initializer_list<Event> events) {
  EventBuffer buffer;
  for (const Event& event : events) buffer.push_back(event);
  return buffer;
}

TEST(TimeSurface, StoresLastTimestampPerChannel) {
  const UndistortionTable table(Camera::Pinhole(40, 30, 30, 30, 19.5, 14.5));
  TimeSurface surface(table);
  const EventBuffer events = MakeEvents(
      {{100, 5, 6, 1}, {200, 5, 6, -1}, {300, 7, 8, 1}, {400, 7, 8, 1}, {500, 39, 29, -1}});
  surface.Insert(events, 0, events.size());
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kAll, 5, 6), 200);
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kOn, 5, 6), 100);
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kOff, 5, 6), 200);
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kOn, 7, 8), 400);
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kOff, 7, 8), kNeverFired);
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kAll, 39, 29), 500);
  EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kAll, 0, 0), kNeverFired);
  EXPECT_EQ(surface.num_stored(), 5);
}

TEST(TimeSurface, EventOutsideTheSensorThrows) {
  const UndistortionTable table(Camera::Pinhole(40, 30, 30, 30, 19.5, 14.5));
  TimeSurface surface(table);
  const EventBuffer events = MakeEvents({{100, 5, 6, 1}, {200, 40, 6, -1}});
  EXPECT_THROW(surface.Insert(events, 0, events.size()), InvalidArgumentError);
}

TEST(TimeSurface, BuiltFromTheCameraMapsEveryPixelAsFromItsTable) {
  // Barrel distortion strong enough that the corners leave the image (dropped), plain and binned.
  Camera camera = Camera::Pinhole(64, 48, 50, 50, 31.5, 23.5);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.45, 0.1, 0.001, -0.002, 0.0};
  for (const int binning : {1, 2, 3}) {
    const TimeSurface from_table(UndistortionTable(camera, binning));
    const TimeSurface from_camera(camera, binning);
    ASSERT_EQ(from_camera.width(), from_table.width()) << binning;
    ASSERT_EQ(from_camera.height(), from_table.height()) << binning;
    int dropped = 0;
    for (int y = 0; y < 48; ++y) {
      for (int x = 0; x < 64; ++x) {
        EXPECT_EQ(from_camera.IdealPixelIndex(x, y), from_table.IdealPixelIndex(x, y))
            << binning << ": " << x << ", " << y;
        dropped += from_camera.IdealPixelIndex(x, y) < 0 ? 1 : 0;
      }
    }
    if (binning == 1) {
      EXPECT_GT(dropped, 0);
    }
    // Both fill the same holes, from the same sensor pixels.
    ASSERT_EQ(from_camera.num_filled_holes(), from_table.num_filled_holes()) << binning;
    for (int y = 0; y < 48; ++y) {
      for (int x = 0; x < 64; ++x) {
        std::vector<int32_t> a, b;
        from_camera.ForEachIdealPixel(x, y, [&a](int32_t index) { a.push_back(index); });
        from_table.ForEachIdealPixel(x, y, [&b](int32_t index) { b.push_back(index); });
        EXPECT_EQ(a, b) << binning << ": " << x << ", " << y;
      }
    }
  }
  Camera invalid = camera;
  invalid.fx = -1;
  EXPECT_THROW(TimeSurface(invalid, 1), InvalidArgumentError);
  EXPECT_THROW(TimeSurface(camera, 0), InvalidArgumentError);
}

TEST(TimeSurface, BarrelDistortionLeavesNoHoleInsideTheSensorsFootprint) {
  // The DAVIS240C of the Event Camera Dataset: its periphery is stretched by the undistortion,
  // so that rounding each sensor pixel to its ideal pixel skips a fifth of the ideal pixels.
  const Camera camera = testing::EcdDavis240Camera();
  const TimeSurface surface(camera, 1);
  std::vector<int> fills(static_cast<size_t>(surface.width()) * surface.height(), 0);
  int rounded = 0;
  for (int y = 0; y < camera.height; ++y) {
    for (int x = 0; x < camera.width; ++x) {
      rounded += surface.IdealPixelIndex(x, y) >= 0 ? 1 : 0;
      surface.ForEachIdealPixel(x, y, [&fills](int32_t index) { ++fills[index]; });
    }
  }
  EXPECT_GT(surface.num_filled_holes(), 0.15 * rounded);
  // Every ideal pixel whose ray falls on the sensor (more than half a pixel inside its border, so
  // that rounding cannot leave it) is filled, exactly once.
  int inside = 0;
  for (int v = 0; v < surface.height(); ++v) {
    for (int u = 0; u < surface.width(); ++u) {
      Eigen::Vector2d pixel;
      const Eigen::Vector3d ray((u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy, 1.0);
      if (!camera.Project(ray, &pixel) || !camera.IsInside(pixel, 1.0)) continue;
      ++inside;
      EXPECT_EQ(fills[static_cast<size_t>(v) * surface.width() + u], 1) << u << ", " << v;
    }
  }
  EXPECT_GT(inside, 30000);

  // An event at a sensor pixel that fills holes reaches them in both its channels.
  int sensor_x = -1, sensor_y = -1;
  std::vector<int32_t> targets;
  for (int y = 0; y < camera.height && targets.size() < 2; ++y) {
    for (int x = 0; x < camera.width && targets.size() < 2; ++x) {
      targets.clear();
      surface.ForEachIdealPixel(x, y, [&targets](int32_t index) { targets.push_back(index); });
      sensor_x = x;
      sensor_y = y;
    }
  }
  ASSERT_GE(targets.size(), 2u);
  TimeSurface inserted(camera, 1);
  const EventBuffer events =
      MakeEvents({{700, static_cast<uint16_t>(sensor_x), static_cast<uint16_t>(sensor_y), -1}});
  inserted.Insert(events, 0, events.size());
  for (const int32_t index : targets) {
    const int u = index % inserted.width();
    const int v = index / inserted.width();
    EXPECT_EQ(inserted.LastTimestamp(SurfaceChannel::kAll, u, v), 700);
    EXPECT_EQ(inserted.LastTimestamp(SurfaceChannel::kOff, u, v), 700);
    EXPECT_EQ(inserted.LastTimestamp(SurfaceChannel::kOn, u, v), kNeverFired);
  }
  EXPECT_EQ(inserted.num_stored(), 1);

  // A pinhole sensor has none.
  EXPECT_EQ(TimeSurface(Camera::Pinhole(240, 180, 200, 200, 119.5, 89.5), 1).num_filled_holes(),
            0u);
  EXPECT_EQ(TimeSurface(Camera::Pinhole(1280, 720, 1000, 1000, 639.5, 359.5), 2).num_filled_holes(),
            0u);
}

TEST(TimeSurface, UndistortsEventsThroughTheTable) {
  Camera camera = Camera::Pinhole(64, 48, 50, 50, 31.5, 23.5);
  camera.model = CameraModel::kRadialTangential;
  camera.distortion = {-0.3, 0.1, 0.001, -0.002, 0.0};
  const UndistortionTable table(camera);
  TimeSurface surface(table);
  int checked = 0;
  for (const auto& [x, y] : {std::pair{8, 8}, std::pair{56, 40}, std::pair{31, 23}}) {
    const UndistortionTable::Entry* entry = table.Find(x, y);
    ASSERT_NE(entry, nullptr);
    const int ideal_x = static_cast<int>(std::lround(entry->ideal_pixel.x()));
    const int ideal_y = static_cast<int>(std::lround(entry->ideal_pixel.y()));
    if (ideal_x < 0 || ideal_y < 0 || ideal_x >= 64 || ideal_y >= 48) continue;
    const EventBuffer events =
        MakeEvents({{1000 + checked, static_cast<uint16_t>(x), static_cast<uint16_t>(y), 1}});
    surface.Insert(events, 0, 1);
    EXPECT_EQ(surface.LastTimestamp(SurfaceChannel::kAll, ideal_x, ideal_y), 1000 + checked);
    ++checked;
  }
  // The corner pixel moves by more than a pixel under this barrel distortion.
  EXPECT_GT((table.At(8, 8).ideal_pixel - Eigen::Vector2f(8, 8)).norm(), 1.0f);
  EXPECT_EQ(checked, 3);
}

TEST(TimeSurface, FieldIsOneMinusExponentialDecayWithEmptyThreshold) {
  const UndistortionTable table(Camera::Pinhole(20, 20, 30, 30, 9.5, 9.5));
  TimeSurface surface(table);
  const int64_t t_ns = 1'000'000'000;
  // Ages 0, 10 ms, 30 ms, 80 ms (the last below delta = 0.1 with tau = 30 ms).
  const EventBuffer events = MakeEvents({{t_ns - 80'000'000, 2, 2, 1},
                                         {t_ns - 30'000'000, 4, 2, 1},
                                         {t_ns - 10'000'000, 6, 2, -1},
                                         {t_ns, 8, 2, 1}});
  surface.Insert(events, 0, events.size());
  const SurfaceDecay decay{30e6, 0.1};
  TimeSurfaceField field(surface, SurfaceChannel::kAll, decay, /*smooth=*/false);
  field.SetTime(t_ns);
  EXPECT_FLOAT_EQ(field.ValueAt(2, 2), 1.0f);
  EXPECT_NEAR(field.ValueAt(4, 2), 1.0 - std::exp(-1.0), 1e-6);
  EXPECT_NEAR(field.ValueAt(6, 2), 1.0 - std::exp(-1.0 / 3.0), 1e-6);
  EXPECT_FLOAT_EQ(field.ValueAt(8, 2), 0.0f);
  EXPECT_FLOAT_EQ(field.ValueAt(10, 10), 1.0f);
  // The ON channel does not see the OFF event.
  TimeSurfaceField on_field(surface, SurfaceChannel::kOn, decay, false);
  on_field.SetTime(t_ns);
  EXPECT_FLOAT_EQ(on_field.ValueAt(6, 2), 1.0f);
  // The active mask follows the same threshold.
  const cv::Mat mask = surface.ActiveMask(SurfaceChannel::kAll, t_ns, decay);
  EXPECT_EQ(mask.at<uint8_t>(2, 2), 0);
  EXPECT_EQ(mask.at<uint8_t>(2, 4), 255);
  EXPECT_EQ(mask.at<uint8_t>(2, 8), 255);
  EXPECT_EQ(cv::countNonZero(mask), 3);
  // The values behind it: each pixel's SurfaceDecay::Value, 0 where empty or never fired.
  const cv::Mat values = surface.Values(SurfaceChannel::kAll, t_ns, decay);
  ASSERT_EQ(values.type(), CV_32FC1);
  for (int y = 0; y < values.rows; ++y) {
    for (int x = 0; x < values.cols; ++x) {
      EXPECT_EQ(
          values.at<float>(y, x),
          static_cast<float>(decay.Value(surface.LastTimestamp(SurfaceChannel::kAll, x, y), t_ns)))
          << x << ", " << y;
      EXPECT_EQ(values.at<float>(y, x) > 0, mask.at<uint8_t>(y, x) == 255) << x << ", " << y;
    }
  }
}

// The table-and-polynomial exponential of the lazy field agrees with std::exp to 1e-10 relative
// over the whole active window, for several decay times and thresholds.
TEST(TimeSurface, DecayExponentialMatchesExpOverTheActiveWindow) {
  for (const SurfaceDecay decay : {SurfaceDecay{30e6, 0.1}, SurfaceDecay{5e6, 0.01},
                                   SurfaceDecay{100e6, 0.5}, SurfaceDecay{1234.5, 1e-6}}) {
    const DecayExponential exponential(decay);
    ASSERT_EQ(exponential.max_active_age_ns(), decay.MaxActiveAgeExactNs());
    const int64_t last = exponential.max_active_age_ns();
    for (int64_t age : {int64_t{0}, int64_t{1}, last / 3, last - 1, last}) {
      const double exact = std::exp(-static_cast<double>(age) / decay.decay_time_ns);
      EXPECT_NEAR(exponential(age), exact, 1e-10 * exact) << age;
    }
    std::mt19937_64 random(9);
    std::uniform_int_distribution<int64_t> ages(0, last);
    for (int i = 0; i < 100000; ++i) {
      const int64_t age = ages(random);
      const double exact = std::exp(-static_cast<double>(age) / decay.decay_time_ns);
      ASSERT_NEAR(exponential(age), exact, 1e-10 * exact) << age;
    }
  }
}

TEST(TimeSurface, LazySmoothedFieldEqualsDenseRebuildAndItsGradientMatchesDifferences) {
  const UndistortionTable table(Camera::Pinhole(64, 48, 50, 50, 31.5, 23.5));
  TimeSurface surface(table);
  std::mt19937 random(3);
  std::uniform_int_distribution<int> column(0, 63), row(0, 47), polarity(0, 1);
  EventBuffer events;
  for (int i = 0; i < 600; ++i) {
    events.push_back({int64_t{i} * 100'000, static_cast<uint16_t>(column(random)),
                      static_cast<uint16_t>(row(random)),
                      static_cast<int8_t>(polarity(random) ? 1 : -1)});
  }
  surface.Insert(events, 0, events.size());
  for (const SurfaceChannel channel : {SurfaceChannel::kAll, SurfaceChannel::kOn}) {
    TimeSurfaceField field(surface, channel, SurfaceDecay{30e6, 0.1}, /*smooth=*/true);
    field.SetTime(60'000'000);
    const cv::Mat dense = field.RenderDense();
    for (int y = 0; y < 48; ++y) {
      for (int x = 0; x < 64; ++x) {
        ASSERT_NEAR(field.ValueAt(x, y), dense.at<float>(y, x), 1e-6) << x << " " << y;
      }
    }
    // The bilinear derivative is the derivative of the sampled value inside a cell.
    for (const auto& [u, v] :
         {std::pair{10.3, 20.6}, std::pair{40.71, 5.25}, std::pair{0.5, 46.5}}) {
      double value;
      Eigen::Vector2d gradient;
      ASSERT_TRUE(field.Sample(u, v, &value, &gradient));
      double plus, minus;
      ASSERT_TRUE(field.Sample(u + 1e-5, v, &plus, nullptr));
      ASSERT_TRUE(field.Sample(u - 1e-5, v, &minus, nullptr));
      EXPECT_NEAR(gradient.x(), (plus - minus) / 2e-5, 1e-6);
      ASSERT_TRUE(field.Sample(u, v + 1e-5, &plus, nullptr));
      ASSERT_TRUE(field.Sample(u, v - 1e-5, &minus, nullptr));
      EXPECT_NEAR(gradient.y(), (plus - minus) / 2e-5, 1e-6);
    }
  }
}

}  // namespace
}  // namespace evloc::tracking
