#include "slamd/filter/pose_ekf.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Dense>

namespace slamd {

namespace {

constexpr double kDegToRad = M_PI / 180.0;
/// A direction update may always move the pose by this many sigmas of the latest increment's
/// noise (the whole 3-vector's), whatever the correction rate limits say.
constexpr double kCorrectionIncrementSigmas = 3.0;
// |z| of the camera-frame direction below which the vanishing point is treated as at infinity in
// the image (at f = 525 px this is a point ~5e5 px from the principal point).
constexpr double kMinDirectionDepth = 1e-3;
// Rotation matrices whose R^T R differs from I by more than this are not rigid motions.
constexpr double kRotationTolerance = 1e-4;
// Pixels farther than this from the image are "at infinity" whatever the configuration says.
constexpr double kMaxPixelMagnitude = 1e7;

/// Symmetric, finite and positive semi-definite within a relative tolerance.
template <int N>
bool isValidCovariance(const Eigen::Matrix<double, N, N>& C, bool strictly_positive) {
  if (!C.allFinite()) return false;
  const Eigen::Matrix<double, N, N> sym = 0.5 * (C + C.transpose());
  if ((C - sym).cwiseAbs().maxCoeff() > 1e-9 * std::max(1.0, C.cwiseAbs().maxCoeff())) {
    return false;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(sym);
  if (eig.info() != Eigen::Success) return false;
  const double scale = std::max(1e-300, eig.eigenvalues().cwiseAbs().maxCoeff());
  const double min_eigen = eig.eigenvalues()(0);
  return strictly_positive ? min_eigen > 1e-12 * scale : min_eigen >= -1e-9 * scale;
}

void symmetrize(Eigen::MatrixXd& P) { P = 0.5 * (P + P.transpose()).eval(); }

}  // namespace

const char* ekfPredictStatusName(EkfPredictStatus status) {
  switch (status) {
    case EkfPredictStatus::kOk:
      return "OK";
    case EkfPredictStatus::kFallbackCovariance:
      return "FALLBACK_COVARIANCE";
    case EkfPredictStatus::kRejected:
      return "REJECTED";
  }
  return "UNKNOWN";
}

const char* vpUpdateStatusName(VpUpdateStatus status) {
  switch (status) {
    case VpUpdateStatus::kAccepted:
      return "ACCEPTED";
    case VpUpdateStatus::kGated:
      return "GATED";
    case VpUpdateStatus::kNewLandmark:
      return "NEW_LANDMARK";
    case VpUpdateStatus::kCandidate:
      return "CANDIDATE";
    case VpUpdateStatus::kBadMeasurement:
      return "BAD_MEASUREMENT";
    case VpUpdateStatus::kUnknownLandmark:
      return "UNKNOWN_LANDMARK";
    case VpUpdateStatus::kNotVisible:
      return "NOT_VISIBLE";
    case VpUpdateStatus::kProbation:
      return "PROBATION";
  }
  return "UNKNOWN";
}

PoseEkf::PoseEkf(const FilterConfig& config, const CameraIntrinsics& intrinsics)
    : config_(config), intrinsics_(intrinsics) {
  Matrix6d P0 = Matrix6d::Zero();
  P0.diagonal().head<3>().setConstant(config_.initial_translation_sigma_m *
                                      config_.initial_translation_sigma_m);
  P0.diagonal().tail<3>().setConstant(config_.initial_rotation_sigma_rad *
                                      config_.initial_rotation_sigma_rad);
  reset(SE3::Identity(), P0);
}

void PoseEkf::reset(const SE3& T_world_camera, const Matrix6d& pose_covariance) {
  T_world_camera_ = normalizedSE3(T_world_camera);
  landmarks_.clear();
  candidates_.clear();
  retired_.clear();
  P_ = pose_covariance;
  symmetrize(P_);
  spreading_correction_ = false;
}

// --- models ----------------------------------------------------------------------------------

SE3 PoseEkf::boxplus(const SE3& T, const Vector6d& delta) {
  SE3 out = T;
  out.translation() += delta.head<3>();
  out.linear() = T.linear() * expSO3(delta.tail<3>());
  return out;
}

Vector6d PoseEkf::boxminus(const SE3& a, const SE3& b) {
  Vector6d delta;
  delta.head<3>() = a.translation() - b.translation();
  delta.tail<3>() = logSO3(b.linear().transpose() * a.linear());
  return delta;
}

void PoseEkf::motionJacobians(const SE3& T_world_prev, const SE3& T_prev_curr, Matrix6d* F,
                              Matrix6d* G) {
  const Eigen::Matrix3d R = T_world_prev.linear();
  if (F) {
    F->setIdentity();
    F->block<3, 3>(0, 3) = -R * skew(T_prev_curr.translation());
    F->block<3, 3>(3, 3) = T_prev_curr.linear().transpose();
  }
  if (G) {
    G->setIdentity();
    G->block<3, 3>(0, 0) = R;
  }
}

Eigen::Matrix<double, 3, 2> PoseEkf::tangentBasis(const Eigen::Vector3d& d) {
  const Eigen::Vector3d helper =
      std::abs(d.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d b1 = d.cross(helper).normalized();
  const Eigen::Vector3d b2 = d.cross(b1);
  Eigen::Matrix<double, 3, 2> B;
  B << b1, b2;
  return B;
}

Eigen::Vector3d PoseEkf::retractDirection(const Eigen::Vector3d& d, const Eigen::Vector2d& delta) {
  return (d + tangentBasis(d) * delta).normalized();
}

bool PoseEkf::projectDirection(const CameraIntrinsics& K, const Eigen::Matrix3d& R_world_camera,
                               const Eigen::Vector3d& d_world, Eigen::Vector2d* pixel,
                               Eigen::Matrix<double, 2, 3>* H_rotation,
                               Eigen::Matrix2d* H_direction) {
  const Eigen::Vector3d d_c = R_world_camera.transpose() * d_world;
  const double z = d_c.z();
  if (!(std::abs(z) >= kMinDirectionDepth * d_c.norm())) return false;
  const double inv_z = 1.0 / z;
  if (pixel) {
    *pixel = Eigen::Vector2d(K.fx * d_c.x() * inv_z + K.cx, K.fy * d_c.y() * inv_z + K.cy);
  }
  Eigen::Matrix<double, 2, 3> J_pi;
  J_pi << K.fx * inv_z, 0.0, -K.fx * d_c.x() * inv_z * inv_z,  //
      0.0, K.fy * inv_z, -K.fy * d_c.y() * inv_z * inv_z;
  if (H_rotation) *H_rotation = J_pi * skew(d_c);
  if (H_direction) *H_direction = J_pi * R_world_camera.transpose() * tangentBasis(d_world);
  return true;
}

Eigen::Vector3d PoseEkf::directionFromPixel(const CameraIntrinsics& K,
                                            const Eigen::Matrix3d& R_world_camera,
                                            const Eigen::Vector2d& pixel,
                                            Eigen::Matrix<double, 2, 3>* J_rotation,
                                            Eigen::Matrix2d* J_pixel) {
  const Eigen::Vector3d m((pixel.x() - K.cx) / K.fx, (pixel.y() - K.cy) / K.fy, 1.0);
  const double m_norm = m.norm();
  const Eigen::Vector3d d_c = m / m_norm;
  const Eigen::Vector3d d_w = R_world_camera * d_c;
  const Eigen::Matrix<double, 3, 2> B = tangentBasis(d_w);
  if (J_rotation) *J_rotation = -B.transpose() * R_world_camera * skew(d_c);
  if (J_pixel) {
    Eigen::Matrix<double, 3, 2> dm_du = Eigen::Matrix<double, 3, 2>::Zero();
    dm_du(0, 0) = 1.0 / K.fx;
    dm_du(1, 1) = 1.0 / K.fy;
    const Eigen::Matrix3d J_norm = (Eigen::Matrix3d::Identity() - d_c * d_c.transpose()) / m_norm;
    *J_pixel = B.transpose() * R_world_camera * J_norm * dm_du;
  }
  return d_w;
}

bool PoseEkf::predictAxis(const Eigen::Matrix3d& R_world_camera, const Eigen::Vector3d& d_world,
                          const Eigen::Vector3d& measured_camera, Eigen::Vector2d* predicted,
                          Eigen::Matrix<double, 2, 3>* H_rotation, Eigen::Matrix2d* H_direction) {
  const Eigen::Vector3d d_c = R_world_camera.transpose() * d_world;
  const double cosine = measured_camera.dot(d_c);
  if (!(std::abs(cosine) >= kMinDirectionDepth)) return false;
  const double s = cosine < 0.0 ? -1.0 : 1.0;
  const Eigen::Matrix<double, 3, 2> B_m = tangentBasis(measured_camera);
  if (predicted) *predicted = s * B_m.transpose() * d_c;
  if (H_rotation) *H_rotation = s * B_m.transpose() * skew(d_c);
  if (H_direction) {
    *H_direction = s * B_m.transpose() * R_world_camera.transpose() * tangentBasis(d_world);
  }
  return true;
}

Eigen::Vector3d PoseEkf::directionFromAxis(const Eigen::Matrix3d& R_world_camera,
                                           const Eigen::Vector3d& axis_camera,
                                           Eigen::Matrix<double, 2, 3>* J_rotation,
                                           Eigen::Matrix2d* J_axis) {
  const Eigen::Vector3d d_w = R_world_camera * axis_camera;
  const Eigen::Matrix<double, 3, 2> B = tangentBasis(d_w);
  if (J_rotation) *J_rotation = -B.transpose() * R_world_camera * skew(axis_camera);
  if (J_axis) *J_axis = B.transpose() * R_world_camera * tangentBasis(axis_camera);
  return d_w;
}

// --- prediction --------------------------------------------------------------------------------

bool PoseEkf::capAtMotionLimits(double dt_s, Matrix6d* Q_odometry) const {
  const double max_translation_m = config_.motion_limits.max_speed_mps * dt_s;
  const double max_rotation_rad = config_.motion_limits.max_angular_rate_radps * dt_s;
  Vector6d scale = Vector6d::Ones();
  for (int i = 0; i < 6; ++i) {
    const double limit = i < 3 ? max_translation_m : max_rotation_rad;
    const double variance = (*Q_odometry)(i, i);
    if (variance > limit * limit) scale(i) = limit / std::sqrt(variance);
  }
  if ((scale.array() == 1.0).all()) return false;
  *Q_odometry = scale.asDiagonal() * (*Q_odometry) * scale.asDiagonal();
  return true;
}

EkfPredictStatus PoseEkf::predict(const SE3& T_prev_curr, const Matrix6d& covariance_prev_curr,
                                  double dt_s) {
  ++counters_.predictions;
  const Eigen::Matrix3d R_pc = T_prev_curr.linear();
  if (!T_prev_curr.matrix().allFinite() ||
      (R_pc.transpose() * R_pc - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() >
          kRotationTolerance ||
      R_pc.determinant() <= 0.0) {
    ++counters_.predictions_rejected;
    return EkfPredictStatus::kRejected;
  }
  EkfPredictStatus status = EkfPredictStatus::kOk;
  Matrix6d Q_odometry;
  if (isValidCovariance<6>(covariance_prev_curr, false)) {
    Q_odometry = config_.odometry_covariance_scale * 0.5 *
                 (covariance_prev_curr + covariance_prev_curr.transpose());
  } else {
    ++counters_.fallback_covariances;
    status = EkfPredictStatus::kFallbackCovariance;
    Q_odometry.setZero();
    Q_odometry.diagonal().head<3>().setConstant(config_.fallback_translation_sigma_m *
                                                config_.fallback_translation_sigma_m);
    Q_odometry.diagonal().tail<3>().setConstant(config_.fallback_rotation_sigma_rad *
                                                config_.fallback_rotation_sigma_rad);
  }
  if (!std::isfinite(dt_s) || dt_s < 0.0) {
    ++counters_.bad_dt;
    dt_s = 0.0;
  }
  if (dt_s > 0.0 && capAtMotionLimits(dt_s, &Q_odometry)) ++counters_.capped_covariances;
  dt_s = std::min(dt_s, config_.max_dt_s);

  Matrix6d F, G;
  motionJacobians(T_world_camera_, T_prev_curr, &F, &G);
  Matrix6d Q = G * Q_odometry * G.transpose();
  Q.diagonal().head<3>().array() +=
      config_.translation_noise_m_per_sqrt_s * config_.translation_noise_m_per_sqrt_s * dt_s;
  Q.diagonal().tail<3>().array() +=
      config_.rotation_noise_rad_per_sqrt_s * config_.rotation_noise_rad_per_sqrt_s * dt_s;

  const Eigen::Index n = P_.rows();
  const Matrix6d P_pp = P_.topLeftCorner<6, 6>();
  P_.topLeftCorner<6, 6>() = F * P_pp * F.transpose() + Q;
  if (n > 6) {
    const Eigen::MatrixXd P_pl = F * P_.topRightCorner(6, n - 6);
    P_.topRightCorner(6, n - 6) = P_pl;
    P_.bottomLeftCorner(n - 6, 6) = P_pl.transpose();
  }
  symmetrize(P_);
  T_world_camera_ = normalizedSE3(T_world_camera_ * T_prev_curr);
  last_increment_noise_ = Q;
  // What this increment alone could have got wrong is always correctable at once; only more than
  // that (error accumulated over many frames, or a jump) is held to the rate limit.
  const auto budget = [dt_s](double limit_per_s, const Eigen::Matrix3d& increment_noise) {
    if (!(limit_per_s > 0.0) || !(dt_s > 0.0)) return std::numeric_limits<double>::infinity();
    return std::max(limit_per_s * dt_s,
                    kCorrectionIncrementSigmas * std::sqrt(increment_noise.trace()));
  };
  correction_budget_rad_ =
      budget(config_.max_correction_rate_degps * kDegToRad, Q.bottomRightCorner<3, 3>());
  correction_budget_m_ = budget(config_.max_correction_speed_mps, Q.topLeftCorner<3, 3>());
  return status;
}

// --- update ------------------------------------------------------------------------------------

bool PoseEkf::validMeasurement(const Eigen::Vector2d& pixel, const Eigen::Matrix2d& covariance,
                               Eigen::Matrix2d* R_px) const {
  if (!pixel.allFinite() || pixel.cwiseAbs().maxCoeff() > kMaxPixelMagnitude) return false;
  const double margin_x = config_.vp.max_outside_fraction * intrinsics_.width;
  const double margin_y = config_.vp.max_outside_fraction * intrinsics_.height;
  if (pixel.x() < -margin_x || pixel.x() > intrinsics_.width - 1.0 + margin_x ||
      pixel.y() < -margin_y || pixel.y() > intrinsics_.height - 1.0 + margin_y) {
    return false;
  }
  if (!isValidCovariance<2>(covariance, true)) return false;
  *R_px = config_.measurement_noise_scale * 0.5 * (covariance + covariance.transpose());
  return true;
}

bool PoseEkf::innovation(std::size_t index, const Observation& observation, VpUpdateResult* result,
                         Eigen::MatrixXd* H) const {
  const DirectionLandmark& landmark = landmarks_[index];
  Eigen::Vector2d predicted;
  Eigen::Matrix<double, 2, 3> H_rotation;
  Eigen::Matrix2d H_direction;
  const bool visible =
      observation.kind == DirectionMeasurement::kVanishingPoint
          ? projectDirection(intrinsics_, T_world_camera_.linear(), landmark.d_world, &predicted,
                             &H_rotation, &H_direction)
          : predictAxis(T_world_camera_.linear(), landmark.d_world, observation.axis_camera,
                        &predicted, &H_rotation, &H_direction);
  if (!visible) return false;
  const Eigen::Index n = P_.rows();
  H->setZero(2, n);
  H->block<2, 3>(0, 3) = H_rotation;
  H->block<2, 2>(0, 6 + 2 * static_cast<Eigen::Index>(index)) = H_direction;
  const Eigen::Matrix2d S = (*H) * P_ * H->transpose() + observation.R;
  const Eigen::LDLT<Eigen::Matrix2d> ldlt(S);
  if (ldlt.info() != Eigen::Success || !(S.determinant() > 0.0)) return false;
  result->landmark_id = landmark.id;
  result->predicted_px = predicted;
  result->innovation_px = result->measured_px - predicted;
  result->innovation_covariance = S;
  result->nis = result->innovation_px.dot(ldlt.solve(result->innovation_px));
  return std::isfinite(result->nis);
}

void PoseEkf::applyUpdate(const Eigen::MatrixXd& H, const Eigen::Vector2d& innovation,
                          const Eigen::Matrix2d& S, const Eigen::Matrix2d& R_px,
                          int only_landmark_index) {
  const Eigen::Index n = P_.rows();
  const Eigen::MatrixXd PHt = P_ * H.transpose();
  Eigen::MatrixXd K = PHt * S.inverse();
  if (only_landmark_index >= 0) {
    // Schmidt update: only the landmark's rows of the optimal gain are kept; the Joseph form below
    // is the exact covariance for any gain, so the correlations with the unchanged rest stay right.
    const Eigen::Index k = 6 + 2 * static_cast<Eigen::Index>(only_landmark_index);
    const Eigen::MatrixXd landmark_rows = K.middleRows(k, 2);
    K.setZero();
    K.middleRows(k, 2) = landmark_rows;
  }
  Eigen::VectorXd dx = K * innovation;
  // A landmark-only (Schmidt) update does not move the pose: it neither uses nor ends a spread.
  if (only_landmark_index < 0) limitReanchoringCorrection(K, dx);
  Eigen::MatrixXd I_KH = -K * H;
  I_KH.diagonal().array() += 1.0;
  P_ = I_KH * P_ * I_KH.transpose() + K * R_px * K.transpose();

  // Inject the error into the nominal state, then move the covariance to the new linearisation
  // point: the rotation error is carried over unchanged in the world frame, which in body
  // coordinates is e' = exp(dtheta)^T e (see the header: "Reset"); B(d')^T B(d) / |d + B dl| for
  // each landmark.
  Eigen::MatrixXd reset = Eigen::MatrixXd::Identity(n, n);
  const Eigen::Vector3d dtheta = dx.segment<3>(3);
  T_world_camera_.translation() += dx.head<3>();
  T_world_camera_.linear() = T_world_camera_.linear() * expSO3(dtheta);
  T_world_camera_ = normalizedSE3(T_world_camera_);
  reset.block<3, 3>(3, 3) = expSO3(dtheta).transpose();
  for (std::size_t i = 0; i < landmarks_.size(); ++i) {
    const Eigen::Index k = 6 + 2 * static_cast<Eigen::Index>(i);
    const Eigen::Vector3d d = landmarks_[i].d_world;
    const Eigen::Matrix<double, 3, 2> B = tangentBasis(d);
    const Eigen::Vector3d moved = d + B * dx.segment<2>(k);
    const Eigen::Vector3d d_new = moved.normalized();
    reset.block<2, 2>(k, k) = tangentBasis(d_new).transpose() * B / moved.norm();
    landmarks_[i].d_world = d_new;
  }
  P_ = reset * P_ * reset.transpose();
  symmetrize(P_);
}

void PoseEkf::refineOnProbation(std::size_t index, const Eigen::MatrixXd& H,
                                const Observation& observation, VpUpdateResult* result) {
  applyUpdate(H, result->innovation_px, result->innovation_covariance, observation.R,
              static_cast<int>(index));
  ++counters_.probation_tests;
  result->status = VpUpdateStatus::kProbation;
}

void PoseEkf::acceptUpdate(std::size_t index, const Eigen::MatrixXd& H,
                           const Observation& observation, VpUpdateResult* result) {
  applyUpdate(H, result->innovation_px, result->innovation_covariance, observation.R);
  ++landmarks_[index].num_updates;
  if (observation.kind == DirectionMeasurement::kVanishingPoint)
    landmarks_[index].gated_run.clear();
  ++counters_.updates_accepted;
  if (observation.kind == DirectionMeasurement::kSurfaceAxis) ++counters_.axis_updates_accepted;
  result->status = VpUpdateStatus::kAccepted;
  result->accepted = true;
}

void PoseEkf::limitReanchoringCorrection(Eigen::MatrixXd& K, Eigen::VectorXd& dx) {
  const double turn_rad = dx.segment<3>(3).norm();
  const double shift_m = dx.head<3>().norm();
  double gain_scale = 1.0;
  if (spreading_correction_) {
    if (turn_rad > correction_budget_rad_) gain_scale = correction_budget_rad_ / turn_rad;
    if (shift_m > correction_budget_m_) {
      gain_scale = std::min(gain_scale, correction_budget_m_ / shift_m);
    }
    if (gain_scale < 1.0) {
      K *= gain_scale;
      dx *= gain_scale;
      ++counters_.corrections_spread;
    } else {
      spreading_correction_ = false;  // the re-anchoring's correction has been applied
    }
  }
  // What is left for this frame; an unlimited update may have used more than there was.
  correction_budget_rad_ = std::max(0.0, correction_budget_rad_ - gain_scale * turn_rad);
  correction_budget_m_ = std::max(0.0, correction_budget_m_ - gain_scale * shift_m);
}

bool PoseEkf::reanchorAfterGating(std::size_t index, const Observation& observation,
                                  VpUpdateResult* result) {
  DirectionLandmark& landmark = landmarks_[index];
  const auto needed = static_cast<std::size_t>(config_.reanchor_detections);
  if (needed == 0 || !landmark.active || landmark.num_updates < config_.reanchor_min_updates) {
    return false;
  }
  auto& run = landmark.gated_run;
  run.push_back({result->innovation_px, result->innovation_covariance});
  if (run.size() > needed) run.erase(run.begin());
  if (run.size() < needed) return false;
  Eigen::Vector2d mean = Eigen::Vector2d::Zero();
  for (const auto& gated : run) mean += gated.innovation_px;
  mean /= static_cast<double>(needed);
  for (const auto& gated : run) {
    const Eigen::Vector2d spread = gated.innovation_px - mean;
    if (spread.dot(gated.covariance_px2.ldlt().solve(spread)) > config_.gate_chi2) {
      return false;  // the gated detections disagree: bad detections, not a pose jump
    }
  }
  // Widen the pose covariance by the jump, with the shape of an odometry increment's noise (the
  // latest one's): a wrong increment turns the camera and moves it together (a rotation about the
  // scene rather than about the camera), so the translation is corrected along with the rotation.
  // The rotation about the direction itself, unobservable, is left alone.
  Eigen::Vector3d d_camera = T_world_camera_.linear().transpose() * landmark.d_world;
  d_camera.normalize();
  Matrix6d keep_observable = Matrix6d::Identity();
  keep_observable.block<3, 3>(3, 3) -= d_camera * d_camera.transpose();
  Matrix6d shape = keep_observable * last_increment_noise_ * keep_observable.transpose();
  const double focal_px = 0.5 * (intrinsics_.fx + intrinsics_.fy);
  const double sigma_rad = 2.0 * mean.norm() / focal_px;
  const double rotation_variance = 0.5 * shape.block<3, 3>(3, 3).trace();
  if (!(rotation_variance > 1e-18) || !shape.allFinite()) {
    shape.setZero();  // no usable increment noise: widen the rotation alone
    shape.block<3, 3>(3, 3) = keep_observable.block<3, 3>(3, 3);
  } else {
    shape /= rotation_variance;
  }
  const Eigen::MatrixXd P_before = P_;
  P_.topLeftCorner<6, 6>() += sigma_rad * sigma_rad * shape;
  symmetrize(P_);
  VpUpdateResult widened = *result;
  Eigen::MatrixXd H;
  if (!innovation(index, observation, &widened, &H)) {
    P_ = P_before;
    return false;
  }
  *result = widened;
  spreading_correction_ = true;
  acceptUpdate(index, H, observation, result);
  ++counters_.reanchors;
  return true;
}

std::int64_t PoseEkf::clock(DirectionMeasurement kind) const {
  return kind == DirectionMeasurement::kVanishingPoint ? vp_calls_ : counters_.predictions;
}

VpUpdateResult PoseEkf::updateLandmark(int landmark_id, const Eigen::Vector2d& pixel,
                                       const Eigen::Matrix2d& pixel_covariance) {
  VpUpdateResult result;
  result.measured_px = pixel;
  Observation observation;
  observation.pixel = pixel;
  if (!validMeasurement(pixel, pixel_covariance, &observation.R)) {
    ++counters_.bad_measurements;
    result.status = VpUpdateStatus::kBadMeasurement;
    return result;
  }
  const auto it = std::find_if(landmarks_.begin(), landmarks_.end(),
                               [&](const DirectionLandmark& l) { return l.id == landmark_id; });
  if (it == landmarks_.end()) {
    result.status = VpUpdateStatus::kUnknownLandmark;
    return result;
  }
  const auto index = static_cast<std::size_t>(it - landmarks_.begin());
  Eigen::MatrixXd H;
  if (!innovation(index, observation, &result, &H)) {
    result.status = VpUpdateStatus::kNotVisible;
    result.landmark_id = landmark_id;
    return result;
  }
  if (result.nis > config_.gate_chi2) {
    ++counters_.updates_gated;
    result.status = VpUpdateStatus::kGated;
    recordOutcome(index, result.nis);
    return result;
  }
  if (!landmarks_[index].active) {
    const double nis = result.nis;
    refineOnProbation(index, H, observation, &result);
    recordOutcome(index, nis);
    return result;
  }
  const double nis = result.nis;
  acceptUpdate(index, H, observation, &result);
  recordOutcome(index, nis);
  return result;
}

VpUpdateResult PoseEkf::updateVanishingPoint(const Eigen::Vector2d& pixel,
                                             const Eigen::Matrix2d& pixel_covariance) {
  ++vp_calls_;
  Observation observation;
  observation.kind = DirectionMeasurement::kVanishingPoint;
  observation.pixel = pixel;
  if (!validMeasurement(pixel, pixel_covariance, &observation.R)) {
    ++counters_.bad_measurements;
    VpUpdateResult result;
    result.measured_px = pixel;
    result.status = VpUpdateStatus::kBadMeasurement;
    return result;
  }
  return updateObservation(observation);
}

VpUpdateResult PoseEkf::updateDirection(const Eigen::Vector3d& direction_camera,
                                        const Eigen::Matrix2d& covariance) {
  Observation observation;
  observation.kind = DirectionMeasurement::kSurfaceAxis;
  if (!direction_camera.allFinite() || std::abs(direction_camera.norm() - 1.0) > 1e-6 ||
      !isValidCovariance<2>(covariance, true)) {
    ++counters_.bad_measurements;
    VpUpdateResult result;
    result.measurement = DirectionMeasurement::kSurfaceAxis;
    result.status = VpUpdateStatus::kBadMeasurement;
    return result;
  }
  observation.axis_camera = direction_camera.normalized();
  observation.R = 0.5 * (covariance + covariance.transpose());
  return updateObservation(observation);
}

Eigen::Vector3d PoseEkf::worldDirection(const Observation& observation,
                                        Eigen::Matrix<double, 2, 3>* J_rotation,
                                        Eigen::Matrix2d* J_measurement) const {
  return observation.kind == DirectionMeasurement::kVanishingPoint
             ? directionFromPixel(intrinsics_, T_world_camera_.linear(), observation.pixel,
                                  J_rotation, J_measurement)
             : directionFromAxis(T_world_camera_.linear(), observation.axis_camera, J_rotation,
                                 J_measurement);
}

VpUpdateResult PoseEkf::updateObservation(const Observation& observation) {
  VpUpdateResult result;
  result.measurement = observation.kind;
  result.measured_px = observation.kind == DirectionMeasurement::kVanishingPoint
                           ? observation.pixel
                           : Eigen::Vector2d::Zero();
  result.status = VpUpdateStatus::kCandidate;
  const bool axis = observation.kind == DirectionMeasurement::kSurfaceAxis;

  // Association: the visible landmark with the smallest NIS.
  bool have_best = false;
  std::size_t best_index = 0;
  VpUpdateResult best;
  Eigen::MatrixXd best_H;
  for (std::size_t i = 0; i < landmarks_.size(); ++i) {
    VpUpdateResult trial = result;
    Eigen::MatrixXd H;
    if (!innovation(i, observation, &trial, &H)) continue;
    if (!have_best || trial.nis < best.nis) {
      have_best = true;
      best_index = i;
      best = trial;
      best_H = std::move(H);
    }
  }
  const Eigen::Vector3d d_world = worldDirection(observation, nullptr, nullptr);
  const double separation_cos = std::cos(config_.landmark_min_separation_deg * kDegToRad);
  if (have_best) {
    result = best;
    if (best.nis <= config_.gate_chi2) {
      if (landmarks_[best_index].active) {
        acceptUpdate(best_index, best_H, observation, &result);
      } else {
        refineOnProbation(best_index, best_H, observation, &result);
      }
      recordOutcome(best_index, best.nis);
      return result;
    }
    // Only a detection of this landmark's direction tells about its consistency; one far from it
    // is another direction.
    const bool same_direction =
        std::abs(landmarks_[best_index].d_world.dot(d_world)) > separation_cos;
    if (same_direction && !axis && reanchorAfterGating(best_index, observation, &result)) {
      recordOutcome(best_index, result.nis);
      return result;
    }
    ++counters_.updates_gated;
    if (axis) ++counters_.axis_updates_gated;
    result.status = VpUpdateStatus::kGated;
    if (same_direction) recordOutcome(best_index, best.nis);
  }

  // Not explained by any landmark: a candidate for a new one, when it is far from every known
  // axis (a gated detection of a known direction is a bad detection, not a new direction) and
  // from every retired one.
  if (static_cast<int>(landmarks_.size()) >= config_.max_landmarks) return result;
  for (const auto& landmark : landmarks_) {
    if (std::abs(landmark.d_world.dot(d_world)) > separation_cos) return result;
  }
  if (nearRetired(d_world)) return result;
  // Candidates must be seen on consecutive ticks of their own clock.
  candidates_.erase(
      std::remove_if(candidates_.begin(), candidates_.end(),
                     [&](const Candidate& c) { return c.last_tick < clock(c.kind) - 1; }),
      candidates_.end());
  const double same_cos = std::cos(config_.landmark_init_angle_deg * kDegToRad);
  const std::int64_t now = clock(observation.kind);
  Candidate* match = nullptr;
  for (auto& c : candidates_) {
    if (c.kind == observation.kind && c.last_tick < now &&
        std::abs(c.d_world.dot(d_world)) >= same_cos) {
      match = &c;
      break;
    }
  }
  if (match) {
    ++match->count;
    match->d_world = d_world;
    match->last_tick = now;
  } else {
    candidates_.push_back({observation.kind, d_world, 1, now});
    match = &candidates_.back();
  }
  if (match->count >= config_.landmark_init_frames) {
    candidates_.erase(candidates_.begin() + (match - candidates_.data()));
    const int id = addLandmarkUnchecked(observation, config_.landmark_probation == 0);
    result.status = VpUpdateStatus::kNewLandmark;
    result.landmark_id = id;
  }
  return result;
}

int PoseEkf::addLandmark(const Eigen::Vector2d& pixel, const Eigen::Matrix2d& pixel_covariance) {
  Observation observation;
  observation.pixel = pixel;
  if (!validMeasurement(pixel, pixel_covariance, &observation.R)) {
    ++counters_.bad_measurements;
    return -1;
  }
  if (static_cast<int>(landmarks_.size()) >= config_.max_landmarks) return -1;
  return addLandmarkUnchecked(observation, true);
}

int PoseEkf::addLandmarkUnchecked(const Observation& observation, bool active) {
  Eigen::Matrix<double, 2, 3> J_rotation;
  Eigen::Matrix2d J_measurement;
  const Eigen::Vector3d d_world = worldDirection(observation, &J_rotation, &J_measurement);
  const Eigen::Index n = P_.rows();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(2, n);
  J.block<2, 3>(0, 3) = J_rotation;
  const Eigen::MatrixXd P_ln = J * P_;
  Eigen::MatrixXd P_new(n + 2, n + 2);
  P_new.topLeftCorner(n, n) = P_;
  P_new.bottomLeftCorner(2, n) = P_ln;
  P_new.topRightCorner(n, 2) = P_ln.transpose();
  P_new.bottomRightCorner<2, 2>() =
      P_ln * J.transpose() + J_measurement * observation.R * J_measurement.transpose();
  P_ = std::move(P_new);
  symmetrize(P_);
  DirectionLandmark landmark;
  landmark.id = next_landmark_id_++;
  landmark.d_world = d_world;
  landmark.active = active;
  landmark.kind = observation.kind;
  landmarks_.push_back(landmark);
  ++counters_.landmarks_created;
  return landmark.id;
}

bool PoseEkf::recordOutcome(std::size_t index, double nis) {
  DirectionLandmark& landmark = landmarks_[index];
  if (!std::isfinite(nis)) nis = std::numeric_limits<double>::max();
  const auto median = [](std::vector<double> v) {
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
  };
  if (!landmark.active) {
    landmark.recent_nis.push_back(nis);
    if (static_cast<int>(landmark.recent_nis.size()) < config_.landmark_probation) return true;
    if (median(landmark.recent_nis) <= config_.landmark_consistency_chi2) {
      landmark.active = true;
      landmark.recent_nis.clear();
      ++counters_.landmarks_activated;
      return true;
    }
    retireLandmark(index);
    return false;
  }
  const auto window = static_cast<std::size_t>(config_.landmark_window);
  if (landmark.recent_nis.size() < window) {
    landmark.recent_nis.push_back(nis);
    landmark.recent_next = 0;
  } else {
    landmark.recent_nis[landmark.recent_next] = nis;
    landmark.recent_next = (landmark.recent_next + 1) % window;
  }
  if (landmark.recent_nis.size() < window ||
      median(landmark.recent_nis) <= config_.landmark_consistency_chi2) {
    return true;
  }
  retireLandmark(index);
  return false;
}

void PoseEkf::retireLandmark(std::size_t index) {
  // Marginalising a Gaussian = dropping its rows and columns.
  const Eigen::Index n = P_.rows();
  const Eigen::Index k = 6 + 2 * static_cast<Eigen::Index>(index);
  const Eigen::Index tail = n - k - 2;
  Eigen::MatrixXd P_new(n - 2, n - 2);
  P_new.topLeftCorner(k, k) = P_.topLeftCorner(k, k);
  if (tail > 0) {
    P_new.topRightCorner(k, tail) = P_.topRightCorner(k, tail);
    P_new.bottomLeftCorner(tail, k) = P_.bottomLeftCorner(tail, k);
    P_new.bottomRightCorner(tail, tail) = P_.bottomRightCorner(tail, tail);
  }
  P_ = std::move(P_new);
  retired_.push_back({landmarks_[index].d_world, landmarks_[index].kind,
                      clock(landmarks_[index].kind) + config_.landmark_retry_calls});
  landmarks_.erase(landmarks_.begin() + static_cast<std::ptrdiff_t>(index));
  ++counters_.landmarks_retired;
}

bool PoseEkf::nearRetired(const Eigen::Vector3d& d_world) const {
  const double separation_cos = std::cos(config_.landmark_min_separation_deg * kDegToRad);
  return std::any_of(retired_.begin(), retired_.end(), [&](const Retired& r) {
    return r.until_tick > clock(r.kind) && std::abs(r.d_world.dot(d_world)) > separation_cos;
  });
}

// --- corrections -------------------------------------------------------------------------------

void PoseEkf::setPose(const SE3& T_world_camera, const Matrix6d& pose_covariance) {
  T_world_camera_ = normalizedSE3(T_world_camera);
  const Eigen::Index n = P_.rows();
  P_.topLeftCorner<6, 6>() = 0.5 * (pose_covariance + pose_covariance.transpose());
  if (n > 6) {
    P_.topRightCorner(6, n - 6).setZero();
    P_.bottomLeftCorner(n - 6, 6).setZero();
  }
  spreading_correction_ = false;  // a pose set from outside replaces what was being corrected
}

void PoseEkf::applyCorrection(const SE3& T_corrected_world) {
  const Eigen::Matrix3d R_c = T_corrected_world.linear();
  const Eigen::Index n = P_.rows();
  Eigen::MatrixXd G = Eigen::MatrixXd::Identity(n, n);
  G.block<3, 3>(0, 0) = R_c;
  for (std::size_t i = 0; i < landmarks_.size(); ++i) {
    const Eigen::Index k = 6 + 2 * static_cast<Eigen::Index>(i);
    const Eigen::Vector3d d = landmarks_[i].d_world;
    const Eigen::Vector3d d_new = (R_c * d).normalized();
    G.block<2, 2>(k, k) = tangentBasis(d_new).transpose() * R_c * tangentBasis(d);
    landmarks_[i].d_world = d_new;
  }
  for (auto& c : candidates_) c.d_world = R_c * c.d_world;
  for (auto& r : retired_) r.d_world = R_c * r.d_world;
  P_ = G * P_ * G.transpose();
  symmetrize(P_);
  T_world_camera_ = normalizedSE3(T_corrected_world * T_world_camera_);
}

}  // namespace slamd
