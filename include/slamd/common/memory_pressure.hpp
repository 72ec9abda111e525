#pragma once
// Memory pressure: the daemon's resident memory against its limit (daemon.memory_limit_mb), as
// a level the stages degrade by, so that a long session stays within the limit instead of
// growing until the robot's computer runs out:
//   kNear (above 80% of the limit): what is added from now on costs less. The back end culls new
//     keyframes harder and keeps them without the image its patch alignment uses; the mapper
//     keeps no new keyframe clouds (new keyframes go into the map at once and no longer follow
//     corrections).
//   kOver (above the limit): also what is held is released. The mapper drops the kept clouds of
//     all but its newest keyframes (their part of the map stays where it is) and makes the map
//     far from the camera coarser; the back end culls a new keyframe that one other keyframe
//     already covers.
// The thresholds have hysteresis (down again below 75% and 95%), so a level does not flap.
//
// MemoryGovernor is owned by the thread that publishes status; the stages read its level
// through an atomic.

#include <cstdint>
#include <optional>

namespace slamd {

enum class MemoryPressure : std::int8_t {
  kNone = 0,  ///< under 80% of the limit, or no limit
  kNear = 1,  ///< above 80%: degrade what is added
  kOver = 2,  ///< above the limit: also release what is held
};

const char* toString(MemoryPressure pressure);

/// Resident set size of this process in megabytes (from /proc/self/statm); nullopt where it
/// cannot be read.
std::optional<double> residentMegabytes();

class MemoryGovernor {
 public:
  /// @param limit_mb megabytes; 0 = no limit (the level stays kNone)
  explicit MemoryGovernor(double limit_mb) : limit_mb_(limit_mb) {}

  /// The level for this resident size (megabytes), with hysteresis.
  MemoryPressure update(double resident_mb);
  MemoryPressure level() const { return level_; }

 private:
  double limit_mb_;
  MemoryPressure level_ = MemoryPressure::kNone;
};

}  // namespace slamd
