// LcmRelay on a real LCM bus (in-process memq://): what the lanes hand over reaches a subscriber
// of the bus, each lane in order. Not run under ThreadSanitizer: memq:// orders its queue with
// glib mutexes, which it cannot see (the relay's own threading: lcm_relay_test.cpp).

#include <cstdint>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/lcm_relay.hpp"

namespace slamd {
namespace {

TEST(LcmRelayOnABus, SubscribersReceiveWhatTheLanesHandOverInOrder) {
  LcmBus bus("memq://");
  std::vector<std::uint8_t> received;
  bus.subscribeRaw(
      "SLAMD_TEST_RELAY",
      [&](const std::string&, const std::uint8_t* data, std::size_t size, Utime) {
        ASSERT_EQ(size, 1u);
        received.push_back(data[0]);
      },
      /*queue_capacity=*/1000);
  LcmRelay relay(bus);
  LcmRelay::Lane& lane = relay.addLane("mapping", 4);
  relay.start();
  constexpr int kMessages = 100;
  for (int i = 0; i < kMessages; ++i) {
    lane.publish("SLAMD_TEST_RELAY", {static_cast<std::uint8_t>(i)});
  }
  relay.stop();
  EXPECT_EQ(lane.relayed(), static_cast<std::uint64_t>(kMessages));
  // memq:// holds published messages until they are handled, here on the test's own thread.
  while (bus.handle(0) > 0) {
  }
  ASSERT_EQ(received.size(), static_cast<std::size_t>(kMessages));
  for (int i = 0; i < kMessages; ++i) EXPECT_EQ(received[static_cast<std::size_t>(i)], i);
}

}  // namespace
}  // namespace slamd
