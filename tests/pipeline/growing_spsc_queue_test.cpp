#include "slamd/pipeline/growing_spsc_queue.hpp"

#include <cstdint>
#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include "test_helpers.hpp"

namespace slamd {
namespace {

using test::LifetimeCounter;

TEST(GrowingSpscQueue, KeepsFifoOrderAcrossSegmentsAndShrinksAsTheConsumerCatchesUp) {
  GrowingSpscQueue<int> queue(4);
  for (int i = 0; i < 30; ++i) queue.push(i);
  EXPECT_EQ(queue.sizeApprox(), 30u);
  EXPECT_EQ(queue.segments(), 8u) << "30 items in segments of 4";
  for (int i = 0; i < 30; ++i) ASSERT_EQ(queue.tryPop(), i);
  EXPECT_FALSE(queue.tryPop().has_value());
  EXPECT_EQ(queue.segments(), 1u) << "every emptied segment but the newest is freed";
  queue.push(30);
  EXPECT_EQ(queue.tryPop(), 30);
}

TEST(GrowingSpscQueue, DrainedOnlyAfterCloseAndTheLastPop) {
  GrowingSpscQueue<int> queue(2);
  for (int i = 0; i < 5; ++i) queue.push(i);
  EXPECT_FALSE(queue.drained());
  queue.close();
  EXPECT_FALSE(queue.drained()) << "closed, but five items wait";
  for (int i = 0; i < 5; ++i) ASSERT_EQ(queue.tryPop(), i);
  EXPECT_TRUE(queue.drained());
}

TEST(GrowingSpscQueue, DestroysEveryItemExactlyOnce) {
  const std::int64_t alive_before = LifetimeCounter::alive.load();
  {
    GrowingSpscQueue<LifetimeCounter> queue(3);
    for (std::uint64_t i = 0; i < 10; ++i) queue.push(LifetimeCounter(i));
    for (std::uint64_t i = 0; i < 4; ++i) ASSERT_EQ(queue.tryPop()->value, i);
    EXPECT_EQ(LifetimeCounter::alive.load() - alive_before, 6);
  }
  EXPECT_EQ(LifetimeCounter::alive.load(), alive_before) << "the six left were destroyed";
}

TEST(GrowingSpscQueue, AProducerAndAConsumerOnTwoThreadsPassEveryItemInOrder) {
  // Small segments, so the consumer frees segments while the producer links new ones.
  constexpr std::uint64_t kItems = 200000;
  GrowingSpscQueue<std::unique_ptr<std::uint64_t>> queue(7);
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kItems; ++i) queue.push(std::make_unique<std::uint64_t>(i));
    queue.close();
  });
  std::uint64_t expected = 0;
  bool in_order = true;
  while (!queue.drained()) {
    if (auto item = queue.tryPop()) {
      in_order = in_order && **item == expected;
      ++expected;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  EXPECT_TRUE(in_order);
  EXPECT_EQ(expected, kItems);
  EXPECT_EQ(queue.segments(), 1u);
}

}  // namespace
}  // namespace slamd
