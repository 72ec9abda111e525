// slamd-backend-eval: visual odometry plus the back end (loop closing, pose graph) over a
// synthetic world; ATE of the keyframe trajectory with odometry only and after loop closing, and
// the optimisation times for the graph sizes involved.
//
//   slamd-backend-eval --scene corridor_loop [--set backend.robust_kernel=huber]
//
// The vocabulary is trained at start-up on keyframes of another scene (room by default), so the
// evaluated world never leaks into it. OpenCV runs on one thread. Prints a summary on stdout.

#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "slamd/backend/backend.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/visual_odometry.hpp"

using namespace slamd;

namespace {

Vocabulary trainVocabulary(const std::string& scene, const BackendConfig& backend) {
  Config config = Config::fromFile(SLAMD_SOURCE_DIR "/config/synthetic.yaml");
  SyntheticSource source(scene, SyntheticConfig::load(config));
  TrackingConfig tracking;
  auto extractor = makeFeatureExtractor(tracking);
  std::vector<cv::Mat> descriptors;
  const int step = std::max(1, source.frameCount() / 20);
  for (int index = 0; index < source.frameCount(); index += step) {
    const RgbdFramePtr frame = source.renderFrame(index);
    cv::Mat gray = frame->gray;
    if (gray.empty()) cv::cvtColor(frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
    FeatureSet features;
    extractor->extract(gray, features);
    descriptors.push_back(features.descriptors);
  }
  return Vocabulary::train(descriptors, backend.vocabulary_branching, backend.vocabulary_depth,
                           42);
}

double ateRmse(const Trajectory& truth, const Trajectory& estimate) {
  return eval::computeAte(truth, estimate).translation_m.rmse;
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options("slamd-backend-eval",
                         "Visual odometry + loop closing on a synthetic world: ATE before/after.");
  options.addOption("scene", "SCENE", "synthetic scene (corridor_loop, corridor, room)",
                    "corridor_loop");
  options.addOption("vocabulary-scene", "SCENE", "scene the vocabulary is trained on", "room");
  if (!options.parse(argc, argv)) return options.exitCode();
  cv::setNumThreads(1);

  Config config = options.loadConfig(SLAMD_SOURCE_DIR "/config/synthetic.yaml");
  BackendConfig backend_config = BackendConfig::load(config);
  const TrackingConfig tracking = TrackingConfig::load(config);
  SyntheticSource source(options.value("scene"), SyntheticConfig::load(config));
  const Trajectory truth = *source.groundTruth();

  const auto t0 = std::chrono::steady_clock::now();
  auto vocabulary = std::make_shared<const Vocabulary>(
      trainVocabulary(options.value("vocabulary-scene"), backend_config));
  std::printf("vocabulary: %d words, trained in %.1f s\n", vocabulary->numWords(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());

  VisualOdometry vo(tracking);
  Backend backend(backend_config, vocabulary);
  std::vector<KeyframePtr> keyframes;
  // Every frame's odometry pose and the keyframe it follows (for the corrected trajectory).
  Trajectory frames_odometry;
  std::vector<std::size_t> frame_keyframe;
  double loop_detection_ms_sum = 0.0;
  double loop_detection_ms_max = 0.0;
  source.open();
  for (int index = 0; index < source.frameCount(); ++index) {
    const FrameRead read = source.next(std::chrono::milliseconds(1000));
    if (read.status != FrameRead::Status::kFrame) continue;
    const OdometryResult r = vo.processFrame(read.frame);
    if (r.keyframe) keyframes.push_back(r.keyframe);
    if (!keyframes.empty()) {
      frames_odometry.push_back({static_cast<double>(r.utime) * 1e-6, r.T_world_camera});
      frame_keyframe.push_back(keyframes.size() - 1);
    }
    if (!r.keyframe) continue;
    const BackendUpdate u = backend.addKeyframe(r.keyframe);
    loop_detection_ms_sum += u.loop.time_ms;
    loop_detection_ms_max = std::max(loop_detection_ms_max, u.loop.time_ms);
    if (u.loop.status == LoopStatus::kLoopFound) {
      std::printf("frame %d: loop keyframe %ld -> %ld (score %.3f, %d inliers)\n", index,
                  static_cast<long>(u.loop.query_id), static_cast<long>(u.loop.match_id),
                  u.loop.score, u.loop.num_inliers);
    }
    if (u.optimized) {
      std::printf("  pose graph: %d nodes, %d edges, %s, %d iterations, cost %.1f -> %.1f, "
                  "%.2f ms\n",
                  u.optimization.num_nodes, u.optimization.num_edges,
                  optimizationStatusName(u.optimization.status), u.optimization.iterations,
                  u.optimization.initial_cost, u.optimization.final_cost,
                  u.optimization.time_ms);
    }
  }

  Trajectory odometry, corrected, truth_at_keyframes;
  for (const KeyframePtr& kf : keyframes) {
    const double t_s = static_cast<double>(kf->utime) * 1e-6;
    odometry.push_back({t_s, kf->T_world_camera});
    corrected.push_back({t_s, backend.pose(kf->id)});
  }
  const double ate_odometry = ateRmse(truth, odometry);
  const double ate_corrected = ateRmse(truth, corrected);
  std::printf("%s: %d frames, %zu keyframes, %d loops; loop detection %.1f ms mean, %.1f ms "
              "max per keyframe\n",
              options.value("scene").c_str(), source.frameCount(), keyframes.size(),
              backend.numLoops(), loop_detection_ms_sum / std::max<std::size_t>(1, keyframes.size()),
              loop_detection_ms_max);
  // Offline corrected trajectory: each frame moves with the keyframe it follows.
  Trajectory frames_corrected;
  for (std::size_t f = 0; f < frames_odometry.size(); ++f) {
    const KeyframePtr& kf = keyframes[frame_keyframe[f]];
    frames_corrected.push_back({frames_odometry[f].timestamp_s,
                                backend.pose(kf->id) * kf->T_world_camera.inverse() *
                                    frames_odometry[f].T_world_camera});
  }
  std::printf("frame ATE RMSE: odometry %.4f m, corrected through the keyframes %.4f m (%.1fx)\n",
              ateRmse(truth, frames_odometry), ateRmse(truth, frames_corrected),
              ateRmse(truth, frames_odometry) /
                  std::max(ateRmse(truth, frames_corrected), 1e-12));
  std::printf("keyframe ATE RMSE: odometry %.4f m, after loop closing %.4f m (%.1fx)\n",
              ate_odometry, ate_corrected, ate_odometry / std::max(ate_corrected, 1e-12));
  return 0;
}
