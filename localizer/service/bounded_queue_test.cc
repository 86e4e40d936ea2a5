// BoundedQueue: TryAppendToBack and FoldPairs, how a searching session behind its stream thins
// its newest packets into its queue and its backlog (localizer_server.cc, ThinIntoQueue and
// FoldQueue).
#include "localizer/service/bounded_queue.h"

#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace evloc::service {
namespace {

std::vector<std::string> Drain(BoundedQueue<std::string>& queue) {
  std::vector<std::string> items;
  while (auto item = queue.TryPop()) items.push_back(*item);
  return items;
}

bool LowerCase(const std::string& item) { return !item.empty() && item[0] >= 'a'; }

TEST(BoundedQueue, TryAppendToBackChangesTheLastItemAndItsWeight) {
  BoundedQueue<std::string> queue(2, 10);
  ASSERT_EQ(queue.TryPush("A", 1), PushResult::kQueued);
  ASSERT_EQ(queue.TryPush("b", 2), PushResult::kQueued);
  EXPECT_TRUE(queue.WouldBeFull(1));  // no room for a third item
  EXPECT_TRUE(queue.TryAppendToBack(3, LowerCase, [](std::string& last) { last += "c"; }));
  EXPECT_EQ(queue.size(), 2u);
  EXPECT_EQ(queue.weight(), 6u);
  // Not beyond the weight bound (6 + 5 > 10): the item is left as it was.
  EXPECT_FALSE(queue.TryAppendToBack(5, LowerCase, [](std::string& last) { last += "x"; }));
  EXPECT_EQ(queue.weight(), 6u);
  EXPECT_EQ(Drain(queue), (std::vector<std::string>{"A", "bc"}));
}

TEST(BoundedQueue, TryAppendToBackNeedsALastItemThatTakesIt) {
  BoundedQueue<std::string> queue(4);
  const auto append = [](std::string& last) { last += "!"; };
  EXPECT_FALSE(queue.TryAppendToBack(1, LowerCase, append));  // empty
  queue.TryPush("a", 1);
  queue.TryPush("B", 1);
  EXPECT_FALSE(queue.TryAppendToBack(1, LowerCase, append));  // the last one refuses
  queue.Close();
  EXPECT_FALSE(queue.TryAppendToBack(
      1, [](const std::string&) { return true; }, append));
  EXPECT_EQ(Drain(queue), (std::vector<std::string>{"a", "B"}));
}

// A pair folds when both are lower case and of equal length, into their concatenation.
bool Foldable(const std::string& a, const std::string& b) {
  return LowerCase(a) && LowerCase(b) && a.size() == b.size();
}
uint64_t Concatenate(std::string& a, std::string&& b) {
  a += b;
  return a.size();
}

TEST(BoundedQueue, FoldPairsFoldsNeighboursFrontToBackAndFreesTheirRoom) {
  BoundedQueue<std::string> queue(6, 100);
  for (const std::string item : {"a", "b", "c", "X", "d", "e"}) {
    ASSERT_EQ(queue.TryPush(item, item.size()), PushResult::kQueued);
  }
  EXPECT_TRUE(queue.WouldBeFull(1));
  const auto [gone, freed] = queue.FoldPairs(Foldable, Concatenate);
  // a+b fold; c cannot fold with X, nor X with d; d+e fold.
  EXPECT_EQ(gone, 2u);
  EXPECT_EQ(freed, 0u);  // concatenation keeps every character
  EXPECT_EQ(queue.size(), 4u);
  EXPECT_EQ(queue.weight(), 6u);
  EXPECT_FALSE(queue.WouldBeFull(1));
  EXPECT_EQ(Drain(queue), (std::vector<std::string>{"ab", "c", "X", "de"}));
}

TEST(BoundedQueue, FoldPairsReportsTheWeightFreedAndKeepsLaterPushesBehind) {
  BoundedQueue<std::string> queue(8);
  for (const std::string item : {"aa", "bb", "cc", "dd"}) queue.TryPush(item, 10);
  // Each fold keeps one weight unit of the pair's 20.
  const auto [gone, freed] =
      queue.FoldPairs(Foldable, [](std::string& a, std::string&& b) -> uint64_t {
        a = a.substr(0, 1) + b.substr(0, 1);
        return 1;
      });
  EXPECT_EQ(gone, 2u);
  EXPECT_EQ(freed, 38u);
  EXPECT_EQ(queue.weight(), 2u);
  queue.TryPush("zz", 5);
  EXPECT_EQ(Drain(queue), (std::vector<std::string>{"ab", "cd", "zz"}));
}

TEST(BoundedQueue, FoldPairsOnAnAbortedQueueLeavesItEmptyAndAClosedOneFolded) {
  BoundedQueue<std::string> queue(4);
  queue.TryPush("a", 1);
  queue.TryPush("b", 1);
  queue.Abort();
  queue.FoldPairs(Foldable, Concatenate);
  EXPECT_EQ(queue.size(), 0u);
  EXPECT_TRUE(queue.drained());
  BoundedQueue<std::string> closed(4);
  closed.TryPush("a", 1);
  closed.TryPush("b", 1);
  closed.Close();
  closed.FoldPairs(Foldable, Concatenate);
  EXPECT_EQ(Drain(closed), (std::vector<std::string>{"ab"}));
}

}  // namespace
}  // namespace evloc::service
