#include "slamd/mapping/mapper.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "box_room.hpp"
#include "keyframe_maps.hpp"
#include "scoped_temp_dir.hpp"
#include "slamd/mapping/map_io.hpp"
#include "test_data.hpp"

namespace slamd {
namespace {

using test::BoxRoom;
using test::expectSameVoxels;
using test::integrateDrifted;
using test::mapAt;

MappingConfig testConfig() {
  MappingConfig c;
  c.update_rate_hz = 0.0;
  c.full_map_period_s = 0.0;
  c.snapshot_period_s = 0.0;
  return c;
}

void buildRoom(Mapper& mapper, const BoxRoom& room, int yaw_steps = 8) {
  Utime utime = 1'000'000;
  for (const SE3& T : test::lookAroundPoses(yaw_steps)) {
    RgbdFrame frame = room.render(T);
    frame.utime = utime += 33'333;
    ASSERT_EQ(mapper.integrate(frame, T).status, IntegrationStatus::kOk);
  }
}

/// Fraction of `samples` points for which `predicate(occupancy)` holds.
template <typename Sampler, typename Predicate>
double fraction(const Mapper& mapper, int samples, Sampler sample, Predicate predicate) {
  int good = 0;
  for (int i = 0; i < samples; ++i) good += predicate(mapper.occupancyAt(sample())) ? 1 : 0;
  return static_cast<double>(good) / samples;
}

TEST(Mapper, SyntheticRoomHasOccupiedWallsFreeInteriorAndUnknownOutside) {
  const BoxRoom room;
  Mapper mapper(testConfig());
  buildRoom(mapper, room);
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> band(-0.3, 0.3);  // seen at every pitch
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  // Walls: points on the four vertical faces (x = +-2.02, z = -2.02 / 2.52) at eye height.
  const auto on_wall = [&]() {
    const int face = static_cast<int>(unit(rng) * 4);
    const double s = unit(rng);
    const double y = band(rng);
    if (face == 0) return Eigen::Vector3d(room.min_m.x(), y, -1.9 + 4.3 * s);
    if (face == 1) return Eigen::Vector3d(room.max_m.x(), y, -1.9 + 4.3 * s);
    if (face == 2) return Eigen::Vector3d(-1.9 + 3.8 * s, y, room.min_m.z());
    return Eigen::Vector3d(-1.9 + 3.8 * s, y, room.max_m.z());
  };
  const double walls = fraction(mapper, 2000, on_wall, [](int o) { return o == 1; });
  // Interior: at least 0.15 m inside the walls, 0.3..  m from the camera, at eye height.
  const auto inside = [&]() {
    while (true) {
      const Eigen::Vector3d p(-1.85 + 3.7 * unit(rng), band(rng), -1.85 + 4.2 * unit(rng));
      if (std::hypot(p.x(), p.z()) > 0.3) return p;
    }
  };
  const double interior = fraction(mapper, 2000, inside, [](int o) { return o == 0; });
  // Outside: 0.1 .. 1 m beyond a wall, floor or ceiling.
  const auto outside = [&]() {
    Eigen::Vector3d p(-2.0 + 4.0 * unit(rng), -1.2 + 2.2 * unit(rng), -2.0 + 4.5 * unit(rng));
    const int axis = static_cast<int>(unit(rng) * 3);
    const double beyond = 0.1 + 0.9 * unit(rng);
    p[axis] = unit(rng) < 0.5 ? room.min_m[axis] - beyond : room.max_m[axis] + beyond;
    return p;
  };
  const double unknown = fraction(mapper, 2000, outside, [](int o) { return o == -1; });
  EXPECT_GT(walls, 0.97) << "walls occupied";
  EXPECT_GT(interior, 0.97) << "interior free";
  EXPECT_EQ(unknown, 1.0) << "outside unknown";
  EXPECT_EQ(mapper.stats().frames_integrated, 24);
  EXPECT_EQ(mapper.stats().depth_nan, 0);
}

TEST(Mapper, DenseMaskInsertionGivesExactlyOctomapsResult) {
  const BoxRoom room;
  MappingConfig dense_config = testConfig();
  MappingConfig octomap_config = testConfig();
  octomap_config.insertion = InsertionMethod::kOctomap;
  Mapper dense(dense_config);
  Mapper reference(octomap_config);
  buildRoom(dense, room, 4);
  buildRoom(reference, room, 4);
  const octomap::OcTree& a = *dense.ocTree();
  const octomap::OcTree& b = *reference.ocTree();
  ASSERT_GT(a.getNumLeafNodes(), 10000u);
  std::size_t compared = 0;
  for (auto it = a.begin_leafs(); it != a.end_leafs(); ++it) {
    const octomap::OcTreeNode* other = b.search(it.getKey(), static_cast<unsigned>(it.getDepth()));
    ASSERT_NE(other, nullptr);
    ASSERT_FLOAT_EQ(it->getLogOdds(), other->getLogOdds());
    ++compared;
  }
  EXPECT_EQ(compared, b.getNumLeafNodes());
}

TEST(Mapper, InvalidDepthNeverReachesTheOcTree) {
  const BoxRoom room;
  const SE3 T = SE3::Identity();
  RgbdFrame clean = room.render(T);
  RgbdFrame dirty = clean;
  dirty.depth_m = clean.depth_m.clone();
  // Every other column invalid in one of five ways; the valid columns are untouched.
  const float bad[] = {std::numeric_limits<float>::quiet_NaN(), 0.0f, -1.0f,
                       std::numeric_limits<float>::infinity(),
                       -std::numeric_limits<float>::infinity()};
  for (int v = 0; v < dirty.depth_m.rows; ++v) {
    for (int u = 1; u < dirty.depth_m.cols; u += 2)
      dirty.depth_m.at<float>(v, u) = bad[(u / 2 + v) % 5];
  }
  RgbdFrame only_valid = clean;
  only_valid.depth_m = dirty.depth_m.clone();
  for (int v = 0; v < only_valid.depth_m.rows; ++v) {
    for (int u = 1; u < only_valid.depth_m.cols; u += 2) {
      only_valid.depth_m.at<float>(v, u) = std::numeric_limits<float>::quiet_NaN();
    }
  }
  Mapper a(testConfig());
  Mapper b(testConfig());
  const IntegrationResult ra = a.integrate(dirty, T);
  const IntegrationResult rb = b.integrate(only_valid, T);
  ASSERT_EQ(ra.status, IntegrationStatus::kOk);
  EXPECT_EQ(ra.depth.valid, 640 * 480 / 2);
  EXPECT_EQ(ra.depth.rejected(), 640 * 480 / 2);
  EXPECT_GT(ra.depth.nan, 0);
  EXPECT_GT(ra.depth.zero, 0);
  EXPECT_GT(ra.depth.negative, 0);
  EXPECT_GT(ra.depth.infinite, 0);
  EXPECT_EQ(a.stats().depth_nan + a.stats().depth_zero + a.stats().depth_negative +
                a.stats().depth_infinite,
            640 * 480 / 2);
  EXPECT_EQ(ra.occupied_voxels, rb.occupied_voxels);
  EXPECT_EQ(ra.free_voxels, rb.free_voxels);
  EXPECT_EQ(a.numLeafNodes(), b.numLeafNodes());

  // A frame with no valid depth at all changes nothing.
  Mapper c(testConfig());
  RgbdFrame empty = clean;
  empty.depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
  EXPECT_EQ(c.integrate(empty, T).status, IntegrationStatus::kNoPoints);
  empty.depth_m.setTo(0.0f);
  EXPECT_EQ(c.integrate(empty, T).status, IntegrationStatus::kNoPoints);
  EXPECT_EQ(c.numLeafNodes(), 0u);
  EXPECT_EQ(c.stats().frames_no_points, 2);
}

TEST(Mapper, BadFramesAndPosesAreRejectedAndCounted) {
  const BoxRoom room;
  Mapper mapper(testConfig());
  RgbdFrame frame = room.render(SE3::Identity());
  SE3 nan_pose = SE3::Identity();
  nan_pose.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(mapper.integrate(frame, nan_pose).status, IntegrationStatus::kBadPose);
  SE3 sheared = SE3::Identity();
  sheared.linear()(0, 1) = 0.5;
  EXPECT_EQ(mapper.integrate(frame, sheared).status, IntegrationStatus::kBadPose);
  SE3 far_away = SE3::Identity();
  far_away.translation() = Eigen::Vector3d(1e7, 0, 0);
  EXPECT_EQ(mapper.integrate(frame, far_away).status, IntegrationStatus::kBadPose);
  RgbdFrame wrong_type = frame;
  frame.depth_m.convertTo(wrong_type.depth_m, CV_16UC1, 1000.0);
  EXPECT_EQ(mapper.integrate(wrong_type, SE3::Identity()).status, IntegrationStatus::kBadFrame);
  RgbdFrame wrong_size = frame;
  wrong_size.depth_m = frame.depth_m(cv::Rect(0, 0, 320, 240)).clone();
  EXPECT_EQ(mapper.integrate(wrong_size, SE3::Identity()).status, IntegrationStatus::kBadFrame);
  PointCloud nan_cloud;
  nan_cloud.points = {{std::nanf(""), 0, 1}, {0, 0, std::numeric_limits<float>::infinity()}};
  EXPECT_EQ(mapper.integrateCloud(nan_cloud, SE3::Identity(), 0).status,
            IntegrationStatus::kNoPoints);
  EXPECT_EQ(mapper.numLeafNodes(), 0u);
  EXPECT_EQ(mapper.stats().frames_bad_pose, 3);
  EXPECT_EQ(mapper.stats().frames_bad_frame, 2);
  EXPECT_EQ(mapper.stats().frames_integrated, 0);
  // Colour of the wrong size is ignored, the depth still integrates.
  RgbdFrame odd_color = frame;
  odd_color.color_bgr = cv::Mat(10, 10, CV_8UC3);
  EXPECT_EQ(mapper.integrate(odd_color, SE3::Identity()).status, IntegrationStatus::kOk);
}

TEST(Mapper, RaysBeyondMaxRangeOnlyClearSpace) {
  MappingConfig config = testConfig();
  config.max_range_m = 1.0;
  config.voxel_filter_m = 0.0;
  Mapper mapper(config);
  PointCloud cloud;
  cloud.points = {{0.0f, 0.0f, 3.01f}};
  ASSERT_EQ(mapper.integrateCloud(cloud, SE3::Identity(), 0).status, IntegrationStatus::kOk);
  EXPECT_EQ(mapper.occupancyAt({0.0, 0.0, 0.52}), 0);
  EXPECT_EQ(mapper.occupancyAt({0.0, 0.0, 3.01}), -1);
  EXPECT_EQ(mapper.occupancyAt({0.0, 0.0, 2.0}), -1);
}

TEST(Mapper, AnUpdateWithNoVoxelsTakesNoSequenceNumber) {
  // New free voxels are not sent (update_new_free_voxels off), so an update holding only those
  // is empty and not sent: had it taken a number, subscribers would see a gap, count the next
  // updates as skipped and wait for a full map.
  MappingConfig config = testConfig();
  config.update_new_free_voxels = false;
  config.max_range_m = 1.0;
  config.voxel_filter_m = 0.0;
  Mapper mapper(config);
  PointCloud beyond_range;
  beyond_range.points = {{0.0f, 0.0f, 3.01f}};  // clears space only
  ASSERT_EQ(mapper.integrateCloud(beyond_range, SE3::Identity(), 0).status, IntegrationStatus::kOk);
  const MapUpdate nothing_to_send = mapper.takeUpdate();
  EXPECT_TRUE(nothing_to_send.voxels.empty());
  PointCloud wall;
  wall.points = {{0.1f, 0.0f, 0.8f}};
  ASSERT_EQ(mapper.integrateCloud(wall, SE3::Identity(), 1).status, IntegrationStatus::kOk);
  const MapUpdate first_sent = mapper.takeUpdate();
  EXPECT_FALSE(first_sent.voxels.empty());
  EXPECT_EQ(first_sent.sequence, 0);
  EXPECT_EQ(mapper.fullMap().update_sequence, 1);
}

TEST(Mapper, PollEmitsUpdatesAtTheConfiguredRateAndFullMapsOnRequest) {
  MappingConfig config = testConfig();
  config.update_rate_hz = 10.0;
  config.full_map_period_s = 1.0;
  Mapper mapper(config);
  const BoxRoom room;
  int updates = 0;
  int full_maps = 0;
  std::int64_t expected_sequence = 0;
  Utime utime = 1'000'000;
  for (const SE3& T : test::lookAroundPoses(8)) {
    RgbdFrame frame = room.render(T);
    frame.utime = utime += 33'333;
    mapper.integrate(frame, T);
    const MapperOutputs out = mapper.poll(frame.utime);
    if (out.update) {
      EXPECT_EQ(out.update->sequence, expected_sequence++);
      EXPECT_FALSE(out.update->voxels.empty());
      ++updates;
    }
    if (out.full_map) {
      EXPECT_EQ(out.full_map->update_sequence, expected_sequence);
      ++full_maps;
    }
  }
  // 24 frames over 0.8 s at 10 Hz: the first frame, then every third frame.
  EXPECT_GE(updates, 8);
  EXPECT_LE(updates, 9);
  EXPECT_EQ(full_maps, 0);
  mapper.requestFullMap();
  const MapperOutputs out = mapper.poll(utime);
  ASSERT_TRUE(out.full_map.has_value());
  EXPECT_GT(out.full_map->data.size(), 100u);
  EXPECT_FALSE(mapper.fullMapRequested());
}

TEST(Mapper, CorrectedKeyframesMoveAndTheMapEqualsMappingAtTheCorrectedPoses) {
  const BoxRoom room;
  const std::vector<SE3> truth = test::lookAroundPoses(4);
  const MappingConfig config = testConfig();
  Mapper corrected(config);
  std::vector<std::pair<std::int64_t, SE3>> poses = integrateDrifted(corrected, room, truth);
  poses.emplace_back(999, SE3::Identity());  // unknown id
  const std::int64_t sequence_before = corrected.nextUpdateSequence();
  const KeyframeCorrectionResult queued = corrected.correctKeyframePoses(poses);
  // Keyframe 0 did not drift in translation or rotation: it stays.
  EXPECT_EQ(queued.keyframes_to_move, truth.size() - 1);
  EXPECT_EQ(queued.unknown_ids, 1u);
  const CatchUpResult moved = corrected.catchUp(std::numeric_limits<double>::infinity());
  EXPECT_EQ(moved.keyframes_moved, truth.size() - 1);
  EXPECT_EQ(moved.keyframes_left, 0u);
  EXPECT_TRUE(moved.caught_up);
  // The drifted surfaces became unknown, which updates cannot say: a full map resynchronises.
  EXPECT_EQ(corrected.nextUpdateSequence(), sequence_before + 1);
  EXPECT_TRUE(corrected.fullMapRequested());
  // Moving is not new data.
  EXPECT_EQ(corrected.stats().frames_integrated, static_cast<std::int64_t>(truth.size()));
  EXPECT_EQ(corrected.stats().keyframes_moved, static_cast<std::int64_t>(truth.size()) - 1);

  const std::unique_ptr<Mapper> reference = mapAt(room, truth, config);
  expectSameVoxels(*corrected.ocTree(), *reference->ocTree());
  // Nothing left to do: a second identical correction queues nothing.
  EXPECT_EQ(corrected.correctKeyframePoses(poses).keyframes_to_move, 0u);
  EXPECT_FALSE(corrected.catchUp(1.0).caught_up);
}

TEST(Mapper, KeyframesMoveWithinTheBudgetFarthestFirstAndFollowNewerCorrections) {
  const BoxRoom room;
  const std::vector<SE3> truth = test::lookAroundPoses(8);  // 24 overlapping views
  MappingConfig config = testConfig();
  config.keyframe_step_points = 10'000'000;  // each keyframe in one part: two steps per move
  Mapper corrected(config);
  const std::vector<std::pair<std::int64_t, SE3>> poses = integrateDrifted(corrected, room, truth);
  ASSERT_EQ(corrected.correctKeyframePoses(poses).keyframes_to_move, truth.size() - 1);
  // No budget, no work.
  EXPECT_EQ(corrected.catchUp(0.0).keyframes_moved, 0u);
  EXPECT_EQ(corrected.keyframesQueued(), truth.size() - 1);
  // A tiny budget still does one step per call: taking the farthest (the last keyframe) out,
  // then putting it in.
  constexpr double kTinyBudgetS = 1e-9;
  CatchUpResult step = corrected.catchUp(kTinyBudgetS);
  EXPECT_EQ(step.keyframes_moved, 0u);
  EXPECT_EQ(step.keyframes_left, truth.size() - 1);
  step = corrected.catchUp(kTinyBudgetS);
  EXPECT_EQ(step.keyframes_moved, 1u);
  EXPECT_EQ(step.keyframes_left, truth.size() - 2);
  EXPECT_FALSE(step.caught_up);
  // Partway, a newer correction moves every keyframe again (0.1 m along x): each one, moved
  // already or not, moves once more, to its newest pose.
  for (int i = 0; i < 21; ++i) corrected.catchUp(kTinyBudgetS);  // 10.5 moves
  std::vector<SE3> final_poses = truth;
  std::vector<std::pair<std::int64_t, SE3>> newer = poses;
  for (std::size_t i = 0; i < newer.size(); ++i) {
    final_poses[i].translation().x() += 0.1;
    newer[i].second = final_poses[i];
  }
  const KeyframeCorrectionResult queued = corrected.correctKeyframePoses(newer);
  EXPECT_EQ(queued.keyframes_to_move, truth.size());
  std::size_t moves = 0;
  std::size_t calls = 0;
  while (corrected.keyframesQueued() > 0 && calls < 1000) {
    step = corrected.catchUp(kTinyBudgetS);
    moves += step.keyframes_moved;
    ++calls;
  }
  EXPECT_EQ(moves, truth.size());
  // Two steps per keyframe, less the one taken out before the newer correction came.
  EXPECT_EQ(calls, 2 * truth.size() - 1);
  EXPECT_TRUE(step.caught_up);
  const std::unique_ptr<Mapper> reference = mapAt(room, truth, config, final_poses);
  expectSameVoxels(*corrected.ocTree(), *reference->ocTree());
}

TEST(Mapper, QueuedKeyframesGoInAPartAStepAndEqualKeyframesIntegratedAtOnce) {
  const BoxRoom room;
  const std::vector<SE3> truth = test::lookAroundPoses(4);
  MappingConfig config = testConfig();
  config.keyframe_step_points = 1500;
  Mapper at_once(config);
  Mapper queued(config);
  int parts = 0;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const RgbdFrame frame = room.render(truth[i]);
    const auto id = static_cast<std::int64_t>(i);
    at_once.integrate(frame, truth[i], id);
    const IntegrationResult added = queued.addKeyframe(frame, truth[i], id);
    ASSERT_TRUE(added.keyframe_cloud_kept);
    parts += static_cast<int>((added.points_filtered + 1499) / 1500);
  }
  ASSERT_GT(parts, static_cast<int>(2 * truth.size()));  // several parts per keyframe
  EXPECT_EQ(queued.numLeafNodes(), 0u);                  // nothing in the map before catchUp
  EXPECT_EQ(queued.stats().frames_integrated, static_cast<std::int64_t>(truth.size()));
  int steps = 0;
  CatchUpResult step;
  while (queued.keyframesQueued() > 0 && steps < 10000) {
    step = queued.catchUp(1e-9);
    ASSERT_EQ(step.steps, 1u);
    ++steps;
  }
  EXPECT_EQ(steps, parts);
  EXPECT_TRUE(step.caught_up);
  expectSameVoxels(*queued.ocTree(), *at_once.ocTree());

