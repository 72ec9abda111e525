#include "slamd/comms/channels.hpp"

namespace slamd {

const ConfigSchema<LcmConfig>& LcmConfig::schema() {
  static const auto table = ConfigSchema<LcmConfig>("lcm").text(
      "url", &LcmConfig::url, "LCM URL (--lcm-url); empty = $LCM_DEFAULT_URL or LCM's default");
  return table;
}

LcmConfig LcmConfig::load(Config& config) {
  LcmConfig out;
  schema().load(config, out);
  return out;
}

const ConfigSchema<ChannelConfig>& ChannelConfig::schema() {
  using C = ChannelConfig;
  static const auto table =
      ConfigSchema<C>("channels")
          .text("pose", &C::pose, "slamd.pose_t, one per frame")
          .text("bot_pose", &C::bot_pose, "bot_core.pose_t, one per frame")
          .text("odometry", &C::odometry, "slamd.odometry_t")
          .text("vanishing_point", &C::vanishing_point, "detected vanishing points")
          .text("map_update", &C::map_update, "voxel_map_update_t")
          .text("map", &C::map, "full voxel_map_t")
          .text("plane_map", &C::plane_map, "plane_map_t: the map's planes (mapping.planes.*)")
          .text("keyframes", &C::keyframes, "optimised keyframe poses")
          .text("status", &C::status, "SLAMD_STATUS (daemon.status_period_s)")
          .text("command", &C::command, "slamd.command_t received");
  return table;
}

ChannelConfig ChannelConfig::load(Config& config) {
  ChannelConfig c;
  c.lcm_url = LcmConfig::load(config).url;
  schema().load(config, c);
  for (const ConfigKeyDescription& key : schema().describe(c)) {
    const std::string& name = key.default_value;  // the loaded value
    if (name.empty() || name.find_first_of(" \t\n") != std::string::npos) {
      throw ConfigError(key.key + " = '" + name +
                        "': a channel name must be non-empty and contain no whitespace");
    }
  }
  return c;
}

}  // namespace slamd
