// slamd-odometry-run: runs visual odometry over a whole sequence (TUM folder) and reports the
// trajectory and its metrics.
//
//   slamd-odometry-run --source tum:../shared/data/tum_fr1_xyz --config config/tum_fr1.yaml
//       --set tracking.frontend=orb --trajectory orb.txt
//
// Prints a per-front-end summary on stderr and, as the last line of stdout, one JSON metrics
// report (schema slamd.metrics/1): frames, per-step median/p95 times (latency_ms.*), ATE and
// RPE (1 s) against the ground truth when the source has one. OpenCV runs on one thread.

#include <ctime>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/capture/tum_source.hpp"
#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/time.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/metrics_report.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/visual_odometry.hpp"

using namespace slamd;

int main(int argc, char** argv) {
  ProgramOptions options("slamd-odometry-run",
                         "Runs visual odometry over a sequence and reports ATE, RPE and timing.");
  options.addOption("source", "SOURCE", "tum:DIR or synthetic:SCENE (room, corridor, ...)",
                    "tum:" SLAMD_SOURCE_DIR "/../shared/data/tum_fr1_xyz");
  options.addOption("trajectory", "FILE", "write the estimated trajectory (TUM format)");
  options.addOption("max-frames", "N", "stop after N frames (0 = all)", "0");
  if (!options.parse(argc, argv)) return options.exitCode();
  cv::setNumThreads(1);

  const std::string spec = options.value("source");
  const bool synthetic = spec.rfind("synthetic:", 0) == 0;
  Config config;
  TrackingConfig tracking;
  std::unique_ptr<FrameSource> source;
  try {
    config = options.loadConfig(synthetic ? SLAMD_SOURCE_DIR "/config/synthetic.yaml"
                                          : SLAMD_SOURCE_DIR "/config/tum_fr1.yaml");
    tracking = TrackingConfig::load(config);
    if (synthetic) {
      source = createSyntheticSource(spec.substr(10), config);
    } else {
      const std::string folder = spec.rfind("tum:", 0) == 0 ? spec.substr(4) : spec;
      source = std::make_unique<TumSource>(folder, TumSourceConfig::load(config));
    }
    reportConfig(config, "slamd-odometry-run", UnknownKeys::kInSectionsItRead);
    source->open();
  } catch (const ConfigError& e) {
    std::cerr << e.what() << "\n";
    return kExitConfigError;
  } catch (const SourceError& e) {
    std::cerr << e.what() << "\n";
    return kExitSourceError;
  }
  const long max_frames = std::stol(options.value("max-frames"));

  VisualOdometry vo(tracking);
  Trajectory estimate;
  std::vector<double> total_ms, features_ms, matching_ms, motion_ms;
  // Thread CPU time per frame: what the work costs on one core, unaffected by other processes
  // competing for the CPU (wall-clock times above include waiting for a core).
  std::vector<double> cpu_ms;
  int frames = 0, failures = 0, keyframes = 0, lost = 0, implausible = 0, prior_disagreements = 0;
  double inliers_sum = 0.0;
  while (max_frames <= 0 || frames < max_frames) {
    FrameRead read = source->next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status != FrameRead::Status::kFrame) continue;
    const double cpu_start_ms = threadCpuMs();
    const OdometryResult r = vo.processFrame(read.frame);
    cpu_ms.push_back(threadCpuMs() - cpu_start_ms);
    ++frames;
    total_ms.push_back(r.stats.time_total_ms);
    features_ms.push_back(r.stats.time_features_ms);
    matching_ms.push_back(r.stats.time_matching_ms);
    motion_ms.push_back(r.stats.time_motion_ms);
    if (r.status != OdometryStatus::kOk) ++failures;
    if (r.tracking_state == TrackingState::kLost) ++lost;
    if (r.is_keyframe) ++keyframes;
    implausible += r.stats.implausible_estimates;
    prior_disagreements += r.stats.prior_disagreements;
    inliers_sum += r.stats.num_inliers;
    estimate.push_back({utimeToSeconds(r.utime), r.T_world_camera});
  }
  source->close();

  eval::MetricsReport report("slamd-odometry-run");
  report.setText("frontend", frontEndName(tracking.frontend));
  report.setText("source", spec);
  report.set("frames", frames);
  report.set("failed_frames_count", failures);
  report.set("lost_frames_count", lost);
  report.set("keyframes_count", keyframes);
  // Keyframes per metre of the estimated path and per second of the sequence.
  double path_m = 0.0;
  for (std::size_t i = 1; i < estimate.size(); ++i) {
    path_m +=
        (estimate[i].T_world_camera.translation() - estimate[i - 1].T_world_camera.translation())
            .norm();
  }
  const double duration_s =
      estimate.size() > 1 ? estimate.back().timestamp_s - estimate.front().timestamp_s : 0.0;
  report.set("path_length_m", path_m);
  report.set("keyframes_per_m", path_m > 0.0 ? keyframes / path_m : 0.0);
  report.set("keyframes_per_s", duration_s > 0.0 ? keyframes / duration_s : 0.0);
  report.set("implausible_estimates_count", implausible);
  report.set("prior_disagreements_count", prior_disagreements);
  report.set("mean_inliers_count", frames ? inliers_sum / frames : 0.0);
  report.setLatencySamples("tracking", total_ms);
  report.setLatencySamples("tracking_cpu", cpu_ms);
  report.setLatencySamples("tracking_features", features_ms);
  report.setLatencySamples("tracking_matching", matching_ms);
  report.setLatencySamples("tracking_motion", motion_ms);
  std::cerr << "frontend " << frontEndName(tracking.frontend) << ": " << frames << " frames, "
            << failures << " failed, " << keyframes << " keyframes ("
            << keyframes / std::max(path_m, 1e-9) << " per m), " << implausible
            << " estimates vetoed as implausible; per frame median " << percentile(total_ms, 50)
            << " ms, p95 " << percentile(total_ms, 95) << " ms; thread CPU median "
            << percentile(cpu_ms, 50) << " ms, p95 " << percentile(cpu_ms, 95)
            << " ms (wall: features " << percentile(features_ms, 50) << ", matching "
            << percentile(matching_ms, 50) << ", motion " << percentile(motion_ms, 50) << ")\n";
  if (options.has("trajectory")) {
    try {
      writeTumTrajectory(
          options.value("trajectory"), estimate,
          std::string("slamd visual odometry, frontend ") + frontEndName(tracking.frontend));
    } catch (const std::exception& e) {
      std::cerr << e.what() << "\n";
      return kExitOutputError;
    }
  }
  if (const auto gt = source->groundTruth(); gt && !gt->empty() && estimate.size() > 2) {
    try {
      const eval::AteResult ate = eval::computeAte(*gt, estimate);
      const eval::RpeResult rpe = eval::computeRpe(*gt, estimate);
      report.setErrorStatistics("ate_m", ate.translation_m);
      report.setErrorStatistics("rpe_translation_m", rpe.translation_m);
      report.setErrorStatistics("rpe_rotation_deg", rpe.rotation_deg);
      // Per-frame motion error (RPE over one frame): the "exact mode" accuracy measure.
      eval::RpeOptions per_frame;
      per_frame.delta = 1.0;
      per_frame.delta_unit = eval::DeltaUnit::kFrames;
      const eval::RpeResult frame_rpe = eval::computeRpe(*gt, estimate, per_frame);
      report.setErrorStatistics("rpe_frame_translation_m", frame_rpe.translation_m);
      report.setErrorStatistics("rpe_frame_rotation_deg", frame_rpe.rotation_deg);
      std::cerr << "per-frame error: translation RMSE " << frame_rpe.translation_m.rmse
                << " m (max " << frame_rpe.translation_m.max << "), rotation RMSE "
                << frame_rpe.rotation_deg.rmse << " deg (max " << frame_rpe.rotation_deg.max
                << ")\n";
      std::cerr << "ATE RMSE " << ate.translation_m.rmse << " m, RPE(1 s) translation RMSE "
                << rpe.translation_m.rmse << " m, rotation RMSE " << rpe.rotation_deg.rmse
                << " deg\n";
    } catch (const std::exception& e) {
      std::cerr << "evaluation failed: " << e.what() << "\n";
    }
  }
  report.print(std::cout);
  return kExitOk;
}
