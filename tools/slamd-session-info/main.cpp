// slamd-session-info: prints what a session folder holds (as written by --session-out or the
// SAVE_SESSION command): format, provenance, camera, summary counts, extents and files. It reads
// only the manifest, unless --verify asks to load and check everything the way the daemon's
// --session-in does.
//
//   slamd-session-info maps/office
//   slamd-session-info maps/office --verify     # exit 1 naming the file and problem if refused
//
// Exit codes: 0 OK, 1 a refused session (the reason on stderr), 2 a usage error.

#include <cstdio>
#include <ctime>
#include <iostream>
#include <string>

#include "slamd/backend/session.hpp"
#include "slamd/common/program_options.hpp"

namespace {

using namespace slamd;

/// UTC ISO 8601 to the second ("2024-04-05T19:34:38Z"), or the raw number when out of range.
std::string isoUtc(Utime utime) {
  const std::time_t seconds = static_cast<std::time_t>(utime / kUtimePerSecond);
  std::tm tm{};
  char text[32];
  if (utime < 0 || gmtime_r(&seconds, &tm) == nullptr ||
      std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%SZ", &tm) == 0) {
    return std::to_string(utime) + " us";
  }
  return text;
}

std::string cameraText(const CameraIntrinsics& K) {
  char text[256];
  std::snprintf(text, sizeof(text), "%dx%d, fx %.3f fy %.3f cx %.3f cy %.3f", K.width, K.height,
                K.fx, K.fy, K.cx, K.cy);
  std::string result = text;
  if (K.distortion_model == DistortionModel::kPlumbBob) {
    std::snprintf(text, sizeof(text), ", plumb-bob k1 %g k2 %g p1 %g p2 %g k3 %g", K.distortion[0],
                  K.distortion[1], K.distortion[2], K.distortion[3], K.distortion[4]);
    result += text;
  } else {
    result += ", no distortion";
  }
  return result;
}

std::string extentText(const Eigen::Vector3d& min_m, const Eigen::Vector3d& max_m) {
  const Eigen::Vector3d size = max_m - min_m;
  char text[256];
  std::snprintf(text, sizeof(text),
                "x %.2f .. %.2f, y %.2f .. %.2f, z %.2f .. %.2f m (%.2f x %.2f x %.2f m)",
                min_m.x(), max_m.x(), min_m.y(), max_m.y(), min_m.z(), max_m.z(), size.x(),
                size.y(), size.z());
  return text;
}

void printInfo(const std::string& dir, const SessionInfo& info) {
  std::printf("session          %s (%s)\n", dir.c_str(), info.generation.c_str());
  std::printf("format           %u\n", info.format_version);
  std::printf("created          %s\n", isoUtc(info.created_utime).c_str());
  std::printf("created by       %s\n", info.created_by.empty() ? "-" : info.created_by.c_str());
  std::printf("camera           %s\n", cameraText(info.camera).c_str());
  std::printf("keyframes        %lld (and %lld culled)\n", static_cast<long long>(info.keyframes),
              static_cast<long long>(info.culled_keyframes));
  std::printf("landmarks        %lld\n", static_cast<long long>(info.landmarks));
  std::printf("edges            %lld\n", static_cast<long long>(info.edges));
  std::printf("segments         %lld\n", static_cast<long long>(info.segments));
  std::printf("loops            %lld\n", static_cast<long long>(info.loops));
  std::printf("keyframe extent  %s\n",
              info.keyframes > 0 ? extentText(info.keyframe_min_m, info.keyframe_max_m).c_str()
                                 : "none (no keyframes)");
  std::printf("map extent       %s\n", info.map_voxels > 0
                                           ? extentText(info.map_min_m, info.map_max_m).c_str()
                                           : "none (no map)");
  std::printf("map voxels       %lld\n", static_cast<long long>(info.map_voxels));
  std::printf("files\n");
  for (const auto& [name, size] : info.files) {
    std::printf("  %-16s %12llu bytes\n", name.c_str(), static_cast<unsigned long long>(size));
  }
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options("slamd-session-info",
                         "Prints what a slamd session folder holds (its manifest); --verify loads "
                         "and checks all of it.");
  options.setPositional("DIR", 1, 1);
  options.addFlag("verify",
                  "also load and check the whole session as the daemon would; say OK or why not");
  if (!options.parse(argc, argv)) return options.exitCode();
  const std::string dir = options.positional()[0];
  try {
    const SessionInfo info = readSessionInfo(dir);
    printInfo(dir, info);
    if (options.flag("verify")) {
      std::fflush(stdout);
      const Session session = loadSession(dir);
      std::printf("verify           OK (%zu keyframes, %zu edges, %d vocabulary words%s)\n",
                  session.backend.keyframes.size(), session.backend.edges.size(),
                  session.vocabulary->numWords(), session.map_path.empty() ? "" : ", a map");
    }
  } catch (const std::exception& e) {  // SessionError, or a failure to allocate or read
    std::fflush(stdout);
    std::cerr << "slamd-session-info: " << e.what() << "\n";
    return kExitFailure;
  }
  return kExitOk;
}
