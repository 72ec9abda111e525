#include "slamd/synth/motion.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "random.hpp"
#include "slamd/common/config.hpp"

namespace slamd::synth {
namespace {

constexpr double kSmoothingHalfWindowM = 0.6;  ///< rounds path corners over +-0.6 m
constexpr int kSmoothingSamples = 25;
constexpr double kLookAheadM = 1.2;  ///< heading points at the path 1.2 m ahead
constexpr double kRandomDurationS = 30.0;
constexpr double kProfileStepM = 0.01;  ///< resolution of the speed profile along the path

/// Signal indices (one seeded stream each).
enum SignalIndex {
  kYawJitter,
  kPitchJitter,
  kRollJitter,
  kPosX,
  kPosY,
  kPosZ,
  kYaw,
  kPitch,
  kRoll,
  kSignalCount
};

}  // namespace

namespace {

struct MotionKindName {
  MotionKind kind;
  const char* name;
};
constexpr MotionKindName kMotionKindNames[] = {{MotionKind::kZigzag, "zigzag"},
                                               {MotionKind::kRandom, "random"},
                                               {MotionKind::kRobot, "robot"},
                                               {MotionKind::kLoop, "loop"}};

}  // namespace

MotionKind parseMotionKind(const std::string& name) {
  std::string allowed;
  for (const MotionKindName& entry : kMotionKindNames) {
    if (name == entry.name) return entry.kind;
    allowed += (allowed.empty() ? "" : ", ") + std::string(entry.name);
  }
  throw std::invalid_argument("unknown trajectory '" + name + "' (allowed: " + allowed + ")");
}

const char* motionKindName(MotionKind kind) {
  for (const MotionKindName& entry : kMotionKindNames) {
    if (entry.kind == kind) return entry.name;
  }
  return "?";
}

MotionKind defaultMotionFor(const std::string& scene_name) {
  if (scene_name == "corridor") return MotionKind::kZigzag;
  if (scene_name == "corridor_loop") return MotionKind::kLoop;
  return MotionKind::kRandom;
}

const ConfigSchema<MotionParams>& MotionParams::schema() {
  using C = MotionParams;
  static const auto table =
      ConfigSchema<C>("synthetic")
          .number("rate_hz", &C::rate_hz, 1.0, 120.0, "Hz", "frame rate of sampled trajectories")
          .number("walk_speed_mps", &C::walk_speed_mps, 0.05, 3.0, "m/s",
                  "walking speed along the path")
          .number("walk_height_m", &C::walk_height_m, 0.3, 2.2, "m", "hand-held camera height")
          .number("zigzag_amplitude_m", &C::zigzag_amplitude_m, 0.0, 2.0, "m",
                  "lateral zigzag amplitude (capped by the scene's clearance)")
          .number("zigzag_period_s", &C::zigzag_period_s, 0.5, 60.0, "s",
                  "one full left-right-left cycle")
          .number("step_hz", &C::step_hz, 0.5, 4.0, "Hz", "walking step frequency (head bob)")
          .number("head_bob_m", &C::head_bob_m, 0.0, 0.1, "m", "vertical bob amplitude")
          .number("look_around_deg", &C::look_around_deg, 0.0, 60.0, "deg",
                  "walkers look left and right: yaw oscillation amplitude; 0 = look ahead")
          .number("look_around_hz", &C::look_around_hz, 0.05, 2.0, "Hz",
                  "frequency of the look-around oscillation")
          .number("robot_speed_mps", &C::robot_speed_mps, 0.05, 3.0, "m/s", "robot speed")
          .number("robot_height_m", &C::robot_height_m, 0.2, 2.2, "m", "camera height of the robot")
          .number("max_speed_mps", &C::max_speed_mps, 0.01, 3.0, "m/s",
                  "peak speed of the random motion")
          .number("max_angular_rate_radps", &C::max_angular_rate_radps, 0.01, 6.0, "rad/s",
                  "peak rotation rate of the random motion")
          .number("max_turn_rate_radps", &C::max_turn_rate_radps, 0.05, 6.0, "rad/s",
                  "walkers and robots slow down so turns stay below this");
  return table;
}

MotionParams MotionParams::load(Config& config) {
  MotionParams p;
  schema().load(config, p);
  return p;
}

double CameraMotion::SmoothSignal::at(double t_s) const {
  double value = 0.0;
  for (int k = 0; k < 3; ++k) {
    value += weight[k] * std::sin(2.0 * M_PI * frequency_hz[k] * t_s + phase_rad[k]);
  }
  return value;
}

CameraMotion::SmoothSignal CameraMotion::makeSignal(std::uint64_t stream, double max_frequency_hz) {
  Rng rng(deriveSeed(seed_, 0x707104, stream));
  SmoothSignal signal{};
  double total = 0.0;
  for (int k = 0; k < 3; ++k) {
    signal.frequency_hz[k] = max_frequency_hz * rng.uniform(0.35, 1.0);
    signal.phase_rad[k] = rng.uniform(0.0, 2.0 * M_PI);
    signal.weight[k] = rng.uniform(0.5, 1.0);
    total += signal.weight[k];
  }
  // Normalised so |signal| <= 1 and its rate never exceeds 2 pi max_frequency_hz.
  for (double& weight : signal.weight) weight /= total;
  return signal;
}

CameraMotion::CameraMotion(const Scene& scene, MotionKind kind, const MotionParams& params,
                           std::uint64_t seed)
    : scene_(scene), kind_(kind), params_(params), seed_(seed) {
  const auto& path = scene_.navigation.patrol_path_xy;
  if (path.size() < 2) throw std::invalid_argument("scene '" + scene.name + "' has no patrol path");
  cumulative_m_.push_back(0.0);
  for (std::size_t i = 0; i < path.size(); ++i) {
    cumulative_m_.push_back(cumulative_m_.back() + (path[(i + 1) % path.size()] - path[i]).norm());
  }
  perimeter_m_ = cumulative_m_.back();

  // Speed profile: full speed on straight stretches, slower through turns (people and robots
  // slow down to turn), so that speed * |d heading / d s| never exceeds the turn-rate limit.
  const double speed =
      kind_ == MotionKind::kRobot ? params_.robot_speed_mps : params_.walk_speed_mps;
  const int steps = static_cast<int>(std::ceil(perimeter_m_ / kProfileStepM));
  time_at_arc_s_.assign(static_cast<std::size_t>(steps) + 1, 0.0);
  double previous_heading = pathHeading(0.0);
  for (int i = 1; i <= steps; ++i) {
    const double heading = pathHeading(i * kProfileStepM);
    double turn = std::abs(heading - previous_heading);
    turn = std::min(turn, 2.0 * M_PI - turn);
    previous_heading = heading;
    const double turn_per_m = turn / kProfileStepM;
    const double local_speed =
        std::min(speed, params_.max_turn_rate_radps / std::max(turn_per_m, 1e-9));
    time_at_arc_s_[static_cast<std::size_t>(i)] =
        time_at_arc_s_[static_cast<std::size_t>(i) - 1] + kProfileStepM / local_speed;
  }

  const Eigen::Vector3d half = 0.5 * scene_.navigation.random_region.sizes();
  const double yaw_range = std::max(1e-3, scene_.navigation.random_yaw_range_rad);
  const double w = params_.max_angular_rate_radps / (2.0 * M_PI);
  signals_.resize(kSignalCount);
  signals_[kYawJitter] = makeSignal(kYawJitter, 0.5);
  signals_[kPitchJitter] = makeSignal(kPitchJitter, 0.6);
  signals_[kRollJitter] = makeSignal(kRollJitter, 0.4);
  // Random motion: a signal of amplitude A and frequency f has peak rate 2 pi f A.
  const double v = params_.max_speed_mps / (2.0 * M_PI);
  signals_[kPosX] = makeSignal(kPosX, v / std::max(half.x(), 1e-3));
  signals_[kPosY] = makeSignal(kPosY, v / std::max(half.y(), 1e-3));
  signals_[kPosZ] = makeSignal(kPosZ, v / std::max(half.z(), 1e-3));
  signals_[kYaw] = makeSignal(kYaw, w / yaw_range);
  signals_[kPitch] = makeSignal(kPitch, w / 0.3);
  signals_[kRoll] = makeSignal(kRoll, w / 0.15);
}

Eigen::Vector2d CameraMotion::pathPoint(double s_m) const {
  const auto& path = scene_.navigation.patrol_path_xy;
  double s = std::fmod(s_m, perimeter_m_);
  if (s < 0.0) s += perimeter_m_;
  const auto it = std::upper_bound(cumulative_m_.begin(), cumulative_m_.end(), s);
  const std::size_t segment = std::min<std::size_t>(
      static_cast<std::size_t>(it - cumulative_m_.begin()) - 1, path.size() - 1);
  const double length = cumulative_m_[segment + 1] - cumulative_m_[segment];
  const double fraction = length > 0.0 ? (s - cumulative_m_[segment]) / length : 0.0;
  const Eigen::Vector2d& a = path[segment];
  const Eigen::Vector2d& b = path[(segment + 1) % path.size()];
  return a + fraction * (b - a);
}

Eigen::Vector2d CameraMotion::smoothPathPoint(double s_m) const {
  // Box-filtering the polyline over a window rounds its corners into C1 curves that stay inside
  // the convex hull of nearby path points (so inside the free corridor around the path).
  Eigen::Vector2d sum = Eigen::Vector2d::Zero();
  for (int k = 0; k < kSmoothingSamples; ++k) {
    const double offset = kSmoothingHalfWindowM * (2.0 * k / (kSmoothingSamples - 1) - 1.0);
    sum += pathPoint(s_m + offset);
  }
  return sum / kSmoothingSamples;
}

Eigen::Matrix3d lookRotation(double yaw_rad, double pitch_rad, double roll_rad) {
  const Eigen::Vector3d forward(std::cos(yaw_rad) * std::cos(pitch_rad),
                                std::sin(yaw_rad) * std::cos(pitch_rad), std::sin(pitch_rad));
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d R_world_look;
  R_world_look.col(0) = right;
  R_world_look.col(1) = down;
  R_world_look.col(2) = forward;
  return R_world_look * Eigen::AngleAxisd(roll_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
}

double CameraMotion::pathHeading(double s_m) const {
  const Eigen::Vector2d ahead = smoothPathPoint(s_m + kLookAheadM) - smoothPathPoint(s_m);
  return std::atan2(ahead.y(), ahead.x());
}

double CameraMotion::arcLengthAt(double t_s) const {
  const double lap_s = time_at_arc_s_.back();
  const double laps = std::floor(t_s / lap_s);
  const double t = t_s - laps * lap_s;
  const auto it = std::upper_bound(time_at_arc_s_.begin(), time_at_arc_s_.end(), t);
  const std::size_t i = std::clamp<std::size_t>(
      static_cast<std::size_t>(it - time_at_arc_s_.begin()), 1, time_at_arc_s_.size() - 1);
  const double t0 = time_at_arc_s_[i - 1];
  const double t1 = time_at_arc_s_[i];
  const double fraction = t1 > t0 ? (t - t0) / (t1 - t0) : 0.0;
  const double s = (static_cast<double>(i - 1) + std::clamp(fraction, 0.0, 1.0)) * kProfileStepM;
  return laps * perimeter_m_ + std::min(s, perimeter_m_);
}

SE3 CameraMotion::walkPose(double t_s, bool zigzag) const {
  const double s = arcLengthAt(t_s);
  const Eigen::Vector2d base = smoothPathPoint(s);
  const double heading = pathHeading(s);
  const Eigen::Vector2d left(-std::sin(heading), std::cos(heading));

  double lateral = 0.0;
  double lateral_slope = 0.0;  // d lateral / d s
  if (zigzag) {
    const double amplitude =
        std::min(params_.zigzag_amplitude_m, scene_.navigation.lateral_clearance_m);
    const double wavelength = params_.walk_speed_mps * params_.zigzag_period_s;
    lateral = amplitude * std::sin(2.0 * M_PI * s / wavelength);
    lateral_slope = amplitude * 2.0 * M_PI / wavelength * std::cos(2.0 * M_PI * s / wavelength);
  }
  // Gait: the head rises twice per stride (once per step) and sways once per stride.
  const double step_phase = 2.0 * M_PI * params_.step_hz * t_s;
  const double bob = params_.head_bob_m * std::sin(step_phase);
  const double sway = 0.5 * params_.head_bob_m * std::sin(0.5 * step_phase);
  const Eigen::Vector2d xy = base + (lateral + sway) * left;
  const Eigen::Vector3d position(xy.x(), xy.y(), params_.walk_height_m + bob);

  // The walker half-turns the camera into the zigzag, with small hand tremor and gait rotations.
  const double deg = M_PI / 180.0;
  const double look_around =
      params_.look_around_deg * deg * std::sin(2.0 * M_PI * params_.look_around_hz * t_s);
  const double yaw = heading + 0.6 * std::atan(lateral_slope) + look_around +
                     2.0 * deg * signals_[kYawJitter].at(t_s);
  const double pitch =
      -6.0 * deg + 1.5 * deg * signals_[kPitchJitter].at(t_s) + 0.5 * deg * std::cos(step_phase);
  const double roll =
      1.5 * deg * signals_[kRollJitter].at(t_s) + 1.0 * deg * std::sin(0.5 * step_phase);
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(yaw, pitch, roll);
  T_world_camera.translation() = position;
  return T_world_camera;
}

SE3 CameraMotion::robotPose(double t_s) const {
  const double s = arcLengthAt(t_s);
  const Eigen::Vector2d base = smoothPathPoint(s);
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(pathHeading(s), 0.0, 0.0);
  T_world_camera.translation() = Eigen::Vector3d(base.x(), base.y(), params_.robot_height_m);
  return T_world_camera;
}

SE3 CameraMotion::randomPose(double t_s) const {
  const Eigen::AlignedBox3d& region = scene_.navigation.random_region;
  const Eigen::Vector3d center = region.center();
  const Eigen::Vector3d half = 0.5 * region.sizes();
  const Eigen::Vector3d position(center.x() + half.x() * signals_[kPosX].at(t_s),
                                 center.y() + half.y() * signals_[kPosY].at(t_s),
                                 center.z() + half.z() * signals_[kPosZ].at(t_s));
  const double yaw = scene_.navigation.random_yaw_center_rad +
                     scene_.navigation.random_yaw_range_rad * signals_[kYaw].at(t_s);
  const double pitch = -0.12 + 0.3 * signals_[kPitch].at(t_s);
  const double roll = 0.15 * signals_[kRoll].at(t_s);
  SE3 T_world_camera = SE3::Identity();
  T_world_camera.linear() = lookRotation(yaw, pitch, roll);
  T_world_camera.translation() = position;
  return T_world_camera;
}

SE3 CameraMotion::poseAt(double t_s) const {
  switch (kind_) {
    case MotionKind::kZigzag:
      return walkPose(t_s, true);
    case MotionKind::kLoop:
      return walkPose(t_s, false);
    case MotionKind::kRobot:
      return robotPose(t_s);
    case MotionKind::kRandom:
      return randomPose(t_s);
  }
  return SE3::Identity();
}

int CameraMotion::naturalFrameCount() const {
  double duration_s = kRandomDurationS;
  switch (kind_) {
    case MotionKind::kZigzag: {
      const auto leg = static_cast<std::size_t>(
          std::min(scene_.navigation.first_leg_m / kProfileStepM, time_at_arc_s_.size() - 1.0));
      duration_s = time_at_arc_s_[leg];
      break;
    }
    case MotionKind::kLoop:
    case MotionKind::kRobot:
      duration_s = time_at_arc_s_.back();
      break;
    case MotionKind::kRandom:
      break;
  }
  // +1: the last frame lands exactly at the end (a loop's last pose equals its first).
  return static_cast<int>(std::floor(duration_s * params_.rate_hz)) + 1;
}

Utime frameUtime(Utime start_utime, int index, double rate_hz) {
  return start_utime + static_cast<Utime>(std::llround(index * 1e6 / rate_hz));
}

Trajectory sampleTrajectory(const CameraMotion& motion, int frames, Utime start_utime,
                            double rate_hz) {
  Trajectory trajectory;
  trajectory.reserve(static_cast<std::size_t>(std::max(0, frames)));
  for (int i = 0; i < frames; ++i) {
    const Utime utime = frameUtime(start_utime, i, rate_hz);
    trajectory.push_back(
        {utimeToSeconds(utime), motion.poseAt(utimeToSeconds(utime - start_utime))});
  }
  return trajectory;
}

}  // namespace slamd::synth
