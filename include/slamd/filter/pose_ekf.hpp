#pragma once
// PoseEkf: an error-state EKF over the camera pose and world-frame vanishing directions, driven by
// odometry increments and corrected by vanishing points (paper 002, done with a point at infinity).
//
// Usage (one instance, owned by the filter thread; no threads inside, not thread-safe):
//   PoseEkf ekf(config, intrinsics);                    // pose = identity: world = first camera
//   for each odometry increment:
//     ekf.predict(T_prev_curr, covariance_prev_curr, dt_s);
//     if (a vanishing point was detected in the current image)
//       VpUpdateResult r = ekf.updateVanishingPoint(vp.pixel, vp.pixel_covariance);
//   ekf.T_world_camera(), ekf.poseCovariance()          // filtered pose, 6x6
//
// State. Nominal: T_world_camera (rotation R = R_world_camera, translation t = camera origin in
// world, metres) and L unit vectors d_world[i] (vanishing-direction landmarks, world frame; an
// axis: d and -d give the same vanishing point). Error state, dimension 6 + 2L, in slamd's
// covariance convention (the same as PoseEstimate and odometry_t):
//   t_true = t + dt                  dt: 3, metres, world frame
//   R_true = R * expSO3(dtheta)      dtheta: 3, radians, right (camera-frame) perturbation
//   d_true = normalise(d + B(d) dl)  dl: 2, tangent plane of d, B(d) a fixed orthonormal basis
// No Euler angles anywhere. After each update the error is injected into the nominal state and the
// covariance is transported to the new linearisation point (right Jacobian of SO(3) for the
// rotation, the change of tangent basis for each landmark).
//
// Prediction. T_world_curr = T_world_prev * T_prev_curr, with odometry noise in odometry_t's
// convention (translation additive in the previous camera frame, rotation right-perturbed in the
// current frame). Error propagation:
//   dt'     = dt - R [t_pc]x dtheta + R n_t
//   dtheta' = R_pc^T dtheta + n_phi
// plus process noise diag(sigma_t^2 dt, sigma_r^2 dt). Landmarks are static.
//
// Measurement (point at infinity). A world direction d seen from a camera with rotation R projects
// to the vanishing point
//   h(x) = pi(K R^T d),   pi([x y z]) = [x/z, y/z]   (pixels, independent of the translation),
// with Jacobians, for d_c = R^T d and J_pi = [fx/z 0 -fx x/z^2; 0 fy/z -fy y/z^2]:
//   dh/ddtheta = J_pi [d_c]x,   dh/ddl = J_pi R^T B(d),   dh/ddt = 0.
// Paper 002 uses a far but finite 3D point instead; the point at infinity is exact for parallel
// lines and observes only rotation (two DoF per direction: the rotation about d itself is
// unobservable from one direction), with no translation Jacobian (docs/filter.md says why).
//
// Gating and association: every landmark whose axis projects in front of the image plane is a
// candidate; the innovation covariance S = H P H^T + R gives the NIS nu^T S^-1 nu; the landmark
// with the smallest NIS is chosen and the update applied when NIS <= gate_chi2 (chi-square, 2 DoF,
// default 5.99), otherwise the measurement is gated (counted, state unchanged). A detection that no
// landmark accepts becomes a candidate direction in the world; seen in landmark_init_frames
// consecutive calls within landmark_init_angle_deg (and far from existing landmarks) it becomes a
// new landmark, initialised with the covariance of R * K^-1 u (correlated with the pose).
// Landmark consistency (NIS statistics per landmark): a landmark created this way is on probation
// for its first landmark_probation detections of its direction (within
// landmark_min_separation_deg): they are gated as usual and never move the pose (kProbation), but
// those inside the gate refine the landmark's own direction (a Schmidt update: only its rows of
// the gain are kept), so that the landmark does not keep the error of the one detection it was
// created from; if the median of their NIS is at most landmark_consistency_chi2 it becomes
// active, otherwise it is retired. An active landmark whose last landmark_window detections have
// a median NIS above landmark_consistency_chi2 is retired too. Retiring removes the landmark from
// the state (marginalisation: its rows and columns are dropped) and blocks its direction for new
// landmarks for landmark_retry_calls calls (then it may start a new probation).
// Why: in cluttered scenes detections of a real direction scatter far more than their covariance
// claims, and such landmarks are gated most of the time, a corridor's rarely (docs/filter.md).
// Re-anchoring (filter.reanchor_detections): an odometry increment that jumps (a wrong match set,
// a bridged failure) with an over-confident covariance moves the pose away from an established
// landmark, and every later detection is gated although they all agree with each other. When the
// last reanchor_detections detections of a landmark with at least reanchor_min_updates accepted
// updates are gated and each innovation lies within gate_chi2 of their mean (under its own S), the
// pose covariance is widened by the jump, sigma = 2 * |mean innovation| / f (radians), and the
// detection is applied: the pose returns to the landmark instead of the landmark being retired and
// replaced by one at the wrong pose. The widening has the shape of the latest odometry increment's
// noise (G Q G^T with the rotation about the direction projected out, its rotation block
// normalised to sigma^2 per observable axis): a wrong increment turns and shifts the camera
// together, so the translation is corrected with the rotation (docs/filter.md). The rotation
// about the direction itself, which no vanishing point observes, is not widened.
// Spread corrections (filter.max_correction_rate_degps, max_correction_speed_mps): a
// re-anchoring's correction is applied at a limited rate. From the re-anchoring on, the updates
// between two predictions may turn the pose by at most rate * dt and move it by at most speed * dt
// (or by 3 sigma of the latest increment's noise, rotation and translation, where that is more:
// what one increment could have got wrong is corrected at once). An update that would move it
// further has its gain scaled down to fit; the Joseph form below is the exact covariance for any
// gain, so the part not applied stays in P and the next detections apply it. The first update
// that fits ends the spreading. Why: the published pose feeds controllers that differentiate it; a
// re-anchoring moves it by a degree or two that the pose's own covariance did not admit, and in
// one frame that is a spike in angular rate that the robot never made. Ordinary updates are not
// limited: they lie inside the gate, so the covariance published with the earlier poses allowed
// them, and spreading them only delays the pose (on the plain corridors, the correction when the
// corridor's vanishing point comes back after the end wall was still under way when the walk
// ended, docs/filter.md).
// Covariance updates use the Joseph form (I - KH) P (I - KH)^T + K R K^T.
// Reset: after an update moves the rotation by dtheta (R' = R exp(dtheta)), the rotation block of
// the covariance is re-expressed at R' with e' = exp(dtheta)^T e: the error is kept unchanged in
// the world frame. The usual first-order reset e' = J_r(dtheta) e turns the covariance by only half
// of dtheta. That matters when one direction pins two rotation axes of a large prior (after a lost
// frame): the posterior is a narrow "cigar" along the unobservable rotation about d, whose
// direction in body coordinates, R^T d, turns by the whole dtheta; turned by half, it leaks into
// the next update's observable axes (measured in docs/filter.md). This is the invariant-EKF
// choice: the unobservable direction of a world-direction measurement does not depend on the
// estimate.
//
// Plane axes (updateDirection, from SurfaceAxisDetector: Manhattan directions told apart by depth
// normals). A measured unoriented unit axis m in the camera frame, with covariance Sigma (rad^2) in
// B(m), observes the same landmarks: the prediction, expressed in the measured axis' tangent
// plane,
//   h(x) = B(m)^T s R^T d,   s = sign(m . R^T d)   (the measurement itself is 0 there),
//   dh/ddtheta = s B(m)^T [R^T d]x,   dh/ddl = s B(m)^T R^T B(d),   dh/ddt = 0,
// so the innovation is -h(x) and R = Sigma. A floor or wall axis is perpendicular to the
// corridor's vanishing direction and observes the roll about it, which one vanishing point cannot.
// Association, gating, candidates, probation and retirement are shared with vanishing points (a
// vanishing point and an end wall's normal are the same axis); candidates from plane axes are
// confirmed over consecutive predictions (frames) rather than consecutive vanishing points.
//
// Bad input (non-finite motion or pixel, NaN or non-positive-(semi)definite covariances) never
// throws: it is rejected or replaced by a documented fallback, reported by the status and counted.

