#pragma once
// PoseGraph: keyframe poses T_world_camera on SE(3) linked by relative measurements, optimised
// with Levenberg-Marquardt; the normal equations are sparse and factorised with CHOLMOD
// (SuiteSparse's supernodal Cholesky, through Eigen's CholmodSupport).
//
// Usage (one thread owns the graph, typically the back-end thread; there are no threads inside):
//   PoseGraph graph;
//   graph.addNode(0, T_world_kf0);           // the first node added is fixed (gauge)
//   graph.addNode(1, T_world_kf1);
//   graph.addEdge({0, 1, T_0_1, information, EdgeKind::kOdometry});
//   graph.addEdge({0, 57, T_0_57, information, EdgeKind::kLoop});
//   PoseGraphOptions options = PoseGraphOptions::fromConfig(BackendConfig::load(config));
//   PoseGraphResult result = graph.optimize(options);
//   if (result.status == OptimizationStatus::kConverged) use(graph.pose(57));
//
// Frames and conventions (common/se3.hpp): T_a_b maps points of frame b into frame a. An edge
// from node i to node j measures Z_i_j ~ T_world_i^-1 * T_world_j. Its error is
//   e = log(Z_i_j^-1 * T_world_i^-1 * T_world_j)   (6-vector [rho; phi], metres / radians)
// and its 6x6 information matrix (inverse covariance of e, same order) weights e^T * Omega * e.
// Poses are updated on the right: T = T_est * exp(xi).

#include <cstdint>
#include <unordered_map>
#include <vector>

#include "slamd/backend/backend_config.hpp"
#include "slamd/common/se3.hpp"

namespace slamd {

/// Odometry edges link consecutive keyframes of a tracking segment; every other kind is a
/// place-recognition measurement and gets the robust kernel.
enum class EdgeKind : std::int8_t {
  kOdometry = 0,
  kLoop = 1,            ///< a loop beyond the recent keyframes, confirmed by consistency
  kLocal = 2,           ///< a covisibility edge to an earlier keyframe of the same map
  kRelocalization = 3,  ///< ties a new tracking segment to the map
};

struct PoseGraphEdge {
  std::int64_t from_id = 0;         ///< node i
  std::int64_t to_id = 0;           ///< node j
  SE3 T_from_to = SE3::Identity();  ///< measured Z_i_j (metres)
  /// Inverse covariance of the error, order x y z rx ry rz (1/m^2, 1/rad^2).
  Matrix6d information = Matrix6d::Identity();
  EdgeKind kind = EdgeKind::kOdometry;
};

enum class OptimizationStatus : std::int8_t {
  kConverged = 0,      ///< a tolerance was met
  kMaxIterations = 1,  ///< stopped after max_iterations (the result is still the best found)
  kSolverFailure = 2,  ///< CHOLMOD could not factorise even with large damping
  kInvalidGraph = 3,   ///< an edge names a missing node, or nothing to optimise
};

const char* optimizationStatusName(OptimizationStatus status);

struct PoseGraphOptions {
  /// Cauchy runs a Huber solve first (convex, closes the true loops), then Cauchy.
  RobustKernel robust_kernel = RobustKernel::kCauchy;
  double robust_kernel_width = 2.0;  ///< whitened units (standard deviations)
  bool robust_odometry_edges = false;
  int max_iterations = 30;
  double initial_lambda = 1e-4;
  double relative_cost_tolerance = 1e-6;
  double step_tolerance = 1e-6;

  static PoseGraphOptions fromConfig(const BackendConfig& config);
};

struct PoseGraphResult {
  OptimizationStatus status = OptimizationStatus::kInvalidGraph;
  int iterations = 0;         ///< LM iterations (accepted or rejected steps)
  double initial_cost = 0.0;  ///< robust cost sum rho(e^T Omega e) before
  double final_cost = 0.0;    ///< and after
  double time_ms = 0.0;       ///< wall time of optimize()
  int num_nodes = 0;
  int num_edges = 0;
  /// Per edge (in addEdge order): the robust weight rho'(e^T Omega e) at the solution, in
  /// (0, 1]; a small weight marks an edge the kernel rejected.
  std::vector<double> edge_weights;
};

class PoseGraph {
 public:
  /// Adds (or replaces the initial value of) node `id` at T_world_node. The first node added is
  /// fixed unless setFixed() says otherwise.
  void addNode(std::int64_t id, const SE3& T_world_node);
  /// Adds an edge; returns false (and adds nothing) when a node is missing or ids are equal.
  bool addEdge(const PoseGraphEdge& edge);
  /// Fixes or frees a node (fixed nodes keep their pose; at least one should be fixed).
  void setFixed(std::int64_t id, bool fixed);
  bool isFixed(std::int64_t id) const { return fixed_[static_cast<std::size_t>(index_.at(id))]; }
  /// Removes a node and every edge that names it; returns those edges (in addEdge order).
  /// Nothing happens (and nothing is returned) for an unknown id.
  std::vector<PoseGraphEdge> removeNode(std::int64_t id);

