#include "slamd/common/se3.hpp"

#include <algorithm>
#include <cmath>

namespace slamd {

namespace {
// Below this angle (radians) the series expansions are used; at 1e-6 rad the next series term is
// ~1e-19 relative, far below double precision.
constexpr double kSmallAngleRad = 1e-6;
}  // namespace

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
  return m;
}

Eigen::Matrix3d expSO3(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  const Eigen::Matrix3d K = skew(phi);
  if (angle < kSmallAngleRad) {
    return Eigen::Matrix3d::Identity() + K + 0.5 * K * K;
  }
  const double a = std::sin(angle) / angle;
  const double b = (1.0 - std::cos(angle)) / (angle * angle);
  return Eigen::Matrix3d::Identity() + a * K + b * K * K;
}

Eigen::Vector3d logSO3(const Eigen::Matrix3d& R) {
  // Eigen's AngleAxis conversion is robust near pi, where the trace formula loses precision.
  const Eigen::AngleAxisd aa(Eigen::Quaterniond(R).normalized());
  double angle = aa.angle();
  Eigen::Vector3d axis = aa.axis();
  if (angle > M_PI) {  // AngleAxis may return (2pi - a, -axis)
    angle = 2.0 * M_PI - angle;
    axis = -axis;
  }
  if (angle < kSmallAngleRad) {
    // vee(R - R^T) / 2 is exact to first order and avoids an undefined axis.
    return 0.5 * Eigen::Vector3d(R(2, 1) - R(1, 2), R(0, 2) - R(2, 0), R(1, 0) - R(0, 1));
  }
  return angle * axis;
}

Eigen::Matrix3d leftJacobianSO3(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  const Eigen::Matrix3d K = skew(phi);
  if (angle < kSmallAngleRad) {
    return Eigen::Matrix3d::Identity() + 0.5 * K + K * K / 6.0;
  }
  const double a2 = angle * angle;
  return Eigen::Matrix3d::Identity() + (1.0 - std::cos(angle)) / a2 * K +
         (angle - std::sin(angle)) / (a2 * angle) * K * K;
}

Eigen::Matrix3d leftJacobianInverseSO3(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  const Eigen::Matrix3d K = skew(phi);
  if (angle < kSmallAngleRad) {
    return Eigen::Matrix3d::Identity() - 0.5 * K + K * K / 12.0;
  }
  const double half = 0.5 * angle;
  const double coeff = (1.0 - half * std::cos(half) / std::sin(half)) / (angle * angle);
  return Eigen::Matrix3d::Identity() - 0.5 * K + coeff * K * K;
}

SE3 expSE3(const Vector6d& xi) {
  const Eigen::Vector3d rho = xi.head<3>();
  const Eigen::Vector3d phi = xi.tail<3>();
  SE3 T = SE3::Identity();
  T.linear() = expSO3(phi);
  T.translation() = leftJacobianSO3(phi) * rho;
  return T;
}

Vector6d logSE3(const SE3& T) {
  const Eigen::Vector3d phi = logSO3(T.linear());
  Vector6d xi;
  xi.head<3>() = leftJacobianInverseSO3(phi) * T.translation();
  xi.tail<3>() = phi;
  return xi;
}

Matrix6d adjointSE3(const SE3& T) {
  Matrix6d ad = Matrix6d::Zero();
  const Eigen::Matrix3d R = T.linear();
  ad.topLeftCorner<3, 3>() = R;
  ad.topRightCorner<3, 3>() = skew(T.translation()) * R;
  ad.bottomRightCorner<3, 3>() = R;
  return ad;
}

SE3 makeSE3(const Eigen::Vector3d& translation_m, const Eigen::Quaterniond& rotation) {
  SE3 T = SE3::Identity();
  T.linear() = rotation.normalized().toRotationMatrix();
  T.translation() = translation_m;
  return T;
}

SE3 normalizedSE3(const SE3& T) {
  SE3 out = T;
  out.linear() = Eigen::Quaterniond(T.linear()).normalized().toRotationMatrix();
  return out;
}

double rotationAngleRad(const Eigen::Matrix3d& R) {
  const double c = std::clamp((R.trace() - 1.0) * 0.5, -1.0, 1.0);
  // acos is ill-conditioned near 0; use the norm of the log there.
  if (c > 0.999) return logSO3(R).norm();
  return std::acos(c);
}

}  // namespace slamd
