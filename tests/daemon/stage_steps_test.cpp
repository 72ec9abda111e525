// The daemon's stage steps driven by hand, without threads: packets wait in queues between the
// steps as they do in the daemon, a RESET is issued while every stage still has packets from
// before it queued, and each step's trace shows that it processed all of those before its reset
// and none after.

#include "slamd/app/stage_steps.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <initializer_list>
#include <limits>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "daemon_fixture.hpp"
#include "slamd/backend/vocabulary.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/pipeline/drop_oldest_queue.hpp"
#include "slamd/pipeline/spsc_queue.hpp"
#include "slamd/sources/create_frame_source.hpp"

namespace slamd {
namespace {

/// Keeps what the steps publish instead of sending it.
class RecordingPublisher final : public DaemonPublisher {
 public:
  void publishPose(const PoseEstimate& pose) override { poses.push_back(pose); }
  void publishOdometry(const OdometryResult&) override {}
  void publishVanishingPoint(Utime, const VanishingPointReport&) override {}
  void publishKeyframes(const KeyframeTrajectory&) override {}
  void publishMapUpdate(const MapUpdate&) override { ++updates; }
  void publishFullMap(const FullMap& map) override { full_maps.push_back(map); }
  void publishPlaneMap(const planes::PlaneMapSnapshot& plane_map) override {
    plane_maps.push_back(plane_map);
  }
  std::vector<PoseEstimate> poses;
  int updates = 0;
  std::vector<FullMap> full_maps;
  std::vector<planes::PlaneMapSnapshot> plane_maps;
};

using Trace = std::vector<StepTraceEntry>;

/// A queue between two steps: FIFO, as the pipeline's edges are.
template <typename T>
using Edge = SpscQueue<T>;

template <typename T>
void push(Edge<T>& edge, const T& packet) {
  ASSERT_TRUE(edge.tryPush(T(packet)));
}

/// Runs `step` on at most `count` packets waiting in `input`, handing what it returns to `out`.
template <typename In, typename Step, typename Out>
void drain(Edge<In>& input, Step& step, Out&& out, std::size_t count = SIZE_MAX) {
  for (std::size_t i = 0; i < count; ++i) {
    std::optional<In> packet = input.tryPop();
    if (!packet) return;
    out(step, std::move(*packet));
  }
}

/// The reset happened exactly between the last packet captured before the RESET and the first
/// captured after it: every packet of epoch e was processed after exactly e resets, and the frames
/// were the ones captured before (`before`) and after (`after`) the RESET, in order. Heartbeats
/// (utime -1) obey the same rule.
void expectResetAtOnePointOfTheStream(const Trace& trace, const std::vector<Utime>& before,
                                      const std::vector<Utime>& after, const char* stage) {
  SCOPED_TRACE(stage);
  std::vector<Utime> frames_before, frames_after;
  for (std::size_t i = 0; i < trace.size(); ++i) {
    const StepTraceEntry& entry = trace[i];
    EXPECT_EQ(entry.resets, entry.reset_epoch)
        << "packet " << i << " (utime " << entry.utime << ", epoch " << entry.reset_epoch
        << ") was processed after " << entry.resets << " resets";
    if (i > 0) {
      EXPECT_GE(entry.reset_epoch, trace[i - 1].reset_epoch) << "packet " << i;
    }
    if (entry.utime < 0) continue;
    (entry.reset_epoch == 0 ? frames_before : frames_after).push_back(entry.utime);
  }
  EXPECT_EQ(frames_before, before);
  EXPECT_EQ(frames_after, after);
}

class DaemonStageSteps : public DaemonInProcess {
 protected:
  void SetUp() override {
    DaemonInProcess::SetUp();
    // The steps run OpenCV on the calling thread, as the daemon does (daemon.opencv_threads = 0):
    // OpenCV's own worker pool is not instrumented, and ThreadSanitizer would report it.
    cv::setNumThreads(0);
    config_ = smallSyntheticConfig(kFrames);
    config_.set("backend.enabled", "true");
    config_.set("backend.vocabulary_depth", "2");
    source_ = createFrameSource("synthetic:room", config_);
    source_->open();
  }

