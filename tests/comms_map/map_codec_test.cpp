#include "slamd/comms/map_codec.hpp"

#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

#include "box_room.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/mapping/mapper.hpp"

namespace slamd {
namespace {

using KeyTuple = std::tuple<int, int, int>;

/// The finest occupied voxels of a tree (pruned leaves expanded), as key triples.
std::set<KeyTuple> occupiedSet(const octomap::OcTree& tree) {
  std::set<KeyTuple> occupied;
  for (auto it = tree.begin_leafs(); it != tree.end_leafs(); ++it) {
    if (!tree.isNodeOccupied(*it)) continue;
    const int n = 1 << (tree.getTreeDepth() - it.getDepth());
    const octomap::OcTreeKey base = it.getIndexKey();
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        for (int k = 0; k < n; ++k) occupied.emplace(base[0] + i, base[1] + j, base[2] + k);
      }
    }
  }
  return occupied;
}

MappingConfig streamingConfig() {
  MappingConfig c;
  c.update_rate_hz = 15.0;
  c.full_map_period_s = 0.0;
  c.snapshot_period_s = 0.0;
  return c;
}

/// Round trip through real LCM encoding, as a subscriber would receive it.
MapUpdate overTheWire(const MapUpdate& update) {
  const auto bytes = encodeMessage(toMapUpdateMessage(update));
  const auto message = decodeMessage<slamd::voxel_map_update_t>(bytes.data(), bytes.size());
  EXPECT_TRUE(message.has_value());
  std::string error;
  const auto decoded = fromMapUpdateMessage(*message, &error);
  EXPECT_TRUE(decoded.has_value()) << error;
  return *decoded;
}

FullMap overTheWire(const FullMap& map) {
  const auto bytes = encodeMessage(toFullMapMessage(map));
  const auto message = decodeMessage<slamd::voxel_map_t>(bytes.data(), bytes.size());
  EXPECT_TRUE(message.has_value());
  std::string error;
  const auto decoded = fromFullMapMessage(*message, &error);
  EXPECT_TRUE(decoded.has_value()) << error;
  return *decoded;
}

class UpdateStream : public ::testing::TestWithParam<bool> {};

TEST_P(UpdateStream, AppliedToAnEmptyTreeReproducesTheFullMapsOccupiedSet) {
  MappingConfig config = streamingConfig();
  config.update_new_free_voxels = GetParam();
  Mapper mapper(config);
  MapReplica replica;
  const test::BoxRoom room;
  Utime utime = 1'000'000;
  std::size_t voxels_sent = 0;
  int messages = 0;
  for (const SE3& T : test::lookAroundPoses(8)) {
    RgbdFrame frame = room.render(T);
    frame.utime = utime += 33'333;
    ASSERT_EQ(mapper.integrate(frame, T).status, IntegrationStatus::kOk);
    if (auto out = mapper.poll(frame.utime); out.update) {
      const MapUpdate received = overTheWire(*out.update);
      EXPECT_EQ(received.voxels.size(), out.update->voxels.size());
      voxels_sent += received.voxels.size();
      ++messages;
      ASSERT_EQ(replica.applyUpdate(received), MapReplica::UpdateResult::kApplied);
    }
  }
  // Flush what changed since the last update, then compare with the full map.
  ASSERT_EQ(replica.applyUpdate(overTheWire(mapper.takeUpdate())),
            MapReplica::UpdateResult::kApplied);
  const FullMap full = overTheWire(mapper.fullMap());
  std::string error;
  const auto from_full = fullMapToOcTree(full, &error);
  ASSERT_NE(from_full, nullptr) << error;
  const auto expected = occupiedSet(*mapper.ocTree());
  ASSERT_GT(expected.size(), 5000u);
  EXPECT_EQ(occupiedSet(*from_full), expected);
  EXPECT_EQ(occupiedSet(replica.tree()), expected);
  EXPECT_EQ(replica.gaps(), 0);
  EXPECT_GT(messages, 5);
  if (GetParam()) {
    EXPECT_GT(voxels_sent, 3 * expected.size());
  } else {
    EXPECT_LT(voxels_sent, 2 * expected.size());
  }
}

