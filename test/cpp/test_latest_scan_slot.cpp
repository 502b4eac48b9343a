#include <gtest/gtest.h>

#include <memory>
#include <thread>
#include <vector>

#include "latest_scan_slot.hpp"

namespace gpl = grid_puzzle_localization;
using Slot = gpl::LatestScanSlot<std::shared_ptr<const int>>;

TEST(LatestScanSlot, TakesEachScanOnceAndEmptyWhenNoneWaits) {
  Slot slot;
  EXPECT_EQ(slot.take(), nullptr);
  slot.put(std::make_shared<const int>(1));
  const std::shared_ptr<const int> first = slot.take();
  ASSERT_NE(first, nullptr);
  EXPECT_EQ(*first, 1);
  EXPECT_EQ(slot.take(), nullptr);
  EXPECT_EQ(slot.dropped(), 0u);
}

TEST(LatestScanSlot, KeepsTheNewestAndCountsTheOthersDropped) {
  Slot slot;
  for (int i = 1; i <= 5; ++i) slot.put(std::make_shared<const int>(i));
  EXPECT_EQ(*slot.take(), 5);
  EXPECT_EQ(slot.dropped(), 4u);  // 1 to 4 were replaced before anyone took them
  slot.put(std::make_shared<const int>(6));
  EXPECT_EQ(*slot.take(), 6);
  EXPECT_EQ(slot.dropped(), 4u);  // a scan taken in time is not dropped
}

// One thread puts n scans while another takes: each scan is either taken or counted dropped, exactly once, and
// the ones taken come in the order they were put.
TEST(LatestScanSlot, ConcurrentPutAndTakeLoseNoScanUncounted) {
  constexpr int n = 200000;
  Slot slot;
  std::vector<int> taken;
  std::thread producer([&] {
    for (int i = 1; i <= n; ++i) slot.put(std::make_shared<const int>(i));
  });
  // The last scan is never replaced, so the taker sees it and stops.
  while (taken.empty() || taken.back() != n) {
    if (const std::shared_ptr<const int> scan = slot.take())
      taken.push_back(*scan);
    else
      std::this_thread::yield();
  }
  producer.join();
  for (std::size_t i = 1; i < taken.size(); ++i) ASSERT_LT(taken[i - 1], taken[i]);
  EXPECT_EQ(taken.size() + slot.dropped(), static_cast<std::size_t>(n));
}
