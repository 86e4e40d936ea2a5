// Runs the evloc-eval binary on small files and checks its exit codes, messages and JSON.
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/common/file_util.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together.
};

CommandResult RunEval(const std::string& arguments, const std::filesystem::path& directory) {
  const std::filesystem::path output_path = directory / "output.txt";
  const std::string command =
      std::string(EVLOC_EVAL_BINARY) + " " + arguments + " > " + output_path.string() + " 2>&1";
  const int status = std::system(command.c_str());
  CommandResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.output = ReadFileToString(output_path);
  return result;
}

class EvalCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = testing::MakeTempDir("eval_cli");
    std::string ground_truth = "# ground truth\n";
    std::string estimate = "# estimate, 3 cm off in y\n";
    for (int k = 0; k <= 300; ++k) {
      const std::string time = std::to_string(100 + k / 100) + "." +
                               std::string(k % 100 < 10 ? "0" : "") + std::to_string(k % 100);
      const std::string x = std::to_string(0.01 * k);
      ground_truth += time + " " + x + " 0 1 0 0 0 1\n";
      estimate += time + " " + x + " 0.03 1 0 0 0 1\n";
    }
    WriteFileAtomically(directory_ / "gt.txt", ground_truth);
    WriteFileAtomically(directory_ / "est.txt", estimate);
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }

  std::string PathOf(const std::string& name) const { return (directory_ / name).string(); }

  std::filesystem::path directory_;
};

TEST_F(EvalCliTest, WritesJsonWithTheDocumentedKeys) {
  const CommandResult result =
      RunEval("--gt " + PathOf("gt.txt") + " --est " + PathOf("est.txt") + " --json " +
                  PathOf("report.json") + " --plot " + PathOf("plot.png") + " --fail-cm 2",
              directory_);
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("ATE translation RMSE"), std::string::npos) << result.output;
  const nlohmann::json json = nlohmann::json::parse(ReadFileToString(PathOf("report.json")));
  for (const char* key : {"ate_t_rmse_cm", "ate_t_mean_cm", "ate_t_median_cm", "ate_t_max_cm",
                          "ate_r_rmse_deg", "rpe_t_rmse_cm_s", "rpe_r_rmse_deg_s", "coverage",
                          "failed_at_s", "alignment", "delta_s", "matched_poses"}) {
    EXPECT_TRUE(json.contains(key)) << key;
  }
  EXPECT_NEAR(json["ate_t_rmse_cm"].get<double>(), 3.0, 1e-6);
  EXPECT_NEAR(json["rpe_t_rmse_cm_s"].get<double>(), 0.0, 1e-6);
  EXPECT_EQ(json["matched_poses"], 301);
  EXPECT_EQ(json["alignment"], "none");
  EXPECT_DOUBLE_EQ(json["delta_s"].get<double>(), 1.0);
  // 3 cm exceeds 2 cm from the first pose on.
  EXPECT_DOUBLE_EQ(json["failed_at_s"].get<double>(), 0.0);
  EXPECT_GT(std::filesystem::file_size(PathOf("plot.png")), 1000u);
}

TEST_F(EvalCliTest, HelpSucceeds) {
  const CommandResult result = RunEval("--help", directory_);
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_NE(result.output.find("--max-dt"), std::string::npos);
}

TEST_F(EvalCliTest, MalformedFileFailsNamingFileAndLine) {
  WriteFileAtomically(directory_ / "bad.txt", "# x\n1.0 0 0 0 0 0 0 1\n2.0 0 0 zero 0 0 0 1\n");
  const CommandResult result =
      RunEval("--gt " + PathOf("gt.txt") + " --est " + PathOf("bad.txt"), directory_);
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_NE(result.output.find("bad.txt: line 3"), std::string::npos) << result.output;
}

TEST_F(EvalCliTest, MissingFileFails) {
  const CommandResult result =
      RunEval("--gt " + PathOf("gt.txt") + " --est " + PathOf("absent.txt"), directory_);
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_NE(result.output.find("absent.txt"), std::string::npos) << result.output;
}

TEST_F(EvalCliTest, BadCommandLineFailsWithUsageHint) {
  CommandResult result = RunEval("--gt " + PathOf("gt.txt"), directory_);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("--est is required"), std::string::npos) << result.output;
  result = RunEval("--gt " + PathOf("gt.txt") + " --est " + PathOf("est.txt") + " --align affine",
                   directory_);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.output.find("affine"), std::string::npos) << result.output;
  result = RunEval("--gt " + PathOf("gt.txt") + " --est " + PathOf("est.txt") + " --delta x",
                   directory_);
  EXPECT_EQ(result.exit_code, 2);
  for (const char* segments : {"1,x", "1,-2", "0"}) {
    result = RunEval(
        "--gt " + PathOf("gt.txt") + " --est " + PathOf("est.txt") + " --segments " + segments,
        directory_);
    EXPECT_EQ(result.exit_code, 2) << segments;
    EXPECT_NE(result.output.find("segments"), std::string::npos) << result.output;
  }
}

TEST_F(EvalCliTest, SegmentsAddTheDriftOverPathLengths) {
  const CommandResult result = RunEval("--gt " + PathOf("gt.txt") + " --est " + PathOf("est.txt") +
                                           " --segments 0.1,1000 --json " + PathOf("drift.json"),
                                       directory_);
  ASSERT_EQ(result.exit_code, 0) << result.output;
  EXPECT_NE(result.output.find("drift over 0.10 m"), std::string::npos) << result.output;
  EXPECT_NE(result.output.find("n/a (the path is shorter)"), std::string::npos) << result.output;
  const nlohmann::json json = nlohmann::json::parse(ReadFileToString(PathOf("drift.json")));
  ASSERT_EQ(json["drift"].size(), 2u);
  EXPECT_GT(json["drift"][0]["segments"].get<int>(), 0);
  EXPECT_TRUE(json["drift"][1]["t_percent"].is_null());
}

}  // namespace
}  // namespace evloc
