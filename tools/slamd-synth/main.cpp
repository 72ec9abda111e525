// slamd-synth: renders one of slamd's synthetic worlds along a trajectory and writes it as a TUM
// RGB-D benchmark folder (rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt).
//
//   slamd-synth --scene corridor --trajectory zigzag --frames 300 --seed 42 --out /tmp/corridor
//   slamd-synth --scene room --out /tmp/room --set synthetic.sensor.exact=true
//
// --scene/--trajectory/--frames/--seed set synthetic.* and win over --config and --set.
// Exit codes: 2 usage, 3 configuration, 4 unknown scene, 5 output folder not writable.

#include <iostream>
#include <string>

#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/synth/synthetic_source.hpp"
#include "slamd/synth/tum_writer.hpp"

int main(int argc, char** argv) {
  using namespace slamd;
  ProgramOptions options("slamd-synth",
                         "Renders a synthetic RGB-D sequence with exact ground truth as a TUM "
                         "RGB-D folder.");
  options.addOption("scene", "SCENE", "corridor | corridor_loop | room", "corridor");
  options.addOption("trajectory", "KIND", "auto | zigzag | random | robot | loop (auto: per scene)");
  options.addOption("frames", "N", "frame count (0 = the trajectory's natural length)");
  options.addOption("seed", "S", "seed of the scene, motion and sensor noise");
  options.addOption("out", "DIR", "output folder (created)");
  if (!options.parse(argc, argv)) return options.exitCode();
  if (!options.has("out")) {
    std::cerr << "slamd-synth: --out DIR is required\n" << options.usage();
    return kExitUsage;
  }
  const std::string scene = options.value("scene");
  const std::string out = options.value("out");

  std::unique_ptr<SyntheticSource> source;
  try {
    Config config = options.loadConfig();
    if (options.has("trajectory")) config.set("synthetic.trajectory", options.value("trajectory"));
    if (options.has("frames")) config.set("synthetic.frames", options.value("frames"));
    if (options.has("seed")) config.set("synthetic.seed", options.value("seed"));
    source = std::make_unique<SyntheticSource>(scene, SyntheticConfig::load(config));
    reportConfig(config, "slamd-synth");
  } catch (const ConfigError& error) {
    std::cerr << "slamd-synth: " << error.what() << "\n";
    return kExitConfigError;
  } catch (const SourceError& error) {
    std::cerr << "slamd-synth: " << error.what() << "\n";
    return kExitSourceError;
  }

  try {
    source->open();
    // camera.depth_scale (default 5000, the TUM factor) so that the same configuration reads the
    // folder back with `tum:DIR`.
    TumSequenceWriter writer(out, "slamd-synth " + source->description(),
                             source->config().camera.depth_scale);
    writer.open();
    while (true) {
      const FrameRead read = source->next(std::chrono::milliseconds(1000));
      if (read.status == FrameRead::Status::kEndOfStream) break;
      if (read.status != FrameRead::Status::kFrame) continue;
      writer.write(*read.frame);
      if (writer.framesWritten() % 100 == 0) {
        SLAMD_LOG_INFO("slamd-synth") << writer.framesWritten() << " frames written";
      }
    }
    writer.finish(source->groundTruth().value_or(Trajectory{}));
    source->close();
    SLAMD_LOG_INFO("slamd-synth") << "wrote " << writer.framesWritten() << " frames of "
                                  << source->description() << " to " << out;
  } catch (const std::exception& error) {
    std::cerr << "slamd-synth: " << error.what() << "\n";
    return kExitOutputError;
  }
  return kExitOk;
}
