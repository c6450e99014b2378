// Checks of the performance work on the ball–ball pass (bench/dem, issue 3 items 9 and 12):
// the cheaper plane-rotation rescale agrees with the exact form, and the threaded pass gives
// the serial forces (to rounding) and bit-identical results from run to run.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>

#include "demfdm/dem/contact_kernels.hpp"
#include "demfdm/dem/world.hpp"
#include "lattice.hpp"

using namespace demfdm::dem;

namespace {
// docs/theory.md §1.6 as written before the optimisation: the rescale by √(m2/k2) exactly.
void rotate_reference(Vec3& v, const Vec3& n_old, const Vec3& n_new, const Vec3& wmean, double dt) {
  const double m2 = norm2(v);
  if (m2 == 0.0) return;
  v -= cross(v, cross(n_old, n_new));
  v -= cross(v, (dot(wmean, n_new) * dt) * n_new);
  v -= dot(v, n_new) * n_new;
  const double k2 = norm2(v);
  if (k2 > 0.0) v *= std::sqrt(m2 / k2);
}

Vec3 unit(const Vec3& a) { return a * (1.0 / norm(a)); }
}  // namespace

// The series path (|δ| < 1e-6) must agree with √(m2/k2) to a few ulps, and the rescale keeps
// ‖v‖ (the invariant of §1.6 step 3) for small and for large rotations.
TEST(PerfKernels, RotateRescaleMatchesExact) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  double err_small = 0.0, err_large = 0.0, norm_err = 0.0;
  int n_small = 0, n_large = 0;
  for (int it = 0; it < 200000; ++it) {
    const Vec3 n_old = unit({u(rng), u(rng), u(rng)});
    // tilt from 1e-9 to 1e-1 rad: both paths of the rescale are exercised
    const double tilt = std::pow(10.0, -9.0 + 8.0 * (0.5 + 0.5 * u(rng)));
    const Vec3 n_new = unit(n_old + tilt * Vec3{u(rng), u(rng), u(rng)});
    Vec3 v0 = Vec3{u(rng), u(rng), u(rng)};
    v0 -= dot(v0, n_old) * n_old;
    const Vec3 wmean{1e3 * u(rng), 1e3 * u(rng), 1e3 * u(rng)};
    const double dt = 1e-9 * (1.0 + u(rng));
    Vec3 a = v0, b = v0;
    rotate_into_plane(a, n_old, n_new, wmean, dt, true);
    rotate_reference(b, n_old, n_new, wmean, dt);
    const double e = norm(a - b) / norm(b);
    const double ne = std::abs(norm(a) - norm(v0)) / norm(v0);
    norm_err = std::max(norm_err, ne);
    if (tilt < 1e-4) { err_small = std::max(err_small, e); ++n_small; }
    else { err_large = std::max(err_large, e); ++n_large; }
  }
  EXPECT_GT(n_small, 1000);
  EXPECT_GT(n_large, 1000);
  EXPECT_LT(err_small, 1e-15);
  EXPECT_LT(err_large, 1e-15);
  EXPECT_LT(norm_err, 1e-15);
  std::printf("rotate rescale: max rel diff %.2e (small tilts, %d) %.2e (large, %d), |v| kept to %.2e\n",
              err_small, n_small, err_large, n_large, norm_err);
  Vec3 z{};  // a zero vector stays exactly zero
  rotate_into_plane(z, {0, 0, 1}, unit({0.1, 0, 1}), {1, 2, 3}, 1e-6, true);
  EXPECT_EQ(norm2(z), 0.0);
}

namespace {
// 16³ balls on a jittered periodic cubic lattice, spacing slightly below 2R: about
// 3 touching pairs per ball (> 4096 pairs, so the threaded branch of the pass runs).
struct LatticeRun {
  std::vector<Vec3> x, f;
  std::uint64_t hash = 0;
  std::size_t pairs = 0;
  double fsum_rel = 0.0;  // ‖Σ f_i‖ / Σ ‖f_i‖ (Newton's third law)
};

LatticeRun lattice_run(int threads, ContactModel model) {
  const int nside = 16;
  const double R = 0.5e-3, s = 1.98 * R;
  WorldParams p;
  p.density = 2650.0;
  p.threads = threads;
  p.periodic.enabled = true;
  p.periodic.origin = {0, 0, 0};
  p.periodic.length = {nside * s, nside * s, nside * s};
  p.ball_ball.model = model;
  p.ball_ball.linear.kn_fixed = 1e5;
  p.ball_ball.linear.kratio = 2.0;
  p.ball_ball.linear.fric = 0.5;
  World w(p);
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  test::add_jittered_lattice(w, nside, s, R, 0.01 * R, 0.005, rng);
  for (auto& v : w.balls().v) v = {0.01 * u(rng), 0.01 * u(rng), 0.01 * u(rng)};
  for (auto& om : w.balls().w) om = {20.0 * u(rng), 20.0 * u(rng), 20.0 * u(rng)};
  w.prepare();
  if (model == ContactModel::kSoftBond) w.bond_ball_ball(-1.0, 0.0);
  w.step(40);
  LatticeRun r;
  r.x = w.balls().x;
  r.f = w.balls().f;
  r.pairs = w.pair_contacts().size();
  std::uint64_t h = 1469598103934665603ULL;
  auto mix = [&](double d) {
    std::uint64_t b;
    std::memcpy(&b, &d, 8);
    for (int k = 0; k < 8; ++k) { h ^= (b >> (8 * k)) & 0xff; h *= 1099511628211ULL; }
  };
  Vec3 fs{};
  double fa = 0.0;
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    for (int k = 0; k < 3; ++k) { mix(w.balls().x[i][k]); mix(w.balls().v[i][k]); mix(w.balls().w[i][k]); }
    fs += w.balls().f[i];
    fa += norm(w.balls().f[i]);
  }
  r.hash = h;
  r.fsum_rel = norm(fs) / fa;
  return r;
}
}  // namespace

// The 2-thread pass (contact blocks, per-thread buffers, fixed-order reduction) must give the
// serial forces to rounding, conserve momentum, and repeat bit for bit.
TEST(PerfKernels, ThreadedPassMatchesSerial) {
  for (ContactModel model : {ContactModel::kLinear, ContactModel::kSoftBond}) {
    const LatticeRun s1 = lattice_run(1, model), t2a = lattice_run(2, model), t2b = lattice_run(2, model);
    EXPECT_GT(s1.pairs, 4096u);
    EXPECT_EQ(t2a.hash, t2b.hash);
    double fmax = 0.0, df = 0.0, dx = 0.0;
    for (std::size_t i = 0; i < s1.f.size(); ++i) {
      fmax = std::max(fmax, norm(s1.f[i]));
      df = std::max(df, norm(s1.f[i] - t2a.f[i]));
      dx = std::max(dx, norm(s1.x[i] - t2a.x[i]));
    }
    ASSERT_GT(fmax, 0.0);
    EXPECT_LT(df / fmax, 1e-9);
    EXPECT_LT(dx, 1e-15);  // [m], R = 0.5 mm: positions agree to ~1e-12 R
    EXPECT_LT(s1.fsum_rel, 1e-12);
    EXPECT_LT(t2a.fsum_rel, 1e-12);
    std::printf("%s: %zu pairs, 1 vs 2 threads max |Δf|/max|f| = %.2e, max |Δx| = %.2e m, "
                "|Σf|/Σ|f| = %.2e / %.2e\n",
                model == ContactModel::kLinear ? "linear" : "softbond", s1.pairs, df / fmax, dx,
                s1.fsum_rel, t2a.fsum_rel);
  }
}
