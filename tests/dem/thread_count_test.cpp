// With WorldParams::thread_independent (scene: run.thread_independent) a DEM run gives the same
// bits at any thread count (issue 17 item 3, for threads): the threaded ball–ball pass cuts the
// contact list into one chunk per thread and rebuilds the sums of the balls whose contacts span
// chunks in the one-thread order (PairSet::pass_law), and every other
// threaded loop (facet walls, the contact scan, the per-ball sums) was already summed in a
// fixed order. Checked for every law, periodic with a straining cell and free, with the scalar
// and the vector pass, at 1, 2, 3 and 4 threads (more threads than cores is fine): positions,
// velocities, spins, forces, torques, bond states and energies equal bit for bit.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "demfdm/dem/world.hpp"
#include "lattice.hpp"

using namespace demfdm::dem;

namespace {

struct Scene {
  std::string name;
  ContactModel model = ContactModel::kLinear;
  bool periodic = true;
  bool bonded = false;
  int steps = 150;
  double skin = 0.0;  // [R] Verlet skin; 0: the default
  double rate = 150.0;  // [1/s] pull rate
};

struct Result : test::BallState {
  std::vector<BondState> state;
  std::size_t pairs = 0;
  Energy e;
  double dt = 0.0;
};

// A jittered lattice of 16³ polydisperse balls whose neighbours overlap (or, bonded, touch across
// small gaps), random velocities and spins, pulled apart by the cell or a radial velocity field:
// contacts load, slip, open and (bonded) soften and break; the list is rebuilt during the run.
Result run(const Scene& sc, int threads, PairKernel kernel) {
  const int ns = 16;
  const double R = 1e-4, s = (sc.bonded ? 2.0 : 1.96) * R;
  WorldParams p;
  p.threads = threads;
  p.thread_independent = true;
  p.periodic.enabled = sc.periodic;
  p.periodic.origin = {0, 0, 0};
  p.periodic.length = {ns * s, ns * s, ns * s};
  p.ball_ball.model = sc.model;
  p.ball_ball.softbond.soft = 20.0;
  p.skin = sc.skin * R;
  World w(p);
  w.set_pair_kernel(kernel);
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double jit = sc.bonded ? 0.002 : 0.03;
  test::add_jittered_lattice(w, ns, s, R, jit * R, sc.bonded ? 0.002 : 0.04, rng);
  w.prepare();
  if (sc.bonded) w.bond_ball_ball(-1.0, 0.01 * R);
  const Vec3 c{0.5 * ns * s, 0.5 * ns * s, 0.5 * ns * s};
  const double vel = sc.bonded ? 0.002 : 0.05, spin = sc.bonded ? 2.0 : 300.0, rate = sc.rate;
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    w.balls().v[i] = vel * Vec3{u(rng), u(rng), u(rng)};
    if (!sc.periodic) w.balls().v[i] += rate * (w.balls().x[i] - c);
    w.balls().w[i] = spin * Vec3{u(rng), u(rng), u(rng)};
  }
  if (sc.periodic) w.set_strain_rate({rate, rate, -0.5 * rate});
  w.step(sc.steps);
  Result r;
  static_cast<test::BallState&>(r) = test::ball_state(w);
  r.pairs = w.pair_contacts().size();
  for (const BondHist& b : w.pair_contacts().bond) r.state.push_back(b.state);
  r.e = w.energy();
  r.dt = w.dt();
  return r;
}

bool same_bits(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3)) == 0;
}
bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

void check(const Scene& sc) {
  for (PairKernel k : {PairKernel::kScalar, PairKernel::kAuto}) {
    const Result ref = run(sc, 1, k);
    ASSERT_GT(ref.pairs, 4096u) << "the threaded pass must run";
    std::printf("%s, %s: %zu balls, %zu pairs\n", sc.name.c_str(), k == PairKernel::kScalar ? "scalar" : "auto",
                ref.x.size(), ref.pairs);
    for (int threads : {2, 3, 4}) {
      SCOPED_TRACE(sc.name + (k == PairKernel::kScalar ? " scalar" : " auto") + ", threads " +
                   std::to_string(threads));
      const Result r = run(sc, threads, k);
      EXPECT_TRUE(same_bits(r.x, ref.x));
      EXPECT_TRUE(same_bits(r.v, ref.v));
      EXPECT_TRUE(same_bits(r.w, ref.w));
      EXPECT_TRUE(same_bits(r.f, ref.f));
      EXPECT_TRUE(same_bits(r.t, ref.t));
      EXPECT_EQ(r.state, ref.state);
      EXPECT_TRUE(same_bits(r.e.friction, ref.e.friction));
      EXPECT_TRUE(same_bits(r.e.softening, ref.e.softening));
      EXPECT_TRUE(same_bits(r.e.strain, ref.e.strain));
      EXPECT_TRUE(same_bits(r.dt, ref.dt));
    }
  }
}

}  // namespace

TEST(ThreadCount, LinearPeriodicStrainedSameBits) { check({"linear periodic", ContactModel::kLinear, true, false}); }
// A wide skin keeps the list for many steps while a fast pull opens contacts: saved contacts of
// split balls go from loaded to open to idle between two rebuilds.
TEST(ThreadCount, LinearPeriodicWideSkinSameBits) {
  Scene sc{"linear periodic, wide skin", ContactModel::kLinear, true, false, 300};
  sc.skin = 0.6;
  sc.rate = 3000.0;
  check(sc);
}
TEST(ThreadCount, LinearFreeSameBits) { check({"linear free", ContactModel::kLinear, false, false, 40}); }
TEST(ThreadCount, HertzPeriodicSameBits) { check({"hertz periodic", ContactModel::kHertz, true, false}); }
TEST(ThreadCount, SoftBondPeriodicSameBits) {
  check({"softbond periodic", ContactModel::kSoftBond, true, true});
}
TEST(ThreadCount, ParallelBondFreeSameBits) {
  check({"pbond free", ContactModel::kLinearPBond, false, true});
}
