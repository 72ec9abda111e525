#include <climits>
#include <cstdint>
#include <random>

#include <gtest/gtest.h>

#include "bot_core/pose_t.hpp"
#include "kinect/frame_msg_t.hpp"
#include "slamd/command_t.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/keyframe_trajectory_t.hpp"
#include "slamd/odometry_t.hpp"
#include "slamd/pose_t.hpp"
#include "slamd/rgbd_frame_t.hpp"
#include "slamd/status_t.hpp"
#include "slamd/vanishing_point_t.hpp"
#include "slamd/voxel_map_t.hpp"
#include "slamd/voxel_map_update_t.hpp"

namespace slamd {
namespace {

// One filled-in example of each message, with every variable-length field non-empty so that a
// truncation anywhere cuts through real data.
template <typename M>
M example();

template <>
slamd::rgbd_frame_t example() {
  slamd::rgbd_frame_t m;
  m.utime = 1305031102175304;
  m.sequence = 17;
  m.frame_id = "camera";
  m.fx = 517.3;
  m.fy = 516.5;
  m.cx = 318.6;
  m.cy = 255.3;
  m.width = 4;
  m.height = 2;
  m.distortion_model = slamd::rgbd_frame_t::DISTORTION_PLUMB_BOB;
  const double distortion[5] = {0.2624, -0.9531, -0.0054, 0.0026, 1.1633};
  for (int i = 0; i < 5; ++i) m.distortion[i] = distortion[i];
  m.depth_scale = 5000;
  m.color_encoding = slamd::rgbd_frame_t::COLOR_BGR8;
  m.color_data.assign(24, 7);
  m.color_nbytes = 24;
  m.depth_encoding = slamd::rgbd_frame_t::DEPTH_RAW_U16;
  m.depth_data.assign(16, 3);
  m.depth_nbytes = 16;
  return m;
}

template <>
slamd::pose_t example() {
  slamd::pose_t m{};
  m.utime = 42;
  m.sequence = 3;
  m.parent_frame = "world";
  m.child_frame = "camera";
  m.position[0] = 1.5;
  m.position[1] = -2;
  m.position[2] = 0.25;
  m.orientation[0] = 1;
  for (int i = 0; i < 36; ++i) m.covariance[i] = i * 0.01;
  m.linear_velocity[2] = 0.8;
  m.angular_velocity[1] = -0.1;
  m.tracking_state = slamd::pose_t::TRACKING_OK;
  m.source = slamd::pose_t::SOURCE_FILTER;
  return m;
}

template <>
slamd::odometry_t example() {
  slamd::odometry_t m{};
  m.utime = 2000;
  m.prev_utime = 1000;
  m.translation[0] = 0.01;
  m.rotation[0] = 1;
  m.covariance[0] = 1e-6;
  m.status = slamd::odometry_t::STATUS_INSUFFICIENT_INLIERS;
  m.num_features = 900;
  m.num_matches = 300;
  m.num_inliers = 12;
  m.reprojection_error_px = 0.7;
  m.is_keyframe = true;
  m.reference_keyframe_id = 5;
  return m;
}

template <>
slamd::vanishing_point_t example() {
  slamd::vanishing_point_t m{};
  m.utime = 5;
  m.pixel[0] = 320.5;
  m.pixel[1] = 240.25;
  m.pixel_covariance[0] = 4;
  m.pixel_covariance[3] = 4;
  m.direction_camera[2] = 1;
  m.num_supporting_lines = 23;
  m.landmark_id = 1;
  m.accepted = true;
  m.mahalanobis_distance_sq = 1.3;
  return m;
}

template <>
slamd::voxel_map_t example() {
  slamd::voxel_map_t m;
  m.utime = 9;
  m.resolution = 0.05;
  m.frame_id = "world";
  m.update_sequence = 12;
  m.data.assign(100, 0xAB);
  m.num_bytes = 100;
  return m;
}

template <>
slamd::voxel_map_update_t example() {
  slamd::voxel_map_update_t m;
  m.utime = 10;
  m.resolution = 0.05;
  m.frame_id = "world";
  m.sequence = 4;
  const float centers[3][3] = {{0.025f, 0.025f, 0.025f}, {1, 2, 3}, {-1, -2, -3}};
  const float log_odds[3] = {0.85f, -0.4f, 3.5f};
  for (int i = 0; i < 3; ++i) {
    slamd::voxel_t voxel;
    for (int j = 0; j < 3; ++j) voxel.center[j] = centers[i][j];
    voxel.log_odds = log_odds[i];
    m.voxels.push_back(voxel);
  }
  m.num_voxels = 3;
  return m;
}

template <>
slamd::status_t example() {
  slamd::status_t m;
  m.utime = 11;
  slamd::stage_status_t stage;
  stage.name = "tracking";
  stage.rate_hz = 30;
  stage.latency_p50_ms = 9;
  stage.latency_p95_ms = 12;
  stage.latency_p99_ms = 15;
  stage.queue_depth = 1;
  stage.queue_capacity = 4;
  stage.drops = 2;
  stage.errors = 1;
  stage.processed = 900;
  m.stages = {stage, stage};
  m.stages[1].name = "mapping";
  m.num_stages = 2;
  m.end_to_end_p50_ms = 10;
  m.end_to_end_p95_ms = 14;
  m.end_to_end_p99_ms = 20;
  m.tracking_state = slamd::pose_t::TRACKING_OK;
  m.map_occupied_voxels = 1000;
  m.map_total_voxels = 5000;
  m.num_keyframes = 40;
  m.num_loops = 3;
  m.num_relocalizations = 1;
  m.memory_rss_mb = 251.5;
  m.memory_limit_mb = 300;
  m.memory_pressure = 1;
  m.message = "ok";
  return m;
}

template <>
slamd::keyframe_trajectory_t example() {
  KeyframeTrajectory trajectory;
  trajectory.utime = 15;
  trajectory.sequence = 2;
  trajectory.T_world_uncorrected =
      makeSE3(Eigen::Vector3d(0.1, -0.2, 0.05),
              Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ())));
  trajectory.num_loops = 1;
  trajectory.optimization_ms = 4.5;
  for (std::int64_t id = 0; id < 3; ++id) {
    trajectory.keyframes.push_back(KeyframePoseEntry{
        id, 15 - 3 + id, 0,
        makeSE3(Eigen::Vector3d(0.3 * id, 0, 0), Eigen::Quaterniond::Identity())});
  }
  return toKeyframeTrajectoryMessage(trajectory);
}

