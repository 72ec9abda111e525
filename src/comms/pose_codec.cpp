#include "slamd/comms/pose_codec.hpp"

#include <cstdio>

namespace slamd {

namespace {
/// Writes a transform as LCM's position[3] + quaternion (w, x, y, z)[4].
void writeTransform(const SE3& T, double* position, double* orientation_wxyz) {
  const Eigen::Vector3d t = T.translation();
  const Eigen::Quaterniond q(T.linear());
  for (int i = 0; i < 3; ++i) position[i] = t[i];
  orientation_wxyz[0] = q.w();
  orientation_wxyz[1] = q.x();
  orientation_wxyz[2] = q.y();
  orientation_wxyz[3] = q.z();
}

SE3 readTransform(const double* position, const double* orientation_wxyz) {
  return makeSE3(Eigen::Vector3d(position[0], position[1], position[2]),
                 Eigen::Quaterniond(orientation_wxyz[0], orientation_wxyz[1], orientation_wxyz[2],
                                    orientation_wxyz[3]));
}
}  // namespace

slamd::pose_t toPoseMessage(const PoseEstimate& pose) {
  slamd::pose_t msg;
  msg.utime = pose.utime;
  msg.sequence = pose.sequence;
  msg.parent_frame = pose.parent_frame;
  msg.child_frame = pose.child_frame;
  writeTransform(pose.T_world_camera, msg.position, msg.orientation);
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) msg.covariance[r * 6 + c] = pose.covariance(r, c);
  }
  for (int i = 0; i < 3; ++i) {
    msg.linear_velocity[i] = pose.linear_velocity_world_mps[i];
    msg.angular_velocity[i] = pose.angular_velocity_camera_radps[i];
  }
  msg.tracking_state = static_cast<int8_t>(pose.tracking_state);
  msg.source = static_cast<int8_t>(pose.source);
  return msg;
}

PoseEstimate fromPoseMessage(const slamd::pose_t& msg) {
  PoseEstimate pose;
  pose.utime = msg.utime;
  pose.sequence = msg.sequence;
  pose.parent_frame = msg.parent_frame;
  pose.child_frame = msg.child_frame;
  pose.T_world_camera = readTransform(msg.position, msg.orientation);
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) pose.covariance(r, c) = msg.covariance[r * 6 + c];
  }
  for (int i = 0; i < 3; ++i) {
    pose.linear_velocity_world_mps[i] = msg.linear_velocity[i];
    pose.angular_velocity_camera_radps[i] = msg.angular_velocity[i];
  }
  pose.tracking_state = static_cast<TrackingState>(msg.tracking_state);
  pose.source = static_cast<PoseSource>(msg.source);
  return pose;
}

bot_core::pose_t toBotCorePose(const PoseEstimate& pose) {
  bot_core::pose_t msg;
  msg.utime = pose.utime;
  writeTransform(pose.T_world_camera, msg.pos, msg.orientation);
  for (int i = 0; i < 3; ++i) {
    msg.vel[i] = pose.linear_velocity_world_mps[i];
    msg.rotation_rate[i] = pose.angular_velocity_camera_radps[i];
    msg.accel[i] = 0.0;
  }
  return msg;
}

PoseEstimate fromBotCorePose(const bot_core::pose_t& msg) {
  PoseEstimate pose;
  pose.utime = msg.utime;
  pose.sequence = 0;
  pose.T_world_camera = readTransform(msg.pos, msg.orientation);
  for (int i = 0; i < 3; ++i) {
    pose.linear_velocity_world_mps[i] = msg.vel[i];
    pose.angular_velocity_camera_radps[i] = msg.rotation_rate[i];
  }
  return pose;
}

const char* const kPoseCsvHeader =
    "utime,sequence,tx,ty,tz,qw,qx,qy,qz,var_x,var_y,var_z,var_rx,var_ry,var_rz,tracking_state,"
    "source";

std::string formatPoseCsv(const PoseEstimate& pose) {
  const Eigen::Vector3d t = pose.T_world_camera.translation();
  const Eigen::Quaterniond q(pose.T_world_camera.linear());
  char buffer[512];
  std::snprintf(buffer, sizeof(buffer),
                "%lld,%lld,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.9f,%.3e,%.3e,%.3e,%.3e,%.3e,%.3e,%s,%d",
                static_cast<long long>(pose.utime), static_cast<long long>(pose.sequence), t.x(),
                t.y(), t.z(), q.w(), q.x(), q.y(), q.z(), pose.covariance(0, 0),
                pose.covariance(1, 1), pose.covariance(2, 2), pose.covariance(3, 3),
                pose.covariance(4, 4), pose.covariance(5, 5),
                trackingStateName(pose.tracking_state), static_cast<int>(pose.source));
  return buffer;
}

slamd::keyframe_trajectory_t toKeyframeTrajectoryMessage(const KeyframeTrajectory& trajectory) {
  slamd::keyframe_trajectory_t msg;
  msg.utime = trajectory.utime;
  msg.sequence = trajectory.sequence;
  msg.frame_id = trajectory.frame_id;
  writeTransform(trajectory.T_world_uncorrected, msg.correction_position,
                 msg.correction_orientation);
  msg.num_loops = trajectory.num_loops;
  msg.num_relocalizations = trajectory.num_relocalizations;
  msg.optimization_ms = static_cast<float>(trajectory.optimization_ms);
  msg.num_keyframes = static_cast<std::int32_t>(trajectory.keyframes.size());
  msg.keyframes.reserve(trajectory.keyframes.size());
  for (const KeyframePoseEntry& entry : trajectory.keyframes) {
    slamd::keyframe_pose_t keyframe;
    keyframe.keyframe_id = entry.keyframe_id;
    keyframe.utime = entry.utime;
    keyframe.segment = entry.segment;
    writeTransform(entry.T_world_camera, keyframe.position, keyframe.orientation);
    msg.keyframes.push_back(keyframe);
  }
  return msg;
}

KeyframeTrajectory fromKeyframeTrajectoryMessage(const slamd::keyframe_trajectory_t& msg) {
  KeyframeTrajectory trajectory;
  trajectory.utime = msg.utime;
  trajectory.sequence = msg.sequence;
  trajectory.frame_id = msg.frame_id;
  trajectory.T_world_uncorrected =
      readTransform(msg.correction_position, msg.correction_orientation);
  trajectory.num_loops = msg.num_loops;
  trajectory.num_relocalizations = msg.num_relocalizations;
  trajectory.optimization_ms = msg.optimization_ms;
  for (const slamd::keyframe_pose_t& keyframe : msg.keyframes) {
    trajectory.keyframes.push_back(
        KeyframePoseEntry{keyframe.keyframe_id, keyframe.utime, keyframe.segment,
                          readTransform(keyframe.position, keyframe.orientation)});
  }
  return trajectory;
}

}  // namespace slamd
