// Walls, interface facets, the footing and gravity on MPI ranks (dem_dist, issue 17 item 1): a
// block of balls in a box of four planes on a facet floor, under gravity, with the footing
// punching in from the top and the floor's vertices moving as a continuum would move them.
// Rank 0 steps one World holding every ball; the ranks step the block cut into bricks. Every
// ball's state, every wall's sums (plane reactions and servo gains, the floor's vertex forces and
// stiffness, the footing reaction) and the per-step histories of the footing reaction and the
// floor's force must equal the reference bit for bit. The cuts lie on planes of ball centres,
// so balls cross them; the footing's travel forces a rebuild every few steps.
#include <gtest/gtest.h>
#include <mpi.h>

#include <cmath>
#include <cstring>
#include <cstdio>
#include <numbers>
#include <random>
#include <string>

#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/dist.hpp"
#include "demfdm/dem/specimen.hpp"
#include "tests/dem/lattice.hpp"
#include "tests/dist/dist_util.hpp"

using namespace demfdm::dem;
using test::g_rank;
using test::g_size;

namespace {

constexpr int kSide = 12;  // kSide³ balls
constexpr double kR = 1e-4;
constexpr double kS = 1.96 * kR;  // lattice spacing
constexpr double kL = kSide * kS;
constexpr double kDt = 5e-8;

struct WallScene {
  std::string name;
  ContactModel facet_model = ContactModel::kLinear;  // kLinearPBond: the floor bonded (2.6)
  int axis = 0;                                      // the axis cut into bricks
  int steps = 800;
  int balance_every = 0;  // DistDem::Balance::every
  DistDem::Weight weight = DistDem::Weight::kContacts;
  double reach = -1.0;  // DistDem::set_neighbour_reach (0: every exchange falls back to all-to-all)
  bool servo = false;   // a platen servo pushes the side plane x = 0 (its stress target above the block's)
  int per_call = 1;     // DEM steps per call of step(n) (the floor's vertices are set once per call)
  bool order_free = false;  // WorldParams::order_free_sums: the walls' sums and the measurements
  bool from_root = false;   // DistDem::load_from_root and unload to rank 0 only: the other ranks never hold the whole World
};

// The floor: a 3 x 3 grid of vertices over the box's base (margin kS), 8 triangles facing +z.
struct Floor {
  std::vector<double> base;  // [nv*3]
  std::vector<std::int32_t> tri;
  Floor() {
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) base.insert(base.end(), {-kS + i * 0.5 * (kL + 2 * kS), -kS + j * 0.5 * (kL + 2 * kS), 0.0});
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 2; ++i) {
        const std::int32_t a = 3 * j + i, b = a + 1, c = a + 4, d = a + 3;
        tri.insert(tri.end(), {a, b, c, a, c, d});
      }
  }
  // Vertex positions after step k (and their velocities): each vertex rises and falls by 2 % of
  // R with its own phase, so the facets tilt and spin.
  void at(std::int64_t k, std::vector<double>& pos, std::vector<double>& vel) const {
    pos = base;
    vel.assign(base.size(), 0.0);
    const double om = 2.0 * std::numbers::pi / 400.0;  // per step
    for (std::size_t v = 0; v < base.size() / 3; ++v) {
      const double ph = 0.7 * static_cast<double>(v);
      pos[3 * v + 2] += 0.02 * kR * std::sin(om * static_cast<double>(k) + ph);
      vel[3 * v + 2] = 0.02 * kR * om / kDt * std::cos(om * static_cast<double>(k) + ph);
    }
  }
};

