// Closed-form verification problems (docs/theory.md 8.11, 8.12, 5.11, 6.9).
#include <gtest/gtest.h>

#include <cmath>

#include "demfdm/fdm/model.hpp"
#include "test_util.hpp"

namespace demfdm::fdm {
namespace {

using test::elastic;

struct ColumnResult {
  double worst_szz = 0.0, worst_sxx = 0.0, utop_error = 0.0, weight_error = 0.0, ratio = 1.0;
  std::int64_t steps = 0;
};

// Elastic column under N g with lateral rollers and a fixed base (docs/theory.md 8.11), static
// mode. 20 zones over H = 10 m. Errors are relative to the closed form.
ColumnResult run_column(double N) {
  const double E = 1e8, nu = 0.3, rho = 2000.0, H = 10.0;
  ModelParams p;
  p.materials = {MaterialGroup{elastic(E, nu, rho), std::nullopt}};
  p.mode = Mode::kStatic;
  p.gravity_level = N;
  Model model(generate_mesh(MeshParams::plain_box(0.5, 0.5, H, 0.5)), p);
  ColumnResult r;
  while (model.ratios().average > 1e-9 && model.step_count() < 50000) model.step(100);
  r.steps = model.step_count();
  r.ratio = model.ratios().average;
  const auto mc = make_constants(elastic(E, nu, rho));
  const double g = N * kStandardGravity;
  const auto s = model.zone_stress();
  const auto conn = model.connectivity();
  for (std::size_t z = 0; z < model.num_zones(); ++z) {
    double zc = 0.0;
    for (int k = 0; k < 8; ++k) zc += model.mesh().points[3 * conn[8 * z + k] + 2] / 8.0;
    const double szz = -rho * g * (H - zc);
    r.worst_szz = std::max(r.worst_szz, std::abs(s[6 * z + 2] - szz) / std::abs(szz));
    r.worst_sxx = std::max(r.worst_sxx, std::abs(s[6 * z + 0] - nu / (1 - nu) * szz) / std::abs(nu / (1 - nu) * szz));
  }
  const double utop = -rho * g * H * H / (2.0 * mc.alpha1);
  const auto top = model.gridpoints_on_plane(2, H);
  for (std::int32_t gp : top) r.utop_error = std::max(r.utop_error, std::abs(model.displacements()[3 * gp + 2] - utop) / std::abs(utop));
  const double weight = rho * 0.5 * 0.5 * H * g;
  r.weight_error = std::abs(model.base_reaction()[2] - weight) / weight;
  return r;
}

TEST(ElasticColumn, OneG) {
  const auto r = run_column(1.0);
  EXPECT_LT(r.ratio, 1e-9);
  EXPECT_LT(r.worst_szz, 0.01);
  EXPECT_LT(r.worst_sxx, 0.01);
  EXPECT_LT(r.utop_error, 0.01);
  EXPECT_LT(r.weight_error, 1e-3);
  RecordProperty("steps", std::to_string(r.steps));
  std::printf("column 1g: steps %lld  szz %.2e  sxx %.2e  utop %.2e  weight %.2e\n",
              static_cast<long long>(r.steps), r.worst_szz, r.worst_sxx, r.utop_error, r.weight_error);
}

TEST(ElasticColumn, FiftyG) {
  const auto r = run_column(50.0);
  EXPECT_LT(r.ratio, 1e-9);
  EXPECT_LT(r.worst_szz, 0.01);
  EXPECT_LT(r.worst_sxx, 0.01);
  EXPECT_LT(r.utop_error, 0.01);
  EXPECT_LT(r.weight_error, 1e-3);
  std::printf("column 50g: steps %lld  szz %.2e  sxx %.2e  utop %.2e  weight %.2e\n",
              static_cast<long long>(r.steps), r.worst_szz, r.worst_sxx, r.utop_error, r.weight_error);
}

// Surface loads: a pressure p on the top of a rollered column (4 zones high) equals point loads
// of p A / 4 on the top gridpoints, and both give the uniaxial-strain settlement
// u_top = -p H / (K + 4G/3) within 1e-6 (static mode).
TEST(SurfaceLoads, PressureAndPointLoadsOnColumn) {
  const double E = 1e8, nu = 0.3, p = 2e5, H = 2.0;
  double settle[2];
  for (int variant = 0; variant < 2; ++variant) {
    ModelParams mp;
    mp.materials = {MaterialGroup{elastic(E, nu, 2000.0), std::nullopt}};
    mp.mode = Mode::kStatic;
    mp.gravity_level = 0.0;
    Model model(generate_mesh(MeshParams::plain_box(0.5, 0.5, H, 0.5)), mp);
    const auto top = model.gridpoints_on_plane(2, H);
    ASSERT_EQ(top.size(), 4u);
    if (variant == 0) {
      std::vector<BoundaryFace> faces;
      for (const auto& f : boundary_faces(model.mesh()))
        if (f.side == Side::kPlusZ) faces.push_back(f);
      model.add_face_pressure(faces, p);
    } else {
      for (std::int32_t g : top) model.add_point_load(g, {0.0, 0.0, -p * 0.25 / 4.0});
    }
    while (model.ratios().average > 1e-10 && model.step_count() < 20000) model.step(100);
    settle[variant] = model.displacements()[3 * top[0] + 2];
    EXPECT_NEAR(model.base_reaction()[2], p * 0.25, 1e-6 * p * 0.25);
  }
  const double M = make_constants(elastic(E, nu, 2000.0)).alpha1;
  EXPECT_NEAR(settle[0], -p * H / M, 1e-6 * p * H / M);
  EXPECT_NEAR(settle[1], settle[0], 1e-9 * p * H / M);
}

// 1-D compression wave in a rollered column, dynamic mode, no damping (docs/theory.md 8.12): the
// half-amplitude front of a smooth base pulse travels between z = 5 m and z = 15 m at
// C_p = sqrt((K + 4G/3)/rho) within 2 %.
TEST(WaveSpeed, RolleredColumnCompressionWave) {
  const double E = 1e8, nu = 0.25, rho = 2000.0;
  ModelParams p;
  p.materials = {MaterialGroup{elastic(E, nu, rho), std::nullopt}};
  p.gravity_level = 0.0;
  p.damping = 0.0;
  p.strongbox_boundary = false;
  Model model(generate_mesh(MeshParams::plain_box(0.1, 0.1, 30.0, 0.1)), p);
  // Rollers on all four sides; the base carries the prescribed pulse.
  for (std::int32_t g : model.gridpoints_on_plane(0, 0.0)) model.fix_velocity(g, kFixX);
  for (std::int32_t g : model.gridpoints_on_plane(0, 0.1)) model.fix_velocity(g, kFixX);
  for (std::int32_t g : model.gridpoints_on_plane(1, 0.0)) model.fix_velocity(g, kFixY);
  for (std::int32_t g : model.gridpoints_on_plane(1, 0.1)) model.fix_velocity(g, kFixY);
  const auto base = model.gridpoints_on_plane(2, 0.0);
  const double cp = std::sqrt(make_constants(elastic(E, nu, rho)).alpha1 / rho);
  const double T = 2.0 / cp, v0 = 1e-3;
  const double zs[3] = {5.0, 10.0, 15.0};
  std::int32_t probe[3];
  for (int i = 0; i < 3; ++i) probe[i] = model.gridpoints_on_plane(2, zs[i]).front();
  double arrival[3] = {-1, -1, -1};
  double prev[3] = {0, 0, 0};
  while (model.time() < 15.0 / cp + 2.0 * T) {
    const double t = model.time() + 0.5 * model.timestep();  // velocities live at half steps
    const double s = t < T ? std::sin(std::numbers::pi * t / T) : 0.0;
    for (std::int32_t g : base) model.fix_velocity(g, kFixAll, {0.0, 0.0, v0 * s * s});
    model.step();
    for (int i = 0; i < 3; ++i) {
      const double v = model.velocities()[3 * probe[i] + 2];
      if (arrival[i] < 0 && v >= 0.5 * v0) {
        const double tn = model.time() - 0.5 * model.timestep();
        arrival[i] = tn - model.timestep() * (v - 0.5 * v0) / (v - prev[i]);
      }
      prev[i] = v;
    }
  }
  ASSERT_GT(arrival[0], 0.0);
  ASSERT_GT(arrival[2], 0.0);
  const double c13 = (zs[2] - zs[0]) / (arrival[2] - arrival[0]);
  const double c12 = (zs[1] - zs[0]) / (arrival[1] - arrival[0]);
  EXPECT_NEAR(c13 / cp, 1.0, 0.02);
  EXPECT_NEAR(c12 / cp, 1.0, 0.02);
  std::printf("wave: C_p %.3f m/s, measured %.3f (5-15 m) %.3f (5-10 m)\n", cp, c13, c12);
}

// Static equilibrium of the graded pocket mesh under gravity from geostatic stresses
// (docs/theory.md 5.9, 5.11, 6.9): R_avg falls below 1e-5, the kinetic energy has decayed, and the
// base reactions carry the total weight within 0.1 %.
TEST(StaticEquilibrium, PocketMeshUnderGravity) {
  ModelParams p;
  p.mesh = test::small_pocket_params();
  p.materials = {MaterialGroup{elastic(1e8, 0.3, 2000.0), std::nullopt}};
  p.mode = Mode::kStatic;
  p.gravity_level = 1.0;
  Model model(p);
  model.set_geostatic_stress({});
  const double r0 = model.ratios().average;
  model.step(20);
  const double ke_early = model.kinetic_energy();
  while (model.ratios().average > 1e-6 && model.step_count() < 20000) model.step(50);
  EXPECT_LT(model.ratios().average, 1e-5);
  EXPECT_LT(model.ratios().max, 1e-3);
  EXPECT_LT(model.kinetic_energy(), 1e-3 * ke_early);
  const double weight = model.total_gravitational_mass() * kStandardGravity;
  EXPECT_NEAR(model.base_reaction()[2], weight, 1e-3 * weight);
  EXPECT_NEAR(model.total_gravitational_mass(), 2000.0 * (64.0 - 2.0), 1e-6);
  std::printf("pocket equilibrium: R_avg %.2e -> %.2e in %lld steps, R_local %.2e\n", r0, model.ratios().average,
              static_cast<long long>(model.step_count()), model.ratios().local);
  model.reset_displacements();
  for (double u : model.displacements()) EXPECT_EQ(u, 0.0);
}

// Global balance with coupling forces on fixed gridpoints: the pocket touches the x = 0 wall,
// so some interface gridpoints are roller-fixed in x. With uniform interface forces, at
// equilibrium the reactions of all supports cancel the total applied force within 0.1 %.
TEST(InterfaceForces, ReactionsBalanceWhenInterfaceTouchesSupports) {
  ModelParams p;
  p.mesh = test::small_pocket_params();
  p.mesh.inner_origin = {0.0, 1.5, kNaN};
  p.materials = {MaterialGroup{elastic(1e8, 0.3, 2000.0), std::nullopt}};
  p.mode = Mode::kStatic;
  p.gravity_level = 0.0;
  Model model(p);
  const std::size_t nif = model.interface_gridpoints().size();
  bool touches = false;
  for (std::int32_t g : model.interface_gridpoints()) touches = touches || model.positions()[3 * g] == 0.0;
  ASSERT_TRUE(touches);
  std::vector<double> f(3 * nif);
  for (std::size_t l = 0; l < nif; ++l) {
    f[3 * l] = 1e3;
    f[3 * l + 1] = -2e3;
    f[3 * l + 2] = -5e3;
  }
  model.set_interface_forces(f);
  while (model.ratios().average > 1e-7 && model.step_count() < 20000) model.step(100);
  std::vector<std::int32_t> all(model.num_gridpoints());
  for (std::size_t g = 0; g < all.size(); ++g) all[g] = static_cast<std::int32_t>(g);
  const Vec3 r = model.reaction_sum(all);
  const double n = static_cast<double>(nif);
  EXPECT_NEAR(r[0], -1e3 * n, 1e-3 * 5e3 * n);
  EXPECT_NEAR(r[1], 2e3 * n, 1e-3 * 5e3 * n);
  EXPECT_NEAR(r[2], 5e3 * n, 1e-3 * 5e3 * n);
}

// Option A vs option B (docs/theory.md 6.6): the same interface load solved in dynamic mode (real
// masses, physical dt, local damping 0.8) and in static mode (mass-scaled, dt = 1) reaches the
// same equilibrium: interface displacements agree within 1e-4 of the largest one.
TEST(ModeCrossCheck, DynamicAndStaticReachSameEquilibrium) {
  std::vector<double> u[2];
  for (int mode = 0; mode < 2; ++mode) {
    ModelParams p;
    p.mesh = test::small_pocket_params();
    p.materials = {MaterialGroup{elastic(1e8, 0.3, 2000.0), std::nullopt}};
    p.mode = mode == 0 ? Mode::kDynamic : Mode::kStatic;
    p.gravity_level = 0.0;
    Model model(p);
    std::vector<double> f(3 * model.interface_gridpoints().size(), 0.0);
    for (std::size_t l = 0; l < f.size() / 3; ++l) f[3 * l + 2] = -1e3;  // downward on every interface point
    model.set_interface_forces(f);
    while (model.ratios().average > 1e-7 && model.step_count() < 200000) model.step(100);
    EXPECT_LT(model.ratios().average, 1e-7) << (mode == 0 ? "dynamic" : "static");
    u[mode] = model.interface_displacements();
    std::printf("%s: %lld steps\n", mode == 0 ? "dynamic" : "static", static_cast<long long>(model.step_count()));
  }
  double umax = 0.0, diff = 0.0;
  for (std::size_t i = 0; i < u[0].size(); ++i) {
    umax = std::max(umax, std::abs(u[1][i]));
    diff = std::max(diff, std::abs(u[0][i] - u[1][i]));
  }
  EXPECT_GT(umax, 0.0);
  EXPECT_LT(diff, 1e-4 * umax);
  std::printf("max |u_dyn - u_static| / max |u| = %.2e\n", diff / umax);
}

// Dead-load check on the paper's geometry (docs/theory.md 6.9, 4.10), FDM side only, 100 g: the
// 16 mm box with the 4 x 4 x 10 mm pocket (1 mm zones next to it), geostatic stresses from the
// surface z = 16 mm, and the DEM block replaced by the forces it would exert through the
// interface triangles: rho N g0 depth on the floor, K0 times that on the walls. The model starts
// close to equilibrium and converges; the base reactions then carry the weight of the FDM
// zones plus the DEM block, (rho_b V_DEM + rho V_FDM) N g0, within 0.1 %.
TEST(DeadLoad, PaperGeometryWithDemWeightOnInterface) {
  const double rho = 1272.0, N = 100.0, nu = 0.25;
  ModelParams p;  // default mesh geometry (docs/theory.md 0.3, 5.1)
  p.mesh.size_near = 1e-3;
  p.mesh.size_far = 3e-3;
  p.materials = {MaterialGroup{elastic(2e9, nu, rho), std::nullopt}};
  p.mode = Mode::kStatic;
  p.gravity_level = N;
  Model model(p);
  model.set_geostatic_stress({});
  const double k0 = nu / (1.0 - nu), g = N * kStandardGravity, ztop = 16e-3;
  const auto tri = model.interface_triangles();
  const auto xi = model.interface_positions();
  std::vector<double> f(xi.size(), 0.0);
  for (std::size_t t = 0; t < tri.size() / 3; ++t) {
    Vec3 q[3];
    for (int c = 0; c < 3; ++c)
      for (int d = 0; d < 3; ++d) q[c][d] = xi[3 * tri[3 * t + c] + d];
    const Vec3 n = cross(sub(q[1], q[0]), sub(q[2], q[0]));  // 2 * area * normal into the pocket
    const double depth = ztop - (q[0][2] + q[1][2] + q[2][2]) / 3.0;
    const bool floor = model.mesh().interface_triangle_side[t] == static_cast<std::int8_t>(Side::kPlusZ);
    const double pressure = (floor ? 1.0 : k0) * rho * g * depth;
    for (int c = 0; c < 3; ++c)
      for (int d = 0; d < 3; ++d) f[3 * tri[3 * t + c] + d] += -pressure * 0.5 * n[d] / 3.0;
  }
  model.set_interface_forces(f);
  const double r0 = model.ratios().average;
  while (model.ratios().average > 1e-6 && model.step_count() < 20000) model.step(50);
  EXPECT_LT(r0, 1e-3);  // geostatic stresses and interface pressures nearly balance at the start
  EXPECT_LT(model.ratios().average, 1e-5);
  const double v_dem = 4e-3 * 4e-3 * 10e-3, v_fdm = 16e-3 * 16e-3 * 16e-3 - v_dem;
  const double weight = rho * (v_dem + v_fdm) * g;
  EXPECT_NEAR(model.base_reaction()[2], weight, 1e-3 * weight);
  std::printf("dead load: %zu zones, R_avg %.1e -> %.1e in %lld steps, base/weight - 1 = %.1e\n", model.num_zones(), r0,
              model.ratios().average, static_cast<long long>(model.step_count()), model.base_reaction()[2] / weight - 1.0);
}

// Coupling forces (docs/theory.md 6.4, 6.9): a uniform pressure p applied through the interface
// triangles (area/3 to each vertex, towards the FDM) is carried to the base: the vertical base
// reaction equals p times the pocket bottom area within 0.1 %, and the pocket floor settles.
TEST(InterfaceForces, PressureOnPocketReachesBase) {
  ModelParams p;
  p.mesh = test::small_pocket_params();
  p.materials = {MaterialGroup{elastic(1e8, 0.3, 2000.0), std::nullopt}};
  p.mode = Mode::kStatic;
  p.gravity_level = 0.0;
  p.history_every = 100;
  Model model(p);
  const double pressure = 1e5;
  const auto tri = model.interface_triangles();
  const auto xi = model.interface_positions();
  std::vector<double> f(xi.size(), 0.0);
  for (std::size_t t = 0; t < tri.size() / 3; ++t) {
    Vec3 q[3];
    for (int c = 0; c < 3; ++c)
      for (int d = 0; d < 3; ++d) q[c][d] = xi[3 * tri[3 * t + c] + d];
    const Vec3 n = cross(sub(q[1], q[0]), sub(q[2], q[0]));  // 2 * area * normal into the pocket
    for (int c = 0; c < 3; ++c)
      for (int d = 0; d < 3; ++d) f[3 * tri[3 * t + c] + d] += -pressure * 0.5 * n[d] / 3.0;
  }
  model.set_interface_forces(f);
  while (model.ratios().average > 1e-7 && model.step_count() < 20000) model.step(100);
  const double load = pressure * 1.0 * 1.0;  // pocket bottom 1 m x 1 m
  EXPECT_NEAR(model.base_reaction()[2], load, 1e-3 * load);
  // Global balance over every support (base and side rollers): reactions = -applied.
  std::vector<std::int32_t> all(model.num_gridpoints());
  for (std::size_t g = 0; g < all.size(); ++g) all[g] = static_cast<std::int32_t>(g);
  const Vec3 total = model.reaction_sum(all);
  EXPECT_NEAR(total[0], 0.0, 1e-3 * load);
  EXPECT_NEAR(total[1], 0.0, 1e-3 * load);
  EXPECT_NEAR(total[2], load, 1e-3 * load);
  const auto u = model.interface_displacements();
  const auto x = model.interface_positions();
  const double zb = model.mesh().pocket.lo[2];
  for (std::size_t l = 0; l < u.size() / 3; ++l)
    if (std::abs(x[3 * l + 2] - u[3 * l + 2] - zb) < 1e-12) {
      EXPECT_LT(u[3 * l + 2], 0.0);
    }
  ASSERT_FALSE(model.history().empty());
  EXPECT_EQ(model.history().back().step % 100, 0);
  EXPECT_NEAR(model.history().back().base_reaction[2], load, 2e-2 * load);
}

}  // namespace
}  // namespace demfdm::fdm
