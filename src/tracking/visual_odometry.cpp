#include "slamd/tracking/visual_odometry.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <optional>
#include <unordered_map>
#include <unordered_set>

#include <opencv2/imgproc.hpp>

namespace slamd {
namespace {

constexpr double kGridCellPx = 8.0;
constexpr int kSiftMaxDistance = 350;    // L2 between SIFT descriptors (norm about 512)
constexpr double kLostCovariance = 1e2;  // metres^2 / radians^2: "unknown"

/// True when at least a quarter of the image has depth (sampled every 8th pixel each way).
bool hasDepthCoverage(const cv::Mat& depth_m) {
  if (depth_m.empty() || depth_m.type() != CV_32FC1) return false;
  int samples = 0;
  int with_depth = 0;
  for (int v = 4; v < depth_m.rows; v += 8) {
    const float* row = depth_m.ptr<float>(v);
    for (int u = 4; u < depth_m.cols; u += 8) {
      ++samples;
      with_depth += row[u] > 0.0F ? 1 : 0;  // false for NaN
    }
  }
  return samples > 0 && 4 * with_depth >= samples;
}

double msSince(std::int64_t start_ns) {
  return static_cast<double>(steadyNowNs() - start_ns) * 1e-6;
}

RefinementOptions refinementOptions(const TrackingConfig& config) {
  RefinementOptions options;
  options.max_iterations = config.max_iterations;
  options.huber_k = config.huber_k;
  options.depth_sigma_coeff = config.depth_sigma_coeff;
  options.estimate_noise_scale = config.estimate_noise_scale;
  return options;
}

/// Marks the correspondences whose reprojection error under T_ref_curr is below threshold_px
/// times their pixel sigma; returns how many are marked.
int markInliers(const std::vector<Correspondence>& matches, const CameraIntrinsics& K,
                const SE3& T_ref_curr, double threshold_px, std::vector<std::uint8_t>& inliers) {
  inliers.assign(matches.size(), 0);
  int count = 0;
  for (std::size_t i = 0; i < matches.size(); ++i) {
    if (reprojectionErrorPx(matches[i], K, T_ref_curr) < threshold_px * matches[i].pixel_sigma_px) {
      inliers[i] = 1;
      ++count;
    }
  }
  return count;
}

/// Fills in a frame measured against a reference (a keyframe, the previous frame, or dense
/// alignment's frame with ref_id -1): T_ref_curr and its covariance, which is the frame's too.
void setMeasured(OdometryResult& res, TrackingState state, const SE3& T_ref_curr,
                 const Matrix6d& covariance, Utime ref_utime, std::int64_t ref_id) {
  res.status = OdometryStatus::kOk;
  res.tracking_state = state;
  res.T_ref_curr = T_ref_curr;
  res.covariance_ref_curr = covariance;
  res.covariance = covariance;
  res.ref_utime = ref_utime;
  res.reference_keyframe_id = ref_id;
}

/// Keeps at most cap elements, spread evenly over the vector (a bound on later per-item cost).
template <typename T>
void keepEvenSample(std::vector<T>& items, std::size_t cap) {
  if (items.size() <= cap) return;
  std::vector<T> kept;
  kept.reserve(cap);
  for (std::size_t i = 0; i < cap; ++i) kept.push_back(items[i * items.size() / cap]);
  items.swap(kept);
}

/// Robust refinement over the flagged correspondences, the inliers re-marked at its result, and
/// refined again on those.
RefinementResult refineAndRemark(const std::vector<Correspondence>& matches,
                                 std::vector<std::uint8_t>& use, const CameraIntrinsics& K,
                                 const SE3& T_initial, const TrackingConfig& config) {
  const RefinementOptions options = refinementOptions(config);
  RefinementResult refined = refinePose(matches, use, K, T_initial, options);
  if (refined.success) {
    markInliers(matches, K, refined.T_ref_curr, config.inlier_threshold_px, use);
    refined = refinePose(matches, use, K, refined.T_ref_curr, options);
  }
  return refined;
}

}  // namespace

const char* odometryStatusName(OdometryStatus status) {
  switch (status) {
    case OdometryStatus::kOk:
      return "OK";
    case OdometryStatus::kInsufficientFeatures:
      return "INSUFFICIENT_FEATURES";
    case OdometryStatus::kInsufficientInliers:
      return "INSUFFICIENT_INLIERS";
    case OdometryStatus::kOptimizationFailure:
      return "OPTIMIZATION_FAILURE";
    case OdometryStatus::kNoDepth:
      return "NO_DEPTH";
    case OdometryStatus::kImplausibleMotion:
      return "IMPLAUSIBLE_MOTION";
  }
  return "UNKNOWN";
}

/// The current frame's features with a grid over undistorted pixels for guided search.
struct VisualOdometry::CurrentFrame {
  std::shared_ptr<FeatureSet> features;
  CameraIntrinsics K;
  cv::Mat gray;     ///< the frame's grey image (owned: a copy when the caller may reuse it)
  cv::Mat depth_m;  ///< the frame's depth (CV_32F metres, NaN = none)
  Utime utime = 0;
  std::shared_ptr<const DenseFrame> pyramid;  ///< dense alignment's pyramid, when built
  /// One feature as guided search first tests it: undistorted pixel, pyramid level, index.
  struct GridEntry {
    double x = 0.0;
    double y = 0.0;
    int octave = 0;
    int index = 0;
  };
  int grid_cols = 0;
  int grid_rows = 0;
  /// The features bucketed by cell (kGridCellPx squares, row-major) in one array: cell c holds
  /// grid[grid_start[c]] up to grid[grid_start[c + 1]], so a run of cells along a row is one
  /// contiguous range.
  std::vector<int> grid_start;
  std::vector<GridEntry> grid;

