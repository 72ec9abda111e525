#include "slamd/common/latency_histogram.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

namespace slamd {

namespace {
constexpr double kFirstEdgeNs = 1000.0;  // 1 microsecond
}

int LatencyHistogram::bucketOf(std::int64_t duration_ns) {
  if (duration_ns <= static_cast<std::int64_t>(kFirstEdgeNs)) return 0;
  const double octaves = std::log2(static_cast<double>(duration_ns) / kFirstEdgeNs);
  const int bucket = static_cast<int>(octaves * kBucketsPerOctave);
  return std::min(bucket, kNumBuckets - 1);
}

double LatencyHistogram::bucketLowerNs(int bucket) {
  return kFirstEdgeNs * std::exp2(static_cast<double>(bucket) / kBucketsPerOctave);
}

void LatencyHistogram::recordNs(std::int64_t duration_ns) {
  duration_ns = std::max<std::int64_t>(duration_ns, 0);
  // Relaxed: each counter is independent; readers only need eventually consistent totals.
  counts_[static_cast<std::size_t>(bucketOf(duration_ns))].fetch_add(1, std::memory_order_relaxed);
  sum_ns_.fetch_add(duration_ns, std::memory_order_relaxed);
  std::int64_t previous_max = max_ns_.load(std::memory_order_relaxed);
  while (duration_ns > previous_max &&
         !max_ns_.compare_exchange_weak(previous_max, duration_ns, std::memory_order_relaxed)) {
  }
}

std::vector<std::uint64_t> LatencyHistogram::snapshot() const {
  std::vector<std::uint64_t> counts(kNumBuckets);
  for (int i = 0; i < kNumBuckets; ++i) {
    counts[static_cast<std::size_t>(i)] =
        counts_[static_cast<std::size_t>(i)].load(std::memory_order_relaxed);
  }
  return counts;
}

LatencySummary LatencyHistogram::summarize(const std::vector<std::uint64_t>& counts) {
  LatencySummary summary;
  double weighted_sum_ns = 0.0;
  int last_nonempty = -1;
  for (std::size_t i = 0; i < counts.size(); ++i) {
    summary.count += counts[i];
    if (counts[i]) {
      last_nonempty = static_cast<int>(i);
      // Geometric centre of the bucket as its representative value.
      weighted_sum_ns += static_cast<double>(counts[i]) * bucketLowerNs(static_cast<int>(i)) *
                         std::exp2(0.5 / kBucketsPerOctave);
    }
  }
  if (summary.count == 0) return summary;
  auto quantile_ms = [&](double q) {
    // Rank of the q-quantile, then linear interpolation inside the bucket holding it.
    const double rank = q * static_cast<double>(summary.count);
    double cumulative = 0.0;
    for (std::size_t i = 0; i < counts.size(); ++i) {
      const double next = cumulative + static_cast<double>(counts[i]);
      if (counts[i] && next >= rank) {
        const double fraction = (rank - cumulative) / static_cast<double>(counts[i]);
        const double low = bucketLowerNs(static_cast<int>(i));
        const double high = bucketLowerNs(static_cast<int>(i) + 1);
        return (low + fraction * (high - low)) * 1e-6;
      }
      cumulative = next;
    }
    return bucketLowerNs(static_cast<int>(counts.size())) * 1e-6;
  };
  summary.p50_ms = quantile_ms(0.50);
  summary.p95_ms = quantile_ms(0.95);
  summary.p99_ms = quantile_ms(0.99);
  summary.max_ms = bucketLowerNs(last_nonempty + 1) * 1e-6;
  summary.mean_ms = weighted_sum_ns / static_cast<double>(summary.count) * 1e-6;
  return summary;
}

LatencySummary LatencyHistogram::summary() const {
  LatencySummary summary = summarize(snapshot());
  if (summary.count) {
    summary.max_ms = static_cast<double>(max_ns_.load(std::memory_order_relaxed)) * 1e-6;
    summary.mean_ms = static_cast<double>(sum_ns_.load(std::memory_order_relaxed)) * 1e-6 /
                      static_cast<double>(summary.count);
  }
  return summary;
}

void LatencyHistogram::reset() {
  for (auto& count : counts_) count.store(0, std::memory_order_relaxed);
  max_ns_.store(0, std::memory_order_relaxed);
  sum_ns_.store(0, std::memory_order_relaxed);
}

std::vector<std::uint64_t> histogramDelta(const std::vector<std::uint64_t>& later,
                                          const std::vector<std::uint64_t>& earlier) {
  std::vector<std::uint64_t> delta = later;
  for (std::size_t i = 0; i < delta.size() && i < earlier.size(); ++i) {
    delta[i] = later[i] >= earlier[i] ? later[i] - earlier[i] : 0;
  }
  return delta;
}

WindowedLatency::WindowedLatency(double window_s) : window_s_(window_s) {}

void WindowedLatency::start(std::int64_t now_ns, std::vector<std::uint64_t> snapshot) {
  run_start_ns_ = now_ns;
  window_start_ns_ = now_ns;
  window_start_counts_ = std::move(snapshot);
  windows_.clear();
}

void WindowedLatency::update(std::int64_t now_ns, const std::vector<std::uint64_t>& snapshot) {
  if (static_cast<double>(now_ns - window_start_ns_) * 1e-9 >= window_s_) close(now_ns, snapshot);
}

void WindowedLatency::finish(std::int64_t now_ns, const std::vector<std::uint64_t>& snapshot) {
  if (LatencyHistogram::summarize(histogramDelta(snapshot, window_start_counts_)).count > 0) {
    close(now_ns, snapshot);
  }
}

void WindowedLatency::close(std::int64_t now_ns, const std::vector<std::uint64_t>& snapshot) {
  LatencyWindow window;
  window.start_s = static_cast<double>(window_start_ns_ - run_start_ns_) * 1e-9;
  window.length_s = static_cast<double>(now_ns - window_start_ns_) * 1e-9;
  window.latency = LatencyHistogram::summarize(histogramDelta(snapshot, window_start_counts_));
  windows_.push_back(window);
  window_start_ns_ = now_ns;
  window_start_counts_ = snapshot;
}

double percentile(std::vector<double> samples, double q) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const double position = q / 100.0 * static_cast<double>(samples.size() - 1);
  const auto below = static_cast<std::size_t>(std::floor(position));
  const auto above = std::min(below + 1, samples.size() - 1);
  const double fraction = position - static_cast<double>(below);
  return samples[below] + fraction * (samples[above] - samples[below]);
}

}  // namespace slamd
