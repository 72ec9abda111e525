#include "slamd/pipeline/drop_oldest_queue.hpp"

#include <thread>

#include <gtest/gtest.h>

#include "test_helpers.hpp"

namespace slamd {
namespace {

using test::LifetimeCounter;

TEST(DropOldestQueue, FullQueueEvictsTheOldestItem) {
  DropOldestQueue<int> queue(3);
  EXPECT_FALSE(queue.push(1));
  EXPECT_FALSE(queue.push(2));
  EXPECT_FALSE(queue.push(3));
  EXPECT_TRUE(queue.push(4));  // evicts 1
  EXPECT_TRUE(queue.push(5));  // evicts 2
  EXPECT_EQ(queue.evicted(), 2u);
  EXPECT_EQ(queue.tryPop(), 3);
  EXPECT_EQ(queue.tryPop(), 4);
  EXPECT_EQ(queue.tryPop(), 5);
  EXPECT_FALSE(queue.tryPop().has_value());
  EXPECT_EQ(queue.dropped(), 2u);
}

TEST(DropOldestQueue, KeepsFifoOrderWithoutOverflow) {
  DropOldestQueue<int> queue(8);
  for (int round = 0; round < 5; ++round) {
    for (int i = 0; i < 6; ++i) queue.push(round * 10 + i);
    for (int i = 0; i < 6; ++i) EXPECT_EQ(queue.tryPop(), round * 10 + i);
  }
  EXPECT_EQ(queue.dropped(), 0u);
}

TEST(DropOldestQueue, CarriesMoveOnlyPayloads) {
  DropOldestQueue<std::unique_ptr<int>> queue(1);
  queue.push(std::make_unique<int>(1));
  queue.push(std::make_unique<int>(2));
  auto item = queue.tryPop();
  ASSERT_TRUE(item);
  EXPECT_EQ(**item, 2);
}

TEST(DropOldestQueue, NeitherLeaksNorDestroysTwice) {
  const auto alive_before = LifetimeCounter::alive.load();
  {
    DropOldestQueue<LifetimeCounter> queue(4);
    for (std::uint64_t i = 0; i < 50; ++i) queue.push(LifetimeCounter(i));
    auto item = queue.tryPop();
    ASSERT_TRUE(item);
    EXPECT_EQ(item->value, 46u);
    EXPECT_EQ(queue.evicted(), 46u);
  }
  EXPECT_EQ(LifetimeCounter::alive.load(), alive_before);
}

TEST(DropOldestQueue, ConcurrentProducerAndConsumerAccountForEveryItem) {
  const auto alive_before = LifetimeCounter::alive.load();
  constexpr std::uint64_t kItems = 1'000'000;
  std::uint64_t delivered = 0;
  std::uint64_t dropped = 0;
  bool increasing = true;
  bool last_delivered = false;
  {
    DropOldestQueue<LifetimeCounter> queue(16);
    std::thread producer([&] {
      for (std::uint64_t i = 0; i < kItems; ++i) queue.push(LifetimeCounter(i));
      queue.close();
    });
    std::int64_t previous = -1;
    while (true) {
      if (auto item = queue.tryPop()) {
        increasing = increasing && static_cast<std::int64_t>(item->value) > previous;
        previous = static_cast<std::int64_t>(item->value);
        last_delivered = item->value == kItems - 1;
        ++delivered;
      } else if (queue.drained()) {
        (void)queue.tryPop();  // accounts for stale items after close
        break;
      } else {
        std::this_thread::yield();
      }
    }
    producer.join();
    dropped = queue.dropped();
  }
  EXPECT_TRUE(increasing);
  EXPECT_TRUE(last_delivered) << "the newest item must always reach the consumer";
  EXPECT_EQ(delivered + dropped, kItems);
  EXPECT_GT(delivered, 0u);
  EXPECT_EQ(LifetimeCounter::alive.load(), alive_before);
}

}  // namespace
}  // namespace slamd
