#include "slamd/tracking/dense_alignment.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

#include "robust_statistics.hpp"
#include "slamd/common/time.hpp"

namespace slamd {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
/// Neighbouring depths differing by more than this fraction of the depth are a discontinuity:
/// no normal there, and no averaging across it when the pyramid is built.
constexpr double kDiscontinuityRatio = 0.05;

/// A float image (CV_32F or CV_32FC3) filled with NaN (std::fill: OpenCV's generic fill with a
/// scalar is slower).
cv::Mat nanImage(int rows, int cols, int type) {
  cv::Mat image(rows, cols, type);
  float* data = image.ptr<float>(0);
  std::fill(data, data + image.total() * static_cast<std::size_t>(image.channels()), kNaN);
  return image;
}

/// A depth is usable: known (NaN fails both comparisons) and within [min_m, max_m].
bool inDepthRange(float z, double min_m, double max_m) {
  const double z_m = z;
  return z_m >= min_m && z_m <= max_m;
}

/// 2x2 block average of the valid depths (not NaN, and within [min_m, max_m]) when they agree;
/// NaN across a discontinuity.
cv::Mat downsampleDepth(const cv::Mat& depth_m,
                        double min_m = -std::numeric_limits<double>::infinity(),
                        double max_m = std::numeric_limits<double>::infinity()) {
  cv::Mat out = nanImage(depth_m.rows / 2, depth_m.cols / 2, CV_32F);
  for (int v = 0; v < out.rows; ++v) {
    const float* r0 = depth_m.ptr<float>(2 * v);
    const float* r1 = depth_m.ptr<float>(2 * v + 1);
    float* o = out.ptr<float>(v);
    for (int u = 0; u < out.cols; ++u) {
      const float values[4] = {r0[2 * u], r0[2 * u + 1], r1[2 * u], r1[2 * u + 1]};
      float lo = std::numeric_limits<float>::max();
      float hi = 0.0F;
      float sum = 0.0F;
      int n = 0;
      for (float z : values) {
        if (!inDepthRange(z, min_m, max_m)) continue;
        lo = std::min(lo, z);
        hi = std::max(hi, z);
        sum += z;
        ++n;
      }
      if (n >= 2 && static_cast<double>(hi - lo) <= kDiscontinuityRatio * static_cast<double>(lo)) {
        o[u] = sum / static_cast<float>(n);
      }
    }
  }
  return out;
}

/// Half-size CV_32F grey image of a CV_8UC1 one of even size: the mean of each 2x2 block.
cv::Mat halveGray(const cv::Mat& gray) {
  cv::Mat out(gray.rows / 2, gray.cols / 2, CV_32F);
  for (int v = 0; v < out.rows; ++v) {
    const std::uint8_t* r0 = gray.ptr<std::uint8_t>(2 * v);
    const std::uint8_t* r1 = gray.ptr<std::uint8_t>(2 * v + 1);
    float* o = out.ptr<float>(v);
    for (int u = 0; u < out.cols; ++u) {
      const int sum = r0[2 * u] + r0[2 * u + 1] + r1[2 * u] + r1[2 * u + 1];
      o[u] = 0.25F * static_cast<float>(sum);
    }
  }
  return out;
}

/// Unit normals facing the camera. Depth noise makes per-pixel normals tilt at random, and a
/// tilted normal of a wall along a corridor claims information along the corridor that the wall
/// does not give: so the normals come from the depth averaged over a window (valid pixels only)
/// and differences across a wider stencil.
cv::Mat computeNormals(const cv::Mat& depth_m, const CameraIntrinsics& K) {
  constexpr int kWindow = 5;   // averaging window, pixels
  constexpr int kStencil = 2;  // half-width of the differences, pixels
  const int rows = depth_m.rows, cols = depth_m.cols;
  cv::Mat filled(depth_m.size(), CV_32F);  // 0 where unknown
  cv::Mat valid(depth_m.size(), CV_32F);   // 1 where known, else 0
  for (int v = 0; v < rows; ++v) {
    const float* raw = depth_m.ptr<float>(v);
    float* f = filled.ptr<float>(v);
    float* m = valid.ptr<float>(v);
    for (int u = 0; u < cols; ++u) {
      const bool known = !std::isnan(raw[u]);
      f[u] = known ? raw[u] : 0.0F;
      m[u] = known ? 1.0F : 0.0F;
    }
  }
  cv::Mat sum, count;
  cv::boxFilter(filled, sum, CV_32F, cv::Size(kWindow, kWindow), cv::Point(-1, -1), false);
  cv::boxFilter(valid, count, CV_32F, cv::Size(kWindow, kWindow), cv::Point(-1, -1), false);
  // The averaged depth and its back-projection (x, y in metres), each pixel's computed once: the
  // differences below take every point four times.
  cv::Mat smooth(depth_m.size(), CV_32F);
  std::vector<double> x_m(static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols));
  std::vector<double> y_m(x_m.size());
  for (int v = 0; v < rows; ++v) {
    const float* raw = depth_m.ptr<float>(v);
    const float* s = sum.ptr<float>(v);
    const float* c = count.ptr<float>(v);
    float* out = smooth.ptr<float>(v);
    const std::size_t row_start = static_cast<std::size_t>(v) * static_cast<std::size_t>(cols);
    for (int u = 0; u < cols; ++u) {
      out[u] = (!std::isnan(raw[u]) && c[u] >= 0.5F * kWindow * kWindow) ? s[u] / c[u] : kNaN;
      const Eigen::Vector3d point = K.backProject(u, v, out[u]);
      x_m[row_start + static_cast<std::size_t>(u)] = point.x();
      y_m[row_start + static_cast<std::size_t>(u)] = point.y();
    }
  }
  const auto at = [&](int u, int v, float z) {
    const std::size_t i =
        static_cast<std::size_t>(v) * static_cast<std::size_t>(cols) + static_cast<std::size_t>(u);
    return Eigen::Vector3d(x_m[i], y_m[i], static_cast<double>(z));
  };
  cv::Mat normals = nanImage(rows, cols, CV_32FC3);
  for (int v = kStencil; v < rows - kStencil; ++v) {
    const float* up = smooth.ptr<float>(v - kStencil);
    const float* row = smooth.ptr<float>(v);
    const float* down = smooth.ptr<float>(v + kStencil);
    cv::Vec3f* out = normals.ptr<cv::Vec3f>(v);
    for (int u = kStencil; u < cols - kStencil; ++u) {
      const float z = row[u];
      const float zl = row[u - kStencil], zr = row[u + kStencil], zu = up[u], zd = down[u];
      if (std::isnan(z) || std::isnan(zl) || std::isnan(zr) || std::isnan(zu) || std::isnan(zd)) {
        continue;
      }
      // A window straddling a discontinuity averages two surfaces: no normal there.
      const double limit = 2.0 * kStencil * kDiscontinuityRatio * static_cast<double>(z);
      if (static_cast<double>(std::abs(zr - zl)) > limit ||
          static_cast<double>(std::abs(zd - zu)) > limit) {
        continue;
      }
      const Eigen::Vector3d du = at(u + kStencil, v, zr) - at(u - kStencil, v, zl);
      const Eigen::Vector3d dv = at(u, v + kStencil, zd) - at(u, v - kStencil, zu);
      Eigen::Vector3d n = du.cross(dv);
      const double norm = n.norm();
      if (!(norm > 0.0)) continue;
      n /= norm;
      if (n.dot(at(u, v, z)) > 0.0) n = -n;
      out[u] = cv::Vec3f(static_cast<float>(n.x()), static_cast<float>(n.y()),
                         static_cast<float>(n.z()));
    }
  }
  return normals;
}

