#include "slamd/filter/vanishing_point_detector.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>

#include <Eigen/Dense>

namespace slamd {

namespace {

constexpr double kDegToRad = M_PI / 180.0;
// Two lines whose normals' cross product is below this (sine of the angle between the lines,
// about 0.3 degrees) meet too far away for their intersection to be a useful candidate.
constexpr double kMinIntersectionSine = 5e-3;

/// A segment as a line in Hessian form: normal . x = c, |normal| = 1.
struct LineRow {
  Eigen::Vector2d normal;
  double c = 0.0;
  Eigen::Vector2d midpoint;
  Eigen::Vector2d direction;  ///< unit
  double length_px = 0.0;
};

LineRow makeRow(const LineSegment& s) {
  LineRow row;
  const Eigen::Vector2d d = s.p2_px - s.p1_px;
  row.length_px = d.norm();
  row.direction = d / row.length_px;
  row.normal = Eigen::Vector2d(-row.direction.y(), row.direction.x());
  row.midpoint = 0.5 * (s.p1_px + s.p2_px);
  row.c = row.normal.dot(row.midpoint);
  return row;
}

/// True when the segment points at u within the angle whose sine is max_sine.
bool supports(const LineRow& row, const Eigen::Vector2d& u, double max_sine) {
  const Eigen::Vector2d q = u - row.midpoint;
  const double q_norm = q.norm();
  if (q_norm < 1e-9) return true;
  const double cross = row.direction.x() * q.y() - row.direction.y() * q.x();
  return std::abs(cross) <= max_sine * q_norm;
}

/// Hough segments join integer edge pixels, a pixel or two off the true line (at half resolution
/// that is 2-4 full-resolution pixels at the vanishing point). Refit the segment's line by least
/// squares (principal axis) to every edge pixel within one pixel of it, then move its endpoints
/// onto the fitted line. Keeps the input when too few pixels are found.
void refineOnEdges(const cv::Mat& edges, const Eigen::Vector2d& p1, const Eigen::Vector2d& p2,
                   Eigen::Vector2d* q1, Eigen::Vector2d* q2) {
  const Eigen::Vector2d d = p2 - p1;
  const double length = d.norm();
  if (length < 2.0) return;
  const Eigen::Vector2d t = d / length;
  const Eigen::Vector2d n(-t.y(), t.x());
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  Eigen::Matrix2d sum_sq = Eigen::Matrix2d::Zero();
  int count = 0;
  int last_x = -1, last_y = -1;
  const int steps = static_cast<int>(length);
  for (int i = 0; i <= steps; ++i) {
    const Eigen::Vector2d c = p1 + t * static_cast<double>(i);
    for (int o = -1; o <= 1; ++o) {
      const Eigen::Vector2d q = c + n * static_cast<double>(o);
      const int x = static_cast<int>(std::lround(q.x()));
      const int y = static_cast<int>(std::lround(q.y()));
      if (x < 0 || y < 0 || x >= edges.cols || y >= edges.rows) continue;
      if (x == last_x && y == last_y) continue;
      if (edges.at<std::uint8_t>(y, x) == 0) continue;
      last_x = x;
      last_y = y;
      const Eigen::Vector2d v(x, y);
      sum += v;
      sum_sq += v * v.transpose();
      ++count;
    }
  }
  if (count < 5) return;
  const Eigen::Vector2d mean = sum / count;
  const Eigen::Matrix2d scatter = sum_sq / count - mean * mean.transpose();
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);
  Eigen::Vector2d axis = eig.eigenvectors().col(1);
  if (axis.dot(t) < 0.0) axis = -axis;
  if (axis.dot(t) < std::cos(5.0 * kDegToRad)) return;  // fit drifted onto another structure
  *q1 = mean + axis * axis.dot(p1 - mean);
  *q2 = mean + axis * axis.dot(p2 - mean);
}

/// Bilinear grey value at (x, y) (pixels, centre of pixel 0 at 0); the caller keeps (x, y) at
/// least one pixel inside the image.
double bilinear(const cv::Mat& gray, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x));
  const int y0 = static_cast<int>(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  const std::uint8_t* row0 = gray.ptr<std::uint8_t>(y0);
  const std::uint8_t* row1 = gray.ptr<std::uint8_t>(y0 + 1);
  const double top = (1.0 - fx) * row0[x0] + fx * row0[x0 + 1];
  const double bottom = (1.0 - fx) * row1[x0] + fx * row1[x0 + 1];
  return (1.0 - fy) * top + fy * bottom;
}

