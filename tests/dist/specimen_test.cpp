// Specimen preparation on MPI ranks (issue 17 item 2; docs/scaling.md "the REV's expansion and
// servo on the ranks"), against one World holding every ball:
//  * the REV's periodic servo (servo_until, §4.5): every rank generates the same REV (one World's
//    generate_rev, deterministic); rank 0 also servos one World
//    (the reference); the ranks servo the REV cut into bricks. The report (steps, verdict, ratio,
//    stress, porosity, overshoot, its sentence), the cell and every ball's state must be the same
//    bits. The loose REV's servo compacts it by several per cent of the cell's edge, so the bricks
//    follow the cell (BrickGrid::follow_cell) and balls cross the cuts and the cell's faces;
//  * the REV's radius expansion (generate_rev on a DistDem): the report and the REV assembled on
//    rank 0, byte for byte as a checkpoint holds it;
//  * BrickGrid::follow_cell itself.
#include <gtest/gtest.h>
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/dist.hpp"
#include "demfdm/dem/specimen.hpp"
#include "tests/dist/dist_util.hpp"

using namespace demfdm::dem;
using test::g_rank;
using test::g_size;

namespace {

struct ServoScene {
  std::string name;
  ContactModel model = ContactModel::kLinear;
  bool rcb = false;        // RCB instead of slabs across z
  bool from_root = false;  // load_from_root: the other ranks never hold the REV
  bool order_free = false; // WorldParams::order_free_sums (the servo's sums order-free too)
  double tol = 0.02, ratio = 1e-3;  // the servo's criterion
  double budget = 700.0;            // [t_c]
  double target = 4e5;              // [Pa] the lateral target
  double vertical = 2.0;            // the vertical target over the lateral one
  double porosity = 0.62;           // the REV's (loose: the servo then compacts it)
  bool idle_rank = false;           // at 3 slabs a rank's rows touch nothing as loaded
};

constexpr std::size_t kBalls = 700;

RevParams rev_params(const ServoScene& sc) {
  RevParams r;
  r.psd.scale = 1.5;
  r.seed = 7;
  r.n_particles = kBalls;
  r.porosity_final = sc.porosity;
  r.increments = 2;
  r.ratio_tol = 2e-2;
  r.increment_budget = 400.0;
  return r;
}

// The REV's periodic cell and parameters (no ball yet).
WorldParams rev_world(const ServoScene& sc) {
  const RevParams r = rev_params(sc);
  const double V = psd_expected_count(r.psd, 1.0, r.porosity_final);  // balls per m^3 at that porosity
  const double L = std::cbrt(static_cast<double>(kBalls) / V);
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.origin = {0.0, 0.0, 0.0};
  p.periodic.length = {L, L, L};
  p.ball_ball.model = sc.model;
  p.ball_ball.linear.fric = 0.3;
  p.dt_fixed = 0.0;  // specimen preparation steps on the automatic step
  p.thread_independent = true;
  p.order_free_sums = sc.order_free;
  return p;
}

// The REV, as every rank makes it (one World's generate_rev: the same bits on every rank).
std::unique_ptr<World> rev(const ServoScene& sc) {
  auto w = std::make_unique<World>(rev_world(sc));
  const StageReport g = generate_rev(*w, rev_params(sc));
  EXPECT_EQ(g.count, kBalls);
  return w;
}

ServoParams servo_params(const ServoScene& sc) {
  ServoParams sp;
  sp.target = {sc.target, sc.target, sc.vertical * sc.target};
  sp.max_face_step = 0.02;  // fast: the test wants strain, not a quasi-static compaction
  sp.quench_every = 40.0;
  return sp;
}
constexpr double kHold = 16.0;

BrickGrid grid(const World& w, const ServoScene& sc);

// generate_rev's radius expansion on the ranks (dist.hpp): rank 0 draws the balls, the ranks
// expand them (the halo grows with the radii, the ghosts are exchanged again at every increment)
// and the REV is assembled on rank 0: its report and its state (state_bytes: every ball, pair,
// history and counter) are one World's, byte for byte. The other ranks hold only their parts.
void check_generate(const ServoScene& sc) {
  World full(rev_world(sc));
  const Vec3 L0 = full.cell_length();
  DistDem d(MPI_COMM_WORLD, full.params(), grid(full, sc));
  const StageReport got = generate_rev(d, full, rev_params(sc));
  long long mine[2] = {static_cast<long long>(d.exchanges()), static_cast<long long>(full.num_balls())};
  long long most[2] = {0, 0};
  MPI_Reduce(mine, most, 2, MPI_LONG_LONG, MPI_MAX, 0, MPI_COMM_WORLD);
  long long others = g_rank == 0 ? 0 : mine[1], other_balls = 0;
  MPI_Reduce(&others, &other_balls, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (g_rank == 0) {
    World ref(rev_world(sc));
    const StageReport want = generate_rev(ref, rev_params(sc));
    std::printf("%s on %d ranks: %s; %zu steps, %lld exchanges\n", sc.name.c_str(), g_size, got.what.c_str(),
                static_cast<std::size_t>(got.steps), most[0]);
    EXPECT_EQ(got.what, want.what);
    EXPECT_EQ(got.steps, want.steps);
    EXPECT_EQ(got.count, want.count);
    EXPECT_EQ(got.converged, want.converged);
    EXPECT_EQ(std::memcmp(&got.ratio, &want.ratio, sizeof(double)), 0) << got.ratio << " vs " << want.ratio;
    EXPECT_EQ(std::memcmp(got.stress.data(), want.stress.data(), sizeof(Mat3)), 0) << "the report's stress";
    EXPECT_EQ(std::memcmp(&got.porosity, &want.porosity, sizeof(double)), 0) << got.porosity << " vs " << want.porosity;
    // the dissipated energies are the ranks' sums in rank order (round-off apart, as on every
    // DistDem unload: walls_test.cpp); with those set equal the state is one World's
    World::Counters k = full.counters();
    const World::Counters kr = ref.counters();
    EXPECT_NEAR(k.e_damp, kr.e_damp, 1e-12 * std::abs(kr.e_damp));
    EXPECT_NEAR(k.e_slip_dead, kr.e_slip_dead, 1e-12 * std::abs(kr.e_slip_dead));
    EXPECT_GT(kr.e_damp, 0.0);
    k.e_damp = kr.e_damp, k.e_slip_dead = kr.e_slip_dead, k.e_soft_dead = kr.e_soft_dead;
    full.set_counters(k);
    EXPECT_TRUE(state_bytes(full, CheckpointMeta{}) == state_bytes(ref, CheckpointMeta{}))
        << "the REV assembled on rank 0 is not one World's";
    EXPECT_EQ(full.cell_length().x, L0.x);
    EXPECT_GT(want.steps, 200);
    if (g_size > 1) {
      EXPECT_GT(most[0], 2) << "every increment exchanges the ghosts again";
    }
    EXPECT_EQ(other_balls, 0) << "the other ranks' Worlds hold no ball";
  }
  test::share_verdict();
}

BrickGrid grid(const World& w, const ServoScene& sc) {
  BrickGrid g;
  g.lo = w.cell_origin();
  g.len = w.cell_length();
  for (bool& p : g.periodic) p = true;
  if (sc.rcb)
    g.set_rcb(g_size);
  else
    g.n[2] = g_size;
  return g;
}

void check(const ServoScene& sc) {
  std::unique_ptr<World> full = rev(sc);
  const Vec3 L0 = full->cell_length();
  DistDem d(MPI_COMM_WORLD, full->params(), grid(*full, sc));
  if (sc.from_root) {
    if (g_rank != 0) full = std::make_unique<World>(full->params());  // no ball
    d.load_from_root(*full);
  } else {
    d.load(*full);
  }
  // the touching or bonded pairs whose ball A this rank owns, as loaded (the dense REV's premise)
  long long touching = 0, fewest = 0;
  {
    const auto& pc = d.world().pair_contacts();
    const auto& gh = d.world().ghost_rows();
    for (std::size_t c = 0; c < pc.size(); ++c)
      if ((gh.empty() || !gh[pc.a[c]]) && servo_term(d.world(), c).stiff) ++touching;
  }
  MPI_Allreduce(&touching, &fewest, 1, MPI_LONG_LONG, MPI_MIN, MPI_COMM_WORLD);
  double over = 0.0;
  const StageReport got = servo_until(d, servo_params(sc), sc.tol, sc.ratio, kHold, sc.budget, &over);
  const DistDem::Balls balls = d.gather();
  const Vec3 L = d.world().cell_length(), edot = d.world().strain_rate();
  long long mine[2] = {static_cast<long long>(d.owned()), static_cast<long long>(d.migrated())}, sum[2] = {0, 0};
  MPI_Reduce(mine, sum, 2, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  const bool servo_left = !d.world().effect_names().empty();
  EXPECT_FALSE(servo_left) << "the servo must be taken off at the end";
  if (g_rank == 0) {
    std::unique_ptr<World> ref = rev(sc);
    double over_ref = 0.0;
    const StageReport want = servo_until(*ref, servo_params(sc), sc.tol, sc.ratio, kHold, sc.budget, &over_ref);
    std::printf("%s on %d ranks: %s; stress %.4g %.4g %.4g Pa, porosity %.4f; cell %.4f %.4f %.4f of its start, %lld "
                "exchanges, %lld migrations\n",
                sc.name.c_str(), g_size, got.what.c_str(), -got.stress[0], -got.stress[4], -got.stress[8], got.porosity,
                L.x / L0.x, L.y / L0.y, L.z / L0.z,
                static_cast<long long>(d.exchanges()), sum[1]);
    EXPECT_EQ(got.what, want.what);
    EXPECT_EQ(got.steps, want.steps);
    EXPECT_EQ(got.converged, want.converged);
    EXPECT_EQ(std::memcmp(&got.ratio, &want.ratio, sizeof(double)), 0) << got.ratio << " vs " << want.ratio;
    EXPECT_EQ(std::memcmp(got.stress.data(), want.stress.data(), sizeof(Mat3)), 0) << "the report's stress";
    EXPECT_EQ(std::memcmp(&got.porosity, &want.porosity, sizeof(double)), 0) << got.porosity << " vs " << want.porosity;
    EXPECT_EQ(std::memcmp(&over, &over_ref, sizeof(double)), 0) << "overshoot " << over << " vs " << over_ref;
    const Vec3 L_ref = ref->cell_length();
    EXPECT_EQ(std::memcmp(&L, &L_ref, sizeof(Vec3)), 0) << "the cell differs";
    EXPECT_EQ(edot.x, 0.0);
    EXPECT_EQ(edot.z, 0.0);
    test::expect_same_balls(balls, *ref, static_cast<std::size_t>(sum[0]));
    // the scene must strain the cell (the bricks follow it) and run the servo for a while
    if (sc.idle_rank && g_size == 3) {
      EXPECT_EQ(fewest, 0) << "a rank whose rows touch nothing (the no-contact step's case)";
    }
    if (sc.porosity > 0.5) {
      EXPECT_LT(L.z / L0.z, 0.95) << "the servo must compact the REV";
      if (g_size > 1) {
        EXPECT_GT(sum[1], 0) << "balls must cross the cuts";
      }
    }
    EXPECT_GT(got.steps, sc.porosity > 0.5 ? 100 : 20);
    EXPECT_EQ(got.converged, sc.ratio > 0.1) << "the scene's criterion";
    if (sc.order_free) {  // the option takes effect: the servo's sums and the stress are order-free
      ServoScene plain = sc;
      plain.order_free = false;
      std::unique_ptr<World> p = rev(plain);
      const StageReport pr = servo_until(*p, servo_params(plain), sc.tol, sc.ratio, kHold, sc.budget, nullptr);
      EXPECT_NE(std::memcmp(got.stress.data(), pr.stress.data(), sizeof(Mat3)), 0)
          << "the order-free servo gave the plain sums' bits";
    }
  }
  test::share_verdict();
}

// n more steps on the ranks and on one World (`ref`, rank 0's; null elsewhere): every ball the
// same bits (collective).
void step_both(DistDem& d, World* ref, int n) {
  d.step(n);
  const DistDem::Balls balls = d.gather();
  long long owned = static_cast<long long>(d.owned()), all = 0;
  MPI_Reduce(&owned, &all, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (ref) {
    ref->step(n);
    test::expect_same_balls(balls, *ref, static_cast<std::size_t>(all));
  }
}

// replicate on the ranks (DistDem::load_replicated): rank 0's REV (bonded to Z = 5 for the
// bonded law) copied 2 x 2 x 3 by every rank into its own part only, against one World's
// replicate: the report, the block assembled on rank 0 byte for byte as a checkpoint holds it
// (with its dissipated energies set equal: the ranks' sums in rank order), then 40 steps of both
// (with gravity pulling the block onto nothing: balls move and cross the cuts) and the block
// again. With keep_periodic the block is a periodic cell and the grid periodic too. Every rank
// other than 0 holds its part, less than the block.
void check_replicate(const ServoScene& sc, bool keep_periodic) {
  std::unique_ptr<World> r = rev(sc);
  if (sc.model == ContactModel::kSoftBond) install_bonds_to_coordination(*r, 5.0, 1e-9);
  const std::string rev_bytes = state_bytes(*r, CheckpointMeta{});
  ReplicateParams p;
  p.nx = 2, p.ny = 2, p.nz = 3;
  p.keep_periodic = keep_periodic;
  BrickGrid g;
  g.lo = r->cell_origin();
  g.len = {2 * r->cell_length().x, 2 * r->cell_length().y, 3 * r->cell_length().z};
  for (bool& per : g.periodic) per = keep_periodic;
  if (sc.rcb)
    g.set_rcb(g_size);
  else
    g.n[2] = g_size;
  World full(r->params());  // rank 0: the REV; the others: no ball
  if (g_rank == 0) load_state_bytes(full, rev_bytes, 0, "the REV");
  DistDem d(MPI_COMM_WORLD, r->params(), g);
  const StageReport got = replicate(d, full, p);
  long long part = static_cast<long long>(d.world().num_balls()), biggest = 0;
  MPI_Reduce(&part, &biggest, 1, MPI_LONG_LONG, MPI_MAX, 0, MPI_COMM_WORLD);
  World block(r->params());
  d.unload(block, true);
  auto same_state = [&](World& a, const World& b, const char* when) {
    World::Counters k = a.counters();
    const World::Counters kr = b.counters();
    EXPECT_NEAR(k.e_damp, kr.e_damp, 1e-12 * std::abs(kr.e_damp)) << when;
    EXPECT_NEAR(k.e_slip_dead, kr.e_slip_dead, 1e-12 * std::abs(kr.e_slip_dead)) << when;
    EXPECT_NEAR(k.e_soft_dead, kr.e_soft_dead, 1e-12 * std::abs(kr.e_soft_dead)) << when;
    k.e_damp = kr.e_damp, k.e_slip_dead = kr.e_slip_dead, k.e_soft_dead = kr.e_soft_dead;
    a.set_counters(k);
    EXPECT_TRUE(state_bytes(a, CheckpointMeta{}) == state_bytes(b, CheckpointMeta{}))
        << "the block assembled on rank 0 is not one World's " << when;
  };
  std::unique_ptr<World> ref;
  if (g_rank == 0) {
    ref = std::make_unique<World>(r->params());
    load_state_bytes(*ref, rev_bytes, 0, "the REV");
    const StageReport want = replicate(*ref, p);
    std::printf("%s, replicate%s on %d ranks: %s; parts of at most %lld balls\n", sc.name.c_str(),
                keep_periodic ? " (periodic)" : "", g_size, got.what.c_str(), biggest);
    EXPECT_EQ(got.what, want.what);
    EXPECT_EQ(got.count, want.count);
    EXPECT_EQ(got.count, 12 * kBalls);
    EXPECT_EQ(std::memcmp(&got.ratio, &want.ratio, sizeof(double)), 0) << got.ratio << " vs " << want.ratio;
    EXPECT_EQ(std::memcmp(&got.porosity, &want.porosity, sizeof(double)), 0);
    EXPECT_EQ(std::memcmp(got.stress.data(), want.stress.data(), sizeof(Mat3)), 0);
    same_state(block, *ref, "after the replication");
    if (g_size > 1) {
      EXPECT_LT(biggest, static_cast<long long>(got.count)) << "a rank holds the whole block";
    }
  }
  // stepping on: gravity on the block (free), or a strained periodic cell
  if (keep_periodic) {
    d.world().set_strain_rate({-50.0, 0.0, 30.0});
    if (ref) ref->set_strain_rate({-50.0, 0.0, 30.0});
  } else {
    d.world().set_gravity(true, 1000.0);  // (every rank's World: its own rows)
    if (ref) ref->set_gravity(true, 1000.0), block.set_gravity(true, 1000.0);  // (unload keeps block's effects)
  }
  step_both(d, ref.get(), 40);
  d.unload(block, true);
  if (ref) same_state(block, *ref, "after 40 steps");
  test::share_verdict();
}

// The bonding and the depth scaling on the ranks (dist.hpp): the soft-bond REV loaded on RCB
// from rank 0, its coordination, the gap for Z = 5 and the bonding (bond_specimen: the generate
// stage's half), then the depth scaling over the cell's height, against one World: the gap and
// the reports bit for bit, the coordination numbers, and the REV assembled on rank 0 byte for byte
// (after each step and after 30 steps on). With newton on (each pair across a cut listed once):
// the coordination, the gap and the bond count.
void check_bonding(bool newton) {
  ServoScene sc{"soft bond law, RCB", ContactModel::kSoftBond};
  sc.rcb = true;
  sc.porosity = 0.45;
  std::unique_ptr<World> r = rev(sc);
  const std::string rev_bytes = state_bytes(*r, CheckpointMeta{});
  World full(r->params());
  if (g_rank == 0) load_state_bytes(full, rev_bytes, 0, "the REV");
  DistDem d(MPI_COMM_WORLD, r->params(), grid(*r, sc));
  d.set_newton(newton);
  d.load_from_root(full);
  const Coordination z0 = d.coordination();
  const double gap = gap_for_coordination(d, 5.0, 1e-9);
  StageReport got;
  got.what = "generated";
  bond_specimen(d, got, 5.0, 1e-9);
  const Coordination z1 = d.coordination();
  DepthScaleParams dp;
  dp.z_top = r->cell_origin().z + r->cell_length().z;
  dp.height = r->cell_length().z;
  const StageReport scaled = depth_scale(d, dp);
  World block(r->params());
  d.unload(block, true);
  std::unique_ptr<World> ref;
  if (g_rank == 0) {
    ref = std::make_unique<World>(r->params());
    load_state_bytes(*ref, rev_bytes, 0, "the REV");
    const Coordination w0 = coordination(*ref);
    const double want_gap = gap_for_coordination(*ref, 5.0, 1e-9);
    StageReport want;
    want.what = "generated";
    bond_specimen(*ref, want, 5.0, 1e-9);
    const Coordination w1 = coordination(*ref);
    const StageReport want_scaled = depth_scale(*ref, dp);
    std::printf("bonding on %d ranks%s: gap %.6g m; %s; %s\n", g_size, newton ? " (newton on)" : "", gap,
                got.what.c_str(), scaled.what.c_str());
    EXPECT_EQ(std::memcmp(&gap, &want_gap, sizeof gap), 0) << gap << " vs " << want_gap;
    EXPECT_GT(gap, 1e-9) << "the gap must come from the separated pairs";
    for (const auto& [a, b] : {std::pair{z0, w0}, std::pair{z1, w1}}) {
      EXPECT_EQ(a.active, b.active);
      EXPECT_EQ(a.rattlers, b.rattlers);
      EXPECT_EQ(std::memcmp(&a.z, &b.z, sizeof(double)), 0) << a.z << " vs " << b.z;
      EXPECT_EQ(std::memcmp(&a.z_no_rattlers, &b.z_no_rattlers, sizeof(double)), 0);
    }
    EXPECT_GT(w1.z, 4.99);
    EXPECT_GT(w0.rattlers, 0u) << "a REV with rattlers: their counts must agree";
    EXPECT_EQ(got.count, want.count);
    EXPECT_EQ(scaled.count, want_scaled.count);
    if (!newton) {
      EXPECT_EQ(got.what, want.what);
      EXPECT_EQ(scaled.what, want_scaled.what);
      EXPECT_EQ(std::memcmp(&scaled.ratio, &want_scaled.ratio, sizeof(double)), 0);
      World::Counters k = block.counters();
      const World::Counters kr = ref->counters();
      k.e_damp = kr.e_damp, k.e_slip_dead = kr.e_slip_dead, k.e_soft_dead = kr.e_soft_dead;
      block.set_counters(k);
      EXPECT_TRUE(state_bytes(block, CheckpointMeta{}) == state_bytes(*ref, CheckpointMeta{}))
          << "the bonded, scaled REV assembled on rank 0 is not one World's";
    }
  }
  if (!newton) step_both(d, ref.get(), 30);
  test::share_verdict();
}

// A quad [p0, p0 + u + v] as two triangles whose normal u x v points into the block.
void add_quad(std::vector<double>& pos, std::vector<std::int32_t>& tri, const Vec3& p0, const Vec3& u, const Vec3& v) {
  const auto base = static_cast<std::int32_t>(pos.size() / 3);
  for (const Vec3& x : {p0, p0 + u, p0 + u + v, p0 + v}) pos.insert(pos.end(), {x.x, x.y, x.z});
  tri.insert(tri.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
}

// The coupled set-up on the ranks, as the DEM node runs it there (dem_node/main.cpp,
// interface_setup): the replicated soft-bond block under gravity in a pocket of facets (its floor
// and four sides, normals inwards), 200 steps settled on one World, cut by RCB from rank 0, the ball-facet contacts found
// (DistDem::prepare) and bonded, the depth scaling, the block's weight and the interface bonds'
// forces (traction or the band means), prepared again; against one World: the counts, the weight
// and every report bit for bit, the block assembled on rank 0 byte for byte, and 30 steps on.
void check_interface(InterfaceBondForce mode) {
  ServoScene sc{"soft bond law, RCB", ContactModel::kSoftBond};
  sc.rcb = true;
  sc.porosity = 0.45;
  std::unique_ptr<World> r = rev(sc);
  install_bonds_to_coordination(*r, 5.0, 1e-9);
  r->mutable_params().ball_facet.model = ContactModel::kLinearPBond;
  ReplicateParams rp;
  rp.nx = 2, rp.ny = 1, rp.nz = 2;
  World block(r->params());
  load_state_bytes(block, state_bytes(*r, CheckpointMeta{}), 0, "the REV");
  replicate(block, rp);
  block.set_gravity(true, 100.0);
  const Vec3 lo = block.cell_origin(), L = r->cell_length();
  const Vec3 hi{lo.x + 2 * L.x, lo.y + L.y, lo.z + 2 * L.z};
  const double W = hi.x - lo.x, D = hi.y - lo.y, H = hi.z - lo.z;
  std::vector<double> pos;
  std::vector<std::int32_t> tri;
  add_quad(pos, tri, lo, {W, 0, 0}, {0, D, 0});                   // floor, +z
  add_quad(pos, tri, lo, {0, D, 0}, {0, 0, H});                   // x = lo, +x
  add_quad(pos, tri, {hi.x, lo.y, lo.z}, {0, 0, H}, {0, D, 0});   // x = hi, -x
  add_quad(pos, tri, lo, {0, 0, H}, {W, 0, 0});                   // y = lo, +y
  add_quad(pos, tri, {lo.x, hi.y, lo.z}, {W, 0, 0}, {0, 0, H});   // y = hi, -y
  block.add_facet_wall(pos, tri);
  block.prepare();
  block.step(200);  // (contact forces under gravity: the band means add many, in one World's order)
  const std::string bytes = state_bytes(block, CheckpointMeta{});
  BrickGrid g;
  g.lo = lo;
  g.len = {W, D, H};
  g.set_rcb(g_size);
  DepthScaleParams dp;
  dp.z_top = hi.z;
  dp.height = H;
  InterfaceBondParams ib;
  ib.mode = mode;
  ib.band = 2.0 * r->balls().r[0];
  ib.z_top = hi.z;
  ib.k0 = 0.5;
  const double gap = 0.05 * r->balls().r[0];
  // the set-up, on one World or on the ranks
  struct Got {
    std::size_t bonds = 0;
    StageReport depth, forces;
    double weight = 0.0;
  };
  auto setup = [&](auto& sys, auto bond, auto weight) {
    Got out;
    sys.prepare();
    out.bonds = bond();
    out.depth = depth_scale(sys.target(), dp);
    out.weight = weight();
    ib.unit_weight = out.weight / (W * D * H);
    out.forces = assign_interface_bond_forces(sys.target(), ib);
    sys.prepare();
    return out;
  };
  World mine(r->params());  // rank 0: the block; the others: no ball
  if (g_rank == 0) load_state_bytes(mine, bytes, 0, "the block");
  DistDem d(MPI_COMM_WORLD, r->params(), g);
  d.load_from_root(mine);
  struct OnRanks {
    DistDem& d;
    void prepare() { d.prepare(); }
    DistDem& target() { return d; }
  } ranks{d};
  const Got got = setup(ranks, [&] { return bond_ball_facet(d, gap); }, [&] { return d.ball_weight(); });
  d.unload(mine, true);
  std::unique_ptr<World> ref;
  if (g_rank == 0) {
    ref = std::make_unique<World>(r->params());
    load_state_bytes(*ref, bytes, 0, "the block");
    struct One {
      World& w;
      void prepare() { w.prepare(); }
      World& target() { return w; }
    } one{*ref};
    const Got want = setup(one, [&] { return ref->bond_ball_facet(gap); }, [&] { return ball_weight(*ref); });
    std::printf("coupled set-up on %d ranks: %zu ball-facet bonds; %s; %s\n", g_size, got.bonds, got.depth.what.c_str(),
                got.forces.what.c_str());
    EXPECT_EQ(got.bonds, want.bonds);
    EXPECT_GT(want.bonds, 50u) << "the pocket must bond balls";
    EXPECT_EQ(got.depth.what, want.depth.what);
    EXPECT_EQ(std::memcmp(&got.weight, &want.weight, sizeof(double)), 0) << got.weight << " vs " << want.weight;
    EXPECT_EQ(got.forces.what, want.forces.what);
    EXPECT_EQ(got.forces.count, want.forces.count);
    EXPECT_EQ(std::memcmp(&got.forces.ratio, &want.forces.ratio, sizeof(double)), 0);
    World::Counters k = mine.counters();
    const World::Counters kr = ref->counters();
    k.e_damp = kr.e_damp, k.e_slip_dead = kr.e_slip_dead, k.e_soft_dead = kr.e_soft_dead;
    mine.set_counters(k);
    EXPECT_TRUE(state_bytes(mine, CheckpointMeta{}) == state_bytes(*ref, CheckpointMeta{}))
        << "the set-up block assembled on rank 0 is not one World's";
  }
  step_both(d, ref.get(), 30);
  test::share_verdict();
}

}  // namespace

TEST(DistSpecimen, CoupledSetUpTractionSameBits) { check_interface(InterfaceBondForce::kTraction); }
TEST(DistSpecimen, CoupledSetUpMeanContactSameBits) { check_interface(InterfaceBondForce::kMeanContact); }

TEST(DistSpecimen, BondingAndDepthScalingSameBits) { check_bonding(false); }
TEST(DistSpecimen, BondingNewtonSameCounts) { check_bonding(true); }

TEST(DistSpecimen, ReplicateLinearSlabsSameBits) {
  check_replicate({"linear, slabs across z"}, false);
}
TEST(DistSpecimen, ReplicateSoftBondRcbSameBits) {
  ServoScene sc{"soft bond law, RCB", ContactModel::kSoftBond};
  sc.rcb = true;
  sc.porosity = 0.45;
  check_replicate(sc, false);
}
// with run.order_free_sums (a state file does not carry it: the ranks' must be the caller's)
TEST(DistSpecimen, ReplicateOrderFreeSumsSameBits) {
  ServoScene sc{"soft bond law, RCB, order-free sums", ContactModel::kSoftBond};
  sc.rcb = sc.order_free = true;
  sc.porosity = 0.45;
  check_replicate(sc, false);
}
TEST(DistSpecimen, ReplicatePeriodicRcbSameBits) {
  ServoScene sc{"soft bond law, RCB", ContactModel::kSoftBond};
  sc.rcb = true;
  sc.porosity = 0.45;
  check_replicate(sc, true);
}

TEST(DistSpecimen, ServoLinearSlabsSameBits) { check({"servo, linear, slabs across z"}); }
TEST(DistSpecimen, ServoSoftBondRcbFromRootSameBits) {
  ServoScene sc{"servo, soft bond law, RCB, from rank 0", ContactModel::kSoftBond};
  sc.rcb = sc.from_root = true;
  check(sc);
}
// A dense REV (porosity 0.45): after the expansion few balls touch, and at 3 slabs the middle
// rank's rows hold no active contact. Its World alone would take the no-contact fallback step
// (one contact per ball at the law's reference stiffness, a shorter step); the ranks reduce the
// ratios first and take the fallback only when no rank has a contact (World::contact_scan).
TEST(DistSpecimen, ServoDenseRevSameBits) {
  ServoScene sc{"servo, linear, dense REV, slabs across z"};
  sc.porosity = 0.45;
  sc.idle_rank = true;
  check(sc);
}
TEST(DistSpecimen, GenerateLinearSlabsSameBits) { check_generate({"generate, linear, slabs across z"}); }
TEST(DistSpecimen, GenerateSoftBondRcbSameBits) {
  ServoScene sc{"generate, soft bond law, RCB", ContactModel::kSoftBond};
  sc.rcb = true;
  sc.porosity = 0.45;
  check_generate(sc);
}
// Order-free sums (run.order_free_sums): the servo's 18 sums and the cell stress are each column's
// order-free sum, folded by every rank over its own contacts and reduced in one allreduce (no
// gather on rank 0); one World sums the same way, so the ranks give its bits, which differ from
// the plain sums' (checked).
TEST(DistSpecimen, ServoOrderFreeSumsLooseRevSameBits) {
  ServoScene sc{"servo, soft bond law, RCB, from rank 0, order-free sums", ContactModel::kSoftBond};
  sc.rcb = sc.from_root = sc.order_free = true;
  check(sc);
}
// a criterion that the servo meets: the hold's checks of the ratio run, and the loop ends there
TEST(DistSpecimen, ServoConvergesOrderFreeSumsSameBits) {
  ServoScene sc{"servo, linear, order-free sums, a loose criterion", ContactModel::kLinear};
  sc.order_free = true;
  sc.tol = 0.05;
  sc.ratio = 0.5;
  sc.budget = 2400.0;
  sc.vertical = 1.0;  // (at twice the lateral stress a loose packing at friction 0.3 keeps flowing)
  sc.porosity = 0.40;
  sc.target = 2e6;
  check(sc);
}

// BrickGrid::follow_cell: a cell strained about its origin (as World::integrate maps the balls)
// maps the bricks with it: every ball keeps its brick, and a ball next to a face that moved in
// is a ghost across that face again. Without it the grid keeps the old cell's length: the bricks'
// shares change, and across a periodic face the images sit a cell's old length away.
TEST(DistSpecimen, BricksFollowTheStrainedCell) {
  for (const bool rcb : {false, true}) {
    BrickGrid g;
    g.lo = {-1.0, 0.0, 2.0};  // the cell's origin
    g.len = {1.0, 2.0, 3.0};
    for (bool& p : g.periodic) p = true;
    if (rcb) {
      g.set_rcb(5);
    } else {
      g.n[1] = 2;
      g.n[2] = 3;
      g.cuts[2] = {0.5, 2.0};
    }
    const Vec3 o = g.lo, f{0.9, 1.0, 0.7};  // the strain: x and z shrink, y keeps
    const Vec3 L{g.len.x * f.x, g.len.y * f.y, g.len.z * f.z};
    BrickGrid h = g;
    h.follow_cell(o, L);
    EXPECT_EQ(h.len.x, L.x);
    EXPECT_EQ(h.len.z, L.z);
    int moved_without = 0;
    for (int i = 0; i < 20; ++i)
      for (int k = 0; k < 20; ++k) {
        const Vec3 x{o.x + (i + 0.5) / 20.0 * g.len.x, o.y + 0.3, o.z + (k + 0.5) / 20.0 * g.len.z};
        const Vec3 y{o.x + (x.x - o.x) * f.x, x.y, o.z + (x.z - o.z) * f.z};
        EXPECT_EQ(h.owner(y), g.owner(x)) << (rcb ? "rcb " : "grid ") << i << " " << k;
        moved_without += g.owner(y) != g.owner(x);
      }
    EXPECT_GT(moved_without, 0) << "the strain must move balls between bricks of the old grid";
    // a ball just below the strained cell's top face is within the halo of the bottom bricks
    // through the face: a ghost there
    const double halo = 0.05;
    const Vec3 top{o.x + 0.1, o.y + 0.3, o.z + L.z - 0.01};
    std::vector<int> near_h, near_g;
    h.near(top, halo, near_h);
    g.near(top, halo, near_g);
    const int bottom = h.owner({top.x, top.y, o.z + 0.001});
    EXPECT_NE(std::find(near_h.begin(), near_h.end(), bottom), near_h.end()) << "a ghost across the top face";
    EXPECT_EQ(std::find(near_g.begin(), near_g.end(), bottom), near_g.end()) << "(the old grid's image is too far)";
  }
}
