// The vectorised ball–ball pass and law of motion (pair_block.hpp, issue 3 item 12) must give
// the scalar loops bit for bit: every lane performs the scalar operations in the same order,
// the rare paths (soft-bond softening, breakage, shear break, large rotations, unbonded
// contacts; parallel-bond breakage; rows with fixity) are redone by the scalar code, and sums keep their order. Checked on small random packings, linear and soft
// bond, periodic (with a straining cell) and free, for every instruction set this CPU has; the
// wall contacts' lane kernels (linear, parallel bond) on a slab between moving facets, platens
// and the footing (linear and Hertz–Mindlin; parallel-bond and soft-bond facets).
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
  int steal = 1;  // the threaded pass's work stealing: 0 off, 1 on, 2 forced (World::set_pair_stealing's hold)
};

struct Result : test::BallState {
  std::vector<BondState> state;
  std::vector<ContactHist> h;
  std::vector<BondHist> bond;
  std::size_t pairs = 0;
  std::uint64_t stolen = 0;  // blocks of the threaded pass taken by another thread
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
  w.set_pair_stealing(sc.steal != 0, sc.steal == 2 ? 2e-3 : 0.0);
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
  r.h = w.pair_contacts().h;
  r.bond = w.pair_contacts().bond;
  r.stolen = w.pair_blocks_stolen().first;
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

// The balls, bond states and energies of two runs, bit for bit.
void expect_same_run(const Result& r, const Result& ref) {
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
    expect_same_run(run(sc, k), ref);
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

// The wall contacts' lane kernels (pair_block.hpp WallIn): a slab of balls on a floor of facets
// whose vertices move (the facets tilt, spin and stretch), bonded to it with interface parallel
// bonds (linear part zero while bonded, restored at a break), between two side platens (linear)
// under the footing (linear), which punches into it. The floor pulls away at one end and shears
// at the other, so interface bonds break in tension and in shear within the run, with intact ones
// left. Every ball, every wall contact's history and outputs, the vertex sums and the walls'
// reactions must be the scalar pass's bits, at 1 and 2 threads (more than 256 facet contacts:
// the facets' parallel loop runs).
namespace {

struct WallRun {
  test::BallState balls;
  std::vector<ContactHist> h[3];
  std::vector<BondHist> bond;
  std::vector<Vec3> F[3], M[3], TA[3], xc[3];
  std::vector<double> vforce, vstiff;
  Vec3 footing, plane0, plane1;
  int count[5] = {0, 0, 0, 0, 0};
  std::size_t pairs = 0;           // ball-ball contacts at the end
  std::int64_t facets_hosted = 0;  // PhaseTimes::facets_hosted
};

bool same_bytes(const void* a, const void* b, std::size_t n) { return std::memcmp(a, b, n) == 0; }

template <class T>
bool same_vec(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || same_bytes(a.data(), b.data(), a.size() * sizeof(T)));
}

// Histories field by field (their padding bytes are not state). Empty: the same bits; else the
// first field that differs.
std::string hist_diff(const std::vector<ContactHist>& a, const std::vector<ContactHist>& b) {
  if (a.size() != b.size()) return "count";
  for (std::size_t c = 0; c < a.size(); ++c) {
    const ContactHist &x = a[c], &y = b[c];
    const char* f = !same_bytes(&x.fs, &y.fs, sizeof(Vec3))         ? "fs"
                    : !same_bytes(&x.fn, &y.fn, sizeof(double))     ? "fn"
                    : !same_bytes(&x.n_old, &y.n_old, sizeof(Vec3)) ? "n_old"
                    : !same_bytes(&x.kn, &y.kn, sizeof(double))     ? "kn"
                    : !same_bytes(&x.ks, &y.ks, sizeof(double))     ? "ks"
                    : !same_bytes(&x.mu, &y.mu, sizeof(double))     ? "mu"
                    : !same_bytes(&x.e_slip, &y.e_slip, sizeof(double)) ? "e_slip"
                    : x.flags != y.flags                            ? "flags"
                                                                    : nullptr;
    if (f) return std::string(f) + " of contact " + std::to_string(c);
  }
  return "";
}

std::string bond_diff(const std::vector<BondHist>& a, const std::vector<BondHist>& b) {
  if (a.size() != b.size()) return "count";
  for (std::size_t c = 0; c < a.size(); ++c) {
    const BondHist &x = a[c], &y = b[c];
    const char* f = !same_bytes(&x.fsb, &y.fsb, sizeof(Vec3))             ? "fsb"
                    : !same_bytes(&x.nb, &y.nb, sizeof(double))           ? "nb"
                    : !same_bytes(&x.mb, &y.mb, sizeof(Vec3))             ? "mb"
                    : !same_bytes(&x.mt, &y.mt, sizeof(double))           ? "mt"
                    : !same_bytes(&x.rb, &y.rb, sizeof(double))           ? "rb"
                    : !same_bytes(&x.kn, &y.kn, sizeof(double))           ? "kn"
                    : !same_bytes(&x.sigma_t, &y.sigma_t, sizeof(double)) ? "sigma_t"
                    : !same_bytes(&x.e_soft, &y.e_soft, sizeof(double))   ? "e_soft"
                    : x.state != y.state || x.slip_b != y.slip_b || x.slip_t != y.slip_t ? "state"
                                                                                          : nullptr;
    if (f) return std::string(f) + " of bond " + std::to_string(c);
  }
  return "";
}

WallRun run_walls(PairKernel kernel, int threads, int steps, ContactModel walls = ContactModel::kLinear,
                  ContactModel facets = ContactModel::kLinearPBond, int layers = 3, bool hosted = true) {
  WorldParams p;
  p.threads = threads;
  p.ball_wall.model = p.ball_footing.model = walls;
  p.ball_facet.model = facets;
  p.ball_facet.softbond.soft = 20.0;  // ζ: soft bonds break after a short softening branch
  p.ball_facet.softbond.ten = p.ball_facet.softbond.coh = 2e7;
  p.local_damping = 0.0;
  p.ball_facet.pbond.zero_linear = true;
  p.ball_facet.pbond.ten = 2e7;
  p.ball_facet.pbond.coh = 2e7;
  World w(p);
  w.set_pair_kernel(kernel);
  w.set_hosted_facets(hosted);
  const double R = 1e-4, s = 2.002 * R;
  const int nx = 20, ny = 16, nz = layers;
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        w.add_ball({(i + 0.5) * s + 0.02 * R * u(rng), (j + 0.5) * s + 0.02 * R * u(rng),
                    R + k * s + 0.01 * R * u(rng)},
                   R * (1.0 + 0.002 * u(rng)));
  // the floor: a grid of 8 x 6 squares, two facets each, at z = 0 (balls of the first layer touch it)
  const int gx = 8, gy = 6;
  const double Lx = nx * s, Ly = ny * s;
  std::vector<double> pos;
  std::vector<std::int32_t> tri;
  for (int j = 0; j <= gy; ++j)
    for (int i = 0; i <= gx; ++i) {
      pos.push_back(-0.5 * s + i * (Lx + s) / gx);
      pos.push_back(-0.5 * s + j * (Ly + s) / gy);
      pos.push_back(0.0);
    }
  auto vid = [&](int i, int j) { return static_cast<std::int32_t>(j * (gx + 1) + i); };
  for (int j = 0; j < gy; ++j)
    for (int i = 0; i < gx; ++i) {
      for (std::int32_t v : {vid(i, j), vid(i + 1, j), vid(i + 1, j + 1)}) tri.push_back(v);
      for (std::int32_t v : {vid(i, j), vid(i + 1, j + 1), vid(i, j + 1)}) tri.push_back(v);
    }
  const int floor = w.add_facet_wall(pos, tri);
  PlaneWallParams side;
  side.point = {-0.5 * s, 0, 0};
  side.normal = {1, 0, 0};
  side.axis1 = {0, 1, 0};
  w.add_plane(side);
  side.point = {Lx + 0.5 * s, 0, 0};
  side.normal = {-1, 0, 0};
  side.velocity = {-0.02, 0, 0};  // closing in
  w.add_plane(side);
  FootingParams fp;
  fp.diameter = 0.4 * Lx;
  fp.height = 3 * R;
  fp.bottom_centre = {0.5 * Lx, 0.5 * Ly, R + (nz - 1) * s + R + 0.2 * R};
  fp.velocity = {0, 0, -0.3};
  w.set_footing(fp);
  w.prepare();
  EXPECT_GT(w.bond_ball_facet(0.05 * R), 256u);
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    w.balls().v[i] = 0.001 * Vec3{u(rng), u(rng), u(rng)};
    w.balls().w[i] = 5.0 * Vec3{u(rng), u(rng), u(rng)};
  }
  // the floor's vertices: down at the low-x end (tension), sideways at the high-x end (shear), a
  // twist about z in between; positions advanced with the velocities each step
  std::vector<double> vel(pos.size());
  for (int j = 0; j <= gy; ++j)
    for (int i = 0; i <= gx; ++i) {
      const double fx = static_cast<double>(i) / gx, fy = static_cast<double>(j) / gy;
      double* v = &vel[3 * static_cast<std::size_t>(vid(i, j))];
      v[0] = 0.05 * (0.4 * fx * fx + 0.05 * (fy - 0.5));
      v[1] = 0.05 * (0.05 * (0.5 - fx) + 0.2 * fx * fy);
      v[2] = 0.05 * (-0.6 * (1.0 - fx) * (1.0 - fx) + 0.02 * fy);
    }
  for (int st = 0; st < steps; ++st) {
    const double dt = w.dt();
    for (std::size_t k = 0; k < pos.size(); ++k) pos[k] += dt * vel[k];
    w.set_vertex_kinematics(floor, pos, vel);
    w.step();
  }
  WallRun r;
  r.balls = test::ball_state(w);
  const WallContacts* lists[3] = {&w.plane_contacts(), &w.facet_contacts(), &w.footing_contacts()};
  for (int k = 0; k < 3; ++k) {
    r.h[k] = lists[k]->h;
    r.F[k] = lists[k]->F;
    r.M[k] = lists[k]->M;
    r.TA[k] = lists[k]->TA;
    r.xc[k] = lists[k]->xc;
  }
  r.bond = w.facet_contacts().bond;
  for (const BondHist& b : r.bond) ++r.count[static_cast<int>(b.state)];
  const auto vf = w.vertex_forces(floor), vk = w.vertex_stiffness(floor);
  r.vforce.assign(vf.begin(), vf.end());
  r.vstiff.assign(vk.begin(), vk.end());
  r.footing = w.footing_reaction();
  r.plane0 = w.plane(0).reaction;
  r.plane1 = w.plane(1).reaction;
  r.pairs = w.pair_contacts().size();
  r.facets_hosted = w.phase_times().facets_hosted;
  return r;
}

// Every result of two wall runs: balls, the three wall kinds' contacts, the interface bonds, the
// vertex sums and the walls' reactions.
void expect_same_walls(const WallRun& r, const WallRun& ref) {
  EXPECT_TRUE(same_bits(r.balls.x, ref.balls.x)) << "x differs by " << rel_diff(r.balls.x, ref.balls.x);
  EXPECT_TRUE(same_bits(r.balls.v, ref.balls.v)) << "v differs by " << rel_diff(r.balls.v, ref.balls.v);
  EXPECT_TRUE(same_bits(r.balls.w, ref.balls.w)) << "w differs by " << rel_diff(r.balls.w, ref.balls.w);
  EXPECT_TRUE(same_bits(r.balls.f, ref.balls.f)) << "f differs by " << rel_diff(r.balls.f, ref.balls.f);
  EXPECT_TRUE(same_bits(r.balls.t, ref.balls.t)) << "t differs by " << rel_diff(r.balls.t, ref.balls.t);
  for (int kind = 0; kind < 3; ++kind) {
    SCOPED_TRACE("wall kind " + std::to_string(kind));
    EXPECT_EQ(hist_diff(r.h[kind], ref.h[kind]), "");
    EXPECT_TRUE(same_vec(r.F[kind], ref.F[kind]));
    EXPECT_TRUE(same_vec(r.M[kind], ref.M[kind]));
    EXPECT_TRUE(same_vec(r.TA[kind], ref.TA[kind]));
    EXPECT_TRUE(same_vec(r.xc[kind], ref.xc[kind]));
  }
  EXPECT_EQ(bond_diff(r.bond, ref.bond), "");
  EXPECT_TRUE(same_vec(r.vforce, ref.vforce));
  EXPECT_TRUE(same_vec(r.vstiff, ref.vstiff));
  EXPECT_TRUE(same_bytes(&r.footing, &ref.footing, sizeof(Vec3)));
  EXPECT_TRUE(same_bytes(&r.plane0, &ref.plane0, sizeof(Vec3)));
  EXPECT_TRUE(same_bytes(&r.plane1, &ref.plane1, sizeof(Vec3)));
}

void check_walls(int threads, int steps, ContactModel walls = ContactModel::kLinear,
                 ContactModel facets = ContactModel::kLinearPBond) {
  const WallRun ref = run_walls(PairKernel::kScalar, threads, steps, walls, facets);
  std::printf("walls (%s, facets %s), %d thread(s): %zu facet, %zu plane, %zu footing contacts; interface bonds "
              "intact %d broken tension %d shear %d; footing %.3e N\n",
              law_name(walls), law_name(facets), threads, ref.h[1].size(), ref.h[0].size(), ref.h[2].size(),
              ref.count[1], ref.count[3], ref.count[4], ref.footing.z);
  ASSERT_GT(ref.h[1].size(), 256u);
  ASSERT_GT(ref.h[0].size(), 0u);
  ASSERT_GT(ref.h[2].size(), 0u);
  if (facets == ContactModel::kLinearPBond) {
    ASSERT_NE(ref.footing.z, 0.0);  // the footing pressed at the end
  }
  ASSERT_NE(ref.plane1.x, 0.0);
  for (PairKernel k : vector_kernels()) {
    SCOPED_TRACE(std::string("walls kernel ") + kernel_name(k) + ", threads " + std::to_string(threads));
    const WallRun r = run_walls(k, threads, steps, walls, facets);
    expect_same_walls(r, ref);
  }
}

}  // namespace

