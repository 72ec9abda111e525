#include "slamd/tracking/motion_estimation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <Eigen/SVD>

#include "robust_statistics.hpp"

namespace slamd {
namespace {

double depthSigma(double z, double coeff) { return coeff * z * z; }

}  // namespace

bool rigidFit(const std::vector<Eigen::Vector3d>& points_a,
              const std::vector<Eigen::Vector3d>& points_b, SE3& T_a_b) {
  const std::size_t n = points_a.size();
  if (n < 3 || points_b.size() != n) return false;
  Eigen::Vector3d mean_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d mean_b = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    mean_a += points_a[i];
    mean_b += points_b[i];
  }
  mean_a /= static_cast<double>(n);
  mean_b /= static_cast<double>(n);
  Eigen::Matrix3d cross = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    cross += (points_b[i] - mean_b) * (points_a[i] - mean_a).transpose();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(cross, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  // Degenerate when all points coincide or lie on a line (second singular value vanishes).
  if (!(sv(0) > 1e-12) || sv(1) < 1e-9 * sv(0)) return false;
  const Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d V = svd.matrixV();
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  if ((V * U.transpose()).determinant() < 0.0) D(2, 2) = -1.0;
  const Eigen::Matrix3d R = V * D * U.transpose();
  T_a_b = SE3::Identity();
  T_a_b.linear() = R;
  T_a_b.translation() = mean_a - R * mean_b;
  return T_a_b.matrix().allFinite();
}

double reprojectionErrorPx(const Correspondence& c, const CameraIntrinsics& K,
                           const SE3& T_ref_curr) {
  const Eigen::Vector3d q = T_ref_curr.inverse() * c.point_ref;
  if (q.z() <= 1e-6) return std::numeric_limits<double>::infinity();
  return (K.project(q) - c.pixel_curr).norm();
}

RansacResult ransacRigid(const std::vector<Correspondence>& matches, const CameraIntrinsics& K,
                         double threshold_px, int max_iterations, std::mt19937& rng) {
  RansacResult result;
  result.inliers.assign(matches.size(), 0);
  std::vector<int> with_depth;
  std::vector<Eigen::Vector3d> curr_points(matches.size());
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (matches[i].hasCurrDepth()) {
      with_depth.push_back(static_cast<int>(i));
      curr_points[i] = matches[i].pointCurr(K);
    }
  }
  const int m = static_cast<int>(with_depth.size());
  if (m < 3) return result;

  // MSAC score: sum of truncated squared errors (lower is better); also the inlier count.
  auto score = [&](const SE3& T_ref_curr, std::vector<std::uint8_t>* inliers, int& count) {
    const SE3 T_curr_ref = T_ref_curr.inverse();
    double cost = 0.0;
    count = 0;
    for (std::size_t i = 0; i < matches.size(); ++i) {
      const Correspondence& c = matches[i];
      const double th = threshold_px * c.pixel_sigma_px;
      const Eigen::Vector3d q = T_curr_ref * c.point_ref;
      double e2 = std::numeric_limits<double>::infinity();
      if (q.z() > 1e-6) e2 = (K.project(q) - c.pixel_curr).squaredNorm();
      const bool in = e2 < th * th;
      if (inliers) (*inliers)[i] = in ? 1 : 0;
      if (in) ++count;
      cost += (in ? e2 : th * th) / (c.pixel_sigma_px * c.pixel_sigma_px);
    }
    return cost;
  };

