// Periodic cell, Love–Weber stress, servo, specimen generation, replication and depth
// scaling (docs/theory.md §0.4, §4, §8.8, §8.9).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>

#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kPi = 3.14159265358979323846;

// Simple cubic lattice of n³ balls, spacing a, overlap δ, in a periodic cell.
void lattice(World& w, int n, double a, double delta) {
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) w.add_ball({(i + 0.5) * a, (j + 0.5) * a, (k + 0.5) * a}, 0.5 * (a + delta));
}

WorldParams rev_params(double Lx, double Ly, double Lz) {
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.length = {Lx, Ly, Lz};
  p.local_damping = 0.7;
  p.threads = 1;  // thread counts are exercised by the determinism tests
  return p;
}

ServoParams servo_target() {
  ServoParams s;
  s.target = {125e3, 125e3, 250e3};
  return s;
}

// A small periodic REV, servoed; shared by several tests (generated once).
struct Rev {
  std::unique_ptr<World> w;
  StageReport gen, servo;
  double overshoot = 0;
};
Rev& shared_rev() {
  static Rev rev = [] {
    Rev r;
    r.w = std::make_unique<World>(rev_params(0.8e-3, 0.8e-3, 0.8e-3));
    RevParams g;
    g.seed = 8;  // seeds 7, 8, 9 give overshoots 0.155, 0.101, 0.040 (all converge)
    g.porosity_target = 0.38;  // frictionless expansion close to jamming (§4.3)
    g.ratio_tol = 1e-2;
    g.increment_budget = 2400;  // 3000 steps at dt_safety 0.8
    r.gen = generate_rev(*r.w, g);
    // K0 = 0.5 targets, 20× the paper's 100g REV stress to keep the test short; μ = tan 32°
    r.servo = servo_until(*r.w, servo_target(), 0.005, 1e-2, 80, 32000, &r.overshoot);
    return r;
  }();
  return rev;
}
}  // namespace

// §8.8: simple cubic lattice, every contact f = k_n δ, σ_xx = σ_yy = σ_zz = −f/a² exactly.
TEST(Periodic, SimpleCubicLoveWeberStress) {
  const int n = 4;
  const double a = 2e-4, delta = 1e-7;
  World w(rev_params(n * a, n * a, n * a));
  lattice(w, n, a, delta);
  w.prepare();
  const double R = 0.5 * (a + delta);
  const double kn = kPi * R * R * w.params().ball_ball.linear.emod / (2 * R);
  const Mat3 s = cell_stress(w);
  const double ref = -kn * delta / (a * a);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s[4 * i] / ref, 1.0, 1e-9);
  EXPECT_NEAR(s[1], 0.0, 1e-9 * std::abs(ref));
  const Coordination z = coordination(w);
  EXPECT_EQ(z.z, 6.0);
  EXPECT_EQ(z.rattlers, 0u);
  EXPECT_NEAR(cell_porosity(w), 1.0 - 4.0 / 3.0 * kPi * R * R * R / (a * a * a), 1e-12);
  // particle-based stress over a sub-box holding whole balls: same tensor
  Region box;
  box.lo = {0, 0, 0};
  box.hi = {n * a, n * a, n * a};
  const Mat3 s2 = region_stress(w, box);
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(s2[4 * i] / ref, 1.0, 1e-9);
  std::printf("lattice: sxx/ref-1 = %.1e\n", s[0] / ref - 1);
}

// §0.4: inverse-CDF sampling of density ∝ d⁻³ (median of the number distribution).
TEST(Specimen, PsdInverseCdf) {
  PsdParams p;
  Rng rng(3);
  const double a = p.d_min, b = p.d_max;
  const double dmed = 1.0 / std::sqrt(1.0 / (a * a) - 0.5 * (1.0 / (a * a) - 1.0 / (b * b)));
  int below = 0;
  const int N = 200000;
  for (int i = 0; i < N; ++i) {
    const double d = psd_diameter(p, rng.uniform());
    ASSERT_GE(d, a);
    ASSERT_LE(d, b);
    below += d < dmed;
  }
  EXPECT_NEAR(double(below) / N, 0.5, 4 * 0.5 / std::sqrt(double(N)));
  EXPECT_DOUBLE_EQ(psd_diameter(p, 0.0), a);
  PsdParams s = p;
  s.scale = 1.5;
  EXPECT_DOUBLE_EQ(psd_diameter(s, 0.3), 1.5 * psd_diameter(p, 0.3));
}

