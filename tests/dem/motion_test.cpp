// Physics checks of the law of motion and the linear contact (docs/theory.md §8.1–8.3).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <memory>
#include <random>

#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kPi = 3.14159265358979323846;

struct Collision {
  double tc, dmax, e, p_err, min_fn;
};

// Two equal balls approaching head-on at relative speed v0, no friction, no gravity.
Collision collide(double alpha) {
  WorldParams p;
  p.local_damping = alpha;
  p.ball_ball.linear.fric = 0.0;
  const double R = 1e-4, v0 = 0.1;
  const double m = p.density * 4.0 / 3.0 * kPi * R * R * R;
  const double kn = kPi * R * R * p.ball_ball.linear.emod / (2 * R);
  const double tc = kPi * std::sqrt(0.5 * m / kn);
  p.dt_fixed = tc / 400.0;
  World w(p);
  w.add_ball({0, 0, 0}, R);
  w.add_ball({2 * R + 0.5 * v0 * 20 * p.dt_fixed, 0, 0}, R);
  w.balls().v[0] = {0.5 * v0, 0, 0};
  w.balls().v[1] = {-0.5 * v0, 0, 0};
  Collision c{0, 0, 0, 0, 1e30};
  double g_prev = w.balls().x[1].x - w.balls().x[0].x - 2 * R, t_prev = 0, t_in = -1, t_out = -1;
  for (int k = 0; k < 2000 && t_out < 0; ++k) {
    w.step();
    const double g = w.balls().x[1].x - w.balls().x[0].x - 2 * R;
    if (g_prev > 0 && g <= 0) t_in = t_prev + (w.time() - t_prev) * g_prev / (g_prev - g);
    if (g_prev <= 0 && g > 0) t_out = t_prev + (w.time() - t_prev) * g_prev / (g_prev - g);
    c.dmax = std::max(c.dmax, -g);
    if (w.pair_contacts().size() > 0) c.min_fn = std::min(c.min_fn, w.pair_contacts().h[0].fn);
    g_prev = g;
    t_prev = w.time();
  }
  w.step(5);
  c.tc = t_out - t_in;
  c.e = (w.balls().v[1].x - w.balls().v[0].x) / v0;
  c.p_err = std::abs(w.balls().m[0] * w.balls().v[0].x + w.balls().m[1] * w.balls().v[1].x);
  c.dmax /= v0 * std::sqrt(0.5 * m / kn);
  c.tc /= tc;
  return c;
}
}  // namespace

// §8.1: t_c = π√(m*/k_n), δ_max = v0√(m*/k_n), e = 1, momentum conserved, no tension.
TEST(Motion, TwoBallCollisionUndamped) {
  const Collision c = collide(0.0);
  EXPECT_NEAR(c.tc, 1.0, 5e-3);
  EXPECT_NEAR(c.dmax, 1.0, 5e-3);
  EXPECT_NEAR(c.e, 1.0, 1e-2);
  EXPECT_LT(c.p_err, 1e-20);
  EXPECT_GE(c.min_fn, 0.0);
  std::printf("undamped: tc/tc_ref-1 = %.2e, dmax/ref-1 = %.2e, e-1 = %.2e\n", c.tc - 1, c.dmax - 1, c.e - 1);
}

// §1.3/§8.1: local damping α gives e = √((1−α)/(1+α)).
TEST(Motion, TwoBallCollisionLocalDamping) {
  const double alpha = 0.3;
  const Collision c = collide(alpha);
  const double e_ref = std::sqrt((1 - alpha) / (1 + alpha));
  EXPECT_NEAR(c.e / e_ref, 1.0, 1e-2);
  EXPECT_GE(c.min_fn, 0.0);
  std::printf("damped: e/e_ref-1 = %.2e\n", c.e / e_ref - 1);
}

// §8.2: a ball resting on a wall under N·g has overlap δ = m N g0/k_n (k_n = π R E*, L = R).
TEST(Motion, BallRestingOnWall) {
  WorldParams p;
  p.local_damping = 0.7;
  p.ball_wall.linear.fric = 0.5;
  const double R = 1e-4, N = 100;
  World w(p);
  PlaneWallParams pw;
  pw.point = {0, 0, 0};
  pw.normal = {0, 0, 1};
  w.add_plane(pw);
  w.add_ball({0, 0, R}, R);
  w.set_gravity(true, N);
  w.step(20000);
  const double m = w.balls().m[0];
  const double kn = kPi * R * R * p.ball_wall.linear.emod / R;
  const double delta = R - w.balls().x[0].z;
  const double ref = m * N * p.g0 / kn;
  EXPECT_NEAR(delta / ref, 1.0, 1e-6);
  std::printf("resting: delta/ref-1 = %.2e\n", delta / ref - 1);
}

