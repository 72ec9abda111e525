#pragma once
// MetricsReport: how a program run by the benchmark harness (slamd-bench) reports what it
// measured. The program prints the report as ONE line of JSON, the last line of its standard
// output (logs go to stderr); the harness adds wall time, CPU time and peak RSS itself.
//
// Usage (in a program's main, after the run):
//   eval::MetricsReport report("slamd-play");
//   report.set("frames", frames);                          // count
//   report.set("fps", frames / wall_s);                    // frames per second of wall time
//   report.setLatency("capture", histogram.summary());     // latency_ms.capture.{p50,p95,p99,...}
//   report.setLatency("end_to_end", end_to_end.summary());
//   report.setErrorStatistics("ate_m", ate.translation_m); // ate_m.{rmse,mean,median,...}
//   report.print(std::cout);
//
// Schema "slamd.metrics/1": an object with "schema", "program", then numbers nested by the dots
// of their keys. Names carry their unit; these names have fixed meaning across slamd:
//   frames                       frames processed (count)
//   fps                          frames per second of wall time (higher is better)
//   latency_ms.<stage>.p50|p95|p99|max|mean   per-stage latency, milliseconds; <stage> is
//                                capture, tracking, filter, mapping, backend or end_to_end
//                                (capture timestamp to pose published)
//   ate_m.rmse|mean|median|std|min|max        absolute trajectory error, metres
//   rpe_translation_m.*, rpe_rotation_deg.*   relative pose error (delta in rpe_delta)
//   drops.<queue>                dropped items per queue (count)
// The harness treats a metric as higher-is-better when its last name part is "fps" or ends in
// "_per_s" or "_hz"; as informational (compared for change only) when it is "frames", "pairs",
// "count" or ends in "_count"; and otherwise as lower-is-better.
//
// Keys: letters, digits, '_' and '-', parts joined by '.'; a key cannot be both a value and a
// prefix of another key (throws std::invalid_argument). Not thread-safe.

#include <cstddef>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include "slamd/common/latency_histogram.hpp"
#include "slamd/eval/trajectory_error.hpp"

namespace slamd::eval {

class MetricsReport {
 public:
  static constexpr const char* kSchema = "slamd.metrics/1";

  explicit MetricsReport(std::string program);

  void set(const std::string& key, double value);
  void setText(const std::string& key, const std::string& text);
  /// <prefix>.p50/p95/p99/max/mean in milliseconds and <prefix>.count, under latency_ms.<stage>.
  void setLatency(const std::string& stage, const LatencySummary& summary);
  /// Exact percentiles of every sample (milliseconds).
  void setLatencySamples(const std::string& stage, const std::vector<double>& samples_ms);
  void setErrorStatistics(const std::string& prefix, const ErrorStatistics& statistics);

  /// The report as JSON (one line unless pretty).
  std::string toJson(bool pretty = false) const;
  /// Writes toJson() and a newline, then flushes.
  void print(std::ostream& out) const;

  const std::map<std::string, double>& numbers() const { return numbers_; }

 private:
  void checkKey(const std::string& key) const;

  std::string program_;
  std::map<std::string, double> numbers_;
  std::map<std::string, std::string> texts_;
};

/// Every number in a JSON object, keyed by its dotted path ("latency_ms.tracking.p50"); array
/// elements get their index as a path part. Strings, booleans and nulls are skipped.
/// Throws std::runtime_error when the text is not a JSON object.
std::map<std::string, double> flattenJsonNumbers(const std::string& json_text);

/// The last line of `output` that holds a JSON object (starts with '{'), or the whole output
/// when it is one multi-line JSON object; empty when there is none.
std::string lastJsonObject(const std::string& output);

}  // namespace slamd::eval