  void buildGrid() {
    grid_cols = std::max(1, static_cast<int>(std::ceil(K.width / kGridCellPx)));
    grid_rows = std::max(1, static_cast<int>(std::ceil(K.height / kGridCellPx)));
    const std::size_t cells = static_cast<std::size_t>(grid_cols * grid_rows);
    std::vector<int> cell_of(features->size());
    grid_start.assign(cells + 1, 0);
    for (std::size_t i = 0; i < features->size(); ++i) {
      const Eigen::Vector2d& p = features->pixels[i];
      const int cx = std::clamp(static_cast<int>(p.x() / kGridCellPx), 0, grid_cols - 1);
      const int cy = std::clamp(static_cast<int>(p.y() / kGridCellPx), 0, grid_rows - 1);
      cell_of[i] = cy * grid_cols + cx;
      ++grid_start[static_cast<std::size_t>(cell_of[i]) + 1];
    }
    for (std::size_t c = 0; c < cells; ++c) grid_start[c + 1] += grid_start[c];
    grid.resize(features->size());
    std::vector<int> fill(grid_start.begin(), grid_start.end() - 1);
    for (std::size_t i = 0; i < features->size(); ++i) {
      GridEntry& e = grid[static_cast<std::size_t>(fill[static_cast<std::size_t>(cell_of[i])]++)];
      e.x = features->pixels[i].x();
      e.y = features->pixels[i].y();
      e.octave = features->keypoints[i].octave;
      e.index = static_cast<int>(i);
    }
  }
};

struct VisualOdometry::TrackAttempt {
  OdometryStatus status = OdometryStatus::kInsufficientInliers;
  SE3 T_ref_curr = SE3::Identity();
  Matrix6d covariance = Matrix6d::Identity();
  int num_matches = 0;
  int num_inliers = 0;
  double rms_px = 0.0;
  bool guided = false;
  double time_matching_ms = 0.0;
  double time_motion_ms = 0.0;
  /// The final correspondences (point_ref in the reference frame) and their inlier flags.
  std::vector<Correspondence> matches;
  std::vector<std::uint8_t> inliers;
};

namespace {

DenseAlignmentOptions denseOptions(const TrackingConfig& config) {
  DenseAlignmentOptions options;
  options.levels = config.dense_levels;
  options.finest_level = config.dense_finest_level;
  options.min_gradient = config.dense_min_gradient;
  options.min_gradient_share = config.dense_min_gradient_share;
  options.min_coarse_gradient_share = config.dense_min_coarse_gradient_share;
  options.min_depth_m = config.min_depth_m;
  options.max_depth_m = config.max_depth_m;
  options.depth_sigma_coeff = config.depth_sigma_coeff;
  return options;
}

}  // namespace

VisualOdometry::VisualOdometry(const TrackingConfig& config)
    : config_(config),
      extractor_(makeFeatureExtractor(config)),
      local_map_(config.depth_sigma_coeff),
      dense_options_(denseOptions(config)),
      refine_dense_options_(dense_options_) {
  refine_dense_options_.max_pixels_per_level = config.few_inliers_dense_max_pixels;
}

VisualOdometry::~VisualOdometry() = default;

void VisualOdometry::reset() {
  state_ = TrackingState::kNotInitialized;
  keyframe_.reset();
  recent_keyframes_.clear();
  map_keyframes_ = MapKeyframes();
  last_keyframe_made_utime_ = 0;
  relocalization_keyframes_made_ = 0;
  local_map_.clear();
  prev_features_.reset();
  prev_tracked_ = false;
  T_world_prev_ = SE3::Identity();
  velocity_prev_curr_ = SE3::Identity();
  have_velocity_ = false;
  failed_frames_ = 0;
  T_world_last_measured_ = SE3::Identity();
  last_measured_utime_ = 0;
  prev_small_.release();
  covariance_keyframe_prev_ = Matrix6d::Zero();
  dense_reference_ = DenseReference();
  ++segment_;
}

void VisualOdometry::continueNumbering(std::int64_t next_keyframe_id, std::int64_t next_segment) {
  next_keyframe_id_ = std::max(next_keyframe_id_, next_keyframe_id);
  segment_ = std::max(segment_, next_segment);
}

OdometryResult VisualOdometry::processFrame(const RgbdFramePtr& frame) {
  if (!frame) return processFrame(RgbdFrame());
  return guardedProcess(*frame, frame);
}

OdometryResult VisualOdometry::processFrame(const RgbdFrame& frame) {
  return guardedProcess(frame, nullptr);
}

OdometryResult VisualOdometry::guardedProcess(const RgbdFrame& frame,
                                              const RgbdFramePtr& frame_ptr) {
  try {
    return process(frame, frame_ptr);
  } catch (const std::exception&) {
    // Last resort (an OpenCV error on unforeseen input, allocation failure): report the frame as
    // failed and keep the state as it was; processFrame never throws.
    OdometryResult r;
    r.utime = frame.utime;
    r.sequence = frame.sequence;
    r.status = OdometryStatus::kOptimizationFailure;
    r.tracking_state = state_;
    r.T_world_camera = T_world_prev_;
    r.covariance = Matrix6d::Identity() * kLostCovariance;
    r.covariance_ref_curr = r.covariance;
    r.segment = segment_;
    return r;
  }
}

void VisualOdometry::matchGuided(const FeatureSet& ref, const SE3& T_ref_curr_prior,
                                 const CurrentFrame& curr, double radius_px,
                                 std::vector<Correspondence>& matches,
                                 const std::vector<int>* ref_subset) const {
  matches.clear();
  const FeatureSet& cf = *curr.features;
  if (ref.descriptors.empty() || cf.descriptors.empty() ||
      ref.descriptors.type() != cf.descriptors.type() ||
      ref.descriptors.cols != cf.descriptors.cols) {
    return;
  }
  const DescriptorNorm norm = extractor_->norm();
  const int max_distance = norm == DescriptorNorm::kHamming ? config_.max_descriptor_distance
                           : norm == DescriptorNorm::kL2    ? kSiftMaxDistance
                                                            : config_.fovis_max_sad;
  const double ratio = std::min(1.0, config_.match_ratio + 0.1);
  // Scale consistency: binary descriptors within one pyramid level of each other, FOVIS patches on
  // the same level, SIFT any.
  const int max_octave_difference = norm == DescriptorNorm::kHamming ? 1
                                    : norm == DescriptorNorm::kSad
                                        ? 0
                                        : std::numeric_limits<int>::max();
  const SE3 T_curr_ref = T_ref_curr_prior.inverse();
  const CameraIntrinsics& K = curr.K;
  // Best match per current feature: (distance, index into matches).
  std::vector<std::pair<int, int>> owner(cf.size(), {std::numeric_limits<int>::max(), -1});
  std::vector<int> in_window;
  const std::size_t num_searched = ref_subset != nullptr ? ref_subset->size() : ref.size();
  for (std::size_t n = 0; n < num_searched; ++n) {
    const std::size_t i = ref_subset != nullptr ? static_cast<std::size_t>((*ref_subset)[n]) : n;
    if (!ref.hasDepth(i)) continue;
    const Eigen::Vector3d q = T_curr_ref * ref.points[i];
    if (q.z() <= 0.05) continue;
    const Eigen::Vector2d uv = K.project(q);
    const double r = radius_px * std::max(1.0, static_cast<double>(ref.scale[i]));
    if (uv.x() < -r || uv.y() < -r || uv.x() > K.width - 1 + r || uv.y() > K.height - 1 + r) {
      continue;
    }
    const int x0 = std::clamp(static_cast<int>((uv.x() - r) / kGridCellPx), 0, curr.grid_cols - 1);
    const int x1 = std::clamp(static_cast<int>((uv.x() + r) / kGridCellPx), 0, curr.grid_cols - 1);
    const int y0 = std::clamp(static_cast<int>((uv.y() - r) / kGridCellPx), 0, curr.grid_rows - 1);
    const int y1 = std::clamp(static_cast<int>((uv.y() + r) / kGridCellPx), 0, curr.grid_rows - 1);
    int best = std::numeric_limits<int>::max();
    int second = std::numeric_limits<int>::max();
    int best_j = -1;
    const int ref_octave = ref.keypoints[i].octave;
    const double r_squared = r * r;
    for (int cy = y0; cy <= y1; ++cy) {
      const std::size_t row = static_cast<std::size_t>(cy * curr.grid_cols);
      const int first = curr.grid_start[row + static_cast<std::size_t>(x0)];
      const int last = curr.grid_start[row + static_cast<std::size_t>(x1) + 1];
      // The window test without branches (whether a feature lies inside is a coin toss for the
      // branch predictor), then descriptors for those inside.
      in_window.resize(std::max(in_window.size(), static_cast<std::size_t>(last - first)));
      std::size_t count = 0;
      for (int e = first; e < last; ++e) {
        const CurrentFrame::GridEntry& entry = curr.grid[static_cast<std::size_t>(e)];
        const double du = entry.x - uv.x(), dv = entry.y - uv.y();
        in_window[count] = entry.index;
        count += static_cast<std::size_t>(
            (du * du + dv * dv <= r_squared) &
            (std::abs(entry.octave - ref_octave) <= max_octave_difference));
      }
      for (std::size_t k = 0; k < count; ++k) {
        const int j = in_window[k];
        const int d =
            descriptorDistance(ref.descriptors, static_cast<int>(i), cf.descriptors, j, norm);
        // Equal distances go to the lower index, whatever order the cells are visited in.
        if (d < best || (d == best && j < best_j)) {
          second = best;
          best = d;
          best_j = j;
        } else if (d < second) {
          second = d;
        }
      }
    }
    if (best_j < 0 || best > max_distance) continue;
    if (second != std::numeric_limits<int>::max() &&
        static_cast<double>(best) > ratio * static_cast<double>(second)) {
      continue;
    }
    auto& own = owner[static_cast<std::size_t>(best_j)];
    Correspondence c;
    c.point_ref = ref.points[i];
    c.pixel_curr = cf.pixels[static_cast<std::size_t>(best_j)];
    c.depth_curr_m = cf.points[static_cast<std::size_t>(best_j)].z();
    c.pixel_sigma_px =
        config_.pixel_sigma_px * static_cast<double>(cf.scale[static_cast<std::size_t>(best_j)]);
    c.ref_index = static_cast<int>(i);
    c.curr_index = best_j;
    if (own.second < 0) {
      own = {best, static_cast<int>(matches.size())};
      matches.push_back(c);
    } else if (best < own.first) {
      own.first = best;
      matches[static_cast<std::size_t>(own.second)] = c;
    }
  }
}

void VisualOdometry::matchByDescriptor(const FeatureSet& ref, const CurrentFrame& curr,
                                       std::vector<Correspondence>& matches) const {
  matches.clear();
  const FeatureSet& cf = *curr.features;
  if (ref.descriptors.empty() || cf.descriptors.empty() ||
      ref.descriptors.type() != cf.descriptors.type() ||
      ref.descriptors.cols != cf.descriptors.cols) {
    return;
  }
  const DescriptorNorm norm = extractor_->norm();
  if (norm == DescriptorNorm::kSad) {
    // FOVIS has no global matching: search a wide window around the unmoved position instead.
    CurrentFrame wide = curr;
    matchGuided(ref, SE3::Identity(), wide, 4.0 * config_.search_radius_px, matches);
    return;
  }
  const int max_distance =
      norm == DescriptorNorm::kHamming ? config_.max_descriptor_distance : kSiftMaxDistance;
  std::vector<int> ref_rows;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    if (ref.hasDepth(i)) ref_rows.push_back(static_cast<int>(i));
  }
  if (ref_rows.empty()) return;
  cv::Mat query(static_cast<int>(ref_rows.size()), ref.descriptors.cols, ref.descriptors.type());
  for (std::size_t k = 0; k < ref_rows.size(); ++k) {
    ref.descriptors.row(ref_rows[k]).copyTo(query.row(static_cast<int>(k)));
  }
  cv::BFMatcher matcher(norm == DescriptorNorm::kHamming ? cv::NORM_HAMMING : cv::NORM_L2);
  std::vector<std::vector<cv::DMatch>> knn;
  matcher.knnMatch(query, cf.descriptors, knn, 2);
  std::vector<std::pair<float, int>> owner(cf.size(), {std::numeric_limits<float>::max(), -1});
  for (const auto& pair : knn) {
    if (pair.empty()) continue;
    const cv::DMatch& m = pair[0];
    if (m.distance > static_cast<float>(max_distance)) continue;
    if (pair.size() > 1 &&
        m.distance > static_cast<float>(config_.match_ratio) * pair[1].distance) {
      continue;
    }
    const std::size_t i = static_cast<std::size_t>(ref_rows[static_cast<std::size_t>(m.queryIdx)]);
    const std::size_t j = static_cast<std::size_t>(m.trainIdx);
    Correspondence c;
    c.point_ref = ref.points[i];
    c.pixel_curr = cf.pixels[j];
    c.depth_curr_m = cf.points[j].z();
    c.pixel_sigma_px = config_.pixel_sigma_px * static_cast<double>(cf.scale[j]);
    c.ref_index = static_cast<int>(i);
    c.curr_index = static_cast<int>(j);
    auto& own = owner[j];
    if (own.second < 0) {
      own = {m.distance, static_cast<int>(matches.size())};
      matches.push_back(c);
    } else if (m.distance < own.first) {
      own.first = m.distance;
      matches[static_cast<std::size_t>(own.second)] = c;
    }
  }
}

