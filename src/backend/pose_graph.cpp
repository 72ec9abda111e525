#include "slamd/backend/pose_graph.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <iterator>
#include <limits>

// GCC 12 reports a false -Wnull-dereference inside Eigen's sparse headers when
// CholmodSupport views a SparseMatrix; the diagnostic is located in these headers.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wnull-dereference"
#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>
#pragma GCC diagnostic pop

namespace slamd {

namespace {

// Q(rho, phi) of the SE(3) left Jacobian [[J, Q], [0, J]] in the [rho; phi] order.
Eigen::Matrix3d leftJacobianQ(const Eigen::Vector3d& rho, const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  const Eigen::Matrix3d R = skew(rho);
  const Eigen::Matrix3d P = skew(phi);
  double c1, c2, c3;
  if (theta < 1e-4) {
    // Series limits of the coefficients below (errors O(theta^2), far under double noise here).
    const double t2 = theta * theta;
    c1 = 1.0 / 6.0 - t2 / 120.0;
    c2 = 1.0 / 24.0 - t2 / 720.0;
    c3 = 1.0 / 120.0 - t2 / 2520.0;
  } else {
    const double t2 = theta * theta;
    const double s = std::sin(theta);
    const double c = std::cos(theta);
    c1 = (theta - s) / (t2 * theta);
    c2 = (t2 + 2.0 * c - 2.0) / (2.0 * t2 * t2);
    c3 = (2.0 * theta - 3.0 * s + theta * c) / (2.0 * t2 * t2 * theta);
  }
  const Eigen::Matrix3d PR = P * R;
  const Eigen::Matrix3d RP = R * P;
  const Eigen::Matrix3d PRP = PR * P;
  return 0.5 * R + c1 * (PR + RP + PRP) + c2 * (P * PR + RP * P - 3.0 * PRP) +
         c3 * (PRP * P + P * PRP);
}

}  // namespace

const char* optimizationStatusName(OptimizationStatus status) {
  switch (status) {
    case OptimizationStatus::kConverged:
      return "converged";
    case OptimizationStatus::kMaxIterations:
      return "max_iterations";
    case OptimizationStatus::kSolverFailure:
      return "solver_failure";
    case OptimizationStatus::kInvalidGraph:
      return "invalid_graph";
  }
  return "unknown";
}

PoseGraphOptions PoseGraphOptions::fromConfig(const BackendConfig& config) {
  PoseGraphOptions o;
  o.robust_kernel = config.robust_kernel;
  o.robust_kernel_width = config.robust_kernel_width;
  o.robust_odometry_edges = config.robust_odometry_edges;
  o.max_iterations = config.max_iterations;
  o.initial_lambda = config.initial_lambda;
  o.relative_cost_tolerance = config.relative_cost_tolerance;
  o.step_tolerance = config.step_tolerance;
  return o;
}

Matrix6d rightJacobianInverseSE3(const Vector6d& xi) {
  // J_r(xi) = J_l(-xi); J_l = [[J, Q], [0, J]] so J_l^-1 = [[J^-1, -J^-1 Q J^-1], [0, J^-1]].
  const Eigen::Vector3d rho = -xi.head<3>();
  const Eigen::Vector3d phi = -xi.tail<3>();
  const Eigen::Matrix3d J_inv = leftJacobianInverseSO3(phi);
  const Eigen::Matrix3d Q = leftJacobianQ(rho, phi);
  Matrix6d result = Matrix6d::Zero();
  result.topLeftCorner<3, 3>() = J_inv;
  result.topRightCorner<3, 3>() = -J_inv * Q * J_inv;
  result.bottomRightCorner<3, 3>() = J_inv;
  return result;
}

Vector6d poseGraphEdgeError(const SE3& T_from_to_measured, const SE3& T_world_i,
                            const SE3& T_world_j, Matrix6d* jacobian_i, Matrix6d* jacobian_j) {
  const SE3 T_i_j = T_world_i.inverse() * T_world_j;
  const Vector6d e = logSE3(T_from_to_measured.inverse() * T_i_j);
  if (jacobian_i != nullptr || jacobian_j != nullptr) {
    // E = Z^-1 T_i^-1 T_j. Right-perturbing T_j: E exp(dj), so de = Jr^-1(e) dj. Right-perturbing
    // T_i: Z^-1 exp(-di) T_i^-1 T_j = E exp(-Ad(T_j^-1 T_i) di), so de = -Jr^-1(e) Ad(T_i_j^-1) di.
    const Matrix6d Jr_inv = rightJacobianInverseSE3(e);
    if (jacobian_j != nullptr) *jacobian_j = Jr_inv;
    if (jacobian_i != nullptr) *jacobian_i = -Jr_inv * adjointSE3(T_i_j.inverse());
  }
  return e;
}

double robustCost(RobustKernel kernel, double width, double squared_error, double* weight) {
  const double k2 = width * width;
  switch (kernel) {
    case RobustKernel::kHuber:
      if (squared_error <= k2) {
        if (weight != nullptr) *weight = 1.0;
        return squared_error;
      } else {
        const double r = std::sqrt(squared_error);
        if (weight != nullptr) *weight = width / r;
        return 2.0 * width * r - k2;
      }
    case RobustKernel::kCauchy:
      if (weight != nullptr) *weight = 1.0 / (1.0 + squared_error / k2);
      return k2 * std::log1p(squared_error / k2);
    case RobustKernel::kNone:
      break;
  }
  if (weight != nullptr) *weight = 1.0;
  return squared_error;
}

void PoseGraph::addNode(std::int64_t id, const SE3& T_world_node) {
  const auto it = index_.find(id);
  if (it != index_.end()) {
    poses_[it->second] = T_world_node;
    return;
  }
  index_[id] = static_cast<int>(ids_.size());
  ids_.push_back(id);
  poses_.push_back(T_world_node);
  fixed_.push_back(ids_.size() == 1);
}

bool PoseGraph::addEdge(const PoseGraphEdge& edge) {
  if (edge.from_id == edge.to_id || !hasNode(edge.from_id) || !hasNode(edge.to_id)) return false;
  edges_.push_back(edge);
  return true;
}

void PoseGraph::setFixed(std::int64_t id, bool fixed) { fixed_[index_.at(id)] = fixed; }

std::vector<PoseGraphEdge> PoseGraph::removeNode(std::int64_t id) {
  std::vector<PoseGraphEdge> removed;
  const auto it = index_.find(id);
  if (it == index_.end()) return removed;
  const auto position = static_cast<std::size_t>(it->second);
  const auto names = [id](const PoseGraphEdge& edge) {
    return edge.from_id == id || edge.to_id == id;
  };
  std::copy_if(edges_.begin(), edges_.end(), std::back_inserter(removed), names);
  edges_.erase(std::remove_if(edges_.begin(), edges_.end(), names), edges_.end());
  const auto offset = static_cast<std::ptrdiff_t>(position);
  ids_.erase(ids_.begin() + offset);
  poses_.erase(poses_.begin() + offset);
  fixed_.erase(fixed_.begin() + offset);
  index_.erase(it);
  for (std::size_t n = position; n < ids_.size(); ++n) index_[ids_[n]] = static_cast<int>(n);
  return removed;
}

namespace {

Matrix6d covarianceOf(const PoseGraphEdge& edge) {
  const Matrix6d covariance = edge.information.inverse();
  return 0.5 * (covariance + covariance.transpose());
}

Matrix6d informationOf(const Matrix6d& covariance) {
  const Matrix6d information = covariance.inverse();
  return 0.5 * (information + information.transpose());
}

}  // namespace

PoseGraphEdge invertedEdge(const PoseGraphEdge& edge) {
  const Matrix6d ad = adjointSE3(edge.T_from_to);
  PoseGraphEdge out{edge.to_id, edge.from_id, edge.T_from_to.inverse(), Matrix6d::Identity(),
                    edge.kind};
  out.information = informationOf(ad * covarianceOf(edge) * ad.transpose());
  return out;
}

PoseGraphEdge composedEdge(const PoseGraphEdge& a_to_b, const PoseGraphEdge& b_to_c,
                           EdgeKind kind) {
  const Matrix6d ad = adjointSE3(b_to_c.T_from_to.inverse());
  PoseGraphEdge out{a_to_b.from_id, b_to_c.to_id, a_to_b.T_from_to * b_to_c.T_from_to,
                    Matrix6d::Identity(), kind};
  out.information =
      informationOf(ad * covarianceOf(a_to_b) * ad.transpose() + covarianceOf(b_to_c));
  return out;
}

namespace {

bool isRobust(const PoseGraphEdge& edge, const PoseGraphOptions& options) {
  return edge.kind != EdgeKind::kOdometry || options.robust_odometry_edges;
}

}  // namespace

double PoseGraph::cost(const PoseGraphOptions& options) const {
  double total = 0.0;
  for (const PoseGraphEdge& edge : edges_) total += edgeCost(edge, options, nullptr);
  return total;
}

PoseGraphResult PoseGraph::optimize(const PoseGraphOptions& options,
                                    const std::vector<std::int64_t>& free_ids) {
  const std::vector<bool> saved = fixed_;
  std::vector<bool> window(ids_.size(), false);
  for (std::int64_t id : free_ids) {
    const auto it = index_.find(id);
    if (it != index_.end()) window[static_cast<std::size_t>(it->second)] = true;
  }
  for (std::size_t n = 0; n < ids_.size(); ++n) fixed_[n] = saved[n] || !window[n];
  PoseGraphResult result = optimize(options);
  fixed_ = saved;
  return result;
}

double PoseGraph::edgeCost(const PoseGraphEdge& edge, const PoseGraphOptions& options,
                           double* weight) const {
  const Vector6d e = poseGraphEdgeError(edge.T_from_to, poses_[index_.at(edge.from_id)],
                                        poses_[index_.at(edge.to_id)]);
  const double s = e.dot(edge.information * e);
  if (weight != nullptr) *weight = 1.0;
  return isRobust(edge, options)
             ? robustCost(options.robust_kernel, options.robust_kernel_width, s, weight)
             : s;
}

double PoseGraph::activeCost(const PoseGraphOptions& options,
                             const std::vector<std::size_t>& active) const {
  double total = 0.0;
  for (std::size_t k : active) total += edgeCost(edges_[k], options, nullptr);
  return total;
}

PoseGraphResult PoseGraph::optimize(const PoseGraphOptions& options) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  PoseGraphResult result;
  result.num_nodes = static_cast<int>(ids_.size());
  result.num_edges = static_cast<int>(edges_.size());
  // Only edges with a free end change: LM works on those alone, so a local window costs the
  // same in a graph of 100 keyframes as in one of 5000. The held edges' cost and weight are
  // constant and taken once.
  std::vector<std::size_t> active;
  double held_cost = 0.0;
  result.edge_weights.assign(edges_.size(), 1.0);
  for (std::size_t k = 0; k < edges_.size(); ++k) {
    const PoseGraphEdge& edge = edges_[k];
    if (!fixed_[static_cast<std::size_t>(index_.at(edge.from_id))] ||
        !fixed_[static_cast<std::size_t>(index_.at(edge.to_id))]) {
      active.push_back(k);
    } else {
      held_cost += edgeCost(edge, options, &result.edge_weights[k]);
    }
  }
  result.initial_cost = held_cost + activeCost(options, active);
  OptimizationStatus status = OptimizationStatus::kInvalidGraph;
  if (!active.empty()) {
    if (options.robust_kernel == RobustKernel::kCauchy) {
      // Cauchy is not convex: loop edges whose error is large only because of odometry drift
      // would be switched off from the start. A Huber (convex) solve first closes the true loops;
      // Cauchy then rejects the edges that still disagree with everything else.
      PoseGraphOptions warm_start = options;
      warm_start.robust_kernel = RobustKernel::kHuber;
      status = levenbergMarquardt(warm_start, active, options.max_iterations, result.iterations);
    }
    if (status != OptimizationStatus::kSolverFailure) {
      status = levenbergMarquardt(options, active, options.max_iterations - result.iterations,
                                  result.iterations);
    }
  }
  result.status = status;
  result.final_cost = held_cost;
  for (std::size_t k : active) {
    result.final_cost += edgeCost(edges_[k], options, &result.edge_weights[k]);
  }
  result.time_ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  return result;
}

