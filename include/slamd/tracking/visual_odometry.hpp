#pragma once
// VisualOdometry: RGB-D frame-to-keyframe visual odometry with ORB, SIFT or FOVIS-style features.
//
// Usage (one thread owns the object; there are no threads inside):
//   VisualOdometry vo(TrackingConfig::load(config));
//   for each frame:
//     OdometryResult r = vo.processFrame(frame_ptr);   // never throws on bad data
//     if (r.status == OdometryStatus::kOk) use(r.T_world_camera, r.covariance);
//     if (r.keyframe) backend.add(r.keyframe);
//
// Frames: camera optical frame x right, y down, z forward. The world frame is the first camera
// frame. T_a_b maps points from frame b into frame a. Covariances are 6x6 in the order x y z rx ry
// rz (metres^2, radians^2) for a right perturbation T = T_est * exp(xi), as in common/se3.hpp.
//
// Per frame: features are extracted (with bucketing and undistortion), matched against the
// current keyframe (guided by the constant-velocity prediction, or by descriptor over the whole
// image when guidance fails), the motion is estimated by RANSAC + closed-form rigid fit (or a
// maximum consistent clique for FOVIS) and refined robustly on SE(3); with few inliers, jointly
// with the matches against the previous frame, then aligned densely from that estimate. When the
// keyframe cannot be tracked the previous frame is tried. A frame becomes a keyframe when inliers,
// overlap or motion since the keyframe cross thresholds. When features cannot measure a frame (a
// plain wall, a fast turn in front of it), dense alignment against the last measured frame does
// (tracking.dense_fallback); such a frame with enough features becomes a keyframe. Frames nothing
// measures are bridged by constant-velocity prediction for tracking.max_predicted_frames frames;
// then tracking is LOST and the next trackable frame starts a new segment (a new keyframe at the
// last predicted pose).

#include <array>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include "slamd/common/pose_estimate.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/tracking/dense_alignment.hpp"
#include "slamd/tracking/features.hpp"
#include "slamd/tracking/keyframe.hpp"
#include "slamd/tracking/local_map.hpp"
#include "slamd/tracking/motion_estimation.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

/// Values match slamd.odometry_t.STATUS_*.
enum class OdometryStatus : std::int8_t {
  kOk = 0,
  kInsufficientFeatures = 1,
  kInsufficientInliers = 2,
  kOptimizationFailure = 3,
  kNoDepth = 4,
  kImplausibleMotion = 5,  ///< every estimate implied motion beyond TrackingConfig::motion_limits
};

const char* odometryStatusName(OdometryStatus status);

struct OdometryStats {
  int num_features = 0;  ///< features detected in the current frame
  int num_features_with_depth = 0;
  int num_matches = 0;                 ///< putative matches with the reference
  int num_inliers = 0;                 ///< matches consistent with the estimated motion
  double reprojection_error_px = 0.0;  ///< RMS over the inliers
  bool used_guided_matching = false;
  bool used_previous_frame = false;  ///< the keyframe failed; tracked from the previous frame
  /// A keyframe of the map (setMapKeyframes) became the reference instead of a new keyframe.
  bool used_map_keyframe = false;
  /// The frame became a keyframe early because its segment awaits relocalisation in the map
  /// (tracking.relocalization_keyframe_*).
  bool relocalization_keyframe = false;
  /// Few inliers against the keyframe: refined jointly with the previous frame's matches.
  bool refined_with_previous_frame = false;
  /// Few inliers: aligned densely against the previous measured frame, the feature estimate as
  /// the prior (tracking.few_inliers_dense).
  bool refined_with_dense_alignment = false;
  int implausible_estimates = 0;  ///< estimates vetoed by the motion limits (then retried)
  int prior_disagreements = 0;    ///< estimates rejected by the motion prior's gate (then retried)
  int local_map_landmarks = 0;    ///< landmarks of covisible keyframes searched (local_map)
  int local_map_inliers = 0;      ///< of those, matched and consistent with the pose
  bool used_dense_alignment = false;    ///< features failed; dense alignment measured the frame
  int dense_degenerate_directions = 0;  ///< directions dense alignment left to the motion prior
  double time_features_ms = 0.0;        ///< extraction + undistortion + depth
  double time_matching_ms = 0.0;
  double time_motion_ms = 0.0;  ///< RANSAC / clique + refinement
  double time_dense_ms = 0.0;   ///< dense alignment (pyramids and alignment), when tried
  double time_total_ms = 0.0;
};