  bool hasNode(std::int64_t id) const { return index_.count(id) != 0; }
  const SE3& pose(std::int64_t id) const { return poses_[index_.at(id)]; }
  void setPose(std::int64_t id, const SE3& T_world_node) { poses_[index_.at(id)] = T_world_node; }
  std::size_t numNodes() const { return ids_.size(); }
  std::size_t numEdges() const { return edges_.size(); }
  const std::vector<std::int64_t>& nodeIds() const { return ids_; }
  const std::vector<PoseGraphEdge>& edges() const { return edges_; }

  /// Levenberg-Marquardt over all free nodes; updates the poses in place.
  PoseGraphResult optimize(const PoseGraphOptions& options);
  /// The same over the listed nodes only (a local window): every other node is held at its pose
  /// for this call (nodes fixed with setFixed stay fixed). Edges between held nodes are constant
  /// and skipped; the cost reported still covers every edge. Unknown ids are ignored.
  PoseGraphResult optimize(const PoseGraphOptions& options,
                           const std::vector<std::int64_t>& free_ids);

  /// The robust cost of the current poses.
  double cost(const PoseGraphOptions& options) const;

 private:
  /// LM over the free nodes, linearising and costing only the `active` edges (indices into
  /// edges_ with at least one free end).
  OptimizationStatus levenbergMarquardt(const PoseGraphOptions& options,
                                        const std::vector<std::size_t>& active, int max_iterations,
                                        int& iterations);
  /// An edge's robust cost at the current poses; its IRLS weight in *weight when not null.
  double edgeCost(const PoseGraphEdge& edge, const PoseGraphOptions& options, double* weight) const;
  double activeCost(const PoseGraphOptions& options, const std::vector<std::size_t>& active) const;

  std::vector<std::int64_t> ids_;
  std::vector<SE3, Eigen::aligned_allocator<SE3>> poses_;
  std::vector<bool> fixed_;
  std::unordered_map<std::int64_t, int> index_;
  std::vector<PoseGraphEdge> edges_;
};

/// The error e = log(Z^-1 * T_world_i^-1 * T_world_j) of one edge and, when requested, its
/// Jacobians with respect to right perturbations of T_world_i and T_world_j.
Vector6d poseGraphEdgeError(const SE3& T_from_to_measured, const SE3& T_world_i,
                            const SE3& T_world_j, Matrix6d* jacobian_i = nullptr,
                            Matrix6d* jacobian_j = nullptr);

/// The edge b -> a measuring the same relative pose as a -> b: Z^-1, with the covariance
/// carried to the other end (right perturbations: Sigma' = Ad(Z) Sigma Ad(Z)^T).
PoseGraphEdge invertedEdge(const PoseGraphEdge& edge);

/// The edge a -> c through b from the edges a -> b and b -> c (b's pose eliminated): Z_ab * Z_bc,
/// covariance Ad(Z_bc^-1) Sigma_ab Ad(Z_bc^-1)^T + Sigma_bc (the two measurements taken as
/// independent). `kind` is the kind of the result.
PoseGraphEdge composedEdge(const PoseGraphEdge& a_to_b, const PoseGraphEdge& b_to_c, EdgeKind kind);

/// Inverse of the right Jacobian of SE(3) at xi = [rho; phi]:
/// log(exp(xi) * exp(delta)) = xi + rightJacobianInverseSE3(xi) * delta + O(|delta|^2).
Matrix6d rightJacobianInverseSE3(const Vector6d& xi);

/// Robust kernel rho(s) of the squared whitened error s and its derivative rho'(s) (the IRLS
/// weight); width k in standard deviations. Huber: s for s <= k^2, 2k*sqrt(s) - k^2 beyond;
/// Cauchy: k^2 * log(1 + s / k^2).
double robustCost(RobustKernel kernel, double width, double squared_error, double* weight);

}  // namespace slamd