/// A reference pixel used at one level.
struct Sample {
  Eigen::Vector3d point_ref;  ///< metres, reference camera frame
  double intensity;           ///< grey level in the reference image
  bool photometric;           ///< its gradient is strong enough for a photometric residual
};

/// The normal equations of one evaluation at one level.
struct Evaluation {
  Matrix6d H = Matrix6d::Zero();  ///< data information (already divided)
  Vector6d g = Vector6d::Zero();
  double cost = 0.0;
  int photometric = 0;
  int geometric = 0;
  double photometric_sq = 0.0;  ///< sum of squared photometric residuals of inliers
  double geometric_sq = 0.0;

  /// One residual r (noise sigma, Jacobian J), Huber-weighted at k sigmas; count and the sum of
  /// squared inlier residuals are its kind's.
  void add(const Eigen::Matrix<double, 1, 6>& J, double r, double sigma, double k, double divisor,
           int& count, double& inlier_sq) {
    const double normalized = std::abs(r) / sigma;
    const double w = huberWeight(normalized, k) / (sigma * sigma * divisor);
    H.noalias() += w * J.transpose() * J;
    g.noalias() += w * r * J.transpose();
    cost += huberCost(normalized, k) / divisor;
    ++count;
    if (normalized <= k) inlier_sq += r * r;
  }
};