/// The result of one processFrame(). Published as slamd.odometry_t (comms/odometry_codec.cpp):
/// utime, prev_utime; translation/rotation = T_prev_curr; covariance; status; num_features,
/// num_matches, num_inliers, reprojection_error_px from stats; is_keyframe;
/// reference_keyframe_id. The filter's prediction uses the same frame-to-frame T_prev_curr and
/// covariance; T_ref_curr and covariance_ref_curr are the raw measurement, for the back end.
struct OdometryResult {
  Utime utime = 0;
  std::int64_t sequence = 0;
  OdometryStatus status = OdometryStatus::kNoDepth;
  TrackingState tracking_state = TrackingState::kNotInitialized;
  /// Motion since the previous processed frame (its output pose, predicted or not):
  /// T_prev_curr = T_world_prev^-1 * T_world_curr.
  SE3 T_prev_curr = SE3::Identity();
  Utime prev_utime = 0;
  /// Covariance of T_prev_curr. When the frame is measured against a keyframe older than the
  /// previous frame, this is the covariance of the keyframe measurement (a conservative bound).
  Matrix6d covariance = Matrix6d::Identity();
  /// The measurement itself: T_ref_curr against the reference (keyframe or previous frame) with
  /// its covariance from the normal equations. A keyframe that was not measured straight against
  /// the previous keyframe carries the chain since it instead: T_ref_curr from the previous
  /// keyframe, with the covariance accumulated along the chain.
  SE3 T_ref_curr = SE3::Identity();
  Matrix6d covariance_ref_curr = Matrix6d::Identity();
  Utime ref_utime = 0;
  std::int64_t reference_keyframe_id = -1;  ///< -1 when measured from the previous frame
  SE3 T_world_camera = SE3::Identity();
  std::int64_t segment = 0;
  bool is_keyframe = false;
  KeyframePtr keyframe;  ///< set when is_keyframe
  OdometryStats stats;
};

class VisualOdometry {
 public:
  explicit VisualOdometry(const TrackingConfig& config = TrackingConfig());
  ~VisualOdometry();
  VisualOdometry(const VisualOdometry&) = delete;
  VisualOdometry& operator=(const VisualOdometry&) = delete;

  /// Processes the next frame (timestamps increasing). gray or color_bgr and depth_m (CV_32FC1
  /// metres, NaN = none) of the size given by the frame's intrinsics. Never throws on bad data.
  OdometryResult processFrame(const RgbdFramePtr& frame);
  OdometryResult processFrame(const RgbdFrame& frame);

  /// Forgets everything; the next frame starts a new segment at the identity.
  void reset();

  /// Numbers the keyframes and segments made from now on from these values (at least): a run
  /// that continues a loaded session (Backend::nextKeyframeId(), nextSegment()) must not reuse
  /// the session's ids.
  void continueNumbering(std::int64_t next_keyframe_id, std::int64_t next_segment);

  /// The keyframes the map (the back end) keeps near one of tracking's recent keyframes, the
  /// anchor: when a frame calls for a new keyframe, the nearest of these and of tracking's own
  /// recent keyframes are tried first (tracking.map_keyframes). Replaces the previous set; a set
  /// whose anchor has left tracking's window is not used. While the set says the anchor's segment
  /// is not yet placed in the map, frames whose view changed become keyframes sooner
  /// (tracking.relocalization_keyframe_*), each one a relocalisation attempt for the back end.
  void setMapKeyframes(MapKeyframes map_keyframes);

  const TrackingConfig& config() const { return config_; }
  KeyframePtr currentKeyframe() const { return keyframe_; }
  TrackingState state() const { return state_; }

 private:
  struct TrackAttempt;
  struct CurrentFrame;

  struct ReferenceMeasurement;

