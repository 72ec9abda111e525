#include "slamd/filter/vanishing_point_filter.hpp"

namespace slamd {

VanishingPointFilter::VanishingPointFilter(const FilterConfig& config,
                                           const CameraIntrinsics& intrinsics)
    : config_(config),
      detector_(intrinsics, config.vp),
      axis_detector_(config.axes, intrinsics),
      ekf_(config, intrinsics) {}

FilterOutput VanishingPointFilter::process(const FilterInput& input) {
  FilterOutput out;
  out.predict_status = ekf_.predict(input.T_prev_curr, input.covariance, input.dt_s);
  if (config_.enabled && config_.vanishing_points && (input.detection || !input.gray.empty())) {
    out.vanishing_point = input.detection ? *input.detection : detector_.detect(input.gray);
    if (out.vanishing_point->status == VanishingPointStatus::kOk &&
        out.vanishing_point->num_supporting_lines >= config_.min_update_lines) {
      out.update = ekf_.updateVanishingPoint(out.vanishing_point->pixel,
                                             out.vanishing_point->pixel_covariance);
    }
  }
  if (config_.enabled && config_.surface_axes && !input.depth_m.empty()) {
    out.surface_axes = axis_detector_.detect(input.depth_m);
    for (const SurfaceAxis& axis : out.surface_axes->axes) {
      out.axis_updates.push_back(ekf_.updateDirection(axis.direction_camera, axis.covariance));
    }
  }
  out.pose.utime = input.utime;
  out.pose.sequence = steps_++;
  out.pose.T_world_camera = ekf_.T_world_camera();
  out.pose.covariance = ekf_.poseCovariance();
  out.pose.tracking_state = out.predict_status == EkfPredictStatus::kRejected
                                ? TrackingState::kPredicted
                                : TrackingState::kOk;
  out.pose.source = config_.enabled ? PoseSource::kFilter : PoseSource::kOdometry;
  return out;
}

}  // namespace slamd
