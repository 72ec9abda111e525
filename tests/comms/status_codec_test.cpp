#include "slamd/comms/status_codec.hpp"

#include <gtest/gtest.h>

namespace slamd {
namespace {

StageStats stage(const std::string& name, std::uint64_t processed, double latency_ms,
                 std::uint64_t count_at_latency, std::uint64_t dropped) {
  LatencyHistogram histogram;
  for (std::uint64_t i = 0; i < count_at_latency; ++i) {
    histogram.recordNs(static_cast<std::int64_t>(latency_ms * 1e6));
  }
  StageStats s;
  s.name = name;
  s.processed = processed;
  s.latency_buckets = histogram.snapshot();
  EdgeStats edge;
  edge.capacity = 4;
  edge.depth = 2;
  edge.dropped = dropped;
  s.inputs.push_back(edge);
  return s;
}

TEST(StatusBuilder, RatesAndPercentilesCoverTheIntervalSinceTheLastMessage) {
  StatusBuilder builder;
  LatencyHistogram end_to_end;
  StatusExtras extras;
  extras.extra_errors["tracking"] = 3;
  builder.build(1, 1'000'000'000, {stage("tracking", 30, 5.0, 30, 0)}, end_to_end.snapshot(),
                extras);
  for (int i = 0; i < 10; ++i) end_to_end.recordNs(20'000'000);
  // One second later: 30 more frames, all at 10 ms.
  StageStats later = stage("tracking", 60, 5.0, 30, 7);
  {
    LatencyHistogram h;
    for (int i = 0; i < 30; ++i) h.recordNs(5'000'000);
    for (int i = 0; i < 30; ++i) h.recordNs(10'000'000);
    later.latency_buckets = h.snapshot();
  }
  const slamd::status_t status =
      builder.build(2, 2'000'000'000, {later}, end_to_end.snapshot(), extras);
  ASSERT_EQ(status.num_stages, 1);
  const auto& s = status.stages[0];
  EXPECT_EQ(s.name, "tracking");
  EXPECT_NEAR(s.rate_hz, 30.0, 1e-9);
  EXPECT_NEAR(s.latency_p50_ms, 10.0, 1.0);  // the interval only saw 10 ms items
  EXPECT_EQ(s.drops, 7);
  EXPECT_EQ(s.errors, 3);
  EXPECT_EQ(s.queue_depth, 2);
  EXPECT_EQ(s.queue_capacity, 4);
  EXPECT_NEAR(status.end_to_end_p50_ms, 20.0, 2.0);
}

TEST(StatusBuilder, CarriesAndShowsResidentMemoryAndTheMemoryLimit) {
  StatusBuilder builder;
  LatencyHistogram end_to_end;
  StatusExtras extras;
  extras.memory_rss_mb = 312.4;
  extras.memory_limit_mb = 300;
  extras.memory_pressure = MemoryPressure::kOver;
  const slamd::status_t status = builder.build(
      1, 1'000'000'000, {stage("tracking", 30, 5.0, 30, 0)}, end_to_end.snapshot(), extras);
  EXPECT_DOUBLE_EQ(status.memory_rss_mb, 312.4);
  EXPECT_EQ(status.memory_limit_mb, 300);
  EXPECT_EQ(status.memory_pressure, 2);
  const std::string table = renderStatusTable(status, 0);
  EXPECT_NE(table.find("memory: 312 MB resident, limit 300 MB, over the limit"), std::string::npos)
      << table;
  // Without a limit only the resident size is shown; a received level out of range is named so.
  slamd::status_t unlimited = status;
  unlimited.memory_limit_mb = 0;
  EXPECT_NE(renderStatusTable(unlimited, 0).find("memory: 312 MB resident\n"), std::string::npos);
  slamd::status_t odd = status;
  odd.memory_pressure = 9;
  EXPECT_NE(renderStatusTable(odd, 0).find("unknown pressure"), std::string::npos);
}

}  // namespace
}  // namespace slamd
