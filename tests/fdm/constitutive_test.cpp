// Constitutive functions (docs/theory.md 5.4) at the stress-point level.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>

#include "demfdm/fdm/constitutive.hpp"

namespace demfdm::fdm {
namespace {

void rotate(const double R[3][3], const double d[3], double* s) {
  // s = R diag(d) R^T in (xx, yy, zz, xy, yz, xz)
  auto c = [&](int i, int j) { return R[i][0] * d[0] * R[j][0] + R[i][1] * d[1] * R[j][1] + R[i][2] * d[2] * R[j][2]; };
  s[0] = c(0, 0); s[1] = c(1, 1); s[2] = c(2, 2); s[3] = c(0, 1); s[4] = c(1, 2); s[5] = c(0, 2);
}

void random_rotation(std::mt19937_64& rng, double R[3][3]) {
  std::uniform_real_distribution<double> u(-std::numbers::pi, std::numbers::pi);
  const double a = u(rng), b = u(rng), c = u(rng);
  const double Rz[3][3] = {{std::cos(a), -std::sin(a), 0}, {std::sin(a), std::cos(a), 0}, {0, 0, 1}};
  const double Ry[3][3] = {{std::cos(b), 0, std::sin(b)}, {0, 1, 0}, {-std::sin(b), 0, std::cos(b)}};
  const double Rx[3][3] = {{1, 0, 0}, {0, std::cos(c), -std::sin(c)}, {0, std::sin(c), std::cos(c)}};
  double T[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      T[i][j] = 0;
      for (int k = 0; k < 3; ++k) T[i][j] += Rz[i][k] * Ry[k][j];
    }
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      R[i][j] = 0;
      for (int k = 0; k < 3; ++k) R[i][j] += T[i][k] * Rx[k][j];
    }
}

// Jacobi and the fast decomposition: recover eigenvalues (including a repeated pair and an
// isotropic tensor) to 1e-12 relative, unit vectors, ascending order, and rebuild the tensor
// to 1e-12; closed-form principal values agree to 1e-7.
class SymmetricEigen : public ::testing::TestWithParam<bool> {};

TEST_P(SymmetricEigen, RecoversRotatedDiagonal) {
  const bool fast = GetParam();
  std::mt19937_64 rng(7);
  const double cases[5][3] = {{-3.0, 1.0, 2.5}, {-2.0, -2.0, 5.0}, {4.0, 4.0, 4.0}, {-1.0, 3.0, 3.0},
                              {1.0, 1.0 + 1e-7, 2.0}};
  for (int trial = 0; trial < 100; ++trial) {
    const auto& d = cases[trial % 5];
    double R[3][3];
    random_rotation(rng, R);
    double s[6];
    rotate(R, d, s);
    std::array<double, 3> val{};
    std::array<std::array<double, 3>, 3> vec{};
    if (fast) {
      symmetric_eigen_fast(s, val, vec);
    } else {
      symmetric_eigen(s, val, vec);
    }
    double sorted[3] = {d[0], d[1], d[2]};
    std::sort(sorted, sorted + 3);
    const auto pv = principal_values(s);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(val[k], sorted[k], 1e-12 * 5.0);
      EXPECT_NEAR(pv[k], sorted[k], 1e-7 * 5.0);  // acos loses digits near repeated roots
      EXPECT_NEAR(vec[k][0] * vec[k][0] + vec[k][1] * vec[k][1] + vec[k][2] * vec[k][2], 1.0, 1e-13);
    }
    // Reconstruction.
    double back[6] = {0, 0, 0, 0, 0, 0};
    for (int k = 0; k < 3; ++k) {
      const auto& v = vec[k];
      back[0] += val[k] * v[0] * v[0];
      back[1] += val[k] * v[1] * v[1];
      back[2] += val[k] * v[2] * v[2];
      back[3] += val[k] * v[0] * v[1];
      back[4] += val[k] * v[1] * v[2];
      back[5] += val[k] * v[0] * v[2];
    }
    for (int i = 0; i < 6; ++i) EXPECT_NEAR(back[i], s[i], 1e-12 * 5.0);
  }
}

INSTANTIATE_TEST_SUITE_P(Method, SymmetricEigen, ::testing::Values(false, true),
                         [](const ::testing::TestParamInfo<bool>& info) {
                           return std::string(info.param ? "Fast" : "Jacobi");
                         });

