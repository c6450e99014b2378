// Hertz–Mindlin law (docs/theory.md §1.9, §8.1) against closed forms: the head-on collision of
// two grains and of a grain with a rigid wall (contact time, largest overlap, restitution 1),
// energy conserved through the collision, the normal and Mindlin shear stiffnesses of one
// contact, the Coulomb limit; and the registry that made the law pluggable (names, bond flag).
// The scalar and vector paths of the law are compared bit for bit in simd_kernel_test.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kPi = 3.14159265358979323846;

// ∫₀¹ dx/√(1 − x^(5/2)): t_c = 2 I δ_max/v0 for a Hertz collision (Johnson 1985, §11.4).
double hertz_time_integral() {
  // x = 1 − u²: dx = −2u du, 1 − x^(5/2) ≈ (5/2)u² near x = 1: the integrand is regular in u.
  const int n = 200000;
  double s = 0.0;
  for (int k = 0; k < n; ++k) {
    const double u = (k + 0.5) / n;
    const double x = 1.0 - u * u;
    s += 2.0 * u / std::sqrt(1.0 - std::pow(x, 2.5));
  }
  return s / n;
}

struct Hit {
  double tc, dmax, e, energy_err;
};

// Head-on approach at relative speed v0 of a grain (radius R) against an equal grain, or
// against a rigid plane (wall = true). No friction, gravity or damping. dt = t_c/steps_per_tc.
Hit collide(bool wall, double steps_per_tc, double& tc_ref, double& dmax_ref) {
  WorldParams p;
  p.local_damping = 0.0;
  ContactFamilyParams& fam = wall ? p.ball_wall : p.ball_ball;
  fam.model = ContactModel::kHertz;
  fam.linear.fric = 0.0;
  fam.hertz.shear = 1.0e9;
  fam.hertz.poisson = 0.25;
  const double R = 1e-4, v0 = 0.2;
  const double m = p.density * 4.0 / 3.0 * kPi * R * R * R;
  const double G = fam.hertz.shear, nu = fam.hertz.poisson;
  // Johnson's E* and R*: two grains 1/E* = 2(1 − ν²)/E with E = 2G(1 + ν); a rigid wall (1 − ν²)/E.
  const double E = 2.0 * G * (1.0 + nu);
  const double e_star = wall ? E / (1.0 - nu * nu) : E / (2.0 * (1.0 - nu * nu));
  const double r_star = wall ? R : 0.5 * R;
  const double m_star = wall ? m : 0.5 * m;
  dmax_ref = std::pow(15.0 * m_star * v0 * v0 / (16.0 * e_star * std::sqrt(r_star)), 0.4);
  tc_ref = 2.0 * hertz_time_integral() * dmax_ref / v0;
  p.dt_fixed = tc_ref / steps_per_tc;
  World w(p);
  const double gap0 = 0.5 * v0 * 20 * p.dt_fixed;
  if (wall) {
    w.add_plane(PlaneWallParams{});
    w.add_ball({0, 0, R + gap0}, R);
    w.balls().v[0] = {0, 0, -v0};
  } else {
    w.add_ball({0, 0, 0}, R);
    w.add_ball({2 * R + gap0, 0, 0}, R);
    w.balls().v[0] = {0.5 * v0, 0, 0};
    w.balls().v[1] = {-0.5 * v0, 0, 0};
  }
  auto gap = [&] { return wall ? w.balls().x[0].z - R : w.balls().x[1].x - w.balls().x[0].x - 2 * R; };
  const double e0 = w.kinetic_energy();
  Hit h{0, 0, 0, 0};
  double g_prev = gap(), t_prev = 0, t_in = -1, t_out = -1;
  for (int k = 0; k < 10 * steps_per_tc && t_out < 0; ++k) {
    w.step();
    const double g = gap();
    if (g_prev > 0 && g <= 0) t_in = t_prev + (w.time() - t_prev) * g_prev / (g_prev - g);
    if (g_prev <= 0 && g > 0) t_out = t_prev + (w.time() - t_prev) * g_prev / (g_prev - g);
    h.dmax = std::max(h.dmax, -g);
    const Energy en = w.energy();
    h.energy_err = std::max(h.energy_err, std::abs(en.kinetic + en.strain - e0) / e0);
    g_prev = g;
    t_prev = w.time();
  }
  w.step(5);
  h.tc = t_out - t_in;
  h.e = wall ? w.balls().v[0].z / v0 : (w.balls().v[1].x - w.balls().v[0].x) / v0;
  return h;
}
}  // namespace

