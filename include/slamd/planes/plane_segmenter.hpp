#pragma once
// PlaneSegmenter: planar regions of one RGB-D frame, by colour region growing, per-segment plane
// fits and merging of neighbouring coplanar segments (issue 23, founding paper 000).
//
// Usage:
//   planes::PlaneSegmenterParams params;           // defaults: the fast variant (4 px grid)
//   planes::PlaneSegmenter segmenter(params);      // throws std::invalid_argument on bad params
//   const planes::PlaneSegmentation& result = segmenter.segment(color_bgr, depth_m, intrinsics);
//   for (const planes::Plane& plane : result.planes) use(plane.normal_camera, plane.offset_m);
//   // result.labels(v, u) = index into result.planes, -1 = no plane
//   std::vector<Eigen::Vector3d> points_camera =
//       planes::samplePlanePoints(result.planes[0], 200, intrinsics, /*seed=*/42);
//
// Method (paper 000, with the choices it leaves open made here):
//  1. Over-segmentation: a stack-based flood fill over a grid of samples (every step_px-th pixel;
//     step_px = 1 is the paper's full-resolution variant). A 4-neighbour joins the segment when
//     the Euclidean distance in CIE Lab (true units: L 0..100, a and b about -128..127) between
//     its colour and the segment's running mean colour is below lab_threshold. Samples without a
//     valid depth (NaN, <= min_depth_m, > max_depth_m) join no segment. With step_px > 1 a
//     sample's colour is the mean of its step_px x step_px block (cv::INTER_AREA), its depth that
//     of the block's centre pixel.
//     GrowCriterion::kColorAndDepth (the default, this implementation's own variant) also needs
//     the neighbour to continue the segment's surface: before the segment has a plane, its depth
//     may differ from the current sample's by at most depth_jump_ratio * z * step_px + 3 sigma_z;
//     once it has one (fitted from the segment's moments when its size reaches 16, 32, 64, ...
//     samples), the neighbour must lie within grow_plane_distance_m + 3 sigma_z(z) of that plane.
//     This keeps equally coloured walls meeting at a corner apart, which colour alone cannot.
//  2. Fit: weighted least squares per segment (smallest eigenvector of the weighted scatter).
//     Depth noise model, Kinect v1 (Nguyen, Izadi & Lovell 2012): sigma_z(z) = 0.0012 +
//     0.0019 (z - 0.4)^2 metres. A point p = z r (r the pixel's ray with r.z = 1) has residual
//     n.p + d with variance sigma_z^2 (n.r)^2 = sigma_z^2 d^2 / z^2 on the plane, so each sample
//     is weighted by z^2 / sigma_z(z)^2 (the common 1/d^2 does not move the fit). Samples
//     farther than 3 sigma_z + outlier_margin_m from the fit are dropped and the plane refitted
//     once. Fits of nearly collinear or tiny point sets are rejected.
//  3. Merge: neighbouring segments (4-adjacent samples) whose normals agree (n_a.n_b >=
//     merge_normal_dot) are merged, best agreement first, when the plane fitted to their union
//     (from summed moments) fits nearly as well as the two parts' own planes (merge_rms_ratio,
//     merge_rms_tolerance_m) and passes the fit test (max_rms_m, max_noise_ratio).
//  4. Final planes: samples next to another plane move to it when nearer to it, and unlabelled
//     samples with depth next to a plane join it when within its outlier distance, for up to
//     32 / step_px + 1 passes (this repairs the folds where two planes meet, and lets planes
//     cover the small segments colour growing left). Each plane is then refitted twice,
//     dropping samples beyond 3 robust standard deviations (median-based, never more than
//     3 sigma_z + outlier_margin_m), so that items a few millimetres off a wall do not tilt it
//     in precise data. Planes smaller than min_plane_px pixels are dropped, and so are planes
//     seen edge-on (within about 3 degrees of the ray to their centroid: a strip a column or two
//     wide lies in the plane through its rays and the optical centre, whatever its depths).
//
// Output frame: the camera optical frame (x right, y down, z forward), metres. Each plane is
// n.p + d = 0 with |n| = 1 and n pointing towards the camera (d > 0 for planes not through the
// optical centre).
//
// Ownership: one thread owns a PlaneSegmenter (it keeps per-frame buffers to avoid reallocating);
// segment() returns a reference to its own result, valid until the next call. No threads inside.

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/rgbd_frame.hpp"

