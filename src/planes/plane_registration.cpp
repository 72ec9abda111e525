#include "slamd/planes/plane_registration.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <utility>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>

namespace slamd::planes {

namespace {

constexpr double kPi = 3.14159265358979323846;

/// Normal equations of the weighted least squares, sum of w r^2 over residuals r = J xi + r0.
struct NormalEquations {
  Matrix6d H = Matrix6d::Zero();
  Vector6d g = Vector6d::Zero();
  double squared_distance_sum_m2 = 0.0;  ///< of point-to-plane distances (unweighted)
  int correspondences = 0;

  void add(const Eigen::Matrix<double, 1, 6>& J, double r, double w) {
    H.noalias() += w * J.transpose() * J;
    g.noalias() += w * J.transpose() * r;
  }
  void addPoint(const Eigen::Matrix<double, 1, 6>& J, double r, double w) {
    add(J, r, w);
    squared_distance_sum_m2 += r * r;
    ++correspondences;
  }
};

/// d(n_target . (T exp(xi) p) + c)/dxi at xi = 0, with m = R^T n_target (the target normal in the
/// source frame).
Eigen::Matrix<double, 1, 6> pointToPlaneJacobian(const Eigen::Vector3d& p_source,
                                                 const Eigen::Vector3d& m) {
  Eigen::Matrix<double, 1, 6> J;
  J.head<3>() = m.transpose();
  J.tail<3>() = p_source.cross(m).transpose();
  return J;
}

/// Scaling of the tangent space that makes rotations comparable with translations: a rotation
/// of phi radians counts as the phi * depth metres it moves a point at the mean depth.
Matrix6d tangentScale(double mean_depth_m) {
  Vector6d s;
  s << 1.0, 1.0, 1.0, Vector6d::Constant(1.0 / std::max(mean_depth_m, 1e-3)).tail<3>();
  return s.asDiagonal();
}

/// The information matrix in the scaled tangent space, eigen-decomposed, with the smallest
/// eigenvalue an observable direction needs (IcpParams::degenerate_sigma_m, degenerate_ratio).
struct ScaledInformation {
  Matrix6d S;
  Eigen::SelfAdjointEigenSolver<Matrix6d> eigen;
  double min_information = 0.0;

