// Fuzz target: commands from the network. The first byte chooses what the rest is:
//   even  a slamd.command_t message, decoded as the daemon's subscriber does, then its argument
//         resolved against the save directory as SAVE_MAP does;
//   odd   a bare SAVE_MAP argument, resolved directly (reaches the name rules faster).
// The save directory exists (a fresh temporary folder), so resolution reaches the filesystem.

#include <cstdlib>
#include <filesystem>
#include <string>

#include "../support/scoped_temp_dir.hpp"
#include "fuzz_input.hpp"
#include "slamd/app/command_save_path.hpp"
#include "slamd/comms/message_codec.hpp"

namespace {

// Removed at normal exit by the static's destructor (libFuzzer ends with exit()).
const std::string& saveDirectory() {
  static const slamd::test::ScopedTempDir directory("fuzz-commands");
  static const std::string path = directory.path().string();
  return path;
}

void checkResolution(const std::string& argument) {
  std::string error;
  const auto path = slamd::resolveCommandSavePath(argument, saveDirectory(), error);
  // The contract: an accepted path is a file directly inside the save directory, and a refusal
  // logs the argument without control characters (no forged log lines).
  namespace fs = std::filesystem;
  if (path && fs::weakly_canonical(fs::path(*path).parent_path()) !=
                  fs::weakly_canonical(saveDirectory())) {
    std::abort();
  }
  if (!path && error.find_first_of("\n\r") != std::string::npos) std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  slamd::fuzz::FuzzInput input(data, size);
  const bool as_message = input.byte() % 2 == 0;
  const std::vector<std::uint8_t> bytes = input.rest();
  if (as_message) {
    if (auto command = slamd::decodeMessage<slamd::command_t>(bytes.data(), bytes.size())) {
      checkResolution(command->argument);
    }
  } else {
    checkResolution(std::string(bytes.begin(), bytes.end()));
  }
  return 0;
}
