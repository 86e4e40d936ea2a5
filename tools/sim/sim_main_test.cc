// Runs the evloc-sim binary: bad command lines fail clearly, and a short render is reproducible.
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "core/dataset/dataset.h"
#include "core/events/event_reader.h"

namespace {

namespace fs = std::filesystem;

struct RunResult {
  int exit_code;
  std::string output;  // stdout and stderr
};

RunResult RunSim(const std::string& arguments) {
  const std::string command = std::string(EVLOC_SIM_BINARY) + " " + arguments + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string output;
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, n);
  const int status = pclose(pipe);
  return {WEXITSTATUS(status), output};
}

// Runs each command line of `cases` and expects exit code 2 and the paired message fragment.
void ExpectBadCommandLines(const std::vector<std::pair<std::string, std::string>>& cases) {
  for (const auto& [arguments, expected] : cases) {
    const RunResult result = RunSim(arguments);
    EXPECT_EQ(result.exit_code, 2) << arguments;
    EXPECT_NE(result.output.find(expected), std::string::npos)
        << arguments << ": " << result.output;
  }
}

TEST(EvlocSimCli, HelpSucceeds) {
  const RunResult result = RunSim("--help");
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_NE(result.output.find("events-from-frames"), std::string::npos);
}

TEST(EvlocSimCli, BadFlagValuesFailWithAClearMessage) {
  const fs::path dir = evloc::testing::MakeTempDir("sim_cli_bad");
  const std::string out = (dir / "out").string();
  ExpectBadCommandLines(
      {{"render --out " + out + " --motion medium", "slow, mid, fast or aggressive"},
       {"render --out " + out + " --lighting night", "bright, dim, dark or hdr"},
       {"render --out " + out + " --duration -1", "--duration"},
       {"render --out " + out + " --fps abc", "--fps expects a number"},
       {"render --out " + out + " --camera vga", "default or davis240"},
       {"render --out " + out + " --bogus", "unknown argument '--bogus'"},
       {"render --out " + out + " --sensor davis999", "ideal, davis240, davis346, gen3 or gen4"},
       {"render --out " + out + " --hot-pixels 1.5", "--hot-pixels must be a fraction"},
       {"render --out " + out + " --noise-rate -1", "--noise-rate must be a rate >= 0"},
       {"render --out " + out + " --clean --hot-pixels 0.01", "drop --noise-rate, --hot-pixels"},
       {"render --out " + out + " --cutoff -5", "--cutoff must be a frequency >= 0"},
       {"render --out " + out + " --time-of-day night", "need --scene carpark"},
       {"render --out " + out + " --path vehicle", "need --scene carpark"},
       {"render --out " + out + " --scene carpark --time-of-day noon", "day, dusk or night"},
       {"render --out " + out + " --scene carpark --path bus", "expected vehicle or pedestrian"},
       {"render --out " + out + " --scene carpark --path vehicle --motion mid",
        "--motion and --path exclude each other"},
       {"render --out " + out + " --scene carpark --path vehicle --speed 0", "--speed must be"},
       {"render --out " + out + " --scene carpark --map-spacing -1", "--map-spacing must be"},
       {"render --out " + out + " --scene carpark --path vehicle --duration 1000",
        "shorten the duration"},
       {"render", "needs --out"},
       {"explode", "unknown command"}});
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(dir);
}

// Numbers are parsed strictly (core/common/cli.h): nan, infinities and trailing text are bad
// command lines, named with the flag, before anything is written.
TEST(EvlocSimCli, RefusesNanInfinityAndTrailingText) {
  const fs::path dir = evloc::testing::MakeTempDir("sim_cli_nan");
  const std::string out = (dir / "out").string();
  const std::string error = "evloc-sim: error: ";
  ExpectBadCommandLines(
      {{"render --out " + out + " --duration nan",
        error + "--duration expects a number, got 'nan'"},
       {"render --out " + out + " --fps inf", error + "--fps expects a number, got 'inf'"},
       {"render --out " + out + " --render-motion 2px", error + "--render-motion expects a number"},
       {"render --out " + out + " --seed -1", error + "--seed expects a non-negative integer"},
       {"events-from-frames --in " + out + " --out " + out + " --contrast nan",
        error + "--contrast expects a number, got 'nan'"},
       {"events-from-frames --in " + out + " --out " + out + " --ecd-size 240x",
        error + "--ecd-size expects an integer"}});
  EXPECT_FALSE(fs::exists(out));
  fs::remove_all(dir);
}

