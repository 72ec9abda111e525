#include "slamd/planes/plane_segmenter.hpp"

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <tuple>
#include <utility>

#include <Eigen/Eigenvalues>
#include <opencv2/imgproc.hpp>

namespace slamd::planes {
namespace {

constexpr int kMinFitSamples = 6;
/// A fit needs a spread of at least this (metres, standard deviation along the second principal
/// axis) and a second eigenvalue 4x the smallest: rejects collinear and tiny point sets.
constexpr double kMinExtentM = 0.005;
constexpr double kMinEigenRatio = 4.0;
/// A final plane whose centroid is seen at less than this sine of an angle to the plane (about
/// 3 deg) is seen edge-on: a strip of pixels one or two columns wide lies in the plane through
/// its rays and the optical centre whatever the depths, so the fit says nothing about a surface.
constexpr double kMinViewSine = 0.05;
/// Growing uses the segment's plane only once its normal is this well determined (radians, a
/// rough standard deviation: model RMS / (sqrt(n) * extent)); a plane from a handful of noisy
/// samples would stop the growth early.
constexpr double kMaxGrowNormalSigmaRad = 0.03;
/// First sample count at which the growing segment's plane is fitted (then at 2x, 4x, ...).
constexpr int kFirstGrowFit = 16;
/// Boundary refinement moves a fold between planes, or a plane's edge into unlabelled samples,
/// by one sample per pass; it runs kBoundaryRefinePx / step_px + 1 passes at most (about the
/// same reach in pixels at any grid step) and stops earlier when nothing moves.
constexpr int kBoundaryRefinePx = 32;
/// Robust refits of each final plane (see buildPlanes) and the smallest outlier distance they
/// use, metres.
constexpr int kRobustRefits = 2;
constexpr double kMinInlierDistanceM = 0.001;
/// Floor on |n.r| in the area footprint (grazing pixels would otherwise have unbounded area).
constexpr double kMinFootprintCos = 0.05;

}  // namespace

std::string PlaneSegmenterParams::validationError() const {
  if (!(lab_threshold > 0.0 && lab_threshold <= 200.0)) return "lab_threshold must be in (0, 200]";
  if (step_px < 1 || step_px > 16) return "step_px must be in 1..16";
  if (!(min_depth_m >= 0.0)) return "min_depth_m must be >= 0";
  if (!(max_depth_m > min_depth_m)) return "max_depth_m must be > min_depth_m";
  if (min_segment_px < 1) return "min_segment_px must be >= 1";
  if (min_plane_px < 1) return "min_plane_px must be >= 1";
  if (!(merge_normal_dot >= -1.0)) return "merge_normal_dot must be >= -1";
  if (!(merge_rms_ratio >= 1.0)) return "merge_rms_ratio must be >= 1";
  if (!(merge_rms_tolerance_m >= 0.0)) return "merge_rms_tolerance_m must be >= 0";
  if (!(max_rms_m >= 0.0)) return "max_rms_m must be >= 0";
  if (!(max_noise_ratio >= 0.0)) return "max_noise_ratio must be >= 0";
  if (!(depth_jump_ratio >= 0.0)) return "depth_jump_ratio must be >= 0";
  if (!(grow_plane_distance_m >= 0.0)) return "grow_plane_distance_m must be >= 0";
  if (!(outlier_margin_m >= 0.0)) return "outlier_margin_m must be >= 0";
  return "";
}

PlaneSegmenterParams PlaneSegmenterParams::paper() {
  PlaneSegmenterParams params;
  params.lab_threshold = 15.0;
  params.step_px = 1;
  params.criterion = GrowCriterion::kColor;
  return params;
}

void PlaneSegmenter::Moments::add(const Eigen::Vector3d& point, double weight) {
  w += weight;
  wp += weight * point;
  wpp.noalias() += weight * point * point.transpose();
  inv_w += 1.0 / weight;
  ++n;
  p += point;
  pp.noalias() += point * point.transpose();
}

void PlaneSegmenter::Moments::add(const Moments& other) {
  w += other.w;
  wp += other.wp;
  wpp += other.wpp;
  inv_w += other.inv_w;
  n += other.n;
  p += other.p;
  pp += other.pp;
}

PlaneSegmenter::Fit PlaneSegmenter::fitMoments(const Moments& m) {
  Fit fit;
  if (m.n < kMinFitSamples || !(m.w > 0.0)) return fit;
  const Eigen::Vector3d mean = m.wp / m.w;
  const Eigen::Matrix3d scatter = m.wpp / m.w - mean * mean.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  if (solver.info() != Eigen::Success) return fit;
  const Eigen::Vector3d eigenvalues = solver.eigenvalues();  // ascending
  const double smallest = std::max(eigenvalues(0), 0.0);
  if (!(eigenvalues(1) >= kMinExtentM * kMinExtentM) ||
      !(eigenvalues(1) >= kMinEigenRatio * smallest)) {
    return fit;
  }
  Eigen::Vector3d normal = solver.eigenvectors().col(0).normalized();
  double offset = -normal.dot(mean);
  if (offset < 0.0) {  // make n point towards the camera (the origin): n.mean < 0
    normal = -normal;
    offset = -offset;
  }
  const double sum_sq = normal.dot(m.pp * normal) + 2.0 * offset * normal.dot(m.p) +
                        static_cast<double>(m.n) * offset * offset;
  fit.ok = true;
  fit.normal = normal;
  fit.offset_m = offset;
  fit.rms_m = std::sqrt(std::max(sum_sq, 0.0) / m.n);
  fit.model_rms_m = offset * std::sqrt(m.inv_w / m.n);
  fit.extent_m = std::sqrt(eigenvalues(1));
  return fit;
}

bool PlaneSegmenter::acceptable(const Fit& fit) const {
  return fit.ok &&
         (fit.rms_m <= params_.max_rms_m || fit.rms_m <= params_.max_noise_ratio * fit.model_rms_m);
}

PlaneSegmenter::PlaneSegmenter(const PlaneSegmenterParams& params) : params_(params) {
  const std::string error = params_.validationError();
  if (!error.empty()) throw std::invalid_argument("PlaneSegmenterParams: " + error);
  // OpenCV builds its 8-bit Lab tables on the first conversion, and two threads converting for
  // the first time at once can both build them (one set is then leaked). Segmenters are made
  // before the threads that use them start, so converting one pixel here builds them once.
  cv::Mat one_pixel_lab;
  cv::cvtColor(cv::Mat(1, 1, CV_8UC3, cv::Scalar(0, 0, 0)), one_pixel_lab, cv::COLOR_BGR2Lab);
}

const PlaneSegmentation& PlaneSegmenter::segment(const RgbdFrame& frame) {
  return segment(frame.color_bgr, frame.depth_m, frame.intrinsics);
}

const PlaneSegmentation& PlaneSegmenter::segment(const cv::Mat& color_bgr, const cv::Mat& depth_m,
                                                 const CameraIntrinsics& intrinsics) {
  if (color_bgr.empty()) throw std::invalid_argument("PlaneSegmenter: empty colour image");
  if (depth_m.empty()) throw std::invalid_argument("PlaneSegmenter: empty depth image");
  if (color_bgr.type() != CV_8UC3)
    throw std::invalid_argument("PlaneSegmenter: colour image must be CV_8UC3 (BGR)");
  if (depth_m.type() != CV_32FC1)
    throw std::invalid_argument("PlaneSegmenter: depth image must be CV_32FC1 (metres)");
  if (color_bgr.size() != depth_m.size())
    throw std::invalid_argument("PlaneSegmenter: colour and depth sizes differ");
  if (color_bgr.cols != intrinsics.width || color_bgr.rows != intrinsics.height)
    throw std::invalid_argument("PlaneSegmenter: image size differs from the intrinsics' size");
  if (!(intrinsics.fx > 0.0 && intrinsics.fy > 0.0))
    throw std::invalid_argument("PlaneSegmenter: focal lengths must be positive");

  result_.planes.clear();
  result_.segments_grown = 0;
  result_.segments_fitted = 0;
  prepareGrid(color_bgr, depth_m, intrinsics);
  growSegments();
  fitSegments();
  mergeSegments();
  buildPlanes(depth_m, intrinsics);
  return result_;
}

void PlaneSegmenter::prepareGrid(const cv::Mat& color_bgr, const cv::Mat& depth_m,
                                 const CameraIntrinsics& intrinsics) {
  const int step = params_.step_px;
  grid_width_ = (color_bgr.cols + step - 1) / step;
  grid_height_ = (color_bgr.rows + step - 1) / step;
  const std::size_t samples = static_cast<std::size_t>(grid_width_) * grid_height_;

  // Lab once per frame on the (block-averaged) grid. OpenCV's 8-bit Lab stores L * 255 / 100,
  // a + 128 and b + 128: converted back to true units for the threshold.
  if (step == 1) {
    cv::cvtColor(color_bgr, small_lab_, cv::COLOR_BGR2Lab);
  } else {
    cv::resize(color_bgr, small_bgr_, cv::Size(grid_width_, grid_height_), 0.0, 0.0,
               cv::INTER_AREA);
    cv::cvtColor(small_bgr_, small_lab_, cv::COLOR_BGR2Lab);
  }
  lab_.resize(3 * samples);
  point_camera_.resize(samples);
  weight_.resize(samples);
  sigma_z_.resize(samples);
  for (int gy = 0; gy < grid_height_; ++gy) {
    const auto* lab_row = small_lab_.ptr<cv::Vec3b>(gy);
    const int v = std::min(gy * step + step / 2, color_bgr.rows - 1);
    const auto* depth_row = depth_m.ptr<float>(v);
    for (int gx = 0; gx < grid_width_; ++gx) {
      const std::size_t i = static_cast<std::size_t>(gy) * grid_width_ + gx;
      lab_[3 * i] = static_cast<float>(lab_row[gx][0]) * (100.0f / 255.0f);
      lab_[3 * i + 1] = static_cast<float>(lab_row[gx][1]) - 128.0f;
      lab_[3 * i + 2] = static_cast<float>(lab_row[gx][2]) - 128.0f;
      const int u = std::min(gx * step + step / 2, color_bgr.cols - 1);
      const double z = static_cast<double>(depth_row[u]);
      if (std::isfinite(z) && z > params_.min_depth_m && z <= params_.max_depth_m) {
        const double sigma = kinectSigmaZ(z);
        point_camera_[i] = intrinsics.backProject(u, v, z).cast<float>();
        sigma_z_[i] = sigma;
        weight_[i] = (z / sigma) * (z / sigma);
      } else {
        point_camera_[i].setZero();
        sigma_z_[i] = 0.0;
        weight_[i] = 0.0;
      }
    }
  }
}

void PlaneSegmenter::growSegments() {
  const std::size_t samples = weight_.size();
  segment_of_.assign(samples, -1);
  members_.clear();
  members_.reserve(samples);
  stack_.clear();
  stack_.reserve(samples);
  segments_.clear();
  const double threshold_sq = params_.lab_threshold * params_.lab_threshold;
  const bool use_depth = params_.criterion == GrowCriterion::kColorAndDepth;
  const double jump_per_step = params_.depth_jump_ratio * params_.step_px;
  const int width = grid_width_;
  const int height = grid_height_;

  for (std::size_t seed = 0; seed < samples; ++seed) {
    if (segment_of_[seed] >= 0 || weight_[seed] == 0.0) continue;
    const int id = static_cast<int>(segments_.size());
    Segment segment;
    segment.first = static_cast<int>(members_.size());
    double sum_l = 0.0, sum_a = 0.0, sum_b = 0.0;
    int next_fit = kFirstGrowFit;
    bool have_plane = false;
    Eigen::Vector3d plane_normal = Eigen::Vector3d::UnitZ();
    double plane_offset = 0.0;

    auto accept = [&](int index) {
      segment_of_[static_cast<std::size_t>(index)] = id;
      members_.push_back(index);
      stack_.push_back(index);
      sum_l += static_cast<double>(lab_[3 * static_cast<std::size_t>(index)]);
      sum_a += static_cast<double>(lab_[3 * static_cast<std::size_t>(index) + 1]);
      sum_b += static_cast<double>(lab_[3 * static_cast<std::size_t>(index) + 2]);
      segment.moments.add(point_camera_[static_cast<std::size_t>(index)].cast<double>(),
                          weight_[static_cast<std::size_t>(index)]);
      ++segment.count;
      if (use_depth && segment.count == next_fit) {
        next_fit *= 2;
        const Fit fit = fitMoments(segment.moments);
        const double normal_sigma =
            fit.ok ? fit.model_rms_m / (std::sqrt(static_cast<double>(segment.count)) *
                                        std::max(fit.extent_m, 1e-9))
                   : 1.0;
        if (fit.ok && normal_sigma <= kMaxGrowNormalSigmaRad) {
          have_plane = true;
          plane_normal = fit.normal;
          plane_offset = fit.offset_m;
        }
      }
    };
    accept(static_cast<int>(seed));

    while (!stack_.empty()) {
      const int current = stack_.back();
      stack_.pop_back();
      const int cx = current % width;
      const int cy = current / width;
      const int neighbours[4] = {cx > 0 ? current - 1 : -1, cx + 1 < width ? current + 1 : -1,
                                 cy > 0 ? current - width : -1,
                                 cy + 1 < height ? current + width : -1};
      for (const int next : neighbours) {
        if (next < 0) continue;
        const auto n = static_cast<std::size_t>(next);
        if (segment_of_[n] >= 0 || weight_[n] == 0.0) continue;
        const double inv = 1.0 / segment.count;
        const double dl = static_cast<double>(lab_[3 * n]) - sum_l * inv;
        const double da = static_cast<double>(lab_[3 * n + 1]) - sum_a * inv;
        const double db = static_cast<double>(lab_[3 * n + 2]) - sum_b * inv;
        if (dl * dl + da * da + db * db >= threshold_sq) continue;
        if (use_depth) {
          const Eigen::Vector3f& p = point_camera_[n];
          if (have_plane) {
            const double distance = std::abs(plane_normal.dot(p.cast<double>()) + plane_offset);
            if (distance > params_.grow_plane_distance_m + 3.0 * sigma_z_[n]) continue;
          } else {
            const auto c = static_cast<std::size_t>(current);
            const double z_current = static_cast<double>(point_camera_[c].z());
            if (std::abs(static_cast<double>(p.z()) - z_current) >
                jump_per_step * z_current + 4.0 * sigma_z_[c])
              continue;
          }
        }
        accept(next);
      }
    }
    segments_.push_back(segment);
  }
  result_.segments_grown = static_cast<int>(segments_.size());
}

void PlaneSegmenter::dropOutliers(Segment& segment, const Fit& fit) {
  Moments moments;
  int kept = 0;
  for (int k = 0; k < segment.count; ++k) {
    const int index = members_[static_cast<std::size_t>(segment.first + k)];
    const auto i = static_cast<std::size_t>(index);
    const Eigen::Vector3d p = point_camera_[i].cast<double>();
    const double residual = std::abs(fit.normal.dot(p) + fit.offset_m);
    if (residual <= 3.0 * sigma_z_[i] + params_.outlier_margin_m) {
      members_[static_cast<std::size_t>(segment.first + kept)] = index;
      ++kept;
      moments.add(p, weight_[i]);
    } else {
      segment_of_[i] = -1;
    }
  }
  segment.count = kept;
  segment.moments = moments;
}

void PlaneSegmenter::fitSegments() {
  const int pixels_per_sample = params_.step_px * params_.step_px;
  int fitted = 0;
  for (Segment& segment : segments_) {
    segment.valid = false;
    if (segment.count < kMinFitSamples ||
        static_cast<long>(segment.count) * pixels_per_sample < params_.min_segment_px) {
      continue;
    }
    const Fit first = fitMoments(segment.moments);
    if (!first.ok) continue;
    dropOutliers(segment, first);
    segment.fit = fitMoments(segment.moments);
    segment.valid = acceptable(segment.fit);
    if (segment.valid) ++fitted;
  }
  // Samples of segments without a plane do not count as neighbours when merging.
  for (std::size_t i = 0; i < segment_of_.size(); ++i) {
    const int id = segment_of_[i];
    if (id >= 0 && !segments_[static_cast<std::size_t>(id)].valid) segment_of_[i] = -1;
  }
  result_.segments_fitted = fitted;
}

int PlaneSegmenter::findRoot(int segment) {
  auto s = static_cast<std::size_t>(segment);
  while (merged_into_[s] != static_cast<int>(s)) {
    const auto parent = static_cast<std::size_t>(merged_into_[s]);
    merged_into_[s] = merged_into_[parent];  // path halving
    s = static_cast<std::size_t>(merged_into_[s]);
  }
  return static_cast<int>(s);
}

void PlaneSegmenter::mergeSegments() {
  merged_into_.resize(segments_.size());
  for (std::size_t s = 0; s < segments_.size(); ++s) merged_into_[s] = static_cast<int>(s);
  if (params_.merge_normal_dot > 1.0) return;

  // Adjacent pairs of segments with planes (right and down neighbours of every sample).
  std::vector<std::pair<int, int>> edges;
  for (int gy = 0; gy < grid_height_; ++gy) {
    for (int gx = 0; gx < grid_width_; ++gx) {
      const std::size_t i = static_cast<std::size_t>(gy) * grid_width_ + gx;
      const int a = segment_of_[i];
      if (a < 0) continue;
      if (gx + 1 < grid_width_) {
        const int b = segment_of_[i + 1];
        if (b >= 0 && b != a) edges.emplace_back(std::min(a, b), std::max(a, b));
      }
      if (gy + 1 < grid_height_) {
        const int b = segment_of_[i + static_cast<std::size_t>(grid_width_)];
        if (b >= 0 && b != a) edges.emplace_back(std::min(a, b), std::max(a, b));
      }
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());

  // Rounds of greedy merging, best normal agreement first, until no pair merges.
  std::vector<std::tuple<double, int, int>> candidates;
  bool merged = true;
  while (merged) {
    merged = false;
    candidates.clear();
    for (const auto& [a, b] : edges) {
      const int ra = findRoot(a);
      const int rb = findRoot(b);
      if (ra == rb) continue;
      const double dot = segments_[static_cast<std::size_t>(ra)].fit.normal.dot(
          segments_[static_cast<std::size_t>(rb)].fit.normal);
      if (dot >= params_.merge_normal_dot) candidates.emplace_back(dot, ra, rb);
    }
    std::sort(candidates.begin(), candidates.end(),
              [](const auto& x, const auto& y) { return std::get<0>(x) > std::get<0>(y); });
    for (const auto& candidate : candidates) {
      const int ra = findRoot(std::get<1>(candidate));
      const int rb = findRoot(std::get<2>(candidate));
      if (ra == rb) continue;
      Segment& sa = segments_[static_cast<std::size_t>(ra)];
      Segment& sb = segments_[static_cast<std::size_t>(rb)];
      if (sa.fit.normal.dot(sb.fit.normal) < params_.merge_normal_dot) continue;
      Moments both = sa.moments;
      both.add(sb.moments);
      const Fit fit = fitMoments(both);
      // One plane explains both only if the union fits about as well as the parts do.
      const double pooled_rms_m = std::sqrt((sa.moments.n * sa.fit.rms_m * sa.fit.rms_m +
                                             sb.moments.n * sb.fit.rms_m * sb.fit.rms_m) /
                                            (sa.moments.n + sb.moments.n));
      if (!acceptable(fit) ||
          fit.rms_m > params_.merge_rms_ratio * pooled_rms_m + params_.merge_rms_tolerance_m) {
        continue;
      }
      merged_into_[static_cast<std::size_t>(rb)] = ra;
      sa.moments = both;
      sa.fit = fit;
      merged = true;
    }
  }
}

void PlaneSegmenter::buildPlanes(const cv::Mat& depth_m, const CameraIntrinsics& intrinsics) {
  const int step = params_.step_px;
  const int pixels_per_sample = step * step;

  // Every sample's merged set ("group"), numbered by first appearance; the sample labels are
  // rewritten in place from segment ids to group ids.
  std::vector<int> group_of(segments_.size(), -1);
  std::vector<Fit> group_fit;
  for (std::size_t s = 0; s < segments_.size(); ++s) {
    if (!segments_[s].valid) continue;
    const auto root = static_cast<std::size_t>(findRoot(static_cast<int>(s)));
    if (group_of[root] < 0) {
      group_of[root] = static_cast<int>(group_fit.size());
      group_fit.push_back(segments_[root].fit);
    }
    group_of[s] = group_of[root];
  }
  for (int& label : segment_of_) {
    if (label >= 0) label = group_of[static_cast<std::size_t>(label)];
  }

  // Boundary refinement. Where two planes meet at a fold, growing lets a few samples of one
  // plane into its neighbour (they are within the growth tolerance of both), and the outlier
  // test then leaves a gap of unlabelled samples between the two. In each pass, every sample
  // next to another plane's sample moves to that plane when it lies nearer to it, and an
  // unlabelled sample with depth joins the nearest neighbouring plane within its outlier
  // distance (so planes also spread over a few samples that growing left out).
  // Each pass reads the previous pass's labels, so the result does not depend on scan order.
  auto residual = [&](int group, std::size_t i) {
    const Fit& fit = group_fit[static_cast<std::size_t>(group)];
    return std::abs(fit.normal.dot(point_camera_[i].cast<double>()) + fit.offset_m);
  };
  const std::size_t w = static_cast<std::size_t>(grid_width_);
  // Where sample i belongs after this pass (reads the previous pass's labels only).
  auto decide = [&](std::size_t i) {
    const int gx = static_cast<int>(i % w);
    const int gy = static_cast<int>(i / w);
    const int group = segment_of_[i];
    const int neighbours[4] = {
        gx > 0 ? segment_of_[i - 1] : -1, gx + 1 < grid_width_ ? segment_of_[i + 1] : -1,
        gy > 0 ? segment_of_[i - w] : -1, gy + 1 < grid_height_ ? segment_of_[i + w] : -1};
    int best = group;
    double best_residual = -1.0;  // computed only for samples at a boundary
    for (const int other : neighbours) {
      if (other < 0 || other == best || other == group) continue;
      if (best_residual < 0.0) {
        best_residual =
            group >= 0 ? residual(group, i) : 3.0 * sigma_z_[i] + params_.outlier_margin_m;
      }
      const double r = residual(other, i);
      if (r < best_residual) {
        best = other;
        best_residual = r;
      }
    }
    return best;
  };
  // The first pass looks at every sample with depth, later ones only where the previous pass
  // changed something (a changed sample and its neighbours).
  candidates_.clear();
  for (std::size_t i = 0; i < weight_.size(); ++i) {
    if (weight_[i] != 0.0) candidates_.push_back(static_cast<int>(i));
  }
  visit_.assign(weight_.size(), -1);
  const int passes = kBoundaryRefinePx / step + 1;
  for (int pass = 0; pass < passes && !group_fit.empty(); ++pass) {
    changes_.clear();
    for (const int candidate : candidates_) {
      const auto i = static_cast<std::size_t>(candidate);
      const int best = decide(i);
      if (best != segment_of_[i]) changes_.emplace_back(candidate, best);
    }
    if (changes_.empty()) break;
    for (const auto& [index, group] : changes_)
      segment_of_[static_cast<std::size_t>(index)] = group;
    candidates_.clear();
    auto visit = [&](std::size_t j) {
      if (weight_[j] != 0.0 && visit_[j] != pass) {
        visit_[j] = pass;
        candidates_.push_back(static_cast<int>(j));
      }
    };
    for (const auto& change : changes_) {
      const auto i = static_cast<std::size_t>(change.first);
      const std::size_t gx = i % w;
      visit(i);
      if (gx > 0) visit(i - 1);
      if (gx + 1 < w) visit(i + 1);
      if (i >= w) visit(i - w);
      if (i + w < weight_.size()) visit(i + w);
    }
  }

  // Each group's samples in raster order, outliers of its merged plane dropped.
  std::vector<std::vector<int>> groups(group_fit.size());
  for (std::size_t i = 0; i < segment_of_.size(); ++i) {
    const int group = segment_of_[i];
    if (group < 0) continue;
    if (residual(group, i) <= 3.0 * sigma_z_[i] + params_.outlier_margin_m) {
      groups[static_cast<std::size_t>(group)].push_back(static_cast<int>(i));
    }
  }

  std::vector<double> ratios;
  for (std::size_t g = 0; g < groups.size(); ++g) {
    std::vector<int>& kept = groups[g];
    if (static_cast<long>(kept.size()) * pixels_per_sample < params_.min_plane_px) continue;
    Moments moments;
    for (const int index : kept) {
      const auto i = static_cast<std::size_t>(index);
      moments.add(point_camera_[i].cast<double>(), weight_[i]);
    }
    Fit fit = fitMoments(moments);
    // Robust refits: items standing a few millimetres off a wall (skirting, doors, posters) are
    // within the noise model's outlier distance and merge into it, tilting its fit when the
    // data are better than the model. Residuals are compared with the data's own spread: the
    // scale s = median(|r| / sigma_z) / 0.6745 (1 for data as noisy as the model), and samples
    // beyond max(3 s sigma_z, kMinInlierDistanceM) are dropped, never more than the model
    // itself would drop.
    for (int round = 0; round < kRobustRefits && fit.ok; ++round) {
      ratios.clear();
      for (const int index : kept) {
        const auto i = static_cast<std::size_t>(index);
        ratios.push_back(std::abs(fit.normal.dot(point_camera_[i].cast<double>()) + fit.offset_m) /
                         sigma_z_[i]);
      }
      const auto middle = ratios.begin() + static_cast<long>(ratios.size() / 2);
      std::nth_element(ratios.begin(), middle, ratios.end());
      const double scale = *middle / 0.6745;
      Moments robust;
      std::size_t count = 0;
      for (const int index : kept) {
        const auto i = static_cast<std::size_t>(index);
        const Eigen::Vector3d p = point_camera_[i].cast<double>();
        const double limit = std::min(3.0 * sigma_z_[i] + params_.outlier_margin_m,
                                      std::max(3.0 * scale * sigma_z_[i], kMinInlierDistanceM));
        if (std::abs(fit.normal.dot(p) + fit.offset_m) <= limit) {
          kept[count++] = index;
          robust.add(p, weight_[i]);
        }
      }
      kept.resize(count);
      moments = robust;
      fit = fitMoments(moments);
    }
    if (!acceptable(fit)) continue;
    if (static_cast<long>(moments.n) * pixels_per_sample < params_.min_plane_px) continue;
    if (fit.offset_m < kMinViewSine * (moments.p / moments.n).norm()) continue;

    Plane plane;
    plane.normal_camera = fit.normal;
    plane.offset_m = fit.offset_m;
    plane.inlier_samples = moments.n;
    plane.inlier_pixels = moments.n * pixels_per_sample;
    plane.centroid_camera = moments.p / moments.n;
    plane.rms_error_m = fit.rms_m;

    // Covariance of (n, d): information of the weighted residuals on the 3-dimensional tangent
    // space of |n| = 1 (two tilts of n and d); a sample's residual variance is
    // sigma_z^2 d^2 / z^2, so the information is H / d^2 with H from the weighted moments.
    Eigen::Matrix4d H;
    H.topLeftCorner<3, 3>() = moments.wpp;
    H.topRightCorner<3, 1>() = moments.wp;
    H.bottomLeftCorner<1, 3>() = moments.wp.transpose();
    H(3, 3) = moments.w;
    const Eigen::Vector3d t1 = fit.normal.unitOrthogonal();
    const Eigen::Vector3d t2 = fit.normal.cross(t1);
    Eigen::Matrix<double, 4, 3> basis = Eigen::Matrix<double, 4, 3>::Zero();
    basis.block<3, 1>(0, 0) = t1;
    basis.block<3, 1>(0, 1) = t2;
    basis(3, 2) = 1.0;
    const double d_sq = std::max(fit.offset_m * fit.offset_m, 1e-12);
    const Eigen::Matrix3d information = basis.transpose() * H * basis / d_sq;
    Eigen::Vector4d theta;
    theta << fit.normal, fit.offset_m;
    const double chi2 = std::max(theta.dot(H * theta) / d_sq, 0.0);
    const double dof = std::max(moments.n - 3, 1);
    const double scale = std::max(1.0, chi2 / dof);
    const Eigen::LDLT<Eigen::Matrix3d> ldlt(information);
    if (ldlt.info() == Eigen::Success && ldlt.isPositive()) {
      plane.covariance =
          scale * basis * ldlt.solve(Eigen::Matrix3d::Identity()) * basis.transpose();
    } else {
      plane.covariance = Eigen::Matrix4d::Identity() * 1e6;  // unconstrained: say so loudly
    }

    plane.pixels.reserve(kept.size());
    double area = 0.0;
    const double footprint_scale =
        fit.offset_m * fit.offset_m / (intrinsics.fx * intrinsics.fy) * pixels_per_sample;
    for (const int index : kept) {
      const int gx = index % grid_width_;
      const int gy = index / grid_width_;
      const int u = std::min(gx * step + step / 2, depth_m.cols - 1);
      const int v = std::min(gy * step + step / 2, depth_m.rows - 1);
      plane.pixels.emplace_back(u, v);
      // z_plane = d / |n.r|, footprint z_plane^2 / (fx fy) / |n.r|.
      const double cos_term =
          std::max(std::abs(fit.normal.dot(intrinsics.ray(u, v))), kMinFootprintCos);
      area += footprint_scale / (cos_term * cos_term * cos_term);
    }
    plane.area_m2 = area;

    std::vector<cv::Point> hull;
    cv::convexHull(plane.pixels, hull);
    plane.boundary_camera.reserve(hull.size());
    for (const cv::Point& corner : hull) {
      const Eigen::Vector3d ray = intrinsics.ray(corner.x, corner.y);
      const double denominator = fit.normal.dot(ray);
      if (!(denominator < -1e-9)) continue;  // ray parallel to the plane or hitting its back
      plane.boundary_camera.push_back(ray * (-fit.offset_m / denominator));
    }
    result_.planes.push_back(std::move(plane));
  }

  std::stable_sort(
      result_.planes.begin(), result_.planes.end(),
      [](const Plane& a, const Plane& b) { return a.inlier_samples > b.inlier_samples; });

  // Labels: per grid sample first, then each grid row expanded to its step_px image rows.
  std::fill(segment_of_.begin(), segment_of_.end(), -1);
  for (std::size_t p = 0; p < result_.planes.size(); ++p) {
    for (const cv::Point& pixel : result_.planes[p].pixels) {
      segment_of_[static_cast<std::size_t>(pixel.y / step) * grid_width_ + pixel.x / step] =
          static_cast<int>(p);
    }
  }
  result_.labels.create(depth_m.size(), CV_32SC1);
  for (int gy = 0; gy < grid_height_; ++gy) {
    const int y0 = gy * step;
    int* first = result_.labels.ptr<int>(y0);
    const int* grid_row = segment_of_.data() + static_cast<std::size_t>(gy) * grid_width_;
    for (int gx = 0; gx < grid_width_; ++gx) {
      std::fill(first + gx * step, first + std::min((gx + 1) * step, depth_m.cols), grid_row[gx]);
    }
    for (int y = y0 + 1; y < std::min(y0 + step, depth_m.rows); ++y) {
      std::copy(first, first + depth_m.cols, result_.labels.ptr<int>(y));
    }
  }
}

std::vector<Eigen::Vector3d> samplePlanePoints(const Plane& plane, int count,
                                               const CameraIntrinsics& intrinsics,
                                               std::uint64_t seed) {
  std::vector<Eigen::Vector3d> points;
  if (count <= 0 || plane.pixels.empty()) return points;
  points.reserve(static_cast<std::size_t>(count));
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<std::size_t> pick(0, plane.pixels.size() - 1);
  // Inlier pixels see the plane from its front (n.r < 0); the attempt cap only guards against a
  // plane record whose pixels do not (a hand-edited one).
  for (long attempt = 0; attempt < 10L * count && static_cast<int>(points.size()) < count;
       ++attempt) {
    const cv::Point& pixel = plane.pixels[pick(rng)];
    const Eigen::Vector3d ray = intrinsics.ray(pixel.x, pixel.y);
    const double denominator = plane.normal_camera.dot(ray);
    if (!(denominator < -1e-9)) continue;
    points.push_back(ray * (-plane.offset_m / denominator));
  }
  return points;
}

}  // namespace slamd::planes