TEST(SimdKernel, WallContactsBitIdentical) {
  check_walls(1, 400);
  const WallRun r = run_walls(PairKernel::kAuto, 1, 400);
  EXPECT_GT(r.count[static_cast<int>(BondState::kIntact)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kBrokenTension)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kBrokenShear)], 0);
}

TEST(SimdKernel, WallContactsTwoThreadsBitIdentical) { check_walls(2, 400); }

// Hertz–Mindlin platens and footing (R* = R against a wall).
TEST(SimdKernel, HertzWallContactsBitIdentical) { check_walls(1, 400, ContactModel::kHertz); }

// Soft-bond interface facets: bonded lanes in the kernel; softening, breakage and the unbonded
// contacts by the scalar law.
TEST(SimdKernel, SoftBondFacetContactsBitIdentical) {
  check_walls(1, 400, ContactModel::kLinear, ContactModel::kSoftBond);
  const WallRun r = run_walls(PairKernel::kAuto, 1, 400, ContactModel::kLinear, ContactModel::kSoftBond);
  std::printf("soft-bond facets: intact %d softening %d broken tension %d shear %d\n", r.count[1], r.count[2],
              r.count[3], r.count[4]);
  EXPECT_GT(r.count[static_cast<int>(BondState::kIntact)], 0);
  EXPECT_GT(r.count[static_cast<int>(BondState::kBrokenTension)] + r.count[static_cast<int>(BondState::kBrokenShear)],
            0);
}

