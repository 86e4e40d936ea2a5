// End to end through the command-line tools, as a user runs them: evloc-sim renders a short
// sequence with its exact map, evloc-track tracks its events, evloc-eval scores the trajectory.
// The accuracy assertion is the default suite's guard on the whole tracking chain.
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <GeographicLib/Geodesic.hpp>
#include <GeographicLib/LocalCartesian.hpp>
#include <nlohmann/json.hpp>

#include "core/common/test_data.h"
#include "core/trajectory/tum_io.h"

namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code;
  std::string output;  // stdout and stderr
};

RunResult RunCommand(const std::string& command) {
  FILE* pipe = popen((command + " 2>&1").c_str(), "r");
  std::string output;
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, n);
  const int status = pclose(pipe);
  return {WEXITSTATUS(status), output};
}

TEST(EndToEnd, SimulatedSequenceIsTrackedToSubCentimetre) {
  const fs::path directory = evloc::testing::MakeTempDir("evloc-end-to-end");
  const fs::path dataset = directory / "dataset";
  const RunResult render = RunCommand(std::string(EVLOC_SIM_BINARY) + " render --out " +
                                      dataset.string() + " --motion slow --duration 1.5 --seed 3");
  ASSERT_EQ(render.exit_code, 0) << render.output;

  const fs::path estimate = directory / "estimate.txt";
  const fs::path stats = directory / "stats.json";
  const RunResult track = RunCommand(
      std::string(EVLOC_TRACK_BINARY) + " --map " + (dataset / "gt_map").string() + " --dataset " +
      dataset.string() + " --out " + estimate.string() + " --stats " + stats.string() + " --quiet");
  ASSERT_EQ(track.exit_code, 0) << track.output;

  const fs::path report = directory / "report.json";
  const RunResult eval = RunCommand(std::string(EVLOC_EVAL_BINARY) + " --gt " +
                                    (dataset / "groundtruth.txt").string() + " --est " +
                                    estimate.string() + " --json " + report.string());
  ASSERT_EQ(eval.exit_code, 0) << eval.output;

  const nlohmann::json figures = nlohmann::json::parse(std::ifstream(report));
  const nlohmann::json steps = nlohmann::json::parse(std::ifstream(stats));
  EXPECT_EQ(steps["lost_steps"].get<int>(), 0);
  EXPECT_LT(figures["ate_t_rmse_cm"].get<double>(), 1.0) << figures.dump(1);
  EXPECT_LT(figures["ate_r_rmse_deg"].get<double>(), 1.0) << figures.dump(1);
  EXPECT_GT(figures["coverage"].get<double>(), 0.98) << figures.dump(1);
  EXPECT_TRUE(figures["failed_at_s"].is_null()) << figures.dump(1);
  fs::remove_all(directory);
}

