#include "slamd/capture/camera_config.hpp"

namespace slamd {

CameraConfig CameraConfig::load(Config& config, double default_depth_scale) {
  CameraConfig out;
  CameraIntrinsics& k = out.intrinsics;
  k.fx = config.getDouble("camera.fx", k.fx, 1e-6, 1e5);
  k.fy = config.getDouble("camera.fy", k.fy, 1e-6, 1e5);
  k.cx = config.getDouble("camera.cx", k.cx, -1e5, 1e5);
  k.cy = config.getDouble("camera.cy", k.cy, -1e5, 1e5);
  k.width = config.getInt("camera.width", k.width, 1, 16384);
  k.height = config.getInt("camera.height", k.height, 1, 16384);
  const std::string model =
      config.getChoice("camera.distortion_model", "none", {"none", "plumb_bob"});
  k.distortion_model = model == "plumb_bob" ? DistortionModel::kPlumbBob : DistortionModel::kNone;
  const std::vector<double> distortion =
      config.getDoubleList("camera.distortion", {0.0, 0.0, 0.0, 0.0, 0.0}, 5);
  for (std::size_t i = 0; i < k.distortion.size(); ++i) k.distortion[i] = distortion[i];
  out.depth_scale = config.getDouble("camera.depth_scale", default_depth_scale, 1e-6, 1e6);
  const std::string error = k.validationError();
  if (!error.empty()) throw ConfigError("camera: " + error);
  return out;
}

}  // namespace slamd
