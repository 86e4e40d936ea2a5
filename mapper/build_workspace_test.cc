#include "mapper/build_workspace.h"

#include <gtest/gtest.h>

#include <fstream>

#include "core/common/error.h"
#include "core/common/file_util.h"
#include "core/common/test_data.h"

namespace evloc::mapper {
namespace {

namespace fs = std::filesystem;

// Writes a 4 x 2 binary PGM whose pixels are all `value`: every such file has the same size.
void WritePgm(const fs::path& path, char value) {
  std::ofstream stream(path, std::ios::binary);
  stream << "P5\n4 2\n255\n" << std::string(8, value);
}

// A re-rendered image of the same byte size (new pixels) changes the workspace fingerprint, so
// the features of the old image are not reused: PrepareWorkspace clears the workspace and the
// feature stage's marker no longer matches. The file size alone (the old fingerprint) missed it.
TEST(BuildWorkspace, ReRenderedImageOfTheSameSizeInvalidatesTheFeatures) {
  const fs::path directory = evloc::testing::MakeTempDir("build_workspace");
  MapBuilderOptions options;
  options.image_dir = directory / "images";
  fs::create_directories(options.image_dir);
  WritePgm(options.image_dir / "a.pgm", 10);
  WritePgm(options.image_dir / "b.pgm", 20);
  const std::vector<InputImage> images = {{"a.pgm", 0, false}, {"b.pgm", 0, false}};
  const std::string version = "COLMAP 3.8 -- Structure-from-Motion and Multi-View Stereo";
  const std::string before =
      WorkspaceFingerprint(options, images, std::nullopt, MatcherType::kExhaustive, version);
  const fs::path workspace = directory / "workspace";
  PrepareWorkspace(workspace, before);
  const fs::path marker = workspace / "colmap_features.done";
  WriteFileAtomically(marker, before);
  PrepareWorkspace(workspace, before);
  EXPECT_TRUE(MarkerMatches(marker, before));  // same inputs: reused

  const uintmax_t size = fs::file_size(options.image_dir / "a.pgm");
  WritePgm(options.image_dir / "a.pgm", 11);  // re-rendered, same size
  ASSERT_EQ(fs::file_size(options.image_dir / "a.pgm"), size);
  const std::string after =
      WorkspaceFingerprint(options, images, std::nullopt, MatcherType::kExhaustive, version);
  EXPECT_NE(after, before);
  PrepareWorkspace(workspace, after);
  EXPECT_FALSE(fs::exists(marker));
  EXPECT_FALSE(MarkerMatches(marker, before));
  EXPECT_EQ(ReadFileToString(workspace / "fingerprint.txt"), after);

  // Another COLMAP version invalidates the features too.
  EXPECT_NE(
      WorkspaceFingerprint(options, images, std::nullopt, MatcherType::kExhaustive, "COLMAP 3.9.1"),
      after);
  // The content hash is the CRC32C of the bytes ("123456789": e3069283).
  { std::ofstream(directory / "check.txt", std::ios::binary) << "123456789"; }
  EXPECT_EQ(FileContentHash(directory / "check.txt"), "e3069283");
  EXPECT_THROW(FileContentHash(directory / "missing.txt"), IoError);
  fs::remove_all(directory);
}

}  // namespace
}  // namespace evloc::mapper
