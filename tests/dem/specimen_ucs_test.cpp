// Unconfined compression of a z-periodic column (docs/ucs-study.md): the harness of the UCS
// study checked against a closed form.
#include <gtest/gtest.h>

#include <cmath>

#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kPi = 3.14159265358979323846;
}

// Bonded simple cubic lattice (spacing a = 2R, soft bond, E*): each z-chain carries
// K_n ε a with K_n = π R² E*/(2R), one chain per a², so the column's axial modulus is
// E = K_n/a = π E*/4, with zero Poisson effect. The harness (lateral opening, cell strain,
// Love–Weber stress over the REV cross-section) must give it within 1 %.
TEST(SpecimenUcs, ColumnModulusOfBondedCubicLattice) {
  const int n = 4;
  const double a = 2e-4;
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.length = {n * a, n * a, n * a};
  p.threads = 1;
  p.ball_ball.model = ContactModel::kSoftBond;
  World w(p);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) w.add_ball({(i + 0.5) * a, (j + 0.5) * a, (k + 0.5) * a}, 0.5 * a);
  w.prepare();
  ASSERT_EQ(install_bonds(w, -1.0, 1e-3 * a).count, std::size_t(3 * n * n * n));
  UcsParams u;
  u.strain_rate = 0.5;
  u.max_strain = 2e-5;
  u.sample_every = 50;
  const UcsResult r = unconfined_compression_column(w, u);
  const double E = kPi * p.ball_ball.linear.emod / 4.0;
  ASSERT_GT(r.curve.size(), 10u);
  EXPECT_NEAR(r.e50 / E, 1.0, 0.01) << r.report.what;
  // last sample: stress = E ε (linear throughout)
  EXPECT_NEAR(r.curve.back().stress / (E * r.curve.back().strain), 1.0, 0.01);
  EXPECT_FALSE(r.report.converged);  // no peak: stopped at max_strain
  EXPECT_EQ(bond_counts(w).intact, std::size_t(3 * n * n * n - 2 * n * n));  // the n² bonds across each lateral face dropped
}

// Bad input gives one clear error.
TEST(SpecimenUcs, ColumnNeedsPeriodicWorld) {
  WorldParams p;
  World w(p);
  w.add_ball({0, 0, 0}, 1e-4);
  EXPECT_THROW(unconfined_compression_column(w, UcsParams{}), std::invalid_argument);
}