#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/filter/filter_config.hpp"

namespace slamd {

enum class EkfPredictStatus : std::int8_t {
  kOk = 0,
  kFallbackCovariance,  ///< odometry covariance NaN or not PSD: fallback covariance used
  kRejected,            ///< non-finite or non-rigid motion: state unchanged
};

enum class VpUpdateStatus : std::int8_t {
  kAccepted = 0,     ///< associated with a landmark, passed the gate, state updated
  kGated,            ///< best landmark's NIS above the gate: state unchanged
  kNewLandmark,      ///< confirmed candidate: a landmark was created from this detection
  kCandidate,        ///< no landmark accepted it; counted towards a new landmark
  kBadMeasurement,   ///< non-finite pixel, or covariance NaN / not positive definite
  kUnknownLandmark,  ///< updateLandmark() with an id that does not exist
  kNotVisible,       ///< the landmark's vanishing point is at infinity in the image
  kProbation,        ///< inside the gate of a landmark on probation: refines it, pose unchanged
};

/// What a measurement of a world direction is.
enum class DirectionMeasurement : std::int8_t {
  kVanishingPoint = 0,  ///< a vanishing point, pixels
  kSurfaceAxis,         ///< a plane axis from depth normals, unit vector in the camera frame
};

const char* ekfPredictStatusName(EkfPredictStatus status);
const char* vpUpdateStatusName(VpUpdateStatus status);

/// What one vanishing-point update did (fields of slamd.vanishing_point_t and of the status
/// channel).
/// For kSurfaceAxis measurements the *_px fields hold radians in the tangent basis of the measured
/// axis (measured is 0 there by construction), and the innovation covariance is in rad^2.
struct VpUpdateResult {
  DirectionMeasurement measurement = DirectionMeasurement::kVanishingPoint;
  VpUpdateStatus status = VpUpdateStatus::kBadMeasurement;
  bool accepted = false;  ///< true for kAccepted only
  int landmark_id = -1;   ///< associated (or best, when gated; or created) landmark, -1 none
  Eigen::Vector2d measured_px = Eigen::Vector2d::Zero();
  Eigen::Vector2d predicted_px = Eigen::Vector2d::Zero();  ///< h(x) before the update
  Eigen::Vector2d innovation_px = Eigen::Vector2d::Zero();
  Eigen::Matrix2d innovation_covariance = Eigen::Matrix2d::Zero();  ///< S, pixels^2
  double nis = 0.0;  ///< Mahalanobis distance squared nu^T S^-1 nu (2 DoF); 0 when none
};

/// A vanishing-direction landmark.
struct DirectionLandmark {
  int id = 0;
  Eigen::Vector3d d_world = Eigen::Vector3d::UnitZ();  ///< unit axis, world frame
  std::int64_t num_updates = 0;
  bool active = true;  ///< false while on probation (tested, refined, never moves the pose)
  /// the kind of measurement it was created from (whose clock times its retirement)
  DirectionMeasurement kind = DirectionMeasurement::kVanishingPoint;
  /// NIS of the recent detections of its direction: the probation's, then a ring of the last
  /// landmark_window (consistency statistics).
  std::vector<double> recent_nis;
  std::size_t recent_next = 0;
  /// The consecutive gated vanishing points of its direction since its last accepted one, at
  /// most filter.reanchor_detections (re-anchoring).
  struct GatedInnovation {
    Eigen::Vector2d innovation_px;
    Eigen::Matrix2d covariance_px2;  ///< S
  };
  std::vector<GatedInnovation> gated_run;
};

struct EkfCounters {
  std::int64_t predictions = 0;
  std::int64_t predictions_rejected = 0;
  std::int64_t fallback_covariances = 0;
  std::int64_t bad_dt = 0;  ///< negative or non-finite dt (treated as 0)
  /// odometry covariances capped at the motion limits (a lost frame's, for example)
  std::int64_t capped_covariances = 0;
  std::int64_t updates_accepted = 0;
  std::int64_t updates_gated = 0;
  std::int64_t bad_measurements = 0;
  std::int64_t landmarks_created = 0;
  std::int64_t landmarks_activated = 0;  ///< passed probation
  std::int64_t landmarks_retired = 0;    ///< failed probation or gated too often
  std::int64_t probation_tests = 0;
  /// pose re-anchored to an established landmark after consistent gated detections (an odometry
  /// jump; see filter.reanchor_detections)
  std::int64_t reanchors = 0;
  /// updates applied with a reduced gain because a re-anchoring would have moved the pose faster
  /// than filter.max_correction_rate_degps / max_correction_speed_mps (the rest follows later)
  std::int64_t corrections_spread = 0;
  std::int64_t axis_updates_accepted = 0;  ///< of updates_accepted: from plane axes
  std::int64_t axis_updates_gated = 0;     ///< of updates_gated: from plane axes
};

class PoseEkf {
 public:
  PoseEkf(const FilterConfig& config, const CameraIntrinsics& intrinsics);

