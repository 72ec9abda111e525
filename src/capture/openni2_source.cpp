#include "slamd/capture/openni2_source.hpp"

#include <OpenNI.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <sstream>
#include <thread>

#include <opencv2/imgproc.hpp>

#include "slamd/common/log.hpp"

namespace slamd {

namespace {

constexpr const char* kComponent = "capture.openni2";

// Debian's DummyDevice driver does not join its frame thread in stop(): destroying a stream right
// after stopping it lets that thread touch freed memory (a crash seen here about one run in
// three). Waiting a few frame periods lets the thread see the stop flag. A close-only cost.
void waitForDriverThreads() { std::this_thread::sleep_for(std::chrono::milliseconds(200)); }

// The same driver's frame thread sets its running flag when it starts, so a stop() that comes
// before the thread has run undoes nothing and the thread outlives its stream (seen under
// AddressSanitizer on a loaded machine, where a thread can start late). A stream that delivered
// a frame has a running thread; one that has not is given a bounded wait for its first frame.
void waitForFirstFrame(openni::VideoStream& stream) {
  openni::VideoStream* streams[1] = {&stream};
  int index = -1;
  if (openni::OpenNI::waitForAnyStream(streams, 1, &index, 1000) == openni::STATUS_OK) {
    openni::VideoFrameRef frame;
    stream.readFrame(&frame);
  }
}

// OpenNI2 is process-wide: initialised on first use, never shut down (see the header).
void ensureOpenNi() {
  static std::once_flag once;
  static std::string error;
  std::call_once(once, [] {
    if (openni::OpenNI::initialize() != openni::STATUS_OK) {
      error = std::string("OpenNI2 initialisation failed: ") + openni::OpenNI::getExtendedError();
    }
  });
  if (!error.empty()) throw SourceError(error);
}

std::string lastError() {
  const char* text = openni::OpenNI::getExtendedError();
  return (text != nullptr && *text != '\0') ? std::string(" (") + text + ")" : std::string();
}

const char* pixelFormatName(openni::PixelFormat format) {
  switch (format) {
    case openni::PIXEL_FORMAT_DEPTH_1_MM:
      return "DEPTH_1_MM";
    case openni::PIXEL_FORMAT_DEPTH_100_UM:
      return "DEPTH_100_UM";
    case openni::PIXEL_FORMAT_SHIFT_9_2:
      return "SHIFT_9_2";
    case openni::PIXEL_FORMAT_SHIFT_9_3:
      return "SHIFT_9_3";
    case openni::PIXEL_FORMAT_RGB888:
      return "RGB888";
    case openni::PIXEL_FORMAT_YUV422:
      return "YUV422";
    case openni::PIXEL_FORMAT_GRAY8:
      return "GRAY8";
    case openni::PIXEL_FORMAT_GRAY16:
      return "GRAY16";
    case openni::PIXEL_FORMAT_JPEG:
      return "JPEG";
    case openni::PIXEL_FORMAT_YUYV:
      return "YUYV";
  }
  return "unknown";
}

std::string modeText(const openni::VideoMode& mode) {
  std::ostringstream out;
  out << mode.getResolutionX() << "x" << mode.getResolutionY() << "@" << mode.getFps() << " "
      << pixelFormatName(mode.getPixelFormat());
  return out.str();
}

bool isDepthFormat(openni::PixelFormat f) {
  return f == openni::PIXEL_FORMAT_DEPTH_1_MM || f == openni::PIXEL_FORMAT_DEPTH_100_UM;
}

bool isColorFormat(openni::PixelFormat f) {
  return f == openni::PIXEL_FORMAT_RGB888 || f == openni::PIXEL_FORMAT_GRAY8;
}

// Picks the configured mode among the sensor's, preferring the wanted pixel formats; returns
// false (and lists what is offered) when no mode matches the size and rate.
bool selectMode(const openni::SensorInfo& info, int width, int height, int fps, bool depth,
                openni::VideoMode& chosen, std::string& offered) {
  const auto& modes = info.getSupportedVideoModes();
  bool found = false;
  for (int i = 0; i < modes.getSize(); ++i) {
    const openni::VideoMode& m = modes[i];
    offered += (offered.empty() ? "" : ", ") + modeText(m);
    const bool usable =
        depth ? isDepthFormat(m.getPixelFormat()) : isColorFormat(m.getPixelFormat());
    if (!found && usable && m.getResolutionX() == width && m.getResolutionY() == height &&
        m.getFps() == fps) {
      chosen = m;
      found = true;
    }
    // Prefer millimetres and RGB when several formats share the size.
    if (found && m.getResolutionX() == width && m.getResolutionY() == height && m.getFps() == fps &&
        (m.getPixelFormat() == openni::PIXEL_FORMAT_DEPTH_1_MM ||
         m.getPixelFormat() == openni::PIXEL_FORMAT_RGB888)) {
      chosen = m;
    }
  }
  return found;
}

}  // namespace

std::vector<std::string> listOpenNi2Devices() {
  ensureOpenNi();
  openni::Array<openni::DeviceInfo> devices;
  openni::OpenNI::enumerateDevices(&devices);
  std::vector<std::string> out;
  for (int i = 0; i < devices.getSize(); ++i) {
    // OpenNI lists every device it has opened, including the DummyDevice and .oni files (also
    // after the file is deleted: the OniFile driver names them "oni File").
    const std::string uri = devices[i].getUri();
    const std::string name = devices[i].getName();
    std::error_code error;
    if (uri == "Dummy" || name == "oni File" || std::filesystem::exists(uri, error)) continue;
    out.push_back(std::string(devices[i].getUri()) + " (" + devices[i].getVendor() + " " +
                  devices[i].getName() + ")");
  }
  return out;
}

void recordOni(const std::string& device_uri, const std::string& path, int frame_count) {
  ensureOpenNi();
  openni::Device device;
  if (device.open(device_uri.empty() ? openni::ANY_DEVICE : device_uri.c_str()) !=
      openni::STATUS_OK) {
    throw SourceError("cannot open OpenNI2 device '" + device_uri + "'" + lastError());
  }
  openni::VideoStream depth;
  openni::VideoStream color;
  if (depth.create(device, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
    throw SourceError("device '" + device_uri + "' has no depth sensor" + lastError());
  }
  const bool has_color = device.hasSensor(openni::SENSOR_COLOR) &&
                         color.create(device, openni::SENSOR_COLOR) == openni::STATUS_OK;
  openni::Recorder recorder;
  if (recorder.create(path.c_str()) != openni::STATUS_OK ||
      recorder.attach(depth, false) != openni::STATUS_OK ||
      (has_color && recorder.attach(color, false) != openni::STATUS_OK)) {
    throw SourceError("cannot record to " + path + lastError());
  }
  depth.start();
  if (has_color) color.start();
  recorder.start();
  int depth_frames = 0;
  int color_frames = 0;
  int waits = 0;
  while ((depth_frames < frame_count || (has_color && color_frames < frame_count)) &&
         waits < frame_count * 8) {
    ++waits;
    openni::VideoStream* streams[2] = {&depth, &color};
    int index = -1;
    if (openni::OpenNI::waitForAnyStream(streams, has_color ? 2 : 1, &index, 2000) !=
        openni::STATUS_OK) {
      break;
    }
    openni::VideoFrameRef frame;
    streams[index]->readFrame(&frame);
    (index == 0 ? depth_frames : color_frames) += 1;
  }
  // The order matters. OpenNI2's frame thread holds its stream's recorder lock while it hands a
  // frame to the recorder, which then takes its own stream lock; destroying the recorder takes
  // the two in the other order. A frame arriving during the destroy deadlocked (a hang seen once
  // in CI). So the streams are stopped, and their driver threads given time to see it, before
  // the recorder is destroyed: no frame can be in flight then.
  recorder.stop();
  depth.stop();
  if (has_color) color.stop();
  waitForDriverThreads();
  recorder.destroy();
  depth.destroy();
  if (has_color) color.destroy();
  device.close();
  if (depth_frames < frame_count) {
    throw SourceError("recording " + path + ": device delivered only " +
                      std::to_string(depth_frames) + " of " + std::to_string(frame_count) +
                      " depth frames");
  }
}

struct OpenNi2Source::Impl {
  openni::Device device;
  openni::VideoStream depth;
  openni::VideoStream color;
  bool has_color = false;
  bool opened = false;
  bool live = false;  // a device, not a recording
  // Whether each stream was started, and delivered a frame since (see waitForFirstFrame).
  bool depth_started = false;
  bool color_started = false;
  bool depth_delivered = false;
  bool color_delivered = false;
  double depth_scale = 1000.0;  // raw units per metre, from the depth pixel format
  /// Depth registered to colour, as the device (or the recording's device properties) says;
  /// unset when it cannot tell.
  std::optional<bool> depth_registered;
  int depth_frames_total = -1;  // recordings: frames in the file per stream
  int color_frames_total = -1;
  int last_depth_index = -1;
  int last_color_index = -1;
  openni::VideoFrameRef pending_depth;
  openni::VideoFrameRef pending_color;
  // Host arrival times of the pending frames, for devices whose streams do not share a clock.
  std::chrono::steady_clock::time_point pending_depth_arrival;
  std::chrono::steady_clock::time_point pending_color_arrival;
  int frames_unpaired_in_a_row = 0;
  bool pair_by_arrival = false;
  CameraIntrinsics device_intrinsics;
  // Live devices: device clock -> wall clock.
  bool clock_anchored = false;
  std::uint64_t first_device_us = 0;
  Utime first_wall_utime = 0;
  // Disconnect handling.
  std::chrono::steady_clock::time_point last_frame_time;
  bool disconnected = false;
  std::chrono::steady_clock::time_point reopen_at;
  double backoff_s = 0.0;

  void closeAll() {
    pending_depth.release();
    pending_color.release();
    const bool running = depth.isValid() || color.isValid();
    if (live && depth_started && !depth_delivered) waitForFirstFrame(depth);
    if (live && color_started && !color_delivered) waitForFirstFrame(color);
    depth_started = color_started = depth_delivered = color_delivered = false;
    frames_unpaired_in_a_row = 0;
    pair_by_arrival = false;
    if (depth.isValid()) depth.stop();
    if (color.isValid()) color.stop();
    if (running) waitForDriverThreads();
    if (depth.isValid()) depth.destroy();
    if (color.isValid()) color.destroy();
    if (opened) device.close();
    opened = false;
  }
};

OpenNi2Source::OpenNi2Source(Kind kind, std::string uri, OpenNi2Config config)
    : kind_(kind),
      uri_(std::move(uri)),
      config_(std::move(config)),
      impl_(std::make_unique<Impl>()) {}

OpenNi2Source::~OpenNi2Source() { close(); }

namespace {

// Opens device, streams and options; throws SourceError. Shared by open() and reconnects.
void openDevice(OpenNi2Source::Kind kind, const std::string& uri, const OpenNi2Config& config,
                OpenNi2Source::Impl& s);

}  // namespace

void OpenNi2Source::open() {
  ensureOpenNi();
  impl_->closeAll();
  openDevice(kind_, uri_, config_, *impl_);
  gate_.reset();
  impl_->disconnected = false;
  impl_->backoff_s = config_.reconnect_initial_s;
  SLAMD_LOG_INFO(kComponent) << "opened " << description();
}

namespace {

void openDevice(OpenNi2Source::Kind kind, const std::string& uri, const OpenNi2Config& config,
                OpenNi2Source::Impl& s) {
  const char* what = kind == OpenNi2Source::Kind::kFile ? "recording" : "device";
  const char* open_uri = uri.empty() ? openni::ANY_DEVICE : uri.c_str();
  if (s.device.open(open_uri) != openni::STATUS_OK) {
    std::string hint;
    if (kind == OpenNi2Source::Kind::kDevice) {
      const auto devices = listOpenNi2Devices();
      hint = devices.empty() ? "; no OpenNI2 device is attached (check USB and udev permissions)"
                             : "; attached: " + devices.front();
    }
    throw SourceError(std::string("cannot open OpenNI2 ") + what + " '" +
                      (uri.empty() ? "first device" : uri) + "'" + lastError() + hint);
  }
  s.opened = true;
  s.live = kind == OpenNi2Source::Kind::kDevice;
  if (s.depth.create(s.device, openni::SENSOR_DEPTH) != openni::STATUS_OK) {
    s.closeAll();
    throw SourceError(std::string("OpenNI2 ") + what + " '" + uri + "' has no depth stream" +
                      lastError());
  }
  s.has_color = config.color && s.device.hasSensor(openni::SENSOR_COLOR) &&
                s.color.create(s.device, openni::SENSOR_COLOR) == openni::STATUS_OK;

  if (kind == OpenNi2Source::Kind::kDevice) {
    openni::VideoMode mode;
    std::string offered;
    if (selectMode(*s.device.getSensorInfo(openni::SENSOR_DEPTH), config.width, config.height,
                   config.fps, true, mode, offered)) {
      s.depth.setVideoMode(mode);
    } else {
      SLAMD_LOG_WARN(kComponent) << "depth mode " << config.width << "x" << config.height << "@"
                                 << config.fps << " not offered (" << offered << "); using "
                                 << modeText(s.depth.getVideoMode());
    }
    if (s.has_color) {
      offered.clear();
      if (selectMode(*s.device.getSensorInfo(openni::SENSOR_COLOR), config.width, config.height,
                     config.fps, false, mode, offered)) {
        s.color.setVideoMode(mode);
      } else {
        SLAMD_LOG_WARN(kComponent)
            << "colour mode " << config.width << "x" << config.height << "@" << config.fps
            << " not offered (" << offered << "); using " << modeText(s.color.getVideoMode());
      }
    }
    if (s.has_color && config.registration) {
      if (s.device.isImageRegistrationModeSupported(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR)) {
        if (s.device.setImageRegistrationMode(openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR) !=
            openni::STATUS_OK) {
          SLAMD_LOG_WARN(kComponent) << "depth-to-colour registration failed" << lastError();
        }
      } else {
        SLAMD_LOG_WARN(kComponent) << "device does not register depth to colour: depth and "
                                      "colour pixels will not line up exactly";
      }
    }
    if (s.has_color && config.sync &&
        s.device.setDepthColorSyncEnabled(true) != openni::STATUS_OK) {
      SLAMD_LOG_WARN(kComponent) << "depth/colour frame sync not supported; pairing by timestamp";
    }
    if (s.depth.setMirroringEnabled(false) != openni::STATUS_OK ||
        (s.has_color && s.color.setMirroringEnabled(false) != openni::STATUS_OK)) {
      SLAMD_LOG_DEBUG(kComponent) << "mirroring cannot be switched (device default kept)";
    }
  } else {
    openni::PlaybackControl* playback = s.device.getPlaybackControl();
    if (playback != nullptr) {
      playback->setRepeatEnabled(false);
      // -1: manual, a new frame only when the previous one was read (nothing lost).
      playback->setSpeed(config.oni_realtime ? static_cast<float>(config.oni_speed) : -1.0f);
      s.depth_frames_total = playback->getNumberOfFrames(s.depth);
      s.color_frames_total = s.has_color ? playback->getNumberOfFrames(s.color) : -1;
    }
  }

  const openni::PixelFormat depth_format = s.depth.getVideoMode().getPixelFormat();
  if (!isDepthFormat(depth_format)) {
    s.closeAll();
    throw SourceError(std::string("OpenNI2 ") + what + " '" + uri + "' depth format " +
                      pixelFormatName(depth_format) + " is not supported (DEPTH_1_MM or " +
                      "DEPTH_100_UM)");
  }
  s.depth_scale = depth_format == openni::PIXEL_FORMAT_DEPTH_100_UM ? 10000.0 : 1000.0;

  s.depth_started = s.depth.start() == openni::STATUS_OK;
  if (!s.depth_started) {
    s.closeAll();
    throw SourceError(std::string("cannot start depth stream of '") + uri + "'" + lastError());
  }
  s.color_started = s.has_color && s.color.start() == openni::STATUS_OK;
  if (s.has_color && !s.color_started) {
    SLAMD_LOG_WARN(kComponent) << "colour stream failed to start" << lastError() << "; depth only";
    s.color.destroy();
    s.has_color = false;
  }

  const openni::VideoMode mode = s.depth.getVideoMode();
  CameraIntrinsics& k = s.device_intrinsics;
  k = config.camera.intrinsics;
  const float hfov =
      s.has_color ? s.color.getHorizontalFieldOfView() : s.depth.getHorizontalFieldOfView();
  const float vfov =
      s.has_color ? s.color.getVerticalFieldOfView() : s.depth.getVerticalFieldOfView();
  if (config.intrinsics_from_device && hfov > 0.0f && vfov > 0.0f) {
    k.width = mode.getResolutionX();
    k.height = mode.getResolutionY();
    k.fx = k.width / (2.0 * std::tan(static_cast<double>(hfov) / 2.0));
    k.fy = k.height / (2.0 * std::tan(static_cast<double>(vfov) / 2.0));
    k.cx = (k.width - 1) / 2.0;
    k.cy = (k.height - 1) / 2.0;
    k.distortion_model = DistortionModel::kNone;
    k.distortion = {};
  } else if (mode.getResolutionX() != k.width || mode.getResolutionY() != k.height) {
    k = k.scaled(mode.getResolutionX(), mode.getResolutionY());
  }
  s.depth_registered.reset();
  openni::ImageRegistrationMode registration = openni::IMAGE_REGISTRATION_OFF;
  if (s.has_color && s.device.getProperty(openni::DEVICE_PROPERTY_IMAGE_REGISTRATION,
                                          &registration) == openni::STATUS_OK) {
    s.depth_registered = registration == openni::IMAGE_REGISTRATION_DEPTH_TO_COLOR;
  }
  if (kind == OpenNi2Source::Kind::kFile) {
    SLAMD_LOG_INFO(kComponent) << "recording " << uri << ": " << s.depth_frames_total
                               << " depth and " << s.color_frames_total
                               << " colour frames; depth registered to colour: "
                               << (!s.depth_registered   ? "not recorded"
                                   : *s.depth_registered ? "yes"
                                                         : "no");
  }
  s.last_depth_index = -1;
  s.last_color_index = -1;
  s.clock_anchored = false;
  s.last_frame_time = std::chrono::steady_clock::now();
}

}  // namespace

std::optional<CameraIntrinsics> OpenNi2Source::intrinsics() const {
  if (!impl_->opened) return std::nullopt;
  return impl_->device_intrinsics;
}

int OpenNi2Source::recordedDepthFrames() const { return impl_->depth_frames_total; }

int OpenNi2Source::recordedColorFrames() const { return impl_->color_frames_total; }

std::optional<bool> OpenNi2Source::depthRegisteredToColor() const {
  return impl_->depth_registered;
}

void OpenNi2Source::close() {
  if (impl_) impl_->closeAll();
}

std::string OpenNi2Source::description() const {
  if (kind_ == Kind::kFile) return "oni:" + uri_;
  return "openni2:" + (uri_.empty() ? std::string("first device") : uri_);
}

// next() waits for a depth frame and its colour partner (reopening a disconnected device first),
// then converts the pair. Each step below is one part of that.

std::optional<FrameRead> OpenNi2Source::reopenIfDisconnected(SteadyTime deadline) {
  Impl& s = *impl_;
  if (!s.disconnected) return std::nullopt;
  const FrameRead timed_out{FrameRead::Status::kTimeout, {}, {}};
  if (std::chrono::steady_clock::now() < s.reopen_at) {
    // Backoff wait (bounded by the caller's timeout), not synchronisation.
    std::this_thread::sleep_until(std::min(s.reopen_at, deadline));
    return timed_out;
  }
  try {
    openDevice(kind_, uri_, config_, s);
    s.disconnected = false;
    s.backoff_s = config_.reconnect_initial_s;
    counters_.reconnected();
    SLAMD_LOG_INFO(kComponent) << "reopened " << description();
    return std::nullopt;
  } catch (const SourceError& e) {
    s.backoff_s = std::min(s.backoff_s * 2.0, config_.reconnect_max_s);
    s.reopen_at = std::chrono::steady_clock::now() +
                  std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                      std::chrono::duration<double>(s.backoff_s));
    counters_.failure(kComponent, std::string("reconnect failed: ") + e.what() +
                                      "; next attempt in " + std::to_string(s.backoff_s) + " s");
    return timed_out;
  }
}

bool OpenNi2Source::reachedEndOfRecording() const {
  const Impl& s = *impl_;
  if (kind_ != Kind::kFile || s.depth_frames_total < 0) return false;
  const bool depth_done = s.last_depth_index >= s.depth_frames_total;
  const bool color_done = !s.has_color || s.last_color_index >= s.color_frames_total;
  // A depth frame still pending here has no colour partner left to come (a pending pair would
  // have been delivered or split already): endOfRecording() counts it.
  return depth_done && color_done;
}

FrameRead OpenNi2Source::endOfRecording() {
  // In real-time playback the player may hand the last colour image to an earlier depth frame
  // (the PrimeSense file's two frames are 0.4 ms apart); the last depth frame then never gets a
  // partner. It is counted, not lost silently, and only once: reading on gives the end again.
  Impl& s = *impl_;
  if (s.pending_depth.isValid()) {
    s.pending_depth.release();
    countLostDepthFrame();
  }
  return FrameRead{FrameRead::Status::kEndOfStream, {}, {}};
}

FrameRead OpenNi2Source::declareStalled(SteadyTime now) {
  // A recording that stops delivering has ended; a device has gone: close it and reopen later.
  if (kind_ == Kind::kFile) return endOfRecording();
  Impl& s = *impl_;
  s.closeAll();
  s.disconnected = true;
  s.reopen_at = now + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                          std::chrono::duration<double>(s.backoff_s));
  counters_.failure(kComponent, description() + ": no frame for " +
                                    std::to_string(config_.frame_timeout_s) +
                                    " s, device disconnected; reopening");
  return FrameRead{FrameRead::Status::kTimeout, {}, {}};
}

