#pragma once
// A tiny ray-cast textured box room for tracking tests: exact colour and depth of the inside of
// an axis-aligned box whose six walls carry seeded random textures (blurred noise with blobs).
// Test-local: slamd's synth library is the full-featured world generator.

#include <array>
#include <cmath>
#include <limits>
#include <random>

#include <opencv2/imgproc.hpp>

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"

namespace slamd::test {

class TexturedBox {
 public:
  /// Box [min_m, max_m] in the world frame; textures at texels_per_m resolution.
  TexturedBox(Eigen::Vector3d min_m, Eigen::Vector3d max_m, std::uint32_t seed,
              double texels_per_m = 200.0)
      : min_(min_m), max_(max_m), texels_per_m_(texels_per_m) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> noise(0.0f, 255.0f);
    for (cv::Mat& tex : textures_) {
      cv::Mat fine(512, 512, CV_32F), coarse(64, 64, CV_32F);
      for (int v = 0; v < fine.rows; ++v)
        for (int u = 0; u < fine.cols; ++u) fine.at<float>(v, u) = noise(rng);
      for (int v = 0; v < coarse.rows; ++v)
        for (int u = 0; u < coarse.cols; ++u) coarse.at<float>(v, u) = noise(rng);
      cv::GaussianBlur(fine, fine, cv::Size(0, 0), 1.5);
      cv::resize(coarse, coarse, fine.size(), 0, 0, cv::INTER_CUBIC);
      tex = 0.5 * fine + 0.5 * coarse;
      cv::normalize(tex, tex, 10, 245, cv::NORM_MINMAX);
    }
  }

  /// Renders the view from T_world_camera (ideal pinhole K).
  RgbdFrame render(const SE3& T_world_camera, const CameraIntrinsics& K) const {
    RgbdFrame frame;
    frame.intrinsics = K;
    frame.gray.create(K.height, K.width, CV_8UC1);
    frame.depth_m.create(K.height, K.width, CV_32FC1);
    const Eigen::Matrix3d R = T_world_camera.linear();
    const Eigen::Vector3d o = T_world_camera.translation();
    for (int v = 0; v < K.height; ++v) {
      for (int u = 0; u < K.width; ++u) {
        const Eigen::Vector3d d = R * K.ray(u, v);  // world direction, camera z = 1
        double t_hit = std::numeric_limits<double>::infinity();
        int axis = -1;
        int side = 0;
        for (int a = 0; a < 3; ++a) {
          if (std::abs(d(a)) < 1e-12) continue;
          const double bound = d(a) > 0 ? max_(a) : min_(a);
          const double t = (bound - o(a)) / d(a);
          if (t > 0 && t < t_hit) {
            t_hit = t;
            axis = a;
            side = d(a) > 0 ? 1 : 0;
          }
        }
        if (axis < 0) {
          frame.gray.at<std::uint8_t>(v, u) = 0;
          frame.depth_m.at<float>(v, u) = std::numeric_limits<float>::quiet_NaN();
          continue;
        }
        const Eigen::Vector3d p = o + t_hit * d;
        const int a1 = (axis + 1) % 3;
        const int a2 = (axis + 2) % 3;
        const double tu = (p(a1) - min_(a1)) * texels_per_m_;
        const double tv = (p(a2) - min_(a2)) * texels_per_m_;
        frame.gray.at<std::uint8_t>(v, u) = cv::saturate_cast<std::uint8_t>(
            sample(textures_[static_cast<std::size_t>(axis * 2 + side)], tu, tv));
        frame.depth_m.at<float>(v, u) = static_cast<float>(t_hit);
      }
    }
    cv::cvtColor(frame.gray, frame.color_bgr, cv::COLOR_GRAY2BGR);
    return frame;
  }

 private:
  static double sample(const cv::Mat& tex, double x, double y) {
    // Bilinear, wrapping (the texture tiles).
    const double fx = std::floor(x), fy = std::floor(y);
    const double ax = x - fx, ay = y - fy;
    auto at = [&](long xi, long yi) {
      const int c = static_cast<int>(((xi % tex.cols) + tex.cols) % tex.cols);
      const int r = static_cast<int>(((yi % tex.rows) + tex.rows) % tex.rows);
      return static_cast<double>(tex.at<float>(r, c));
    };
    const long x0 = static_cast<long>(fx), y0 = static_cast<long>(fy);
    return (1 - ay) * ((1 - ax) * at(x0, y0) + ax * at(x0 + 1, y0)) +
           ay * ((1 - ax) * at(x0, y0 + 1) + ax * at(x0 + 1, y0 + 1));
  }

  Eigen::Vector3d min_, max_;
  double texels_per_m_;
  std::array<cv::Mat, 6> textures_;
};

/// The TUM freiburg1 Kinect's pinhole intrinsics (640x480), used by the tracking tests and bench.
inline CameraIntrinsics fr1Camera() {
  CameraIntrinsics K;
  K.fx = 517.3;
  K.fy = 516.5;
  K.cx = 318.6;
  K.cy = 255.3;
  return K;
}

}  // namespace slamd::test