/// Sub-pixel refit of a segment's line on the full-resolution grey image (full-resolution pixels,
/// before undistortion). Lines through edge-pixel centres of the reduced image are a fraction of a
/// pixel off, each in its own direction: on the rendered corridor the vanishing point scattered
/// 0.7 px (x) and 0.9 px (y) per frame around a 0.3 px bias; refitted, 0.23 and 0.41 px around
/// 0.15 px. At stations every 2 px along the segment the grey profile across the line is sampled
/// (bilinear, 1 px steps, +-kSearchPx); the edge is at the largest difference of neighbouring
/// samples with the segment's dominant contrast sign, refined to the centroid of the five
/// differences around it. The line is the contrast-weighted total-least-squares fit to those edge
/// points, refitted once without the points farther than kOutlierPx from the first fit.
/// Returns false (segment unchanged) when fewer than a third of the stations found an edge.
bool refineOnGradient(const cv::Mat& gray, Eigen::Vector2d* p1, Eigen::Vector2d* p2) {
  constexpr double kMinContrast = 4.0;  // grey levels between samples 1 px apart
  constexpr int kSearchPx = 4;
  constexpr double kStationStepPx = 2.0;
  constexpr double kOutlierPx = 0.75;
  const Eigen::Vector2d d = *p2 - *p1;
  const double length = d.norm();
  if (!(length > 4.0 * kStationStepPx)) return false;
  const Eigen::Vector2d t = d / length;
  const Eigen::Vector2d n(-t.y(), t.x());
  const double lo = kSearchPx + 1.0;
  const double hi_x = gray.cols - 2.0 - kSearchPx, hi_y = gray.rows - 2.0 - kSearchPx;

  struct EdgePoint {
    Eigen::Vector2d p;
    double weight;
  };
  std::vector<EdgePoint> points;
  const int stations = static_cast<int>((length - 2.0 * kStationStepPx) / kStationStepPx);
  std::array<double, 2 * kSearchPx + 1> profile{};
  std::array<double, 2 * kSearchPx> diff{};
  double signed_sum = 0.0;
  std::vector<std::array<double, 2 * kSearchPx>> diffs;
  std::vector<Eigen::Vector2d> centres;
  diffs.reserve(static_cast<std::size_t>(stations) + 1);
  centres.reserve(static_cast<std::size_t>(stations) + 1);
  for (int i = 0; i <= stations; ++i) {
    const Eigen::Vector2d c = *p1 + t * (kStationStepPx * (i + 1));
    if (std::min(c.x(), c.y()) < lo || c.x() > hi_x || c.y() > hi_y) continue;
    for (int k = -kSearchPx; k <= kSearchPx; ++k) {
      const Eigen::Vector2d q = c + n * static_cast<double>(k);
      profile[static_cast<std::size_t>(k + kSearchPx)] = bilinear(gray, q.x(), q.y());
    }
    for (std::size_t k = 0; k < diff.size(); ++k) {
      diff[k] = profile[k + 1] - profile[k];
      signed_sum += diff[k];
    }
    diffs.push_back(diff);
    centres.push_back(c);
  }
  if (diffs.empty()) return false;
  const double sign = signed_sum >= 0.0 ? 1.0 : -1.0;
  for (std::size_t s = 0; s < diffs.size(); ++s) {
    const auto& g = diffs[s];
    std::size_t best = 0;
    for (std::size_t k = 1; k < g.size(); ++k) {
      if (sign * g[k] > sign * g[best]) best = k;
    }
    const double peak = sign * g[best];
    if (!(peak >= kMinContrast) || best < 2 || best + 2 >= g.size()) continue;
    // Centroid of the differences around the peak: exact for a step edge blurred by any symmetric
    // kernel (pixel area, optics, motion), where a parabola through the peak locks to pixels.
    double moment = 0.0, mass = 0.0;
    for (std::size_t k = best - 2; k <= best + 2; ++k) {
      const double v = std::max(0.0, sign * g[k]);
      moment += v * static_cast<double>(k);
      mass += v;
    }
    // diff[k] sits between profile samples k and k + 1, i.e. at offset k - kSearchPx + 0.5.
    const double offset = moment / mass - kSearchPx + 0.5;
    points.push_back({centres[s] + n * offset, peak});
  }
  if (3 * static_cast<int>(points.size()) < static_cast<int>(diffs.size()) || points.size() < 4) {
    return false;
  }

  Eigen::Vector2d mean, axis;
  const auto fit = [&]() {
    double weight_sum = 0.0;
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    for (const auto& e : points) {
      sum += e.weight * e.p;
      weight_sum += e.weight;
    }
    mean = sum / weight_sum;
    Eigen::Matrix2d scatter = Eigen::Matrix2d::Zero();
    for (const auto& e : points) scatter += e.weight * (e.p - mean) * (e.p - mean).transpose();
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(scatter);
    axis = eig.eigenvectors().col(1);
    if (axis.dot(t) < 0.0) axis = -axis;
    return axis.dot(t) >= std::cos(2.0 * kDegToRad);  // else the fit left the segment
  };
  if (!fit()) return false;
  // Second pass: only the points near the first fit's line.
  const Eigen::Vector2d first_normal(-axis.y(), axis.x());
  const Eigen::Vector2d first_mean = mean;
  std::vector<EdgePoint> kept;
  kept.reserve(points.size());
  for (const auto& e : points) {
    if (std::abs(first_normal.dot(e.p - first_mean)) <= kOutlierPx) kept.push_back(e);
  }
  if (3 * static_cast<int>(kept.size()) < static_cast<int>(diffs.size()) || kept.size() < 4) {
    return false;
  }
  points.swap(kept);
  if (!fit()) return false;
  *p1 = mean + axis * axis.dot(*p1 - mean);
  *p2 = mean + axis * axis.dot(*p2 - mean);
  return true;
}