// Work stealing in the threaded pass (World::set_pair_stealing): the owner of the first chunk is
// held 2 ms per pass, so the other thread takes all but one of its blocks (4 of 5 here) and the
// owner adds their contacts to the ball sums in contact order. Every ball, contact history, bond
// record and energy must be the bits of the pass without stealing, with the lane kernels and the
// scalar loop.
TEST(SimdKernel, TwoThreadsStealingBitIdentical) {
  for (ContactModel m : {ContactModel::kLinear, ContactModel::kSoftBond, ContactModel::kLinearPBond})
    for (PairKernel k : {PairKernel::kAuto, PairKernel::kScalar}) {
      Scene sc;
      sc.name = std::string(law_name(m)) + " 2 threads stealing";
      SCOPED_TRACE(sc.name + " kernel " + kernel_name(k));
      if (m != ContactModel::kLinear) bonded_setup(sc);
      sc.model = m;
      sc.nside = 18;  // about 17,500 pairs: chunk 0 has 5 blocks of 2,048 contacts, 4 of them taken
      sc.threads = 2;
      sc.steps = 30;
      sc.steal = 0;
      const Result ref = run(sc, k);
      sc.steal = 2;
      const Result r = run(sc, k);
      ASSERT_GT(ref.pairs, 4096u);
      std::printf("%s, kernel %s: %zu pairs, %llu blocks taken in %d steps\n", sc.name.c_str(), kernel_name(k),
                  ref.pairs, static_cast<unsigned long long>(r.stolen), sc.steps);
      EXPECT_EQ(ref.stolen, 0u);
      // Blocks were taken (all but one of chunk 0's in a pass where the other thread ran during
      // the hold; on a loaded machine fewer passes): the replay ran.
      EXPECT_GT(r.stolen, 0u);
      expect_same_run(r, ref);
      EXPECT_EQ(hist_diff(r.h, ref.h), "");
      EXPECT_EQ(bond_diff(r.bond, ref.bond), "");
    }
}