// §8.1: contact time and largest overlap within 0.5 % for Δt = t_c/1000, e = 1 within 1e-3,
// kinetic + stored energy constant within 3e-3 of the impact energy (the velocities are half a
// step behind the positions: an offset of order Δt/t_c, measured 1.7e-3 here).
TEST(Hertz, TwoGrainCollisionMatchesTheClosedForm) {
  double tc, dmax;
  const Hit h = collide(false, 1000.0, tc, dmax);
  std::printf("two grains: t_c %.6e s (closed form %.6e), delta_max %.6e m (%.6e), e %.6f, energy %.2e\n", h.tc, tc,
              h.dmax, dmax, h.e, h.energy_err);
  EXPECT_NEAR(h.tc / tc, 1.0, 5e-3);
  EXPECT_NEAR(h.dmax / dmax, 1.0, 5e-3);
  EXPECT_NEAR(h.e, 1.0, 1e-3);
  EXPECT_LT(h.energy_err, 3e-3);
}

TEST(Hertz, GrainOnRigidWallMatchesTheClosedForm) {
  double tc, dmax;
  const Hit h = collide(true, 1000.0, tc, dmax);
  std::printf("grain on wall: t_c %.6e s (closed form %.6e), delta_max %.6e m (%.6e), e %.6f, energy %.2e\n", h.tc,
              tc, h.dmax, dmax, h.e, h.energy_err);
  EXPECT_NEAR(h.tc / tc, 1.0, 5e-3);
  EXPECT_NEAR(h.dmax / dmax, 1.0, 5e-3);
  EXPECT_NEAR(h.e, 1.0, 1e-3);
  EXPECT_LT(h.energy_err, 3e-3);
}

// The error of the contact time falls as the step shrinks (the scheme converges to the closed
// form): 4x fewer steps per collision give a larger error than the finest step.
TEST(Hertz, ContactTimeConvergesWithTheStep) {
  double tc, dmax;
  const double coarse = std::abs(collide(false, 50.0, tc, dmax).tc / tc - 1.0);
  const double fine = std::abs(collide(false, 800.0, tc, dmax).tc / tc - 1.0);
  std::printf("contact time error: %.3e at t_c/50, %.3e at t_c/800\n", coarse, fine);
  EXPECT_LT(fine, coarse);
  EXPECT_LT(fine, 2e-3);
}

// One contact through the law: F_n = (4/3) E* a δ, tangent K_n = 2 E* a (= dF_n/dδ, checked
// by a central difference), Mindlin k_s = 8 G* a and F_s = −k_s Δu_s, then the Coulomb limit.
TEST(Hertz, NormalAndMindlinStiffnessOfOneContact) {
  ContactFamilyParams f;
  f.model = ContactModel::kHertz;
  f.linear.fric = 0.5;
  f.hertz.shear = 2.0e9;
  f.hertz.poisson = 0.3;
  const LawConst c = HertzLaw::constants(f, true, false);
  const double G = 2.0e9, nu = 0.3;
  EXPECT_DOUBLE_EQ(c.hz_e, G / (1.0 - nu));
  EXPECT_DOUBLE_EQ(c.hz_g, G / (2.0 * (2.0 - nu)));
  const double reff = 5e-5, delta = 2e-7;
  auto fn_at = [&](double d) {
    ContactHist h;
    HertzLaw::init(0, 0, h, nullptr, f);
    Kin k;
    k.n = {0, 0, 1};
    k.gap = -d;
    k.reff = reff;
    k.dt = 1e-8;
    Vec3 M;
    return HertzLaw::update(k, h, nullptr, c, M).z;
  };
  const double a = std::sqrt(reff * delta);
  EXPECT_NEAR(fn_at(delta), 4.0 / 3.0 * c.hz_e * a * delta, 1e-12 * fn_at(delta));
  const double eps = 1e-11;
  const double dfd = (fn_at(delta + eps) - fn_at(delta - eps)) / (2 * eps);
  ContactHist h;
  HertzLaw::init(0, 0, h, nullptr, f);
  Kin k;
  k.n = {0, 0, 1};
  k.gap = -delta;
  k.reff = reff;
  k.dt = 1e-8;
  Vec3 M;
  HertzLaw::update(k, h, nullptr, c, M);
  EXPECT_NEAR(h.kn, 2.0 * c.hz_e * a, 1e-12 * h.kn);
  EXPECT_NEAR(dfd / h.kn, 1.0, 1e-5);
  EXPECT_NEAR(h.ks, 8.0 * c.hz_g * a, 1e-12 * h.ks);
  // a small tangential increment at the same overlap: F_s = −k_s Δu_s, no slip
  k.du = {1e-10, 0, 0};
  const Vec3 F = HertzLaw::update(k, h, nullptr, c, M);
  EXPECT_NEAR(F.x, -8.0 * c.hz_g * a * 1e-10, 1e-12 * std::abs(F.x));
  EXPECT_FALSE(h.flags & ContactHist::kSlip);
  // a large one: the shear force sits on the Coulomb limit μ F_n and slip work is booked
  k.du = {1e-6, 0, 0};
  const Vec3 F2 = HertzLaw::update(k, h, nullptr, c, M);
  EXPECT_NEAR(std::abs(F2.x), 0.5 * F2.z, 1e-12 * F2.z);
  EXPECT_TRUE(h.flags & ContactHist::kSlip);
  EXPECT_GT(h.e_slip, 0.0);
  // separation: no force, no tension
  k.gap = 1e-9;
  k.du = {};
  EXPECT_EQ(norm(HertzLaw::update(k, h, nullptr, c, M)), 0.0);
  EXPECT_EQ(h.fn, 0.0);
}

