#pragma once
// Backend: the keyframe graph with loop closing. It takes keyframes from visual odometry one at a
// time, links each to the previous one with an odometry edge, looks for loops (LoopDetector) and,
// when one is found, adds the loop edge and re-optimises the pose graph (PoseGraph, CHOLMOD).
//
// Usage (one thread owns it, the back-end thread; there are no threads inside):
//   Backend backend(BackendConfig::load(config), vocabulary);
//   on each OdometryResult r with r.keyframe:
//     BackendUpdate u = backend.addKeyframe(r.keyframe);
//     if (u.optimized) {
//       // corrected keyframe poses for the map; correction for the live pose:
//       mapper.correctKeyframePoses(u.corrected_poses);  // moves the keyframes that moved
//       T_world_camera_corrected = u.T_world_odometry * T_world_camera_odometry;
//     }
//
// Frames: the world frame is the first keyframe's (visual odometry's world). Odometry poses are
// the keyframes' T_world_camera as tracking made them; corrected poses are the optimised
// T_world_camera of the same keyframes. T_world_odometry = T_world_latest_corrected *
// T_world_latest_odometry^-1 maps odometry-world points into the corrected world, the correction
// to apply to any pose tracking reports after the latest keyframe.
//
// Odometry edges: consecutive keyframes of one tracking segment, measurement
// T_prev_curr = T_world_prev^-1 * T_world_curr from the odometry poses, standard deviation
// odometry_sigma_ratio * distance (+ 5 mm) per axis and odometry_sigma_rad per axis, or the
// covariance tracking measured when the caller passes it (addKeyframe's second argument).
//
// Local edges (backend.local_edges): each new keyframe is also matched against earlier keyframes
// of the same map that look alike (recent ones included) and verified with RANSAC + refinement;
// an edge whose relative pose agrees with the current graph estimate is added with the
// refinement's information. The graph is then re-optimised (backend.optimize_every_keyframe),
// warm-started from the previous solution, over a local window (the keyframe and its neighbours
// within backend.local_window_hops edges); a loop or relocalisation that is far from closed
// re-optimises the whole graph. corrected_poses lists every keyframe either way.
//
// Culling (backend.cull_redundant_keyframes): a new keyframe is redundant when the earlier
// keyframes whose verified local matches show they see its place already hold what it holds
// (ORB-SLAM's rule, with views for landmarks: see BackendConfig), or when one verified match
// holds nearly all its features (the same view again). It is removed at once, after
// the optimisation that placed it: its node and edges leave the graph, its loop-detector entry
// is dropped, and it stays only as an offset (the optimised one) from the keyframe M that sees
// it best. Its odometry edge and a loop edge it closed are merged through that offset into edges
// of M (composedEdge), and the next keyframe's odometry edge starts from M the same way, so the
// chain stays connected. pose() of a culled keyframe is M's pose composed with the offset. Not
// culled: the first keyframe of a segment, one that relocalised, one of a segment not yet joined
// to the map.
//
// A new keyframe that is kept can make earlier ones redundant (ORB-SLAM culls its local
// keyframes the same way): every keyframe it verifiably matches (cull_min_inliers) counts it as
// a view, and one whose views (every keyframe still in the graph that ever verifiably matched it,
// at the current optimised poses) now cover it under the same rule is culled into the new
// keyframe. Its odometry chain is joined around it (in and out edges composed); its other
// odometry, loop and relocalisation edges move onto the new keyframe through the offset, and
// keyframes culled into it earlier follow it there. Revisiting a place then replaces keyframes
// rather than adding them. Not culled this way: a fixed keyframe (a loaded map's, the gauge),
// the first keyframe of a segment.
//
// Whole-graph optimisations in the background (setFullOptimizationDeferred(true), as the daemon
// runs it): a correction the local window cannot absorb is not run in addKeyframe. The keyframe
// gets its local-window optimisation, and a copy of the whole graph is handed out
// (takeFullOptimizationJob) to be optimised elsewhere (BackgroundOptimizer). Keyframes keep
// coming meanwhile. finishFullOptimization() merges the optimised copy: its keyframes take
// their optimised poses, keyframes added since are moved rigidly with the copy's newest
// keyframe, and a local-window optimisation around the newest keyframe then brings in the
// edges added since. Wanted again while one is out (another far loop), the next copy is taken
// after the merge. Per keyframe the cost is then the local window's, whatever the graph's size.
//
// Sessions (backend/session.hpp): snapshot() is what a later run needs to continue, restore()
// loads it into an empty Backend. The loaded keyframes are either all fixed (the map is a fixed
// reference: localisation, or a map whose keyframe clouds were not kept and so cannot follow a
// move), or keep the fixed flags they were saved with (the session's first keyframe holds the
// gauge), so that loops and relocalisations correct the old keyframes too. The first keyframe added
// after restore() starts a segment of its own at its own odometry pose, tied to the loaded map by
// the weak link only, and relocalises against it like a segment after LOST; until then
// T_world_odometry is the identity and relocalization_pending is true (the map's frame is not yet
// known). The caller numbers the new keyframes and segments from nextKeyframeId() and
// nextSegment(). backend.mode (BackendMode) is the daemon's: both modes restore the same way.
//
// Relocalisation (backend.relocalization): a keyframe starting a new segment (after LOST) is tied
// to the previous one by a very weak edge only, and matched against every keyframe of earlier
// segments (LoopDetector::query, no recency exclusion or consistency). On a verified match a
// strong edge joins the segment to the map, the graph is re-optimised and the update says
// relocalized; T_world_odometry then carries the new segment's odometry into the map's world.
// Until a match is found every later keyframe of the segment tries again; keyframesNear() says
// the segment awaits relocalisation (MapKeyframes::relocalization_pending), and tracking then
// makes keyframes of changed views sooner than its usual ones, so that attempts come as soon as a
// frame allows. A segment's keyframes make local edges only with keyframes of segments already
// joined to it.

