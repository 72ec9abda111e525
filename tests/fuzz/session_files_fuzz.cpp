// Fuzz target: the session files a later run loads (--session-in): keyframes.bin and graph.bin
// (parseBackendFiles, after the manifest's checks) and keyframe_clouds.bin
// (readKeyframeCloudRecords). Each must reject anything malformed with a sentence (SessionError,
// or false with an error), never crash or allocate for sizes the bytes cannot hold.
//
// First byte: bit 0 selects the file (0: keyframes.bin + graph.bin, 1: keyframe_clouds.bin).
//   keyframes.bin + graph.bin: two bytes give the length of keyframes.bin, the rest is graph.bin.
//   keyframe_clouds.bin ends in an FNV-1a checksum of the bytes before it; with bit 1 set the
//   harness rewrites it to match, so that the fuzzer reaches the record checks behind it.

#include <unistd.h>

#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "fuzz_input.hpp"
#include "slamd/backend/session.hpp"
#include "slamd/common/file_io.hpp"
#include "slamd/mapping/keyframe_cloud_io.hpp"

namespace {

void fixChecksum(std::vector<std::uint8_t>& file) {
  if (file.size() < 8) return;
  const std::uint64_t hash = slamd::fnv1a64(file.data(), file.size() - 8);
  for (int i = 0; i < 8; ++i)
    file[file.size() - 8 + i] = static_cast<std::uint8_t>(hash >> (8 * i));
}

/// The clouds reader takes a path: one scratch file per process.
const std::string& scratchPath() {
  static const std::string path =
      "/tmp/slamd-fuzz-keyframe-clouds-" + std::to_string(::getpid()) + ".bin";
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  slamd::fuzz::FuzzInput input(data, size);
  const std::uint8_t selector = input.byte();
  if ((selector & 1) == 0) {
    const std::vector<std::uint8_t> keyframes = input.bytes(input.uint16());
    const std::vector<std::uint8_t> graph = input.rest();
    try {
      const slamd::BackendSnapshot snapshot = slamd::parseBackendFiles(keyframes, graph, "fuzz");
      // A snapshot that parses is consistent: every node is a keyframe.
      if (snapshot.nodes.size() != snapshot.keyframes.size()) __builtin_trap();
    } catch (const slamd::SessionError&) {
    }
    return 0;
  }
  std::vector<std::uint8_t> file = input.rest();
  if ((selector & 2) != 0) fixChecksum(file);
  {
    std::ofstream out(scratchPath(), std::ios::binary | std::ios::trunc);
    out.write(reinterpret_cast<const char*>(file.data()),
              static_cast<std::streamsize>(file.size()));
  }
  std::vector<slamd::KeyframeCloudRecord> records;
  std::string error;
  if (!slamd::readKeyframeCloudRecords(scratchPath(), records, &error) && error.empty()) {
    __builtin_trap();  // a refusal must say why
  }
  return 0;
}