std::unique_ptr<World> build(const WallScene& sc, const Floor& floor, bool final_prepare) {
  WorldParams p;
  p.threads = 1;
  p.thread_independent = true;
  p.order_free_sums = sc.order_free;
  p.dt_fixed = kDt;
  p.gravity = true;
  p.g_level = 100.0;
  p.ball_facet.model = sc.facet_model;
  if (sc.facet_model == ContactModel::kLinearPBond) {
    p.ball_facet.pbond.zero_linear = true;
    p.ball_facet.pbond.ten = p.ball_facet.pbond.coh = 2e4;  // weak: some break in the run
  }
  auto w = std::make_unique<World>(p);
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  test::add_jittered_lattice(*w, kSide, kS, kR, 0.03 * kR, 0.04, rng);
  const double h = 0.5 * kL;
  w->add_plane({{0, h, h}, {1, 0, 0}});
  w->add_plane({{kL, h, h}, {-1, 0, 0}});
  w->add_plane({{h, 0, h}, {0, 1, 0}});
  w->add_plane({{h, kL, h}, {0, -1, 0}});
  w->add_facet_wall(floor.base, floor.tri);
  if (sc.servo) {
    PlatenServoParams sp;
    sp.wall = 0;
    sp.stress = 2e6;  // [Pa], near the block's lateral stress: the wall follows the reaction
    sp.area = kL * kL;
    sp.vmax = 5.0;  // [m/s], not reached
    w->add_effect(std::make_unique<PlatenServo>(sp));
  }
  FootingParams fp;
  fp.diameter = 0.5 * kL;
  fp.height = 0.3 * kL;
  fp.bottom_centre = {h, h, kL};
  fp.velocity = {0, 0, -2.0};
  w->set_footing(fp);
  w->prepare();
  if (sc.facet_model == ContactModel::kLinearPBond) w->bond_ball_facet(0.05 * kR);
  for (std::size_t i = 0; i < w->num_balls(); ++i) {
    Vec3& v = w->balls().v[i];
    v = 0.05 * Vec3{u(rng), u(rng), u(rng)};
    v.x += 200.0 * (w->balls().x[i].z - h);  // a shear: balls cross the cuts along x
    w->balls().w[i] = 300.0 * Vec3{u(rng), u(rng), u(rng)};
  }
  if (final_prepare) w->prepare();
  return w;
}

// What is compared: the balls (DistDem::Balls on the ranks), the walls' sums and the histories.
struct Sums {
  std::vector<Vec3> plane_reaction, vforce, history;
  std::vector<double> k_sum, vstiff;
};

Sums sums(const World& w, std::vector<Vec3> history) {
  Sums s;
  for (int i = 0; i < w.num_planes(); ++i) {
    s.plane_reaction.push_back(w.plane(i).reaction);
    s.k_sum.push_back(w.plane(i).k_sum);
  }
  s.vforce = w.facet_wall(0).vforce;
  s.vforce.push_back(w.facet_wall(0).total_force);
  s.vforce.push_back(w.footing_reaction());
  s.vstiff = w.facet_wall(0).vstiff;
  s.history = std::move(history);
  return s;
}

// One step of a World or of the ranks, the floor's vertices set first (as the node does).
template <class StepFn>
void run(World& w, const Floor& floor, int steps, std::vector<Vec3>& history, StepFn step, int from = 1) {
  std::vector<double> pos, vel;
  for (int k = from; k < from + steps; ++k) {
    floor.at(k, pos, vel);
    w.set_vertex_kinematics(0, pos, vel);
    step();
    history.push_back(w.footing_reaction());
    history.push_back(w.facet_wall_force(0));
    history.push_back(w.plane(0).reaction);
  }
}

// The block cut into g_size slabs across sc.axis, the cuts on planes of ball centres.
BrickGrid grid(const WallScene& sc) {
  BrickGrid g;
  g.lo = {-0.5 * kS, -0.5 * kS, -0.5 * kS};
  g.len = {kL, kL, kL};
  g.n[sc.axis] = g_size;
  return g;
}

