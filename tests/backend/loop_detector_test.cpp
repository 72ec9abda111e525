// Place recognition on slamd's synthetic worlds: keyframes are rendered along the ground-truth
// trajectory (every kKeyframeStep frames) with ORB features; the vocabulary is trained on a
// different scene (the room) so that nothing about the corridors leaks into it.

#include "slamd/backend/loop_detector.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "slamd/backend/backend.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace slamd {
namespace {

constexpr int kKeyframeStep = 12;  // frames between keyframes (0.32 m at 0.8 m/s, 30 Hz)

struct RenderedKeyframes {
  std::vector<KeyframePtr> keyframes;
  std::vector<SE3, Eigen::aligned_allocator<SE3>> truth;  ///< T_world_camera per keyframe
};

// A true keyframe step as odometry measures it: 2% translation noise and 0.3 degree rotation
// noise (drift).
SE3 noisyStep(const SE3& step_true, std::mt19937& rng, std::normal_distribution<double>& noise) {
  Vector6d xi;
  const double step_m = step_true.translation().norm();
  for (int k = 0; k < 3; ++k) xi(k) = 0.02 * step_m * noise(rng);
  for (int k = 3; k < 6; ++k) xi(k) = 0.3 * M_PI / 180.0 * noise(rng);
  return step_true * expSE3(xi);
}

RenderedKeyframes renderKeyframes(const std::string& scene, int step, int max_keyframes) {
  cv::setNumThreads(1);
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/synthetic.yaml");
  SyntheticSource source(scene, SyntheticConfig::load(config));
  const Trajectory truth = *source.groundTruth();
  TrackingConfig tracking;
  auto extractor = makeFeatureExtractor(tracking);
  // Keyframe poses as odometry would give them: the true steps with 2% translation noise and
  // 0.3 degree rotation noise per keyframe (drift), seeded.
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 1.0);
  SE3 T_world_odometry = SE3::Identity();
  SE3 T_world_prev_true = SE3::Identity();
  RenderedKeyframes out;
  for (int index = 0;
       index < source.frameCount() && static_cast<int>(out.keyframes.size()) < max_keyframes;
       index += step) {
    const RgbdFramePtr frame = source.renderFrame(index);
    auto keyframe = std::make_shared<Keyframe>();
    keyframe->id = static_cast<std::int64_t>(out.keyframes.size());
    keyframe->intrinsics = frame->intrinsics;
    const SE3 T_world_true = truth[static_cast<std::size_t>(index)].T_world_camera;
    if (out.keyframes.empty()) {
      T_world_odometry = T_world_true;
    } else {
      T_world_odometry =
          T_world_odometry * noisyStep(T_world_prev_true.inverse() * T_world_true, rng, noise);
    }
    T_world_prev_true = T_world_true;
    keyframe->T_world_camera = T_world_odometry;
    cv::Mat gray = frame->gray;
    if (gray.empty()) cv::cvtColor(frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
    extractor->extract(gray, keyframe->features);
    attachGeometry(frame->depth_m, frame->intrinsics, tracking, keyframe->features);
    out.keyframes.push_back(keyframe);
    out.truth.push_back(T_world_true);
  }
  return out;
}

std::shared_ptr<const Vocabulary> roomVocabulary() {
  static const std::shared_ptr<const Vocabulary> vocabulary = [] {
    const RenderedKeyframes room = renderKeyframes("room", 45, 20);
    std::vector<cv::Mat> descriptors;
    for (const KeyframePtr& kf : room.keyframes) descriptors.push_back(kf->features.descriptors);
    const BackendConfig config;
    return std::make_shared<const Vocabulary>(
        Vocabulary::train(descriptors, config.vocabulary_branching, config.vocabulary_depth, 42));
  }();
  return vocabulary;
}

// The ring corridor's keyframes, rendered once for the tests that need them (the tests of this
// executable run in one process: ONE_PROCESS in CMakeLists.txt).
const RenderedKeyframes& ringKeyframes() {
  static const RenderedKeyframes world = renderKeyframes("corridor_loop", kKeyframeStep, 1000);
  return world;
}

// A lap of the room, a keyframe every 5 frames, rendered once as well.
const RenderedKeyframes& roomLapKeyframes() {
  static const RenderedKeyframes lap = renderKeyframes("room", 5, 40);
  return lap;
}

struct DetectionRun {
  std::vector<LoopDetection> loops;
  int keyframes = 0;
  int odometry_rejected = 0;
  double max_time_ms = 0.0;
  double total_time_ms = 0.0;
};

DetectionRun detectLoops(const RenderedKeyframes& world) {
  LoopDetector detector(BackendConfig(), roomVocabulary());
  DetectionRun run;
  for (const KeyframePtr& kf : world.keyframes) {
    const LoopDetection d = detector.processKeyframe(kf);
    ++run.keyframes;
    run.max_time_ms = std::max(run.max_time_ms, d.time_ms);
    run.total_time_ms += d.time_ms;
    if (d.status == LoopStatus::kLoopFound) run.loops.push_back(d);
    if (d.status == LoopStatus::kOdometryRejected) ++run.odometry_rejected;
  }
  return run;
}

TEST(Vocabulary, TrainsWordsAndScoresIdenticalImagesAsOne) {
  const auto vocabulary = roomVocabulary();
  ASSERT_FALSE(vocabulary->empty());
  EXPECT_GT(vocabulary->numWords(), 100);
  EXPECT_LE(vocabulary->numWords(), 512);
  const RenderedKeyframes room = renderKeyframes("room", 200, 3);
  const BowVector a = vocabulary->transform(room.keyframes[0]->features.descriptors);
  const BowVector b = vocabulary->transform(room.keyframes[2]->features.descriptors);
  EXPECT_NEAR(bowScore(a, a), 1.0, 1e-12);
  EXPECT_LT(bowScore(a, b), 0.5);
  // Serialisation round trip gives the same words.
  std::stringstream buffer;
  vocabulary->write(buffer);
  Vocabulary copy;
  ASSERT_TRUE(copy.read(buffer));
  const BowVector c = copy.transform(room.keyframes[0]->features.descriptors);
  EXPECT_NEAR(bowScore(a, c), 1.0, 1e-12);
  std::stringstream garbage("not a vocabulary");
  EXPECT_FALSE(copy.read(garbage));
}

TEST(LoopDetector, FindsTheRevisitOnTheRingCorridor) {
  const RenderedKeyframes& world = ringKeyframes();
  const DetectionRun run = detectLoops(world);
  std::printf("corridor_loop: %d keyframes, %zu loops, detection %.1f ms mean, %.1f ms max\n",
              run.keyframes, run.loops.size(), run.total_time_ms / run.keyframes, run.max_time_ms);
  ASSERT_FALSE(run.loops.empty());
  const int n = run.keyframes;
  bool revisit = false;
  for (const LoopDetection& d : run.loops) {
    const SE3 T_true = world.truth[static_cast<std::size_t>(d.match_id)].inverse() *
                       world.truth[static_cast<std::size_t>(d.query_id)];
    const SE3 error = T_true.inverse() * d.T_match_query;
    std::printf(
        "  loop %ld -> %ld: score %.3f, %d/%d inliers, consistency %d, error %.3f m "
        "%.2f deg\n",
        static_cast<long>(d.query_id), static_cast<long>(d.match_id), d.score, d.num_inliers,
        d.num_matches, d.consistency, error.translation().norm(),
        rotationAngleRad(error.linear()) * 180.0 / M_PI);
    // Every accepted loop is a true one: the measured relative pose matches the ground truth.
    EXPECT_LT(error.translation().norm(), 0.05);
    EXPECT_LT(rotationAngleRad(error.linear()) * 180.0 / M_PI, 1.0);
    if (d.query_id >= n * 85 / 100 && d.match_id <= n * 15 / 100) revisit = true;
  }
  EXPECT_TRUE(revisit) << "no loop from the end of the lap back to its start";
}

TEST(LoopDetector, FindsNoLoopOnTheStraightCorridor) {
  const RenderedKeyframes world = renderKeyframes("corridor", kKeyframeStep, 1000);
  const DetectionRun run = detectLoops(world);
  std::printf("corridor: %d keyframes, %zu loops, %d verified places rejected by odometry\n",
              run.keyframes, run.loops.size(), run.odometry_rejected);
  EXPECT_GT(run.keyframes, 50);
  EXPECT_TRUE(run.loops.empty());
}

// Relocalisation: a frame half-way between two keyframes is matched against the database.
// (Part of the Backend test to render the ring once per test process.)
void expectRelocalisation(const RenderedKeyframes& world, LoopDetector& detector) {
  // A frame half-way between keyframes 40 and 41, as after tracking loss.
  const int frame_index = 40 * kKeyframeStep + kKeyframeStep / 2;
  Config config = Config::fromFile(std::string(SLAMD_SOURCE_DIR) + "/config/synthetic.yaml");
  SyntheticSource source("corridor_loop", SyntheticConfig::load(config));
  const RgbdFramePtr frame = source.renderFrame(frame_index);
  TrackingConfig tracking;
  FeatureSet features;
  cv::Mat gray = frame->gray;
  if (gray.empty()) cv::cvtColor(frame->color_bgr, gray, cv::COLOR_BGR2GRAY);
  makeFeatureExtractor(tracking)->extract(gray, features);
  attachGeometry(frame->depth_m, frame->intrinsics, tracking, features);
  const LoopDetection d = detector.query(features, frame->intrinsics);
  ASSERT_EQ(d.status, LoopStatus::kLoopFound) << loopStatusName(d.status);
  EXPECT_LE(std::abs(d.match_id - 40), 2);
  const SE3 T_true = world.truth[static_cast<std::size_t>(d.match_id)].inverse() *
                     source.groundTruth()->at(static_cast<std::size_t>(frame_index)).T_world_camera;
  const SE3 error = T_true.inverse() * d.T_match_query;
  std::printf("relocalised against keyframe %ld: %d inliers, error %.3f m %.2f deg, %.1f ms\n",
              static_cast<long>(d.match_id), d.num_inliers, error.translation().norm(),
              rotationAngleRad(error.linear()) * 180.0 / M_PI, d.time_ms);
  EXPECT_LT(error.translation().norm(), 0.05);
  EXPECT_LT(rotationAngleRad(error.linear()) * 180.0 / M_PI, 1.0);
}

TEST(Backend, ClosingTheRingLoopPullsTheDriftedKeyframesBackAndRelocalises) {
  const RenderedKeyframes& world = ringKeyframes();
  Backend backend(BackendConfig(), roomVocabulary());
  int optimisations = 0;
  for (const KeyframePtr& kf : world.keyframes) {
    const BackendUpdate u = backend.addKeyframe(kf);
    if (u.optimized) {
      ++optimisations;
      EXPECT_EQ(u.corrected_poses.size(), backend.graph().numNodes());
      EXPECT_NE(u.optimization.status, OptimizationStatus::kSolverFailure);
      std::printf("optimised %d nodes, %d edges: %d iterations, %.2f ms\n",
                  u.optimization.num_nodes, u.optimization.num_edges, u.optimization.iterations,
                  u.optimization.time_ms);
    }
  }
  double before = 0.0;
  double after = 0.0;
  double end_before = 0.0;
  double end_after = 0.0;
  for (std::size_t k = 0; k < world.keyframes.size(); ++k) {
    const Eigen::Vector3d p_true = world.truth[k].translation();
    const double e_before = (world.keyframes[k]->T_world_camera.translation() - p_true).norm();
    const double e_after = (backend.pose(world.keyframes[k]->id).translation() - p_true).norm();
    before += e_before * e_before;
    after += e_after * e_after;
    end_before = e_before;
    end_after = e_after;
  }
  before = std::sqrt(before / static_cast<double>(world.keyframes.size()));
  after = std::sqrt(after / static_cast<double>(world.keyframes.size()));
  std::printf(
      "ring keyframes: RMS position error %.3f m -> %.3f m, last keyframe %.3f m -> "
      "%.3f m\n",
      before, after, end_before, end_after);
  EXPECT_GE(backend.numLoops(), 1);
  EXPECT_GT(backend.numLocalEdges(), 0);
  // Every keyframe that brought an edge (local or loop) was followed by an optimisation.
  EXPECT_GE(optimisations, backend.numLoops());
  EXPECT_LT(end_after, 0.1);
  EXPECT_LT(after, before / 2.0);
  expectRelocalisation(world, backend.loopDetector());
}

// The daemon's way: the whole-graph optimisation a far loop asks for is handed out as a job
// and merged later (here three keyframes later, run on this thread). The ring ends as well
// placed as when the whole graph is optimised in place.
TEST(Backend, AWholeGraphOptimisationMergedLaterPlacesTheRingAsWellAsOneInPlace) {
  const RenderedKeyframes& world = ringKeyframes();
  Backend in_place(BackendConfig(), roomVocabulary());
  Backend deferred(BackendConfig(), roomVocabulary());
  deferred.setFullOptimizationDeferred(true);
  std::optional<FullOptimizationJob> job;
  int keyframes_since_job = 0;
  int jobs = 0;
  int whole_in_place = 0;
  for (const KeyframePtr& kf : world.keyframes) {
    if (in_place.addKeyframe(kf).full_optimization) ++whole_in_place;
    const BackendUpdate u = deferred.addKeyframe(kf);
    EXPECT_FALSE(u.full_optimization) << "keyframe " << kf->id;
    if (job && ++keyframes_since_job == 3) {
      job->run();
      const BackendUpdate merged = deferred.finishFullOptimization(*job);
      EXPECT_TRUE(merged.optimized);
      EXPECT_TRUE(merged.full_optimization);
      EXPECT_EQ(merged.corrected_poses.size(), deferred.graph().numNodes());
      job.reset();
    }
    if (!job && (job = deferred.takeFullOptimizationJob())) {
      ++jobs;
      keyframes_since_job = 0;
      EXPECT_FALSE(deferred.takeFullOptimizationJob().has_value()) << "one job at a time";
    }
  }
  // At the end (BackendStage::finish): the job out, then one asked for while it was out.
  if (job) {
    job->run();
    deferred.finishFullOptimization(*job);
  }
  if ((job = deferred.takeFullOptimizationJob())) {
    ++jobs;
    job->run();
    deferred.finishFullOptimization(*job);
  }
  EXPECT_FALSE(deferred.fullOptimizationPending());
  double rms_in_place = 0.0;
  double rms_deferred = 0.0;
  for (std::size_t k = 0; k < world.keyframes.size(); ++k) {
    const Eigen::Vector3d p_true = world.truth[k].translation();
    const std::int64_t id = world.keyframes[k]->id;
    rms_in_place += (in_place.pose(id).translation() - p_true).squaredNorm();
    rms_deferred += (deferred.pose(id).translation() - p_true).squaredNorm();
  }
  rms_in_place = std::sqrt(rms_in_place / static_cast<double>(world.keyframes.size()));
  rms_deferred = std::sqrt(rms_deferred / static_cast<double>(world.keyframes.size()));
  std::printf("ring: %d whole-graph optimisations in place, %d deferred; RMS %.4f m / %.4f m\n",
              whole_in_place, jobs, rms_in_place, rms_deferred);
  // Loops asked for while a job was out are served by the next one.
  EXPECT_GE(whole_in_place, 1);
  EXPECT_GE(jobs, 1);
  EXPECT_LE(jobs, whole_in_place + 1);
  EXPECT_LT(rms_deferred, rms_in_place + 0.01);
}

TEST(Backend, WithoutLocalEdgesOptimisesOnlyOnLoops) {
  const RenderedKeyframes& world = ringKeyframes();
  BackendConfig config;
  config.local_edges = 0;
  Backend backend(config, roomVocabulary());
  int optimisations = 0;
  for (const KeyframePtr& kf : world.keyframes) {
    const BackendUpdate u = backend.addKeyframe(kf);
    EXPECT_EQ(u.num_local_edges, 0);
    if (u.optimized) ++optimisations;
  }
  EXPECT_GE(backend.numLoops(), 1);
  EXPECT_EQ(optimisations, backend.numLoops());
  EXPECT_EQ(backend.numLocalEdges(), 0);
}

TEST(Backend, TheLocalEdgesOfAKeyframeShareTheInformationOfItsFeatures) {
  // Two back ends, with and without the share, fed the same keyframes: they stay the same until
  // the first keyframe that brings two or more local edges, whose edges must then hold 1/n of the
  // information each.
  const RenderedKeyframes& world = ringKeyframes();
  BackendConfig shared_config;
  shared_config.local_edges_share_information = true;
  BackendConfig independent_config = shared_config;
  independent_config.local_edges_share_information = false;
  Backend shared(shared_config, roomVocabulary());
  Backend independent(independent_config, roomVocabulary());
  const auto localEdgesTo = [](const Backend& backend, std::int64_t id) {
    std::vector<PoseGraphEdge> out;
    for (const PoseGraphEdge& e : backend.graph().edges()) {
      if (e.kind == EdgeKind::kLocal && e.to_id == id) out.push_back(e);
    }
    std::sort(out.begin(), out.end(),
              [](const auto& a, const auto& b) { return a.from_id < b.from_id; });
    return out;
  };
  for (const KeyframePtr& kf : world.keyframes) {
    const BackendUpdate u_shared = shared.addKeyframe(kf);
    const BackendUpdate u_independent = independent.addKeyframe(kf);
    ASSERT_EQ(u_shared.num_local_edges, u_independent.num_local_edges) << kf->id;
    const int n = u_shared.num_local_edges;
    const std::vector<PoseGraphEdge> with_share = localEdgesTo(shared, kf->id);
    const std::vector<PoseGraphEdge> without = localEdgesTo(independent, kf->id);
    ASSERT_EQ(with_share.size(), static_cast<std::size_t>(n));
    ASSERT_EQ(without.size(), static_cast<std::size_t>(n));
    for (int k = 0; k < n; ++k) {
      EXPECT_EQ(with_share[k].from_id, without[k].from_id);
      EXPECT_TRUE(with_share[k].information.isApprox(without[k].information / n, 1e-12))
          << "keyframe " << kf->id << ", edge from " << with_share[k].from_id;
    }
    if (n >= 2) {
      std::printf("keyframe %ld: %d local edges, each with 1/%d of its information\n",
                  static_cast<long>(kf->id), n, n);
      return;
    }
  }
  FAIL() << "no keyframe brought two local edges";
}

// A copy of `keyframe` as a new tracking segment would report it: its own odometry world
// (T_odometry_world applied to the pose), segment `segment`.
KeyframePtr inNewSegment(const KeyframePtr& keyframe, std::int64_t segment,
                         const SE3& T_odometry_world, bool drop_features = false) {
  auto copy = std::make_shared<Keyframe>(*keyframe);
  copy->segment = segment;
  copy->T_world_camera = T_odometry_world * keyframe->T_world_camera;
  if (drop_features) copy->features = FeatureSet();
  return copy;
}

struct SegmentRun {
  double rms_after_m = 0.0;  ///< RMS position error of the new segment's corrected keyframes
  std::vector<BackendUpdate> updates;
  /// What tracking is told with the keyframes near each new one: the segment awaits
  /// relocalisation (MapKeyframes::relocalization_pending).
  std::vector<bool> tracking_told_pending;
  int relocalizations = 0;
};

// The ring's first 50 keyframes in segment 0, then (as if tracking was lost) keyframes 44..79 in
// segment 1 whose odometry world is 2 m and 40 degrees away from the map's. The first keyframe of
// segment 1 has no features (nothing to match), so relocalisation must wait for the second.
SegmentRun runWithLostTracking(bool relocalization) {
  const RenderedKeyframes& world = ringKeyframes();
  BackendConfig config;
  config.relocalization = relocalization;
  Backend backend(config, roomVocabulary());
  const SE3 T_odometry_world =
      SE3(Eigen::Translation3d(2.0, -1.0, 0.3) *
          Eigen::AngleAxisd(40.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  SegmentRun run;
  for (std::size_t k = 0; k < 50; ++k) backend.addKeyframe(world.keyframes[k]);
  for (std::size_t k = 44; k < 80; ++k) {
    // Ids keep increasing across segments, as tracking numbers them.
    auto kf =
        std::make_shared<Keyframe>(*inNewSegment(world.keyframes[k], 1, T_odometry_world, k == 44));
    kf->id = static_cast<std::int64_t>(50 + (k - 44));
    run.updates.push_back(backend.addKeyframe(kf));
    run.tracking_told_pending.push_back(backend.keyframesNear(kf->id).relocalization_pending);
    if (run.updates.back().relocalized) ++run.relocalizations;
  }
  double sum = 0.0;
  for (std::size_t k = 44; k < 80; ++k) {
    const std::int64_t id = static_cast<std::int64_t>(50 + (k - 44));
    const double e = (backend.pose(id).translation() - world.truth[k].translation()).norm();
    sum += e * e;
  }
  run.rms_after_m = std::sqrt(sum / 36.0);
  return run;
}

TEST(Backend, RelocalisationPutsANewTrackingSegmentBackIntoTheMap) {
  const SegmentRun run = runWithLostTracking(true);
  std::printf("lost tracking: new segment RMS error %.3f m with relocalisation\n", run.rms_after_m);
  // The featureless first keyframe tries and fails; the next one relocalises.
  ASSERT_GE(run.updates.size(), 2u);
  EXPECT_TRUE(run.updates[0].relocalization_attempted);
  EXPECT_FALSE(run.updates[0].relocalized);
  EXPECT_TRUE(run.updates[0].relocalization_pending);
  EXPECT_TRUE(run.tracking_told_pending[0]);  // tracking offers more views sooner
  EXPECT_EQ(run.updates[0].relocalization_attempts, 1);
  EXPECT_TRUE(run.updates[1].relocalized);
  EXPECT_EQ(run.updates[1].relocalization_attempts, 2);
  EXPECT_TRUE(run.updates[1].optimized);
  EXPECT_FALSE(run.updates[1].relocalization_pending);
  EXPECT_GE(run.updates[1].relocalization.match_id, 0);
  EXPECT_LT(run.updates[1].relocalization.match_id, 50);  // a keyframe of the first segment
  EXPECT_EQ(run.relocalizations, 1);
  // Once joined, no more attempts; T_world_odometry maps the segment's odometry into the map.
  for (std::size_t u = 1; u < run.updates.size(); ++u) {
    EXPECT_FALSE(run.tracking_told_pending[u]) << u;
    if (u < 2) continue;
    EXPECT_FALSE(run.updates[u].relocalization_attempted);
    EXPECT_FALSE(run.updates[u].relocalization_pending);
  }
  EXPECT_LT(run.rms_after_m, 0.2);  // the first segment's own drift; 7 m without relocalisation
}

TEST(Backend, WithoutRelocalisationANewSegmentStaysInItsOwnWorld) {
  const SegmentRun run = runWithLostTracking(false);
  std::printf("lost tracking: new segment RMS error %.3f m without relocalisation\n",
              run.rms_after_m);
  EXPECT_EQ(run.relocalizations, 0);
  for (const BackendUpdate& u : run.updates) EXPECT_FALSE(u.relocalization_attempted);
  EXPECT_TRUE(run.updates.back().relocalization_pending);
  // No attempts will be made: tracking is not asked for views to attempt with.
  for (const bool told : run.tracking_told_pending) EXPECT_FALSE(told);
  EXPECT_GT(run.rms_after_m, 1.0);
}

TEST(Backend, LocalMatchesThatDisagreeWithTheGraphAreRejected) {
  const RenderedKeyframes& world = ringKeyframes();
  BackendConfig config;
  // Unguided matching: guided by the graph, a false match would not even be found.
  config.local_search_radius_px = 1000.0;
  Backend backend(config, roomVocabulary());
  int with_local_edges = 0;
  for (std::size_t k = 0; k < 30; ++k) {
    const BackendUpdate u = backend.addKeyframe(world.keyframes[k]);
    if (u.num_local_edges > 0) ++with_local_edges;
    EXPECT_EQ(u.num_local_rejected, 0) << k;  // true matches agree with the odometry
  }
  // Keyframes two or more apart overlap except around the ring's corners.
  EXPECT_GE(with_local_edges, 20);
  // Keyframe 30 with a 1 m odometry jump: the images still match keyframes 27, 28 (etc.), but the
  // relative poses disagree with the graph by 1 m, as a false match would.
  auto jumped = std::make_shared<Keyframe>(*world.keyframes[30]);
  jumped->T_world_camera =
      world.keyframes[30]->T_world_camera * SE3(Eigen::Translation3d(1.0, 0.0, 0.0));
  const BackendUpdate u = backend.addKeyframe(jumped);
  EXPECT_EQ(u.num_local_edges, 0);
  EXPECT_GT(u.num_local_rejected, 0);
}

TEST(LoopDetector, RejectsNonBinaryDescriptors) {
  LoopDetector detector(BackendConfig(), roomVocabulary());
  auto keyframe = std::make_shared<Keyframe>();
  keyframe->features.descriptors = cv::Mat(10, 128, CV_32F, cv::Scalar(0));
  EXPECT_EQ(detector.processKeyframe(keyframe).status, LoopStatus::kUnsupportedDescriptors);
  EXPECT_EQ(detector.size(), 0u);
}

// A camera that goes over the same ground again and again (a robot patrolling, fr1/xyz's desk):
// the room's first keyframes forward, backward, forward, ... as new keyframes with new ids and
// odometry that keeps drifting (the true steps with the noise of renderKeyframes).
struct PingPong {
  std::vector<KeyframePtr> keyframes;
  std::vector<SE3, Eigen::aligned_allocator<SE3>> truth;
  std::vector<int> lap;  ///< lap of each keyframe, from 0
};

PingPong pingPong(const RenderedKeyframes& lap, int laps) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 1.0);
  PingPong out;
  SE3 T_world_odometry = lap.truth.front();
  SE3 T_world_prev_true = lap.truth.front();
  const int n = static_cast<int>(lap.keyframes.size());
  for (int k = 0; k < laps; ++k) {
    for (int i = 0; i < n; ++i) {
      const int index = k % 2 == 0 ? i : n - 1 - i;
      if (k > 0 && i == 0) continue;  // the turn: the same view is not a new keyframe
      const SE3& T_world_true = lap.truth[static_cast<std::size_t>(index)];
      if (!out.keyframes.empty()) {
        T_world_odometry =
            T_world_odometry * noisyStep(T_world_prev_true.inverse() * T_world_true, rng, noise);
      }
      T_world_prev_true = T_world_true;
      auto keyframe = std::make_shared<Keyframe>(*lap.keyframes[static_cast<std::size_t>(index)]);
      keyframe->id = static_cast<std::int64_t>(out.keyframes.size());
      keyframe->T_world_camera = T_world_odometry;
      out.keyframes.push_back(keyframe);
      out.truth.push_back(T_world_true);
      out.lap.push_back(k);
    }
  }
  return out;
}

struct CullingRun {
  std::vector<std::size_t> keyframes_after_lap;  ///< graph nodes at the end of each lap
  int culled = 0;
  int culled_earlier = 0;    ///< of culled: earlier keyframes a kept new one made redundant
  double rms_error_m = 0.0;  ///< every keyframe (culled ones through backend.pose)
};

CullingRun runPingPong(const PingPong& run, bool cull,
                       MemoryPressure pressure = MemoryPressure::kNone, bool cull_earlier = true) {
  BackendConfig config;
  config.cull_redundant_keyframes = cull;
  config.cull_earlier_keyframes = cull_earlier;
  Backend backend(config, roomVocabulary());
  backend.setMemoryPressure(pressure);
  CullingRun out;
  for (std::size_t k = 0; k < run.keyframes.size(); ++k) {
    const BackendUpdate update = backend.addKeyframe(run.keyframes[k]);
    if (update.culled) {
      ++out.culled;
      EXPECT_TRUE(backend.graph().hasNode(update.culled_into_id));
      EXPECT_FALSE(backend.graph().hasNode(run.keyframes[k]->id));
      EXPECT_TRUE(backend.hasKeyframe(run.keyframes[k]->id));
      for (const auto& entry : update.corrected_poses) EXPECT_NE(entry.first, update.keyframe_id);
    }
    for (const std::int64_t id : update.culled_earlier_ids) {
      ++out.culled;
      ++out.culled_earlier;
      EXPECT_LT(id, update.keyframe_id);
      EXPECT_FALSE(backend.graph().hasNode(id));
      EXPECT_TRUE(backend.hasKeyframe(id));
      EXPECT_TRUE(backend.graph().hasNode(update.keyframe_id)) << "culled into the new keyframe";
      for (const auto& entry : update.corrected_poses) EXPECT_NE(entry.first, id);
    }
    if (k + 1 == run.keyframes.size() || run.lap[k + 1] != run.lap[k]) {
      out.keyframes_after_lap.push_back(backend.graph().numNodes());
    }
  }
  // The graph stays one connected chain: optimising the whole of it converges.
  PoseGraph graph = backend.graph();
  EXPECT_NE(graph.optimize(PoseGraphOptions()).status, OptimizationStatus::kSolverFailure);
  double sum = 0.0;
  for (std::size_t k = 0; k < run.keyframes.size(); ++k) {
    const double e =
        (backend.pose(run.keyframes[k]->id).translation() - run.truth[k].translation()).norm();
    sum += e * e;
  }
  out.rms_error_m = std::sqrt(sum / static_cast<double>(run.keyframes.size()));
  EXPECT_EQ(backend.numCulled(), out.culled);
  EXPECT_EQ(backend.graph().numNodes() + static_cast<std::size_t>(out.culled),
            run.keyframes.size());
  return out;
}

TEST(Backend, RevisitingTheSamePlaceAddsNoKeyframesWhenRedundantOnesAreCulled) {
  const RenderedKeyframes& lap = roomLapKeyframes();
  const PingPong run = pingPong(lap, 4);
  const CullingRun culled = runPingPong(run, true);
  const CullingRun kept = runPingPong(run, false);
  std::printf("room ping-pong, %zu keyframes over 4 laps: graph after each lap",
              run.keyframes.size());
  for (std::size_t n : culled.keyframes_after_lap) std::printf(" %zu", n);
  std::printf(" (culled %d); without culling", culled.culled);
  for (std::size_t n : kept.keyframes_after_lap) std::printf(" %zu", n);
  std::printf("; RMS keyframe error %.4f m culled, %.4f m kept\n", culled.rms_error_m,
              kept.rms_error_m);
  ASSERT_EQ(culled.keyframes_after_lap.size(), 4u);
  // Without culling every lap adds its keyframes; with it, laps 3 and 4 add at most 10% to what
  // lap 2 left (issue 24's target for fr1/xyz played back and forth).
  EXPECT_EQ(kept.keyframes_after_lap.back(), run.keyframes.size());
  EXPECT_LE(static_cast<double>(culled.keyframes_after_lap.back()),
            1.1 * static_cast<double>(culled.keyframes_after_lap[1]));
  EXPECT_LT(culled.keyframes_after_lap[1], kept.keyframes_after_lap[1]);
  EXPECT_GT(culled.culled, 0);
  // What a culled keyframe held is still in the map: every keyframe's pose, culled or not, is
  // as good as without culling (within a centimetre).
  EXPECT_LT(culled.rms_error_m, kept.rms_error_m + 0.01);
}

// A kept new keyframe culls the earlier keyframes it makes redundant (ORB-SLAM culls its local
// keyframes so): a place keeps the keyframes that see it from the most views, the graph holds
// fewer keyframes, and it stays at what lap 2 left for the laps after.
TEST(Backend, KeptKeyframesCullTheEarlierOnesTheyMakeRedundant) {
  const RenderedKeyframes& lap = roomLapKeyframes();
  const PingPong run = pingPong(lap, 8);
  const CullingRun both = runPingPong(run, true);
  const CullingRun newest_only = runPingPong(run, true, MemoryPressure::kNone, false);
  const auto print = [](const char* name, const CullingRun& r) {
    std::printf("%s: graph after each lap", name);
    for (std::size_t n : r.keyframes_after_lap) std::printf(" %zu", n);
    std::printf(" (culled %d, %d of them earlier keyframes); RMS keyframe error %.4f m\n", r.culled,
                r.culled_earlier, r.rms_error_m);
  };
  print("earlier keyframes culled too", both);
  print("new keyframes culled only", newest_only);
  ASSERT_EQ(both.keyframes_after_lap.size(), 8u);
  EXPECT_GT(both.culled_earlier, 0);
  EXPECT_EQ(newest_only.culled_earlier, 0);
  EXPECT_LE(static_cast<double>(both.keyframes_after_lap.back()),
            1.1 * static_cast<double>(both.keyframes_after_lap[1]));
  EXPECT_LT(both.keyframes_after_lap.back(), newest_only.keyframes_after_lap.back());
  EXPECT_LT(both.rms_error_m, newest_only.rms_error_m + 0.01);
}

// What tracking gets back from the back end (VisualOdometry::setMapKeyframes): the kept keyframes
// near one keyframe, culled or not, each at its optimised pose relative to it, nearest first.
TEST(Backend, KeyframesNearAKeyframeAreTheKeptOnesWithinReachAtTheirOptimisedPoses) {
  const RenderedKeyframes& lap = roomLapKeyframes();
  const PingPong run = pingPong(lap, 2);
  Backend backend(BackendConfig(), roomVocabulary());
  std::int64_t culled_anchor = -1;
  for (const KeyframePtr& keyframe : run.keyframes) {
    if (backend.addKeyframe(keyframe).culled) culled_anchor = keyframe->id;
  }
  ASSERT_GE(culled_anchor, 0) << "the second lap culls some keyframe";
  const double max_translation_m = 1.0;
  const double max_rotation_deg = 60.0;
  for (const std::int64_t anchor : {run.keyframes.back()->id, culled_anchor}) {
    SCOPED_TRACE(anchor);
    const MapKeyframes near =
        backend.keyframesNear(anchor, max_translation_m, max_rotation_deg, 1000);
    EXPECT_EQ(near.anchor_id, anchor);
    const SE3 T_anchor_world = backend.pose(anchor).inverse();
    std::size_t within_reach = 0;
    for (const std::int64_t id : backend.graph().nodeIds()) {
      const SE3 T = T_anchor_world * backend.pose(id);
      if (id != anchor && T.translation().norm() <= max_translation_m &&
          rotationAngleRad(T.linear()) * 180.0 / M_PI <= max_rotation_deg) {
        ++within_reach;
      }
    }
    ASSERT_GT(within_reach, 3u);
    EXPECT_EQ(near.members.size(), within_reach) << "every kept keyframe in reach";
    double previous_distance = 0.0;
    for (const MapKeyframes::Member& member : near.members) {
      ASSERT_NE(member.keyframe, nullptr);
      EXPECT_NE(member.keyframe->id, anchor);
      EXPECT_TRUE(backend.graph().hasNode(member.keyframe->id)) << "culled ones are not offered";
      const SE3 expected = T_anchor_world * backend.pose(member.keyframe->id);
      EXPECT_LT((member.T_anchor_keyframe.translation() - expected.translation()).norm(), 1e-12);
      const double distance =
          member.T_anchor_keyframe.translation().norm() / max_translation_m +
          rotationAngleRad(member.T_anchor_keyframe.linear()) * 180.0 / M_PI / max_rotation_deg;
      EXPECT_GE(distance, previous_distance - 1e-12) << "nearest first";
      previous_distance = distance;
    }
    const MapKeyframes nearest =
        backend.keyframesNear(anchor, max_translation_m, max_rotation_deg, 3);
    ASSERT_EQ(nearest.members.size(), 3u);
    for (std::size_t k = 0; k < 3; ++k) {
      EXPECT_EQ(nearest.members[k].keyframe->id, near.members[k].keyframe->id);
    }
  }
  const MapKeyframes unknown = backend.keyframesNear(123456, 1.0, 60.0, 10);
  EXPECT_EQ(unknown.anchor_id, -1);
  EXPECT_TRUE(unknown.members.empty());
}

// Culling an earlier keyframe keeps the back end whole: keyframes culled into it follow it to
// its anchor, every culled keyframe keeps a pose, and a snapshot restores.
TEST(Backend, AfterEarlierKeyframesAreCulledEveryAnchorIsInTheGraphAndASnapshotRestores) {
  const RenderedKeyframes& lap = roomLapKeyframes();
  const PingPong run = pingPong(lap, 6);
  Backend backend(BackendConfig(), roomVocabulary());
  int culled_earlier = 0;
  for (const KeyframePtr& keyframe : run.keyframes) {
    culled_earlier += static_cast<int>(backend.addKeyframe(keyframe).culled_earlier_ids.size());
  }
  ASSERT_GT(culled_earlier, 0);
  const BackendSnapshot snapshot = backend.snapshot();
  for (const CulledKeyframeRecord& record : snapshot.culled) {
    EXPECT_TRUE(backend.graph().hasNode(record.anchor_id)) << "keyframe " << record.id;
    EXPECT_TRUE(backend.pose(record.id).matrix().allFinite());
  }
  for (const PoseGraphEdge& edge : snapshot.edges) {
    EXPECT_TRUE(backend.graph().hasNode(edge.from_id) && backend.graph().hasNode(edge.to_id));
  }
  Backend restored(BackendConfig(), roomVocabulary());
  EXPECT_NO_THROW(restored.restore(snapshot, false));
  for (const KeyframePtr& keyframe : run.keyframes) {
    EXPECT_LT((restored.pose(keyframe->id).translation() - backend.pose(keyframe->id).translation())
                  .norm(),
              1e-9);
  }
  // The views the culling counts come back too, so that a loaded map's keyframes can be culled
  // as they would have been had the run gone on.
  EXPECT_FALSE(snapshot.views.empty());
  EXPECT_EQ(restored.snapshot().views, snapshot.views);
}

// The same view again: a keyframe whose features are nearly all inliers of one match is culled
// into that keyframe even where the 3-view rule could not call it redundant.
TEST(Backend, AKeyframeThatRepeatsAnEarlierViewIsCulledIntoIt) {
  const RenderedKeyframes& lap = roomLapKeyframes();
  BackendConfig config;
  config.cull_min_covering_keyframes = 50;  // the view rule never holds
  config.cull_earlier_keyframes = false;
  Backend backend(config, roomVocabulary());
  const std::size_t n = 12;
  for (std::size_t k = 0; k < n; ++k) EXPECT_FALSE(backend.addKeyframe(lap.keyframes[k]).culled);
  // The camera comes back to keyframe 5's view (odometry puts it where keyframe 5 is).
  auto again = std::make_shared<Keyframe>(*lap.keyframes[5]);
  again->id = static_cast<std::int64_t>(n);
  again->T_world_camera = backend.pose(lap.keyframes[5]->id);
  const BackendUpdate update = backend.addKeyframe(again);
  EXPECT_TRUE(update.culled);
  EXPECT_EQ(update.culled_into_id, lap.keyframes[5]->id);
  EXPECT_EQ(backend.graph().numNodes(), n);
}

// daemon.memory_limit_mb: near and over the limit the culling rule is relaxed, so fewer
// keyframes are kept, and what the culled ones held stays in the map.
TEST(Backend, UnderMemoryPressureFewerKeyframesAreKept) {
  const RenderedKeyframes& lap = roomLapKeyframes();
  const PingPong run = pingPong(lap, 2);
  const CullingRun normal = runPingPong(run, true);
  const CullingRun near = runPingPong(run, true, MemoryPressure::kNear);
  const CullingRun over = runPingPong(run, true, MemoryPressure::kOver);
  std::printf(
      "room ping-pong, %zu keyframes over 2 laps: kept %zu / %zu / %zu (no pressure / near / "
      "over the limit); RMS keyframe error %.4f / %.4f / %.4f m\n",
      run.keyframes.size(), normal.keyframes_after_lap.back(), near.keyframes_after_lap.back(),
      over.keyframes_after_lap.back(), normal.rms_error_m, near.rms_error_m, over.rms_error_m);
  EXPECT_LT(near.keyframes_after_lap.back(), normal.keyframes_after_lap.back());
  EXPECT_LT(over.keyframes_after_lap.back(), near.keyframes_after_lap.back());
  EXPECT_LT(over.rms_error_m, normal.rms_error_m + 0.02);
}

TEST(LoopDetector, ARemovedKeyframeIsNeverReturnedAgain) {
  const RenderedKeyframes& world = ringKeyframes();
  LoopDetector detector(BackendConfig(), roomVocabulary());
  for (std::size_t k = 0; k < 10; ++k) detector.processKeyframe(world.keyframes[k]);
  const Keyframe& probe = *world.keyframes[5];
  const LoopDetection before = detector.query(probe.features, probe.intrinsics);
  ASSERT_EQ(before.status, LoopStatus::kLoopFound);
  ASSERT_EQ(before.match_id, probe.id);
  EXPECT_TRUE(detector.removeKeyframe(probe.id));
  EXPECT_FALSE(detector.removeKeyframe(probe.id)) << "removed twice";
  EXPECT_FALSE(detector.removeKeyframe(12345)) << "never stored";
  EXPECT_EQ(detector.size(), 10u);
  EXPECT_EQ(detector.numSearchable(), 9u);
  const LoopDetection after = detector.query(probe.features, probe.intrinsics);
  EXPECT_NE(after.match_id, probe.id);
  const std::vector<LoopDetection> local =
      detector.matchLocal(probe, [](std::int64_t, std::int64_t) { return true; });
  for (const LoopDetection& d : local) EXPECT_NE(d.match_id, probe.id);
  // Keyframes added after a removal are found as before.
  detector.processKeyframe(world.keyframes[10]);
  EXPECT_EQ(detector.query(world.keyframes[10]->features, world.keyframes[10]->intrinsics).match_id,
            world.keyframes[10]->id);
}

}  // namespace
}  // namespace slamd
