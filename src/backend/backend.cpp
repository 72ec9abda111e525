#include "slamd/backend/backend.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

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

Backend::LocalMatches Backend::addLocalEdges(const Keyframe& keyframe, BackendUpdate& update) {
  LocalMatches out;
  if (config_.local_edges <= 0) return out;
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
  std::vector<const LoopDetection*> accepted;
  for (const LoopDetection& match : matches) {
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
    out.agreeing.push_back(match);
    if (static_cast<int>(accepted.size()) < config_.local_edges) accepted.push_back(&match);
  }
  // Every local edge of this keyframe is measured from the same features of it: n edges counted
  // as independent would hold n times the information those observations carry. Covariance
  // intersection with equal weights keeps their sum consistent whatever the correlation.
  const double information_share = config_.local_edges_share_information && !accepted.empty()
                                       ? 1.0 / static_cast<double>(accepted.size())
                                       : 1.0;
  for (const LoopDetection* accepted_match : accepted) {
    const LoopDetection& match = *accepted_match;
    const PoseGraphEdge edge{match.match_id, keyframe.id, match.T_match_query,
                             match.information * information_share, EdgeKind::kLocal};
    if (addEdge(edge)) {
      // An edge far from closed between keyframes far apart in the graph (drift accumulated
      // along a long cycle) is a loop in effect: the correction must spread over the whole
      // graph.
      // (Judged at the measurement's own precision, before its share.)
      if (edgeChi2(edge) / information_share > config_.full_optimization_chi2 &&
          std::find(reach.begin(), reach.end(), match.match_id) == reach.end()) {
        update.full_optimization = true;
      }
      ++update.num_local_edges;
      ++num_local_edges_;
      out.added.push_back(match);
    }
  }
  return out;
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

PoseGraphEdge Backend::odometryEdge(const Keyframe& keyframe, const Matrix6d* covariance_prev_curr,
                                    bool new_segment, KeyframeInfo& info) const {
  const SE3 T_prev_curr = previous_->T_world_camera.inverse() * keyframe.T_world_camera;
  PoseGraphEdge edge{previous_->id, keyframe.id, T_prev_curr, odometryInformation(T_prev_curr),
                     EdgeKind::kOdometry};
  if (new_segment) {
    edge.information = Matrix6d::Identity() / (kSegmentLinkSigma * kSegmentLinkSigma);
  } else {
    info.path_length_m =
        keyframes_.at(previous_->id).path_length_m + T_prev_curr.translation().norm();
    if (covariance_prev_curr != nullptr && covariance_prev_curr->allFinite()) {
      Matrix6d covariance = 0.5 * (*covariance_prev_curr + covariance_prev_curr->transpose());
      for (int k = 0; k < 3; ++k) covariance(k, k) += kTrackingFloorM * kTrackingFloorM;
      for (int k = 3; k < 6; ++k) covariance(k, k) += kTrackingFloorRad * kTrackingFloorRad;
      const Matrix6d information = covariance.inverse();
      if (information.allFinite()) edge.information = 0.5 * (information + information.transpose());
    }
  }
  const auto culled = culled_.find(previous_->id);
  if (culled == culled_.end()) return edge;
  // The previous keyframe was merged into its anchor: start the edge there.
  const PoseGraphEdge anchor_to_previous{culled->second.anchor_id, previous_->id,
                                         culled->second.T_anchor_keyframe,
                                         culled->second.information, EdgeKind::kOdometry};
  return composedEdge(anchor_to_previous, edge, EdgeKind::kOdometry);
}

SE3 Backend::pose(std::int64_t keyframe_id) const {
  if (graph_.hasNode(keyframe_id)) return graph_.pose(keyframe_id);
  const CulledKeyframe& culled = culled_.at(keyframe_id);
  return graph_.pose(culled.anchor_id) * culled.T_anchor_keyframe;
}

MapKeyframes Backend::keyframesNear(std::int64_t anchor_id, double max_translation_m,
                                    double max_rotation_deg, std::size_t max_count) const {
  MapKeyframes near;
  const auto anchor = keyframes_.find(anchor_id);
  if (anchor == keyframes_.end() || !hasKeyframe(anchor_id)) return near;
  near.anchor_id = anchor_id;
  const std::int64_t map = segmentRoot(anchor->second.segment);
  near.relocalization_pending = config_.relocalization && map != segmentRoot(first_segment_);
  const SE3 T_anchor_world = pose(anchor_id).inverse();
  struct Candidate {
    double distance = 0.0;  ///< translation and rotation, each over its bound
    std::int64_t id = -1;
    SE3 T_anchor_keyframe;
  };
  std::vector<Candidate> candidates;
  for (const std::int64_t id : graph_.nodeIds()) {
    if (id == anchor_id || segmentRoot(keyframes_.at(id).segment) != map) continue;
    const SE3 T_anchor_keyframe = T_anchor_world * graph_.pose(id);
    const double translation_m = T_anchor_keyframe.translation().norm();
    const double rotation_deg = rotationAngleRad(T_anchor_keyframe.linear()) * 180.0 / M_PI;
    if (translation_m > max_translation_m || rotation_deg > max_rotation_deg) continue;
    candidates.push_back({translation_m / max_translation_m + rotation_deg / max_rotation_deg, id,
                          T_anchor_keyframe});
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.distance < b.distance; });
  for (const Candidate& candidate : candidates) {
    if (near.members.size() >= max_count) break;
    KeyframePtr keyframe = detector_.keyframe(candidate.id);
    if (keyframe != nullptr)
      near.members.push_back({std::move(keyframe), candidate.T_anchor_keyframe});
  }
  return near;
}

