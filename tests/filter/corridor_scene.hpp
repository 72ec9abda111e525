#pragma once
// A line-drawing corridor for the filter's tests and benchmark: the corridor's edges, skirting
// boards, handrails, floor-tile joints and door frames projected with a pinhole camera and drawn
// with cv::line (sub-pixel, anti-aliased) on a noisy textured background.
//
// Corridor frame ("world" here): optical-style, x right, y down, z along the corridor, so the
// corridor's vanishing direction is +z and the first camera (identity pose) looks straight down
// it. Walls at x = +-1 m, floor at y = +1.2 m, ceiling at y = -1.4 m, from z = -5 m to 80 m.

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/se3.hpp"

namespace slamd::filter_test {

struct Segment3 {
  Eigen::Vector3d a, b;  ///< corridor frame, metres
  int grey = 40;         ///< drawing intensity
};

inline std::vector<Segment3> corridorSegments() {
  constexpr double kHalfWidth = 1.0, kFloor = 1.2, kCeiling = -1.4, kStart = -5.0, kEnd = 80.0;
  std::vector<Segment3> s;
  const auto along = [&](double x, double y, int grey) {
    s.push_back({{x, y, kStart}, {x, y, kEnd}, grey});
  };
  for (double x : {-kHalfWidth, kHalfWidth}) {
    along(x, kFloor, 30);        // wall-floor edge
    along(x, kCeiling, 60);      // wall-ceiling edge
    along(x, kFloor - 0.1, 50);  // skirting board
    along(x, 0.2, 70);           // handrail
  }
  for (double x : {-0.5, 0.0, 0.5}) along(x, kFloor, 80);  // floor tile joints along the corridor
  for (double x : {-0.33, 0.33}) along(x, kCeiling, 90);   // ceiling light strip
  for (double z = kStart; z <= kEnd; z += 1.0) {           // transverse floor joints
    s.push_back({{-kHalfWidth, kFloor, z}, {kHalfWidth, kFloor, z}, 80});
  }
  for (double z = 2.0; z <= kEnd; z += 5.0) {  // door frames, alternating sides
    const double x = (static_cast<int>(z) / 5) % 2 == 0 ? -kHalfWidth : kHalfWidth;
    const double top = -0.85;
    s.push_back({{x, kFloor, z}, {x, top, z}, 20});
    s.push_back({{x, kFloor, z + 1.0}, {x, top, z + 1.0}, 20});
    s.push_back({{x, top, z}, {x, top, z + 1.0}, 20});
  }
  return s;
}

/// Renders the corridor seen from T_world_camera (corridor frame <- camera), CV_8UC1.
inline cv::Mat renderCorridor(const CameraIntrinsics& K, const SE3& T_world_camera, unsigned seed) {
  cv::Mat image(K.height, K.width, CV_8UC1);
  // Textured background: smooth noise (plaster-like), too weak for Canny's thresholds.
  cv::Mat noise(K.height, K.width, CV_32FC1);
  cv::RNG rng(seed);
  rng.fill(noise, cv::RNG::NORMAL, 170.0, 6.0);
  cv::GaussianBlur(noise, noise, cv::Size(5, 5), 1.5);
  noise.convertTo(image, CV_8UC1);
  const SE3 T_camera_world = T_world_camera.inverse();
  constexpr double kNear = 0.1;
  constexpr int kShift = 4;  // sub-pixel drawing: coordinates in 1/16 pixel
  for (const auto& seg : corridorSegments()) {
    Eigen::Vector3d a = T_camera_world * seg.a, b = T_camera_world * seg.b;
    if (a.z() < kNear && b.z() < kNear) continue;
    if (a.z() < kNear) a = a + (b - a) * ((kNear - a.z()) / (b.z() - a.z()));
    if (b.z() < kNear) b = b + (a - b) * ((kNear - b.z()) / (a.z() - b.z()));
    const Eigen::Vector2d pa = K.project(a), pb = K.project(b);
    const auto to_point = [](const Eigen::Vector2d& p) {
      const double limit = 1e5;
      return cv::Point(static_cast<int>(std::lround(std::clamp(p.x(), -limit, limit) * 16.0)),
                       static_cast<int>(std::lround(std::clamp(p.y(), -limit, limit) * 16.0)));
    };
    cv::line(image, to_point(pa), to_point(pb), cv::Scalar(seg.grey), 2, cv::LINE_AA, kShift);
  }
  return image;
}

/// The analytic vanishing point of the corridor direction (+z) seen with rotation R_world_camera.
inline Eigen::Vector2d corridorVanishingPoint(const CameraIntrinsics& K,
                                              const Eigen::Matrix3d& R_world_camera) {
  return K.project(R_world_camera.transpose() * Eigen::Vector3d::UnitZ());
}

/// Depth image (CV_32FC1 metres, NaN = none) of the corridor's walls, floor and ceiling seen from
/// T_world_camera. With noise_seed > 0, Kinect-like noise is added in inverse depth (sigma 0.0015
/// per metre, about 6 mm at 2 m).
inline cv::Mat renderCorridorDepth(const CameraIntrinsics& K, const SE3& T_world_camera,
                                   unsigned noise_seed = 0) {
  constexpr double kHalfWidth = 1.0, kFloor = 1.2, kCeiling = -1.4;
  std::mt19937 rng(noise_seed);
  std::normal_distribution<double> noise(0.0, 0.0015);
  cv::Mat depth(K.height, K.width, CV_32FC1, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d o = T_world_camera.translation();
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const Eigen::Vector3d ray_c = K.ray(u, v);  // z = 1: the distance along it is the depth
      const Eigen::Vector3d ray_w = R * ray_c;
      double best = std::numeric_limits<double>::infinity();
      const auto hit = [&](double position, double origin, double direction) {
        if (std::abs(direction) < 1e-12) return;
        const double t = (position - origin) / direction;
        if (t > 0.0 && t < best) best = t;
      };
      hit(-kHalfWidth, o.x(), ray_w.x());
      hit(kHalfWidth, o.x(), ray_w.x());
      hit(kFloor, o.y(), ray_w.y());
      hit(kCeiling, o.y(), ray_w.y());
      if (!std::isfinite(best)) continue;
      double inverse_depth = 1.0 / best;
      if (noise_seed > 0) inverse_depth += noise(rng);
      depth.at<float>(v, u) = static_cast<float>(1.0 / inverse_depth);
    }
  }
  return depth;
}

/// Rotation from yaw (about y, down), pitch (about x, right) and roll (about z, forward), radians.
inline Eigen::Matrix3d yawPitchRoll(double yaw_rad, double pitch_rad, double roll_rad) {
  return expSO3(Eigen::Vector3d(0, yaw_rad, 0)) * expSO3(Eigen::Vector3d(pitch_rad, 0, 0)) *
         expSO3(Eigen::Vector3d(0, 0, roll_rad));
}

}  // namespace slamd::filter_test
