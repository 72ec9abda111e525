#include "slamd/eval/trajectory_error.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>
#include <tuple>

#include <Eigen/SVD>

#include "slamd/common/latency_histogram.hpp"
#include "slamd/common/timestamp_association.hpp"

namespace slamd::eval {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// evaluate_rpe.py's compute_angle: arccos of the clamped (trace - 1) / 2.
double scriptRotationAngleRad(const Eigen::Matrix3d& R) {
  return std::acos(std::min(1.0, std::max(-1.0, (R.trace() - 1.0) / 2.0)));
}

std::vector<double> timestampsOf(const Trajectory& trajectory) {
  std::vector<double> stamps;
  stamps.reserve(trajectory.size());
  for (const auto& pose : trajectory) stamps.push_back(pose.timestamp_s);
  return stamps;
}

}  // namespace

ErrorStatistics computeStatistics(const std::vector<double>& values) {
  ErrorStatistics s;
  s.count = values.size();
  if (values.empty()) return s;
  const double n = static_cast<double>(values.size());
  double sum = 0.0;
  double sum_squares = 0.0;
  for (double v : values) {
    sum += v;
    sum_squares += v * v;
  }
  s.rmse = std::sqrt(sum_squares / n);
  s.mean = sum / n;
  double deviation_squares = 0.0;
  for (double v : values) deviation_squares += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(deviation_squares / n);
  s.median = percentile(values, 50.0);
  const auto [min_it, max_it] = std::minmax_element(values.begin(), values.end());
  s.min = *min_it;
  s.max = *max_it;
  return s;
}

ErrorStatistics scaledStatistics(const ErrorStatistics& statistics, double factor) {
  ErrorStatistics s = statistics;
  s.rmse *= factor;
  s.mean *= factor;
  s.median *= factor;
  s.std *= std::abs(factor);
  s.min *= factor;
  s.max *= factor;
  if (factor < 0.0) std::swap(s.min, s.max);
  return s;
}

std::vector<AssociatedPair> associateTimestamps(const std::vector<double>& first_s,
                                                const std::vector<double>& second_s,
                                                const AssociationOptions& options) {
  // The scripts read each file into a dict: a repeated timestamp keeps its last line.
  auto uniqueKeys = [](const std::vector<double>& stamps) {
    std::map<double, std::size_t> last_index;
    for (std::size_t i = 0; i < stamps.size(); ++i) last_index[stamps[i]] = i;
    std::vector<double> keys;
    std::vector<std::size_t> indices;
    for (const auto& [stamp, index] : last_index) {
      keys.push_back(stamp);
      indices.push_back(index);
    }
    return std::make_pair(keys, indices);
  };
  const auto [first_keys, first_indices] = uniqueKeys(first_s);
  const auto [second_keys, second_indices] = uniqueKeys(second_s);
  std::vector<AssociatedPair> pairs;
  for (const auto& [i, j] : slamd::associateTimestamps(
           first_keys, second_keys, options.max_difference_s, options.offset_s)) {
    pairs.push_back({first_indices[i], second_indices[j]});
  }
  return pairs;
}

AlignmentModel parseAlignmentModel(const std::string& text) {
  if (text == "none") return AlignmentModel::kNone;
  if (text == "se3") return AlignmentModel::kSE3;
  if (text == "sim3") return AlignmentModel::kSim3;
  throw std::invalid_argument("alignment '" + text + "': allowed values are none, se3, sim3");
}

const char* alignmentModelName(AlignmentModel model) {
  switch (model) {
    case AlignmentModel::kNone:
      return "none";
    case AlignmentModel::kSE3:
      return "se3";
    case AlignmentModel::kSim3:
      return "sim3";
  }
  return "?";
}

