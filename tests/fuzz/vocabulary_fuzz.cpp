// Fuzz target: vocabulary files (backend.vocabulary_file). Vocabulary::read must reject anything
// but a well-formed tree with a sentence, never crash or allocate for sizes the bytes cannot hold.
//
// Files end in an FNV-1a checksum of everything between the magic and the checksum. Random
// mutations would nearly always fail it, so when the first input byte is odd the harness
// rewrites the checksum to match: the fuzzer then reaches the tree checks behind it.

#include <cstring>
#include <sstream>
#include <string>

#include <opencv2/core.hpp>

#include "fuzz_input.hpp"
#include "slamd/backend/vocabulary.hpp"

namespace {

constexpr std::size_t kMagicBytes = 8;

void fixChecksum(std::string& file) {
  if (file.size() < kMagicBytes + 8) return;
  std::uint64_t hash = 14695981039346656037ull;
  for (std::size_t i = kMagicBytes; i < file.size() - 8; ++i) {
    hash ^= static_cast<std::uint8_t>(file[i]);
    hash *= 1099511628211ull;
  }
  std::memcpy(&file[file.size() - 8], &hash, sizeof(hash));
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  slamd::fuzz::FuzzInput input(data, size);
  const bool fix_checksum = input.byte() % 2 == 1;
  std::string file = input.restAsString();
  if (fix_checksum) fixChecksum(file);
  std::istringstream in(file, std::ios::binary);
  slamd::Vocabulary vocabulary;
  std::string error;
  if (vocabulary.read(in, &error)) {
    // A vocabulary that reads must also work: look up words for a few descriptors.
    cv::Mat descriptors(4, 32, CV_8UC1);
    cv::randu(descriptors, 0, 256);
    vocabulary.transform(descriptors);
  }
  return 0;
}