namespace slamd::planes {

/// How a neighbouring sample is accepted during region growing.
enum class GrowCriterion {
  kColor,          ///< paper 000: Lab distance to the segment's mean colour only
  kColorAndDepth,  ///< colour, plus continuity with the segment's depth or plane (see above)
};

struct PlaneSegmenterParams {
  /// Lab distance (true CIE Lab units) from the segment's mean colour below which a neighbour
  /// joins; the paper compared 15, 20 and 25 and found 15 the most accurate. Range (0, 200].
  double lab_threshold = 15.0;
  /// Grid step in pixels: every step_px-th pixel along rows and columns is processed; 1 = the
  /// paper's full resolution. Range 1..16.
  int step_px = 4;
  GrowCriterion criterion = GrowCriterion::kColorAndDepth;
  /// Samples with depth outside (min_depth_m, max_depth_m] are ignored, metres.
  double min_depth_m = 0.1;
  double max_depth_m = 4.5;
  /// Smallest segment (in full-resolution pixels: samples * step_px^2) that gets a plane fit and
  /// takes part in merging; it also needs at least 6 samples. Range >= 1.
  int min_segment_px = 64;
  /// Smallest plane reported, full-resolution pixels. Range >= 1.
  int min_plane_px = 1000;
  /// Neighbouring segments merge only when their unit normals have a dot product >= this
  /// (0.985 = about 10 degrees). Range [-1, 1]; above 1 disables merging.
  double merge_normal_dot = 0.985;
  /// ... and when the plane fitted to their union has an RMS error <= merge_rms_ratio times the
  /// pooled RMS error of the two parts' own fits + merge_rms_tolerance_m (metres): one plane
  /// must explain both about as well as their own planes do. Parallel surfaces a centimetre
  /// apart stay apart in precise data and merge where noise hides the step.
  double merge_rms_ratio = 1.5;
  double merge_rms_tolerance_m = 0.002;
  /// A fitted plane (a segment's, a union's or a final one) is kept only when its RMS error is
  /// <= max_rms_m (metres) or <= max_noise_ratio times the RMS the noise model predicts for its
  /// points.
  double max_rms_m = 0.01;
  double max_noise_ratio = 2.0;
  /// kColorAndDepth: depth step allowed between 4-neighbours before a segment has a plane, as a
  /// fraction of depth per pixel of separation (a plane seen at grazing angles changes depth
  /// fast); and the distance from the segment's plane allowed beyond 3 sigma_z, metres.
  double depth_jump_ratio = 0.03;
  double grow_plane_distance_m = 0.01;
  /// Samples farther than 3 sigma_z + outlier_margin_m (metres) from their segment's plane are
  /// dropped.
  double outlier_margin_m = 0.005;

  /// Empty when valid, otherwise a sentence naming the first bad parameter.
  std::string validationError() const;
  /// Paper 000's configuration: full resolution, colour-only growing, threshold 15.
  static PlaneSegmenterParams paper();
};

struct Plane {
  /// n.p + d = 0 in the camera optical frame, |n| = 1, n towards the camera.
  Eigen::Vector3d normal_camera = Eigen::Vector3d::UnitZ();
  double offset_m = 0.0;  ///< d, metres
  /// Covariance of (n_x, n_y, n_z, d) from the depth noise model (units 1, 1, 1, metres), scaled
  /// up by the fit's chi^2 per degree of freedom when that exceeds 1. Rank 3: the direction
  /// (n, 0) is fixed by |n| = 1. Samples are taken as independent, so with step_px > 1 it
  /// describes the samples used, not every pixel.
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
  int inlier_samples = 0;  ///< grid samples fitted (after outlier removal)
  int inlier_pixels = 0;   ///< inlier_samples * step_px^2 (full-resolution estimate)
  /// Sum over inlier samples of step_px^2 pixel footprints on the plane, z^2 / (fx fy) / |n.r|
  /// with r the pixel's ray scaled to r.z = 1 and z = d / |n.r| the plane's depth there
  /// (|n.r| floored at 0.05 to keep grazing pixels finite), m^2.
  double area_m2 = 0.0;
  Eigen::Vector3d centroid_camera = Eigen::Vector3d::Zero();  ///< mean of the inliers, metres
  double rms_error_m = 0.0;  ///< RMS point-to-plane distance of the inliers, metres
  /// Convex hull of the inlier samples in the image, its vertices cast onto the plane
  /// (a convex polygon on the plane, camera frame, metres, in the image hull's order).
  std::vector<Eigen::Vector3d> boundary_camera;
  /// Pixel coordinates (u = x, v = y) of the inlier samples, for samplePlanePoints().
  std::vector<cv::Point> pixels;
};

struct PlaneSegmentation {
  std::vector<Plane> planes;  ///< largest first (by inlier_samples)
  /// CV_32S, input size: plane index per pixel, -1 = no plane. With step_px > 1 every pixel of
  /// an inlier sample's step_px x step_px block carries its label.
  cv::Mat labels;
  int segments_grown = 0;   ///< segments from region growing (any size)
  int segments_fitted = 0;  ///< segments large enough and with an acceptable plane fit
};

class PlaneSegmenter {
 public:
  /// Throws std::invalid_argument when params.validationError() is not empty.
  explicit PlaneSegmenter(const PlaneSegmenterParams& params = PlaneSegmenterParams());