#include <cstdint>
#include <memory>
#include <optional>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>

#include "slamd/backend/backend_config.hpp"
#include "slamd/backend/background_optimizer.hpp"
#include "slamd/backend/loop_detector.hpp"
#include "slamd/backend/pose_graph.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/common/memory_pressure.hpp"
#include "slamd/tracking/visual_odometry.hpp"

namespace slamd {

struct BackendUpdate {
  std::int64_t keyframe_id = -1;
  LoopDetection loop;            ///< the loop search for this keyframe
  bool optimized = false;        ///< a loop was added and the graph re-optimised
  PoseGraphResult optimization;  ///< valid when optimized
  /// The optimisation moved the whole graph (a loop or relocalisation that was far from closed),
  /// not only the local window around this keyframe.
  bool full_optimization = false;
  int num_local_edges = 0;     ///< local (covisibility) edges added for this keyframe
  int num_local_rejected = 0;  ///< verified local matches that disagreed with the graph
  /// This keyframe's segment was joined to the map by a relocalisation now.
  bool relocalized = false;
  /// The relocalisation attempt of this keyframe (when attempted): match_id, inliers, status.
  LoopDetection relocalization;
  bool relocalization_attempted = false;
  /// Attempts made for this keyframe's segment so far (this one included); 0 when the segment
  /// needed none (the first segment, or already joined).
  int relocalization_attempts = 0;
  /// The keyframe's segment is not (yet) joined to the map of the first segment.
  bool relocalization_pending = false;
  /// This keyframe was culled (redundant with culled_into_id); it is not in corrected_poses.
  bool culled = false;
  std::int64_t culled_into_id = -1;
  /// Earlier keyframes this one made redundant, culled into it; not in corrected_poses.
  std::vector<std::int64_t> culled_earlier_ids;
  /// Every keyframe's corrected T_world_camera (metres), when optimized.
  std::vector<std::pair<std::int64_t, SE3>> corrected_poses;
  /// Correction from the odometry world to the corrected world (see the class comment).
  SE3 T_world_odometry = SE3::Identity();
};

class Backend {
 public:
  Backend(const BackendConfig& config, std::shared_ptr<const Vocabulary> vocabulary);

