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
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>

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
};

constexpr int kSide = 12;  // kSide³ balls
constexpr double kR = 1e-4;

double spacing(const Scene& sc) { return (sc.bonded ? 2.0 : 1.96) * kR; }

// The packing of simd_kernel_test (a jittered lattice, random velocities and spins, pulled apart
// by the cell or a radial field), with a fixed step. `final_prepare`: also prepare after the
// velocities are set. The ranks load the prepared World as it is (DistDem::load).
std::unique_ptr<World> build(const Scene& sc, bool final_prepare) {
  const double s = spacing(sc);
  WorldParams p;
  p.threads = sc.threads;
  p.thread_independent = true;  // what the ranks run with (DistDem::load)
  p.periodic.enabled = sc.periodic;
  p.periodic.origin = {0, 0, 0};
  p.periodic.length = {kSide * s, kSide * s, kSide * s};
  p.ball_ball.model = sc.model;
  p.ball_ball.softbond.soft = 20.0;
  p.dt_fixed = sc.auto_dt ? 0.0 : 5e-8;
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
  if (sc.periodic) w->set_strain_rate({rate, rate, -0.5 * rate});
  if (final_prepare) w->prepare();
  return w;
}

BrickGrid grid(const Scene& sc) {
  const double L = kSide * spacing(sc);
  BrickGrid g;
  g.lo = {0, 0, 0};
  g.len = {L, L, L};
  // The free cluster flies apart from its centre: cut it off-centre, so that balls cross the cuts.
  if (!sc.periodic) g.len = {1.5 * L, 1.5 * L, 1.5 * L};
  g.n[sc.axis] = g_size;
  for (int k = 0; k < 3; ++k) g.periodic[k] = sc.periodic;
  return g;
}

// Runs the scene on the ranks; rank 0 compares with the reference. The verdict is shared, so
// every rank passes or fails together.
void check(const Scene& sc) {
  std::unique_ptr<World> full = build(sc, true);
  DistDem d(MPI_COMM_WORLD, full->params(), grid(sc));
  d.load(*full);
  d.step(sc.steps);
  const DistDem::Balls got = d.gather();
  const double dt_end = d.world().dt();
  // the node's measurements, collective
  const double ke = d.kinetic_energy(), fc = d.mean_contact_force(), ratio = d.unbalanced_ratio(fc);
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
    const double dt_ref = ref->dt();
    test::expect_same_measures(*ref, ke, fc, ratio);
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
      EXPECT_GT(sum_migrated, 0) << "balls must cross brick faces";
    }
  }
  test::share_verdict();
}

}  // namespace

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
  check({"pbond periodic, cut along x, 2 threads", ContactModel::kLinearPBond, true, true, 0, 600, 2});
}

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
