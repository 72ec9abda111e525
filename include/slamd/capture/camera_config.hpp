#pragma once
// CameraConfig: the `camera.*` section of a configuration file (see config/tum_fr1.yaml).
//
//   Config config = Config::fromFile("config/tum_fr1.yaml");
//   CameraConfig camera = CameraConfig::load(config);   // throws ConfigError naming the key
//   source uses camera.intrinsics and camera.depth_scale
//
// Keys (defaults are the Kinect v1 factory values):
//   camera.fx, camera.fy        focal lengths, pixels, (0, 1e5]            525.0
//   camera.cx, camera.cy        principal point, pixels, [-1e5, 1e5]       319.5, 239.5
//   camera.width, camera.height image size, pixels, 1..16384               640, 480
//   camera.distortion_model     none | plumb_bob                          none
//   camera.distortion           [k1, k2, p1, p2, k3], dimensionless        zeros
//   camera.depth_scale          raw depth units per metre, (0, 1e6]        source-specific default
//                               (5000 for TUM folders, 1000 for OpenNI2 millimetres)

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/config.hpp"

namespace slamd {

struct CameraConfig {
  CameraIntrinsics intrinsics;
  double depth_scale = 1000.0;  ///< raw units per metre

  /// Reads `camera.*`; `default_depth_scale` is the source's convention when the key is absent.
  static CameraConfig load(Config& config, double default_depth_scale);
};

}  // namespace slamd