  /// Adds the next keyframe (ids increasing). Never throws on bad data; a keyframe without usable
  /// descriptors still joins the graph (with its odometry edge), it just cannot close loops.
  BackendUpdate addKeyframe(const KeyframePtr& keyframe);

  /// As above, with the covariance tracking measured for the odometry step (order x y z rx ry rz,
  /// metres^2 / radians^2, right perturbation): covariance of T_prev_curr between the previous
  /// keyframe and this one. Used for the odometry edge instead of the fixed ratio (floored at
  /// 1 mm / 0.05 degree). Ignored for the first keyframe of a segment.
  BackendUpdate addKeyframe(const KeyframePtr& keyframe, const Matrix6d& covariance_prev_curr);

  /// Whole-graph optimisations become jobs (see the class comment) instead of running inside
  /// addKeyframe. Off by default: the graph is then optimised in place, deterministically.
  void setFullOptimizationDeferred(bool deferred) { defer_full_optimization_ = deferred; }
  /// A copy of the graph to optimise whole, when one is wanted and none is out (the caller runs
  /// it and hands it back to finishFullOptimization).
  std::optional<FullOptimizationJob> takeFullOptimizationJob();
  /// Merges an optimised copy (see the class comment). The update lists every keyframe's pose
  /// and the correction for the newest one (optimized is false when the optimisation failed).
  BackendUpdate finishFullOptimization(const FullOptimizationJob& job);
  /// A whole-graph optimisation is wanted or out.
  bool fullOptimizationPending() const {
    return full_optimization_wanted_ || full_optimization_out_;
  }

  /// Memory pressure (common/memory_pressure.hpp) relaxes the culling rule for new keyframes:
  /// kNear needs one covering keyframe fewer (at least 1) and at most 80% of the features
  /// covered; kOver one covering keyframe and at most 70%.
  void setMemoryPressure(MemoryPressure pressure) { memory_pressure_ = pressure; }

  /// Everything needed to continue later (see the class comment): the graph, the keyframes in it
  /// (features and descriptors; keyframes without binary descriptors are kept without
  /// features), culled keyframes, segments and counters.
  BackendSnapshot snapshot() const;
  /// Loads a snapshot into this Backend, which must be empty (nothing added, nothing restored):
  /// throws std::logic_error otherwise, and std::invalid_argument when the snapshot is not
  /// consistent (an edge or culled keyframe naming a missing keyframe). With
  /// `fix_loaded_keyframes` every loaded keyframe is fixed (see the class comment).
  void restore(const BackendSnapshot& snapshot, bool fix_loaded_keyframes);
  /// One above every keyframe id and segment added or restored.
  std::int64_t nextKeyframeId() const { return next_keyframe_id_; }
  std::int64_t nextSegment() const { return next_segment_; }

