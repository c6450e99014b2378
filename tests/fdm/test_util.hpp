// Shared helpers for the FDM tests.
#pragma once

#include <random>
#include <set>

#include "demfdm/fdm/mesh.hpp"
#include "demfdm/fdm/model.hpp"

namespace demfdm::fdm::test {

// Small graded mesh with an off-centre pocket (irregular zone sizes), 4 m box.
inline MeshParams small_pocket_params() {
  MeshParams p;
  p.length = 4.0;
  p.width = 4.0;
  p.height = 4.0;
  p.inner_size = {1.0, 1.0, 2.0};
  p.inner_origin = {1.0, 1.5, kNaN};
  p.size_near = 0.5;
  p.size_far = 1.0;
  p.growth = 1.2;
  return p;
}

// Gridpoints on the outer boundary or on the pocket faces.
inline std::set<std::int32_t> boundary_points(const Mesh& m) {
  std::set<std::int32_t> b;
  for (const auto& f : boundary_faces(m)) b.insert(f.points.begin(), f.points.end());
  return b;
}

// Moves every gridpoint that is not on a boundary face by up to +-amp in each direction.
inline void perturb_interior(Mesh& m, double amp, unsigned seed) {
  const auto b = boundary_points(m);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-amp, amp);
  for (std::size_t g = 0; g < m.num_points(); ++g) {
    if (b.count(static_cast<std::int32_t>(g))) continue;
    for (int d = 0; d < 3; ++d) m.points[3 * g + d] += u(rng);
  }
}

inline Material elastic(double E, double nu, double rho) {
  Material m;
  m.young = E;
  m.poisson = nu;
  m.density = rho;
  return m;
}

}  // namespace demfdm::fdm::test