/// Ideal (pinhole) pixel of a distorted pixel under the plumb-bob model, by the usual fixed-point
/// iteration on normalised coordinates (converges in a few steps for Kinect-class lenses).
Eigen::Vector2d undistortPixel(const CameraIntrinsics& K, const Eigen::Vector2d& distorted) {
  const double k1 = K.distortion[0], k2 = K.distortion[1], p1 = K.distortion[2],
               p2 = K.distortion[3], k3 = K.distortion[4];
  const double xd = (distorted.x() - K.cx) / K.fx, yd = (distorted.y() - K.cy) / K.fy;
  double x = xd, y = yd;
  for (int i = 0; i < 8; ++i) {
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
    const double dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
    if (!(radial > 0.1)) break;  // far outside the model's valid range: keep the last estimate
    x = (xd - dx) / radial;
    y = (yd - dy) / radial;
  }
  return {K.fx * x + K.cx, K.fy * y + K.cy};
}

}  // namespace

const char* vanishingPointStatusName(VanishingPointStatus status) {
  switch (status) {
    case VanishingPointStatus::kOk:
      return "OK";
    case VanishingPointStatus::kEmptyImage:
      return "EMPTY_IMAGE";
    case VanishingPointStatus::kWrongImageType:
      return "WRONG_IMAGE_TYPE";
    case VanishingPointStatus::kWrongImageSize:
      return "WRONG_IMAGE_SIZE";
    case VanishingPointStatus::kTooFewLines:
      return "TOO_FEW_LINES";
    case VanishingPointStatus::kNoConsensus:
      return "NO_CONSENSUS";
    case VanishingPointStatus::kDegenerate:
      return "DEGENERATE";
    case VanishingPointStatus::kOutsideImage:
      return "OUTSIDE_IMAGE";
  }
  return "UNKNOWN";
}

