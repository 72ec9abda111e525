#include "slamd/filter/pose_ekf.hpp"

#include <cmath>
#include <limits>
#include <random>

#include <Eigen/Dense>
#include <gtest/gtest.h>

namespace slamd {
namespace {

constexpr double kStep = 1e-6;  // central-difference step (radians, metres, tangent units)

SE3 randomPose(std::mt19937& rng, double translation_m, double angle_rad) {
  std::normal_distribution<double> n(0.0, 1.0);
  SE3 T = SE3::Identity();
  T.linear() = expSO3(angle_rad * Eigen::Vector3d(n(rng), n(rng), n(rng)));
  T.translation() = translation_m * Eigen::Vector3d(n(rng), n(rng), n(rng));
  return T;
}

/// Inverse of PoseEkf::retractDirection: the tangent delta with retract(d, delta) parallel to e.
Eigen::Vector2d localDirection(const Eigen::Vector3d& d, const Eigen::Vector3d& e) {
  return PoseEkf::tangentBasis(d).transpose() * e / d.dot(e);
}

TEST(PoseEkf, MotionJacobiansMatchCentralDifferences) {
  std::mt19937 rng(42);
  for (int trial = 0; trial < 5; ++trial) {
    const SE3 T_world_prev = randomPose(rng, 2.0, 1.0);
    const SE3 T_prev_curr = randomPose(rng, 0.3, 0.2);
    Matrix6d F, G;
    PoseEkf::motionJacobians(T_world_prev, T_prev_curr, &F, &G);
    const SE3 nominal = T_world_prev * T_prev_curr;
    Matrix6d F_num, G_num;
    for (int k = 0; k < 6; ++k) {
      Vector6d e = Vector6d::Zero();
      e(k) = kStep;
      F_num.col(k) = (PoseEkf::boxminus(PoseEkf::boxplus(T_world_prev, e) * T_prev_curr, nominal) -
                      PoseEkf::boxminus(PoseEkf::boxplus(T_world_prev, -e) * T_prev_curr, nominal)) /
                     (2 * kStep);
      // Odometry noise in odometry_t's convention: translation additive in the previous frame,
      // rotation right-perturbed: the same boxplus applied to T_prev_curr's own components.
      G_num.col(k) = (PoseEkf::boxminus(T_world_prev * PoseEkf::boxplus(T_prev_curr, e), nominal) -
                      PoseEkf::boxminus(T_world_prev * PoseEkf::boxplus(T_prev_curr, -e), nominal)) /
                     (2 * kStep);
    }
    EXPECT_LT((F - F_num).cwiseAbs().maxCoeff(), 1e-7) << "F\n" << F << "\nnumeric\n" << F_num;
    EXPECT_LT((G - G_num).cwiseAbs().maxCoeff(), 1e-7) << "G\n" << G << "\nnumeric\n" << G_num;
  }
}

TEST(PoseEkf, ProjectionJacobiansMatchCentralDifferences) {
  const CameraIntrinsics K;
  std::mt19937 rng(7);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::Matrix3d R = randomPose(rng, 0.0, 0.3).linear();
    // A direction roughly in front of the camera, and its x-heavy variant (other tangent basis).
    const Eigen::Vector3d d =
        (R * Eigen::Vector3d(trial % 2 ? 0.95 : 0.2, -0.1, 1.0)).normalized();
    Eigen::Vector2d pixel;
    Eigen::Matrix<double, 2, 3> H_rot;
    Eigen::Matrix2d H_dir;
    ASSERT_TRUE(PoseEkf::projectDirection(K, R, d, &pixel, &H_rot, &H_dir));
    const auto h = [&](const Eigen::Matrix3d& Rx, const Eigen::Vector3d& dx) {
      Eigen::Vector2d p;
      EXPECT_TRUE(PoseEkf::projectDirection(K, Rx, dx, &p, nullptr, nullptr));
      return p;
    };
    Eigen::Matrix<double, 2, 3> H_rot_num;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e = kStep * Eigen::Vector3d::Unit(k);
      H_rot_num.col(k) = (h(R * expSO3(e), d) - h(R * expSO3(-e), d)) / (2 * kStep);
    }
    Eigen::Matrix2d H_dir_num;
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector2d e = kStep * Eigen::Vector2d::Unit(k);
      H_dir_num.col(k) = (h(R, PoseEkf::retractDirection(d, e)) -
                          h(R, PoseEkf::retractDirection(d, -e))) / (2 * kStep);
    }
    EXPECT_LT((H_rot - H_rot_num).cwiseAbs().maxCoeff(), 1e-4 * H_rot.cwiseAbs().maxCoeff());
    EXPECT_LT((H_dir - H_dir_num).cwiseAbs().maxCoeff(), 1e-4 * H_dir.cwiseAbs().maxCoeff());
    // A point at infinity: translation never matters.
    EXPECT_LT((pixel - K.project(R.transpose() * d)).norm(), 1e-9);
  }
}