std::vector<std::int64_t> Backend::culledKeyframeIds() const {
  std::vector<std::int64_t> ids;
  ids.reserve(culled_.size());
  for (const auto& entry : culled_) ids.push_back(entry.first);
  std::sort(ids.begin(), ids.end());
  return ids;
}

Backend::CullRule Backend::cullRule() const {
  // Under memory pressure fewer keyframes are kept: the rule is relaxed.
  CullRule rule{config_.cull_min_covering_keyframes, config_.cull_min_covered_ratio};
  if (memory_pressure_ == MemoryPressure::kNear) {
    rule.min_covering = std::max(1, rule.min_covering - 1);
    rule.min_covered_ratio = std::min(rule.min_covered_ratio, 0.8);
  } else if (memory_pressure_ == MemoryPressure::kOver) {
    rule.min_covering = 1;
    rule.min_covered_ratio = std::min(rule.min_covered_ratio, 0.7);
  }
  return rule;
}

bool Backend::covered(const FeatureSet& features, const CameraIntrinsics& K,
                      const std::vector<SE3>& T_view_keyframe, const CullRule& rule) {
  if (static_cast<int>(T_view_keyframe.size()) < rule.min_covering) return false;
  // ORB-SLAM's rule with views for landmarks: a feature with depth is covered by a keyframe
  // whose view it lies in (in front, inside the image) at the same or a finer scale (at most one
  // ORB pyramid level, 1.2x, farther away).
  constexpr double kMaxDepthRatio = 1.2;
  constexpr double kBorderPx = 8.0;
  int with_depth = 0;
  int num_covered = 0;
  for (std::size_t i = 0; i < features.points.size(); ++i) {
    if (!features.hasDepth(i)) continue;
    ++with_depth;
    const Eigen::Vector3d& X = features.points[i];
    int views = 0;
    for (const SE3& T : T_view_keyframe) {
      const Eigen::Vector3d Y = T * X;
      if (!(Y.z() > 0.0) || Y.z() > kMaxDepthRatio * X.z()) continue;
      const double u = K.fx * Y.x() / Y.z() + K.cx;
      const double v = K.fy * Y.y() / Y.z() + K.cy;
      if (u >= kBorderPx && v >= kBorderPx && u < K.width - kBorderPx && v < K.height - kBorderPx) {
        ++views;
      }
    }
    if (views >= rule.min_covering) ++num_covered;
  }
  return with_depth > 0 && static_cast<double>(num_covered) >= rule.min_covered_ratio * with_depth;
}

