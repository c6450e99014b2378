// Bit-exact resume of a DEM World from a saved state (issue 13; docs/checkpoint-format.md):
// run N steps, save, load into a fresh World, run M more steps in both, and compare every
// ball's state, every contact and bond history field, the walls, the footing, the energies
// and the counters bit for bit. Scenes: a bonded periodic lattice pulled apart by the cell
// strain rate (bonds soften and break), and a free bonded block under gravity in a box of
// planes (one of them a stress servo) on a moving facet floor with bonded interface contacts,
// punched by a footing (bonds break). N is chosen off the timestep interval and between
// neighbour rebuilds; 1 and 2 OpenMP threads.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <algorithm>
#include <array>
#include <filesystem>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {

constexpr std::uint64_t kSceneHash = 0x5eed5eedcafe0001ULL;
constexpr double R = 1e-4;

// ---- comparison ----------------------------------------------------------------------------

// First difference between two worlds (empty: identical bits), checking the state the
// public interface exposes field by field, independently of the checkpoint writer.
class Diff {
 public:
  template <class T>
  void bits(const std::string& what, const std::vector<T>& a, const std::vector<T>& b) {
    if (!first_.empty()) return;
    if (a.size() != b.size()) {
      first_ = what + ": sizes " + std::to_string(a.size()) + " and " + std::to_string(b.size());
      return;
    }
    for (std::size_t i = 0; i < a.size(); ++i)
      if (std::memcmp(&a[i], &b[i], sizeof(T)) != 0) {
        first_ = what + "[" + std::to_string(i) + "] differs";
        return;
      }
  }
  template <class T>
  void value(const std::string& what, const T& a, const T& b) {
    if (first_.empty() && std::memcmp(&a, &b, sizeof(T)) != 0) first_ = what + " differs";
  }
  void hist(const std::string& what, const std::vector<ContactHist>& a, const std::vector<ContactHist>& b) {
    bits(what + ".size", std::vector<std::size_t>{a.size()}, std::vector<std::size_t>{b.size()});
    for (std::size_t c = 0; c < a.size() && c < b.size() && first_.empty(); ++c) {
      const std::string w = what + "[" + std::to_string(c) + "].";
      value(w + "fs", a[c].fs, b[c].fs);
      value(w + "fn", a[c].fn, b[c].fn);
      value(w + "n_old", a[c].n_old, b[c].n_old);
      value(w + "kn", a[c].kn, b[c].kn);
      value(w + "ks", a[c].ks, b[c].ks);
      value(w + "mu", a[c].mu, b[c].mu);
      value(w + "e_slip", a[c].e_slip, b[c].e_slip);
      value(w + "flags", a[c].flags, b[c].flags);
    }
  }
  void bond(const std::string& what, const std::vector<BondHist>& a, const std::vector<BondHist>& b) {
    bits(what + ".size", std::vector<std::size_t>{a.size()}, std::vector<std::size_t>{b.size()});
    for (std::size_t c = 0; c < a.size() && c < b.size() && first_.empty(); ++c) {
      const std::string w = what + "[" + std::to_string(c) + "].";
      value(w + "fsb", a[c].fsb, b[c].fsb);
      value(w + "nb", a[c].nb, b[c].nb);
      value(w + "mb", a[c].mb, b[c].mb);
      value(w + "mt", a[c].mt, b[c].mt);
      value(w + "rb", a[c].rb, b[c].rb);
      value(w + "kn", a[c].kn, b[c].kn);
      value(w + "sigma_t", a[c].sigma_t, b[c].sigma_t);
      value(w + "e_soft", a[c].e_soft, b[c].e_soft);
      value(w + "state", a[c].state, b[c].state);
      value(w + "slip_b", a[c].slip_b, b[c].slip_b);
      value(w + "slip_t", a[c].slip_t, b[c].slip_t);
    }
  }
  void walls(const std::string& what, const WallContacts& a, const WallContacts& b) {
    bits(what + ".ball", a.ball, b.ball);
    bits(what + ".wall", a.wall, b.wall);
    bits(what + ".facet", a.facet, b.facet);
    bits(what + ".cand_off", a.cand_off, b.cand_off);
    bits(what + ".cand", a.cand, b.cand);
    bits(what + ".F", a.F, b.F);
    bits(what + ".M", a.M, b.M);
    bits(what + ".TA", a.TA, b.TA);
    bits(what + ".xc", a.xc, b.xc);
    bits(what + ".bary", a.bary, b.bary);
    hist(what + ".h", a.h, b.h);
    bond(what + ".bond", a.bond, b.bond);
  }
  const std::string& first() const { return first_; }

 private:
  std::string first_;
};

