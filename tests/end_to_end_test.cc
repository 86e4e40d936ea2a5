// End to end through the command-line tools, as a user runs them: evloc-sim renders a short
// sequence with its exact map, evloc-track tracks its events, evloc-eval scores the trajectory.
// The accuracy assertion is the default suite's guard on the whole tracking chain.
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/common/test_data.h"

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

}  // namespace
