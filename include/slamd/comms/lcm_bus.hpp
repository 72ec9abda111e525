#pragma once
// LcmBus: one LCM connection shared by the threads of a program.
//
// Publishing is thread-safe (LCM's publish is) and never throws: a failure is counted and logged
// once per channel. Subscriptions are raw: the handler receives the bytes, and subscribe<M>()
// decodes them with decodeMessage<M>() so that malformed messages are counted per channel (LCM's
// typed subscriptions would drop them with only a stderr line). Handlers run on the bus's handling
// thread (startHandling()) or on whichever thread calls handle(); they must be quick and hand
// data over through a queue.
//
//   LcmBus bus("");                                     // "" = $LCM_DEFAULT_URL or LCM's default
//   bus.subscribe<slamd::command_t>("SLAMD_COMMAND", [&](const slamd::command_t& c, Utime) {...});
//   bus.startHandling();
//   bus.publishMessage("SLAMD_POSE", pose_message);

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include <lcm/lcm-cpp.hpp>

#include "slamd/common/time.hpp"
#include "slamd/comms/message_codec.hpp"

namespace slamd {

class LcmBus {
 public:
  using RawHandler = std::function<void(const std::string& channel, const std::uint8_t* data,
                                        std::size_t size, Utime receive_utime)>;

  /// Connects; throws std::runtime_error naming the URL when LCM cannot start.
  explicit LcmBus(const std::string& url);
  ~LcmBus();
  LcmBus(const LcmBus&) = delete;
  LcmBus& operator=(const LcmBus&) = delete;

  /// Publishes raw bytes; returns false (and counts) on failure.
  bool publish(const std::string& channel, const std::vector<std::uint8_t>& bytes);

  template <typename Message>
  bool publishMessage(const std::string& channel, const Message& message) {
    return publish(channel, encodeMessage(message));
  }

  /// Subscribes to a channel (a regular expression, as in LCM) with a raw handler.
  /// `queue_capacity` bounds LCM's own receive queue for this subscription (older messages are
  /// dropped by LCM when the handler falls behind).
  void subscribeRaw(const std::string& channel, RawHandler handler, int queue_capacity = 30);

  /// Subscribes with decoding; malformed messages are counted (malformedCount) and reported to
  /// `on_malformed` when given.
  template <typename Message>
  void subscribe(const std::string& channel,
                 std::function<void(const Message&, Utime receive_utime)> on_message,
                 std::function<void(const std::string& error)> on_malformed = nullptr,
                 int queue_capacity = 30) {
    subscribeRaw(
        channel,
        [this, on_message = std::move(on_message), on_malformed = std::move(on_malformed)](
            const std::string& received_channel, const std::uint8_t* data, std::size_t size,
            Utime receive_utime) {
          std::string error;
          auto message = decodeMessage<Message>(data, size, &error);
          if (!message) {
            countMalformed(received_channel);
            if (on_malformed) on_malformed(received_channel + ": " + error);
            return;
          }
          on_message(*message, receive_utime);
        },
        queue_capacity);
  }

  /// Starts a thread that dispatches incoming messages until stopHandling() or destruction.
  void startHandling();
  void stopHandling();
  /// Dispatches at most one batch of messages, waiting up to timeout_ms. Returns the LCM status
  /// (>0 handled, 0 timeout, <0 error). For programs without a handling thread.
  int handle(int timeout_ms);

  std::uint64_t publishFailures() const {
    return publish_failures_.load(std::memory_order_relaxed);
  }
  std::uint64_t malformedCount(const std::string& channel) const;
  std::uint64_t malformedTotal() const;
  const std::string& url() const { return url_; }
  /// The underlying connection, for components written against lcm::LCM (thread-safe to
  /// publish on; do not call handle() on it while startHandling() runs).
  lcm::LCM& connection() { return lcm_; }

 private:
  struct Subscription {
    LcmBus* bus;
    RawHandler handler;
  };
  static void onRaw(const lcm::ReceiveBuffer* buffer, const std::string& channel,
                    Subscription* subscription);
  void countMalformed(const std::string& channel);

  std::string url_;
  lcm::LCM lcm_;
  std::vector<std::unique_ptr<Subscription>> subscriptions_;
  std::thread handler_thread_;
  std::atomic<bool> handling_{false};
  std::atomic<std::uint64_t> publish_failures_{0};
  mutable std::mutex malformed_mutex_;
  std::map<std::string, std::uint64_t> malformed_by_channel_;
};

}  // namespace slamd
