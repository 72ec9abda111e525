// slamd-place-eval: how well the back end's vocabulary ranks the places a keyframe really sees.
//
// Every N-th frame of a sequence with ground truth becomes a keyframe: ORB features with depth
// (tracking's extractor) and a BoW vector (the vocabulary under test). For each pair, the true
// overlap is the share of the query's features with depth that the other keyframe's camera sees
// at its ground-truth pose (in front, inside the image, at a distance within the 1.44x that the
// ORB pyramid's three default levels span). Each keyframe then queries the others, those within
// --exclude-s of it in time left out, as loop detection and relocalisation do, and the report says
// where the BoW ranking puts the keyframes that really see its place:
//   - precision at 1 and at 5: the share of the best 1 / 5 scores whose true overlap reaches
//     --min-overlap;
//   - the rank of the keyframe with the largest true overlap (1 = first), median and mean;
//   - the mean score of keyframes that see the place and of those that do not.
// Only queries with at least one keyframe at --min-overlap count. Diagnostics: no test runs it.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "backend_eval_setup.hpp"
#include "slamd/backend/backend.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/time.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/eval/metrics_report.hpp"
#include "slamd/eval/trajectory_error.hpp"
#include "slamd/tracking/features.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace slamd {
namespace {

struct PlaceKeyframe {
  double time_s = 0.0;
  SE3 T_world_camera = SE3::Identity();  ///< ground truth
  FeatureSet features;
  CameraIntrinsics intrinsics;
  BowVector bow;
};

/// Share of `from`'s features with depth that `to`'s camera sees at the true poses.
double trueOverlap(const PlaceKeyframe& from, const PlaceKeyframe& to) {
  // ORB's pyramid spans 1.2^2 = 1.44 in scale at the default three levels: a point seen more
  // than that much nearer or farther is not matched however well the images overlap.
  constexpr double kMaxDepthRatio = 1.44;
  constexpr double kBorderPx = 8.0;
  const SE3 T_to_from = to.T_world_camera.inverse() * from.T_world_camera;
  const CameraIntrinsics& K = to.intrinsics;
  int with_depth = 0, seen = 0;
  for (std::size_t i = 0; i < from.features.points.size(); ++i) {
    if (!from.features.hasDepth(i)) continue;
    ++with_depth;
    const Eigen::Vector3d& X = from.features.points[i];
    const Eigen::Vector3d Y = T_to_from * X;
    if (!(Y.z() > 0.0) || Y.z() > kMaxDepthRatio * X.z() || X.z() > kMaxDepthRatio * Y.z()) {
      continue;
    }
    const Eigen::Vector2d pixel = K.project(Y);
    if (K.contains(pixel.x(), pixel.y(), kBorderPx)) ++seen;
  }
  return with_depth > 0 ? static_cast<double>(seen) / with_depth : 0.0;
}

double mean(const std::vector<double>& values) { return eval::computeStatistics(values).mean; }

}  // namespace
}  // namespace slamd

