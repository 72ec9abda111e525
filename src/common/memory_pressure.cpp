#include "slamd/common/memory_pressure.hpp"

#include <unistd.h>

#include <fstream>

namespace slamd {

namespace {
constexpr double kNearRatio = 0.8;
constexpr double kNearReleaseRatio = 0.75;
constexpr double kOverRatio = 1.0;
constexpr double kOverReleaseRatio = 0.95;
}  // namespace

const char* toString(MemoryPressure pressure) {
  switch (pressure) {
    case MemoryPressure::kNone:
      return "none";
    case MemoryPressure::kNear:
      return "near the limit";
    case MemoryPressure::kOver:
      return "over the limit";
  }
  return "unknown";
}

std::optional<double> residentMegabytes() {
  std::ifstream statm("/proc/self/statm");
  long long total_pages = 0;
  long long resident_pages = 0;
  if (!(statm >> total_pages >> resident_pages)) return std::nullopt;
  const long page_bytes = sysconf(_SC_PAGESIZE);
  if (page_bytes <= 0) return std::nullopt;
  return static_cast<double>(resident_pages) * static_cast<double>(page_bytes) / (1024.0 * 1024.0);
}

MemoryPressure MemoryGovernor::update(double resident_mb) {
  if (!(limit_mb_ > 0.0)) return level_ = MemoryPressure::kNone;
  const double ratio = resident_mb / limit_mb_;
  switch (level_) {
    case MemoryPressure::kNone:
      if (ratio > kOverRatio) {
        level_ = MemoryPressure::kOver;
      } else if (ratio > kNearRatio) {
        level_ = MemoryPressure::kNear;
      }
      break;
    case MemoryPressure::kNear:
      if (ratio > kOverRatio) {
        level_ = MemoryPressure::kOver;
      } else if (ratio < kNearReleaseRatio) {
        level_ = MemoryPressure::kNone;
      }
      break;
    case MemoryPressure::kOver:
      if (ratio < kNearReleaseRatio) {
        level_ = MemoryPressure::kNone;
      } else if (ratio < kOverReleaseRatio) {
        level_ = MemoryPressure::kNear;
      }
      break;
  }
  return level_;
}

}  // namespace slamd
