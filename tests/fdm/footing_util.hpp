// Rigid circular footing on an elastic layer (docs/theory.md 8.13), quarter model.
// The footing of radius a sits at the corner x = y = 0 of the top surface; x = 0 and y = 0 are
// symmetry planes (rollers), the far sides are rollers, the base is fixed. The footing's top
// gridpoints (r <= a) get a uniform vertical displacement delta (smooth footing: x, y free);
// static mode cycles to equilibrium and the reaction gives K = 4 R_z / delta, compared with the
// half-space value K = 2 a E / (1 - nu^2).
#pragma once

#include <cmath>
#include <cstdio>

#include "demfdm/fdm/model.hpp"

namespace demfdm::fdm::test {

struct FootingResult {
  double ratio = 0.0;        // K_numerical / K_half-space
  std::size_t zones = 0;
  std::int64_t steps = 0;
  double r_avg = 0.0;
};

// zones_per_radius: zone size a / zones_per_radius under the footing; extent: half-width and
// depth of the model in footing radii.
// Quarter-model parameters: radius a = 1 m, zones a/zones_per_radius in [0,a]^2 x [H-a, H],
// graded (1.2, at most 4a) to the extent; E = 1e8 Pa, nu = 0.3, static mode, no gravity.
inline ModelParams quarter_model_params(int zones_per_radius, double extent) {
  const double a = 1.0, E = 1e8, nu = 0.3;
  ModelParams p;
  p.mesh.length = extent * a;
  p.mesh.width = extent * a;
  p.mesh.height = extent * a;
  p.mesh.inner_size = {a, a, a};
  p.mesh.inner_origin = {0.0, 0.0, extent * a - a};
  p.mesh.pocket = false;  // refinement box only
  p.mesh.size_near = a / zones_per_radius;
  p.mesh.size_far = 4.0 * a;
  p.mesh.growth = 1.2;
  Material m;
  m.young = E;
  m.poisson = nu;
  p.materials = {MaterialGroup{m, std::nullopt}};
  p.mode = Mode::kStatic;
  p.gravity_level = 0.0;
  p.strongbox_boundary = true;  // fixed base, rollers on all four sides (incl. symmetry planes)
  return p;
}

inline FootingResult run_footing(int zones_per_radius, double extent, double tolerance = 1e-4) {
  const double a = 1.0, E = 1e8, nu = 0.3, delta = 1e-4;
  Model model(quarter_model_params(zones_per_radius, extent));
  std::vector<std::int32_t> footing;
  for (std::int32_t g : model.gridpoints_on_plane(2, extent * a)) {
    const double x = model.positions()[3 * g], y = model.positions()[3 * g + 1];
    if (std::hypot(x, y) <= a * (1.0 + 1e-9)) footing.push_back(g);
  }
  // Static mode: velocity = displacement per step. One step moves the footing by delta.
  for (std::int32_t g : footing) model.fix_velocity(g, kFixZ, {0.0, 0.0, -delta});
  model.step();
  for (std::int32_t g : footing) model.fix_velocity(g, kFixZ, {0.0, 0.0, 0.0});
  double last = 0.0;
  while (model.step_count() < 200000) {
    model.step(200);
    const double rz = model.reaction_sum(footing)[2];
    // Converged when the reaction changes by less than tolerance/10 over 200 steps and the
    // average ratio is small.
    if (std::abs(rz - last) < 0.1 * tolerance * std::abs(rz) && model.ratios().average < tolerance) break;
    last = rz;
  }
  FootingResult r;
  const double K = 4.0 * -model.reaction_sum(footing)[2] / delta;
  r.ratio = K / (2.0 * a * E / (1.0 - nu * nu));
  r.zones = model.num_zones();
  r.steps = model.step_count();
  r.r_avg = model.ratios().average;
  return r;
}

}  // namespace demfdm::fdm::test
