#pragma once
// WakeSignal: lets a thread sleep until another thread reports progress, without polling.
// Data never passes through it (the lock-free queues carry the data); it only avoids busy waiting.
//
//   const auto seen = signal.epoch();      // 1. remember the epoch
//   if (auto item = queue.tryPop()) ...    // 2. check the condition
//   signal.waitFor(seen, deadline);        // 3. sleep until the epoch moves or the deadline
//
// Because the epoch is read before the condition is checked, a notify() between 2 and 3 is never
// lost: it changes the epoch and waitFor returns at once.

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>

namespace slamd {

class WakeSignal {
 public:
  std::uint64_t epoch() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return epoch_;
  }

  void notify() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++epoch_;
    }
    cv_.notify_all();
  }

  /// Returns true when the epoch moved past `seen`, false at the deadline.
  bool waitFor(std::uint64_t seen, std::chrono::steady_clock::time_point deadline) const {
    std::unique_lock<std::mutex> lock(mutex_);
    return cv_.wait_until(lock, deadline, [&] { return epoch_ != seen; });
  }

 private:
  mutable std::mutex mutex_;
  mutable std::condition_variable cv_;
  std::uint64_t epoch_ = 0;
};

}  // namespace slamd