TEST(PoseEkf, DirectionFromPixelJacobiansMatchCentralDifferences) {
  const CameraIntrinsics K;
  std::mt19937 rng(11);
  for (int trial = 0; trial < 10; ++trial) {
    const Eigen::Matrix3d R = randomPose(rng, 0.0, 1.0).linear();
    const Eigen::Vector2d pixel(100.0 + 40.0 * trial, 60.0 + 30.0 * trial);
    Eigen::Matrix<double, 2, 3> J_rot;
    Eigen::Matrix2d J_px;
    const Eigen::Vector3d d = PoseEkf::directionFromPixel(K, R, pixel, &J_rot, &J_px);
    // Round trip: the direction projects back to the pixel.
    Eigen::Vector2d back;
    ASSERT_TRUE(PoseEkf::projectDirection(K, R, d, &back, nullptr, nullptr));
    EXPECT_LT((back - pixel).norm(), 1e-9);
    const auto g = [&](const Eigen::Matrix3d& Rx, const Eigen::Vector2d& px) {
      return localDirection(d, PoseEkf::directionFromPixel(K, Rx, px, nullptr, nullptr));
    };
    Eigen::Matrix<double, 2, 3> J_rot_num;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d e = kStep * Eigen::Vector3d::Unit(k);
      J_rot_num.col(k) = (g(R * expSO3(e), pixel) - g(R * expSO3(-e), pixel)) / (2 * kStep);
    }
    Eigen::Matrix2d J_px_num;
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector2d e = 1e-3 * Eigen::Vector2d::Unit(k);
      J_px_num.col(k) = (g(R, pixel + e) - g(R, pixel - e)) / 2e-3;
    }
    EXPECT_LT((J_rot - J_rot_num).cwiseAbs().maxCoeff(), 1e-7);
    EXPECT_LT((J_px - J_px_num).cwiseAbs().maxCoeff(), 1e-9);
  }
}

/// A filter with one landmark on the optical axis of a camera that has moved a little.
struct OneLandmarkFixture {
  CameraIntrinsics K;
  FilterConfig config;
  PoseEkf ekf{config, K};
  int id = -1;
  OneLandmarkFixture() {
    id = ekf.addLandmark(Eigen::Vector2d(K.cx, K.cy), Eigen::Matrix2d::Identity());
    Matrix6d Q = Matrix6d::Zero();
    Q.diagonal() << 1e-4, 1e-4, 1e-4, 1e-4, 1e-4, 1e-4;
    SE3 step = SE3::Identity();
    step.translation() = Eigen::Vector3d(0, 0, 0.1);
    for (int i = 0; i < 5; ++i) EXPECT_EQ(ekf.predict(step, Q, 1.0 / 30), EkfPredictStatus::kOk);
  }
};

TEST(PoseEkf, AcceptsAConsistentVanishingPointAndShrinksRotationUncertainty) {
  OneLandmarkFixture f;
  ASSERT_EQ(f.id, 0);
  const Matrix6d before = f.ekf.poseCovariance();
  const VpUpdateResult r =
      f.ekf.updateVanishingPoint(Eigen::Vector2d(f.K.cx + 1.0, f.K.cy - 0.5),
                                 Eigen::Matrix2d::Identity());
  EXPECT_EQ(r.status, VpUpdateStatus::kAccepted);
  EXPECT_TRUE(r.accepted);
  EXPECT_EQ(r.landmark_id, f.id);
  EXPECT_LT(r.nis, 5.99);
  const Matrix6d after = f.ekf.poseCovariance();
  // Yaw (ry) and pitch (rx) are observed; roll (rz) about the direction is not.
  EXPECT_LT(after(3, 3), 0.5 * before(3, 3));
  EXPECT_LT(after(4, 4), 0.5 * before(4, 4));
  EXPECT_NEAR(after(5, 5), before(5, 5), 1e-3 * before(5, 5));
  // Covariance stays symmetric positive definite (Joseph form).
  const Eigen::MatrixXd& P = f.ekf.covariance();
  EXPECT_LT((P - P.transpose()).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(P).eigenvalues()(0), 0.0);
  EXPECT_EQ(f.ekf.counters().updates_accepted, 1);
}

