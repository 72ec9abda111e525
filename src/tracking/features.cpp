#include "slamd/tracking/features.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <Eigen/Core>
#include <opencv2/calib3d.hpp>
#include <opencv2/core/hal/hal.hpp>
#include <opencv2/imgproc.hpp>

namespace slamd {
namespace {

constexpr int kPatchSize = 9;  // FOVIS patch descriptor: 9x9 pixels
constexpr int kPatchHalf = kPatchSize / 2;

/// alignPatch's 9x9 patch, padded with zeros to a whole number of 4- and 8-float SIMD packets.
constexpr int kAlignSide = 9;
constexpr int kPatchPadded = 88;
static_assert(kPatchPadded >= kAlignSide * kAlignSide && kPatchPadded % 8 == 0,
              "the padded patch holds the patch in whole 8-float packets");

/// The kSide x kSide bilinear samples of a CV_8UC1 image around (x, y), row by row: sample
/// (i, j) at (x - kSide / 2 + i, y - kSide / 2 + j), into out[j * kSide + i]. All of them lie at
/// integer offsets from (x, y), so one set of weights serves them all. The caller keeps the
/// samples inside the image.
template <int kSide>
void sampleSquare(const cv::Mat& image, double x, double y, float* out) {
  const double fx = std::floor(x), fy = std::floor(y);
  const float ax = static_cast<float>(x - fx), ay = static_cast<float>(y - fy);
  const int x0 = static_cast<int>(fx) - kSide / 2, y0 = static_cast<int>(fy) - kSide / 2;
  // Rows interpolated vertically, then horizontally (loops over plain float arrays, which the
  // compiler turns into SIMD).
  float upper[kSide + 1], lower[kSide + 1], vertical[kSide + 1];
  const std::uint8_t* r0 = image.ptr<std::uint8_t>(y0) + x0;
  for (int col = 0; col <= kSide; ++col) lower[col] = r0[col];
  for (int row = 0; row < kSide; ++row) {
    const std::uint8_t* r1 = image.ptr<std::uint8_t>(y0 + row + 1) + x0;
    for (int col = 0; col <= kSide; ++col) {
      upper[col] = lower[col];
      lower[col] = r1[col];
    }
    for (int col = 0; col <= kSide; ++col) {
      vertical[col] = upper[col] + ay * (lower[col] - upper[col]);
    }
    float* samples = out + row * kSide;
    for (int col = 0; col < kSide; ++col) {
      samples[col] = vertical[col] + ax * (vertical[col + 1] - vertical[col]);
    }
  }
}

/// Sub-pixel refinement of level-0 corners (others keep their position).
void refineSubpixel(const cv::Mat& gray, std::vector<cv::KeyPoint>& keypoints) {
  for (cv::KeyPoint& kp : keypoints) {
    if (kp.octave != 0) continue;
    cv::Point2f refined;
    // The refinement can wander along edges; keep moves within one pixel.
    if (refineCorner(gray, kp.pt, refined) && std::abs(refined.x - kp.pt.x) < 1.0f &&
        std::abs(refined.y - kp.pt.y) < 1.0f) {
      kp.pt = refined;
    }
  }
}

/// Keeps the selected rows of keypoints/descriptors.
void selectFeatures(const std::vector<cv::KeyPoint>& all, const cv::Mat& all_desc,
                    const std::vector<int>& keep, FeatureSet& out) {
  out.keypoints.clear();
  out.keypoints.reserve(keep.size());
  out.descriptors.create(static_cast<int>(keep.size()), all_desc.cols, all_desc.type());
  for (std::size_t k = 0; k < keep.size(); ++k) {
    out.keypoints.push_back(all[static_cast<std::size_t>(keep[k])]);
    all_desc.row(keep[k]).copyTo(out.descriptors.row(static_cast<int>(k)));
  }
}

std::vector<int> bucketIndices(const std::vector<cv::KeyPoint>& keypoints, cv::Size size, int cols,
                               int rows, int max_total) {
  const int cells = cols * rows;
  std::vector<int> order(keypoints.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return keypoints[static_cast<std::size_t>(a)].response >
           keypoints[static_cast<std::size_t>(b)].response;
  });
  const int quota = std::max(1, max_total / cells);
  std::vector<int> count(static_cast<std::size_t>(cells), 0);
  std::vector<int> keep;
  std::vector<int> spill;
  keep.reserve(static_cast<std::size_t>(max_total));
  for (int i : order) {
    const cv::Point2f& p = keypoints[static_cast<std::size_t>(i)].pt;
    const int cx = std::clamp(
        static_cast<int>(p.x * static_cast<float>(cols) / static_cast<float>(size.width)), 0,
        cols - 1);
    const int cy = std::clamp(
        static_cast<int>(p.y * static_cast<float>(rows) / static_cast<float>(size.height)), 0,
        rows - 1);
    int& n = count[static_cast<std::size_t>(cy * cols + cx)];
    if (n < quota) {
      ++n;
      keep.push_back(i);
    } else {
      spill.push_back(i);
    }
  }
  for (int i : spill) {
    if (static_cast<int>(keep.size()) >= max_total) break;
    keep.push_back(i);
  }
  if (static_cast<int>(keep.size()) > max_total) keep.resize(static_cast<std::size_t>(max_total));
  return keep;
}

/// detectAndCompute, then spatial bucketing of the result.
void detectBucketed(cv::Feature2D& detector, const cv::Mat& gray, const TrackingConfig& config,
                    FeatureSet& features) {
  std::vector<cv::KeyPoint> keypoints;
  cv::Mat descriptors;
  detector.detectAndCompute(gray, cv::noArray(), keypoints, descriptors);
  features = FeatureSet();
  if (keypoints.empty() || descriptors.empty()) return;
  const std::vector<int> keep = bucketIndices(keypoints, gray.size(), config.grid_cols,
                                              config.grid_rows, config.max_features);
  selectFeatures(keypoints, descriptors, keep, features);
}

class OrbExtractor : public FeatureExtractor {
 public:
  explicit OrbExtractor(const TrackingConfig& config) : config_(config) {
    // Detect more than needed; bucketing then spreads the kept ones over the image.
    orb_ = cv::ORB::create(config.max_features * 3 / 2, 1.2f, config.orb_levels, 19, 0, 2,
                           cv::ORB::HARRIS_SCORE, 31, config.orb_fast_threshold);
  }
  void extract(const cv::Mat& gray, FeatureSet& features) override {
    detectBucketed(*orb_, gray, config_, features);
    if (config_.subpixel) refineSubpixel(gray, features.keypoints);
    features.scale.resize(features.keypoints.size());
    for (std::size_t i = 0; i < features.keypoints.size(); ++i) {
      features.scale[i] = std::pow(1.2f, static_cast<float>(features.keypoints[i].octave));
    }
  }
  DescriptorNorm norm() const override { return DescriptorNorm::kHamming; }