  // Moved in parts, they still equal the map at the corrected poses.
  std::vector<std::pair<std::int64_t, SE3>> corrected;
  std::vector<SE3> corrected_poses;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    SE3 T = truth[i];
    T.translation() += Eigen::Vector3d(0.07, -0.04, 0.11);
    corrected.emplace_back(static_cast<std::int64_t>(i), T);
    corrected_poses.push_back(T);
  }
  EXPECT_EQ(queued.correctKeyframePoses(corrected).keyframes_to_move, truth.size());
  steps = 0;
  while (queued.keyframesQueued() > 0 && steps < 10000) {
    queued.catchUp(1e-9);
    ++steps;
  }
  EXPECT_EQ(steps, 2 * parts);
  EXPECT_EQ(queued.stats().keyframes_moved, static_cast<std::int64_t>(truth.size()));
  const std::unique_ptr<Mapper> reference = mapAt(room, truth, config, corrected_poses);
  expectSameVoxels(*queued.ocTree(), *reference->ocTree());
}

TEST(Mapper, ACorrectionUnderHalfAVoxelLeavesTheKeyframeWhereItIs) {
  const BoxRoom room;
  const MappingConfig config = testConfig();
  Mapper mapper(config);
  const SE3 T = SE3::Identity();
  ASSERT_TRUE(mapper.integrate(room.render(T), T, 7).keyframe_cloud_kept);
  SE3 nudged = T;
  nudged.translation().x() += 0.2 * config.resolution_m;
  EXPECT_EQ(mapper.correctKeyframePoses({{7, nudged}}).keyframes_to_move, 0u);
  // A rotation moves far points most: 0.6 degrees at the room's far corners (3.4 m) moves them
  // by 3.6 cm, over half a 5 cm voxel.
  SE3 turned = T;
  turned.linear() = Eigen::AngleAxisd(0.6 * M_PI / 180.0, Eigen::Vector3d::UnitY()).matrix();
  EXPECT_EQ(mapper.correctKeyframePoses({{7, turned}}).keyframes_to_move, 1u);
  // Small corrections add up: the distance counts from where the keyframe is in the map.
  SE3 twice = T;
  twice.translation().x() += 0.6 * config.resolution_m;
  EXPECT_EQ(mapper.correctKeyframePoses({{7, twice}}).keyframes_to_move, 1u);
  // Bad poses are refused.
  SE3 bad = T;
  bad.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(mapper.correctKeyframePoses({{7, bad}}).unknown_ids, 1u);
}