TEST(PoseEkf, RejectsAWrongVanishingPointByGating) {
  OneLandmarkFixture f;
  const SE3 pose_before = f.ekf.T_world_camera();
  const Eigen::MatrixXd P_before = f.ekf.covariance();
  // 60 pixels off with a 1-pixel measurement: far outside the 5.99 gate.
  const VpUpdateResult r = f.ekf.updateVanishingPoint(Eigen::Vector2d(f.K.cx + 60.0, f.K.cy + 5.0),
                                                      Eigen::Matrix2d::Identity());
  EXPECT_EQ(r.status, VpUpdateStatus::kGated);
  EXPECT_FALSE(r.accepted);
  EXPECT_EQ(r.landmark_id, f.id);
  EXPECT_GT(r.nis, 5.99);
  EXPECT_TRUE(f.ekf.T_world_camera().isApprox(pose_before, 1e-15));
  EXPECT_TRUE(f.ekf.covariance().isApprox(P_before, 1e-15));
  EXPECT_EQ(f.ekf.counters().updates_gated, 1);
  // Close to the landmark's axis (within 20 degrees): never a new landmark however often seen.
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(f.ekf.updateVanishingPoint(Eigen::Vector2d(f.K.cx + 60.0, f.K.cy + 5.0),
                                         Eigen::Matrix2d::Identity())
                  .status,
              VpUpdateStatus::kGated);
  }
  EXPECT_EQ(f.ekf.landmarks().size(), 1u);
  // The same with the known-association entry point.
  EXPECT_EQ(f.ekf.updateLandmark(f.id, Eigen::Vector2d(f.K.cx - 50.0, f.K.cy),
                                 Eigen::Matrix2d::Identity())
                .status,
            VpUpdateStatus::kGated);
  EXPECT_EQ(f.ekf.updateLandmark(99, Eigen::Vector2d(f.K.cx, f.K.cy), Eigen::Matrix2d::Identity())
                .status,
            VpUpdateStatus::kUnknownLandmark);
}

TEST(PoseEkf, CreatesALandmarkOnlyFromConsistentDetections) {
  const CameraIntrinsics K;
  FilterConfig config;
  config.landmark_init_frames = 3;
  config.landmark_probation = 0;  // tested below
  PoseEkf ekf(config, K);
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  // Inconsistent detections (jumping by ~10 degrees) never confirm.
  for (int i = 0; i < 6; ++i) {
    const auto r = ekf.updateVanishingPoint(Eigen::Vector2d(200.0 + 100.0 * (i % 2), 240.0), R);
    EXPECT_EQ(r.status, VpUpdateStatus::kCandidate);
  }
  EXPECT_TRUE(ekf.landmarks().empty());
  // Three consistent ones do.
  EXPECT_EQ(ekf.updateVanishingPoint(Eigen::Vector2d(330.0, 230.0), R).status,
            VpUpdateStatus::kCandidate);
  EXPECT_EQ(ekf.updateVanishingPoint(Eigen::Vector2d(330.5, 230.2), R).status,
            VpUpdateStatus::kCandidate);
  const auto created = ekf.updateVanishingPoint(Eigen::Vector2d(329.8, 229.9), R);
  EXPECT_EQ(created.status, VpUpdateStatus::kNewLandmark);
  ASSERT_EQ(ekf.landmarks().size(), 1u);
  EXPECT_EQ(created.landmark_id, ekf.landmarks()[0].id);
  EXPECT_EQ(ekf.covariance().rows(), 8);
  // The next one is associated with it.
  EXPECT_EQ(ekf.updateVanishingPoint(Eigen::Vector2d(330.0, 230.0), R).status,
            VpUpdateStatus::kAccepted);
}

