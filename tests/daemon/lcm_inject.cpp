// slamd-test-inject: publishes malformed messages on an LCM channel, for the daemon scenarios:
// random bytes, truncated or bit-flipped copies of a valid command_t, and the 23-byte command_t
// whose string length is INT32_MIN (once a SIGSEGV in any receiver; its fingerprint is replaced by
// the channel's type when the channel is SLAMD_POSE or SLAMD_STATUS).
//   slamd-test-inject CHANNEL COUNT [SEED]

#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "slamd/command_t.hpp"
#include "slamd/comms/lcm_bus.hpp"
#include "slamd/pose_t.hpp"
#include "slamd/status_t.hpp"

int main(int argc, char** argv) {
  if (argc < 3) {
    std::cerr << "usage: slamd-test-inject CHANNEL COUNT [SEED]\n";
    return 2;
  }
  const std::string channel = argv[1];
  const int count = std::stoi(argv[2]);
  std::mt19937 rng(argc > 3 ? static_cast<unsigned>(std::stoul(argv[3])) : 42u);
  slamd::command_t valid;
  valid.utime = 1;
  valid.command = slamd::command_t::PAUSE;
  valid.argument = "never delivered intact";
  const std::vector<std::uint8_t> valid_bytes = slamd::encodeMessage(valid);
  slamd::LcmBus bus("");
  for (int i = 0; i < count; ++i) {
    std::vector<std::uint8_t> bytes;
    switch (i % 4) {
      case 0:  // random bytes of random length
        bytes.resize(1 + rng() % 2000);
        for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
        break;
      case 1:  // a valid message cut short
        bytes.assign(valid_bytes.begin(),
                     valid_bytes.begin() + static_cast<long>(rng() % valid_bytes.size()));
        break;
      case 2:  // a valid fingerprint followed by a corrupted length field
        bytes = valid_bytes;
        for (std::size_t j = 8; j < bytes.size(); j += 3)
          bytes[j] = static_cast<std::uint8_t>(rng());
        bytes[17] = 0x7f;
        break;
      default: {  // a valid fingerprint, then a string whose length field is INT32_MIN
        // The fields before the first string: command_t utime, command; pose_t utime, sequence;
        // status_t utime, num_stages 0, three latencies, tracking state, two voxel counts, three
        // counters, resident memory, memory limit, memory pressure.
        std::int64_t hash = slamd::command_t::getHash();
        std::size_t before_string = 8 + 1;
        if (channel == "SLAMD_POSE") {
          hash = slamd::pose_t::getHash();
          before_string = 8 + 8;
        } else if (channel == "SLAMD_STATUS") {
          hash = slamd::status_t::getHash();
          before_string = 8 + 4 + 3 * 8 + 1 + 2 * 8 + 3 * 4 + 8 + 4 + 1;
        }
        for (int k = 0; k < 8; ++k)
          bytes.push_back(static_cast<std::uint8_t>(hash >> (56 - 8 * k)));
        bytes.resize(8 + before_string, 0);
        for (const std::uint8_t b : {0x80, 0x00, 0x00, 0x00, 0x41, 0x42}) bytes.push_back(b);
        break;
      }
    }
    if (!bus.publish(channel, bytes)) return 1;
  }
  std::cout << "published " << count << " malformed messages on " << channel << "\n";
  return 0;
}