TEST(Mapper, AForgottenKeyframeLeavesTheMapAsIfItHadNeverBeenThere) {
  const BoxRoom room;
  const MappingConfig config = testConfig();
  const std::vector<SE3> views = test::lookAroundPoses(4);
  Mapper mapper(config);
  Mapper without(config);
  for (std::size_t i = 0; i < views.size(); ++i) {
    const RgbdFrame frame = room.render(views[i]);
    mapper.integrate(frame, views[i], static_cast<std::int64_t>(i));
    if (i != 4) without.integrate(frame, views[i], static_cast<std::int64_t>(i));
  }
  mapper.forgetKeyframe(4);
  EXPECT_EQ(mapper.stats().keyframe_clouds, static_cast<std::int64_t>(views.size()) - 1);
  EXPECT_EQ(mapper.stats().keyframes_taken_out, 1);
  expectSameVoxels(*mapper.ocTree(), *without.ocTree());
  // Taking every keyframe out leaves an empty map.
  for (const std::int64_t id : mapper.keptKeyframeIds()) mapper.forgetKeyframe(id);
  EXPECT_EQ(mapper.numLeafNodes(), 0u);
  EXPECT_TRUE(mapper.keptKeyframeIds().empty());
  // Integrating an id again replaces its contribution instead of adding a second one, at once
  // or through the queue.
  Mapper twice(config);
  Mapper once(config);
  twice.integrate(room.render(views[1]), views[0], 3);
  twice.integrate(room.render(views[0]), views[0], 3);
  once.integrate(room.render(views[0]), views[0], 3);
  expectSameVoxels(*twice.ocTree(), *once.ocTree());
  Mapper queued_twice(config);
  queued_twice.addKeyframe(room.render(views[1]), views[0], 3);
  queued_twice.catchUp(1e-9);  // one part of the first cloud in
  queued_twice.addKeyframe(room.render(views[0]), views[0], 3);
  queued_twice.catchUp(std::numeric_limits<double>::infinity());
  EXPECT_EQ(queued_twice.keyframesQueued(), 0u);
  expectSameVoxels(*queued_twice.ocTree(), *once.ocTree());
}

