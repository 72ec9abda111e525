#pragma once
// SyntheticSource: RGB-D frames rendered from slamd's own worlds with exact ground truth
// (`synthetic:corridor`, `synthetic:corridor_loop`, `synthetic:room`).
//
// Usage:
//   Config config = Config::fromFile("config/synthetic.yaml");
//   std::unique_ptr<FrameSource> source = createSyntheticSource("corridor", config);
//   reportConfig(config, "program");
//   source->open();
//   while ((read = source->next(timeout)).status == FrameRead::Status::kFrame) use(read.frame);
//   Trajectory gt = *source->groundTruth();   // T_world_camera per frame, same timestamps
//
// Configuration (`synthetic.*`, intrinsics and depth scale from `camera.*` via CameraConfig):
//   synthetic.trajectory   auto | zigzag | random | robot | loop      auto (corridor: zigzag,
//                          corridor_loop: loop, room: random)
//   synthetic.frames       frame count, 0 = the trajectory's natural length (see motion.hpp)
//   synthetic.seed         0..2^31-1: scene textures, layout, motion jitter and sensor noise
//   synthetic.variety      true: draw the look of the world and the walk from the seed too
//                          (synth/variety.hpp); the drawn values replace configured ones
//   synthetic.start_time_s timestamp of frame 0, seconds since the Unix epoch   1.6e9
//   synthetic.texture_density, doors, posters, corridor_*, loop_*   see SceneParams
//   synthetic.rate_hz, walk_speed_mps, zigzag_*, robot_*, ...       see MotionParams
//   synthetic.sensor.*     Kinect v1 model; synthetic.sensor.exact: true for exact frames
//
// Frames: colour CV_8UC3 BGR, depth CV_32F metres along z (NaN = no return), registered, with the
// configured intrinsics; utime of frame i = start + round(i * 1e6 / rate_hz) microseconds.
// Ground truth: T_world_camera of the camera optical frame in the scene's world frame (z up),
// the TUM convention. Not live: next() renders as fast as it can (about 10-25 ms per frame on a
// quiet machine, several times that under load); a real-time player that falls behind passes
// over frames without rendering them (dropUpcoming).
// Frame i depends only on (scene, config, seed, i): bit-identical across runs.
// One thread owns the source.

#include <cstdint>
#include <memory>
#include <optional>
#include <string>

#include "slamd/capture/camera_config.hpp"
#include "slamd/capture/frame_source.hpp"
#include "slamd/capture/source_support.hpp"
#include "slamd/synth/motion.hpp"
#include "slamd/synth/renderer.hpp"
#include "slamd/synth/scene.hpp"
#include "slamd/synth/sensor_model.hpp"

namespace slamd {

struct SyntheticConfig {
  std::string trajectory = "auto";  ///< resolved per scene when "auto"
  int frames = 0;                   ///< 0 = natural length of the trajectory
  std::uint64_t seed = 42;
  double start_time_s = 1.6e9;
  bool variety = false;       ///< draw scene, walk and exposure from the seed (variety.hpp)
  std::string variety_drawn;  ///< what the draw chose (set by load), for logs and reports
  /// Frames in [start, start + duration) come out covered, as if a hand or a passer-by blocked
  /// the lens: black colour, no depth (ground truth still lists them), for testing tracking loss
  /// and relocalisation.
  double blackout_start_s = 0.0;
  double blackout_duration_s = 0.0;
  synth::SceneParams scene;
  synth::MotionParams motion;
  synth::SensorParams sensor;
  CameraConfig camera;  ///< camera.* (depth_scale default 5000, the TUM factor)

  /// The source's own `synthetic.*` keys (rows in synthetic_source.cpp).
  static const ConfigSchema<SyntheticConfig>& schema();
  /// Reads and validates `synthetic.*` and `camera.*`; throws ConfigError.
  static SyntheticConfig load(Config& config);
};

class SyntheticSource : public FrameSource {
 public:
  /// Builds the scene and the trajectory; throws SourceError for an unknown scene or a camera
  /// model the renderer cannot produce (distortion).
  SyntheticSource(const std::string& scene_name, const SyntheticConfig& config);

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

  /// Frame `index` (0-based, any order), with the sensor model applied.
  RgbdFramePtr renderFrame(int index) const;
  /// The exact render (no sensor effects, no blur) of frame `index`.
  void renderExact(int index, synth::RenderOutput& out) const;

  int frameCount() const { return frame_count_; }
  const synth::Scene& scene() const { return *scene_; }
  const SyntheticConfig& config() const { return config_; }
  synth::MotionKind motionKind() const { return motion_->kind(); }

 private:
  std::string scene_name_;
  SyntheticConfig config_;
  std::unique_ptr<synth::Scene> scene_;  ///< heap: renderer and motion keep references
  std::unique_ptr<synth::Renderer> renderer_;
  std::unique_ptr<synth::CameraMotion> motion_;
  synth::SensorModel sensor_;
  int frame_count_ = 0;
  Utime start_utime_ = 0;
  Trajectory ground_truth_;
  int position_ = 0;
  bool open_ = false;
  SourceCounters counters_;  ///< read by other threads through stats()
};

/// The factory behind `synthetic:SCENE`: `scene` is corridor | corridor_loop | room. Reads the
/// configuration (ConfigError) and builds the source (SourceError for an unknown scene).
std::unique_ptr<FrameSource> createSyntheticSource(const std::string& scene, Config& config);

}  // namespace slamd
