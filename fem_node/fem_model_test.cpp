// fem_core against closed-form answers (no bus): an elastic column with rollers on the sides
// and a fixed base (the FDM's verification problem, physics.md 8.11).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>

#include "fem_model.hpp"

using namespace demfdm;

namespace {

fem::Params column(double size) {
  fem::Params p;
  p.mesh = fdm::MeshParams::plain_box(2e-3, 2e-3, 10e-3, size);
  p.materials[0] = fem::ElasticGroup{1272.0, 2.0e9, 0.25, std::nullopt};
  p.gravity = {0.0, 0.0, -100 * 9.81};
  return p;
}
double modulus(double E, double nu) { return E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)); }

// Self-weight: u_z(z) = -rho g (H z - z^2 / 2) / M (quadratic; trilinear elements are exact at
// the nodes for this 1-D problem), base reaction = weight, sigma_zz = -rho g (H - z).
TEST(FemModel, ColumnUnderSelfWeight) {
  fem::Model m(column(0.5e-3));
  m.solve();
  const double rho = 1272.0, g = 981.0, H = 10e-3, M = modulus(2.0e9, 0.25);
  double worst = 0, lateral = 0;
  const auto& pts = m.mesh().points;
  for (std::size_t i = 0; i < m.num_points(); ++i) {
    double z = pts[3 * i + 2];
    double expected = -rho * g * (H * z - z * z / 2) / M;
    worst = std::max(worst, std::abs(m.displacements()[3 * i + 2] - expected));
    lateral = std::max({lateral, std::abs(m.displacements()[3 * i]), std::abs(m.displacements()[3 * i + 1])});
  }
  double utop = rho * g * H * H / (2 * M);
  EXPECT_LT(lateral, 1e-9 * utop) << "uniaxial strain: no lateral displacement";
  EXPECT_LT(worst, 1e-9 * utop) << "nodal u_z vs closed form, scale " << utop;
  auto weight = m.gravity_load();
  EXPECT_NEAR(weight[2], -rho * g * 2e-3 * 2e-3 * H, 1e-12);
  EXPECT_NEAR(m.base_reaction()[2], -weight[2], 1e-9 * -weight[2]);
  EXPECT_LT(m.residual_ratio(), 1e-10);
  // Zone-centroid stress: linear in z, so the centroid value is exact.
  auto s = m.zone_stress();
  for (std::size_t z = 0; z < m.num_zones(); ++z) {
    double zc = 0;
    for (int k = 0; k < 8; ++k) zc += pts[3 * m.mesh().zones[8 * z + k] + 2] / 8;
    EXPECT_NEAR(s[6 * z + 2], -rho * g * (H - zc), 1e-6 * rho * g * H) << "zone " << z;
  }
}

// Geostatic initial stress is in equilibrium with gravity: no displacement, same reaction.
TEST(FemModel, GeostaticStressBalancesGravity) {
  fem::Model m(column(0.5e-3));
  m.set_geostatic_stress(fdm::kNaN);
  m.solve();
  double umax = 0;
  for (double u : m.displacements()) umax = std::max(umax, std::abs(u));
  EXPECT_LT(umax, 1e-20) << "geostatic state should not move";
  EXPECT_NEAR(m.base_reaction()[2], -m.gravity_load()[2], 1e-9 * -m.gravity_load()[2]);
}

// Factorised once: a back-substitution is much cheaper than the factorisation + assembly.
TEST(FemModel, SolveIsOneBackSubstitution) {
  fem::Model m(column(0.25e-3));
  auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 10; ++i) m.solve();
  double per_solve = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() / 10;
  std::cout << m.num_free_dofs() << " free dofs: assembly + factorisation " << m.factorisation_s() << " s, solve "
            << per_solve << " s\n";
  EXPECT_LT(per_solve, m.factorisation_s());
}

TEST(FemModel, RejectsBadInput) {
  auto p = column(0.5e-3);
  p.materials[0].poisson = 0.5;
  EXPECT_THROW(fem::Model{p}, std::invalid_argument);
  auto q = column(0.5e-3);
  fem::Model m(q);
  EXPECT_THROW(m.set_interface_forces(std::vector<double>(3, 1.0)), std::invalid_argument);
}

}  // namespace

// The two linear solvers (CHOLMOD supernodal, SimplicialLDLT) solve the same system: the same
// column under self-weight plus lateral nodal loads agrees to round-off (1e-12 of max |u|),
// both with residual |K u - f| / |f| < 1e-9; a build without CHOLMOD refuses "cholmod".
TEST(FemModel, CholmodAndLdltAgree) {
  EXPECT_EQ(fem::linear_solver_from_name("ldlt"), fem::LinearSolver::kLdlt);
  EXPECT_THROW(fem::linear_solver_from_name("lu"), std::invalid_argument);
  auto p = column(0.5e-3);
  p.solver = fem::LinearSolver::kCholmod;
  if (!fem::have_cholmod()) {
    EXPECT_THROW({ fem::Model m(p); }, std::invalid_argument);
    GTEST_SKIP() << "this build has no CHOLMOD";
  }
  fem::Model a(p);
  p.solver = fem::LinearSolver::kLdlt;
  fem::Model b(p);
  EXPECT_TRUE(a.uses_cholmod());
  EXPECT_FALSE(b.uses_cholmod());
  std::vector<double> f(3 * a.num_points(), 0.0);
  for (std::size_t i = 0; i < a.num_points(); ++i) f[3 * i] = 1e-3 * static_cast<double>(i % 5);  // x loads
  a.set_applied_forces(f);
  b.set_applied_forces(f);
  a.solve();
  b.solve();
  double du = 0, umax = 0;
  for (std::size_t i = 0; i < a.displacements().size(); ++i) {
    du = std::max(du, std::abs(a.displacements()[i] - b.displacements()[i]));
    umax = std::max(umax, std::abs(a.displacements()[i]));
  }
  ASSERT_GT(umax, 0.0);
  EXPECT_LT(du, 1e-12 * umax);
  EXPECT_LT(a.residual_ratio(), 1e-9);
  EXPECT_LT(b.residual_ratio(), 1e-9);
}