 private:
  TrackingConfig config_;
  cv::Ptr<cv::ORB> orb_;
};

class SiftExtractor : public FeatureExtractor {
 public:
  explicit SiftExtractor(const TrackingConfig& config) : config_(config) {
    sift_ = cv::SIFT::create(config.max_features * 3 / 2);
  }
  void extract(const cv::Mat& gray, FeatureSet& features) override {
    detectBucketed(*sift_, gray, config_, features);
    features.scale.resize(features.keypoints.size());
    for (std::size_t i = 0; i < features.keypoints.size(); ++i) {
      // SIFT packs the octave in the low byte (signed; -1 = the upsampled octave). Its keypoints
      // are already sub-pixel.
      int octave = features.keypoints[i].octave & 255;
      if (octave >= 128) octave -= 256;
      features.scale[i] = std::max(1.0f, std::ldexp(1.0f, octave));
    }
  }
  DescriptorNorm norm() const override { return DescriptorNorm::kL2; }

 private:
  TrackingConfig config_;
  cv::Ptr<cv::SIFT> sift_;
};

/// FOVIS-style: FAST on a Gaussian pyramid with a threshold adapted towards the wanted feature
/// count, bucketing, and 9x9 brightness-normalised patch descriptors compared by SAD.
class FovisExtractor : public FeatureExtractor {
 public:
  explicit FovisExtractor(const TrackingConfig& config)
      : config_(config), threshold_(config.fovis_fast_threshold) {}

