#pragma once
// ShutdownSignals: turns SIGINT, SIGTERM, SIGHUP and SIGUSR1 into an orderly shutdown request,
// and ignores SIGPIPE (a closed log pipe makes writes fail, not the process die).
//
// Construct it first thing in main(), before any other thread starts: it blocks those signals in
// the calling thread (new threads inherit the mask) and waits for them on a dedicated thread with
// sigwait(), so no handler ever runs in the middle of another thread's work.
// The first signal sets requested() and wakes waitFor(); a second signal means the user insists:
// the process exits at once with kExitForced (skipping the drain and saves).
//
//   ShutdownSignals signals;
//   ... start threads ...
//   while (!signals.waitFor(std::chrono::milliseconds(100))) { periodic work }
//   ... drain, save, join ...

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

namespace slamd {

class ShutdownSignals {
 public:
  static constexpr int kExitForced = 130;  // 128 + SIGINT, as shells report

  ShutdownSignals();
  ~ShutdownSignals();
  ShutdownSignals(const ShutdownSignals&) = delete;
  ShutdownSignals& operator=(const ShutdownSignals&) = delete;

  bool requested() const { return requested_.load(std::memory_order_acquire); }
  /// The number of the first signal received (0 if none, or if requested by request()).
  int signalNumber() const { return signal_number_.load(std::memory_order_acquire); }
  /// Requests shutdown from inside the program (e.g. a SHUTDOWN command).
  void request();
  /// Waits until shutdown is requested or the timeout passes; returns requested().
  bool waitFor(std::chrono::milliseconds timeout);

 private:
  void run();

  std::atomic<bool> requested_{false};
  std::atomic<int> signal_number_{0};
  std::atomic<bool> stopping_{false};
  std::mutex mutex_;
  std::condition_variable cv_;
  std::thread thread_;
};

}  // namespace slamd
