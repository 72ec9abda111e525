#pragma once
// CameraConfig: the `camera.*` section of a configuration file (see config/tum_fr1.yaml).
//
//   Config config = Config::fromFile("config/tum_fr1.yaml");
//   CameraConfig camera = CameraConfig::load(config);   // throws ConfigError naming the key
//   source uses camera.intrinsics and camera.depth_scale
//
// Defaults are the Kinect v1 factory values. Each key's type, default, range, unit and doc: its
// row in camera_config.cpp, or `slamd --describe-config camera`.

#include "slamd/common/camera_intrinsics.hpp"
#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

struct CameraConfig {
  CameraIntrinsics intrinsics;
  double depth_scale = 1000.0;  ///< raw units per metre

  /// The `camera.*` keys.
  static const ConfigSchema<CameraConfig>& schema();
  /// Reads `camera.*`; `default_depth_scale` is the source's convention when the key is absent.
  static CameraConfig load(Config& config, double default_depth_scale);
};

}  // namespace slamd
