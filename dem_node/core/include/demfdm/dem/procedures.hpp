// Stage procedures and diagnostics of the DEM node that need no scene and no bus (issue 15 item 4:
// the node executable only adapts messages and scene keys to these calls). Each is unit-tested in
// tests/dem/procedures_test.cpp.
#pragma once

#include <cmath>
#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "demfdm/dem/guard.hpp"
#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"
#include "demfdm/io/state_file.hpp"

namespace demfdm::dem {

/// Unbalanced-force ratio of the load-bearing skeleton under gravity (docs/paper-study.md): the
/// engine's ratio (mean |F_unb| over balls / mean contact force) without the rattlers, the balls
/// whose contact force is exactly zero (their whole force is their weight: under local damping a
/// rattler in a pore falls for far longer than the skeleton needs to settle, and would keep the
/// engine's ratio at about rattler share x weight / mean contact force). Fixed components do not
/// count. Infinite when no ball carries a contact force.
struct SkeletonRatio {
  double ratio = 0.0;
  std::size_t rattlers = 0;
};
SkeletonRatio skeleton_ratio(const World& w);
/// The same with the mean contact force of this state given (World::mean_contact_force()).
SkeletonRatio skeleton_ratio(const World& w, double mean_contact_force);
/// Its parts, for sums formed elsewhere (DistDem::skeleton_ratio): whether ball i is a rattler
/// (no contact force), its term (its unbalanced force, +0 for a rattler), and the ratio from the
/// sum of the terms and the count of rattlers.
bool is_rattler(const World& w, std::size_t i);
double skeleton_term(const World& w, std::size_t i);
/// The same with the World's gravity g = w.gravity() given (a loop over the balls reads it once).
bool is_rattler(const World& w, std::size_t i, const Vec3& g);
double skeleton_term(const World& w, std::size_t i, const Vec3& g);
SkeletonRatio skeleton_ratio_of(double sum, std::size_t rattlers, std::size_t balls, double mean_contact_force);

/// The engine's unbalanced-force ratio (World::unbalanced_ratio) and the skeleton ratio of one
/// state, with its mean contact force given. A ball's skeleton term is its unbalanced force (+0
/// for a rattler), so on one thread, without order-free sums, one pass over the balls forms both
/// sums, each in row order, with one root per ball: the bits of the two functions called one
/// after the other (which is what the other cases do).
struct BallRatios {
  double unbalanced = 0.0;
  SkeletonRatio skeleton;
};
BallRatios ball_ratios(const World& w, double mean_contact_force);
namespace detail {
// The two formulas of the skeleton ratio, written once: whether ball i is a rattler (its contact
// part of the force, F + F_a - m g, is zero; F + F_a left in f) and its term |F + F_a| over the
// free axes.
[[gnu::always_inline]] inline bool rattler_of(const Particles& b, std::size_t i, const Vec3& g, Vec3& f) {
  f = b.f[i] + b.fa[i];
  const Vec3 c = f - b.m[i] * g;  // contact part of the force
  return c.x == 0 && c.y == 0 && c.z == 0;
}
[[gnu::always_inline]] inline double term_of(const Particles& b, std::size_t i, const Vec3& f) {
  double s2 = 0;
  for (int k = 0; k < 3; ++k)
    if (!(b.fix[i] & (1u << k))) s2 += f[k] * f[k];
  return std::sqrt(s2);
}
}  // namespace detail
/// Ball i's terms of both ratios, as ball_ratios forms them: returns its unbalanced force
/// (World::unbalanced_force_of, bit for bit) and sets `rattler` (is_rattler with gravity g); its
/// skeleton term is +0 for a rattler, else the same value.
[[gnu::always_inline]] inline double unbalanced_term(const World& w, std::size_t i, const Vec3& g, bool& rattler) {
  Vec3 f;
  rattler = detail::rattler_of(w.balls(), i, g, f);  // f = F + F_a, as World::unbalanced_force_of forms it
  return detail::term_of(w.balls(), i, f);
}

/// One horizontal slab of a vertical stress profile: particle-based stress (region_stress) of the
/// balls whose centres lie in the slab, depth measured down from the block top.
struct ProfileSlab {
  double depth = 0, depth_top = 0, depth_bottom = 0;  // [m] slab centre, top, bottom
  double szz = 0, sxx = 0, syy = 0;                   // [Pa] tension positive
  std::size_t balls = 0;                              // centres inside the slab
};
/// The box x in [x_lo, x_hi], y in [y_lo, y_hi], from z_top down `height`, cut into `slabs` equal
/// horizontal slabs, top first (Fig. 3 profiles).
struct ProfileBox {
  double x_lo = 0, y_lo = 0, x_hi = 0, y_hi = 0;  // [m] footprint
  double z_top = 0, height = 0;                   // [m] top of the block, its height
};
std::vector<ProfileSlab> stress_profile(const World& w, const ProfileBox& box, int slabs);
/// Its slabs, top first: each one's region and depths (stress and count left 0). Throws
/// std::invalid_argument when slabs < 1.
std::vector<std::pair<Region, ProfileSlab>> profile_slabs(const ProfileBox& box, int slabs);

/// DEM-only box (scene dem.specimen.box = "walls"): five planar walls (family ball_wall) on the
/// bottom and the four sides of the balls' bounding box, each touching the outermost ball surfaces
/// (a wall placed at a cut face would overlap the balls that reach past it and push them out at
/// once), normals pointing inwards. Throws std::invalid_argument while the world is periodic or
/// has no ball. Returns the bounding box of the ball surfaces [lo, hi].
std::pair<Vec3, Vec3> add_box_walls(World& w);
/// Its halves: the bounding box [lo, hi] of `w`'s ball surfaces (on a rank's part, of its own
/// balls; empty: lo = +1e300, hi = -1e300, the identities of the minimum and maximum over the
/// ranks), and the five planes on a given box added to `w` (the same refusals).
std::pair<Vec3, Vec3> ball_bounds(const World& w);
void add_box_planes(World& w, const Vec3& lo, const Vec3& hi);

/// Places the footing `f` (its bottom_centre x and y give the axis; z is ignored) at first
/// contact: the highest point where a ball touches its flat bottom (a ball within the footprint,
/// at its top z + r) or its bottom rim (a ball whose axis distance rho is in (r_f, r_f + r), at
/// z + sqrt(r^2 - (rho - r_f)^2)), at rest. Returns the bottom height [m]. Throws
/// std::runtime_error when no ball lies under the footprint (the footing would never touch).
double place_footing_at_first_contact(World& w, FootingParams f);
/// Its height of first contact over `w`'s balls (on a rank's part, its own: not the ghosts):
/// -infinity when none lies under the footprint (the maximum of the parts' heights is the
/// whole's).
double footing_contact_height(const World& w, const FootingParams& f);
/// The footing `f` at rest with its bottom at `z` (a height of first contact), set on `w`; the
/// error of place_footing_at_first_contact when z is not finite.
void set_footing_at(World& w, FootingParams f, double z);

/// Power of the moving boundaries on the balls [W]: the footing and the facet walls (the force of
/// a wall on the balls is minus the balls' force on it), from the last force pass.
double boundary_power(const World& w);

/// Work of gravity on the balls since positions `x_begin` [J] (0 without gravity).
double gravity_work(const World& w, const std::vector<Vec3>& x_begin);

/// Upper bound of the critical step of docs/theory.md 1.8 [s] (without dt_safety) for a packing
/// of balls with radii in [r_min, r_max] under the ball-ball family of `p` that holds a ball of
/// radius r_min: that ball with one contact, to a ball of the smallest or of the largest size
/// (the larger of the two); every further contact or bond adds stiffness and lowers the step.
/// (Packings of larger balls only can have a larger step: it grows with the radius.)
double largest_critical_step(WorldParams p, double r_min, double r_max);

/// The DEM's total energy [J]: kinetic + strain + dissipated (damping, friction, softening;
/// docs/theory.md 8.18).
double total_energy(const World& w);
/// The same from energies already measured (World::energy()).
double total_energy(const Energy& e);

/// Energy balance of a stage (docs/stability.md, docs/theory.md 8.18): the change of the total
/// energy equals the work of the moving boundaries (boundary_power) and of gravity. begin()
/// before the stage's first step (after its set-up), add_work() after every block of `steps`
/// steps, balance() at the end. The fields are the state a checkpoint carries.
struct StageEnergy {
  double total_begin = 0.0;       // [J] total_energy at begin()
  double mechanical_begin = 0.0;  // [J] kinetic + strain at begin()
  double work = 0.0;              // [J] boundary work since begin()
  std::vector<Vec3> x_begin;      // [m] ball positions at begin() (gravity's work)
  void begin(const World& w);
  /// begin() from the energy `e0` of the state (x_begin left to the caller: the DEM on ranks
  /// keeps the positions on the ranks, DistDem::owned_positions).
  void begin_with(const Energy& e0);
  void add_work(const World& w, std::int64_t steps) {
    work += boundary_power(w) * w.dt() * static_cast<double>(steps);
  }
  struct Balance {
    double kinetic, strain, dissipated, work;  // [J] now; dissipated in the stage; boundary + gravity work
    double error;  // (change of the total energy - work) / the largest energy flow of the stage
  };
  Balance balance(const World& w) const;
  /// balance() from the energy `e` of the state and gravity's work since begin().
  Balance balance_with(const Energy& e, double gravity_work) const;
  /// Checkpoint (docs/checkpoint-format.md, section dem_node): total_begin, mechanical_begin,
  /// work (f64), then x_begin (u64 count, x y z f64 each). load() reads what save() wrote.
  void save(io::StateWriter& w) const;
  void load(io::SectionReader& r);
};

/// The ball whose top (z + r) is highest gets velocity `v` (stability studies), of equal tops
/// the lowest id; returns its row. Throws std::invalid_argument without balls.
std::size_t kick_highest_ball(World& w, const Vec3& v);

/// The generate stage (docs/theory.md 4.3, 4.6): the REV (generate_rev), then, when
/// `bond_coordination` > 0, bonds over the gaps that give that coordination number
/// (install_bonds_to_coordination, gaps at least `gap_floor`; docs/ucs-study.md). The report is
/// the generation's, the bonding and the coordination (of the touching contacts before it, of
/// every active contact after it) appended to `what`, `count` the balls.
StageReport generate_specimen(World& w, const RevParams& p, double bond_coordination, double gap_floor);
/// Its bonding half, on a generated REV: appends to `r` (nothing when bond_coordination <= 0).
void bond_specimen(World& w, StageReport& r, double bond_coordination, double gap_floor);

/// The servo stage of the REV (docs/theory.md 4.5, 4.3 step 4): compaction with the ball-ball
/// friction lowered to min(mu, compaction_fric), then at the final friction mu (the linear law's,
/// restored) at constant stress, each until the criterion of servo_until holds for `hold` critical
/// steps, the first within `budget` critical steps, the second within budget / 2. A compaction
/// that misses its criterion is returned as it is (friction still lowered: the node stops the
/// run). `steps` counts both phases.
StageReport servo_specimen(World& w, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                           double budget, double compaction_fric);

/// Weight of the balls [N]: their total mass times |g_z| of the world's gravity (0 without).
double ball_weight(const World& w);

/// The blow-up guard's report of a kinetic-energy jump (docs/stability.md): `jump` (what the
/// jump detector said) and the ball with the largest kinetic energy, translational plus
/// rotational, with its neighbourhood (the 10 nearest balls). Throws std::invalid_argument
/// without balls.
GuardFinding energy_jump_finding(const World& w, const std::string& jump);

}  // namespace demfdm::dem