VisualOdometry::TrackAttempt VisualOdometry::track(const FeatureSet& ref,
                                                   const SE3& T_ref_curr_prior, bool have_prior,
                                                   const CurrentFrame& curr, Search search) {
  TrackAttempt a;
  const CameraIntrinsics& K = curr.K;
  std::int64_t t0 = steadyNowNs();
  std::vector<Correspondence> matches;
  if (have_prior) {
    matchGuided(ref, T_ref_curr_prior, curr, config_.search_radius_px * search.radius_scale,
                matches);
    a.guided = true;
  }
  if (search.allow_global && static_cast<int>(matches.size()) < config_.min_guided_matches) {
    std::vector<Correspondence> global;
    matchByDescriptor(ref, curr, global);
    if (global.size() > matches.size()) {
      matches.swap(global);
      a.guided = false;
    }
  }
  a.num_matches = static_cast<int>(matches.size());
  a.time_matching_ms = msSince(t0);
  t0 = steadyNowNs();
  if (a.num_matches < config_.min_inliers) {
    a.status = OdometryStatus::kInsufficientInliers;
    a.time_motion_ms = msSince(t0);
    return a;
  }

  // Inlier detection and an initial closed-form estimate.
  std::vector<std::uint8_t> inliers(matches.size(), 0);
  SE3 T = SE3::Identity();
  int num_inliers = 0;
  if (config_.useClique()) {
    const std::vector<int> clique = maximumConsistentClique(
        matches, K, config_.fovis_clique_tolerance_m, config_.depth_sigma_coeff);
    std::vector<Eigen::Vector3d> pa, pb;
    for (int i : clique) {
      inliers[static_cast<std::size_t>(i)] = 1;
      pa.push_back(matches[static_cast<std::size_t>(i)].point_ref);
      pb.push_back(matches[static_cast<std::size_t>(i)].pointCurr(K));
    }
    num_inliers = static_cast<int>(clique.size());
    if (num_inliers < config_.min_inliers || !rigidFit(pa, pb, T)) {
      a.status = OdometryStatus::kInsufficientInliers;
      a.time_motion_ms = msSince(t0);
      return a;
    }
  } else {
    RansacResult ransac =
        ransacRigid(matches, K, config_.inlier_threshold_px, config_.ransac_iterations, rng_);
    if (!ransac.success || ransac.num_inliers < config_.min_inliers) {
      a.status = OdometryStatus::kInsufficientInliers;
      a.time_motion_ms = msSince(t0);
      return a;
    }
    T = ransac.T_ref_curr;
    inliers = ransac.inliers;
    num_inliers = ransac.num_inliers;
  }

  const RefinementOptions options = refinementOptions(config_);
  auto recheck = [&](const SE3& T_est) {
    num_inliers = markInliers(matches, K, T_est, config_.inlier_threshold_px, inliers);
  };
  RefinementResult refined = refinePose(matches, inliers, K, T, options);
  if (!refined.success) {
    a.status = OdometryStatus::kOptimizationFailure;
    a.time_motion_ms = msSince(t0);
    return a;
  }
  if (config_.refine_search_radius_px <= 0.0) {
    recheck(refined.T_ref_curr);
    refined = refinePose(matches, inliers, K, refined.T_ref_curr, options);
  } else {
    // Second, tighter guided search with the estimated motion: more (and surer) matches.
    std::vector<Correspondence> more;
    const std::int64_t tm = steadyNowNs();
    matchGuided(ref, refined.T_ref_curr, curr, config_.refine_search_radius_px, more);
    a.time_matching_ms += msSince(tm);
    // Too few matches in the tight window means a doubtful estimate: keep the first matches.
    if (more.size() >= matches.size() / 2) {
      matches.swap(more);
      inliers.assign(matches.size(), 0);
      a.num_matches = static_cast<int>(matches.size());
    }
    recheck(refined.T_ref_curr);
    refined = refinePose(matches, inliers, K, refined.T_ref_curr, options);
  }
  if (refined.success && config_.patch_refinement) {
    alignInlierPatches(ref, refined.T_ref_curr, curr, matches, inliers);
    recheck(refined.T_ref_curr);
    refined = refinePose(matches, inliers, K, refined.T_ref_curr, options);
  }
  if (refined.success) recheck(refined.T_ref_curr);
  a.time_motion_ms = msSince(t0);
  if (!refined.success) {
    a.status = OdometryStatus::kOptimizationFailure;
    return a;
  }
  if (num_inliers < config_.min_inliers) {
    a.status = OdometryStatus::kInsufficientInliers;
    return a;
  }
  a.status = OdometryStatus::kOk;
  a.T_ref_curr = refined.T_ref_curr;
  a.covariance = refined.covariance;
  a.num_inliers = num_inliers;
  a.rms_px = refined.rms_reprojection_px;
  a.matches = std::move(matches);
  a.inliers = std::move(inliers);
  return a;
}

void VisualOdometry::alignInlierPatches(const FeatureSet& ref, const SE3& T_ref_curr,
                                        const CurrentFrame& curr,
                                        std::vector<Correspondence>& matches,
                                        const std::vector<std::uint8_t>& inliers) const {
  const AlignedInliers aligned =
      slamd::alignInlierPatches(ref, *curr.features, curr.K, T_ref_curr, matches, inliers);
  const std::vector<Eigen::Vector2d> pixels = undistortPixels(aligned.pixels_raw, curr.K, config_);
  for (std::size_t k = 0; k < aligned.match_indices.size(); ++k) {
    Correspondence& c = matches[aligned.match_indices[k]];
    const cv::Point2f& raw = aligned.pixels_raw[k];
    c.pixel_curr = pixels[k];
    c.pixel_sigma_px = config_.pixel_sigma_px;
    // The depth where the patch now lies, not where the keypoint was detected.
    c.depth_curr_m =
        depthAtPixel(curr.depth_m, static_cast<double>(raw.x), static_cast<double>(raw.y), config_);
  }
}

void VisualOdometry::refineWithExtraReferences(const SE3& T_world_ref,
                                               const std::vector<ExtraReference>& extras,
                                               const CurrentFrame& curr, TrackAttempt& attempt) {
  const CameraIntrinsics& K = curr.K;
  std::vector<Correspondence> all = attempt.matches;
  std::vector<std::uint8_t> use = attempt.inliers;
  const std::size_t own = all.size();
  std::int64_t t0 = steadyNowNs();
  for (const ExtraReference& extra : extras) {
    // Matches against the extra reference, guided tightly by the estimate; their points are then
    // expressed in the main reference's frame through the (fixed) odometry poses.
    const SE3 T_extra_ref = extra.T_world_extra.inverse() * T_world_ref;
    const SE3 T_extra_curr = T_extra_ref * attempt.T_ref_curr;
    std::vector<Correspondence> matches;
    matchGuided(*extra.features, T_extra_curr, curr, config_.refine_search_radius_px, matches);
    // A sample spread over the match list bounds the cost (patch alignment dominates it).
    keepEvenSample(matches, static_cast<std::size_t>(config_.joint_max_matches));
    std::vector<std::uint8_t> inliers;
    markInliers(matches, K, T_extra_curr, config_.inlier_threshold_px, inliers);
    if (config_.patch_refinement) {
      alignInlierPatches(*extra.features, T_extra_curr, curr, matches, inliers);
      markInliers(matches, K, T_extra_curr, config_.inlier_threshold_px, inliers);
    }
    const SE3 T_ref_extra = T_extra_ref.inverse();
    for (std::size_t i = 0; i < matches.size(); ++i) {
      if (!inliers[i]) continue;
      Correspondence c = matches[i];
      c.point_ref = T_ref_extra * c.point_ref;
      all.push_back(c);
      use.push_back(1);
    }
  }
  attempt.time_matching_ms += msSince(t0);
  t0 = steadyNowNs();
  if (all.size() > own) {
    const RefinementResult refined = refineAndRemark(all, use, K, attempt.T_ref_curr, config_);
    // The covariance stays the main reference's own (the extra references' poses are uncertain
    // too); only the estimate moves.
    if (refined.success) attempt.T_ref_curr = refined.T_ref_curr;
  }
  attempt.time_motion_ms += msSince(t0);
}

SE3 VisualOdometry::alignRotation(const cv::Mat& small_curr, const CameraIntrinsics& K_full) const {
  // FOVIS's initial rotation: minimise the photometric error between the blurred 80x60 images of
  // the previous and current frames over a pure rotation R_prev_curr (pixels warp by K R K^-1):
  //   sum_x (I_curr(x) - I_prev(pi(K R K^-1 x)))^2.
  // Inverse compositional Gauss-Newton: the Jacobian uses the current image's gradient at the
  // identity warp, so it and the normal matrix are computed once; R <- R * exp(-delta).
  SE3 T = SE3::Identity();
  if (have_velocity_) T.linear() = velocity_prev_curr_.linear();
  if (prev_small_.empty() || prev_small_.size() != small_curr.size()) return T;
  const CameraIntrinsics K = K_full.scaled(small_curr.cols, small_curr.rows);
  struct Sample {
    Eigen::Vector3d ray;
    Eigen::Vector3d J;
    double value;
  };
  std::vector<Sample> samples;
  samples.reserve(static_cast<std::size_t>(small_curr.rows * small_curr.cols));
  Eigen::Matrix3d H = Eigen::Matrix3d::Zero();
  for (int v = 2; v < small_curr.rows - 2; ++v) {
    const float* row = small_curr.ptr<float>(v);
    const float* up = small_curr.ptr<float>(v - 1);
    const float* down = small_curr.ptr<float>(v + 1);
    for (int u = 2; u < small_curr.cols - 2; ++u) {
      const double gu = 0.5 * (static_cast<double>(row[u + 1]) - static_cast<double>(row[u - 1]));
      const double gv = 0.5 * (static_cast<double>(down[u]) - static_cast<double>(up[u]));
      if (gu * gu + gv * gv < 1.0) continue;  // flat pixels carry no information
      const Eigen::Vector3d f = K.ray(u, v);
      // d pi(K exp(delta) f) / d delta at delta = 0, with f.z = 1: dpi * (-[f]x).
      Eigen::Matrix<double, 2, 3> dpi;
      dpi << K.fx, 0, -K.fx * f.x(), 0, K.fy, -K.fy * f.y();
      const Eigen::Vector3d J = (Eigen::RowVector2d(gu, gv) * dpi * (-skew(f))).transpose();
      samples.push_back({f, J, static_cast<double>(row[u])});
      H += J * J.transpose();
    }
  }
  if (samples.size() < 100) return T;
  const Eigen::LDLT<Eigen::Matrix3d> solver(H);
  Eigen::Matrix3d R = T.linear();
  for (int it = 0; it < 6; ++it) {
    Eigen::Vector3d g = Eigen::Vector3d::Zero();
    int used = 0;
    for (const Sample& s : samples) {
      const Eigen::Vector3d p = R * s.ray;
      if (p.z() <= 0.1) continue;
      const double pu = K.fx * p.x() / p.z() + K.cx;
      const double pv = K.fy * p.y() / p.z() + K.cy;
      if (pu < 1 || pv < 1 || pu > small_curr.cols - 2 || pv > small_curr.rows - 2) continue;
      g += s.J * (s.value - sampleBilinear(prev_small_, pu, pv));
      ++used;
    }
    if (used < 100) break;
    const Eigen::Vector3d delta = -solver.solve(g);
    if (!delta.allFinite() || delta.norm() > 0.2) break;
    R = R * expSO3(-delta);
    if (delta.norm() < 1e-5) break;
  }
  T.linear() = R;
  return T;
}

std::shared_ptr<Keyframe> compactKeyframe(const Keyframe& keyframe, bool keep_alignment_image) {
  auto compact = std::make_shared<Keyframe>(keyframe);
  compact->frame.reset();
  compact->features.gray = cv::Mat();
  if (!keep_alignment_image) compact->features.align_gray = cv::Mat();
  return compact;
}