  /// Segments one registered frame. color_bgr: CV_8UC3 BGR; depth_m: CV_32FC1 metres along z,
  /// NaN (or <= 0) = no data, same size as the colour image and as intrinsics' width and height.
  /// Throws std::invalid_argument for empty images, wrong types or mismatched sizes.
  const PlaneSegmentation& segment(const cv::Mat& color_bgr, const cv::Mat& depth_m,
                                   const CameraIntrinsics& intrinsics);
  /// The same for a frame (its color_bgr, depth_m and intrinsics).
  const PlaneSegmentation& segment(const RgbdFrame& frame);

  const PlaneSegmenterParams& params() const { return params_; }

 private:
  /// Sums over a set of samples: weighted (weight z^2 / sigma_z^2) and unweighted.
  struct Moments {
    double w = 0.0;
    Eigen::Vector3d wp = Eigen::Vector3d::Zero();
    Eigen::Matrix3d wpp = Eigen::Matrix3d::Zero();
    double inv_w = 0.0;  ///< sum of 1 / weight: the noise model's residual variance / d^2
    int n = 0;
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    Eigen::Matrix3d pp = Eigen::Matrix3d::Zero();
    void add(const Eigen::Vector3d& point, double weight);
    void add(const Moments& other);
  };
  struct Fit {
    bool ok = false;  ///< false for too few, tiny or nearly collinear point sets
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    double offset_m = 0.0;
    double rms_m = 0.0;        ///< RMS point-to-plane distance (unweighted)
    double model_rms_m = 0.0;  ///< RMS the noise model predicts for these points
    double extent_m = 0.0;     ///< standard deviation along the second principal axis
  };
  struct Segment {
    int first = 0;  ///< its samples are members_[first, first + count)
    int count = 0;
    Moments moments;
    Fit fit;
    bool valid = false;  ///< has an acceptable fit and takes part in merging
  };

  static Fit fitMoments(const Moments& moments);
  bool acceptable(const Fit& fit) const;
  /// Drops members of `segment` farther than 3 sigma + margin from `fit`, compacts them and
  /// recomputes the segment's moments.
  void dropOutliers(Segment& segment, const Fit& fit);
  int findRoot(int segment);

  void prepareGrid(const cv::Mat& color_bgr, const cv::Mat& depth_m,
                   const CameraIntrinsics& intrinsics);
  void growSegments();
  void fitSegments();
  void mergeSegments();
  void buildPlanes(const cv::Mat& depth_m, const CameraIntrinsics& intrinsics);

  PlaneSegmenterParams params_;
  PlaneSegmentation result_;
  // Per-frame buffers, one entry per grid sample (row-major, grid_width_ x grid_height_).
  int grid_width_ = 0;
  int grid_height_ = 0;
  cv::Mat small_bgr_;
  cv::Mat small_lab_;
  std::vector<float> lab_;                     ///< L, a, b per sample, true units
  std::vector<Eigen::Vector3f> point_camera_;  ///< back-projected sample, metres
  std::vector<double> weight_;                 ///< z^2 / sigma_z^2, 0 = no valid depth
  std::vector<double> sigma_z_;                ///< noise model at the sample's depth, metres
  std::vector<int> segment_of_;  ///< segment, later merged group, id per sample; -1 = none
  std::vector<int> candidates_;  ///< samples to look at in a boundary refinement pass
  std::vector<std::pair<int, int>> changes_;  ///< (sample, new group) of a refinement pass
  std::vector<int> visit_;                    ///< pass that last queued each sample
  std::vector<int> stack_;
  std::vector<int> members_;  ///< sample indices, grouped by segment
  std::vector<Segment> segments_;
  std::vector<int> merged_into_;  ///< union-find parent per segment
};

/// `count` points on `plane` (camera frame, metres) at inlier pixels drawn uniformly with
/// replacement (seeded, deterministic): each pixel's ray is intersected with the plane, so the
/// points lie exactly on it and within its inlier region. Empty when the plane has no pixels or
/// count <= 0. Uniform over pixels, so nearer parts of the plane get more points per m^2.
std::vector<Eigen::Vector3d> samplePlanePoints(const Plane& plane, int count,
                                               const CameraIntrinsics& intrinsics,
                                               std::uint64_t seed);

/// Kinect v1 axial depth noise at depth z (Nguyen et al. 2012), metres.
inline double kinectSigmaZ(double z_m) { return 0.0012 + 0.0019 * (z_m - 0.4) * (z_m - 0.4); }

}  // namespace slamd::planes