void check(const WallScene& sc) {
  const Floor floor;
  std::unique_ptr<World> full = build(sc, floor, true);  // prepared: taken as it is (the node's case)
  DistDem d(MPI_COMM_WORLD, full->params(), grid(sc));
  if (sc.from_root) {
    if (g_rank != 0) full = std::make_unique<World>(full->params());  // no ball, no wall, no effect
    d.set_part_chunk(4096);  // each part and each assembled share in many messages
    d.load_from_root(*full);
  } else {
    d.load(*full);
  }
  d.set_balance({sc.balance_every, 2048, sc.weight, {}});
  d.set_neighbour_reach(sc.reach);
  std::vector<Vec3> hist;
  run(d.world(), floor, sc.steps / sc.per_call, hist, [&] { d.step(sc.per_call); });
  const DistDem::Balls got = d.gather();
  const Sums got_sums = sums(d.world(), hist);
  // the node's measurements, collective
  const double ke = d.kinetic_energy(), fc = d.mean_contact_force(), ratio = d.unbalanced_ratio(fc);
  // the checkpoint written from the parts (blocks of 37 rows) against the assembled World's: the
  // wall contacts (planes, facets with their candidates, the footing) and the walls too
  test::expect_same_state_file(d, [&] { return build(sc, floor, true); }, 37);
  // One World again from the ranks' parts (DistDem::unload), on every rank (from_root: on rank 0).
  d.unload(*full, sc.from_root);
  if (sc.from_root && g_rank != 0) {
    EXPECT_EQ(full->num_balls(), 0u) << "a rank other than 0 assembled the whole World";
    EXPECT_EQ(full->num_planes(), 0);
  }
  long long mine[2] = {static_cast<long long>(d.owned()), static_cast<long long>(d.migrated())};
  long long sum[2] = {0, 0};
  MPI_Reduce(mine, sum, 2, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (g_rank == 0) {
    std::unique_ptr<World> ref = build(sc, floor, true);
    std::vector<Vec3> rh;
    run(*ref, floor, sc.steps / sc.per_call, rh, [&] { ref->step(sc.per_call); });
    const Sums want = sums(*ref, rh);
    test::expect_same_measures(*ref, ke, fc, ratio);
    std::size_t bonded_floor = 0;
    for (const BondHist& b : ref->facet_contacts().bond) bonded_floor += bonded(b.state);
    std::printf("%s on %d ranks: %lld exchanges (%lld with the neighbour bricks only), %lld migrations, reference %lld "
                "rebuilds; footing %.4g N, floor %.4g N, %zu floor bonds intact\n",
                sc.name.c_str(), g_size, static_cast<long long>(d.exchanges()),
                static_cast<long long>(d.neighbour_exchanges()), sum[1],
                static_cast<long long>(ref->rebuild_count()), ref->footing_reaction().z, ref->facet_wall_force(0).z,
                bonded_floor);
    test::expect_same_balls(got, *ref, static_cast<std::size_t>(sum[0]));
    EXPECT_TRUE(test::same_bits(got_sums.plane_reaction, want.plane_reaction)) << "plane reactions differ";
    EXPECT_TRUE(test::same_bits(got_sums.k_sum, want.k_sum)) << "plane servo gains differ";
    EXPECT_TRUE(test::same_bits(got_sums.vforce, want.vforce)) << "vertex forces, floor or footing force differ";
    EXPECT_TRUE(test::same_bits(got_sums.vstiff, want.vstiff)) << "vertex stiffness differs";
    EXPECT_TRUE(test::same_bits(got_sums.history, want.history)) << "the per-step histories differ";
    if (sc.order_free) {  // the default sums of the same contacts: the last bits apart
      std::vector<WallSumRec> recs;
      std::vector<FacetSumShare> shares;
      ref->wall_sum_records(recs);
      ref->facet_sum_shares(shares);
      std::vector<double> of, plain;
      ref->pack_wall_sums(of);
      ref->set_wall_sums(recs);  // one World's records in its order: the default sums
      ref->set_facet_sums(shares);
      ref->pack_wall_sums(plain);
      ref->unpack_wall_sums(of);  // (the reference steps on below)
      double worst = 0.0, rel = 0.0;
      for (std::size_t k = 0; k < of.size(); ++k) {
        const double d = std::abs(of[k] - plain[k]);
        worst = std::max(worst, d);
        if (plain[k] != 0.0) rel = std::max(rel, d / std::abs(plain[k]));
        EXPECT_LE(d, 1e-12 * std::abs(plain[k])) << "wall sum " << k << ": " << of[k] << " against " << plain[k];
      }
      std::printf("  order-free walls' sums: %zu values, largest difference from the default sums %.3g, relative "
                  "%.3g\n", of.size(), worst, rel);
      EXPECT_GT(worst, 0.0) << "the option changed no wall sum";
    }
    // the run exercises what it claims: the footing and the floor carry load, the lists rebuild
    EXPECT_GT(ref->footing_reaction().z, 0.0) << "the balls push the footing up";
    EXPECT_LT(ref->facet_wall_force(0).z, 0.0) << "the balls press on the floor";
    EXPECT_GT(ref->rebuild_count(), 10);
    if (sc.servo) {  // the servo moved its wall, and on the ranks by the same steps
      const double v = ref->plane(0).p.velocity.x;
      std::printf("  servo: plane 0 at x = %.6g R, velocity %.4g m/s, reaction %.4g N\n", ref->plane(0).p.point.x / kR, v,
                  ref->plane(0).reaction.x);
      EXPECT_NE(ref->plane(0).p.point.x, 0.0);
      EXPECT_LT(std::abs(v), 5.0) << "the servo must follow the sums, not its speed limit";
      EXPECT_EQ(full->plane(0).p.point.x, ref->plane(0).p.point.x);
      EXPECT_EQ(full->plane(0).p.velocity.x, v);
    }
    if (g_size > 1) {
      EXPECT_GT(sum[1], 0) << "balls must cross brick faces";
      // Every record of these runs goes to a brick within the halo and the skin: point to point
      // with the neighbours only, unless the reach is 0 (every exchange then all-to-all). Cuts
      // balanced by measured time move by what the clock saw, and at 9 slabs across z cuts
      // balanced by contacts move by the floor's facet contacts (5 each) coming and going: a
      // rebalance may move one far enough that the next exchange falls back to all-to-all
      // (DistDem::exchange; the bits above hold either way), so there are at most as many
      // fallbacks as rebalances (seen: 94 of 95 exchanges with the neighbours only, by time at 2
      // ranks and by contacts at 9). Contact-balanced cuts at 2 and 3 ranks keep to the neighbours.
      if (sc.reach == 0.0)
        EXPECT_EQ(d.neighbour_exchanges(), 0);
      else if (sc.weight == DistDem::Weight::kTime || (sc.balance_every > 0 && g_size > 3))
        EXPECT_GE(d.neighbour_exchanges(), d.exchanges() - d.rebalances());
      else
        EXPECT_EQ(d.neighbour_exchanges(), d.exchanges());
    }
    // The unloaded World is the reference's state, field by field as a checkpoint holds it, but
    // for the energies the ranks sum in their order; with those set equal it steps on with the
    // reference's bits (neighbour lists, Verlet references and wall candidates included).
    {
      World::Counters k = full->counters();
      const World::Counters kr = ref->counters();
      std::printf("  unload: damping energy %.17g vs %.17g, slip %.17g vs %.17g, softening %.17g vs %.17g J\n",
                  k.e_damp, kr.e_damp, k.e_slip_dead, kr.e_slip_dead, k.e_soft_dead, kr.e_soft_dead);
      EXPECT_EQ(k.bond_failures, kr.bond_failures);
      if (g_size == 1) {
        EXPECT_EQ(std::memcmp(&k.e_damp, &kr.e_damp, sizeof(double)), 0) << "one rank: the damping energy's own bits";
      }
      // more ranks: the ranks' sums in rank order, round-off apart (ghosts count nothing)
      EXPECT_NEAR(k.e_damp, kr.e_damp, 1e-12 * std::abs(kr.e_damp));
      EXPECT_NEAR(k.e_slip_dead, kr.e_slip_dead, 1e-12 * std::abs(kr.e_slip_dead));
      EXPECT_NEAR(k.e_soft_dead, kr.e_soft_dead, 1e-12 * std::abs(kr.e_soft_dead));
      k.e_damp = kr.e_damp, k.e_slip_dead = kr.e_slip_dead, k.e_soft_dead = kr.e_soft_dead;
      full->set_counters(k);
      EXPECT_TRUE(state_bytes(*full, {}) == state_bytes(*ref, {})) << "the unloaded World is not the reference's state";
      std::vector<Vec3> h1, h2;
      run(*full, floor, 100, h1, [&] { full->step(); }, sc.steps + 1);
      run(*ref, floor, 100, h2, [&] { ref->step(); }, sc.steps + 1);
      EXPECT_TRUE(test::same_bits(h1, h2)) << "the unloaded World steps on with other bits";
      EXPECT_TRUE(state_bytes(*full, {}) == state_bytes(*ref, {})) << "the unloaded World steps on with other bits";
    }
    if (sc.balance_every > 0) {  // the cuts moved
      EXPECT_EQ(d.rebalances(), d.exchanges() / sc.balance_every);
      const auto& cuts = d.grid().cuts[sc.axis];
      std::printf("  %lld rebalances; cuts along axis %d [L]:", static_cast<long long>(d.rebalances()), sc.axis);
      for (double c : cuts) std::printf(" %.4f", c / kL);
      std::printf("\n");
      EXPECT_EQ(cuts.size(), static_cast<std::size_t>(g_size - 1));
      if (sc.weight == DistDem::Weight::kContacts) {  // measured times may land on an even cut
        for (std::size_t j = 0; j < cuts.size(); ++j) {
          EXPECT_NE(cuts[j], (j + 1) * (kL / g_size)) << "cut " << j << " did not move";
        }
      }
    }
  }
  test::share_verdict();
}

}  // namespace