  OdometryResult guardedProcess(const RgbdFrame& frame, const RgbdFramePtr& frame_ptr);
  OdometryResult process(const RgbdFrame& frame, const RgbdFramePtr& frame_ptr);
  // The steps of process(), in order.
  /// Validates the frame and extracts its features (curr) and the small image for rotation
  /// alignment; the failure status when the frame cannot be tracked (curr.features is null when
  /// the input itself was unusable).
  std::optional<OdometryStatus> prepareFrame(const RgbdFrame& frame, const RgbdFramePtr& frame_ptr,
                                             CurrentFrame& curr, cv::Mat& small,
                                             OdometryStats& stats);
  OdometryResult startSegment(OdometryResult res, const CurrentFrame& curr, const RgbdFrame& frame,
                              const RgbdFramePtr& frame_ptr, std::int64_t t_start);
  /// The motion prior since the previous frame; keeps small for the next frame's alignment.
  SE3 predictMotion(const cv::Mat& small, const CameraIntrinsics& K);
  /// The current features' depths at the colour image's time when the frame's depth image was
  /// taken at another (tracking.depth_time_correction), under the predicted motion.
  void moveDepthsToColourTime(const RgbdFrame& frame, const SE3& T_prev_curr_pred,
                              CurrentFrame& curr) const;
  ReferenceMeasurement measureAgainstReference(const SE3& T_world_pred, const CurrentFrame& curr,
                                               double dt_s, OdometryStats& stats);
  /// Empty when T_world_curr is a motion the camera can make since the previous frame (dt_s
  /// earlier), given the estimate's covariance; else why not.
  std::string implausibility(const SE3& T_world_curr, const Matrix6d& covariance,
                             double dt_s) const;
  /// The constant-velocity prior's covariance over interval_s (motion_prior_sigma_*).
  Matrix6d motionPriorCovariance(double interval_s) const;
  /// Whether a feature estimate lies further than tracking.motion_prior_gate_sigma from the
  /// prediction T_world_pred made dt_s after the last measured frame (prior and estimate
  /// covariance combined). False while no velocity is known.
  bool disagreesWithPrior(const SE3& T_world_curr, const Matrix6d& covariance,
                          const SE3& T_world_pred, double dt_s) const;
  /// Counts a rejected estimate in stats; true if it was rejected (implausible or disagreeing).
  bool rejected(const SE3& T_world_curr, const Matrix6d& covariance, const SE3& T_world_pred,
                double dt_s, OdometryStats& stats) const;
  /// features_with_depth: the current frame's. novelty scales the bounds: 1 for the usual
  /// keyframes, smaller for a view that has changed less (relocalization_keyframe_novelty).
  bool needsNewKeyframe(const TrackAttempt& attempt, const Keyframe& kf, int features_with_depth,
                        double novelty = 1.0) const;
  /// Whether a frame measured by attempt against keyframe_ (at utime, not otherwise a keyframe)
  /// should become one for the back end to relocalise: its segment not yet placed in the map
  /// (MapKeyframes::relocalization_pending), the view changed, the interval passed.
  bool wantsRelocalizationKeyframe(const TrackAttempt& attempt, const CurrentFrame& curr,
                                   Utime utime) const;
  /// Measures against a recent or map keyframe near T_world_curr instead of making a new one;
  /// true (and attempt, T_world_curr and res updated) when one was good enough. attempt: the
  /// measurement against keyframe_ when keyframe_was_reference.
  bool reuseRecentKeyframe(const CurrentFrame& curr, TrackAttempt& attempt,
                           bool keyframe_was_reference, SE3& T_world_curr, OdometryResult& res);
  /// The keyframe of recent_keyframes_ with this id, or null.
  const Keyframe* recentKeyframe(std::int64_t id) const;
  void refineInLocalWindow(const CurrentFrame& curr, TrackAttempt& attempt, SE3& T_world_curr,
                           OdometryResult& res);
  /// A measurement against keyframe_ with few inliers (tracking.few_inliers_previous_frame):
  /// refined jointly with the matches against the previous measured frame, held at its pose.
  void refineWithPreviousFrame(const CurrentFrame& curr, TrackAttempt& attempt, SE3& T_world_curr,
                               OdometryResult& res);
  /// A feature estimate with few inliers (tracking.few_inliers_dense), measured against keyframe_
  /// when keyframe_is_reference, else against the previous frame: aligned densely against the
  /// previous measured frame from it, with its covariance (carried from the keyframe through the
  /// chain since it) as the prior. On success T_world_curr, the step's covariance and
  /// res.T_ref_curr hold the combined estimate.
  void refineWithDenseAlignment(CurrentFrame& curr, const TrackAttempt& attempt,
                                bool keyframe_is_reference, SE3& T_world_curr, OdometryResult& res);
  /// Dense alignment's pyramids of the reference and the current frame, each built once.
  void buildDensePyramids(CurrentFrame& curr);
  /// After LOST: measures the frame against the most recent keyframes (relocalization_*); true
  /// (keyframe_, T_world_curr and res's reference fields set) when one matched well enough at a
  /// pose the camera can have reached since the last measured frame.
  bool relocalizeAfterLoss(const CurrentFrame& curr, SE3& T_world_curr, OdometryResult& res);
  /// Fills local_search_ for the current keyframe.
  void collectLocalMapGroups(bool keyframe_is_reference);
  /// The landmarks of the keyframes covisible with the keyframe, searched by projection at
  /// T_world_curr and refined jointly with the attempt (measured against T_world_ref; the
  /// keyframe's own landmarks are left out when it is the reference). Updates attempt.T_ref_curr,
  /// T_world_curr and the current frame's landmark associations.
  void trackLocalMap(const CurrentFrame& curr, const SE3& T_world_ref, bool keyframe_is_reference,
                     TrackAttempt& attempt, SE3& T_world_curr, OdometryResult& res);
  /// Associates the attempt's inliers with the landmarks of the keyframe they were matched to:
  /// curr_landmarks[i] becomes the landmark of current feature i (grown as needed, -1 for
  /// none); nothing when kf is not in the local map.
  void associateWithKeyframe(const TrackAttempt& attempt, const Keyframe& kf,
                             std::vector<std::int64_t>& curr_landmarks) const;
  /// Appends a keyframe to recent_keyframes_ and the local map; drops the oldest beyond the
  /// window.
  void addToWindow(const KeyframePtr& keyframe, const std::vector<std::int64_t>& feature_landmarks);
  void addKeyframe(const CurrentFrame& curr, const RgbdFrame& frame, const RgbdFramePtr& frame_ptr,
                   const SE3& T_world_curr, OdometryResult& res);
  /// Dense alignment of the current frame against the last measured frame with depth, when
  /// features failed; true (and res filled as a measured frame) when it succeeded and the motion
  /// is plausible.
  bool measureDense(CurrentFrame& curr, const SE3& T_world_pred, OdometryResult& res,
                    SE3& T_world_curr);
  /// A measured frame (features or dense): keyframe if asked, motion model, state, commit.
  OdometryResult acceptMeasurement(OdometryResult res, const CurrentFrame& curr,
                                   const RgbdFrame& frame, const RgbdFramePtr& frame_ptr,
                                   const SE3& T_world_curr, bool new_keyframe,
                                   std::int64_t t_start);
  void rememberMeasuredFrame(const CurrentFrame& curr, const SE3& T_world_curr, Utime utime);
  /// Covariance of T_keyframe_curr for a frame reached through T_prev_curr with step covariance.
  Matrix6d chainedCovariance(const SE3& T_prev_curr, const Matrix6d& step_covariance) const;
  /// A failed frame: predicted with constant velocity for a short gap, then LOST.
  OdometryResult fail(OdometryResult res, OdometryStatus status,
                      std::shared_ptr<const FeatureSet> features, std::int64_t t_start);
  /// Every exit: the frame becomes the previous frame of the next call.
  OdometryResult commit(OdometryResult res, std::shared_ptr<const FeatureSet> features,
                        bool tracked, std::int64_t t_start);
  /// ref_subset: when given, only these reference features (indices, ascending) are matched.
  void matchGuided(const FeatureSet& ref, const SE3& T_ref_curr_prior, const CurrentFrame& curr,
                   double radius_px, std::vector<Correspondence>& matches,
                   const std::vector<int>* ref_subset = nullptr) const;
  /// How track() searches: around the prior, falling back to whole-image descriptor matching
  /// when too few are found; or only around the prior, in a window wider by a factor.
  struct Search {
    explicit Search(bool allow_global_matching = true, double window_scale = 1.0)
        : allow_global(allow_global_matching), radius_scale(window_scale) {}
    bool allow_global;
    double radius_scale;
  };
  void matchByDescriptor(const FeatureSet& ref, const CurrentFrame& curr,
                         std::vector<Correspondence>& matches) const;
  TrackAttempt track(const FeatureSet& ref, const SE3& T_ref_curr_prior, bool have_prior,
                     const CurrentFrame& curr, Search search = Search());
  /// Another reference measured jointly with the main one: its features and odometry pose.
  struct ExtraReference {
    const FeatureSet* features = nullptr;
    SE3 T_world_extra = SE3::Identity();
  };
  void alignInlierPatches(const FeatureSet& ref, const SE3& T_ref_curr, const CurrentFrame& curr,
                          std::vector<Correspondence>& matches,
                          const std::vector<std::uint8_t>& inliers) const;
  void refineWithExtraReferences(const SE3& T_world_ref, const std::vector<ExtraReference>& extras,
                                 const CurrentFrame& curr, TrackAttempt& attempt);
  SE3 alignRotation(const cv::Mat& small_curr, const CameraIntrinsics& K) const;
  KeyframePtr makeKeyframe(const CurrentFrame& curr, const RgbdFrame& frame,
                           const RgbdFramePtr& frame_ptr, const SE3& T_world_camera);

