#include "slamd/filter/motion_fusion.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>

namespace slamd {

double chiSquareQuantile(int dof, double probability) {
  // Rows: 1-6 degrees of freedom; columns: 0.95, 0.99, 0.999.
  static const double kTable[6][3] = {{3.841, 6.635, 10.828},   {5.991, 9.210, 13.816},
                                      {7.815, 11.345, 16.266},  {9.488, 13.277, 18.467},
                                      {11.070, 15.086, 20.515}, {12.592, 16.812, 22.458}};
  const int row = std::min(std::max(dof, 1), 6) - 1;
  const int column = probability < 0.97 ? 0 : probability < 0.995 ? 1 : 2;
  return kTable[row][column];
}

Matrix6d translationInformation(const Matrix6d& information) {
  const Eigen::Matrix3d tt = information.topLeftCorner<3, 3>();
  const Eigen::Matrix3d tr = information.topRightCorner<3, 3>();
  Eigen::Matrix3d rr = information.bottomRightCorner<3, 3>();
  rr = 0.5 * (rr + rr.transpose());
  // Pseudo-inverse of the rotation block: a rotation direction without information contributes
  // nothing to marginalise.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(rr);
  const double largest = std::max(eigen.eigenvalues().maxCoeff(), 0.0);
  Eigen::Matrix3d rr_pinv = Eigen::Matrix3d::Zero();
  for (int i = 0; i < 3; ++i) {
    const double value = eigen.eigenvalues()(i);
    if (value > 1e-9 * largest && value > 0.0) {
      rr_pinv += eigen.eigenvectors().col(i) * eigen.eigenvectors().col(i).transpose() / value;
    }
  }
  Matrix6d result = Matrix6d::Zero();
  Eigen::Matrix3d marginal = tt - tr * rr_pinv * tr.transpose();
  result.topLeftCorner<3, 3>() = 0.5 * (marginal + marginal.transpose());
  return result;
}

MotionFusionResult fuseMotion(const SE3& T_prev_curr, const Matrix6d& covariance,
                              const SE3& T_prev_curr_measured, const Matrix6d& information_right,
                              double gate_probability) {
  MotionFusionResult result;
  result.T_prev_curr = T_prev_curr;
  result.covariance = covariance;
  if (!covariance.allFinite() || !information_right.allFinite()) return result;

  // The information in odometry_t's convention: n = J xi with J = diag(R, I), so
  // Lambda_n = J^-T Lambda_xi J^-1 = diag(R, I) Lambda_xi diag(R^T, I).
  Matrix6d J = Matrix6d::Identity();
  J.topLeftCorner<3, 3>() = T_prev_curr_measured.linear();
  Matrix6d information = J * information_right * J.transpose();
  information = 0.5 * (information + information.transpose());

  Vector6d error;
  error.head<3>() = T_prev_curr_measured.translation() - T_prev_curr.translation();
  error.tail<3>() = logSO3(T_prev_curr.linear().transpose() * T_prev_curr_measured.linear());

  const Eigen::SelfAdjointEigenSolver<Matrix6d> eigen(information);
  if (eigen.info() != Eigen::Success) return result;
  const double largest = eigen.eigenvalues().maxCoeff();
  if (!(largest > 0.0)) return result;
  // Directions with less than 1e-9 of the best one's information are not measured (the
  // registration already set its degenerate directions to zero; this catches round-off). The
  // eigenvalues come in increasing order, so the measured ones are the last columns.
  int first_measured = 0;
  while (eigen.eigenvalues()(first_measured) <= 1e-9 * largest) ++first_measured;
  result.measured_directions = 6 - first_measured;
  const auto U = eigen.eigenvectors().rightCols(result.measured_directions);
  const Eigen::VectorXd eigenvalues = eigen.eigenvalues().tail(result.measured_directions);
  const Eigen::VectorXd z = U.transpose() * error;
  Eigen::MatrixXd S = U.transpose() * covariance * U;
  S.diagonal() += eigenvalues.cwiseInverse();
  const Eigen::LDLT<Eigen::MatrixXd> S_ldlt(S);
  if (S_ldlt.info() != Eigen::Success) return result;
  result.nis = z.dot(S_ldlt.solve(z));
  result.gate_chi2 = chiSquareQuantile(result.measured_directions, gate_probability);
  if (!std::isfinite(result.nis) || result.nis > result.gate_chi2) return result;

  const Eigen::LDLT<Matrix6d> covariance_ldlt(covariance);
  if (covariance_ldlt.info() != Eigen::Success) return result;
  const Matrix6d prior_information = covariance_ldlt.solve(Matrix6d::Identity());
  Matrix6d fused_information = prior_information + information;
  fused_information = 0.5 * (fused_information + fused_information.transpose());
  const Eigen::LDLT<Matrix6d> fused_ldlt(fused_information);
  if (fused_ldlt.info() != Eigen::Success) return result;
  const Vector6d delta = fused_ldlt.solve(information * error);
  Matrix6d fused_covariance = fused_ldlt.solve(Matrix6d::Identity());
  fused_covariance = 0.5 * (fused_covariance + fused_covariance.transpose());
  if (!delta.allFinite() || !fused_covariance.allFinite()) return result;

  SE3 fused = SE3::Identity();
  fused.linear() = T_prev_curr.linear() * expSO3(delta.tail<3>());
  fused.translation() = T_prev_curr.translation() + delta.head<3>();
  result.T_prev_curr = normalizedSE3(fused);
  result.covariance = fused_covariance;
  result.fused = true;
  return result;
}

}  // namespace slamd
