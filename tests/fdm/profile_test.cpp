// fdm::stress_profile (the node's fdm_profile_<stage>.csv): under geostatic stress every layer
// of zones carries sigma_zz = -rho N g0 depth and sigma_xx = K0 sigma_zz at its mid-depth, top
// layer first, with every zone of the layer counted.
#include <gtest/gtest.h>

#include <cmath>

#include "demfdm/fdm/model.hpp"
#include "demfdm/fdm/profile.hpp"

using namespace demfdm::fdm;

TEST(FdmStressProfile, GeostaticLayersFollowTheSelfWeightLine) {
  ModelParams p;
  p.mesh = MeshParams::plain_box(2.0, 1.0, 3.0, 0.5);
  p.gravity_level = 1.0;
  Model m(p);
  GeostaticStress g;
  g.k0 = 0.5;
  m.set_geostatic_stress(g);
  const auto layers = stress_profile(m);
  ASSERT_EQ(layers.size(), 6u);
  const double rho = p.materials.front().material.density, g0 = kStandardGravity;
  for (std::size_t i = 0; i < layers.size(); ++i) {
    const auto& l = layers[i];
    EXPECT_NEAR(l.depth, 0.25 + 0.5 * static_cast<double>(i), 1e-12) << "layer " << i;
    EXPECT_EQ(l.zones, 8u) << "layer " << i;
    const double szz = -rho * g0 * l.depth;
    EXPECT_NEAR(l.szz, szz, 1e-9 * std::abs(szz)) << "layer " << i;
    EXPECT_NEAR(l.sxx, 0.5 * szz, 1e-9 * std::abs(szz)) << "layer " << i;
  }
}