  TrackingConfig config_;
  std::unique_ptr<FeatureExtractor> extractor_;
  std::mt19937 rng_{42};

  TrackingState state_ = TrackingState::kNotInitialized;
  KeyframePtr keyframe_;
  std::deque<KeyframePtr> recent_keyframes_;  ///< the last keyframe_window keyframes (segment)
  MapKeyframes map_keyframes_;                ///< setMapKeyframes()
  Utime last_keyframe_made_utime_ = 0;        ///< the newest keyframe this object made
  /// Keyframes made for relocalisation in the current segment (wantsRelocalizationKeyframe).
  int relocalization_keyframes_made_ = 0;
  /// The landmarks of recent_keyframes_.
  LocalMap local_map_;
  /// The landmark each feature of the current frame was matched to (-1: none); the associations
  /// a keyframe made of the frame takes into the local map.
  std::vector<std::int64_t> curr_landmarks_;
  /// The local map's landmarks trackLocalMap searches, grouped by the keyframe whose view
  /// represents them (its descriptor, scale and patch): which features of that keyframe to search
  /// and the landmark of each.
  struct LocalMapGroup {
    const Keyframe* kf = nullptr;
    std::vector<int> features;  ///< ascending
    std::vector<std::int64_t> landmark_of_feature;
  };
  /// The groups depend only on the keyframe, whether the frame was measured against it, and the
  /// local map's keyframes and observations; they are rebuilt when one of those changes (about
  /// once per keyframe), not every frame.
  struct LocalMapSearch {
    std::int64_t keyframe_id = -1;  ///< -1: none collected yet
    bool keyframe_is_reference = false;
    std::uint64_t map_revision = 0;
    int num_landmarks = 0;
    std::unordered_map<std::int64_t, LocalMapGroup> groups;
  };
  LocalMapSearch local_search_;
  std::int64_t next_keyframe_id_ = 0;
  std::int64_t segment_ = 0;