class LevelAligner {
 public:
  LevelAligner(const DenseFrame::Level& ref, const DenseFrame::Level& curr, double gate_m,
               const DenseAlignmentOptions& options)
      : ref_(ref), curr_(curr), gate_m_(gate_m), options_(options) {
    collectSamples();
  }

  std::size_t numSamples() const { return samples_.size(); }
  /// The weaker axis's share of the photometric pixels' gradient scatter (0 without any).
  double gradientShare() const { return gradient_share_; }
  /// Leaves the level to the depth alone: no photometric residuals.
  void dropPhotometric() {
    for (Sample& s : samples_) s.photometric = false;
  }

  /// Robust scale of the photometric residuals at T (median absolute residual).
  double photometricSigma(const SE3& T_ref_curr) const {
    std::vector<double> magnitudes;
    magnitudes.reserve(samples_.size());
    const SE3 T_curr_ref = T_ref_curr.inverse();
    for (const Sample& s : samples_) {
      if (!s.photometric) continue;
      double u = 0.0, v = 0.0;
      const Eigen::Vector3d y = T_curr_ref * s.point_ref;
      if (!project(y, u, v)) continue;
      magnitudes.push_back(std::abs(sampleBilinear(curr_.gray, u, v) - s.intensity));
    }
    return std::max(options_.min_photometric_sigma, 1.4826 * medianInPlace(magnitudes));
  }

  Evaluation evaluate(const SE3& T_ref_curr, double photometric_sigma) const {
    Evaluation e;
    const SE3 T_curr_ref = T_ref_curr.inverse();
    const CameraIntrinsics& K = curr_.K;
    const double k = options_.huber_k;
    const double divisor = options_.information_divisor;
    Eigen::Matrix<double, 3, 6> dX;  // d X_curr / d xi = [-I, [X_curr]x]
    dX.leftCols<3>() = -Eigen::Matrix3d::Identity();
    // Point-to-plane Jacobians lose their components along the free directions (current frame).
    Eigen::Matrix<double, 6, 6> keep_geometric = Eigen::Matrix<double, 6, 6>::Identity();
    for (const Eigen::Vector3d& axis : free_translations_ref_) {
      const Eigen::Vector3d a = T_curr_ref.linear() * axis;
      keep_geometric.topLeftCorner<3, 3>() -= a * a.transpose();
    }
    if (free_rotation_ref_) {
      const Eigen::Vector3d a = T_curr_ref.linear() * *free_rotation_ref_;
      keep_geometric.bottomRightCorner<3, 3>() -= a * a.transpose();
    }
    for (const Sample& s : samples_) {
      const Eigen::Vector3d y = T_curr_ref * s.point_ref;
      double u = 0.0, v = 0.0;
      if (!project(y, u, v)) continue;
      dX.rightCols<3>() = skew(y);
      if (s.photometric) {
        const double r = sampleBilinear(curr_.gray, u, v) - s.intensity;
        double gu = sampleBilinear(curr_.grad_x, u, v);
        double gv = sampleBilinear(curr_.grad_y, u, v);
        if (measured_gradient_axis_) {  // keep only the flow component the gradients measure
          const Eigen::Vector2d& a = *measured_gradient_axis_;
          const double along = gu * a.x() + gv * a.y();
          gu = along * a.x();
          gv = along * a.y();
        }
        const double inv_z = 1.0 / y.z();
        const Eigen::RowVector3d dI_dX(gu * K.fx * inv_z, gv * K.fy * inv_z,
                                       -(gu * K.fx * y.x() + gv * K.fy * y.y()) * inv_z * inv_z);
        e.add(dI_dX * dX, r, photometric_sigma, k, divisor, e.photometric, e.photometric_sq);
      }
      const int ui = static_cast<int>(std::lround(u));
      const int vi = static_cast<int>(std::lround(v));
      const double z_curr = curr_.depth_m.at<float>(vi, ui);
      const cv::Vec3f& nc = curr_.normals.at<cv::Vec3f>(vi, ui);
      if (std::isnan(z_curr) || std::isnan(nc[0])) continue;
      const Eigen::Vector3d n(static_cast<double>(nc[0]), static_cast<double>(nc[1]),
                              static_cast<double>(nc[2]));
      const double r = n.dot(y - K.backProject(ui, vi, z_curr));
      if (std::abs(r) > gate_m_) continue;
      const double sigma =
          std::max(options_.min_depth_sigma_m, options_.depth_sigma_coeff * z_curr * z_curr);
      e.add(n.transpose() * dX * keep_geometric, r, sigma, k, divisor, e.geometric, e.geometric_sq);
    }
    return e;
  }

