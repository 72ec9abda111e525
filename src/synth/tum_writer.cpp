#include "slamd/synth/tum_writer.hpp"

#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <vector>

#include <opencv2/imgcodecs.hpp>

namespace slamd {
namespace {

std::ofstream openList(const std::filesystem::path& path, const std::string& what,
                       const std::string& description) {
  std::ofstream file(path, std::ios::trunc);
  if (!file) throw std::runtime_error("cannot write " + path.string());
  file << "# " << what << "\n# file: '" << description << "'\n# timestamp filename\n";
  return file;
}

void writeImage(const std::filesystem::path& path, const cv::Mat& image, TumImageFormat format) {
  // PNG at zlib level 1: level 9 saves a few percent on noisy rendered images at many times the
  // time. PPM/PGM are always binary (P6/P5), OpenCV's default.
  const std::vector<int> params = format == TumImageFormat::kPng
                                      ? std::vector<int>{cv::IMWRITE_PNG_COMPRESSION, 1}
                                      : std::vector<int>{cv::IMWRITE_PXM_BINARY, 1};
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), image, params);
  } catch (const cv::Exception& error) {
    throw std::runtime_error("cannot write " + path.string() + ": " + error.what());
  }
  if (!ok) throw std::runtime_error("cannot write " + path.string());
}

}  // namespace

std::optional<TumImageFormat> parseTumImageFormat(const std::string& name) {
  if (name == "png") return TumImageFormat::kPng;
  if (name == "uncompressed") return TumImageFormat::kUncompressed;
  return std::nullopt;
}

std::string formatTumTimestamp(Utime utime) {
  char text[64];
  const Utime seconds = utime / kUtimePerSecond;
  const Utime micros = utime % kUtimePerSecond;
  std::snprintf(text, sizeof text, "%" PRId64 ".%06" PRId64, seconds, micros);
  return text;
}

TumSequenceWriter::TumSequenceWriter(std::string folder, std::string description,
                                     double depth_scale, TumImageFormat format)
    : folder_(std::move(folder)),
      description_(std::move(description)),
      depth_scale_(depth_scale),
      format_(format) {
  if (!(depth_scale_ > 0.0)) throw std::invalid_argument("depth scale must be positive");
}

void TumSequenceWriter::open() {
  const std::filesystem::path root(folder_);
  std::error_code error;
  for (const char* sub : {"rgb", "depth"}) {
    std::filesystem::create_directories(root / sub, error);
    if (error) {
      throw std::runtime_error("cannot create " + (root / sub).string() + ": " + error.message());
    }
  }
  rgb_list_ = openList(root / "rgb.txt", "color images", description_);
  depth_list_ = openList(root / "depth.txt", "depth maps", description_);
  frames_written_ = 0;
}

void TumSequenceWriter::write(const RgbdFrame& frame) {
  if (!rgb_list_.is_open()) throw std::logic_error("TumSequenceWriter::write before open");
  if (frame.utime < 0) {
    throw std::runtime_error("frame " + std::to_string(frame.sequence) + " has negative utime " +
                             std::to_string(frame.utime));
  }
  // The depth map keeps its own capture time (a Kinect's depth and colour are not taken at the
  // same instant; TumSource pairs them by time and tracking uses the difference).
  const std::string rgb_stamp = formatTumTimestamp(frame.utime);
  const std::string depth_stamp = formatTumTimestamp(frame.depthUtime());
  const std::filesystem::path root(folder_);
  const bool png = format_ == TumImageFormat::kPng;
  const std::string rgb_name = "rgb/" + rgb_stamp + (png ? ".png" : ".ppm");
  const std::string depth_name = "depth/" + depth_stamp + (png ? ".png" : ".pgm");
  writeImage(root / rgb_name, frame.color_bgr, format_);
  writeImage(root / depth_name, depthMetersToRaw(frame.depth_m, depth_scale_), format_);
  rgb_list_ << rgb_stamp << " " << rgb_name << "\n";
  depth_list_ << depth_stamp << " " << depth_name << "\n";
  if (!rgb_list_ || !depth_list_)
    throw std::runtime_error("cannot append to the lists in " + folder_);
  ++frames_written_;
}

void TumSequenceWriter::finish(const Trajectory& ground_truth) {
  rgb_list_.close();
  depth_list_.close();
  if (!rgb_list_ || !depth_list_) throw std::runtime_error("cannot finish the lists in " + folder_);
  if (!ground_truth.empty()) {
    writeTumTrajectory((std::filesystem::path(folder_) / "groundtruth.txt").string(), ground_truth,
                       "ground truth trajectory\nfile: '" + description_ + "'");
  }
}

}  // namespace slamd
