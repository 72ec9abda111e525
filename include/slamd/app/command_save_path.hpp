#pragma once
// Where a SAVE_MAP command received over LCM may write. Any peer on the LCM network can send one,
// and slamd often runs as root, so the file it names is confined to daemon.save_dir:
//   - a bare file name: save_dir/NAME;
//   - an absolute path: accepted only when its folder is save_dir itself (after resolving "..",
//     "." and symbolic links of the folder);
//   - anything else (a relative path with folders, "..", an empty name) is refused.
// The name must be 1-128 characters of letters, digits, '.', '_' or '-', must not start with '.',
// and must end in .bt or .ot (the map formats). Paths from the command line or the configuration
// (--map-out, daemon.map_save_path) are the operator's and are not checked here.
//
//   std::string error;
//   auto path = resolveCommandSavePath(command.argument, daemon.save_dir, error);
//   if (!path) refuse(error);

#include <optional>
#include <string>

namespace slamd {

/// The path to write, or nullopt with `error` saying why the argument was refused.
std::optional<std::string> resolveCommandSavePath(const std::string& argument,
                                                  const std::string& save_dir, std::string& error);

/// The session folder a SAVE_SESSION command names: a bare name of the same characters (no
/// extension needed), made inside save_dir; nullopt with `error` saying why when refused.
std::optional<std::string> resolveCommandSessionPath(const std::string& argument,
                                                     const std::string& save_dir,
                                                     std::string& error);

}  // namespace slamd