int main(int argc, char** argv) {
  using namespace slamd;
  ProgramOptions options("slamd-place-eval",
                         "Ranks of the truly overlapping keyframes in BoW retrieval (needs ground "
                         "truth): how well a vocabulary recognises places.");
  options.addOption("source", "SOURCE", "tum:DIR or synthetic:SCENE", "");
  options.addOption("vocabulary", "FILE", "vocabulary file (default: backend.vocabulary_file)");
  options.addOption("vocabulary-scene", "SCENE",
                    "without a file: train on this synthetic scene as the build does", "room");
  options.addOption("every", "N", "every N-th frame is a keyframe", "10");
  options.addOption("exclude-s", "SECONDS", "keyframes this close in time are not candidates",
                    "1.0");
  options.addOption("min-overlap", "FRACTION", "true overlap that makes a candidate correct",
                    "0.5");
  options.addOption("max-frames", "N", "stop after N frames (0 = all)", "0");
  if (!options.parse(argc, argv)) return options.exitCode();
  cv::setNumThreads(1);

  const std::string spec = options.value("source");
  if (spec.empty()) {
    std::cerr << "--source is required\n";
    return kExitUsage;
  }
  long every = 1, max_frames = 0;
  double exclude_s = 0.0, min_overlap = 0.0;
  try {
    every = std::max(1L, std::stol(options.value("every")));
    max_frames = std::stol(options.value("max-frames"));
    exclude_s = std::stod(options.value("exclude-s"));
    min_overlap = std::stod(options.value("min-overlap"));
  } catch (const std::logic_error&) {  // std::invalid_argument, std::out_of_range
    std::cerr << "--every, --max-frames, --exclude-s and --min-overlap take numbers\n";
    return kExitUsage;
  }
  BackendEvalSetup setup;
  if (const int exit_code = openBackendEvalSetup(options, spec, setup)) return exit_code;
  const TrackingConfig& tracking = setup.tracking;
  const std::unique_ptr<FrameSource>& source = setup.source;
  const std::shared_ptr<const Vocabulary>& vocabulary = setup.vocabulary;
  const auto truth = source->groundTruth();
  if (!truth || truth->empty()) {
    std::cerr << spec << " has no ground truth\n";
    return kExitSourceError;
  }
  std::vector<double> truth_stamps;
  for (const StampedPose& p : *truth) truth_stamps.push_back(p.timestamp_s);

  // Keyframes: features, BoW and true pose.
  const std::unique_ptr<FeatureExtractor> extractor = makeFeatureExtractor(tracking);
  std::vector<PlaceKeyframe> keyframes;
  for (long index = 0; max_frames <= 0 || index < max_frames;) {
    const FrameRead read = source->next(std::chrono::milliseconds(1000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status != FrameRead::Status::kFrame) continue;
    if (index++ % every != 0) continue;
    const RgbdFrame& frame = *read.frame;
    PlaceKeyframe kf;
    kf.time_s = utimeToSeconds(frame.utime);
    const std::size_t closest = eval::findClosestIndex(truth_stamps, kf.time_s);
    if (std::abs(truth_stamps[closest] - kf.time_s) > 0.02) continue;
    kf.T_world_camera = (*truth)[closest].T_world_camera;
    cv::Mat gray = frame.gray;
    if (gray.empty()) cv::cvtColor(frame.color_bgr, gray, cv::COLOR_BGR2GRAY);
    extractor->extract(gray, kf.features);
    attachGeometry(frame.depth_m, frame.intrinsics, tracking, kf.features);
    kf.intrinsics = frame.intrinsics;
    kf.bow = vocabulary->transform(kf.features.descriptors);
    keyframes.push_back(std::move(kf));
  }

  // Each keyframe queries the others.
  std::vector<double> precision_at_1, precision_at_5, best_rank, score_seen, score_unseen;
  for (std::size_t q = 0; q < keyframes.size(); ++q) {
    struct Candidate {
      double score, overlap;
    };
    std::vector<Candidate> candidates;
    for (std::size_t c = 0; c < keyframes.size(); ++c) {
      if (c == q || std::abs(keyframes[c].time_s - keyframes[q].time_s) <= exclude_s) continue;
      candidates.push_back(
          {bowScore(keyframes[q].bow, keyframes[c].bow), trueOverlap(keyframes[q], keyframes[c])});
    }
    const auto best_true = std::max_element(
        candidates.begin(), candidates.end(),
        [](const Candidate& a, const Candidate& b) { return a.overlap < b.overlap; });
    if (best_true == candidates.end() || best_true->overlap < min_overlap) continue;
    const double best_overlap = best_true->overlap;
    std::stable_sort(candidates.begin(), candidates.end(),
                     [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
    int correct_in_5 = 0;
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      const bool correct = candidates[k].overlap >= min_overlap;
      if (k < 5 && correct) ++correct_in_5;
      (correct ? score_seen : score_unseen).push_back(candidates[k].score);
    }
    precision_at_1.push_back(candidates.front().overlap >= min_overlap ? 1.0 : 0.0);
    precision_at_5.push_back(correct_in_5 /
                             static_cast<double>(std::min<std::size_t>(5, candidates.size())));
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      if (candidates[k].overlap == best_overlap) {
        best_rank.push_back(static_cast<double>(k + 1));
        break;
      }
    }
  }
  std::printf(
      "%s: %zu keyframes (every %ld frames), vocabulary of %d words; %zu queries with a keyframe "
      "at %.0f%% true overlap or more (others %.1f s or more apart)\n",
      spec.c_str(), keyframes.size(), every, vocabulary->numWords(), precision_at_1.size(),
      100.0 * min_overlap, exclude_s);
  std::printf(
      "precision at 1 %.3f, at 5 %.3f; rank of the most overlapping keyframe median %.1f, mean "
      "%.1f; mean score of keyframes that see the place %.4f, of those that do not %.4f\n",
      mean(precision_at_1), mean(precision_at_5), eval::computeStatistics(best_rank).median,
      mean(best_rank), mean(score_seen), mean(score_unseen));
  eval::MetricsReport report("slamd-place-eval");
  report.setText("source", spec);
  report.set("keyframes_count", static_cast<double>(keyframes.size()));
  report.set("queries_count", static_cast<double>(precision_at_1.size()));
  report.set("vocabulary_words_count", vocabulary->numWords());
  report.set("precision_at_1", mean(precision_at_1));
  report.set("precision_at_5", mean(precision_at_5));
  report.set("best_rank_median", eval::computeStatistics(best_rank).median);
  report.set("best_rank_mean", mean(best_rank));
  report.set("score_seen_mean", mean(score_seen));
  report.set("score_unseen_mean", mean(score_unseen));
  report.print(std::cout);
  return 0;
}
