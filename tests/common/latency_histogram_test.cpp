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

TEST(Percentile, InterpolatesLikeNumpy) {
  EXPECT_DOUBLE_EQ(percentile({1, 2, 3, 4}, 50), 2.5);
  EXPECT_DOUBLE_EQ(percentile({5}, 95), 5.0);
  EXPECT_DOUBLE_EQ(percentile({1, 2, 3, 4, 5}, 100), 5.0);
}

}  // namespace
}  // namespace slamd
