#pragma once
// A plain corridor rendered without the synthetic renderer: walls, floor and ceiling only, each a
// flat colour, exact depth. Planes fix five of its six degrees of freedom; the translation along
// the corridor (z) is free. For the plane ICP and corridor-mode tests.

#include <array>
#include <limits>
#include <tuple>

#include <opencv2/core.hpp>

#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"

namespace slamd {
namespace test {

/// The corridor x in [-1, 1], y in [-1.3, 1.2] (y down, optical frame of the first camera),
/// endless along z, seen from T_world_camera by a 320x240 camera; exact depth.
inline RgbdFrame renderCorridor(const SE3& T_world_camera) {
  RgbdFrame frame;
  CameraIntrinsics& k = frame.intrinsics;
  k.fx = k.fy = 262.5;
  k.cx = 159.5;
  k.cy = 119.5;
  k.width = 320;
  k.height = 240;
  frame.depth_m.create(k.height, k.width, CV_32FC1);
  frame.color_bgr.create(k.height, k.width, CV_8UC3);
  // (axis, bound, colour): the planes x = -1, x = 1, y = -1.3, y = 1.2.
  const std::array<std::tuple<int, double, cv::Vec3b>, 4> surfaces = {{
      {0, -1.0, cv::Vec3b(40, 60, 200)},
      {0, 1.0, cv::Vec3b(200, 80, 40)},
      {1, -1.3, cv::Vec3b(220, 220, 220)},
      {1, 1.2, cv::Vec3b(60, 140, 60)},
  }};
  const Eigen::Matrix3d R = T_world_camera.linear();
  const Eigen::Vector3d o = T_world_camera.translation();
  for (int v = 0; v < k.height; ++v) {
    for (int u = 0; u < k.width; ++u) {
      const Eigen::Vector3d ray_camera = k.ray(u, v);
      const Eigen::Vector3d d = R * ray_camera;
      double best = std::numeric_limits<double>::infinity();
      cv::Vec3b colour(0, 0, 0);
      for (const auto& [axis, bound, surface_colour] : surfaces) {
        if (d[axis] == 0.0) continue;
        const double t = (bound - o[axis]) / d[axis];
        if (t > 0.0 && t < best) {
          best = t;
          colour = surface_colour;
        }
      }
      // Depth along the camera's z: the ray has z = 1 in the camera frame.
      frame.depth_m.at<float>(v, u) =
          best < 20.0 ? static_cast<float>(best) : std::numeric_limits<float>::quiet_NaN();
      frame.color_bgr.at<cv::Vec3b>(v, u) = colour;
    }
  }
  return frame;
}

}  // namespace test
}  // namespace slamd
