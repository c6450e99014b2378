// Blow-up guard of the DEM (dem/guard.hpp, docs/stability.md): a NaN injected into a ball or a
// contact is named with its id, position and 10 nearest balls; a ball leaving the domain is
// named at the first step it is out; a ball pushed half a radius into a wall is expelled with
// its strain energy turned into kinetic energy (undamped, energy conserved).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <sstream>

#include "demfdm/dem/guard.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kR = 1e-4;

// 5 x 4 x 3 balls on a jittered lattice, touching their neighbours (no exact distance ties).
void fill(World& w) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> j(-0.02 * kR, 0.02 * kR);
  for (int k = 0; k < 3; ++k)
    for (int y = 0; y < 4; ++y)
      for (int x = 0; x < 5; ++x) w.add_ball({1.99 * kR * x + j(rng), 1.99 * kR * y + j(rng), 1.99 * kR * k + j(rng)}, kR);
  w.prepare();
}

// Ids of the balls in a detail text's neighbour lines, in order.
std::vector<std::uint64_t> listed_ids(const std::string& detail) {
  std::vector<std::uint64_t> ids;
  std::istringstream is(detail);
  std::string line;
  while (std::getline(is, line)) {
    if (line.rfind("  distance ", 0) != 0) continue;
    auto p = line.find(": id ");
    ids.push_back(std::stoull(line.substr(p + 5)));
  }
  return ids;
}

std::vector<std::uint64_t> nearest(const World& w, std::size_t row, std::size_t k) {
  const auto& b = w.balls();
  std::vector<std::pair<double, std::uint64_t>> d;
  for (std::size_t j = 0; j < b.size(); ++j)
    if (j != row) d.push_back({norm(b.x[j] - b.x[row]), b.id[j]});
  std::sort(d.begin(), d.end());
  std::vector<std::uint64_t> ids;
  for (std::size_t n = 0; n < k; ++n) ids.push_back(d[n].second);
  return ids;
}
}  // namespace

TEST(Guard, CleanStateHasNoFinding) {
  World w(WorldParams{});
  fill(w);
  w.step(50);
  EXPECT_FALSE(check_finite(w).has_value());
  EXPECT_FALSE(check_escape(w, {0, 0, 0}, {8 * kR, 6 * kR, 4 * kR}, kR).has_value());
}

TEST(Guard, NaNVelocityNamesTheBallAndItsTenNearestNeighbours) {
  World w(WorldParams{});
  fill(w);
  w.step(10);
  const std::size_t row = 27;
  w.balls().v[row].y = std::numeric_limits<double>::quiet_NaN();
  auto f = check_finite(w);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->row, row);
  EXPECT_EQ(f->id, w.balls().id[row]);
  EXPECT_NE(f->cause.find("non-finite velocity"), std::string::npos) << f->cause;
  EXPECT_NE(f->cause.find("ball id " + std::to_string(w.balls().id[row])), std::string::npos) << f->cause;
  EXPECT_EQ(listed_ids(f->detail), nearest(w, row, 10)) << f->detail;
}

TEST(Guard, NaNContactForceNamesThePairAndModel) {
  World w(WorldParams{});
  fill(w);
  w.step(10);
  auto& pc = w.pair_contacts();
  ASSERT_GT(pc.size(), 20u);
  const std::size_t c = pc.size() / 2;
  const auto a = pc.a[c], b = pc.b[c];
  pc.h[c].fn = std::numeric_limits<double>::quiet_NaN();
  const std::size_t first = std::min(a, b);
  w.balls().f[first].z = std::numeric_limits<double>::quiet_NaN();  // what the force pass would give
  auto f = check_finite(w);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(f->row, first);
  EXPECT_TRUE(f->contact);
  EXPECT_EQ(f->other_id, w.balls().id[first == a ? b : a]);
  const std::string pair = std::to_string(w.balls().id[a]) + "-" + std::to_string(w.balls().id[b]) + " (linear)";
  EXPECT_NE(f->cause.find(pair), std::string::npos) << f->cause;
  EXPECT_NE(f->detail.find("NON-FINITE"), std::string::npos);
}

// A ball at v leaves the box [0, L]^3 by more than the margin at the first step where
// x0 + v t > L + margin (t = steps x dt): the guard names it at that step, not before.
TEST(Guard, EscapingBallIsNamedAtTheFirstStepOutside) {
  WorldParams p;
  p.dt_fixed = 1e-6;
  World w(p);
  const double L = 1e-3, margin = 2.05e-4, v = 10.0;  // no tie at a step boundary
  w.add_ball({5e-4, 5e-4, 5e-4}, kR);
  const auto far = w.add_ball({1e-4, 1e-4, 1e-4}, kR);  // stays inside
  (void)far;
  w.balls().v[0] = {v, 0, 0};
  w.prepare();
  const auto expected = static_cast<std::int64_t>(std::floor((L + margin - 5e-4) / (v * p.dt_fixed))) + 1;
  std::int64_t tripped = -1;
  for (std::int64_t s = 1; s <= 200 && tripped < 0; ++s) {
    w.step();
    auto f = check_escape(w, {0, 0, 0}, {L, L, L}, margin);
    if (f) {
      tripped = s;
      EXPECT_EQ(f->id, w.balls().id[0]);
      EXPECT_NE(f->cause.find("left the DEM domain"), std::string::npos) << f->cause;
    }
  }
  EXPECT_EQ(tripped, expected);
}

