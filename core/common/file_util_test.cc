#include "core/common/file_util.h"

#include <gtest/gtest.h>

#include <stdexcept>

#include "core/common/error.h"
#include "core/common/test_data.h"

namespace evloc {
namespace {

TEST(WriteFileAtomically, WritesContentAndLeavesNoTemporary) {
  const auto directory = testing::MakeTempDir("evloc-file-util");
  const auto path = directory / "a.txt";
  WriteFileAtomically(path, "hello");
  EXPECT_EQ(ReadFileToString(path), "hello");
  int files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(directory)) ++files;
  EXPECT_EQ(files, 1);
  std::filesystem::remove_all(directory);
}

TEST(WriteFileAtomically, FailedWriteKeepsOldContent) {
  const auto directory = testing::MakeTempDir("evloc-file-util");
  const auto path = directory / "a.txt";
  WriteFileAtomically(path, "old");
  EXPECT_THROW(WriteFileAtomically(path,
                                   [](std::ostream& stream) {
                                     stream << "half";
                                     throw std::runtime_error("interrupted");
                                   }),
               std::runtime_error);
  EXPECT_EQ(ReadFileToString(path), "old");
  int files = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(directory)) ++files;
  EXPECT_EQ(files, 1);
  std::filesystem::remove_all(directory);
}

TEST(WriteFileAtomically, MissingDirectoryIsAnIoError) {
  EXPECT_THROW(WriteFileAtomically("/nonexistent-evloc-dir/x.txt", "x"), IoError);
}

TEST(ReadFileToString, MissingFileIsAnIoError) {
  EXPECT_THROW(ReadFileToString("/nonexistent-evloc-dir/x.txt"), IoError);
}

}  // namespace
}  // namespace evloc