const LoopDetection* Backend::redundancyMatch(const Keyframe& keyframe,
                                              const std::vector<LoopDetection>& local) const {
  // The keyframes that verifiably see this place now (enough inliers, still in the graph).
  std::vector<const LoopDetection*> covering;
  std::vector<SE3> T_view_keyframe;
  for (const LoopDetection& match : local) {
    if (match.num_inliers >= config_.cull_min_inliers && graph_.hasNode(match.match_id)) {
      covering.push_back(&match);
      T_view_keyframe.push_back(match.T_match_query);
    }
  }
  const CullRule rule = cullRule();
  const LoopDetection* best = nullptr;  // the one that sees it best
  for (const LoopDetection* match : covering) {
    if (best == nullptr || match->num_inliers > best->num_inliers) best = match;
  }
  // A keyframe whose features are nearly all inliers of one match holds nothing that keyframe
  // does not (the same view again): culling it leaves the map as it was before it came.
  int with_depth = 0;
  for (std::size_t i = 0; i < keyframe.features.size(); ++i) {
    if (keyframe.features.hasDepth(i)) ++with_depth;
  }
  if (best != nullptr && with_depth > 0 &&
      best->num_inliers >= rule.min_covered_ratio * with_depth) {
    return best;
  }
  if (!covered(keyframe.features, keyframe.intrinsics, T_view_keyframe, rule)) return nullptr;
  return best;  // merged into the one that sees it best
}

void Backend::cull(const Keyframe& keyframe, const LoopDetection& match, BackendUpdate& update) {
  // The offset kept is the optimised one (odometry and every local edge fused), not the single
  // match; its information is the match's (a conservative bound).
  mergeIntoAnchor(keyframe.id, match.match_id, match.information);
  update.culled = true;
  update.culled_into_id = match.match_id;
}

void Backend::cullCoveredEarlierKeyframes(const Keyframe& keyframe,
                                          const std::vector<LoopDetection>& local,
                                          BackendUpdate& update) {
  // The new keyframe stays: it now verifiably sees the places of the keyframes it matched.
  std::vector<const LoopDetection*> seen;
  for (const LoopDetection& match : local) {
    if (match.num_inliers < config_.cull_min_inliers || !graph_.hasNode(match.match_id)) continue;
    addCoverer(keyframe.id, match.match_id);
    seen.push_back(&match);
  }
  const CullRule rule = cullRule();
  for (const LoopDetection* match : seen) {
    // The graph's first keyframe (the gauge) is a segment start too.
    const std::int64_t id = match->match_id;
    if (graph_.isFixed(id) || segment_starts_.count(id) != 0) continue;
    const FeatureSet* features = detector_.features(id);
    const auto header = headers_.find(id);
    if (features == nullptr || header == headers_.end()) continue;
    // Its views: every keyframe still in the graph that a verified match showed seeing it.
    std::vector<SE3> T_view_keyframe;
    const SE3 T_world_keyframe = graph_.pose(id);
    for (const std::int64_t view : coverers_[id]) {
      if (graph_.hasNode(view)) {
        T_view_keyframe.push_back(graph_.pose(view).inverse() * T_world_keyframe);
      }
    }
    if (!covered(*features, header->second.intrinsics, T_view_keyframe, rule)) continue;
    // Merged into the new keyframe, with the information of the match that saw it.
    mergeIntoAnchor(
        id, keyframe.id,
        invertedEdge({id, keyframe.id, match->T_match_query, match->information, EdgeKind::kLocal})
            .information);
    update.culled_earlier_ids.push_back(id);
  }
}

void Backend::addCoverer(std::int64_t a, std::int64_t b) {
  for (const auto& [from, to] : {std::make_pair(a, b), std::make_pair(b, a)}) {
    auto& list = coverers_[from];
    if (std::find(list.begin(), list.end(), to) == list.end()) list.push_back(to);
  }
}

