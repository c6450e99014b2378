// DEM stage procedures and diagnostics moved out of the node executable (issue 15 item 4,
// demfdm/dem/procedures.hpp), each against an analytic answer or a stated invariant.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>

#include <cmath>
#include <stdexcept>

#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/procedures.hpp"

using namespace demfdm::dem;

namespace {
WorldParams plain() {
  WorldParams p;
  p.threads = 1;
  p.ball_ball.model = ContactModel::kLinear;
  return p;
}
}  // namespace

// Two stacked balls on a floor carry contact forces; a ball far above them falls freely (a
// rattler). The skeleton ratio is the mean |F_unb| of the two over the mean contact force.
TEST(Procedures, SkeletonRatioLeavesOutRattlers) {
  WorldParams p = plain();
  p.local_damping = 0.0;
  World w(p);
  const double R = 1e-3;
  w.add_ball({0, 0, R * (1 - 1e-3)}, R);            // pressed 1 µm into the floor
  w.add_ball({0, 0, R * (3 - 2e-3) - 0.5e-6}, R);   // resting on it, 0.5 µm overlap
  w.add_ball({0.1, 0, 0.5}, R);                     // far from everything
  PlaneWallParams floor;
  floor.point = {0, 0, 0};
  w.add_plane(floor);
  w.set_gravity(true, 1.0);
  w.prepare();
  const SkeletonRatio s = skeleton_ratio(w);
  EXPECT_EQ(s.rattlers, 1u);
  const auto& b = w.balls();
  const double fc = w.mean_contact_force();
  ASSERT_GT(fc, 0.0);
  EXPECT_DOUBLE_EQ(s.ratio, (norm(b.f[0] + b.fa[0]) + norm(b.f[1] + b.fa[1])) / 2 / fc);
  // The rattler's whole force is its weight.
  EXPECT_DOUBLE_EQ(b.f[2].z, -b.m[2] * 9.81);
}

namespace {
// 5,832 balls under gravity with random forces (every 7th a rattler: its force is its weight),
// some with fixed axes.
void random_forces(World& w, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double R = 1e-3;
  for (int k = 0; k < 18; ++k)
    for (int j = 0; j < 18; ++j)
      for (int i = 0; i < 18; ++i) w.add_ball({3 * R * i, 3 * R * j, 3 * R * k}, R);
  w.set_gravity(true, 1.0);
  w.prepare();
  auto& b = w.balls();
  const Vec3 g = w.gravity();
  for (std::size_t i = 0; i < b.size(); ++i) {
    b.f[i] = (i % 7 == 3) ? b.m[i] * g : Vec3{u(rng), u(rng), u(rng)};
    b.fa[i] = (i % 7 == 3) ? Vec3{} : Vec3{u(rng), u(rng), u(rng)} * 1e-3;
    b.fix[i] = (i % 11 == 5) ? static_cast<std::uint8_t>(kFixVz) : static_cast<std::uint8_t>(i % 13 == 2 ? kFixVel : 0);
  }
}
}  // namespace

// The skeleton ratio's one-thread loop (sums fused into the pass over the balls) and its
// threaded path (work arrays, then the sums in row order) give the bits of a plain loop over
// is_rattler and skeleton_term, on 5,832 balls with random forces, some with fixed axes and
// some rattlers.
TEST(Procedures, SkeletonRatioSameBitsOnOneAndTwoThreads) {
  World w(plain());
  random_forces(w, 7);
  auto& b = w.balls();
  const double fc = 0.37;
  double sum = 0.0;
  std::size_t rattlers = 0;
  for (std::size_t i = 0; i < b.size(); ++i) {
    rattlers += is_rattler(w, i);
    sum += skeleton_term(w, i);
  }
  ASSERT_GT(rattlers, 800u);
  const SkeletonRatio ref = skeleton_ratio_of(sum, rattlers, b.size(), fc);
  for (int threads : {1, 2}) {
    w.mutable_params().threads = threads;
    const SkeletonRatio s = skeleton_ratio(w, fc);
    EXPECT_EQ(s.rattlers, ref.rattlers) << threads << " thread(s)";
    std::uint64_t a, e;
    std::memcpy(&a, &s.ratio, 8);
    std::memcpy(&e, &ref.ratio, 8);
    EXPECT_EQ(a, e) << threads << " thread(s): " << s.ratio << " vs " << ref.ratio;
  }
}