VanishingPointDetector::VanishingPointDetector(const CameraIntrinsics& intrinsics,
                                               const VanishingPointConfig& config)
    : intrinsics_(intrinsics), config_(config) {
  if (config_.segment_detector == "lsd") {
    lsd_ = cv::createLineSegmentDetector(cv::LSD_REFINE_STD);
  }
}

VanishingPointDetector::VanishingPointDetector(const FilterConfig& config,
                                               const CameraIntrinsics& intrinsics)
    : VanishingPointDetector(intrinsics, config.vp) {}

void VanishingPointDetector::extractSegments(const cv::Mat& gray) {
  const double scale = config_.image_scale;
  const cv::Mat* input = &gray;
  if (scale < 1.0) {
    const cv::Size size(std::max(8, static_cast<int>(std::lround(gray.cols * scale))),
                        std::max(8, static_cast<int>(std::lround(gray.rows * scale))));
    cv::resize(gray, scaled_, size, 0.0, 0.0, cv::INTER_AREA);
    input = &scaled_;
  }
  // Resized pixel centres back to full-resolution pixels (centre of pixel 0 at 0 in both).
  const double sx = static_cast<double>(gray.cols) / input->cols;
  const double sy = static_cast<double>(gray.rows) / input->rows;
  // Lines are straight only in the ideal pinhole image: with a distorted camera (fr1: k1 = 0.26)
  // each segment's end points are undistorted, which makes the chord of a curved image line a
  // piece of the straight one.
  const bool distorted = intrinsics_.distortion_model == DistortionModel::kPlumbBob &&
                         std::any_of(intrinsics_.distortion.begin(), intrinsics_.distortion.end(),
                                     [](double k) { return k != 0.0; });
  // A segment of the resized image to full resolution: end points scaled, optionally refitted to
  // sub-pixel edges of the full-resolution image, then undistorted.
  const auto to_full = [&](const Eigen::Vector2d& q1, const Eigen::Vector2d& q2) {
    LineSegment s{Eigen::Vector2d((q1.x() + 0.5) * sx - 0.5, (q1.y() + 0.5) * sy - 0.5),
                  Eigen::Vector2d((q2.x() + 0.5) * sx - 0.5, (q2.y() + 0.5) * sy - 0.5)};
    if (config_.subpixel_lines) refineOnGradient(gray, &s.p1_px, &s.p2_px);
    if (distorted) {
      s.p1_px = undistortPixel(intrinsics_, s.p1_px);
      s.p2_px = undistortPixel(intrinsics_, s.p2_px);
    }
    return s;
  };
  std::vector<LineSegment> raw;
  if (lsd_) {
    std::vector<cv::Vec4f> lines;
    lsd_->detect(*input, lines);
    raw.reserve(lines.size());
    for (const auto& l : lines) raw.push_back(to_full({l[0], l[1]}, {l[2], l[3]}));
  } else {
    if (config_.blur_kernel_px > 1) {
      const int k = config_.blur_kernel_px | 1;  // odd
      cv::GaussianBlur(*input, blurred_, cv::Size(k, k), 0.0);
      input = &blurred_;
    }
    cv::Canny(*input, edges_, config_.canny_low, config_.canny_high, config_.canny_aperture, true);
    std::vector<cv::Vec4i> lines;
    const double s = std::min(sx, sy);
    cv::HoughLinesP(edges_, lines, config_.hough_rho_px, config_.hough_theta_deg * kDegToRad,
                    std::max(1, static_cast<int>(std::lround(config_.hough_threshold / s))),
                    config_.min_line_length_px / s, config_.max_line_gap_px / s);
    raw.reserve(lines.size());
    for (const auto& l : lines) {
      const Eigen::Vector2d p1(l[0], l[1]), p2(l[2], l[3]);
      Eigen::Vector2d q1 = p1, q2 = p2;
      refineOnEdges(edges_, p1, p2, &q1, &q2);
      raw.push_back(to_full(q1, q2));
    }
  }

  const double axis_sine = std::sin(config_.axis_parallel_angle_deg * kDegToRad);
  segments_.clear();
  for (const auto& s : raw) {
    const Eigen::Vector2d d = s.p2_px - s.p1_px;
    const double length = d.norm();
    if (!(length >= config_.min_line_length_px)) continue;
    if (config_.reject_axis_parallel) {
      // Nearly horizontal: |dy| small; nearly vertical: |dx| small.
      if (std::abs(d.y()) <= axis_sine * length || std::abs(d.x()) <= axis_sine * length) continue;
    }
    segments_.push_back(s);
  }
  if (static_cast<int>(segments_.size()) > config_.max_segments) {
    std::nth_element(
        segments_.begin(), segments_.begin() + config_.max_segments, segments_.end(),
        [](const LineSegment& a, const LineSegment& b) { return a.length_px() > b.length_px(); });
    segments_.resize(static_cast<std::size_t>(config_.max_segments));
  }
}

