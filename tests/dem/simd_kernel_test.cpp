// The vectorised ball–ball pass and law of motion (pair_block.hpp, issue 3 item 12) must give
// the scalar loops bit for bit: every lane performs the scalar operations in the same order,
// the rare paths (soft-bond softening, breakage, shear break, large rotations, unbonded
// contacts; parallel-bond breakage; rows with fixity) are redone by the scalar code, and sums keep their order. Checked on small random packings, linear and soft
// bond, periodic (with a straining cell) and free, for every instruction set this CPU has.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "demfdm/dem/world.hpp"
#include "lattice.hpp"

using namespace demfdm::dem;

namespace {

struct Scene;
void bonded_setup(Scene& sc);

struct Scene {
  std::string name;
  ContactModel model = ContactModel::kLinear;
  bool periodic = true;
  NormalMode mode = NormalMode::kAbsolute;
  SoftReturn ret = SoftReturn::kAssociated;
  CohesionSoftening cohesion = CohesionSoftening::kNone;
  bool bend_soft = true;
  UnbondedMoments moments = UnbondedMoments::kJiang;
  int nside = 7;  // nside³ balls
  double spacing = 1.96;  // lattice spacing / R̄
  double pos_jitter = 0.03;  // position jitter / R̄
  double rad_jitter = 0.04;  // radius jitter / R̄
  double vel = 0.05;      // [m/s] amplitude of the random velocities
  double spin = 300.0;    // [rad/s] amplitude of the random spins
  double rate = 150.0;    // [1/s] pull rate (negative: converging velocity field)
  double bond_gap = 0.0;  // bond pairs with gap ≤ bond_gap R̄
  int threads = 1;
  int steps = 400;
};

struct Result : test::BallState {
  std::vector<BondState> state;
  std::size_t pairs = 0;
  int count[5] = {0, 0, 0, 0, 0};  // by BondState
  Energy e;
};

// Soft-bond runs: a lattice with small gaps, bonded across them, pulled apart slowly: bonds
// stay intact, soften, and break in tension and in shear within the run.
void bonded_setup(Scene& sc) {
  sc.model = ContactModel::kSoftBond;
  sc.spacing = 2.0;
  sc.pos_jitter = sc.rad_jitter = 0.002;
  sc.vel = 0.002;
  sc.spin = 2.0;
  sc.bond_gap = 0.01;
}

// Jittered cubic lattice of polydisperse balls (spacing below 2 R̄: neighbours overlap),
// random velocities and spins; the packing is pulled apart (cell strain rate, or a radial
// velocity field without the cell) so that bonds soften and break within the run.
Result run(const Scene& sc, PairKernel kernel) {
  const double R = 1e-4, s = sc.spacing * R;
  const int ns = sc.nside;
  WorldParams p;
  p.threads = sc.threads;
  p.periodic.enabled = sc.periodic;
  p.periodic.origin = {0, 0, 0};
  p.periodic.length = {ns * s, ns * s, ns * s};
  p.ball_ball.model = sc.model;
  p.ball_ball.linear.mode = sc.mode;
  p.ball_ball.softbond.ret = sc.ret;
  p.ball_ball.softbond.cohesion = sc.cohesion;
  p.ball_ball.softbond.bending_in_softening = sc.bend_soft;
  p.ball_ball.softbond.moments = sc.moments;
  p.ball_ball.softbond.soft = 20.0;  // ζ: bonds break after a short softening branch
  World w(p);
  w.set_pair_kernel(kernel);
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const Vec3 c{0.5 * ns * s, 0.5 * ns * s, 0.5 * ns * s};
  test::add_jittered_lattice(w, ns, s, R, sc.pos_jitter * R, sc.rad_jitter, rng);
  w.prepare();
  if (law_has_bond(sc.model)) w.bond_ball_ball(-1.0, sc.bond_gap * R);
  const double rate = sc.rate;
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    w.balls().v[i] = sc.vel * Vec3{u(rng), u(rng), u(rng)};
    if (!sc.periodic) w.balls().v[i] += rate * (w.balls().x[i] - c);
    w.balls().w[i] = sc.spin * Vec3{u(rng), u(rng), u(rng)};
    // a few rows with fixity: the law of motion takes its scalar path for their blocks
    if (i % 29 == 5) w.balls().fix[i] = kFixVx | kFixWz;
  }
  if (sc.periodic) w.set_strain_rate({rate, rate, -0.5 * rate});
  w.step(sc.steps);
  Result r;
  static_cast<test::BallState&>(r) = test::ball_state(w);
  r.pairs = w.pair_contacts().size();
  for (const BondHist& b : w.pair_contacts().bond) {
    r.state.push_back(b.state);
    ++r.count[static_cast<int>(b.state)];
  }
  r.e = w.energy();
  return r;
}

