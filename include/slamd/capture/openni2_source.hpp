#pragma once
// OpenNi2Source: frames from an OpenNI2 device (`openni2` or `openni2:URI`, e.g. a Kinect v1 or
// an Asus Xtion) or from an .oni recording (`oni:FILE`).
//
//   OpenNi2Source camera(OpenNi2Source::Kind::kDevice, "", OpenNi2Config::load(config));
//   camera.open();            // throws SourceError: no device, no depth sensor, ...
//   FrameRead read = camera.next(100ms);
//
// Device: the first device (empty URI) or the named one; depth and colour streams in the
// configured mode (default 640x480 at 30 Hz; when the device lacks it, its default mode is used
// and a warning lists the modes it offers); depth registered to colour and frame sync enabled
// where the device supports them; mirroring off; depth in millimetres (or 100 um units, scaled
// accordingly). Colour and depth frames are paired by timestamp (at most half a frame period
// apart); a device without a colour sensor gives depth-only frames. Frame utime: the device
// clock anchored to the wall clock at the first frame, so frame spacing is the device's.
// A device that delivers no frame for capture.openni2.frame_timeout_s, or whose wait fails, is
// reported disconnected, closed and reopened with exponential backoff (counted in
// stats().reconnects); next() keeps returning kTimeout meanwhile and never blocks longer than its
// timeout.
//
// Recording: played once (no repeat), as fast as frames are read (OpenNI's manual speed) or in
// real time (capture.oni.realtime, or capture.pacing.mode = realtime): then OpenNI's player runs
// on the recorded clock like a camera, a reader that falls behind gets the newest frame, and the
// frames it never read are counted as dropped behind schedule (gaps in the frame index). The end
// of the file is kEndOfStream. Frame utime is the
// recorded device timestamp (microseconds from the recording's start), so replays are
// reproducible.
//
// Intrinsics: from camera.* (scaled when the stream size differs from camera.width/height), or
// from the device's fields of view when capture.openni2.intrinsics = device.
//
// OpenNI2 is initialised once per process and never shut down: Debian's DummyDevice driver
// crashes in OpenNI::shutdown(), and drivers are process-wide anyway. One owner thread.

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "slamd/capture/camera_config.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/capture/source_support.hpp"

namespace slamd {

/// Keys `capture.openni2.*` and `capture.oni.*` (type, default, range, unit and doc of each: its
/// row in openni2_config.cpp, or `slamd --describe-config capture`) and camera.*.
struct OpenNi2Config {
  CameraConfig camera;  ///< depth_scale comes from the pixel format
  bool intrinsics_from_device = false;
  int width = 640;
  int height = 480;
  int fps = 30;
  bool registration = true;
  bool sync = true;
  bool color = true;
  double frame_timeout_s = 2.0;
  double reconnect_initial_s = 0.5;
  double reconnect_max_s = 8.0;
  bool oni_realtime = false;
  /// Real-time playback speed (OpenNI's player), set from capture.pacing.speed when slamd's
  /// pacing is realtime (createFrameSource); 1 = as recorded.
  double oni_speed = 1.0;

  static const ConfigSchema<OpenNi2Config>& schema();
  static OpenNi2Config load(Config& config);
};

/// OpenNI2 hardware currently attached, as "URI (vendor name)" (not the DummyDevice or files).
std::vector<std::string> listOpenNi2Devices();

/// Writes an .oni recording of `frame_count` frame pairs from an OpenNI2 device (used by tests
/// with the DummyDevice, and by tools). Throws SourceError.
void recordOni(const std::string& device_uri, const std::string& path, int frame_count);

class OpenNi2Source : public FrameSource {
 public:
  enum class Kind { kDevice, kFile };

  OpenNi2Source(Kind kind, std::string uri, OpenNi2Config config);
  ~OpenNi2Source() override;
  OpenNi2Source(const OpenNi2Source&) = delete;
  OpenNi2Source& operator=(const OpenNi2Source&) = delete;

  void open() override;
  FrameRead next(std::chrono::milliseconds timeout) override;
  void close() override;
  FrameSourceStats stats() const override { return counters_.snapshot(); }
  std::string description() const override;
  /// Devices, and recordings played in real time: both run on their own clock.
  bool isLive() const override { return kind_ == Kind::kDevice || config_.oni_realtime; }
  std::optional<CameraIntrinsics> intrinsics() const override;

  /// Recordings: depth (colour) frames the file holds (from its index), after open(); -1 for
  /// devices and for a recording without that stream.
  int recordedDepthFrames() const;
  int recordedColorFrames() const;
  /// After open(): whether depth is registered to colour (a device's mode after configuration, a
  /// recording's recorded device property); nullopt without colour or when it cannot tell.
  std::optional<bool> depthRegisteredToColor() const;

  struct Impl;  ///< opaque: OpenNI2 types stay out of this header

 private:
  using SteadyTime = std::chrono::steady_clock::time_point;
  // The steps of next().
  /// Nothing when the device is open (or was reopened now); a timeout while it stays closed.
  std::optional<FrameRead> reopenIfDisconnected(SteadyTime deadline);
  bool reachedEndOfRecording() const;
  /// The end of a recording: a depth frame still waiting for colour is counted as lost.
  FrameRead endOfRecording();
  FrameRead declareStalled(SteadyTime now);
  void countLostDepthFrame();
  /// Whether the pending depth frame has its colour partner (dropping an unpaired older one).
  bool pendingFramesArePaired();
  FrameRead frameFromPendingPair();

  Kind kind_;
  std::string uri_;
  OpenNi2Config config_;
  std::unique_ptr<Impl> impl_;
  SourceCounters counters_;
  FrameGate gate_;
};

}  // namespace slamd
