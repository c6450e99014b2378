// Measurements and snapshot arrays (docs/theory.md §4.3, §4.4, §3.6, §5.11, §8.18).
// All functions read the state of the last force pass; none of them changes the world.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "demfdm/dem/world.hpp"

namespace demfdm::dem {

/// Row-major 3×3 tensor, tension positive (§0.2).
using Mat3 = std::array<double, 9>;

/// Love–Weber stress of the periodic cell: σ = −(1/V) Σ F ⊗ ℓ, symmetrised (§4.4).
Mat3 cell_stress(const World& w);
/// Its two steps, for sums formed elsewhere (the periodic servo's, also on MPI ranks): one
/// contact's increments to Σ −F ⊗ ℓ, f(3 i + j, −F_i ℓ_j) (none for a contact that carries no
/// force), added in contact order from +0 or as order-free sums; and the stress from the finished
/// sum: s / V, symmetrised.
template <class Fn>
void for_each_stress_increment(const Vec3& F, const Vec3& l, Fn&& f) {
  if (F.x == 0.0 && F.y == 0.0 && F.z == 0.0) return;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) f(3 * i + j, -(F[i] * l[j]));
}
Mat3 cell_stress_of(Mat3 s, double volume);

/// Measurement region: an axis-aligned box or a sphere.
struct Region {
  enum class Kind { kBox, kSphere } kind = Kind::kBox;
  Vec3 lo{}, hi{};     // [m] box corners
  Vec3 centre{};       // [m] sphere centre
  double radius = 0;   // [m] sphere radius
  bool contains(const Vec3& x) const;
  double volume() const;
};

/// Particle-based stress of a region (§4.4 second form, balls whose centres lie inside,
/// (1 − n_V)/Σ V_p = 1/V): σ = (1/V) Σ_p Σ_c (x_c − x_p) ⊗ F^{c→p}, symmetrised.
/// Includes ball–wall contacts of those balls.
Mat3 region_stress(const World& w, const Region& r);
/// Its terms of ball–ball contact c with force F (on B; zero: no term): the force -F on A acts at
/// `arm_a` from A's centre, F on B at `arm_b` from B's, the contact point halfway across the gap.
inline void pair_stress_arms(const World& w, std::size_t c, Vec3& arm_a, Vec3& arm_b) {
  const auto& pt = w.balls();
  const auto& pc = w.pair_contacts();
  const std::uint32_t a = pc.a[c], b = pc.b[c];
  const Vec3 d = w.branch(c);
  const double dist = norm(d);
  const Vec3 n = d * (1.0 / dist);
  const double gap = dist - pt.r[a] - pt.r[b];
  arm_a = (pt.r[a] + 0.5 * gap) * n;
  arm_b = -(pt.r[b] + 0.5 * gap) * n;
}

/// Porosity of a region: 1 − Σ V_p(centre inside)/V (the periodic cell: exact solid volume).
double porosity(const World& w, const Region& r);
double cell_porosity(const World& w);
/// Its term (a ball's volume), added in row order from +0, and the porosity from the sum (the
/// ranks' one World's bits: DistDem::cell_porosity).
inline double ball_volume_term(double r) { return 4.0 / 3.0 * 3.14159265358979323846 * r * r * r; }
inline double cell_porosity_of(double solid, double volume) { return 1.0 - solid / volume; }

struct Coordination {
  double z = 0.0;             // [-] 2 N_c / N_p over active ball–ball contacts (§4.3)
  double z_no_rattlers = 0.0; // [-] same without balls having < 2 contacts
  std::size_t active = 0;     // active ball–ball contacts (touching or bonded)
  std::size_t rattlers = 0;   // balls with < 2 contacts
};
Coordination coordination(const World& w);
/// The coordination numbers from their counts: the balls, the active contacts, the rattlers and
/// the active contacts' ends on the other balls (coordination, and DistDem's from every rank's).
Coordination coordination_of(std::size_t balls, std::size_t active, std::size_t rattlers, std::size_t ends);
/// Whether ball-ball pair c of `w` is active: touching, or bonded.
inline bool pair_active(const World& w, std::size_t c) {
  const auto& pc = w.pair_contacts();
  if (pc.h[c].flags & ContactHist::kActive) return true;
  return !pc.bond.empty() && bonded(pc.bond[c].state);
}

struct BondCounts {
  std::size_t never_bonded = 0, intact = 0, softening = 0, broken_tension = 0, broken_shear = 0;
};
/// Bond counts by state of the ball–ball family (§3.6). On a rank of the DEM on MPI ranks
/// (ghost rows) a pair whose ball A is a ghost is left out: the counts of the ranks add up to
/// one World's.
BondCounts bond_counts(const World& w);
/// Same for ball–facet contacts (interface bonds).
BondCounts facet_bond_counts(const World& w);

/// Flat snapshot arrays for the HDF5 writer (row order = particle rows).
struct Snapshot {
  std::vector<double> position;     // [n,3] m
  std::vector<double> velocity;     // [n,3] m/s
  std::vector<double> radius;       // [n] m
  std::vector<std::uint64_t> id;    // [n]
  // ball–ball contacts that are active or bonded (or ever bonded)
  std::vector<std::uint32_t> pair;  // [nc,2] particle rows
  std::vector<double> force;        // [nc,3] N, force on the second ball
  std::vector<std::uint8_t> state;  // [nc] BondState as uint8 (0 = never bonded)
};
Snapshot snapshot(const World& w);

/// One line of measurements, for a history file every N steps (§3.6, §5.11, §8.18).
struct Measurement {
  double time = 0.0;
  std::int64_t step = 0;
  double ratio = 0.0;        // unbalanced-force ratio
  Energy energy;
  Coordination coord;
  BondCounts bonds;
  Mat3 stress{};             // cell stress (periodic) or zeros
  double porosity = 0.0;     // cell porosity (periodic) or 0
};
Measurement measure(const World& w);

/// End-of-step effect that records a Measurement every `interval` steps (§3.6 counters,
/// §5.11 ratio, §8.18 energies). Add it with World::add_effect; read samples() any time.
class MeasurementRecorder final : public Effect {
 public:
  explicit MeasurementRecorder(std::int64_t interval);
  unsigned phases() const override { return kEndOfStep; }
  void apply(World& w, Phase) override;
  const char* name() const override { return "measurement_recorder"; }
  const std::vector<Measurement>& samples() const { return samples_; }

 private:
  std::int64_t interval_;
  std::vector<Measurement> samples_;
};

}  // namespace demfdm::dem