namespace {
// Sphere released on an incline of angle θ with friction μ, no damping; returns the mean
// acceleration along the slope measured from s(T) = ½ a T².
double incline_accel(double theta, double mu, double& spin_rate) {
  WorldParams p;
  p.local_damping = 0.0;
  p.ball_wall.linear.fric = mu;
  const double R = 1e-3;
  World w(p);
  PlaneWallParams pw;
  pw.normal = {-std::sin(theta), 0, std::cos(theta)};  // slope descends along +x
  w.add_plane(pw);
  const double m = p.density * 4.0 / 3.0 * kPi * R * R * R;
  const double kn = kPi * R * p.ball_wall.linear.emod;
  const double d0 = m * p.g0 * std::cos(theta) / kn;  // start at the static overlap
  w.add_ball((R - d0) * pw.normal, R);
  w.set_gravity(true, 1.0);
  const Vec3 s_dir{std::cos(theta), 0, std::sin(theta)};
  const Vec3 x0 = w.balls().x[0];
  w.step(4000);
  const double T = w.time();
  const double s = -dot(w.balls().x[0] - x0, s_dir);  // downhill distance
  spin_rate = w.balls().w[0].y / T;
  return 2 * s / (T * T);
}
}  // namespace

// §8.3: rolling without slip when tanθ ≤ 7/2 μ: a = 5/7 g sinθ.
TEST(Motion, InclineRolling) {
  const double th = 20 * kPi / 180, mu = 0.5;
  double spin;
  const double a = incline_accel(th, mu, spin);
  const double ref = 5.0 / 7.0 * 9.81 * std::sin(th);
  EXPECT_NEAR(a / ref, 1.0, 1e-2);
  std::printf("rolling: a/ref-1 = %.2e\n", a / ref - 1);
}

// §8.3: sliding when tanθ > 7/2 μ: a = g(sinθ − μ cosθ), spin grows at 5μg cosθ/(2R).
TEST(Motion, InclineSliding) {
  const double th = 30 * kPi / 180, mu = 0.1;
  double spin;
  const double a = incline_accel(th, mu, spin);
  const double ref = 9.81 * (std::sin(th) - mu * std::cos(th));
  EXPECT_NEAR(a / ref, 1.0, 1e-2);
  const double spin_ref = 5 * mu * 9.81 * std::cos(th) / (2 * 1e-3);
  EXPECT_NEAR(std::abs(spin) / spin_ref, 1.0, 2e-2);
  std::printf("sliding: a/ref-1 = %.2e spin/ref-1 = %.2e\n", a / ref - 1, std::abs(spin) / spin_ref - 1);
}

// Bad parameters are rejected with a sentence naming the field by its scene key.
TEST(Params, RejectsBadDamping) {
  WorldParams p;
  p.local_damping = 1.5;
  try {
    World w(p);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("'dem.damping'"), std::string::npos) << e.what();
  }
}

// §1.7 incremental mode: the same collision as in absolute mode (linear spring from 0).
TEST(Motion, IncrementalModeCollision) {
  WorldParams p;
  p.local_damping = 0.0;
  p.ball_ball.linear.fric = 0.0;
  p.ball_ball.linear.mode = NormalMode::kIncremental;
  const double R = 1e-4, v0 = 0.1;
  const double m = p.density * 4.0 / 3.0 * kPi * R * R * R;
  const double kn = kPi * R * p.ball_ball.linear.emod / 2;
  p.dt_fixed = kPi * std::sqrt(0.5 * m / kn) / 400.0;
  World w(p);
  w.add_ball({0, 0, 0}, R);
  w.add_ball({2 * R, 0, 0}, R);  // touching: the incremental force starts at 0
  w.balls().v[0] = {0.5 * v0, 0, 0};
  w.balls().v[1] = {-0.5 * v0, 0, 0};
  double dmax = 0;
  for (int k = 0; k < 1000; ++k) {
    w.step();
    dmax = std::max(dmax, 2 * R - (w.balls().x[1].x - w.balls().x[0].x));
  }
  EXPECT_NEAR(dmax / (v0 * std::sqrt(0.5 * m / kn)), 1.0, 5e-3);
  EXPECT_NEAR((w.balls().v[1].x - w.balls().v[0].x) / v0, 1.0, 1e-2);
  EXPECT_EQ(w.pair_contacts().h[0].fn, 0.0);  // reset to 0 once inactive
}