Material mc_material(double c, double phi, double psi, double t = kNaN) {
  Material m;
  m.model = Constitutive::kMohrCoulomb;
  m.young = 1e8;
  m.poisson = 0.3;
  m.cohesion = c;
  m.friction_deg = phi;
  m.dilation_deg = psi;
  m.tension = t;
  return m;
}

// Elastic increment: uniaxial strain de_zz gives sigma_zz = (K + 4G/3) de, sigma_xx = (K - 2G/3) de.
TEST(Elastic, UniaxialStrainModulus) {
  const auto m = make_constants(Material{});
  double s[6] = {0, 0, 0, 0, 0, 0};
  const double de[6] = {0, 0, 1e-4, 0, 0, 0};
  elastic_update(m, de, s);
  EXPECT_NEAR(s[2], m.alpha1 * 1e-4, 1e-9 * m.alpha1 * 1e-4);
  EXPECT_NEAR(s[0], m.alpha2 * 1e-4, 1e-9 * m.alpha1 * 1e-4);
  const double shear[6] = {0, 0, 0, 1e-4, 0, 0};
  double t[6] = {0, 0, 0, 0, 0, 0};
  elastic_update(m, shear, t);
  EXPECT_NEAR(t[3], 2.0 * m.shear * 1e-4, 1e-6);
}

// Stress-point return: random compressive trial states (all principal stresses < 0, so only
// the shear planes can be active; edge states with two equal principal stresses included) come
// back onto the surface, f^s = 0 within 1e-9 of the stress scale, never outside it; states
// inside are untouched.
TEST(MohrCoulombReturn, CompressiveTrialStatesEndOnTheSurface) {
  for (double psi : {0.0, 10.0}) {
    const auto m = make_constants(mc_material(1e5, 30.0, psi, 5e4));
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<double> u(-1e6, -1e3);
    int plastic = 0;
    for (int trial = 0; trial < 600; ++trial) {
      double d[3] = {u(rng), u(rng), u(rng)};
      if (trial % 3 == 1) d[2] = d[1];  // triaxial compression / extension edges
      double R[3][3];
      random_rotation(rng, R);
      double s[6];
      rotate(R, d, s);
      double s0[6];
      std::copy(s, s + 6, s0);
      const auto state = mohr_coulomb_return(m, s);
      std::array<double, 3> pv{};
      std::array<std::array<double, 3>, 3> vec{};
      symmetric_eigen(s, pv, vec);  // Jacobi: accurate at the edges, where the closed form is not
      const double fs = pv[0] - pv[2] * m.n_phi + 2.0 * m.cohesion * m.sqrt_n_phi;
      EXPECT_GE(fs, -1e-9 * 1e6) << "trial " << trial;
      if (state == 0) {
        for (int i = 0; i < 6; ++i) EXPECT_EQ(s[i], s0[i]);
      } else {
        EXPECT_EQ(state, kShearNow);
        EXPECT_LT(std::abs(fs), 1e-9 * 1e6) << "trial " << trial;
        ++plastic;
      }
    }
    EXPECT_GT(plastic, 100);
  }
}

// Hydrostatic tension beyond the cut-off maps onto sigma^t I (apex), tensile mode.
TEST(MohrCoulombReturn, HydrostaticTensionToApex) {
  const auto m = make_constants(mc_material(1e5, 30.0, 0.0, 4e4));
  double s[6] = {1e5, 1e5, 1e5, 0, 0, 0};
  EXPECT_EQ(mohr_coulomb_return(m, s), kTensionNow);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s[i], 4e4, 1e-9 * 4e4);
  for (int i = 3; i < 6; ++i) EXPECT_NEAR(s[i], 0.0, 1e-9);
  // Applying the return again does nothing (no oscillation between modes).
  EXPECT_EQ(mohr_coulomb_return(m, s), 0);
}

// The cut-off is limited to the apex c / tan(phi) (docs/theory.md 5.4).
TEST(MohrCoulombReturn, TensionLimitedToApex) {
  const auto m = make_constants(mc_material(1e5, 30.0, 0.0, 1e9));
  EXPECT_NEAR(m.tension, 1e5 / std::tan(30.0 * std::numbers::pi / 180.0), 1e-6);
}

}  // namespace
}  // namespace demfdm::fdm