template <>
slamd::command_t example() {
  slamd::command_t m;
  m.utime = 12;
  m.command = slamd::command_t::SAVE_MAP;
  m.argument = "/tmp/map.bt";
  return m;
}

template <>
bot_core::pose_t example() {
  bot_core::pose_t m{};
  m.utime = 13;
  m.pos[0] = 1;
  m.vel[1] = 2;
  m.orientation[0] = 1;
  m.rotation_rate[2] = 0.5;
  return m;
}

template <>
kinect::frame_msg_t example() {
  kinect::frame_msg_t m;
  m.timestamp = 14;
  m.image.timestamp = 14;
  m.image.width = 2;
  m.image.height = 1;
  m.image.image_data.assign(6, 1);
  m.image.image_data_nbytes = 6;
  m.image.image_data_format = kinect::image_msg_t::VIDEO_RGB;
  m.depth.timestamp = 14;
  m.depth.width = 2;
  m.depth.height = 1;
  m.depth.depth_data.assign(4, 2);
  m.depth.depth_data_nbytes = 4;
  m.depth.depth_data_format = kinect::depth_msg_t::DEPTH_MM;
  m.depth.compression = kinect::depth_msg_t::COMPRESSION_NONE;
  m.depth.uncompressed_size = 4;
  return m;
}

template <typename M>
class MessageRoundTrip : public ::testing::Test {};

using AllMessages =
    ::testing::Types<slamd::rgbd_frame_t, slamd::pose_t, slamd::odometry_t,
                     slamd::vanishing_point_t, slamd::voxel_map_t, slamd::voxel_map_update_t,
                     slamd::status_t, slamd::keyframe_trajectory_t, slamd::command_t,
                     bot_core::pose_t, kinect::frame_msg_t>;
TYPED_TEST_SUITE(MessageRoundTrip, AllMessages);

TYPED_TEST(MessageRoundTrip, EncodeDecodeReproducesTheMessage) {
  const TypeParam original = example<TypeParam>();
  const auto bytes = encodeMessage(original);
  ASSERT_FALSE(bytes.empty());
  std::string error;
  const auto decoded = decodeMessage<TypeParam>(bytes.data(), bytes.size(), &error);
  ASSERT_TRUE(decoded.has_value()) << error;
  // Re-encoding the decoded message gives the same bytes: every field survived.
  EXPECT_EQ(encodeMessage(*decoded), bytes);
}

