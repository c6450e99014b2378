// The kinetic-energy jump test of the blow-up guard (node::EnergyJump, docs/stability.md).
#include <gtest/gtest.h>

#include "common/node/node_runtime.hpp"

using demfdm::node::EnergyJump;

// A start from rest is measured against the floor; growth by less than the factor over the
// window's maximum never trips; a larger jump trips at that check.
TEST(EnergyJump, FloorAndFactor) {
  EnergyJump j(100.0, 1e-6, 3);
  EXPECT_FALSE(j.check(0.0));
  EXPECT_FALSE(j.check(5e-5));  // reference: the floor 1e-6 -> limit 1e-4
  EXPECT_FALSE(j.check(4e-3));  // reference 5e-5 -> limit 5e-3
  EXPECT_FALSE(j.check(0.3));   // reference 4e-3 -> limit 0.4
  auto r = j.check(31.0);       // reference 0.3 -> limit 30
  ASSERT_TRUE(r.has_value());
  EXPECT_NE(r->find("kinetic energy jumped to 31"), std::string::npos) << *r;
}

// Values older than the window are forgotten: after a peak of 1 J and two quiet checks the
// reference is the floor 0.1 J, so 2 J trips with a window of 2 but not with a window of 3
// (reference 1 J, limit 10 J).
TEST(EnergyJump, WindowForgetsOldPeaks) {
  for (std::size_t window : {2u, 3u}) {
    EnergyJump j(10.0, 0.1, window);
    EXPECT_FALSE(j.check(1.0));
    EXPECT_FALSE(j.check(1e-3));
    EXPECT_FALSE(j.check(1e-3));
    EXPECT_EQ(j.check(2.0).has_value(), window == 2) << "window " << window;
  }
}

TEST(EnergyJump, FactorZeroIsOff) {
  EnergyJump j(0.0, 1e-6, 3);
  EXPECT_FALSE(j.check(0.0));
  EXPECT_FALSE(j.check(1e30));
}