// A ball pushed 0.5 R into a plane wall, undamped, no gravity: it is expelled without any
// non-finite value, and once free its kinetic energy equals the initial strain energy of the
// contact up to the integrator's error at the contact's end, which falls with dt: within 2 % at
// dt_safety 0.05, within 25 % at the default 0.8 (measured 18 %), never more.
double expelled_energy_ratio(double dt_safety) {
  WorldParams p;
  p.local_damping = 0.0;
  p.dt_safety = dt_safety;
  World w(p);
  PlaneWallParams pw;
  pw.point = {0, 0, 0};
  pw.normal = {0, 0, 1};
  w.add_plane(pw);
  w.add_ball({0, 0, 0.5 * kR}, kR);
  w.prepare();
  const double e0 = w.energy().strain;
  EXPECT_GT(e0, 0.0);
  double ke_max = 0;
  for (int s = 0; s < 40000 && w.balls().x[0].z < 2 * kR; ++s) {
    w.step();
    EXPECT_FALSE(check_finite(w).has_value()) << "step " << s;
    ke_max = std::max(ke_max, w.kinetic_energy());
  }
  EXPECT_GT(w.balls().x[0].z, kR) << "the ball must have left the wall";
  const double ke = w.kinetic_energy();
  std::cout << "[ figures  ] dt_safety " << dt_safety << ": initial strain energy " << e0 << " J, final kinetic " << ke
            << " J, ratio " << ke / e0 << ", largest kinetic / initial strain " << ke_max / e0 << "\n";
  return std::max(ke, ke_max) / e0;
}

TEST(Guard, BallPushedHalfARadiusIntoAWallIsExpelledConservingEnergy) {
  EXPECT_NEAR(expelled_energy_ratio(0.05), 1.0, 0.02);
  const double r = expelled_energy_ratio(0.8);
  EXPECT_GT(r, 0.75);
  EXPECT_LT(r, 1.25);
}

// dem::screen_balls, the node's per-step pass (docs/stability.md): its finite flag trips on a
// NaN or an infinity in any component of x, v, ω, F and T, its escape distance is the largest
// of a serial loop over the balls, and its kinetic energy has World::kinetic_energy()'s bits, on
// the serial path (one thread) and the parallel one (two threads, more than 4,096 balls), with
// the plain and with order-free sums.
TEST(Guard, ScreenBallsMatchesTheSeparateTests) {
  World w(WorldParams{});
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> j(-0.02 * kR, 0.02 * kR);
  for (int k = 0; k < 16; ++k)
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 20; ++x) w.add_ball({1.99 * kR * x + j(rng), 1.99 * kR * y + j(rng), 1.99 * kR * k + j(rng)}, kR);
  ASSERT_GT(w.num_balls(), 4096u);
  w.prepare();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (std::size_t i = 0; i < w.num_balls(); ++i) w.balls().v[i] = {u(rng), u(rng), u(rng)};
  w.step(5);
  const Vec3 lo{0, 0, 0}, hi{38 * kR, 30 * kR, 30 * kR};
  // A ball well outside, another slightly: the largest distance wins.
  w.balls().x[100].x = hi.x + 3.3 * kR;
  w.balls().x[4000].z = lo.z - 1.7 * kR;
  double expect_out = 0;
  for (std::size_t i = 0; i < w.num_balls(); ++i)
    for (int k = 0; k < 3; ++k) expect_out = std::max({expect_out, lo[k] - w.balls().x[i][k], w.balls().x[i][k] - hi[k]});
  ASSERT_GT(expect_out, 3 * kR);
  std::vector<double> scratch;
  for (int mode = 0; mode < 4; ++mode) {
    const int threads = 1 + mode % 2;
    const bool order_free = mode >= 2;  // WorldParams::order_free_sums: the same sum as the World's
    SCOPED_TRACE("threads " + std::to_string(threads) + (order_free ? ", order-free sums" : ""));
    w.mutable_params().threads = threads;
    w.mutable_params().order_free_sums = order_free;
    const BallScreen sc = screen_balls(w, lo, hi, true, scratch);
    EXPECT_TRUE(sc.finite);
    EXPECT_EQ(sc.outside, expect_out);
    EXPECT_EQ(sc.kinetic, w.kinetic_energy());  // the same bits, not a tolerance
    EXPECT_TRUE(check_escape(w, lo, hi, 3 * kR).has_value());
    EXPECT_FALSE(check_escape(w, lo, hi, sc.outside).has_value());
    EXPECT_EQ(screen_balls(w, lo, hi, false, scratch).outside, 0.0);  // no box: not computed
    const double bad[2] = {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()};
    std::vector<Vec3>* arrays[5] = {&w.balls().x, &w.balls().v, &w.balls().w, &w.balls().f, &w.balls().t};
    for (int a = 0; a < 5; ++a)
      for (int k = 0; k < 3; ++k)
        for (double v : bad) {
          const std::size_t row = 4500 + static_cast<std::size_t>(a * 3 + k);
          Vec3& slot = (*arrays[a])[row];
          const double keep = slot[k];
          slot[k] = v;
          EXPECT_FALSE(screen_balls(w, lo, hi, true, scratch).finite) << "array " << a << " component " << k;
          EXPECT_TRUE(check_finite(w).has_value());
          slot[k] = keep;
        }
    EXPECT_TRUE(screen_balls(w, lo, hi, true, scratch).finite);
  }
}