// Both ratios in one pass (dem::ball_ratios, the DEM node's report of a coupled step) give the
// bits of World::unbalanced_ratio and skeleton_ratio called one after the other: one and two
// threads, with and without order-free sums, on the state of the test above (rattlers, fixed axes).
TEST(Procedures, BallRatiosGiveTheBitsOfTheTwoRatios) {
  World w(plain());
  random_forces(w, 11);
  auto bits = [](double v) {
    std::uint64_t a;
    std::memcpy(&a, &v, 8);
    return a;
  };
  for (bool order_free : {false, true})
    for (int threads : {1, 2}) {
      w.mutable_params().threads = threads;
      w.mutable_params().order_free_sums = order_free;
      for (double fc : {0.37, 0.0}) {
        const BallRatios r = ball_ratios(w, fc);
        const SkeletonRatio s = skeleton_ratio(w, fc);
        const std::string at = std::to_string(threads) + " thread(s), order-free " + std::to_string(order_free) +
                               ", fc " + std::to_string(fc);
        EXPECT_EQ(bits(r.unbalanced), bits(w.unbalanced_ratio(fc))) << at;
        EXPECT_EQ(bits(r.skeleton.ratio), bits(s.ratio)) << at;
        EXPECT_EQ(r.skeleton.rattlers, s.rattlers) << at;
        EXPECT_GT(s.rattlers, 800u);
      }
    }
}

// The slabs tile the block from its top down; every ball centre inside the block is counted
// once; in a box without forces the stresses are zero.
TEST(Procedures, StressProfileSlabsTileTheBlock) {
  World w(plain());
  const double R = 1e-4;
  int n = 0;
  for (int k = 0; k < 10; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i, ++n) w.add_ball({(2 * i + 1) * 1.2 * R, (2 * j + 1) * 1.2 * R, (2 * k + 1) * 1.2 * R}, R);
  w.prepare();
  ProfileBox box;
  box.x_hi = box.y_hi = 6 * 1.2 * R;
  box.z_top = 20 * 1.2 * R;
  box.height = box.z_top;
  const auto slabs = stress_profile(w, box, 5);
  ASSERT_EQ(slabs.size(), 5u);
  std::size_t count = 0;
  for (std::size_t i = 0; i < slabs.size(); ++i) {
    count += slabs[i].balls;
    EXPECT_NEAR(slabs[i].depth_top, box.height * i / 5, 1e-15);
    EXPECT_NEAR(slabs[i].depth_bottom, box.height * (i + 1) / 5, 1e-15);
    EXPECT_NEAR(slabs[i].depth, 0.5 * (slabs[i].depth_top + slabs[i].depth_bottom), 1e-15);
    EXPECT_EQ(slabs[i].szz, 0.0);  // no contact touches: spacing 2.4 R
    EXPECT_EQ(slabs[i].balls, 18u);
  }
  EXPECT_EQ(count, static_cast<std::size_t>(n));
  EXPECT_THROW(stress_profile(w, box, 0), std::invalid_argument);
}

