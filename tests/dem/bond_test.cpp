// Bond model checks: parallel bond (docs/theory.md §2, §8.4–8.6) and soft bond (§3, §8.7).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kPi = 3.14159265358979323846;

// A chain of n+1 touching balls of radius R along x, bonded with the parallel bond
// (linear part off, §8.4) and ball 0 clamped.
WorldParams chain_params(ContactModel model) {
  WorldParams p;
  p.local_damping = 0.7;
  p.ball_ball.model = model;
  if (model == ContactModel::kLinearPBond) p.ball_ball.linear.emod = 0.0;  // linear part off
  p.ball_ball.softbond.soft = 0.0;
  return p;
}

void make_chain(World& w, int n, double R) {
  for (int i = 0; i <= n; ++i) w.add_ball({2 * R * i, 0, 0}, R);
  w.balls().fix[0] = kFixAll;
  ASSERT_EQ(w.bond_ball_ball(-1e-9, 1e-9), static_cast<std::size_t>(n));
}

void run_to_rest(World& w, double ratio, int max_steps) {
  for (int k = 0; k < max_steps; k += 100) {
    w.step(100);
    if (w.max_unbalanced_force() <= ratio) return;
  }
}
}  // namespace

// §8.4: axial stiffness of a bonded chain: elongation N P/(k̄_n Ā), modulus Ē* exactly.
TEST(ParallelBond, ChainAxialStiffness) {
  const int N = 4;
  const double R = 5e-5;
  WorldParams p = chain_params(ContactModel::kLinearPBond);
  World w(p);
  make_chain(w, N, R);
  const double A = kPi * R * R, kbn = p.ball_ball.pbond.emod / (2 * R);
  const double P = 1e-2 * p.ball_ball.pbond.ten * A;
  w.balls().fa[N] = {P, 0, 0};
  run_to_rest(w, 1e-12 * P, 400000);
  const double elong = w.balls().x[N].x - 2 * R * N;
  const double E = (P / A) / (elong / (2 * R * N));
  EXPECT_NEAR(E / p.ball_ball.pbond.emod, 1.0, 1e-6);
  EXPECT_NEAR(elong / (N * P / (kbn * A)), 1.0, 1e-6);
  std::printf("axial: E/E*-1 = %.2e\n", E / p.ball_ball.pbond.emod - 1);
}

// §2.5: a bonded pair pulled apart breaks in tension when N̄ first exceeds σ̄_c Ā.
TEST(ParallelBond, TensileBreakAtStrength) {
  const double R = 5e-5;
  WorldParams p = chain_params(ContactModel::kLinearPBond);
  p.dt_fixed = 1e-9;
  World w(p);
  make_chain(w, 1, R);
  const double A = kPi * R * R, kbn = p.ball_ball.pbond.emod / (2 * R);
  const double Fc = p.ball_ball.pbond.ten * A;
  const double dN = 1e-4 * Fc;  // force increment per step
  w.balls().fix[1] = kFixAll;
  w.balls().v[1] = {dN / (kbn * A * p.dt_fixed), 0, 0};
  double last_intact = 0;
  int steps = 0;
  while (w.pair_contacts().bond[0].state == BondState::kIntact && steps < 20000) {
    last_intact = w.pair_contacts().bond[0].nb;
    w.step();
    ++steps;
  }
  EXPECT_EQ(w.pair_contacts().bond[0].state, BondState::kBrokenTension);
  EXPECT_LE(last_intact, Fc);
  EXPECT_GT(last_intact + dN * (1 + 1e-9), Fc);
  EXPECT_EQ(w.pair_contacts().bond[0].nb, 0.0);
  std::printf("tension break: last intact N/(sigma_c A) = %.8f (step %.1e)\n", last_intact / Fc, dN / Fc);
}

// Strictly-greater break test (U15): a bond loaded exactly to σ̄_c survives.
TEST(ParallelBond, KernelStrictBreak) {
  BondHist b;
  b.rb = 1e-4;
  b.kn = 1.0 / b.area();  // k̄_n Ā = 1 N/m: the force equals the displacement exactly
  b.state = BondState::kIntact;
  LawConst c;
  c.ks_kn = 1 / 2.4;
  c.sigc = 1.0 / b.area();  // σ̄_c Ā = 1 N
  c.coh = 1e30;
  c.tanphi = 0.5;
  const Vec3 n{1, 0, 0};
  Vec3 F{}, M{};
  b.nb = 0;
  pbond_update(b, c, 1.0, {}, 0, {}, n, F, M);  // N̄ = 1 N = σ̄_c Ā
  EXPECT_EQ(b.state, BondState::kIntact);
  EXPECT_EQ(b.nb, 1.0);
  pbond_update(b, c, 1e-6, {}, 0, {}, n, F, M);
  EXPECT_EQ(b.state, BondState::kBrokenTension);
}

