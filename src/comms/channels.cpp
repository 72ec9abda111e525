#include "slamd/comms/channels.hpp"

namespace slamd {

namespace {
std::string channelName(Config& config, const std::string& key, const std::string& default_name) {
  const std::string name = config.getString("channels." + key, default_name);
  if (name.empty() || name.find_first_of(" \t\n") != std::string::npos) {
    throw ConfigError("channels." + key + " = '" + name +
                      "': a channel name must be non-empty and contain no whitespace");
  }
  return name;
}
}  // namespace

ChannelConfig ChannelConfig::load(Config& config) {
  ChannelConfig c;
  c.lcm_url = config.getString("lcm.url", c.lcm_url);
  c.pose = channelName(config, "pose", c.pose);
  c.bot_pose = channelName(config, "bot_pose", c.bot_pose);
  c.odometry = channelName(config, "odometry", c.odometry);
  c.vanishing_point = channelName(config, "vanishing_point", c.vanishing_point);
  c.map_update = channelName(config, "map_update", c.map_update);
  c.map = channelName(config, "map", c.map);
  c.keyframes = channelName(config, "keyframes", c.keyframes);
  c.status = channelName(config, "status", c.status);
  c.command = channelName(config, "command", c.command);
  return c;
}

}  // namespace slamd