std::string first_difference(World& a, World& b) {
  Diff d;
  const Particles &pa = a.balls(), &pb = b.balls();
  d.bits("x", pa.x, pb.x);
  d.bits("v", pa.v, pb.v);
  d.bits("w", pa.w, pb.w);
  d.bits("f", pa.f, pb.f);
  d.bits("t", pa.t, pb.t);
  d.bits("fa", pa.fa, pb.fa);
  d.bits("ta", pa.ta, pb.ta);
  d.bits("x_ref", pa.x_ref, pb.x_ref);
  d.bits("r", pa.r, pb.r);
  d.bits("m", pa.m, pb.m);
  d.bits("inertia", pa.inertia, pb.inertia);
  d.bits("id", pa.id, pb.id);
  d.bits("fix", pa.fix, pb.fix);
  const PairContacts &ca = a.pair_contacts(), &cb = b.pair_contacts();
  d.bits("pair.a", ca.a, cb.a);
  d.bits("pair.b", ca.b, cb.b);
  d.bits("pair.shift", ca.shift, cb.shift);
  d.hist("pair.h", ca.h, cb.h);
  d.bond("pair.bond", ca.bond, cb.bond);
  d.walls("plane_contacts", a.plane_contacts(), b.plane_contacts());
  d.walls("facet_contacts", a.facet_contacts(), b.facet_contacts());
  d.walls("footing_contacts", a.footing_contacts(), b.footing_contacts());
  d.value("num_planes", a.num_planes(), b.num_planes());
  for (int i = 0; i < a.num_planes() && i < b.num_planes(); ++i) {
    const PlaneWall &x = a.plane(i), &y = b.plane(i);
    const std::string w = "plane[" + std::to_string(i) + "].";
    d.value(w + "point", x.p.point, y.p.point);
    d.value(w + "velocity", x.p.velocity, y.p.velocity);
    d.value(w + "disp", x.disp, y.disp);
    d.value(w + "reaction", x.reaction, y.reaction);
    d.value(w + "k_sum", x.k_sum, y.k_sum);
  }
  d.value("num_facet_walls", a.num_facet_walls(), b.num_facet_walls());
  for (int i = 0; i < a.num_facet_walls() && i < b.num_facet_walls(); ++i) {
    const FacetWall &x = a.facet_wall(i), &y = b.facet_wall(i);
    const std::string w = "facet_wall[" + std::to_string(i) + "].";
    d.bits(w + "pos", x.pos, y.pos);
    d.bits(w + "vel", x.vel, y.vel);
    d.bits(w + "vforce", x.vforce, y.vforce);
    d.bits(w + "vstiff", x.vstiff, y.vstiff);
    d.bits(w + "tri_spin", x.tri_spin, y.tri_spin);
    d.value(w + "total_force", x.total_force, y.total_force);
  }
  d.value("footing.enabled", a.has_footing(), b.has_footing());
  d.value("footing.bottom_centre", a.footing().p.bottom_centre, b.footing().p.bottom_centre);
  d.value("footing.velocity", a.footing().p.velocity, b.footing().p.velocity);
  d.value("footing.disp", a.footing().disp, b.footing().disp);
  d.value("footing.reaction", a.footing().reaction, b.footing().reaction);
  d.value("step", a.step_count(), b.step_count());
  d.value("time", a.time(), b.time());
  d.value("dt", a.dt(), b.dt());
  d.value("skin", a.skin(), b.skin());
  d.value("rebuilds", a.rebuild_count(), b.rebuild_count());
  d.value("bond_failures", a.bond_failures(), b.bond_failures());
  d.value("cell_length", a.cell_length(), b.cell_length());
  d.value("strain_rate", a.strain_rate(), b.strain_rate());
  d.value("cell_strain", a.cell_strain_since_reset(), b.cell_strain_since_reset());
  d.value("gravity", a.gravity(), b.gravity());
  const Energy ea = a.energy(), eb = b.energy();
  d.value("energy.kinetic", ea.kinetic, eb.kinetic);
  d.value("energy.strain", ea.strain, eb.strain);
  d.value("energy.damping", ea.damping, eb.damping);
  d.value("energy.friction", ea.friction, eb.friction);
  d.value("energy.softening", ea.softening, eb.softening);
  if (!d.first().empty()) return d.first();
  // Everything the checkpoint holds (counters included), through the writer.
  if (state_bytes(a, {kSceneHash, "test"}) != state_bytes(b, {kSceneHash, "test"})) return "saved state bytes differ";
  return {};
}

// ---- scenes ----------------------------------------------------------------------------------

// Jittered cubic lattice of soft-bonded balls in a periodic cell pulled apart by the cell
// strain rate (the pattern of tests/dem/simd_kernel_test.cpp): bonds stay intact, soften and
// break in tension and shear within a few hundred steps.
std::unique_ptr<World> periodic_lattice(int nside, int threads, int dt_interval) {
  const double s = 2.0 * R;
  WorldParams p;
  p.threads = threads;
  p.dt_interval = dt_interval;
  p.skin = 0.01 * R;  // a thin Verlet skin: the list is rebuilt every few tens of steps
  p.periodic.enabled = true;
  p.periodic.length = {nside * s, nside * s, nside * s};
  p.ball_ball.model = ContactModel::kSoftBond;
  p.ball_ball.softbond.soft = 20.0;
  auto w = std::make_unique<World>(p);
  std::mt19937_64 rng(2024);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < nside; ++k)
    for (int j = 0; j < nside; ++j)
      for (int i = 0; i < nside; ++i)
        w->add_ball({(i + 0.5) * s + 0.002 * R * u(rng), (j + 0.5) * s + 0.002 * R * u(rng),
                     (k + 0.5) * s + 0.002 * R * u(rng)},
                    R * (1.0 + 0.002 * u(rng)));
  w->prepare();
  w->bond_ball_ball(-1.0, 0.01 * R);
  for (std::size_t i = 0; i < w->num_balls(); ++i) {
    w->balls().v[i] = 0.002 * Vec3{u(rng), u(rng), u(rng)};
    w->balls().w[i] = 2.0 * Vec3{u(rng), u(rng), u(rng)};
    if (i % 29 == 5) w->balls().fix[i] = kFixVx | kFixWz;
  }
  w->set_strain_rate({150.0, 150.0, -75.0});
  return w;
}