  /// Restarts at T_world_camera with a 6x6 pose covariance (slamd convention) and no landmarks.
  void reset(const SE3& T_world_camera, const Matrix6d& pose_covariance);

  /// Propagates by one odometry increment.
  /// @param T_prev_curr current camera frame -> previous camera frame (metres)
  /// @param covariance_prev_curr 6x6, x y z (m^2, previous camera frame), rx ry rz (rad^2, right
  ///        perturbation in the current camera frame), as in slamd.odometry_t
  /// @param dt_s time between the two frames, seconds (for the process noise)
  EkfPredictStatus predict(const SE3& T_prev_curr, const Matrix6d& covariance_prev_curr,
                           double dt_s);

  /// Associates a vanishing point with the landmarks, gates and updates (or counts it towards a
  /// new landmark).
  /// @param pixel vanishing point, pixels; @param pixel_covariance 2x2, pixels^2
  /// A non-finite pixel, one farther outside the image than filter.vp.max_outside_fraction, or a
  /// covariance that is NaN or not positive definite gives kBadMeasurement (counted).
  VpUpdateResult updateVanishingPoint(const Eigen::Vector2d& pixel,
                                      const Eigen::Matrix2d& pixel_covariance);

  /// Update against one given landmark (known association), with the same gate.
  VpUpdateResult updateLandmark(int landmark_id, const Eigen::Vector2d& pixel,
                                const Eigen::Matrix2d& pixel_covariance);