void OpenNi2Source::countLostDepthFrame() {
  // A depth frame that will never be delivered: in real-time playback the reader was behind, on
  // a device depth and colour lost sync. A colour image alone is not a frame.
  if (kind_ == Kind::kFile && config_.oni_realtime) {
    counters_.droppedBehindSchedule();
  } else {
    counters_.dropped();
  }
}

bool OpenNi2Source::pendingFramesArePaired() {
  Impl& s = *impl_;
  if (!s.pending_depth.isValid() || (s.has_color && !s.pending_color.isValid())) return false;
  if (!s.has_color) return true;
  // With sync on, the two frames carry (nearly) the same device timestamp. A live device whose
  // streams keep their own clocks (the DummyDevice numbers each stream's frames, and its two
  // threads fall a frame apart on a loaded machine) would never pair again: after two seconds'
  // worth of frames without a partner, pair by host arrival time instead.
  const int fps = std::max(1, s.depth.getVideoMode().getFps());
  const auto half_period_us = static_cast<std::int64_t>(500000 / fps);
  const std::int64_t depth_after_color_us =
      s.pair_by_arrival ? std::chrono::duration_cast<std::chrono::microseconds>(
                              s.pending_depth_arrival - s.pending_color_arrival)
                              .count()
                        : static_cast<std::int64_t>(s.pending_depth.getTimestamp()) -
                              static_cast<std::int64_t>(s.pending_color.getTimestamp());
  if (std::llabs(depth_after_color_us) <= half_period_us) {
    s.frames_unpaired_in_a_row = 0;
    return true;
  }
  // The older one has no partner any more: drop it and wait for the next.
  if (depth_after_color_us < 0) {
    s.pending_depth.release();
    countLostDepthFrame();
  } else {
    s.pending_color.release();
  }
  if (kind_ == Kind::kDevice && !s.pair_by_arrival && ++s.frames_unpaired_in_a_row >= 2 * fps) {
    s.pair_by_arrival = true;
    counters_.failure(kComponent, description() + ": " + std::to_string(2 * fps) +
                                      " frames in a row found no partner with their device " +
                                      "timestamp; pairing depth and colour by arrival time");
  }
  return false;
}

