// The ball store of the DEM (docs/theory.md 1.1): structure of arrays, one row per ball, flat
// arrays the hot loops read directly. Rows move (World::reorder_spatially); a ball's identity is
// its stable id, which keys every contact history.
#pragma once

#include <cstdint>
#include <vector>

#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

/// Degree-of-freedom fixity bits (§1.2: a fixed component keeps its prescribed velocity).
enum Fix : std::uint8_t {
  kFixVx = 1, kFixVy = 2, kFixVz = 4, kFixWx = 8, kFixWy = 16, kFixWz = 32,
  kFixVel = 7, kFixRot = 56, kFixAll = 63,
};

/// SoA particle store. Every array has one row per ball; Vec3 arrays are flat [n,3].
struct Particles {
  std::vector<Vec3> x;    // [m] position
  std::vector<Vec3> v;    // [m/s] velocity (half step)
  std::vector<Vec3> w;    // [rad/s] angular velocity (half step)
  std::vector<Vec3> f;    // [N] contact + body force of the last force pass
  std::vector<Vec3> t;    // [N m] contact torque of the last force pass
  std::vector<Vec3> fa;   // [N] applied force (user)
  std::vector<Vec3> ta;   // [N m] applied moment (user)
  std::vector<Vec3> x_ref;  // [m] position at the last neighbour rebuild
  std::vector<double> r;  // [m] radius
  std::vector<double> m;  // [kg] mass
  std::vector<double> inertia;  // [kg m^2] moment of inertia (2/5) m R²
  std::vector<std::uint64_t> id;  // stable id
  std::vector<std::uint8_t> fix;  // Fix bits
  std::size_t size() const { return x.size(); }

  /// Append a ball at rest of radius r and density rho (a solid sphere); returns its row.
  std::size_t add(const Vec3& x0, double radius, double rho, std::uint64_t ball_id);
  /// Change a ball's radius at its density: mass and moment of inertia follow.
  void set_radius(std::size_t i, double radius);
  /// Move every row i to new_row[i] (a permutation of the rows).
  void permute(const std::vector<std::uint32_t>& new_row);
};

/// Rows in a space-filling (Morton) order of cells of size 2 R_max, as new_row[old_row]:
/// neighbours end up close in memory (cache locality of the contact loop).
std::vector<std::uint32_t> morton_rows(const Particles& pt);

}  // namespace demfdm::dem
