// OpenNi2Config's keys, compiled with or without OpenNI2 so that every build describes the same
// configuration.
#include "slamd/capture/openni2_source.hpp"

namespace slamd {

namespace {

const EnumNames<bool> kIntrinsicsOriginNames = {
    {false, "config", "camera.* (scaled when the stream size differs from camera.width/height)"},
    {true, "device", "the device's fields of view"},
};

}  // namespace

const ConfigSchema<OpenNi2Config>& OpenNi2Config::schema() {
  using C = OpenNi2Config;
  static const auto table =
      ConfigSchema<C>("capture")
          .choice("openni2.intrinsics", &C::intrinsics_from_device, kIntrinsicsOriginNames,
                  "where the intrinsics come from")
          .number("openni2.width", &C::width, 1, 4096, "px", "stream width")
          .number("openni2.height", &C::height, 1, 4096, "px", "stream height")
          .number("openni2.fps", &C::fps, 1, 120, "Hz", "stream frame rate")
          .flag("openni2.registration", &C::registration, "register depth to colour")
          .flag("openni2.sync", &C::sync, "depth/colour frame sync")
          .flag("openni2.color", &C::color, "open the colour stream (false: depth only)")
          .number("openni2.frame_timeout_s", &C::frame_timeout_s, 1e-3, 60.0, "s",
                  "a device that delivers no frame for this long is reported disconnected and "
                  "reopened")
          .number("openni2.reconnect_initial_s", &C::reconnect_initial_s, 1e-3, 60.0, "s",
                  "first reconnection delay (doubled after each failure)")
          .number("openni2.reconnect_max_s", &C::reconnect_max_s, 1e-3, 600.0, "s",
                  "longest reconnection delay")
          .flag("oni.realtime", &C::oni_realtime,
                "play .oni recordings on the recorded clock instead of as fast as read");
  return table;
}

OpenNi2Config OpenNi2Config::load(Config& config) {
  OpenNi2Config out;
  out.camera = CameraConfig::load(config, 1000.0);
  schema().load(config, out);
  return out;
}

}  // namespace slamd
