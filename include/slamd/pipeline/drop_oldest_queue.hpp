#pragma once
// DropOldestQueue<T>: a bounded, lock-free (wait-free push) single-producer single-consumer queue
// whose producer never blocks: pushing into a full queue evicts the oldest unconsumed item.
//
// This is the policy for live sources (a camera must not stall because tracking is slow): the
// consumer always finds the newest `capacity` items, and every evicted item is counted exactly.
//
// Each slot is an atomic pointer to a heap node stamped with its sequence number. Ownership of a
// node moves only through atomic exchange on its slot, so every pushed item ends exactly once:
// popped by the consumer, evicted by the producer (counted in evicted()), discarded by the consumer
// as stale after the producer lapped it (counted in discarded()), or destroyed with the queue.
// One allocation per push is the price; slamd pushes frames at 30 Hz.
//
// Threads: one producer (tryPush never fails unless closed, close) and one consumer (tryPop);
// the counters may be read from any thread.

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <utility>

#include "slamd/pipeline/spsc_queue.hpp"

namespace slamd {

template <typename T>
class DropOldestQueue {
 public:
  explicit DropOldestQueue(std::size_t capacity)
      : capacity_(capacity), slots_(std::make_unique<std::atomic<Node*>[]>(capacity)) {
    if (capacity == 0) throw std::invalid_argument("DropOldestQueue capacity must be at least 1");
    for (std::size_t i = 0; i < capacity_; ++i) slots_[i].store(nullptr, std::memory_order_relaxed);
  }

  ~DropOldestQueue() {
    for (std::size_t i = 0; i < capacity_; ++i) delete slots_[i].load(std::memory_order_relaxed);
  }

  DropOldestQueue(const DropOldestQueue&) = delete;
  DropOldestQueue& operator=(const DropOldestQueue&) = delete;

  /// Producer: stores the item, evicting the oldest one if the queue is full. Returns true when
  /// an older item was evicted.
  template <typename U>
  bool push(U&& value) {
    const std::uint64_t sequence = tail_.load(std::memory_order_relaxed);
    auto node = std::make_unique<Node>(Node{sequence, T(std::forward<U>(value))});
    // acq_rel: release publishes the node's contents to the consumer's exchange; acquire makes
    // the old node (ours, or left by the consumer as null) safe to delete here.
    Node* old = slots_[sequence % capacity_].exchange(node.release(), std::memory_order_acq_rel);
    const bool evicted = old != nullptr;
    if (evicted) {
      delete old;
      evicted_.fetch_add(1, std::memory_order_relaxed);
    }
    // Release: a consumer that reads this tail finds the slot already holding our node (or a
    // newer one).
    tail_.store(sequence + 1, std::memory_order_release);
    return evicted;
  }

  /// Consumer: the oldest item still held, or nullopt when empty. Delivered sequence numbers are
  /// strictly increasing (FIFO among delivered items). After close(), the call that finds the
  /// queue empty also discards (and counts) stale items left in slots, so that at end of stream
  /// pushed == delivered + dropped() exactly.
  [[nodiscard]] std::optional<T> tryPop() {
    std::uint64_t next = next_.load(std::memory_order_relaxed);  // own index
    while (true) {
      // Read closed before tail: if closed, this tail is final (close() releases after pushes).
      const bool was_closed = closed();
      const std::uint64_t tail = tail_.load(std::memory_order_acquire);
      if (next >= tail) {
        if (was_closed) discardStaleAfterClose();
        return std::nullopt;
      }
      // Items older than tail - capacity were overwritten (and counted) by the producer.
      if (tail - next > capacity_) next = tail - capacity_;
      Node* node = slots_[next % capacity_].exchange(nullptr, std::memory_order_acq_rel);
      if (node == nullptr) {
        ++next;  // evicted, slot not yet refilled
        next_.store(next, std::memory_order_relaxed);
        continue;
      }
      std::unique_ptr<Node> owned(node);
      if (owned->sequence < next) {
        // Older than something already delivered: the producer lapped us between our reads.
        discarded_.fetch_add(1, std::memory_order_relaxed);
        continue;
      }
      // owned->sequence >= next: deliver it; anything older still in a slot is stale and will be
      // discarded when met (or at close).
      next = owned->sequence + 1;
      // Relaxed: next_ is only read by this thread and, approximately, by sizeApprox().
      next_.store(next, std::memory_order_relaxed);
      return std::optional<T>(std::move(owned->value));
    }
  }

  void close() { closed_.store(true, std::memory_order_release); }
  bool closed() const { return closed_.load(std::memory_order_acquire); }

  /// Consumer: closed and nothing left to deliver.
  bool drained() {
    if (!closed()) return false;
    return next_.load(std::memory_order_relaxed) >= tail_.load(std::memory_order_acquire);
  }

  /// Items waiting for the consumer (approximate while both sides run).
  std::size_t sizeApprox() const {
    const std::uint64_t tail = tail_.load(std::memory_order_acquire);
    const std::uint64_t next = next_.load(std::memory_order_relaxed);
    if (next >= tail) return 0;
    return static_cast<std::size_t>(std::min<std::uint64_t>(tail - next, capacity_));
  }

  std::size_t capacity() const { return capacity_; }
  /// Items evicted by the producer because the queue was full.
  std::uint64_t evicted() const { return evicted_.load(std::memory_order_relaxed); }
  /// Items the consumer threw away because it had already delivered something newer.
  std::uint64_t discarded() const { return discarded_.load(std::memory_order_relaxed); }
  /// All items dropped by the drop-oldest policy.
  std::uint64_t dropped() const { return evicted() + discarded(); }

 private:
  struct Node {
    std::uint64_t sequence;
    T value;
  };

  // Consumer only, once the producer has closed: every slot still holding a node is stale.
  void discardStaleAfterClose() {
    for (std::size_t i = 0; i < capacity_; ++i) {
      if (Node* node = slots_[i].exchange(nullptr, std::memory_order_acq_rel)) {
        delete node;
        discarded_.fetch_add(1, std::memory_order_relaxed);
      }
    }
  }

  const std::size_t capacity_;
  const std::unique_ptr<std::atomic<Node*>[]> slots_;
  // Consumer-owned: next sequence to deliver.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> next_{0};
  std::atomic<std::uint64_t> discarded_{0};
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> tail_{0};  // producer-owned
  std::atomic<std::uint64_t> evicted_{0};
  std::atomic<bool> closed_{false};
};

}  // namespace slamd