  /// Current (corrected) T_world_camera of a keyframe; the odometry pose before any loop. A
  /// culled keyframe's is the pose of the keyframe it was merged into, composed with the offset
  /// measured between them. Throws std::out_of_range for an id never added.
  SE3 pose(std::int64_t keyframe_id) const;
  /// The keyframes in the graph that the loop detector keeps (those with binary descriptors)
  /// within max_translation_m and max_rotation_deg of keyframe anchor_id (culled or not; itself
  /// excluded), in the map its segment belongs to, nearest first, at most max_count: for
  /// tracking to measure against (MapKeyframes). Empty when the anchor was never added.
  MapKeyframes keyframesNear(std::int64_t anchor_id, double max_translation_m,
                             double max_rotation_deg, std::size_t max_count) const;
  /// The same with the reach tracking needs: it tries keyframes within half its keyframe bounds
  /// (0.25 m, 15 degrees by default) of a pose that is some keyframes past the anchor by the time
  /// the set arrives.
  MapKeyframes keyframesNear(std::int64_t anchor_id) const {
    return keyframesNear(anchor_id, 1.0, 60.0, 64);
  }
  /// The keyframe was added (culled or not).
  bool hasKeyframe(std::int64_t keyframe_id) const {
    return graph_.hasNode(keyframe_id) || culled_.count(keyframe_id) != 0;
  }
  int numCulled() const { return static_cast<int>(culled_.size()); }
  std::vector<std::int64_t> culledKeyframeIds() const;
  const PoseGraph& graph() const { return graph_; }
  const LoopDetector& loopDetector() const { return detector_; }
  LoopDetector& loopDetector() { return detector_; }
  int numLoops() const { return num_loops_; }
  int numLocalEdges() const { return num_local_edges_; }
  int numRelocalizations() const { return num_relocalizations_; }
  /// The newest keyframe's segment is joined to the map of the first segment (a restored
  /// session's map, or this run's first segment's).
  bool newestKeyframeInMap() const {
    return previous_ != nullptr && segmentRoot(previous_->segment) == segmentRoot(first_segment_);
  }
  /// The tracking segment of the newest keyframe added (-1: none yet).
  std::int64_t newestKeyframeSegment() const {
    return previous_ != nullptr ? previous_->segment : -1;
  }
  /// The segment whose map `segment` has been joined to (the segment itself until then).
  std::int64_t segmentRoot(std::int64_t segment) const;

 private:
  /// A culled keyframe: merged into anchor_id, at T_anchor_keyframe from it (the optimised offset
  /// when it was culled).
  struct CulledKeyframe {
    std::int64_t anchor_id = -1;
    SE3 T_anchor_keyframe = SE3::Identity();
    Matrix6d information = Matrix6d::Identity();  ///< of T_anchor_keyframe (the match's)
  };
  struct KeyframeInfo {
    std::int64_t segment = 0;
    double path_length_m = 0.0;  ///< odometry path from the first keyframe of its segment
  };
  /// What a snapshot needs of a keyframe in the graph beyond the features the loop detector
  /// keeps (held here so that the features are not held twice).
  struct KeyframeHeader {
    Utime utime = 0;
    std::int64_t frame_sequence = 0;
    SE3 T_world_camera = SE3::Identity();  ///< odometry pose
    CameraIntrinsics intrinsics;
    double median_depth_m = 0.0;

    static KeyframeHeader of(const Keyframe& keyframe) {
      return {keyframe.utime, keyframe.frame_sequence, keyframe.T_world_camera, keyframe.intrinsics,
              keyframe.median_depth_m};
    }
  };

