#pragma once
// Trajectory error metrics that reproduce the TUM RGB-D benchmark's tools numerically:
// associate.py (timestamp association), evaluate_ate.py (absolute trajectory error after a
// closed-form alignment) and evaluate_rpe.py (relative pose error over a fixed delta).
//
// Usage:
//   const Trajectory gt = readTumTrajectory("groundtruth.txt");
//   const Trajectory est = readTumTrajectory("estimate.txt");
//   eval::AteResult ate = eval::computeAte(gt, est);          // SE(3), max difference 0.02 s
//   std::cout << ate.translation_m.rmse;                      // metres
//   eval::RpeOptions rpe_options;                             // 1 s fixed delta
//   eval::RpeResult rpe = eval::computeRpe(gt, est, rpe_options);
//
// Frames and units: both trajectories hold T_world_camera with timestamps in seconds; each may
// use its own world frame (ATE aligns the estimate's onto the ground truth's). Errors are metres
// for translation; rotations are reported in degrees (as evaluate_rpe.py prints them).
//
// Compatibility notes (what the reference scripts do and these functions do too):
// - Duplicate timestamps: the scripts read files into a dict, so the last line with a given
//   timestamp wins.
// - Association (associate.py): every pair with |t_first - (t_second + offset)| strictly below
//   max_difference is a candidate; candidates are taken greedily by increasing difference (ties
//   by first, then second timestamp), each timestamp used at most once; result sorted by the
//   first timestamp.
// - ATE (evaluate_ate.py): the estimate's positions (times `scale`) are aligned to the ground
//   truth's with Horn's closed form (SVD; reflection corrected); error = |R p_est + t - p_gt|.
//   Sim(3) alignment (Umeyama's scale, as evo's --correct_scale) is an option.
// - RPE (evaluate_rpe.py --fixed_delta): for each estimate pose i the pose j whose index value
//   (time, frame number, distance or angle along the estimate) is closest to index(i) + delta,
//   found with the script's binary search; pairs with j == last pose are skipped, as are pairs
//   whose closest ground-truth stamps differ by more than twice the median ground-truth interval.
//   error = (E_i^-1 E_j)^-1 (G_i^-1 G_j) in the script's order; translation = |t|, rotation =
//   angle. The script samples at most 10000 pairs at random; here all pairs are used unless
//   max_pairs is set (then a seeded sample, so results differ from the script's random choice).
//
// Thread safety: pure functions.

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "slamd/common/trajectory.hpp"

namespace slamd::eval {

/// Summary statistics of a set of non-negative errors, as numpy computes them (std is the
/// population standard deviation, median interpolates between the two middle values).
struct ErrorStatistics {
  std::size_t count = 0;
  double rmse = 0.0;
  double mean = 0.0;
  double median = 0.0;
  double std = 0.0;
  double min = 0.0;
  double max = 0.0;
};

ErrorStatistics computeStatistics(const std::vector<double>& values);

/// Same statistics with every value multiplied by `factor` (e.g. radians to degrees).
ErrorStatistics scaledStatistics(const ErrorStatistics& statistics, double factor);

struct AssociationOptions {
  double max_difference_s = 0.02;  ///< candidates must differ by strictly less than this
  double offset_s = 0.0;           ///< added to the second list's timestamps
};

/// One associated pair: indices into the two input lists.
struct AssociatedPair {
  std::size_t first = 0;
  std::size_t second = 0;
};

/// associate.py's association of two timestamp lists (seconds). Duplicate timestamps resolve to
/// the last index holding them. Result sorted by the first list's timestamp.
std::vector<AssociatedPair> associateTimestamps(const std::vector<double>& first_s,
                                                const std::vector<double>& second_s,
                                                const AssociationOptions& options = {});

enum class AlignmentModel {
  kNone,  ///< no alignment (trajectories already share a world frame)
  kSE3,   ///< rotation + translation (evaluate_ate.py, evo default)
  kSim3,  ///< rotation + translation + scale (monocular-style, evo --correct_scale)
};

/// Parses "none|se3|sim3"; throws std::invalid_argument otherwise.
AlignmentModel parseAlignmentModel(const std::string& text);
const char* alignmentModelName(AlignmentModel model);

/// A similarity transform mapping estimate-world points to ground-truth-world points:
/// p_gt = scale * R_gt_est * p_est + t_gt_est_m.
struct Alignment {
  Eigen::Matrix3d R_gt_est = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t_gt_est_m = Eigen::Vector3d::Zero();
  double scale = 1.0;