Alignment alignPoints(const Eigen::Matrix3Xd& points_est, const Eigen::Matrix3Xd& points_gt,
                      AlignmentModel model) {
  if (points_est.cols() != points_gt.cols()) {
    throw std::invalid_argument("alignPoints: point sets differ in size");
  }
  Alignment alignment;
  if (model == AlignmentModel::kNone || points_est.cols() == 0) return alignment;
  const Eigen::Vector3d mean_est = points_est.rowwise().mean();
  const Eigen::Vector3d mean_gt = points_gt.rowwise().mean();
  const Eigen::Matrix3Xd centred_est = points_est.colwise() - mean_est;
  const Eigen::Matrix3Xd centred_gt = points_gt.colwise() - mean_gt;
  // Cross-covariance gt * est^T = U D V^T; R = U S V^T with S fixing a reflection (Horn/Umeyama).
  const Eigen::Matrix3d W = centred_gt * centred_est.transpose();
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(W, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d s(1.0, 1.0, 1.0);
  if (svd.matrixU().determinant() * svd.matrixV().determinant() < 0.0) s(2) = -1.0;
  alignment.R_gt_est = svd.matrixU() * s.asDiagonal() * svd.matrixV().transpose();
  if (model == AlignmentModel::kSim3) {
    const double variance_est = centred_est.squaredNorm();
    if (variance_est > 0.0) alignment.scale = svd.singularValues().dot(s) / variance_est;
  }
  alignment.t_gt_est_m = mean_gt - alignment.scale * (alignment.R_gt_est * mean_est);
  return alignment;
}

Trajectory uniqueSortedByTime(const Trajectory& trajectory) {
  std::map<double, std::size_t> last_index;
  for (std::size_t i = 0; i < trajectory.size(); ++i) last_index[trajectory[i].timestamp_s] = i;
  Trajectory result;
  result.reserve(last_index.size());
  for (const auto& entry : last_index) result.push_back(trajectory[entry.second]);
  return result;
}

AteResult computeAte(const Trajectory& groundtruth, const Trajectory& estimate,
                     const AteOptions& options) {
  const auto matches =
      associateTimestamps(timestampsOf(groundtruth), timestampsOf(estimate), options.association);
  if (matches.size() < 2) {
    throw std::runtime_error(
        "only " + std::to_string(matches.size()) +
        " pose pairs associate between ground truth and estimate: are they the same sequence? "
        "(check --max-difference and --offset)");
  }
  const auto n = static_cast<Eigen::Index>(matches.size());
  Eigen::Matrix3Xd points_gt(3, n);
  Eigen::Matrix3Xd points_est(3, n);
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto& match = matches[static_cast<std::size_t>(k)];
    points_gt.col(k) = groundtruth[match.first].T_world_camera.translation();
    points_est.col(k) = estimate[match.second].T_world_camera.translation() * options.scale;
  }
  AteResult result;
  result.alignment = alignPoints(points_est, points_gt, options.alignment);
  std::vector<double> errors;
  errors.reserve(matches.size());
  for (Eigen::Index k = 0; k < n; ++k) {
    const auto& match = matches[static_cast<std::size_t>(k)];
    AtePair pair;
    pair.timestamp_gt_s = groundtruth[match.first].timestamp_s;
    pair.timestamp_est_s = estimate[match.second].timestamp_s;
    pair.position_gt_m = points_gt.col(k);
    pair.position_est_m = result.alignment.apply(points_est.col(k));
    pair.error_m = (pair.position_est_m - pair.position_gt_m).norm();
    errors.push_back(pair.error_m);
    result.pairs.push_back(pair);
  }
  result.translation_m = computeStatistics(errors);
  return result;
}

DeltaUnit parseDeltaUnit(const std::string& text) {
  if (text == "s") return DeltaUnit::kSeconds;
  if (text == "f") return DeltaUnit::kFrames;
  if (text == "m") return DeltaUnit::kMetres;
  if (text == "rad") return DeltaUnit::kRadians;
  if (text == "deg") return DeltaUnit::kDegrees;
  throw std::invalid_argument("delta unit '" + text + "': allowed values are s, f, m, rad, deg");
}

const char* deltaUnitName(DeltaUnit unit) {
  switch (unit) {
    case DeltaUnit::kSeconds:
      return "s";
    case DeltaUnit::kFrames:
      return "f";
    case DeltaUnit::kMetres:
      return "m";
    case DeltaUnit::kRadians:
      return "rad";
    case DeltaUnit::kDegrees:
      return "deg";
  }
  return "?";
}

std::size_t findClosestIndex(const std::vector<double>& sorted_values, double value) {
  std::size_t beginning = 0;
  std::size_t end = sorted_values.size();
  double difference = std::abs(sorted_values[0] - value);
  std::size_t best = 0;
  while (beginning < end) {
    const std::size_t middle = (beginning + end) / 2;
    if (std::abs(sorted_values[middle] - value) < difference) {
      difference = std::abs(sorted_values[middle] - value);
      best = middle;
    }
    if (value == sorted_values[middle]) return middle;
    if (sorted_values[middle] > value) {
      end = middle;
    } else {
      beginning = middle + 1;
    }
  }
  return best;
}