// holdKeyframe (a run not yet localised in a loaded map): the cloud waits out of the map, goes in
// at the pose a correction gives it, and is dropped, not put in at once, when it cannot be kept.
TEST(Mapper, AHeldKeyframeGoesInAtItsCorrectedPoseOrNotAtAll) {
  const BoxRoom room;
  const MappingConfig config = testConfig();
  const std::vector<SE3> views = test::lookAroundPoses(4);
  ASSERT_GE(views.size(), 2u);
  const RgbdFrame frame = room.render(views[1]);
  SE3 wrong = views[1];  // the pose in the run's own frame, before the correction
  wrong.translation().x() += 0.5;

  Mapper held(config);
  const IntegrationResult kept = held.holdKeyframe(frame, wrong, 7);
  EXPECT_TRUE(kept.keyframe_cloud_kept);
  EXPECT_EQ(held.countVoxels().leaves, 0u) << "a held keyframe went into the map";
  held.correctKeyframePoses({{7, views[1]}});
  held.catchUp(std::numeric_limits<double>::infinity());
  Mapper reference(config);
  reference.integrate(frame, views[1]);
  expectSameVoxels(*held.ocTree(), *reference.ocTree());

  Mapper pressed(config);
  pressed.setMemoryPressure(MemoryPressure::kNear);
  const IntegrationResult dropped = pressed.holdKeyframe(frame, wrong, 7);
  EXPECT_FALSE(dropped.keyframe_cloud_kept);
  pressed.catchUp(std::numeric_limits<double>::infinity());
  EXPECT_EQ(pressed.countVoxels().leaves, 0u) << "a keyframe that could not be held went in";
  // addKeyframe under the same pressure puts it in at once (the daemon's normal path).
  pressed.addKeyframe(frame, wrong, 8);
  EXPECT_GT(pressed.countVoxels().leaves, 0u);
}