  std::uniform_int_distribution<int> pick(0, m - 1);
  double best_cost = std::numeric_limits<double>::infinity();
  SE3 best = SE3::Identity();
  int needed = max_iterations;
  std::vector<Eigen::Vector3d> sample_a(3), sample_b(3);
  int it = 0;
  for (; it < needed; ++it) {
    int idx[3];
    idx[0] = pick(rng);
    do idx[1] = pick(rng);
    while (idx[1] == idx[0] && m > 1);
    do idx[2] = pick(rng);
    while ((idx[2] == idx[0] || idx[2] == idx[1]) && m > 2);
    bool ok = true;
    for (int k = 0; k < 3; ++k) {
      const int i = with_depth[static_cast<std::size_t>(idx[k])];
      sample_a[static_cast<std::size_t>(k)] = matches[static_cast<std::size_t>(i)].point_ref;
      sample_b[static_cast<std::size_t>(k)] = curr_points[static_cast<std::size_t>(i)];
    }
    // Cheap pre-check: a rigid motion keeps distances (within depth noise).
    for (int a = 0; a < 3 && ok; ++a) {
      for (int b = a + 1; b < 3; ++b) {
        const double da =
            (sample_a[static_cast<std::size_t>(a)] - sample_a[static_cast<std::size_t>(b)]).norm();
        const double db =
            (sample_b[static_cast<std::size_t>(a)] - sample_b[static_cast<std::size_t>(b)]).norm();
        if (da < 0.01 || std::abs(da - db) > 0.05 + 0.05 * da) {
          ok = false;
          break;
        }
      }
    }
    if (!ok) continue;
    SE3 T;
    if (!rigidFit(sample_a, sample_b, T)) continue;
    int count = 0;
    const double cost = score(T, nullptr, count);
    if (cost < best_cost) {
      best_cost = cost;
      best = T;
      // Adaptive number of hypotheses for 99.9% confidence with the inlier ratio seen so far.
      const double w =
          std::clamp(static_cast<double>(count) / static_cast<double>(matches.size()), 1e-3, 1.0);
      const double denom = std::log(std::max(1e-12, 1.0 - w * w * w));
      const double n_needed = denom < 0.0 ? std::log(1e-3) / denom : 1.0;
      needed = std::min(max_iterations, std::max(10, static_cast<int>(std::ceil(n_needed))));
    }
  }
  result.iterations = it;
  if (!std::isfinite(best_cost)) return result;

  // Refit on the inliers (with depth) twice.
  int count = 0;
  score(best, &result.inliers, count);
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<Eigen::Vector3d> a, b;
    for (int i : with_depth) {
      if (result.inliers[static_cast<std::size_t>(i)]) {
        a.push_back(matches[static_cast<std::size_t>(i)].point_ref);
        b.push_back(curr_points[static_cast<std::size_t>(i)]);
      }
    }
    SE3 T;
    if (!rigidFit(a, b, T)) break;
    std::vector<std::uint8_t> inl(matches.size());
    int c2 = 0;
    score(T, &inl, c2);
    if (c2 < count) break;
    best = T;
    result.inliers = inl;
    count = c2;
  }
  result.T_ref_curr = best;
  result.num_inliers = count;
  result.success = count >= 3;
  return result;
}

std::vector<int> maximumConsistentClique(const std::vector<Correspondence>& matches,
                                         const CameraIntrinsics& K, double tolerance_m,
                                         double depth_sigma_coeff) {
  std::vector<int> nodes;
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (matches[i].hasCurrDepth()) nodes.push_back(static_cast<int>(i));
  }
  const std::size_t n = nodes.size();
  if (n == 0) return {};
  std::vector<Eigen::Vector3d> p(n), q(n);
  std::vector<double> sigma(n);
  for (std::size_t k = 0; k < n; ++k) {
    const Correspondence& c = matches[static_cast<std::size_t>(nodes[k])];
    p[k] = c.point_ref;
    q[k] = c.pointCurr(K);
    sigma[k] = depthSigma(p[k].z(), depth_sigma_coeff) + depthSigma(q[k].z(), depth_sigma_coeff);
  }
  const std::size_t words = (n + 63) / 64;
  std::vector<std::uint64_t> adjacency(n * words, 0);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = i + 1; j < n; ++j) {
      const double dp = (p[i] - p[j]).norm();
      const double dq = (q[i] - q[j]).norm();
      if (std::abs(dp - dq) < tolerance_m + 2.0 * (sigma[i] + sigma[j])) {
        adjacency[i * words + j / 64] |= std::uint64_t{1} << (j % 64);
        adjacency[j * words + i / 64] |= std::uint64_t{1} << (i % 64);
      }
    }
  }
  std::vector<int> degree(n, 0);
  for (std::size_t v = 0; v < n; ++v) {
    for (std::size_t w = 0; w < words; ++w) {
      degree[v] += __builtin_popcountll(adjacency[v * words + w]);
    }
  }
  // Greedy, as FOVIS: start from the vertex of highest degree, then repeatedly add the candidate
  // of highest degree; candidates are the common neighbours of the clique so far.
  std::vector<std::uint64_t> candidates(words, ~std::uint64_t{0});
  if (n % 64) candidates[words - 1] = (std::uint64_t{1} << (n % 64)) - 1;
  std::vector<int> clique;
  while (true) {
    int best = -1;
    int best_degree = -1;
    for (std::size_t w = 0; w < words; ++w) {
      std::uint64_t bits = candidates[w];
      while (bits) {
        const std::size_t v = w * 64 + static_cast<std::size_t>(__builtin_ctzll(bits));
        bits &= bits - 1;
        if (degree[v] > best_degree) {
          best_degree = degree[v];
          best = static_cast<int>(v);
        }
      }
    }
    if (best < 0) break;
    clique.push_back(nodes[static_cast<std::size_t>(best)]);
    for (std::size_t w = 0; w < words; ++w) {
      candidates[w] &= adjacency[static_cast<std::size_t>(best) * words + w];
    }
  }
  std::sort(clique.begin(), clique.end());
  return clique;
}

