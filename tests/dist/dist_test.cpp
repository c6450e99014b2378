// The DEM on MPI ranks (dem_dist, issue 17 items 1 and 3): started by mpirun on 1, 2 and 3 ranks
// (tests/dist/CMakeLists.txt). Every rank builds the same packing; rank 0 also steps one World
// holding every ball (the reference); the ranks step the packing cut into bricks (DistDem), and
// every ball's position, velocity, spin, force and torque must equal the reference bit for bit.
// The packings are pulled apart so that balls cross brick faces, the lists are rebuilt and
// balls migrate during the run; periodic (straining cell) and free; linear and soft bond (bonds
// across brick faces soften and break); one and two threads per rank.
#include <gtest/gtest.h>
#include <mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <numeric>
#include <random>
#include <string>
#include <tuple>

#include "demfdm/dem/dist.hpp"
#include "demfdm/dem/measure.hpp"
#include "tests/dem/lattice.hpp"
#include "tests/dist/dist_util.hpp"

using namespace demfdm::dem;
using test::g_rank;
using test::g_size;

namespace {

struct Scene {
  std::string name;
  ContactModel model = ContactModel::kLinear;
  bool periodic = true;
  bool bonded = false;
  int axis = 0;  // the axis cut into bricks
  int steps = 600;
  int threads = 1;
  bool auto_dt = false;  // the automatic step instead of a fixed one
  bool rcb = false;      // recursive coordinate bisection instead of slabs along `axis`
  int balance_every = 0;  // DistDem's balancing (contact weights) every this many exchanges
  double tall = 1.0;      // the free cluster's grid: this many times as high as wide
  bool order_free = false;  // WorldParams::order_free_sums: the measurements without a gather
  bool from_root = false;   // DistDem::load_from_root: the other ranks never hold the whole World
  bool balance_at_load = false;  // set_balance before the load (as the DEM node): the first cut balanced
  double damping = 0.0;  // local damping of the periodic lattices (the free cluster: the default 0.7)
  bool migrate = true;   // balls must cross brick faces (on more than one rank)
};

constexpr int kSide = 12;  // kSide³ balls
constexpr double kR = 1e-4;

double spacing(const Scene& sc) { return (sc.bonded ? 2.0 : 1.96) * kR; }
constexpr double kDrift = 4.0;  // [m/s] the periodic lattices' drift: about R in 600 steps

// The packing of simd_kernel_test (a jittered lattice, random velocities and spins, pulled apart
// by the cell or a radial field), with a fixed step. `final_prepare`: also prepare after the
// velocities are set. The ranks load the prepared World as it is (DistDem::load).
std::unique_ptr<World> build(const Scene& sc, bool final_prepare) {
  const double s = spacing(sc);
  WorldParams p;
  p.threads = sc.threads;
  p.thread_independent = true;  // what the ranks run with (DistDem::load)
  p.order_free_sums = sc.order_free;
  p.periodic.enabled = sc.periodic;
  p.periodic.origin = {0, 0, 0};
  p.periodic.length = {kSide * s, kSide * s, kSide * s};
  p.ball_ball.model = sc.model;
  p.ball_ball.softbond.soft = 20.0;
  p.dt_fixed = sc.auto_dt ? 0.0 : 5e-8;
  if (sc.periodic) p.local_damping = sc.damping;  // (the default 0.7 would stop the drift below)
  auto w = std::make_unique<World>(p);
  std::mt19937_64 rng(91);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  test::add_jittered_lattice(*w, kSide, s, kR, (sc.bonded ? 0.002 : 0.03) * kR, sc.bonded ? 0.002 : 0.04, rng);
  w->prepare();
  if (sc.bonded) w->bond_ball_ball(-1.0, 0.01 * kR);
  const Vec3 c{0.5 * kSide * s, 0.5 * kSide * s, 0.5 * kSide * s};
  const double vel = sc.bonded ? 0.002 : 0.05, spin = sc.bonded ? 2.0 : 300.0, rate = sc.periodic ? 1500.0 : 150.0;
  for (std::size_t i = 0; i < w->num_balls(); ++i) {
    w->balls().v[i] = vel * Vec3{u(rng), u(rng), u(rng)};
    if (!sc.periodic) w->balls().v[i] += rate * (w->balls().x[i] - c);
    w->balls().w[i] = spin * Vec3{u(rng), u(rng), u(rng)};
  }
  if (sc.periodic) {
    w->set_strain_rate({rate, rate, -0.5 * rate});
    // The bricks follow the straining cell (BrickGrid::follow_cell), so its affine motion moves
    // no ball across a cut: a drift along the cut axis does (and across the cell's faces).
    for (Vec3& v : w->balls().v) v[sc.rcb ? 0 : sc.axis] += kDrift;  // (RCB's first cut is across x)
  }
  if (final_prepare) w->prepare();
  return w;
}

BrickGrid grid(const Scene& sc) {
  const double L = kSide * spacing(sc);
  BrickGrid g;
  g.lo = {0, 0, 0};
  g.len = {L, L, L};
  // The free cluster flies apart from its centre: cut it off-centre, so that balls cross the cuts.
  if (!sc.periodic) g.len = {1.5 * L, 1.5 * L, 1.5 * L * sc.tall};
  for (int k = 0; k < 3; ++k) g.periodic[k] = sc.periodic;
  if (sc.rcb)
    g.set_rcb(g_size);
  else
    g.n[sc.axis] = g_size;
  return g;
}

// The largest brick's balancing weight (contact_weights: a ball's modelled cost) over the
// mean, for the balls of `w` cut by `g`.
double weight_imbalance(const World& w, const BrickGrid& g) {
  std::vector<std::int64_t> wt, per(static_cast<std::size_t>(g.count()), 0);
  contact_weights(w, wt);
  std::int64_t total = 0;
  for (std::size_t i = 0; i < wt.size(); ++i) {
    per[static_cast<std::size_t>(g.owner(w.balls().x[i]))] += wt[i];
    total += wt[i];
  }
  return double(*std::max_element(per.begin(), per.end())) * g.count() / double(total);
}

// Runs the scene on the ranks; rank 0 compares with the reference. The verdict is shared, so
// every rank passes or fails together.
void check(const Scene& sc) {
  std::unique_ptr<World> full = build(sc, true);
  // from_root: the other ranks run 2 threads, rank 0 sc.threads while its whole World says one
  // more (as a checkpoint from another machine: bench_dist --run); each rank keeps its own count,
  // and the bits do not depend on it
  WorldParams own = full->params();
  if (sc.from_root && g_rank != 0) own.threads = 2;
  if (sc.from_root && g_rank == 0) full->mutable_params().threads = own.threads + 1;
  DistDem d(MPI_COMM_WORLD, own, grid(sc));
  if (sc.balance_at_load) d.set_balance({sc.balance_every, 2048, DistDem::Weight::kContacts, {}});
  if (sc.from_root) {
    if (g_rank != 0) full = std::make_unique<World>(own);  // no ball
    d.load_from_root(*full);
    int kept = d.world().params().threads == own.threads, all_kept = 0;
    MPI_Allreduce(&kept, &all_kept, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
    EXPECT_TRUE(all_kept) << "a rank took another rank's thread count";
  } else {
    d.load(*full);
  }
  if (sc.balance_at_load && g_rank == 0 && g_size > 1) {  // the loaded state cut by the first cuts
    const std::unique_ptr<World> start = build(sc, true);
    const double first = weight_imbalance(*start, d.grid()), geometric = weight_imbalance(*start, grid(sc));
    std::printf("  balanced at the load: weight imbalance %.4f (geometric cuts %.4f)\n", first, geometric);
    // (the cluster is still a lattice of 12 layers of 144 balls at the load and a cut falls
    // between layers: 1.0000 at 2 ranks, 1.197 at 3, 1.026 at 4, 1.320 at 9 (geometric cuts 2.0,
    // 3.0, 4.0, 6.8); at 3 ranks 1.0040 once it has flown apart)
    EXPECT_LT(first, g_size == 2 ? 1.02 : g_size <= 4 ? 1.25 : 1.4) << "the first cut must carry equal weight";
    EXPECT_GT(geometric, 1.5) << "the scene must need balancing";
  }
  if (!sc.balance_at_load) d.set_balance({sc.balance_every, 2048, DistDem::Weight::kContacts, {}});
  d.step(sc.steps);
  const DistDem::Balls got = d.gather();
  const double dt_end = d.world().dt();
  // a frame's arrays streamed to rank 0 in blocks of 37 rows (merged from every rank)
  const Snapshot frame = test::streamed_snapshot(d, 37);
  // the checkpoint written from the parts (blocks of 37 rows) against the assembled World's
  test::expect_same_state_file(d, [&] { return build(sc, true); }, 37);
  // the node's measurements, collective
  const double ke = d.kinetic_energy(), fc = d.mean_contact_force(), ratio = d.unbalanced_ratio(fc);
  const double skel = d.skeleton_ratio(fc).ratio;
  // the node's step measurements on ranks: both ratios in one gather, the guard's screen with the
  // kinetic energy (a box of no volume: its distance outside is every centre's largest |x_k|)
  const BallRatios both = d.ball_ratios(fc);
  const Vec3 origin{0.0, 0.0, 0.0};
  const DistDem::Screen scr = d.screen(origin, origin, true);
  // gravity switched on and every 7th ball made a rattler (its contact part of the force exactly
  // 0), the same in one World below: the skeleton sum leaves them out and counts them
  const auto make_rattlers = [](World& w) {
    if (!w.gravity_on()) w.set_gravity(true, 1.0);
    Particles& b = w.balls();
    for (std::size_t i = 0; i < b.size(); ++i)
      if (b.id[i] % 7 == 0) b.fa[i] = Vec3{0.0, 0.0, 0.0}, b.f[i] = b.m[i] * w.gravity();
  };
  make_rattlers(d.world());
  const BallRatios rattled = d.ball_ratios(fc);
  const BondCounts bonds = d.bond_counts();
  const std::int64_t failures = d.bond_failures();
  long long mine[3] = {static_cast<long long>(d.owned()), static_cast<long long>(d.ghosts()),
                       static_cast<long long>(d.migrated())};
  long long sum[3] = {0, 0, 0};
  MPI_Reduce(mine, sum, 3, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  const long long sum_owned = sum[0], sum_ghosts = sum[1], sum_migrated = sum[2];
  if (g_rank == 0) {
    std::unique_ptr<World> ref = build(sc, true);
    ref->step(sc.steps);
    std::printf("%s on %d ranks: dt %.4e s, %zu balls, %lld ghosts at the end, %lld exchanges, %lld migrations, reference "
                "%lld rebuilds\n",
                sc.name.c_str(), g_size, ref->dt(), got.id.size(), sum_ghosts, static_cast<long long>(d.exchanges()),
                sum_migrated, static_cast<long long>(ref->rebuild_count()));
    test::expect_same_balls(got, *ref, static_cast<std::size_t>(sum_owned));
    test::expect_same_snapshot(frame, snapshot(*ref));
    const double dt_ref = ref->dt();
    test::expect_same_measures(*ref, ke, fc, ratio);
    const double skel_ref = skeleton_ratio(*ref, fc).ratio;
    EXPECT_EQ(std::memcmp(&skel_ref, &skel, sizeof skel), 0) << "skeleton ratio " << skel << " vs " << skel_ref;
    const BallRatios both_ref = ball_ratios(*ref, fc);
    EXPECT_EQ(std::memcmp(&both_ref.unbalanced, &both.unbalanced, sizeof(double)), 0)
        << "ball_ratios: unbalanced " << both.unbalanced << " vs " << both_ref.unbalanced;
    EXPECT_EQ(std::memcmp(&both_ref.skeleton.ratio, &both.skeleton.ratio, sizeof(double)), 0)
        << "ball_ratios: skeleton " << both.skeleton.ratio << " vs " << both_ref.skeleton.ratio;
    EXPECT_EQ(both.skeleton.rattlers, both_ref.skeleton.rattlers);
    EXPECT_EQ(std::memcmp(&both.unbalanced, &ratio, sizeof ratio), 0) << "ball_ratios against unbalanced_ratio";
    std::vector<double> scratch;
    const BallScreen scr_ref = screen_balls(*ref, origin, origin, true, scratch);
    EXPECT_TRUE(scr.finite);
    EXPECT_EQ(std::memcmp(&scr.kinetic, &scr_ref.kinetic, sizeof(double)), 0)
        << "screen: kinetic energy " << scr.kinetic << " vs " << scr_ref.kinetic;
    EXPECT_EQ(std::memcmp(&scr.kinetic, &ke, sizeof ke), 0) << "screen against kinetic_energy";
    EXPECT_EQ(scr.outside, scr_ref.outside);
    EXPECT_GT(scr.outside, 0.0);
    make_rattlers(*ref);
    const BallRatios rattled_ref = ball_ratios(*ref, fc);
    const SkeletonRatio skel_rattled = skeleton_ratio(*ref, fc);
    EXPECT_EQ(std::memcmp(&rattled.skeleton.ratio, &skel_rattled.ratio, sizeof(double)), 0)
        << "with rattlers: skeleton " << rattled.skeleton.ratio << " vs " << skel_rattled.ratio;
    EXPECT_EQ(std::memcmp(&rattled.unbalanced, &rattled_ref.unbalanced, sizeof(double)), 0)
        << "with rattlers: unbalanced " << rattled.unbalanced << " vs " << rattled_ref.unbalanced;
    EXPECT_EQ(rattled.skeleton.rattlers, skel_rattled.rattlers);
    EXPECT_GE(rattled.skeleton.rattlers, ref->num_balls() / 7);
    if (sc.order_free) {  // the plain sums of the same state: the last bits apart
      World& plain = *ref;
      plain.mutable_params().order_free_sums = false;
      const double ke_p = plain.kinetic_energy(), fc_p = plain.mean_contact_force();
      std::printf("  order-free against plain sums: kinetic energy %.17g / %.17g, mean contact force %.17g / %.17g\n",
                  ke, ke_p, fc, fc_p);
      EXPECT_NEAR(ke, ke_p, 1e-13 * ke_p);
      EXPECT_NEAR(fc, fc_p, 1e-13 * fc_p);
      plain.mutable_params().order_free_sums = true;
    }
    EXPECT_EQ(std::memcmp(&dt_ref, &dt_end, sizeof dt_end), 0) << "the last step differs";
    EXPECT_GT(ref->rebuild_count(), 2) << "the run must rebuild its lists";
    if (sc.bonded) {  // bonds failed during the run (some across the cuts)
      const BondCounts bc = bond_counts(*ref);
      std::printf("  bonds: intact %zu, softening %zu, broken in tension %zu, in shear %zu; %lld failures\n", bc.intact,
                  bc.softening, bc.broken_tension, bc.broken_shear, static_cast<long long>(ref->bond_failures()));
      // the ranks' counts (each pair counted where its ball A is owned)
      EXPECT_EQ(bonds.intact, bc.intact);
      EXPECT_EQ(bonds.softening, bc.softening);
      EXPECT_EQ(bonds.broken_tension, bc.broken_tension);
      EXPECT_EQ(bonds.broken_shear, bc.broken_shear);
      EXPECT_EQ(bonds.never_bonded, bc.never_bonded);
      EXPECT_EQ(failures, ref->bond_failures());
      EXPECT_GT(failures, 0);
      EXPECT_GT(bc.intact, 0u);
      EXPECT_GT(bc.softening + bc.broken_tension + bc.broken_shear, 0u);
    }
    if (g_size > 1) {
      EXPECT_GT(sum_ghosts, 0);
      if (sc.migrate) {
        EXPECT_GT(sum_migrated, 0) << "balls must cross brick faces";
      }
    }
    if (sc.rcb) {  // the final state's weights cut by the ranks' cuts and by the geometric ones
      const double moved = weight_imbalance(*ref, d.grid()), geometric = weight_imbalance(*ref, grid(sc));
      std::printf("  RCB, %lld rebalances: weight imbalance %.4f (geometric cuts %.4f); cuts (axis, at/L):",
                  static_cast<long long>(d.rebalances()), moved, geometric);
      for (const BrickGrid::Cut& c : d.grid().rcb) std::printf(" (%d, %.4f)", c.axis, c.at / (kSide * spacing(sc)));
      std::printf("\n");
      if (sc.balance_every > 0 && g_size > 1) {
        EXPECT_EQ(d.rebalances(), d.exchanges() / sc.balance_every);
        // (the weights of the final state against cuts from up to two exchanges before, in
        // bricks of 1,728 / P balls: 1.0014-1.0139 at 2-4 ranks, 1.077 at 9)
        EXPECT_LT(moved, g_size <= 4 ? 1.05 : 1.10) << "the balanced bricks must carry equal weight";
        EXPECT_GT(geometric, 1.5) << "the scene must need balancing";
      }
    }
  }
  test::share_verdict();
  // A non-finite velocity in the last rank's first row only: every rank's screen finds it.
  const int last = g_size - 1;
  int planted = 0;
  if (g_rank == last && d.world().num_balls() > 0) {
    d.world().balls().v[0].y = std::numeric_limits<double>::quiet_NaN();
    planted = 1;
  }
  MPI_Bcast(&planted, 1, MPI_INT, last, MPI_COMM_WORLD);
  ASSERT_EQ(planted, 1) << "the last rank holds no row";
  EXPECT_FALSE(d.screen(origin, origin, false).finite) << "rank " << g_rank << " missed the last rank's NaN";
}

}  // namespace

// DistDem::ordered_sums on terms a rank lists out of key order (the node's terms nearly always
// come in key order; this is the path for those that do not): every rank's terms, keyed by id and
// listed in descending id, with values whose sum depends on the order of the additions. The sums
// must be the additions in ascending id of every rank's terms, in the first call (the merge order
// formed) and in a second with new values (the kept order and local permutation, values only);
// the mean's rule (positive, count) likewise; and the largest of the maxima asked for.
TEST(Dist, OrderedSumsOfUnsortedTermsAddInKeyOrder) {
  BrickGrid g;
  g.lo = {0, 0, 0};
  g.len = {1, 1, 1};
  g.n[0] = g_size;
  const DistDem d(MPI_COMM_WORLD, WorldParams{}, g);
  const std::size_t n = 500;
  // rank r holds the ids r, r + P, r + 2P, ... (interleaved with every other rank's), descending
  auto id_of = [](std::size_t j) { return static_cast<std::uint64_t>(g_rank) + static_cast<std::uint64_t>(g_size) * (n - 1 - j); };
  // id 0 is 1e16 (ulp 2): after it, each term near 1 is lost to rounding; before it, they add up
  auto value = [](std::uint64_t id, int round, int col) {
    if (id == 0) return 1e16 * (1.0 + 0.125 * col);
    return (id % 5 == 3 ? -0.5 : 1.0) + 0.125 * col + round * 0.25;
  };
  const DistDem::KeyFill keys = [&](std::vector<World::ContactTerm>& out) {
    for (std::size_t j = 0; j < n; ++j) out.push_back({0, id_of(j), 0, 0.0});
  };
  for (int round = 0; round < 2; ++round) {
    std::vector<double> v(2 * n);
    for (std::size_t j = 0; j < n; ++j)
      for (int c = 0; c < 2; ++c) v[2 * j + static_cast<std::size_t>(c)] = value(id_of(j), round, c);
    double got[2];
    double mx[1] = {static_cast<double>(g_rank) + 0.5};
    d.ordered_sums(n, v.data(), 2, keys, DistDem::kBallTerms, false, got, nullptr, mx, 1);
    // the reference: every id in ascending order, one chain per column from +0
    double want[2] = {0.0, 0.0}, plain[2] = {0.0, 0.0};
    for (std::uint64_t id = 0; id < n * static_cast<std::uint64_t>(g_size); ++id)
      for (int c = 0; c < 2; ++c) want[c] += value(id, round, c);
    for (std::size_t j = 0; j < n; ++j)  // (this rank's own terms in its listed order: not the sum)
      for (int c = 0; c < 2; ++c) plain[c] += v[2 * j + static_cast<std::size_t>(c)];
    for (int c = 0; c < 2; ++c)
      EXPECT_EQ(std::memcmp(&got[c], &want[c], sizeof(double)), 0)
          << "round " << round << " column " << c << ": " << got[c] << " vs " << want[c];
    EXPECT_EQ(mx[0], g_size - 0.5) << "the maximum over the ranks";
    if (g_size == 1) {
      EXPECT_NE(std::memcmp(&plain[0], &want[0], sizeof(double)), 0) << "the values must make the order matter";
    }
  }
  // the mean's rule: only the terms > 0, and their count (contacts' kind: its own kept order)
  std::vector<double> v(n);
  for (std::size_t j = 0; j < n; ++j) v[j] = value(id_of(j), 0, 0);
  double s = 0.0;
  std::int64_t count = -1;
  d.ordered_sums(n, v.data(), 1, keys, DistDem::kBallTerms, true, &s, &count);
  double want = 0.0;
  std::int64_t want_count = 0;
  for (std::uint64_t id = 0; id < n * static_cast<std::uint64_t>(g_size); ++id)
    if (const double x = value(id, 0, 0); x > 0.0) want += x, ++want_count;
  EXPECT_EQ(std::memcmp(&s, &want, sizeof s), 0) << s << " vs " << want;
  EXPECT_EQ(count, want_count);
}

TEST(Dist, LinearPeriodicStrainedSameBits) { check({"linear periodic, cut along x", ContactModel::kLinear, true}); }
TEST(Dist, LinearFreeSameBits) {
  check({"linear free, cut along z", ContactModel::kLinear, false, false, 2, 200});
}
TEST(Dist, SoftBondPeriodicSameBits) {
  check({"softbond periodic, cut along y", ContactModel::kSoftBond, true, true, 1});
}
// The automatic step, recomputed every step for Hertz–Mindlin (its stiffness grows with the
// overlap): the smallest over the ranks.
TEST(Dist, HertzPeriodicAutomaticStepSameBits) {
  Scene sc{"hertz periodic, automatic step, cut along x", ContactModel::kHertz, true};
  sc.auto_dt = true;
  sc.steps = 300;
  check(sc);
}
TEST(Dist, ParallelBondPeriodicTwoThreadsSameBits) {
  Scene sc{"pbond periodic, cut along x, 2 threads", ContactModel::kLinearPBond, true, true, 0, 600, 2};
  // (undamped, the strained cell breaks every parallel bond; damped, the drift stops before balls
  // cross the cuts: the migrations are the other cases')
  sc.damping = 0.7;
  sc.migrate = false;
  check(sc);
}
// The whole World on rank 0 only (DistDem::load_from_root): the strained periodic cell with soft
// bonds across the cuts, cut by RCB; the free cluster, RCB balanced every 2nd exchange.
TEST(Dist, SoftBondPeriodicFromRootRcbSameBits) {
  Scene sc{"softbond periodic, from rank 0, RCB", ContactModel::kSoftBond, true, true, 1};
  sc.rcb = true;
  sc.from_root = true;
  check(sc);
}
static Scene free_rcb_balanced(const char* name);  // (below)
TEST(Dist, LinearFreeFromRootRcbBalancedSameBits) {
  Scene sc = free_rcb_balanced("linear free, from rank 0, RCB balanced");
  sc.from_root = true;
  check(sc);
}
// The balancing set before the load, as the DEM node does: the first cut is already balanced
// (rank 0's whole World weighed, DistDem::balance_at_load), for load_from_root and for load.
TEST(Dist, LinearFreeFromRootRcbBalancedAtLoadSameBits) {
  Scene sc = free_rcb_balanced("linear free, from rank 0, RCB balanced from the load");
  sc.from_root = true;
  sc.balance_at_load = true;
  check(sc);
}
TEST(Dist, LinearFreeRcbBalancedAtLoadSameBits) {
  Scene sc = free_rcb_balanced("linear free, RCB balanced from the load");
  sc.balance_at_load = true;
  check(sc);
}

// The measurements as order-free sums (order_free_sum.hpp): each rank folds its own terms, two
// allreduces, no terms gathered; the same bits as one World summing the same way.
TEST(Dist, SoftBondPeriodicOrderFreeSumsSameBits) {
  Scene sc{"softbond periodic, order-free sums, cut along y", ContactModel::kSoftBond, true, true, 1};
  sc.order_free = true;
  check(sc);
}

// RCB: the periodic cell cut into bricks of a tree (at 3 ranks the low third across x, the rest
// halved across y), and the free cluster in a grid three times as high as the cluster, balanced
// every 2nd exchange (the geometric cuts leave the top bricks nearly empty).
TEST(Dist, LinearPeriodicRcbSameBits) {
  Scene sc{"linear periodic, RCB", ContactModel::kLinear, true};
  sc.rcb = true;
  check(sc);
}
static Scene free_rcb_balanced(const char* name) {
  Scene sc{name, ContactModel::kLinear, false, false, 2, 200};
  sc.rcb = true;
  sc.balance_every = 2;
  sc.tall = 3.0;
  return sc;
}
TEST(Dist, LinearFreeRcbBalancedSameBits) { check(free_rcb_balanced("linear free, RCB balanced")); }

// `newton on` (DistDem::set_newton): each pair across a brick face computed once, on the rank
// that owns its ball A, its force on the ghost B sent back to B's owner. Checked against one
// World: every pair listed exactly once over the ranks (newton off lists a pair across a face
// twice); on one rank (no ghosts) the same bits; on more, the ghosts' remote forces are added
// after the local ones, so the results differ from one World's by round-off, which these
// violent scenes (strained at 1,500/s, spinning at 300 rad/s) amplify about tenfold every 40
// steps (measured: 1e-19 m at step 20, 5e-12 m at step 340, then a contact made a step apart and
// the trajectories part): the runs are kept short enough (still with rebuilds and migrations)
// for a bound in the range of round-off (positions to 1e-8 of a radius, forces and torques to
// 1e-6 of the largest); a second run on the same ranks gives the same bits. The free cluster
// moves pairs with their ball A to its new owner (about 900-1,650 migrations at 2-4 ranks).
// With newton on more than one rank the ghosts are rows of their own (DistDem::own_first): the
// owned rows first, then the ghosts, each part in id order, and only the owned rows integrated;
// the pair list stays sorted by (row A, row B) with A < B, and every A is owned. This rank's
// faults against that (0 on one rank, whose rows are all owned and in id order).
long long layout_faults(const DistDem& d) {
  const World& w = d.world();
  const auto& gh = w.ghost_rows();
  const auto& id = w.balls().id;
  const std::size_t n = id.size(), own = d.owned();
  long long bad = w.moving_rows() != own;
  for (std::size_t i = 0; i < n; ++i) {
    bad += (!gh.empty() && gh[i]) != (i >= own);
    bad += i > 0 && i != own && !(id[i - 1] < id[i]);
  }
  const PairContacts& pc = w.pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    bad += !(pc.a[c] < pc.b[c]) || pc.a[c] >= own;
    bad += c > 0 && !(std::tie(pc.a[c - 1], pc.b[c - 1]) < std::tie(pc.a[c], pc.b[c]));
  }
  return bad;
}

void check_newton(const Scene& sc, double pos_tol, double force_tol) {
  long long migrated = 0, layout_bad = 0;
  // (the second run loads from rank 0 alone, DistDem::load_from_root: the same bits again)
  auto run = [&](DistDem::Balls& got, long long& listed, double& dt_end, bool from_root) {
    std::unique_ptr<World> full = build(sc, true);
    DistDem d(MPI_COMM_WORLD, full->params(), grid(sc));
    d.set_newton(true);
    if (from_root) {
      if (g_rank != 0) full = std::make_unique<World>(full->params());
      d.load_from_root(*full);
    } else {
      d.load(*full);
    }
    d.set_balance({sc.balance_every, 2048, DistDem::Weight::kContacts, {}});
    long long faults = layout_faults(d);  // as loaded, then after the exchanges of the run
    d.step(sc.steps);
    faults += layout_faults(d);
    got = d.gather();
    // a frame streamed in blocks of 37 rows against the frame of the World the ranks assemble
    const Snapshot frame = test::streamed_snapshot(d, 37);
    World assembled(full->params());
    d.unload(assembled, true);
    if (g_rank == 0) test::expect_same_snapshot(frame, snapshot(assembled));
    test::expect_same_state_file(d, [&] { return build(sc, true); }, 37);
    dt_end = d.world().dt();
    long long mine[3] = {static_cast<long long>(d.world().pair_contacts().size()),
                         static_cast<long long>(d.migrated()), faults};
    long long sum[3] = {0, 0, 0};
    MPI_Reduce(mine, sum, 3, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
    listed = sum[0];
    migrated = sum[1];
    layout_bad += sum[2];
    return d.ghosts();
  };
  DistDem::Balls got, again;
  long long listed = 0, listed2 = 0;
  double dt_end = 0.0, dt2 = 0.0;
  const std::size_t ghosts = run(got, listed, dt_end, false);
  run(again, listed2, dt2, true);
  unsigned long long gh = ghosts, all_gh = 0;
  MPI_Reduce(&gh, &all_gh, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (g_rank == 0) {
    std::unique_ptr<World> ref = build(sc, true);
    ref->step(sc.steps);
    const Particles& r = ref->balls();
    ASSERT_EQ(got.id, r.id);
    double dx = 0.0, df = 0.0, dtq = 0.0, fmax = 0.0, tmax = 0.0;
    for (std::size_t i = 0; i < r.size(); ++i) {
      dx = std::max(dx, norm(got.x[i] - r.x[i]));
      df = std::max(df, norm(got.f[i] - r.f[i]));
      dtq = std::max(dtq, norm(got.t[i] - r.t[i]));
      fmax = std::max(fmax, norm(r.f[i]));
      tmax = std::max(tmax, norm(r.t[i]));
    }
    std::printf("%s, newton on, %d ranks, %d steps: %lld pairs listed over the ranks (one World: %zu), %llu ghosts, "
                "%lld migrations, reference %lld rebuilds; largest difference from one World: position %.3e R, force "
                "%.3e, torque %.3e of the largest\n",
                sc.name.c_str(), g_size, sc.steps, listed, ref->pair_contacts().size(), all_gh, migrated,
                static_cast<long long>(ref->rebuild_count()), dx / kR, df / fmax, dtq / tmax);
    EXPECT_EQ(listed, static_cast<long long>(ref->pair_contacts().size())) << "every pair computed once";
    EXPECT_EQ(layout_bad, 0) << "the ghosts in rows of their own after the owned rows, each part in id order";
    EXPECT_TRUE(test::same_bits(got.x, again.x) && test::same_bits(got.f, again.f) && test::same_bits(got.t, again.t))
        << "two runs on the same ranks (the second loaded from rank 0) must give the same bits";
    EXPECT_EQ(std::memcmp(&dt_end, &dt2, sizeof dt2), 0);
    if (g_size == 1) {
      test::expect_same_balls(got, *ref, r.size());
    } else {
      EXPECT_GT(all_gh, 0u);
      // (the periodic lattices strain affinely: their first balls cross a face after the bound
      // above is spent; the free cluster's cross from the start)
      if (!sc.periodic) {
        EXPECT_GT(migrated, 0) << "balls must cross brick faces";
      }
      EXPECT_GT(ref->rebuild_count(), 2) << "the run must rebuild its lists";
      EXPECT_LT(dx, pos_tol * kR) << "positions";
      EXPECT_LT(df, force_tol * fmax) << "forces";
      EXPECT_LT(dtq, force_tol * tmax) << "torques";
      // the critical step from the owners' complete stiffness sums (the ghosts' sent back)
      EXPECT_NEAR(dt_end, ref->dt(), 1e-9 * ref->dt()) << "the last step";
    }
  }
  test::share_verdict();
}

TEST(Dist, NewtonLinearPeriodicStrained) {
  check_newton({"linear periodic, cut along x", ContactModel::kLinear, true, false, 0, 200}, 1e-8, 1e-6);
}
TEST(Dist, NewtonSoftBondPeriodic) {
  check_newton({"softbond periodic, cut along y", ContactModel::kSoftBond, true, true, 1, 200}, 1e-8, 1e-6);
}
TEST(Dist, NewtonHertzPeriodicAutomaticStep) {
  Scene sc{"hertz periodic, automatic step, cut along x", ContactModel::kHertz, true};
  sc.auto_dt = true;
  sc.steps = 200;
  check_newton(sc, 1e-8, 1e-6);
}
// two threads per rank: the threaded pass's chunks, then the reverse
TEST(Dist, NewtonParallelBondPeriodicTwoThreads) {
  check_newton({"pbond periodic, cut along x, 2 threads", ContactModel::kLinearPBond, true, true, 0, 200, 2}, 1e-8, 1e-6);
}
TEST(Dist, NewtonLinearFreeRcbBalanced) {
  Scene sc{"linear free, RCB balanced", ContactModel::kLinear, false, false, 2, 200};
  sc.rcb = true;
  sc.balance_every = 2;
  sc.tall = 3.0;
  check_newton(sc, 1e-8, 1e-6);
}

// Bonds stretched beyond the halo (2 R_max + skin): pairs of balls bonded by unbreakable,
// soft parallel bonds fly apart across the cuts, their gaps growing to several skins, so that a
// bonded partner is farther from its pair's rank than any ghost. Newton off: the partner rule
// (each owner sends its ball to the owners of its partners) keeps both rows on both ranks, the
// bits of one World. Newton on: the rank of a pair's ball A asks B's owner for B (a need
// record), and the run stays within round-off of one World.
void check_stretched(bool newton) {
  auto build2 = [] {
    WorldParams p;
    p.threads = 1;
    p.thread_independent = true;
    p.ball_ball.model = ContactModel::kLinearPBond;
    p.ball_ball.pbond.ten = 1e30;
    p.ball_ball.pbond.coh = 1e30;
    p.ball_ball.pbond.emod = 1e3;
    p.dt_fixed = 5e-8;
    auto w = std::make_unique<World>(p);
    // four pairs in a row along x, each pair touching, its balls moving apart along x
    for (int k = 0; k < 4; ++k) {
      const double y = 3.0 * kR * k;
      w->add_ball({-kR, y, 0.0}, kR);
      w->add_ball({kR, y, 0.0}, kR);
    }
    w->prepare();
    w->bond_ball_ball(-1.0, 0.01 * kR);
    for (std::size_t i = 0; i < w->num_balls(); ++i) w->balls().v[i] = {(i % 2 ? 1.0 : -1.0) * (2.0 + 0.2 * double(i)), 0, 0};
    w->prepare();
    return w;
  };
  std::unique_ptr<World> full = build2();
  BrickGrid g;
  g.lo = {-12 * kR, -5 * kR, -5 * kR};  // (the end bricks of a free axis reach to infinity)
  g.len = {24 * kR, 20 * kR, 10 * kR};
  g.n[0] = g_size;
  DistDem d(MPI_COMM_WORLD, full->params(), g);
  d.set_newton(newton);
  d.load(*full);
  const int steps = 3000;
  double widest = 0.0;  // largest gap of a pair over the run, in skins (the reference's)
  d.step(steps);
  const DistDem::Balls got = d.gather();
  long long mine[2] = {static_cast<long long>(d.world().pair_contacts().size()), newton ? layout_faults(d) : 0};
  long long sum[2] = {0, 0};
  MPI_Reduce(mine, sum, 2, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  const long long listed = sum[0];
  if (g_rank == 0) {
    EXPECT_EQ(sum[1], 0) << "the ghosts in rows of their own (newton on)";
    std::unique_ptr<World> ref = build2();
    for (int s = 0; s < steps; ++s) {
      ref->step(1);
      const Particles& b = ref->balls();
      for (std::size_t i = 0; i + 1 < b.size(); i += 2)
        widest = std::max(widest, (norm(b.x[i + 1] - b.x[i]) - 2 * kR) / ref->skin());
    }
    std::printf("stretched bonds, newton %s, %d ranks: widest gap %.2f skins (halo %.2f skins), %lld pairs listed over "
                "the ranks (one World: %zu), %lld bonds intact\n",
                newton ? "on" : "off", g_size, widest, (2 * kR + ref->skin()) / ref->skin(), listed,
                ref->pair_contacts().size(), static_cast<long long>(bond_counts(*ref).intact));
    EXPECT_GT(widest, (2 * kR + ref->skin()) / ref->skin() + 1.0) << "the bonds must stretch beyond the halo";
    EXPECT_EQ(bond_counts(*ref).intact, 4u);
    if (!newton) {
      test::expect_same_balls(got, *ref, ref->num_balls());
    } else {
      EXPECT_EQ(listed, static_cast<long long>(ref->pair_contacts().size()));
      const Particles& r = ref->balls();
      for (std::size_t i = 0; i < r.size(); ++i) EXPECT_LT(norm(got.x[i] - r.x[i]), 1e-8 * kR) << "ball " << i;
    }
  }
  test::share_verdict();
}
TEST(Dist, StretchedBondsPartnerRuleSameBits) { check_stretched(false); }
TEST(Dist, NewtonStretchedBondsNeedRecords) { check_stretched(true); }

// BrickGrid::near against its definition, brick by brick: every brick that, grown by the halo
// (the end bricks of a free axis reaching to infinity), holds the point or a periodic image of
// it; ascending, once each; the owner among them. Grids with one brick along an axis (periodic
// and free, the exchange's shortcut), even and shifted cuts, points near faces and outside.
TEST(Dist, NearIsEveryGrownBrickThatHoldsThePoint) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  struct Case {
    int n[3];
    bool periodic[3];
    bool shifted;
  };
  const Case cases[] = {{{2, 1, 1}, {true, true, true}, false},  {{3, 2, 1}, {true, false, true}, true},
                        {{1, 1, 1}, {false, false, false}, false}, {{1, 4, 2}, {false, true, false}, true},
                        {{5, 1, 3}, {true, false, false}, false}};
  std::size_t multi = 0;
  for (const Case& cs : cases) {
    BrickGrid g;
    g.lo = {-1.0, 0.5, 2.0};
    g.len = {4.0, 3.0, 2.5};
    for (int k = 0; k < 3; ++k) {
      g.n[k] = cs.n[k];
      g.periodic[k] = cs.periodic[k];
      if (cs.shifted && g.n[k] > 1)
        for (int i = 1; i < g.n[k]; ++i) g.cuts[k].push_back(g.len[k] * (i + 0.3 * u01(rng) - 0.15) / g.n[k]);
    }
    const double halo = 0.2;
    std::vector<int> got;
    for (int t = 0; t < 4000; ++t) {
      Vec3 x;
      for (int k = 0; k < 3; ++k) x[k] = g.lo[k] + g.len[k] * (1.4 * u01(rng) - 0.2);
      g.near(x, halo, got);
      std::vector<int> want;
      for (int r = 0; r < g.count(); ++r) {
        const int idx[3] = {r % g.n[0], (r / g.n[0]) % g.n[1], r / (g.n[0] * g.n[1])};
        bool in_all = true;
        for (int k = 0; k < 3 && in_all; ++k) {
          double u = x[k] - g.lo[k];
          if (g.periodic[k]) u -= std::floor(u / g.len[k]) * g.len[k];
          const int i = idx[k];
          const double lo = (!g.periodic[k] && i == 0) ? -INFINITY : g.edge(k, i) - halo;
          const double hi = (!g.periodic[k] && i == g.n[k] - 1) ? INFINITY : g.edge(k, i + 1) + halo;
          bool in = u >= lo && u < hi;
          if (g.periodic[k]) in = in || (u - g.len[k] >= lo && u - g.len[k] < hi) || (u + g.len[k] >= lo && u + g.len[k] < hi);
          in_all = in;
        }
        if (in_all) want.push_back(r);
      }
      ASSERT_EQ(got, want) << "grid " << cs.n[0] << "x" << cs.n[1] << "x" << cs.n[2] << ", point " << x.x << " " << x.y
                           << " " << x.z;
      EXPECT_TRUE(std::binary_search(got.begin(), got.end(), g.owner(x)));
      multi += got.size() > 1;
    }
  }
  EXPECT_GT(multi, 1000u);  // points within the halo of a face, not only inside bricks
}

// The same for RCB trees of 1-7 ranks, random axes and cuts, periodic and free axes: near()
// against every brick grown by the halo (box(); a face of a free axis at 0 or len reaching to
// infinity), the owner's brick holds the point, and the bricks tile the box (volumes add up).
TEST(Dist, RcbNearIsEveryGrownBrickThatHoldsThePoint) {
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const bool per[4][3] = {{true, true, true}, {false, false, false}, {true, false, true}, {false, true, false}};
  std::size_t multi = 0, deep = 0;
  for (int parts = 1; parts <= 7; ++parts)
    for (const auto& pc : per) {
      BrickGrid g;
      g.lo = {-1.0, 0.5, 2.0};
      g.len = {4.0, 3.0, 2.5};
      for (int k = 0; k < 3; ++k) g.periodic[k] = pc[k];
      g.set_rcb(parts);
      // random cuts inside each node's box, the tree's shape kept (preorder as set_rcb)
      auto cut = [&](auto&& self, int i, int p, std::array<double, 3> a0, std::array<double, 3> a1) -> void {
        if (p < 2) return;
        const int k = static_cast<int>(u01(rng) * 3.0) % 3, left = p / 2;
        const double at = a0[k] + (a1[k] - a0[k]) * (0.15 + 0.7 * u01(rng));
        g.rcb[static_cast<std::size_t>(i)] = {k, at};
        auto m1 = a1, m0 = a0;
        m1[k] = at;
        m0[k] = at;
        self(self, i + 1, left, a0, m1);
        self(self, i + left, p - left, m0, a1);
      };
      cut(cut, 0, parts, {0.0, 0.0, 0.0}, {g.len[0], g.len[1], g.len[2]});
      double vol = 0.0;
      for (int r = 0; r < parts; ++r) {
        double a0[3], a1[3];
        g.box(r, a0, a1);
        vol += (a1[0] - a0[0]) * (a1[1] - a0[1]) * (a1[2] - a0[2]);
      }
      EXPECT_NEAR(vol, g.len[0] * g.len[1] * g.len[2], 1e-9) << parts << " parts: the bricks must tile the box";
      const double halo = 0.2;
      std::vector<int> got;
      for (int t = 0; t < 1500; ++t) {
        Vec3 x;
        for (int k = 0; k < 3; ++k) x[k] = g.lo[k] + g.len[k] * (1.4 * u01(rng) - 0.2);
        g.near(x, halo, got);
        std::vector<int> want;
        int holder = -1;
        for (int r = 0; r < parts; ++r) {
          double a0[3], a1[3];
          g.box(r, a0, a1);
          bool in_all = true, own = true;
          for (int k = 0; k < 3; ++k) {
            double u = x[k] - g.lo[k];
            if (g.periodic[k]) u -= std::floor(u / g.len[k]) * g.len[k];
            const double lo = (!g.periodic[k] && a0[k] == 0.0) ? -INFINITY : a0[k] - halo;
            const double hi = (!g.periodic[k] && a1[k] == g.len[k]) ? INFINITY : a1[k] + halo;
            bool in = u >= lo && u < hi;
            if (g.periodic[k]) in = in || (u - g.len[k] >= lo && u - g.len[k] < hi) || (u + g.len[k] >= lo && u + g.len[k] < hi);
            in_all = in_all && in;
            own = own && u >= ((!g.periodic[k] && a0[k] == 0.0) ? -INFINITY : a0[k]) &&
                  u < ((!g.periodic[k] && a1[k] == g.len[k]) ? INFINITY : a1[k]);
          }
          if (in_all) want.push_back(r);
          if (own) {
            EXPECT_EQ(holder, -1) << "two bricks own a point";
            holder = r;
          }
        }
        ASSERT_EQ(got, want) << parts << " parts, point " << x.x << " " << x.y << " " << x.z;
        EXPECT_EQ(g.owner(x), holder);
        multi += got.size() > 1;
        deep += got.size() > 2;
      }
    }
  EXPECT_GT(multi, 3000u);  // points within the halo of a cut
  EXPECT_GT(deep, 300u);    // and of several
}

// rcb_cuts on one process (no reduction): points in a dense off-centre cluster over a sparse
// background, weights 1-8. Every brick's weight is within a few bins' weight of the mean (the
// geometric cuts are far off), and the root cut is the first bin end where the low side's weight
// reaches its share, p / 2 of p, rounded up: reached at the cut, not reached one bin before.
TEST(Dist, RcbCutsGiveEveryBrickItsShareOfTheWeight) {
  std::mt19937_64 rng(13);
  std::normal_distribution<double> nd(0.0, 1.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::vector<Vec3> x;
  std::vector<std::int64_t> wt;
  for (int i = 0; i < 60000; ++i) {
    if (i % 5 == 0)
      x.push_back({4.0 * u01(rng), 3.0 * u01(rng), 2.0 * u01(rng)});
    else
      x.push_back({1.0 + 0.3 * nd(rng), 2.2 + 0.2 * nd(rng), 0.5 + 0.25 * nd(rng)});
    wt.push_back(1 + static_cast<std::int64_t>(u01(rng) * 8.0));
  }
  const std::int64_t total = std::accumulate(wt.begin(), wt.end(), std::int64_t{0});
  for (int parts = 2; parts <= 9; ++parts) {
    BrickGrid g;
    g.lo = {0.0, 0.0, 0.0};
    g.len = {4.0, 3.0, 2.0};
    g.periodic[0] = true;  // a periodic axis and two free ones (points outside belong to the end bricks)
    g.set_rcb(parts);
    auto imbalance = [&](const BrickGrid& gg) {
      std::vector<std::int64_t> per(static_cast<std::size_t>(parts), 0);
      for (std::size_t i = 0; i < x.size(); ++i) per[static_cast<std::size_t>(gg.owner(x[i]))] += wt[i];
      return double(*std::max_element(per.begin(), per.end())) * parts / double(total);
    };
    const double geometric = imbalance(g);
    const int bins = 2048;
    rcb_cuts(g, x, wt, {}, bins, [](std::vector<std::int64_t>&) {});
    const double cut = imbalance(g);
    std::printf("  RCB of %d parts: weight imbalance %.4f, geometric cuts %.4f\n", parts, cut, geometric);
    // (a bin at the cluster's centre holds about 1.5 % of a brick's mean weight at 7 parts; each
    // level's cut overshoots by less than one bin)
    EXPECT_LT(cut, 1.03) << parts << " parts";
    EXPECT_GT(geometric, 1.3) << parts << " parts";
    // the root cut: across the box's longest side (x), at a bin end, the first to reach the share
    const BrickGrid::Cut c = g.rcb[0];
    EXPECT_EQ(c.axis, 0);
    const double bw = g.len[0] / bins;
    const double e = c.at / bw;
    EXPECT_NEAR(e, std::round(e), 1e-9) << "the cut is not at a bin end";
    std::int64_t low = 0, last = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      const double u = x[i].x - std::floor(x[i].x / g.len[0]) * g.len[0];
      if (u < c.at) low += wt[i];
      if (u < c.at && u >= c.at - bw) last += wt[i];
    }
    const std::int64_t target = (total * (parts / 2) + parts - 1) / parts;
    EXPECT_GE(low, target) << parts << " parts: the low side short of its share";
    EXPECT_LT(low - last, target) << parts << " parts: the share was reached before the cut";
  }
}

// contact_weights on a bonded specimen (the soft bond law): every ball's weight against its
// counts of bonded pairs, unbonded pairs that touch and pairs listed apart after 600 strained
// steps (one process), with the model's costs and with costs of different orders of magnitude.
TEST(Dist, ContactWeightsOfABondedSpecimen) {
  if (g_rank != 0) return;
  std::unique_ptr<World> w = build({"softbond periodic, weights", ContactModel::kSoftBond, true, true}, true);
  w->step(600);
  const test::CostCounts n = test::cost_counts(*w);
  std::printf("  bonded %zu, touching %zu, apart %zu\n", n.bonded, n.touching, n.apart);
  ASSERT_GT(n.bonded, 0u);
  ASSERT_GT(n.touching, 0u);
  ASSERT_GT(n.apart, 0u);
  EXPECT_EQ(test::weights(*w), n.row);
  EXPECT_EQ(test::weights(*w, test::kDistinctCosts), test::cost_counts(*w, test::kDistinctCosts).row);
}

// radix_order is std::stable_sort's order of the keys (duplicates in index order), for keys of
// 1 to 64 bits; order_wall_shares puts 2-40 sorted runs of shares, with keys repeated across
// runs, in one World's order as a stable sort does (the same records in the same places), on
// the merge path (< 8 runs) and the radix path.
TEST(Dist, RadixOrderAndWallSharesAreTheStableSortsOrder) {
  std::mt19937_64 rng(14);
  for (int bits : {1, 5, 11, 12, 23, 33, 47, 64})
    for (std::size_t n : {0u, 1u, 7u, 2048u, 30001u}) {
      std::vector<std::uint64_t> keys(n);
      for (auto& k : keys) k = bits == 64 ? rng() : rng() & ((std::uint64_t{1} << bits) - 1);
      if (n > 10) keys[3] = keys[n - 2];  // a repeat at least
      std::vector<std::uint32_t> got, want(n);
      radix_order(keys, got);
      std::iota(want.begin(), want.end(), 0u);
      std::stable_sort(want.begin(), want.end(), [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
      ASSERT_EQ(got, want) << bits << " bits, " << n << " keys";
    }
  for (int runs : {2, 5, 8, 13, 40}) {
    std::vector<WallSumRec> v;
    std::vector<std::size_t> starts;
    for (int r = 0; r < runs; ++r) {
      starts.push_back(v.size());
      std::vector<WallSumRec> run(300 + rng() % 200);
      for (std::size_t j = 0; j < run.size(); ++j) {
        run[j].ball = rng() % 5000;  // ids repeat across runs (and within)
        run[j].wall = static_cast<std::uint32_t>(rng() % 3);
        run[j].kind = 1;
        run[j].F = {double(r), double(j), 0.0};  // where the share came from
      }
      std::stable_sort(run.begin(), run.end(), [](const WallSumRec& a, const WallSumRec& b) {
        return std::tie(a.ball, a.wall) < std::tie(b.ball, b.wall);
      });
      v.insert(v.end(), run.begin(), run.end());
    }
    starts.push_back(v.size());
    std::vector<WallSumRec> want = v;
    std::stable_sort(want.begin(), want.end(), [](const WallSumRec& a, const WallSumRec& b) {
      return std::tie(a.ball, a.wall) < std::tie(b.ball, b.wall);
    });
    order_wall_shares(v, starts);
    for (std::size_t j = 0; j < v.size(); ++j) {
      ASSERT_EQ(v[j].ball, want[j].ball) << runs << " runs, share " << j;
      ASSERT_EQ(v[j].wall, want[j].wall) << runs << " runs, share " << j;
      ASSERT_EQ(v[j].F.x, want[j].F.x) << runs << " runs, share " << j << ": equal keys out of rank order";
      ASSERT_EQ(v[j].F.y, want[j].F.y) << runs << " runs, share " << j;
    }
  }
}

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(MPI_COMM_WORLD, &g_rank);
  MPI_Comm_size(MPI_COMM_WORLD, &g_size);
  ::testing::InitGoogleTest(&argc, argv);
  if (g_rank != 0) {  // one report
    auto& l = ::testing::UnitTest::GetInstance()->listeners();
    delete l.Release(l.default_result_printer());
  }
  const int rc = RUN_ALL_TESTS();
  MPI_Finalize();
  return rc;
}

// newton on with cuts balanced by measured time is refused, in either order of the calls:
// newton's results follow the cuts, and time-weighted cuts differ from run to run.
TEST(Dist, NewtonWithTimeWeightedCutsIsRefused) {
  Scene sc{"refusal", ContactModel::kLinear, true};
  const DistDem::Balance by_time{1, 2048, DistDem::Weight::kTime, {}}, by_contacts{1, 2048, DistDem::Weight::kContacts, {}};
  {
    DistDem d(MPI_COMM_WORLD, WorldParams{}, grid(sc));
    d.set_newton(true);
    EXPECT_THROW(d.set_balance(by_time), std::invalid_argument);
    EXPECT_NO_THROW(d.set_balance(by_contacts));
    EXPECT_NO_THROW(d.set_balance({0, 2048, DistDem::Weight::kTime, {}}));  // no balancing: no cuts to follow
  }
  {
    DistDem d(MPI_COMM_WORLD, WorldParams{}, grid(sc));
    d.set_balance(by_time);
    EXPECT_THROW(d.set_newton(true), std::invalid_argument);
  }
  test::share_verdict();
}
