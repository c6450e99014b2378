// fem_core against closed-form answers (no bus): an elastic column with rollers on the sides
// and a fixed base (the FDM's verification problem, docs/theory.md 8.11).
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include <Eigen/Dense>

#include "demfdm/fem/model.hpp"

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

// Interface relaxation (docs/continuum-solvers.md): repeated under-relaxed solves with fixed loads
// approach the static answer geometrically, u_k - u_s = (1 - omega)^k (u_0 - u_s), and reach it to
// round-off; the gap reported is the distance before the update.
namespace {
fem::Params pocket_box(double young) {
  fem::Params p;
  p.mesh.length = p.mesh.width = p.mesh.height = 4e-3;
  p.mesh.inner_size = {1e-3, 1e-3, 2e-3};
  p.mesh.size_near = 0.5e-3;
  p.mesh.size_far = 1e-3;
  p.materials[0] = fem::ElasticGroup{1272.0, young, 0.25, std::nullopt};
  p.gravity = {0.0, 0.0, -100 * 9.81};
  return p;
}
std::vector<double> interface_load(const fem::Model& m) {
  std::vector<double> f(3 * m.mesh().interface_points.size());
  for (std::size_t i = 0; i < f.size(); ++i) f[i] = 1e-3 * std::sin(0.7 * static_cast<double>(i) + 0.3);
  return f;
}
}  // namespace

TEST(FemModel, RelaxationConvergesGeometricallyToTheStaticAnswer) {
  fem::Model ref(pocket_box(1e8)), m(pocket_box(1e8));
  ref.set_interface_forces(interface_load(ref));
  m.set_interface_forces(interface_load(m));
  ref.solve();
  const auto us = ref.displacements();
  double umax = 0;
  for (double v : us) umax = std::max(umax, std::abs(v));
  ASSERT_GT(umax, 0);
  const double omega = 0.3;
  for (int k = 1; k <= 60; ++k) {
    m.solve(omega);
    double err = 0;
    for (std::size_t i = 0; i < us.size(); ++i) err = std::max(err, std::abs(m.displacements()[i] - us[i]));
    const double expected = std::pow(1 - omega, k) * umax;  // from rest: u_0 = 0
    EXPECT_NEAR(err, expected, 1e-9 * umax) << "step " << k;
    EXPECT_NEAR(m.relaxation_gap(), std::pow(1 - omega, k - 1), 1e-9) << "step " << k;
  }
  // 0.7^60 = 5e-10: the static answer, and its residual and reactions.
  EXPECT_LT(m.residual_ratio(), 1e-8);
  EXPECT_NEAR(m.base_reaction()[2], ref.base_reaction()[2], 1e-8 * std::abs(ref.base_reaction()[2]));
  EXPECT_THROW(m.solve(0.0), std::invalid_argument);
  EXPECT_THROW(m.solve(1.5), std::invalid_argument);
}

// coupling_gain = lambda_max(C D): against the dense interface compliance (one interface_response
// per interface dof) and a dense symmetric eigen-solve; scales linearly with k and with 1/E.
TEST(FemModel, CouplingGainMatchesDenseEigenvalue) {
  fem::Model m(pocket_box(1e8));
  const std::size_t n = m.mesh().interface_points.size(), nd = 3 * n;
  std::vector<double> k(n);
  for (std::size_t i = 0; i < n; ++i) k[i] = 5e5 * (1.0 + 0.5 * std::cos(1.3 * static_cast<double>(i)));
  Eigen::MatrixXd A(nd, nd);
  for (std::size_t j = 0; j < nd; ++j) {
    std::vector<double> e(nd, 0.0);
    e[j] = std::sqrt(k[j / 3]);
    auto c = m.interface_response(e);
    for (std::size_t i = 0; i < nd; ++i) A(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
        std::sqrt(k[i / 3]) * c[i];
  }
  EXPECT_LT((A - A.transpose()).norm(), 1e-10 * A.norm()) << "D^1/2 C D^1/2 is symmetric";
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (A + A.transpose()), Eigen::EigenvaluesOnly);
  const double exact = es.eigenvalues().maxCoeff();
  int its = 0;
  const double est = m.coupling_gain(k, 200, 1e-9, &its);
  EXPECT_LE(est, exact * (1 + 1e-9)) << "a Rayleigh quotient never exceeds lambda_max";
  EXPECT_NEAR(est, exact, 1e-3 * exact) << its << " iterations";
  int its40 = 0;
  const double est40 = m.coupling_gain(k, 40, 1e-4, &its40);  // the node's setting
  EXPECT_NEAR(est40, exact, 0.05 * exact) << its40 << " iterations";
  std::printf("coupling gain: dense %.6g, power %.6g (%d its), node setting %.6g (%d its)\n", exact, est, its, est40,
              its40);
  EXPECT_GT(exact, 1.0) << "this case (E = 1e8 Pa, k = 5e5 N/m) is unstable without relaxation";
  std::vector<double> k2(k);
  for (auto& v : k2) v *= 3;
  EXPECT_NEAR(m.coupling_gain(k2, 200, 1e-9), 3 * est, 1e-6 * 3 * est);
  fem::Model stiff(pocket_box(1e9));
  EXPECT_NEAR(stiff.coupling_gain(k, 200, 1e-9), 0.1 * est, 1e-6 * est);
  EXPECT_EQ(m.coupling_gain(std::vector<double>(n, 0.0)), 0.0);
  EXPECT_THROW(m.coupling_gain(std::vector<double>(n + 1, 1.0)), std::invalid_argument);
}

