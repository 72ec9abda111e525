#include "slamd/common/memory_pressure.hpp"

#include <vector>

#include <gtest/gtest.h>

namespace slamd {
namespace {

TEST(MemoryGovernor, RaisesAt80And100PercentAndLowersOnlyWellBelow) {
  MemoryGovernor governor(400.0);
  EXPECT_EQ(governor.update(300.0), MemoryPressure::kNone);
  EXPECT_EQ(governor.update(321.0), MemoryPressure::kNear);  // above 80%
  EXPECT_EQ(governor.update(310.0), MemoryPressure::kNear);  // hysteresis: not below 75% yet
  EXPECT_EQ(governor.update(401.0), MemoryPressure::kOver);
  EXPECT_EQ(governor.update(390.0), MemoryPressure::kOver);  // not below 95% yet
  EXPECT_EQ(governor.update(370.0), MemoryPressure::kNear);
  EXPECT_EQ(governor.update(299.0), MemoryPressure::kNone);
  // From none straight over, and from over straight back to none.
  EXPECT_EQ(governor.update(500.0), MemoryPressure::kOver);
  EXPECT_EQ(governor.update(100.0), MemoryPressure::kNone);
  EXPECT_EQ(governor.level(), MemoryPressure::kNone);
}

TEST(MemoryGovernor, WithoutALimitThereIsNoPressure) {
  MemoryGovernor governor(0.0);
  for (double resident_mb : {1.0, 1e3, 1e6}) {
    EXPECT_EQ(governor.update(resident_mb), MemoryPressure::kNone);
  }
}

TEST(ResidentMegabytes, GrowsWhenThisProcessTouchesMemory) {
  const std::optional<double> before = residentMegabytes();
  ASSERT_TRUE(before.has_value());
  EXPECT_GT(*before, 1.0);
  std::vector<char> block(64u << 20, 1);  // 64 MB, every page written
  const std::optional<double> after = residentMegabytes();
  ASSERT_TRUE(after.has_value());
  EXPECT_GT(*after, *before + 50.0);
  EXPECT_EQ(block[block.size() / 2], 1);
}

}  // namespace
}  // namespace slamd
