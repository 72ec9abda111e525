#pragma once
// SpscQueue<T>: a bounded, lock-free, single-producer single-consumer ring buffer.
//
// Exactly one thread may call the producer functions (tryPush, close) and exactly one thread the
// consumer functions (tryPop); sizeApprox/closed/capacity may be called from any thread. T only
// needs to be move-constructible: items are constructed in place on push and moved out on pop.
//
// Indices are monotonically increasing 64-bit counters (slot = index % capacity), so "full" is
// tail - head == capacity and no slot is wasted. Each side owns one index, writes it with release
// (publishing the slot it just filled or emptied) and reads the other side's with acquire. Each
// side also caches the other's index, and only re-reads the shared atomic when the cache says
// full/empty, which keeps the cache line traffic to one transfer per batch.
//
// close() marks end of stream: after the consumer sees closed() and then an empty queue, no item
// will ever arrive again (items pushed before close() are still delivered).

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <optional>
#include <stdexcept>
#include <type_traits>
#include <utility>

namespace slamd {

/// Cache-line size used to keep producer and consumer state apart. 64 on every x86-64 and most
/// ARM cores slamd targets (std::hardware_destructive_interference_size warns on GCC 12).
inline constexpr std::size_t kCacheLineBytes = 64;

template <typename T>
class SpscQueue {
  static_assert(std::is_nothrow_move_constructible_v<T> || std::is_copy_constructible_v<T>,
                "SpscQueue needs a movable payload");

 public:
  explicit SpscQueue(std::size_t capacity)
      : capacity_(capacity), slots_(std::make_unique<Slot[]>(capacity)) {
    if (capacity == 0) throw std::invalid_argument("SpscQueue capacity must be at least 1");
  }

  ~SpscQueue() {
    // Single-threaded by now: destroy what was never popped.
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);
    for (std::uint64_t i = head_.load(std::memory_order_relaxed); i != tail; ++i) {
      slotPtr(i)->~T();
    }
  }

  SpscQueue(const SpscQueue&) = delete;
  SpscQueue& operator=(const SpscQueue&) = delete;

  /// Producer: moves value in and returns true, or returns false (value untouched) when full.
  template <typename U>
  [[nodiscard]] bool tryPush(U&& value) {
    const std::uint64_t tail = tail_.load(std::memory_order_relaxed);  // own index
    if (tail - cached_head_ == capacity_) {
      // Acquire: the consumer's release store of head_ happens after it moved the item out of
      // the slot we are about to reuse, so our construction cannot race with its read.
      cached_head_ = head_.load(std::memory_order_acquire);
      if (tail - cached_head_ == capacity_) return false;
    }
    new (slotPtr(tail)) T(std::forward<U>(value));
    // Release: publishes the constructed item before the consumer can see the new tail.
    tail_.store(tail + 1, std::memory_order_release);
    return true;
  }

  /// Consumer: the oldest item, or nullopt when empty.
  [[nodiscard]] std::optional<T> tryPop() {
    const std::uint64_t head = head_.load(std::memory_order_relaxed);  // own index
    if (head == cached_tail_) {
      // Acquire: pairs with the producer's release of tail_, making the item's contents visible.
      cached_tail_ = tail_.load(std::memory_order_acquire);
      if (head == cached_tail_) return std::nullopt;
    }
    T* slot = slotPtr(head);
    std::optional<T> value(std::move(*slot));
    slot->~T();
    // Release: the slot is empty before the producer can observe it as free.
    head_.store(head + 1, std::memory_order_release);
    return value;
  }

  /// Producer: no more items will be pushed.
  void close() {
    // Release: every push before close() is visible to a consumer that observes closed().
    closed_.store(true, std::memory_order_release);
  }

  bool closed() const { return closed_.load(std::memory_order_acquire); }

  /// Consumer: true once closed and every item has been popped (end of stream reached).
  bool drained() {
    if (!closed()) return false;
    // closed() acquired the producer's final tail, so this read sees every item ever pushed.
    return head_.load(std::memory_order_relaxed) == tail_.load(std::memory_order_acquire);
  }

  /// Number of items in the queue; exact when called by the producer or consumer while the other
  /// side is idle, approximate otherwise.
  std::size_t sizeApprox() const {
    const std::uint64_t head = head_.load(std::memory_order_acquire);
    const std::uint64_t tail = tail_.load(std::memory_order_acquire);
    return tail >= head ? static_cast<std::size_t>(tail - head) : 0;
  }

  std::size_t capacity() const { return capacity_; }

 private:
  struct Slot {
    alignas(T) unsigned char bytes[sizeof(T)];
  };

  T* slotPtr(std::uint64_t index) {
    return std::launder(reinterpret_cast<T*>(slots_[index % capacity_].bytes));
  }

  const std::size_t capacity_;
  const std::unique_ptr<Slot[]> slots_;

  // Consumer-owned line: its index and its cache of the producer's index.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> head_{0};
  std::uint64_t cached_tail_ = 0;
  // Producer-owned line.
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> tail_{0};
  std::uint64_t cached_head_ = 0;
  std::atomic<bool> closed_{false};
  // Padding so that whatever follows this object does not share the producer's line.
  char padding_[kCacheLineBytes - sizeof(std::atomic<std::uint64_t>) - sizeof(std::uint64_t) -
                sizeof(std::atomic<bool>)]{};
};

}  // namespace slamd