// evloc-track --init-pose none --start S: no pose given, the tracker searches the map (the
// keyframes of the simulator's exact map), says INITIALIZING meanwhile and writes no pose for
// those steps, and the poses it then writes as TRACKING are right.
TEST(EndToEnd, TrackerFindsItselfWithoutAnInitialPose) {
  const fs::path directory = evloc::testing::MakeTempDir("evloc-end-to-end-no-pose");
  const fs::path dataset = directory / "dataset";
  const RunResult render = RunCommand(std::string(EVLOC_SIM_BINARY) + " render --out " +
                                      dataset.string() + " --motion slow --duration 1.5 --seed 5");
  ASSERT_EQ(render.exit_code, 0) << render.output;

  const fs::path estimate = directory / "estimate.txt";
  const fs::path stats = directory / "stats.json";
  const RunResult track =
      RunCommand(std::string(EVLOC_TRACK_BINARY) + " --map " + (dataset / "gt_map").string() +
                 " --dataset " + dataset.string() + " --out " + estimate.string() + " --stats " +
                 stats.string() + " --init-pose none --start 0.4 --quiet");
  ASSERT_EQ(track.exit_code, 0) << track.output;
  const nlohmann::json steps = nlohmann::json::parse(std::ifstream(stats));
  const nlohmann::json& per_step = steps["per_step"];
  ASSERT_GT(per_step.size(), 100u);
  // The first step is at the start time (0.4 s after the first event, which evloc-sim writes at
  // the first render after t = 0) and searches.
  const double start_s = per_step[0]["t_s"].get<double>();
  EXPECT_NEAR(start_s, 0.4, 0.01);
  EXPECT_EQ(per_step[0]["status"], "INITIALIZING");
  double first_tracking_s = -1;
  for (const nlohmann::json& step : per_step) {
    const std::string status = step["status"];
    EXPECT_TRUE(status == "INITIALIZING" || status == "TRACKING" || status == "LOST" ||
                status == "RELOCALIZING")
        << status;
    if (status == "TRACKING" && first_tracking_s < 0) first_tracking_s = step["t_s"];
    EXPECT_TRUE(step.contains("total_ms"));
  }
  ASSERT_GE(first_tracking_s, 0) << "never TRACKING";
  EXPECT_LT(first_tracking_s - start_s, 1.0);
  ASSERT_EQ(steps["relocalizations"].size(), 1u) << steps["relocalizations"].dump();
  const nlohmann::json& episode = steps["relocalizations"][0];
  EXPECT_EQ(episode["outcome"], "found");
  EXPECT_DOUBLE_EQ(episode["start_t_s"].get<double>(), start_s);
  EXPECT_DOUBLE_EQ(episode["end_t_s"].get<double>(), first_tracking_s);
  EXPECT_EQ(steps["lost_steps"].get<int>(), 0);

  // The trajectory holds the TRACKING poses only (no pose while searching): all of them right.
  const fs::path report = directory / "report.json";
  const RunResult eval = RunCommand(std::string(EVLOC_EVAL_BINARY) + " --align none --gt " +
                                    (dataset / "groundtruth.txt").string() + " --est " +
                                    estimate.string() + " --json " + report.string());
  ASSERT_EQ(eval.exit_code, 0) << eval.output;
  const nlohmann::json figures = nlohmann::json::parse(std::ifstream(report));
  EXPECT_LT(figures["ate_t_max_cm"].get<double>(), 5.0) << figures.dump(1);
  EXPECT_LT(figures["ate_t_rmse_cm"].get<double>(), 1.5) << figures.dump(1);
  EXPECT_LT(figures["ate_r_rmse_deg"].get<double>(), 3.0) << figures.dump(1);
  fs::remove_all(directory);
}

TEST(EndToEnd, TrackerRefusesADatasetWithoutEventsClearly) {
  const fs::path directory = evloc::testing::MakeTempDir("evloc-end-to-end-bad");
  const RunResult track =
      RunCommand(std::string(EVLOC_TRACK_BINARY) + " --map " + (directory / "no-map").string() +
                 " --dataset " + (directory / "no-dataset").string() + " --out " +
                 (directory / "out.txt").string());
  EXPECT_EQ(track.exit_code, 1);
  EXPECT_NE(track.output.find("no-dataset"), std::string::npos) << track.output;
  EXPECT_FALSE(fs::exists(directory / "out.txt"));
  fs::remove_all(directory);
}

// The geo-reference end to end (docs/geo.md, docs/accuracy.md "Geo-reference"): evloc-sim renders
// a sequence with its exact map, `evloc-mapper georef` gives the map an anchor, evloc-track
// writes the poses in WGS84 (--geo), and they are compared with the ground truth converted to
// WGS84 independently of evloc's core/geo: the anchor's rotation written out by hand and
// GeographicLib's LocalCartesian, the distance on the ellipsoid by GeographicLib's Geodesic.
// Target (issue 18): within 0.1 m of the truth.
// The anchor given to the map: a car park in Zurich, the map's +y axis 30 degrees east of north.
constexpr double kLatitude = 47.3769, kLongitude = 8.5417, kAltitude = 408.0, kHeading = 30.0;

