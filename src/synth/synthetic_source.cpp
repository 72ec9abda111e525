#include "slamd/synth/synthetic_source.hpp"

#include <algorithm>
#include <climits>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "slamd/common/config.hpp"
#include "slamd/synth/variety.hpp"

namespace slamd {

namespace {

const EnumNames<std::string> kTrajectoryNames = {
    {"auto", "auto", "zigzag in the corridor, loop in corridor_loop, random elsewhere"},
    {"zigzag", "zigzag", "walk along the corridor, swaying"},
    {"random", "random", "smooth random motion"},
    {"robot", "robot", "a low robot driving the path"},
    {"loop", "loop", "walk around the ring corridor"},
};

}  // namespace

const ConfigSchema<SyntheticConfig>& SyntheticConfig::schema() {
  using C = SyntheticConfig;
  static const auto table =
      ConfigSchema<C>("synthetic")
          .choice("trajectory", &C::trajectory, kTrajectoryNames, "camera path")
          .number("frames", &C::frames, 0, 10'000'000, "frames",
                  "0 = natural length of the trajectory")
          .number("seed", &C::seed, 0, INT_MAX, "", "scene, motion and sensor noise seed")
          .number("start_time_s", &C::start_time_s, 0.0, 4.0e9, "s", "first frame's timestamp")
          .flag("variety", &C::variety,
                "draw the world's look and the walk from the seed (evaluation worlds); replaces "
                "the configured corridor_width_m, texture_density, doors, posters, floor/wall "
                "tiles, gloss, lamps, walk speed, zigzag, look-around and exposure variation")
          .number("blackout_start_s", &C::blackout_start_s, 0.0, 1.0e6, "s",
                  "from the first frame: frames from here on come out covered (black, no depth)")
          .number("blackout_duration_s", &C::blackout_duration_s, 0.0, 1.0e6, "s",
                  "length of the blackout; 0 = none");
  return table;
}

SyntheticConfig SyntheticConfig::load(Config& config) {
  SyntheticConfig out;
  schema().load(config, out);
  out.scene = synth::SceneParams::load(config);
  out.motion = synth::MotionParams::load(config);
  out.sensor = synth::SensorParams::load(config);
  out.camera = CameraConfig::load(config, 5000.0);
  if (out.variety) {
    out.variety_drawn = synth::applyVariety(out.seed, out.scene, out.motion, out.sensor);
  }
  if (out.camera.intrinsics.distortion_model != DistortionModel::kNone) {
    throw ConfigError(
        "camera.distortion_model = plumb_bob: synthetic worlds render an ideal pinhole camera "
        "(allowed: none)");
  }
  return out;
}

SyntheticSource::SyntheticSource(const std::string& scene_name, const SyntheticConfig& config)
    : scene_name_(scene_name), config_(config), sensor_(config.sensor) {
  try {
    scene_ =
        std::make_unique<synth::Scene>(synth::makeScene(scene_name, config_.scene, config_.seed));
  } catch (const std::invalid_argument& error) {
    throw SourceError(std::string("synthetic source: ") + error.what());
  }
  const synth::MotionKind kind = config_.trajectory == "auto"
                                     ? synth::defaultMotionFor(scene_name)
                                     : synth::parseMotionKind(config_.trajectory);
  renderer_ = std::make_unique<synth::Renderer>(*scene_, config_.camera.intrinsics);
  motion_ = std::make_unique<synth::CameraMotion>(*scene_, kind, config_.motion, config_.seed);
  frame_count_ = config_.frames > 0 ? config_.frames : motion_->naturalFrameCount();
  start_utime_ = secondsToUtime(config_.start_time_s);
  ground_truth_ =
      synth::sampleTrajectory(*motion_, frame_count_, start_utime_, config_.motion.rate_hz);
}

void SyntheticSource::open() {
  position_ = 0;
  open_ = true;
}

void SyntheticSource::close() { open_ = false; }

std::string SyntheticSource::description() const {
  std::ostringstream out;
  out << "synthetic:" << scene_name_ << " (" << synth::motionKindName(motion_->kind()) << ", "
      << frame_count_ << " frames, seed " << config_.seed << ")";
  if (config_.variety) out << " variety: " << config_.variety_drawn;
  return out.str();
}

void SyntheticSource::renderExact(int index, synth::RenderOutput& out) const {
  renderer_->render(ground_truth_.at(static_cast<std::size_t>(index)).T_world_camera, out);
}

RgbdFramePtr SyntheticSource::renderFrame(int index) const {
  if (index < 0 || index >= frame_count_) {
    throw std::out_of_range("synthetic frame " + std::to_string(index) + " outside [0, " +
                            std::to_string(frame_count_) + ")");
  }
  const Utime utime = synth::frameUtime(start_utime_, index, config_.motion.rate_hz);
  const double t_s = utimeToSeconds(utime - start_utime_);
  synth::RenderOutput render;
  renderExact(index, render);

  cv::Mat color = render.color_bgr;
  const synth::SensorParams& sensor = config_.sensor;
  if (sensor.motion_blur) {
    // Motion blur: the colour camera integrates light over its shutter time, centred on the
    // frame's timestamp (the ground-truth pose is the pose at mid-exposure, as for a camera whose
    // timestamps mark the middle of the exposure); average renders at evenly spaced instants
    // across it. An exposure that ended at the timestamp would put the image's mean pose half an
    // exposure before its ground truth: on the zigzag corridor walk (yaw rates near 30 deg/s)
    // that is a 0.17 deg yaw error no estimator could remove.
    cv::Mat sum(render.color_bgr.size(), CV_32FC3, cv::Scalar::all(0));
    synth::RenderOutput sub;
    for (int k = 0; k < sensor.blur_samples; ++k) {
      const double offset_s =
          sensor.exposure_time_s * (static_cast<double>(k) / (sensor.blur_samples - 1) - 0.5);
      if (2 * k + 1 == sensor.blur_samples) {
        cv::accumulate(render.color_bgr, sum);  // the middle instant is the frame's own render
        continue;
      }
      renderer_->render(motion_->poseAt(std::max(0.0, t_s + offset_s)), sub);
      cv::accumulate(sub.color_bgr, sum);
    }
    sum.convertTo(color, CV_8UC3, 1.0 / sensor.blur_samples);
  }

  auto frame = std::make_shared<RgbdFrame>();
  frame->utime = utime;
  frame->sequence = index;
  frame->frame_id = "camera";
  frame->intrinsics = config_.camera.intrinsics;
  frame->depth_m = sensor_.measureDepth(render, config_.seed, index);
  sensor_.measureColor(color, config_.seed, index, sensor_.exposureGain(config_.seed, t_s),
                       frame->color_bgr);
  ensureGray(*frame);
  if (t_s >= config_.blackout_start_s &&
      t_s < config_.blackout_start_s + config_.blackout_duration_s) {
    frame->color_bgr.setTo(cv::Scalar::all(0));
    frame->gray.setTo(cv::Scalar::all(0));
    frame->depth_m.setTo(std::numeric_limits<float>::quiet_NaN());
  }
  frame->received_steady_ns = steadyNowNs();
  return frame;
}

FrameRead SyntheticSource::next(std::chrono::milliseconds /*timeout*/) {
  FrameRead read;
  if (!open_ || position_ >= frame_count_) {
    read.status = FrameRead::Status::kEndOfStream;
    return read;
  }
  read.frame = renderFrame(position_++);
  read.status = FrameRead::Status::kFrame;
  counters_.frameRead();
  return read;
}

std::optional<Utime> SyntheticSource::upcomingUtime(std::size_t ahead) const {
  const std::size_t index = static_cast<std::size_t>(position_) + ahead;
  if (!open_ || index >= static_cast<std::size_t>(frame_count_)) return std::nullopt;
  return synth::frameUtime(start_utime_, static_cast<int>(index), config_.motion.rate_hz);
}

bool SyntheticSource::dropUpcoming() {
  if (!upcomingUtime(0)) return false;
  ++position_;
  counters_.droppedBehindSchedule();
  return true;
}

std::unique_ptr<FrameSource> createSyntheticSource(const std::string& scene, Config& config) {
  const SyntheticConfig synthetic = SyntheticConfig::load(config);
  return std::make_unique<SyntheticSource>(scene, synthetic);
}

}  // namespace slamd