bool same_bits(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Vec3)) == 0;
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Largest difference in units of the largest magnitude (printed when bits differ).
double rel_diff(const std::vector<Vec3>& a, const std::vector<Vec3>& b) {
  double d = 0.0, m = 0.0;
  for (std::size_t i = 0; i < a.size() && i < b.size(); ++i) {
    d = std::max(d, norm(a[i] - b[i]));
    m = std::max(m, norm(a[i]));
  }
  return m > 0.0 ? d / m : d;
}

std::vector<PairKernel> vector_kernels() {
  std::vector<PairKernel> k{PairKernel::kAuto, PairKernel::kBlockBaseline};
  for (PairKernel q : {PairKernel::kBlockAvx2, PairKernel::kBlockAvx512})
    if (World::pair_kernel_available(q)) k.push_back(q);
  return k;
}

const char* kernel_name(PairKernel k) {
  switch (k) {
    case PairKernel::kAuto: return "auto";
    case PairKernel::kScalar: return "scalar";
    case PairKernel::kBlockBaseline: return "block-baseline";
    case PairKernel::kBlockAvx2: return "block-avx2";
    case PairKernel::kBlockAvx512: return "block-avx512";
  }
  return "?";
}

void check_scene(const Scene& sc) {
  const Result ref = run(sc, PairKernel::kScalar);
  ASSERT_GT(ref.pairs, 3u * ref.x.size() / 2);  // a connected packing, not a gas
  // the contacts carried load and slipped during the run
  ASSERT_GT(ref.e.friction, 0.0);
  std::printf("%s: %zu balls, %zu pairs; bonds intact %d softening %d broken tension %d shear %d; "
              "friction %.3e J, bond dissipation %.3e J\n",
              sc.name.c_str(), ref.x.size(), ref.pairs, ref.count[1], ref.count[2], ref.count[3], ref.count[4],
              ref.e.friction, ref.e.softening);
  for (PairKernel k : vector_kernels()) {
    SCOPED_TRACE(std::string(sc.name) + " kernel " + kernel_name(k));
    const Result r = run(sc, k);
    EXPECT_TRUE(same_bits(r.x, ref.x)) << "x differs by " << rel_diff(r.x, ref.x);
    EXPECT_TRUE(same_bits(r.v, ref.v)) << "v differs by " << rel_diff(r.v, ref.v);
    EXPECT_TRUE(same_bits(r.w, ref.w)) << "w differs by " << rel_diff(r.w, ref.w);
    EXPECT_TRUE(same_bits(r.f, ref.f)) << "f differs by " << rel_diff(r.f, ref.f);
    EXPECT_TRUE(same_bits(r.t, ref.t)) << "t differs by " << rel_diff(r.t, ref.t);
    EXPECT_EQ(r.state, ref.state);
    EXPECT_TRUE(same_bits(r.e.friction, ref.e.friction));
    EXPECT_TRUE(same_bits(r.e.softening, ref.e.softening));
    EXPECT_TRUE(same_bits(r.e.strain, ref.e.strain));
  }
}

}  // namespace

TEST(SimdKernel, KernelsAvailable) {
  EXPECT_TRUE(World::pair_kernel_available(PairKernel::kScalar));
  EXPECT_TRUE(World::pair_kernel_available(PairKernel::kBlockBaseline));
  WorldParams p;
  World w(p);
  EXPECT_EQ(w.pair_kernel(), PairKernel::kAuto);
  for (PairKernel k : {PairKernel::kBlockAvx2, PairKernel::kBlockAvx512}) {
    if (World::pair_kernel_available(k)) {
      w.set_pair_kernel(k);
      EXPECT_EQ(w.pair_kernel(), k);
    } else {
      EXPECT_THROW(w.set_pair_kernel(k), std::invalid_argument);
    }
    std::printf("%s: %s\n", kernel_name(k), World::pair_kernel_available(k) ? "available" : "not available");
  }
}