TEST(PoseEkf, NewLandmarkUpdatesThePoseOnlyAfterAConsistentProbation) {
  const CameraIntrinsics K;
  FilterConfig config;
  config.landmark_init_frames = 3;
  config.landmark_probation = 5;
  PoseEkf ekf(config, K);
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  for (int i = 0; i < 3; ++i) ekf.updateVanishingPoint(Eigen::Vector2d(330.0, 230.0), R);
  ASSERT_EQ(ekf.landmarks().size(), 1u);
  EXPECT_FALSE(ekf.landmarks()[0].active);
  const SE3 before = ekf.T_world_camera();
  for (int i = 0; i < 5; ++i) {
    const auto r = ekf.updateVanishingPoint(Eigen::Vector2d(330.2, 230.1), R);
    EXPECT_EQ(r.status, VpUpdateStatus::kProbation);
    EXPECT_FALSE(r.accepted);
  }
  EXPECT_TRUE(ekf.T_world_camera().isApprox(before));  // probation changes nothing
  ASSERT_EQ(ekf.landmarks().size(), 1u);
  EXPECT_TRUE(ekf.landmarks()[0].active);
  EXPECT_EQ(ekf.counters().landmarks_activated, 1);
  EXPECT_EQ(ekf.updateVanishingPoint(Eigen::Vector2d(330.2, 230.1), R).status,
            VpUpdateStatus::kAccepted);
}

TEST(PoseEkf, LandmarkWhoseDetectionsScatterIsRetiredWithoutTouchingThePose) {
  // A desk-like direction: confirmed by three close detections, then seen 5-10 pixels (about a
  // degree) off each time although each claims 1 pixel.
  const CameraIntrinsics K;
  FilterConfig config;
  config.landmark_init_frames = 3;
  config.landmark_probation = 10;
  PoseEkf ekf(config, K);
  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  for (int i = 0; i < 3; ++i) ekf.updateVanishingPoint(Eigen::Vector2d(400.0, 300.0), R);
  ASSERT_EQ(ekf.landmarks().size(), 1u);
  const SE3 before = ekf.T_world_camera();
  for (int i = 0; i < 10; ++i) {
    const double sign = i % 2 == 0 ? 1.0 : -1.0;
    ekf.updateVanishingPoint(Eigen::Vector2d(400.0 + sign * (5.0 + i % 3), 300.0 - sign * 4.0), R);
  }
  EXPECT_TRUE(ekf.landmarks().empty());
  EXPECT_EQ(ekf.counters().landmarks_retired, 1);
  EXPECT_EQ(ekf.counters().updates_accepted, 0);
  EXPECT_EQ(ekf.covariance().rows(), 6);  // marginalised
  EXPECT_TRUE(ekf.T_world_camera().isApprox(before));
  // Its direction does not come straight back.
  for (int i = 0; i < 5; ++i) ekf.updateVanishingPoint(Eigen::Vector2d(400.0, 300.0), R);
  EXPECT_TRUE(ekf.landmarks().empty());
}

