// slamd-test-inject: publishes malformed messages on an LCM channel, for the daemon scenarios:
// random bytes, and truncated or bit-flipped copies of a valid command_t.
//   slamd-test-inject CHANNEL COUNT [SEED]

#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "slamd/command_t.hpp"
#include "slamd/comms/lcm_bus.hpp"

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
    switch (i % 3) {
      case 0:  // random bytes of random length
        bytes.resize(1 + rng() % 2000);
        for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
        break;
      case 1:  // a valid message cut short
        bytes.assign(valid_bytes.begin(), valid_bytes.begin() + static_cast<long>(rng() % valid_bytes.size()));
        break;
      default:  // a valid fingerprint followed by a corrupted length field
        bytes = valid_bytes;
        for (std::size_t j = 8; j < bytes.size(); j += 3) bytes[j] = static_cast<std::uint8_t>(rng());
        bytes[17] = 0x7f;
        break;
    }
    if (!bus.publish(channel, bytes)) return 1;
  }
  std::cout << "published " << count << " malformed messages on " << channel << "\n";
  return 0;
}
