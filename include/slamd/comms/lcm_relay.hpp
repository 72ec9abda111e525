#pragma once
// LcmRelay: publishes on an LcmBus, from a thread of its own, the messages that low-priority
// threads hand to it, so that those threads never take the LCM connection's lock.
//
// Every publish on an LCM connection takes a lock of the connection's (UDP multicast holds it while
// every fragment of a large message goes out). A thread running at low priority (the daemon nices
// mapping and the back end on a live source) that holds it while starved of CPU makes every other
// publisher wait: on a fully loaded machine, hundreds of milliseconds without a pose published.
// Such a thread encodes its messages itself (the costly part) and pushes the bytes into its own
// lane, a bounded single-producer queue; the relay thread, at normal priority, publishes them in
// the order each lane received them. Messages of different lanes are not ordered with respect to
// each other.
//
// A full lane makes its producer wait (backpressure): a relay message is never dropped, and only
// the low-priority producer is held up. Before start() and after stop() a lane publishes directly
// on the calling thread, so that a step run on the control thread after the pipeline stopped still
// publishes.
//
//   LcmRelay relay(bus);
//   LcmRelay::Lane& mapping_lane = relay.addLane("mapping", 16);   // before start()
//   relay.start();
//   mapping_lane.publish("SLAMD_MAP_UPDATE", encodeMessage(update)); // on the mapping thread only
//   ...                                                              // join the producers, then
//   relay.stop();                                                    // publishes what is queued
//
// Thread ownership: addLane/start/stop on one controlling thread; each lane's publish() on one
// producing thread at a time (ownership may pass to another thread after a join).

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "slamd/comms/lcm_bus.hpp"
#include "slamd/pipeline/spsc_queue.hpp"
#include "slamd/pipeline/wake_signal.hpp"

namespace slamd {

class LcmRelay {
 public:
  /// One producer's queue of encoded messages.
  class Lane {
   public:
    /// Queues the message for the relay thread (waiting while the lane is full), or publishes it
    /// directly when the relay is not running.
    void publish(std::string channel, std::vector<std::uint8_t> bytes);

    const std::string& name() const { return name_; }
    /// Messages the relay thread has published for this lane.
    std::uint64_t relayed() const { return relayed_.load(std::memory_order_relaxed); }
    /// Messages that found the lane full, so that their producer had to wait.
    std::uint64_t waited() const { return waited_.load(std::memory_order_relaxed); }

   private:
    friend class LcmRelay;
    struct Message {
      std::string channel;
      std::vector<std::uint8_t> bytes;
    };
    Lane(LcmRelay& relay, std::string name, std::size_t capacity)
        : relay_(relay), name_(std::move(name)), queue_(capacity) {}

    LcmRelay& relay_;
    const std::string name_;
    SpscQueue<Message> queue_;
    std::atomic<std::uint64_t> relayed_{0};
    std::atomic<std::uint64_t> waited_{0};
  };

  /// Publishes one encoded message; returns false on failure (counted by whoever publishes).
  using Publish =
      std::function<bool(const std::string& channel, const std::vector<std::uint8_t>& bytes)>;

  /// A relay that publishes on `bus`, which must outlive it.
  explicit LcmRelay(LcmBus& bus);
  /// A relay that publishes with `publish` (tests observe or hold the publishing with it).
  explicit LcmRelay(Publish publish) : publish_(std::move(publish)) {}
  /// Stops (publishing what is still queued) if still running.
  ~LcmRelay();
  LcmRelay(const LcmRelay&) = delete;
  LcmRelay& operator=(const LcmRelay&) = delete;

  /// A new lane holding at most `capacity` messages (at least 1). Only before start(); the lane
  /// lives as long as the relay.
  Lane& addLane(std::string name, std::size_t capacity);

  /// Starts the relay thread ("slamd:lcm-relay").
  void start();
  /// Publishes every queued message, then joins the relay thread. Call it after the lanes'
  /// producers have finished (joined): a message pushed during stop() may otherwise be left
  /// behind, and a later one is published directly.
  void stop();
  bool running() const { return running_.load(std::memory_order_acquire); }

  const std::vector<std::unique_ptr<Lane>>& lanes() const { return lanes_; }

 private:
  /// The relay thread: publishes what the lanes hold until stop() and the lanes are empty.
  void run();
  /// Publishes every message the lanes hold now; returns how many.
  std::size_t relayQueued();

  Publish publish_;
  std::vector<std::unique_ptr<Lane>> lanes_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> stopping_{false};
  WakeSignal data_signal_;   // producers -> relay: a message was queued
  WakeSignal space_signal_;  // relay -> producers: a lane has room again
};

}  // namespace slamd