TEST(PoseEkf, BadInputIsRejectedWithStatusAndCounted) {
  OneLandmarkFixture f;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const SE3 pose_before = f.ekf.T_world_camera();
  Matrix6d Q = Matrix6d::Identity() * 1e-4;

  SE3 bad_motion = SE3::Identity();
  bad_motion.translation().x() = nan;
  EXPECT_EQ(f.ekf.predict(bad_motion, Q, 0.03), EkfPredictStatus::kRejected);
  SE3 not_rigid = SE3::Identity();
  not_rigid.linear() *= 2.0;
  EXPECT_EQ(f.ekf.predict(not_rigid, Q, 0.03), EkfPredictStatus::kRejected);
  EXPECT_TRUE(f.ekf.T_world_camera().isApprox(pose_before));
  EXPECT_EQ(f.ekf.counters().predictions_rejected, 2);

  Matrix6d nan_cov = Q;
  nan_cov(2, 2) = nan;
  EXPECT_EQ(f.ekf.predict(SE3::Identity(), nan_cov, 0.03), EkfPredictStatus::kFallbackCovariance);
  Matrix6d negative = Q;
  negative(0, 0) = -1.0;
  EXPECT_EQ(f.ekf.predict(SE3::Identity(), negative, 0.03), EkfPredictStatus::kFallbackCovariance);
  EXPECT_EQ(f.ekf.counters().fallback_covariances, 2);
  EXPECT_EQ(f.ekf.predict(SE3::Identity(), Q, nan), EkfPredictStatus::kOk);
  EXPECT_EQ(f.ekf.counters().bad_dt, 1);
  EXPECT_TRUE(f.ekf.covariance().allFinite());

  const Eigen::Matrix2d R = Eigen::Matrix2d::Identity();
  Eigen::Matrix2d not_pd;
  not_pd << 1.0, 2.0, 2.0, 1.0;
  const Eigen::Vector2d centre(f.K.cx, f.K.cy);
  EXPECT_EQ(f.ekf.updateVanishingPoint(Eigen::Vector2d(nan, 3.0), R).status,
            VpUpdateStatus::kBadMeasurement);
  EXPECT_EQ(f.ekf.updateVanishingPoint(Eigen::Vector2d(inf, 3.0), R).status,
            VpUpdateStatus::kBadMeasurement);
  EXPECT_EQ(f.ekf.updateVanishingPoint(Eigen::Vector2d(1e5, 240.0), R).status,
            VpUpdateStatus::kBadMeasurement);  // far outside the image
  EXPECT_EQ(f.ekf.updateVanishingPoint(centre, not_pd).status, VpUpdateStatus::kBadMeasurement);
  EXPECT_EQ(f.ekf.updateVanishingPoint(centre, R * nan).status, VpUpdateStatus::kBadMeasurement);
  EXPECT_EQ(f.ekf.updateVanishingPoint(centre, Eigen::Matrix2d::Zero()).status,
            VpUpdateStatus::kBadMeasurement);
  EXPECT_EQ(f.ekf.counters().bad_measurements, 6);
  EXPECT_EQ(f.ekf.addLandmark(Eigen::Vector2d(nan, nan), R), -1);
  EXPECT_TRUE(f.ekf.covariance().allFinite());
}

TEST(PoseEkf, CorrectionMovesPoseAndLandmarksTogether) {
  OneLandmarkFixture f;
  Eigen::Vector2d before;
  ASSERT_TRUE(PoseEkf::projectDirection(f.K, f.ekf.T_world_camera().linear(),
                                        f.ekf.landmarks()[0].d_world, &before, nullptr, nullptr));
  const Matrix6d camera_rotation_cov = f.ekf.poseCovariance();
  SE3 correction = SE3::Identity();
  correction.linear() = expSO3(Eigen::Vector3d(0.1, -0.4, 0.2));
  correction.translation() = Eigen::Vector3d(1.0, 2.0, -0.5);
  const SE3 expected = correction * f.ekf.T_world_camera();
  f.ekf.applyCorrection(correction);
  EXPECT_TRUE(f.ekf.T_world_camera().isApprox(expected, 1e-12));
  Eigen::Vector2d after;
  ASSERT_TRUE(PoseEkf::projectDirection(f.K, f.ekf.T_world_camera().linear(),
                                        f.ekf.landmarks()[0].d_world, &after, nullptr, nullptr));
  EXPECT_LT((after - before).norm(), 1e-9);
  // The camera-frame rotation uncertainty does not change; the world-frame translation rotates.
  const Matrix6d cov = f.ekf.poseCovariance();
  const Eigen::Matrix3d rotation_block = cov.bottomRightCorner(3, 3);
  EXPECT_TRUE(rotation_block.isApprox(camera_rotation_cov.bottomRightCorner(3, 3)));
  const double translation_trace = cov.topLeftCorner(3, 3).trace();
  EXPECT_NEAR(translation_trace, camera_rotation_cov.topLeftCorner(3, 3).trace(), 1e-12);
  // A subsequent measurement gives the same NIS as before the correction would have.
  EXPECT_EQ(f.ekf.updateVanishingPoint(before, Eigen::Matrix2d::Identity()).status,
            VpUpdateStatus::kAccepted);

  Matrix6d new_cov = Matrix6d::Identity() * 1e-6;
  f.ekf.setPose(SE3::Identity(), new_cov);
  EXPECT_TRUE(f.ekf.T_world_camera().isApprox(SE3::Identity()));
  EXPECT_TRUE(f.ekf.poseCovariance().isApprox(new_cov));
  EXPECT_TRUE(f.ekf.covariance().topRightCorner(6, 2).isZero());
}

}  // namespace
}  // namespace slamd
