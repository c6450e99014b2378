// Mohr-Coulomb element tests (docs/theory.md 8.15): drained triaxial on 1 zone and 3x3x3 zones,
// plastic flow direction for psi = 0 and psi > 0, uniaxial tension cut-off, hydrostatic tension
// at the apex. Static mode, small strain, stresses tension positive (compression-positive
// quantities are written with a prime).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <ostream>
#include <string>

#include "demfdm/fdm/model.hpp"

namespace demfdm::fdm {
namespace {

constexpr double kE = 1e8, kNu = 0.3, kC = 1e5, kPhi = 30.0;

Material mc(double psi, double tension = kNaN) {
  Material m;
  m.model = Constitutive::kMohrCoulomb;
  m.young = kE;
  m.poisson = kNu;
  m.density = 2000.0;
  m.cohesion = kC;
  m.friction_deg = kPhi;
  m.dilation_deg = psi;
  m.tension = tension;
  return m;
}

// Unit cube of n^3 zones: symmetry rollers on x = 0, y = 0, base z = 0; pressure on x = 1 and
// y = 1; the top moves at `rate` [m/step] in z.
struct Element {
  Model model;
  std::vector<std::int32_t> top, xface, yface;
  Element(int n, const Material& m, VolumetricAveraging avg)
      : model(generate_mesh(MeshParams::plain_box(1.0, 1.0, 1.0, 1.0 / n)), [&] {
          ModelParams p;
          p.materials = {MaterialGroup{m, std::nullopt}};
          p.mode = Mode::kStatic;
          p.gravity_level = 0.0;
          p.strongbox_boundary = false;
          p.averaging = avg;
          return p;
        }()) {
    for (std::int32_t g : model.gridpoints_on_plane(0, 0.0)) model.fix_velocity(g, kFixX);
    for (std::int32_t g : model.gridpoints_on_plane(1, 0.0)) model.fix_velocity(g, kFixY);
    for (std::int32_t g : model.gridpoints_on_plane(2, 0.0)) model.fix_velocity(g, kFixZ);
    top = model.gridpoints_on_plane(2, 1.0);
    xface = model.gridpoints_on_plane(0, 1.0);
    yface = model.gridpoints_on_plane(1, 1.0);
  }
  void confine(double p) {
    std::vector<BoundaryFace> faces;
    for (const auto& f : boundary_faces(model.mesh()))
      if (f.side == Side::kPlusX || f.side == Side::kPlusY) faces.push_back(f);
    model.add_face_pressure(faces, p);
    model.set_uniform_stress({-p, -p, -p, 0.0, 0.0, 0.0});
  }
  void drive_top(double rate) {
    for (std::int32_t g : top) model.fix_velocity(g, kFixZ, {0.0, 0.0, rate});
  }
  double mean_u(const std::vector<std::int32_t>& gps, int d) const {
    double s = 0.0;
    for (std::int32_t g : gps) s += model.displacements()[3 * g + d];
    return s / static_cast<double>(gps.size());
  }
  // Volume-weighted mean stress of all zones (uniform zones).
  std::array<double, 6> mean_stress() const {
    const auto zs = model.zone_stress();
    std::array<double, 6> m{};
    for (std::size_t z = 0; z < model.num_zones(); ++z)
      for (int i = 0; i < 6; ++i) m[i] += zs[6 * z + i] / static_cast<double>(model.num_zones());
    return m;
  }
  std::uint8_t plastic_or() const {
    std::uint8_t s = 0;
    for (auto v : model.plastic_state()) s |= v;
    return s;
  }
};

struct TriaxialCase {
  int zones_per_side;
  double psi;
  VolumetricAveraging averaging;
};

void PrintTo(const TriaxialCase& c, std::ostream* os) {
  *os << c.zones_per_side << "^3 zones, psi " << c.psi << " deg, "
      << (c.averaging == VolumetricAveraging::kPerZone ? "per-zone" : "per-overlay") << " averaging";
}

class Triaxial : public ::testing::TestWithParam<TriaxialCase> {};

// Confine at sigma3' = 100 kPa, compress axially to 1.2 % strain. The peak and the residual
// axial stress match sigma1' = sigma3' N_phi + 2c sqrt(N_phi) within 1 %; after yield the
// volumetric-to-axial plastic strain ratio is 1 - N_psi (0 for psi = 0) within 0.02 absolute.
TEST_P(Triaxial, PeakStrengthAndFlowRule) {
  const auto tc = GetParam();
  Element e(tc.zones_per_side, mc(tc.psi), tc.averaging);
  const double p = 1e5, rate = -1e-6;
  e.confine(p);
  e.drive_top(rate);
  const double sphi = std::sin(kPhi * std::numbers::pi / 180.0);
  const double nphi = (1 + sphi) / (1 - sphi);
  const double spsi = std::sin(tc.psi * std::numbers::pi / 180.0);
  const double npsi = (1 + spsi) / (1 - spsi);
  const double s1_expected = p * nphi + 2.0 * kC * std::sqrt(nphi);
  double peak = 0.0;
  double ev_a = 0.0, e1_a = 0.0;
  const int total = 12000, mark = 8000;
  for (int s = 1; s <= total; ++s) {
    e.model.step();
    if (s % 100 == 0) peak = std::max(peak, -e.mean_stress()[2]);
    if (s == mark) {
      e1_a = -e.mean_u(e.top, 2);
      ev_a = -(e.mean_u(e.xface, 0) + e.mean_u(e.yface, 1) + e.mean_u(e.top, 2));
    }
  }
  const auto sig = e.mean_stress();
  const double e1_b = -e.mean_u(e.top, 2);
  const double ev_b = -(e.mean_u(e.xface, 0) + e.mean_u(e.yface, 1) + e.mean_u(e.top, 2));
  const double s3 = -0.5 * (sig[0] + sig[1]);
  EXPECT_NEAR(s3 / p, 1.0, 0.01);
  EXPECT_NEAR(peak / s1_expected, 1.0, 0.01);
  EXPECT_NEAR(-sig[2] / s1_expected, 1.0, 0.01);
  EXPECT_NEAR(-sig[2] / (s3 * nphi + 2.0 * kC * std::sqrt(nphi)), 1.0, 0.01);
  const double flow = (ev_b - ev_a) / (e1_b - e1_a);
  EXPECT_NEAR(flow, 1.0 - npsi, 0.02);
  EXPECT_TRUE(e.plastic_or() & kShearNow);
  std::printf("triaxial n=%d psi=%g avg=%d: peak/expected %.5f  final %.5f  s3/p %.5f  dev/de1 %.4f (expect %.4f)\n",
              tc.zones_per_side, tc.psi, static_cast<int>(tc.averaging), peak / s1_expected, -sig[2] / s1_expected,
              s3 / p, flow, 1.0 - npsi);
}

INSTANTIATE_TEST_SUITE_P(
    MohrCoulomb, Triaxial,
    ::testing::Values(TriaxialCase{1, 0.0, VolumetricAveraging::kPerOverlay},
                      TriaxialCase{3, 0.0, VolumetricAveraging::kPerOverlay},
                      TriaxialCase{3, 0.0, VolumetricAveraging::kPerZone},
                      TriaxialCase{1, 10.0, VolumetricAveraging::kPerOverlay},
                      TriaxialCase{3, 10.0, VolumetricAveraging::kPerOverlay}),
    [](const ::testing::TestParamInfo<TriaxialCase>& info) {
      const auto& c = info.param;
      return "Zones" + std::to_string(c.zones_per_side) + "Psi" + std::to_string(static_cast<int>(c.psi)) +
             (c.averaging == VolumetricAveraging::kPerZone ? "PerZone" : "PerOverlay");
    });

// Unconfined compression: peak = UCS = 2c sqrt(N_phi) within 1 %.
TEST(MohrCoulombElement, UnconfinedCompressionStrength) {
  Element e(1, mc(0.0), VolumetricAveraging::kPerOverlay);
  e.drive_top(-5e-7);
  double peak = 0.0;
  for (int s = 1; s <= 12000; ++s) {
    e.model.step();
    if (s % 100 == 0) peak = std::max(peak, -e.mean_stress()[2]);
  }
  const double sphi = std::sin(kPhi * std::numbers::pi / 180.0);
  const double ucs = 2.0 * kC * std::sqrt((1 + sphi) / (1 - sphi));
  EXPECT_NEAR(peak / ucs, 1.0, 0.01);
}

// Uniaxial tension: sigma_zz caps at the cut-off sigma^t (< 2c/sqrt(N_phi), so tension governs),
// within 1 %; after yield the lateral strain stops changing (plastic strain normal to the
// cut-off) and the zones report tensile failure only.
TEST(MohrCoulombElement, UniaxialTensionCappedAtCutOff) {
  const double st = 3e4;
  Element e(3, mc(0.0, st), VolumetricAveraging::kPerOverlay);
  e.drive_top(+4e-7);
  double peak = -1e30, ex_a = 0.0, ez_a = 0.0;
  for (int s = 1; s <= 3000; ++s) {
    e.model.step();
    if (s % 50 == 0) peak = std::max(peak, e.mean_stress()[2]);
    if (s == 2000) {
      ex_a = e.mean_u(e.xface, 0);
      ez_a = e.mean_u(e.top, 2);
    }
  }
  const auto sig = e.mean_stress();
  EXPECT_LT(peak, st * 1.01);
  EXPECT_NEAR(sig[2] / st, 1.0, 0.01);
  EXPECT_NEAR(sig[0] / st, 0.0, 0.01);
  const double lateral = (e.mean_u(e.xface, 0) - ex_a) / (e.mean_u(e.top, 2) - ez_a);
  EXPECT_NEAR(lateral, 0.0, 0.01);
  EXPECT_TRUE(e.plastic_or() & kTensionNow);
  EXPECT_FALSE(e.plastic_or() & kShearPast);
}

// Hydrostatic extension (every gridpoint prescribed v = rate * x): the stress reaches the apex
// sigma^t I and stays there, tensile mode on every step, never shear (no oscillation).
TEST(MohrCoulombElement, HydrostaticTensionApex) {
  const double st = 4e4;
  Element e(1, mc(0.0, st), VolumetricAveraging::kPerOverlay);
  const auto x = e.model.positions();
  const std::vector<double> x0(x.begin(), x.end());
  for (std::size_t g = 0; g < e.model.num_gridpoints(); ++g)
    e.model.fix_velocity(static_cast<std::int32_t>(g), kFixAll,
                         {1e-6 * x0[3 * g], 1e-6 * x0[3 * g + 1], 1e-6 * x0[3 * g + 2]});
  int tension_steps = 0;
  for (int s = 1; s <= 400; ++s) {
    e.model.step();
    const auto st_bits = e.model.plastic_state()[0];
    EXPECT_FALSE(st_bits & kShearNow) << "step " << s;
    if (st_bits & kTensionNow) {
      ++tension_steps;
      const auto sig = e.mean_stress();
      for (int i = 0; i < 3; ++i) EXPECT_NEAR(sig[i], st, 1e-9 * st) << "step " << s;
      for (int i = 3; i < 6; ++i) EXPECT_NEAR(sig[i], 0.0, 1e-9 * st) << "step " << s;
    }
  }
  // Bulk modulus 8.3e7 Pa * 3e-6 per step: the apex is reached after about 160 steps.
  EXPECT_GT(tension_steps, 200);
  EXPECT_FALSE(e.plastic_or() & kShearPast);
}

}  // namespace
}  // namespace demfdm::fdm