  BackendUpdate add(const KeyframePtr& keyframe, const Matrix6d* covariance_prev_curr);
  Matrix6d odometryInformation(const SE3& T_prev_curr) const;
  struct LocalMatches {
    std::vector<LoopDetection> added;     ///< those that became edges (at most local_edges)
    std::vector<LoopDetection> agreeing;  ///< every one that agreed with the graph
  };
  /// Verifies the keyframe's local matches against the graph and adds the best as edges.
  LocalMatches addLocalEdges(const Keyframe& keyframe, BackendUpdate& update);
  void tryRelocalization(const Keyframe& keyframe, BackendUpdate& update);
  /// Adds an edge to the graph and the adjacency.
  bool addEdge(const PoseGraphEdge& edge);
  /// The new keyframe and its neighbours within backend.local_window_hops, nearest first.
  std::vector<std::int64_t> localWindow(std::int64_t keyframe_id) const;
  /// Whitened squared error of an edge at the current estimate.
  double edgeChi2(const PoseGraphEdge& edge) const;
  /// The odometry edge from the previous keyframe to this one; from the keyframe the previous
  /// one was merged into when it was culled.
  PoseGraphEdge odometryEdge(const Keyframe& keyframe, const Matrix6d* covariance_prev_curr,
                             bool new_segment, KeyframeInfo& info) const;
  /// How many views must see a feature, and what fraction of the features with depth must be
  /// seen, for a keyframe to be redundant (relaxed under memory pressure).
  struct CullRule {
    int min_covering = 3;
    double min_covered_ratio = 0.9;
  };
  CullRule cullRule() const;
  /// The culling rule on a keyframe's features, given the poses of the keyframes that see its
  /// place relative to it (T_view_keyframe, one per view).
  static bool covered(const FeatureSet& features, const CameraIntrinsics& K,
                      const std::vector<SE3>& T_view_keyframe, const CullRule& rule);
  /// The verified local match that makes the keyframe redundant, if any (most inliers first).
  const LoopDetection* redundancyMatch(const Keyframe& keyframe,
                                       const std::vector<LoopDetection>& local) const;
  /// After a new keyframe is kept: records the keyframes its verified matches (at least
  /// cull_min_inliers) see, and culls into it those of them that their views now cover.
  void cullCoveredEarlierKeyframes(const Keyframe& keyframe,
                                   const std::vector<LoopDetection>& local, BackendUpdate& update);
  /// Records that two keyframes verifiably see each other's place.
  void addCoverer(std::int64_t a, std::int64_t b);
  /// Takes keyframe `id` out of the graph and the loop detector; it stays as the optimised
  /// offset from `anchor_id` (with `information`). See the class comment for its edges.
  void mergeIntoAnchor(std::int64_t id, std::int64_t anchor_id, const Matrix6d& information);
  /// Re-optimises the local window around `keyframe_id` (bounded iterations).
  PoseGraphResult optimizeLocalWindow(std::int64_t keyframe_id);
  /// Removes the keyframe from the graph and the loop detector, merging its odometry edge into
  /// the keyframe of `match`.
  void cull(const Keyframe& keyframe, const LoopDetection& match, BackendUpdate& update);

  BackendConfig config_;
  PoseGraphOptions options_;
  PoseGraph graph_;
  LoopDetector detector_;
  KeyframePtr previous_;  ///< the latest keyframe added
  std::unordered_map<std::int64_t, KeyframeInfo> keyframes_;
  std::unordered_map<std::int64_t, std::vector<std::int64_t>> neighbours_;  ///< graph adjacency
  std::unordered_map<std::int64_t, std::int64_t> segment_parent_;  ///< joined segments (union-find)
  std::unordered_map<std::int64_t, CulledKeyframe> culled_;
  std::unordered_map<std::int64_t, KeyframeHeader> headers_;  ///< keyframes in the graph
  /// Keyframes in the graph that verifiably see each keyframe's place (cull_min_inliers).
  std::unordered_map<std::int64_t, std::vector<std::int64_t>> coverers_;
  /// First keyframes of segments (never culled: each holds its segment's link).
  std::unordered_set<std::int64_t> segment_starts_;
  std::int64_t next_keyframe_id_ = 0;
  std::int64_t next_segment_ = 0;
  /// restore() happened and no keyframe has been added since.
  bool restored_link_pending_ = false;
  std::int64_t first_segment_ = 0;
  int relocalization_attempts_ = 0;  ///< attempts of the latest segment
  int num_loops_ = 0;
  int num_local_edges_ = 0;
  int num_relocalizations_ = 0;
  MemoryPressure memory_pressure_ = MemoryPressure::kNone;
  bool defer_full_optimization_ = false;
  bool full_optimization_wanted_ = false;  ///< deferred: a job should be handed out
  bool full_optimization_out_ = false;     ///< deferred: a job is being optimised elsewhere
};

}  // namespace slamd
