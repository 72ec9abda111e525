#pragma once
// GrowingSpscQueue<T>: an unbounded, lock-free, single-producer single-consumer queue for a
// consumer that must see every item and whose producer must never wait for it (the back end:
// a lost keyframe would break the pose graph, and a filter thread held up by a long optimisation
// would hold up every pose after it).
//
// It is a chain of bounded SpscQueue segments. The producer pushes into the newest segment; when
// that is full it makes a new one and links it (release), so the old segment receives nothing
// after the link. The consumer pops from the oldest segment; once that is empty and linked to a
// newer one (acquire), a last tryPop settles whether it is finished, and the consumer frees it.
// Only the producer touches the newest segment's link and only the consumer frees segments.
//
// Memory grows with the backlog, one segment at a time, and shrinks as the consumer catches up.
// sizeApprox/closed may be called from any thread; push/close by the producer only; tryPop and
// drained by the consumer only.

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <stdexcept>
#include <utility>

#include "slamd/pipeline/spsc_queue.hpp"

namespace slamd {

template <typename T>
class GrowingSpscQueue {
 public:
  explicit GrowingSpscQueue(std::size_t segment_capacity) : segment_capacity_(segment_capacity) {
    if (segment_capacity == 0) {
      throw std::invalid_argument("GrowingSpscQueue segment capacity must be at least 1");
    }
    head_segment_ = new Segment(segment_capacity_);
    tail_segment_ = head_segment_;
  }

  ~GrowingSpscQueue() {
    // Single-threaded by now: each segment destroys what it still holds.
    Segment* segment = head_segment_;
    while (segment != nullptr) {
      Segment* next = segment->next.load(std::memory_order_relaxed);
      delete segment;
      segment = next;
    }
  }

  GrowingSpscQueue(const GrowingSpscQueue&) = delete;
  GrowingSpscQueue& operator=(const GrowingSpscQueue&) = delete;

  /// Producer: never fails and never waits.
  template <typename U>
  void push(U&& value) {
    if (!tail_segment_->items.tryPush(std::forward<U>(value))) {  // moves only on success
      auto* fresh = new Segment(segment_capacity_);
      const bool pushed = fresh->items.tryPush(std::forward<U>(value));
      (void)pushed;  // a fresh segment has room
      // Release: the old segment's items, and the new segment's first, are visible to a consumer
      // that sees the link.
      tail_segment_->next.store(fresh, std::memory_order_release);
      tail_segment_ = fresh;
      segments_.fetch_add(1, std::memory_order_relaxed);
    }
    pushed_.fetch_add(1, std::memory_order_release);
  }

  /// Consumer: the oldest item, or nullopt when empty.
  [[nodiscard]] std::optional<T> tryPop() {
    while (true) {
      if (std::optional<T> item = head_segment_->items.tryPop()) {
        popped_.fetch_add(1, std::memory_order_release);
        return item;
      }
      Segment* next = head_segment_->next.load(std::memory_order_acquire);
      if (next == nullptr) return std::nullopt;
      // Linked: the producer pushed its last item here before the link we just acquired.
      if (std::optional<T> item = head_segment_->items.tryPop()) {
        popped_.fetch_add(1, std::memory_order_release);
        return item;
      }
      delete head_segment_;
      head_segment_ = next;
      segments_.fetch_sub(1, std::memory_order_relaxed);
    }
  }

  /// Producer: no more items will be pushed.
  void close() { closed_.store(true, std::memory_order_release); }

  bool closed() const { return closed_.load(std::memory_order_acquire); }

  /// Consumer: true once closed and every item has been popped.
  bool drained() {
    if (!closed()) return false;
    // closed() acquired the producer's last push count.
    return popped_.load(std::memory_order_relaxed) == pushed_.load(std::memory_order_acquire);
  }

  /// Items waiting (approximate while both sides run).
  std::size_t sizeApprox() const {
    const std::uint64_t popped = popped_.load(std::memory_order_acquire);
    const std::uint64_t pushed = pushed_.load(std::memory_order_acquire);
    return pushed >= popped ? static_cast<std::size_t>(pushed - popped) : 0;
  }

  /// Segments allocated now (1 when the consumer keeps up).
  std::size_t segments() const { return segments_.load(std::memory_order_relaxed); }

  std::size_t segmentCapacity() const { return segment_capacity_; }

 private:
  struct Segment {
    explicit Segment(std::size_t capacity) : items(capacity) {}
    SpscQueue<T> items;
    std::atomic<Segment*> next{nullptr};
  };

  const std::size_t segment_capacity_;
  Segment* head_segment_ = nullptr;  // consumer-owned
  Segment* tail_segment_ = nullptr;  // producer-owned
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> pushed_{0};
  alignas(kCacheLineBytes) std::atomic<std::uint64_t> popped_{0};
  std::atomic<std::size_t> segments_{1};
  std::atomic<bool> closed_{false};
};

}  // namespace slamd