struct FreeBlock {
  int nx = 8, ny = 8, nz = 6;
  int threads = 1;
  int dt_interval = 13;
};

// A soft-bonded block (nx × ny × nz lattice) at 100 g in a box: planes at x = 0, y = 0 and
// y = W, a stress-servo plane at x = L, a floor of two facets at z = 0 with parallel-bonded
// interface contacts, and a footing that starts just above the top and moves down at 2 m/s.
std::unique_ptr<World> free_block(const FreeBlock& b) {
  const double s = 2.0 * R;
  const double L = b.nx * s, W = b.ny * s, H = b.nz * s;
  WorldParams p;
  p.threads = b.threads;
  p.dt_interval = b.dt_interval;
  p.skin = 0.02 * R;  // a thin Verlet skin: the list is rebuilt every few tens of steps
  p.gravity = true;
  p.g_level = 100.0;
  p.ball_ball.model = ContactModel::kSoftBond;
  p.ball_ball.softbond.soft = 20.0;
  p.ball_facet.model = ContactModel::kLinearPBond;
  p.ball_footing.linear.fric = 0.5;
  auto w = std::make_unique<World>(p);
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < b.nz; ++k)
    for (int j = 0; j < b.ny; ++j)
      for (int i = 0; i < b.nx; ++i)
        w->add_ball({(i + 0.5) * s + 0.002 * R * u(rng), (j + 0.5) * s + 0.002 * R * u(rng),
                     (k + 0.5) * s + 0.002 * R * u(rng)},
                    R * (1.0 + 0.002 * u(rng)));
  auto plane = [&](Vec3 point, Vec3 normal) {
    PlaneWallParams q;
    q.point = point;
    q.normal = normal;
    return q;
  };
  w->add_plane(plane({0, 0, 0}, {1, 0, 0}));
  w->add_plane(plane({0, 0, 0}, {0, 1, 0}));
  w->add_plane(plane({0, W, 0}, {0, -1, 0}));
  PlatenServoParams servo;
  servo.wall = w->add_plane(plane({L, 0, 0}, {-1, 0, 0}));
  servo.stress = 2e4;
  servo.area = W * H;
  servo.vmax = 0.05;
  w->add_effect(std::make_unique<PlatenServo>(servo));
  const double e = 2.0 * s;
  const std::vector<double> v{-e, -e, 0, L + e, -e, 0, L + e, W + e, 0, -e, W + e, 0};
  w->add_facet_wall(v, std::vector<std::int32_t>{0, 1, 2, 0, 2, 3});
  FootingParams f;
  f.diameter = 4.0 * s;
  f.height = 2.0 * s;
  f.bottom_centre = {0.5 * L, 0.5 * W, H + 0.1 * R};
  f.velocity = {0, 0, -2.0};
  w->set_footing(f);
  w->prepare();
  w->bond_ball_ball(-1.0, 0.01 * R);
  w->bond_ball_facet(0.01 * R);
  for (std::size_t i = 0; i < w->num_balls(); ++i) {
    w->balls().v[i] = 0.002 * Vec3{u(rng), u(rng), u(rng)};
    w->balls().w[i] = 2.0 * Vec3{u(rng), u(rng), u(rng)};
  }
  return w;
}

// The facet floor is driven from outside, as the continuum does in a coupled run with a
// coupling interval of 3 DEM steps: a small rocking about the y axis (vertex speeds grow with
// x, so the facets spin), computed from the world's own state (so both runs get the same).
// Between updates the facet spins of the last update stay in use, so they must come from the
// file.
void drive_floor(World& w) {
  if (w.num_facet_walls() == 0 || w.step_count() % 3 != 0) return;
  FacetWall& fw = w.facet_wall(0);
  const double amp = 0.02 * std::sin(0.05 * static_cast<double>(w.step_count()));
  std::vector<double> pos, vel;
  for (const Vec3& x : fw.pos) {
    const double vz = amp * (x.x / (10.0 * R));
    pos.insert(pos.end(), {x.x, x.y, x.z + 3.0 * vz * w.dt()});
    vel.insert(vel.end(), {0.0, 0.0, vz});
  }
  w.set_vertex_kinematics(0, pos, vel);
}

void run(World& w, int steps) {
  for (int k = 0; k < steps; ++k) {
    drive_floor(w);
    w.step();
  }
}

int count_state(const World& w, BondState s) {
  int n = 0;
  for (const BondHist& b : w.pair_contacts().bond) n += b.state == s;
  return n;
}

bool mid_rebuild_interval(const World& w) {
  const Particles& pt = w.balls();
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (std::memcmp(&pt.x[i], &pt.x_ref[i], sizeof(Vec3)) != 0) return true;
  return false;
}