  void extract(const cv::Mat& gray, FeatureSet& features) override {
    pyramid_.resize(static_cast<std::size_t>(config_.fovis_levels));
    pyramid_[0] = gray;
    for (int l = 1; l < config_.fovis_levels; ++l) {
      cv::pyrDown(pyramid_[static_cast<std::size_t>(l - 1)], pyramid_[static_cast<std::size_t>(l)]);
    }
    std::vector<cv::KeyPoint> all;
    const int margin = kPatchHalf + 2;
    for (int l = 0; l < config_.fovis_levels; ++l) {
      const cv::Mat& img = pyramid_[static_cast<std::size_t>(l)];
      if (img.cols < 2 * margin + 1 || img.rows < 2 * margin + 1) break;
      std::vector<cv::KeyPoint> level_kps;
      cv::FAST(img, level_kps, threshold_, true);
      const float s = static_cast<float>(1 << l);
      for (cv::KeyPoint kp : level_kps) {
        if (kp.pt.x < static_cast<float>(margin) || kp.pt.y < static_cast<float>(margin) ||
            kp.pt.x >= static_cast<float>(img.cols - margin) ||
            kp.pt.y >= static_cast<float>(img.rows - margin)) {
          continue;
        }
        kp.octave = l;
        // Level coordinates map to level 0 so that pixel centres stay aligned.
        kp.pt = cv::Point2f((kp.pt.x + 0.5f) * s - 0.5f, (kp.pt.y + 0.5f) * s - 0.5f);
        kp.size = 7.0f * s;
        all.push_back(kp);
      }
    }
    // Adapt the threshold: aim at 1.5x the kept count before bucketing.
    const int wanted = config_.max_features * 3 / 2;
    const int n = static_cast<int>(all.size());
    if (n > wanted * 13 / 10) {
      threshold_ = std::min(100, threshold_ + std::max(1, threshold_ / 10));
    } else if (n < wanted * 7 / 10) {
      threshold_ = std::max(5, threshold_ - std::max(1, threshold_ / 10));
    }
    features = FeatureSet();
    if (all.empty()) return;
    const std::vector<int> keep =
        bucketIndices(all, gray.size(), config_.grid_cols, config_.grid_rows, config_.max_features);
    features.keypoints.reserve(keep.size());
    for (int i : keep) features.keypoints.push_back(all[static_cast<std::size_t>(i)]);
    // Descriptors at the detection position (before sub-pixel refinement).
    features.descriptors.create(static_cast<int>(keep.size()), kPatchSize * kPatchSize, CV_8U);
    for (std::size_t k = 0; k < features.keypoints.size(); ++k) {
      const cv::KeyPoint& kp = features.keypoints[k];
      const int l = kp.octave;
      const float s = static_cast<float>(1 << l);
      const int u = static_cast<int>(std::lround((kp.pt.x + 0.5f) / s - 0.5f));
      const int v = static_cast<int>(std::lround((kp.pt.y + 0.5f) / s - 0.5f));
      const cv::Mat& img = pyramid_[static_cast<std::size_t>(l)];
      int sum = 0;
      for (int dy = -kPatchHalf; dy <= kPatchHalf; ++dy) {
        const std::uint8_t* row = img.ptr<std::uint8_t>(v + dy);
        for (int dx = -kPatchHalf; dx <= kPatchHalf; ++dx) sum += row[u + dx];
      }
      const int mean = sum / (kPatchSize * kPatchSize);
      std::uint8_t* out = features.descriptors.ptr<std::uint8_t>(static_cast<int>(k));
      int j = 0;
      for (int dy = -kPatchHalf; dy <= kPatchHalf; ++dy) {
        const std::uint8_t* row = img.ptr<std::uint8_t>(v + dy);
        for (int dx = -kPatchHalf; dx <= kPatchHalf; ++dx) {
          out[j++] = cv::saturate_cast<std::uint8_t>(row[u + dx] - mean + 128);
        }
      }
    }
    if (config_.subpixel) refineSubpixel(gray, features.keypoints);
    features.scale.resize(features.keypoints.size());
    for (std::size_t i = 0; i < features.keypoints.size(); ++i) {
      features.scale[i] = static_cast<float>(1 << features.keypoints[i].octave);
    }
  }
  DescriptorNorm norm() const override { return DescriptorNorm::kSad; }

