// Fuzz target: configuration text and --set overrides. The first byte chooses what the rest is:
//   even  a configuration file's text (Config::fromYamlString, which bounds size and nesting
//         before cv::FileStorage parses it);
//   odd   --set lines, one per line, applied over the defaults.
// Then every module reads its section, as the daemon does at start-up. The only error allowed
// out is ConfigError (the daemon reports it and exits 3).

#include <sstream>
#include <string>

#include "fuzz_input.hpp"
#include "slamd/app/config_reference.hpp"
#include "slamd/capture/camera_config.hpp"
#include "slamd/common/config.hpp"
#include "slamd/synth/synthetic_source.hpp"

namespace {

using namespace slamd;

void loadEveryModule(Config& config) {
  loadEveryConfigArea(config);
  CameraConfig::load(config, 1000.0);
  SyntheticConfig::load(config);  // with its check across the camera and synthetic areas
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