  ScaledInformation(const Matrix6d& H, double mean_depth_m, const IcpParams& params)
      : S(tangentScale(mean_depth_m)), eigen(S * H * S) {
    const double largest = eigen.eigenvalues()(5);
    min_information = std::max(1.0 / (params.degenerate_sigma_m * params.degenerate_sigma_m),
                               largest / (params.degenerate_ratio * params.degenerate_ratio));
  }
  bool observable(int i) const { return eigen.eigenvalues()(i) >= min_information; }
};

/// The Gauss-Newton step in the observable directions only (none along a degenerate one).
Vector6d observableStep(const NormalEquations& equations, double mean_depth_m,
                        const IcpParams& params) {
  const ScaledInformation information(equations.H, mean_depth_m, params);
  const Vector6d g_scaled = information.S * equations.g;
  Vector6d step_scaled = Vector6d::Zero();
  for (int i = 0; i < 6; ++i) {
    if (!information.observable(i)) continue;
    const Vector6d v = information.eigen.eigenvectors().col(i);
    step_scaled -= v * (v.dot(g_scaled) / information.eigen.eigenvalues()(i));
  }
  return information.S * step_scaled;
}

/// Sets information, degenerate_directions and covariance from the final normal equations.
void describeUncertainty(const NormalEquations& equations, const IcpParams& params,
                         IcpResult& result) {
  result.information = equations.H;
  const ScaledInformation information(equations.H, result.mean_depth_m, params);
  result.degenerate_directions.clear();
  for (int i = 0; i < 6; ++i) {
    if (information.observable(i)) continue;
    result.degenerate_directions.push_back(
        (information.S * information.eigen.eigenvectors().col(i)).normalized());
  }
  if (result.degenerate_directions.empty()) {
    result.covariance = equations.H.inverse();
  } else {
    result.covariance.reset();
  }
}

std::string poseError(const SE3& T) {
  if (!T.matrix().allFinite()) return "the guess is not finite";
  const Eigen::Matrix3d R = T.linear();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-6 || R.determinant() < 0.0) {
    return "the guess's rotation is not orthonormal";
  }
  return {};
}

/// Gauss-Newton from `guess`: `associate(T, gate_m, equations)` fills the normal equations of
/// the associations at estimate T. Returns the result with everything but source_points set.
template <typename Associate>
IcpResult solve(const SE3& guess, double mean_depth_m, const IcpParams& params,
                Associate&& associate) {
  IcpResult result;
  result.mean_depth_m = mean_depth_m;
  SE3 T = guess;
  double gate_m = params.max_distance_m;
  for (int iteration = 0; iteration < params.max_iterations; ++iteration) {
    gate_m = std::max(params.min_distance_m, params.max_distance_m * std::pow(0.5, iteration));
    NormalEquations equations;
    associate(T, gate_m, equations);
    result.iterations = iteration + 1;
    if (equations.correspondences < params.min_correspondences) break;
    const Vector6d step = observableStep(equations, mean_depth_m, params);
    T = T * expSE3(step);
    T.linear() = normalizedSE3(T).linear();
    if (step.head<3>().norm() < params.converged_translation_m &&
        step.tail<3>().norm() < params.converged_rotation_rad && gate_m <= params.min_distance_m) {
      break;
    }
  }
  // The uncertainty and the statistics of the final estimate.
  NormalEquations equations;
  associate(T, gate_m, equations);
  result.T_target_source = T;
  result.correspondences = equations.correspondences;
  result.rms_m = equations.correspondences > 0
                     ? std::sqrt(equations.squared_distance_sum_m2 / equations.correspondences)
                     : 0.0;
  if (equations.correspondences < params.min_correspondences) {
    std::ostringstream out;
    out << "only " << equations.correspondences << " correspondences (need "
        << params.min_correspondences << ")";
    result.error = out.str();
    return result;
  }
  describeUncertainty(equations, params, result);
  result.ok = true;
  return result;
}

/// Pixel (column, row) nearest to the projection of p (target camera frame); false off the image
/// or behind the camera.
bool pixelOf(const CameraIntrinsics& intrinsics, const Eigen::Vector3d& p, int& u, int& v) {
  if (!(p.z() > 1e-6)) return false;
  const Eigen::Vector2d uv = intrinsics.project(p);
  if (!(uv.x() > -0.5 && uv.y() > -0.5 && uv.x() < intrinsics.width - 0.5 &&
        uv.y() < intrinsics.height - 0.5)) {
    return false;
  }
  u = static_cast<int>(std::lround(uv.x()));
  v = static_cast<int>(std::lround(uv.y()));
  return true;
}

/// Back-projected points and normals (from each pixel's neighbours, towards the camera) of a
/// depth image; NaN where the depth, a neighbour's or the surface's continuity is missing.
/// Not the normals dense alignment uses (tracking/dense_alignment.cpp, from a 5x5 depth average):
/// those keep creases, where a wall meets the floor, and there their tilt gives whole-cloud ICP
/// information along a plain corridor that it does not have (tried: the corridor test then finds
/// no free direction). Dense alignment finds its free directions from the normals' scatter
/// instead.
struct PointsAndNormals {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector3d> normals;
};

PointsAndNormals pointsAndNormals(const cv::Mat& depth_m, const CameraIntrinsics& intrinsics,
                                  const IcpParams& params) {
  const int width = depth_m.cols;
  const int height = depth_m.rows;
  const Eigen::Vector3d none = Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN());
  PointsAndNormals out;
  out.points.assign(static_cast<std::size_t>(width) * height, none);
  out.normals.assign(out.points.size(), none);
  for (int v = 0; v < height; ++v) {
    const float* row = depth_m.ptr<float>(v);
    for (int u = 0; u < width; ++u) {
      const double z = row[u];
      if (!(z > params.min_depth_m && z <= params.max_depth_m)) continue;
      out.points[static_cast<std::size_t>(v) * width + u] = intrinsics.backProject(u, v, z);
    }
  }
  // Normals from the neighbours kNormalSpanPx pixels away on either side: one pixel apart,
  // depth quantisation steps (centimetres at 3-4 m) would tilt them at random.
  constexpr int kNormalSpanPx = 2;
  const int step = kNormalSpanPx;
  for (int v = step; v + step < height; ++v) {
    for (int u = step; u + step < width; ++u) {
      const std::size_t i = static_cast<std::size_t>(v) * width + u;
      const Eigen::Vector3d& p = out.points[i];
      const Eigen::Vector3d& left = out.points[i - step];
      const Eigen::Vector3d& right = out.points[i + step];
      const Eigen::Vector3d& up = out.points[i - static_cast<std::size_t>(step) * width];
      const Eigen::Vector3d& down = out.points[i + static_cast<std::size_t>(step) * width];
      if (!p.allFinite() || !left.allFinite() || !right.allFinite() || !up.allFinite() ||
          !down.allFinite()) {
        continue;
      }
      Eigen::Vector3d n = (right - left).cross(down - up);
      const double length = n.norm();
      if (!(length > 0.0)) continue;
      n /= length;
      if (n.dot(p) > 0.0) n = -n;
      // Only where the neighbours and the pixel lie on one plane (within the depth noise along
      // the ray): at a crease or an occluding edge the cross product is no surface's normal.
      const double tolerance_m = 3.0 * kinectSigmaZ(p.z()) + 0.002 * p.z();
      bool planar = true;
      for (const Eigen::Vector3d* neighbour : {&left, &right, &up, &down}) {
        planar = planar && std::abs(n.dot(*neighbour - p)) <= tolerance_m;
      }
      if (planar) out.normals[i] = n;
    }
  }
  return out;
}

