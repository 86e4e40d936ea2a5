#include "mapper/mapper_cli.h"

#include <gtest/gtest.h>

#include <sys/wait.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"
#include "mapper/relocalization_data.h"
#include "mapper/testing/mapper_cli_runner.h"
#include "mapper/testing/middlebury_map.h"
#include "maps/map.h"
#include "maps/map_directory.h"
#include "maps/testing/map_file_editing.h"

namespace evloc {
namespace {

using testing::CliResult;
using testing::RunCli;

bool Contains(const std::string& text, const std::string& fragment) {
  return text.find(fragment) != std::string::npos;
}

const char kPcd[] =
    "# .PCD v0.7 - Point Cloud Data file format\n"
    "VERSION 0.7\n"
    "FIELDS x y z normal_x normal_y normal_z\n"
    "SIZE 4 4 4 4 4 4\nTYPE F F F F F F\nCOUNT 1 1 1 1 1 1\n"
    "WIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA ascii\n"
    "0 0 1 0.02 0 1\n"
    "1 2 3 1 2 3\n"
    "-1 0.5 2 -1 0.5 2.025\n";

class MapperCliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    directory_ = testing::MakeTempDir("mapper_cli_test");
    pcd_ = directory_ / "map.pcd";
    WriteFileAtomically(pcd_, std::string(kPcd));
  }
  void TearDown() override { std::filesystem::remove_all(directory_); }
  std::filesystem::path directory_;
  std::filesystem::path pcd_;
};

TEST_F(MapperCliTest, ImportPcdThenInfo) {
  const std::filesystem::path map_dir = directory_ / "out";
  const CliResult import = RunCli({"import-pcd", pcd_.string(), "--out", map_dir.string()});
  ASSERT_EQ(import.exit_code, 0) << import.err;
  EXPECT_TRUE(Contains(import.out, "imported 2 of 3 points")) << import.out;
  EXPECT_TRUE(Contains(import.out, "dropped 1 with a zero-length gradient")) << import.out;
  EXPECT_TRUE(std::filesystem::exists(map_dir / "map.ply"));
  const Map map = LoadMap(map_dir / "map.evmap");
  ASSERT_EQ(map.size(), 2u);
  EXPECT_EQ(map.gradients[1], Eigen::Vector3f(0, 0, 1));
  EXPECT_EQ(map.provenance.tool, "evloc-mapper import-pcd");
  EXPECT_TRUE(Contains(map.provenance.command_line, "import-pcd")) << map.provenance.command_line;
  ASSERT_EQ(map.provenance.inputs.size(), 1u);
  EXPECT_TRUE(Contains(map.provenance.inputs[0], "map.pcd"));
  EXPECT_EQ(map.provenance.created_utc.size(), 20u) << map.provenance.created_utc;

  for (const std::filesystem::path& target : {map_dir, map_dir / "map.evmap"}) {
    const CliResult info = RunCli({"info", target.string()});
    ASSERT_EQ(info.exit_code, 0) << info.err;
    EXPECT_TRUE(Contains(info.out, "points:           2")) << info.out;
    EXPECT_TRUE(Contains(info.out, "keyframes:        0")) << info.out;
    EXPECT_TRUE(Contains(info.out, "verified")) << info.out;
    EXPECT_TRUE(Contains(info.out, "evloc-mapper import-pcd")) << info.out;
  }
}

TEST_F(MapperCliTest, ImportRefusesAnExistingMapUnlessForced) {
  const std::filesystem::path map_dir = directory_ / "out";
  ASSERT_EQ(RunCli({"import-pcd", pcd_.string(), "--out", map_dir.string()}).exit_code, 0);
  const CliResult again = RunCli({"import-pcd", pcd_.string(), "--out", map_dir.string()});
  EXPECT_EQ(again.exit_code, 1);
  EXPECT_TRUE(Contains(again.err, "already holds a map")) << again.err;
  EXPECT_TRUE(Contains(again.err, "--force")) << again.err;
  EXPECT_EQ(RunCli({"import-pcd", pcd_.string(), "--out", map_dir.string(), "--force"}).exit_code,
            0);
}

