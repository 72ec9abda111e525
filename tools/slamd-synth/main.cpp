// slamd-synth: renders one of slamd's synthetic worlds along a trajectory and writes it as a TUM
// RGB-D benchmark folder (rgb/, depth/, rgb.txt, depth.txt, groundtruth.txt).
//
//   slamd-synth --scene corridor --trajectory zigzag --frames 300 --seed 42 --out /tmp/corridor
//   slamd-synth --scene room --out /tmp/room --set synthetic.sensor.exact=true
//   slamd-synth --scene room --out /tmp/room --images uncompressed   # for real-time replay
//
// --scene/--trajectory/--frames/--seed set synthetic.* and win over --config and --set.
// Frames are rendered --threads at a time (default: one per core) and written in order.
// Exit codes: 2 usage, 3 configuration, 4 unknown scene, 5 output folder not writable.

#include <algorithm>
#include <deque>
#include <future>
#include <iostream>
#include <string>
#include <thread>

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
  options.addOption("trajectory", "KIND",
                    "auto | zigzag | random | robot | loop (auto: per scene)");
  options.addOption("frames", "N", "frame count (0 = the trajectory's natural length)");
  options.addOption("seed", "S", "seed of the scene, motion and sensor noise");
  options.addOption("out", "DIR", "output folder (created)");
  options.addOption("threads", "N", "frames rendered at once (default: the machine's cores)");
  options.addOption("images", "FORMAT",
                    "png | uncompressed (PPM/PGM: larger, but cheap to read in real time)", "png");
  if (!options.parse(argc, argv)) return options.exitCode();
  if (!options.has("out")) {
    std::cerr << "slamd-synth: --out DIR is required\n" << options.usage();
    return kExitUsage;
  }
  const std::string scene = options.value("scene");
  const std::string out = options.value("out");
  const std::optional<TumImageFormat> image_format = parseTumImageFormat(options.value("images"));
  if (!image_format) {
    std::cerr << "slamd-synth: --images " << options.value("images")
              << " is not png or uncompressed\n";
    return kExitUsage;
  }
  int threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  if (options.has("threads")) {
    try {
      threads = std::stoi(options.value("threads"));
    } catch (const std::exception&) {
      threads = 0;
    }
    if (threads < 1 || threads > 256) {
      std::cerr << "slamd-synth: --threads " << options.value("threads")
                << " is not a thread count (1..256)\n";
      return kExitUsage;
    }
  }

  std::unique_ptr<SyntheticSource> source;
  try {
    Config config = options.loadConfig();
    if (options.has("trajectory")) config.set("synthetic.trajectory", options.value("trajectory"));
    if (options.has("frames")) config.set("synthetic.frames", options.value("frames"));
    if (options.has("seed")) config.set("synthetic.seed", options.value("seed"));
    source = std::make_unique<SyntheticSource>(scene, SyntheticConfig::load(config));
    reportConfig(config, "slamd-synth", UnknownKeys::kInSectionsItRead);
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
                             source->config().camera.depth_scale, *image_format);
    writer.open();
    // Frames depend only on their index: render `threads` of them at once, write them in order.
    std::deque<std::future<RgbdFramePtr>> rendering;
    int next_index = 0;
    auto renderNext = [&] {
      rendering.push_back(std::async(std::launch::async, [&source, index = next_index] {
        return source->renderFrame(index);
      }));
      ++next_index;
    };
    while (static_cast<int>(rendering.size()) < threads && next_index < source->frameCount()) {
      renderNext();
    }
    while (!rendering.empty()) {
      const RgbdFramePtr frame = rendering.front().get();
      rendering.pop_front();
      if (next_index < source->frameCount()) renderNext();
      writer.write(*frame);
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