std::size_t keyframeBytes(const Keyframe& keyframe) {
  std::vector<const void*> counted;
  std::size_t bytes = 0;
  const auto image = [&](const cv::Mat& m) {
    if (m.empty() || std::find(counted.begin(), counted.end(), m.datastart) != counted.end()) {
      return;
    }
    counted.push_back(m.datastart);
    bytes += static_cast<std::size_t>(m.dataend - m.datastart);
  };
  const FeatureSet& f = keyframe.features;
  bytes += f.keypoints.size() * sizeof(cv::KeyPoint) + f.pixels.size() * sizeof(Eigen::Vector2d) +
           f.points.size() * sizeof(Eigen::Vector3d) + f.scale.size() * sizeof(float) +
           f.inverse_depth_gradient.size() * sizeof(Eigen::Vector2d);
  image(f.descriptors);
  image(f.gray);
  image(f.align_gray);
  if (keyframe.frame) {
    image(keyframe.frame->color_bgr);
    image(keyframe.frame->gray);
    image(keyframe.frame->depth_m);
  }
  return bytes;
}

KeyframePtr VisualOdometry::makeKeyframe(const CurrentFrame& curr, const RgbdFrame& frame,
                                         const RgbdFramePtr& frame_ptr, const SE3& T_world_camera) {
  auto kf = std::make_shared<Keyframe>();
  kf->id = next_keyframe_id_++;
  kf->segment = segment_;
  kf->utime = frame.utime;
  kf->frame_sequence = frame.sequence;
  kf->T_world_camera = T_world_camera;
  kf->intrinsics = curr.K;
  kf->features = *curr.features;
  kf->frame = frame_ptr;
  std::vector<double> depths_m;
  depths_m.reserve(kf->features.points.size());
  for (const Eigen::Vector3d& point : kf->features.points) {
    if (!std::isnan(point.z())) depths_m.push_back(point.z());
  }
  if (!depths_m.empty()) {
    auto middle = depths_m.begin() + static_cast<std::ptrdiff_t>(depths_m.size() / 2);
    std::nth_element(depths_m.begin(), middle, depths_m.end());
    kf->median_depth_m = *middle;
  }
  return kf;
}

// --- one frame, step by step ----------------------------------------------------------------
// process() reads top to bottom: prepare the frame, start a segment or measure it against the
// keyframe (the previous frame as fallback), re-use a nearby keyframe or refine in the local
// window, then make a keyframe if needed. Every exit goes through commit(), which makes the frame
// the "previous frame" of the next call.

struct VisualOdometry::ReferenceMeasurement {
  TrackAttempt attempt;
  SE3 T_world_ref = SE3::Identity();
  Utime ref_utime = 0;
  std::int64_t ref_id = -1;    ///< -1 when measured from the previous frame
  bool from_previous = false;  ///< the keyframe failed; the previous frame served
};

OdometryResult VisualOdometry::commit(OdometryResult res,
                                      std::shared_ptr<const FeatureSet> features, bool tracked,
                                      std::int64_t t_start) {
  T_world_prev_ = res.T_world_camera;
  prev_utime_ = res.utime;
  prev_features_ = std::move(features);
  prev_tracked_ = tracked;
  res.stats.time_total_ms = msSince(t_start);
  return res;
}

OdometryResult VisualOdometry::fail(OdometryResult res, OdometryStatus status,
                                    std::shared_ptr<const FeatureSet> features,
                                    std::int64_t t_start) {
  // Constant-velocity prediction for a short gap, then LOST.
  res.status = status;
  res.segment = segment_;
  if (state_ == TrackingState::kNotInitialized) {
    res.tracking_state = TrackingState::kNotInitialized;
    res.T_world_camera = T_world_prev_;
    res.covariance = Matrix6d::Identity() * kLostCovariance;
  } else if (state_ != TrackingState::kLost && failed_frames_ < config_.max_predicted_frames) {
    ++failed_frames_;
    const SE3 motion = have_velocity_ ? velocity_prev_curr_ : SE3::Identity();
    res.T_prev_curr = motion;
    res.T_world_camera = normalizedSE3(T_world_prev_ * motion);
    const double s = config_.failure_sigma_scale;
    res.covariance = last_covariance_ * (s * s);
    covariance_keyframe_prev_ = chainedCovariance(motion, res.covariance);
    state_ = TrackingState::kPredicted;
    res.tracking_state = state_;
  } else {
    // LOST: hold the last pose; the next trackable frame starts a new segment there.
    state_ = TrackingState::kLost;
    res.tracking_state = state_;
    res.T_world_camera = T_world_prev_;
    res.covariance = Matrix6d::Identity() * kLostCovariance;
    keyframe_.reset();
    have_velocity_ = false;
  }
  res.covariance_ref_curr = res.covariance;
  res.T_ref_curr = res.T_prev_curr;
  res.ref_utime = prev_utime_;
  return commit(std::move(res), std::move(features), false, t_start);
}

std::optional<OdometryStatus> VisualOdometry::prepareFrame(const RgbdFrame& frame,
                                                           const RgbdFramePtr& frame_ptr,
                                                           CurrentFrame& curr, cv::Mat& small,
                                                           OdometryStats& stats) {
  // Validate the input: never throw, report a status.
  cv::Mat gray;
  if (!frame.gray.empty() && frame.gray.type() == CV_8UC1) {
    gray = frame.gray;
  } else if (!frame.color_bgr.empty() && frame.color_bgr.type() == CV_8UC3) {
    cv::cvtColor(frame.color_bgr, gray, cv::COLOR_BGR2GRAY);
  }
  const CameraIntrinsics& K = frame.intrinsics;
  if (gray.empty() || !K.validationError().empty() || gray.cols != K.width ||
      gray.rows != K.height || gray.cols < 32 || gray.rows < 32) {
    return OdometryStatus::kInsufficientFeatures;
  }
  if (frame.depth_m.empty() || frame.depth_m.type() != CV_32FC1 ||
      frame.depth_m.size() != gray.size()) {
    return OdometryStatus::kNoDepth;
  }

  // Features.
  const std::int64_t t0 = steadyNowNs();
  curr.K = K;
  curr.utime = frame.utime;
  // Frames passed by reference may be reused by the caller: what is kept is copied.
  const bool borrowed = !frame_ptr;
  curr.depth_m = borrowed && config_.dense_fallback ? frame.depth_m.clone() : frame.depth_m;
  curr.features = std::make_shared<FeatureSet>();
  try {
    extractor_->extract(gray, *curr.features);
  } catch (const cv::Exception&) {
    *curr.features = FeatureSet();
  }
  attachGeometry(frame.depth_m, K, config_, *curr.features);
  // Keyframes keep the image for patch alignment (a copy when borrowed).
  curr.features->gray = frame_ptr && gray.data == frame.gray.data ? gray : gray.clone();
  curr.gray = curr.features->gray;
  if (config_.patch_refinement) {
    if (config_.align_blur_sigma_px > 0.0) {
      cv::GaussianBlur(gray, curr.features->align_gray, cv::Size(), config_.align_blur_sigma_px);
    } else {
      curr.features->align_gray = curr.features->gray;
    }
  }
  curr.buildGrid();
  if (config_.useRotationPrior()) {
    cv::Mat tmp = gray;
    while (tmp.cols > 100) {
      cv::Mat down;
      cv::pyrDown(tmp, down);
      tmp = down;
    }
    tmp.convertTo(small, CV_32F);
    cv::GaussianBlur(small, small, cv::Size(3, 3), 0.0);
  }
  stats.time_features_ms = msSince(t0);
  stats.num_features = static_cast<int>(curr.features->size());
  stats.num_features_with_depth = curr.features->num_with_depth;
  if (curr.features->num_with_depth < config_.min_features) {
    const bool no_depth = curr.features->size() >= static_cast<std::size_t>(config_.min_features);
    return no_depth ? OdometryStatus::kNoDepth : OdometryStatus::kInsufficientFeatures;
  }
  return std::nullopt;
}

OdometryResult VisualOdometry::startSegment(OdometryResult res, const CurrentFrame& curr,
                                            const RgbdFrame& frame, const RgbdFramePtr& frame_ptr,
                                            std::int64_t t_start) {
  // First frame, or first after LOST: a new keyframe (and segment) at the last pose.
  if (state_ == TrackingState::kLost) ++segment_;
  const SE3 T_world_curr = T_world_prev_;
  keyframe_ = makeKeyframe(curr, frame, frame_ptr, T_world_curr);
  last_keyframe_made_utime_ = frame.utime;
  relocalization_keyframes_made_ = 0;
  recent_keyframes_.clear();
  recent_keyframes_.push_back(keyframe_);
  local_map_.clear();
  local_map_.addKeyframe(keyframe_, {});
  res.status = OdometryStatus::kOk;
  res.tracking_state = TrackingState::kOk;
  res.T_world_camera = T_world_curr;
  res.covariance =
      Matrix6d::Identity() * (state_ == TrackingState::kNotInitialized ? 0.0 : kLostCovariance);
  res.covariance_ref_curr = res.covariance;
  res.ref_utime = frame.utime;
  res.reference_keyframe_id = keyframe_->id;
  res.is_keyframe = true;
  res.keyframe = keyframe_;
  res.segment = segment_;
  state_ = TrackingState::kOk;
  failed_frames_ = 0;
  have_velocity_ = false;
  covariance_keyframe_prev_ = Matrix6d::Zero();
  rememberMeasuredFrame(curr, T_world_curr, frame.utime);
  return commit(std::move(res), curr.features, true, t_start);
}

void VisualOdometry::moveDepthsToColourTime(const RgbdFrame& frame, const SE3& T_prev_curr_pred,
                                            CurrentFrame& curr) const {
  if (!config_.depth_time_correction || !have_velocity_ || prev_utime_ <= 0) return;
  const double interval_s = static_cast<double>(frame.utime - prev_utime_) * 1e-6;
  const double colour_after_depth_s = static_cast<double>(frame.utime - frame.depthUtime()) * 1e-6;
  // A pair further apart than the frame interval was badly associated; the motion prior says
  // nothing reliable about it.
  if (colour_after_depth_s == 0.0 || !(interval_s > 0.0) ||
      std::abs(colour_after_depth_s) > interval_s) {
    return;
  }
  // Constant velocity over the interval: the colour camera's pose in the depth camera's frame.
  const SE3 T_depth_colour = expSE3(logSE3(T_prev_curr_pred) * (colour_after_depth_s / interval_s));
  slamd::moveDepthsToColourTime(T_depth_colour.inverse(), *curr.features);
}