// Five walls touch the outermost ball surfaces: no wall overlaps a ball, and each touches one.
TEST(Procedures, BoxWallsTouchTheOutermostSurfaces) {
  World w(plain());
  w.add_ball({0, 0, 0}, 1e-3);
  w.add_ball({3e-3, 1e-3, 0.5e-3}, 0.8e-3);
  w.add_ball({1e-3, 4e-3, 2e-3}, 1.2e-3);
  const auto [lo, hi] = add_box_walls(w);
  ASSERT_EQ(w.num_planes(), 5);
  EXPECT_DOUBLE_EQ(lo.x, -1e-3);
  EXPECT_DOUBLE_EQ(hi.x, 3.8e-3);
  EXPECT_DOUBLE_EQ(lo.z, -1e-3);
  EXPECT_DOUBLE_EQ(hi.y, 5.2e-3);
  const auto& b = w.balls();
  for (int k = 0; k < 5; ++k) {
    const PlaneWall& pw = w.plane(k);
    double closest = 1e300;
    for (std::size_t i = 0; i < b.size(); ++i) closest = std::min(closest, dot(b.x[i] - pw.p.point, pw.p.normal) - b.r[i]);
    EXPECT_NEAR(closest, 0.0, 1e-18) << "wall " << k;  // touching, never overlapping
  }
  WorldParams per = plain();
  per.periodic.enabled = true;
  per.periodic.length = {1, 1, 1};
  World wp(per);
  wp.add_ball({0.5, 0.5, 0.5}, 1e-3);
  EXPECT_THROW(add_box_walls(wp), std::invalid_argument);
  World empty(plain());
  EXPECT_THROW(add_box_walls(empty), std::invalid_argument);
}

// First contact: a ball under the footprint touches the bottom at its top; one beyond the edge
// touches the rim at z + sqrt(r^2 - (rho - r_f)^2); none under the footprint is an error.
TEST(Procedures, FootingPlacedAtFirstContactIncludingTheRim) {
  World w(plain());
  const double r = 1e-3;
  w.add_ball({0, 0, 0}, r);            // under the centre: top at 1e-3
  w.add_ball({2.5e-3, 0, 0.5e-3}, r);  // 0.5 mm beyond the rim of a 4 mm footing
  FootingParams f;
  f.diameter = 4e-3;
  f.bottom_centre = {0, 0, 123.0};  // z is ignored
  const double z = place_footing_at_first_contact(w, f);
  EXPECT_DOUBLE_EQ(z, 0.5e-3 + std::sqrt(r * r - 0.5e-3 * 0.5e-3));
  ASSERT_TRUE(w.has_footing());
  EXPECT_DOUBLE_EQ(w.footing().p.bottom_centre.z, z);
  EXPECT_EQ(w.footing().p.velocity.z, 0.0);
  f.bottom_centre = {1.0, 1.0, 0};  // 1 m away from every ball
  EXPECT_THROW(place_footing_at_first_contact(w, f), std::runtime_error);
}

// The footing pushing a ball down at v: the boundary power is -F.v; gravity's work is m g dz.
TEST(Procedures, BoundaryPowerAndGravityWork) {
  World w(plain());
  w.add_ball({0, 0, 0}, 1e-3);
  FootingParams f;
  f.diameter = 1e-3;
  f.bottom_centre = {0, 0, 0};
  place_footing_at_first_contact(w, f);
  w.set_footing_position({0, 0, 1e-3 - 1e-6});  // 1 µm into the ball
  w.set_footing_velocity({0, 0, -0.5});
  w.prepare();
  const Vec3 F = w.footing_reaction();
  ASSERT_GT(F.z, 0.0);  // the ball pushes the footing up
  EXPECT_DOUBLE_EQ(boundary_power(w), -dot(F, Vec3{0, 0, -0.5}));
  EXPECT_GT(boundary_power(w), 0.0);  // the footing works on the ball
  const std::vector<Vec3> x0 = w.balls().x;
  EXPECT_EQ(gravity_work(w, x0), 0.0);  // gravity off
  w.set_gravity(true, 2.0);
  w.balls().x[0].z -= 1e-4;
  EXPECT_NEAR(gravity_work(w, x0), w.balls().m[0] * 2.0 * 9.81 * 1e-4, 1e-15);
}