// §8.5: cantilever chain vs the exact discrete formula (1e-4) and Euler–Bernoulli.
TEST(ParallelBond, ChainCantilever) {
  const int N = 5;
  const double R = 5e-5;
  WorldParams p = chain_params(ContactModel::kLinearPBond);
  World w(p);
  make_chain(w, N, R);
  const auto& pb = p.ball_ball.pbond;
  const double A = kPi * R * R, I = 0.25 * A * R * R;
  const double kbn = pb.emod / (2 * R), kbs = kbn / pb.kratio;
  const double kr = kbn * I, Ks = kbs * A;
  const double L = 2 * R * N;
  const double P = 1e-9;
  w.balls().fa[N] = {0, 0, P};
  run_to_rest(w, 1e-13 * P, 2000000);
  const double d = w.balls().x[N].z;
  const double ref = P * R * R * N * (4.0 * N * N - 1) / (3 * kr) + N * P / Ks;
  EXPECT_NEAR(d / ref, 1.0, 1e-4);
  const double bend = d - N * P / Ks;
  const double eb = P * L * L * L / (3 * pb.emod * I);
  EXPECT_LE(std::abs(bend / eb - 1.0), 1.0 / (4.0 * N * N) + 1e-4);
  // bond moment at bond 1: M_1 = P (L − x_1), x_1 = R
  const double m1 = norm(w.pair_contacts().bond[0].mb);
  EXPECT_NEAR(m1 / (P * (L - R)), 1.0, 1e-4);
  std::printf("cantilever: d/ref-1 = %.2e, bend/EB = %.6f (1-1/4N^2 = %.6f), M1/ref-1 = %.2e\n",
              d / ref - 1, bend / eb, 1 - 1.0 / (4.0 * N * N), m1 / (P * (L - R)) - 1);
}

// §8.6: torsion of a bonded chain: tip rotation N M_t/(k̄_s J̄).
TEST(ParallelBond, ChainTorsion) {
  const int N = 4;
  const double R = 5e-5;
  WorldParams p = chain_params(ContactModel::kLinearPBond);
  World w(p);
  make_chain(w, N, R);
  const auto& pb = p.ball_ball.pbond;
  const double A = kPi * R * R, J = 0.5 * A * R * R;
  const double kbs = pb.emod / (2 * R) / pb.kratio;
  const double Mt = 1e-12;
  w.balls().ta[N] = {Mt, 0, 0};
  // integrate the tip rotation from ω (spheres carry no orientation)
  double rot = 0;
  for (int k = 0; k < 400000; ++k) {
    w.step();
    rot += w.balls().w[N].x * w.dt();
    if (k % 100 == 0 && w.max_unbalanced_force() < 1e-30 && std::abs(w.balls().t[N].x + Mt) < 1e-9 * Mt) break;
  }
  const double ref = N * Mt / (kbs * J);
  EXPECT_NEAR(rot / ref, 1.0, 1e-4);
  // peak shear stress β̄ M_t R̄/J̄ in every bond
  const double tau = std::abs(w.pair_contacts().bond[0].mt) * R / J;
  EXPECT_NEAR(tau / (Mt * R / J), 1.0, 1e-4);
  std::printf("torsion: rot/ref-1 = %.2e\n", rot / ref - 1);
}

// ------------------------------------------------------------------------------------------
// Soft bond (§3.3–3.5)

namespace {
// Soft-bond geometry and constants for a pair of equal balls (§3.3), written out here
// independently of World::init_contact.
struct Soft {
  BondHist b;
  double area, inertia, polar, ks, sigc = 0.45e6;
};
Soft soft_geometry(double R, double E, double kratio) {
  Soft s;
  s.b.rb = R;
  s.b.kn = E / (2 * R);
  s.b.sigma_t = s.sigc;
  s.b.state = BondState::kIntact;
  s.area = kPi * R * R;
  s.inertia = 0.25 * s.area * R * R;
  s.polar = 2 * s.inertia;
  s.ks = s.b.kn / kratio;
  return s;
}
LawConst soft_const(double zeta, double gamma) {
  LawConst c;
  c.zeta = zeta;
  c.gamma = gamma;
  c.ks_kn = 1 / 2.4;
  c.sigc = 0.45e6;
  c.coh = 0.45e6;
  c.tanphi = std::tan(32 * kPi / 180);
  return c;
}
}  // namespace