 private:
  TrackingConfig config_;
  int threshold_;
  std::vector<cv::Mat> pyramid_;
};

}  // namespace

bool refineCorner(const cv::Mat& gray, const cv::Point2f& initial, cv::Point2f& refined) {
  constexpr int kHalf = 2;              // 5x5 window of gradients
  constexpr int kSide = 2 * kHalf + 3;  // 7x7 samples: the window and a ring for the gradients
  constexpr double kSigmaPx = kHalf * 0.70710678118654752;  // window / sqrt(2), as cornerSubPix
  constexpr double kMinStepSq = 0.02 * 0.02;
  static const auto weights = [] {
    std::array<double, (2 * kHalf + 1) * (2 * kHalf + 1)> w{};
    for (int dy = -kHalf; dy <= kHalf; ++dy) {
      for (int dx = -kHalf; dx <= kHalf; ++dx) {
        w[static_cast<std::size_t>((dy + kHalf) * (2 * kHalf + 1) + dx + kHalf)] =
            std::exp(-(dx * dx + dy * dy) / (2.0 * kSigmaPx * kSigmaPx));
      }
    }
    return w;
  }();
  if (gray.type() != CV_8UC1) return false;
  double px = initial.x, py = initial.y;
  for (int it = 0; it < 6; ++it) {
    const int x0 = static_cast<int>(std::floor(px)) - kHalf - 1;
    const int y0 = static_cast<int>(std::floor(py)) - kHalf - 1;
    if (x0 < 0 || y0 < 0 || x0 + kSide >= gray.cols || y0 + kSide >= gray.rows) return false;
    float samples[kSide * kSide];
    sampleSquare<kSide>(gray, px, py, samples);
    // Normal equations in the offset d from (px, py): sum w g g^T d = sum w g g^T x.
    double a00 = 0, a01 = 0, a11 = 0, b0 = 0, b1 = 0;
    std::size_t k = 0;
    for (int dy = -kHalf; dy <= kHalf; ++dy) {
      for (int dx = -kHalf; dx <= kHalf; ++dx, ++k) {
        const int sx = dx + kHalf + 1, sy = dy + kHalf + 1;
        const double gx =
            0.5 * static_cast<double>(samples[sy * kSide + sx + 1] - samples[sy * kSide + sx - 1]);
        const double gy = 0.5 * static_cast<double>(samples[(sy + 1) * kSide + sx] -
                                                    samples[(sy - 1) * kSide + sx]);
        const double w = weights[k];
        const double gxx = w * gx * gx, gxy = w * gx * gy, gyy = w * gy * gy;
        a00 += gxx;
        a01 += gxy;
        a11 += gyy;
        b0 += gxx * dx + gxy * dy;
        b1 += gxy * dx + gyy * dy;
      }
    }
    const double det = a00 * a11 - a01 * a01;
    if (!(det > 1e-6 * (a00 + a11) * (a00 + a11)) || a00 + a11 < 1.0) return false;
    const double step_x = (a11 * b0 - a01 * b1) / det;
    const double step_y = (a00 * b1 - a01 * b0) / det;
    px += step_x;
    py += step_y;
    if (step_x * step_x + step_y * step_y < kMinStepSq) break;
  }
  refined = cv::Point2f(static_cast<float>(px), static_cast<float>(py));
  return true;
}

