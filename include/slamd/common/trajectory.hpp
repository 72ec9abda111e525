#pragma once
// Stamped poses and TUM-format trajectory files.
//
// TUM format (the RGB-D benchmark's): one pose per line, `timestamp tx ty tz qx qy qz qw`, the
// timestamp in seconds (any precision), the pose T_world_camera (camera origin and orientation in
// the world frame); lines starting with '#' and blank lines are ignored; fields are separated by
// spaces, tabs or commas. Timestamps are kept as double seconds exactly as read, because the
// benchmark's tools associate on those values.

#include <string>
#include <vector>

#include "slamd/common/se3.hpp"

namespace slamd {

struct StampedPose {
  double timestamp_s = 0.0;
  SE3 T_world_camera = SE3::Identity();
};

using Trajectory = std::vector<StampedPose>;

/// Reads a TUM trajectory. Throws std::runtime_error naming the file and line for unreadable
/// files and malformed lines (wrong field count, non-numbers, a zero quaternion).
Trajectory readTumTrajectory(const std::string& path);

/// Parses TUM trajectory text (`source` names it in errors).
Trajectory parseTumTrajectory(const std::string& text, const std::string& source = "<text>");

/// Writes a TUM trajectory with 6 decimals for the timestamp (microseconds) and 9 for values;
/// an optional comment header is written as '# ' lines. Written crash-safely (writeOutputFile);
/// throws std::runtime_error naming the file and the reason (strerror) on any I/O error.
void writeTumTrajectory(const std::string& path, const Trajectory& trajectory,
                        const std::string& header_comment = "");

/// Distance travelled along the trajectory: the sum of the camera's moves between consecutive
/// poses (metres).
double pathLengthM(const Trajectory& trajectory);
/// Time from the first to the last pose (seconds); 0 for fewer than two poses.
double durationS(const Trajectory& trajectory);
/// One TUM line (without newline) for a pose.
std::string formatTumPose(const StampedPose& pose);

}  // namespace slamd
