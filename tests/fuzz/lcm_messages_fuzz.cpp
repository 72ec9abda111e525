// Fuzz target: every LCM type slamd or its clients receive, as raw bytes off the network.
//
// A peer can send any bytes on any channel, so each input is decoded as every type, the way
// LcmBus would (decodeMessage: the structural precheck, then lcm-gen's decoder). What decodes
// is handed to the code that consumes that type on the receiving side: the frame codecs, the
// command path check, the pose, keyframe-trajectory, status and plane map readers, and a map
// replica.

#include <filesystem>
#include <string>

#include "fuzz_input.hpp"
#include "slamd/app/command_save_path.hpp"
#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/map_codec.hpp"
#include "slamd/comms/message_codec.hpp"
#include "slamd/comms/plane_map_codec.hpp"
#include "slamd/comms/pose_codec.hpp"
#include "slamd/comms/status_codec.hpp"

namespace {

using namespace slamd;

template <typename Message, typename Consume>
void decodeAs(const std::uint8_t* data, std::size_t size, Consume consume) {
  std::string error;
  if (auto message = decodeMessage<Message>(data, size, &error)) consume(*message);
}

template <typename Message>
void decodeAs(const std::uint8_t* data, std::size_t size) {
  decodeAs<Message>(data, size, [](const Message&) {});
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  decodeAs<slamd::rgbd_frame_t>(data, size, [](const slamd::rgbd_frame_t& message) {
    try {
      decodeRgbdFrame(message);
    } catch (const FrameDecodeError&) {
    }
  });
  decodeAs<kinect::frame_msg_t>(data, size, [](const kinect::frame_msg_t& message) {
    try {
      decodeKinectFrame(message, CameraIntrinsics{});
    } catch (const FrameDecodeError&) {
    }
  });
  decodeAs<kinect::image_msg_t>(data, size);
  decodeAs<kinect::depth_msg_t>(data, size);
  decodeAs<slamd::command_t>(data, size, [](const slamd::command_t& command) {
    // A save directory that does not exist: path resolution must not need one.
    static const std::string save_dir =
        (std::filesystem::temp_directory_path() / "slamd-fuzz-save-dir-absent").string();
    std::string error;
    resolveCommandSavePath(command.argument, save_dir, error);
  });
  decodeAs<slamd::pose_t>(data, size,
                          [](const slamd::pose_t& message) { fromPoseMessage(message); });
  decodeAs<slamd::keyframe_trajectory_t>(
      data, size,
      [](const slamd::keyframe_trajectory_t& message) { fromKeyframeTrajectoryMessage(message); });
  decodeAs<slamd::status_t>(data, size,
                            [](const slamd::status_t& message) { renderStatusTable(message, 1); });
  decodeAs<slamd::voxel_map_update_t>(data, size, [](const slamd::voxel_map_update_t& message) {
    if (auto update = fromMapUpdateMessage(message)) {
      MapReplica replica;
      replica.applyUpdate(*update);
    }
  });
  decodeAs<slamd::voxel_map_t>(data, size, [](const slamd::voxel_map_t& message) {
    if (auto map = fromFullMapMessage(message)) {
      MapReplica replica;
      replica.applyFullMap(*map);
    }
  });
  decodeAs<slamd::plane_map_t>(
      data, size, [](const slamd::plane_map_t& message) { fromPlaneMapMessage(message); });
  decodeAs<slamd::plane_t>(data, size);
  decodeAs<slamd::odometry_t>(data, size);
  decodeAs<slamd::vanishing_point_t>(data, size);
  decodeAs<slamd::stage_status_t>(data, size);
  decodeAs<slamd::keyframe_pose_t>(data, size);
  decodeAs<slamd::voxel_t>(data, size);
  decodeAs<bot_core::pose_t>(data, size);
  return 0;
}
