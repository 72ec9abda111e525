#include "slamd/comms/status_codec.hpp"

#include <cstdio>
#include <sstream>

namespace slamd {

slamd::status_t StatusBuilder::build(Utime now_utime, std::int64_t now_steady_ns,
                                     const std::vector<StageStats>& stages,
                                     const std::vector<std::uint64_t>& end_to_end_buckets,
                                     const StatusExtras& extras) {
  const double interval_s = previous_steady_ns_ > 0
                                ? static_cast<double>(now_steady_ns - previous_steady_ns_) * 1e-9
                                : 0.0;
  slamd::status_t status;
  status.utime = now_utime;
  for (const StageStats& stage : stages) {
    Previous& previous = previous_[stage.name];
    slamd::stage_status_t out;
    out.name = stage.name;
    out.rate_hz = interval_s > 0.0
                      ? static_cast<double>(stage.processed - previous.processed) / interval_s
                      : 0.0;
    const LatencySummary latency = LatencyHistogram::summarize(
        histogramDelta(stage.latency_buckets, previous.latency_buckets));
    out.latency_p50_ms = latency.p50_ms;
    out.latency_p95_ms = latency.p95_ms;
    out.latency_p99_ms = latency.p99_ms;
    out.queue_depth = 0;
    out.queue_capacity = 0;
    out.drops = 0;
    for (const EdgeStats& edge : stage.inputs) {
      out.queue_depth += static_cast<int32_t>(edge.depth);
      out.queue_capacity += static_cast<int32_t>(edge.capacity);
      out.drops += static_cast<int64_t>(edge.dropped + edge.discarded);
    }
    out.errors = static_cast<int64_t>(stage.errors);
    if (const auto it = extras.extra_errors.find(stage.name); it != extras.extra_errors.end()) {
      out.errors += static_cast<int64_t>(it->second);
    }
    if (const auto it = extras.extra_drops.find(stage.name); it != extras.extra_drops.end()) {
      out.drops += static_cast<int64_t>(it->second);
    }
    out.processed = static_cast<int64_t>(stage.processed);
    status.stages.push_back(out);
    previous.processed = stage.processed;
    previous.latency_buckets = stage.latency_buckets;
  }
  status.num_stages = static_cast<int32_t>(status.stages.size());
  const LatencySummary end_to_end =
      LatencyHistogram::summarize(histogramDelta(end_to_end_buckets, previous_end_to_end_));
  status.end_to_end_p50_ms = end_to_end.p50_ms;
  status.end_to_end_p95_ms = end_to_end.p95_ms;
  status.end_to_end_p99_ms = end_to_end.p99_ms;
  previous_end_to_end_ = end_to_end_buckets;
  status.tracking_state = static_cast<int8_t>(extras.tracking_state);
  status.map_occupied_voxels = extras.map_occupied_voxels;
  status.map_total_voxels = extras.map_total_voxels;
  status.num_keyframes = extras.num_keyframes;
  status.num_loops = extras.num_loops;
  status.num_relocalizations = extras.num_relocalizations;
  status.memory_rss_mb = extras.memory_rss_mb;
  status.memory_limit_mb = extras.memory_limit_mb;
  status.memory_pressure = static_cast<std::int8_t>(extras.memory_pressure);
  status.message = extras.message;
  previous_steady_ns_ = now_steady_ns;
  return status;
}

std::string renderStatusTable(const status_t& status, std::uint64_t malformed) {
  std::ostringstream out;
  char line[256];
  std::snprintf(line, sizeof(line), "%-12s %8s %9s %9s %9s %11s %9s %8s %10s\n", "stage", "rate Hz",
                "p50 ms", "p95 ms", "p99 ms", "queue", "drops", "errors", "processed");
  out << line;
  for (const auto& stage : status.stages) {
    std::snprintf(line, sizeof(line), "%-12s %8.1f %9.2f %9.2f %9.2f %5d/%-5d %9lld %8lld %10lld\n",
                  stage.name.c_str(), stage.rate_hz, stage.latency_p50_ms, stage.latency_p95_ms,
                  stage.latency_p99_ms, stage.queue_depth, stage.queue_capacity,
                  static_cast<long long>(stage.drops), static_cast<long long>(stage.errors),
                  static_cast<long long>(stage.processed));
    out << line;
  }
  std::snprintf(line, sizeof(line),
                "end-to-end latency (capture -> pose published): p50 %.2f ms  p95 %.2f ms  p99 "
                "%.2f ms\n",
                status.end_to_end_p50_ms, status.end_to_end_p95_ms, status.end_to_end_p99_ms);
  out << line;
  out << "tracking: " << trackingStateName(static_cast<TrackingState>(status.tracking_state))
      << "   map: " << status.map_occupied_voxels << " occupied / " << status.map_total_voxels
      << " voxels   back end: " << status.num_keyframes << " keyframes, " << status.num_loops
      << " loops, " << status.num_relocalizations << " relocalisations\n";
  std::snprintf(line, sizeof(line), "memory: %.0f MB resident", status.memory_rss_mb);
  out << line;
  if (status.memory_limit_mb > 0) {
    const int pressure = status.memory_pressure;
    out << ", limit " << status.memory_limit_mb << " MB, "
        << (pressure >= 0 && pressure <= 2 ? toString(static_cast<MemoryPressure>(pressure))
                                           : "unknown pressure");
  }
  out << "\n";
  if (!status.message.empty()) out << "note: " << status.message << "\n";
  if (malformed) out << "(" << malformed << " malformed status messages ignored)\n";
  return out.str();
}

}  // namespace slamd
