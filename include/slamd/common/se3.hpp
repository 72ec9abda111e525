#pragma once
// SE(3) and SO(3) helpers on Eigen.
//
// Conventions used across slamd:
// - T_a_b (Eigen::Isometry3d) maps points from frame b into frame a: p_a = T_a_b * p_b.
// - A tangent vector xi = [rho; phi] orders translation first, then rotation (x y z rx ry rz), the
//   same order as every covariance in slamd's messages.
// - Perturbations are local (right): T = T_est * exp(xi).
// - Quaternions in messages and files are (w, x, y, z) unless a file format says otherwise
//   (TUM files store qx qy qz qw).

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace slamd {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;
using SE3 = Eigen::Isometry3d;

/// Skew-symmetric matrix [v]x such that [v]x * w = v.cross(w).
Eigen::Matrix3d skew(const Eigen::Vector3d& v);

/// Rotation matrix of the axis-angle vector phi (radians), Rodrigues' formula; exact near zero.
Eigen::Matrix3d expSO3(const Eigen::Vector3d& phi);

/// Axis-angle vector (radians, norm in [0, pi]) of a rotation matrix.
Eigen::Vector3d logSO3(const Eigen::Matrix3d& R);

/// Left Jacobian of SO(3) at phi, and its inverse.
Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& phi);
Eigen::Matrix3d leftJacobianInverseSO3(const Eigen::Vector3d& phi);

/// exp of a twist xi = [rho; phi] (rho metres, phi radians): the transform with rotation
/// expSO3(phi) and translation J_l(phi) * rho.
SE3 expSE3(const Vector6d& xi);

/// Inverse of expSE3.
Vector6d logSE3(const SE3& T);

/// Adjoint of T in the [rho; phi] ordering: Ad(T) * xi = log(T * exp(xi) * T^-1).
Matrix6d adjointSE3(const SE3& T);

/// Builds a transform from a translation (metres) and a unit quaternion.
SE3 makeSE3(const Eigen::Vector3d& translation_m, const Eigen::Quaterniond& rotation);

/// Re-orthonormalises the rotation part (after long chains of products).
SE3 normalizedSE3(const SE3& T);

/// Rotation angle of R in radians, in [0, pi].
double rotationAngleRad(const Eigen::Matrix3d& R);

}  // namespace slamd