INSTANTIATE_TEST_SUITE_P(MapCodec, UpdateStream, ::testing::Bool(),
                         [](const ::testing::TestParamInfo<bool>& param_info) {
                           return param_info.param ? std::string("WithNewFreeVoxels")
                                                   : std::string("OccupiedAndFlipsOnly");
                         });

TEST(MapCodec, ALostUpdateOrARebuildWaitsForTheNextFullMap) {
  Mapper mapper(streamingConfig());
  MapReplica replica;
  const test::BoxRoom room;
  const auto poses = test::lookAroundPoses(4);
  Utime utime = 1'000'000;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    RgbdFrame frame = room.render(poses[i]);
    frame.utime = utime += 100'000;
    mapper.integrate(frame, poses[i], static_cast<std::int64_t>(i));
    const MapUpdate update = mapper.takeUpdate();
    if (i == 3) continue;  // lost on the network
    const auto result = replica.applyUpdate(overTheWire(update));
    EXPECT_EQ(result, i < 3 ? MapReplica::UpdateResult::kApplied
                            : MapReplica::UpdateResult::kWaitingForFullMap);
  }
  EXPECT_FALSE(replica.synchronised());
  EXPECT_EQ(replica.gaps(), 1);
  ASSERT_TRUE(replica.applyFullMap(overTheWire(mapper.fullMap())));
  EXPECT_TRUE(replica.synchronised());
  EXPECT_EQ(occupiedSet(replica.tree()), occupiedSet(*mapper.ocTree()));

  // Keyframes moved by a correction leave voxels unknown, which updates cannot say: the mapper
  // skips a sequence number, the replica notices and resynchronises from a full map.
  std::vector<std::pair<std::int64_t, SE3>> corrected;
  for (std::size_t i = 0; i < poses.size(); ++i) {
    SE3 T = poses[i];
    T.translation().x() += 0.1;
    corrected.emplace_back(static_cast<std::int64_t>(i), T);
  }
  mapper.correctKeyframePoses(corrected);
  ASSERT_TRUE(mapper.catchUp(1e9).caught_up);
  mapper.integrate(room.render(poses[0]), poses[0]);
  const MapperOutputs out = mapper.poll(utime + 1'000'000);
  ASSERT_TRUE(out.update.has_value());
  ASSERT_TRUE(out.full_map.has_value());
  EXPECT_EQ(replica.applyUpdate(overTheWire(*out.update)),
            MapReplica::UpdateResult::kWaitingForFullMap);
  ASSERT_TRUE(replica.applyFullMap(overTheWire(*out.full_map)));
  EXPECT_EQ(replica.nextSequence(), out.update->sequence + 1);
  EXPECT_EQ(replica.applyUpdate(overTheWire(*out.update)),
            MapReplica::UpdateResult::kAlreadyContained);
  EXPECT_EQ(occupiedSet(replica.tree()), occupiedSet(*mapper.ocTree()));
}

TEST(MapCodec, FullMapRequestsGoOutAtOnceAfterAGapThenAtMostOncePerPeriod) {
  constexpr std::int64_t kSecond = 1'000'000'000;
  MapReplica replica;
  FullMapRequestPacer requests;
  EXPECT_FALSE(requests.due(replica, kSecond, 1.0)) << "synchronised: nothing to ask for";
  MapUpdate after_a_gap;
  after_a_gap.resolution_m = 0.05;
  after_a_gap.sequence = 1;  // update 0 never arrived
  ASSERT_EQ(replica.applyUpdate(after_a_gap), MapReplica::UpdateResult::kWaitingForFullMap);
  EXPECT_TRUE(requests.due(replica, 2 * kSecond, 1.0));
  EXPECT_FALSE(requests.due(replica, 2 * kSecond + kSecond / 2, 1.0));
  EXPECT_TRUE(requests.due(replica, 3 * kSecond, 1.0));
}

