// slamd-play: reads any frame source, prints its rate and statistics, and optionally republishes
// the frames on LCM (slamd.rgbd_frame_t) and/or writes them as a TUM-format folder.
//
//   slamd-play --source tum:/data/fr1_xyz --config config/tum_fr1.yaml
//   slamd-play --source openni2 --config config/xtion.yaml --publish --lcm-url udpm://...
//   slamd-play --source lcm:SLAMD_FRAMES --write-tum /tmp/capture --set camera.depth_scale=1000
//   slamd-play --source tum:/data/fr1_xyz --config config/tum_fr1.yaml --write-tum /tmp/fr1
//       --images uncompressed --set capture.preprocess.range_gate=false
//       --set capture.preprocess.flying_pixels=false      (one command: decoded once, to replay)

#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>

#include <lcm/lcm-cpp.hpp>

#include "slamd/common/log.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/sources/create_frame_source.hpp"
#ifdef SLAMD_HAVE_TUM_WRITER
#include "slamd/synth/tum_writer.hpp"
#endif

namespace {

std::atomic<bool> g_stop{false};

extern "C" void onSignal(int /*signal*/) { g_stop.store(true); }

struct PlayConfig {
  double stats_interval_s = 1.0;  ///< play.stats_interval_s, (0, 3600]
  int max_frames = 0;             ///< play.max_frames, 0 = all
  double timeout_s = 0.0;         ///< play.timeout_s: give up after this long without a frame

  static PlayConfig load(slamd::Config& config) {
    PlayConfig out;
    out.stats_interval_s =
        config.getDouble("play.stats_interval_s", out.stats_interval_s, 1e-3, 3600.0);
    out.max_frames = config.getInt("play.max_frames", out.max_frames, 0, 100'000'000);
    out.timeout_s = config.getDouble("play.timeout_s", out.timeout_s, 0.0, 1e6);
    return out;
  }
};

std::string summaryText(const slamd::LatencySummary& s) {
  std::ostringstream out;
  out.setf(std::ios::fixed);
  out.precision(2);
  out << "p50 " << s.p50_ms << " ms, p95 " << s.p95_ms << " ms, max " << s.max_ms << " ms (n "
      << s.count << ")";
  return out.str();
}

// One line per frame (--list): enough to compare two runs frame by frame.
void printFrame(const slamd::RgbdFrame& frame) {
  double depth_sum = 0.0;
  int valid = 0;
  for (int r = 0; r < frame.depth_m.rows; ++r) {
    const auto* row = frame.depth_m.ptr<float>(r);
    for (int c = 0; c < frame.depth_m.cols; ++c) {
      if (row[c] > 0.0f) {
        depth_sum += static_cast<double>(row[c]);
        ++valid;
      }
    }
  }
  const cv::Scalar color_sum = frame.color_bgr.empty() ? cv::Scalar() : cv::sum(frame.color_bgr);
  std::printf("frame %lld utime %lld size %dx%d depth_valid %d depth_sum_m %.4f color_sum %.0f\n",
              static_cast<long long>(frame.sequence), static_cast<long long>(frame.utime),
              frame.depth_m.cols, frame.depth_m.rows, valid, depth_sum,
              color_sum[0] + color_sum[1] + color_sum[2]);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace slamd;
  ProgramOptions options("slamd-play",
                         "Reads an RGB-D source and reports its rate and statistics; optionally "
                         "republishes it on LCM and/or writes a TUM-format folder.");
  options.addOption("source", "SPEC", frameSourceSpecHelp());
  options.addOption("lcm-url", "URL", "LCM URL for --publish and lcm: sources (default: LCM's)");
  options.addOption("write-tum", "DIR", "write the frames as a TUM RGB-D folder");
  options.addOption("images", "FORMAT",
                    "images --write-tum writes: png | uncompressed (PPM/PGM: larger, but cheap to "
                    "read in real time)",
                    "png");
  options.addFlag("publish", "publish frames as slamd.rgbd_frame_t (capture.publish.*)");
  options.addFlag("list", "print one line per frame (sequence, utime, depth and colour sums)");
  if (!options.parse(argc, argv)) return options.exitCode();
  if (!options.has("source")) {
    std::cerr << "slamd-play: --source is required\n" << options.usage();
    return kExitUsage;
  }

  std::unique_ptr<FrameSource> source;
  std::unique_ptr<lcm::LCM> lcm;
  std::unique_ptr<LcmFramePublisher> publisher;
  PlayConfig play;
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    source = createFrameSource(options.value("source"), config);
    play = PlayConfig::load(config);
    if (options.flag("publish")) {
      const LcmFramePublisherConfig publish_config = LcmFramePublisherConfig::load(config);
      lcm = std::make_unique<lcm::LCM>(options.value("lcm-url"));
      if (!lcm->good()) {
        std::cerr << "slamd-play: cannot start LCM with URL '" << options.value("lcm-url") << "'\n";
        return kExitFailure;
      }
      publisher = std::make_unique<LcmFramePublisher>(*lcm, publish_config);
    }
    reportConfig(config, "slamd-play", UnknownKeys::kInSectionsItRead);
  } catch (const ConfigError& e) {
    std::cerr << "slamd-play: configuration error: " << e.what() << "\n";
    return kExitConfigError;
  } catch (const SourceError& e) {
    std::cerr << "slamd-play: " << e.what() << "\n";
    return kExitSourceError;
  }

#ifdef SLAMD_HAVE_TUM_WRITER
  std::unique_ptr<TumSequenceWriter> writer;
#endif
  if (options.has("write-tum")) {
#ifdef SLAMD_HAVE_TUM_WRITER
    const std::optional<TumImageFormat> format = parseTumImageFormat(options.value("images"));
    if (!format) {
      std::cerr << "slamd-play: --images " << options.value("images")
                << " is not png or uncompressed\n";
      return kExitUsage;
    }
    writer = std::make_unique<TumSequenceWriter>(options.value("write-tum"),
                                                 "slamd-play " + options.value("source"), 5000.0,
                                                 *format);  // the benchmark's scale
    try {
      writer->open();
    } catch (const std::exception& e) {
      std::cerr << "slamd-play: " << e.what() << "\n";
      return kExitOutputError;
    }
#else
    std::cerr << "slamd-play: --write-tum needs the synth area (TumSequenceWriter), not built\n";
    return kExitUsage;
#endif
  }

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  try {
    source->open();
  } catch (const SourceError& e) {
    std::cerr << "slamd-play: " << e.what() << "\n";
    return kExitSourceError;
  }
  SLAMD_LOG_INFO("slamd-play") << "reading " << source->description();