std::string frameError(const cv::Mat& depth_m, const CameraIntrinsics& intrinsics,
                       const char* name) {
  if (depth_m.empty() || depth_m.type() != CV_32FC1) {
    return std::string(name) + " depth is empty or not CV_32FC1";
  }
  if (depth_m.cols != intrinsics.width || depth_m.rows != intrinsics.height) {
    return std::string(name) + " depth size differs from the intrinsics";
  }
  return {};
}

IcpResult failure(std::string error) {
  IcpResult result;
  result.error = std::move(error);
  return result;
}

}  // namespace

std::string IcpParams::validationError() const {
  std::ostringstream out;
  if (max_iterations < 1) {
    out << "max_iterations = " << max_iterations << ": need >= 1";
  } else if (!(min_distance_m > 0.0 && max_distance_m >= min_distance_m)) {
    out << "min_distance_m = " << min_distance_m << ", max_distance_m = " << max_distance_m
        << ": need 0 < min_distance_m <= max_distance_m";
  } else if (!(max_normal_angle_deg > 0.0 && max_normal_angle_deg <= 180.0)) {
    out << "max_normal_angle_deg = " << max_normal_angle_deg << ": need (0, 180]";
  } else if (!(converged_translation_m >= 0.0 && converged_rotation_rad >= 0.0)) {
    out << "convergence thresholds must be >= 0";
  } else if (!(degenerate_sigma_m > 0.0)) {
    out << "degenerate_sigma_m = " << degenerate_sigma_m << ": need > 0";
  } else if (!(degenerate_ratio > 1.0)) {
    out << "degenerate_ratio = " << degenerate_ratio << ": need > 1";
  } else if (min_correspondences < 6) {
    out << "min_correspondences = " << min_correspondences << ": need >= 6";
  } else if (points_per_plane < 1) {
    out << "points_per_plane = " << points_per_plane << ": need >= 1";
  } else if (cloud_stride_px < 1) {
    out << "cloud_stride_px = " << cloud_stride_px << ": need >= 1";
  } else if (!(min_depth_m >= 0.0 && max_depth_m > min_depth_m)) {
    out << "min_depth_m = " << min_depth_m << ", max_depth_m = " << max_depth_m
        << ": need 0 <= min_depth_m < max_depth_m";
  }
  return out.str();
}

Matrix6d observableProjector(const IcpResult& result) {
  if (result.degenerate_directions.empty()) return Matrix6d::Identity();
  Eigen::Matrix<double, 6, Eigen::Dynamic> free(
      6, static_cast<Eigen::Index>(result.degenerate_directions.size()));
  for (std::size_t i = 0; i < result.degenerate_directions.size(); ++i) {
    free.col(static_cast<Eigen::Index>(i)) = result.degenerate_directions[i];
  }
  // An orthonormal basis of the free directions (they are orthogonal only in the scaled space).
  const Eigen::HouseholderQR<Eigen::Matrix<double, 6, Eigen::Dynamic>> qr(free);
  const Eigen::MatrixXd basis = qr.householderQ() * Eigen::MatrixXd::Identity(6, free.cols());
  return Matrix6d::Identity() - basis * basis.transpose();
}