void Backend::mergeIntoAnchor(std::int64_t id, std::int64_t anchor_id,
                              const Matrix6d& information) {
  const SE3 T_anchor_keyframe = graph_.pose(anchor_id).inverse() * graph_.pose(id);
  const std::vector<PoseGraphEdge> removed = graph_.removeNode(id);
  for (const PoseGraphEdge& edge : removed) {
    const std::int64_t other = edge.from_id == id ? edge.to_id : edge.from_id;
    auto& list = neighbours_[other];
    list.erase(std::remove(list.begin(), list.end(), id), list.end());
  }
  neighbours_.erase(id);
  headers_.erase(id);
  detector_.removeKeyframe(id);
  for (const std::int64_t view : coverers_[id]) {
    auto& list = coverers_[view];
    list.erase(std::remove(list.begin(), list.end(), id), list.end());
  }
  coverers_.erase(id);

  // The odometry chain through the keyframe is joined around it (prev -> next composed: its pose
  // eliminated, as marginalising it out of the chain would). Loop and relocalisation edges, and
  // odometry edges when the chain is not that simple (several ways in, a newest keyframe with no
  // way out yet), go on to the anchor through the offset, so the chain stays connected and loops
  // stay closed. Local edges are dropped: the anchor has its own, and composed with the same
  // offset they would count it many times over.
  const PoseGraphEdge anchor_to_keyframe{anchor_id, id, T_anchor_keyframe, information,
                                         EdgeKind::kLocal};
  const PoseGraphEdge keyframe_to_anchor = invertedEdge(anchor_to_keyframe);
  std::vector<const PoseGraphEdge*> odometry_in;
  std::vector<const PoseGraphEdge*> odometry_out;
  for (const PoseGraphEdge& edge : removed) {
    if (edge.kind != EdgeKind::kOdometry) continue;
    (edge.to_id == id ? odometry_in : odometry_out).push_back(&edge);
  }
  const bool join_chain = odometry_in.size() == 1 && !odometry_out.empty();
  for (const PoseGraphEdge& edge : removed) {
    const bool carried = edge.kind == EdgeKind::kOdometry || edge.kind == EdgeKind::kLoop ||
                         edge.kind == EdgeKind::kRelocalization;
    if (!carried || (join_chain && edge.kind == EdgeKind::kOdometry)) continue;
    if (edge.to_id == id && edge.from_id != anchor_id) {
      addEdge(composedEdge(edge, keyframe_to_anchor, edge.kind));
    } else if (edge.from_id == id && edge.to_id != anchor_id) {
      addEdge(composedEdge(anchor_to_keyframe, edge, edge.kind));
    }
  }
  if (join_chain) {
    for (const PoseGraphEdge* out : odometry_out) {
      if (out->to_id != odometry_in.front()->from_id) {
        addEdge(composedEdge(*odometry_in.front(), *out, EdgeKind::kOdometry));
      }
    }
  }
  // Keyframes culled into this one earlier follow it to its anchor.
  for (auto& entry : culled_) {
    CulledKeyframe& earlier = entry.second;
    if (earlier.anchor_id != id) continue;
    earlier.anchor_id = anchor_id;
    earlier.T_anchor_keyframe = T_anchor_keyframe * earlier.T_anchor_keyframe;
  }
  culled_[id] = CulledKeyframe{anchor_id, T_anchor_keyframe, information};
}

PoseGraphResult Backend::optimizeLocalWindow(std::int64_t keyframe_id) {
  PoseGraphOptions options = options_;
  options.max_iterations = std::min(options.max_iterations, config_.local_max_iterations);
  return graph_.optimize(options, localWindow(keyframe_id));
}

std::optional<FullOptimizationJob> Backend::takeFullOptimizationJob() {
  if (!full_optimization_wanted_ || full_optimization_out_ || graph_.numNodes() == 0) {
    return std::nullopt;
  }
  full_optimization_wanted_ = false;
  full_optimization_out_ = true;
  FullOptimizationJob job;
  job.graph = graph_;
  job.options = options_;
  job.newest_id = graph_.nodeIds().back();  // nodes are kept in the order they were added
  return job;
}

