#include "slamd/filter/surface_axes.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

#include "slamd/filter/pose_ekf.hpp"

namespace slamd {
namespace {

constexpr double kDegToRad = M_PI / 180.0;
/// Added to each cell's inverse-depth residual variance (m^-2; 1e-8 is 0.04% of 1/z at 2.5 m),
/// so noiseless (rendered) depth does not give a cell an unbounded weight.
constexpr double kMinResidualVariance = 1e-8;

}  // namespace

const ConfigSchema<SurfaceAxesConfig>& SurfaceAxesConfig::schema() {
  using C = SurfaceAxesConfig;
  static const auto table =
      ConfigSchema<C>("filter.axes")
          .number("cell_px", &C::cell_px, 6, 160, "px",
                  "side of the square cells a plane is fitted in")
          .number("sample_step_px", &C::sample_step_px, 1, 16, "px",
                  "depth pixels used inside a cell")
          .number("min_cell_points", &C::min_cell_points, 3, 10000, "",
                  "a cell with fewer valid samples is skipped")
          .number("min_depth_m", &C::min_depth_m, 0.05, 50.0, "m", "nearest depth used")
          .number("max_depth_m", &C::max_depth_m, 0.05, 50.0, "m",
                  "farthest depth used; > min_depth_m")
          .number("max_relative_residual", &C::max_relative_residual, 1e-5, 1.0, "",
                  "a cell is planar when the RMS residual of its fit in inverse depth is at most "
                  "this fraction of its mean inverse depth")
          .number("inlier_angle_deg", &C::inlier_angle_deg, 0.1, 45.0, "deg",
                  "a cell supports an axis when its normal is within this angle of it (either "
                  "sign)")
          .number("orthogonality_deg", &C::orthogonality_deg, 0.1, 45.0, "deg",
                  "the second and third axes must be this close to perpendicular to the axes "
                  "already found")
          .number("min_axis_cells", &C::min_axis_cells, 1, 10000, "",
                  "fewer supporting cells = no axis")
          .number("max_axes", &C::max_axes, 1, 3, "", "axes reported at most")
          .number("min_sigma_deg", &C::min_sigma_deg, 0.001, 10.0, "deg",
                  "floor of each axis' standard deviation (added in quadrature)");
  return table;
}

SurfaceAxesConfig SurfaceAxesConfig::load(Config& config) {
  SurfaceAxesConfig c;
  schema().load(config, c);
  if (c.max_depth_m <= c.min_depth_m) {
    throw ConfigError("filter.axes.max_depth_m (" + std::to_string(c.max_depth_m) +
                      ") must be greater than filter.axes.min_depth_m (" +
                      std::to_string(c.min_depth_m) + ")");
  }
  return c;
}

const char* surfaceAxesStatusName(SurfaceAxesStatus status) {
  switch (status) {
    case SurfaceAxesStatus::kOk:
      return "ok";
    case SurfaceAxesStatus::kEmptyImage:
      return "empty image";
    case SurfaceAxesStatus::kWrongImageType:
      return "wrong image type";
    case SurfaceAxesStatus::kWrongImageSize:
      return "wrong image size";
    case SurfaceAxesStatus::kNoPlanes:
      return "no planes";
  }
  return "unknown";
}

SurfaceAxisDetector::SurfaceAxisDetector(const SurfaceAxesConfig& config,
                                         const CameraIntrinsics& intrinsics)
    : config_(config), intrinsics_(intrinsics) {}

SurfaceAxes SurfaceAxisDetector::detect(const cv::Mat& depth_m) {
  ++counters_.images;
  SurfaceAxes result;
  if (depth_m.empty()) {
    result.status = SurfaceAxesStatus::kEmptyImage;
  } else if (depth_m.type() != CV_32FC1) {
    result.status = SurfaceAxesStatus::kWrongImageType;
  } else if (depth_m.cols != intrinsics_.width || depth_m.rows != intrinsics_.height) {
    result.status = SurfaceAxesStatus::kWrongImageSize;
  } else {
    result.status = SurfaceAxesStatus::kOk;
  }
  if (result.status != SurfaceAxesStatus::kOk) {
    ++counters_.bad_input;
    return result;
  }
  fitCells(depth_m);
  result.num_planar_cells = static_cast<int>(cells_.size());
  SurfaceAxis axis;
  while (static_cast<int>(result.axes.size()) < config_.max_axes && findAxis(result.axes, &axis)) {
    result.axes.push_back(axis);
  }
  if (result.axes.empty()) {
    result.status = SurfaceAxesStatus::kNoPlanes;
    ++counters_.not_detected;
  } else {
    ++counters_.detected;
  }
  return result;
}

void SurfaceAxisDetector::fitCells(const cv::Mat& depth_m) {
  cells_.clear();
  const int side = config_.cell_px;
  const int step = config_.sample_step_px;
  const double fx = intrinsics_.fx, fy = intrinsics_.fy, cx = intrinsics_.cx, cy = intrinsics_.cy;
  for (int top = 0; top + side <= depth_m.rows; top += side) {
    for (int left = 0; left + side <= depth_m.cols; left += side) {
      // A plane n . X = d seen through normalised coordinates r = (x, y, 1) has inverse depth
      // 1/z = (n . r) / d: linear in r. Fit beta = n / d by ordinary least squares on w = 1/z.
      // Depth sensors of this class measure disparity (~ 1/z) with roughly constant noise, so the
      // errors are in w alone and the fit is unbiased; a total-least-squares (PCA) fit of the 3D
      // points would tilt the normal towards the viewing ray, whose direction the noise takes
      // (0.7 degrees on a corridor floor seen at a grazing angle).
      Eigen::Matrix3d normal_matrix = Eigen::Matrix3d::Zero();
      Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
      double sum_w = 0.0, sum_w2 = 0.0;
      int n = 0;
      for (int v = top + step / 2; v < top + side; v += step) {
        const float* row = depth_m.ptr<float>(v);
        for (int u = left + step / 2; u < left + side; u += step) {
          const double z = row[u];
          if (!(z >= config_.min_depth_m && z <= config_.max_depth_m)) continue;
          const Eigen::Vector3d r((u - cx) / fx, (v - cy) / fy, 1.0);
          const double w = 1.0 / z;
          normal_matrix += r * r.transpose();
          rhs += r * w;
          sum_w += w;
          sum_w2 += w * w;
          ++n;
        }
      }
      if (n < config_.min_cell_points) continue;
      const Eigen::LDLT<Eigen::Matrix3d> ldlt(normal_matrix);
      if (ldlt.info() != Eigen::Success) continue;
      const Eigen::Vector3d beta = ldlt.solve(rhs);
      const double beta_norm = beta.norm();
      if (!beta.allFinite() || !(beta_norm > 0.0)) continue;
      const double residual_ss =
          std::max(0.0, sum_w2 - 2.0 * beta.dot(rhs) + beta.dot(normal_matrix * beta));
      const double residual_var = residual_ss / (n - 3) + kMinResidualVariance;
      // Planar: the residual RMS of 1/z relative to its mean (~ relative depth error) is small.
      const double mean_w = sum_w / n;
      if (std::sqrt(residual_var) > config_.max_relative_residual * mean_w) continue;
      // Covariance of the unit normal n = beta / |beta|, in its tangent basis.
      const Eigen::Vector3d normal = beta / beta_norm;
      const Eigen::Matrix3d beta_cov = residual_var * ldlt.solve(Eigen::Matrix3d::Identity());
      const Eigen::Matrix3d J =
          (Eigen::Matrix3d::Identity() - normal * normal.transpose()) / beta_norm;
      const Eigen::Matrix<double, 3, 2> B = PoseEkf::tangentBasis(normal);
      const Eigen::Matrix2d tangent_cov = B.transpose() * J * beta_cov * J.transpose() * B;
      const Eigen::Matrix2d information = tangent_cov.inverse();
      if (!information.allFinite() || !(information.determinant() > 0.0)) continue;
      Cell cell;
      cell.normal = normal;
      cell.information = information;
      cell.weight = 0.5 * information.trace();
      cell.num_points = n;
      cells_.push_back(cell);
    }
  }
}

bool SurfaceAxisDetector::findAxis(const std::vector<SurfaceAxis>& found, SurfaceAxis* axis) {
  const double inlier_cos = std::cos(config_.inlier_angle_deg * kDegToRad);
  const double perpendicular_sin = std::sin(config_.orthogonality_deg * kDegToRad);
  const auto eligible = [&](const Eigen::Vector3d& n) {
    return std::all_of(found.begin(), found.end(), [&](const SurfaceAxis& a) {
      return std::abs(a.direction_camera.dot(n)) <= perpendicular_sin;
    });
  };
  // Seed: the unused, eligible cell normal with the most inlier weight.
  double best_weight = 0.0;
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  for (const Cell& seed : cells_) {
    if (seed.used || !eligible(seed.normal)) continue;
    double weight = 0.0;
    for (const Cell& c : cells_) {
      if (!c.used && std::abs(c.normal.dot(seed.normal)) >= inlier_cos) weight += c.weight;
    }
    if (weight > best_weight) {
      best_weight = weight;
      best = seed.normal;
    }
  }
  if (!(best_weight > 0.0)) return false;

  // Refine: principal axis of the inliers' weighted scatter (sign-free), inliers re-chosen; then
  // Gauss-Newton steps of the information-weighted mean in the axis' tangent plane.
  Eigen::Vector3d direction = best;
  std::vector<std::size_t> inliers;
  const auto chooseInliers = [&]() {
    inliers.clear();
    for (std::size_t i = 0; i < cells_.size(); ++i) {
      if (!cells_[i].used && std::abs(cells_[i].normal.dot(direction)) >= inlier_cos) {
        inliers.push_back(i);
      }
    }
    return !inliers.empty();
  };
  for (int iteration = 0; iteration < 2; ++iteration) {
    if (!chooseInliers()) return false;
    Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
    for (const std::size_t i : inliers) {
      scatter += cells_[i].weight * cells_[i].normal * cells_[i].normal.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(scatter);
    if (eig.info() != Eigen::Success) return false;
    const Eigen::Vector3d refined = eig.eigenvectors().col(2).normalized();
    direction = refined.dot(direction) < 0.0 ? Eigen::Vector3d(-refined) : refined;
  }
  // Each cell's normal, sign-aligned, in the axis' tangent basis B(a), with its information
  // moved there: t_i = B(a)^T n_i, I_i = M_i^T Info_i M_i with M_i = B(n_i)^T B(a).
  Eigen::Matrix2d total_information = Eigen::Matrix2d::Zero();
  double chi2 = 0.0;
  for (int iteration = 0; iteration < 3; ++iteration) {
    if (!chooseInliers()) return false;
    const Eigen::Matrix<double, 3, 2> B = PoseEkf::tangentBasis(direction);
    total_information.setZero();
    Eigen::Vector2d information_residual = Eigen::Vector2d::Zero();
    std::vector<std::pair<Eigen::Vector2d, Eigen::Matrix2d>> residuals;
    for (const std::size_t i : inliers) {
      const Cell& c = cells_[i];
      const Eigen::Vector3d n =
          c.normal.dot(direction) < 0.0 ? Eigen::Vector3d(-c.normal) : c.normal;
      const Eigen::Matrix2d M = PoseEkf::tangentBasis(c.normal).transpose() * B;
      const Eigen::Matrix2d information = M.transpose() * c.information * M;
      const Eigen::Vector2d t = B.transpose() * n;
      total_information += information;
      information_residual += information * t;
      residuals.emplace_back(t, information);
    }
    const Eigen::Vector2d step = total_information.ldlt().solve(information_residual);
    if (!step.allFinite()) return false;
    direction = (direction + B * step).normalized();
    chi2 = 0.0;
    for (const auto& [t, information] : residuals) {
      const Eigen::Vector2d r = t - step;
      chi2 += r.dot(information * r);
    }
  }
  if (static_cast<int>(inliers.size()) < config_.min_axis_cells || !eligible(direction)) {
    return false;
  }

  const Eigen::Matrix<double, 3, 2> B = PoseEkf::tangentBasis(direction);
  double sum_sq_angle = 0.0;
  int points = 0;
  for (const std::size_t i : inliers) {
    Cell& c = cells_[i];
    c.used = true;
    const Eigen::Vector3d n = c.normal.dot(direction) < 0.0 ? Eigen::Vector3d(-c.normal) : c.normal;
    sum_sq_angle += (B.transpose() * n).squaredNorm();
    points += c.num_points;
  }
  // The cells' own covariances, scaled up by the variance of unit weight when they scatter more
  // than those claim (neighbouring cells share quantisation steps and edges).
  const double count = static_cast<double>(inliers.size());
  const double unit_variance = count > 1.0 ? chi2 / (2.0 * count - 2.0) : 1.0;
  Eigen::Matrix2d covariance = std::max(1.0, unit_variance) * total_information.inverse();
  const double floor_rad = config_.min_sigma_deg * kDegToRad;
  covariance.diagonal().array() += floor_rad * floor_rad;

  axis->direction_camera = direction;
  axis->covariance = covariance;
  axis->num_cells = static_cast<int>(inliers.size());
  axis->num_points = points;
  axis->rms_angle_deg = std::sqrt(sum_sq_angle / count) / kDegToRad;
  return true;
}

}  // namespace slamd
