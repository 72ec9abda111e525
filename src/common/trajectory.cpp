#include "slamd/common/trajectory.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "slamd/common/file_io.hpp"

namespace slamd {

Trajectory parseTumTrajectory(const std::string& text, const std::string& source) {
  Trajectory trajectory;
  std::istringstream lines(text);
  std::string line;
  int line_number = 0;
  while (std::getline(lines, line)) {
    ++line_number;
    for (char& c : line) {
      if (c == ',' || c == '\t' || c == '\r') c = ' ';
    }
    const auto first = line.find_first_not_of(' ');
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    double v[8];
    int count = 0;
    std::string token;
    while (fields >> token) {
      if (count == 8) {
        count = 9;
        break;
      }
      char* end = nullptr;
      v[count] = std::strtod(token.c_str(), &end);
      if (end != token.c_str() + token.size() || !std::isfinite(v[count])) {
        throw std::runtime_error(source + ":" + std::to_string(line_number) + ": '" + token +
                                 "' is not a number");
      }
      ++count;
    }
    if (count != 8) {
      throw std::runtime_error(source + ":" + std::to_string(line_number) +
                               ": expected 8 fields 'timestamp tx ty tz qx qy qz qw'");
    }
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    if (q.norm() < 1e-6) {
      throw std::runtime_error(source + ":" + std::to_string(line_number) + ": zero quaternion");
    }
    StampedPose pose;
    pose.timestamp_s = v[0];
    pose.T_world_camera = makeSE3(Eigen::Vector3d(v[1], v[2], v[3]), q);
    trajectory.push_back(pose);
  }
  return trajectory;
}

Trajectory readTumTrajectory(const std::string& path) {
  std::ifstream file(path);
  if (!file) throw std::runtime_error("cannot open trajectory file '" + path + "'");
  std::stringstream text;
  text << file.rdbuf();
  return parseTumTrajectory(text.str(), path);
}

std::string formatTumPose(const StampedPose& pose) {
  const Eigen::Vector3d t = pose.T_world_camera.translation();
  Eigen::Quaterniond q(pose.T_world_camera.linear());
  q.normalize();
  char buffer[256];
  std::snprintf(buffer, sizeof(buffer), "%.6f %.9f %.9f %.9f %.9f %.9f %.9f %.9f", pose.timestamp_s,
                t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
  return buffer;
}

void writeTumTrajectory(const std::string& path, const Trajectory& trajectory,
                        const std::string& header_comment) {
  std::string error;
  const bool written = writeOutputFile(
      path,
      [&](std::ostream& file) {
        if (!header_comment.empty()) {
          std::istringstream lines(header_comment);
          std::string line;
          while (std::getline(lines, line)) file << "# " << line << "\n";
        }
        file << "# timestamp tx ty tz qx qy qz qw\n";
        for (const auto& pose : trajectory) file << formatTumPose(pose) << "\n";
        return true;
      },
      &error);
  if (!written) throw std::runtime_error("trajectory not written: " + error);
}

double pathLengthM(const Trajectory& trajectory) {
  double length_m = 0.0;
  for (std::size_t i = 1; i < trajectory.size(); ++i) {
    length_m += (trajectory[i].T_world_camera.translation() -
                 trajectory[i - 1].T_world_camera.translation())
                    .norm();
  }
  return length_m;
}

double durationS(const Trajectory& trajectory) {
  return trajectory.size() < 2 ? 0.0
                               : trajectory.back().timestamp_s - trajectory.front().timestamp_s;
}

}  // namespace slamd
