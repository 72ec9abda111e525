// ViewerModel: what a page is sent, as a page would apply it.

#include "slamd/web/viewer_model.hpp"

#include <cstring>
#include <map>
#include <set>
#include <tuple>

#include <gtest/gtest.h>
#include <octomap/OcTree.h>

namespace slamd::web {
namespace {

using Key = std::tuple<int, int, int>;

/// A page's copy: applies messages as viewer.js does.
struct PageCopy {
  std::set<Key> voxels;
  std::vector<std::int64_t> trail_sequences;
  int resets = 0;
  int hellos = 0;
  std::string last_status;
  std::string last_keyframes;

  static std::uint32_t u32(const std::string& b, std::size_t at) {
    std::uint32_t v = 0;
    for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<std::uint8_t>(b[at + i]);
    return v;
  }
  static int u16(const std::string& b, std::size_t at) {
    return static_cast<std::uint8_t>(b[at]) | (static_cast<std::uint8_t>(b[at + 1]) << 8);
  }

  void apply(const OutgoingMessage& message) {
    if (message.kind == OutgoingMessage::Kind::kBinary) {
      const std::string& b = message.payload;
      ASSERT_GE(b.size(), kVoxelFrameHeaderBytes);
      const std::uint32_t kind = u32(b, 0);
      const std::uint32_t count = u32(b, 4);
      ASSERT_EQ(b.size(), kVoxelFrameHeaderBytes + count * kVoxelRecordBytes);
      if (kind == static_cast<std::uint32_t>(VoxelFrameKind::kReplace)) voxels.clear();
      for (std::uint32_t i = 0; i < count; ++i) {
        const std::size_t at = kVoxelFrameHeaderBytes + i * kVoxelRecordBytes;
        const Key key{u16(b, at), u16(b, at + 2), u16(b, at + 4)};
        if (u16(b, at + 6)) {
          voxels.insert(key);
        } else {
          voxels.erase(key);
        }
      }
      return;
    }
    const std::string& t = message.payload;
    if (t.find("\"type\":\"hello\"") != std::string::npos) {
      ++hellos;
      voxels.clear();
      trail_sequences.clear();
    } else if (t.find("\"type\":\"reset\"") != std::string::npos) {
      ++resets;
      voxels.clear();
      trail_sequences.clear();
    } else if (t.find("\"type\":\"trail\"") != std::string::npos ||
               t.find("\"type\":\"poses\"") != std::string::npos) {
      if (t.find("\"type\":\"trail\"") != std::string::npos) trail_sequences.clear();
      for (std::size_t at = t.find("\"seq\":"); at != std::string::npos;
           at = t.find("\"seq\":", at + 1)) {
        trail_sequences.push_back(std::stoll(t.substr(at + 6)));
      }
    } else if (t.find("\"type\":\"status\"") != std::string::npos) {
      last_status = t;
    } else if (t.find("\"type\":\"keyframes\"") != std::string::npos) {
      last_keyframes = t;
    }
  }
  void apply(const std::vector<OutgoingMessage>& messages) {
    for (const OutgoingMessage& m : messages) apply(m);
  }
};

PoseEstimate poseAt(std::int64_t sequence, double x_m) {
  PoseEstimate pose;
  pose.utime = 1'000'000 + sequence * 33'333;
  pose.sequence = sequence;
  pose.T_world_camera.translation() = Eigen::Vector3d(x_m, 0.0, 0.0);
  pose.tracking_state = TrackingState::kOk;
  return pose;
}

MapUpdate updateOf(std::int64_t sequence, std::vector<VoxelChange> voxels) {
  MapUpdate update;
  update.resolution_m = 0.05;
  update.frame_id = "world";
  update.sequence = sequence;
  update.voxels = std::move(voxels);
  return update;
}

VoxelChange voxel(float x, float y, float z, float log_odds) {
  return VoxelChange{Eigen::Vector3f(x, y, z), log_odds};
}

Key keyOf(float x, float y, float z) {
  octomap::OcTree tree(0.05);
  const octomap::OcTreeKey k = tree.coordToKey(x, y, z);
  return {k[0], k[1], k[2]};
}

constexpr std::int64_t kSecond = 1'000'000'000;

TEST(ViewerModel, APageConnectedAllAlongAndALateOneSeeTheSameState) {
  ViewerModel model(ViewerModel::Options{});
  PageCopy early;
  early.apply(model.fullState(0));
  std::int64_t now = 0;
  for (int step = 0; step < 20; ++step) {
    now += kSecond / 10;
    model.onPose(poseAt(step, 0.01 * step), now);
    // Voxel step becomes occupied; voxel step-5 becomes free again.
    std::vector<VoxelChange> changes = {voxel(0.05f * step + 0.025f, 0.025f, 1.025f, 2.0f)};
    if (step >= 5) changes.push_back(voxel(0.05f * (step - 5) + 0.025f, 0.025f, 1.025f, -1.0f));
    model.onMapUpdate(updateOf(step, changes), now);
    early.apply(model.takeBroadcast(now));
  }
  // Changes not yet broadcast must not reach a late page's full state either.
  model.onPose(poseAt(20, 0.2), now);
  model.onMapUpdate(updateOf(20, {voxel(5.025f, 0.025f, 1.025f, 2.0f)}), now);
  PageCopy late;
  late.apply(model.fullState(now));
  EXPECT_EQ(late.voxels, early.voxels);
  EXPECT_EQ(late.trail_sequences, early.trail_sequences);

  early.apply(model.takeBroadcast(now + 1));
  late.apply(model.takeBroadcast(now + 1));  // what the server sends both after this tick
  EXPECT_EQ(early.voxels.size(), 6u);        // voxels 15..19 and the one at x = 5 m
  EXPECT_TRUE(early.voxels.count(keyOf(5.025f, 0.025f, 1.025f)));
  EXPECT_FALSE(early.voxels.count(keyOf(0.025f, 0.025f, 1.025f)));
  ASSERT_EQ(early.trail_sequences.size(), 21u);
  EXPECT_EQ(early.trail_sequences.back(), 20);
  EXPECT_EQ(model.occupiedVoxels(), early.voxels.size());
}

TEST(ViewerModel, AVoxelThatFlipsAndFlipsBackWithinATickIsNotSent) {
  ViewerModel model(ViewerModel::Options{});
  model.onMapUpdate(updateOf(0, {voxel(0.025f, 0.025f, 0.025f, 2.0f)}), 1);
  model.onMapUpdate(updateOf(1, {voxel(0.025f, 0.025f, 0.025f, -2.0f)}), 2);
  for (const OutgoingMessage& m : model.takeBroadcast(3)) {
    EXPECT_NE(m.kind, OutgoingMessage::Kind::kBinary) << "an empty change was sent";
  }
}

TEST(ViewerModel, ARestartedSlamdClearsThePagesAndStartsAFreshMap) {
  ViewerModel model(ViewerModel::Options{});
  PageCopy page;
  page.apply(model.fullState(0));
  for (int step = 0; step < 5; ++step) {
    model.onPose(poseAt(step, 0.0), step);
    model.onMapUpdate(updateOf(step, {voxel(0.05f * step, 0.0f, 1.0f, 2.0f)}), step);
  }
  page.apply(model.takeBroadcast(10));
  EXPECT_EQ(page.voxels.size(), 5u);

  // A new slamd: its pose and map sequences start at 0 again.
  model.onPose(poseAt(0, 1.0), 20);
  model.onMapUpdate(updateOf(0, {voxel(3.0f, 0.0f, 1.0f, 2.0f)}), 21);
  page.apply(model.takeBroadcast(22));
  EXPECT_EQ(page.resets, 1);
  EXPECT_EQ(page.voxels, std::set<Key>({keyOf(3.0f, 0.0f, 1.0f)}));
  EXPECT_EQ(page.trail_sequences, std::vector<std::int64_t>({0}));
  EXPECT_EQ(model.counters().restarts, 1);
  EXPECT_TRUE(model.map().synchronised());
}

TEST(ViewerModel, AGapAsksForAFullMapAtMostOncePerPeriodAndTheFullMapHealsIt) {
  ViewerModel::Options options;
  options.map_request_period_s = 2.0;
  ViewerModel model(options);
  PageCopy page;
  page.apply(model.fullState(0));
  model.onMapUpdate(updateOf(0, {voxel(0.0f, 0.0f, 1.0f, 2.0f)}), 1);
  EXPECT_FALSE(model.wantsFullMap(1));
  model.onMapUpdate(updateOf(2, {voxel(1.0f, 0.0f, 1.0f, 2.0f)}), 2);  // 1 was lost
  EXPECT_TRUE(model.wantsFullMap(kSecond));
  EXPECT_FALSE(model.wantsFullMap(2 * kSecond));
  EXPECT_TRUE(model.wantsFullMap(3 * kSecond + 1));
  EXPECT_EQ(model.counters().map_requests, 2);

  // The full map slamd sends: two voxels, one of them a pruned 2x2x2 block (8 finest voxels).
  octomap::OcTree tree(0.05);
  tree.setNodeValue(octomap::point3d(1.025f, 0.025f, 1.025f), 2.0f);
  for (int dx = 0; dx < 2; ++dx) {
    for (int dy = 0; dy < 2; ++dy) {
      for (int dz = 0; dz < 2; ++dz) {
        tree.setNodeValue(
            octomap::point3d(2.025f + 0.05f * dx, 2.025f + 0.05f * dy, 2.025f + 0.05f * dz), 2.0f);
      }
    }
  }
  tree.prune();
  FullMap map;
  map.resolution_m = 0.05;
  map.frame_id = "world";
  map.update_sequence = 3;
  std::stringstream stream;
  tree.writeBinaryData(stream);
  const std::string bytes = stream.str();
  map.data.assign(bytes.begin(), bytes.end());
  std::string error;
  ASSERT_TRUE(model.onFullMap(map, 4 * kSecond, &error)) << error;
  EXPECT_FALSE(model.wantsFullMap(10 * kSecond));
  page.apply(model.takeBroadcast(4 * kSecond));
  EXPECT_EQ(page.voxels.size(), 9u);
  EXPECT_FALSE(page.voxels.count(keyOf(0.0f, 0.0f, 1.0f)));  // not in the full map: removed
  EXPECT_TRUE(page.voxels.count(keyOf(2.075f, 2.075f, 2.075f)));
}

TEST(ViewerModel, BadValuesNeverReachThePage) {
  ViewerModel model(ViewerModel::Options{});
  PoseEstimate nan_pose = poseAt(0, 0.0);
  nan_pose.T_world_camera.translation().x() = std::numeric_limits<double>::quiet_NaN();
  model.onPose(nan_pose, 1);
  model.onMapUpdate(updateOf(0, {voxel(std::numeric_limits<float>::infinity(), 0, 0, 2.0f),
                                 voxel(1e9f, 0, 0, 2.0f)}),
                    1);
  slamd::vanishing_point_t point{};
  point.direction_camera[0] = std::numeric_limits<double>::quiet_NaN();
  model.onVanishingPoint(point, 1);
  EXPECT_EQ(model.trailSize(), 0u);
  EXPECT_EQ(model.occupiedVoxels(), 0u);
  for (const OutgoingMessage& m : model.takeBroadcast(2 * kSecond)) {
    EXPECT_EQ(m.payload.find("nan"), std::string::npos) << m.payload;
    EXPECT_NE(m.kind, OutgoingMessage::Kind::kBinary);
  }
  EXPECT_EQ(model.counters().poses_rejected, 1);
}

TEST(ViewerModel, StatusAndKeyframesAreSentOnceWhenTheyChange) {
  ViewerModel model(ViewerModel::Options{});
  slamd::status_t status{};
  status.num_stages = 1;
  status.stages.resize(1);
  status.stages[0].name = "tracking";
  status.stages[0].latency_p99_ms = 12.5;
  status.message = "say \"hi\"";
  model.onStatus(status, 1);
  KeyframeTrajectory keyframes;
  keyframes.keyframes.push_back(KeyframePoseEntry{7, 100, 0, SE3::Identity()});
  model.onKeyframes(keyframes, 1);
  PageCopy page;
  page.apply(model.takeBroadcast(2));
  EXPECT_NE(page.last_status.find("\"latency_p99_ms\":12.5"), std::string::npos);
  EXPECT_NE(page.last_status.find("say \\\"hi\\\""), std::string::npos);
  EXPECT_NE(page.last_keyframes.find("\"id\":7"), std::string::npos);
  page.last_status.clear();
  page.apply(model.takeBroadcast(3));
  EXPECT_TRUE(page.last_status.empty());
}

}  // namespace
}  // namespace slamd::web