// daemon.memory_limit_mb: under pressure no new keyframe cloud is kept (it goes in at once), and
// releasing clouds keeps the newest ones; neither changes the map.
TEST(Mapper, UnderMemoryPressureCloudsAreNotKeptOrAreReleasedAndTheMapStaysTheSame) {
  const BoxRoom room;
  const MappingConfig config = testConfig();
  const std::vector<SE3> views = test::lookAroundPoses(4);
  ASSERT_GE(views.size(), 6u);
  Mapper pressed(config);
  Mapper normal(config);
  for (std::size_t i = 0; i < views.size(); ++i) {
    const RgbdFrame frame = room.render(views[i]);
    // The first two keyframes come before the pressure, the others under it.
    if (i == 2) pressed.setMemoryPressure(MemoryPressure::kNear);
    pressed.addKeyframe(frame, views[i], static_cast<std::int64_t>(i));
    normal.addKeyframe(frame, views[i], static_cast<std::int64_t>(i));
  }
  pressed.catchUp(std::numeric_limits<double>::infinity());
  normal.catchUp(std::numeric_limits<double>::infinity());
  EXPECT_EQ(pressed.keptKeyframeIds(), (std::vector<std::int64_t>{0, 1}));
  EXPECT_EQ(pressed.stats().keyframe_clouds_refused, static_cast<std::int64_t>(views.size()) - 2);
  expectSameVoxels(*pressed.ocTree(), *normal.ocTree());

  // Releasing keeps the newest clouds; a cloud with a move still queued is not released.
  const std::int64_t bytes_before = normal.stats().keyframe_cloud_bytes;
  SE3 moved = views[0];
  moved.translation().x() += 0.2;
  normal.correctKeyframePoses({{0, moved}});
  ASSERT_EQ(normal.keyframesQueued(), 1u);
  EXPECT_EQ(normal.releaseKeyframeClouds(2), views.size() - 3);
  std::vector<std::int64_t> expected_kept{0};
  for (std::size_t i = views.size() - 2; i < views.size(); ++i) {
    expected_kept.push_back(static_cast<std::int64_t>(i));
  }
  EXPECT_EQ(normal.keptKeyframeIds(), expected_kept);
  EXPECT_EQ(normal.stats().keyframe_clouds_released, static_cast<std::int64_t>(views.size()) - 3);
  EXPECT_LT(normal.stats().keyframe_cloud_bytes, bytes_before);
  Mapper reference(config);
  for (std::size_t i = 0; i < views.size(); ++i) {
    reference.integrate(room.render(views[i]), views[i], static_cast<std::int64_t>(i));
  }
  expectSameVoxels(*normal.ocTree(), *reference.ocTree());
  // A released keyframe can no longer be moved: its correction names an unknown id.
  EXPECT_EQ(normal.correctKeyframePoses({{1, moved}}).unknown_ids, 1u);
}

