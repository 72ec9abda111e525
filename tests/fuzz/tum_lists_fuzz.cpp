// Fuzz target: TUM RGB-D list files (rgb.txt, depth.txt, associations) and trajectory files
// (groundtruth.txt, slamd-eval's inputs). The first byte chooses the parser; parsed lists are
// also associated, as TumSource does with rgb.txt and depth.txt.

#include <stdexcept>
#include <string>

#include "fuzz_input.hpp"
#include "slamd/capture/tum_dataset.hpp"
#include "slamd/common/trajectory.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  slamd::fuzz::FuzzInput input(data, size);
  const std::uint8_t kind = input.byte() % 3;
  const std::string text = input.restAsString();
  switch (kind) {
    case 0: {
      // Split in two at the first form feed: the colour list, then the depth list.
      const std::size_t split = text.find('\f');
      const auto rgb = slamd::parseTumFileList(text.substr(0, split), "rgb.txt");
      const auto depth = slamd::parseTumFileList(
          split == std::string::npos ? std::string() : text.substr(split + 1), "depth.txt");
      std::vector<double> rgb_stamps, depth_stamps;
      for (const auto& entry : rgb.entries) rgb_stamps.push_back(entry.timestamp_s);
      for (const auto& entry : depth.entries) depth_stamps.push_back(entry.timestamp_s);
      slamd::associateTimestamps(rgb_stamps, depth_stamps, 0.02);
      break;
    }
    case 1:
      slamd::parseTumAssociations(text, "associations.txt");
      break;
    case 2:
      try {
        slamd::parseTumTrajectory(text, "groundtruth.txt");
      } catch (const std::runtime_error&) {
        // parseTumTrajectory documents std::runtime_error for malformed text.
      }
      break;
  }
  return 0;
}