// Interface springs against a model DEM whose contacts answer the interface displacement at once,
// F_k = F0 - k u_{k-1} (k per point, as the DEM's contact stiffness, docs/theory.md 6.5). The coupled
// static answer solves (K + k) u = F0 + f_body. Unrelaxed (omega = 1, no springs) the iteration
// diverges when the coupling gain exceeds 1; with springs D = k it reaches the coupled answer; with
// D >= k it converges to it geometrically; and with fixed loads
// the springs leave the static answer K u = f unchanged.
namespace {
struct SpringDem {
  std::vector<double> f0, k;  // [3 n_if], [n_if]
  std::vector<double> forces(const std::vector<double>& u_if) const {
    std::vector<double> f(f0);
    for (std::size_t i = 0; i < f.size(); ++i) f[i] -= k[i / 3] * u_if[i];
    return f;
  }
};
double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double m = 0;
  for (std::size_t i = 0; i < a.size(); ++i) m = std::max(m, std::abs(a[i] - b[i]));
  return m;
}
}  // namespace

TEST(FemModel, InterfaceSpringsMakeTheCouplingContractive) {
  fem::Model probe(pocket_box(1e8));
  const std::size_t n = probe.mesh().interface_points.size();
  SpringDem dem{interface_load(probe), std::vector<double>(n)};
  for (std::size_t i = 0; i < n; ++i) dem.k[i] = 5e5 * (1.0 + 0.5 * std::cos(1.3 * static_cast<double>(i)));
  ASSERT_GT(probe.coupling_gain(dem.k), 1.0);

  // Reference, dense and independent of the springs: u = u_b + C (F0 - k u), u_b the interface
  // displacement under the body load alone, C the interface compliance (one response per dof):
  // (I + C k) u = u_b + C F0.
  fem::Model ref(pocket_box(1e8));
  ref.solve();
  const auto ub = ref.interface_displacements();
  const std::size_t nd = 3 * n;
  Eigen::MatrixXd A = Eigen::MatrixXd::Identity(nd, nd);
  Eigen::VectorXd rhs(nd);
  const auto cf0 = ref.interface_response(dem.f0);
  for (std::size_t j = 0; j < nd; ++j) {
    std::vector<double> e(nd, 0.0);
    e[j] = dem.k[j / 3];
    auto c = ref.interface_response(e);
    for (std::size_t i = 0; i < nd; ++i) A(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) += c[i];
    rhs[static_cast<Eigen::Index>(j)] = ub[j] + cf0[j];
  }
  Eigen::VectorXd uc = A.partialPivLu().solve(rhs);
  const std::vector<double> u_coupled(uc.data(), uc.data() + nd);
  double scale = 0;
  for (double v : u_coupled) scale = std::max(scale, std::abs(v));

  // Unrelaxed: diverges.
  fem::Model raw(pocket_box(1e8));
  for (int it = 0; it < 20; ++it) {
    raw.set_interface_forces(dem.forces(raw.interface_displacements()));
    raw.solve();
  }
  EXPECT_GT(max_diff(raw.interface_displacements(), u_coupled), 1e3 * scale) << "unrelaxed must diverge";

  // Springs D = k: the implicit coupling, the coupled answer after one step (to round-off).
  fem::Model exact(pocket_box(1e8));
  exact.set_interface_springs(dem.k);
  exact.set_interface_forces(dem.forces(exact.interface_displacements()));
  exact.solve();
  EXPECT_LT(max_diff(exact.interface_displacements(), u_coupled), 1e-8 * scale);

  // Springs D >= k (floored): geometric convergence, monotone error.
  fem::Model floored(pocket_box(1e8));
  double kmax = *std::max_element(dem.k.begin(), dem.k.end());
  std::vector<double> d(dem.k);
  for (auto& v : d) v = std::max(v, 0.6 * kmax);  // D > k on most points (the node floors at 0.25)
  floored.set_interface_springs(d);
  double prev = INFINITY;
  int steps = 0;
  for (; steps < 500; ++steps) {
    floored.set_interface_forces(dem.forces(floored.interface_displacements()));
    floored.solve();
    const double err = max_diff(floored.interface_displacements(), u_coupled);
    ASSERT_LT(err, prev * (1 + 1e-9)) << "step " << steps;
    prev = err;
    if (err < 1e-9 * scale) break;
  }
  std::printf("floored springs: coupled answer to 1e-9 in %d steps\n", steps + 1);
  EXPECT_LT(prev, 1e-9 * scale);
  EXPECT_EQ(floored.refactorisations(), 1);

  // Fixed loads: the springs do not change the static answer.
  fem::Model plain(pocket_box(1e8)), sprung(pocket_box(1e8));
  plain.set_interface_forces(dem.f0);
  sprung.set_interface_forces(dem.f0);
  sprung.set_interface_springs(d);
  plain.solve();
  // Error factor (K + D)^-1 D: about lambda / (1 + lambda) for the stiffest mode, so thousands of
  // steps; in a coupled run D - k, not D, drives the error (above).
  int fixed_steps = 0;
  for (; fixed_steps < 6000 && !(fixed_steps > 0 && sprung.relaxation_gap() < 1e-13); ++fixed_steps) sprung.solve();
  std::printf("springs with fixed loads: static answer in %d steps\n", fixed_steps);
  double us = 0;
  for (double v : plain.displacements()) us = std::max(us, std::abs(v));
  EXPECT_LT(max_diff(sprung.displacements(), plain.displacements()), 1e-9 * us);
  EXPECT_LT(sprung.residual_ratio(), 1e-9);
  EXPECT_THROW(sprung.set_interface_springs(std::vector<double>(n + 1, 1.0)), std::invalid_argument);
  EXPECT_THROW(sprung.set_interface_springs(std::vector<double>(n, -1.0)), std::invalid_argument);
}