TEST(SimdKernel, LinearPeriodicStrainedIncrementalBitIdentical) {
  Scene sc;
  sc.name = "linear periodic strained incremental";
  sc.mode = NormalMode::kIncremental;
  check_scene(sc);
}

TEST(SimdKernel, LinearFreeBitIdentical) {
  Scene sc;
  sc.name = "linear free";
  sc.periodic = false;
  sc.rate = 0.0;
  sc.steps = 40;  // the overlapping free cluster flies apart: contacts load, slip and open
  sc.mode = NormalMode::kIncremental;
  check_scene(sc);
}

// Default soft bond: the pull drives bonds through softening into tensile breakage, and the
// spins break some in shear; all of them go through the scalar fallback of their lane.
TEST(SimdKernel, SoftBondPeriodicSofteningAndBreakageBitIdentical) {
  Scene sc;
  sc.name = "softbond periodic strained";
  bonded_setup(sc);
  check_scene(sc);
  const Result r = run(sc, PairKernel::kAuto);
  EXPECT_GT(r.count[static_cast<int>(BondState::kSoftening)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kBrokenTension)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kIntact)], 0);
}

TEST(SimdKernel, SoftBondFreeVariantsBitIdentical) {
  Scene sc;
  sc.name = "softbond free radial/proportional cohesion/no bending";
  bonded_setup(sc);
  sc.periodic = false;
  sc.ret = SoftReturn::kRadial;
  sc.cohesion = CohesionSoftening::kProportional;
  sc.bend_soft = false;
  sc.moments = UnbondedMoments::kNone;
  check_scene(sc);
  const Result r = run(sc, PairKernel::kAuto);
  EXPECT_GT(r.count[static_cast<int>(BondState::kSoftening)] + r.count[static_cast<int>(BondState::kBrokenTension)] +
                r.count[static_cast<int>(BondState::kBrokenShear)],
            0);
}

// Hertz–Mindlin (docs/theory.md §1.9): the lane loop calls the law's own formula (hertz_core),
// so the vector pass gives the scalar one bit for bit, tangent stiffnesses included.
TEST(SimdKernel, HertzPeriodicStrainedAndFreeBitIdentical) {
  Scene sc;
  sc.name = "hertz periodic strained";
  sc.model = ContactModel::kHertz;
  check_scene(sc);
  Scene fr = sc;
  fr.name = "hertz free";
  fr.periodic = false;
  fr.rate = 0.0;
  fr.steps = 40;
  check_scene(fr);
}

// Parallel bond (docs/theory.md §2): every contact has a lane (intact bonds, broken and
// never-bonded ones alike); a bond that breaks in its lane is redone by the scalar law. The pull
// breaks bonds in tension and the spins in shear within the run, with intact ones left.
TEST(SimdKernel, ParallelBondPeriodicAndFreeBitIdentical) {
  Scene sc;
  sc.name = "pbond periodic strained";
  bonded_setup(sc);
  sc.model = ContactModel::kLinearPBond;
  sc.spin = 400.0;
  check_scene(sc);
  const Result r = run(sc, PairKernel::kAuto);
  EXPECT_GT(r.count[static_cast<int>(BondState::kBrokenTension)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kBrokenShear)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kIntact)], 0);
  Scene fr = sc;
  fr.name = "pbond free incremental";
  fr.periodic = false;
  fr.mode = NormalMode::kIncremental;
  check_scene(fr);
}

// Two threads: contact blocks per thread and the fixed-order reduction are shared by both
// passes, so the vectorised pass repeats the scalar one bit for bit there too.
TEST(SimdKernel, TwoThreadsBitIdentical) {
  for (ContactModel m : {ContactModel::kLinear, ContactModel::kSoftBond, ContactModel::kLinearPBond}) {
    Scene sc;
    sc.name = std::string(law_name(m)) + " 2 threads";
    if (m != ContactModel::kLinear) bonded_setup(sc);
    sc.model = m;
    sc.nside = 12;  // > 4096 pairs: the threaded branch of the pass runs
    sc.threads = 2;
    sc.steps = 30;
    check_scene(sc);
  }
}
