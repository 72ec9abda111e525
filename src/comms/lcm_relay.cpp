#include "slamd/comms/lcm_relay.hpp"

#include <pthread.h>

#include <chrono>
#include <stdexcept>
#include <utility>

namespace slamd {

namespace {
/// How long a waiting thread sleeps before it re-checks running()/stopping: a lost wake-up (none
/// is expected) or a stop costs at most this much.
constexpr std::chrono::milliseconds kWaitSlice{50};
}  // namespace

void LcmRelay::Lane::publish(std::string channel, std::vector<std::uint8_t> bytes) {
  Message message{std::move(channel), std::move(bytes)};
  bool counted_wait = false;
  while (relay_.running()) {
    // The epoch is read before the push is tried, so room made between the two is not missed.
    const std::uint64_t seen = relay_.space_signal_.epoch();
    if (queue_.tryPush(std::move(message))) {
      relay_.data_signal_.notify();
      return;
    }
    if (!counted_wait) {
      waited_.fetch_add(1, std::memory_order_relaxed);
      counted_wait = true;
    }
    relay_.space_signal_.waitFor(seen, std::chrono::steady_clock::now() + kWaitSlice);
  }
  // Not running (before start() or after stop()): the calling thread publishes itself.
  relay_.publish_(message.channel, message.bytes);
}

LcmRelay::LcmRelay(LcmBus& bus)
    : publish_([&bus](const std::string& channel, const std::vector<std::uint8_t>& bytes) {
        return bus.publish(channel, bytes);
      }) {}

LcmRelay::~LcmRelay() { stop(); }

LcmRelay::Lane& LcmRelay::addLane(std::string name, std::size_t capacity) {
  if (running()) throw std::logic_error("LcmRelay: lanes are added before start()");
  lanes_.push_back(std::unique_ptr<Lane>(new Lane(*this, std::move(name), capacity)));
  return *lanes_.back();
}

void LcmRelay::start() {
  if (thread_.joinable()) return;
  stopping_.store(false, std::memory_order_relaxed);
  // Release: the lanes added so far are complete before a producer can see running() and push.
  running_.store(true, std::memory_order_release);
  thread_ = std::thread([this] { run(); });
}

void LcmRelay::stop() {
  if (!thread_.joinable()) return;
  // Release: every message the (finished) producers pushed is visible to the relay thread once it
  // sees stopping_, and it drains the lanes after that.
  stopping_.store(true, std::memory_order_release);
  data_signal_.notify();
  thread_.join();
  running_.store(false, std::memory_order_release);
  space_signal_.notify();
}

std::size_t LcmRelay::relayQueued() {
  std::size_t published = 0;
  for (const auto& lane : lanes_) {
    while (auto message = lane->queue_.tryPop()) {
      space_signal_.notify();
      publish_(message->channel, message->bytes);
      lane->relayed_.fetch_add(1, std::memory_order_relaxed);
      ++published;
    }
  }
  return published;
}

void LcmRelay::run() {
  pthread_setname_np(pthread_self(), "slamd:lcm-relay");
  while (true) {
    const std::uint64_t seen = data_signal_.epoch();
    // Acquire: pairs with stop()'s release; read before the lanes are emptied, so a stop seen here
    // means the pass below finds every message that will ever be pushed before stop().
    const bool stopping = stopping_.load(std::memory_order_acquire);
    if (relayQueued() > 0) continue;
    if (stopping) return;
    data_signal_.waitFor(seen, std::chrono::steady_clock::now() + kWaitSlice);
  }
}

}  // namespace slamd
