#include "slamd/common/shutdown_signals.hpp"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <cstdio>

namespace slamd {

namespace {
sigset_t shutdownSignalSet() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  // A closed terminal and a stray user signal end the run in order too, with outputs written,
  // instead of the default termination.
  sigaddset(&set, SIGHUP);
  sigaddset(&set, SIGUSR1);
  sigaddset(&set, SIGUSR2);  // internal: wakes the waiting thread at destruction
  return set;
}
}  // namespace

ShutdownSignals::ShutdownSignals() {
  // A reader that goes away (`slamd ... 2>&1 | head -1`) must not kill the process: writes to a
  // closed pipe fail with EPIPE instead, and logging carries on without them.
  signal(SIGPIPE, SIG_IGN);
  const sigset_t set = shutdownSignalSet();
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  thread_ = std::thread([this] { run(); });
}

ShutdownSignals::~ShutdownSignals() {
  stopping_.store(true, std::memory_order_release);
  pthread_kill(thread_.native_handle(), SIGUSR2);
  thread_.join();
}

void ShutdownSignals::run() {
  const sigset_t set = shutdownSignalSet();
  while (true) {
    int signal_number = 0;
    if (sigwait(&set, &signal_number) != 0) continue;
    if (stopping_.load(std::memory_order_acquire)) return;
    if (signal_number == SIGUSR2) continue;
    if (requested_.load(std::memory_order_acquire)) {
      // Second signal: the user insists. Only async-signal-safe calls from here on.
      static const char kMessage[] = "second signal: exiting immediately without saving\n";
      (void)!write(STDERR_FILENO, kMessage, sizeof(kMessage) - 1);
      _exit(kExitForced);
    }
    signal_number_.store(signal_number, std::memory_order_release);
    request();
  }
}

void ShutdownSignals::request() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    requested_.store(true, std::memory_order_release);
  }
  cv_.notify_all();
}

bool ShutdownSignals::waitFor(std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  cv_.wait_for(lock, timeout, [&] { return requested_.load(std::memory_order_acquire); });
  return requested_.load(std::memory_order_acquire);
}

}  // namespace slamd
