// slamd-test-flood: a camera on LCM at its normal rate, plus a flood around it, for the flood
// scenario and benchmark. Reads a TUM folder (slamd-synth's output), encodes each frame once as
// slamd.rgbd_frame_t (JPEG colour, zlib depth), then for --seconds publishes, in every frame
// period (1 / --rate-hz), --factor messages evenly spaced (default 10: ten times the camera's
// message rate):
//   the camera's frame, stamped now;
//   three more valid frames (the same image, stamped 1/10, 4/10 and 7/10 of a period later);
//   three malformed frames on the frame channel (cut short, bit-flipped, random bytes);
//   three commands: SAVE_MAP outside the save folder (refused), one with an INT32_MIN string
//   length (malformed), RESUME (valid, harmless).
// With --factor 1 it is only the camera. Prints what it published.
//
//   slamd-test-flood --source tum:DIR [--seconds 10] [--rate-hz 30] [--factor 10] [--seed 1]

#include <chrono>
#include <fstream>
#include <iostream>
#include <random>
#include <thread>

#include "slamd/capture/frame_source.hpp"
#include "slamd/command_t.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/common/time.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/frame_codec.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/comms/lcm_frame_publisher.hpp"
#include "slamd/sources/create_frame_source.hpp"

namespace {

using namespace slamd;
using Bytes = std::vector<std::uint8_t>;

std::vector<slamd::rgbd_frame_t> encodeAllFrames(const std::string& source_name, Config& config) {
  config.set("capture.pacing.mode", "fastest");
  std::unique_ptr<FrameSource> source = createFrameSource(source_name, config);
  source->open();
  FrameEncodeOptions options;  // JPEG colour, zlib depth: what slamd-play --publish sends
  std::vector<slamd::rgbd_frame_t> frames;
  while (true) {
    const FrameRead read = source->next(std::chrono::milliseconds(5000));
    if (read.status == FrameRead::Status::kEndOfStream) break;
    if (read.status == FrameRead::Status::kFrame)
      frames.push_back(encodeRgbdFrame(*read.frame, options));
  }
  source->close();
  return frames;
}

Bytes malformedCommand() {
  // command_t: hash, utime, command, then a string whose length field is INT32_MIN.
  Bytes bytes;
  const std::int64_t hash = slamd::command_t::getHash();
  for (int k = 0; k < 8; ++k) bytes.push_back(static_cast<std::uint8_t>(hash >> (56 - 8 * k)));
  bytes.resize(8 + 8 + 1, 0);
  for (const std::uint8_t b : {0x80, 0x00, 0x00, 0x00, 0x41, 0x42}) bytes.push_back(b);
  return bytes;
}

}  // namespace

int main(int argc, char** argv) {
  ProgramOptions options(
      "slamd-test-flood",
      "Publishes a camera on LCM at its rate, with a flood of valid and malformed "
      "frames and commands around it.");
  options.addOption("source", "SOURCE", "frames to publish (tum:DIR)");
  options.addOption("seconds", "S", "how long to publish (the frames loop)", "10");
  options.addOption("rate-hz", "HZ", "the camera's frame rate", "30");
  options.addOption("factor", "N", "messages per frame period (1 = the camera only)", "10");
  options.addOption("seed", "N", "seed of the corruptions", "1");
  options.addOption("started-file", "PATH", "created when publishing starts (frames are encoded)");
  if (!options.parse(argc, argv)) return options.exitCode();
  try {
    Config config = options.loadConfig();
    const ChannelConfig channels = ChannelConfig::load(config);
    const std::string frame_channel = LcmFramePublisherConfig::load(config).channel;
    const double seconds = std::stod(options.value("seconds"));
    const double rate_hz = std::stod(options.value("rate-hz"));
    const int factor = std::stoi(options.value("factor"));
    std::mt19937 random(static_cast<unsigned>(std::stoul(options.value("seed"))));
    const std::vector<slamd::rgbd_frame_t> frames =
        encodeAllFrames(options.value("source"), config);
    if (frames.empty()) throw std::runtime_error("no frames in " + options.value("source"));

    slamd::command_t refused_save;
    refused_save.command = slamd::command_t::SAVE_MAP;
    refused_save.argument = "../outside-the-save-folder.bt";
    slamd::command_t resume;
    resume.command = slamd::command_t::RESUME;
    const Bytes bad_command = malformedCommand();

    LcmBus bus(channels.lcm_url);
    if (options.has("started-file")) std::ofstream(options.value("started-file")) << "publishing\n";
    std::uint64_t camera = 0, valid_frames = 0, malformed_frames = 0, commands = 0,
                  malformed_commands = 0;
    const auto period = std::chrono::duration<double>(1.0 / rate_hz);
    const auto slot = period / factor;
    const auto start = std::chrono::steady_clock::now();
    const auto periods = static_cast<std::size_t>(seconds * rate_hz);
    for (std::size_t i = 0; i < periods; ++i) {
      slamd::rgbd_frame_t frame = frames[i % frames.size()];
      frame.sequence = static_cast<std::int64_t>(i);
      const Utime now = wallClockUtime();
      for (int k = 0; k < factor; ++k) {
        std::this_thread::sleep_until(
            start +
            std::chrono::duration_cast<std::chrono::steady_clock::duration>(period * i + slot * k));
        frame.utime = now + static_cast<Utime>(1e6 / rate_hz * k / factor);
        switch (k) {
          case 0:
            bus.publishMessage(frame_channel, frame);
            ++camera;
            break;
          case 1:
          case 4:
          case 7:
            bus.publishMessage(frame_channel, frame);
            ++valid_frames;
            break;
          case 2: {
            Bytes bytes = encodeMessage(frame);
            bytes.resize(random() % bytes.size());
            bus.publish(frame_channel, bytes);
            ++malformed_frames;
            break;
          }
          case 5: {
            Bytes bytes = encodeMessage(frame);
            for (int flip = 0; flip < 16; ++flip) bytes[8 + random() % (bytes.size() - 8)] ^= 0x5a;
            bus.publish(frame_channel, bytes);
            ++malformed_frames;
            break;
          }
          case 8: {
            Bytes bytes(1 + random() % 2000);
            for (auto& b : bytes) b = static_cast<std::uint8_t>(random());
            bus.publish(frame_channel, bytes);
            ++malformed_frames;
            break;
          }
          case 3:
            refused_save.utime = now;
            bus.publishMessage(channels.command, refused_save);
            ++commands;
            break;
          case 6:
            bus.publish(channels.command, bad_command);
            ++malformed_commands;
            break;
          default:
            resume.utime = now;
            bus.publishMessage(channels.command, resume);
            ++commands;
            break;
        }
      }
    }
    const double elapsed_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    std::cout << "published in " << elapsed_s << " s: " << camera << " camera frames, "
              << valid_frames << " extra valid frames, " << malformed_frames
              << " malformed frames, " << commands << " valid commands (SAVE_MAP outside the save "
              << "folder, RESUME), " << malformed_commands << " malformed commands; "
              << bus.publishFailures() << " publish failures\n";
  } catch (const std::exception& e) {
    std::cerr << "slamd-test-flood: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
