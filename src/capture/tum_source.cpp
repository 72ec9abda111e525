#include "slamd/capture/tum_source.hpp"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "slamd/capture/image_io.hpp"
#include "slamd/common/log.hpp"

namespace slamd {

namespace {

constexpr const char* kComponent = "capture.tum";

std::string joinPath(const std::string& folder, const std::string& relative) {
  return (std::filesystem::path(folder) / relative).string();
}

}  // namespace

const ConfigSchema<TumSourceConfig>& TumSourceConfig::schema() {
  using C = TumSourceConfig;
  static const auto table =
      ConfigSchema<C>("capture.tum")
          .number("max_difference_s", &C::max_difference_s, 1e-6, 1.0, "s",
                  "largest time difference of an associated depth and colour image")
          .number("time_offset_s", &C::time_offset_s, -10.0, 10.0, "s",
                  "added to the depth times before association")
          .text("associations", &C::associations,
                "association file (relative to the folder); empty = associate by time")
          .text("groundtruth", &C::groundtruth,
                "ground-truth file (relative to the folder); empty = none")
          .number("first_frame", &C::first_frame, 0, 100000000, "frames",
                  "play from this associated frame on (0 = the first): part of a sequence, "
                  "e.g. to map one half and localise in it with the other")
          .number("frame_count", &C::frame_count, 0, 100000000, "frames",
                  "play at most this many frames; 0 = to the end");
  return table;
}

TumSourceConfig TumSourceConfig::load(Config& config) {
  TumSourceConfig out;
  out.camera = CameraConfig::load(config, 5000.0);
  schema().load(config, out);
  return out;
}

TumSource::TumSource(std::string folder, TumSourceConfig config)
    : folder_(std::move(folder)), config_(std::move(config)) {}

void TumSource::open() {
  std::error_code error;
  if (!std::filesystem::is_directory(folder_, error)) {
    throw SourceError("TUM folder " + folder_ +
                      " does not exist or is not a directory (expected rgb.txt, depth.txt, "
                      "rgb/ and depth/ inside)");
  }
  pairs_.clear();
  playlist_.clear();
  std::vector<std::string> rejected;
  if (!config_.associations.empty()) {
    const std::string path = joinPath(folder_, config_.associations);
    std::ifstream in(path);
    if (!in) throw SourceError("cannot read associations file " + path);
    std::ostringstream text;
    text << in.rdbuf();
    TumAssociationList list = parseTumAssociations(text.str(), path);
    pairs_ = std::move(list.pairs);
    rejected = std::move(list.rejected);
  } else {
    TumFileList rgb;
    TumFileList depth;
    const std::string rgb_path = joinPath(folder_, "rgb.txt");
    const std::string depth_path = joinPath(folder_, "depth.txt");
    try {
      rgb = readTumFileList(rgb_path);
      depth = readTumFileList(depth_path);
    } catch (const std::exception& e) {
      throw SourceError(std::string(e.what()) + " (a TUM folder lists its images in rgb.txt and " +
                        "depth.txt, or set capture.tum.associations)");
    }
    if (rgb.entries.empty()) throw SourceError(rgb_path + " lists no images");
    if (depth.entries.empty()) throw SourceError(depth_path + " lists no images");
    rejected = std::move(depth.rejected);
    rejected.insert(rejected.end(), rgb.rejected.begin(), rgb.rejected.end());
    std::vector<double> rgb_times;
    std::vector<double> depth_times;
    for (const auto& e : rgb.entries) rgb_times.push_back(e.timestamp_s);
    for (const auto& e : depth.entries) depth_times.push_back(e.timestamp_s);
    for (const auto& [i, j] : associateTimestamps(rgb_times, depth_times, config_.max_difference_s,
                                                  config_.time_offset_s)) {
      pairs_.push_back({rgb.entries[i].timestamp_s, rgb.entries[i].path,
                        depth.entries[j].timestamp_s, depth.entries[j].path});
    }
  }
  if (pairs_.empty()) {
    throw SourceError("TUM folder " + folder_ + ": no colour image has a depth image within " +
                      std::to_string(config_.max_difference_s) + " s");
  }
  const std::size_t first = std::min(pairs_.size(), static_cast<std::size_t>(config_.first_frame));
  std::size_t last = pairs_.size();
  if (config_.frame_count > 0) {
    last = std::min(last, first + static_cast<std::size_t>(config_.frame_count));
  }
  pairs_.erase(pairs_.begin() + static_cast<std::ptrdiff_t>(last), pairs_.end());
  pairs_.erase(pairs_.begin(), pairs_.begin() + static_cast<std::ptrdiff_t>(first));
  if (pairs_.empty()) {
    throw SourceError("TUM folder " + folder_ + ": capture.tum.first_frame " +
                      std::to_string(config_.first_frame) + " is past its last frame");
  }
  // Rejected list lines are reported as skipped frames first, so they are counted like any other
  // bad frame; then the pairs in time order.
  for (auto& message : rejected) playlist_.push_back({0, std::move(message)});
  for (std::size_t i = 0; i < pairs_.size(); ++i) playlist_.push_back({i, {}});

  ground_truth_.reset();
  if (!config_.groundtruth.empty()) {
    const std::string path = joinPath(folder_, config_.groundtruth);
    if (std::filesystem::exists(path, error)) {
      try {
        ground_truth_ = readTumTrajectory(path);
      } catch (const std::exception& e) {
        SLAMD_LOG_WARN(kComponent) << "ignoring ground truth: " << e.what();
      }
    }
  }
  position_ = 0;
  sequence_ = 0;
  gate_.reset();
  SLAMD_LOG_INFO(kComponent) << description() << ": " << rejected.size()
                             << " list lines rejected; ground truth "
                             << (ground_truth_ ? std::to_string(ground_truth_->size()) + " poses"
                                               : std::string("absent"));
}

FrameRead TumSource::next(std::chrono::milliseconds /*timeout*/) {
  if (position_ >= playlist_.size()) return FrameRead{FrameRead::Status::kEndOfStream, {}, {}};
  const PlayItem& item = playlist_[position_++];
  if (!item.message.empty()) return skipFrame(counters_, kComponent, item.message);
  return readPair(pairs_[item.pair]);
}

std::optional<Utime> TumSource::upcomingUtime(std::size_t ahead) const {
  if (position_ + ahead >= playlist_.size()) return std::nullopt;
  const PlayItem& item = playlist_[position_ + ahead];
  if (!item.message.empty()) return std::nullopt;
  return secondsToUtime(pairs_[item.pair].rgb_timestamp_s);
}

bool TumSource::dropUpcoming() {
  if (!upcomingUtime(0)) return false;
  ++position_;
  counters_.droppedBehindSchedule();
  return true;
}

FrameRead TumSource::readPair(const TumFramePair& pair) {
  const std::string rgb_path = joinPath(folder_, pair.rgb_path);
  const std::string depth_path = joinPath(folder_, pair.depth_path);
  std::vector<std::uint8_t> bytes;
  std::string error;
  if (!readFileBytes(rgb_path, bytes, error)) return skipFrame(counters_, kComponent, error);
  auto frame = std::make_shared<RgbdFrame>();
  frame->color_bgr = decodeColorImage(bytes.data(), bytes.size(), error);
  if (frame->color_bgr.empty()) return skipFrame(counters_, kComponent, rgb_path + ": " + error);
  if (!readFileBytes(depth_path, bytes, error)) return skipFrame(counters_, kComponent, error);
  const cv::Mat raw = decodeDepthImage(bytes.data(), bytes.size(), error);
  if (raw.empty()) return skipFrame(counters_, kComponent, depth_path + ": " + error);
  if (raw.size() != frame->color_bgr.size()) {
    return skipFrame(counters_, kComponent,
                     depth_path + " is " + std::to_string(raw.cols) + "x" +
                         std::to_string(raw.rows) + " but colour " + rgb_path + " is " +
                         std::to_string(frame->color_bgr.cols) + "x" +
                         std::to_string(frame->color_bgr.rows));
  }
  frame->utime = secondsToUtime(pair.rgb_timestamp_s);
  frame->depth_utime = secondsToUtime(pair.depth_timestamp_s);
  frame->sequence = sequence_++;
  frame->intrinsics = config_.camera.intrinsics;
  frame->depth_m = depthRawToMeters(raw, config_.camera.depth_scale);
  ensureGray(*frame);
  frame->received_steady_ns = steadyNowNs();
  const std::string gate_error = gate_.check(*frame, rgb_path);
  if (!gate_error.empty()) {
    return skipFrame(
        counters_, kComponent,
        gate_error + (raw.size() != cv::Size(frame->intrinsics.width, frame->intrinsics.height)
                          ? " (set camera.width/height for this dataset)"
                          : ""));
  }
  counters_.frameRead();
  return FrameRead{FrameRead::Status::kFrame, std::move(frame), {}};
}

void TumSource::close() { position_ = playlist_.size(); }

std::string TumSource::description() const {
  return "tum:" + folder_ + " (" + std::to_string(pairs_.size()) + " frames)";
}

}  // namespace slamd
