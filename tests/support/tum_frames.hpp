#pragma once
// Frames of a TUM RGB-D sequence (fr1: depth scale 5000, the published fr1 intrinsics,
// distortion ignored) with the ground-truth pose nearest in time, for the plane tests.

#include <cmath>
#include <cstddef>
#include <filesystem>
#include <optional>

#include <opencv2/imgcodecs.hpp>

#include "slamd/capture/tum_dataset.hpp"
#include "slamd/common/rgbd_frame.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/common/trajectory.hpp"

namespace slamd::test {

struct TumFrame {
  RgbdFrame frame;
  SE3 T_world_camera = SE3::Identity();  ///< ground truth nearest the depth image's time
};

/// Colour frame `index` of the sequence in `dir`, with the depth image nearest in time and the
/// ground-truth pose nearest that; nullopt when the index is out of range or a file cannot be read.
inline std::optional<TumFrame> loadTumFrame(const std::filesystem::path& dir, std::size_t index) {
  const TumFileList rgb = readTumFileList((dir / "rgb.txt").string());
  const TumFileList depth = readTumFileList((dir / "depth.txt").string());
  const Trajectory gt = readTumTrajectory((dir / "groundtruth.txt").string());
  if (index >= rgb.entries.size() || depth.entries.empty() || gt.empty()) return std::nullopt;
  const double t = rgb.entries[index].timestamp_s;
  auto nearest = [t](const auto& items, auto time_of) {
    std::size_t best = 0;
    for (std::size_t i = 1; i < items.size(); ++i) {
      if (std::abs(time_of(items[i]) - t) < std::abs(time_of(items[best]) - t)) best = i;
    }
    return best;
  };
  const auto& depth_entry =
      depth.entries[nearest(depth.entries, [](const TumListEntry& e) { return e.timestamp_s; })];
  // The pose when the depth image was taken: the geometry comes from it (colour and depth
  // images of fr1 are up to about 15 ms apart).
  const double depth_t = depth_entry.timestamp_s;
  std::size_t pose = 0;
  for (std::size_t i = 1; i < gt.size(); ++i) {
    if (std::abs(gt[i].timestamp_s - depth_t) < std::abs(gt[pose].timestamp_s - depth_t)) pose = i;
  }
  TumFrame out;
  out.T_world_camera = gt[pose].T_world_camera;
  out.frame.color_bgr = cv::imread((dir / rgb.entries[index].path).string(), cv::IMREAD_COLOR);
  const cv::Mat raw = cv::imread((dir / depth_entry.path).string(), cv::IMREAD_UNCHANGED);
  if (out.frame.color_bgr.empty() || raw.empty()) return std::nullopt;
  out.frame.depth_m = depthRawToMeters(raw, 5000.0);
  out.frame.intrinsics.fx = 517.3;
  out.frame.intrinsics.fy = 516.5;
  out.frame.intrinsics.cx = 318.6;
  out.frame.intrinsics.cy = 255.3;
  out.frame.intrinsics.width = out.frame.color_bgr.cols;
  out.frame.intrinsics.height = out.frame.color_bgr.rows;
  return out;
}

}  // namespace slamd::test
