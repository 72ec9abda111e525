#include "slamd/common/latency_histogram.hpp"

#include <random>

#include <gtest/gtest.h>

namespace slamd {
namespace {

TEST(LatencyHistogram, PercentilesWithinBucketResolution) {
  LatencyHistogram histogram;
  std::vector<double> samples_ms;
  std::mt19937 rng(42);
  std::lognormal_distribution<double> dist(std::log(5.0), 0.5);  // around 5 ms
  for (int i = 0; i < 20000; ++i) {
    const double ms = dist(rng);
    samples_ms.push_back(ms);
    histogram.recordNs(static_cast<std::int64_t>(ms * 1e6));
  }
  const LatencySummary s = histogram.summary();
  EXPECT_EQ(s.count, 20000u);
  // Buckets are 2^(1/8) wide: percentiles are accurate to a few percent.
  EXPECT_NEAR(s.p50_ms, percentile(samples_ms, 50), 0.05 * percentile(samples_ms, 50));
  EXPECT_NEAR(s.p95_ms, percentile(samples_ms, 95), 0.05 * percentile(samples_ms, 95));
  EXPECT_NEAR(s.p99_ms, percentile(samples_ms, 99), 0.05 * percentile(samples_ms, 99));
  EXPECT_NEAR(s.max_ms, *std::max_element(samples_ms.begin(), samples_ms.end()), 1e-5);
}

TEST(LatencyHistogram, IntervalSummaryFromSnapshots) {
  LatencyHistogram histogram;
  for (int i = 0; i < 100; ++i) histogram.recordNs(1'000'000);  // 1 ms
  const auto before = histogram.snapshot();
  for (int i = 0; i < 100; ++i) histogram.recordNs(10'000'000);  // 10 ms
  auto after = histogram.snapshot();
  for (std::size_t i = 0; i < after.size(); ++i) after[i] -= before[i];
  const LatencySummary interval = LatencyHistogram::summarize(after);
  EXPECT_EQ(interval.count, 100u);
  EXPECT_NEAR(interval.p50_ms, 10.0, 1.0);
}

TEST(LatencyHistogram, EmptyHistogramSummarisesToZero) {
  LatencyHistogram histogram;
  EXPECT_EQ(histogram.summary().count, 0u);
  EXPECT_EQ(histogram.summary().p99_ms, 0.0);
}

TEST(WindowedLatency, EachWindowSummarisesOnlyItsOwnSamples) {
  // Three minutes fed once a second: the second minute holds 30 slow frames among 1770 fast ones
  // (its p99 is slow), the first and third only fast ones; the whole run's p99 hides the bad
  // minute.
  constexpr std::int64_t kSecondNs = 1'000'000'000;
  LatencyHistogram histogram;
  WindowedLatency by_minute(60.0);
  by_minute.start(0, histogram.snapshot());
  for (int second = 1; second <= 150; ++second) {
    for (int frame = 0; frame < 30; ++frame) {
      const bool slow = second > 60 && second <= 120 && second % 2 == 0 && frame == 0;
      histogram.recordNs(slow ? 80'000'000 : 10'000'000);
    }
    by_minute.update(second * kSecondNs, histogram.snapshot());
  }
  ASSERT_EQ(by_minute.windows().size(), 2u);
  by_minute.finish(150 * kSecondNs, histogram.snapshot());
  by_minute.finish(150 * kSecondNs, histogram.snapshot());  // nothing new: no empty window
  const auto& windows = by_minute.windows();
  ASSERT_EQ(windows.size(), 3u);
  EXPECT_DOUBLE_EQ(windows[0].start_s, 0.0);
  EXPECT_DOUBLE_EQ(windows[1].start_s, 60.0);
  EXPECT_DOUBLE_EQ(windows[2].start_s, 120.0);
  EXPECT_DOUBLE_EQ(windows[2].length_s, 30.0);
  EXPECT_EQ(windows[0].latency.count, 1800u);
  EXPECT_EQ(windows[1].latency.count, 1800u);
  EXPECT_EQ(windows[2].latency.count, 900u);
  EXPECT_LT(windows[0].latency.p99_ms, 11.0);
  EXPECT_GT(windows[1].latency.p99_ms, 70.0);
  EXPECT_LT(windows[1].latency.p50_ms, 11.0);
  EXPECT_LT(windows[2].latency.p99_ms, 11.0);
  EXPECT_LT(histogram.summary().p99_ms, 11.0);  // 30 of 4500 frames: under the whole run's p99
}

TEST(Percentile, InterpolatesLikeNumpy) {
  EXPECT_DOUBLE_EQ(percentile({1, 2, 3, 4}, 50), 2.5);
  EXPECT_DOUBLE_EQ(percentile({5}, 95), 5.0);
  EXPECT_DOUBLE_EQ(percentile({1, 2, 3, 4, 5}, 100), 5.0);
}

}  // namespace
}  // namespace slamd