BackendUpdate Backend::finishFullOptimization(const FullOptimizationJob& job) {
  full_optimization_out_ = false;
  BackendUpdate update;
  update.optimization = job.result;
  if (previous_ == nullptr || !mergeOptimizedCopy(job, graph_)) return update;
  const std::int64_t newest_id = graph_.nodeIds().back();
  if (newest_id != job.newest_id && config_.local_window_hops > 0) {
    optimizeLocalWindow(newest_id);
  }
  update.keyframe_id = previous_->id;
  update.optimized = true;
  update.full_optimization = true;
  update.corrected_poses.reserve(graph_.numNodes());
  for (std::int64_t id : graph_.nodeIds()) update.corrected_poses.emplace_back(id, graph_.pose(id));
  update.T_world_odometry = pose(previous_->id) * previous_->T_world_camera.inverse();
  return update;
}

BackendUpdate Backend::add(const KeyframePtr& keyframe, const Matrix6d* covariance_prev_curr) {
  BackendUpdate update;
  if (keyframe == nullptr || hasKeyframe(keyframe->id)) return update;
  update.keyframe_id = keyframe->id;
  KeyframeInfo info;
  info.segment = keyframe->segment;
  bool new_segment = false;
  const bool first_keyframe = previous_ == nullptr;
  if (first_keyframe) {
    graph_.addNode(keyframe->id, keyframe->T_world_camera);
    first_segment_ = keyframe->segment;
  } else if (restored_link_pending_) {
    // The first keyframe after a loaded session: its run's world has no known relation to the
    // session's until it relocalises. It starts at its own odometry pose (T_world_odometry is
    // the identity until then), with the weak link to keep the graph connected.
    restored_link_pending_ = false;
    new_segment = true;
    relocalization_attempts_ = 0;
    graph_.addNode(keyframe->id, keyframe->T_world_camera);
    addEdge({previous_->id, keyframe->id,
             graph_.pose(previous_->id).inverse() * keyframe->T_world_camera,
             Matrix6d::Identity() / (kSegmentLinkSigma * kSegmentLinkSigma), EdgeKind::kOdometry});
  } else {
    new_segment = keyframe->segment != previous_->segment;
    if (new_segment) relocalization_attempts_ = 0;
    const PoseGraphEdge edge = odometryEdge(*keyframe, covariance_prev_curr, new_segment, info);
    // Initial value: the corrected pose at the edge's start composed with the odometry step.
    graph_.addNode(keyframe->id, graph_.pose(edge.from_id) * edge.T_from_to);
    addEdge(edge);
  }
  keyframes_[keyframe->id] = info;
  headers_[keyframe->id] = KeyframeHeader::of(*keyframe);
  if (first_keyframe || new_segment) segment_starts_.insert(keyframe->id);
  segment_parent_.emplace(keyframe->segment, keyframe->segment);
  next_keyframe_id_ = std::max(next_keyframe_id_, keyframe->id + 1);
  next_segment_ = std::max(next_segment_, keyframe->segment + 1);

  bool changed = false;
  bool full = false;  // a correction the local window cannot absorb
  // Relocalisation first: once the segment is joined, this keyframe's local edges can reach the
  // map it joined.
  if (config_.relocalization && segmentRoot(keyframe->segment) != segmentRoot(first_segment_)) {
    tryRelocalization(*keyframe, update);
    changed = changed || update.relocalized;
    full = update.relocalized;
  }

  const LocalMatches local_matches = addLocalEdges(*keyframe, update);
  const std::vector<LoopDetection>& local = local_matches.added;
  full = full || update.full_optimization;
  changed = changed || (config_.optimize_every_keyframe && update.num_local_edges > 0);

  previous_ = keyframe;
  update.loop = detector_.processKeyframe(keyframe, local);
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
    const bool whole = full || config_.local_window_hops == 0;
    if (whole && !defer_full_optimization_) {
      update.optimization = graph_.optimize(options_);
      update.full_optimization = true;
    } else {
      // Deferred: the window now, the whole graph when the job comes back.
      if (whole) full_optimization_wanted_ = true;
      update.optimization = optimizeLocalWindow(keyframe->id);
      update.full_optimization = false;
    }
    update.optimized = true;
  } else {
    update.full_optimization = false;
  }
  // Culling comes after the optimisation: the culled keyframe keeps its optimised offset.
  const bool first_of_segment = first_keyframe || new_segment;
  const LoopDetection* redundant =
      config_.cull_redundant_keyframes && !first_of_segment && !update.relocalized &&
              segmentRoot(keyframe->segment) == segmentRoot(first_segment_)
          ? redundancyMatch(*keyframe, local_matches.agreeing)
          : nullptr;
  if (redundant != nullptr) {
    cull(*keyframe, *redundant, update);
  } else if (config_.cull_redundant_keyframes && config_.cull_earlier_keyframes &&
             !first_of_segment && segmentRoot(keyframe->segment) == segmentRoot(first_segment_)) {
    cullCoveredEarlierKeyframes(*keyframe, local_matches.agreeing, update);
  }
  // The keyframe list changed: downstream must hear of it.
  if (update.culled || !update.culled_earlier_ids.empty()) update.optimized = true;
  if (update.optimized) {
    update.corrected_poses.reserve(graph_.numNodes());
    for (std::int64_t id : graph_.nodeIds())
      update.corrected_poses.emplace_back(id, graph_.pose(id));
  }
  // After the loop search too: a loop into the map also joins a new segment.
  update.relocalization_pending = segmentRoot(keyframe->segment) != segmentRoot(first_segment_);
  update.T_world_odometry = pose(keyframe->id) * keyframe->T_world_camera.inverse();
  return update;
}