// §3.8 test 1 through the World: trilinear path, unload/reload with slope K_n and the
// plastic offset kept, break at u_brk = u_pk[1 + ζ(1−γ)].
TEST(SoftBond, LoadUnloadPath) {
  const double R = 5.8e-5;
  WorldParams p;
  p.ball_ball.model = ContactModel::kSoftBond;
  p.dt_fixed = 1e-9;
  World w(p);
  w.add_ball({0, 0, 0}, R);
  w.add_ball({2 * R, 0, 0}, R);
  w.balls().fix[0] = w.balls().fix[1] = kFixAll;
  ASSERT_EQ(w.bond_ball_ball(-1e-12, 1e-12), 1u);
  const auto& sb = p.ball_ball.softbond;
  const double A = kPi * R * R, kn = p.ball_ball.linear.emod / (2 * R), Kn = kn * A;
  const double upk = sb.ten / kn, ubrk = upk * (1 + sb.soft * (1 - sb.cut));
  const double du = upk / 200.0;
  auto set_rate = [&](double s) { w.balls().v[1] = {s * du / p.dt_fixed, 0, 0}; };
  auto u = [&] { return w.balls().x[1].x - 2 * R; };
  auto N = [&] { return -w.pair_contacts().h[0].fn; };
  double err_el = 0, err_soft = 0, err_unl = 0;
  set_rate(1.0);
  // elastic branch: N = K_n u
  for (int k = 0; k < 150; ++k) {
    w.step();
    err_el = std::max(err_el, std::abs(N() - Kn * u()) / (sb.ten * A));
  }
  // into softening, to the middle of the branch
  const double umid = 0.5 * (upk + ubrk);
  while (u() < umid) {
    w.step();
    if (u() > upk * 1.01) {
      const double ref = (sb.ten - (kn / sb.soft) * (u() - upk)) * A;
      err_soft = std::max(err_soft, std::abs(N() - ref) / (sb.ten * A));
    }
  }
  EXPECT_EQ(w.pair_contacts().bond[0].state, BondState::kSoftening);
  const double u_turn = u(), N_turn = N();
  // unload with slope K_n, then reload: the plastic offset is kept
  set_rate(-1.0);
  for (int k = 0; k < 100; ++k) {
    w.step();
    err_unl = std::max(err_unl, std::abs(N() - (N_turn - Kn * (u_turn - u()))) / (sb.ten * A));
  }
  set_rate(1.0);
  for (int k = 0; k < 100; ++k) {
    w.step();
    err_unl = std::max(err_unl, std::abs(N() - (N_turn - Kn * (u_turn - u()))) / (sb.ten * A));
  }
  EXPECT_EQ(w.pair_contacts().bond[0].state, BondState::kSoftening);
  // continue to the break
  double u_break = 0;
  while (w.pair_contacts().bond[0].state == BondState::kSoftening && u() < 2 * ubrk) {
    w.step();
    if (w.pair_contacts().bond[0].state == BondState::kBrokenTension) u_break = u();
  }
  EXPECT_LT(err_el, 1e-9);
  EXPECT_LT(err_soft, 1e-9);
  EXPECT_LT(err_unl, 1e-9);
  EXPECT_EQ(w.pair_contacts().bond[0].state, BondState::kBrokenTension);
  EXPECT_NEAR(u_break, ubrk, 1.01 * du);
  EXPECT_EQ(N(), 0.0);  // tension cannot be carried after the break (§3.5)
  std::printf("softbond path: err elastic %.1e softening %.1e unload %.1e; u_break/u_brk-1 = %.2e\n",
              err_el, err_soft, err_unl, u_break / ubrk - 1);
}