  static constexpr int kFrames = 10;
  Config config_;
  std::unique_ptr<FrameSource> source_;
};

/// A keyframe packet of `frame` at `T_world_camera`, as the filter step passes it on.
EstimatedPacket keyframePacket(RgbdFramePtr frame, std::int64_t id, const SE3& T_world_camera) {
  EstimatedPacket packet;
  OdometryResult odometry;
  odometry.utime = frame->utime;
  odometry.is_keyframe = true;
  auto keyframe = std::make_shared<Keyframe>();
  keyframe->id = id;
  keyframe->utime = frame->utime;
  odometry.keyframe = keyframe;
  packet.frame = std::move(frame);
  packet.odometry = std::move(odometry);
  packet.pose.tracking_state = TrackingState::kOk;
  packet.pose.T_world_camera = T_world_camera;
  return packet;
}

TEST_F(DaemonStageSteps, MappingPutsKeyframePlanesInAPlaneMapThatFollowsCorrectionsAndIsPublished) {
  const MappingConfig mapping_config = MappingConfig::load(config_);
  ASSERT_TRUE(mapping_config.planes_enabled);  // the default
  Mapper mapper(mapping_config);
  RecordingPublisher publisher;
  SpscQueue<MapCorrection> map_corrections(64);
  SpscQueue<MapRequest> map_requests(4);
  MappingStep mapping(mapper, mapping_config, publisher, &map_corrections, &map_requests);
  const Trajectory truth = *source_->groundTruth();
  std::vector<RgbdFramePtr> frames;
  for (int i = 0; i < kFrames; ++i) {
    const FrameRead read = source_->next(std::chrono::seconds(10));
    ASSERT_EQ(read.status, FrameRead::Status::kFrame);
    frames.push_back(read.frame);
  }
  const std::vector<int> keyframe_frames = {0, 4, 8};
  for (std::size_t k = 0; k < keyframe_frames.size(); ++k) {
    const auto index = static_cast<std::size_t>(keyframe_frames[k]);
    mapping.process(
        keyframePacket(frames[index], static_cast<std::int64_t>(k), truth[index].T_world_camera));
  }
  EXPECT_EQ(mapping.stats().keyframes_segmented, 3);
  EXPECT_GT(mapping.stats().pixels_snapped, 10000);
  const std::vector<planes::WorldPlane> before = mapping.planeMap().worldPlanes();
  ASSERT_GE(before.size(), 2u);

  // PUBLISH_MAP sends the plane map with the full map.
  const std::size_t published = publisher.plane_maps.size();
  MapRequest request;
  request.kind = MapRequest::Kind::kPublish;
  ASSERT_TRUE(map_requests.tryPush(std::move(request)));
  mapping.serveRequests();
  ASSERT_EQ(publisher.plane_maps.size(), published + 1);
  EXPECT_EQ(publisher.plane_maps.back().frame_id, mapping_config.frame_id);
  EXPECT_EQ(publisher.plane_maps.back().planes.size(), before.size());

  // A correction that raises keyframes 1 and 2 by a metre and no longer lists keyframe 0 (culled):
  // the plane map is what those two keyframes' planes make at their new poses.
  SE3 raise = SE3::Identity();
  raise.translation() = Eigen::Vector3d(0.0, 0.0, 1.0);
  BackendCorrection correction;
  for (std::int64_t id : {1, 2}) {
    const SE3 moved =
        raise * truth[static_cast<std::size_t>(keyframe_frames[static_cast<std::size_t>(id)])]
                    .T_world_camera;
    correction.keyframe_poses.emplace_back(id, moved);
  }
  ASSERT_TRUE(map_corrections.tryPush(MapCorrection{correction, mapping.resetEpoch()}));
  mapping.process(EstimatedPacket{});  // a heartbeat: corrections are taken on every packet
  EXPECT_EQ(mapping.planeMap().keyframeIds(), (std::vector<std::int64_t>{1, 2}));

  planes::PlaneSegmenter segmenter;
  planes::PlaneMap expected;
  for (const auto& [id, T_world_camera] : correction.keyframe_poses) {
    const RgbdFrame& frame =
        *frames[static_cast<std::size_t>(keyframe_frames[static_cast<std::size_t>(id)])];
    expected.addKeyframe(id, T_world_camera, segmenter.segment(frame).planes, frame.utime);
  }
  const std::vector<planes::WorldPlane>& after = mapping.planeMap().worldPlanes();
  ASSERT_EQ(after.size(), expected.worldPlanes().size());
  for (std::size_t i = 0; i < after.size(); ++i) {
    const planes::WorldPlane& want = expected.worldPlanes()[i];
    EXPECT_LT((after[i].normal_world - want.normal_world).norm(), 1e-9) << i;
    EXPECT_NEAR(after[i].offset_m, want.offset_m, 1e-9) << i;
    EXPECT_EQ(after[i].keyframe_ids, want.keyframe_ids) << i;
  }
  // The plane map changed: it goes out with the next map update.
  EXPECT_GE(publisher.plane_maps.size(), published + 1);
}

// With a back end, a tracking segment started after a loss is not in the map's frame until the
// back end says it joined it: its poses are published TRACKING_NOT_LOCALIZED until then, the first
// after says TRACKING_RELOCALIZED. A correction about an older segment's keyframe does not count.
TEST(PublishStepSegments, APoseAfterALossIsNotLocalisedUntilACorrectionPutsItsSegmentInTheMap) {
  RecordingPublisher publisher;
  SpscQueue<PoseCorrection> corrections(8);
  PublishStep publish(publisher, "world", "camera", &corrections);
  Utime utime = 1'000'000;
  const auto publishFrame = [&](PublishStep& step, std::int64_t segment, TrackingState state) {
    EstimatedPacket packet;
    auto frame = std::make_shared<RgbdFrame>();
    frame->utime = (utime += 33'333);
    frame->received_steady_ns = steadyNowNs();
    packet.frame = frame;
    OdometryResult odometry;
    odometry.utime = frame->utime;
    odometry.segment = segment;
    packet.odometry = odometry;
    packet.pose.utime = frame->utime;
    packet.pose.tracking_state = state;
    step.process(std::move(packet));
    return publisher.poses.back().tracking_state;
  };
  const auto correction = [&](bool relocalized, bool map_frame_known, std::int64_t segment) {
    ASSERT_TRUE(corrections.tryPush(
        PoseCorrection{SE3::Identity(), relocalized, map_frame_known, 0, segment}));
  };
  using S = TrackingState;
  EXPECT_EQ(publishFrame(publish, 3, S::kOk), S::kOk);  // the run's first segment: the map's
  correction(false, true, 3);
  EXPECT_EQ(publishFrame(publish, 3, S::kOk), S::kOk);
  EXPECT_EQ(publishFrame(publish, 3, S::kLost), S::kLost);
  EXPECT_EQ(publishFrame(publish, 4, S::kOk), S::kNotLocalized);  // after the loss
  correction(false, true, 3);  // late, about the last keyframe before the loss
  EXPECT_EQ(publishFrame(publish, 4, S::kOk), S::kNotLocalized);
  correction(false, false, 4);  // the new segment's keyframes optimised, not yet joined
  EXPECT_EQ(publishFrame(publish, 4, S::kPredicted), S::kNotLocalized);
  correction(true, true, 4);  // relocalised
  EXPECT_EQ(publishFrame(publish, 4, S::kOk), S::kRelocalized);
  EXPECT_EQ(publishFrame(publish, 4, S::kOk), S::kOk);
  // Lost again, and the back end joined the next segment before this step saw its first frame.
  EXPECT_EQ(publishFrame(publish, 4, S::kLost), S::kLost);
  correction(true, true, 5);
  EXPECT_EQ(publishFrame(publish, 5, S::kOk), S::kRelocalized);
  EXPECT_EQ(publish.stats().not_localized.load(), 3u);
  EXPECT_FALSE(publish.stats().awaiting_map_frame.load());

  // Without a back end there is no map to be placed in: segments change nothing.
  PublishStep odometry_only(publisher, "world", "camera", nullptr);
  EXPECT_EQ(publishFrame(odometry_only, 0, S::kOk), S::kOk);
  EXPECT_EQ(publishFrame(odometry_only, 1, S::kOk), S::kOk);
}

TEST_F(DaemonStageSteps, NoPacketFromBeforeAResetIsProcessedAfterAStageReset) {
  const FilterConfig filter_config = FilterConfig::load(config_);
  const MappingConfig mapping_config = MappingConfig::load(config_);
  const BackendConfig backend_config = BackendConfig::load(config_);
  Mapper mapper(mapping_config);
  BackendStage backend(backend_config, loadVocabulary(backend_config));
  RecordingPublisher publisher;
  SpscQueue<PoseCorrection> pose_corrections(64);
  SpscQueue<MapCorrection> map_corrections(64);
  SpscQueue<MapRequest> map_requests(4);
  VanishingPointChannel vanishing_points;

  CaptureStep capture(*source_, 1'000'000'000, {});
  TrackingStep tracking(TrackingConfig::load(config_));
  VanishingPointStep vanishing(filter_config, vanishing_points);
  FilterStep filter(filter_config, &vanishing_points, std::chrono::microseconds(0));
  PublishStep publish(publisher, "world", "camera", &pose_corrections);
  MappingStep mapping(mapper, mapping_config, publisher, &map_corrections, &map_requests);
  BackendStep backend_step(backend, "world", publisher, &pose_corrections, &map_corrections);
  Trace tracking_trace, vanishing_trace, filter_trace, publish_trace, mapping_trace, backend_trace;
  tracking.setTrace([&](const StepTraceEntry& e) { tracking_trace.push_back(e); });
  vanishing.setTrace([&](const StepTraceEntry& e) { vanishing_trace.push_back(e); });
  filter.setTrace([&](const StepTraceEntry& e) { filter_trace.push_back(e); });
  publish.setTrace([&](const StepTraceEntry& e) { publish_trace.push_back(e); });
  mapping.setTrace([&](const StepTraceEntry& e) { mapping_trace.push_back(e); });
  backend_step.setTrace([&](const StepTraceEntry& e) { backend_trace.push_back(e); });

  // The daemon's graph: capture -> {tracking, vanishing}; tracking -> filter;
  // filter -> {publish, mapping, backend}.
  Edge<CapturePacket> to_tracking(64), to_vanishing(64);
  Edge<TrackedPacket> to_filter(64);
  Edge<EstimatedPacket> to_publish(64), to_mapping(64), to_backend(64);
  std::vector<Utime> before, after;
  auto captureFrames = [&](int count, std::vector<Utime>& utimes) {
    for (int i = 0; i < count; ++i) {
      SourceStep<CapturePacket> step = capture.process();
      ASSERT_EQ(step.kind, SourceStep<CapturePacket>::Kind::kItem);
      ASSERT_TRUE(step.item->frame);
      utimes.push_back(step.item->frame->utime);
      push(to_tracking, *step.item);
      push(to_vanishing, *step.item);
    }
  };
  auto toFilter = [&](TrackingStep& step, CapturePacket packet) {
    if (auto out = step.process(std::move(packet))) push(to_filter, *out);
  };
  auto detect = [](VanishingPointStep& step, CapturePacket packet) {
    step.process(std::move(packet));
  };
  auto fanOut = [&](FilterStep& step, TrackedPacket packet) {
    if (auto out = step.process(std::move(packet))) {
      push(to_publish, *out);
      push(to_mapping, *out);
      push(to_backend, *out);
    }
  };
  auto sink = [](auto& step, EstimatedPacket packet) { step.process(std::move(packet)); };

  // Four frames captured; every stage has processed some of them and has others still queued.
  captureFrames(4, before);
  drain(to_vanishing, vanishing, detect, 3);
  drain(to_tracking, tracking, toFilter, 3);
  drain(to_filter, filter, fanOut, 2);
  drain(to_publish, publish, sink, 1);
  drain(to_mapping, mapping, sink, 1);
  drain(to_backend, backend_step, sink, 1);
  ASSERT_EQ(publish_trace.size(), 1u);

  // RESET: the control thread's command. Frames keep coming.
  capture.reset();
  captureFrames(kFrames - 4, after);
  // The stages catch up, the sinks a little behind the others.
  drain(to_vanishing, vanishing, detect);
  drain(to_tracking, tracking, toFilter);
  drain(to_filter, filter, fanOut);
  drain(to_backend, backend_step, sink);
  drain(to_publish, publish, sink);
  drain(to_mapping, mapping, sink);

  expectResetAtOnePointOfTheStream(tracking_trace, before, after, "tracking");
  expectResetAtOnePointOfTheStream(vanishing_trace, before, after, "vanishing");
  expectResetAtOnePointOfTheStream(filter_trace, before, after, "filter");
  expectResetAtOnePointOfTheStream(publish_trace, before, after, "publish");
  expectResetAtOnePointOfTheStream(mapping_trace, before, after, "mapping");
  expectResetAtOnePointOfTheStream(backend_trace, before, after, "backend");
  for (const StepBase* step : std::initializer_list<const StepBase*>{
           &tracking, &vanishing, &filter, &publish, &mapping, &backend_step}) {
    EXPECT_EQ(step->resets(), 1u);
    EXPECT_EQ(step->stalePackets(), 0u);
  }
  // The reset took effect where the stream says: the first frame after it starts a new world at
  // the identity, and every pose before it continued the old one.
  ASSERT_EQ(publisher.poses.size(), static_cast<std::size_t>(kFrames));
  EXPECT_EQ(publisher.poses[before.size()].utime, after.front());
  EXPECT_LT(publisher.poses[before.size()].T_world_camera.translation().norm(), 1e-9);
  EXPECT_GT(publisher.poses[before.size() - 1].T_world_camera.translation().norm(), 1e-6);
}

// After each keyframe the back-end step hands the tracking step the keyframes it keeps near that
// one, at their optimised poses relative to it; tracking takes each set before its next frame.
TEST_F(DaemonStageSteps, TheBackEndHandsTrackingTheKeyframesItKeepsNearItsNewest) {
  const int frames = 60;  // a few keyframes
  Config config = smallSyntheticConfig(frames);
  config.set("backend.enabled", "true");
  config.set("backend.vocabulary_depth", "2");
  std::unique_ptr<FrameSource> source = createFrameSource("synthetic:room", config);
  source->open();
  const FilterConfig filter_config = FilterConfig::load(config);
  const BackendConfig backend_config = BackendConfig::load(config);
  BackendStage backend(backend_config, loadVocabulary(backend_config));
  RecordingPublisher publisher;
  SpscQueue<PoseCorrection> pose_corrections(64);
  SpscQueue<MapKeyframesPacket> map_keyframes(16);
  CaptureStep capture(*source, 1'000'000'000, {});
  TrackingStep tracking(TrackingConfig::load(config), &map_keyframes);
  FilterStep filter(filter_config, nullptr, std::chrono::microseconds(0));
  BackendStep backend_step(backend, "world", publisher, &pose_corrections, nullptr, &map_keyframes);
  int sets = 0;
  std::size_t largest_set = 0;
  for (int i = 0; i < frames; ++i) {
    SourceStep<CapturePacket> captured = capture.process();
    ASSERT_EQ(captured.kind, SourceStep<CapturePacket>::Kind::kItem);
    std::optional<TrackedPacket> tracked = tracking.process(std::move(*captured.item));
    ASSERT_TRUE(tracked);
    EXPECT_EQ(map_keyframes.sizeApprox(), 0u) << "tracking took the last set before frame " << i;
    std::optional<EstimatedPacket> estimated = filter.process(std::move(*tracked));
    ASSERT_TRUE(estimated);
    const bool keyframe = estimated->odometry && estimated->odometry->is_keyframe;
    backend_step.process(*estimated);
    std::optional<MapKeyframesPacket> set = map_keyframes.tryPop();
    EXPECT_EQ(set.has_value(), keyframe) << "frame " << i;
    if (!set) continue;
    ++sets;
    const Backend& graph = backend.backend();
    EXPECT_EQ(set->keyframes.anchor_id, estimated->odometry->keyframe->id);
    EXPECT_EQ(set->reset_epoch, backend_step.resetEpoch());
    largest_set = std::max(largest_set, set->keyframes.members.size());
    const SE3 T_anchor_world = graph.pose(set->keyframes.anchor_id).inverse();
    for (const MapKeyframes::Member& member : set->keyframes.members) {
      ASSERT_NE(member.keyframe, nullptr);
      EXPECT_TRUE(graph.graph().hasNode(member.keyframe->id));
      const SE3 expected = T_anchor_world * graph.pose(member.keyframe->id);
      EXPECT_LT((member.T_anchor_keyframe.translation() - expected.translation()).norm(), 1e-9);
    }
    ASSERT_TRUE(map_keyframes.tryPush(std::move(*set)));  // on to tracking
  }
  EXPECT_GE(sets, 2);
  EXPECT_GE(largest_set, 1u) << "a later keyframe gets the earlier ones";
}

TEST_F(DaemonStageSteps, AResetSurvivesAnEdgeThatDropsPacketsAndReachesStagesWhilePaused) {
  CaptureStep capture(*source_, /*heartbeat_period_ns=*/0, {});
  TrackingStep tracking(TrackingConfig::load(config_));
  Trace trace;
  tracking.setTrace([&](const StepTraceEntry& e) { trace.push_back(e); });

  // A live source's edge keeps the newest two packets: the first packet after the RESET is
  // evicted, and the reset still happens, at the next packet, which carries the same epoch.
  DropOldestQueue<CapturePacket> to_tracking(2);
  for (int i = 0; i < 3; ++i) to_tracking.push(*capture.process().item);
  capture.reset();
  std::vector<Utime> captured_after;
  for (int i = 0; i < 3; ++i) {
    CapturePacket packet = *capture.process().item;
    captured_after.push_back(packet.frame->utime);
    to_tracking.push(std::move(packet));
  }
  const std::vector<Utime> kept(captured_after.begin() + 1, captured_after.end());
  while (auto packet = to_tracking.tryPop()) tracking.process(std::move(*packet));
  ASSERT_EQ(trace.size(), 2u);
  for (std::size_t i = 0; i < trace.size(); ++i) {
    EXPECT_EQ(trace[i].utime, kept[i]);
    EXPECT_EQ(trace[i].reset_epoch, 1u);
    EXPECT_EQ(trace[i].resets, 1u);
  }

  // Paused, a recording sends heartbeats: a RESET rides on the next one.
  capture.pause();
  capture.reset();
  SourceStep<CapturePacket> heartbeat = capture.process();
  ASSERT_EQ(heartbeat.kind, SourceStep<CapturePacket>::Kind::kItem);
  EXPECT_TRUE(heartbeat.item->isHeartbeat());
  EXPECT_EQ(heartbeat.item->reset_epoch, 2u);
  tracking.process(*heartbeat.item);
  EXPECT_EQ(tracking.resets(), 2u);

  // A packet from before the last reset (which FIFO edges never deliver) is refused, not
  // processed.
  const std::size_t traced = trace.size();
  EXPECT_FALSE(tracking.process(CapturePacket{nullptr, 1}).has_value());
  EXPECT_EQ(tracking.stalePackets(), 1u);
  EXPECT_EQ(trace.size(), traced);
}

// The same steps on the daemon's threads: a RESET issued while frames are queued at every stage.
TEST_F(DaemonStageSteps, OnThreadsEveryStageResetsAtTheSamePointOfTheStream) {
  Config config = smallSyntheticConfig(40);
  std::unique_ptr<FrameSource> source = createFrameSource("synthetic:room", config);
  source->open();
  const FilterConfig filter_config = FilterConfig::load(config);
  const MappingConfig mapping_config = MappingConfig::load(config);
  Mapper mapper(mapping_config);
  RecordingPublisher publisher;
  VanishingPointChannel vanishing_points;
  CaptureStep capture(*source, 1'000'000'000, {});
  TrackingStep tracking(TrackingConfig::load(config));
  VanishingPointStep vanishing(filter_config, vanishing_points);
  FilterStep filter(filter_config, &vanishing_points, std::chrono::seconds(2));
  PublishStep publish(publisher, "world", "camera", nullptr);
  MappingStep mapping(mapper, mapping_config, publisher, nullptr, nullptr);
  // Each trace is written by its stage's thread only and read after the threads joined.
  Trace tracking_trace, vanishing_trace, filter_trace, publish_trace, mapping_trace;
  std::atomic<int> published{0};
  tracking.setTrace([&](const StepTraceEntry& e) { tracking_trace.push_back(e); });
  vanishing.setTrace([&](const StepTraceEntry& e) { vanishing_trace.push_back(e); });
  filter.setTrace([&](const StepTraceEntry& e) { filter_trace.push_back(e); });
  publish.setTrace([&](const StepTraceEntry& e) {
    publish_trace.push_back(e);
    published.fetch_add(1);
  });
  mapping.setTrace([&](const StepTraceEntry& e) { mapping_trace.push_back(e); });

  // Small queues: capture cannot run far ahead, so the RESET lands in the middle of the stream.
  const EdgeOptions edge{2, EdgePolicy::kBackpressure};
  Pipeline pipeline(PipelineMode::kThreaded);
  auto captured = pipeline.addSource<CapturePacket>("capture", [&] { return capture.process(); });
  auto tracked = pipeline.addStage<CapturePacket, TrackedPacket>(
      "tracking", captured, edge, [&](CapturePacket p) { return tracking.process(std::move(p)); });
  pipeline.addSink<CapturePacket>("vanishing", captured, edge,
                                  [&](CapturePacket p) { vanishing.process(std::move(p)); });
  auto estimated = pipeline.addStage<TrackedPacket, EstimatedPacket>(
      "filter", tracked, edge, [&](TrackedPacket p) { return filter.process(std::move(p)); });
  pipeline.addSink<EstimatedPacket>("publish", estimated, edge,
                                    [&](EstimatedPacket p) { publish.process(std::move(p)); });
  pipeline.addSink<EstimatedPacket>("mapping", estimated, edge,
                                    [&](EstimatedPacket p) { mapping.process(p); });
  pipeline.start();
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(300);
  while (published.load() < 10 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  capture.reset();  // the control thread's RESET
  ASSERT_TRUE(pipeline.waitUntilFinished(deadline));
  pipeline.stop(std::chrono::seconds(2));

  // Where the RESET landed: the first frame capture stamped with the new epoch.
  const auto first_after = std::find_if(tracking_trace.begin(), tracking_trace.end(),
                                        [](const StepTraceEntry& e) { return e.reset_epoch == 1; });
  ASSERT_NE(first_after, tracking_trace.end()) << "capture had finished before the RESET";
  std::vector<Utime> before, after;
  for (const StepTraceEntry& e : tracking_trace) {
    if (e.utime >= 0) (e.reset_epoch == 0 ? before : after).push_back(e.utime);
  }
  EXPECT_GE(before.size(), 10u);
  EXPECT_EQ(before.size() + after.size(), 40u);
  expectResetAtOnePointOfTheStream(tracking_trace, before, after, "tracking");
  expectResetAtOnePointOfTheStream(vanishing_trace, before, after, "vanishing");
  expectResetAtOnePointOfTheStream(filter_trace, before, after, "filter");
  expectResetAtOnePointOfTheStream(publish_trace, before, after, "publish");
  expectResetAtOnePointOfTheStream(mapping_trace, before, after, "mapping");
}

/// Voxels of `a` whose occupancy `b` does not share (unknown in b, or the other state).
std::size_t occupancyDisagreements(const octomap::OcTree& a, const octomap::OcTree& b) {
  std::size_t disagreements = 0;
  for (auto it = a.begin_leafs(); it != a.end_leafs(); ++it) {
    const octomap::OcTreeNode* other = b.search(it.getKey(), static_cast<unsigned>(it.getDepth()));
    if (other == nullptr || a.isNodeOccupied(*it) != b.isNodeOccupied(other)) ++disagreements;
  }
  return disagreements;
}

/// What the filter hands the mapping step: a tracked frame at T_world_camera, a keyframe when
/// keyframe_id is set.
EstimatedPacket mappingPacket(const RgbdFramePtr& frame, std::optional<std::int64_t> keyframe_id,
                              const SE3& T_world_camera) {
  EstimatedPacket p;
  p.frame = frame;
  p.odometry.emplace();
  p.odometry->utime = frame->utime;
  if (keyframe_id) {
    auto keyframe = std::make_shared<Keyframe>();
    keyframe->id = *keyframe_id;
    p.odometry->is_keyframe = true;
    p.odometry->keyframe = keyframe;
  }
  p.pose.utime = frame->utime;
  p.pose.T_world_camera = T_world_camera;
  p.pose.tracking_state = TrackingState::kOk;
  return p;
}

// Issue 24 item 3: keyframes mapped at drifted poses, then a back-end correction. The mapping
// step moves them a step at a time within its budget, never the whole map at once; with no
// room in any frame's budget, still a step every other frame. Once it has caught up, the map it
// publishes is the map of those keyframes at the corrected poses.
TEST_F(DaemonStageSteps,
       TheMapFollowsACorrectionAStepEveryOtherFrameAndThenMatchesTheCorrectedPoses) {
  config_.set("mapping.full_map_period_s", "0");
  config_.set("mapping.update_rate_hz", "0");
  config_.set("mapping.keyframe_step_budget_ms", "0.001");  // no room for a step in any frame
  MappingConfig mapping_config = MappingConfig::load(config_);
  mapping_config.keyframes_only = true;  // as the daemon sets it when the back end runs
  // The reference integrates the frames as measured: the step must too (no depth snapped onto
  // planes) for the two maps to be comparable voxel for voxel.
  mapping_config.planes_snap_depth = false;
  Mapper mapper(mapping_config);
  Mapper reference(mapping_config);
  RecordingPublisher publisher;
  SpscQueue<MapCorrection> map_corrections(4);
  MappingStep mapping(mapper, mapping_config, publisher, &map_corrections, nullptr);
  const Trajectory truth = *source_->groundTruth();

  BackendCorrection correction;
  std::vector<RgbdFramePtr> frames;
  for (int i = 0; i < kFrames; ++i) {
    const FrameRead read = source_->next(std::chrono::milliseconds(1000));
    ASSERT_EQ(read.status, FrameRead::Status::kFrame);
    frames.push_back(read.frame);
    const SE3& T_true = truth.at(static_cast<std::size_t>(i)).T_world_camera;
    SE3 drifted = T_true;
    drifted.translation() += static_cast<double>(i) * Eigen::Vector3d(0.02, -0.01, 0.03);
    drifted.linear() =
        Eigen::AngleAxisd(0.005 * i, Eigen::Vector3d::UnitY()).toRotationMatrix() * T_true.linear();
    mapping.process(mappingPacket(read.frame, i, drifted));
    reference.integrate(*read.frame, T_true, i);
    correction.keyframe_poses.emplace_back(i, T_true);
  }
  ASSERT_EQ(mapper.stats().keyframe_clouds, kFrames);
  // The keyframes went into the queue; a step every other frame has put only some in so far.
  EXPECT_GT(mapper.keyframesQueued(), 0u);
  mapper.catchUp(std::numeric_limits<double>::infinity());
  EXPECT_GT(occupancyDisagreements(*reference.ocTree(), *mapper.ocTree()), 1000u);

  ASSERT_TRUE(map_corrections.tryPush(MapCorrection{correction, 0}));
  // Frames that are not keyframes keep coming; each gives the step a little time.
  int frames_to_catch_up = 0;
  Utime utime = frames.back()->utime;
  auto laterFrame = [&] {
    auto frame = std::make_shared<RgbdFrame>(*frames.back());
    frame->utime = utime += 33'333;
    return frame;
  };
  do {
    mapping.process(mappingPacket(laterFrame(), std::nullopt, SE3::Identity()));
    ++frames_to_catch_up;
  } while (mapper.keyframesQueued() > 0 && frames_to_catch_up < 100);
  // Keyframe 0 did not drift; each part of the others is taken out, then put in: at least two
  // steps each, and with no room in any frame's budget a step every other frame, no more.
  EXPECT_GE(frames_to_catch_up, 2 * 2 * (kFrames - 1) - 1);
  EXPECT_GT(mapping.stats().catch_up_cycles_deferred, 0);
  EXPECT_LT(frames_to_catch_up, 100);
  EXPECT_EQ(mapper.stats().keyframes_moved, kFrames - 1);
  EXPECT_EQ(mapper.stats().frames_integrated, kFrames);  // the other frames were not mapped

  // The map published after catching up (a full map: voxels became unknown) is the map of the
  // keyframes at their corrected poses.
  mapping.process(mappingPacket(laterFrame(), std::nullopt, SE3::Identity()));
  ASSERT_FALSE(publisher.full_maps.empty());
  std::string why;
  const std::unique_ptr<octomap::OcTree> published =
      fullMapToOcTree(publisher.full_maps.back(), &why);
  ASSERT_NE(published, nullptr) << why;
  EXPECT_EQ(occupancyDisagreements(*reference.ocTree(), *published), 0u);
  EXPECT_EQ(occupancyDisagreements(*published, *reference.ocTree()), 0u);
}

// Issue 24 (mapping p99): a cycle that maps a keyframe (its planes and cloud) does not also
// put waiting parts in, publish an update or count voxels; the next frame, which maps nothing,
// does them in its budget. A second keyframe straight after still takes a step, so the map
// never stalls behind keyframes.
TEST_F(DaemonStageSteps, AKeyframesCycleLeavesCatchUpStepsAndTheUpdateToTheNextFrame) {
  config_.set("mapping.full_map_period_s", "0");
  config_.set("mapping.update_rate_hz", "1000");           // an update whenever something changed
  config_.set("mapping.keyframe_step_budget_ms", "1000");  // room for every step in other frames
  MappingConfig mapping_config = MappingConfig::load(config_);
  mapping_config.keyframes_only = true;
  Mapper mapper(mapping_config);
  RecordingPublisher publisher;
  MappingStep mapping(mapper, mapping_config, publisher, nullptr, nullptr);
  const Trajectory truth = *source_->groundTruth();
  std::vector<RgbdFramePtr> frames;
  for (int i = 0; i < 3; ++i) {
    const FrameRead read = source_->next(std::chrono::milliseconds(1000));
    ASSERT_EQ(read.status, FrameRead::Status::kFrame);
    frames.push_back(read.frame);
  }
  auto pose = [&](int i) { return truth.at(static_cast<std::size_t>(i)).T_world_camera; };

  mapping.process(mappingPacket(frames[0], 0, pose(0)));
  EXPECT_EQ(mapper.stats().keyframe_clouds, 1u);
  EXPECT_EQ(mapper.keyframesQueued(), 1u) << "its parts wait for the next frame";
  EXPECT_EQ(mapping.stats().catch_up_cycles_deferred, 1);
  EXPECT_EQ(publisher.updates + static_cast<int>(publisher.full_maps.size()), 0);

  // A frame that maps nothing puts the keyframe in; the next publishes it.
  mapping.process(mappingPacket(frames[1], std::nullopt, pose(1)));
  EXPECT_EQ(mapper.keyframesQueued(), 0u);
  mapping.process(mappingPacket(frames[2], std::nullopt, pose(2)));
  EXPECT_GT(publisher.updates + static_cast<int>(publisher.full_maps.size()), 0);

  // Two keyframes in a row: the first defers, the second takes a step anyway.
  mapping.process(mappingPacket(frames[1], 1, pose(1)));
  EXPECT_EQ(mapping.stats().catch_up_cycles_deferred, 2);
  mapping.process(mappingPacket(frames[2], 2, pose(2)));
  EXPECT_EQ(mapping.stats().catch_up_cycles_deferred, 2) << "the second keyframe's cycle stepped";
  EXPECT_LE(mapper.keyframesQueued(), 1u);
}

}  // namespace
}  // namespace slamd