// Run `make()` N steps, save, load into a fresh default World, run M more steps in both and
// compare. Returns the first difference (empty: bit-identical). `mid` (optional) tells whether
// the save fell between two neighbour rebuilds (false: the list was rebuilt in step N).
template <class Make>
std::string resume_check(Make make, int n, int m, const char* name, bool* mid = nullptr) {
  auto a = make();
  run(*a, n);
  const std::int64_t rebuilds_at_save = a->rebuild_count();
  const std::int64_t failures_at_save = a->bond_failures();
  const bool at_mid = mid_rebuild_interval(*a);
  if (mid) *mid = at_mid;
  const std::string bytes = state_bytes(*a, {kSceneHash, "test"});
  World b{WorldParams{}};
  load_state_bytes(b, bytes, kSceneHash, name);
  // Right after the load the state is the same, and saving it again gives the same file.
  EXPECT_EQ(first_difference(*a, b), "") << name << " after load";
  EXPECT_TRUE(state_bytes(b, {kSceneHash, "test"}) == bytes) << name << ": save(load(save)) != save";
  run(*a, m);
  run(b, m);
  EXPECT_GT(a->rebuild_count(), rebuilds_at_save) << name << ": the continuation should rebuild the neighbour list";
  EXPECT_GT(a->bond_failures(), failures_at_save) << name << ": bonds should fail during the continuation";
  std::printf("%s: N = %d (%s), M = %d: %zu balls, %zu pairs, %zu wall contacts, rebuilds %lld -> %lld, bond failures "
              "%lld -> %lld, softening %d, broken %d, dt %.3g s, state %zu bytes\n",
              name, n, at_mid ? "between rebuilds" : "rebuilt in step N", m, a->num_balls(), a->pair_contacts().size(),
              a->plane_contacts().size() + a->facet_contacts().size() + a->footing_contacts().size(),
              static_cast<long long>(rebuilds_at_save), static_cast<long long>(a->rebuild_count()),
              static_cast<long long>(failures_at_save), static_cast<long long>(a->bond_failures()),
              count_state(*a, BondState::kSoftening),
              count_state(*a, BondState::kBrokenTension) + count_state(*a, BondState::kBrokenShear), a->dt(), bytes.size());
  return first_difference(*a, b);
}

}  // namespace

// ---- resume tests ------------------------------------------------------------------------------

// N = 37 and 150 are not multiples of the timestep interval (7); N = 1 saves right after
// the first step, before the first timestep recompute.
TEST(DemCheckpoint, PeriodicBondedLatticeResumesBitExact) {
  int between = 0;
  for (int n : {1, 37, 150}) {
    SCOPED_TRACE("N = " + std::to_string(n));
    bool mid = false;
    EXPECT_EQ(resume_check([] { return periodic_lattice(7, 1, 7); }, n, 250, "periodic 1 thread", &mid), "");
    between += mid;
  }
  EXPECT_GT(between, 0) << "at least one save between two neighbour rebuilds";
}

// nside 12: more than 4096 pairs, so the ball–ball pass runs in 2 thread blocks with the
// fixed-order reduction of the thread buffers.
TEST(DemCheckpoint, PeriodicBondedLatticeTwoThreadsResumesBitExact) {
  auto make = [] { return periodic_lattice(12, 2, 100); };
  {
    auto probe = make();
    ASSERT_GT(probe->pair_contacts().size(), 4096u) << "the threaded branch of the pair pass must run";
  }
  EXPECT_EQ(resume_check(make, 101, 120, "periodic 2 threads"), "");
}

// Gravity, planes with a servo, a driven facet floor with interface bonds, a footing moving
// down: N = 1, 91 and 173 are off the timestep interval (13) and off the floor's update
// interval (3); one more N falls on a step that rebuilt the neighbour list.
TEST(DemCheckpoint, FreeBlockWallsFacetsFootingResumesBitExact) {
  // The first step after step 60 in which the neighbour list is rebuilt: a save right there.
  int rebuilt = 0;
  {
    auto probe = free_block({});
    run(*probe, 60);
    const std::int64_t r0 = probe->rebuild_count();
    while (probe->rebuild_count() == r0 && probe->step_count() < 400) run(*probe, 1);
    rebuilt = static_cast<int>(probe->step_count());
  }
  int between = 0, after = 0;
  for (int n : {1, 91, 173, rebuilt}) {
    SCOPED_TRACE("N = " + std::to_string(n));
    bool mid = false;
    EXPECT_EQ(resume_check([] { return free_block({}); }, n, 220, "free block 1 thread", &mid), "");
    between += mid;
    after += !mid;
  }
  // Saves between two rebuilds and right after one.
  EXPECT_GT(between, 0);
  EXPECT_GT(after, 0);
  // The scene does what it is meant to cover.
  auto w = free_block({});
  run(*w, 300);
  EXPECT_GT(w->footing_reaction().z, 0.0) << "the block pushes back on the footing";
  EXPECT_GT(w->facet_contacts().size(), 0u);
  std::size_t bonded_facet = 0;
  for (const BondHist& b : w->facet_contacts().bond) bonded_facet += b.state == BondState::kIntact;
  EXPECT_GT(bonded_facet, 0u) << "interface bonds on the floor";
  EXPECT_NE(w->plane(3).p.point.x, 16.0 * R) << "the servo plane moved";
  EXPECT_TRUE(w->gravity_on());
}