FrameRead OpenNi2Source::frameFromPendingPair() {
  Impl& s = *impl_;
  openni::VideoFrameRef depth_frame = s.pending_depth;
  openni::VideoFrameRef color_frame = s.pending_color;
  s.pending_depth.release();
  s.pending_color.release();

  const std::string what = description() + " frame " + std::to_string(depth_frame.getFrameIndex());
  const int width = depth_frame.getWidth();
  const int height = depth_frame.getHeight();
  if (width <= 0 || height <= 0 || depth_frame.getStrideInBytes() < width * 2 ||
      depth_frame.getDataSize() < depth_frame.getStrideInBytes() * height) {
    return skipFrame(counters_, kComponent, what + ": depth buffer inconsistent with its size");
  }
  auto out = std::make_shared<RgbdFrame>();
  const cv::Mat raw(height, width, CV_16UC1, const_cast<void*>(depth_frame.getData()),
                    static_cast<std::size_t>(depth_frame.getStrideInBytes()));
  out->depth_m = depthRawToMeters(raw, s.depth_scale);
  if (s.has_color) {
    const openni::PixelFormat format = color_frame.getVideoMode().getPixelFormat();
    if (color_frame.getWidth() != width || color_frame.getHeight() != height) {
      return skipFrame(counters_, kComponent,
                       what + ": colour is " + std::to_string(color_frame.getWidth()) + "x" +
                           std::to_string(color_frame.getHeight()) + ", depth is " +
                           std::to_string(width) + "x" + std::to_string(height));
    }
    const int channels = format == openni::PIXEL_FORMAT_RGB888 ? 3 : 1;
    if (!isColorFormat(format) || color_frame.getStrideInBytes() < width * channels ||
        color_frame.getDataSize() < color_frame.getStrideInBytes() * height) {
      return skipFrame(counters_, kComponent,
                       what + ": colour format " + pixelFormatName(format) +
                           " or buffer not supported (RGB888 or GRAY8)");
    }
    const cv::Mat color(height, width, channels == 3 ? CV_8UC3 : CV_8UC1,
                        const_cast<void*>(color_frame.getData()),
                        static_cast<std::size_t>(color_frame.getStrideInBytes()));
    cv::cvtColor(color, out->color_bgr, channels == 3 ? cv::COLOR_RGB2BGR : cv::COLOR_GRAY2BGR);
    ensureGray(*out);
  }
  const auto depth_device_us = static_cast<std::uint64_t>(depth_frame.getTimestamp());
  if (kind_ != Kind::kFile && (!s.clock_anchored || depth_device_us < s.first_device_us)) {
    s.clock_anchored = true;
    s.first_device_us = depth_device_us;
    s.first_wall_utime = wallClockUtime();
  }
  // Recordings keep the device clock; a live device is anchored to the host's wall clock.
  auto toUtime = [&](std::uint64_t device_us) {
    if (kind_ == Kind::kFile) return static_cast<Utime>(device_us);
    return s.first_wall_utime + static_cast<Utime>(device_us) -
           static_cast<Utime>(s.first_device_us);
  };
  out->utime = toUtime(depth_device_us);
  // Streams without hardware sync (a Kinect v1) stamp colour and depth apart: utime is the
  // colour image's, and tracking moves the depths to it.
  if (s.has_color && !s.pair_by_arrival) {
    const auto color_device_us = static_cast<std::uint64_t>(color_frame.getTimestamp());
    if (color_device_us != depth_device_us) {
      out->depth_utime = out->utime;
      out->utime = toUtime(color_device_us);
    }
  }
  out->sequence = depth_frame.getFrameIndex();
  out->intrinsics = s.device_intrinsics;
  if (out->intrinsics.width != width || out->intrinsics.height != height) {
    out->intrinsics = out->intrinsics.scaled(width, height);
  }
  out->received_steady_ns = steadyNowNs();
  const std::string error = gate_.check(*out, what);
  if (!error.empty()) return skipFrame(counters_, kComponent, error);
  counters_.frameRead();
  return FrameRead{FrameRead::Status::kFrame, std::move(out), {}};
}