// daemon.memory_limit_mb, over the limit: the map far from the camera is made coarser. Along a
// 21 m corridor mapped every metre, with a kept keyframe near its start (its reach, 2 to 6 m
// along, stays fine) and the camera at its far end, sampled every 10 cm in and around the corridor
// against the same map left fine.
TEST(Mapper, OverTheMemoryLimitTheMapFarFromTheCameraIsMadeCoarser) {
  BoxRoom corridor;
  corridor.min_m = Eigen::Vector3d(-1.02, -1.22, -1.02);
  corridor.max_m = Eigen::Vector3d(1.02, 1.02, 20.02);
  const Eigen::Vector3d camera_m(0.0, 0.0, 19.0);
  const Eigen::Vector3d kept_camera_m(0.0, 0.0, 2.0);
  for (const bool color : {false, true}) {
    SCOPED_TRACE(color ? "ColorOcTree" : "OcTree");
    MappingConfig config = testConfig();
    config.color = color;
    config.pixel_stride = 4;
    config.coarse_far_radius_m = 5.0;
    config.coarse_far_levels = 2;
    const auto build = [&](Mapper& mapper) {
      Utime utime = 1'000'000;
      for (int z = 0; z <= 19; ++z) {
        for (const double yaw : {0.0, M_PI}) {
          SE3 T = SE3::Identity();
          T.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()).toRotationMatrix();
          T.translation() = Eigen::Vector3d(0.0, 0.0, z);
          RgbdFrame frame = corridor.render(T);
          frame.utime = utime += 33'333;
          if (T.translation() == kept_camera_m && yaw == 0.0) {
            mapper.addKeyframe(frame, T, 1);
          } else {
            ASSERT_EQ(mapper.integrate(frame, T).status, IntegrationStatus::kOk);
          }
        }
      }
      mapper.catchUp(std::numeric_limits<double>::infinity());
    };
    Mapper fine(config);
    Mapper coarse(config);
    build(fine);
    build(coarse);
    ASSERT_EQ(coarse.keptKeyframeIds(), (std::vector<std::int64_t>{1}));
    const std::size_t nodes_before =
        coarse.ocTree() ? coarse.ocTree()->size() : coarse.colorOcTree()->size();
    const std::size_t bytes_before = coarse.memoryBytes();
    const std::int64_t sequence_before = coarse.nextUpdateSequence();

    const CoarsenResult result = coarse.coarsenFarMap(camera_m);
    const std::size_t nodes_after =
        coarse.ocTree() ? coarse.ocTree()->size() : coarse.colorOcTree()->size();
    EXPECT_GT(result.blocks_merged, 0u);
    EXPECT_EQ(result.nodes_removed, nodes_before - nodes_after);
    EXPECT_LT(nodes_after, nodes_before * 2 / 3) << "of " << nodes_before << " nodes";
    EXPECT_LT(coarse.memoryBytes(), bytes_before);
    EXPECT_EQ(coarse.stats().far_map_coarsenings, 1);
    EXPECT_EQ(coarse.stats().far_map_blocks_merged,
              static_cast<std::int64_t>(result.blocks_merged));
    // Updates cannot say that voxels merged: subscribers resynchronise from a full map.
    EXPECT_TRUE(coarse.fullMapRequested());
    EXPECT_GT(coarse.nextUpdateSequence(), sequence_before);
    // Everything far was merged at once: a second call finds nothing more.
    EXPECT_EQ(coarse.coarsenFarMap(camera_m).blocks_merged, 0u);
    std::printf(
        "corridor map (%s): %zu -> %zu nodes, %zu -> %zu bytes, %zu blocks merged in "
        "%.1f ms\n",
        color ? "colour" : "no colour", nodes_before, nodes_after, bytes_before,
        coarse.memoryBytes(), result.blocks_merged, 1e3 * result.seconds);

    // Merged blocks of 4x4x4 voxels exist, and merged occupied ones keep a colour.
    const double resolution = config.resolution_m;
    std::size_t coarse_leaves = 0;
    std::size_t coarse_coloured = 0;
    if (color) {
      const octomap::ColorOcTree& tree = *coarse.colorOcTree();
      for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
        if (it.getSize() < 3.5 * resolution || !tree.isNodeOccupied(*it)) continue;
        ++coarse_leaves;
        if (it->isColorSet()) ++coarse_coloured;
      }
      EXPECT_EQ(coarse_coloured, coarse_leaves);
    } else {
      const octomap::OcTree& tree = *coarse.ocTree();
      for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
        if (it.getSize() > 3.5 * resolution && tree.isNodeOccupied(*it)) ++coarse_leaves;
      }
    }
    EXPECT_GT(coarse_leaves, 0u);

    // Sampled at voxel centres every 10 cm: occupied stays occupied, known stays known, unknown
    // never becomes free; near the camera and where the kept keyframe's rays went, nothing
    // changed.
    const auto log_odds_at = [](Mapper& mapper, const Eigen::Vector3d& p) {
      const auto search = [&p](const auto& tree) -> std::optional<float> {
        const auto* node = tree.search(p.x(), p.y(), p.z());
        if (node == nullptr) return std::nullopt;
        return node->getLogOdds();
      };
      return mapper.ocTree() ? search(*mapper.ocTree()) : search(*mapper.colorOcTree());
    };
    std::size_t samples = 0;
    std::size_t lost_occupied = 0;
    std::size_t lost_known = 0;
    std::size_t unknown_made_free = 0;
    std::size_t near_changed = 0;
    std::size_t kept_changed = 0;
    std::size_t far_changed = 0;
    const double step = 2.0 * resolution;
    for (double x = -1.325; x < 1.3; x += step) {
      for (double y = -1.525; y < 1.3; y += step) {
        for (double z = -1.325; z < 20.3; z += step) {
          const Eigen::Vector3d p(x, y, z);
          const int before = fine.occupancyAt(p);
          const int after = coarse.occupancyAt(p);
          ++samples;
          if (before == 1 && after != 1) ++lost_occupied;
          if (before != -1 && after == -1) ++lost_known;
          if (before == -1 && after == 0) ++unknown_made_free;
          const bool near = (p - camera_m).norm() < config.coarse_far_radius_m;
          const bool in_kept_reach = z > 1.9 && z < 6.1;
          if (log_odds_at(fine, p) != log_odds_at(coarse, p)) {
            if (near) {
              ++near_changed;
            } else if (in_kept_reach) {
              ++kept_changed;
            } else {
              ++far_changed;
            }
          }
        }
      }
    }
    EXPECT_EQ(lost_occupied, 0u) << "of " << samples;
    EXPECT_EQ(lost_known, 0u);
    EXPECT_EQ(unknown_made_free, 0u);
    EXPECT_EQ(near_changed, 0u);
    EXPECT_EQ(kept_changed, 0u);
    EXPECT_GT(far_changed, 0u);

    // The kept keyframe still comes out exactly: its reach is what the fine map's is without it.
    fine.forgetKeyframe(1);
    coarse.forgetKeyframe(1);
    std::size_t taken_out_differs = 0;
    for (double x = -1.325; x < 1.3; x += step) {
      for (double y = -1.525; y < 1.3; y += step) {
        for (double z = 1.925; z < 6.1; z += step) {
          const Eigen::Vector3d p(x, y, z);
          if (log_odds_at(fine, p) != log_odds_at(coarse, p)) ++taken_out_differs;
        }
      }
    }
    EXPECT_EQ(taken_out_differs, 0u);
  }
}