 private:
  bool project(const Eigen::Vector3d& y, double& u, double& v) const {
    if (y.z() < options_.min_depth_m) return false;
    u = curr_.K.fx * y.x() / y.z() + curr_.K.cx;
    v = curr_.K.fy * y.y() / y.z() + curr_.K.cy;
    return u >= 1.0 && v >= 1.0 && u < curr_.gray.cols - 2 && v < curr_.gray.rows - 2;
  }

  /// The surfaces' normals decide what point-to-plane residuals can measure. Where the normals
  /// span fewer than three directions (share of the scatter below min_normal_share: one plane
  /// orientation, or planes all parallel to one axis like a corridor's), the translation along
  /// what they leave out, and for a single orientation the rotation about it, are free: depth
  /// noise tilts each normal by a few degrees, and those tilts must not pass for information.
  void findFreeDirections(const Eigen::Matrix3d& normal_scatter) {
    const double total = normal_scatter.trace();
    if (!(total > 0.0)) return;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(normal_scatter);
    const Eigen::Vector3d share = eigen.eigenvalues() / total;  // ascending
    const Eigen::Matrix3d& axes = eigen.eigenvectors();
    for (int k = 0; k < 2; ++k) {
      if (share(k) < options_.min_normal_share) free_translations_ref_.push_back(axes.col(k));
    }
    if (free_translations_ref_.size() == 2) free_rotation_ref_ = axes.col(2);
  }

  /// The photometric residuals measure the image motion along each pixel's gradient only (the
  /// aperture problem). When the gradients all but share one orientation (one straight edge, a
  /// door's jamb, with a few specks), the motion across it is measured by the edge's ends and the
  /// specks alone, whose cost is flat a pixel away and whose curvature claims a precision they
  /// do not have: the Jacobians then keep only their component along the dominant gradient.
  void findMeasuredGradientAxis(const Eigen::Matrix2d& gradient_scatter) {
    const double total = gradient_scatter.trace();
    if (!(total > 0.0)) return;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(gradient_scatter);
    gradient_share_ = eigen.eigenvalues()(0) / total;
    if (gradient_share_ < options_.min_gradient_share) {
      measured_gradient_axis_ = eigen.eigenvectors().col(1);
    }
  }

  void collectSamples() {
    const cv::Mat& depth = ref_.depth_m;
    Eigen::Matrix3d normal_scatter = Eigen::Matrix3d::Zero();
    Eigen::Matrix2d gradient_scatter = Eigen::Matrix2d::Zero();
    int valid = 0;
    for (int v = 1; v < depth.rows - 1; ++v) {
      const float* row = depth.ptr<float>(v);
      for (int u = 1; u < depth.cols - 1; ++u) valid += std::isnan(row[u]) ? 0 : 1;
    }
    const int step = std::max(1, (valid + options_.max_pixels_per_level - 1) /
                                     std::max(1, options_.max_pixels_per_level));
    const double min_gradient_sq = options_.min_gradient * options_.min_gradient;
    samples_.reserve(static_cast<std::size_t>(valid / step + 1));
    int index = 0;
    for (int v = 1; v < depth.rows - 1; ++v) {
      const float* row = depth.ptr<float>(v);
      const float* gray = ref_.gray.ptr<float>(v);
      const float* gx = ref_.grad_x.ptr<float>(v);
      const float* gy = ref_.grad_y.ptr<float>(v);
      for (int u = 1; u < depth.cols - 1; ++u) {
        if (std::isnan(row[u])) continue;
        if (index++ % step != 0) continue;
        const double gu = gx[u], gv = gy[u];
        const double gradient_sq = gu * gu + gv * gv;
        const bool photometric = gradient_sq >= min_gradient_sq;
        samples_.push_back(
            {ref_.K.backProject(u, v, row[u]), static_cast<double>(gray[u]), photometric});
        if (photometric) {
          gradient_scatter += Eigen::Vector2d(gu, gv) * Eigen::Vector2d(gu, gv).transpose();
        }
        const cv::Vec3f& n = ref_.normals.at<cv::Vec3f>(v, u);
        if (std::isnan(n[0])) continue;
        const Eigen::Vector3d normal(static_cast<double>(n[0]), static_cast<double>(n[1]),
                                     static_cast<double>(n[2]));
        normal_scatter += normal * normal.transpose();
      }
    }
    findFreeDirections(normal_scatter);
    findMeasuredGradientAxis(gradient_scatter);
  }

