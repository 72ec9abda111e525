#include "slamd/backend/backend.hpp"

namespace slamd {

namespace {

// Standard deviation (metres, radians) of the edge joining a new tracking segment to the
// previous keyframe: it only keeps the normal equations regular until a loop places the segment.
constexpr double kSegmentLinkSigma = 1e3;
constexpr double kOdometryFloorM = 0.005;

}  // namespace

Backend::Backend(const BackendConfig& config, std::shared_ptr<const Vocabulary> vocabulary)
    : config_(config),
      options_(PoseGraphOptions::fromConfig(config)),
      detector_(config, std::move(vocabulary)) {}

Matrix6d Backend::odometryInformation(const SE3& T_prev_curr) const {
  const double sigma_m =
      config_.odometry_sigma_ratio * T_prev_curr.translation().norm() + kOdometryFloorM;
  Vector6d diagonal;
  diagonal << Eigen::Vector3d::Constant(1.0 / (sigma_m * sigma_m)),
      Eigen::Vector3d::Constant(1.0 / (config_.odometry_sigma_rad * config_.odometry_sigma_rad));
  return diagonal.asDiagonal();
}

BackendUpdate Backend::addKeyframe(const KeyframePtr& keyframe) {
  BackendUpdate update;
  if (keyframe == nullptr) return update;
  update.keyframe_id = keyframe->id;
  if (previous_ == nullptr) {
    graph_.addNode(keyframe->id, keyframe->T_world_camera);
  } else {
    // Initial value: the previous keyframe's corrected pose composed with the odometry step.
    const SE3 T_prev_curr = previous_->T_world_camera.inverse() * keyframe->T_world_camera;
    graph_.addNode(keyframe->id, graph_.pose(previous_->id) * T_prev_curr);
    PoseGraphEdge edge{previous_->id, keyframe->id, T_prev_curr, odometryInformation(T_prev_curr),
                       EdgeKind::kOdometry};
    if (keyframe->segment != previous_->segment) {
      edge.information = Matrix6d::Identity() / (kSegmentLinkSigma * kSegmentLinkSigma);
    }
    graph_.addEdge(edge);
  }
  previous_ = keyframe;

  update.loop = detector_.processKeyframe(*keyframe);
  if (update.loop.status == LoopStatus::kLoopFound &&
      graph_.addEdge({update.loop.match_id, update.loop.query_id, update.loop.T_match_query,
                      update.loop.information, EdgeKind::kLoop})) {
    ++num_loops_;
    update.optimization = graph_.optimize(options_);
    update.optimized = true;
    update.corrected_poses.reserve(graph_.numNodes());
    for (std::int64_t id : graph_.nodeIds()) update.corrected_poses.emplace_back(id, graph_.pose(id));
  }
  update.T_world_odometry = graph_.pose(keyframe->id) * keyframe->T_world_camera.inverse();
  return update;
}

}  // namespace slamd