BackendSnapshot Backend::snapshot() const {
  BackendSnapshot snapshot;
  const auto features = detector_.storedFeatures();
  snapshot.keyframes.reserve(graph_.numNodes());
  snapshot.nodes.reserve(graph_.numNodes());
  for (std::int64_t id : graph_.nodeIds()) {
    snapshot.nodes.push_back({id, graph_.pose(id), graph_.isFixed(id)});
    auto keyframe = std::make_shared<Keyframe>();
    keyframe->id = id;
    keyframe->segment = keyframes_.at(id).segment;
    const KeyframeHeader& header = headers_.at(id);
    keyframe->utime = header.utime;
    keyframe->frame_sequence = header.frame_sequence;
    keyframe->T_world_camera = header.T_world_camera;
    keyframe->intrinsics = header.intrinsics;
    keyframe->median_depth_m = header.median_depth_m;
    const auto stored = features.find(id);
    if (stored != features.end()) {
      keyframe->features = *stored->second;
      keyframe->features.gray = cv::Mat();
      keyframe->features.align_gray = cv::Mat();
    }
    snapshot.keyframes.push_back(std::move(keyframe));
  }
  snapshot.edges = graph_.edges();
  for (const auto& [id, culled] : culled_) {
    snapshot.culled.push_back({id, culled.anchor_id, culled.T_anchor_keyframe, culled.information});
  }
  std::sort(
      snapshot.culled.begin(), snapshot.culled.end(),
      [](const CulledKeyframeRecord& a, const CulledKeyframeRecord& b) { return a.id < b.id; });
  for (const auto& [id, info] : keyframes_) {
    snapshot.records.push_back({id, info.segment, info.path_length_m});
  }
  std::sort(snapshot.records.begin(), snapshot.records.end(),
            [](const KeyframeRecord& a, const KeyframeRecord& b) { return a.id < b.id; });
  snapshot.segment_parents.assign(segment_parent_.begin(), segment_parent_.end());
  std::sort(snapshot.segment_parents.begin(), snapshot.segment_parents.end());
  for (const auto& [id, views] : coverers_) {
    for (const std::int64_t view : views) {
      if (id < view && graph_.hasNode(id) && graph_.hasNode(view)) {
        snapshot.views.emplace_back(id, view);
      }
    }
  }
  std::sort(snapshot.views.begin(), snapshot.views.end());
  snapshot.first_segment = first_segment_;
  snapshot.next_keyframe_id = next_keyframe_id_;
  snapshot.next_segment = next_segment_;
  snapshot.num_loops = num_loops_;
  snapshot.num_local_edges = num_local_edges_;
  snapshot.num_relocalizations = num_relocalizations_;
  return snapshot;
}

