#pragma once
// Dense RGB-D alignment: the motion between two frames from every pixel, where features are too
// few (a plain wall at arm's length, a turn in front of it). DVO-style photometric residuals on
// pixels with a gradient plus point-to-plane residuals on every pixel with depth, coarse to fine
// over an image pyramid, regularised by a motion prior.
//
// Usage (no threads inside, no state between calls):
//   const DenseFrame ref = makeDenseFrame(gray_prev, depth_prev_m, K, options);
//   const DenseFrame curr = makeDenseFrame(gray_curr, depth_curr_m, K, options);
//   DenseAlignmentResult r = alignDense(ref, curr, T_ref_curr_prior, prior_covariance, options);
//   if (r.success) use(r.T_ref_curr, r.covariance);
//
// Residuals, for each reference pixel x with depth (3D point X_ref), warped into the current
// frame by X_curr = T_ref_curr^-1 X_ref:
//   photometric  I_curr(pi(X_curr)) - I_ref(x), where |grad I_ref(x)| >= min_gradient;
//   geometric    n_curr . (X_curr - P_curr), P_curr and n_curr the current frame's point and
//                normal at the pixel X_curr projects to (projective association).
// When the photometric pixels' gradients all but share one orientation (min_gradient_share, off by
// default), the photometric Jacobians keep only their component along it: what edge ends and
// specks seem to measure across it is not counted as information.
// Coarse to fine; a coarse level whose gradients all but share one orientation aligns the depth
// alone (min_coarse_gradient_share).
// Each is weighted by its noise (photometric: a robust scale estimated per iteration; geometric:
// the depth noise model sigma_z = depth_sigma_coeff z^2) and a Huber kernel. The prior adds
// (xi - xi_prior)' prior_covariance^-1 (xi - xi_prior), so a direction the scene leaves free (the
// translation along a plain corridor) keeps the prior's value and, in the covariance, the prior's
// uncertainty: never a made-up precision. `degenerate_directions` counts those directions.
//
// Images are used as given: lens distortion is not modelled (the pinhole K only).
// Frames: camera optical (x right, y down, z forward). T_ref_curr maps current-frame points into
// the reference frame. Covariances are 6x6, order x y z rx ry rz, for T = T_est * exp(xi).

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"

