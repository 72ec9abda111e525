// LcmRelay: what low-priority threads hand over is published, in order, by the relay thread, and
// handing over never waits for the publishing (on LCM: never takes the connection's lock).

#include "slamd/comms/lcm_relay.hpp"

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <future>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

namespace slamd {
namespace {

using std::chrono::seconds;

std::vector<std::uint8_t> counterBytes(std::uint32_t counter) {
  return {static_cast<std::uint8_t>(counter), static_cast<std::uint8_t>(counter >> 8),
          static_cast<std::uint8_t>(counter >> 16), static_cast<std::uint8_t>(counter >> 24)};
}

std::uint32_t counterOf(const std::uint8_t* data) {
  return static_cast<std::uint32_t>(data[0]) | static_cast<std::uint32_t>(data[1]) << 8 |
         static_cast<std::uint32_t>(data[2]) << 16 | static_cast<std::uint32_t>(data[3]) << 24;
}

/// Records what the relay publishes (channel, counter, publishing thread) in the order published.
/// The relay's threads are what these tests exercise; LCM itself is left out because its in-process
/// provider orders its queue with glib mutexes, which ThreadSanitizer cannot see (the relay on a
/// real bus: lcm_relay_bus_test.cpp and the daemon tests).
class Recorder {
 public:
  LcmRelay::Publish publish() {
    return [this](const std::string& channel, const std::vector<std::uint8_t>& bytes) {
      EXPECT_EQ(bytes.size(), 4u);
      {
        std::lock_guard<std::mutex> lock(mutex_);
        counters_[channel].push_back(counterOf(bytes.data()));
        threads_.push_back(std::this_thread::get_id());
      }
      changed_.notify_all();
      return true;
    };
  }

  /// The counters published on `channel` once there are `count` of them (or at the deadline).
  std::vector<std::uint32_t> await(const std::string& channel, std::size_t count) {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait_for(lock, seconds(30), [&] { return counters_[channel].size() >= count; });
    return counters_[channel];
  }

