#pragma once
// Pinhole camera intrinsics with optional plumb-bob (OpenCV k1 k2 p1 p2 k3) distortion.
//
// Frames: the camera optical frame has x right, y down, z forward (along the look vector); pixel
// (0, 0) is the centre of the top-left pixel. project()/backProject() use the ideal pinhole model;
// distortion coefficients are carried so that sources can undistort images when configured.

#include <array>
#include <string>

#include <Eigen/Core>

namespace slamd {

enum class DistortionModel { kNone = 0, kPlumbBob = 1 };

struct CameraIntrinsics {
  double fx = 525.0;  ///< focal length along x, pixels
  double fy = 525.0;  ///< focal length along y, pixels
  double cx = 319.5;  ///< principal point x, pixels
  double cy = 239.5;  ///< principal point y, pixels
  int width = 640;    ///< image width, pixels
  int height = 480;   ///< image height, pixels
  DistortionModel distortion_model = DistortionModel::kNone;
  std::array<double, 5> distortion{};  ///< k1 k2 p1 p2 k3 (dimensionless)

  /// Pixel of a point in the camera optical frame (metres). z must be positive.
  Eigen::Vector2d project(const Eigen::Vector3d& p_camera) const {
    return {fx * p_camera.x() / p_camera.z() + cx, fy * p_camera.y() / p_camera.z() + cy};
  }

  /// Point in the camera optical frame (metres) seen at pixel (u, v) with depth z = depth_m.
  Eigen::Vector3d backProject(double u, double v, double depth_m) const {
    return {(u - cx) * depth_m / fx, (v - cy) * depth_m / fy, depth_m};
  }

  /// Unit-depth ray (z = 1) through pixel (u, v).
  Eigen::Vector3d ray(double u, double v) const { return backProject(u, v, 1.0); }

  /// True when (u, v) lies inside the image (with a margin in pixels).
  bool contains(double u, double v, double margin_px = 0.0) const {
    return u >= margin_px && v >= margin_px && u <= width - 1 - margin_px &&
           v <= height - 1 - margin_px;
  }

  /// The same camera at another resolution (e.g. a pyramid level or a 320x240 mode): focal
  /// lengths scale with the size, and the principal point so that pixel centres stay aligned.
  CameraIntrinsics scaled(int new_width, int new_height) const;

  /// 3x3 camera matrix K.
  Eigen::Matrix3d matrix() const;

  /// Empty when valid, otherwise a sentence saying what is wrong.
  std::string validationError() const;

  bool operator==(const CameraIntrinsics& other) const;
  bool operator!=(const CameraIntrinsics& other) const { return !(*this == other); }
};

}  // namespace slamd
