#pragma once
// SurfaceAxisDetector: the dominant plane orientations of one depth image, as unoriented unit
// axes in the camera frame (the "Manhattan directions, told apart by depth normals").
//
// A corridor shows three such axes: the floor and ceiling share the vertical axis, both walls the
// lateral one, and the corridor's own direction (seen as the vanishing point) is the normal of an
// end wall. One vanishing point observes only two of the three rotation angles (not the roll about
// the corridor axis); a plane axis observes the two angles about the axes perpendicular to it, so
// the floor or a wall makes the roll observable and tightens the pitch. PoseEkf::updateDirection()
// uses them as measurements of world-direction landmarks, the same landmarks the vanishing points
// update (an end wall's normal and the corridor's vanishing point are the same axis).
//
// Usage (no threads inside, not thread-safe: one instance per thread that detects):
//   SurfaceAxisDetector detector(filter_config.axes, intrinsics);
//   SurfaceAxes axes = detector.detect(frame.depth_m);   // a self-contained value
//   for (const SurfaceAxis& a : axes.axes) ekf.updateDirection(a.direction_camera, a.covariance);
//
// Steps: the image is cut into square cells (filter.axes.cell_px); in each, the valid depth pixels
// (every sample_step_px, within [min_depth_m, max_depth_m]) fit a plane by ordinary least squares
// in inverse depth, 1/z = (n . r) / d with r the normalised pixel (x, y, 1): the sensor's noise is
// in disparity, so this is unbiased where a 3D principal-component fit is not. Cells whose
// residual is large (max_relative_residual: edges, corners, clutter) are dropped; the others get
// the covariance of their unit normal from the fit. The axes are then found greedily: the cell
// normal whose inlier cone (inlier_angle_deg, sign ignored) holds the most information seeds an
// axis, refined as the principal eigenvector of its inliers' weighted scatter and then as their
// information-weighted mean (Gauss-Newton in the tangent plane, inliers re-chosen each time); the
// next axis is sought among cells not yet used whose normals lie within orthogonality_deg of
// perpendicular to every axis found so far (Manhattan world). An axis needs min_axis_cells cells.
//
// Covariance (2x2, radians^2) is expressed in PoseEkf::tangentBasis(direction_camera): the inverse
// of the summed cell information, multiplied by the variance of unit weight when the cells scatter
// more than their fits claim, plus min_sigma_deg^2 on the diagonal.
//
// Frames and units: camera optical frame (x right, y down, z forward); depth CV_32FC1 metres, NaN
// or non-positive = none; pixels through the ideal pinhole model of the intrinsics (the depth
// image is not undistorted; the lens distortion of a Kinect-class camera bends a normal by far
// less than the cell scatter). Bad input (empty, wrong type, wrong size) returns a status and is
// counted, never throws.

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

/// Surface-axis detector options, keys `filter.axes.*` (type, default, range, unit and doc of
/// each: its row in surface_axes.cpp, or `slamd --describe-config filter`).
struct SurfaceAxesConfig {
  int cell_px = 24;
  int sample_step_px = 2;
  int min_cell_points = 40;
  double min_depth_m = 0.4;  ///< far Kinect-class depth is too noisy and coarse for normals
  double max_depth_m = 3.5;
  double max_relative_residual = 0.015;
  double inlier_angle_deg = 6.0;
  double orthogonality_deg = 6.0;
  int min_axis_cells = 12;
  int max_axes = 3;
  /// Stands for what averaging cells cannot remove: the depth calibration of a real sensor (a
  /// Kinect v1's planes bend by a degree or more towards the image corners). Rendered depth has
  /// none: config/synthetic.yaml uses 0.1.
  double min_sigma_deg = 2.0;

  /// The `filter.axes.*` keys.
  static const ConfigSchema<SurfaceAxesConfig>& schema();
  /// Reads `filter.axes.*`; throws ConfigError naming the key when a value is out of range.
  static SurfaceAxesConfig load(Config& config);
};

enum class SurfaceAxesStatus : std::int8_t {
  kOk = 0,          ///< at least one axis
  kEmptyImage,      ///< no pixels
  kWrongImageType,  ///< not CV_32FC1
  kWrongImageSize,  ///< size differs from the intrinsics
  kNoPlanes,        ///< no axis with min_axis_cells planar cells
};

const char* surfaceAxesStatusName(SurfaceAxesStatus status);

/// One dominant plane orientation.
struct SurfaceAxis {
  /// Unit axis in the camera optical frame (a plane normal; the sign carries no meaning).
  Eigen::Vector3d direction_camera = Eigen::Vector3d::UnitZ();
  /// Covariance in PoseEkf::tangentBasis(direction_camera), radians^2.
  Eigen::Matrix2d covariance = Eigen::Matrix2d::Identity();
  int num_cells = 0;           ///< planar cells supporting it
  int num_points = 0;          ///< depth samples in those cells
  double rms_angle_deg = 0.0;  ///< RMS angle of the supporting cells' normals from the axis
};

/// The result of one detect() call: a plain value, safe to move to another thread.
struct SurfaceAxes {
  SurfaceAxesStatus status = SurfaceAxesStatus::kEmptyImage;
  std::vector<SurfaceAxis> axes;  ///< strongest first; mutually near-perpendicular
  int num_planar_cells = 0;       ///< cells that passed the planarity test
};

struct SurfaceAxesCounters {
  std::int64_t images = 0;
  std::int64_t detected = 0;      ///< images with at least one axis
  std::int64_t bad_input = 0;     ///< empty, wrong type or wrong size
  std::int64_t not_detected = 0;  ///< no axis
};

class SurfaceAxisDetector {
 public:
  SurfaceAxisDetector(const SurfaceAxesConfig& config, const CameraIntrinsics& intrinsics);

  /// @param depth_m the frame's depth (RgbdFrame::depth_m), not modified, not kept
  SurfaceAxes detect(const cv::Mat& depth_m);

  const SurfaceAxesCounters& counters() const { return counters_; }
  const SurfaceAxesConfig& config() const { return config_; }

 private:
  struct Cell {
    Eigen::Vector3d normal;       ///< unit, camera frame
    Eigen::Matrix2d information;  ///< inverse covariance of the normal in B(normal), rad^-2
    double weight = 0.0;          ///< mean of information's eigenvalues, rad^-2
    int num_points = 0;
    bool used = false;  ///< already supports an axis
  };
  void fitCells(const cv::Mat& depth_m);
  /// The best axis among unused cells whose normals are within orthogonality_deg of perpendicular
  /// to every axis in `found`; false when none has min_axis_cells cells.
  bool findAxis(const std::vector<SurfaceAxis>& found, SurfaceAxis* axis);

  SurfaceAxesConfig config_;
  CameraIntrinsics intrinsics_;
  std::vector<Cell> cells_;
  SurfaceAxesCounters counters_;
};

}  // namespace slamd