TEST_F(MapperCliTest, BadInputsGiveAClearMessageAndNonZeroExit) {
  const std::filesystem::path map_dir = directory_ / "out";
  CliResult result =
      RunCli({"import-pcd", (directory_ / "missing.pcd").string(), "--out", map_dir.string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "missing.pcd' does not exist")) << result.err;
  EXPECT_FALSE(std::filesystem::exists(map_dir));

  WriteFileAtomically(directory_ / "bad.pcd", std::string(kPcd).substr(0, 300) + "\n1 2 x\n");
  result = RunCli({"import-pcd", (directory_ / "bad.pcd").string(), "--out", map_dir.string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "bad.pcd: line")) << result.err;
  EXPECT_FALSE(std::filesystem::exists(map_dir)) << "nothing is written on error";

  result = RunCli({"info", (directory_ / "missing.evmap").string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "cannot open map")) << result.err;

  result = RunCli({"info", pcd_.string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "not an evloc map")) << result.err;

  ASSERT_EQ(RunCli({"import-pcd", pcd_.string(), "--out", map_dir.string()}).exit_code, 0);
  const std::string bytes = ReadFileToString(map_dir / "map.evmap");
  WriteFileAtomically(directory_ / "truncated.evmap", bytes.substr(0, bytes.size() - 10));
  result = RunCli({"info", (directory_ / "truncated.evmap").string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err,
                       "truncated evloc map: expected " + std::to_string(bytes.size()) + " bytes"))
      << result.err;

  result = RunCli({"info", directory_.string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "without map.evmap")) << result.err;
}