SE3 VisualOdometry::predictMotion(const cv::Mat& small, const CameraIntrinsics& K) {
  // Constant velocity (FOVIS: rotation from image alignment against the previous frame).
  SE3 motion_prior = have_velocity_ ? velocity_prev_curr_ : SE3::Identity();
  if (config_.useRotationPrior()) {
    const SE3 rotation = alignRotation(small, K);
    motion_prior.linear() = rotation.linear();
  }
  prev_small_ = small;
  return motion_prior;
}

std::string VisualOdometry::implausibility(const SE3& T_world_curr, const Matrix6d& covariance,
                                           double dt_s) const {
  const Matrix6d& C = covariance;
  const double translation_sigma_m = std::sqrt(std::max(0.0, C.topLeftCorner<3, 3>().trace()));
  const double rotation_sigma_rad = std::sqrt(std::max(0.0, C.bottomRightCorner<3, 3>().trace()));
  return config_.motion_limits.violation(T_world_last_measured_.inverse() * T_world_curr, dt_s,
                                         translation_sigma_m, rotation_sigma_rad);
}

Matrix6d VisualOdometry::motionPriorCovariance(double interval_s) const {
  const double sigma_m = config_.motion_prior_sigma_mps * interval_s;
  const double sigma_rad = config_.motion_prior_sigma_degps * M_PI / 180.0 * interval_s;
  Vector6d variance;
  variance << Eigen::Vector3d::Constant(sigma_m * sigma_m),
      Eigen::Vector3d::Constant(sigma_rad * sigma_rad);
  return variance.asDiagonal();
}

bool VisualOdometry::disagreesWithPrior(const SE3& T_world_curr, const Matrix6d& covariance,
                                        const SE3& T_world_pred, double dt_s) const {
  if (config_.motion_prior_gate_sigma <= 0.0 || !have_velocity_) return false;
  // Both covariances are of a perturbation on the right (the current camera's frame); the
  // prior's is isotropic, so the frame it is expressed in does not matter.
  const Vector6d error = logSE3(T_world_pred.inverse() * T_world_curr);
  const Matrix6d combined =
      motionPriorCovariance(std::max(dt_s, MotionLimits::kMinIntervalS)) + covariance;
  const double mahalanobis_squared = error.dot(combined.ldlt().solve(error));
  const double gate = config_.motion_prior_gate_sigma;
  return !std::isfinite(mahalanobis_squared) || mahalanobis_squared > gate * gate;
}

bool VisualOdometry::rejected(const SE3& T_world_curr, const Matrix6d& covariance,
                              const SE3& T_world_pred, double dt_s, OdometryStats& stats) const {
  if (!implausibility(T_world_curr, covariance, dt_s).empty()) {
    ++stats.implausible_estimates;
    return true;
  }
  if (disagreesWithPrior(T_world_curr, covariance, T_world_pred, dt_s)) {
    ++stats.prior_disagreements;
    return true;
  }
  return false;
}

VisualOdometry::ReferenceMeasurement VisualOdometry::measureAgainstReference(
    const SE3& T_world_pred, const CurrentFrame& curr, double dt_s, OdometryStats& stats) {
  // Each reference (the keyframe, then the previous frame) is measured as usual; an estimate
  // the camera cannot have made, or one far from the prediction, is vetoed and that reference
  // retried with guided search only, in a window twice as wide (whole-image matching is what
  // repeating patterns fool).
  ReferenceMeasurement m;
  double matching_ms = 0.0;
  double motion_ms = 0.0;
  bool vetoed = false;
  auto measure = [&](const FeatureSet& ref, const SE3& T_world_ref) {
    const SE3 prior = T_world_ref.inverse() * T_world_pred;
    TrackAttempt a = track(ref, prior, true, curr);
    for (int retry = 0; retry < 2; ++retry) {
      matching_ms += a.time_matching_ms;
      motion_ms += a.time_motion_ms;
      if (a.status != OdometryStatus::kOk) return a;
      if (!rejected(T_world_ref * a.T_ref_curr, a.covariance, T_world_pred, dt_s, stats)) return a;
      vetoed = true;
      a.status = OdometryStatus::kImplausibleMotion;
      if (retry == 0) a = track(ref, prior, true, curr, Search(false, 2.0));
    }
    return a;
  };
  m.attempt = measure(keyframe_->features, keyframe_->T_world_camera);
  m.T_world_ref = keyframe_->T_world_camera;
  m.ref_utime = keyframe_->utime;
  m.ref_id = keyframe_->id;
  if (m.attempt.status != OdometryStatus::kOk && prev_features_ && prev_tracked_ &&
      prev_utime_ != keyframe_->utime) {
    TrackAttempt fallback = measure(*prev_features_, T_world_prev_);
    if (fallback.status == OdometryStatus::kOk) {
      m.attempt = fallback;
      m.T_world_ref = T_world_prev_;
      m.ref_utime = prev_utime_;
      m.ref_id = -1;
      m.from_previous = true;
    }
  }
  if (m.attempt.status != OdometryStatus::kOk && vetoed) {
    m.attempt.status = OdometryStatus::kImplausibleMotion;
  }
  m.attempt.time_matching_ms = matching_ms;
  m.attempt.time_motion_ms = motion_ms;
  return m;
}

bool VisualOdometry::needsNewKeyframe(const TrackAttempt& attempt, const Keyframe& kf,
                                      int features_with_depth, double novelty) const {
  const double overlap =
      static_cast<double>(attempt.num_inliers) / std::max(1, kf.features.num_with_depth);
  const double translation_m = attempt.T_ref_curr.translation().norm();
  const double rotation_deg = rotationAngleRad(attempt.T_ref_curr.linear()) * 180.0 / M_PI;
  // The view changes with the parallax, baseline over depth: a desk 0.8 m away looks different
  // after 0.15 m, a corridor wall 3 m away hardly does.
  double max_translation_m = config_.keyframe_max_translation_m;
  if (kf.median_depth_m > 0.0) {
    max_translation_m =
        std::min(max_translation_m, config_.keyframe_max_baseline_ratio * kf.median_depth_m);
  }
  max_translation_m *= novelty;
  const double max_rotation_deg = novelty * config_.keyframe_max_rotation_deg;
  const double min_overlap = 1.0 - novelty * (1.0 - config_.keyframe_min_overlap);
  // Few inliers call for a keyframe only when the frame has many more features to offer: where
  // the scene has few (a plain corridor), a new keyframe would hold no more than the old one.
  const bool few_inliers = attempt.num_inliers < config_.keyframe_min_inliers &&
                           features_with_depth >= 2 * attempt.num_inliers;
  return few_inliers || overlap < min_overlap || translation_m > max_translation_m ||
         rotation_deg > max_rotation_deg;
}

bool VisualOdometry::wantsRelocalizationKeyframe(const TrackAttempt& attempt,
                                                 const CurrentFrame& curr, Utime utime) const {
  if (config_.relocalization_keyframe_interval_s <= 0.0 || !map_keyframes_.relocalization_pending) {
    return false;
  }
  // The flag is about the anchor's segment; after another loss it no longer applies.
  const Keyframe* anchor = recentKeyframe(map_keyframes_.anchor_id);
  if (anchor == nullptr || anchor->segment != segment_) return false;
  // The same view would give the back end the same answer, and a segment that never joins the
  // map (a new place, a wrong map) must not fill the graph: the wait doubles with each attempt,
  // up to a bound.
  const double wait_s = std::min(std::ldexp(config_.relocalization_keyframe_interval_s,
                                            std::min(relocalization_keyframes_made_, 30)),
                                 std::max(config_.relocalization_keyframe_max_interval_s,
                                          config_.relocalization_keyframe_interval_s));
  if (static_cast<double>(utime - last_keyframe_made_utime_) * 1e-6 < wait_s) return false;
  return curr.features->num_with_depth >= config_.keyframe_min_inliers &&
         needsNewKeyframe(attempt, *keyframe_, curr.features->num_with_depth,
                          config_.relocalization_keyframe_novelty);
}

bool VisualOdometry::reuseRecentKeyframe(const CurrentFrame& curr, TrackAttempt& attempt,
                                         bool keyframe_was_reference, SE3& T_world_curr,
                                         OdometryResult& res) {
  // Before making a keyframe, try the keyframes near the current pose: re-using one (the camera
  // came back) measures against it directly instead of chaining more drift, and adds nothing.
  // Tracking's recent keyframes are where it put them; the map's are placed through the anchor,
  // a recent keyframe of tracking's, at their optimised pose relative to it.
  struct Candidate {
    double distance = 0.0;
    KeyframePtr kf;
    SE3 T_world_kf;
    bool from_map = false;
  };
  std::vector<Candidate> candidates;
  const auto consider = [&](const KeyframePtr& kf, const SE3& T_world_kf, bool from_map) {
    const SE3 T_kf_curr = T_world_kf.inverse() * T_world_curr;
    const double translation_m = T_kf_curr.translation().norm();
    const double rotation_deg = rotationAngleRad(T_kf_curr.linear()) * 180.0 / M_PI;
    if (translation_m > 0.5 * config_.keyframe_max_translation_m ||
        rotation_deg > 0.5 * config_.keyframe_max_rotation_deg) {
      return;
    }
    candidates.push_back({translation_m / config_.keyframe_max_translation_m +
                              rotation_deg / config_.keyframe_max_rotation_deg,
                          kf, T_world_kf, from_map});
  };
  for (const KeyframePtr& kf : recent_keyframes_) {
    if (kf != keyframe_) consider(kf, kf->T_world_camera, false);
  }
  if (const Keyframe* anchor = recentKeyframe(map_keyframes_.anchor_id)) {
    for (const MapKeyframes::Member& member : map_keyframes_.members) {
      if (recentKeyframe(member.keyframe->id) != nullptr) continue;
      consider(member.keyframe, anchor->T_world_camera * member.T_anchor_keyframe, true);
    }
  }
  std::sort(candidates.begin(), candidates.end(),
            [](const Candidate& a, const Candidate& b) { return a.distance < b.distance; });
  for (std::size_t k = 0; k < candidates.size() && k < 2; ++k) {
    const Candidate& candidate = candidates[k];
    const TrackAttempt reuse =
        track(candidate.kf->features, candidate.T_world_kf.inverse() * T_world_curr, true, curr);
    res.stats.time_matching_ms += reuse.time_matching_ms;
    res.stats.time_motion_ms += reuse.time_motion_ms;
    if (reuse.status != OdometryStatus::kOk ||
        needsNewKeyframe(reuse, *candidate.kf, curr.features->num_with_depth)) {
      continue;
    }
    if (candidate.from_map) {
      // The map's keyframe joins tracking's window at the pose the map gives it relative to the
      // anchor, sharing the landmarks of the current features it matched. The pose then follows
      // the map: it moves by the drift the back end corrected between the anchor and the
      // keyframe, as it moves to a recent keyframe's reference when one is re-used.
      auto placed = std::make_shared<Keyframe>(*candidate.kf);
      placed->T_world_camera = candidate.T_world_kf;
      std::vector<std::int64_t> curr_landmarks;
      if (keyframe_was_reference) associateWithKeyframe(attempt, *keyframe_, curr_landmarks);
      std::vector<std::int64_t> placed_landmarks(placed->features.size(), -1);
      for (std::size_t m = 0; m < reuse.matches.size(); ++m) {
        const Correspondence& c = reuse.matches[m];
        if (!reuse.inliers[m] || c.ref_index < 0 || c.curr_index < 0 ||
            static_cast<std::size_t>(c.curr_index) >= curr_landmarks.size()) {
          continue;
        }
        placed_landmarks[static_cast<std::size_t>(c.ref_index)] =
            curr_landmarks[static_cast<std::size_t>(c.curr_index)];
      }
      addToWindow(placed, placed_landmarks);
      keyframe_ = placed;
      res.stats.used_map_keyframe = true;
    } else {
      keyframe_ = candidate.kf;
    }
    T_world_curr = normalizedSE3(candidate.T_world_kf * reuse.T_ref_curr);
    attempt = reuse;
    res.reference_keyframe_id = keyframe_->id;
    res.ref_utime = keyframe_->utime;
    res.stats.num_matches = reuse.num_matches;
    res.stats.num_inliers = reuse.num_inliers;
    res.stats.reprojection_error_px = reuse.rms_px;
    res.T_ref_curr = reuse.T_ref_curr;
    res.covariance_ref_curr = reuse.covariance;
    res.covariance = reuse.covariance;
    return true;
  }
  return false;
}

