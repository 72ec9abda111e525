#pragma once
// Motion estimation between a reference frame (previous frame or keyframe) and the current frame.
//
// - rigidFit(): closed-form least-squares rigid transform between two 3D point sets (Umeyama /
//   Horn, via SVD of the cross-covariance, no scale).
// - ransacRigid(): RANSAC on 3-point minimal sets, hypotheses scored by reprojection error in the
//   current image.
// - maximumConsistentClique(): FOVIS's inlier detection: matches whose pairwise 3D distances agree
//   in both frames, as a (greedy) maximum clique.
// - refinePose(): robust Gauss-Newton / Levenberg-Marquardt on SE(3) of the reprojection error
//   plus the depth error where the current depth is valid; covariance from the final normal
//   equations scaled by the residual.
//
// The estimated transform is T_ref_curr (maps current-camera points into the reference camera),
// perturbed on the right: T = T_est * exp(xi), xi = [rho; phi] as in common/se3.hpp.

#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/tracking/features.hpp"

namespace slamd {

/// One putative correspondence: a reference 3D point and its observation in the current frame.
struct Correspondence {
  Eigen::Vector3d point_ref;    ///< reference camera frame, metres (always valid)
  Eigen::Vector2d pixel_curr;   ///< undistorted pixel in the current image
  double depth_curr_m = 0.0;    ///< depth at the current keypoint, metres; NaN when unknown
  double pixel_sigma_px = 1.0;  ///< keypoint noise in the current image, pixels
  int ref_index = -1;           ///< feature index in the reference frame
  int curr_index = -1;          ///< feature index in the current frame

  bool hasCurrDepth() const { return depth_curr_m == depth_curr_m; }
  /// Current point in the current camera frame (metres); only meaningful with depth.
  Eigen::Vector3d pointCurr(const CameraIntrinsics& K) const {
    return K.backProject(pixel_curr.x(), pixel_curr.y(), depth_curr_m);
  }
};

/// Closed-form rigid T_a_b minimising sum ||a_i - T_a_b * b_i||^2. Returns false for fewer than
/// 3 points or a degenerate (collinear) configuration.
bool rigidFit(const std::vector<Eigen::Vector3d>& points_a,
              const std::vector<Eigen::Vector3d>& points_b, SE3& T_a_b);

struct RansacResult {
  bool success = false;
  SE3 T_ref_curr = SE3::Identity();
  std::vector<std::uint8_t> inliers;  ///< per correspondence
  int num_inliers = 0;
  int iterations = 0;
};

/// RANSAC over correspondences with current depth. A hypothesis T_ref_curr comes from 3 points;
/// correspondence i is an inlier when the reference point projects into the current image within
/// threshold_px (scaled by its pixel sigma). The best hypothesis is refitted on its inliers.
RansacResult ransacRigid(const std::vector<Correspondence>& matches, const CameraIntrinsics& K,
                         double threshold_px, int max_iterations, std::mt19937& rng);

/// Indices of a large set of matches (with current depth) that are pairwise consistent:
/// | ||P_i - P_j|| - ||Q_i - Q_j|| | < tolerance_m + depth noise of the four points, where P are
/// reference points and Q current points. Greedy maximum clique as in FOVIS.
std::vector<int> maximumConsistentClique(const std::vector<Correspondence>& matches,
                                         const CameraIntrinsics& K, double tolerance_m,
                                         double depth_sigma_coeff);

struct RefinementOptions {
  int max_iterations = 10;
  double huber_k = 1.5;               ///< Huber width, in sigmas
  double depth_sigma_coeff = 0.0015;  ///< sigma_z = coeff * z^2 (1/m); 0 = no depth residual
  /// Estimate the noise of the reprojection and of the depth residuals from the data (robustly,
  /// from the median residual at the initial pose) and whiten each kind by its own scale, so
  /// that the kernel width and the relative weight of pixels and depth follow the actual noise.
  bool estimate_noise_scale = true;
};

struct RefinementResult {
  bool success = false;
  SE3 T_ref_curr = SE3::Identity();
  /// Covariance of xi (T = T_est * exp(xi)), order x y z rx ry rz; metres^2, radians^2.
  Matrix6d covariance = Matrix6d::Identity();
  double rms_reprojection_px = 0.0;  ///< over the correspondences used
  int iterations = 0;
};

/// Per-correspondence whitened residual: 2 reprojection components (pixels / sigma) and, when the
/// current depth is valid and depth_sigma_coeff > 0, one depth component ((z - d) / sigma_z).
/// Returns the number of rows written (2 or 3). The Jacobian is d r / d xi for T = T_ref_curr *
/// exp(xi). Returns 0 when the point is behind the camera.
int refinementResidual(const Correspondence& c, const CameraIntrinsics& K, const SE3& T_ref_curr,
                       double depth_sigma_coeff, Eigen::Vector3d& residual,
                       Eigen::Matrix<double, 3, 6>& jacobian);

/// Robust refinement of T_ref_curr over the correspondences whose `use` flag is set.
RefinementResult refinePose(const std::vector<Correspondence>& matches,
                            const std::vector<std::uint8_t>& use, const CameraIntrinsics& K,
                            const SE3& T_initial, const RefinementOptions& options);

/// Reprojection error (pixels) of correspondence c under T_ref_curr; infinity behind the camera.
double reprojectionErrorPx(const Correspondence& c, const CameraIntrinsics& K,
                           const SE3& T_ref_curr);

/// Inliers whose reference patch was found again in the current image (alignInlierPatches).
struct AlignedInliers {
  std::vector<std::size_t> match_indices;  ///< into the matches
  std::vector<cv::Point2f> pixels_raw;     ///< aligned position in the current image (distorted)
};

/// Aligns each inlier's reference patch in the current image (alignPatch, warped by the homography
/// of the plane the reference depth shows around the point, under T_ref_curr), so that the
/// correspondences become sub-pixel consistent with the reference keypoints rather than two
/// independent detections. Needs both feature sets' align_gray and keypoints; otherwise nothing
/// is aligned.
AlignedInliers alignInlierPatches(const FeatureSet& ref, const FeatureSet& curr,
                                  const CameraIntrinsics& K, const SE3& T_ref_curr,
                                  const std::vector<Correspondence>& matches,
                                  const std::vector<std::uint8_t>& inliers);

}  // namespace slamd