namespace {

/// The factors that whiten a correspondence's residuals: 1 / pixel sigma, and 1 / the depth
/// difference's sigma (0 when the current depth is not measured or depth is not used). They do
/// not depend on the pose, so refinement computes them once.
struct Whitening {
  double inv_sigma_px = 1.0;
  double inv_sigma_depth = 0.0;
};

Whitening whiteningOf(const Correspondence& c, double depth_sigma_coeff) {
  Whitening w;
  w.inv_sigma_px = 1.0 / c.pixel_sigma_px;
  if (depth_sigma_coeff > 0.0 && c.hasCurrDepth()) {
    const double s_curr = depthSigma(c.depth_curr_m, depth_sigma_coeff);
    const double s_ref = depthSigma(c.point_ref.z(), depth_sigma_coeff);
    w.inv_sigma_depth = 1.0 / std::sqrt(s_curr * s_curr + s_ref * s_ref);
  }
  return w;
}

/// refinementResidual() with the inverse transform T_curr_ref = T_ref_curr^-1 and the whitening
/// precomputed.
int whitenedResidual(const Correspondence& c, const CameraIntrinsics& K, const SE3& T_curr_ref,
                     const Whitening& whitening, Eigen::Vector3d& residual,
                     Eigen::Matrix<double, 3, 6>& jacobian) {
  // q = T^-1 * P; with T' = T * exp(xi): q' = exp(-xi) * q ~ q - rho + [q]x phi.
  const Eigen::Vector3d q = T_curr_ref * c.point_ref;
  if (q.z() <= 1e-6) return 0;
  const double inv_z = 1.0 / q.z();
  const double x = q.x() * inv_z;
  const double y = q.y() * inv_z;
  const double inv_sigma = whitening.inv_sigma_px;
  residual(0) = (K.fx * x + K.cx - c.pixel_curr.x()) * inv_sigma;
  residual(1) = (K.fy * y + K.cy - c.pixel_curr.y()) * inv_sigma;
  Eigen::Matrix<double, 3, 6> dq_dxi;
  dq_dxi.leftCols<3>() = -Eigen::Matrix3d::Identity();
  dq_dxi.rightCols<3>() = skew(q);
  Eigen::Matrix<double, 2, 3> dpi_dq;
  dpi_dq << K.fx * inv_z, 0.0, -K.fx * x * inv_z, 0.0, K.fy * inv_z, -K.fy * y * inv_z;
  jacobian.topRows<2>() = inv_sigma * dpi_dq * dq_dxi;
  if (whitening.inv_sigma_depth > 0.0) {
    residual(2) = (q.z() - c.depth_curr_m) * whitening.inv_sigma_depth;
    jacobian.row(2) = whitening.inv_sigma_depth * dq_dxi.row(2);
    return 3;
  }
  residual(2) = 0.0;
  jacobian.row(2).setZero();
  return 2;
}

/// whitenedResidual() with the whitening computed here.
int residualFromInverse(const Correspondence& c, const CameraIntrinsics& K, const SE3& T_curr_ref,
                        double depth_sigma_coeff, Eigen::Vector3d& residual,
                        Eigen::Matrix<double, 3, 6>& jacobian) {
  return whitenedResidual(c, K, T_curr_ref, whiteningOf(c, depth_sigma_coeff), residual, jacobian);
}

/// H += w * J^T J for the rows of J, on H's upper triangle only (the lower is filled once the
/// sum is complete).
template <int kRows>
void addToUpperNormal(const Eigen::Matrix<double, kRows, 6>& J, double w, Matrix6d& H) {
  const Eigen::Matrix<double, kRows, 6> weighted = w * J;
  for (int col = 0; col < 6; ++col) {
    for (int row = 0; row <= col; ++row) {
      H(row, col) += weighted.col(row).dot(J.col(col));
    }
  }
}

/// Robust noise scales of the whitened reprojection and depth residuals at T_ref_curr: the
/// median residual over its expected value for unit Gaussian noise (norm of 2D: 1.1774 sigma;
/// absolute 1D: 0.6745 sigma). Clamped to [kMinNoiseScale, kMaxNoiseScale]; 1 with too few
/// residuals to tell.
void estimateNoiseScales(const std::vector<Correspondence>& matches,
                         const std::vector<std::uint8_t>& use, const CameraIntrinsics& K,
                         const SE3& T_ref_curr, double depth_sigma_coeff, double& scale_px,
                         double& scale_depth) {
  constexpr double kMinNoiseScale = 0.05;
  constexpr double kMaxNoiseScale = 20.0;
  constexpr std::size_t kMinResiduals = 12;
  std::vector<double> px, depth;
  Eigen::Vector3d r;
  Eigen::Matrix<double, 3, 6> J;
  const SE3 T_inv = T_ref_curr.inverse();
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (!use[i]) continue;
    const int rows = residualFromInverse(matches[i], K, T_inv, depth_sigma_coeff, r, J);
    if (rows >= 2) px.push_back(r.head<2>().norm());
    if (rows == 3) depth.push_back(std::abs(r(2)));
  }
  scale_px = 1.0;
  scale_depth = 1.0;
  if (px.size() >= kMinResiduals) {
    scale_px = std::clamp(medianInPlace(px) / 1.1774, kMinNoiseScale, kMaxNoiseScale);
  }
  if (depth.size() >= kMinResiduals) {
    scale_depth = std::clamp(medianInPlace(depth) / 0.6745, kMinNoiseScale, kMaxNoiseScale);
  }
}

}  // namespace