// §1.8: critical step of two touching equal balls: f_s·min(√(m/Σk_n), √(I/Σk_s R²)).
TEST(Motion, CriticalTimestep) {
  WorldParams p;
  World w(p);
  const double R = 1e-4;
  w.add_ball({0, 0, 0}, R);
  w.add_ball({2 * R - 1e-8, 0, 0}, R);
  w.prepare();
  const double m = w.balls().m[0], I = w.balls().inertia[0];
  const double kn = kPi * R * p.ball_ball.linear.emod / 2, ks = kn / p.ball_ball.linear.kratio;
  const double ref = p.dt_safety * std::min(std::sqrt(m / kn), std::sqrt(I / (ks * R * R)));
  EXPECT_NEAR(w.dt() / ref, 1.0, 1e-12);
}

// §1.6: the plane rotation keeps a shear vector in the new plane with its magnitude.
TEST(Kernels, ShearRotationKeepsPlaneAndMagnitude) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(-1, 1);
  double err_plane = 0, err_mag = 0;
  for (int t = 0; t < 1000; ++t) {
    Vec3 n0{U(rng), U(rng), U(rng)};
    n0 *= 1 / norm(n0);
    Vec3 n1 = n0 + 0.01 * Vec3{U(rng), U(rng), U(rng)};
    n1 *= 1 / norm(n1);
    Vec3 v{U(rng), U(rng), U(rng)};
    v -= dot(v, n0) * n0;
    const double m0 = norm(v);
    rotate_into_plane(v, n0, n1, {U(rng), U(rng), U(rng)}, 1e-3, true);
    err_plane = std::max(err_plane, std::abs(dot(v, n1)) / m0);
    err_mag = std::max(err_mag, std::abs(norm(v) / m0 - 1));
  }
  EXPECT_LT(err_plane, 1e-14);
  EXPECT_LT(err_mag, 1e-14);
}

// World::set_moving_rows (a rank's ghosts in rows of their own, DistDem with newton on): the
// rows from n on keep their x, v and ω; the rows before it move with the bits of a World that
// moves every row (lane blocks and the scalar tail alike: 37 rows, 13 moving).
TEST(Motion, RowsFromTheMovingRowsOnStayPut) {
  auto make = [] {
    WorldParams p;
    p.dt_fixed = 1e-7;
    p.local_damping = 0.3;
    auto w = std::make_unique<World>(p);
    std::mt19937 g(7);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < 37; ++i) w->add_ball({i * 5e-4, 0.0, 0.0}, 1e-4);  // apart: no contact
    for (std::size_t i = 0; i < w->balls().size(); ++i) {
      w->balls().v[i] = {u(g), u(g), u(g)};
      w->balls().w[i] = {100 * u(g), 100 * u(g), 100 * u(g)};
    }
    w->add_effect(std::make_unique<GravityEffect>(Vec3{0.0, 0.0, -9.81e3}));
    return w;
  };
  auto all = make(), part = make();
  part->set_moving_rows(13);
  const Particles before = part->balls();
  all->step(5);
  part->step(5);
  const Particles &a = all->balls(), &p = part->balls();
  for (std::size_t i = 0; i < a.size(); ++i) {
    const Particles& want = i < 13 ? a : before;
    EXPECT_EQ(std::memcmp(&p.x[i], &want.x[i], sizeof(Vec3)), 0) << "row " << i;
    EXPECT_EQ(std::memcmp(&p.v[i], &want.v[i], sizeof(Vec3)), 0) << "row " << i;
    EXPECT_EQ(std::memcmp(&p.w[i], &want.w[i], sizeof(Vec3)), 0) << "row " << i;
  }
  EXPECT_NE(std::memcmp(&a.x[20], &before.x[20], sizeof(Vec3)), 0) << "a moving row must move";
}
