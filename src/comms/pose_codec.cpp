#include "slamd/comms/pose_codec.hpp"

namespace slamd {

slamd::pose_t toPoseMessage(const PoseEstimate& pose) {
  slamd::pose_t msg;
  msg.utime = pose.utime;
  msg.sequence = pose.sequence;
  msg.parent_frame = pose.parent_frame;
  msg.child_frame = pose.child_frame;
  const Eigen::Vector3d t = pose.T_world_camera.translation();
  const Eigen::Quaterniond q(pose.T_world_camera.linear());
  for (int i = 0; i < 3; ++i) msg.position[i] = t[i];
  msg.orientation[0] = q.w();
  msg.orientation[1] = q.x();
  msg.orientation[2] = q.y();
  msg.orientation[3] = q.z();
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
  pose.T_world_camera =
      makeSE3(Eigen::Vector3d(msg.position[0], msg.position[1], msg.position[2]),
              Eigen::Quaterniond(msg.orientation[0], msg.orientation[1], msg.orientation[2],
                                 msg.orientation[3]));
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
  const Eigen::Vector3d t = pose.T_world_camera.translation();
  const Eigen::Quaterniond q(pose.T_world_camera.linear());
  for (int i = 0; i < 3; ++i) {
    msg.pos[i] = t[i];
    msg.vel[i] = pose.linear_velocity_world_mps[i];
    msg.rotation_rate[i] = pose.angular_velocity_camera_radps[i];
    msg.accel[i] = 0.0;
  }
  msg.orientation[0] = q.w();
  msg.orientation[1] = q.x();
  msg.orientation[2] = q.y();
  msg.orientation[3] = q.z();
  return msg;
}

}  // namespace slamd