// A rigid wall doubles E* and G* (docs/theory.md §1.9).
TEST(Hertz, WallConstantsAreThoseOfARigidWall) {
  ContactFamilyParams f;
  f.model = ContactModel::kHertz;
  const LawConst g = HertzLaw::constants(f, true, false), w = HertzLaw::constants(f, true, true);
  EXPECT_DOUBLE_EQ(w.hz_e, 2.0 * g.hz_e);
  EXPECT_DOUBLE_EQ(w.hz_g, 2.0 * g.hz_g);
}

// The registry: every model has a law whose name maps back to it; bonds only where the law
// has them; a Hertz family refuses to bond, naming the law.
TEST(LawRegistry, NamesRoundTripAndBondFlags) {
  for (ContactModel m : kAllModels) {
    ContactModel back{};
    ASSERT_TRUE(law_from_name(law_name(m), back)) << law_name(m);
    EXPECT_EQ(back, m);
  }
  ContactModel x{};
  EXPECT_FALSE(law_from_name("linearpbond", x));
  EXPECT_STREQ(to_string(ContactModel::kLinearPBond), "pbond");  // the scene's name everywhere
  EXPECT_FALSE(law_has_bond(ContactModel::kLinear));
  EXPECT_TRUE(law_has_bond(ContactModel::kLinearPBond));
  EXPECT_TRUE(law_has_bond(ContactModel::kSoftBond));
  EXPECT_FALSE(law_has_bond(ContactModel::kHertz));
  WorldParams p;
  p.ball_ball.model = ContactModel::kHertz;
  World w(p);
  w.add_ball({0, 0, 0}, 1e-4);
  w.add_ball({2e-4, 0, 0}, 1e-4);
  try {
    w.bond_ball_ball(-1.0, 1.0);
    FAIL() << "a Hertz family bonded";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'hertz'"), std::string::npos) << e.what();
  }
}

// A Hertz pile dropped onto a plane under its own weight: the work of gravity equals kinetic +
// stored energy + damping + friction (docs/theory.md §8.18) once it has landed.
TEST(Hertz, PackingSettlesWithTheEnergyBalanceClosed) {
  WorldParams p;
  p.ball_ball.model = ContactModel::kHertz;
  p.ball_wall.model = ContactModel::kHertz;
  p.local_damping = 0.3;
  World w(p);
  w.add_plane(PlaneWallParams{});
  const double R = 1e-4;
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i)
        w.add_ball({(2.05 * i + 0.1 * (k % 2)) * R, (2.05 * j + 0.07 * k) * R, (1.0 + 2.2 * k) * R},
                   R * (1.0 - 0.03 * ((i + j + k) % 3)));
  w.set_gravity(true, 1.0);
  std::vector<Vec3> x0 = w.balls().x;
  w.step(20000);
  double work = 0.0;  // gravity work = m g (z0 − z)
  for (std::size_t i = 0; i < w.num_balls(); ++i) work += w.balls().m[i] * p.g0 * (x0[i].z - w.balls().x[i].z);
  const Energy e = w.energy();
  const double sum = e.kinetic + e.strain + e.damping + e.friction;
  std::printf("settled Hertz packing: gravity work %.4e J, kinetic %.2e, strain %.3e, damping %.3e, friction %.3e\n",
              work, e.kinetic, e.strain, e.damping, e.friction);
  EXPECT_GT(e.strain, 0.0);
  EXPECT_GT(e.damping, 0.5 * work);  // the pile has landed: most of the work is dissipated
  EXPECT_NEAR(sum / work, 1.0, 1e-2);
}
