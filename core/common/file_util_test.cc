#include "core/common/file_util.h"

#include <gtest/gtest.h>

#include <unistd.h>

#include <atomic>
#include <stdexcept>
#include <thread>
#include <vector>

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

TEST(UniqueSiblingName, NamesAreHiddenDistinctAndNextToThePath) {
  const std::filesystem::path a = UniqueSiblingName("/d/map.evmap", "staging");
  const std::filesystem::path b = UniqueSiblingName("/d/map.evmap", "staging");
  EXPECT_NE(a, b);
  EXPECT_EQ(a.parent_path(), "/d");
  EXPECT_EQ(
      a.filename().string().rfind(".map.evmap.staging-" + std::to_string(::getpid()) + "-", 0), 0u);
}

TEST(ScopedFileLock, SerialisesHolders) {
  const auto directory = testing::MakeTempDir("evloc-file-util");
  const auto lock_path = directory / "x.lock";
  std::atomic<int> inside{0};
  std::atomic<int> most{0};
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      for (int i = 0; i < 20; ++i) {
        const ScopedFileLock lock(lock_path);
        most = std::max(most.load(), ++inside);
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        --inside;
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(most.load(), 1);
  EXPECT_THROW(ScopedFileLock("/nonexistent-evloc-dir/x.lock"), IoError);
  std::filesystem::remove_all(directory);
}

TEST(SyncPath, MissingPathIsAnIoError) {
  EXPECT_THROW(SyncPath("/nonexistent-evloc-dir/x"), IoError);
}

TEST(WriteFileAtomically, MissingDirectoryIsAnIoError) {
  EXPECT_THROW(WriteFileAtomically("/nonexistent-evloc-dir/x.txt", "x"), IoError);
}

TEST(ReadFileToString, MissingFileIsAnIoError) {
  EXPECT_THROW(ReadFileToString("/nonexistent-evloc-dir/x.txt"), IoError);
}

}  // namespace
}  // namespace evloc
