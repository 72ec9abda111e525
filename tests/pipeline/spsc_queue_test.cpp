#include "slamd/pipeline/spsc_queue.hpp"

#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include "test_helpers.hpp"

namespace slamd {
namespace {

using test::LifetimeCounter;

TEST(SpscQueue, KeepsFifoOrder) {
  SpscQueue<int> queue(8);
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(queue.tryPush(i));
  for (int i = 0; i < 5; ++i) EXPECT_EQ(queue.tryPop(), i);
  EXPECT_FALSE(queue.tryPop().has_value());
}

TEST(SpscQueue, TryPushFailsWhenFullAndTryPopWhenEmpty) {
  SpscQueue<int> queue(3);
  EXPECT_FALSE(queue.tryPop().has_value());
  EXPECT_TRUE(queue.tryPush(1));
  EXPECT_TRUE(queue.tryPush(2));
  EXPECT_TRUE(queue.tryPush(3));
  EXPECT_FALSE(queue.tryPush(4));
  EXPECT_EQ(queue.sizeApprox(), 3u);
  EXPECT_EQ(queue.tryPop(), 1);
  EXPECT_TRUE(queue.tryPush(4));  // the freed slot is reused (wrap-around)
  EXPECT_EQ(queue.tryPop(), 2);
  EXPECT_EQ(queue.tryPop(), 3);
  EXPECT_EQ(queue.tryPop(), 4);
  EXPECT_FALSE(queue.tryPop().has_value());
}

TEST(SpscQueue, FailedPushLeavesTheValueIntact) {
  SpscQueue<std::unique_ptr<int>> queue(1);
  ASSERT_TRUE(queue.tryPush(std::make_unique<int>(1)));
  auto value = std::make_unique<int>(2);
  EXPECT_FALSE(queue.tryPush(std::move(value)));
  ASSERT_NE(value, nullptr);
  EXPECT_EQ(*value, 2);
}

TEST(SpscQueue, CarriesMoveOnlyPayloads) {
  SpscQueue<std::unique_ptr<int>> queue(4);
  ASSERT_TRUE(queue.tryPush(std::make_unique<int>(7)));
  auto item = queue.tryPop();
  ASSERT_TRUE(item.has_value());
  EXPECT_EQ(**item, 7);
}

TEST(SpscQueue, ZeroCapacityIsRejected) { EXPECT_THROW(SpscQueue<int>(0), std::invalid_argument); }

TEST(SpscQueue, NeitherLeaksNorDestroysTwice) {
  const auto alive_before = LifetimeCounter::alive.load();
  {
    SpscQueue<LifetimeCounter> queue(5);
    for (std::uint64_t i = 0; i < 4; ++i) ASSERT_TRUE(queue.tryPush(LifetimeCounter(i)));
    {
      auto item = queue.tryPop();
      ASSERT_TRUE(item);
      EXPECT_EQ(item->value, 0u);
    }
    for (std::uint64_t i = 0; i < 20; ++i) {  // wrap around several times
      if (!queue.tryPush(LifetimeCounter(100 + i))) {
        auto popped = queue.tryPop();
        ASSERT_TRUE(popped);
      }
    }
    EXPECT_EQ(LifetimeCounter::alive.load() - alive_before,
              static_cast<std::int64_t>(queue.sizeApprox()));
    // Remaining items are destroyed with the queue.
  }
  EXPECT_EQ(LifetimeCounter::alive.load(), alive_before);
}

TEST(SpscQueue, CloseMarksEndOfStreamAfterRemainingItems) {
  SpscQueue<int> queue(4);
  ASSERT_TRUE(queue.tryPush(1));
  queue.close();
  EXPECT_TRUE(queue.closed());
  EXPECT_FALSE(queue.drained());
  EXPECT_EQ(queue.tryPop(), 1);
  EXPECT_TRUE(queue.drained());
}

TEST(SpscQueue, TwoThreadsPassAMillionItemsWithMatchingChecksum) {
  constexpr std::uint64_t kItems = 1'000'000;
  SpscQueue<std::uint64_t> queue(1024);
  std::uint64_t producer_sum = 0;
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kItems; ++i) {
      const std::uint64_t value = i * 2654435761u;
      producer_sum += value;
      while (!queue.tryPush(value)) std::this_thread::yield();
    }
    queue.close();
  });
  std::uint64_t consumer_sum = 0;
  std::uint64_t count = 0;
  std::uint64_t expected_next = 0;
  bool in_order = true;
  while (true) {
    if (auto item = queue.tryPop()) {
      in_order = in_order && *item == expected_next * 2654435761u;
      ++expected_next;
      consumer_sum += *item;
      ++count;
    } else if (queue.drained()) {
      break;
    } else {
      std::this_thread::yield();
    }
  }
  producer.join();
  EXPECT_EQ(count, kItems);
  EXPECT_EQ(consumer_sum, producer_sum);
  EXPECT_TRUE(in_order);
}

TEST(SpscQueue, TwoThreadsWithLifetimeCountedItemsLeakNothing) {
  const auto alive_before = LifetimeCounter::alive.load();
  constexpr std::uint64_t kItems = 200'000;
  {
    SpscQueue<LifetimeCounter> queue(64);
    std::thread producer([&] {
      for (std::uint64_t i = 0; i < kItems; ++i) {
        LifetimeCounter item(i);
        while (!queue.tryPush(std::move(item))) std::this_thread::yield();
      }
      queue.close();
    });
    std::uint64_t sum = 0;
    while (!queue.drained()) {
      if (auto item = queue.tryPop())
        sum += item->value;
      else
        std::this_thread::yield();
    }
    producer.join();
    EXPECT_EQ(sum, kItems * (kItems - 1) / 2);
  }
  EXPECT_EQ(LifetimeCounter::alive.load(), alive_before);
}

}  // namespace
}  // namespace slamd
