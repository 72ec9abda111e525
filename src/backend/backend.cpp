#include "slamd/backend/backend.hpp"

#include <algorithm>
#include <cmath>

namespace slamd {

namespace {

// Standard deviation (metres, radians) of the edge joining a new tracking segment to the
// previous keyframe: it only keeps the normal equations regular until a loop places the segment.
constexpr double kSegmentLinkSigma = 1e3;
constexpr double kOdometryFloorM = 0.005;
// Floor on tracking's own odometry covariance: the normal equations assume perfect matches.
constexpr double kTrackingFloorM = 0.001;
constexpr double kTrackingFloorRad = 0.05 * M_PI / 180.0;

double rotationAngle(const SE3& T) { return Eigen::AngleAxisd(T.rotation()).angle(); }

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

std::int64_t Backend::segmentRoot(std::int64_t segment) const {
  auto it = segment_parent_.find(segment);
  while (it != segment_parent_.end() && it->second != segment) {
    segment = it->second;
    it = segment_parent_.find(segment);
  }
  return segment;
}

BackendUpdate Backend::addKeyframe(const KeyframePtr& keyframe) { return add(keyframe, nullptr); }

BackendUpdate Backend::addKeyframe(const KeyframePtr& keyframe,
                                   const Matrix6d& covariance_prev_curr) {
  return add(keyframe, &covariance_prev_curr);
}

bool Backend::addEdge(const PoseGraphEdge& edge) {
  if (!graph_.addEdge(edge)) return false;
  neighbours_[edge.from_id].push_back(edge.to_id);
  neighbours_[edge.to_id].push_back(edge.from_id);
  return true;
}

double Backend::edgeChi2(const PoseGraphEdge& edge) const {
  const Vector6d e =
      poseGraphEdgeError(edge.T_from_to, graph_.pose(edge.from_id), graph_.pose(edge.to_id));
  return e.dot(edge.information * e);
}

std::vector<std::int64_t> Backend::localWindow(std::int64_t keyframe_id) const {
  // Breadth first from the new keyframe: nearest keyframes (in edges) first.
  std::vector<std::int64_t> window{keyframe_id};
  std::unordered_map<std::int64_t, int> hops{{keyframe_id, 0}};
  for (std::size_t head = 0; head < window.size(); ++head) {
    const std::int64_t id = window[head];
    const int h = hops.at(id);
    if (h >= config_.local_window_hops) continue;
    const auto it = neighbours_.find(id);
    if (it == neighbours_.end()) continue;
    for (std::int64_t next : it->second) {
      if (hops.count(next) != 0) continue;
      if (static_cast<int>(window.size()) >= config_.local_window_size) return window;
      hops[next] = h + 1;
      window.push_back(next);
    }
  }
  return window;
}

std::vector<LoopDetection> Backend::addLocalEdges(const Keyframe& keyframe, BackendUpdate& update) {
  std::vector<LoopDetection> added;
  if (config_.local_edges <= 0) return added;
  // The keyframes the local window reaches before this keyframe's own edges: an edge to one of
  // them closes a short cycle, which the window optimisation absorbs.
  const std::vector<std::int64_t> reach = localWindow(keyframe.id);
  const std::int64_t root = segmentRoot(keyframe.segment);
  const std::int64_t previous_id = previous_ != nullptr ? previous_->id : -1;
  // The previous keyframe is already linked by odometry from the same images; keyframes of
  // segments not joined to this one have no meaningful relative estimate to check against.
  const LoopDetector::KeyframeFilter allowed = [&](std::int64_t id, std::int64_t segment) {
    return id != previous_id && graph_.hasNode(id) && segmentRoot(segment) == root;
  };
  const SE3 T_world_query = graph_.pose(keyframe.id);
  const LoopDetector::PosePrior prior = [&](std::int64_t id, SE3& T_match_query) {
    if (!graph_.hasNode(id)) return false;
    T_match_query = graph_.pose(id).inverse() * T_world_query;
    return true;
  };
  const std::vector<LoopDetection> matches = detector_.matchLocal(keyframe, allowed, prior);
  const KeyframeInfo& query = keyframes_.at(keyframe.id);
  for (const LoopDetection& match : matches) {
    if (update.num_local_edges >= config_.local_edges) break;
    // False-match protection: the measured relative pose must agree with the current estimate
    // (odometry drift plus earlier corrections) within what drift allows over the path between.
    const SE3 T_estimate = graph_.pose(match.match_id).inverse() * T_world_query;
    const SE3 T_difference = T_estimate.inverse() * match.T_match_query;
    const auto info = keyframes_.find(match.match_id);
    const double path_m = info != keyframes_.end() && info->second.segment == keyframe.segment
                              ? std::abs(query.path_length_m - info->second.path_length_m)
                              : 0.0;
    const double allowed_m =
        config_.local_max_discrepancy_m + config_.local_max_discrepancy_ratio * path_m;
    if (T_difference.translation().norm() > allowed_m ||
        rotationAngle(T_difference) > config_.local_max_discrepancy_rad) {
      ++update.num_local_rejected;
      continue;
    }
    const PoseGraphEdge edge{match.match_id, keyframe.id, match.T_match_query, match.information,
                             EdgeKind::kLocal};
    if (addEdge(edge)) {
      // An edge far from closed between keyframes far apart in the graph (drift accumulated
      // along a long cycle) is a loop in effect: the correction must spread over the whole
      // graph.
      if (edgeChi2(edge) > config_.full_optimization_chi2 &&
          std::find(reach.begin(), reach.end(), match.match_id) == reach.end()) {
        update.full_optimization = true;
      }
      ++update.num_local_edges;
      ++num_local_edges_;
      added.push_back(match);
    }
  }
  return added;
}

void Backend::tryRelocalization(const Keyframe& keyframe, BackendUpdate& update) {
  const std::int64_t root = segmentRoot(keyframe.segment);
  const LoopDetector::KeyframeFilter other_map = [&](std::int64_t, std::int64_t segment) {
    return segmentRoot(segment) != root;
  };
  ++relocalization_attempts_;
  update.relocalization_attempted = true;
  update.relocalization_attempts = relocalization_attempts_;
  update.relocalization = detector_.query(keyframe.features, keyframe.intrinsics, other_map,
                                          config_.relocalization_min_inliers);
  update.relocalization.query_id = keyframe.id;
  if (update.relocalization.status != LoopStatus::kLoopFound) return;
  const LoopDetection& match = update.relocalization;
  if (!addEdge({match.match_id, keyframe.id, match.T_match_query, match.information,
                EdgeKind::kRelocalization})) {
    return;
  }
  // Move the whole new segment rigidly next to the match before optimising: the weak tie gives
  // no useful initial value, and LM converges from a consistent start.
  const SE3 T_world_query = graph_.pose(match.match_id) * match.T_match_query;
  const SE3 T_correction = T_world_query * graph_.pose(keyframe.id).inverse();
  for (std::int64_t id : graph_.nodeIds()) {
    const auto info = keyframes_.find(id);
    if (info != keyframes_.end() && segmentRoot(info->second.segment) == root) {
      graph_.setPose(id, T_correction * graph_.pose(id));
    }
  }
  const std::int64_t match_root = segmentRoot(keyframes_.at(match.match_id).segment);
  segment_parent_[root] = match_root;
  update.relocalized = true;
  ++num_relocalizations_;
}

BackendUpdate Backend::add(const KeyframePtr& keyframe, const Matrix6d* covariance_prev_curr) {
  BackendUpdate update;
  if (keyframe == nullptr || graph_.hasNode(keyframe->id)) return update;
  update.keyframe_id = keyframe->id;
  KeyframeInfo info;
  info.segment = keyframe->segment;
  bool new_segment = false;
  if (previous_ == nullptr) {
    graph_.addNode(keyframe->id, keyframe->T_world_camera);
    first_segment_ = keyframe->segment;
  } else {
    // Initial value: the previous keyframe's corrected pose composed with the odometry step.
    const SE3 T_prev_curr = previous_->T_world_camera.inverse() * keyframe->T_world_camera;
    graph_.addNode(keyframe->id, graph_.pose(previous_->id) * T_prev_curr);
    PoseGraphEdge edge{previous_->id, keyframe->id, T_prev_curr, odometryInformation(T_prev_curr),
                       EdgeKind::kOdometry};
    new_segment = keyframe->segment != previous_->segment;
    if (new_segment) {
      edge.information = Matrix6d::Identity() / (kSegmentLinkSigma * kSegmentLinkSigma);
      relocalization_attempts_ = 0;
    } else {
      info.path_length_m =
          keyframes_.at(previous_->id).path_length_m + T_prev_curr.translation().norm();
      if (covariance_prev_curr != nullptr && covariance_prev_curr->allFinite()) {
        Matrix6d covariance = 0.5 * (*covariance_prev_curr + covariance_prev_curr->transpose());
        for (int k = 0; k < 3; ++k) covariance(k, k) += kTrackingFloorM * kTrackingFloorM;
        for (int k = 3; k < 6; ++k) covariance(k, k) += kTrackingFloorRad * kTrackingFloorRad;
        const Matrix6d information = covariance.inverse();
        if (information.allFinite()) {
          edge.information = 0.5 * (information + information.transpose());
        }
      }
    }
    addEdge(edge);
  }
  keyframes_[keyframe->id] = info;
  segment_parent_.emplace(keyframe->segment, keyframe->segment);

  bool changed = false;
  bool full = false;  // a correction the local window cannot absorb
  // Relocalisation first: once the segment is joined, this keyframe's local edges can reach the
  // map it joined.
  if (config_.relocalization && segmentRoot(keyframe->segment) != segmentRoot(first_segment_)) {
    tryRelocalization(*keyframe, update);
    changed = changed || update.relocalized;
    full = update.relocalized;
  }

  const std::vector<LoopDetection> local = addLocalEdges(*keyframe, update);
  full = full || update.full_optimization;
  changed = changed || (config_.optimize_every_keyframe && update.num_local_edges > 0);

  previous_ = keyframe;
  update.loop = detector_.processKeyframe(*keyframe, local);
  const PoseGraphEdge loop_edge{update.loop.match_id, update.loop.query_id,
                                update.loop.T_match_query, update.loop.information,
                                EdgeKind::kLoop};
  // A loop to a keyframe this one already has a local edge with is that edge (the same
  // measurement): counted as a loop, not added twice.
  const bool duplicate = std::any_of(local.begin(), local.end(), [&](const LoopDetection& d) {
    return d.match_id == update.loop.match_id;
  });
  if (update.loop.status == LoopStatus::kLoopFound && (duplicate || addEdge(loop_edge))) {
    ++num_loops_;
    changed = true;
    full = full || (!duplicate && edgeChi2(loop_edge) > config_.full_optimization_chi2);
    // A loop into another segment joins the two maps as a relocalisation does.
    const auto match = keyframes_.find(update.loop.match_id);
    if (match != keyframes_.end()) {
      const std::int64_t a = segmentRoot(match->second.segment);
      const std::int64_t b = segmentRoot(keyframe->segment);
      if (a != b) segment_parent_[b] = a;
    }
  }
  if (changed) {
    if (full || config_.local_window_hops == 0) {
      update.optimization = graph_.optimize(options_);
      update.full_optimization = true;
    } else {
      PoseGraphOptions options = options_;
      options.max_iterations = std::min(options.max_iterations, config_.local_max_iterations);
      update.optimization = graph_.optimize(options, localWindow(keyframe->id));
    }
    update.optimized = true;
    update.corrected_poses.reserve(graph_.numNodes());
    for (std::int64_t id : graph_.nodeIds())
      update.corrected_poses.emplace_back(id, graph_.pose(id));
  } else {
    update.full_optimization = false;
  }
  // After the loop search too: a loop into the map also joins a new segment.
  update.relocalization_pending = segmentRoot(keyframe->segment) != segmentRoot(first_segment_);
  update.T_world_odometry = graph_.pose(keyframe->id) * keyframe->T_world_camera.inverse();
  return update;
}

}  // namespace slamd
