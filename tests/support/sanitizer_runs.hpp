#pragma once
// Whole-sequence accuracy tests in the sanitizer builds (`make tsan`, `make asan-ubsan`).
//
// A sanitizer runs slamd's code three to six times slower, and it can fail a run but never change
// the run's numbers: accuracy over a whole sequence is checked in the release build, where the unit
// stage of `make test` runs every such test in full. Under a sanitizer such a test runs a prefix of
// its sequence, long enough to take the code paths the whole run takes, so the sanitizer checks
// them, and then skips its accuracy checks, saying so.

#include <gtest/gtest.h>

namespace slamd::test {

#if defined(SLAMD_SANITIZED_BUILD)
inline constexpr bool kSanitizedBuild = true;
#else
inline constexpr bool kSanitizedBuild = false;
#endif

/// The frames a whole-sequence accuracy run takes: all of them (0) in a release build,
/// `prefix_frames` under a sanitizer.
inline int accuracyRunFrames(int prefix_frames) { return kSanitizedBuild ? prefix_frames : 0; }

}  // namespace slamd::test

/// Ends a whole-sequence accuracy test after its (prefix) run under a sanitizer, before the
/// checks that need the whole sequence.
#define SLAMD_SKIP_ACCURACY_CHECKS_UNDER_SANITIZER()                                           \
  if (::slamd::test::kSanitizedBuild)                                                          \
  GTEST_SKIP() << "sanitizer build: ran a prefix of the sequence for the sanitizer's checks; " \
                  "accuracy over the whole sequence is checked by the release build's unit stage"