// §3.8 test 2: pure bending, N = 0: peak moment σ_c I/(βR̄), then softening. N = 0 is
// held by letting the contact open or close freely: each step the normal increment is the
// one that brings the predicted N back to zero (a free ball would translate that way).
TEST(SoftBond, PureBendingPeak) {
  Soft g = soft_geometry(5.8e-5, 2.8e9, 2.4);
  BondHist& b = g.b;
  LawConst c = soft_const(100, 0.05);
  ContactHist h;
  h.kn = b.kn * g.area;
  h.ks = g.ks * g.area;
  h.mu = 0.5;
  h.flags = ContactHist::kIncremental | ContactHist::kHasNormal;
  const Vec3 n{1, 0, 0};
  h.n_old = n;
  const double th_pk = g.sigc / (b.kn * b.rb);  // rotation at the peak (β = 1)
  Kin k;
  k.n = n;
  k.dt = 1.0;
  const int nsteps = 5000;
  k.dtheta = {0, th_pk / nsteps, 0};
  double mmax = 0, m_end = 0;
  for (int s = 0; s < 3 * nsteps; ++s) {
    k.du = {h.fn / (b.kn * g.area), 0, 0};
    Vec3 M;
    contact_law<ContactModel::kSoftBond>(k, h, &b, c, M);
    mmax = std::max(mmax, norm(M));
    m_end = norm(M);
  }
  const double ref = g.sigc * g.inertia / b.rb;
  EXPECT_NEAR(mmax / ref, 1.0, 1.0 / nsteps);
  EXPECT_EQ(b.state, BondState::kSoftening);
  EXPECT_LT(m_end, mmax);  // softening after the peak
  // associated return keeps σ on the current strength
  const double sigma = -h.fn / g.area + norm(b.mb) * b.rb / g.inertia;
  EXPECT_NEAR(sigma / b.sigma_t, 1.0, 1e-12);
  std::printf("bending: Mmax/ref-1 = %.2e\n", mmax / ref - 1);
}

// §3.8 test 3: shear under confinement breaks at τ = c − (N/A) tanφ → BROKEN_SHEAR.
TEST(SoftBond, ShearBreakUnderCompression) {
  Soft g = soft_geometry(5.8e-5, 2.8e9, 2.4);
  BondHist& b = g.b;
  LawConst c = soft_const(100, 0.05);
  ContactHist h;
  h.kn = b.kn * g.area;
  h.ks = g.ks * g.area;
  h.mu = 0.5;
  h.flags = ContactHist::kIncremental | ContactHist::kHasNormal;
  const Vec3 n{1, 0, 0};
  h.n_old = n;
  Kin k;
  k.n = n;
  k.dt = 1.0;
  const double sig_n = -0.3e6;  // compression
  k.du = {sig_n / b.kn, 0, 0};
  Vec3 M;
  contact_law<ContactModel::kSoftBond>(k, h, &b, c, M);
  const double tau_c = c.coh - sig_n * c.tanphi;
  const double dus = tau_c / g.ks / 2000.0;
  k.du = {0, dus, 0};
  double tau_last = 0;
  int steps = 0;
  while (b.state == BondState::kIntact && steps < 5000) {
    tau_last = norm(h.fs) / g.area;
    contact_law<ContactModel::kSoftBond>(k, h, &b, c, M);
    ++steps;
  }
  EXPECT_EQ(b.state, BondState::kBrokenShear);
  EXPECT_LE(tau_last, tau_c);
  EXPECT_GT(tau_last, tau_c * (1 - 1.0 / 1999.0));
  // after the break the shear force is limited by Coulomb friction μ F_n
  EXPECT_LE(norm(h.fs), h.mu * h.fn * (1 + 1e-12));
  std::printf("shear break: tau_last/tau_c = %.6f\n", tau_last / tau_c);
}

// §3.8 test 4: ζ = 0 reproduces the PBM tensile break (same geometry, Ē* = E*).
TEST(SoftBond, ZetaZeroEqualsParallelBond) {
  Soft g = soft_geometry(5.8e-5, 2.8e9, 2.4);
  BondHist& s = g.b;
  BondHist pbh = s;
  LawConst c = soft_const(0.0, 0.05);
  ContactHist h;
  h.kn = s.kn * g.area;
  h.ks = g.ks * g.area;
  h.mu = 0.5;
  h.flags = ContactHist::kIncremental | ContactHist::kHasNormal;
  const Vec3 n{1, 0, 0};
  h.n_old = n;
  const double du = g.sigc / s.kn / 777.0;
  int step_soft = -1, step_pb = -1;
  double Nmax_soft = 0, Nmax_pb = 0;
  for (int k = 0; k < 2000; ++k) {
    Kin kin;
    kin.n = n;
    kin.du = {du, 0, 0};
    kin.dtheta = {0, 0.3 * du / s.rb, 0};  // combined bending
    Vec3 M;
    if (step_soft < 0) {
      contact_law<ContactModel::kSoftBond>(kin, h, &s, c, M);
      if (s.state == BondState::kBrokenTension) step_soft = k;
      else Nmax_soft = std::max(Nmax_soft, -h.fn);
    }
    if (step_pb < 0) {
      Vec3 F{}, Mp{};
      const double dtt = 0;
      pbond_update(pbh, c, du, {}, dtt, kin.dtheta, n, F, Mp);
      if (pbh.state == BondState::kBrokenTension) step_pb = k;
      else Nmax_pb = std::max(Nmax_pb, pbh.nb);
    }
  }
  EXPECT_GE(step_soft, 0);
  EXPECT_EQ(step_soft, step_pb);
  EXPECT_NEAR(Nmax_soft / Nmax_pb, 1.0, 1e-12);
  std::printf("zeta=0: break step soft %d pbm %d\n", step_soft, step_pb);
}