TEST(EvlocSimCli, ExistingOutputNeedsForce) {
  const fs::path dir = evloc::testing::MakeTempDir("sim_cli_force");
  fs::create_directories(dir / "out");
  std::ofstream(dir / "out" / "keep.txt") << "precious";
  const RunResult result =
      RunSim("render --out " + (dir / "out").string() + " --camera davis240 --duration 0.1");
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("--force"), std::string::npos) << result.output;
  EXPECT_TRUE(fs::exists(dir / "out" / "keep.txt"));
  fs::remove_all(dir);
}

TEST(EvlocSimCli, SameSeedSameBytesAndTheDatasetLoads) {
  const fs::path dir = evloc::testing::MakeTempDir("sim_cli_seed");
  const std::string common =
      " --camera davis240 --duration 0.15 --motion fast --seed 5 --events-txt";
  ASSERT_EQ(RunSim("render --out " + (dir / "a").string() + common).exit_code, 0);
  ASSERT_EQ(RunSim("render --out " + (dir / "b").string() + common).exit_code, 0);
  for (const char* name :
       {"events.evb", "events.txt", "groundtruth.txt", "images/frame_00000004.png"}) {
    EXPECT_EQ(evloc::ReadFileToString(dir / "a" / name), evloc::ReadFileToString(dir / "b" / name))
        << name;
  }
  const evloc::Dataset dataset = evloc::ReadDataset(dir / "a");
  EXPECT_EQ(dataset.camera.width, 240);
  EXPECT_EQ(dataset.images.size(), 5u);  // exposures [k/30, k/30 + 10 ms] inside 0.15 s: k = 0..4
  EXPECT_EQ(dataset.depth.size(), 5u);
  ASSERT_TRUE(dataset.ground_truth.has_value());
  EXPECT_GE(dataset.ground_truth->size(), 0.15 * 200);
  ASSERT_TRUE(dataset.events_path.has_value());
  auto reader = evloc::OpenEventFile(*dataset.events_path);
  evloc::EventBuffer events;
  while (reader->Read(100000, &events) > 0) {
  }
  EXPECT_EQ(static_cast<int64_t>(events.size()),
            (*dataset.info)["counts"]["events"].get<int64_t>());
  EXPECT_GT(events.size(), 1000u);
  EXPECT_TRUE(dataset.ground_truth_map_path.has_value());
  fs::remove_all(dir);
}

// Reads info.json's counts of a rendered dataset.
nlohmann::json CountsOf(const fs::path& dataset) {
  return nlohmann::json::parse(evloc::ReadFileToString(dataset / "info.json"))["counts"];
}