  /// The threads that published, one per message.
  std::vector<std::thread::id> threads() {
    std::lock_guard<std::mutex> lock(mutex_);
    return threads_;
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  std::map<std::string, std::vector<std::uint32_t>> counters_;
  std::vector<std::thread::id> threads_;
};

std::vector<std::uint32_t> upTo(std::uint32_t count) {
  std::vector<std::uint32_t> counters(count);
  for (std::uint32_t i = 0; i < count; ++i) counters[i] = i;
  return counters;
}

TEST(LcmRelay, PublishesEveryMessageOfEachLaneInTheLanesOrder) {
  Recorder published;
  LcmRelay relay(published.publish());
  // Lanes far smaller than what is published: the producers have to wait for room.
  LcmRelay::Lane& mapping = relay.addLane("mapping", 2);
  LcmRelay::Lane& backend = relay.addLane("backend", 3);
  relay.start();
  constexpr std::uint32_t kMessages = 500;
  auto produce = [](LcmRelay::Lane& lane, const std::string& channel) {
    for (std::uint32_t i = 0; i < kMessages; ++i) lane.publish(channel, counterBytes(i));
  };
  std::thread mapping_thread(produce, std::ref(mapping), "MAPPING");
  std::thread backend_thread(produce, std::ref(backend), "BACKEND");
  const std::thread::id mapping_id = mapping_thread.get_id();
  const std::thread::id backend_id = backend_thread.get_id();
  mapping_thread.join();
  backend_thread.join();
  relay.stop();
  EXPECT_EQ(mapping.relayed(), kMessages);
  EXPECT_EQ(backend.relayed(), kMessages);
  EXPECT_EQ(published.await("MAPPING", kMessages), upTo(kMessages));
  EXPECT_EQ(published.await("BACKEND", kMessages), upTo(kMessages));
  for (const auto& thread : published.threads()) {
    EXPECT_NE(thread, mapping_id);
    EXPECT_NE(thread, backend_id);
  }
}

TEST(LcmRelay, StopPublishesWhatTheLanesStillHold) {
  std::promise<void> release_publishing;
  std::shared_future<void> released = release_publishing.get_future().share();
  Recorder published;
  // The relay thread is held in its first publish while the lane fills up behind it.
  LcmRelay relay([&, record = published.publish()](const std::string& channel,
                                                   const std::vector<std::uint8_t>& bytes) {
    released.wait();
    return record(channel, bytes);
  });
  LcmRelay::Lane& lane = relay.addLane("mapping", 64);
  relay.start();
  for (std::uint32_t i = 0; i < 40; ++i) lane.publish("MAPPING", counterBytes(i));
  // Stopped while at most one message is out and the rest wait in the lane.
  auto stopping = std::async(std::launch::async, [&] { relay.stop(); });
  release_publishing.set_value();
  stopping.wait();
  EXPECT_FALSE(relay.running());
  EXPECT_EQ(lane.relayed(), 40u);
  EXPECT_EQ(published.await("MAPPING", 0), upTo(40));
}

TEST(LcmRelay, ALanePublishesDirectlyBeforeStartAndAfterStop) {
  Recorder published;
  LcmRelay relay(published.publish());
  LcmRelay::Lane& lane = relay.addLane("mapping", 4);
  lane.publish("MAPPING", counterBytes(0));
  relay.start();
  lane.publish("MAPPING", counterBytes(1));
  relay.stop();
  lane.publish("MAPPING", counterBytes(2));
  EXPECT_EQ(published.await("MAPPING", 3), upTo(3));
  EXPECT_EQ(lane.relayed(), 1u);
  const std::vector<std::thread::id> threads = published.threads();
  ASSERT_EQ(threads.size(), 3u);
  EXPECT_EQ(threads[0], std::this_thread::get_id());
  EXPECT_NE(threads[1], std::this_thread::get_id());
  EXPECT_EQ(threads[2], std::this_thread::get_id());
}

TEST(LcmRelay, LanesAreAddedBeforeStartOnly) {
  Recorder published;
  LcmRelay relay(published.publish());
  relay.addLane("mapping", 4);
  relay.start();
  EXPECT_THROW(relay.addLane("backend", 4), std::logic_error);
}

// The reason the relay exists. Publishing on an LCM connection takes its lock (UDP multicast holds
// it while every fragment of a large message goes out). The daemon's niced threads must never be
// the ones holding it, so they only hand messages to their lanes, and the relay thread, at full
// priority, does all the publishing. Here the publishing is held, as a long transmit holds it: the
// producer must still hand its messages over at once, and none may be published on its thread.
TEST(LcmRelay, HandingOverNeverWaitsForThePublishingItself) {
  std::promise<void> release_publishing;
  std::shared_future<void> released = release_publishing.get_future().share();
  std::mutex published_mutex;
  std::vector<std::uint32_t> published;
  std::vector<std::thread::id> publishing_threads;
  LcmRelay relay([&](const std::string&, const std::vector<std::uint8_t>& bytes) {
    released.wait();
    std::lock_guard<std::mutex> lock(published_mutex);
    published.push_back(counterOf(bytes.data()));
    publishing_threads.push_back(std::this_thread::get_id());
    return true;
  });
  constexpr std::uint32_t kLaneCapacity = 8;
  LcmRelay::Lane& lane = relay.addLane("mapping", kLaneCapacity);
  relay.start();

  // While publishing is held, a lane with room takes every message at once.
  std::thread::id producer_thread;
  auto handing_over = std::async(std::launch::async, [&] {
    producer_thread = std::this_thread::get_id();
    for (std::uint32_t i = 0; i < kLaneCapacity; ++i) lane.publish("MAPPING", counterBytes(i));
  });
  const bool handed_over = handing_over.wait_for(seconds(10)) == std::future_status::ready;
  EXPECT_TRUE(handed_over) << "publishing on a lane waited for the publishing itself";
  release_publishing.set_value();
  handing_over.wait();
  relay.stop();
  EXPECT_EQ(published, upTo(kLaneCapacity));
  for (const auto& thread : publishing_threads) EXPECT_NE(thread, producer_thread);
  EXPECT_EQ(lane.waited(), 0u);
}

}  // namespace
}  // namespace slamd
