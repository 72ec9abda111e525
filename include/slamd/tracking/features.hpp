#pragma once
// Feature extraction for visual odometry: ORB, SIFT and the FOVIS-style FAST + patch front end.
//
// A FeatureSet holds, per feature, the keypoint as detected (raw, distorted image pixels), the
// undistorted pixel (ideal pinhole with the frame's K), the depth read at the raw pixel and the
// 3D point in the camera optical frame (x right, y down, z forward; metres; NaN without depth).
// Extractors are plain objects without threads, owned by VisualOdometry.

#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/features2d.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace slamd {

struct FeatureSet {
  std::vector<cv::KeyPoint> keypoints;  ///< raw image pixels, as detected
  cv::Mat descriptors;                  ///< one row per keypoint (CV_8U or CV_32F)
  std::vector<Eigen::Vector2d> pixels;  ///< undistorted pixels (ideal pinhole), pixels
  std::vector<Eigen::Vector3d> points;  ///< camera optical frame, metres; NaN without depth
  std::vector<float> scale;             ///< keypoint scale relative to level 0 (>= 1)
  /// d(1/z)/du and d(1/z)/dv at each raw keypoint (1/m per pixel): the slope of the surface
  /// around the feature; zero where the depth around it is missing or broken. May be empty.
  std::vector<Eigen::Vector2d> inverse_depth_gradient;
  cv::Mat gray;  ///< the image the features come from (CV_8UC1, shared)
  /// gray smoothed for patch alignment (tracking.align_blur_sigma_px; gray itself when 0)
  cv::Mat align_gray;
  int num_with_depth = 0;

  std::size_t size() const { return keypoints.size(); }
  bool hasDepth(std::size_t i) const { return !std::isnan(points[i].z()); }
};

/// Descriptor distance conventions of a front end.
enum class DescriptorNorm { kHamming, kL2, kSad };

class FeatureExtractor {
 public:
  virtual ~FeatureExtractor() = default;
  /// Detects features in gray (CV_8UC1) and fills keypoints, descriptors and scale. Never throws
  /// for image content; an empty result means no features.
  virtual void extract(const cv::Mat& gray, FeatureSet& features) = 0;
  virtual DescriptorNorm norm() const = 0;
};

std::unique_ptr<FeatureExtractor> makeFeatureExtractor(const TrackingConfig& config);

/// Undistorts keypoints (when configured and the intrinsics have plumb-bob coefficients), reads
/// depth at each raw keypoint (CV_32F metres, NaN = none; depthAtPixel) and back-projects the
/// points, and records the surface slope around each (inverseDepthGradient).
void attachGeometry(const cv::Mat& depth_m, const CameraIntrinsics& intrinsics,
                    const TrackingConfig& config, FeatureSet& features);

/// Moves each feature's point along its pixel's ray to the depth its depth-image point has in
/// the colour camera's frame: for a depth image taken at another time than the colour image
/// (T_colour_depth = the depth camera's pose in the colour camera's frame, the motion between
/// the two times). The pixel stays the colour image's; a point that would land behind the
/// camera is left as it was. Exact for a surface facing the camera, first order otherwise.
void moveDepthsToColourTime(const SE3& T_colour_depth, FeatureSet& features);

/// Depth (metres) at raw pixel (x, y) of depth_m (CV_32F, NaN = none): NaN outside
/// [min_depth_m, max_depth_m], near the border or on a depth discontinuity (the 3x3 neighbourhood
/// of the nearest pixel disagrees with it); otherwise interpolated bilinearly (pixel centres at
/// integer coordinates).
double depthAtPixel(const cv::Mat& depth_m, double x, double y, const TrackingConfig& config);

/// Slope of the inverse depth (1/m per pixel) around raw pixel (x, y) whose depth is z_m, by
/// central differences over +-2 pixels: on a plane 1/z is affine in the pixel coordinates, so this
/// gives the local plane. Zero when a neighbour is missing or on another surface.
Eigen::Vector2d inverseDepthGradient(const cv::Mat& depth_m, double x, double y, double z_m);

/// Undistorted (ideal pinhole) pixels of raw image pixels, when configured and the intrinsics
/// carry plumb-bob coefficients; otherwise the raw pixels.
std::vector<Eigen::Vector2d> undistortPixels(const std::vector<cv::Point2f>& raw,
                                             const CameraIntrinsics& intrinsics,
                                             const TrackingConfig& config);

/// The corner position near `initial` in a CV_8UC1 image (Foerstner): the point that every
/// gradient in a 5x5 window points at or away from, minimising the Gaussian-weighted sum of
/// (g . (x - p))^2 over the window's pixels x with gradients g. The window follows the estimate
/// (at most 6 times, until it moves less than 0.02 px). Returns false when the window leaves the
/// image or the gradients do not fix a point (an edge or a flat patch).
bool refineCorner(const cv::Mat& gray, const cv::Point2f& initial, cv::Point2f& refined);

/// Sub-pixel alignment of a square patch (translation plus brightness offset, inverse
/// compositional Lucas-Kanade): the position in `image` (raw pixels) of the patch of `templ`
/// centred at templ_px, starting from initial_px. Returns false when it does not converge or
/// leaves the image or moves more than max_shift_px from initial_px. ref_from_curr (3x3
/// homography, (2, 2) = 1) maps a pixel offset (dx, dy, 1) in `image` to the homogeneous offset in
/// `templ` (the motion between the views around the point: identity when they differ by a
/// translation, affine for a rotated or scaled view, projective for a slanted surface), so that
/// such views align.
bool alignPatch(const cv::Mat& templ, const cv::Point2f& templ_px, const cv::Mat& image,
                const cv::Point2f& initial_px, double max_shift_px, cv::Point2f& aligned_px,
                const cv::Matx33d& ref_from_curr = cv::Matx33d::eye());

/// Keeps at most max_total features, at most max_total / (cols * rows) per grid cell (strongest
/// response first); cells left under quota give their share to the strongest remaining ones.
std::vector<cv::KeyPoint> bucketKeypoints(const std::vector<cv::KeyPoint>& keypoints,
                                          cv::Size image_size, int cols, int rows, int max_total);

/// Distance between descriptor rows a.row(i) and b.row(j) in the given norm.
int descriptorDistance(const cv::Mat& a, int i, const cv::Mat& b, int j, DescriptorNorm norm);

}  // namespace slamd
