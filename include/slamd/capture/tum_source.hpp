#pragma once
// TumSource: frames from a TUM RGB-D benchmark folder (`tum:DIR`).
//
//   Config config = Config::fromFile("config/tum_fr1.yaml");
//   TumSource source("/data/rgbd_dataset_freiburg1_xyz", TumSourceConfig::load(config));
//   source.open();                               // throws SourceError (missing folder, lists)
//   while ((read = source.next(timeout)).status != FrameRead::Status::kEndOfStream) ...
//   Trajectory gt = *source.groundTruth();       // when groundtruth.txt is present
//
// The folder holds rgb.txt and depth.txt (or an associations file given by
// capture.tum.associations), the listed images (colour PNG or JPEG, depth 16-bit PNG) and
// optionally groundtruth.txt. Colour and depth are paired as associate.py does (nearest
// timestamp, at most capture.tum.max_difference_s apart). Each frame's utime is its colour
// timestamp; depth_m = raw / camera.depth_scale (default 5000), NaN where raw is 0.
// Intrinsics come from camera.* (the images carry none).
//
// Not live: next() returns as fast as images decode (wrap in PacedSource for real time).
// An unreadable, truncated or inconsistent image skips that frame (kSkipped, counted, message
// naming the file). One thread owns the source.

#include <optional>
#include <string>
#include <vector>

#include "slamd/capture/camera_config.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/capture/source_support.hpp"
#include "slamd/capture/tum_dataset.hpp"

namespace slamd {

/// Keys `capture.tum.*` (type, default, range, unit and doc of each: its row in tum_source.cpp,
/// or `slamd --describe-config capture`) and camera.* (depth_scale default 5000).
struct TumSourceConfig {
  CameraConfig camera;
  double max_difference_s = 0.02;
  double time_offset_s = 0.0;
  std::string associations;
  std::string groundtruth = "groundtruth.txt";
  int first_frame = 0;  ///< frames (associated pairs) before this one are not played
  int frame_count = 0;  ///< at most this many frames are played; 0 = to the end

  static const ConfigSchema<TumSourceConfig>& schema();
  static TumSourceConfig load(Config& config);
};

class TumSource : public FrameSource {
 public:
  TumSource(std::string folder, TumSourceConfig config);

  void open() override;
  FrameRead next(std::chrono::milliseconds timeout) override;
  void close() override;
  FrameSourceStats stats() const override { return counters_.snapshot(); }
  std::string description() const override;
  bool isLive() const override { return false; }
  std::optional<CameraIntrinsics> intrinsics() const override { return config_.camera.intrinsics; }
  std::optional<Trajectory> groundTruth() const override { return ground_truth_; }
  std::optional<Utime> upcomingUtime(std::size_t ahead) const override;
  bool dropUpcoming() override;

  /// The associated pairs in playback order (after open()).
  const std::vector<TumFramePair>& pairs() const { return pairs_; }

 private:
  struct PlayItem {
    std::size_t pair = 0;  ///< index into pairs_ when message is empty
    std::string message;   ///< a list line rejected at open(), reported as a skip
  };

  FrameRead readPair(const TumFramePair& pair);

  std::string folder_;
  TumSourceConfig config_;
  std::vector<TumFramePair> pairs_;
  std::vector<PlayItem> playlist_;
  std::size_t position_ = 0;
  std::int64_t sequence_ = 0;
  std::optional<Trajectory> ground_truth_;
  SourceCounters counters_;
  FrameGate gate_;
};

}  // namespace slamd