TEST(Mapper, KeyframesForgottenInStepsGoFirstAndLeaveNothingBehind) {
  const BoxRoom room;
  const MappingConfig config = testConfig();
  const std::vector<SE3> truth = test::lookAroundPoses(4);
  Mapper mapper(config);
  std::vector<std::pair<std::int64_t, SE3>> poses = integrateDrifted(mapper, room, truth);
  mapper.correctKeyframePoses(poses);
  const std::size_t to_move = mapper.keyframesQueued();
  mapper.forgetKeyframeInSteps(5);
  mapper.forgetKeyframeInSteps(5);  // once is enough
  EXPECT_EQ(mapper.keyframesQueued(), to_move + 1);
  // The first steps take its parts out and forget it, before any move; a later correction no
  // longer moves it.
  const std::int64_t sequence_before = mapper.nextUpdateSequence();
  const auto kept = [&mapper](std::int64_t id) {
    const std::vector<std::int64_t> ids = mapper.keptKeyframeIds();
    return std::find(ids.begin(), ids.end(), id) != ids.end();
  };
  int steps = 0;
  while (kept(5) && steps < 100) {
    EXPECT_EQ(mapper.catchUp(1e-9).keyframes_moved, 0u);
    ++steps;
  }
  EXPECT_GE(steps, 2);  // its parts, then the forgetting
  EXPECT_EQ(mapper.stats().keyframes_taken_out, 1);
  EXPECT_EQ(mapper.correctKeyframePoses(poses).unknown_ids, 1u);
  mapper.catchUp(std::numeric_limits<double>::infinity());
  EXPECT_EQ(mapper.nextUpdateSequence(), sequence_before + 1);
  Mapper reference(config);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (i != 5) reference.integrate(room.render(truth[i]), truth[i], static_cast<std::int64_t>(i));
  }
  expectSameVoxels(*mapper.ocTree(), *reference.ocTree());
}