// The interface facets' contacts as side units of the ball-ball pass (World::set_hosted_facets,
// the default) against their own pass after it: the same bits, on one thread and on two, with a
// ball-ball pass too small to be cut into chunks (3 layers) and one cut in two (6 layers: more
// than 4,096 pairs), the vector kernels and the scalar loops, bonds breaking.
TEST(SimdKernel, HostedFacetsBitIdentical) {
  for (int threads : {1, 2})
    for (int layers : {3, 6})
      for (PairKernel k : {PairKernel::kAuto, PairKernel::kScalar})
        for (ContactModel facets : {ContactModel::kLinearPBond, ContactModel::kSoftBond}) {
          SCOPED_TRACE(std::string("threads ") + std::to_string(threads) + ", layers " + std::to_string(layers) +
                       ", kernel " + kernel_name(k) + ", facets " + law_name(facets));
          const WallRun ref = run_walls(k, threads, 150, ContactModel::kLinear, facets, layers, false);
          const WallRun r = run_walls(k, threads, 150, ContactModel::kLinear, facets, layers, true);
          if (layers == 6) {
            ASSERT_GT(ref.pairs, 4096u);  // the threaded ball-ball pass at 2 threads
          } else {
            ASSERT_LE(ref.pairs, 4096u);
          }
          ASSERT_GT(ref.h[1].size(), 256u);  // the facets' own loop at 2 threads
          EXPECT_EQ(ref.facets_hosted, 0);
          EXPECT_EQ(r.facets_hosted, 151);  // prepare() and 150 steps
          expect_same_walls(r, ref);
        }
}