  const std::int64_t start_ns = steadyNowNs();
  std::int64_t last_report_ns = start_ns;
  std::int64_t last_frame_ns = start_ns;
  std::uint64_t frames = 0;
  std::uint64_t frames_at_last_report = 0;
  int exit_code = kExitOk;
  auto report = [&](std::int64_t now_ns, bool final_line) {
    const FrameSourceStats s = source->stats();
    const double interval_s = static_cast<double>(now_ns - last_report_ns) * 1e-9;
    const double total_s = static_cast<double>(now_ns - start_ns) * 1e-9;
    const double rate = final_line ? (total_s > 0 ? static_cast<double>(frames) / total_s : 0.0)
                                   : static_cast<double>(frames - frames_at_last_report) /
                                         std::max(interval_s, 1e-9);
    std::fprintf(
        stderr,
        "%s %.1f s: %llu frames, %.1f Hz; skipped %llu, dropped %llu, reconnects %llu%s%s\n",
        final_line ? "total" : "at", total_s, static_cast<unsigned long long>(frames), rate,
        static_cast<unsigned long long>(s.frames_skipped),
        static_cast<unsigned long long>(s.frames_dropped),
        static_cast<unsigned long long>(s.reconnects),
        s.last_error.empty() ? "" : "; last error: ", s.last_error.c_str());
    last_report_ns = now_ns;
    frames_at_last_report = frames;
  };

  while (!g_stop.load()) {
    const FrameRead read = source->next(std::chrono::milliseconds(100));
    const std::int64_t now_ns = steadyNowNs();
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status == FrameRead::Status::kFrame) {
      ++frames;
      last_frame_ns = now_ns;
      if (options.flag("list")) printFrame(*read.frame);
      if (publisher) publisher->publish(*read.frame);
#ifdef SLAMD_HAVE_TUM_WRITER
      if (writer) {
        try {
          writer->write(*read.frame);
        } catch (const std::exception& e) {
          std::cerr << "slamd-play: " << e.what() << "\n";
          exit_code = kExitOutputError;
          break;
        }
      }
#endif
      if (play.max_frames > 0 && frames >= static_cast<std::uint64_t>(play.max_frames)) break;
    }
    if (play.timeout_s > 0.0 &&
        static_cast<double>(now_ns - last_frame_ns) * 1e-9 > play.timeout_s) {
      std::cerr << "slamd-play: no frame for " << play.timeout_s << " s, stopping\n";
      exit_code = kExitSourceError;
      break;
    }
    if (static_cast<double>(now_ns - last_report_ns) * 1e-9 >= play.stats_interval_s) {
      report(now_ns, false);
    }
  }
  source->close();
  report(steadyNowNs(), true);
  if (const PreprocessedSource* pre = findPreprocessing(*source)) {
    const PreprocessingStats t = pre->timings();
    std::fprintf(stderr, "source next() per frame: %s\n", summaryText(t.source_next).c_str());
    std::fprintf(stderr, "pre-processing per frame: %s\n", summaryText(t.preprocess).c_str());
    if (t.range_gate.count)
      std::fprintf(stderr, "  range gate: %s\n", summaryText(t.range_gate).c_str());
    if (t.flying_pixels.count) {
      std::fprintf(stderr, "  flying pixels: %s\n", summaryText(t.flying_pixels).c_str());
    }
    if (t.bilateral.count)
      std::fprintf(stderr, "  bilateral: %s\n", summaryText(t.bilateral).c_str());
  }
  if (publisher) {
    std::fprintf(stderr, "published %llu frames (%.1f MB) on %s, %llu failures\n",
                 static_cast<unsigned long long>(publisher->published()),
                 static_cast<double>(publisher->bytesPublished()) / 1e6,
                 publisher->config().channel.c_str(),
                 static_cast<unsigned long long>(publisher->failures()));
  }
#ifdef SLAMD_HAVE_TUM_WRITER
  if (writer && exit_code == kExitOk) {
    try {
      const auto ground_truth = source->groundTruth();
      writer->finish(ground_truth ? *ground_truth : Trajectory{});
      std::fprintf(stderr, "wrote %d frames to %s\n", writer->framesWritten(),
                   options.value("write-tum").c_str());
    } catch (const std::exception& e) {
      std::cerr << "slamd-play: " << e.what() << "\n";
      exit_code = kExitOutputError;
    }
  }
#endif
  std::fflush(stdout);
  return exit_code;
}
