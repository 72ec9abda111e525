#pragma once
// Camera motions through a synthetic Scene, as continuous functions of time.
//
// Usage:
//   MotionParams params = MotionParams::load(config);             // "synthetic.*"
//   CameraMotion motion(scene, MotionKind::kZigzag, params, seed);
//   SE3 T_world_camera = motion.poseAt(t_s);                       // any t_s >= 0, seconds
//   Trajectory gt = sampleTrajectory(motion, frames, start_utime, params.rate_hz);
//
// Kinds:
//   kZigzag  hand-held walk along the scene's patrol path at about 0.8 m/s with a lateral zigzag,
//            head bob at the step frequency, sway and small rotations (the experiment of paper
//            002: a person walking down a corridor holding the camera). Natural length: the
//            first leg (down the corridor).
//   kRandom  smooth random 6-DoF motion inside the scene's free region, looking at geometry.
//            Natural length: 30 s.
//   kRobot   planar motion at a fixed camera height, level camera, heading along the path.
//            Natural length: one lap of the patrol path.
//   kLoop    the walk without zigzag, once around the closed patrol path back to the start.
//            Natural length: one lap.
//
// Poses are T_world_camera of the camera optical frame (x right, y down, z forward) in the
// scene's world frame (z up). Smooth in time (C1 everywhere), deterministic in (scene, kind,
// params, seed); the camera stays in free space (see Scene::isFree).

#include <cstdint>
#include <string>
#include <vector>

#include "slamd/common/config_schema.hpp"
#include "slamd/common/se3.hpp"
#include "slamd/common/time.hpp"
#include "slamd/common/trajectory.hpp"
#include "slamd/synth/scene.hpp"

namespace slamd::synth {

enum class MotionKind { kZigzag, kRandom, kRobot, kLoop };

/// "zigzag" | "random" | "robot" | "loop"; throws std::invalid_argument otherwise.
MotionKind parseMotionKind(const std::string& name);
const char* motionKindName(MotionKind kind);
/// The motion a scene is meant for: corridor -> zigzag, corridor_loop -> loop, room -> random.
MotionKind defaultMotionFor(const std::string& scene_name);

struct MotionParams {
  double rate_hz = 30.0;            ///< frame rate of sampled trajectories
  double walk_speed_mps = 0.8;      ///< walking speed along the path
  double walk_height_m = 1.5;       ///< hand-held camera height
  double zigzag_amplitude_m = 0.3;  ///< lateral zigzag amplitude (capped by the scene's clearance)
  double zigzag_period_s = 4.0;     ///< one full left-right-left cycle
  double step_hz = 1.8;             ///< walking step frequency (head bob)
  double head_bob_m = 0.02;         ///< vertical bob amplitude
  /// The walker looks left and right while walking: a yaw oscillation of this amplitude (degrees)
  /// at look_around_hz, on top of the zigzag's heading. 0 = looks ahead.
  double look_around_deg = 0.0;
  double look_around_hz = 0.3;
  double robot_speed_mps = 0.4;
  double robot_height_m = 0.5;          ///< camera height of the robot
  double max_speed_mps = 0.35;          ///< peak speed of the random motion
  double max_angular_rate_radps = 0.6;  ///< peak rotation rate of the random motion
  double max_turn_rate_radps = 1.2;     ///< walkers and robots slow down so turns stay below this

  /// The motion's `synthetic.*` keys (rows in motion.cpp).
  static const ConfigSchema<MotionParams>& schema();
  static MotionParams load(Config& config);
};

class CameraMotion {
 public:
  CameraMotion(const Scene& scene, MotionKind kind, const MotionParams& params, std::uint64_t seed);

  /// T_world_camera at time t_s (seconds from the start of the motion).
  SE3 poseAt(double t_s) const;
  /// Frames at params.rate_hz for the kind's natural length (see the class comment).
  int naturalFrameCount() const;
  MotionKind kind() const { return kind_; }

 private:
  /// A smooth pseudo-random signal in [-1, 1]: a normalised sum of three sinusoids.
  struct SmoothSignal {
    double frequency_hz[3];
    double phase_rad[3];
    double weight[3];
    double at(double t_s) const;
  };
  SmoothSignal makeSignal(std::uint64_t stream, double max_frequency_hz);
  Eigen::Vector2d pathPoint(double s_m) const;        ///< on the polyline, s modulo perimeter
  Eigen::Vector2d smoothPathPoint(double s_m) const;  ///< window-averaged (rounded corners)
  double pathHeading(double s_m) const;  ///< yaw towards the smoothed path kLookAhead ahead
  double arcLengthAt(double t_s) const;  ///< distance travelled along the path after t_s
  SE3 walkPose(double t_s, bool zigzag) const;
  SE3 robotPose(double t_s) const;
  SE3 randomPose(double t_s) const;

  const Scene& scene_;
  MotionKind kind_;
  MotionParams params_;
  std::uint64_t seed_;
  std::vector<double> cumulative_m_;  ///< arc length at each path vertex (closed path)
  double perimeter_m_ = 0.0;
  /// Time (s) to reach arc length i * kProfileStepM along the path: the speed profile, slowed
  /// where the heading turns fast so that the turn rate stays below max_turn_rate_radps.
  std::vector<double> time_at_arc_s_;
  std::vector<SmoothSignal> signals_;
};

/// Camera orientation looking along yaw (about world z from +x) and pitch (up positive), rolled
/// about the optical axis, as the rotation of T_world_camera.
Eigen::Matrix3d lookRotation(double yaw_rad, double pitch_rad, double roll_rad);

/// Frame timestamp i: start_utime + round(i * 1e6 / rate_hz).
Utime frameUtime(Utime start_utime, int index, double rate_hz);

/// `frames` poses at rate_hz, stamped frameUtime(...) in seconds.
Trajectory sampleTrajectory(const CameraMotion& motion, int frames, Utime start_utime,
                            double rate_hz);

}  // namespace slamd::synth