TEST(GeoEndToEnd, PosesInWgs84AreWithinATenthOfAMetreOfTheTruth) {
  const fs::path directory = evloc::testing::MakeTempDir("evloc-geo-end-to-end");
  const fs::path dataset = directory / "dataset";
  const RunResult render = RunCommand(std::string(EVLOC_SIM_BINARY) + " render --out " +
                                      dataset.string() + " --motion slow --duration 1.0 --seed 5");
  ASSERT_EQ(render.exit_code, 0) << render.output;
  const fs::path map = dataset / "gt_map";

  // Without an anchor --geo is refused, naming the map and the remedy.
  const std::string track = std::string(EVLOC_TRACK_BINARY) + " --map " + map.string() +
                            " --dataset " + dataset.string() + " --quiet --out " +
                            (directory / "estimate.txt").string() + " --geo " +
                            (directory / "geo.txt").string();
  RunResult run = RunCommand(track);
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_NE(run.output.find("has no geo anchor"), std::string::npos) << run.output;
  EXPECT_NE(run.output.find("evloc-mapper georef"), std::string::npos) << run.output;
  // So is a GNSS fix (it has no meaning in the map frame without one).
  run = RunCommand(std::string(EVLOC_TRACK_BINARY) + " --map " + map.string() + " --dataset " +
                   dataset.string() + " --quiet --out " + (directory / "estimate.txt").string() +
                   " --init-pose none --gnss 47.3769,8.5417,408,3");
  EXPECT_EQ(run.exit_code, 1);
  EXPECT_NE(run.output.find("has no geo anchor"), std::string::npos) << run.output;

  char anchor[128];
  std::snprintf(anchor, sizeof(anchor), "%.4f,%.4f,%.1f,%.1f", kLatitude, kLongitude, kAltitude,
                kHeading);
  run = RunCommand(std::string(EVLOC_MAPPER_BINARY) + " georef --map " + map.string() +
                   " --geo-anchor " + anchor);
  ASSERT_EQ(run.exit_code, 0) << run.output;
  run = RunCommand(track);
  ASSERT_EQ(run.exit_code, 0) << run.output;

  const evloc::Trajectory truth = evloc::ReadTumTrajectory(dataset / "groundtruth.txt");
  const GeographicLib::LocalCartesian enu(kLatitude, kLongitude, kAltitude);
  const double h = kHeading * M_PI / 180.0;
  // Map frame to ENU, written out: map +y at heading h, map +x at heading h + 90 degrees.
  const auto to_enu = [h](const Eigen::Vector3d& v) {
    return Eigen::Vector3d(v.x() * std::cos(h) + v.y() * std::sin(h),
                           -v.x() * std::sin(h) + v.y() * std::cos(h), v.z());
  };
  // Scores one --geo file against the truth.
  const auto score = [&](const fs::path& path, const char* what, int min_poses = 250) {
    std::ifstream geo(path);
    std::string line;
    int poses = 0;
    double sum_squared = 0.0, worst = 0.0, worst_heading = 0.0;
    while (std::getline(geo, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream fields(line);
      double t_s, latitude, longitude, altitude, heading, pitch, east, north, up;
      ASSERT_TRUE(fields >> t_s >> latitude >> longitude >> altitude >> heading >> pitch >> east >>
                  north >> up)
          << line;
      const auto world_from_cam = truth.Lookup(std::llround(t_s * 1e9));
      ASSERT_TRUE(world_from_cam.has_value()) << line;
      const Eigen::Vector3d centre = to_enu(world_from_cam->translation);
      double true_latitude, true_longitude, true_altitude;
      enu.Reverse(centre.x(), centre.y(), centre.z(), true_latitude, true_longitude, true_altitude);
      double horizontal = 0.0;
      GeographicLib::Geodesic::WGS84().Inverse(true_latitude, true_longitude, latitude, longitude,
                                               horizontal);
      const double error = std::hypot(horizontal, altitude - true_altitude);
      sum_squared += error * error;
      worst = std::max(worst, error);
      // The heading of the true optical axis (the local north differs from the anchor's by 1e-7
      // degrees over the room's metres).
      const Eigen::Vector3d axis = to_enu(world_from_cam->rotation * Eigen::Vector3d::UnitZ());
      double true_heading = std::atan2(axis.x(), axis.y()) * 180.0 / M_PI;
      if (true_heading < 0) true_heading += 360.0;
      double heading_error = std::abs(heading - true_heading);
      heading_error = std::min(heading_error, 360.0 - heading_error);
      worst_heading = std::max(worst_heading, heading_error);
      ++poses;
    }
    ASSERT_GT(poses, min_poses) << what;
    const double rms = std::sqrt(sum_squared / poses);
    std::printf(
        "geo end to end (%s): %d poses, WGS84 position error RMS %.4f m, max %.4f m; heading "
        "error max %.3f deg\n",
        what, poses, rms, worst, worst_heading);
    RecordProperty(std::string(what) + "_poses", poses);
    RecordProperty(std::string(what) + "_rms_m", std::to_string(rms));
    RecordProperty(std::string(what) + "_max_m", std::to_string(worst));
    EXPECT_LT(worst, 0.1) << what;
    EXPECT_LT(worst_heading, 1.0) << what;
  };
  score(directory / "geo.txt", "map");

  // The same map served as a site of tiles: the manifest carries the anchor, so --geo works on
  // the site too (0.5 m tiles, composed 1.5 m around the camera and 2 m ahead on its axis: the
  // room's walls are 2 m away).
  const fs::path site = directory / "site";
  run = RunCommand(std::string(EVLOC_MAPPER_BINARY) + " tile --map " + map.string() + " --out " +
                   site.string() + " --tile-size 0.5 --overlap 0.2");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  run =
      RunCommand(std::string(EVLOC_TRACK_BINARY) + " --map " + site.string() + " --dataset " +
                 dataset.string() + " --quiet --out " + (directory / "site_estimate.txt").string() +
                 " --geo " + (directory / "site_geo.txt").string() +
                 " --tile-radius 1.5 --tile-view-distance 2");
  ASSERT_EQ(run.exit_code, 0) << run.output;
  score(directory / "site_geo.txt", "site");

  // Without a pose, a GNSS fix where the run starts (the true position at 0.4 s, accuracy 0.5 m)
  // narrows the search (--gnss); on the site it also chooses the tiles, which no pose can. The
  // poses written (TRACKING only) are right.
  const Eigen::Vector3d start = to_enu(truth.Lookup(400'000'000)->translation);
  double fix_latitude, fix_longitude, fix_altitude;
  enu.Reverse(start.x(), start.y(), start.z(), fix_latitude, fix_longitude, fix_altitude);
  char fix[160];
  std::snprintf(fix, sizeof(fix), "%.9f,%.9f,%.3f,0.5", fix_latitude, fix_longitude, fix_altitude);
  for (const auto& [target, what] :
       {std::pair{map, "map, no pose, GNSS fix"}, std::pair{site, "site, no pose, GNSS fix"}}) {
    const fs::path geo = directory / "fix_geo.txt";
    run = RunCommand(std::string(EVLOC_TRACK_BINARY) + " --map " + target.string() + " --dataset " +
                     dataset.string() + " --quiet --out " +
                     (directory / "fix_estimate.txt").string() + " --geo " + geo.string() +
                     " --init-pose none --start 0.4 --gnss " + fix +
                     " --tile-radius 1.5 --tile-view-distance 2");
    ASSERT_EQ(run.exit_code, 0) << what << ": " << run.output;
    score(geo, what, 100);
  }
  fs::remove_all(directory);
}

}  // namespace