  Eigen::Vector3d apply(const Eigen::Vector3d& p_est) const {
    return scale * (R_gt_est * p_est) + t_gt_est_m;
  }
};

/// Closed-form least-squares alignment of corresponding points (columns), minimising
/// sum |apply(est_i) - gt_i|^2. Needs at least 3 non-collinear points for a unique rotation.
Alignment alignPoints(const Eigen::Matrix3Xd& points_est, const Eigen::Matrix3Xd& points_gt,
                      AlignmentModel model);

struct AteOptions {
  AssociationOptions association;
  AlignmentModel alignment = AlignmentModel::kSE3;
  double scale = 1.0;  ///< estimate positions are multiplied by this before alignment
};

/// One associated pose pair after alignment.
struct AtePair {
  double timestamp_gt_s = 0.0;
  double timestamp_est_s = 0.0;
  Eigen::Vector3d position_gt_m = Eigen::Vector3d::Zero();   ///< ground-truth world frame
  Eigen::Vector3d position_est_m = Eigen::Vector3d::Zero();  ///< aligned, ground-truth frame
  double error_m = 0.0;
};

struct AteResult {
  std::vector<AtePair> pairs;  ///< sorted by ground-truth time
  Alignment alignment;
  ErrorStatistics translation_m;
};

/// Absolute trajectory error. Throws std::runtime_error when fewer than 2 pairs associate (the
/// message suggests checking --max-difference and --offset).
AteResult computeAte(const Trajectory& groundtruth, const Trajectory& estimate,
                     const AteOptions& options = {});

enum class DeltaUnit {
  kSeconds,  ///< "s": time
  kFrames,   ///< "f": pose index
  kMetres,   ///< "m": distance travelled along the estimate
  kRadians,  ///< "rad": rotation accumulated along the estimate
  kDegrees,  ///< "deg"
};

/// Parses "s|f|m|rad|deg"; throws std::invalid_argument otherwise.
DeltaUnit parseDeltaUnit(const std::string& text);
const char* deltaUnitName(DeltaUnit unit);

struct RpeOptions {
  double delta = 1.0;
  DeltaUnit delta_unit = DeltaUnit::kSeconds;
  double offset_s = 0.0;      ///< added to the estimate's timestamps
  double scale = 1.0;         ///< estimate relative translations are multiplied by this
  std::size_t max_pairs = 0;  ///< 0 = every pair; otherwise a seeded random sample
  std::uint32_t seed = 42;
};

struct RpePair {
  double timestamp_est_0_s = 0.0;
  double timestamp_est_1_s = 0.0;
  double timestamp_gt_0_s = 0.0;
  double timestamp_gt_1_s = 0.0;
  double translation_error_m = 0.0;
  double rotation_error_rad = 0.0;
};

struct RpeResult {
  std::vector<RpePair> pairs;  ///< in the order of the first estimate pose
  ErrorStatistics translation_m;
  ErrorStatistics rotation_deg;
};

/// Relative pose error. Throws std::runtime_error when fewer than 2 pairs can be formed.
RpeResult computeRpe(const Trajectory& groundtruth, const Trajectory& estimate,
                     const RpeOptions& options = {});

/// evaluate_rpe.py's find_closest_index: a binary search over a sorted list that returns the
/// index of the closest value among those it visits (the list must not be empty).
std::size_t findClosestIndex(const std::vector<double>& sorted_values, double value);

/// The poses of a trajectory as the reference scripts see them: sorted by timestamp, one per
/// timestamp (the last line wins).
Trajectory uniqueSortedByTime(const Trajectory& trajectory);

}  // namespace slamd::eval