  const DenseFrame::Level& ref_;
  const DenseFrame::Level& curr_;
  double gate_m_;
  const DenseAlignmentOptions& options_;
  std::vector<Sample> samples_;
  std::vector<Eigen::Vector3d> free_translations_ref_;  ///< unit, reference frame
  std::optional<Eigen::Vector3d> free_rotation_ref_;    ///< unit axis, reference frame
  double gradient_share_ = 0.0;  ///< the weaker axis's share of the gradient scatter
  std::optional<Eigen::Vector2d> measured_gradient_axis_;  ///< unit, image; set when one dominates
};

bool sameShape(const DenseFrame& a, const DenseFrame& b) {
  if (a.levels.size() != b.levels.size()) return false;
  for (std::size_t k = 0; k < a.levels.size(); ++k) {
    if (a.levels[k].depth_m.size() != b.levels[k].depth_m.size()) return false;
  }
  return true;
}

}  // namespace

DenseFrame makeDenseFrame(const cv::Mat& gray, const cv::Mat& depth_m, const CameraIntrinsics& K,
                          const DenseAlignmentOptions& options) {
  DenseFrame frame;
  if (gray.empty() || gray.type() != CV_8UC1 || depth_m.type() != CV_32FC1 ||
      gray.size() != depth_m.size() || gray.cols != K.width || gray.rows != K.height ||
      options.levels < 1 || options.finest_level < 0 || options.finest_level >= options.levels ||
      (K.width >> (options.levels - 1)) < 8 || (K.height >> (options.levels - 1)) < 8) {
    return frame;
  }
  frame.levels.resize(static_cast<std::size_t>(options.levels));
  frame.levels[0].K = K;
  cv::Mat level_gray;
  cv::Mat level_depth;
  int first_level = 0;
  if (options.finest_level > 0 && gray.cols % 2 == 0 && gray.rows % 2 == 0) {
    // Full resolution is never aligned: half resolution comes straight from the inputs, without
    // full-size float copies. The same values as resizing the float image: the 2x2 mean of whole
    // grey levels is exact either way.
    level_gray = halveGray(gray);
    level_depth = downsampleDepth(depth_m, options.min_depth_m, options.max_depth_m);
    first_level = 1;
  } else {
    gray.convertTo(level_gray, CV_32F);
    level_depth = cv::Mat(depth_m.size(), CV_32F);
    for (int v = 0; v < depth_m.rows; ++v) {
      const float* in = depth_m.ptr<float>(v);
      float* out = level_depth.ptr<float>(v);
      for (int u = 0; u < depth_m.cols; ++u) {
        out[u] = inDepthRange(in[u], options.min_depth_m, options.max_depth_m) ? in[u] : kNaN;
      }
    }
  }
  for (int k = first_level; k < options.levels; ++k) {
    if (k > first_level) {
      cv::Mat smaller;
      cv::resize(level_gray, smaller, cv::Size(level_gray.cols / 2, level_gray.rows / 2), 0, 0,
                 cv::INTER_AREA);
      level_gray = smaller;
      level_depth = downsampleDepth(level_depth);
    }
    DenseFrame::Level& level = frame.levels[static_cast<std::size_t>(k)];
    level.K = k == 0 ? K : K.scaled(level_gray.cols, level_gray.rows);
    level.gray = level_gray;
    level.depth_m = level_depth;
    if (k < options.finest_level) continue;  // never aligned: no gradients or normals needed
    cv::Sobel(level_gray, level.grad_x, CV_32F, 1, 0, 1, 0.5);
    cv::Sobel(level_gray, level.grad_y, CV_32F, 0, 1, 1, 0.5);
    level.normals = computeNormals(level_depth, level.K);
  }
  return frame;
}