FrameRead OpenNi2Source::next(std::chrono::milliseconds timeout) {
  Impl& s = *impl_;
  const SteadyTime deadline = std::chrono::steady_clock::now() + timeout;
  if (auto waiting = reopenIfDisconnected(deadline)) return *waiting;

  const auto frame_timeout = std::chrono::duration_cast<std::chrono::steady_clock::duration>(
      std::chrono::duration<double>(config_.frame_timeout_s));
  while (true) {
    if (reachedEndOfRecording()) return endOfRecording();
    const auto now = std::chrono::steady_clock::now();
    if (now - s.last_frame_time > frame_timeout) return declareStalled(now);
    if (now >= deadline) return FrameRead{FrameRead::Status::kTimeout, {}, {}};
    const auto remaining_ms = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - now);
    const auto until_stall_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
        s.last_frame_time + frame_timeout - now);
    const int wait_ms = static_cast<int>(
        std::max<std::int64_t>(1, std::min(remaining_ms.count(), until_stall_ms.count() + 1)));
    openni::VideoStream* streams[2] = {&s.depth, &s.color};
    int index = -1;
    const openni::Status status =
        openni::OpenNI::waitForAnyStream(streams, s.has_color ? 2 : 1, &index, wait_ms);
    if (status == openni::STATUS_TIME_OUT) continue;
    if (status != openni::STATUS_OK || index < 0) {
      if (kind_ == Kind::kFile) return endOfRecording();
      // Treated like a stall: the next pass finds last_frame_time too old unless a frame comes.
      std::this_thread::sleep_until(std::min(deadline, now + std::chrono::milliseconds(5)));
      continue;
    }
    openni::VideoFrameRef frame;
    if (streams[index]->readFrame(&frame) != openni::STATUS_OK || !frame.isValid()) continue;
    s.last_frame_time = std::chrono::steady_clock::now();
    (index == 0 ? s.depth_delivered : s.color_delivered) = true;
    if (index == 0) {
      if (s.pending_depth.isValid()) countLostDepthFrame();  // replaced before its colour came
      if (kind_ == Kind::kFile && config_.oni_realtime) {
        // OpenNI's real-time player replaces a frame nobody read by the next one: count the gap
        // (recorded frame indices start at 1).
        for (int missed = std::max(s.last_depth_index, 0) + 1; missed < frame.getFrameIndex();
             ++missed) {
          counters_.droppedBehindSchedule();
        }
      }
      s.last_depth_index = frame.getFrameIndex();
      s.pending_depth = frame;
      s.pending_depth_arrival = s.last_frame_time;
    } else {
      s.last_color_index = frame.getFrameIndex();
      s.pending_color = frame;
      s.pending_color_arrival = s.last_frame_time;
    }
    if (pendingFramesArePaired()) return frameFromPendingPair();
  }
}

}  // namespace slamd