TEST_F(MapperCliTest, UsageErrorsAndHelp) {
  CliResult result = RunCli({});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(Contains(result.err, "import-pcd")) << result.err;
  result = RunCli({"--help"});
  EXPECT_EQ(result.exit_code, 0);
  EXPECT_TRUE(Contains(result.out, "info")) << result.out;
  result = RunCli({"frobnicate"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(Contains(result.err, "unknown subcommand 'frobnicate'")) << result.err;
  result = RunCli({"import-pcd", pcd_.string()});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(Contains(result.err, "needs --out MAPDIR")) << result.err;
  result = RunCli({"import-pcd", pcd_.string(), "--out", "x", "--min-gradient-offset", "abc"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(Contains(result.err, "expects a number, got 'abc'")) << result.err;
  result = RunCli({"info", "--bogus"});
  EXPECT_EQ(result.exit_code, 2);
  for (const char* subcommand : {"import-pcd", "info"}) {
    result = RunCli({subcommand, "--help"});
    EXPECT_EQ(result.exit_code, 0);
    EXPECT_TRUE(Contains(result.out, std::string("usage: evloc-mapper ") + subcommand));
  }
}

// Numbers are parsed strictly (core/common/cli.h): nan, infinities and trailing text are bad
// command lines, and nothing is written.
TEST_F(MapperCliTest, RefusesNanInfinityAndTrailingText) {
  const std::filesystem::path map_dir = directory_ / "out";
  for (const char* value : {"nan", "inf", "-inf", "0.01m"}) {
    const CliResult result = RunCli(
        {"import-pcd", pcd_.string(), "--out", map_dir.string(), "--min-gradient-offset", value});
    EXPECT_EQ(result.exit_code, 2) << value;
    EXPECT_TRUE(Contains(result.err, std::string("evloc-mapper import-pcd: error: "
                                                 "--min-gradient-offset expects a number, got '") +
                                         value + "'"))
        << result.err;
  }
  // A number outside the option's domain is a bad command line too.
  const CliResult negative = RunCli(
      {"import-pcd", pcd_.string(), "--out", map_dir.string(), "--min-gradient-offset", "-1"});
  EXPECT_EQ(negative.exit_code, 2) << negative.err;
  EXPECT_FALSE(std::filesystem::exists(map_dir));
}

TEST_F(MapperCliTest, TheBinaryExitsNonZeroOnAForeignFile) {
  const std::string command = std::string(EVLOC_MAPPER_BINARY) + " info '" + pcd_.string() +
                              "' > '" + (directory_ / "stdout.txt").string() + "' 2> '" +
                              (directory_ / "stderr.txt").string() + "'";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  EXPECT_TRUE(Contains(ReadFileToString(directory_ / "stderr.txt"), "not an evloc map"));
}

// Writes `map` as a format version 1 file: a v2 file without relocalization data, with the
// version 1 in the header and the payload (what the v1 writer wrote).
void SaveAsVersion1(const std::filesystem::path& path, const Map& map) {
  ASSERT_FALSE(map.relocalization.has_value());
  SaveMap(path, map);
  const std::string bytes = testing::EditMapPayload(
      ReadFileToString(path), [](map_format::MapFile& file) { file.set_format_version(1); }, 1);
  ASSERT_FALSE(bytes.empty());
  WriteFileAtomically(path, bytes);
}

// `upgrade` on a v1 map of the 8 first templeSparseRing photos at their calibrated poses: in place
// with a backup, the data equal to the build stage's (one function), refusals, --out, a missing
// image named.
TEST_F(MapperCliTest, UpgradeAddsRelocalizationDataToAVersion1Map) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  std::vector<testing::MiddleburyView> views = testing::ReadMiddleburyParameters(parameters);
  ASSERT_EQ(views.size(), 16u);
  views.resize(8);
  Map map = testing::MiddleburyKeyframeMap(views);
  map.AddPoint(Eigen::Vector3f(0.0f, 0.1f, 0.02f), Eigen::Vector3f::UnitX(), 0.1f, 0.2f, 0);
  const std::filesystem::path map_dir = directory_ / "temple";
  std::filesystem::create_directories(map_dir);
  const std::filesystem::path file = map_dir / "map.evmap";
  SaveAsVersion1(file, map);
  const std::string v1_bytes = ReadFileToString(file);
  ASSERT_EQ(ReadMapFileHeader(file).format_version, 1u);
  const std::string images = parameters.parent_path().string();

  // Relocalizing this map is refused with the shared message.
  EXPECT_THROW(RequireRelocalizationData(LoadMap(file), file.string()), InvalidArgumentError);

  CliResult result = RunCli({"upgrade", "--map", map_dir.string(), "--images", images});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(Contains(result.out, "landmarks")) << result.out;
  EXPECT_EQ(ReadMapFileHeader(file).format_version, 2u);
  EXPECT_EQ(ReadFileToString(map_dir / "map.evmap.v1.bak"), v1_bytes);
  const Map upgraded = LoadMap(file);
  ASSERT_TRUE(HasRelocalizationData(upgraded));
  // The same data as the build stage computes (the same function), points and keyframes kept.
  Map expected = map;
  expected.relocalization = mapper::ComputeRelocalizationData(map, parameters.parent_path(), {});
  EXPECT_EQ(ComputeMapContentChecksum(upgraded), ComputeMapContentChecksum(expected));
  EXPECT_EQ(upgraded.size(), 1u);
  std::cout << "temple 8 views upgrade: " << result.out;
  result = RunCli({"info", file.string()});
  EXPECT_TRUE(Contains(
      result.out, "relocalization:   " + std::to_string(upgraded.relocalization->landmarks.size()) +
                      " landmarks"))
      << result.out;

  // Already upgraded: refused without --force.
  result = RunCli({"upgrade", "--map", file.string(), "--images", images});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "already has relocalization data")) << result.err;
  // In place again from the backup: the backup exists, refused without --force.
  const std::filesystem::path v1_copy = directory_ / "copy" / "map.evmap";
  std::filesystem::create_directories(v1_copy.parent_path());
  WriteFileAtomically(v1_copy, v1_bytes);
  WriteFileAtomically(v1_copy.string() + ".v1.bak", std::string("older backup"));
  result = RunCli({"upgrade", "--map", v1_copy.string(), "--images", images});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "map.evmap.v1.bak' exists")) << result.err;
  EXPECT_EQ(ReadFileToString(v1_copy), v1_bytes);
  // --out: the source is left alone.
  const std::filesystem::path out_dir = directory_ / "out";
  result = RunCli({"upgrade", "--map", v1_copy.string(), "--images", images, "--out",
                   out_dir.string(), "--threads", "1"});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(ReadFileToString(v1_copy), v1_bytes);
  EXPECT_EQ(ComputeMapContentChecksum(LoadMap(out_dir / "map.evmap")),
            ComputeMapContentChecksum(expected));
  result =
      RunCli({"upgrade", "--map", v1_copy.string(), "--images", images, "--out", out_dir.string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "exists; choose another --out")) << result.err;
  // A folder without the keyframe images: the missing image is named, nothing written.
  result = RunCli({"upgrade", "--map", v1_copy.string(), "--images", directory_.string(), "--out",
                   (directory_ / "none.evmap").string()});
  EXPECT_EQ(result.exit_code, 1);
  EXPECT_TRUE(Contains(result.err, "keyframe 0 image 'templeSR0001.png' is not in")) << result.err;
  EXPECT_FALSE(std::filesystem::exists(directory_ / "none.evmap"));
  // Usage errors.
  EXPECT_EQ(RunCli({"upgrade", "--map", v1_copy.string()}).exit_code, 2);
  EXPECT_EQ(RunCli({"upgrade", "--images", images}).exit_code, 2);
  EXPECT_EQ(RunCli({"upgrade", "--help"}).exit_code, 0);
}

