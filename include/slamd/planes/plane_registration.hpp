#pragma once
// Registration of two RGB-D frames by ICP (issue 23, item 2; founding paper 000):
//  - registerPlanes(): paper 000's plane-based ICP. A fixed number of points is drawn on each
//    plane of the source frame (samplePlanePoints), and each must lie on the target frame's plane
//    that it projects into (point-to-plane against the fitted plane, so depth noise is averaged
//    out by the fit). Matched planes also add plane-to-plane constraints: the two normals agree
//    (2 residuals) and the source plane's centroid lies on the target plane (1 residual).
//  - registerClouds(): the reference, point-to-plane ICP on the whole source cloud (every
//    cloud_stride_px-th pixel with depth) against the target depth image, with normals from each
//    target pixel's neighbours.
// Both associate by projection (a source point moved by the current estimate is looked up at the
// target pixel it projects to), gate associations by distance (shrinking from max_distance_m to
// min_distance_m over the first iterations) and normal angle, weight each residual by the Kinect
// v1 depth noise at its depth (kinectSigmaZ; samples taken as independent), and solve by
// Gauss-Newton.
//
// Degenerate directions: planes alone leave some motions free (along a corridor with walls,
// floor and ceiling only, the translation along it; facing one wall above a floor, the
// translation along both). The information matrix of the estimate is eigen-decomposed with
// rotations scaled by the mean depth of the source points (so a rotation counts as the motion it
// gives a point there). A direction is degenerate when its standard deviation would exceed
// degenerate_sigma_m, or exceed degenerate_ratio times that of the best constrained direction:
// with every sample taken as independent, tens of thousands of points make even the slight
// normal errors of whole-cloud ICP look like information, and the ratio does not depend on that
// overall scale. Gauss-Newton steps do not move the estimate along a degenerate direction (to
// first order: a step's rotation turns it slightly), so it stays at the guess, e.g. the motion
// prior's; it is listed in degenerate_directions, and there is no covariance (nullopt): the
// information matrix, with its null space, is what a filter can fuse. Nothing is filled in for
// what the data do not say.
//
// Convention: T_target_source maps source camera points into the target camera frame (optical
// frames, metres). The information matrix is that of a right perturbation, T_target_source *
// exp(xi), xi = [rho; phi] (common/se3.hpp).
//
// No threads, no state: each call is independent.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/planes/plane_segmenter.hpp"

namespace slamd::planes {

struct IcpParams {
  int max_iterations = 30;  ///< Gauss-Newton iterations at most; >= 1
  /// Association gate on the point-to-plane distance (metres): max_distance_m at the first
  /// iteration, halved at each iteration down to min_distance_m.
  double max_distance_m = 0.10;
  double min_distance_m = 0.02;
  /// Largest angle between a source normal (moved by the estimate) and its target normal.
  double max_normal_angle_deg = 30.0;
  /// Stop when a step moves less than both (metres, radians).
  double converged_translation_m = 1e-5;
  double converged_rotation_rad = 1e-5;
  /// A direction of the estimate whose standard deviation would exceed this (metres; rotations
  /// scaled by the source points' mean depth) is degenerate.
  double degenerate_sigma_m = 0.05;
  /// ... or whose standard deviation exceeds this many times the best constrained direction's.
  double degenerate_ratio = 100.0;
  /// Fewer correspondences than this at the end: the registration fails.
  int min_correspondences = 30;
  // --- registerPlanes ---
  int points_per_plane = 200;  ///< paper 000: a fixed number per plane; >= 1
  bool plane_to_plane = true;  ///< also the plane-to-plane constraints of matched planes
  std::uint64_t seed = 1;      ///< for samplePlanePoints
  // --- registerClouds ---
  int cloud_stride_px = 1;  ///< every n-th source pixel in x and y; 1 = the whole cloud
  double min_depth_m = 0.1;
  double max_depth_m = 4.5;

  /// Empty when valid, otherwise a sentence naming the first bad parameter.
  std::string validationError() const;
};

struct IcpResult {
  bool ok = false;
  std::string error;  ///< a sentence when !ok
  SE3 T_target_source = SE3::Identity();
  /// Of xi in T_target_source * exp(xi), [rho; phi] (1/m^2, 1/(m rad), 1/rad^2).
  Matrix6d information = Matrix6d::Zero();
  /// The inverse of information; nullopt when a direction is degenerate.
  std::optional<Matrix6d> covariance;
  /// Unit twists [rho; phi] (rotation scaled by mean_depth_m) the data leave free.
  std::vector<Vector6d> degenerate_directions;
  int iterations = 0;
  int source_points = 0;    ///< points the source contributed
  int correspondences = 0;  ///< point associations in the last iteration
  int plane_matches = 0;    ///< registerPlanes: matched plane pairs in the last iteration
  double rms_m = 0.0;       ///< RMS point-to-plane distance of the last iteration's associations
  double mean_depth_m = 0.0;
};

/// The projector that removes the components along result.degenerate_directions from a twist
/// (identity when there are none): what of an error or a correction the data speak for.
Matrix6d observableProjector(const IcpResult& result);

/// Paper 000's plane-based ICP: source and target are the segmentations of the two frames
/// (both from frames with `intrinsics`; target.labels is read). T_target_source_guess: the
/// starting estimate (identity for consecutive frames, or a motion prior).
IcpResult registerPlanes(const PlaneSegmentation& source, const PlaneSegmentation& target,
                         const CameraIntrinsics& intrinsics, const SE3& T_target_source_guess,
                         const IcpParams& params = IcpParams());

/// Point-to-plane ICP on the whole source cloud against the target depth image (CV_32FC1
/// metres, NaN or <= 0 = none; both of intrinsics' size).
IcpResult registerClouds(const cv::Mat& source_depth_m, const cv::Mat& target_depth_m,
                         const CameraIntrinsics& intrinsics, const SE3& T_target_source_guess,
                         const IcpParams& params = IcpParams());

}  // namespace slamd::planes
