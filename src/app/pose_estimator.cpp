#include "slamd/app/pose_estimator.hpp"

#include <cmath>

#include "slamd/common/log.hpp"
#include "slamd/filter/motion_fusion.hpp"
#include "slamd/planes/plane_registration.hpp"

namespace slamd {

PoseEstimator::PoseEstimator(const FilterConfig& config, VanishingPointSource vanishing_points)
    : config_(config), vanishing_point_source_(vanishing_points) {}

void PoseEstimator::reset() {
  filter_.reset();
  last_pose_ = PoseEstimate();
  covariance_last_measured_.reset();
  last_utime_ = 0;
  corridor_.on.store(false, std::memory_order_relaxed);
  frames_with_features_ = 0;
  plane_anchors_.clear();
  previous_planes_.reset();
  previous_reference_pose_.reset();
}

void PoseEstimator::updateCorridorMode(const OdometryResult& odometry) {
  if (!config_.planes.enabled) return;
  const bool measured_by_features = (odometry.tracking_state == TrackingState::kOk ||
                                     odometry.tracking_state == TrackingState::kRelocalized) &&
                                    !odometry.stats.used_dense_alignment;
  const bool features_ran_out =
      !measured_by_features || odometry.stats.num_inliers < config_.planes.corridor_min_inliers;
  const bool on = corridor_.on.load(std::memory_order_relaxed);
  if (features_ran_out) {
    frames_with_features_ = 0;
    if (!on) {
      corridor_.on.store(true, std::memory_order_relaxed);
      corridor_.switched_on.fetch_add(1, std::memory_order_relaxed);
    }
  } else if (on && ++frames_with_features_ >= config_.planes.corridor_exit_frames) {
    corridor_.on.store(false, std::memory_order_relaxed);
  }
  if (corridor_.on.load(std::memory_order_relaxed)) {
    corridor_.frames.fetch_add(1, std::memory_order_relaxed);
  }
}

void PoseEstimator::fusePlaneOdometry(
    const std::shared_ptr<const planes::PlaneSegmentation>& planes, const OdometryResult& odometry,
    const CameraIntrinsics& intrinsics, FilterInput& input) {
  // (The first frame has no motion to fuse: it only defines the world frame.)
  const bool measured =
      odometry.tracking_state == TrackingState::kOk && odometry.ref_utime > 0 && last_utime_ > 0;
  if (!measured) {
    previous_reference_pose_.reset();
    previous_planes_.reset();
    // A keyframe is a reference whatever measured it (the first frame of a segment too).
    if (planes && odometry.is_keyframe) {
      plane_anchors_.push_back(PlaneAnchor{odometry.utime, 0, SE3::Identity(), planes});
      if (plane_anchors_.size() > kMaxPlaneAnchors) plane_anchors_.pop_front();
    }
    return;
  }
  const Utime ref_utime = odometry.ref_utime;
  // The previous frame's pose relative to this frame's reference: as given to the filter when it
  // had the same reference, else tracking's.
  const bool same_reference = previous_reference_pose_ &&
                              previous_reference_pose_->utime == odometry.prev_utime &&
                              previous_reference_pose_->ref_utime == ref_utime;
  const SE3 T_ref_prev = same_reference ? previous_reference_pose_->T_ref_frame
                                        : odometry.T_ref_curr * odometry.T_prev_curr.inverse();
  if (!planes) {
    // Not segmented: tracking's increment, which carries the correction the previous frame had
    // on (returning to tracking's T_ref_curr would undo it within one frame).
    previous_reference_pose_ =
        ReferencePose{odometry.utime, ref_utime, normalizedSE3(T_ref_prev * odometry.T_prev_curr)};
    previous_planes_.reset();
    return;
  }
  // The anchor: the reference itself when it was segmented, else the first segmented frame
  // measured from it, whose pose relative to the reference is known.
  const PlaneAnchor* anchor = nullptr;
  SE3 T_ref_anchor = SE3::Identity();
  if (previous_planes_ && previous_planes_->utime == ref_utime) anchor = &*previous_planes_;
  for (const PlaneAnchor& candidate : plane_anchors_) {
    if (anchor) break;
    if (candidate.utime == ref_utime) anchor = &candidate;
  }
  for (const PlaneAnchor& candidate : plane_anchors_) {
    if (anchor) break;
    if (candidate.ref_utime == ref_utime) {
      anchor = &candidate;
      T_ref_anchor = candidate.T_ref_frame;
    }
  }
  const bool reference_has_anchor = anchor != nullptr;

  SE3 T_ref_curr = odometry.T_ref_curr;
  bool fused = false;
  if (!anchor) {
    corridor_.unmatched.fetch_add(1, std::memory_order_relaxed);
  } else {
    planes::IcpParams params;
    params.points_per_plane = config_.planes.points_per_plane;
    // The current frame's planes are the source, the anchor's the target; tracking's estimate
    // is the starting point (at a turn the identity can be several centimetres off at the
    // walls, beyond where the associations converge).
    const planes::IcpResult icp = planes::registerPlanes(
        *planes, *anchor->planes, intrinsics, T_ref_anchor.inverse() * odometry.T_ref_curr, params);
    if (!icp.ok) {
      corridor_.registrations_failed.fetch_add(1, std::memory_order_relaxed);
    } else {
      // The information is of a right perturbation of T_anchor_curr, which is also one of
      // T_ref_anchor * T_anchor_curr.
      Matrix6d information = icp.information * config_.planes.information_scale;
      if (!config_.planes.fuse_rotation) information = translationInformation(information);
      // The EKF scales the odometry covariance by odometry_covariance_scale; fusing against the
      // scaled one weighs the two as the filter will.
      const double scale = config_.odometry_covariance_scale;
      const SE3 T_ref_curr_planes = T_ref_anchor * icp.T_target_source;
      const MotionFusionResult fusion =
          fuseMotion(odometry.T_ref_curr, odometry.covariance_ref_curr * scale, T_ref_curr_planes,
                     information, config_.planes.gate_probability);
      if (logLevel() <= LogLevel::kDebug) {
        // How far the planes' T_ref_curr is from tracking's, in tracking's camera frame.
        const Vector6d disagreement = logSE3(odometry.T_ref_curr.inverse() * T_ref_curr_planes);
        SLAMD_LOG_DEBUG("filter") << "plane increment " << odometry.utime << " (reference "
                                  << ref_utime << ", "
                                  << (odometry.stats.used_dense_alignment
                                          ? std::string("dense alignment")
                                          : std::to_string(odometry.stats.num_inliers) + " inliers")
                                  << "): " << (fusion.fused ? "fused" : "not fused") << ", NIS "
                                  << fusion.nis << " of " << fusion.gate_chi2 << " over "
                                  << fusion.measured_directions
                                  << " directions; planes - tracking: rotation "
                                  << disagreement.tail<3>().transpose() * 180.0 / M_PI
                                  << " deg, translation "
                                  << disagreement.head<3>().transpose() * 1000.0 << " mm";
      }
      if (fusion.fused) {
        fused = true;
        T_ref_curr = fusion.T_prev_curr;
        input.covariance = fusion.covariance / scale;
        corridor_.fused.fetch_add(1, std::memory_order_relaxed);
        corridor_.nis_sum_milli.fetch_add(
            static_cast<std::uint64_t>(std::lround(fusion.nis * 1000.0)),
            std::memory_order_relaxed);
      } else if (fusion.measured_directions > 0) {
        corridor_.gated.fetch_add(1, std::memory_order_relaxed);
      }
    }
  }

  // A fused frame's increment is the step from the previous frame's pose to the fused one, both
  // relative to the reference. A frame not fused (gated, or no anchor) keeps tracking's increment
  // and with it the previous frame's correction, as above.
  if (fused) {
    input.T_prev_curr = normalizedSE3(T_ref_prev.inverse() * T_ref_curr);
  } else {
    T_ref_curr = normalizedSE3(T_ref_prev * odometry.T_prev_curr);
  }
  previous_reference_pose_ = ReferencePose{odometry.utime, ref_utime, T_ref_curr};

  PlaneAnchor self{odometry.utime, ref_utime, T_ref_curr, planes};
  if (odometry.is_keyframe || !reference_has_anchor) {
    plane_anchors_.push_back(self);
    if (plane_anchors_.size() > kMaxPlaneAnchors) plane_anchors_.pop_front();
  }
  previous_planes_ = std::move(self);
}

EstimatedPacket PoseEstimator::process(TrackedPacket packet) {
  EstimatedPacket out;
  out.frame = std::move(packet.frame);
  out.odometry = std::move(packet.odometry);
  out.reset_epoch = packet.reset_epoch;
  out.pose = last_pose_;
  if (!out.frame || !out.odometry) return out;  // heartbeat

  const OdometryResult& odometry = *out.odometry;
  const RgbdFrame& frame = *out.frame;
  if (!filter_) filter_.emplace(config_, frame.intrinsics);
  FilterInput input;
  input.utime = odometry.utime;
  // The first frame defines the world frame: no motion to apply.
  input.T_prev_curr = last_utime_ > 0 ? odometry.T_prev_curr : SE3::Identity();
  input.covariance = last_utime_ > 0 ? odometry.covariance : Matrix6d::Identity() * 1e-12;
  input.dt_s = last_utime_ > 0 ? utimeToSeconds(odometry.utime - last_utime_) : 0.0;
  updateCorridorMode(odometry);
  if (config_.planes.enabled) {
    fusePlaneOdometry(packet.plane_segmentation ? packet.plane_segmentation->planes : nullptr,
                      odometry, frame.intrinsics, input);
  }
  // (A covariance of the last measured frame implies an earlier frame: last_utime_ > 0.)
  if (odometry.tracking_state == TrackingState::kRelocalized && covariance_last_measured_) {
    // The step from the pose held through the loss to the relocalised one is applied exactly,
    // with the covariance of the last measured frame plus the measurement's (rotated into the
    // filter's convention: translation in the world frame).
    PoseEkf& ekf = filter_->ekf();
    const SE3 T_world_curr = normalizedSE3(ekf.T_world_camera() * input.T_prev_curr);
    Matrix6d J = Matrix6d::Identity();
    J.topLeftCorner<3, 3>() = T_world_curr.linear();
    const Matrix6d measurement = J * odometry.covariance_ref_curr * J.transpose();
    Matrix6d covariance = *covariance_last_measured_;
    if (measurement.allFinite()) covariance += measurement;
    ekf.setPose(T_world_curr, covariance);
    input.T_prev_curr = SE3::Identity();
    input.covariance = Matrix6d::Identity() * 1e-12;
  }
  input.depth_m = frame.depth_m;  // plane axes (filter.surface_axes) are detected here
  if (vanishing_point_source_ == VanishingPointSource::kDetectHere) {
    input.gray = frame.gray;
  } else {
    input.detection = std::move(packet.vanishing_point);
  }
  const FilterOutput filtered = filter_->process(input);
  if (odometry.tracking_state == TrackingState::kOk ||
      odometry.tracking_state == TrackingState::kRelocalized) {
    covariance_last_measured_ = filter_->ekf().poseCovariance();
  }
  if (filtered.vanishing_point && filtered.update) {
    out.vanishing_point = VanishingPointReport{*filtered.vanishing_point, *filtered.update};
  }

  PoseEstimate& pose = out.pose;
  pose = filtered.pose;
  pose.utime = odometry.utime;
  pose.sequence = sequence_++;
  pose.tracking_state = odometry.tracking_state;
  pose.source = config_.enabled ? PoseSource::kFilter : PoseSource::kOdometry;
  if (input.dt_s > 0.0) {
    const SE3& previous = last_pose_.T_world_camera;
    pose.linear_velocity_world_mps =
        (pose.T_world_camera.translation() - previous.translation()) / input.dt_s;
    pose.angular_velocity_camera_radps =
        logSE3(previous.inverse() * pose.T_world_camera).tail<3>() / input.dt_s;
  }
  last_pose_ = pose;
  last_utime_ = odometry.utime;
  return out;
}

}  // namespace slamd
