// fem::check_finite (the FEM node's blow-up guard): nothing on a solved column; a NaN load makes
// non-finite displacements, and the finding names the first such gridpoint, its position and
// the zones around it.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "demfdm/fem/guard.hpp"
#include "demfdm/fem/model.hpp"

using namespace demfdm;

namespace {

fem::Params column() {
  fem::Params p;
  p.mesh = fdm::MeshParams::plain_box(1e-3, 1e-3, 2e-3, 0.5e-3);
  p.gravity = {0.0, 0.0, -981.0};
  return p;
}

bool finite_at(const std::vector<double>& u, std::size_t g) {
  return std::isfinite(u[3 * g]) && std::isfinite(u[3 * g + 1]) && std::isfinite(u[3 * g + 2]);
}

}  // namespace

TEST(FemGuard, FiniteStateHasNoFinding) {
  fem::Model m(column());
  m.solve();
  EXPECT_FALSE(fem::check_finite(m).has_value());
}

TEST(FemGuard, NonFiniteDisplacementNamesTheFirstGridpoint) {
  fem::Model m(column());
  std::vector<double> f(3 * m.num_points(), 0.0);
  f[3 * (m.num_points() - 1) + 2] = std::numeric_limits<double>::quiet_NaN();  // a top corner
  m.set_applied_forces(f);
  m.solve();
  const auto found = fem::check_finite(m);
  ASSERT_TRUE(found.has_value());
  const auto g = static_cast<std::size_t>(found->gridpoint);
  const auto& u = m.displacements();
  EXPECT_FALSE(finite_at(u, g));
  for (std::size_t k = 0; k < g; ++k) EXPECT_TRUE(finite_at(u, k)) << "gridpoint " << k << " comes first";
  const std::string id = std::to_string(g);
  EXPECT_EQ(found->cause.rfind("non-finite displacement of gridpoint " + id + " at (", 0), 0u) << found->cause;
  EXPECT_EQ(found->detail.rfind("gridpoint " + id + " at (", 0), 0u) << found->detail;
  // One line per zone that has g as a corner, after the header line.
  std::size_t zones = 0;
  const auto& z = m.mesh().zones;
  for (std::size_t k = 0; k < m.num_zones(); ++k)
    for (int c = 0; c < 8; ++c) zones += z[8 * k + c] == found->gridpoint;
  const std::string around = fem::zones_around(m, found->gridpoint);
  EXPECT_GT(zones, 0u);
  EXPECT_EQ(static_cast<std::size_t>(std::count(around.begin(), around.end(), '\n')), zones);
  EXPECT_NE(found->detail.find("\nzones around it:\n" + around), std::string::npos);
}