const Keyframe* VisualOdometry::recentKeyframe(std::int64_t id) const {
  for (const KeyframePtr& kf : recent_keyframes_) {
    if (kf->id == id) return kf.get();
  }
  return nullptr;
}

void VisualOdometry::setMapKeyframes(MapKeyframes map_keyframes) {
  if (!config_.map_keyframes) map_keyframes.members.clear();
  map_keyframes_ = std::move(map_keyframes);
}

void VisualOdometry::refineInLocalWindow(const CurrentFrame& curr, TrackAttempt& attempt,
                                         SE3& T_world_curr, OdometryResult& res) {
  // The most recent other keyframes, held fixed. (The previous frame is no help: its pose is
  // itself measured from the keyframe.)
  std::vector<ExtraReference> extras;
  for (auto it = recent_keyframes_.rbegin();
       it != recent_keyframes_.rend() &&
       static_cast<int>(extras.size()) < config_.jointReferences();
       ++it) {
    if (*it == keyframe_ || (*it)->utime == prev_utime_) continue;
    extras.push_back({&(*it)->features, (*it)->T_world_camera});
  }
  const double matching_ms = attempt.time_matching_ms;
  const double motion_ms = attempt.time_motion_ms;
  refineWithExtraReferences(keyframe_->T_world_camera, extras, curr, attempt);
  res.stats.time_matching_ms += attempt.time_matching_ms - matching_ms;
  res.stats.time_motion_ms += attempt.time_motion_ms - motion_ms;
  res.T_ref_curr = attempt.T_ref_curr;
  T_world_curr = normalizedSE3(keyframe_->T_world_camera * attempt.T_ref_curr);
}

void VisualOdometry::refineWithPreviousFrame(const CurrentFrame& curr, TrackAttempt& attempt,
                                             SE3& T_world_curr, OdometryResult& res) {
  if (!config_.few_inliers_previous_frame || attempt.num_inliers >= config_.keyframe_min_inliers ||
      !prev_tracked_ || !prev_features_ || keyframe_->utime == prev_utime_) {
    return;
  }
  const double matching_ms = attempt.time_matching_ms;
  const double motion_ms = attempt.time_motion_ms;
  refineWithExtraReferences(keyframe_->T_world_camera, {{prev_features_.get(), T_world_prev_}},
                            curr, attempt);
  res.stats.time_matching_ms += attempt.time_matching_ms - matching_ms;
  res.stats.time_motion_ms += attempt.time_motion_ms - motion_ms;
  res.stats.refined_with_previous_frame = true;
  res.T_ref_curr = attempt.T_ref_curr;
  T_world_curr = normalizedSE3(keyframe_->T_world_camera * attempt.T_ref_curr);
}

void VisualOdometry::refineWithDenseAlignment(CurrentFrame& curr, const TrackAttempt& attempt,
                                              bool keyframe_is_reference, SE3& T_world_curr,
                                              OdometryResult& res) {
  if (!config_.few_inliers_dense || attempt.num_inliers >= config_.keyframe_min_inliers ||
      !config_.dense_fallback || dense_reference_.gray.empty() || curr.gray.empty() ||
      dense_reference_.utime != last_measured_utime_ || dense_reference_.K.width != curr.K.width ||
      dense_reference_.K.height != curr.K.height) {
    return;
  }
  // Measured against the previous frame, that frame must be the one aligned against.
  if (!keyframe_is_reference && res.ref_utime != dense_reference_.utime) return;
  const std::int64_t t0 = steadyNowNs();
  buildDensePyramids(curr);
  // Against the keyframe, the feature estimate's uncertainty relative to the previous frame adds
  // that of the chain from the keyframe to it; measured against the previous frame, it is its own.
  const SE3& T_world_ref = dense_reference_.T_world_camera;
  const SE3 T_ref_curr_features = T_world_ref.inverse() * T_world_curr;
  const Matrix6d prior = keyframe_is_reference
                             ? chainedCovariance(T_ref_curr_features, attempt.covariance)
                             : attempt.covariance;
  const DenseAlignmentResult dense = alignDense(*dense_reference_.pyramid, *curr.pyramid,
                                                T_ref_curr_features, prior, refine_dense_options_);
  res.stats.time_dense_ms += msSince(t0);
  if (!dense.success) return;
  // Two measurements that disagree by far more than the features' covariance allows (the
  // alignment settled in another minimum), or a result the camera cannot have reached: the
  // feature estimate stands alone, as it would without this step.
  const Vector6d moved = logSE3(T_ref_curr_features.inverse() * dense.T_ref_curr);
  const double mahalanobis_squared = moved.dot(prior.ldlt().solve(moved));
  const double gate = config_.motion_prior_gate_sigma;
  const SE3 T_world_dense = normalizedSE3(T_world_ref * dense.T_ref_curr);
  const double dt_s = static_cast<double>(curr.utime - last_measured_utime_) * 1e-6;
  if (!std::isfinite(mahalanobis_squared) || (gate > 0.0 && mahalanobis_squared > gate * gate) ||
      !implausibility(T_world_dense, dense.covariance, dt_s).empty()) {
    return;
  }
  T_world_curr = T_world_dense;
  const SE3& T_world_measured_ref =
      keyframe_is_reference ? keyframe_->T_world_camera : dense_reference_.T_world_camera;
  res.T_ref_curr = normalizedSE3(T_world_measured_ref.inverse() * T_world_curr);
  // The step from the previous frame is the alignment's posterior (features and pixels together).
  res.covariance = dense.covariance;
  if (!keyframe_is_reference) res.covariance_ref_curr = dense.covariance;
  res.stats.refined_with_dense_alignment = true;
}

void VisualOdometry::associateWithKeyframe(const TrackAttempt& attempt, const Keyframe& kf,
                                           std::vector<std::int64_t>& curr_landmarks) const {
  if (!local_map_.hasKeyframe(kf.id)) return;
  const std::vector<std::int64_t>& landmarks = local_map_.landmarksOf(kf.id);
  for (std::size_t k = 0; k < attempt.matches.size(); ++k) {
    const Correspondence& c = attempt.matches[k];
    if (!attempt.inliers[k] || c.ref_index < 0 || c.curr_index < 0) continue;
    const std::size_t curr_index = static_cast<std::size_t>(c.curr_index);
    if (curr_index >= curr_landmarks.size()) curr_landmarks.resize(curr_index + 1, -1);
    curr_landmarks[curr_index] = landmarks[static_cast<std::size_t>(c.ref_index)];
  }
}

void VisualOdometry::collectLocalMapGroups(bool keyframe_is_reference) {
  // The landmarks to search: those of the keyframes covisible with the keyframe, and of the
  // keyframe itself unless the attempt already measured against it. Each is searched through its
  // representative view (the latest keyframe that observed it): that keyframe's descriptor,
  // scale, orientation and patch.
  local_search_ = LocalMapSearch();
  local_search_.keyframe_id = keyframe_->id;
  local_search_.keyframe_is_reference = keyframe_is_reference;
  local_search_.map_revision = local_map_.revision();
  std::vector<std::int64_t> sources = local_map_.covisibleKeyframes(
      keyframe_->id, config_.local_map_min_shared, config_.local_map_keyframes);
  if (!keyframe_is_reference) sources.push_back(keyframe_->id);
  // Landmarks seen once: searched, or excluded (the keyframe's own, already measured).
  std::unordered_set<std::int64_t> seen;
  if (keyframe_is_reference) {
    for (std::int64_t id : local_map_.landmarksOf(keyframe_->id)) seen.insert(id);
  }
  const std::size_t num_excluded = seen.size();
  for (std::int64_t source : sources) {
    for (std::int64_t id : local_map_.landmarksOf(source)) {
      if (id < 0 || !seen.insert(id).second) continue;
      const MapLandmark* landmark = local_map_.landmark(id);
      if (landmark == nullptr) continue;
      const MapLandmark::Observation& view = landmark->representative();
      LocalMapGroup& group = local_search_.groups[view.keyframe_id];
      if (group.kf == nullptr) {
        group.kf = &local_map_.keyframe(view.keyframe_id);
        group.landmark_of_feature.assign(group.kf->features.size(), -1);
      }
      group.landmark_of_feature[static_cast<std::size_t>(view.feature_index)] = id;
    }
  }
  for (auto& [kf_id, group] : local_search_.groups) {
    for (std::size_t f = 0; f < group.landmark_of_feature.size(); ++f) {
      if (group.landmark_of_feature[f] >= 0) group.features.push_back(static_cast<int>(f));
    }
  }
  local_search_.num_landmarks = static_cast<int>(seen.size() - num_excluded);
}