  // The previous frame (for fallback tracking and the motion model).
  std::shared_ptr<const FeatureSet> prev_features_;
  bool prev_tracked_ = false;
  Utime prev_utime_ = 0;
  SE3 T_world_prev_ = SE3::Identity();
  SE3 velocity_prev_curr_ = SE3::Identity();  ///< last frame-to-frame motion
  bool have_velocity_ = false;
  Matrix6d last_covariance_ = Matrix6d::Identity() * 1e-6;
  int failed_frames_ = 0;
  // The last measured frame (not predicted): the plausibility check's reference.
  SE3 T_world_last_measured_ = SE3::Identity();
  Utime last_measured_utime_ = 0;
  cv::Mat prev_small_;  ///< blurred 80x60 image of the previous frame (FOVIS rotation alignment)
  /// Covariance of T_keyframe_prev along the chain of measurements since the keyframe.
  Matrix6d covariance_keyframe_prev_ = Matrix6d::Zero();

  /// The last measured frame with depth: dense alignment's reference.
  struct DenseReference {
    cv::Mat gray;
    cv::Mat depth_m;
    CameraIntrinsics K;
    std::shared_ptr<const DenseFrame> pyramid;  ///< built when first needed
    SE3 T_world_camera = SE3::Identity();
    Utime utime = 0;
  };
  DenseReference dense_reference_;
  DenseAlignmentOptions dense_options_;
  /// The same, with refineWithDenseAlignment's pixel budget.
  DenseAlignmentOptions refine_dense_options_;
};

}  // namespace slamd
