// Fuzz target: configuration text and --set overrides. The first byte chooses what the rest is:
//   even  a configuration file's text (Config::fromYamlString, which bounds size and nesting
//         before cv::FileStorage parses it);
//   odd   --set lines, one per line, applied over the defaults.
// Then every module reads its section, as the daemon does at start-up. The only error allowed
// out is ConfigError (the daemon reports it and exits 3).

#include <sstream>
#include <string>

#include "fuzz_input.hpp"
#include "slamd/app/daemon_config.hpp"
#include "slamd/backend/backend_config.hpp"
#include "slamd/capture/camera_config.hpp"
#include "slamd/capture/depth_preprocessor.hpp"
#include "slamd/capture/openni2_source.hpp"
#include "slamd/capture/paced_source.hpp"
#include "slamd/capture/tum_source.hpp"
#include "slamd/common/config.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/comms/lcm_frame_source.hpp"
#include "slamd/filter/filter_config.hpp"
#include "slamd/mapping/mapping_config.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/tracking/tracking_config.hpp"

namespace {

using namespace slamd;

void loadEveryModule(Config& config) {
  DaemonConfig::load(config);
  ChannelConfig::load(config);
  TrackingConfig::load(config);
  FilterConfig::load(config);
  MappingConfig::load(config);
  BackendConfig::load(config);
  LcmFramePublisherConfig::load(config);
  LcmFrameSourceConfig::load(config);
  TumSourceConfig::load(config);
  OpenNi2Config::load(config);
  PacingConfig::load(config);
  DepthPreprocessorConfig::load(config);
  CameraConfig::load(config, 1000.0);
  SyntheticConfig::load(config);
  config.unknownKeys();
  config.effectiveYaml();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  fuzz::FuzzInput input(data, size);
  const bool as_file = input.byte() % 2 == 0;
  const std::string text = input.restAsString();
  try {
    Config config;
    if (as_file) {
      config = Config::fromYamlString(text);
    } else {
      std::istringstream lines(text);
      std::string line;
      while (std::getline(lines, line)) config.applyOverride(line);
    }
    loadEveryModule(config);
  } catch (const ConfigError&) {
  }
  return 0;
}