std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const TrackingConfig& config) {
  switch (config.frontend) {
    case FrontEndType::kSift:
      return std::make_unique<SiftExtractor>(config);
    case FrontEndType::kFovis:
      return std::make_unique<FovisExtractor>(config);
    case FrontEndType::kOrb:
      break;
  }
  return std::make_unique<OrbExtractor>(config);
}

std::vector<cv::KeyPoint> bucketKeypoints(const std::vector<cv::KeyPoint>& keypoints,
                                          cv::Size image_size, int cols, int rows, int max_total) {
  std::vector<cv::KeyPoint> out;
  for (int i : bucketIndices(keypoints, image_size, cols, rows, max_total)) {
    out.push_back(keypoints[static_cast<std::size_t>(i)]);
  }
  return out;
}

std::vector<Eigen::Vector2d> undistortPixels(const std::vector<cv::Point2f>& raw,
                                             const CameraIntrinsics& K,
                                             const TrackingConfig& config) {
  std::vector<Eigen::Vector2d> out(raw.size());
  const bool distorted =
      config.undistort && K.distortion_model == DistortionModel::kPlumbBob &&
      std::any_of(K.distortion.begin(), K.distortion.end(), [](double d) { return d != 0.0; });
  if (distorted && !raw.empty()) {
    const cv::Matx33d camera(K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
    const cv::Matx<double, 1, 5> dist(K.distortion[0], K.distortion[1], K.distortion[2],
                                      K.distortion[3], K.distortion[4]);
    std::vector<cv::Point2f> undistorted;
    cv::undistortPoints(raw, undistorted, camera, dist, cv::noArray(), camera);
    for (std::size_t i = 0; i < raw.size(); ++i) {
      out[i] = Eigen::Vector2d(undistorted[i].x, undistorted[i].y);
    }
  } else {
    for (std::size_t i = 0; i < raw.size(); ++i) out[i] = Eigen::Vector2d(raw[i].x, raw[i].y);
  }
  return out;
}

bool alignPatch(const cv::Mat& templ, const cv::Point2f& templ_px, const cv::Mat& image,
                const cv::Point2f& initial_px, double max_shift_px, cv::Point2f& aligned_px,
                const cv::Matx33d& ref_from_curr) {
  constexpr int kHalf = kAlignSide / 2;
  constexpr int kSide = kAlignSide;
  constexpr int kBorder = kHalf + 2;
  constexpr double kMinCorrelation = 0.85;
  auto inside = [](const cv::Mat& img, double x, double y) {
    return x >= kBorder && y >= kBorder && x < img.cols - kBorder - 1 && y < img.rows - kBorder - 1;
  };
  auto sample = [](const cv::Mat& img, double x, double y) {
    const int x0 = static_cast<int>(x);
    const int y0 = static_cast<int>(y);
    const float ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
    const std::uint8_t* r0 = img.ptr<std::uint8_t>(y0) + x0;
    const std::uint8_t* r1 = img.ptr<std::uint8_t>(y0 + 1) + x0;
    return (1 - ay) * ((1 - ax) * r0[0] + ax * r0[1]) + ay * ((1 - ax) * r1[0] + ax * r1[1]);
  };
  // Offset in templ of the pixel offset (dx, dy) in image; w is the homogeneous scale.
  auto warp = [&ref_from_curr](double dx, double dy, double& rx, double& ry) {
    const double w = ref_from_curr(2, 0) * dx + ref_from_curr(2, 1) * dy + ref_from_curr(2, 2);
    if (!(w > 0.0)) return false;
    const double inverse_w = 1.0 / w;
    rx = (ref_from_curr(0, 0) * dx + ref_from_curr(0, 1) * dy + ref_from_curr(0, 2)) * inverse_w;
    ry = (ref_from_curr(1, 0) * dx + ref_from_curr(1, 1) * dy + ref_from_curr(1, 2)) * inverse_w;
    return true;
  };
  // The warped template reaches further than kHalf + 1 when ref_from_curr magnifies; the image of
  // the square is a convex quadrilateral (w > 0 at its corners), so its corners bound it.
  double reach = 0.0;
  for (const double cy : {-1.0, 1.0}) {
    for (const double cx : {-1.0, 1.0}) {
      double rx = 0.0, ry = 0.0;
      if (!warp(cx * (kHalf + 1), cy * (kHalf + 1), rx, ry)) return false;
      reach = std::max(reach, std::max(std::abs(rx), std::abs(ry)));
    }
  }
  if (templ.empty() || image.empty() || !(reach < 3 * kHalf) ||
      !inside(image, initial_px.x, initial_px.y)) {
    return false;
  }
  const double tx0 = static_cast<double>(templ_px.x), ty0 = static_cast<double>(templ_px.y);
  if (tx0 - reach < 0 || ty0 - reach < 0 || tx0 + reach > templ.cols - 2 ||
      ty0 + reach > templ.rows - 2) {
    return false;
  }
  // Template with a one-pixel ring for central-difference gradients. The homography's
  // numerators and scale are affine in the column offset, so each row starts from its constant.
  // (w > 0 everywhere inside the convex quadrilateral checked above.)
  const cv::Matx33d& H = ref_from_curr;
  constexpr int kRing = kSide + 2;
  float t[kRing][kRing];
  for (int row = 0; row < kRing; ++row) {
    const double dy = row - kHalf - 1;
    const double x_row = H(0, 1) * dy + H(0, 2), y_row = H(1, 1) * dy + H(1, 2);
    const double w_row = H(2, 1) * dy + H(2, 2);
    double xs[kRing], ys[kRing];
    for (int col = 0; col < kRing; ++col) {
      const double dx = col - kHalf - 1;
      const double inverse_w = 1.0 / (H(2, 0) * dx + w_row);
      xs[col] = tx0 + (H(0, 0) * dx + x_row) * inverse_w;
      ys[col] = ty0 + (H(1, 0) * dx + y_row) * inverse_w;
    }
    for (int col = 0; col < kRing; ++col) t[row][col] = sample(templ, xs[col], ys[col]);
  }
  // Zero-mean template and zero-mean gradients (a brightness offset is eliminated by mean
  // subtraction, so the gradients are centred too). The per-iteration sums below run over these
  // as single-precision vectors (grey levels and their differences need no more), padded with
  // zeros to whole SIMD packets.
  using PatchVector = Eigen::Matrix<float, kPatchPadded, 1>;
  PatchVector gx = PatchVector::Zero(), gy = PatchVector::Zero(), tc = PatchVector::Zero();
  for (int y = 0; y < kSide; ++y) {
    for (int x = 0; x < kSide; ++x) {
      const int k = y * kSide + x;
      gx[k] = 0.5f * (t[y + 1][x + 2] - t[y + 1][x]);
      gy[k] = 0.5f * (t[y + 2][x + 1] - t[y][x + 1]);
      tc[k] = t[y + 1][x + 1];
    }
  }
  constexpr int kCount = kSide * kSide;
  gx.head<kCount>().array() -= gx.sum() / kCount;
  gy.head<kCount>().array() -= gy.sum() / kCount;
  tc.head<kCount>().array() -= tc.sum() / kCount;
  const double h00 = gx.squaredNorm(), h01 = gx.dot(gy), h11 = gy.squaredNorm();
  const double det = h00 * h11 - h01 * h01;
  if (det < 1e-6 * (h00 + h11) * (h00 + h11) || h00 + h11 < 1.0) return false;
  // Gauss-Newton on the patch position. The gradients sum to zero, so the image's mean drops out of
  // the gradient products.
  double px = initial_px.x, py = initial_px.y;
  bool converged = false;
  PatchVector iv = PatchVector::Zero();
  for (int it = 0; it < 10; ++it) {
    if (!inside(image, px, py)) return false;
    sampleSquare<kAlignSide>(image, px, py, iv.data());
    const PatchVector difference = iv - tc;
    const double b0 = gx.dot(difference), b1 = gy.dot(difference);
    const double dx = (h11 * b0 - h01 * b1) / det;
    const double dy = (h00 * b1 - h01 * b0) / det;
    px -= dx;
    py -= dy;
    if (dx * dx + dy * dy < 1e-3) {
      converged = true;
      break;
    }
  }
  if (!converged || !inside(image, px, py)) return false;
  // Accept only a patch that really looks like the template (zero-mean normalised correlation,
  // on the last iteration's samples, a hundredth of a pixel away).
  const float i_mean = iv.sum() / kCount;
  iv.head<kCount>().array() -= i_mean;
  const double sit = iv.dot(tc), sii = iv.squaredNorm(), stt = tc.squaredNorm();
  if (sii <= 0.0 || stt <= 0.0 || sit / std::sqrt(sii * stt) < kMinCorrelation) return false;
  if (std::hypot(px - static_cast<double>(initial_px.x), py - static_cast<double>(initial_px.y)) >
      max_shift_px) {
    return false;
  }
  aligned_px = cv::Point2f(static_cast<float>(px), static_cast<float>(py));
  return true;
}

void attachGeometry(const cv::Mat& depth_m, const CameraIntrinsics& K, const TrackingConfig& config,
                    FeatureSet& features) {
  const std::size_t n = features.keypoints.size();
  features.pixels.resize(n);
  features.points.resize(n);
  features.num_with_depth = 0;
  if (n == 0) return;
  std::vector<cv::Point2f> raw(n);
  for (std::size_t i = 0; i < n; ++i) raw[i] = features.keypoints[i].pt;
  features.pixels = undistortPixels(raw, K, config);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const bool have_depth = !depth_m.empty() && depth_m.type() == CV_32FC1;
  features.inverse_depth_gradient.assign(n, Eigen::Vector2d::Zero());
  for (std::size_t i = 0; i < n; ++i) {
    features.points[i] = Eigen::Vector3d(nan, nan, nan);
    if (!have_depth) continue;
    const double x = static_cast<double>(features.keypoints[i].pt.x);
    const double y = static_cast<double>(features.keypoints[i].pt.y);
    const double z = depthAtPixel(depth_m, x, y, config);
    if (std::isnan(z)) continue;
    features.points[i] = K.backProject(features.pixels[i].x(), features.pixels[i].y(), z);
    ++features.num_with_depth;
    features.inverse_depth_gradient[i] = inverseDepthGradient(depth_m, x, y, z);
  }
}

void moveDepthsToColourTime(const SE3& T_colour_depth, FeatureSet& features) {
  // The depth image measured the surface under the colour pixel's ray from where the camera
  // was then. Moving that point into the colour camera's frame gives the surface's depth at
  // the colour image's time; sideways motion hardly changes the depth of a surface facing the
  // camera, so the point is scaled along the colour pixel's ray rather than moved off it.
  for (std::size_t i = 0; i < features.points.size(); ++i) {
    Eigen::Vector3d& point = features.points[i];
    if (!features.hasDepth(i)) continue;
    const double depth_then_m = point.z();
    const double depth_now_m = (T_colour_depth * point).z();
    if (depth_then_m > 0.0 && depth_now_m > 0.0) point *= depth_now_m / depth_then_m;
  }
}

Eigen::Vector2d inverseDepthGradient(const cv::Mat& depth_m, double x, double y, double z_m) {
  // Central differences over +-kStep pixels; both sides must lie on the same surface (within
  // 15% of the centre's depth), otherwise the slope is unknown (zero).
  constexpr int kStep = 2;
  const int u = static_cast<int>(std::lround(x));
  const int v = static_cast<int>(std::lround(y));
  if (depth_m.empty() || depth_m.type() != CV_32FC1 || u < kStep || v < kStep ||
      u + kStep >= depth_m.cols || v + kStep >= depth_m.rows || !(z_m > 0.0)) {
    return Eigen::Vector2d::Zero();
  }
  auto inverse_at = [&](int uu, int vv) {
    const double zn = depth_m.at<float>(vv, uu);
    return (std::isfinite(zn) && std::abs(zn - z_m) <= 0.15 * z_m) ? 1.0 / zn : -1.0;
  };
  const double left = inverse_at(u - kStep, v), right = inverse_at(u + kStep, v);
  const double up = inverse_at(u, v - kStep), down = inverse_at(u, v + kStep);
  if (left < 0.0 || right < 0.0 || up < 0.0 || down < 0.0) return Eigen::Vector2d::Zero();
  return Eigen::Vector2d((right - left) / (2 * kStep), (down - up) / (2 * kStep));
}

double depthAtPixel(const cv::Mat& depth_m, double x, double y, const TrackingConfig& config) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const int u = static_cast<int>(std::lround(x));
  const int v = static_cast<int>(std::lround(y));
  if (u < 1 || v < 1 || u >= depth_m.cols - 1 || v >= depth_m.rows - 1) return nan;
  double z = depth_m.at<float>(v, u);
  if (!(z >= config.min_depth_m && z <= config.max_depth_m)) return nan;
  // Reject corners on depth discontinuities: the 3x3 neighbourhood must agree with the centre.
  const double tolerance = 0.03 * z + 0.01;
  for (int dy = -1; dy <= 1; ++dy) {
    const float* row = depth_m.ptr<float>(v + dy);
    for (int dx = -1; dx <= 1; ++dx) {
      const double zn = row[u + dx];
      if (std::isfinite(zn) && std::abs(zn - z) > tolerance) return nan;
    }
  }
  // Sub-pixel position: when the four neighbours are valid (they agree with the centre, checked
  // above), interpolate the inverse depth bilinearly. On a plane the inverse depth is affine in the
  // pixel coordinates, so this is exact there; interpolating the depth itself overestimates it on
  // slanted surfaces (1/z is convex in the pixel coordinates).
  const int x0 = static_cast<int>(std::floor(x));
  const int y0 = static_cast<int>(std::floor(y));
  if (x0 >= 0 && y0 >= 0 && x0 + 1 < depth_m.cols && y0 + 1 < depth_m.rows) {
    const double z00 = depth_m.at<float>(y0, x0), z01 = depth_m.at<float>(y0, x0 + 1);
    const double z10 = depth_m.at<float>(y0 + 1, x0), z11 = depth_m.at<float>(y0 + 1, x0 + 1);
    if (z00 > 0.0 && z01 > 0.0 && z10 > 0.0 && z11 > 0.0 && std::isfinite(z00) &&
        std::isfinite(z01) && std::isfinite(z10) && std::isfinite(z11)) {
      const double ax = x - x0, ay = y - y0;
      const double inverse_depth =
          (1 - ay) * ((1 - ax) / z00 + ax / z01) + ay * ((1 - ax) / z10 + ax / z11);
      z = 1.0 / inverse_depth;
    }
  }
  return z;
}

int descriptorDistance(const cv::Mat& a, int i, const cv::Mat& b, int j, DescriptorNorm norm) {
  switch (norm) {
    case DescriptorNorm::kHamming:
      return cv::hal::normHamming(a.ptr<std::uint8_t>(i), b.ptr<std::uint8_t>(j), a.cols);
    case DescriptorNorm::kL2:
      return static_cast<int>(
          std::sqrt(cv::hal::normL2Sqr_(a.ptr<float>(i), b.ptr<float>(j), a.cols)));
    case DescriptorNorm::kSad: {
      const std::uint8_t* pa = a.ptr<std::uint8_t>(i);
      const std::uint8_t* pb = b.ptr<std::uint8_t>(j);
      int sum = 0;
      for (int k = 0; k < a.cols; ++k) sum += std::abs(int{pa[k]} - int{pb[k]});
      return sum;
    }
  }
  return std::numeric_limits<int>::max();
}

}  // namespace slamd