// A stage's energy balance: a 3x3x3 column under gravity on a fixed floor, pushed by the
// footing, with local damping and friction: the change of the total energy equals the footing's
// and gravity's work to a small fraction of the energy that flowed; leaving the footing's work
// out breaks the balance.
TEST(Procedures, StageEnergyBalancesTheFootingsAndGravitysWork) {
  WorldParams p = plain();
  p.local_damping = 0.3;
  World w(p);
  const double R = 1e-3;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) w.add_ball({2 * R * i, 2 * R * j, R + 2 * R * k}, R);
  PlaneWallParams floor;
  w.add_plane(floor);
  w.set_gravity(true, 10.0);
  FootingParams f;
  f.diameter = 3 * R;
  f.bottom_centre = {2 * R, 2 * R, 0};
  place_footing_at_first_contact(w, f);
  w.set_footing_velocity({0, 0, -0.02});
  w.prepare();
  StageEnergy e, no_footing_work;
  e.begin(w);
  no_footing_work.begin(w);
  for (int s = 0; s < 3000; ++s) {
    w.step();
    e.add_work(w, 1);
  }
  const auto b = e.balance(w), bad = no_footing_work.balance(w);
  EXPECT_GT(b.work, 0.0);
  EXPECT_GT(b.dissipated, 0.0);
  EXPECT_LT(std::abs(b.error), 1e-2) << "work " << b.work << " J, dissipated " << b.dissipated << " J";
  EXPECT_GT(std::abs(bad.error), 0.1) << "the footing's work must matter in this test";
  std::printf("stage energy: work %.4e J, dissipated %.4e J, error %.2e (without the footing's work %.2e)\n", b.work,
              b.dissipated, b.error, bad.error);
}

// The bound of dem.dt_fixed's check: no cluster of balls from the PSD that holds a ball of the
// smallest size, in contact, has a larger critical step (random clusters of 2 to 8 balls, linear
// and soft-bond families). A cluster of large balls alone can: the step grows with the radius.
TEST(Procedures, NoPackingOfThePsdHasALargerCriticalStepThanTheBound) {
  const double rmin = 0.05e-3, rmax = 0.14e-3;
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (ContactModel m : {ContactModel::kLinear, ContactModel::kSoftBond}) {
    WorldParams p = plain();
    p.ball_ball.model = m;
    const double bound = largest_critical_step(p, rmin, rmax);
    double largest = 0.0;
    for (int trial = 0; trial < 200; ++trial) {
      p.dt_safety = 1.0;
      World w(p);
      const int n = 2 + static_cast<int>(u(rng) * 7);
      w.add_ball({0, 0, 0}, rmin);  // the PSD's smallest ball; ball 1 touches it
      for (int i = 1; i < n; ++i) {  // each new ball overlaps a random earlier one slightly
        const auto& b = w.balls();
        const std::size_t j = static_cast<std::size_t>(u(rng) * i);
        const double r = rmin + (rmax - rmin) * u(rng);
        Vec3 d{u(rng) - 0.5, u(rng) - 0.5, u(rng) - 0.5};
        d = d * (1.0 / norm(d));
        w.add_ball(b.x[j] + (b.r[j] + r) * (1 - 1e-6) * d, r);
      }
      w.prepare();
      largest = std::max(largest, w.critical_timestep());
    }
    EXPECT_LE(largest, bound) << to_string(m);
    EXPECT_GT(largest, 0.5 * bound) << "the clusters come near the bound";
    // Two balls of the largest size only: above the bound.
    World big(p);
    big.add_ball({0, 0, 0}, rmax);
    big.add_ball({2 * rmax * (1 - 1e-6), 0, 0}, rmax);
    big.prepare();
    EXPECT_GT(big.critical_timestep(), bound) << to_string(m);
  }
}

TEST(Procedures, KickGivesTheHighestTopItsVelocity) {
  World w(plain());
  w.add_ball({0, 0, 1e-3}, 1e-3);    // top 2e-3
  w.add_ball({1, 0, 1.5e-3}, 0.2e-3);  // top 1.7e-3: higher centre, lower top
  EXPECT_EQ(kick_highest_ball(w, {0, 0, 3}), 0u);
  EXPECT_EQ(w.balls().v[0].z, 3.0);
  EXPECT_EQ(w.balls().v[1].z, 0.0);
  World empty(plain());
  EXPECT_THROW(kick_highest_ball(empty, {0, 0, 1}), std::invalid_argument);
}

