// Long FDM checks (label `long`): Boussinesq stresses under a circular load (docs/theory.md 8.14,
// about 10 s) and the rigid circular footing on the finest affordable mesh (docs/theory.md 8.13):
// a/8 under the footing, half-width and depth 30 a (27,000 zones, about 6,800 static steps,
// about 3 minutes on one core). Tolerance 5 % against K = 2aE/(1 - nu^2).
// Measured (K / K_half-space):   extent 15 a   extent 30 a
//                        a/4       1.023         0.994
//                        a/8       1.045         1.017
// Doubling the extent removes about 2.8 % of stiffness on both meshes: that part is the fixed
// base and walls of the finite box (docs/theory.md 8.13 expects a few per cent).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "footing_util.hpp"

namespace demfdm::fdm {
namespace {

TEST(RigidFootingLong, FineMeshWithinFivePercent) {
  const auto r = test::run_footing(8, 30.0, 1e-3);
  std::printf("footing a/8 extent 30: K/K0 %.4f (%zu zones, %lld steps, R_avg %.1e)\n", r.ratio, r.zones,
              static_cast<long long>(r.steps), r.r_avg);
  EXPECT_NEAR(r.ratio, 1.0, 0.05);
}

}  // namespace
}  // namespace demfdm::fdm

namespace demfdm::fdm {
namespace {

// sigma_zz of a uniform pressure p on the disc r <= a of a half-space at (r, depth z), from the
// point-load solution -3 P z^3 / (2 pi R^5) (docs/theory.md 8.14) integrated over the disc
// (midpoint rule, 400 x 720); on the axis it gives -p [1 - (1 + (a/z)^2)^(-3/2)].
double boussinesq_disc_szz(double p, double a, double r, double z) {
  const int nr = 400, nt = 720;
  double sum = 0.0;
  for (int i = 0; i < nr; ++i) {
    const double rho = (i + 0.5) * a / nr;
    for (int j = 0; j < nt; ++j) {
      const double t = (j + 0.5) * 2.0 * std::numbers::pi / nt;
      const double dx = rho * std::cos(t) - r, dy = rho * std::sin(t);
      const double R2 = dx * dx + dy * dy + z * z;
      sum += rho / (R2 * R2 * std::sqrt(R2));
    }
  }
  const double dA = (a / nr) * (2.0 * std::numbers::pi / nt);
  return -3.0 * p * z * z * z / (2.0 * std::numbers::pi) * sum * dA;
}

// Boussinesq (docs/theory.md 8.14): uniform pressure p over the circle r <= a on the same quarter
// model (a/4 zones, extent 20 a). In the column of zones next to the axis (centroids at
// r = 0.18 a), the zone sigma_zz matches the half-space value at the centroid within 5 % for
// a/z in [0.2, 2] (z up to 5 a, well above the fixed base at 20 a); the quadrature itself is
// checked against the closed form on the axis.
TEST(Boussinesq, UniformCircularLoadAxisStress) {
  const double a = 1.0, p = 1e5, extent = 20.0;
  Model model(test::quarter_model_params(4, extent));
  // Each top face carries p times the fraction of its area inside the circle (20 x 20
  // sub-samples), so the load follows the circle to within the sampling.
  for (const auto& f : boundary_faces(model.mesh())) {
    if (f.side != Side::kPlusZ) continue;
    const double* p0 = &model.positions()[3 * f.points[0]];
    const double* p2 = &model.positions()[3 * f.points[2]];
    if (std::abs(p0[2] - extent * a) > 1e-9) continue;
    const double x0 = std::min(p0[0], p2[0]), x1 = std::max(p0[0], p2[0]);
    const double y0 = std::min(p0[1], p2[1]), y1 = std::max(p0[1], p2[1]);
    if (std::hypot(x0, y0) >= a) continue;
    int inside = 0;
    for (int i = 0; i < 20; ++i)
      for (int j = 0; j < 20; ++j)
        inside += std::hypot(x0 + (i + 0.5) / 20.0 * (x1 - x0), y0 + (j + 0.5) / 20.0 * (y1 - y0)) < a ? 1 : 0;
    model.add_face_pressure(std::span<const BoundaryFace>(&f, 1), p * inside / 400.0);
  }
  while (model.ratios().average > 1e-4 && model.step_count() < 100000) model.step(200);
  const auto s = model.zone_stress();
  const auto& mesh = model.mesh();
  int checked = 0;
  double worst = 0.0;
  for (std::size_t z = 0; z < model.num_zones(); ++z) {
    if (mesh.zone_ijk[3 * z] != 0 || mesh.zone_ijk[3 * z + 1] != 0) continue;
    double zc = 0.0;
    for (int k = 0; k < 8; ++k) zc += mesh.points[3 * mesh.zones[8 * z + k] + 2] / 8.0;
    const double depth = extent * a - zc;
    if (a / depth > 2.0 || a / depth < 0.2) continue;
    double cx = 0.0, cy = 0.0;
    for (int k = 0; k < 8; ++k) {
      cx += mesh.points[3 * mesh.zones[8 * z + k]] / 8.0;
      cy += mesh.points[3 * mesh.zones[8 * z + k] + 1] / 8.0;
    }
    const double axis = -p * (1.0 - std::pow(1.0 + (a / depth) * (a / depth), -1.5));
    EXPECT_NEAR(boussinesq_disc_szz(p, a, 0.0, depth), axis, 1e-4 * std::abs(axis));
    const double exact = boussinesq_disc_szz(p, a, std::hypot(cx, cy), depth);
    const double err = std::abs(s[6 * z + 2] - exact) / std::abs(exact);
    worst = std::max(worst, err);
    EXPECT_LT(err, 0.05) << "depth " << depth;
    std::printf("  z/a %.3f  sigma_zz/p %.4f  exact %.4f  axis %.4f\n", depth / a, s[6 * z + 2] / p, exact / p, axis / p);
    ++checked;
  }
  EXPECT_GE(checked, 5);
  std::printf("Boussinesq: %d zones on the axis, worst error %.2f %%, %lld steps\n", checked, 100.0 * worst,
              static_cast<long long>(model.step_count()));
}

}  // namespace
}  // namespace demfdm::fdm