VanishingPoint VanishingPointDetector::detect(const cv::Mat& gray) {
  ++counters_.images;
  VanishingPoint result;
  segments_.clear();
  inliers_.clear();
  if (gray.empty()) {
    result.status = VanishingPointStatus::kEmptyImage;
  } else if (gray.type() != CV_8UC1) {
    result.status = VanishingPointStatus::kWrongImageType;
  } else if (gray.cols != intrinsics_.width || gray.rows != intrinsics_.height) {
    result.status = VanishingPointStatus::kWrongImageSize;
  } else {
    extractSegments(gray);
    return estimateFromSegments(segments_);  // counts the outcome
  }
  ++counters_.bad_input;
  return result;
}

VanishingPoint VanishingPointDetector::estimateFromSegments(
    const std::vector<LineSegment>& segments) {
  VanishingPoint result;
  if (&segments != &segments_) segments_ = segments;
  inliers_.clear();
  std::vector<LineRow> rows;
  rows.reserve(segments.size());
  for (const auto& s : segments) {
    const double length = s.length_px();
    if (std::isfinite(length) && length > 1e-6 && s.p1_px.allFinite() && s.p2_px.allFinite()) {
      rows.push_back(makeRow(s));
    }
  }
  result.num_segments = static_cast<int>(rows.size());
  const auto fail = [&](VanishingPointStatus status) {
    result.status = status;
    ++counters_.not_detected;
    return result;
  };
  const int n = static_cast<int>(rows.size());
  if (n < std::max(2, config_.min_supporting_lines))
    return fail(VanishingPointStatus::kTooFewLines);

  const double w = intrinsics_.width, h = intrinsics_.height;
  const double margin_x = config_.max_outside_fraction * w;
  const double margin_y = config_.max_outside_fraction * h;
  const auto inside_region = [&](const Eigen::Vector2d& u) {
    return u.x() >= -margin_x && u.x() <= w - 1.0 + margin_x && u.y() >= -margin_y &&
           u.y() <= h - 1.0 + margin_y;
  };
  const double max_sine = std::sin(config_.inlier_angle_deg * kDegToRad);

  // RANSAC over pairs: all of them when there are few, otherwise random ones (seeded per image so
  // a frame always gives the same answer).
  const long long num_pairs = static_cast<long long>(n) * (n - 1) / 2;
  std::mt19937 rng(static_cast<std::mt19937::result_type>(config_.seed));
  std::uniform_int_distribution<int> pick(0, n - 1);
  double best_score = -1.0;
  Eigen::Vector2d best_u = Eigen::Vector2d::Zero();
  bool any_candidate_outside = false;
  const auto try_pair = [&](int i, int j) {
    const LineRow& a = rows[static_cast<std::size_t>(i)];
    const LineRow& b = rows[static_cast<std::size_t>(j)];
    const double det = a.normal.x() * b.normal.y() - a.normal.y() * b.normal.x();
    if (std::abs(det) < kMinIntersectionSine) return;
    const Eigen::Vector2d u((a.c * b.normal.y() - b.c * a.normal.y()) / det,
                            (a.normal.x() * b.c - b.normal.x() * a.c) / det);
    if (!inside_region(u)) {
      any_candidate_outside = true;
      return;
    }
    double score = 0.0;
    for (const auto& r : rows) {
      if (supports(r, u, max_sine)) score += r.length_px;
    }
    if (score > best_score) {
      best_score = score;
      best_u = u;
    }
  };
  if (num_pairs <= config_.ransac_iterations) {
    for (int i = 0; i < n; ++i) {
      for (int j = i + 1; j < n; ++j) try_pair(i, j);
    }
  } else {
    for (int it = 0; it < config_.ransac_iterations; ++it) {
      const int i = pick(rng);
      const int j = pick(rng);
      if (i != j) try_pair(i, j);
    }
  }
  if (best_score < 0.0) {
    return fail(any_candidate_outside ? VanishingPointStatus::kOutsideImage
                                      : VanishingPointStatus::kNoConsensus);
  }

  // Least-squares refinement on the inliers: paper 002's u = (A^T A)^-1 A^T c, unweighted (a
  // length/distance weighting was tried: it favours the short, crowded segments next to the point
  // and was less accurate on the synthetic corridors). Each pass re-chooses the inliers around the
  // current point and accumulates the normal equations and residuals at it.
  std::vector<int> inliers;
  Eigen::Matrix2d AtA;
  Eigen::Vector2d Atc;
  double sum_sq = 0.0;
  const auto accumulate = [&](const Eigen::Vector2d& at) {
    inliers.clear();
    AtA.setZero();
    Atc.setZero();
    sum_sq = 0.0;
    for (int i = 0; i < n; ++i) {
      const LineRow& r = rows[static_cast<std::size_t>(i)];
      if (!supports(r, at, max_sine)) continue;
      inliers.push_back(i);
      AtA += r.normal * r.normal.transpose();
      Atc += r.normal * r.c;
      const double residual = r.normal.dot(at) - r.c;
      sum_sq += residual * residual;
    }
    return static_cast<int>(inliers.size()) >= config_.min_supporting_lines;
  };
  Eigen::Vector2d u = best_u;
  for (int iteration = 0; iteration < config_.refine_iterations; ++iteration) {
    if (!accumulate(u)) return fail(VanishingPointStatus::kNoConsensus);
    // Inliers all (nearly) parallel: the smaller eigenvalue of A^T A relative to the larger is
    // the spread of the normals; below ~1e-6 the point is not determined.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(AtA);
    if (eig.eigenvalues()(0) < 1e-6 * eig.eigenvalues()(1)) {
      return fail(VanishingPointStatus::kDegenerate);
    }
    const Eigen::Vector2d refined = AtA.ldlt().solve(Atc);
    if (!refined.allFinite()) return fail(VanishingPointStatus::kDegenerate);
    const bool converged = (refined - u).norm() < 1e-3;
    u = refined;
    if (converged && iteration > 0) break;
  }
  if (!inside_region(u)) return fail(VanishingPointStatus::kOutsideImage);

  // Final inliers and residual covariance at the refined point.
  if (!accumulate(u)) return fail(VanishingPointStatus::kNoConsensus);
  const int m = static_cast<int>(inliers.size());
  const double sigma_sq = m > 2 ? sum_sq / (m - 2) : 0.0;
  Eigen::Matrix2d covariance = sigma_sq * AtA.inverse();
  covariance +=
      config_.min_pixel_sigma_px * config_.min_pixel_sigma_px * Eigen::Matrix2d::Identity();
  if (!covariance.allFinite()) return fail(VanishingPointStatus::kDegenerate);

  result.status = VanishingPointStatus::kOk;
  result.pixel = u;
  result.pixel_covariance = 0.5 * (covariance + covariance.transpose());
  result.direction_camera = intrinsics_.ray(u.x(), u.y()).normalized();
  result.num_supporting_lines = m;
  result.rms_residual_px = std::sqrt(sum_sq / m);
  inliers_ = inliers;
  ++counters_.detected;
  return result;
}

}  // namespace slamd