TEST(DistWalls, LinearFloorCutAlongXSameBits) { check({"walls, linear floor, cut along x"}); }
// An effect the ranks cannot run yet (the periodic servo reads the whole cell's stress every
// step) is refused by name, on every rank; from_root: the whole World on rank 0 only, every rank
// throws rank 0's words.
static void check_refusal(bool from_root) {
  const Floor floor;
  std::unique_ptr<World> full = build({"refusal"}, floor, true);
  full->add_effect(std::make_unique<PeriodicServo>(ServoParams{}, kR));
  if (from_root && g_rank != 0) full = std::make_unique<World>(full->params());
  DistDem d(MPI_COMM_WORLD, full->params(), grid({"refusal"}));
  try {
    if (from_root)
      d.load_from_root(*full);
    else
      d.load(*full);
    ADD_FAILURE() << "the ranks took a world with a periodic servo";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'periodic_servo'"), std::string::npos) << e.what();
  }
}
TEST(DistWalls, PeriodicServoIsRefusedByName) { check_refusal(false); }
TEST(DistWalls, PeriodicServoIsRefusedByNameFromRoot) { check_refusal(true); }

TEST(DistWalls, PlatenServoCutAlongYSameBits) {
  WallScene sc{"walls, a platen servo on a side, cut along y, 4 steps per call"};
  sc.servo = true;
  sc.axis = 1;  // the servo's wall (x = 0) meets every brick
  sc.per_call = 4;  // the servo reads the walls' sums inside step(n)
  check(sc);
}
// The walls' sums and the measurements as order-free sums (order_free_sum.hpp): every rank folds
// its own shares, two allreduces; with the platen servo reading them every step.
TEST(DistWalls, OrderFreeSumsWithAServoCutAlongYSameBits) {
  WallScene sc{"walls, order-free sums, a platen servo, cut along y, 4 steps per call"};
  sc.servo = true;
  sc.axis = 1;
  sc.per_call = 4;
  sc.order_free = true;
  check(sc);
}
TEST(DistWalls, BondedFloorCutAlongZSameBits) {
  check({"walls, bonded floor, cut along z", ContactModel::kLinearPBond, 2});
}
// The whole World on rank 0 only (DistDem::load_from_root, unload to rank 0): each rank gets its
// part as a World's state file in memory, in messages of 4 KiB; the walls, the footing, the
// bonded floor's histories, the platen servo and the counters come with it.
TEST(DistWalls, FromRootBondedFloorAndServoSameBits) {
  WallScene sc{"walls, from rank 0, bonded floor, a platen servo, cut along y", ContactModel::kLinearPBond, 1};
  sc.servo = true;
  sc.per_call = 4;
  sc.from_root = true;
  check(sc);
}
// Dynamic balancing: the cuts move every 3rd exchange (balls change rank), the bits do not.
TEST(DistWalls, BalancedCutsAlongZSameBits) {
  WallScene sc{"walls, linear floor, cut along z, balanced", ContactModel::kLinear, 2};
  sc.balance_every = 3;
  check(sc);
}
// The neighbour exchange's fallback: with a reach of 0 no brick is a peer, so every exchange
// finds records for a non-peer and all ranks take the all-to-all (the same bits).
TEST(DistWalls, AllToAllFallbackSameBits) {
  WallScene sc{"walls, linear floor, cut along x, all-to-all", ContactModel::kLinear, 0};
  sc.reach = 0.0;
  check(sc);
}
// Balancing by measured time (the cuts differ from run to run; the bits do not).
TEST(DistWalls, TimeBalancedCutsAlongXSameBits) {
  WallScene sc{"walls, linear floor, cut along x, balanced by time", ContactModel::kLinear, 0};
  sc.balance_every = 3;
  sc.weight = DistDem::Weight::kTime;
  check(sc);
}
// The balancing's weights (contact_weights, ContactCost) of every ball of the floor scene after 200
// steps, with pairs that touch and pairs apart, plane, footing and facet contacts, against its
// counts of each kind: with the model's costs, with costs of six different orders of magnitude
// and with session 28's weights (1 per ball, pair end and plane contact, 5 per facet contact).
TEST(DistWalls, ContactWeightsAreTheModelledCostOfEachKindOfContact) {
  WallScene sc{"walls, linear floor, weights"};
  const Floor floor;
  std::unique_ptr<World> w = build(sc, floor, true);
  w->step(200);
  const test::CostCounts n = test::cost_counts(*w);
  ASSERT_GT(n.touching, 0u);
  ASSERT_GT(n.apart, 0u);
  ASSERT_GT(w->plane_contacts().size(), 0u);
  ASSERT_GT(w->footing_contacts().size(), 0u);
  ASSERT_GT(n.facets, 0u) << "the scene must touch its floor";
  EXPECT_EQ(test::weights(*w), n.row);
  EXPECT_EQ(test::weights(*w, test::kDistinctCosts), test::cost_counts(*w, test::kDistinctCosts).row);
  const ContactCost s28{1, 1, 1, 1, 5, 1};
  std::int64_t total = 0;
  for (std::int64_t v : test::weights(*w, s28)) total += v;
  EXPECT_EQ(total, static_cast<std::int64_t>(w->num_balls() + 2 * w->pair_contacts().size() + n.planes + 5 * n.facets));
}