void VisualOdometry::trackLocalMap(const CurrentFrame& curr, const SE3& T_world_ref,
                                   bool keyframe_is_reference, TrackAttempt& attempt,
                                   SE3& T_world_curr, OdometryResult& res) {
  if (!local_map_.hasKeyframe(keyframe_->id)) return;
  const std::int64_t t0 = steadyNowNs();
  const FeatureSet& cf = *curr.features;
  if (local_search_.keyframe_id != keyframe_->id ||
      local_search_.keyframe_is_reference != keyframe_is_reference ||
      local_search_.map_revision != local_map_.revision()) {
    collectLocalMapGroups(keyframe_is_reference);
  }
  res.stats.local_map_landmarks = local_search_.num_landmarks;
  const std::unordered_map<std::int64_t, LocalMapGroup>& groups = local_search_.groups;
  if (groups.empty()) return;

  // Search by projection around the current estimate: ratio test within the window and scale
  // consistency (matchGuided); the points are the landmarks' fused positions.
  struct Candidate {
    Correspondence match;
    std::int64_t landmark_id = -1;
    const LocalMapGroup* group = nullptr;
  };
  std::vector<Candidate> candidates;
  std::vector<std::uint8_t> curr_taken(cf.size(), 0);
  for (std::size_t k = 0; k < attempt.matches.size(); ++k) {
    if (attempt.inliers[k] && attempt.matches[k].curr_index >= 0) {
      curr_taken[static_cast<std::size_t>(attempt.matches[k].curr_index)] = 1;
    }
  }
  for (const auto& [kf_id, group] : groups) {
    const SE3 T_world_kf = group.kf->T_world_camera;
    const SE3 T_kf_world = T_world_kf.inverse();
    std::vector<Correspondence> matches;
    matchGuided(group.kf->features, T_kf_world * T_world_curr, curr,
                config_.refine_search_radius_px, matches, &group.features);
    for (Correspondence& c : matches) {
      const std::int64_t id = group.landmark_of_feature[static_cast<std::size_t>(c.ref_index)];
      c.point_ref = T_kf_world * local_map_.landmark(id)->p_world;
      candidates.push_back({c, id, &group});
    }
  }
  // Orientation consistency (ORB, SIFT): the change of keypoint angle between the two views is
  // nearly the same for every true match, the camera's roll; matches outside the three most
  // common 12-degree bins are dropped.
  if (extractor_->norm() != DescriptorNorm::kSad && candidates.size() >= 10) {
    constexpr int kBins = 30;
    std::vector<int> bin_of(candidates.size(), -1);
    std::array<int, kBins> histogram{};
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      const Candidate& cand = candidates[k];
      const float a_ref =
          cand.group->kf->features.keypoints[static_cast<std::size_t>(cand.match.ref_index)].angle;
      const float a_curr = cf.keypoints[static_cast<std::size_t>(cand.match.curr_index)].angle;
      if (a_ref < 0.0f || a_curr < 0.0f) continue;
      double difference = static_cast<double>(a_curr - a_ref);
      if (difference < 0.0) difference += 360.0;
      bin_of[k] = std::min(kBins - 1, static_cast<int>(difference / (360.0 / kBins)));
      ++histogram[static_cast<std::size_t>(bin_of[k])];
    }
    std::array<int, kBins> order{};
    for (int b = 0; b < kBins; ++b) order[static_cast<std::size_t>(b)] = b;
    std::partial_sort(order.begin(), order.begin() + 3, order.end(), [&](int a, int b) {
      return histogram[static_cast<std::size_t>(a)] > histogram[static_cast<std::size_t>(b)];
    });
    std::vector<Candidate> consistent;
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      const int b = bin_of[k];
      if (b < 0 || b == order[0] || b == order[1] || b == order[2]) {
        consistent.push_back(candidates[k]);
      }
    }
    candidates.swap(consistent);
  }
  // One landmark per current feature, none that the attempt already holds; then an even sample
  // bounds the cost of patch alignment. (The first candidate of a feature is kept: keeping the
  // one with the closest descriptor instead was tried and was no better, see docs/tracking.md.)
  std::vector<Candidate> unique;
  for (const Candidate& cand : candidates) {
    std::uint8_t& taken = curr_taken[static_cast<std::size_t>(cand.match.curr_index)];
    if (taken) continue;
    taken = 1;
    unique.push_back(cand);
  }
  keepEvenSample(unique, static_cast<std::size_t>(config_.local_map_max_matches));
  // Geometric verification per source view (reprojection at the estimate), sub-pixel patch
  // alignment against that view, verification again; the survivors join the attempt's inliers
  // in the world frame.
  std::vector<Correspondence> all;
  std::vector<std::uint8_t> use;
  all.reserve(attempt.matches.size() + unique.size());
  for (std::size_t k = 0; k < attempt.matches.size(); ++k) {
    Correspondence c = attempt.matches[k];
    c.point_ref = T_world_ref * c.point_ref;
    all.push_back(c);
    use.push_back(attempt.inliers[k]);
  }
  const std::size_t own = all.size();
  std::vector<std::int64_t> landmark_of_match;
  const CameraIntrinsics& K = curr.K;
  for (const auto& [kf_id, group] : groups) {
    std::vector<Correspondence> matches;
    std::vector<std::int64_t> ids;
    for (const Candidate& cand : unique) {
      if (cand.group != &group) continue;
      matches.push_back(cand.match);
      ids.push_back(cand.landmark_id);
    }
    if (matches.empty()) continue;
    const SE3 T_kf_curr = group.kf->T_world_camera.inverse() * T_world_curr;
    std::vector<std::uint8_t> inliers;
    markInliers(matches, K, T_kf_curr, config_.inlier_threshold_px, inliers);
    if (config_.patch_refinement) {
      alignInlierPatches(group.kf->features, T_kf_curr, curr, matches, inliers);
      markInliers(matches, K, T_kf_curr, config_.inlier_threshold_px, inliers);
    }
    for (std::size_t i = 0; i < matches.size(); ++i) {
      if (!inliers[i]) continue;
      Correspondence c = matches[i];
      c.point_ref = group.kf->T_world_camera * c.point_ref;
      all.push_back(c);
      use.push_back(1);
      landmark_of_match.push_back(ids[i]);
    }
  }
  attempt.time_matching_ms += msSince(t0);
  res.stats.time_matching_ms += msSince(t0);
  if (all.size() == own) return;
  const std::int64_t t1 = steadyNowNs();
  const RefinementResult refined = refineAndRemark(all, use, K, T_world_curr, config_);
  const double motion_ms = msSince(t1);
  attempt.time_motion_ms += motion_ms;
  res.stats.time_motion_ms += motion_ms;
  if (!refined.success) return;
  // The covariance stays the reference's own (the landmarks' positions are uncertain too); the
  // estimate moves.
  T_world_curr = normalizedSE3(refined.T_ref_curr);
  attempt.T_ref_curr = normalizedSE3(T_world_ref.inverse() * T_world_curr);
  res.T_ref_curr = attempt.T_ref_curr;
  if (curr_landmarks_.size() < cf.size()) curr_landmarks_.resize(cf.size(), -1);
  int local_inliers = 0;
  for (std::size_t k = own; k < all.size(); ++k) {
    if (!use[k]) continue;
    ++local_inliers;
    curr_landmarks_[static_cast<std::size_t>(all[k].curr_index)] = landmark_of_match[k - own];
  }
  res.stats.local_map_inliers = local_inliers;
}

void VisualOdometry::addKeyframe(const CurrentFrame& curr, const RgbdFrame& frame,
                                 const RgbdFramePtr& frame_ptr, const SE3& T_world_curr,
                                 OdometryResult& res) {
  keyframe_ = makeKeyframe(curr, frame, frame_ptr, T_world_curr);
  res.is_keyframe = true;
  res.keyframe = keyframe_;
  last_keyframe_made_utime_ = frame.utime;
  addToWindow(keyframe_, curr_landmarks_);
}

void VisualOdometry::addToWindow(const KeyframePtr& keyframe,
                                 const std::vector<std::int64_t>& feature_landmarks) {
  recent_keyframes_.push_back(keyframe);
  local_map_.addKeyframe(keyframe, feature_landmarks);
  while (static_cast<int>(recent_keyframes_.size()) > config_.keyframe_window) {
    local_map_.removeKeyframe(recent_keyframes_.front()->id);
    recent_keyframes_.pop_front();
  }
}

