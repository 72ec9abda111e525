#include "slamd/capture/camera_config.hpp"

namespace slamd {

namespace {

const EnumNames<DistortionModel> kDistortionModelNames = {
    {DistortionModel::kNone, "none", "ideal pinhole"},
    {DistortionModel::kPlumbBob, "plumb_bob", "radial-tangential [k1, k2, p1, p2, k3]"},
};

}  // namespace

const ConfigSchema<CameraConfig>& CameraConfig::schema() {
  using C = CameraConfig;
  static const auto table =
      ConfigSchema<C>("camera")
          .number(
              "fx", [](auto& c) -> auto& { return c.intrinsics.fx; }, 1e-6, 1e5, "px",
              "focal length along x")
          .number(
              "fy", [](auto& c) -> auto& { return c.intrinsics.fy; }, 1e-6, 1e5, "px",
              "focal length along y")
          .number(
              "cx", [](auto& c) -> auto& { return c.intrinsics.cx; }, -1e5, 1e5, "px",
              "principal point x")
          .number(
              "cy", [](auto& c) -> auto& { return c.intrinsics.cy; }, -1e5, 1e5, "px",
              "principal point y")
          .number(
              "width", [](auto& c) -> auto& { return c.intrinsics.width; }, 1, 16384, "px",
              "image width")
          .number(
              "height", [](auto& c) -> auto& { return c.intrinsics.height; }, 1, 16384, "px",
              "image height")
          .choice(
              "distortion_model", [](auto& c) -> auto& { return c.intrinsics.distortion_model; },
              kDistortionModelNames, "lens distortion model")
          .list(
              "distortion", [](auto& c) -> auto& { return c.intrinsics.distortion; }, "",
              "[k1, k2, p1, p2, k3] of plumb_bob")
          .number("depth_scale", &C::depth_scale, 1e-6, 1e6, "raw units per metre",
                  "raw depth units per metre; default by source: 5000 for TUM folders and "
                  "synthetic worlds, 1000 for OpenNI2 and LCM (millimetres)")
          .describedDefault("by source");
  return table;
}

CameraConfig CameraConfig::load(Config& config, double default_depth_scale) {
  CameraConfig out;
  out.depth_scale = default_depth_scale;
  schema().load(config, out);
  const std::string error = out.intrinsics.validationError();
  if (!error.empty()) throw ConfigError("camera: " + error);
  return out;
}

}  // namespace slamd