DenseAlignmentResult alignDense(const DenseFrame& ref, const DenseFrame& curr,
                                const SE3& T_ref_curr_prior, const Matrix6d& prior_covariance,
                                const DenseAlignmentOptions& options) {
  const std::int64_t t0 = steadyNowNs();
  DenseAlignmentResult result;
  result.T_ref_curr = T_ref_curr_prior;
  result.covariance = prior_covariance;
  const auto finish = [&](const char* failure) {
    result.failure = failure;
    result.success = result.failure.empty();
    result.time_ms = static_cast<double>(steadyNowNs() - t0) * 1e-6;
    return result;
  };
  if (ref.empty() || curr.empty() || !sameShape(ref, curr)) return finish("frames do not fit");
  const int levels = static_cast<int>(ref.levels.size());
  const int finest = std::clamp(options.finest_level, 0, levels - 1);
  if (ref.levels[static_cast<std::size_t>(finest)].normals.empty() ||
      curr.levels[static_cast<std::size_t>(finest)].normals.empty()) {
    return finish("the pyramid was built for a coarser finest level");
  }
  const Matrix6d symmetric_prior = 0.5 * (prior_covariance + prior_covariance.transpose());
  const Eigen::LDLT<Matrix6d> prior_ldlt(symmetric_prior);
  if (!symmetric_prior.allFinite() || prior_ldlt.info() != Eigen::Success ||
      !prior_ldlt.isPositive() || (prior_ldlt.vectorD().array() <= 0.0).any()) {
    return finish("the prior covariance is not positive definite");
  }
  const Matrix6d prior_information = prior_ldlt.solve(Matrix6d::Identity());
  const SE3 prior_inverse = T_ref_curr_prior.inverse();
  const auto priorResidual = [&](const SE3& T) { return logSE3(prior_inverse * T); };
  const auto priorCost = [&](const SE3& T) {  // on huberCost's scale: the squared residual
    const Vector6d r = priorResidual(T);
    return r.dot(prior_information * r);
  };

  SE3 T = T_ref_curr_prior;
  Evaluation final_evaluation;
  for (int level = levels - 1; level >= finest; --level) {
    const std::size_t l = static_cast<std::size_t>(level);
    if (ref.levels[l].normals.empty() || curr.levels[l].normals.empty()) continue;
    const double gate_m = options.max_point_to_plane_m * std::pow(2.0, level - finest);
    LevelAligner aligner(ref.levels[l], curr.levels[l], gate_m, options);
    if (aligner.numSamples() == 0) continue;
    if (level > finest && aligner.gradientShare() < options.min_coarse_gradient_share) {
      aligner.dropPhotometric();
    }
    const double photometric_sigma = aligner.photometricSigma(T);
    Evaluation e = aligner.evaluate(T, photometric_sigma);
    double cost = e.cost + priorCost(T);
    for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
      const Vector6d b = e.g + prior_information * priorResidual(T);
      const Eigen::LDLT<Matrix6d> solver(e.H + prior_information);
      const Vector6d delta = -solver.solve(b);
      if (!delta.allFinite()) break;
      const SE3 T_next = normalizedSE3(T * expSE3(delta));
      Evaluation e_next = aligner.evaluate(T_next, photometric_sigma);
      const double cost_next = e_next.cost + priorCost(T_next);
      ++result.iterations;
      if (cost_next > cost) break;  // no progress: keep T
      T = T_next;
      e = std::move(e_next);
      cost = cost_next;
      if (delta.head<3>().norm() < 1e-6 && delta.tail<3>().norm() < 1e-7) break;
    }
    if (level == finest) final_evaluation = e;
  }

  result.photometric_residuals = final_evaluation.photometric;
  result.geometric_residuals = final_evaluation.geometric;
  if (final_evaluation.photometric > 0) {
    result.photometric_rms =
        std::sqrt(final_evaluation.photometric_sq / final_evaluation.photometric);
  }
  if (final_evaluation.geometric > 0) {
    result.geometric_rms_m = std::sqrt(final_evaluation.geometric_sq / final_evaluation.geometric);
  }
  if (final_evaluation.photometric + final_evaluation.geometric < options.min_residuals) {
    return finish("too few pixels with depth overlap");
  }
  const Matrix6d posterior_information = final_evaluation.H + prior_information;
  const Matrix6d covariance = posterior_information.inverse();
  if (!covariance.allFinite() || !T.matrix().allFinite()) return finish("no finite solution");
  result.T_ref_curr = T;
  result.covariance = 0.5 * (covariance + covariance.transpose());
  const Eigen::GeneralizedSelfAdjointEigenSolver<Matrix6d> directions(
      final_evaluation.H, prior_information, Eigen::EigenvaluesOnly);
  if (directions.info() != Eigen::Success) return finish("no finite solution");
  result.degenerate_directions = static_cast<int>((directions.eigenvalues().array() < 1.0).count());
  if (6 - result.degenerate_directions < options.min_constrained_directions) {
    return finish("the images constrain too few directions of the motion");
  }
  return finish("");
}

}  // namespace slamd