// §4.3/§4.5: generation reaches its porosity; the servo reaches (σ_h, σ_h, σ_v) within 1 %
// with an overshoot of at most 20 %.
TEST(Specimen, GenerateAndServo) {
  Rev& r = shared_rev();
  std::printf("generate: %s (%lld steps)\nservo: %s, ratio %.2e, overshoot %.3f\n", r.gen.what.c_str(),
              (long long)r.gen.steps, r.servo.what.c_str(), r.servo.ratio, r.overshoot);
  EXPECT_GT(r.gen.count, 300u);
  EXPECT_NEAR(r.gen.porosity, 0.38, 0.01);
  EXPECT_TRUE(r.servo.converged);
  const Mat3 s = cell_stress(*r.w);
  const Vec3 t = servo_target().target;
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(-s[4 * a] / t[a], 1.0, 1e-2);
  EXPECT_LE(r.overshoot, 0.2);
  std::printf("servo errors: %.2e %.2e %.2e\n", -s[0] / t[0] - 1, -s[4] / t[1] - 1, -s[8] / t[2] - 1);
}

// Same seed → identical specimen (determinism of generation).
TEST(Specimen, GenerationIsSeeded) {
  auto gen = [](std::uint64_t seed) {
    World w(rev_params(1e-3, 1e-3, 1e-3));
    RevParams g;
    g.seed = seed;
    g.increments = 1;
    g.increment_budget = 160;  // 200 steps at dt_safety 0.8
    generate_rev(w, g);
    return w.balls().x;
  };
  const auto a = gen(11), b = gen(11), c = gen(12);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].x, b[i].x);
    EXPECT_EQ(a[i].z, b[i].z);
  }
  EXPECT_NE(a[0].x, c[0].x);
}

// A copy of a REV made by replaying its balls and contacts (the replication tests).
static std::unique_ptr<World> clone_rev(const World& w0) {
  auto w = std::make_unique<World>(w0.params());
  const auto& pt = w0.balls();
  for (std::size_t i = 0; i < pt.size(); ++i) w->add_ball(pt.x[i], pt.r[i]);
  const auto& pc = w0.pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c)
    w->append_pair(pc.a[c], pc.b[c], pc.shift[c], pc.h[c], pc.bond.empty() ? nullptr : &pc.bond[c]);
  return w;
}

// §4.7/§8.9: 2×2×2 periodic replication keeps the stress tensor; opening the faces drops
// exactly the contacts across them.
TEST(Specimen, ReplicationPreservesStress) {
  Rev& r = shared_rev();
  World& w0 = *r.w;
  const Mat3 s0 = cell_stress(w0);
  // copy the REV into two new worlds by replaying its balls and contacts
  auto w1 = clone_rev(w0);
  ReplicateParams rp;
  rp.nx = rp.ny = rp.nz = 2;
  rp.keep_periodic = true;
  const StageReport rr = replicate(*w1, rp);
  EXPECT_EQ(rr.count, 8 * w0.num_balls());
  const Mat3 s1 = cell_stress(*w1);
  double err = 0;
  const double scale = std::abs(s0[8]);
  for (int i = 0; i < 9; ++i) err = std::max(err, std::abs(s1[i] - s0[i]) / scale);
  EXPECT_LT(err, 0.02);
  EXPECT_NEAR(rr.porosity, r.servo.porosity, 1e-9);
  // keep cycling: the state stays in equilibrium
  const double ratio0 = w0.unbalanced_ratio();
  w1->step(200);
  EXPECT_LT(w1->unbalanced_ratio(), 2.0 * ratio0 + 1e-3);
  // open (non-periodic) stack 1×1×3: contacts crossing the outer faces are dropped
  std::size_t cross_xy = 0, cross_z = 0, total = 0;
  const auto& pc = w0.pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (norm(w0.pair_force(c)) == 0.0) continue;
    ++total;
    if (pc.shift[c][0] != 0 || pc.shift[c][1] != 0) ++cross_xy;
    else if (pc.shift[c][2] != 0) ++cross_z;
  }
  auto w2 = clone_rev(w0);
  ReplicateParams open;
  open.nx = open.ny = 1;
  open.nz = 3;
  replicate(*w2, open);
  std::size_t active = 0;
  for (std::size_t c = 0; c < w2->pair_contacts().size(); ++c) active += norm(w2->pair_force(c)) > 0.0;
  // every copy keeps its inner contacts; z-crossing contacts survive between copies (2 of 3)
  EXPECT_EQ(active, 3 * (total - cross_xy - cross_z) + 2 * cross_z);
  std::printf("replication: stress max rel diff %.1e; open stack %zu active contacts\n", err, active);
}