TEST(DemCheckpoint, FreeBlockTwoThreadsResumesBitExact) {
  FreeBlock b;
  b.nx = b.ny = 16;
  b.nz = 9;
  b.threads = 2;
  {
    auto probe = free_block(b);
    ASSERT_GT(probe->pair_contacts().size(), 4096u) << "the threaded branch of the pair pass must run";
    ASSERT_GT(probe->num_balls(), 2048u) << "the law of motion must run in more than one chunk";
  }
  EXPECT_EQ(resume_check([&] { return free_block(b); }, 111, 120, "free block 2 threads"), "");
}

// The platen servo is an effect (kKinematics) that travels with the checkpoint: a platen
// servoed onto a small column, saved while it regulates (its speed below the limit), loaded into
// an empty World, keeps being servoed, bit for bit.
TEST(DemCheckpoint, PlatenServoTravelsWithTheCheckpoint) {
  WorldParams p;
  p.ball_ball.model = ContactModel::kLinear;
  World a(p);
  const double r = 1e-4, s = 2 * r;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) a.add_ball({i * s, j * s, r + k * s}, r);
  PlaneWallParams bot;
  bot.point = {0.5 * s, 0.5 * s, 0};
  a.add_plane(bot);
  PlaneWallParams top = bot;
  top.point.z = 3 * s;
  top.normal = {0, 0, -1};
  PlatenServoParams servo;
  servo.wall = a.add_plane(top);
  servo.stress = 1e5;
  servo.area = 4 * s * s;
  servo.vmax = 1e-3;
  a.add_effect(std::make_unique<PlatenServo>(servo));
  run(a, 480);  // the servo regulates from about step 450 to 900 (below its speed limit)
  World b{WorldParams{}};
  load_state_bytes(b, state_bytes(a, {kSceneHash, "test"}), kSceneHash, "platen");
  const double v0 = a.plane(1).p.velocity.z;
  EXPECT_LT(std::abs(v0), servo.vmax) << "saved while the servo regulates";
  run(a, 200);
  run(b, 200);
  EXPECT_NE(a.plane(1).p.velocity.z, v0) << "the servo changes the platen's speed in this window";
  EXPECT_EQ(first_difference(a, b), "");
}

// ---- the comparison can fail ---------------------------------------------------------------

// One ulp in one ball's spin after the load, and the runs part: the comparison sees it.
TEST(DemCheckpoint, OneUlpAfterLoadIsDetected) {
  auto a = free_block({});
  run(*a, 90);
  World b{WorldParams{}};
  load_state_bytes(b, state_bytes(*a, {kSceneHash, "test"}), kSceneHash, "ulp");
  b.balls().w[10].x = std::nextafter(b.balls().w[10].x, 1e300);
  run(*a, 50);
  run(b, 50);
  EXPECT_NE(first_difference(*a, b), "");
}

// What prepare() derives must come from the file: rebuilding it after the load (new neighbour
// list order, fresh Verlet reference, timestep recomputed at another step, a force pass with
// zero increments) gives other bits.
TEST(DemCheckpoint, RebuildingDerivedStateInsteadOfLoadingItDiffers) {
  for (bool periodic : {true, false}) {
    SCOPED_TRACE(periodic ? "periodic" : "free block");
    auto a = periodic ? periodic_lattice(7, 1, 7) : free_block({});
    run(*a, 37);
    World b{WorldParams{}};
    load_state_bytes(b, state_bytes(*a, {kSceneHash, "test"}), kSceneHash, "derived");
    b.prepare();
    run(*a, 100);
    run(b, 100);
    const std::string d = first_difference(*a, b);
    EXPECT_NE(d, "");
    std::printf("%s: prepare() after load -> first difference: %s\n", periodic ? "periodic" : "free block", d.c_str());
  }
}

// ---- files, streams, effects, refusals ----------------------------------------------------

