#pragma once
// Channel names and the LCM URL, shared by the daemon and every client so that a renamed
// channel is renamed everywhere by one configuration key.

#include <string>

#include "slamd/common/config.hpp"

namespace slamd {

struct ChannelConfig {
  std::string lcm_url;                            ///< lcm.url; "" = $LCM_DEFAULT_URL or LCM's default
  std::string pose = "SLAMD_POSE";                ///< channels.pose: slamd.pose_t per frame
  std::string bot_pose = "POSE";                  ///< channels.bot_pose: bot_core.pose_t per frame
  std::string odometry = "SLAMD_ODOMETRY";        ///< channels.odometry: slamd.odometry_t
  std::string vanishing_point = "SLAMD_VP";       ///< channels.vanishing_point
  std::string map_update = "SLAMD_MAP_UPDATE";    ///< channels.map_update
  std::string map = "SLAMD_MAP";                  ///< channels.map: full map
  std::string keyframes = "SLAMD_KEYFRAMES";      ///< channels.keyframes: optimised keyframes
  std::string status = "SLAMD_STATUS";            ///< channels.status: 1 Hz
  std::string command = "SLAMD_COMMAND";          ///< channels.command: slamd.command_t in
  // Republished frames go to capture.publish.channel (LcmFramePublisherConfig).

  /// Reads lcm.url and channels.*; a channel name must be non-empty and without spaces.
  static ChannelConfig load(Config& config);
};

}  // namespace slamd
