#pragma once
// LatencyHistogram: a fixed log-scale histogram of durations for percentiles (p50/p95/p99).
//
// Buckets are geometric with ratio 2^(1/8) (about 9% wide) from 1 microsecond to about 1.2 hours,
// so a percentile is accurate to within half a bucket (about 4.5%). record() is wait-free
// (relaxed atomic increments) so the owning stage thread can record while a status thread reads a
// snapshot; counts read concurrently may be a few items apart, which percentiles tolerate.

#include <array>
#include <atomic>
#include <cstdint>
#include <vector>

namespace slamd {

struct LatencySummary {
  std::uint64_t count = 0;
  double p50_ms = 0.0;
  double p95_ms = 0.0;
  double p99_ms = 0.0;
  double max_ms = 0.0;
  double mean_ms = 0.0;
};

class LatencyHistogram {
 public:
  static constexpr int kBucketsPerOctave = 8;
  static constexpr int kNumBuckets = 8 * 32;  // 32 octaves above 1 us

  LatencyHistogram() = default;
  LatencyHistogram(const LatencyHistogram&) = delete;
  LatencyHistogram& operator=(const LatencyHistogram&) = delete;

  void recordNs(std::int64_t duration_ns);

  /// Summary of everything recorded since construction or reset().
  LatencySummary summary() const;
  /// Bucket counts, for summaries over an interval (subtract two snapshots).
  std::vector<std::uint64_t> snapshot() const;
  /// Summary of the difference between two snapshots (later minus earlier).
  static LatencySummary summarize(const std::vector<std::uint64_t>& counts);
  void reset();

  /// Lower edge of bucket i in nanoseconds.
  static double bucketLowerNs(int bucket);
  static int bucketOf(std::int64_t duration_ns);

 private:
  std::array<std::atomic<std::uint64_t>, kNumBuckets> counts_{};
  std::atomic<std::int64_t> max_ns_{0};
  std::atomic<std::int64_t> sum_ns_{0};
};

/// Bucket-wise difference later - earlier (earlier may be empty: all zeros).
std::vector<std::uint64_t> histogramDelta(const std::vector<std::uint64_t>& later,
                                          const std::vector<std::uint64_t>& earlier);

/// One window of a run: the latencies recorded between its start and its end.
struct LatencyWindow {
  double start_s = 0.0;  ///< since the run's start
  double length_s = 0.0;
  LatencySummary latency;  ///< from buckets: max_ms and mean_ms are bucket estimates
};

/// Latency percentiles over consecutive windows of a run (e.g. each minute: "p99 at most 33 ms in
/// every minute" is a statement about each window's own frames, which neither the whole run's
/// percentiles nor a second's handful of frames can show). Fed cumulative snapshots of one
/// histogram by one thread; a window closes at the first snapshot at or after its nominal end, so
/// fed once a second, windows are within a second of their nominal length. Keeps one summary per
/// window: an eight-hour run at one minute holds 480.
class WindowedLatency {
 public:
  explicit WindowedLatency(double window_s);

  void start(std::int64_t now_ns, std::vector<std::uint64_t> snapshot);
  /// Closes the current window when now_ns reached its end.
  void update(std::int64_t now_ns, const std::vector<std::uint64_t>& snapshot);
  /// Closes the current window, however short, if anything was recorded in it.
  void finish(std::int64_t now_ns, const std::vector<std::uint64_t>& snapshot);

  const std::vector<LatencyWindow>& windows() const { return windows_; }

 private:
  void close(std::int64_t now_ns, const std::vector<std::uint64_t>& snapshot);

  double window_s_;
  std::int64_t run_start_ns_ = 0;
  std::int64_t window_start_ns_ = 0;
  std::vector<std::uint64_t> window_start_counts_;
  std::vector<LatencyWindow> windows_;
};

/// Exact percentile (linear interpolation between order statistics, as numpy's default) of a
/// set of samples; used by benchmarks that keep every sample. q in [0, 100].
double percentile(std::vector<double> samples, double q);

}  // namespace slamd