namespace slamd {

struct DenseAlignmentOptions {
  int levels = 4;             ///< pyramid levels; level k has 1/2^k the resolution
  int finest_level = 1;       ///< the finest level aligned (1 = half resolution)
  int max_iterations = 12;    ///< Gauss-Newton iterations per level
  double min_gradient = 4.0;  ///< grey levels per pixel: photometric residuals above it
  double min_depth_m = 0.3;   ///< depths outside [min, max] are ignored
  double max_depth_m = 5.0;
  double depth_sigma_coeff = 0.0015;   ///< sigma_z = coeff * z^2, metres
  double min_depth_sigma_m = 0.002;    ///< floor on sigma_z (quantisation, calibration)
  double min_photometric_sigma = 1.0;  ///< floor on the photometric scale, grey levels
  double huber_k = 1.345;              ///< Huber threshold in sigmas
  double max_point_to_plane_m = 0.08;  ///< association gate (at the finest level; x2 per level)
  int max_pixels_per_level = 20000;    ///< reference pixels sampled evenly beyond this
  int min_residuals = 300;             ///< fewer at the finest level: failure
  /// Fewer directions where the data outweigh the prior: failure (a blank image without depth
  /// constrains none; a plain wall with depth three).
  int min_constrained_directions = 3;
  /// A direction takes less than this share of the surface normals' scatter: the point-to-plane
  /// residuals measure nothing along it (depth noise alone tilts normals by 2-5 degrees, a share
  /// of 0.1-0.8%).
  double min_normal_share = 0.01;
  /// The weaker axis of the photometric pixels' gradient scatter (their structure tensor) holds
  /// less than this share: the image motion along it is not measured, as the gradients of one
  /// straight edge cannot measure motion along the edge (the aperture problem). An edge's ends and
  /// a few specks stay under it (one edge down a wall with four specks: 3%); texture with two
  /// orientations is far above it (9 specks: 17%, a 12 x 12 grid of them: over 30%). 0 = off.
  double min_gradient_share = 0.0;
  /// A level coarser than the finest aligns its grey image only when the weaker axis of its
  /// photometric pixels' gradient scatter holds at least this share (the gradients span two
  /// orientations); below, depth alone aligns it. Downsampled, the sparse texture of a plain wall
  /// (one edge, a few specks) blurs into a cost that is flat along the edge with minima
  /// centimetres from the truth, which the finest level cannot leave; depth, smooth, brings the
  /// estimate into the finest level's reach without that, and what depth leaves free stays at the
  /// motion prior until the finest level measures it. Such walls hold 0.6-8% at the coarse levels,
  /// textured scenes 30-50%. 0 = the grey image at every level.
  double min_coarse_gradient_share = 0.1;
  /// The residuals of neighbouring pixels are not independent (blur, pyramid smoothing, depth
  /// noise correlated in patches): the data information is divided by this.
  double information_divisor = 16.0;
};

/// One frame's pyramid: grey (float), its gradients, depth (NaN = none) and normals per level.
/// Levels finer than DenseAlignmentOptions::finest_level are never aligned: they hold no gradients
/// or normals, and full resolution (level 0) may hold only its K.
struct DenseFrame {
  struct Level {
    CameraIntrinsics K;
    cv::Mat gray;    ///< CV_32F, grey levels 0-255
    cv::Mat grad_x;  ///< CV_32F, grey levels per pixel
    cv::Mat grad_y;
    cv::Mat depth_m;  ///< CV_32F, NaN where unknown
    cv::Mat normals;  ///< CV_32FC3, unit, facing the camera; NaN where unknown
  };
  std::vector<Level> levels;
  bool empty() const { return levels.empty(); }
};

/// Builds the pyramid of a frame: gray CV_8UC1, depth_m CV_32FC1 (metres, NaN or 0 = none), both
/// of K's size. Returns an empty DenseFrame when the inputs do not fit.
DenseFrame makeDenseFrame(const cv::Mat& gray, const cv::Mat& depth_m, const CameraIntrinsics& K,
                          const DenseAlignmentOptions& options);

struct DenseAlignmentResult {
  bool success = false;
  std::string failure;  ///< why not, when !success
  SE3 T_ref_curr = SE3::Identity();
  Matrix6d covariance = Matrix6d::Identity();  ///< posterior: data and prior together
  /// Directions where the data carry less information than the prior (generalised eigenvalue of
  /// the data information against the prior information below 1): the scene leaves them free.
  int degenerate_directions = 0;
  int photometric_residuals = 0;  ///< used at the finest level
  int geometric_residuals = 0;
  double photometric_rms = 0.0;  ///< grey levels, inliers at the finest level
  double geometric_rms_m = 0.0;
  int iterations = 0;  ///< over all levels
  double time_ms = 0.0;
};

/// Bilinear sample of a CV_32F image; (u, v) must satisfy 0 <= u < cols - 1, 0 <= v < rows - 1.
inline double sampleBilinear(const cv::Mat& img, double u, double v) {
  const int x = static_cast<int>(u);
  const int y = static_cast<int>(v);
  const double ax = u - x;
  const double ay = v - y;
  const float* r0 = img.ptr<float>(y);
  const float* r1 = img.ptr<float>(y + 1);
  const double a00 = r0[x], a01 = r0[x + 1], a10 = r1[x], a11 = r1[x + 1];
  return (1 - ay) * ((1 - ax) * a00 + ax * a01) + ay * ((1 - ax) * a10 + ax * a11);
}

/// Aligns curr to ref starting from T_ref_curr_prior, the motion prior with its covariance
/// (must be positive definite). Never throws on bad data: reports failure instead.
DenseAlignmentResult alignDense(const DenseFrame& ref, const DenseFrame& curr,
                                const SE3& T_ref_curr_prior, const Matrix6d& prior_covariance,
                                const DenseAlignmentOptions& options);

}  // namespace slamd