// An in-place upgrade takes the map's writer lock (the one WriteMapDirectory takes): while
// another writer holds it, the upgrade waits and the map is not touched.
TEST_F(MapperCliTest, InPlaceUpgradeWaitsForTheMapsWriterLock) {
  EVLOC_REQUIRE_SHARED_DATA(parameters, "middlebury/templeSparseRing/templeSR_par.txt");
  std::vector<testing::MiddleburyView> views = testing::ReadMiddleburyParameters(parameters);
  views.resize(8);
  Map map = testing::MiddleburyKeyframeMap(views);
  map.AddPoint(Eigen::Vector3f(0.0f, 0.1f, 0.02f), Eigen::Vector3f::UnitX(), 0.1f, 0.2f, 0);
  const std::filesystem::path map_dir = directory_ / "locked";
  std::filesystem::create_directories(map_dir);
  SaveAsVersion1(map_dir / "map.evmap", map);
  auto lock = std::make_unique<ScopedFileLock>(MapDirectoryLockFile(map_dir));
  std::atomic<bool> done{false};
  CliResult result;
  std::thread upgrade([&] {
    result = RunCli(
        {"upgrade", "--map", map_dir.string(), "--images", parameters.parent_path().string()});
    done = true;
  });
  std::this_thread::sleep_for(std::chrono::seconds(2));
  EXPECT_FALSE(done) << "the upgrade did not wait for the lock";
  EXPECT_EQ(ReadMapFileHeader(map_dir / "map.evmap").format_version, 1u);
  lock.reset();
  upgrade.join();
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(ReadMapFileHeader(map_dir / "map.evmap").format_version, 2u);
}

TEST(MapperCliRealData, ImportsTheCannyEvtMap) {
  EVLOC_REQUIRE_SHARED_DATA(pcd, "canny-evt-maps/vector_robot_fast.pcd");
  const std::filesystem::path directory = testing::MakeTempDir("mapper_cli_real");
  const CliResult result =
      RunCli({"import-pcd", pcd.string(), "--out", (directory / "m").string()});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(Contains(result.out, "of 40946 points")) << result.out;
  const CliResult info = RunCli({"info", (directory / "m").string()});
  EXPECT_EQ(info.exit_code, 0) << info.err;
  std::filesystem::remove_all(directory);
}

}  // namespace
}  // namespace evloc