  /// Associates a plane axis (unit vector in the camera frame, sign ignored; covariance 2x2 in
  /// tangentBasis(direction_camera), rad^2) with the landmarks, gates and updates, or counts it
  /// towards a new landmark, exactly as updateVanishingPoint(). A non-unit or non-finite axis or a
  /// covariance that is NaN or not positive definite gives kBadMeasurement (counted).
  VpUpdateResult updateDirection(const Eigen::Vector3d& direction_camera,
                                 const Eigen::Matrix2d& covariance);

  /// Adds an active landmark from a vanishing point seen now (no confirmation, no probation);
  /// returns its id, or -1 when the input is bad or max_landmarks is reached.
  int addLandmark(const Eigen::Vector2d& pixel, const Eigen::Matrix2d& pixel_covariance);

  // --- corrections from a back end -------------------------------------------------------------
  /// Replaces the pose and its 6x6 covariance; landmarks are kept, pose-landmark correlations
  /// are dropped.
  void setPose(const SE3& T_world_camera, const Matrix6d& pose_covariance);
  /// Moves the whole map by T_corrected_world (world -> corrected world): the pose becomes
  /// T_corrected_world * T_world_camera and landmark directions rotate with it; covariances are
  /// transformed accordingly (the correction itself is treated as exact).
  void applyCorrection(const SE3& T_corrected_world);

  // --- outputs ---------------------------------------------------------------------------------
  const SE3& T_world_camera() const { return T_world_camera_; }
  /// Pose covariance, slamd convention (translation m^2 world frame, rotation rad^2 camera frame).
  Matrix6d poseCovariance() const { return P_.topLeftCorner<6, 6>(); }
  /// Full error-state covariance, (6 + 2L) square.
  const Eigen::MatrixXd& covariance() const { return P_; }
  const std::vector<DirectionLandmark>& landmarks() const { return landmarks_; }
  const EkfCounters& counters() const { return counters_; }
  const FilterConfig& config() const { return config_; }