TEST(DemCheckpoint, FileAndStreamRoundTrip) {
  auto a = free_block({});
  run(*a, 60);
  const auto dir = std::filesystem::temp_directory_path() / ("demfdm_dem_ckpt_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto file = dir / "dem.state";
  save_state_file(*a, file, {kSceneHash, "v-test"});
  EXPECT_FALSE(std::filesystem::exists(file.string() + ".tmp-" + std::to_string(::getpid())));
  World b{WorldParams{}};
  const auto h = load_state_file(b, file, kSceneHash);
  EXPECT_EQ(h.kind, "dem");
  EXPECT_EQ(h.code_version, "v-test");
  EXPECT_EQ(h.scene_hash, kSceneHash);
  EXPECT_EQ(h.format_version, demfdm::io::kStateFormatVersion);
  std::stringstream ss;
  save_state(*a, ss, {kSceneHash, "v-test"});
  World c{WorldParams{}};
  load_state(c, ss, kSceneHash, "stream");
  run(*a, 40);
  run(b, 40);
  run(c, 40);
  EXPECT_EQ(first_difference(*a, b), "");
  EXPECT_EQ(first_difference(*a, c), "");
  std::filesystem::remove_all(dir);
}

// A state file written in pieces (StateStream: the balls and pairs in blocks of rows, the wall
// contacts at the end, the rest from a World without balls) has the bytes of state_bytes() of
// the whole World: the bonded periodic lattice (image shifts, pair bonds) and the free block
// (planes with a servo, bonded facet contacts, the footing), blocks of 1, 7 and all rows.
TEST(DemCheckpoint, StateWrittenInPiecesHasTheWholeWorldsBytes) {
  const auto dir = std::filesystem::temp_directory_path() / ("demfdm_dem_stream_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const CheckpointMeta meta{kSceneHash, "v-test"};
  for (int scene = 0; scene < 2; ++scene) {
    auto w = scene == 0 ? periodic_lattice(6, 1, 13) : free_block({});
    run(*w, 70);
    const std::string want = state_bytes(*w, meta);
    // the frame: a copy without its balls and contacts (as rank 0's World while the ranks step)
    World frame{WorldParams{}};
    load_state_bytes(frame, want, kSceneHash, "copy");
    frame.drop_balls();
    ASSERT_EQ(frame.num_balls(), 0u);
    const Particles& pt = w->balls();
    const PairContacts& pc = w->pair_contacts();
    ASSERT_GT(pc.size(), 100u);
    ASSERT_EQ(pc.bond.size(), pc.size()) << "the pairs carry bonds";
    for (std::size_t block : {std::size_t{1}, std::size_t{7}, pt.size() + pc.size()}) {
      SCOPED_TRACE("scene " + std::to_string(scene) + ", blocks of " + std::to_string(block));
      const auto file = dir / ("pieces-" + std::to_string(scene) + "-" + std::to_string(block) + ".state");
      StateStream out(file, frame, pt.size(), pc.size(), meta);
      for (std::size_t r0 = 0; r0 < pt.size(); r0 += block) {
        Particles rows;
        for (std::size_t i = r0; i < std::min(pt.size(), r0 + block); ++i) {
          rows.x.push_back(pt.x[i]), rows.v.push_back(pt.v[i]), rows.w.push_back(pt.w[i]), rows.f.push_back(pt.f[i]);
          rows.t.push_back(pt.t[i]), rows.fa.push_back(pt.fa[i]), rows.ta.push_back(pt.ta[i]);
          rows.x_ref.push_back(pt.x_ref[i]), rows.r.push_back(pt.r[i]), rows.m.push_back(pt.m[i]);
          rows.inertia.push_back(pt.inertia[i]), rows.id.push_back(pt.id[i]), rows.fix.push_back(pt.fix[i]);
        }
        out.balls(rows);
      }
      if (block == 7) {
        EXPECT_THROW(out.commit(w->plane_contacts(), w->facet_contacts(), w->footing_contacts()), std::logic_error)
            << "a commit before the pairs came";
      }
      for (std::size_t c0 = 0; c0 < pc.size(); c0 += block) {
        PairContacts rows;
        for (std::size_t c = c0; c < std::min(pc.size(), c0 + block); ++c) {
          rows.a.push_back(pc.a[c]), rows.b.push_back(pc.b[c]), rows.shift.push_back(pc.shift[c]);
          rows.h.push_back(pc.h[c]), rows.bond.push_back(pc.bond[c]);
        }
        out.pairs(rows);
      }
      out.commit(w->plane_contacts(), w->facet_contacts(), w->footing_contacts());
      EXPECT_EQ(demfdm::io::read_whole_file(file) == want, true) << "the file differs from state_bytes";
    }
    if (scene == 1) {
      EXPECT_GT(w->plane_contacts().size(), 0u);
      EXPECT_GT(w->facet_contacts().size(), 0u);
    } else {
      bool shifted = false;
      for (const auto& s : pc.shift) shifted = shifted || s[0] != 0 || s[1] != 0 || s[2] != 0;
      EXPECT_TRUE(shifted) << "pairs across the periodic cell";
    }
  }
  // A stream given up before its commit leaves no file.
  {
    auto w = free_block({});
    StateStream out(dir / "abandoned.state", *w, 3, 0, meta);
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "abandoned.state"));
  std::size_t temporaries = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    temporaries += e.path().string().find(".tmp-") != std::string::npos;
  EXPECT_EQ(temporaries, 0u);
  std::filesystem::remove_all(dir);
}

// A state file read in pieces (StateSource: the frame, the balls and pairs in blocks of rows,
// the wall contacts whole) gives back the World: reassembled, its state file has the file's
// bytes. A contact naming a ball beyond the file's balls is refused by file and section.
TEST(DemCheckpoint, StateReadInPiecesGivesTheWorldBack) {
  const auto dir = std::filesystem::temp_directory_path() / ("demfdm_dem_source_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const CheckpointMeta meta{kSceneHash, "v-test"};
  for (int scene = 0; scene < 2; ++scene) {
    SCOPED_TRACE("scene " + std::to_string(scene));
    auto w = scene == 0 ? periodic_lattice(6, 1, 13) : free_block({});
    run(*w, 70);
    const auto file = dir / ("whole-" + std::to_string(scene) + ".state");
    save_state_file(*w, file, meta);
    const std::string want = demfdm::io::read_whole_file(file);
    const StateSource src(file, kSceneHash);
    ASSERT_EQ(src.balls(), w->num_balls());
    ASSERT_EQ(src.pairs(), w->pair_contacts().size());
    World g{WorldParams{}};
    src.load_frame(g);
    EXPECT_EQ(g.num_balls(), 0u);
    const auto k = g.counters();
    Particles pt;
    for (std::uint64_t r0 = 0; r0 < src.balls(); r0 += 7) {
      Particles b;
      src.read_balls(r0, static_cast<std::size_t>(std::min<std::uint64_t>(7, src.balls() - r0)), b);
      std::vector<Vec3> x;
      std::vector<double> r;
      std::vector<std::uint64_t> id;
      src.read_positions(r0, b.size(), x, r, id);
      EXPECT_TRUE(std::memcmp(x.data(), b.x.data(), x.size() * sizeof(Vec3)) == 0 && r == b.r && id == b.id);
      for (std::size_t i = 0; i < b.size(); ++i) {
        pt.x.push_back(b.x[i]), pt.v.push_back(b.v[i]), pt.w.push_back(b.w[i]), pt.f.push_back(b.f[i]);
        pt.t.push_back(b.t[i]), pt.fa.push_back(b.fa[i]), pt.ta.push_back(b.ta[i]), pt.x_ref.push_back(b.x_ref[i]);
        pt.r.push_back(b.r[i]), pt.m.push_back(b.m[i]), pt.inertia.push_back(b.inertia[i]), pt.id.push_back(b.id[i]);
        pt.fix.push_back(b.fix[i]);
      }
    }
    PairContacts pc;
    for (std::uint64_t c0 = 0; c0 < src.pairs(); c0 += 7) {
      PairContacts b;
      src.read_pairs(c0, static_cast<std::size_t>(std::min<std::uint64_t>(7, src.pairs() - c0)), b);
      std::vector<std::uint32_t> ra, rb;
      src.read_pair_rows(c0, b.size(), ra, rb);
      EXPECT_TRUE(ra == b.a && rb == b.b);
      for (std::size_t c = 0; c < b.size(); ++c) {
        pc.a.push_back(b.a[c]), pc.b.push_back(b.b[c]), pc.shift.push_back(b.shift[c]), pc.h.push_back(b.h[c]);
        pc.bond.push_back(b.bond[c]);
      }
    }
    std::array<WallContacts, 3> wc = src.read_wall_contacts();
    std::vector<std::uint8_t> no_ghosts;
    g.swap_balls(pt, pc, wc, no_ghosts);
    g.set_counters(k);
    EXPECT_TRUE(state_bytes(g, meta) == want) << "the World read in pieces differs from the saved one";
    if (scene == 1) {
      EXPECT_GT(g.facet_contacts().size(), 0u);
    }
  }
  // a contact's ball A beyond the balls, the checksum made right again
  {
    auto w = periodic_lattice(4, 1, 13);
    run(*w, 5);
    std::string b = state_bytes(*w, meta);
    const std::size_t name = b.find(std::string("\x05\0\0\0pairs", 9));  // the section's name, then its length
    ASSERT_NE(name, std::string::npos);
    const std::size_t at = name + 9 + 8;  // its content: the count of A rows, then the first
    ASSERT_GT(w->pair_contacts().size(), 0u);
    const std::uint32_t rows = static_cast<std::uint32_t>(w->num_balls());
    for (int i = 0; i < 4; ++i) b[at + 8 + static_cast<std::size_t>(i)] = static_cast<char>((rows >> (8 * i)) & 0xffu);
    const std::uint64_t h = demfdm::io::fnv1a64(b.data(), b.size() - 8);
    for (int i = 0; i < 8; ++i) b[b.size() - 8 + static_cast<std::size_t>(i)] = static_cast<char>((h >> (8 * i)) & 0xff);
    const auto file = dir / "bad.state";
    demfdm::io::write_atomically(file, b);
    const StateSource src(file, kSceneHash);
    PairContacts out;
    try {
      src.read_pairs(0, 3, out);
      ADD_FAILURE() << "a row out of range must be refused";
    } catch (const demfdm::io::StateFileError& e) {
      EXPECT_NE(std::string(e.what()).find(file.string() + ": section 'pairs': contact 0 names a ball row out of range"),
                std::string::npos) << e.what();
    }
    EXPECT_THROW(StateSource(dir / "missing.state", kSceneHash), demfdm::io::StateFileError);
    EXPECT_THROW(StateSource(file, kSceneHash + 1), demfdm::io::StateFileError);
  }
  std::filesystem::remove_all(dir);
}

// Gravity is restored from the file: a world built with gravity loses it when the state has
// none, and gains it when the state has it.
TEST(DemCheckpoint, GravityFollowsTheFile) {
  auto a = periodic_lattice(6, 1, 7);
  ASSERT_FALSE(a->gravity_on());
  WorldParams with_g;
  with_g.gravity = true;
  World b(with_g);
  ASSERT_TRUE(b.gravity_on());
  load_state_bytes(b, state_bytes(*a, {kSceneHash, "test"}), kSceneHash, "no gravity");
  EXPECT_FALSE(b.gravity_on());
  auto c = free_block({});
  World d{WorldParams{}};
  load_state_bytes(d, state_bytes(*c, {kSceneHash, "test"}), kSceneHash, "gravity");
  EXPECT_TRUE(d.gravity_on());
  EXPECT_EQ(d.gravity().z, c->gravity().z);
}

// The servo of servo_until() and observers are effects a checkpoint cannot hold: refused by name.
TEST(DemCheckpoint, UnsaveableEffectsAreRefusedByName) {
  auto w = periodic_lattice(6, 1, 7);
  Effect* servo = w->add_effect(std::make_unique<PeriodicServo>(ServoParams{}, 2.0 * R));
  try {
    (void)state_bytes(*w, {kSceneHash, "test"});
    ADD_FAILURE() << "expected a refusal";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'periodic_servo'"), std::string::npos) << e.what();
  }
  w->remove_effect(servo);
  Effect* rec = w->add_effect(std::make_unique<MeasurementRecorder>(10));
  EXPECT_THROW((void)state_bytes(*w, {kSceneHash, "test"}), std::invalid_argument);
  w->remove_effect(rec);
  EXPECT_NO_THROW((void)state_bytes(*w, {kSceneHash, "test"}));
}

// A refused file leaves the world as it was; messages name the source.
TEST(DemCheckpoint, RefusalsNameTheFileAndLeaveTheWorldUntouched) {
  auto a = periodic_lattice(6, 1, 7);
  run(*a, 5);
  const std::string bytes = state_bytes(*a, {kSceneHash, "test"});
  auto b = free_block({});
  const std::size_t n0 = b->num_balls();
  auto refused = [&](std::string data, std::uint64_t hash, const std::string& expect) {
    try {
      load_state_bytes(*b, std::move(data), hash, "ckpt/dem-000123.state");
      ADD_FAILURE() << "expected a refusal containing '" << expect << "'";
    } catch (const demfdm::io::StateFileError& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.rfind("ckpt/dem-000123.state: ", 0), 0u) << m;
      EXPECT_NE(m.find(expect), std::string::npos) << m;
    }
    EXPECT_EQ(b->num_balls(), n0);
  };
  refused(bytes, kSceneHash + 1, "scene hash");
  std::string damaged = bytes;
  damaged[damaged.size() / 2] ^= 0x10;
  refused(damaged, kSceneHash, "checksum mismatch");
  refused(bytes.substr(0, bytes.size() - 100), kSceneHash, "truncated");
  // A loaded world steps on; the refused ones above changed nothing.
  run(*b, 3);
}

// ---- size and timing on the accuracy study's block (run with --gtest_also_run_disabled_tests)

// scenes/accuracy_footing.toml: a 2 x 2 x 1 mm REV at upscaling 1.5, porosity 0.52042, bonded to
// Z = 6.82, replicated 1 x 1 x 3 into a 2856-ball block. Prints bytes per ball and per contact
// and the save and load times.
TEST(DemCheckpoint, SizeAndTimeOfAccuracyFootingBlock) {
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.length = {2e-3, 2e-3, 1e-3};
  p.threads = 1;
  p.skin_factor = 0.8;
  p.ball_ball.model = ContactModel::kSoftBond;
  World w(p);
  RevParams g;
  g.psd.scale = 1.5;
  g.seed = 1;
  g.porosity_final = 0.52042;
  generate_rev(w, g);
  install_bonds_to_coordination(w, 6.82, 1e-3 * g.psd.d_min * g.psd.scale);
  ReplicateParams rp;
  rp.nx = 1;
  rp.ny = 1;
  rp.nz = 3;
  replicate(w, rp);
  w.prepare();
  w.step(10);
  const std::size_t nb = w.num_balls(), nc = w.pair_contacts().size();
  std::size_t bonded = 0;
  for (const BondHist& b : w.pair_contacts().bond) bonded += b.state == BondState::kIntact;
  using Clock = std::chrono::steady_clock;
  std::string bytes;
  const int reps = 20;
  auto t0 = Clock::now();
  for (int k = 0; k < reps; ++k) bytes = state_bytes(w, {kSceneHash, "test"});
  auto t1 = Clock::now();
  World b{WorldParams{}};
  for (int k = 0; k < reps; ++k) load_state_bytes(b, bytes, kSceneHash, "timing");
  auto t2 = Clock::now();
  const auto file = std::filesystem::temp_directory_path() / ("demfdm_dem_size_" + std::to_string(::getpid()));
  save_state_file(w, file, {kSceneHash, "test"});
  auto t3 = Clock::now();
  World c{WorldParams{}};
  load_state_file(c, file, kSceneHash);
  auto t4 = Clock::now();
  std::filesystem::remove(file);
  const double per_contact = 4 + 4 + 4 + (11 * 8 + 1) + (12 * 8 + 3);
  const double per_ball = 8 * 24 + 3 * 8 + 8 + 1;
  std::printf("accuracy block: %zu balls, %zu ball-ball contacts (%zu bonded), %zu wall contacts; state %zu bytes "
              "= %.1f per ball; layout: %.0f bytes per ball, %.0f per ball-ball contact\n",
              nb, nc, bonded, w.plane_contacts().size() + w.facet_contacts().size() + w.footing_contacts().size(),
              bytes.size(), double(bytes.size()) / double(nb), per_ball, per_contact);
  auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  std::printf("save (memory) %.2f ms, load (memory) %.2f ms, save to file incl. fsync %.2f ms, load from file %.2f ms\n",
              ms(t0, t1) / reps, ms(t1, t2) / reps, ms(t2, t3), ms(t3, t4));
  EXPECT_EQ(nb, 2856u);
  EXPECT_EQ(first_difference(w, c), "");
  // The file is its per-item layout plus a bounded header and parameter block (no hidden
  // per-item overhead); the times are printed, never asserted.
  const double layout = per_ball * double(nb) + per_contact * double(nc);
  EXPECT_GE(double(bytes.size()), layout);
  EXPECT_LE(double(bytes.size()), layout + 0.1 * layout) << "state grew beyond its documented layout";
}
