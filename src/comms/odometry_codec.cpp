#include "slamd/comms/odometry_codec.hpp"

namespace slamd {

slamd::odometry_t toOdometryMessage(const OdometryResult& odometry) {
  slamd::odometry_t msg;
  msg.utime = odometry.utime;
  msg.prev_utime = odometry.prev_utime;
  const Eigen::Vector3d t = odometry.T_prev_curr.translation();
  const Eigen::Quaterniond q(odometry.T_prev_curr.linear());
  for (int i = 0; i < 3; ++i) msg.translation[i] = t[i];
  msg.rotation[0] = q.w();
  msg.rotation[1] = q.x();
  msg.rotation[2] = q.y();
  msg.rotation[3] = q.z();
  for (int r = 0; r < 6; ++r) {
    for (int c = 0; c < 6; ++c) msg.covariance[r * 6 + c] = odometry.covariance(r, c);
  }
  msg.status = static_cast<int8_t>(odometry.status);
  msg.num_features = odometry.stats.num_features;
  msg.num_matches = odometry.stats.num_matches;
  msg.num_inliers = odometry.stats.num_inliers;
  msg.reprojection_error_px = odometry.stats.reprojection_error_px;
  msg.is_keyframe = odometry.is_keyframe;
  msg.reference_keyframe_id = odometry.reference_keyframe_id;
  return msg;
}

slamd::vanishing_point_t toVanishingPointMessage(Utime utime, const VanishingPointReport& report) {
  slamd::vanishing_point_t msg;
  msg.utime = utime;
  msg.pixel[0] = report.detection.pixel.x();
  msg.pixel[1] = report.detection.pixel.y();
  for (int r = 0; r < 2; ++r) {
    for (int c = 0; c < 2; ++c) {
      msg.pixel_covariance[r * 2 + c] = report.detection.pixel_covariance(r, c);
    }
  }
  for (int i = 0; i < 3; ++i) msg.direction_camera[i] = report.detection.direction_camera[i];
  msg.num_supporting_lines = report.detection.num_supporting_lines;
  msg.landmark_id = report.update.landmark_id;
  msg.accepted = report.update.accepted;
  msg.mahalanobis_distance_sq = report.update.nis;
  return msg;
}

}  // namespace slamd
