#pragma once
// Builds small TUM-format folders for capture tests: seeded colour noise and smooth depth.

#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "scoped_temp_dir.hpp"
#include "slamd/capture/tum_source.hpp"
#include "test_data.hpp"

namespace slamd::test {

inline cv::Mat makeColor(int width, int height, std::uint32_t seed) {
  cv::Mat image(height, width, CV_8UC3);
  cv::RNG rng(seed);  // seeded, unlike cv::randu's global generator
  rng.fill(image, cv::RNG::UNIFORM, 0, 256);
  // Smooth it a little so that JPEG round trips stay close.
  cv::GaussianBlur(image, image, cv::Size(5, 5), 1.5);
  return image;
}

/// Depth raw (TUM units, 5000 per metre): a ramp from 1 m, different per frame.
inline cv::Mat makeDepthRaw(int width, int height, int frame) {
  cv::Mat raw(height, width, CV_16UC1);
  for (int r = 0; r < height; ++r) {
    for (int c = 0; c < width; ++c) {
      raw.at<std::uint16_t>(r, c) = static_cast<std::uint16_t>(5000 + 10 * c + r + frame);
    }
  }
  raw.at<std::uint16_t>(0, 0) = 0;  // no measurement
  return raw;
}

struct TumFolder {
  ScopedTempDir dir;  ///< removed with the TumFolder
  std::vector<double> rgb_times;
  std::vector<double> depth_times;
};

/// `count` frames at 30 Hz, colour as PNG or JPEG, depth 3 ms later than colour.
inline TumFolder writeTumFolder(const std::string& tag, int count, bool jpeg_color, int width = 64,
                                int height = 48) {
  TumFolder folder{ScopedTempDir(tag), {}, {}};
  std::filesystem::create_directories(folder.dir / "rgb");
  std::filesystem::create_directories(folder.dir / "depth");
  std::ofstream rgb(folder.dir / "rgb.txt");
  std::ofstream depth(folder.dir / "depth.txt");
  rgb << "# color images\n# timestamp filename\n";
  depth << "# depth maps\n";
  for (int i = 0; i < count; ++i) {
    const double t = 1000.0 + i / 30.0;
    char name[64];
    std::snprintf(name, sizeof(name), "%.6f", t);
    const std::string rgb_name = std::string("rgb/") + name + (jpeg_color ? ".jpg" : ".png");
    cv::imwrite((folder.dir / rgb_name).string(),
                makeColor(width, height, 42u + static_cast<unsigned>(i)));
    rgb << name << " " << rgb_name << "\n";
    folder.rgb_times.push_back(std::stod(std::string(name)));
    std::snprintf(name, sizeof(name), "%.6f", t + 0.003);
    const std::string depth_name = std::string("depth/") + name + ".png";
    cv::imwrite((folder.dir / depth_name).string(), makeDepthRaw(width, height, i));
    depth << name << "\t" << depth_name << "\n";
    folder.depth_times.push_back(std::stod(std::string(name)));
  }
  return folder;
}

/// A TUM config for the small test images.
inline TumSourceConfig smallTumConfig(int width = 64, int height = 48) {
  Config config;
  config.set("camera.width", std::to_string(width));
  config.set("camera.height", std::to_string(height));
  config.set("camera.cx", std::to_string((width - 1) / 2.0));
  config.set("camera.cy", std::to_string((height - 1) / 2.0));
  return TumSourceConfig::load(config);
}

/// Reads everything; returns delivered frames (and counts reads by status).
struct ReadAll {
  std::vector<RgbdFramePtr> frames;
  std::vector<std::string> skip_messages;
};

inline ReadAll readAll(FrameSource& source, int max_reads = 100000) {
  ReadAll out;
  for (int i = 0; i < max_reads; ++i) {
    FrameRead read = source.next(std::chrono::milliseconds(2000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status == FrameRead::Status::kFrame) out.frames.push_back(read.frame);
    if (read.status == FrameRead::Status::kSkipped) out.skip_messages.push_back(read.message);
  }
  return out;
}

}  // namespace slamd::test
