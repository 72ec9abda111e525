#pragma once
// Channel names and the LCM URL, shared by the daemon and every client so that a renamed
// channel is renamed everywhere by one configuration key.

#include <string>

#include "slamd/common/config.hpp"
#include "slamd/common/config_schema.hpp"

namespace slamd {

/// The program's LCM URL, key `lcm.url` (its row: channels.cpp).
struct LcmConfig {
  std::string url;  ///< "" = $LCM_DEFAULT_URL or LCM's default

  static const ConfigSchema<LcmConfig>& schema();
  static LcmConfig load(Config& config);
};

/// Keys `channels.*` (type, default and doc of each: its row in channels.cpp, or
/// `slamd --describe-config channels`). Republished frames go to capture.publish.channel
/// (LcmFramePublisherConfig).
struct ChannelConfig {
  std::string lcm_url;  ///< LcmConfig::url
  std::string pose = "SLAMD_POSE";
  std::string bot_pose = "POSE";
  std::string odometry = "SLAMD_ODOMETRY";
  std::string vanishing_point = "SLAMD_VP";
  std::string map_update = "SLAMD_MAP_UPDATE";
  std::string map = "SLAMD_MAP";
  std::string plane_map = "SLAMD_PLANE_MAP";
  std::string keyframes = "SLAMD_KEYFRAMES";
  std::string status = "SLAMD_STATUS";
  std::string command = "SLAMD_COMMAND";

  static const ConfigSchema<ChannelConfig>& schema();
  /// Reads lcm.url and channels.*; a channel name must be non-empty and without spaces.
  static ChannelConfig load(Config& config);
};

}  // namespace slamd
