#pragma once
// An analytic box room for mapping tests and benchmarks: depth (and colour) images rendered by
// intersecting each pixel's ray with the six faces of an axis-aligned box seen from inside.

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"

namespace slamd::test {

struct BoxRoom {
  /// Inner faces in the world frame, metres. The defaults keep every face off the 5 cm and 2 cm
  /// voxel boundaries so that "the voxel containing the wall" is unambiguous.
  Eigen::Vector3d min_m{-2.02, -1.22, -2.02};
  Eigen::Vector3d max_m{2.02, 1.02, 2.52};

  /// Distance along the unit-z ray direction d (camera frame), from origin o (world).
  double hit(const Eigen::Vector3d& o, const Eigen::Vector3d& d_world, int* face) const {
    double best = std::numeric_limits<double>::infinity();
    for (int axis = 0; axis < 3; ++axis) {
      if (d_world[axis] == 0.0) continue;
      const double bound = d_world[axis] > 0.0 ? max_m[axis] : min_m[axis];
      const double t = (bound - o[axis]) / d_world[axis];
      if (t > 0.0 && t < best) {
        best = t;
        *face = axis * 2 + (d_world[axis] > 0.0 ? 1 : 0);
      }
    }
    return best;
  }

  /// A 640x480 frame (default intrinsics) seen from T_world_camera.
  RgbdFrame render(const SE3& T_world_camera, const CameraIntrinsics& intrinsics = {}) const {
    RgbdFrame frame;
    frame.intrinsics = intrinsics;
    frame.depth_m = cv::Mat(intrinsics.height, intrinsics.width, CV_32FC1);
    frame.color_bgr = cv::Mat(intrinsics.height, intrinsics.width, CV_8UC3);
    const Eigen::Matrix3d R = T_world_camera.linear();
    const Eigen::Vector3d o = T_world_camera.translation();
    for (int v = 0; v < intrinsics.height; ++v) {
      for (int u = 0; u < intrinsics.width; ++u) {
        const Eigen::Vector3d d = R * intrinsics.ray(u, v);  // camera z = 1 along the ray
        int face = 0;
        const double t = hit(o, d, &face);
        frame.depth_m.at<float>(v, u) = static_cast<float>(t);
        frame.color_bgr.at<cv::Vec3b>(v, u) = cv::Vec3b(
            static_cast<unsigned char>(40 * face), static_cast<unsigned char>(200 - 30 * face),
            static_cast<unsigned char>(100 + 20 * face));
      }
    }
    return frame;
  }
};

/// Camera poses at the world origin looking around: `yaw_steps` headings about the world y axis
/// (down), each at pitches -30, 0, +30 degrees.
inline std::vector<SE3> lookAroundPoses(int yaw_steps = 8) {
  std::vector<SE3> poses;
  for (int i = 0; i < yaw_steps; ++i) {
    for (const double pitch_deg : {-30.0, 0.0, 30.0}) {
      const double yaw = 2.0 * M_PI * i / yaw_steps;
      SE3 T = SE3::Identity();
      T.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitY()) *
                    Eigen::AngleAxisd(pitch_deg * M_PI / 180.0, Eigen::Vector3d::UnitX()))
                       .toRotationMatrix();
      poses.push_back(T);
    }
  }
  return poses;
}

}  // namespace slamd::test