int refinementResidual(const Correspondence& c, const CameraIntrinsics& K, const SE3& T_ref_curr,
                       double depth_sigma_coeff, Eigen::Vector3d& residual,
                       Eigen::Matrix<double, 3, 6>& jacobian) {
  return residualFromInverse(c, K, T_ref_curr.inverse(), depth_sigma_coeff, residual, jacobian);
}

RefinementResult refinePose(const std::vector<Correspondence>& matches,
                            const std::vector<std::uint8_t>& use, const CameraIntrinsics& K,
                            const SE3& T_initial, const RefinementOptions& options) {
  RefinementResult result;
  result.T_ref_curr = T_initial;
  const double k = options.huber_k;
  // Noise scales (in units of the modelled sigmas) of the reprojection and depth residuals.
  double scale_px = 1.0;
  double scale_depth = 1.0;
  if (options.estimate_noise_scale) {
    estimateNoiseScales(matches, use, K, T_initial, options.depth_sigma_coeff, scale_px,
                        scale_depth);
  }
  const double inv_scale_px = 1.0 / scale_px;
  const double inv_scale_depth = 1.0 / scale_depth;
  std::vector<Whitening> whitening(matches.size());
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (use[i]) whitening[i] = whiteningOf(matches[i], options.depth_sigma_coeff);
  }

  struct Eval {
    double cost = 0.0;
    Matrix6d H = Matrix6d::Zero();
    Vector6d g = Vector6d::Zero();
    double sum_sq_whitened = 0.0;
    int rows = 0;
    int used = 0;
    double sum_sq_px = 0.0;
  };
  auto evaluate = [&](const SE3& T, bool with_system) {
    Eval e;
    Eigen::Vector3d r;
    Eigen::Matrix<double, 3, 6> J;
    const SE3 T_inv = T.inverse();
    for (std::size_t i = 0; i < matches.size(); ++i) {
      if (!use[i]) continue;
      const Correspondence& c = matches[i];
      const int rows = whitenedResidual(c, K, T_inv, whitening[i], r, J);
      if (rows == 0) {
        e.cost += 2.0 * k * 100.0;  // behind the camera: a large constant penalty
        continue;
      }
      r.head<2>() *= inv_scale_px;
      J.topRows<2>() *= inv_scale_px;
      r(2) *= inv_scale_depth;
      J.row(2) *= inv_scale_depth;
      ++e.used;
      e.sum_sq_px +=
          r.head<2>().squaredNorm() * c.pixel_sigma_px * c.pixel_sigma_px * scale_px * scale_px;
      const double s_reproj = r.head<2>().norm();
      const double w_reproj = huberWeight(s_reproj, k);
      e.cost += huberCost(s_reproj, k);
      e.sum_sq_whitened += w_reproj * r.head<2>().squaredNorm();
      e.rows += 2;
      double w_depth = 0.0;
      if (rows == 3) {
        const double s_depth = std::abs(r(2));
        w_depth = huberWeight(s_depth, k);
        e.cost += huberCost(s_depth, k);
        e.sum_sq_whitened += w_depth * r(2) * r(2);
        e.rows += 1;
      }
      if (with_system) {
        addToUpperNormal<2>(J.topRows<2>(), w_reproj, e.H);
        e.g.noalias() += w_reproj * J.topRows<2>().transpose() * r.head<2>();
        if (rows == 3) {
          addToUpperNormal<1>(J.row(2), w_depth, e.H);
          e.g.noalias() += w_depth * J.row(2).transpose() * r(2);
        }
      }
    }
    for (int col = 0; col < 6; ++col) {
      for (int row = col + 1; row < 6; ++row) e.H(row, col) = e.H(col, row);
    }
    return e;
  };

  SE3 T = T_initial;
  Eval current = evaluate(T, true);
  if (current.used < 3 || !std::isfinite(current.cost)) return result;
  double lambda = 1e-4;
  int it = 0;
  for (; it < options.max_iterations; ++it) {
    Matrix6d A = current.H;
    A.diagonal() += lambda * current.H.diagonal() + Vector6d::Constant(1e-12);
    const Vector6d delta = A.ldlt().solve(-current.g);
    if (!delta.allFinite()) break;
    const SE3 T_new = normalizedSE3(T * expSE3(delta));
    Eval next = evaluate(T_new, true);
    if (next.cost <= current.cost) {
      T = T_new;
      // Converged when the step is far below the noise (0.1 um, 1e-7 rad) or the cost stalls.
      const bool converged = delta.norm() < 1e-7 || current.cost - next.cost < 1e-6 * current.cost;
      current = next;
      lambda = std::max(1e-7, lambda * 0.1);
      if (converged) {
        ++it;
        break;
      }
    } else {
      lambda *= 10.0;
      if (lambda > 1e6) break;
    }
  }
  result.iterations = it;
  result.T_ref_curr = T;
  result.rms_reprojection_px =
      current.used > 0 ? std::sqrt(current.sum_sq_px / static_cast<double>(current.used)) : 0.0;
  // Covariance: inverse of the weighted normal equations, scaled by the residual variance.
  const int dof = current.rows - 6;
  Eigen::LDLT<Matrix6d> ldlt(current.H);
  if (dof <= 0 || ldlt.info() != Eigen::Success || !ldlt.isPositive()) return result;
  const double scale = current.sum_sq_whitened / static_cast<double>(dof);
  const Matrix6d cov = ldlt.solve(Matrix6d::Identity()) * scale;
  if (!cov.allFinite() || cov.diagonal().minCoeff() <= 0.0) return result;
  result.covariance = 0.5 * (cov + cov.transpose());
  result.success = T.matrix().allFinite();
  return result;
}