OdometryResult VisualOdometry::process(const RgbdFrame& frame, const RgbdFramePtr& frame_ptr) {
  const std::int64_t t_start = steadyNowNs();
  OdometryResult res;
  res.utime = frame.utime;
  res.sequence = frame.sequence;
  res.prev_utime = prev_utime_;

  CurrentFrame curr;
  cv::Mat small;
  curr_landmarks_.clear();
  if (const auto failure = prepareFrame(frame, frame_ptr, curr, small, res.stats)) {
    if (!curr.features || !keyframe_) {
      if (curr.features) prev_small_ = small;
      return fail(std::move(res), *failure, curr.features, t_start);
    }
    // The image is usable but its features are too few: dense alignment may still measure it.
    const SE3 T_world_pred = T_world_prev_ * predictMotion(small, curr.K);
    SE3 T_world_curr;
    if (!measureDense(curr, T_world_pred, res, T_world_curr)) {
      return fail(std::move(res), *failure, curr.features, t_start);
    }
    return acceptMeasurement(std::move(res), curr, frame, frame_ptr, T_world_curr, false, t_start);
  }
  if (!keyframe_) {
    prev_small_ = small;
    SE3 T_world_curr;
    if (state_ == TrackingState::kLost && relocalizeAfterLoss(curr, T_world_curr, res)) {
      OdometryResult out =
          acceptMeasurement(std::move(res), curr, frame, frame_ptr, T_world_curr, false, t_start);
      // The step from the held pose is the loss's, not a velocity to extrapolate.
      have_velocity_ = false;
      return out;
    }
    return startSegment(std::move(res), curr, frame, frame_ptr, t_start);
  }

  const SE3 T_prev_curr_pred = predictMotion(small, curr.K);
  const SE3 T_world_pred = T_world_prev_ * T_prev_curr_pred;
  const double dt_s = static_cast<double>(frame.utime - last_measured_utime_) * 1e-6;
  moveDepthsToColourTime(frame, T_prev_curr_pred, curr);
  ReferenceMeasurement measured = measureAgainstReference(T_world_pred, curr, dt_s, res.stats);
  TrackAttempt& attempt = measured.attempt;
  res.stats.num_matches = attempt.num_matches;
  res.stats.num_inliers = attempt.num_inliers;
  res.stats.reprojection_error_px = attempt.rms_px;
  res.stats.used_guided_matching = attempt.guided;
  res.stats.used_previous_frame = measured.from_previous;
  res.stats.time_matching_ms = attempt.time_matching_ms;
  res.stats.time_motion_ms = attempt.time_motion_ms;
  if (attempt.status != OdometryStatus::kOk) {
    SE3 T_world_curr;
    if (!measureDense(curr, T_world_pred, res, T_world_curr)) {
      return fail(std::move(res), attempt.status, curr.features, t_start);
    }
    // Features exist but matched nothing: with enough of them, the frame is the new keyframe
    // the following frames track against.
    const bool new_keyframe = curr.features->num_with_depth >= config_.keyframe_min_inliers;
    return acceptMeasurement(std::move(res), curr, frame, frame_ptr, T_world_curr, new_keyframe,
                             t_start);
  }

  setMeasured(res, TrackingState::kOk, attempt.T_ref_curr, attempt.covariance, measured.ref_utime,
              measured.ref_id);

  SE3 T_world_curr = normalizedSE3(measured.T_world_ref * attempt.T_ref_curr);
  bool new_keyframe = measured.from_previous ||
                      needsNewKeyframe(attempt, *keyframe_, curr.features->num_with_depth);
  bool keyframe_is_reference = !measured.from_previous;
  // A keyframe for relocalisation is wanted as a view of its own: no re-use.
  const bool for_relocalization =
      !new_keyframe && wantsRelocalizationKeyframe(attempt, curr, frame.utime);
  if (for_relocalization) {
    new_keyframe = true;
    ++relocalization_keyframes_made_;
    res.stats.relocalization_keyframe = true;
  }
  if (new_keyframe && !for_relocalization && config_.keyframe_window > 1 &&
      reuseRecentKeyframe(curr, attempt, !measured.from_previous, T_world_curr, res)) {
    new_keyframe = false;
    keyframe_is_reference = true;
  }
  if (config_.local_map) {
    if (keyframe_is_reference) associateWithKeyframe(attempt, *keyframe_, curr_landmarks_);
    trackLocalMap(curr, keyframe_is_reference ? keyframe_->T_world_camera : measured.T_world_ref,
                  keyframe_is_reference, attempt, T_world_curr, res);
  } else if (!measured.from_previous && config_.jointReferences() > 0) {
    refineInLocalWindow(curr, attempt, T_world_curr, res);
  }
  if (keyframe_is_reference) refineWithPreviousFrame(curr, attempt, T_world_curr, res);
  refineWithDenseAlignment(curr, attempt, keyframe_is_reference, T_world_curr, res);
  // Re-using another keyframe or refining can move the estimate: the veto holds for the result.
  if (rejected(T_world_curr, attempt.covariance, T_world_pred, dt_s, res.stats)) {
    return fail(std::move(res), OdometryStatus::kImplausibleMotion, curr.features, t_start);
  }
  return acceptMeasurement(std::move(res), curr, frame, frame_ptr, T_world_curr, new_keyframe,
                           t_start);
}

bool VisualOdometry::relocalizeAfterLoss(const CurrentFrame& curr, SE3& T_world_curr,
                                         OdometryResult& res) {
  const double dt_s = static_cast<double>(curr.utime - last_measured_utime_) * 1e-6;
  int tried = 0;
  for (auto it = recent_keyframes_.rbegin();
       it != recent_keyframes_.rend() && tried < config_.relocalization_keyframes; ++it, ++tried) {
    const KeyframePtr& kf = *it;
    // Guided at the pose held through the loss first; the whole image when that finds too few.
    const TrackAttempt attempt =
        track(kf->features, kf->T_world_camera.inverse() * T_world_prev_, true, curr);
    res.stats.time_matching_ms += attempt.time_matching_ms;
    res.stats.time_motion_ms += attempt.time_motion_ms;
    if (attempt.status != OdometryStatus::kOk ||
        attempt.num_inliers < config_.relocalization_min_inliers) {
      continue;
    }
    const SE3 T_world_candidate = normalizedSE3(kf->T_world_camera * attempt.T_ref_curr);
    if (!implausibility(T_world_candidate, attempt.covariance, dt_s).empty()) {
      ++res.stats.implausible_estimates;
      continue;
    }
    keyframe_ = kf;
    T_world_curr = T_world_candidate;
    setMeasured(res, TrackingState::kRelocalized, attempt.T_ref_curr, attempt.covariance, kf->utime,
                kf->id);
    res.stats.num_matches = attempt.num_matches;
    res.stats.num_inliers = attempt.num_inliers;
    res.stats.reprojection_error_px = attempt.rms_px;
    res.stats.used_guided_matching = attempt.guided;
    return true;
  }
  return false;
}

OdometryResult VisualOdometry::acceptMeasurement(OdometryResult res, const CurrentFrame& curr,
                                                 const RgbdFrame& frame,
                                                 const RgbdFramePtr& frame_ptr,
                                                 const SE3& T_world_curr, bool new_keyframe,
                                                 std::int64_t t_start) {
  res.T_world_camera = T_world_curr;
  res.T_prev_curr = normalizedSE3(T_world_prev_.inverse() * T_world_curr);
  res.segment = segment_;
  if (res.reference_keyframe_id == keyframe_->id) {
    covariance_keyframe_prev_ = res.covariance_ref_curr;
  } else {
    covariance_keyframe_prev_ = chainedCovariance(res.T_prev_curr, res.covariance);
    if (new_keyframe) {
      // The back end's edge from the previous keyframe: the chain of measurements since it.
      res.reference_keyframe_id = keyframe_->id;
      res.ref_utime = keyframe_->utime;
      res.T_ref_curr = normalizedSE3(keyframe_->T_world_camera.inverse() * T_world_curr);
      res.covariance_ref_curr = covariance_keyframe_prev_;
    }
  }
  if (new_keyframe) {
    addKeyframe(curr, frame, frame_ptr, T_world_curr, res);
    covariance_keyframe_prev_ = Matrix6d::Zero();
  }
  velocity_prev_curr_ = res.T_prev_curr;
  have_velocity_ = true;
  last_covariance_ = res.covariance;
  failed_frames_ = 0;
  state_ = TrackingState::kOk;
  rememberMeasuredFrame(curr, T_world_curr, frame.utime);
  return commit(std::move(res), curr.features, true, t_start);
}

void VisualOdometry::rememberMeasuredFrame(const CurrentFrame& curr, const SE3& T_world_curr,
                                           Utime utime) {
  T_world_last_measured_ = T_world_curr;
  last_measured_utime_ = utime;
  // A frame without depth cannot be dense alignment's reference: the last one with depth stays.
  if (!config_.dense_fallback || !hasDepthCoverage(curr.depth_m)) return;
  dense_reference_.gray = curr.gray;
  dense_reference_.depth_m = curr.depth_m;
  dense_reference_.K = curr.K;
  dense_reference_.pyramid = curr.pyramid;
  dense_reference_.T_world_camera = T_world_curr;
  dense_reference_.utime = utime;
}

Matrix6d VisualOdometry::chainedCovariance(const SE3& T_prev_curr,
                                           const Matrix6d& step_covariance) const {
  // T_kf_curr = T_kf_prev exp(a) T_prev_curr exp(b) = T_kf_curr exp(Ad(T_prev_curr^-1) a + b).
  const Matrix6d ad = adjointSE3(T_prev_curr.inverse());
  return ad * covariance_keyframe_prev_ * ad.transpose() + step_covariance;
}

void VisualOdometry::buildDensePyramids(CurrentFrame& curr) {
  if (!dense_reference_.pyramid) {
    dense_reference_.pyramid = std::make_shared<const DenseFrame>(makeDenseFrame(
        dense_reference_.gray, dense_reference_.depth_m, dense_reference_.K, dense_options_));
  }
  if (!curr.pyramid) {
    curr.pyramid = std::make_shared<const DenseFrame>(
        makeDenseFrame(curr.gray, curr.depth_m, curr.K, dense_options_));
  }
}

bool VisualOdometry::measureDense(CurrentFrame& curr, const SE3& T_world_pred, OdometryResult& res,
                                  SE3& T_world_curr) {
  if (!config_.dense_fallback || dense_reference_.gray.empty() || curr.gray.empty() ||
      (state_ != TrackingState::kOk && state_ != TrackingState::kPredicted) ||
      dense_reference_.K.width != curr.K.width || dense_reference_.K.height != curr.K.height) {
    return false;
  }
  const std::int64_t t0 = steadyNowNs();
  buildDensePyramids(curr);
  // The prior: constant velocity from the last measured frame, as uncertain as a change of
  // speed and turn rate over the interval allows.
  const double interval_s =
      std::max(static_cast<double>(curr.utime - dense_reference_.utime) * 1e-6, 1e-3);
  const SE3& T_world_ref = dense_reference_.T_world_camera;
  const DenseAlignmentResult dense =
      alignDense(*dense_reference_.pyramid, *curr.pyramid, T_world_ref.inverse() * T_world_pred,
                 motionPriorCovariance(interval_s), dense_options_);
  res.stats.time_dense_ms = msSince(t0);
  if (!dense.success) return false;
  T_world_curr = normalizedSE3(T_world_ref * dense.T_ref_curr);
  const double dt_s = static_cast<double>(curr.utime - last_measured_utime_) * 1e-6;
  if (!implausibility(T_world_curr, dense.covariance, dt_s).empty()) {
    ++res.stats.implausible_estimates;
    return false;
  }
  setMeasured(res, TrackingState::kOk, dense.T_ref_curr, dense.covariance, dense_reference_.utime,
              -1);
  res.stats.used_dense_alignment = true;
  res.stats.dense_degenerate_directions = dense.degenerate_directions;
  return true;
}

}  // namespace slamd
