// slamd-backend-eval: visual odometry plus the back end (local edges, loop closing,
// relocalisation, pose graph) over a sequence; ATE/RPE with odometry only and with the back end,
// and the optimisation times for the graph sizes involved.
//
//   slamd-backend-eval --source synthetic:corridor_loop
//   slamd-backend-eval --source tum:../shared/data/tum_fr1_xyz --config config/tum_fr1.yaml
//       --trajectory slam.txt --odometry-trajectory vo.txt
//   slamd-backend-eval ... --blackout 300:40     # frames 300..339 blank: LOST, relocalisation
//                                                # (blank frames are left out of the ATE)
//
// Trajectories (TUM format, every frame): odometry as tracking made it; "slam": each frame is the
// final corrected pose of its reference keyframe composed with the frame's odometry pose relative
// to that keyframe; "online": each frame corrected with the T_world_odometry known when it was
// processed (what the daemon can publish live). The vocabulary is loaded from --vocabulary or
// backend.vocabulary_file, else trained on another synthetic scene (room by default), so the
// evaluated world never leaks into it. OpenCV runs on one thread. Prints a summary and, as the
// last line of stdout, one JSON metrics report (schema slamd.metrics/1).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <iostream>
#include <limits>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <opencv2/core.hpp>

#include "backend_eval_setup.hpp"
#include "slamd/backend/backend.hpp"
#include "slamd/backend/keyframe_trajectory.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/time.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/metrics_report.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/tracking/visual_odometry.hpp"

using namespace slamd;