void Backend::restore(const BackendSnapshot& snapshot, bool fix_loaded_keyframes) {
  if (previous_ != nullptr || graph_.numNodes() != 0 || !keyframes_.empty()) {
    throw std::logic_error("Backend::restore: the back end is not empty");
  }
  if (snapshot.keyframes.empty() || snapshot.keyframes.size() != snapshot.nodes.size()) {
    throw std::invalid_argument("Backend::restore: a snapshot needs one keyframe per graph node");
  }
  std::unordered_map<std::int64_t, KeyframeInfo> records;
  for (const KeyframeRecord& record : snapshot.records) {
    records[record.id] = KeyframeInfo{record.segment, record.path_length_m};
  }
  for (std::size_t i = 0; i < snapshot.nodes.size(); ++i) {
    const BackendSnapshot::Node& node = snapshot.nodes[i];
    const KeyframePtr& keyframe = snapshot.keyframes[i];
    if (keyframe == nullptr || keyframe->id != node.id || graph_.hasNode(node.id) ||
        records.count(node.id) == 0) {
      throw std::invalid_argument("Backend::restore: keyframe " + std::to_string(node.id) +
                                  " does not match its graph node or record");
    }
    graph_.addNode(node.id, node.T_world_camera);
    graph_.setFixed(node.id, fix_loaded_keyframes || node.fixed);
    keyframes_[node.id] = records.at(node.id);
    headers_[node.id] = KeyframeHeader::of(*keyframe);
    segment_parent_.emplace(keyframe->segment, keyframe->segment);
    detector_.insertKeyframe(keyframe);
  }
  for (const PoseGraphEdge& edge : snapshot.edges) {
    if (!addEdge(edge)) {
      throw std::invalid_argument("Backend::restore: an edge names a missing keyframe (" +
                                  std::to_string(edge.from_id) + " -> " +
                                  std::to_string(edge.to_id) + ")");
    }
  }
  for (const CulledKeyframeRecord& record : snapshot.culled) {
    if (!graph_.hasNode(record.anchor_id) || graph_.hasNode(record.id)) {
      throw std::invalid_argument("Backend::restore: culled keyframe " + std::to_string(record.id) +
                                  " is anchored to " + std::to_string(record.anchor_id) +
                                  ", which is not a keyframe of the graph");
    }
    culled_[record.id] =
        CulledKeyframe{record.anchor_id, record.T_anchor_keyframe, record.information};
    keyframes_.emplace(record.id,
                       records.count(record.id) != 0 ? records.at(record.id) : KeyframeInfo{});
  }
  // A segment's first keyframe is never culled, so it is the segment's lowest id.
  std::unordered_map<std::int64_t, std::int64_t> segment_first_id;
  for (const auto& [id, info] : keyframes_) {
    const auto [it, inserted] = segment_first_id.emplace(info.segment, id);
    if (!inserted) it->second = std::min(it->second, id);
  }
  for (const auto& entry : segment_first_id) segment_starts_.insert(entry.second);
  for (const auto& [segment, parent] : snapshot.segment_parents) segment_parent_[segment] = parent;
  for (const auto& [a, b] : snapshot.views) {
    if (!graph_.hasNode(a) || !graph_.hasNode(b) || a == b) {
      throw std::invalid_argument("Backend::restore: view " + std::to_string(a) + " - " +
                                  std::to_string(b) + " does not join two keyframes");
    }
    addCoverer(a, b);
  }
  first_segment_ = snapshot.first_segment;
  segment_parent_.emplace(first_segment_, first_segment_);
  next_keyframe_id_ = snapshot.next_keyframe_id;
  next_segment_ = snapshot.next_segment;
  for (const auto& [id, info] : keyframes_) {
    next_keyframe_id_ = std::max(next_keyframe_id_, id + 1);
    next_segment_ = std::max(next_segment_, info.segment + 1);
  }
  num_loops_ = static_cast<int>(snapshot.num_loops);
  num_local_edges_ = static_cast<int>(snapshot.num_local_edges);
  num_relocalizations_ = static_cast<int>(snapshot.num_relocalizations);
  previous_ = snapshot.keyframes.back();
  restored_link_pending_ = true;
}

}  // namespace slamd