AlignedInliers alignInlierPatches(const FeatureSet& ref, const FeatureSet& curr,
                                  const CameraIntrinsics& K, const SE3& T_ref_curr,
                                  const std::vector<Correspondence>& matches,
                                  const std::vector<std::uint8_t>& inliers) {
  AlignedInliers aligned;
  if (ref.align_gray.empty() || curr.align_gray.empty() || ref.keypoints.size() != ref.size() ||
      curr.keypoints.size() != curr.size()) {
    return aligned;
  }
  const SE3 T_curr_ref = T_ref_curr.inverse();
  Eigen::Matrix3d K_matrix;
  K_matrix << K.fx, 0.0, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0;
  const Eigen::Matrix3d K_inverse = K_matrix.inverse();
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (!inliers[i]) continue;
    const Correspondence& c = matches[i];
    // The patch lies on the surface the depth shows around the feature: the plane whose inverse
    // depth is affine in the reference pixels, 1/z = 1/z0 + slope . (p - p0) (fronto-parallel
    // where the slope is unknown). A plane n^T X = 1 maps reference to current pixels by the
    // homography K (R + t n^T) K^-1. The template is warped by that homography, not by its affine
    // (first-order) part: on a slanted surface the magnification changes across the patch (the
    // floor of a corridor is magnified more below the feature than above it). An affine template
    // leaves that second-order term to the alignment, and since it is even in the offset it does
    // not average out: the aligned position moves by about curvature x patch second moment towards
    // the more magnified side, away from the focus of expansion. Relative to the flow this does not
    // shrink with the motion, so it lengthened the estimated translation (rendered corridor, exact
    // sensor: scale error +0.019% -> +0.011%).
    const std::size_t r = static_cast<std::size_t>(c.ref_index);
    const Eigen::Vector2d& ref_px = ref.pixels[r];
    const Eigen::Vector2d slope = r < ref.inverse_depth_gradient.size()
                                      ? ref.inverse_depth_gradient[r]
                                      : Eigen::Vector2d::Zero();
    const Eigen::Vector3d w(slope.x(), slope.y(),
                            1.0 / c.point_ref.z() - slope.dot(ref_px));  // 1/z = w . (u, v, 1)
    const Eigen::Vector3d normal = K_matrix.transpose() * w;             // n^T X = 1
    const Eigen::Matrix3d curr_from_ref =
        K_matrix * (T_curr_ref.linear() + T_curr_ref.translation() * normal.transpose()) *
        K_inverse;
    const Eigen::Vector3d p0 = curr_from_ref * Eigen::Vector3d(ref_px.x(), ref_px.y(), 1.0);
    if (!(p0.z() > 0.0)) continue;
    // In pixel offsets: from the current position p0 of the reference pixel to the reference.
    Eigen::Matrix3d to_curr = Eigen::Matrix3d::Identity();
    to_curr.topRightCorner<2, 1>() = p0.head<2>() / p0.z();
    Eigen::Matrix3d from_ref = Eigen::Matrix3d::Identity();
    from_ref.topRightCorner<2, 1>() = -ref_px;
    Eigen::Matrix3d offsets = from_ref * curr_from_ref.inverse() * to_curr;
    if (!offsets.allFinite() || !(std::abs(offsets(2, 2)) > 0.0)) continue;
    offsets /= offsets(2, 2);
    cv::Matx33d ref_from_curr;
    for (int row = 0; row < 3; ++row) {
      for (int col = 0; col < 3; ++col) ref_from_curr(row, col) = offsets(row, col);
    }
    cv::Point2f out;
    if (alignPatch(ref.align_gray, ref.keypoints[static_cast<std::size_t>(c.ref_index)].pt,
                   curr.align_gray, curr.keypoints[static_cast<std::size_t>(c.curr_index)].pt, 3.0,
                   out, ref_from_curr)) {
      aligned.match_indices.push_back(i);
      aligned.pixels_raw.push_back(out);
    }
  }
  return aligned;
}

}  // namespace slamd