TEST(MapCodec, MalformedMessagesAreRejectedWithoutCrashing) {
  Mapper mapper(streamingConfig());
  const test::BoxRoom room;
  mapper.integrate(room.render(SE3::Identity()), SE3::Identity());
  const FullMap full = mapper.fullMap();
  ASSERT_TRUE(validateOctreeBinary(full.data.data(), full.data.size()));
  slamd::voxel_map_t message = toFullMapMessage(full);

  // Truncated, padded, and randomly corrupted octree streams.
  std::string error;
  slamd::voxel_map_t truncated = message;
  truncated.data.resize(truncated.data.size() / 2);
  truncated.num_bytes = static_cast<std::int32_t>(truncated.data.size());
  EXPECT_FALSE(fromFullMapMessage(truncated, &error).has_value());
  slamd::voxel_map_t padded = message;
  padded.data.push_back(0);
  padded.num_bytes += 1;
  EXPECT_FALSE(fromFullMapMessage(padded, &error).has_value());
  slamd::voxel_map_t miscounted = message;
  miscounted.num_bytes += 7;
  EXPECT_FALSE(fromFullMapMessage(miscounted, &error).has_value());
  slamd::voxel_map_t bad_resolution = message;
  bad_resolution.resolution = std::nan("");
  EXPECT_FALSE(fromFullMapMessage(bad_resolution, &error).has_value());
  const std::vector<std::uint8_t> all_inner(64, 0xFF);  // deeper than 16 levels
  EXPECT_FALSE(validateOctreeBinary(all_inner.data(), all_inner.size()));

  std::mt19937 rng(42);
  MapReplica replica;
  int accepted = 0;
  for (int trial = 0; trial < 300; ++trial) {
    slamd::voxel_map_t corrupt = message;
    for (int flips = 0; flips < 3; ++flips) {
      corrupt.data[rng() % corrupt.data.size()] = static_cast<std::uint8_t>(rng());
    }
    if (const auto decoded = fromFullMapMessage(corrupt, &error)) {
      // Structurally valid corruption (e.g. leaf states swapped) is a legal map.
      EXPECT_TRUE(replica.applyFullMap(*decoded));
      ++accepted;
    }
  }
  EXPECT_LT(accepted, 300);

  slamd::voxel_map_update_t update = toMapUpdateMessage(mapper.takeUpdate());
  ASSERT_GT(update.voxels.size(), 0u);
  slamd::voxel_map_update_t nan_voxel = update;
  nan_voxel.voxels[0].center[1] = std::nanf("");
  EXPECT_FALSE(fromMapUpdateMessage(nan_voxel, &error).has_value());
  slamd::voxel_map_update_t miscount = update;
  miscount.num_voxels = -1;
  EXPECT_FALSE(fromMapUpdateMessage(miscount, &error).has_value());
  // A raw update with a NaN voxel applied directly skips it.
  MapUpdate raw;
  raw.resolution_m = 0.05;
  raw.voxels.push_back({Eigen::Vector3f(std::nanf(""), 0, 0), 1.0f});
  raw.voxels.push_back({Eigen::Vector3f(0.1f, 0.1f, 0.1f), 1.0f});
  octomap::OcTree tree(0.05);
  EXPECT_EQ(applyMapUpdate(raw, tree), 1u);
  // An update of another resolution is refused once the replica holds a map.
  MapUpdate other = raw;
  other.resolution_m = 0.1;
  other.sequence = replica.nextSequence();
  EXPECT_EQ(replica.applyUpdate(other), MapReplica::UpdateResult::kRejected);
}

// Found by fuzzing: OctoMap converts coordinates to keys without a range check, so a voxel
// centre far outside the tree (2.7e24 m in a received update) was undefined behaviour.
TEST(MapCodec, VoxelsOutsideTheTreesExtentAreSkipped) {
  MapUpdate update;
  update.resolution_m = 0.05;
  update.voxels.push_back({Eigen::Vector3f(2.7e24f, 0.0f, 0.0f), 1.0f});
  update.voxels.push_back({Eigen::Vector3f(0.0f, -2.4e9f, 0.0f), 1.0f});
  update.voxels.push_back({Eigen::Vector3f(0.0f, 0.0f, 1639.0f), 1.0f});  // 0.05 * 2^15 = 1638.4
  update.voxels.push_back({Eigen::Vector3f(1.0f, 2.0f, 3.0f), 1.0f});
  octomap::OcTree tree(0.05);
  EXPECT_EQ(applyMapUpdate(update, tree), 1u);
}

}  // namespace
}  // namespace slamd