// ReplicateParams::spatial_order (the scene's dem.spatial_order): the block's rows renumbered
// along the Morton curve. The same balls (by id: position, radius, velocity bit for bit) and the
// same pairs with the same normal forces to round-off, the rows now in Morton order (a second
// ordering is the identity), and the state after 100 steps the same to round-off (the sums run
// in another order).
TEST(Specimen, ReplicationInSpatialOrder) {
  Rev& r = shared_rev();
  World& w0 = *r.w;
  ReplicateParams rp;
  rp.nx = 2;
  rp.ny = 1;
  rp.nz = 3;
  auto plain = clone_rev(w0), sorted = clone_rev(w0);
  replicate(*plain, rp);
  rp.spatial_order = true;
  replicate(*sorted, rp);
  const Particles& a = plain->balls();
  const Particles& b = sorted->balls();
  ASSERT_EQ(a.size(), b.size());
  std::map<std::uint64_t, std::size_t> row_a;
  for (std::size_t i = 0; i < a.size(); ++i) row_a[a.id[i]] = i;
  std::size_t moved = 0;
  for (std::size_t j = 0; j < b.size(); ++j) {
    const std::size_t i = row_a.at(b.id[j]);
    moved += i != j;
    ASSERT_EQ(std::memcmp(&a.x[i], &b.x[j], sizeof(Vec3)), 0) << "ball " << b.id[j];
    ASSERT_EQ(std::memcmp(&a.v[i], &b.v[j], sizeof(Vec3)), 0) << "ball " << b.id[j];
    ASSERT_EQ(a.r[i], b.r[j]);
  }
  EXPECT_GT(moved, a.size() / 2) << "the copies' order was already spatial";
  const std::vector<std::uint32_t> again = morton_rows(b);
  for (std::size_t j = 0; j < again.size(); ++j) ASSERT_EQ(again[j], j) << "row " << j << " not in Morton order";
  // The pairs by the ids of their balls, with |F_n| of their histories.
  auto pairs = [](const World& w) {
    std::map<std::pair<std::uint64_t, std::uint64_t>, double> m;
    const auto& pc = w.pair_contacts();
    const auto& id = w.balls().id;
    for (std::size_t c = 0; c < pc.size(); ++c) {
      const std::uint64_t p = id[pc.a[c]], q = id[pc.b[c]];
      m[{std::min(p, q), std::max(p, q)}] = pc.h[c].fn;
    }
    return m;
  };
  const auto pa = pairs(*plain), pb = pairs(*sorted);
  ASSERT_EQ(pa.size(), pb.size());
  // (replicate's prepare evaluates the forces once; a pair whose balls swapped their order forms
  // its gap as (d - R_B) - R_A, so F_n agrees to the round-off of d, which the small overlap
  // magnifies by d / overlap: 1e-9 of F_n, not to the bit)
  for (const auto& [k, fn] : pa)
    ASSERT_NEAR(pb.at(k), fn, 1e-9 * std::abs(fn)) << "pair " << k.first << "-" << k.second;
  plain->step(100);
  sorted->step(100);
  double dx = 0.0, rmin = 1e300;
  for (std::size_t j = 0; j < b.size(); ++j) {
    const std::size_t i = row_a.at(b.id[j]);  // (rows move only at the renumbering)
    dx = std::max(dx, norm(a.x[i] - b.x[j]));
    rmin = std::min(rmin, b.r[j]);
  }
  EXPECT_LT(dx, 1e-9 * rmin) << "the two orders drifted apart";
  std::printf("spatial order: %zu of %zu rows moved; after 100 steps positions within %.1e m (r_min %.1e m)\n",
              moved, b.size(), dx, rmin);
}