TEST(Mapper, WithoutKeptKeyframeCloudsTheLogOddsAreClamped) {
  MappingConfig config = testConfig();
  config.keep_keyframe_clouds = false;
  Mapper mapper(config);
  const BoxRoom room;
  const RgbdFrame frame = room.render(SE3::Identity());
  for (int i = 0; i < 20; ++i) mapper.integrate(frame, SE3::Identity(), i);
  EXPECT_EQ(mapper.stats().keyframe_clouds, 0);
  const octomap::OcTree& tree = *mapper.ocTree();
  float largest = 0.0f;
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    largest = std::max(largest, std::abs(it->getLogOdds()));
  }
  EXPECT_LE(largest, octomap::logodds(config.clamp_max) + 1e-4f);
  Mapper unclamped(testConfig());
  for (int i = 0; i < 20; ++i) unclamped.integrate(frame, SE3::Identity(), 100 + i);
  float unclamped_largest = 0.0f;
  const octomap::OcTree& other = *unclamped.ocTree();
  for (auto it = other.begin_leafs(); it != other.end_leafs(); ++it) {
    unclamped_largest = std::max(unclamped_largest, std::abs(it->getLogOdds()));
  }
  EXPECT_GT(unclamped_largest, 20 * 0.8f);  // 20 hits of logodds(0.7) = 0.85
}

TEST(Mapper, KeyframeCloudsRespectTheMemoryBudget) {
  MappingConfig config = testConfig();
  config.keyframe_cloud_budget_mb = 1;  // a 5 cm filtered frame is ~100-300 kB
  Mapper mapper(config);
  const BoxRoom room;
  int kept = 0;
  const RgbdFrame frame = room.render(SE3::Identity());
  for (int i = 0; i < 40; ++i) {
    kept += mapper.integrate(frame, SE3::Identity(), i).keyframe_cloud_kept;
  }
  EXPECT_GT(kept, 0);
  EXPECT_LT(kept, 40);
  EXPECT_EQ(mapper.stats().keyframe_clouds_refused, 40 - kept);
  EXPECT_LE(mapper.stats().keyframe_cloud_bytes, 1 << 20);
}

TEST(Mapper, ProjectionShowsWallsAsObstaclesAroundFreeFloorSpace) {
  const BoxRoom room;
  Mapper mapper(testConfig());
  buildRoom(mapper, room);
  // World = first camera frame, y down: up is -y, so height = -y. Band around eye height.
  const OccupancyGrid2D grid = mapper.projectToGrid(UpAxis::kMinusY, -0.3, 0.3);
  ASSERT_FALSE(grid.cells.empty());
  // (u, v, up) = (x, z, -y): u = x, v = z.
  EXPECT_EQ(grid.at(room.max_m.x(), 0.3), OccupancyGrid2D::kOccupied);
  EXPECT_EQ(grid.at(room.min_m.x(), -0.7), OccupancyGrid2D::kOccupied);
  EXPECT_EQ(grid.at(0.4, room.max_m.z()), OccupancyGrid2D::kOccupied);
  EXPECT_EQ(grid.at(1.0, 1.0), OccupancyGrid2D::kFree);
  EXPECT_EQ(grid.at(-1.2, -1.3), OccupancyGrid2D::kFree);
  EXPECT_EQ(grid.at(3.0, 0.0), OccupancyGrid2D::kUnknown);
  EXPECT_NEAR(grid.origin_u_m, -2.05, 1e-9);
  EXPECT_NEAR(grid.origin_v_m, -2.05, 1e-9);
  const test::ScopedTempDir dir("grid");
  std::string error;
  ASSERT_TRUE(saveOccupancyGrid(grid, (dir / "room.pgm").string(), &error)) << error;
  ASSERT_TRUE(saveOccupancyGrid(grid, (dir / "room.png").string(), &error)) << error;
  const cv::Mat pgm = cv::imread((dir / "room.pgm").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(pgm.size(), grid.cells.size());
  EXPECT_TRUE(std::filesystem::exists(dir / "room.yaml"));
}

TEST(Mapper, PlyExportsHoldEveryOccupiedVoxelWithColour) {
  MappingConfig config = testConfig();
  config.color = true;
  Mapper mapper(config);
  const BoxRoom room;
  for (int i = 0; i < 3; ++i) {
    const SE3 T = test::lookAroundPoses(4)[static_cast<std::size_t>(i)];
    mapper.integrate(room.render(T), T, i);
  }
  ASSERT_TRUE(mapper.hasColor());
  const PointCloud occupied = mapper.occupiedCloud();
  ASSERT_GT(occupied.size(), 1000u);
  const test::ScopedTempDir dir("ply");
  for (const PlyFormat format : {PlyFormat::kAscii, PlyFormat::kBinary}) {
    const std::string path = (dir / "map.ply").string();
    ASSERT_TRUE(mapper.exportOccupiedPly(path, format).ok);
    PointCloud back;
    ASSERT_TRUE(readPly(path, back));
    ASSERT_EQ(back.size(), occupied.size());
    EXPECT_NEAR(back.points[7].x(), occupied.points[7].x(), 1e-4f);
    EXPECT_EQ(back.colors_bgr[7], occupied.colors_bgr[7]);
  }
  // Voxel colours come from the rendered walls, not the white default.
  EXPECT_NE(occupied.colors_bgr[0], (ColorBgr{255, 255, 255}));
  const MapFileResult clouds =
      mapper.exportKeyframeCloudPly((dir / "kf.ply").string(), 0.05, PlyFormat::kBinary);
  ASSERT_TRUE(clouds.ok) << clouds.error;
  PointCloud kf;
  ASSERT_TRUE(readPly((dir / "kf.ply").string(), kf));
  EXPECT_GT(kf.size(), 1000u);
}

}  // namespace
}  // namespace slamd