TYPED_TEST(MessageRoundTrip, EveryTruncationIsADecodeErrorNotACrash) {
  const auto bytes = encodeMessage(example<TypeParam>());
  for (std::size_t length = 0; length < bytes.size(); ++length) {
    std::string error;
    const auto decoded = decodeMessage<TypeParam>(bytes.data(), length, &error);
    EXPECT_FALSE(decoded.has_value()) << "length " << length;
    EXPECT_NE(error.find(TypeParam::getTypeName()), std::string::npos) << error;
  }
}

TYPED_TEST(MessageRoundTrip, RandomBytesNeverCrashTheDecoder) {
  std::mt19937 rng(42);
  const auto bytes = encodeMessage(example<TypeParam>());
  for (int trial = 0; trial < 2000; ++trial) {
    auto corrupted = bytes;
    // Keep the fingerprint (first 8 bytes) so the corruption reaches the field decoders.
    std::uniform_int_distribution<std::size_t> position(8, corrupted.size() - 1);
    for (int flips = 0; flips < 4; ++flips)
      corrupted[position(rng)] ^= static_cast<std::uint8_t>(rng());
    (void)decodeMessage<TypeParam>(corrupted.data(), corrupted.size());
  }
  SUCCEED();
}

TYPED_TEST(MessageRoundTrip, AnyLengthFieldOverwrittenWithAHostileValueNeverCrashes) {
  // Every aligned or unaligned 4-byte window after the hash is treated as a length field and
  // overwritten: negative (a string of INT32_MIN bytes once read 2 GB past a 23-byte packet),
  // zero, one past the buffer, huge. The decoder must reject the message or decode exactly what
  // the bytes say.
  const auto bytes = encodeMessage(example<TypeParam>());
  const std::int32_t hostile[] = {INT32_MIN, -1, 0, static_cast<std::int32_t>(bytes.size()),
                                  INT32_MAX};
  for (std::size_t at = 8; at + 4 <= bytes.size(); ++at) {
    for (const std::int32_t value : hostile) {
      auto corrupted = bytes;
      const auto raw = static_cast<std::uint32_t>(value);
      for (int k = 0; k < 4; ++k)
        corrupted[at + k] = static_cast<std::uint8_t>(raw >> (24 - 8 * k));
      const auto decoded = decodeMessage<TypeParam>(corrupted.data(), corrupted.size());
      if (decoded) {
        EXPECT_EQ(encodeMessage(*decoded), corrupted) << "offset " << at;
      }
    }
  }
}

TYPED_TEST(MessageRoundTrip, TrailingBytesAreRejected) {
  auto bytes = encodeMessage(example<TypeParam>());
  bytes.push_back(0);
  std::string error;
  EXPECT_FALSE(decodeMessage<TypeParam>(bytes.data(), bytes.size(), &error).has_value());
  EXPECT_NE(error.find("trailing"), std::string::npos) << error;
}

TEST(MessageDecode, A23ByteCommandWhoseStringLengthIsInt32MinIsRejected) {
  // Hostile-input issue, row 1: this packet on SLAMD_COMMAND killed slamd with SIGSEGV.
  auto bytes = encodeMessage(example<slamd::command_t>());
  bytes.resize(8 + 8 + 1);  // hash, utime, command
  for (const std::uint8_t b : {0x80, 0x00, 0x00, 0x00, 0x41, 0x42}) bytes.push_back(b);
  ASSERT_EQ(bytes.size(), 23u);
  std::string error;
  EXPECT_FALSE(decodeMessage<slamd::command_t>(bytes.data(), bytes.size(), &error).has_value());
  EXPECT_NE(error.find("string length"), std::string::npos) << error;
}

TEST(MessageDecode, PoseAndStatusWithAnEmptyOrNegativeStringLengthAreRejected) {
  // Row 2: the same trick on SLAMD_POSE and SLAMD_STATUS killed slamd-pose-log and slamd-status.
  // A string's length counts its NUL: 0 is as impossible as negative.
  auto pose = encodeMessage(example<slamd::pose_t>());
  const std::size_t parent_frame_length = 8 + 8 + 8;  // hash, utime, sequence
  for (const std::uint8_t first : {0x80, 0x00}) {
    auto corrupted = pose;
    corrupted[parent_frame_length] = first;
    for (int k = 1; k < 4; ++k) corrupted[parent_frame_length + k] = 0;
    EXPECT_FALSE(decodeMessage<slamd::pose_t>(corrupted.data(), corrupted.size()).has_value());
  }
  auto status = encodeMessage(example<slamd::status_t>());
  // The message string is last: its length field sits 4 + 3 bytes ("ok" + NUL) from the end.
  const std::size_t message_length = status.size() - 7;
  for (const std::uint8_t first : {0x80, 0xFF}) {
    auto corrupted = status;
    for (int k = 0; k < 4; ++k) corrupted[message_length + k] = first;
    EXPECT_FALSE(decodeMessage<slamd::status_t>(corrupted.data(), corrupted.size()).has_value());
  }
}

