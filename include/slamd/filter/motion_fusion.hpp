#pragma once
// fuseMotion: combines two estimates of the same frame-to-frame motion, one with a covariance
// (tracking's odometry increment) and one with an information matrix that may be singular (plane
// ICP, whose planes leave the translation along a corridor free), into one increment with its
// covariance for the EKF's prediction (issue 23, item 4: the corridor mode).
//
// Both are T_prev_curr. The result is in odometry_t's convention (translation additive in the
// previous camera frame, rotation right-perturbed in the current one, as PoseEkf::predict takes
// it); the information comes as planes::IcpResult gives it, for the right perturbation
// T_prev_curr * exp(xi), xi = [rho; phi], whose translation part is in the current camera frame,
// so it is rotated first: n_t = R rho, n_phi = phi.
//
// With e the second estimate's error relative to the first (e_t = t_2 - t_1, e_phi =
// log(R_1^T R_2)), Lambda_1 = covariance^-1 and Lambda_2 the rotated information:
//   Lambda = Lambda_1 + Lambda_2,  delta = Lambda^-1 Lambda_2 e,  covariance' = Lambda^-1,
// and the fused increment is the first moved by delta: what the second estimate does not measure
// (the null space of Lambda_2) stays the first estimate's, value and variance.
//
// Gate: e is compared with what both estimates allow only in the directions the second one
// measures (the eigenvectors U of Lambda_2 with non-zero eigenvalues): z = U^T e,
// S = U^T covariance U + diag(1 / eigenvalue), NIS = z^T S^-1 z against chi-square with as many
// degrees of freedom as measured directions at gate_probability. A gated pair leaves the first
// estimate as it was.

#include "slamd/common/se3.hpp"

namespace slamd {

struct MotionFusionResult {
  bool fused = false;  ///< false: gated, or nothing measured, or a covariance not invertible
  SE3 T_prev_curr = SE3::Identity();
  Matrix6d covariance = Matrix6d::Identity();
  int measured_directions = 0;  ///< rank of the second estimate's information
  double nis = 0.0;             ///< of the second estimate against the first
  double gate_chi2 = 0.0;       ///< the NIS allowed for measured_directions
};

/// gate_probability: one of 0.95, 0.99, 0.999 (other values use the nearest of them).
MotionFusionResult fuseMotion(const SE3& T_prev_curr, const Matrix6d& covariance,
                              const SE3& T_prev_curr_measured, const Matrix6d& information_right,
                              double gate_probability = 0.999);

/// The information about the translation alone ([rho; phi] order), the rotation marginalised out
/// (Schur complement; a rotation the information leaves free is dropped too): what a measurement
/// says of the translation whatever the rotation is, for fusing a measurement whose rotation is
/// not to be trusted.
Matrix6d translationInformation(const Matrix6d& information);

/// The chi-square quantile for 1-6 degrees of freedom at 0.95, 0.99 or 0.999 (the nearest).
double chiSquareQuantile(int dof, double probability);

}  // namespace slamd
