#pragma once
// Writing output files so that a failure is never silent and a crash never leaves half a file.
//
//   std::string error;
//   if (!writeOutputFile("trajectory.txt", [&](std::ostream& out) { out << text; return true; },
//                        &error)) {
//     report(error);   // "cannot write trajectory.txt: write failed: No space left on device"
//   }
//
// Every write, flush, fsync, close and rename is checked; errors carry strerror's text.

#include <cstddef>
#include <cstdint>
#include <functional>
#include <ostream>
#include <string>
#include <vector>

namespace slamd {

/// Writes a file crash-safely: into <path>.tmp, fsync, rename over <path>, fsync of the folder.
/// `writer` streams the content and returns false to abandon the write (the temporary file is
/// removed and <path> is untouched). Returns false with a sentence in *error on any failure
/// (writer refused, open/write/fsync/rename error).
bool writeFileAtomically(const std::string& path, const std::function<bool(std::ostream&)>& writer,
                         std::string* error = nullptr);

/// The temporary file name writeFileAtomically() uses for `path`.
std::string temporaryPathFor(const std::string& path);

/// writeFileAtomically() for a regular or new file; a device, FIFO or socket that already exists
/// (/dev/stdout, /dev/full, a pipe) is written in place with every write and the close checked.
/// A directory is an error.
bool writeOutputFile(const std::string& path, const std::function<bool(std::ostream&)>& writer,
                     std::string* error = nullptr);

/// Removes the temporary files an interrupted writeFileAtomically() left behind (a crash, power
/// cut or kill -9 between creating "<path>.tmp" and renaming it): "<path>.tmp" of every path in
/// `output_paths` (empty paths are skipped), and in `folder` (when not empty) every regular file
/// named "*<suffix>.tmp" for one of `suffixes` (e.g. ".bt", ".ot"). Only regular files are
/// removed. Returns the removed paths, for the caller to log.
std::vector<std::string> removeStaleTemporaryFiles(const std::vector<std::string>& output_paths,
                                                   const std::string& folder = "",
                                                   const std::vector<std::string>& suffixes = {});

/// The FNV-1a offset basis: the 64-bit FNV-1a hash of no bytes, where a hash starts.
inline constexpr std::uint64_t kFnv1a64Basis = 14695981039346656037ull;

/// 64-bit FNV-1a hash of `size` bytes at `data`, continuing from `hash`: a file checksummed in
/// pieces gives the same value as in one call (fnv1a64(b, nb, fnv1a64(a, na)) hashes a then b).
/// A checksum against accidental damage (vocabulary and session files), not against tampering.
std::uint64_t fnv1a64(const void* data, std::size_t size, std::uint64_t hash = kFnv1a64Basis);

/// Reads a whole regular file (a FIFO, directory or device is refused: reading one could block
/// forever or never end). Returns false and sets `error` when it cannot be read or is empty.
bool readFileBytes(const std::string& path, std::vector<std::uint8_t>& bytes, std::string& error);

}  // namespace slamd
