// Per-phase wall timers of dem::World (World::phase_times, needed by the run summary of
// issue 7): non-negative, summing to no more than the wall time of the timed calls, one
// entry per effect name, and exactly zero for wall passes the world does not have.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>

#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
// Counts its calls; runs in every phase so the three effect hooks are all timed.
class Probe final : public Effect {
 public:
  unsigned phases() const override { return kPreStep | kForce | kEndOfStep; }
  void apply(World&, Phase) override { ++calls; }
  const char* name() const override { return "probe"; }
  long calls = 0;
};

// 8×8×8 jittered lattice of touching balls (spacing 1.98 R) under gravity: ball–ball contacts
// from the first step, so the pair pass does real work.
void add_lattice(World& w, double R) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-0.005, 0.005);
  for (int i = 0; i < 8; ++i)
    for (int j = 0; j < 8; ++j)
      for (int k = 0; k < 8; ++k)
        w.add_ball({(1.98 * i + u(rng)) * R, (1.98 * j + u(rng)) * R, (1.0 + 1.98 * k + u(rng)) * R}, R);
}

double effect_time(const PhaseTimes& t, const char* name) {
  for (const auto& e : t.effect)
    if (e.first == name) return e.second;
  return -1.0;
}

// Runs n steps, returns the wall time of the calls [s].
double timed_steps(World& w, int n) {
  const auto t0 = std::chrono::steady_clock::now();
  w.step(n);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void expect_consistent(const PhaseTimes& t, double wall) {
  for (double v : {t.rebuild, t.pair, t.plane, t.facet, t.footing, t.gather, t.motion, t.effects_total})
    EXPECT_GE(v, 0.0);
  double eff = 0.0;
  for (const auto& e : t.effect) {
    EXPECT_GE(e.second, 0.0);
    eff += e.second;
  }
  EXPECT_NEAR(eff, t.effects_total, 1e-12 + 1e-12 * t.effects_total);
  EXPECT_LE(t.total(), wall);
  // The phases are chained laps inside step(): only loop and call overhead falls between
  // them (measured sum/wall 0.998 here); a quarter leaves room for preemption in a gap.
  EXPECT_GT(t.total(), 0.25 * wall) << "the phases should cover most of the step";
}
}  // namespace

// No walls: the wall phases are never entered (exactly 0); the rest is consistent with the
// wall time measured around step(n); each effect has its own entry.
TEST(PhaseTimes, NoWallsReportsZeroWallPhases) {
  WorldParams p;
  const double R = 1e-4;
  World w(p);
  add_lattice(w, R);
  w.set_gravity(true, 1.0);
  auto* probe = static_cast<Probe*>(w.add_effect(std::make_unique<Probe>()));
  w.prepare();
  w.reset_phase_times();
  const int n = 200;
  const double wall = timed_steps(w, n);
  const PhaseTimes& t = w.phase_times();
  EXPECT_EQ(t.steps, n);
  EXPECT_EQ(probe->calls, 3L * n + 1);  // + the force phase of prepare()
  EXPECT_EQ(t.plane, 0.0);
  EXPECT_EQ(t.facet, 0.0);
  EXPECT_EQ(t.footing, 0.0);
  EXPECT_GT(t.pair, 0.0);
  EXPECT_GT(t.motion, 0.0);
  EXPECT_STREQ(t.pair_model, "linear");
  ASSERT_EQ(t.effect.size(), 2u);
  EXPECT_GT(effect_time(t, "gravity"), 0.0);
  EXPECT_GT(effect_time(t, "probe"), 0.0);
  expect_consistent(t, wall);
  std::printf("phase times over %d steps (wall %.3e s): rebuild %.2e pair %.2e gather %.2e motion %.2e "
              "effects %.2e, sum %.3e\n",
              n, wall, t.rebuild, t.pair, t.gather, t.motion, t.effects_total, t.total());
  // Reset zeroes the times and keeps the effect names; switching gravity off and on again
  // reuses its entry.
  w.reset_phase_times();
  EXPECT_EQ(w.phase_times().total(), 0.0);
  EXPECT_EQ(w.phase_times().steps, 0);
  ASSERT_EQ(w.phase_times().effect.size(), 2u);
  EXPECT_EQ(effect_time(w.phase_times(), "gravity"), 0.0);
  w.set_gravity(false, 0.0);
  w.set_gravity(true, 1.0);
  EXPECT_EQ(w.phase_times().effect.size(), 2u);
}

// A planar floor and a footing: their passes are timed, the facet pass stays at 0.
TEST(PhaseTimes, WallPassesTimedWhenPresent) {
  WorldParams p;
  p.ball_ball.model = ContactModel::kSoftBond;
  const double R = 1e-4;
  World w(p);
  add_lattice(w, R);
  PlaneWallParams floor;
  floor.point = {0, 0, 0};
  floor.normal = {0, 0, 1};
  w.add_plane(floor);
  FootingParams fp;
  fp.bottom_centre = {7 * R, 7 * R, 20 * R};
  fp.diameter = 4 * R;
  fp.height = 2 * R;
  w.set_footing(fp);
  w.set_gravity(true, 1.0);
  w.prepare();
  w.reset_phase_times();
  const int n = 200;
  const double wall = timed_steps(w, n);
  const PhaseTimes& t = w.phase_times();
  EXPECT_GT(w.plane_contacts().size(), 0u);
  EXPECT_GT(t.plane, 0.0);
  EXPECT_GT(t.footing, 0.0);
  EXPECT_EQ(t.facet, 0.0);
  EXPECT_STREQ(t.pair_model, "softbond");
  expect_consistent(t, wall);
}