// §4.9: depth scaling multiplies each ball–ball force by (z_top − z_c)/H_D and switches
// the contacts to incremental mode, so the scaled forces persist.
TEST(Specimen, DepthScaling) {
  Rev& r = shared_rev();
  auto w = std::make_unique<World>(r.w->params());
  const auto& pt = r.w->balls();
  for (std::size_t i = 0; i < pt.size(); ++i) w->add_ball(pt.x[i], pt.r[i]);
  const auto& pc0 = r.w->pair_contacts();
  for (std::size_t c = 0; c < pc0.size(); ++c)
    w->append_pair(pc0.a[c], pc0.b[c], pc0.shift[c], pc0.h[c], nullptr);
  ReplicateParams open;
  open.nx = open.ny = 1;
  open.nz = 2;
  replicate(*w, open);
  const auto& pc = w->pair_contacts();
  std::map<std::pair<std::uint64_t, std::uint64_t>, double> before;
  auto key = [&](std::size_t c) {
    return std::make_pair(w->balls().id[pc.a[c]], w->balls().id[pc.b[c]]);
  };
  for (std::size_t c = 0; c < pc.size(); ++c) before[key(c)] = pc.h[c].fn;
  DepthScaleParams dp;
  dp.z_top = 2e-3;
  dp.height = 2e-3;
  depth_scale(*w, dp);
  // A force pass with zero increments (rebuild + Δu = 0): incremental mode keeps the scaled
  // forces; absolute mode would restore K_n·overlap (§4.9).
  w->prepare();
  double err = 0;
  std::size_t n = 0;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const double b0 = before.count(key(c)) ? before[key(c)] : 0.0;
    if (b0 <= 0.0) continue;
    const Vec3 d = w->branch(c);
    const double dist = norm(d);
    const double gap = dist - w->balls().r[pc.a[c]] - w->balls().r[pc.b[c]];
    const double zc = w->balls().x[pc.a[c]].z + (w->balls().r[pc.a[c]] + 0.5 * gap) * d.z / dist;
    const double f = std::clamp((dp.z_top - zc) / dp.height, 0.0, 1.0);
    err = std::max(err, std::abs(pc.h[c].fn - f * b0) / b0);
    ++n;
  }
  EXPECT_GT(n, 100u);
  EXPECT_LT(err, 1e-12);
  std::printf("depth scaling: %zu contacts, max rel deviation %.2e\n", n, err);
}

// Habit 13: a bonded random packing (soft bonds, replicated 2×2×1 so that the threaded
// paths run) gives bit-identical positions from run to run, and (thread_independent) the same
// at 1 and 2 threads.
TEST(Determinism, SameThreadCountSameHash) {
  Rev& r = shared_rev();
  auto run = [&](int threads) {
    WorldParams p = r.w->params();
    p.threads = threads;
    p.thread_independent = true;
    p.ball_ball.model = ContactModel::kSoftBond;
    World w(p);
    const auto& pt = r.w->balls();
    for (std::size_t i = 0; i < pt.size(); ++i) w.add_ball(pt.x[i], pt.r[i]);
    const auto& pc = r.w->pair_contacts();
    for (std::size_t c = 0; c < pc.size(); ++c) w.append_pair(pc.a[c], pc.b[c], pc.shift[c], pc.h[c], nullptr);
    ReplicateParams rp;
    rp.nx = rp.ny = 2;
    rp.nz = 1;
    rp.keep_periodic = true;
    replicate(w, rp);
    w.refresh_contact_constants();
    w.bond_ball_ball(-1.0, 1e-3 * 0.0655e-3);
    w.set_strain_rate({0, 0, -2.0});  // load the bonds so that some soften and break
    w.step(60);
    std::uint64_t h = 1469598103934665603ULL;  // FNV-1a over the bits of x, v, ω
    auto mix = [&](double d) {
      std::uint64_t u;
      std::memcpy(&u, &d, 8);
      for (int k = 0; k < 8; ++k) { h ^= (u >> (8 * k)) & 0xff; h *= 1099511628211ULL; }
    };
    for (std::size_t i = 0; i < w.num_balls(); ++i)
      for (int k = 0; k < 3; ++k) { mix(w.balls().x[i][k]); mix(w.balls().v[i][k]); mix(w.balls().w[i][k]); }
    EXPECT_GT(w.pair_contacts().size(), 4096u);  // the threaded branch is taken
    return h;
  };
  const auto h1a = run(1), h1b = run(1), h2a = run(2), h2b = run(2);
  EXPECT_EQ(h1a, h1b);
  EXPECT_EQ(h2a, h2b);
  EXPECT_EQ(h1a, h2a);
  std::printf("hash 1 thread %016llx / %016llx, 2 threads %016llx / %016llx\n", (unsigned long long)h1a,
              (unsigned long long)h1b, (unsigned long long)h2a, (unsigned long long)h2b);
}