namespace {
// A periodic cell for the specimen procedures (as tests/dem/specimen_generation_test.cpp), small
// enough for a unit test: about 90 balls at scale 1.5.
WorldParams cell(ContactModel model) {
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.length = {0.8e-3, 0.8e-3, 0.8e-3};
  p.local_damping = 0.7;
  p.threads = 1;
  p.skin_factor = 0.8;
  p.ball_ball.model = model;
  return p;
}
RevParams small_rev() {
  RevParams g;
  g.psd.scale = 1.5;
  g.seed = 11;
  g.porosity_final = 0.5195;
  return g;
}
std::string fixed3(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.3f", v);
  return b;
}
}  // namespace

// generate_specimen: without a coordination it is generate_rev; with one, the bonded specimen
// reaches it, and the report names the coordination before and after bonding.
TEST(Procedures, GenerateSpecimenBondsToTheCoordination) {
  World plain_rev(cell(ContactModel::kSoftBond)), unbonded(cell(ContactModel::kSoftBond));
  const StageReport r0 = generate_rev(plain_rev, small_rev());
  const StageReport r1 = generate_specimen(unbonded, small_rev(), 0.0, 1e-7);
  EXPECT_EQ(r1.what, r0.what);
  EXPECT_EQ(r1.count, r0.count);
  EXPECT_EQ(bond_counts(unbonded).intact, 0u);

  World bonded(cell(ContactModel::kSoftBond));
  const StageReport r = generate_specimen(bonded, small_rev(), 6.82, 1e-7);
  ASSERT_TRUE(r.converged) << r.what;
  const double z = coordination(bonded).z;
  EXPECT_GE(z, 6.82);
  EXPECT_GT(bond_counts(bonded).intact, 0u);
  EXPECT_EQ(r.count, bonded.num_balls());
  EXPECT_EQ(r.what.rfind(r0.what + "; ", 0), 0u) << r.what;
  // The touching coordination before bonding is the plain REV's.
  const std::string tail = "; Z " + fixed3(z) + " (touching before bonding: " + fixed3(coordination(plain_rev).z) + ")";
  ASSERT_GE(r.what.size(), tail.size());
  EXPECT_EQ(r.what.substr(r.what.size() - tail.size()), tail);
}

// servo_specimen: the servo reaches its targets and leaves the final friction in place; a
// compaction that misses its criterion is returned as it is.
TEST(Procedures, ServoSpecimenEndsAtTheTargetsWithTheFinalFriction) {
  auto rev = [] {
    auto w = std::make_unique<World>(cell(ContactModel::kSoftBond));
    w->mutable_params().ball_ball.linear.fric = 0.5;
    w->refresh_contact_constants();
    EXPECT_TRUE(generate_specimen(*w, small_rev(), 6.82, 1e-7).converged);
    return w;
  };
  auto wp = rev(), missed_p = rev();
  World &w = *wp, &missed = *missed_p;
  ServoParams s;
  s.target = {6.25e3, 6.25e3, 12.5e3};
  const StageReport r = servo_specimen(w, s, 0.005, 1e-4, 160, 16000, 0.1);
  ASSERT_TRUE(r.converged) << r.what;
  EXPECT_EQ(w.params().ball_ball.linear.fric, 0.5);
  for (int a = 0; a < 3; ++a) EXPECT_NEAR(-r.stress[4 * a] / s.target[a], 1.0, 0.005 + 1e-12) << "axis " << a;
  EXPECT_LT(r.ratio, 1e-4);
  EXPECT_EQ(r.what.rfind("servo to sigma_v 12500.000000 Pa, sigma_h 6250.000000 Pa: ", 0), 0u) << r.what;
  EXPECT_NE(r.what.find("; at final friction: "), std::string::npos) << r.what;

  const StageReport m = servo_specimen(missed, s, 0.005, 1e-4, 160, 1, 0.1);  // one critical step
  EXPECT_FALSE(m.converged);
  EXPECT_EQ(missed.params().ball_ball.linear.fric, 0.1) << "the compaction's friction, the run stops";
  EXPECT_EQ(m.what.find("at final friction"), std::string::npos);
}