namespace {

struct Errors {
  double ate_m = std::numeric_limits<double>::quiet_NaN();
  double rpe_m = std::numeric_limits<double>::quiet_NaN();
  double rpe_deg = std::numeric_limits<double>::quiet_NaN();
};

Errors evaluate(const Trajectory& truth, const Trajectory& estimate) {
  Errors e;
  if (truth.empty() || estimate.size() < 3) return e;
  e.ate_m = eval::computeAte(truth, estimate).translation_m.rmse;
  const eval::RpeResult rpe = eval::computeRpe(truth, estimate);
  e.rpe_m = rpe.translation_m.rmse;
  e.rpe_deg = rpe.rotation_deg.rmse;
  return e;
}

double percentileOf(std::vector<double> samples, double p) {
  if (samples.empty()) return 0.0;
  std::sort(samples.begin(), samples.end());
  const std::size_t index = static_cast<std::size_t>(p / 100.0 * (samples.size() - 1) + 0.5);
  return samples[std::min(index, samples.size() - 1)];
}

double mean(const std::vector<double>& samples) {
  double sum = 0.0;
  for (double v : samples) sum += v;
  return samples.empty() ? 0.0 : sum / static_cast<double>(samples.size());
}

// Each edge's measurement against the ground-truth relative pose of its keyframes (closest
// ground-truth stamps), summarised per edge kind, with the worst edges.
void reportEdges(const Trajectory& truth, const std::vector<KeyframePtr>& keyframes,
                 const Backend& backend) {
  std::vector<double> stamps;
  for (const StampedPose& p : truth) stamps.push_back(p.timestamp_s);
  std::unordered_map<std::int64_t, SE3> T_world_true;
  for (const KeyframePtr& kf : keyframes) {
    T_world_true[kf->id] =
        truth[eval::findClosestIndex(stamps, utimeToSeconds(kf->utime))].T_world_camera;
  }
  const char* names[] = {"odometry", "loop", "local", "relocalization"};
  std::vector<double> errors[4];
  // Error against the edge's true baseline (from 1 cm up: shorter ones say little).
  std::vector<double> error_per_baseline[4];
  std::vector<double> baselines_m[4];
  // Whitened (sqrt of e^T Omega e): against the truth and against the optimised poses.
  std::vector<double> whitened_truth[4];
  std::vector<double> whitened_optimised[4];
  std::vector<std::pair<double, std::size_t>> worst;
  // Calibration by baseline: does each part of the edge's claimed covariance (translation,
  // rotation) match its error against the truth, and is the translation biased along the
  // baseline (a scale error)? A 3-dof Gaussian's whitened error has median 1.54, p90 2.50.
  struct Calibration {
    std::vector<double> whitened_translation, whitened_rotation, rotation_error_deg;
    std::vector<double> along_per_baseline;  ///< signed error along the true baseline / baseline
    /// Sum of the rotation part of log(measured^-1 true) [rad], in the edge's end camera
    /// (x right, y down, z forward): its mean shows a bias where the cameras face the same way,
    /// as on a corridor walk.
    Eigen::Vector3d rotation_error_sum = Eigen::Vector3d::Zero();
  };
  constexpr int kNumBuckets = 4;
  constexpr double kBaselineBucketsM[kNumBuckets] = {0.0, 0.3, 0.6, 1.0};  // lower bounds
  Calibration calibration[4][kNumBuckets];
  const auto whitened = [](const PoseGraphEdge& edge, const SE3& T_world_from,
                           const SE3& T_world_to) {
    const Vector6d e = poseGraphEdgeError(edge.T_from_to, T_world_from, T_world_to);
    return std::sqrt(e.dot(edge.information * e));
  };
  const auto& edges = backend.graph().edges();
  for (std::size_t e = 0; e < edges.size(); ++e) {
    const PoseGraphEdge& edge = edges[e];
    if (edge.information(0, 0) < 1e-3) continue;  // segment ties
    const SE3 T_true = T_world_true.at(edge.from_id).inverse() * T_world_true.at(edge.to_id);
    const double error_m = (T_true.inverse() * edge.T_from_to).translation().norm();
    errors[static_cast<int>(edge.kind)].push_back(error_m);
    const double baseline_m = T_true.translation().norm();
    baselines_m[static_cast<int>(edge.kind)].push_back(baseline_m);
    if (baseline_m >= 0.01) {
      error_per_baseline[static_cast<int>(edge.kind)].push_back(error_m / baseline_m);
    }
    const Vector6d e_true = poseGraphEdgeError(edge.T_from_to, T_world_true.at(edge.from_id),
                                               T_world_true.at(edge.to_id));
    whitened_truth[static_cast<int>(edge.kind)].push_back(
        std::sqrt(e_true.dot(edge.information * e_true)));
    whitened_optimised[static_cast<int>(edge.kind)].push_back(
        whitened(edge, backend.pose(edge.from_id), backend.pose(edge.to_id)));
    worst.emplace_back(error_m, e);
    int bucket = 0;
    while (bucket + 1 < kNumBuckets && baseline_m >= kBaselineBucketsM[bucket + 1]) ++bucket;
    Calibration& c = calibration[static_cast<int>(edge.kind)][bucket];
    const Matrix6d covariance = edge.information.inverse();
    const Eigen::Vector3d e_translation = e_true.head<3>();
    const Eigen::Vector3d e_rotation = e_true.tail<3>();
    c.whitened_translation.push_back(
        std::sqrt(e_translation.dot(covariance.topLeftCorner<3, 3>().ldlt().solve(e_translation))));
    c.whitened_rotation.push_back(
        std::sqrt(e_rotation.dot(covariance.bottomRightCorner<3, 3>().ldlt().solve(e_rotation))));
    c.rotation_error_sum += e_rotation;
    c.rotation_error_deg.push_back(e_rotation.norm() * 180.0 / M_PI);  // the log's angle
    if (baseline_m >= 0.01) {
      c.along_per_baseline.push_back(
          (edge.T_from_to.translation() - T_true.translation()).dot(T_true.translation()) /
          (baseline_m * baseline_m));
    }
  }
  for (int k = 0; k < 4; ++k) {
    if (errors[k].empty()) continue;
    std::printf("  %s edges: %zu, error vs truth median %.4f m, p95 %.4f m, max %.4f m\n", names[k],
                errors[k].size(), percentileOf(errors[k], 50), percentileOf(errors[k], 95),
                percentileOf(errors[k], 100));
    std::printf(
        "    whitened error median / p95: against truth %.2f / %.2f, against the optimised "
        "poses %.2f / %.2f (a 6-dof Gaussian: 2.31 / 3.55)\n",
        percentileOf(whitened_truth[k], 50), percentileOf(whitened_truth[k], 95),
        percentileOf(whitened_optimised[k], 50), percentileOf(whitened_optimised[k], 95));
    std::printf(
        "    true baseline median %.4f m; error / baseline (baselines of 1 cm or more) median "
        "%.3f, p95 %.3f\n",
        percentileOf(baselines_m[k], 50), percentileOf(error_per_baseline[k], 50),
        percentileOf(error_per_baseline[k], 95));
  }
  std::printf(
      "  calibration by true baseline (whitened error against the truth, median / p90; a 3-dof "
      "Gaussian: 1.54 / 2.50):\n");
  for (int k = 0; k < 4; ++k) {
    for (int b = 0; b < kNumBuckets; ++b) {
      const Calibration& c = calibration[k][b];
      if (c.whitened_translation.empty()) continue;
      const Eigen::Vector3d mean_rotation_deg =
          c.rotation_error_sum * (180.0 / M_PI / static_cast<double>(c.rotation_error_deg.size()));
      char range[32];
      if (b + 1 < kNumBuckets) {
        std::snprintf(range, sizeof(range), "%.1f-%.1f m", kBaselineBucketsM[b],
                      kBaselineBucketsM[b + 1]);
      } else {
        std::snprintf(range, sizeof(range), "%.1f m and more", kBaselineBucketsM[b]);
      }
      std::printf(
          "    %s %s: %zu edges; translation %.2f / %.2f, rotation %.2f / %.2f; rotation error "
          "median %.4f deg, mean (%+.4f, %+.4f, %+.4f) deg; error along the baseline per metre "
          "median %+.5f\n",
          names[k], range, c.whitened_translation.size(), percentileOf(c.whitened_translation, 50),
          percentileOf(c.whitened_translation, 90), percentileOf(c.whitened_rotation, 50),
          percentileOf(c.whitened_rotation, 90), percentileOf(c.rotation_error_deg, 50),
          mean_rotation_deg.x(), mean_rotation_deg.y(), mean_rotation_deg.z(),
          c.along_per_baseline.empty() ? 0.0 : percentileOf(c.along_per_baseline, 50));
    }
  }
  std::sort(worst.rbegin(), worst.rend());
  for (std::size_t w = 0; w < std::min<std::size_t>(10, worst.size()); ++w) {
    const PoseGraphEdge& edge = edges[worst[w].second];
    const SE3 T_optimised = backend.pose(edge.from_id).inverse() * backend.pose(edge.to_id);
    const SE3 T_true = T_world_true.at(edge.from_id).inverse() * T_world_true.at(edge.to_id);
    std::printf(
        "  worst: %s %ld -> %ld, %.4f m, sigma_x %.4f m, |t| %.3f m, optimised vs edge %.4f m, "
        "optimised vs truth %.4f m\n",
        names[static_cast<int>(edge.kind)], static_cast<long>(edge.from_id),
        static_cast<long>(edge.to_id), worst[w].first, 1.0 / std::sqrt(edge.information(0, 0)),
        edge.T_from_to.translation().norm(),
        (T_optimised.inverse() * edge.T_from_to).translation().norm(),
        (T_true.inverse() * T_optimised).translation().norm());
  }
}

// A frame with no depth and a black image: tracking fails on it (for --blackout).
RgbdFramePtr blankFrame(const RgbdFrame& frame) {
  auto blank = std::make_shared<RgbdFrame>(frame);
  blank->depth_m =
      cv::Mat(frame.depth_m.size(), CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  if (!frame.gray.empty()) blank->gray = cv::Mat::zeros(frame.gray.size(), CV_8UC1);
  if (!frame.color_bgr.empty()) blank->color_bgr = cv::Mat::zeros(frame.color_bgr.size(), CV_8UC3);
  return blank;
}

void write(const std::string& path, const Trajectory& trajectory, const std::string& comment) {
  if (!path.empty()) writeTumTrajectory(path, trajectory, comment);
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options("slamd-backend-eval",
                         "Visual odometry + back end over a sequence: ATE/RPE before and after.");
  options.addOption("source", "SOURCE", "tum:DIR or synthetic:SCENE", "");
  options.addOption("scene", "SCENE", "synthetic scene (same as --source synthetic:SCENE)",
                    "corridor_loop");
  options.addOption("vocabulary-scene", "SCENE", "scene the vocabulary is trained on", "room");
  options.addOption("vocabulary", "FILE", "vocabulary file (overrides backend.vocabulary_file)");
  options.addOption("trajectory", "FILE", "write the full-SLAM per-frame trajectory (TUM)");
  options.addOption("odometry-trajectory", "FILE", "write the odometry trajectory (TUM)");
  options.addOption("online-trajectory", "FILE", "write the live-corrected trajectory (TUM)");
  options.addOption("blackout", "START:COUNT", "replace COUNT frames from START by blank ones");
  options.addOption("max-frames", "N", "stop after N frames (0 = all)", "0");
  options.addFlag("edge-report",
                  "per edge kind: measurement error against the ground truth (diagnostics)");
  options.addFlag("tracking-covariance",
                  "odometry edges weighted by tracking's covariance instead of the fixed ratio");
  if (!options.parse(argc, argv)) return options.exitCode();
  cv::setNumThreads(1);

  std::string spec = options.value("source");
  if (spec.empty()) spec = "synthetic:" + options.value("scene");
  BackendEvalSetup setup;
  if (const int exit_code = openBackendEvalSetup(options, spec, setup)) return exit_code;
  const BackendConfig& backend_config = setup.backend;
  const TrackingConfig& tracking = setup.tracking;
  const std::unique_ptr<FrameSource>& source = setup.source;
  const std::shared_ptr<const Vocabulary>& vocabulary = setup.vocabulary;
  long blackout_start = -1, blackout_count = 0;
  if (options.has("blackout")) {
    const std::string b = options.value("blackout");
    const auto colon = b.find(':');
    if (colon == std::string::npos) {
      std::cerr << "--blackout wants START:COUNT\n";
      return kExitUsage;
    }
    blackout_start = std::stol(b.substr(0, colon));
    blackout_count = std::stol(b.substr(colon + 1));
  }
  const long max_frames = std::stol(options.value("max-frames"));
  const bool tracking_covariance = options.has("tracking-covariance");

  std::printf("vocabulary: %d words, ready in %.1f s\n", vocabulary->numWords(),
              setup.vocabulary_ready_s);

  VisualOdometry vo(tracking);
  Backend backend(backend_config, vocabulary);
  std::vector<KeyframePtr> keyframes;
  KeyframeAnchoredTrajectory trajectory;
  Trajectory frames_online;
  std::vector<double> loop_ms, optimisation_ms, local_ms, iterations, backend_cpu_ms;
  int optimisations = 0, full_optimisations = 0, lost_frames = 0, relocalization_attempts = 0;
  int map_keyframe_reuses = 0;       // frames that took a map keyframe instead of making one
  int relocalization_keyframes = 0;  // keyframes made early for the back end to relocalise
  // Frames posed while their segment was not yet placed in the map: the online pose is then in
  // the segment's own frame, off by whatever the loss did.
  int frames_awaiting_relocalization = 0;
  bool relocalization_pending = false;
  SE3 T_world_odometry = SE3::Identity();
  long index = 0;
  while (max_frames <= 0 || index < max_frames) {
    const FrameRead read = source->next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status != FrameRead::Status::kFrame) continue;
    const bool blank = index >= blackout_start && index < blackout_start + blackout_count;
    const OdometryResult r = vo.processFrame(blank ? blankFrame(*read.frame) : read.frame);
    ++index;
    if (r.tracking_state == TrackingState::kLost) ++lost_frames;
    if (r.stats.used_map_keyframe) ++map_keyframe_reuses;
    if (r.stats.relocalization_keyframe) ++relocalization_keyframes;
    if (r.keyframe) {
      trajectory.addKeyframe(r.keyframe);
      const bool same_segment =
          !keyframes.empty() && keyframes.back()->segment == r.keyframe->segment;
      const bool measured_from_previous =
          same_segment && r.reference_keyframe_id == keyframes.back()->id;
      keyframes.push_back(r.keyframe);
      const auto start = std::chrono::steady_clock::now();
      const double cpu_start_ms = threadCpuMs();
      const BackendUpdate u = tracking_covariance && measured_from_previous
                                  ? backend.addKeyframe(r.keyframe, r.covariance_ref_curr)
                                  : backend.addKeyframe(r.keyframe);
      const double total_ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
              .count();
      backend_cpu_ms.push_back(threadCpuMs() - cpu_start_ms);
      T_world_odometry = u.T_world_odometry;
      relocalization_pending = u.relocalization_pending;
      vo.setMapKeyframes(backend.keyframesNear(r.keyframe->id));
      loop_ms.push_back(u.loop.time_ms);
      if (u.optimized) {
        ++optimisations;
        if (u.full_optimization) ++full_optimisations;
        optimisation_ms.push_back(u.optimization.time_ms);
        iterations.push_back(u.optimization.iterations);
      }
      local_ms.push_back(total_ms - u.loop.time_ms - (u.optimized ? u.optimization.time_ms : 0.0));
      if (u.loop.status == LoopStatus::kLoopFound) {
        std::printf("frame %ld: loop keyframe %ld -> %ld (score %.3f, %d inliers)\n", index - 1,
                    static_cast<long>(u.loop.query_id), static_cast<long>(u.loop.match_id),
                    u.loop.score, u.loop.num_inliers);
      }
      if (u.relocalization_attempted) {
        ++relocalization_attempts;
        std::printf(
            "frame %ld: keyframe %ld (segment %ld) relocalisation attempt %d: %s%s\n", index - 1,
            static_cast<long>(r.keyframe->id), static_cast<long>(r.keyframe->segment),
            u.relocalization_attempts, loopStatusName(u.relocalization.status),
            u.relocalized ? (" -> keyframe " + std::to_string(u.relocalization.match_id) + " (" +
                             std::to_string(u.relocalization.num_inliers) + " inliers)")
                                .c_str()
                          : "");
      }
    }
    // Blank frames carry no information; they are left out of the trajectories.
    if (!blank) {
      if (keyframes.empty()) continue;
      if (relocalization_pending) ++frames_awaiting_relocalization;
      trajectory.addFrame(r);
      frames_online.push_back({utimeToSeconds(r.utime), T_world_odometry * r.T_world_camera});
    }
  }
  source->close();

  // Full SLAM: each frame moves with its reference keyframe's final correction.
  const Trajectory frames_odometry = trajectory.odometry();
  const Trajectory frames_slam = trajectory.corrected(backend);
  Trajectory kf_odometry, kf_corrected;
  for (const KeyframePtr& kf : keyframes) {
    const double t_s = utimeToSeconds(kf->utime);
    kf_odometry.push_back({t_s, kf->T_world_camera});
    kf_corrected.push_back({t_s, backend.pose(kf->id)});
  }
  try {
    write(options.value("trajectory"), frames_slam, "slamd visual odometry + back end");
    write(options.value("odometry-trajectory"), frames_odometry, "slamd visual odometry");
    write(options.value("online-trajectory"), frames_online,
          "slamd visual odometry corrected live by the back end");
  } catch (const std::exception& e) {
    std::cerr << e.what() << "\n";
    return kExitOutputError;
  }

  eval::MetricsReport report("slamd-backend-eval");
  report.setText("source", spec);
  report.set("frames", static_cast<double>(index));
  report.set("keyframes_count", static_cast<double>(keyframes.size()));
  report.set("loops_count", backend.numLoops());
  report.set("local_edges_count", backend.numLocalEdges());
  report.set("relocalizations_count", backend.numRelocalizations());
  report.set("relocalization_attempts_count", relocalization_attempts);
  report.set("map_keyframe_reuses_count", map_keyframe_reuses);
  report.set("relocalization_keyframes_count", relocalization_keyframes);
  report.set("frames_awaiting_relocalization_count", frames_awaiting_relocalization);
  report.set("graph_nodes_count", static_cast<double>(backend.graph().numNodes()));
  report.set("graph_edges_count", static_cast<double>(backend.graph().numEdges()));
  report.setLatencySamples("optimization", optimisation_ms);
  report.setLatencySamples("loop_detection", loop_ms);
  report.setLatencySamples("local_edges", local_ms);
  std::printf(
      "%s: %ld frames (%d lost), %zu keyframes, %d segments joined by relocalisation "
      "(%d attempts), %d loops, %d local edges; graph %zu nodes, %zu edges; %d map keyframes "
      "re-used\n",
      spec.c_str(), index, lost_frames, keyframes.size(), backend.numRelocalizations(),
      relocalization_attempts, backend.numLoops(), backend.numLocalEdges(),
      backend.graph().numNodes(), backend.graph().numEdges(), map_keyframe_reuses);
  std::printf(
      "%d frames posed while their segment awaited relocalisation; %d keyframes made early for "
      "it\n",
      frames_awaiting_relocalization, relocalization_keyframes);
  report.set("optimization_iterations_mean", mean(iterations));
  report.setLatencySamples("backend_cpu", backend_cpu_ms);
  std::printf("back end per keyframe (thread CPU): %.1f ms mean, %.1f ms p95, %.1f ms max\n",
              mean(backend_cpu_ms), percentileOf(backend_cpu_ms, 95),
              percentileOf(backend_cpu_ms, 100));
  report.set("full_optimizations_count", full_optimisations);
  std::printf(
      "per keyframe: %d optimisations (%d of the whole graph; %.1f iterations mean), "
      "%.2f ms mean, %.2f ms p95, %.2f ms max; loop detection %.2f ms mean; local "
      "matching %.2f ms mean\n",
      optimisations, full_optimisations, mean(iterations), mean(optimisation_ms),
      percentileOf(optimisation_ms, 95), percentileOf(optimisation_ms, 100), mean(loop_ms),
      mean(local_ms));
  if (const auto gt = source->groundTruth(); gt && !gt->empty()) {
    try {
      const Errors odometry = evaluate(*gt, frames_odometry);
      const Errors slam = evaluate(*gt, frames_slam);
      const Errors online = evaluate(*gt, frames_online);
      const Errors kf_before = evaluate(*gt, kf_odometry);
      const Errors kf_after = evaluate(*gt, kf_corrected);
      report.set("odometry_ate_m", odometry.ate_m);
      report.set("slam_ate_m", slam.ate_m);
      report.set("online_ate_m", online.ate_m);
      report.set("odometry_rpe_translation_m", odometry.rpe_m);
      report.set("slam_rpe_translation_m", slam.rpe_m);
      report.set("odometry_rpe_rotation_deg", odometry.rpe_deg);
      report.set("slam_rpe_rotation_deg", slam.rpe_deg);
      std::printf("frame ATE RMSE: odometry %.4f m, full SLAM %.4f m (%.1fx), online %.4f m\n",
                  odometry.ate_m, slam.ate_m, odometry.ate_m / std::max(slam.ate_m, 1e-12),
                  online.ate_m);
      std::printf("frame RPE(1 s) RMSE: odometry %.4f m / %.3f deg, full SLAM %.4f m / %.3f deg\n",
                  odometry.rpe_m, odometry.rpe_deg, slam.rpe_m, slam.rpe_deg);
      if (options.has("edge-report")) reportEdges(*gt, keyframes, backend);
      std::printf("keyframe ATE RMSE: odometry %.4f m, after the back end %.4f m (%.1fx)\n",
                  kf_before.ate_m, kf_after.ate_m,
                  kf_before.ate_m / std::max(kf_after.ate_m, 1e-12));
    } catch (const std::exception& e) {
      std::cerr << "evaluation failed: " << e.what() << "\n";
    }
  }
  std::fflush(stdout);
  report.print(std::cout);
  return kExitOk;
}
