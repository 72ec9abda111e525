#pragma once
// Helpers for the concurrency tests: a payload that counts its lifetimes, and a one-shot gate.

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>

namespace slamd::test {

/// Counts constructions and destructions of live objects so tests can prove that a queue neither
/// leaks nor destroys an item twice. `alive` must return to its start value.
struct LifetimeCounter {
  static std::atomic<std::int64_t> alive;
  static std::atomic<std::int64_t> constructed;
  std::uint64_t value = 0;
  bool moved_from = false;

  explicit LifetimeCounter(std::uint64_t v) : value(v) { onConstruct(); }
  LifetimeCounter(const LifetimeCounter& other) : value(other.value) { onConstruct(); }
  LifetimeCounter(LifetimeCounter&& other) noexcept : value(other.value) {
    other.moved_from = true;
    onConstruct();
  }
  LifetimeCounter& operator=(const LifetimeCounter&) = default;
  LifetimeCounter& operator=(LifetimeCounter&&) = default;
  ~LifetimeCounter() {
    // A second destruction of the same object would drive `alive` below its start value.
    alive.fetch_sub(1, std::memory_order_relaxed);
  }

 private:
  static void onConstruct() {
    alive.fetch_add(1, std::memory_order_relaxed);
    constructed.fetch_add(1, std::memory_order_relaxed);
  }
};

inline std::atomic<std::int64_t> LifetimeCounter::alive{0};
inline std::atomic<std::int64_t> LifetimeCounter::constructed{0};

/// A gate one thread waits at until another opens it (with a deadline so a bug fails, not hangs).
class Gate {
 public:
  void open() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      open_ = true;
    }
    cv_.notify_all();
  }
  bool waitOpen(std::chrono::milliseconds timeout = std::chrono::seconds(20)) {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_for(lock, timeout, [&] { return open_; });
  }

 private:
  std::mutex mutex_;
  std::condition_variable cv_;
  bool open_ = false;
};

}  // namespace slamd::test