  // --- models, public for tests (Jacobians are checked against central differences) -----------
  /// T boxplus delta: translation + delta[0:3] (world), rotation * expSO3(delta[3:6]).
  static SE3 boxplus(const SE3& T, const Vector6d& delta);
  /// a boxminus b: the delta with boxplus(b, delta) = a.
  static Vector6d boxminus(const SE3& a, const SE3& b);
  /// Error-propagation Jacobians of T_world_curr = T_world_prev * T_prev_curr: F with respect to
  /// the pose error, G with respect to the odometry noise.
  static void motionJacobians(const SE3& T_world_prev, const SE3& T_prev_curr, Matrix6d* F,
                              Matrix6d* G);
  /// Orthonormal basis (3x2) of the plane perpendicular to the unit vector d.
  static Eigen::Matrix<double, 3, 2> tangentBasis(const Eigen::Vector3d& d);
  /// normalise(d + B(d) delta).
  static Eigen::Vector3d retractDirection(const Eigen::Vector3d& d, const Eigen::Vector2d& delta);
  /// h = pi(K R^T d) and its Jacobians with respect to the rotation error (2x3) and the landmark
  /// tangent error (2x2). False when R^T d is (nearly) parallel to the image plane.
  static bool projectDirection(const CameraIntrinsics& K, const Eigen::Matrix3d& R_world_camera,
                               const Eigen::Vector3d& d_world, Eigen::Vector2d* pixel,
                               Eigen::Matrix<double, 2, 3>* H_rotation,
                               Eigen::Matrix2d* H_direction);
  /// Prediction of a measured plane axis m (unit, camera frame) in its tangent basis B(m):
  /// h = B(m)^T s R^T d with s = sign(m . R^T d), and its Jacobians with respect to the rotation
  /// error (2x3) and the landmark tangent error (2x2). False when m is perpendicular to R^T d.
  static bool predictAxis(const Eigen::Matrix3d& R_world_camera, const Eigen::Vector3d& d_world,
                          const Eigen::Vector3d& measured_camera, Eigen::Vector2d* predicted,
                          Eigen::Matrix<double, 2, 3>* H_rotation, Eigen::Matrix2d* H_direction);
  /// World direction d = R m of a camera-frame axis m, and the Jacobians of its tangent error (in
  /// B(d)) with respect to the rotation error (2x3) and the axis' own tangent error (in B(m), 2x2).
  static Eigen::Vector3d directionFromAxis(const Eigen::Matrix3d& R_world_camera,
                                           const Eigen::Vector3d& axis_camera,
                                           Eigen::Matrix<double, 2, 3>* J_rotation,
                                           Eigen::Matrix2d* J_axis);
  /// World direction of a vanishing pixel, d = R K^-1 [u 1] / |.|, and the Jacobians of its
  /// tangent error (in B(d)) with respect to the rotation error (2x3) and the pixel (2x2).
  static Eigen::Vector3d directionFromPixel(const CameraIntrinsics& K,
                                            const Eigen::Matrix3d& R_world_camera,
                                            const Eigen::Vector2d& pixel,
                                            Eigen::Matrix<double, 2, 3>* J_rotation,
                                            Eigen::Matrix2d* J_pixel);

 private:
  /// Scales rows and columns of an odometry covariance so no axis exceeds the motion limits over
  /// dt_s (filter.max_speed_mps, filter.max_angular_rate_radps); true when it changed anything.
  bool capAtMotionLimits(double dt_s, Matrix6d* Q_odometry) const;
  /// One measurement of a world direction, validated: a vanishing point (pixel) or a plane axis
  /// (axis_camera), with its noise R (pixels^2, or rad^2 in B(axis_camera)).
  struct Observation {
    DirectionMeasurement kind = DirectionMeasurement::kVanishingPoint;
    Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
    Eigen::Vector3d axis_camera = Eigen::Vector3d::UnitZ();
    Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  };
  struct Candidate {
    DirectionMeasurement kind = DirectionMeasurement::kVanishingPoint;
    Eigen::Vector3d d_world;
    int count = 0;
    std::int64_t last_tick = 0;  ///< clock(kind) when last seen
  };

