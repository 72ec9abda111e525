// slamd-cmd: sends a command to a running slamd daemon.
//
//   slamd-cmd save-map [FILE.bt|FILE.ot]   slamd-cmd publish-map   slamd-cmd save-session [NAME]
//   slamd-cmd pause | resume | reset | shutdown

#include <iostream>
#include <map>

#include "slamd/command_t.hpp"
#include "slamd/common/program_options.hpp"
#include "slamd/comms/channels.hpp"
#include "slamd/comms/lcm_bus.hpp"

int main(int argc, char** argv) {
  using namespace slamd;
  ProgramOptions options("slamd-cmd",
                         "Sends a command to slamd: save-map [FILE], publish-map, save-session "
                         "[NAME], pause, resume, reset, shutdown.");
  options.setPositional("COMMAND [ARGUMENT]", 1, 2);
  options.addOption("lcm-url", "URL", "LCM URL (overrides lcm.url)");
  if (!options.parse(argc, argv)) return options.exitCode();
  // Each constant is copied (std::int8_t{...}): lcm-gen declares them without a definition, so
  // binding one to a reference (std::pair's constructor) fails to link without optimisation.
  const std::map<std::string, std::int8_t> commands = {
      {"save-map", std::int8_t{slamd::command_t::SAVE_MAP}},
      {"publish-map", std::int8_t{slamd::command_t::PUBLISH_MAP}},
      {"save-session", std::int8_t{slamd::command_t::SAVE_SESSION}},
      {"pause", std::int8_t{slamd::command_t::PAUSE}},
      {"resume", std::int8_t{slamd::command_t::RESUME}},
      {"reset", std::int8_t{slamd::command_t::RESET}},
      {"shutdown", std::int8_t{slamd::command_t::SHUTDOWN}}};
  const auto command = commands.find(options.positional()[0]);
  if (command == commands.end()) {
    std::cerr << "slamd-cmd: unknown command '" << options.positional()[0] << "'\n\n"
              << options.usage();
    return kExitUsage;
  }
  try {
    Config config = options.loadConfig();
    if (options.has("lcm-url")) config.set("lcm.url", options.value("lcm-url"));
    const ChannelConfig channels = ChannelConfig::load(config);
    slamd::command_t message;
    message.utime = wallClockUtime();
    message.command = command->second;
    message.argument = options.positional().size() > 1 ? options.positional()[1] : "";
    LcmBus bus(channels.lcm_url);
    if (!bus.publishMessage(channels.command, message)) {
      std::cerr << "slamd-cmd: publishing on " << channels.command << " failed\n";
      return kExitFailure;
    }
    std::cout << "sent " << command->first
              << (message.argument.empty() ? "" : " " + message.argument) << " on "
              << channels.command << "\n";
  } catch (const std::exception& e) {
    std::cerr << "slamd-cmd: " << e.what() << "\n";
    return kExitFailure;
  }
  return kExitOk;
}