// §3.5: unbonded soft-bond moment limits λ_b F_n R̄/4 and (2/3) μ F_n R̄.
namespace {
// An unbonded soft-bond contact (state `st`) along x, overlapping by 1e-8 m, μ = 0.5, Δt = 1 s.
struct Unbonded {
  Soft g = soft_geometry(5.8e-5, 2.8e9, 2.4);
  LawConst c = soft_const(100, 0.05);
  ContactHist h;
  Kin k;
  explicit Unbonded(BondState st) {
    g.b.state = st;
    h.kn = g.b.kn * g.area;
    h.ks = g.ks * g.area;
    h.mu = 0.5;
    h.flags = ContactHist::kHasNormal;
    h.n_old = {1, 0, 0};
    k.n = h.n_old;
    k.gap = -1e-8;
    k.dt = 1.0;
  }
  // `steps` calls of the soft-bond law with the rotation increment dtheta per step.
  void rotate(const Vec3& dtheta, int steps) {
    k.dtheta = dtheta;
    Vec3 M;
    for (int s = 0; s < steps; ++s) contact_law<ContactModel::kSoftBond>(k, h, &g.b, c, M);
  }
};
}  // namespace

TEST(SoftBond, UnbondedMomentLimits) {
  Unbonded u(BondState::kNeverBonded);
  u.rotate({1e-5, 1e-5, 0}, 200);
  const BondHist& b = u.g.b;
  const ContactHist& h = u.h;
  const double Fn = h.kn * 1e-8;
  EXPECT_NEAR(h.fn / Fn, 1.0, 1e-12);
  EXPECT_NEAR(norm(b.mb) / (Fn * b.rb / 4), 1.0, 1e-12);
  EXPECT_NEAR(std::abs(b.mt) / (2.0 / 3.0 * 0.5 * Fn * b.rb), 1.0, 1e-12);
}

// §3.5 with §8.18: a moment held at its limit slips, and the work of the slip is booked with the
// contact's frictional slip. Monotone rotation θ at a fixed F_n, elastic up to M_lim/k, then
// slipping: the work M_lim θ − M_lim²/(2k) = stored M_lim²/(2k) + booked, for bending and
// twisting alike, so the booked slip is M_lim θ − M_lim²/k summed over both.
TEST(SoftBond, UnbondedMomentSlipWorkIsBooked) {
  Unbonded u(BondState::kBrokenShear);
  const double dth = 1e-5;
  const int steps = 300;
  u.rotate({dth, 0, dth}, steps);  // twist about n, bending about z
  const BondHist& b = u.g.b;
  const LawConst& c = u.c;
  const ContactHist& h = u.h;
  const double Fn = h.kn * 1e-8, theta = steps * dth;
  const double mbl = Fn * b.rb / 4, kb = b.kn * b.inertia();
  const double mtl = 2.0 / 3.0 * 0.5 * Fn * b.rb, kt = b.kn * c.ks_kn * b.polar();
  ASSERT_LT(mbl / kb, 0.5 * theta);  // both moments reach their limits early in the run
  ASSERT_LT(mtl / kt, 0.5 * theta);
  const double want = mbl * theta - mbl * mbl / kb + mtl * theta - mtl * mtl / kt;
  EXPECT_NEAR(h.e_slip / want, 1.0, 1e-9) << "booked " << h.e_slip << " J, expected " << want << " J";
  double stored = 0.0;
  ContactFamilyParams f;
  f.linear.kratio = 1.0 / c.ks_kn;
  SoftBondLaw::add_strain(stored, h, &b, f);
  const double work = mbl * theta - 0.5 * mbl * mbl / kb + mtl * theta - 0.5 * mtl * mtl / kt;
  EXPECT_NEAR((stored - 0.5 * h.fn * h.fn / h.kn + h.e_slip) / work, 1.0, 1e-9);
}