  /// The clock candidates of this kind are confirmed on: vanishing-point calls, or predictions.
  std::int64_t clock(DirectionMeasurement kind) const;
  /// Association, gate, update or candidate bookkeeping for a validated observation.
  VpUpdateResult updateObservation(const Observation& observation);
  /// World direction of an observation, with the Jacobians of its tangent error.
  Eigen::Vector3d worldDirection(const Observation& observation,
                                 Eigen::Matrix<double, 2, 3>* J_rotation,
                                 Eigen::Matrix2d* J_measurement) const;
  /// NIS and pieces for landmark index i; false when not visible.
  bool innovation(std::size_t index, const Observation& observation, VpUpdateResult* result,
                  Eigen::MatrixXd* H) const;
  /// Kalman update with Joseph-form covariance. With only_landmark_index >= 0 only that
  /// landmark's direction moves (Schmidt update): the pose and other landmarks are unchanged.
  void applyUpdate(const Eigen::MatrixXd& H, const Eigen::Vector2d& innovation,
                   const Eigen::Matrix2d& S, const Eigen::Matrix2d& R_px,
                   int only_landmark_index = -1);
  /// A detection inside the gate of a landmark on probation refines that landmark's direction.
  void refineOnProbation(std::size_t index, const Eigen::MatrixXd& H,
                         const Observation& observation, VpUpdateResult* result);
  void acceptUpdate(std::size_t index, const Eigen::MatrixXd& H, const Observation& observation,
                    VpUpdateResult* result);
  /// After a re-anchoring, scales the gain K and the state update dx down so that the pose moves
  /// no more than this frame's correction budget ("Spread corrections"); ends the spread once an
  /// update fits.
  void limitReanchoringCorrection(Eigen::MatrixXd& K, Eigen::VectorXd& dx);
  /// Records a gated vanishing point of landmark index's direction; when the last
  /// reanchor_detections of them agree, widens the pose covariance and applies this one.
  /// True when it did (result updated, status kAccepted); false leaves the state unchanged.
  bool reanchorAfterGating(std::size_t index, const Observation& observation,
                           VpUpdateResult* result);
  int addLandmarkUnchecked(const Observation& observation, bool active);
  /// Records the NIS of a detection of landmark index's direction for its consistency statistics;
  /// may activate or retire it. Returns false when the landmark was retired (indices shift).
  bool recordOutcome(std::size_t index, double nis);
  void retireLandmark(std::size_t index);
  bool nearRetired(const Eigen::Vector3d& d_world) const;
  bool validMeasurement(const Eigen::Vector2d& pixel, const Eigen::Matrix2d& covariance,
                        Eigen::Matrix2d* R_px) const;

  FilterConfig config_;
  CameraIntrinsics intrinsics_;
  SE3 T_world_camera_ = SE3::Identity();
  std::vector<DirectionLandmark> landmarks_;
  Eigen::MatrixXd P_;
  std::vector<Candidate> candidates_;
  struct Retired {
    Eigen::Vector3d d_world;
    /// the kind of the measurement whose landmark was retired; blocked for new landmarks while
    /// clock(kind) is below until_tick
    DirectionMeasurement kind = DirectionMeasurement::kVanishingPoint;
    std::int64_t until_tick = 0;
  };
  std::vector<Retired> retired_;
  std::int64_t vp_calls_ = 0;
  /// G Q G^T of the latest prediction (the shape of an odometry increment's error, re-anchoring)
  Matrix6d last_increment_noise_ = Matrix6d::Zero();
  /// What direction updates may still move the pose until the next prediction (rad, m): the
  /// correction rate limits times the prediction's dt; unlimited before the first timed one.
  double correction_budget_rad_ = std::numeric_limits<double>::infinity();
  double correction_budget_m_ = std::numeric_limits<double>::infinity();
  /// A re-anchoring's correction is being spread: set by the re-anchoring, cleared by the first
  /// update that fits in the budget.
  bool spreading_correction_ = false;
  int next_landmark_id_ = 0;
  EkfCounters counters_;
};

}  // namespace slamd