TEST(MessageDecode, AnotherTypesBytesAreRejected) {
  const auto bytes = encodeMessage(example<slamd::pose_t>());
  std::string error;
  EXPECT_FALSE(decodeMessage<slamd::command_t>(bytes.data(), bytes.size(), &error).has_value());
  EXPECT_NE(error.find("command_t"), std::string::npos);
}

TEST(PoseCodec, PoseEstimateRoundTripsThroughPoseT) {
  PoseEstimate pose;
  pose.utime = 123;
  pose.sequence = 9;
  pose.T_world_camera = expSE3((Vector6d() << 1, 2, 3, 0.1, -0.2, 0.3).finished());
  pose.covariance = Matrix6d::Identity() * 0.01;
  pose.covariance(0, 5) = pose.covariance(5, 0) = 0.001;
  pose.linear_velocity_world_mps = Eigen::Vector3d(0.1, 0.2, 0.3);
  pose.tracking_state = TrackingState::kPredicted;
  pose.source = PoseSource::kOptimized;
  const PoseEstimate back = fromPoseMessage(toPoseMessage(pose));
  EXPECT_EQ(back.utime, 123);
  EXPECT_LT((back.T_world_camera.matrix() - pose.T_world_camera.matrix()).norm(), 1e-12);
  EXPECT_EQ(back.covariance, pose.covariance);
  EXPECT_EQ(back.tracking_state, TrackingState::kPredicted);
  EXPECT_EQ(back.source, PoseSource::kOptimized);
  const bot_core::pose_t bot = toBotCorePose(pose);
  EXPECT_DOUBLE_EQ(bot.pos[2], pose.T_world_camera.translation().z());
  const Eigen::Quaterniond q(pose.T_world_camera.linear());
  EXPECT_NEAR(std::abs(bot.orientation[0]), std::abs(q.w()), 1e-12);
}

TEST(PoseCodec, KeyframeTrajectoryRoundTrips) {
  const slamd::keyframe_trajectory_t message = example<slamd::keyframe_trajectory_t>();
  EXPECT_EQ(message.num_keyframes, 3);
  const KeyframeTrajectory back = fromKeyframeTrajectoryMessage(message);
  ASSERT_EQ(back.keyframes.size(), 3u);
  EXPECT_EQ(back.keyframes[2].keyframe_id, 2);
  EXPECT_NEAR(back.keyframes[2].T_world_camera.translation().x(), 0.6, 1e-12);
  EXPECT_NEAR(back.T_world_uncorrected.translation().y(), -0.2, 1e-12);
  EXPECT_EQ(back.num_loops, 1);
}

TEST(PoseEstimateTransform, ACorrectionRotatesTranslationCovarianceAndVelocityOnly) {
  PoseEstimate pose;
  pose.T_world_camera = expSE3((Vector6d() << 1, 0, 0, 0, 0, 0.2).finished());
  pose.covariance = Matrix6d::Zero();
  pose.covariance(0, 0) = 4e-4;  // 2 cm along world x
  pose.covariance(5, 5) = 1e-4;  // camera-frame rotation
  pose.linear_velocity_world_mps = Eigen::Vector3d(1, 0, 0);
  pose.angular_velocity_camera_radps = Eigen::Vector3d(0, 0, 0.5);
  // A correction turning the world by 90 degrees about z: world x becomes world y.
  const SE3 T_new_old =
      makeSE3(Eigen::Vector3d(0, 0, 1),
              Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ())));
  const PoseEstimate moved = transformedPose(pose, T_new_old);
  EXPECT_LT((moved.T_world_camera.matrix() - (T_new_old * pose.T_world_camera).matrix()).norm(),
            1e-12);
  EXPECT_NEAR(moved.covariance(0, 0), 0.0, 1e-15);
  EXPECT_NEAR(moved.covariance(1, 1), 4e-4, 1e-15);
  EXPECT_NEAR(moved.covariance(5, 5), 1e-4, 1e-15);
  EXPECT_LT((moved.linear_velocity_world_mps - Eigen::Vector3d(0, 1, 0)).norm(), 1e-12);
  EXPECT_EQ(moved.angular_velocity_camera_radps, pose.angular_velocity_camera_radps);
}

}  // namespace
}  // namespace slamd