// ball_weight: sum of 4/3 pi r^3 rho_s times |g| (g-level N g0), 0 without gravity.
TEST(Procedures, BallWeightIsTheMassTimesG) {
  World w(plain());
  w.add_ball({0, 0, 0}, 1e-3);
  w.add_ball({1, 0, 0}, 2e-3);
  EXPECT_EQ(ball_weight(w), 0.0);
  w.set_gravity(true, 50.0);
  const double pi = 3.14159265358979323846;
  const double m = 4.0 / 3.0 * pi * (1e-9 + 8e-9) * w.params().density;
  EXPECT_NEAR(ball_weight(w), m * 50.0 * w.params().g0, 1e-12 * m * 50 * 9.81);
}

// energy_jump_finding names the ball with the largest kinetic energy, spin included.
TEST(Procedures, EnergyJumpFindingNamesTheMostEnergeticBall) {
  World w(plain());
  w.add_ball({0, 0, 0}, 1e-3);
  w.add_ball({1, 0, 0}, 1e-3);
  w.add_ball({2, 0, 0}, 1e-3);
  auto& b = w.balls();
  b.v[0] = {0.1, 0, 0};   // 0.5 m 0.01
  b.v[1] = {0, 0.2, 0};   // 0.5 m 0.04
  b.w[2] = {0, 0, 400.0};  // 0.5 (0.4 m r^2) 160000 = 0.5 m 0.064 with r = 1 mm
  const GuardFinding f = energy_jump_finding(w, "kinetic energy jumped 10x");
  EXPECT_EQ(f.row, 2u);
  EXPECT_EQ(f.id, b.id[2]);
  EXPECT_EQ(f.cause, "DEM kinetic energy jumped 10x; fastest ball id " + std::to_string(b.id[2]));
  EXPECT_NE(f.detail.find("10 nearest balls:"), std::string::npos);
  b.w[2] = {0, 0, 0};
  EXPECT_EQ(energy_jump_finding(w, "x").row, 1u);
  World empty(plain());
  EXPECT_THROW(energy_jump_finding(empty, "x"), std::invalid_argument);
}

// StageEnergy's checkpoint: the fields of docs/checkpoint-format.md (3 doubles, count, x y z per
// ball) and the same balance after a load.
TEST(Procedures, StageEnergySavesAndLoadsItsState) {
  World w(plain());
  w.add_ball({0, 0, 0.5}, 1e-3);
  w.add_ball({0.01, 0, 0.5}, 1e-3);
  w.set_gravity(true, 1.0);
  w.prepare();
  StageEnergy e;
  e.begin(w);
  w.balls().x[0].z -= 0.01;  // gravity's work in the balance
  e.work = 0.25;
  demfdm::io::StateWriter out("dem", "test", 1);
  out.begin("e");
  e.save(out);
  out.end();
  demfdm::io::StateReader in(out.bytes(), "mem", "dem", 1);
  auto sec = in.section("e");
  EXPECT_EQ(sec.remaining(), 3 * 8 + 8 + 2 * 24u);
  StageEnergy back;
  back.load(sec);
  sec.done();
  EXPECT_EQ(back.total_begin, e.total_begin);
  EXPECT_EQ(back.mechanical_begin, e.mechanical_begin);
  EXPECT_EQ(back.work, 0.25);
  ASSERT_EQ(back.x_begin.size(), 2u);
  EXPECT_EQ(back.x_begin[1].x, 0.01);
  EXPECT_EQ(back.x_begin[1].z, 0.5);
  const auto a = e.balance(w), c = back.balance(w);
  EXPECT_EQ(a.error, c.error);
  EXPECT_EQ(a.work, c.work);
}