// The ranks' weights (DistDem::weight: each rank's own balls, with Balance::cost) add up to one
// World's after 200 steps on the ranks (newton off: a pair across two bricks is listed on both,
// each rank weighing its own ball's end), with costs of six different orders of magnitude.
TEST(DistWalls, RankWeightsAddUpToOneWorldsWithTheBalanceCosts) {
  WallScene sc{"walls, linear floor, rank weights", ContactModel::kLinear, 2};
  const Floor floor;
  std::unique_ptr<World> full = build(sc, floor, true);
  DistDem d(MPI_COMM_WORLD, full->params(), grid(sc));
  d.load(*full);
  d.set_balance({0, 2048, DistDem::Weight::kContacts, test::kDistinctCosts});
  std::vector<Vec3> hist, rh;
  run(d.world(), floor, 200, hist, [&] { d.step(1); });
  long long mine = d.weight(), sum = 0;
  MPI_Allreduce(&mine, &sum, 1, MPI_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
  std::unique_ptr<World> ref = build(sc, floor, true);
  run(*ref, floor, 200, rh, [&] { ref->step(1); });
  const test::CostCounts n = test::cost_counts(*ref, test::kDistinctCosts);
  ASSERT_GT(n.touching, 0u);
  ASSERT_GT(n.apart, 0u);
  EXPECT_EQ(sum, n.total);
}

// The stage's measurements the DEM node takes from the ranks while they stay live between stages
// (docs/scaling.md, "the ranks live across stages"): the stress profile with one World's bits,
// the footing placed at first contact as one World places it, and the stage's energies, whose
// contacts' and dissipated terms and gravity's work the ranks add in rank order (one World's
// bits on one rank, round-off apart on more). The block of walls above, stepped 400 steps under
// gravity with its floor moving; bonded floor contacts, so that the profile has wall terms of
// two kinds; a shear, so that balls migrate between the begin and the end.
TEST(DistWalls, StageMeasurementsOnTheRanks) {
  WallScene sc{"walls, stage measurements", ContactModel::kLinearPBond, 2, 400};
  const Floor floor;
  std::unique_ptr<World> full = build(sc, floor, true);
  DistDem d(MPI_COMM_WORLD, full->params(), grid(sc));
  d.load(*full);
  StageEnergy ranked, one;
  ranked.begin_with(d.energy());
  const std::vector<DistDem::IdPos> x0 = d.owned_positions();
  std::vector<Vec3> hist, rh;
  run(d.world(), floor, sc.steps, hist, [&] { d.step(1); });
  ProfileBox box;
  box.x_lo = box.y_lo = -0.5 * kS;
  box.x_hi = box.y_hi = kL - 0.5 * kS;
  box.z_top = kL - 0.5 * kS;
  box.height = kL;
  const std::vector<ProfileSlab> prof = stress_profile(d, box, 6);
  const Energy e = d.energy();
  const double gw = d.gravity_work(x0);
  long long migrated = static_cast<long long>(d.migrated()), all_migrated = 0;
  MPI_Reduce(&migrated, &all_migrated, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  FootingParams fp;
  fp.diameter = 0.4 * kL;
  fp.height = 0.3 * kL;
  fp.bottom_centre = {0.3 * kL, 0.6 * kL, 5.0 * kL};
  const double z = place_footing_at_first_contact(d, fp);
  // the DEM-only box's planes from every rank's balls (the block already has four side planes)
  const int planes_before = d.world().num_planes();
  const auto [box_lo, box_hi] = add_box_walls(d);
  const Vec3 bottom = d.world().plane(planes_before).p.point;
  int nplanes = d.world().num_planes(), fewest = 0;
  MPI_Allreduce(&nplanes, &fewest, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  double zs[2] = {z, d.world().footing().p.bottom_centre.z}, lo[2], hi[2];
  MPI_Allreduce(zs, lo, 2, MPI_DOUBLE, MPI_MIN, MPI_COMM_WORLD);
  MPI_Allreduce(zs, hi, 2, MPI_DOUBLE, MPI_MAX, MPI_COMM_WORLD);
  // the kick (dem.kick) on the parts: one World's top ball, the same steps after it
  const Vec3 kick_v{0.01, -0.02, 0.5};
  const Kicked kicked = kick_highest_ball(d, kick_v);
  d.step(30);
  const DistDem::Balls after_kick = d.gather();
  long long owned = static_cast<long long>(d.owned()), all_owned = 0;
  MPI_Reduce(&owned, &all_owned, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (g_rank == 0) {
    std::unique_ptr<World> ref = build(sc, floor, true);
    one.begin(*ref);
    run(*ref, floor, sc.steps, rh, [&] { ref->step(1); });
    ASSERT_TRUE(test::same_bits(hist, rh));
    const std::vector<ProfileSlab> want = stress_profile(*ref, box, 6);
    ASSERT_EQ(prof.size(), want.size());
    std::size_t loaded = 0;
    for (std::size_t k = 0; k < want.size(); ++k) {
      EXPECT_EQ(prof[k].balls, want[k].balls) << "slab " << k;
      for (auto m : {&ProfileSlab::szz, &ProfileSlab::sxx, &ProfileSlab::syy, &ProfileSlab::depth, &ProfileSlab::depth_top})
        EXPECT_EQ(std::memcmp(&(prof[k].*m), &(want[k].*m), sizeof(double)), 0)
            << "slab " << k << ": " << prof[k].*m << " against one World's " << want[k].*m;
      loaded += want[k].szz != 0.0 && want[k].sxx != 0.0;
    }
    EXPECT_EQ(loaded, want.size()) << "every slab must carry stress";
    // the energies: the kinetic energy's bits; the rest in rank order
    const Energy we = ref->energy();
    const double wgw = gravity_work(*ref, one.x_begin);
    double scale = 0.0;  // Σ |m g·dx|: the size of gravity's terms
    for (std::size_t i = 0; i < ref->num_balls(); ++i)
      scale += std::abs(ref->balls().m[i] * dot(ref->gravity(), ref->balls().x[i] - one.x_begin[i]));
    std::printf("%s on %d ranks, %lld migrations: strain %.17g / %.17g J, gravity's work %.17g / %.17g J, profile "
                "szz of the bottom slab %.6g Pa, footing at %.9g L\n",
                sc.name.c_str(), g_size, all_migrated, e.strain, we.strain, gw, wgw, want.back().szz, z / kL);
    EXPECT_EQ(std::memcmp(&e.kinetic, &we.kinetic, sizeof(double)), 0);
    for (auto m : {&Energy::strain, &Energy::damping, &Energy::friction, &Energy::softening}) {
      EXPECT_NEAR(e.*m, we.*m, 1e-12 * std::abs(we.*m));
      if (g_size == 1) {
        EXPECT_EQ(std::memcmp(&(e.*m), &(we.*m), sizeof(double)), 0);
      }
    }
    EXPECT_GT(we.strain, 0.0);
    EXPECT_GT(we.damping, 0.0);
    EXPECT_NEAR(gw, wgw, 1e-12 * scale);
    if (g_size == 1) {
      EXPECT_EQ(std::memcmp(&gw, &wgw, sizeof(double)), 0);
    }
    EXPECT_GT(scale, 0.0);
    const StageEnergy::Balance b = ranked.balance_with(e, gw), bw = one.balance(*ref);
    EXPECT_NEAR(b.error, bw.error, 1e-9);
    if (g_size > 1) {
      EXPECT_GT(all_migrated, 0) << "balls must change ranks between the begin and the end";
    }
    // the footing: one World's height, on every rank
    const double zw = place_footing_at_first_contact(*ref, fp);
    EXPECT_EQ(std::memcmp(&z, &zw, sizeof z), 0) << z << " against " << zw;
    EXPECT_EQ(lo[0], hi[0]);
    EXPECT_EQ(lo[1], zw);
    EXPECT_EQ(hi[1], zw);
    EXPECT_LT(zw, 2.0 * kL);  // (the sheared block has grown to about 1.17 L)
    const auto [wlo, whi] = add_box_walls(*ref);
    EXPECT_TRUE(test::same_bits(std::vector<Vec3>{box_lo, box_hi}, std::vector<Vec3>{wlo, whi})) << "the box's bounds";
    EXPECT_TRUE(test::same_bits(std::vector<Vec3>{bottom}, std::vector<Vec3>{ref->plane(planes_before).p.point}));
    EXPECT_EQ(fewest, ref->num_planes()) << "every rank's part gets the five planes";
    EXPECT_LT(wlo.z, 0.0);
    EXPECT_GT(zw, 0.5 * kL);
    const std::size_t top = kick_highest_ball(*ref, kick_v);
    EXPECT_EQ(kicked.id, ref->balls().id[top]);
    EXPECT_TRUE(test::same_bits(std::vector<Vec3>{kicked.x}, std::vector<Vec3>{ref->balls().x[top]}));
    ref->step(30);
    test::expect_same_balls(after_kick, *ref, static_cast<std::size_t>(all_owned));
    std::printf("  kicked ball %llu at z = %.6f L\n", static_cast<unsigned long long>(kicked.id), kicked.x.z / kL);
  }
  test::share_verdict();
}