IcpResult registerPlanes(const PlaneSegmentation& source, const PlaneSegmentation& target,
                         const CameraIntrinsics& intrinsics, const SE3& T_target_source_guess,
                         const IcpParams& params) {
  if (std::string error = params.validationError(); !error.empty()) return failure(error);
  if (std::string error = poseError(T_target_source_guess); !error.empty()) return failure(error);
  if (target.labels.type() != CV_32SC1 || target.labels.cols != intrinsics.width ||
      target.labels.rows != intrinsics.height) {
    return failure("the target's labels are not CV_32S of the intrinsics' size");
  }
  if (source.planes.empty() || target.planes.empty()) {
    return failure("no planes in the source or the target frame");
  }

  // Paper 000: a fixed number of points on each source plane.
  struct Sample {
    Eigen::Vector3d p;
    int plane;
  };
  std::vector<Sample> samples;
  samples.reserve(source.planes.size() * static_cast<std::size_t>(params.points_per_plane));
  double depth_sum_m = 0.0;
  for (std::size_t i = 0; i < source.planes.size(); ++i) {
    for (const Eigen::Vector3d& p : samplePlanePoints(source.planes[i], params.points_per_plane,
                                                      intrinsics, params.seed + i)) {
      samples.push_back({p, static_cast<int>(i)});
      depth_sum_m += p.z();
    }
  }
  if (samples.empty()) return failure("no points on the source planes");
  const double mean_depth_m = depth_sum_m / static_cast<double>(samples.size());
  const double min_normal_dot = std::cos(params.max_normal_angle_deg * kPi / 180.0);
  int plane_matches = 0;

  const auto associate = [&](const SE3& T, double gate_m, NormalEquations& equations) {
    const Eigen::Matrix3d R = T.linear();
    // Hits of each source plane's points on each target plane, for plane matching.
    std::map<std::pair<int, int>, int> hits;
    std::vector<int> plane_hits(source.planes.size(), 0);
    for (const Sample& sample : samples) {
      const Eigen::Vector3d q = T * sample.p;
      int u = 0;
      int v = 0;
      if (!pixelOf(intrinsics, q, u, v)) continue;
      const int label = target.labels.at<int>(v, u);
      if (label < 0 || label >= static_cast<int>(target.planes.size())) continue;
      const Plane& target_plane = target.planes[static_cast<std::size_t>(label)];
      const Eigen::Vector3d& n = target_plane.normal_camera;
      if ((R * source.planes[static_cast<std::size_t>(sample.plane)].normal_camera).dot(n) <
          min_normal_dot) {
        continue;
      }
      const double r = n.dot(q) + target_plane.offset_m;
      if (std::abs(r) > gate_m) continue;
      const double sigma_m = kinectSigmaZ(q.z());
      equations.addPoint(pointToPlaneJacobian(sample.p, R.transpose() * n), r,
                         1.0 / (sigma_m * sigma_m));
      ++hits[{sample.plane, label}];
      ++plane_hits[static_cast<std::size_t>(sample.plane)];
    }
    plane_matches = 0;
    if (!params.plane_to_plane) return;
    // A source plane matches the target plane most of its associated points landed on.
    std::vector<std::pair<int, int>> best(source.planes.size(), {-1, 0});
    for (const auto& [pair, count] : hits) {
      auto& entry = best[static_cast<std::size_t>(pair.first)];
      if (count > entry.second) entry = {pair.second, count};
    }
    for (std::size_t i = 0; i < source.planes.size(); ++i) {
      const int j = best[i].first;
      if (j < 0 || 2 * best[i].second < plane_hits[i] || best[i].second < 10) continue;
      const Plane& s = source.planes[i];
      const Plane& t = target.planes[static_cast<std::size_t>(j)];
      const Eigen::Vector3d& n = t.normal_camera;
      // The source centroid on the target plane.
      const double r_offset = n.dot(T * s.centroid_camera) + t.offset_m;
      if (std::abs(r_offset) > gate_m) continue;
      const double offset_variance = std::max(s.covariance(3, 3) + t.covariance(3, 3), 1e-10);
      equations.add(pointToPlaneJacobian(s.centroid_camera, R.transpose() * n), r_offset,
                    1.0 / offset_variance);
      // The normals agree: n x (R n_s) = 0 in the two directions across n.
      const Eigen::Vector3d moved_normal = R * s.normal_camera;
      const Eigen::Vector3d cross = n.cross(moved_normal);
      Eigen::Vector3d b1 = n.unitOrthogonal();
      Eigen::Vector3d b2 = n.cross(b1);
      const Eigen::Matrix3d d_cross_d_phi = -skew(n) * R * skew(s.normal_camera);
      const double normal_variance = std::max(0.5 * (s.covariance.topLeftCorner<3, 3>().trace() +
                                                     t.covariance.topLeftCorner<3, 3>().trace()),
                                              1e-12);
      for (const Eigen::Vector3d& b : {b1, b2}) {
        Eigen::Matrix<double, 1, 6> J = Eigen::Matrix<double, 1, 6>::Zero();
        J.tail<3>() = b.transpose() * d_cross_d_phi;
        equations.add(J, b.dot(cross), 1.0 / normal_variance);
      }
      ++plane_matches;
    }
  };

  IcpResult result = solve(T_target_source_guess, mean_depth_m, params, associate);
  result.source_points = static_cast<int>(samples.size());
  result.plane_matches = plane_matches;
  return result;
}