OptimizationStatus PoseGraph::levenbergMarquardt(const PoseGraphOptions& options,
                                                 const std::vector<std::size_t>& active,
                                                 int max_iterations, int& iterations) {
  // Free nodes get consecutive variable blocks; fixed nodes get -1.
  std::vector<int> block(ids_.size(), -1);
  int num_free = 0;
  for (std::size_t n = 0; n < ids_.size(); ++n) {
    if (!fixed_[n]) block[n] = num_free++;
  }
  const int dim = 6 * num_free;

  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> solver;
  bool pattern_analysed = false;
  double lambda = options.initial_lambda;
  double current_cost = activeCost(options, active);
  std::vector<Eigen::Triplet<double>> triplets;
  triplets.reserve(active.size() * 3 * 36 + static_cast<std::size_t>(dim));
  Eigen::VectorXd gradient(dim);
  Eigen::SparseMatrix<double> H(dim, dim);

  const auto addBlock = [&triplets](int row_block, int col_block, const Matrix6d& m) {
    // Lower triangle only: CHOLMOD reads the lower part of a symmetric matrix.
    for (int c = 0; c < 6; ++c) {
      for (int r = 0; r < 6; ++r) {
        const int row = 6 * row_block + r;
        const int col = 6 * col_block + c;
        if (row >= col) triplets.emplace_back(row, col, m(r, c));
      }
    }
  };

  OptimizationStatus status = OptimizationStatus::kMaxIterations;
  bool relinearise = true;
  Eigen::VectorXd diagonal(dim);
  for (int local = 0; local < max_iterations; ++local) {
    if (relinearise) {
      triplets.clear();
      gradient.setZero();
      for (std::size_t k : active) {
        const PoseGraphEdge& edge = edges_[k];
        const int ni = index_.at(edge.from_id);
        const int nj = index_.at(edge.to_id);
        Matrix6d Ji, Jj;
        const Vector6d e = poseGraphEdgeError(edge.T_from_to, poses_[ni], poses_[nj], &Ji, &Jj);
        double w = 1.0;
        if (isRobust(edge, options)) {
          robustCost(options.robust_kernel, options.robust_kernel_width,
                     e.dot(edge.information * e), &w);
        }
        const Matrix6d W = w * edge.information;
        const int bi = block[ni];
        const int bj = block[nj];
        if (bi >= 0) {
          addBlock(bi, bi, Ji.transpose() * W * Ji);
          gradient.segment<6>(6 * bi) += Ji.transpose() * W * e;
        }
        if (bj >= 0) {
          addBlock(bj, bj, Jj.transpose() * W * Jj);
          gradient.segment<6>(6 * bj) += Jj.transpose() * W * e;
        }
        if (bi >= 0 && bj >= 0) {
          if (bi > bj) {
            addBlock(bi, bj, Ji.transpose() * W * Jj);
          } else {
            addBlock(bj, bi, Jj.transpose() * W * Ji);
          }
        }
      }
      // The diagonal is always present so the sparsity pattern never changes with damping.
      for (int d = 0; d < dim; ++d) triplets.emplace_back(d, d, 0.0);
      H.setFromTriplets(triplets.begin(), triplets.end());
      diagonal = H.diagonal();
      relinearise = false;
    }

    ++iterations;
    Eigen::SparseMatrix<double> H_damped = H;
    for (int d = 0; d < dim; ++d) {
      H_damped.coeffRef(d, d) += lambda * std::max(diagonal(d), 1e-6);
    }
    if (!pattern_analysed) {
      solver.analyzePattern(H_damped);
      pattern_analysed = true;
    }
    solver.factorize(H_damped);
    if (solver.info() != Eigen::Success) {
      lambda *= 10.0;
      if (lambda > 1e12) return OptimizationStatus::kSolverFailure;
      continue;
    }
    const Eigen::VectorXd step = solver.solve(-gradient);
    if (solver.info() != Eigen::Success || !step.allFinite()) {
      lambda *= 10.0;
      if (lambda > 1e12) return OptimizationStatus::kSolverFailure;
      continue;
    }

    std::vector<SE3, Eigen::aligned_allocator<SE3>> saved;  // the free poses, in block order
    saved.reserve(static_cast<std::size_t>(num_free));
    for (std::size_t n = 0; n < ids_.size(); ++n) {
      if (block[n] >= 0) {
        saved.push_back(poses_[n]);
        poses_[n] = normalizedSE3(poses_[n] * expSE3(step.segment<6>(6 * block[n])));
      }
    }
    const double new_cost = activeCost(options, active);
    if (new_cost < current_cost) {
      const double decrease = (current_cost - new_cost) / std::max(current_cost, 1e-300);
      current_cost = new_cost;
      lambda = std::max(lambda / 5.0, 1e-12);
      relinearise = true;
      if (decrease < options.relative_cost_tolerance ||
          step.lpNorm<Eigen::Infinity>() < options.step_tolerance) {
        status = OptimizationStatus::kConverged;
        break;
      }
    } else {
      for (std::size_t n = 0; n < ids_.size(); ++n) {
        if (block[n] >= 0) poses_[n] = saved[static_cast<std::size_t>(block[n])];
      }
      lambda *= 5.0;
      if (step.lpNorm<Eigen::Infinity>() < options.step_tolerance || lambda > 1e12) {
        // No descent direction left at any damping: the current poses are a minimum.
        status = OptimizationStatus::kConverged;
        break;
      }
    }
  }
  return status;
}

}  // namespace slamd