// `--sensor ideal` is the default pixel (the original ESIM, whose recorded stream esim_test.cc
// checks); a realistic sensor's events follow the light: the same path in the dark has other
// events and more noise than in bright light, and info.json counts them by origin.
TEST(EvlocSimCli, IdealIsTheDefaultAndTheRealisticPixelSeesTheLight) {
  const fs::path dir = evloc::testing::MakeTempDir("sim_cli_sensor");
  const double duration_s = 0.2;
  const std::string common =
      " --camera davis240 --motion fast --seed 3 --duration " + std::to_string(duration_s);
  ASSERT_EQ(RunSim("render --out " + (dir / "default").string() + common).exit_code, 0);
  ASSERT_EQ(
      RunSim("render --out " + (dir / "ideal").string() + common + " --sensor ideal").exit_code, 0);
  EXPECT_EQ(evloc::ReadFileToString(dir / "default" / "events.evb"),
            evloc::ReadFileToString(dir / "ideal" / "events.evb"));
  const std::string realistic = common + " --sensor davis240 --noise-rate 3 --hot-pixels 0.002";
  for (const char* lighting : {"bright", "dark"}) {
    const RunResult result =
        RunSim("render --out " + (dir / lighting).string() + realistic + " --lighting " + lighting);
    ASSERT_EQ(result.exit_code, 0) << result.output;
  }
  const nlohmann::json bright = CountsOf(dir / "bright");
  const nlohmann::json dark = CountsOf(dir / "dark");
  for (const nlohmann::json& counts : {bright, dark}) {
    EXPECT_EQ(counts["events"].get<int64_t>(),
              counts["signal_events"].get<int64_t>() + counts["noise_events"].get<int64_t>() +
                  counts["leak_events"].get<int64_t>() + counts["hot_pixel_events"].get<int64_t>());
    // 86 hot pixels at 1 kHz, 0.5 ms refractory period: 1000 / (1 + 0.5) = 667 Hz each.
    const double expected_hot = 86 * 1000 / 1.5 * duration_s;
    EXPECT_NEAR(counts["hot_pixel_events"].get<double>(), expected_hot,
                5 * std::sqrt(expected_hot));
  }
  // Shot noise rises as the light falls (dark: illumination 0.02 of bright).
  EXPECT_GT(dark["noise_events"].get<double>(), 3 * bright["noise_events"].get<double>());
  // The slow dark photoreceptor blurs edges: fewer signal events for the same path.
  EXPECT_LT(dark["signal_events"].get<double>(), 0.9 * bright["signal_events"].get<double>());
  EXPECT_NE(evloc::ReadFileToString(dir / "bright" / "events.evb"),
            evloc::ReadFileToString(dir / "dark" / "events.evb"));
  fs::remove_all(dir);
}

// The survey: photos of the car park with their exact poses, a dataset the reader (and so the
// mapper's --images-list / --known-poses) takes; bad survey flags are bad command lines.
TEST(EvlocSimCli, SurveyWritesPhotosWithExactPosesAsADataset) {
  const fs::path dir = evloc::testing::MakeTempDir("sim_cli_survey");
  const std::string out = (dir / "survey").string();
  ExpectBadCommandLines({{"survey --out " + out + " --survey drone", "expected walk or car"},
                         {"survey --out " + out + " --spacing 0", "--spacing must be"},
                         {"survey --out " + out + " --max-photos 0", "--max-photos must be"},
                         {"survey", "needs --out"}});
  const RunResult result = RunSim("survey --out " + out +
                                  " --survey car --spacing 1.5 --max-photos 3 --camera davis240");
  ASSERT_EQ(result.exit_code, 0) << result.output;
  const evloc::Dataset dataset = evloc::ReadDataset(out);
  ASSERT_EQ(dataset.images.size(), 3u);
  ASSERT_TRUE(dataset.ground_truth.has_value());
  ASSERT_EQ(dataset.ground_truth->size(), 3u);
  // The mapping car drives at 3 m/s: photos 0.5 s and 1.5 m apart, 2 m up, along the route.
  EXPECT_NEAR(dataset.images[1].t_ns * 1e-9, 0.5, 1e-9);
  const auto first = dataset.ground_truth->Lookup(dataset.images[0].t_ns);
  const auto second = dataset.ground_truth->Lookup(dataset.images[1].t_ns);
  ASSERT_TRUE(first && second);
  EXPECT_NEAR((second->translation - first->translation).head<2>().norm(), 1.5, 1e-3);
  EXPECT_NEAR(first->translation.z(), 2.0, 0.01);
  EXPECT_EQ(dataset.camera.width, 240);
  fs::remove_all(dir);
}

}  // namespace
