#pragma once
// Timestamps in slamd: int64_t microseconds since the Unix epoch ("utime"), as in every LCM
// message. Latencies are measured on the monotonic clock and never mixed with utime.

#include <chrono>
#include <cmath>
#include <cstdint>
#include <ctime>

namespace slamd {

using Utime = std::int64_t;  ///< microseconds since the Unix epoch

constexpr Utime kUtimePerSecond = 1'000'000;

/// Converts seconds (as in TUM files, e.g. 1305031102.175304) to utime, rounding to the nearest
/// microsecond so that a value printed with 6 decimals round-trips exactly.
inline Utime secondsToUtime(double seconds) {
  return static_cast<Utime>(std::llround(seconds * static_cast<double>(kUtimePerSecond)));
}

inline double utimeToSeconds(Utime utime) {
  return static_cast<double>(utime) / static_cast<double>(kUtimePerSecond);
}

/// Wall-clock time now as utime (for message stamps).
inline Utime wallClockUtime() {
  return std::chrono::duration_cast<std::chrono::microseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

/// Monotonic time now in nanoseconds (for latencies and pacing).
inline std::int64_t steadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

/// CPU time consumed by the calling thread, nanoseconds.
inline std::int64_t threadCpuNowNs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

/// CPU time consumed by the calling thread, milliseconds: what work costs on one core, unaffected
/// by other processes competing for the CPU (benchmarks report it next to wall time).
inline double threadCpuMs() { return static_cast<double>(threadCpuNowNs()) * 1e-6; }

}  // namespace slamd
