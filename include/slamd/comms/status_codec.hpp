#pragma once
// StatusBuilder: turns successive snapshots of the pipeline's counters into slamd.status_t
// messages describing the interval since the previous message (rates and latency percentiles) and
// the totals since start (drops, errors, processed).
//
// Owned by the thread that publishes status (the daemon's main thread); Pipeline::stats() may be
// read from there while the stages run.

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "slamd/common/memory_pressure.hpp"
#include "slamd/common/pose_estimate.hpp"
#include "slamd/pipeline/pipeline.hpp"
#include "slamd/status_t.hpp"

namespace slamd {

struct StatusExtras {
  /// Errors counted outside the pipeline, added to the stage of that name (e.g. frames a source
  /// skipped as corrupt are errors of "capture").
  std::map<std::string, std::uint64_t> extra_errors;
  /// Drops counted outside the pipeline (e.g. frames a live source dropped before queueing).
  std::map<std::string, std::uint64_t> extra_drops;
  TrackingState tracking_state = TrackingState::kNotInitialized;
  std::int64_t map_occupied_voxels = 0;
  std::int64_t map_total_voxels = 0;
  std::int32_t num_keyframes = 0;
  std::int32_t num_loops = 0;
  std::int32_t num_relocalizations = 0;
  double memory_rss_mb = 0.0;
  std::int32_t memory_limit_mb = 0;  ///< 0 = none
  MemoryPressure memory_pressure = MemoryPressure::kNone;
  std::string message;
};

class StatusBuilder {
 public:
  /// @param now_utime wall-clock stamp of the message
  /// @param now_steady_ns monotonic time, for rates over the interval
  /// @param stages Pipeline::stats()
  /// @param end_to_end_buckets LatencyHistogram::snapshot() of capture-to-publication latency
  slamd::status_t build(Utime now_utime, std::int64_t now_steady_ns,
                        const std::vector<StageStats>& stages,
                        const std::vector<std::uint64_t>& end_to_end_buckets,
                        const StatusExtras& extras);

 private:
  struct Previous {
    std::uint64_t processed = 0;
    std::vector<std::uint64_t> latency_buckets;
  };
  std::map<std::string, Previous> previous_;
  std::vector<std::uint64_t> previous_end_to_end_;
  std::int64_t previous_steady_ns_ = 0;
};

/// The table slamd-status prints for one status message: one row per stage, then end-to-end
/// latency, tracking state, map and back end. Any field values (a received message) are safe.
/// @param malformed status messages the caller ignored as malformed (0: no line about them)
std::string renderStatusTable(const slamd::status_t& status, std::uint64_t malformed);

}  // namespace slamd