IcpResult registerClouds(const cv::Mat& source_depth_m, const cv::Mat& target_depth_m,
                         const CameraIntrinsics& intrinsics, const SE3& T_target_source_guess,
                         const IcpParams& params) {
  if (std::string error = params.validationError(); !error.empty()) return failure(error);
  if (std::string error = poseError(T_target_source_guess); !error.empty()) return failure(error);
  if (std::string error = frameError(source_depth_m, intrinsics, "source"); !error.empty()) {
    return failure(error);
  }
  if (std::string error = frameError(target_depth_m, intrinsics, "target"); !error.empty()) {
    return failure(error);
  }
  const PointsAndNormals target = pointsAndNormals(target_depth_m, intrinsics, params);
  const PointsAndNormals source_all = pointsAndNormals(source_depth_m, intrinsics, params);
  struct Sample {
    Eigen::Vector3d p;
    Eigen::Vector3d n;
  };
  std::vector<Sample> samples;
  double depth_sum_m = 0.0;
  for (int v = 0; v < intrinsics.height; v += params.cloud_stride_px) {
    for (int u = 0; u < intrinsics.width; u += params.cloud_stride_px) {
      const std::size_t i = static_cast<std::size_t>(v) * intrinsics.width + u;
      if (!source_all.normals[i].allFinite()) continue;
      samples.push_back({source_all.points[i], source_all.normals[i]});
      depth_sum_m += source_all.points[i].z();
    }
  }
  if (samples.empty()) return failure("no source points with a surface normal");
  const double mean_depth_m = depth_sum_m / static_cast<double>(samples.size());
  const double min_normal_dot = std::cos(params.max_normal_angle_deg * kPi / 180.0);

  const auto associate = [&](const SE3& T, double gate_m, NormalEquations& equations) {
    const Eigen::Matrix3d R = T.linear();
    for (const Sample& sample : samples) {
      const Eigen::Vector3d q = T * sample.p;
      int u = 0;
      int v = 0;
      if (!pixelOf(intrinsics, q, u, v)) continue;
      const std::size_t i = static_cast<std::size_t>(v) * intrinsics.width + u;
      const Eigen::Vector3d& n = target.normals[i];
      if (!n.allFinite() || (R * sample.n).dot(n) < min_normal_dot) continue;
      const Eigen::Vector3d& target_point = target.points[i];
      const double r = n.dot(q - target_point);
      if (std::abs(r) > gate_m) continue;
      const double sigma_m = kinectSigmaZ(target_point.z());
      equations.addPoint(pointToPlaneJacobian(sample.p, R.transpose() * n), r,
                         1.0 / (sigma_m * sigma_m));
    }
  };

  IcpResult result = solve(T_target_source_guess, mean_depth_m, params, associate);
  result.source_points = static_cast<int>(samples.size());
  return result;
}

}  // namespace slamd::planes
