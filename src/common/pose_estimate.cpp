#include "slamd/common/pose_estimate.hpp"

namespace slamd {

const char* trackingStateName(TrackingState state) {
  switch (state) {
    case TrackingState::kNotInitialized:
      return "not_initialized";
    case TrackingState::kOk:
      return "ok";
    case TrackingState::kPredicted:
      return "predicted";
    case TrackingState::kLost:
      return "lost";
    case TrackingState::kRelocalized:
      return "relocalized";
  }
  return "?";
}

}  // namespace slamd