RpeResult computeRpe(const Trajectory& groundtruth, const Trajectory& estimate,
                     const RpeOptions& options) {
  const Trajectory gt = uniqueSortedByTime(groundtruth);
  const Trajectory est = uniqueSortedByTime(estimate);
  if (gt.size() < 2 || est.size() < 2) {
    throw std::runtime_error("RPE needs at least 2 poses in each trajectory");
  }
  const std::vector<double> stamps_gt = timestampsOf(gt);
  const std::vector<double> stamps_est = timestampsOf(est);

  // The index along which delta is measured.
  std::vector<double> index_est;
  switch (options.delta_unit) {
    case DeltaUnit::kSeconds:
      index_est = stamps_est;
      break;
    case DeltaUnit::kFrames:
      for (std::size_t i = 0; i < est.size(); ++i) index_est.push_back(static_cast<double>(i));
      break;
    case DeltaUnit::kMetres:
    case DeltaUnit::kRadians:
    case DeltaUnit::kDegrees: {
      index_est.push_back(0.0);
      double sum = 0.0;
      for (std::size_t i = 0; i + 1 < est.size(); ++i) {
        const SE3 motion = est[i + 1].T_world_camera.inverse() * est[i].T_world_camera;
        if (options.delta_unit == DeltaUnit::kMetres) {
          sum += motion.translation().norm();
        } else {
          const double factor = options.delta_unit == DeltaUnit::kDegrees ? kRadToDeg : 1.0;
          sum += scriptRotationAngleRad(motion.linear()) * factor;
        }
        index_est.push_back(sum);
      }
      break;
    }
  }

  std::vector<std::pair<std::size_t, std::size_t>> index_pairs;
  for (std::size_t i = 0; i < est.size(); ++i) {
    const std::size_t j = findClosestIndex(index_est, index_est[i] + options.delta);
    if (j != est.size() - 1) index_pairs.emplace_back(i, j);
  }
  if (options.max_pairs != 0 && index_pairs.size() > options.max_pairs) {
    std::mt19937 rng(options.seed);
    std::shuffle(index_pairs.begin(), index_pairs.end(), rng);
    index_pairs.resize(options.max_pairs);
    std::sort(index_pairs.begin(), index_pairs.end());
  }

  std::vector<double> intervals;
  for (std::size_t i = 0; i + 1 < stamps_gt.size(); ++i) {
    intervals.push_back(stamps_gt[i + 1] - stamps_gt[i]);
  }
  const double gt_max_time_difference = 2.0 * percentile(intervals, 50.0);

  RpeResult result;
  std::vector<double> translation_errors;
  std::vector<double> rotation_errors;
  for (const auto& [i, j] : index_pairs) {
    const double stamp_est_0 = stamps_est[i];
    const double stamp_est_1 = stamps_est[j];
    const std::size_t g0 = findClosestIndex(stamps_gt, stamp_est_0 + options.offset_s);
    const std::size_t g1 = findClosestIndex(stamps_gt, stamp_est_1 + options.offset_s);
    if (std::abs(stamps_gt[g0] - (stamp_est_0 + options.offset_s)) > gt_max_time_difference ||
        std::abs(stamps_gt[g1] - (stamp_est_1 + options.offset_s)) > gt_max_time_difference) {
      continue;
    }
    // The script's order: ominus(a, b) = a^-1 b, error = ominus(scale(ominus(E1, E0)),
    // ominus(G1, G0)).
    SE3 motion_est = est[j].T_world_camera.inverse() * est[i].T_world_camera;
    motion_est.translation() *= options.scale;
    const SE3 motion_gt = gt[g1].T_world_camera.inverse() * gt[g0].T_world_camera;
    const SE3 error = motion_est.inverse() * motion_gt;
    RpePair pair;
    pair.timestamp_est_0_s = stamp_est_0;
    pair.timestamp_est_1_s = stamp_est_1;
    pair.timestamp_gt_0_s = stamps_gt[g0];
    pair.timestamp_gt_1_s = stamps_gt[g1];
    pair.translation_error_m = error.translation().norm();
    pair.rotation_error_rad = scriptRotationAngleRad(error.linear());
    translation_errors.push_back(pair.translation_error_m);
    rotation_errors.push_back(pair.rotation_error_rad);
    result.pairs.push_back(pair);
  }
  if (result.pairs.size() < 2) {
    throw std::runtime_error("only " + std::to_string(result.pairs.size()) +
                             " relative pose pairs match the ground truth: are they the same "
                             "sequence, and is delta shorter than the trajectory?");
  }
  result.translation_m = computeStatistics(translation_errors);
  result.rotation_deg = scaledStatistics(computeStatistics(rotation_errors), kRadToDeg);
  return result;
}

}  // namespace slamd::eval
