// Kept keyframe clouds saved with the map and restored into a new mapper (sessions): the restored
// map follows corrections and forgetting exactly as the saved one would have; and the records'
// file format refuses anything it did not write.

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "box_room.hpp"
#include "keyframe_maps.hpp"
#include "scoped_temp_dir.hpp"
#include "slamd/common/file_io.hpp"
#include "slamd/mapping/keyframe_cloud_io.hpp"
#include "slamd/mapping/mapper.hpp"

namespace slamd {
namespace {

using test::BoxRoom;
using test::expectSameVoxels;

constexpr double kAllTheTime = std::numeric_limits<double>::infinity();
constexpr double kOneStep = 1e-9;  // catchUp() does one step with a budget this small

MappingConfig testConfig() {
  MappingConfig c;
  c.update_rate_hz = 0.0;
  c.full_map_period_s = 0.0;
  c.snapshot_period_s = 0.0;
  c.keyframe_step_points = 1000;  // several parts per keyframe (they keep about 3000 points)
  return c;
}

std::size_t partsOf(const KeyframeCloudRecord& record) {
  return std::max<std::size_t>(
      1, (record.cloud_camera.size() + record.part_points - 1) / record.part_points);
}

std::int64_t cloudBytes(const std::vector<KeyframeCloudRecord>& records) {
  std::int64_t bytes = 0;
  for (const KeyframeCloudRecord& r : records) {
    bytes += static_cast<std::int64_t>(r.cloud_camera.points.size() * sizeof(Eigen::Vector3f) +
                                       r.cloud_camera.colors_bgr.size() * sizeof(ColorBgr));
  }
  return bytes;
}

/// Saves `mapper`'s map and keyframe clouds as a session does, and loads them into a new mapper.
std::unique_ptr<Mapper> saveAndRestore(Mapper& mapper, const test::ScopedTempDir& dir,
                                       std::size_t* kept = nullptr) {
  const std::string map_path = (dir.path() / "map.ot").string();
  const std::string clouds_path = (dir.path() / "keyframe_clouds.bin").string();
  EXPECT_TRUE(mapper.saveMap(map_path).ok);
  std::string error;
  EXPECT_TRUE(writeKeyframeCloudRecords(clouds_path, mapper.keyframeCloudRecords(), &error))
      << error;
  auto restored = std::make_unique<Mapper>(mapper.config());
  EXPECT_TRUE(restored->loadMap(map_path).ok);
  std::vector<KeyframeCloudRecord> records;
  EXPECT_TRUE(readKeyframeCloudRecords(clouds_path, records, &error)) << error;
  const std::size_t count = records.size();
  const std::size_t restored_count = restored->restoreKeyframeClouds(std::move(records));
  EXPECT_EQ(restored_count, count);
  if (kept != nullptr) *kept = restored_count;
  return restored;
}

/// Where the keyframe being moved is when the map is saved.
enum class MoveState { kPartlyOut, kWhollyOut, kPartlyIn };

/// Keyframes integrated at drifted poses are corrected, and the map is saved while one of them is
/// partway through its move (`state`) and a new keyframe has only some of its parts in. The same
/// later correction, fully caught up, must give the restored map and the saved one the same
/// voxels, which must also be the map of the frames integrated at the corrected poses.
void expectRestoredMapToFollowACorrection(MoveState state) {
  const BoxRoom room;
  const std::vector<SE3> truth = test::lookAroundPoses(4);
  const MappingConfig config = testConfig();
  Mapper original(config);
  const std::vector<std::pair<std::int64_t, SE3>> first =
      test::integrateDrifted(original, room, truth);
  ASSERT_EQ(original.correctKeyframePoses(first).keyframes_to_move, truth.size() - 1);
  // Only one keyframe moves at a time; the others are wholly in the map at their drifted poses.
  const auto reached = [&](const std::vector<KeyframeCloudRecord>& records) {
    for (const KeyframeCloudRecord& r : records) {
      const bool partly =
          r.parts_in_map > 0 && static_cast<std::size_t>(r.parts_in_map) < partsOf(r);
      const bool at_truth = r.T_world_camera_in_map.isApprox(truth[static_cast<std::size_t>(r.id)]);
      if (r.id == 0) continue;  // did not drift: it does not move
      if (state == MoveState::kPartlyOut && partly && !at_truth) return true;
      if (state == MoveState::kWhollyOut && r.parts_in_map == 0) return true;
      if (state == MoveState::kPartlyIn && partly && at_truth) return true;
    }
    return false;
  };
  int steps = 0;
  while (!reached(original.keyframeCloudRecords()) && steps < 100) {
    original.catchUp(kOneStep);
    ++steps;
  }
  ASSERT_TRUE(reached(original.keyframeCloudRecords()));
  constexpr std::int64_t kNewId = 50;
  SE3 new_pose = truth[1];
  new_pose.translation() += Eigen::Vector3d(0.1, 0.0, -0.1);
  const RgbdFrame new_frame = room.render(new_pose);
  ASSERT_TRUE(original.addKeyframe(new_frame, new_pose, kNewId).keyframe_cloud_kept);
  original.catchUp(kOneStep);
  const std::vector<KeyframeCloudRecord> saved = original.keyframeCloudRecords();
  ASSERT_EQ(saved.size(), truth.size() + 1);
  ASSERT_EQ(saved.back().id, kNewId);
  ASSERT_EQ(saved.back().parts_in_map, 1);
  ASSERT_GT(partsOf(saved.back()), 1u);

  const test::ScopedTempDir dir("keyframe-clouds");
  std::size_t kept = 0;
  const std::unique_ptr<Mapper> restored = saveAndRestore(original, dir, &kept);
  EXPECT_EQ(kept, truth.size() + 1);
  EXPECT_EQ(restored->keptKeyframeIds(), original.keptKeyframeIds());
  EXPECT_EQ(restored->stats().keyframe_clouds, original.stats().keyframe_clouds);
  EXPECT_EQ(restored->stats().keyframe_cloud_bytes, original.stats().keyframe_cloud_bytes);
  EXPECT_EQ(restored->stats().keyframe_clouds_invalid, 0);
  // Queued: those with parts not in the map, the new one and the one being moved (its parts go
  // in at the pose its others are in at, unless a correction moves it first).
  EXPECT_EQ(restored->keyframesQueued(), 2u);
  expectSameVoxels(*restored->ocTree(), *original.ocTree(), 1e-6f);

  // The same correction in both (every keyframe 6 cm further along x), fully caught up: the
  // same map, voxel by voxel.
  std::vector<std::pair<std::int64_t, SE3>> final_poses = first;
  final_poses.emplace_back(kNewId, new_pose);
  for (auto& entry : final_poses) entry.second.translation().x() += 0.06;
  original.correctKeyframePoses(final_poses);
  // Every keyframe moves, but one wholly out of the map goes in at its newest pose: no move.
  EXPECT_EQ(restored->correctKeyframePoses(final_poses).keyframes_to_move,
            state == MoveState::kWhollyOut ? truth.size() : truth.size() + 1);
  EXPECT_TRUE(original.catchUp(kAllTheTime).caught_up);
  const CatchUpResult caught_up = restored->catchUp(kAllTheTime);
  EXPECT_TRUE(caught_up.caught_up);
  EXPECT_EQ(caught_up.keyframes_left, 0u);
  EXPECT_GT(restored->numLeafNodes(), 10000u);
  expectSameVoxels(*restored->ocTree(), *original.ocTree(), 1e-5f);

  // And both are the map of the frames integrated at the corrected poses: nothing of the drifted
  // poses is left in the restored map.
  std::vector<SE3> corrected(truth.size());
  for (std::size_t i = 0; i < truth.size(); ++i) corrected[i] = final_poses[i].second;
  const std::unique_ptr<Mapper> reference = test::mapAt(room, truth, config, corrected);
  reference->integrate(new_frame, final_poses.back().second, kNewId);
  expectSameVoxels(*restored->ocTree(), *reference->ocTree());
}

TEST(KeyframeCloudRecords, ARestoredMapFollowsACorrectionExactlyAsTheSavedMapDoes) {
  {
    SCOPED_TRACE("saved with a keyframe partway out of the map for a move");
    expectRestoredMapToFollowACorrection(MoveState::kPartlyOut);
  }
  {
    SCOPED_TRACE("saved with a keyframe wholly out of the map for a move");
    expectRestoredMapToFollowACorrection(MoveState::kWhollyOut);
  }
  {
    SCOPED_TRACE("saved with a keyframe partway into the map at its corrected pose");
    expectRestoredMapToFollowACorrection(MoveState::kPartlyIn);
  }
}

TEST(KeyframeCloudRecords, ForgettingARestoredKeyframeLeavesTheSameMapAsInTheSavedMap) {
  const BoxRoom room;
  const std::vector<SE3> truth = test::lookAroundPoses(4);
  const MappingConfig config = testConfig();
  Mapper original(config);
  test::integrateDrifted(original, room, truth);
  const test::ScopedTempDir dir("keyframe-clouds");
  const std::unique_ptr<Mapper> restored = saveAndRestore(original, dir);
  EXPECT_EQ(restored->keyframesQueued(), 0u);

  original.forgetKeyframe(4);
  restored->forgetKeyframe(4);
  EXPECT_EQ(restored->stats().keyframes_taken_out, 1);
  expectSameVoxels(*restored->ocTree(), *original.ocTree(), 1e-5f);
  original.forgetKeyframeInSteps(7);
  restored->forgetKeyframeInSteps(7);
  original.catchUp(kAllTheTime);
  restored->catchUp(kAllTheTime);
  EXPECT_EQ(restored->keptKeyframeIds(), original.keptKeyframeIds());
  expectSameVoxels(*restored->ocTree(), *original.ocTree(), 1e-5f);
  // What the loaded map holds is exactly the restored keyframes' contributions: taking all of
  // them out leaves it empty.
  for (const std::int64_t id : restored->keptKeyframeIds()) restored->forgetKeyframe(id);
  EXPECT_EQ(restored->numLeafNodes(), 0u);
  EXPECT_EQ(restored->stats().keyframe_cloud_bytes, 0);
}

TEST(KeyframeCloudRecords, RecordsListTheKeptCloudsAsTheyStandInTheMap) {
  const BoxRoom room;
  const std::vector<SE3> views = test::lookAroundPoses(4);
  const MappingConfig config = testConfig();
  Mapper mapper(config);
  for (std::int64_t id = 0; id < 3; ++id) {
    RgbdFrame frame = room.render(views[static_cast<std::size_t>(id)]);
    frame.utime = 1'000'000 + id;
    ASSERT_TRUE(
        mapper.integrate(frame, views[static_cast<std::size_t>(id)], id).keyframe_cloud_kept);
  }
  std::vector<KeyframeCloudRecord> records = mapper.keyframeCloudRecords();
  ASSERT_EQ(records.size(), 3u);
  std::int64_t points = 0;
  for (std::size_t i = 0; i < records.size(); ++i) {
    const KeyframeCloudRecord& record = records[i];
    EXPECT_EQ(record.id, static_cast<std::int64_t>(i));
    EXPECT_EQ(record.utime, 1'000'000 + record.id);
    EXPECT_TRUE(record.T_world_camera_in_map.isApprox(views[i]));
    EXPECT_EQ(record.part_points, 1000u);
    EXPECT_GT(partsOf(record), 1u);
    EXPECT_EQ(static_cast<std::size_t>(record.parts_in_map), partsOf(record));
    EXPECT_EQ(record.cloud_camera.colors_bgr.size(), record.cloud_camera.points.size());
    points += static_cast<std::int64_t>(record.cloud_camera.size());
  }
  EXPECT_EQ(points, mapper.stats().points_inserted);
  EXPECT_EQ(cloudBytes(records), mapper.stats().keyframe_cloud_bytes);
  // The mapper's part order: by elevation (image row), so y / z never decreases.
  const PointCloud& cloud = records[0].cloud_camera;
  for (std::size_t i = 1; i < cloud.size(); ++i) {
    ASSERT_LE(std::atan2(cloud.points[i - 1].y(), cloud.points[i - 1].z()),
              std::atan2(cloud.points[i].y(), cloud.points[i].z()));
  }

  // Keyframe 1 partway out for a move: recorded with its remaining parts at the old pose.
  SE3 moved = views[1];
  moved.translation().x() += 0.1;
  ASSERT_EQ(mapper.correctKeyframePoses({{1, moved}}).keyframes_to_move, 1u);
  mapper.catchUp(kOneStep);
  records = mapper.keyframeCloudRecords();
  const std::size_t parts = partsOf(records[1]);
  EXPECT_EQ(static_cast<std::size_t>(records[1].parts_in_map), parts - 1);
  EXPECT_TRUE(records[1].T_world_camera_in_map.isApprox(views[1]));
  // Wholly out: nothing of it is in the map, and it goes in at its corrected pose.
  for (std::size_t i = 1; i < parts; ++i) mapper.catchUp(kOneStep);
  records = mapper.keyframeCloudRecords();
  EXPECT_EQ(records[1].parts_in_map, 0);
  EXPECT_TRUE(records[1].T_world_camera_in_map.isApprox(moved));
  // A keyframe being forgotten is not recorded.
  mapper.forgetKeyframeInSteps(2);
  records = mapper.keyframeCloudRecords();
  ASSERT_EQ(records.size(), 2u);
  EXPECT_EQ(records[0].id, 0);
  EXPECT_EQ(records[1].id, 1);
}

TEST(KeyframeCloudRecords, InvalidRecordsAreCountedAndNeverKept) {
  const BoxRoom room;
  const std::vector<SE3> views = test::lookAroundPoses(4);
  Mapper source(testConfig());
  for (std::int64_t id = 0; id < 2; ++id) {
    source.integrate(room.render(views[static_cast<std::size_t>(id)]),
                     views[static_cast<std::size_t>(id)], id);
  }
  const std::vector<KeyframeCloudRecord> valid = source.keyframeCloudRecords();
  ASSERT_EQ(valid.size(), 2u);
  std::vector<KeyframeCloudRecord> records = valid;
  // Valid too: a record with none of its parts in the map yet (queued), and all of them.
  KeyframeCloudRecord none_in = valid[0];
  none_in.id = 20;
  none_in.parts_in_map = 0;
  records.push_back(none_in);
  KeyframeCloudRecord one_part = valid[1];
  one_part.id = 21;
  one_part.part_points = one_part.cloud_camera.size();  // exactly one part
  one_part.parts_in_map = 1;
  records.push_back(one_part);

  std::int64_t next_id = 100;
  std::size_t invalid = 0;
  const auto add_invalid = [&](auto spoil) {
    KeyframeCloudRecord record = valid[0];
    record.id = next_id++;
    spoil(record);
    records.push_back(std::move(record));
    ++invalid;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  add_invalid([&](KeyframeCloudRecord& r) { r.T_world_camera_in_map.translation().y() = nan; });
  add_invalid([](KeyframeCloudRecord& r) { r.T_world_camera_in_map.linear() *= 2.0; });
  add_invalid([](KeyframeCloudRecord& r) { r.T_world_camera_in_map.translation().x() = 1e5; });
  add_invalid([](KeyframeCloudRecord& r) { r.cloud_camera.clear(); });
  add_invalid(
      [&](KeyframeCloudRecord& r) { r.cloud_camera.points[17].x() = static_cast<float>(nan); });
  add_invalid([&](KeyframeCloudRecord& r) { r.cloud_camera.points.back().z() = inf; });
  add_invalid([](KeyframeCloudRecord& r) { r.cloud_camera.points[3].z() = 3e7f; });
  add_invalid([](KeyframeCloudRecord& r) { r.cloud_camera.colors_bgr.pop_back(); });
  add_invalid([](KeyframeCloudRecord& r) { r.part_points = 0; });
  add_invalid([](KeyframeCloudRecord& r) { r.parts_in_map = -1; });
  add_invalid([](KeyframeCloudRecord& r) { r.parts_in_map = static_cast<int>(partsOf(r)) + 1; });
  add_invalid([](KeyframeCloudRecord& r) {
    r.part_points = 1;  // a part per point: still fine, but more parts than the map has in it
    r.parts_in_map = static_cast<int>(r.cloud_camera.size()) + 1;
  });
  add_invalid([](KeyframeCloudRecord& r) {  // kept already: the first record of an id wins
    r.id = 0;
    r.cloud_camera.points.resize(10);
    r.cloud_camera.colors_bgr.resize(10);
  });

  Mapper restored(testConfig());
  EXPECT_EQ(restored.restoreKeyframeClouds(records), 4u);
  EXPECT_EQ(restored.stats().keyframe_clouds_invalid, static_cast<std::int64_t>(invalid));
  EXPECT_EQ(restored.stats().keyframe_clouds_refused, 0);
  EXPECT_EQ(restored.keptKeyframeIds(), (std::vector<std::int64_t>{0, 1, 20, 21}));
  EXPECT_EQ(restored.stats().keyframe_clouds, 4);
  EXPECT_EQ(restored.stats().keyframe_cloud_bytes, 2 * cloudBytes(valid));
  const std::vector<KeyframeCloudRecord> kept = restored.keyframeCloudRecords();
  ASSERT_EQ(kept.size(), 4u);
  EXPECT_EQ(kept[0].cloud_camera.size(), valid[0].cloud_camera.size());  // the first id 0
  // The one with no part in the map is queued and goes in at its pose; nothing else moves.
  EXPECT_EQ(restored.keyframesQueued(), 1u);
  const CatchUpResult result = restored.catchUp(kAllTheTime);
  EXPECT_EQ(result.keyframes_added, 1u);
  EXPECT_EQ(result.keyframes_moved, 0u);
  Mapper reference(testConfig());
  reference.integrate(room.render(views[0]), views[0], 20);
  expectSameVoxels(*restored.ocTree(), *reference.ocTree());

  MappingConfig without = testConfig();
  without.keep_keyframe_clouds = false;
  Mapper unkept(without);
  EXPECT_EQ(unkept.restoreKeyframeClouds(valid), 0u);
  EXPECT_TRUE(unkept.keptKeyframeIds().empty());
  EXPECT_EQ(unkept.stats().keyframe_cloud_bytes, 0);
}

TEST(KeyframeCloudRecords, TheCloudBudgetAndMemoryPressureRefuseRecordsAndCountThem) {
  const BoxRoom room;
  const std::vector<SE3> views = test::lookAroundPoses(4);
  Mapper source(testConfig());
  for (std::size_t i = 0; i < views.size(); ++i) {
    source.integrate(room.render(views[i]), views[i], static_cast<std::int64_t>(i));
  }
  // Four copies of each under other ids: over 1 MiB.
  std::vector<KeyframeCloudRecord> records;
  for (std::int64_t copy = 0; copy < 4; ++copy) {
    for (KeyframeCloudRecord record : source.keyframeCloudRecords()) {
      record.id += 100 * copy;
      records.push_back(std::move(record));
    }
  }
  ASSERT_GT(cloudBytes(records), 3 << 19);

  MappingConfig small = testConfig();
  small.keyframe_cloud_budget_mb = 1;
  Mapper budgeted(small);
  const std::size_t kept = budgeted.restoreKeyframeClouds(records);
  EXPECT_GT(kept, 0u);
  EXPECT_LT(kept, records.size());
  EXPECT_EQ(budgeted.stats().keyframe_clouds_refused,
            static_cast<std::int64_t>(records.size() - kept));
  EXPECT_EQ(budgeted.stats().keyframe_clouds, static_cast<std::int64_t>(kept));
  EXPECT_LE(budgeted.stats().keyframe_cloud_bytes, 1 << 20);
  EXPECT_EQ(budgeted.stats().keyframe_cloud_bytes, cloudBytes(budgeted.keyframeCloudRecords()));

  Mapper pressed(testConfig());
  pressed.setMemoryPressure(MemoryPressure::kNear);
  EXPECT_EQ(pressed.restoreKeyframeClouds(records), 0u);
  EXPECT_EQ(pressed.stats().keyframe_clouds_refused, static_cast<std::int64_t>(records.size()));
  EXPECT_EQ(pressed.stats().keyframe_cloud_bytes, 0);
}

// --- the file format ------------------------------------------------------------------------

std::vector<std::uint8_t> fileBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

void writeBytes(const std::string& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(reinterpret_cast<const char*>(bytes.data()),
            static_cast<std::streamsize>(bytes.size()));
}

/// Makes the last 8 bytes the checksum of the others again (to reach the parser's checks).
void fixChecksum(std::vector<std::uint8_t>& bytes) {
  const std::uint64_t checksum = fnv1a64(bytes.data(), bytes.size() - 8);
  for (int i = 0; i < 8; ++i) {
    bytes[bytes.size() - 8 + static_cast<std::size_t>(i)] =
        static_cast<std::uint8_t>(checksum >> (8 * i));
  }
}

void putU64(std::vector<std::uint8_t>& bytes, std::size_t offset, std::uint64_t value) {
  for (int i = 0; i < 8; ++i) {
    bytes[offset + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(value >> (8 * i));
  }
}

/// Two small records: one with colours, one without.
std::vector<KeyframeCloudRecord> smallRecords() {
  std::vector<KeyframeCloudRecord> records(2);
  records[0].id = -3;
  records[0].utime = 1'700'000'000'123'456;
  records[0].T_world_camera_in_map.linear() =
      Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  records[0].T_world_camera_in_map.translation() = Eigen::Vector3d(1.5, -2.25, 1e-9);
  records[0].part_points = std::size_t{1} << 40;
  records[0].parts_in_map = 1;
  records[0].cloud_camera.points = {{0.1f, -0.2f, 1.3f},
                                    {-0.0f, std::numeric_limits<float>::denorm_min(), 9.5f},
                                    {3.0e4f, -1.0f, 0.25f}};
  records[0].cloud_camera.colors_bgr = {{{1, 2, 3}}, {{250, 0, 128}}, {{7, 7, 7}}};
  records[1].id = std::numeric_limits<std::int64_t>::max();
  records[1].utime = -1;
  records[1].part_points = 1;
  records[1].parts_in_map = 2;
  records[1].cloud_camera.points = {{0.5f, 0.5f, 2.0f}, {-0.5f, 0.5f, 2.0f}};
  return records;
}

void expectSameRecords(const std::vector<KeyframeCloudRecord>& actual,
                       const std::vector<KeyframeCloudRecord>& expected) {
  ASSERT_EQ(actual.size(), expected.size());
  for (std::size_t i = 0; i < actual.size(); ++i) {
    const KeyframeCloudRecord& a = actual[i];
    const KeyframeCloudRecord& e = expected[i];
    EXPECT_EQ(a.id, e.id);
    EXPECT_EQ(a.utime, e.utime);
    EXPECT_TRUE(a.T_world_camera_in_map.matrix() == e.T_world_camera_in_map.matrix());
    EXPECT_EQ(a.part_points, e.part_points);
    EXPECT_EQ(a.parts_in_map, e.parts_in_map);
    ASSERT_EQ(a.cloud_camera.points.size(), e.cloud_camera.points.size());
    // Bit for bit (-0.0 and denormals included).
    EXPECT_EQ(std::memcmp(a.cloud_camera.points.data(), e.cloud_camera.points.data(),
                          e.cloud_camera.points.size() * sizeof(Eigen::Vector3f)),
              0);
    EXPECT_EQ(a.cloud_camera.colors_bgr, e.cloud_camera.colors_bgr);
  }
}

TEST(KeyframeCloudFile, RecordsRoundTripBitForBit) {
  const test::ScopedTempDir dir("keyframe-cloud-file");
  const std::string path = (dir.path() / "clouds.bin").string();
  const std::vector<KeyframeCloudRecord> records = smallRecords();
  std::string error;
  ASSERT_TRUE(writeKeyframeCloudRecords(path, records, &error)) << error;
  // magic, version, count; per record 133 bytes and 12 per point (+3 with colours); checksum.
  EXPECT_EQ(std::filesystem::file_size(path), 8u + 4 + 8 + (133 + 3 * 15) + (133 + 2 * 12) + 8);
  EXPECT_FALSE(std::filesystem::exists(temporaryPathFor(path)));
  std::vector<KeyframeCloudRecord> read(1);  // replaced
  ASSERT_TRUE(readKeyframeCloudRecords(path, read, &error)) << error;
  expectSameRecords(read, records);

  ASSERT_TRUE(writeKeyframeCloudRecords(path, {}, &error)) << error;
  ASSERT_TRUE(readKeyframeCloudRecords(path, read, &error)) << error;
  EXPECT_TRUE(read.empty());

  // A mapper's records too (thousands of points, several pieces of the reader).
  const BoxRoom room;
  Mapper mapper(testConfig());
  mapper.integrate(room.render(SE3::Identity()), SE3::Identity(), 5);
  const std::vector<KeyframeCloudRecord> kept = mapper.keyframeCloudRecords();
  ASSERT_GT(kept.at(0).cloud_camera.size(), 2048u);
  ASSERT_TRUE(writeKeyframeCloudRecords(path, kept, &error)) << error;
  ASSERT_TRUE(readKeyframeCloudRecords(path, read, &error)) << error;
  expectSameRecords(read, kept);
}

TEST(KeyframeCloudFile, EveryTruncationIsRefused) {
  const test::ScopedTempDir dir("keyframe-cloud-file");
  const std::string path = (dir.path() / "clouds.bin").string();
  const std::string cut = (dir.path() / "cut.bin").string();
  ASSERT_TRUE(writeKeyframeCloudRecords(path, smallRecords()));
  const std::vector<std::uint8_t> bytes = fileBytes(path);
  for (std::size_t length = 0; length < bytes.size(); ++length) {
    writeBytes(cut, std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + length));
    std::vector<KeyframeCloudRecord> records(1);
    std::string error;
    ASSERT_FALSE(readKeyframeCloudRecords(cut, records, &error)) << length << " bytes";
    EXPECT_TRUE(records.empty());
    EXPECT_NE(error.find(cut), std::string::npos) << error;
    EXPECT_NE(error.find(length < 8 ? "too short" : "truncated"), std::string::npos)
        << length << " bytes: " << error;
  }
}

TEST(KeyframeCloudFile, EveryCorruptByteIsRefused) {
  const test::ScopedTempDir dir("keyframe-cloud-file");
  const std::string path = (dir.path() / "clouds.bin").string();
  const std::string corrupt = (dir.path() / "corrupt.bin").string();
  ASSERT_TRUE(writeKeyframeCloudRecords(path, smallRecords()));
  const std::vector<std::uint8_t> bytes = fileBytes(path);
  for (std::size_t i = 0; i < bytes.size(); ++i) {
    std::vector<std::uint8_t> changed = bytes;
    changed[i] ^= 0x10;
    writeBytes(corrupt, changed);
    std::vector<KeyframeCloudRecord> records;
    std::string error;
    EXPECT_FALSE(readKeyframeCloudRecords(corrupt, records, &error)) << "byte " << i;
    EXPECT_NE(error.find(corrupt), std::string::npos) << error;
  }
  // A byte of a point: the checksum finds it.
  std::vector<std::uint8_t> changed = bytes;
  changed[8 + 4 + 8 + 133] ^= 1;
  writeBytes(corrupt, changed);
  std::vector<KeyframeCloudRecord> records;
  std::string error;
  EXPECT_FALSE(readKeyframeCloudRecords(corrupt, records, &error));
  EXPECT_NE(error.find("checksum mismatch"), std::string::npos) << error;
}

TEST(KeyframeCloudFile, RandomBytesAreRefused) {
  const test::ScopedTempDir dir("keyframe-cloud-file");
  const std::string path = (dir.path() / "random.bin").string();
  ASSERT_TRUE(writeKeyframeCloudRecords(path, smallRecords()));
  const std::vector<std::uint8_t> header = [&] {
    const std::vector<std::uint8_t> bytes = fileBytes(path);
    return std::vector<std::uint8_t>(bytes.begin(), bytes.begin() + 12);  // magic, version
  }();
  std::mt19937 rng(42);
  std::uniform_int_distribution<int> byte(0, 255);
  std::uniform_int_distribution<std::size_t> length(0, 3000);
  int refused = 0;
  constexpr int kTrials = 300;
  for (int trial = 0; trial < kTrials; ++trial) {
    std::vector<std::uint8_t> bytes(length(rng));
    for (std::uint8_t& b : bytes) b = static_cast<std::uint8_t>(byte(rng));
    // A third plain noise, a third after a valid magic and version, a third with a valid
    // checksum too, so that the parser itself sees the noise.
    const int kind = trial % 3;
    if (kind > 0) bytes.insert(bytes.begin(), header.begin(), header.end());
    if (kind == 2) {
      bytes.resize(bytes.size() + 8);
      fixChecksum(bytes);
    }
    writeBytes(path, bytes);
    std::vector<KeyframeCloudRecord> records;
    std::string error;
    const bool read = readKeyframeCloudRecords(path, records, &error);
    refused += read ? 0 : 1;
    EXPECT_EQ(read, error.empty()) << error;
  }
  EXPECT_EQ(refused, kTrials);
}

TEST(KeyframeCloudFile, AbsurdCountsAreRefusedBeforeAnythingIsAllocated) {
  const test::ScopedTempDir dir("keyframe-cloud-file");
  const std::string path = (dir.path() / "clouds.bin").string();
  ASSERT_TRUE(writeKeyframeCloudRecords(path, smallRecords()));
  const std::vector<std::uint8_t> bytes = fileBytes(path);
  constexpr std::size_t kRecordCount = 12;
  constexpr std::size_t kFirstPointCount = 20 + 8 + 8 + 96 + 8 + 4;
  for (const std::size_t offset : {kRecordCount, kFirstPointCount}) {
    for (const std::uint64_t count :
         {std::uint64_t{1} << 62, std::uint64_t{1} << 40, std::numeric_limits<std::uint64_t>::max(),
          std::uint64_t{100}}) {
      std::vector<std::uint8_t> changed = bytes;
      putU64(changed, offset, count);
      fixChecksum(changed);
      writeBytes(path, changed);
      std::vector<KeyframeCloudRecord> records;
      std::string error;
      EXPECT_FALSE(readKeyframeCloudRecords(path, records, &error)) << count;
      // Refused by the size check, not by a failed allocation.
      EXPECT_NE(error.find("cannot fit"), std::string::npos) << error;
    }
  }
}

TEST(KeyframeCloudFile, OtherFilesAndVersionsAreRefusedWithTheReason) {
  const test::ScopedTempDir dir("keyframe-cloud-file");
  const std::string path = (dir.path() / "clouds.bin").string();
  const auto refusal = [&path](const std::vector<std::uint8_t>& bytes) {
    writeBytes(path, bytes);
    std::vector<KeyframeCloudRecord> records;
    std::string error;
    EXPECT_FALSE(readKeyframeCloudRecords(path, records, &error));
    EXPECT_NE(error.find(path), std::string::npos) << error;
    return error;
  };
  ASSERT_TRUE(writeKeyframeCloudRecords(path, smallRecords()));
  const std::vector<std::uint8_t> good = fileBytes(path);

  const std::string text = "mapping:\n  resolution_m: 0.05\n";
  EXPECT_NE(refusal({text.begin(), text.end()}).find("bad magic"), std::string::npos);
  std::vector<std::uint8_t> newer = good;
  newer[8] = 2;
  fixChecksum(newer);
  EXPECT_NE(refusal(newer).find("newer slamd (format version 2, this slamd reads 1)"),
            std::string::npos);
  std::vector<std::uint8_t> older = good;
  older[8] = 0;
  fixChecksum(older);
  EXPECT_NE(refusal(older).find("format version 0"), std::string::npos);
  std::vector<std::uint8_t> flag = good;
  flag[20 + 133 + 3 * 12 - 1] = 2;  // the first record's colour flag
  fixChecksum(flag);
  EXPECT_NE(refusal(flag).find("colour flag 2"), std::string::npos);
  std::vector<std::uint8_t> longer = good;
  longer.push_back(0);
  EXPECT_NE(refusal(longer).find("1 unexpected bytes after the checksum"), std::string::npos);
  writeBytes(path, good);

  std::vector<KeyframeCloudRecord> records;
  std::string error;
  EXPECT_FALSE(readKeyframeCloudRecords((dir.path() / "missing.bin").string(), records, &error));
  EXPECT_NE(error.find("missing.bin"), std::string::npos) << error;
  EXPECT_FALSE(readKeyframeCloudRecords(dir.path().string(), records, &error));
  EXPECT_NE(error.find("not a regular file"), std::string::npos) << error;

  // The writer: a folder that does not exist, colours that are not one per point.
  EXPECT_FALSE(writeKeyframeCloudRecords((dir.path() / "no" / "clouds.bin").string(),
                                         smallRecords(), &error));
  EXPECT_FALSE(error.empty());
  std::vector<KeyframeCloudRecord> bad = smallRecords();
  bad[0].cloud_camera.colors_bgr.pop_back();
  error.clear();
  EXPECT_FALSE(writeKeyframeCloudRecords(path, bad, &error));
  EXPECT_NE(error.find("2 colours for 3 points"), std::string::npos) << error;
  // The file written before is untouched.
  ASSERT_TRUE(readKeyframeCloudRecords(path, records, &error)) << error;
  expectSameRecords(records, smallRecords());
}

}  // namespace
}  // namespace slamd
