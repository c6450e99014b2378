// Blow-up guard of the DEM (issue 7 item 4, docs/stability.md): cheap O(n) scans of the ball
// state after a step, and a detailed report (the offending ball or contact, its position and
// values, and its neighbourhood) built only when a scan finds something.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "demfdm/dem/world.hpp"

namespace demfdm::dem {

struct GuardFinding {
  std::string cause;       // one line: what, which object, its value
  std::string detail;      // multi-line: where, values, neighbourhood
  std::size_t row = 0;     // ball row of the offending ball (or ball A of the contact)
  std::uint64_t id = 0;    // its stable id
  bool contact = false;    // a ball-ball contact was named (ids in cause/detail)
  std::uint64_t other_id = 0;  // ball B of that contact
};

/// First ball with a non-finite position, velocity, spin, force or torque (rows in order); if
/// its force is non-finite, the first of its ball-ball contacts with a non-finite force is
/// named too (pair ids and contact model). O(n) when everything is finite.
std::optional<GuardFinding> check_finite(const World& w, std::size_t neighbours = 10);

/// First ball whose centre lies more than `margin` outside the box [lo, hi].
std::optional<GuardFinding> check_escape(const World& w, const Vec3& lo, const Vec3& hi, double margin,
                                         std::size_t neighbours = 10);

/// The guard's per-step tests and the kinetic energy in one parallel pass over the balls (the
/// three read the same rows): `finite` is false where check_finite would find something (a ball
/// value or the footing reaction), `outside` is the largest distance of a centre outside [lo, hi]
/// (0 inside; not computed without `box`), and `kinetic` is World::kinetic_energy() with its bits
/// (its terms, summed in row order from +0). `scratch` holds the per-ball terms between calls.
/// The reports themselves come from check_finite and check_escape, called only on a finding.
struct BallScreen {
  bool finite = true;
  double outside = 0.0;  // [m]
  double kinetic = 0.0;  // [J]
};
BallScreen screen_balls(const World& w, const Vec3& lo, const Vec3& hi, bool box, std::vector<double>& scratch);
/// The same tests over every row of a rank's World (dem_node/dist), one thread; the kinetic
/// energy terms of the rows not marked in `ghost` (every row if it is empty) are written to
/// `terms` in row order instead of summed (`kinetic` stays 0).
BallScreen screen_rows(const World& w, const Vec3& lo, const Vec3& hi, bool box, const std::vector<std::uint8_t>& ghost,
                       std::vector<double>& terms);

/// The `k` balls nearest to ball `row` (minimum image in a periodic cell), one line each:
/// id, distance, position, radius, velocity, force.
std::string neighbourhood(const World& w, std::size_t row, std::size_t k);

/// One line describing ball `row`: id, position, radius, velocity, spin, force, torque, fixity.
std::string describe_ball(const World& w, std::size_t row);

}  // namespace demfdm::dem
