// Staged specimen generation (docs/theory.md §0.4, §4.3–4.9): each operation is callable on
// its own and returns a small report. Randomness comes only from the seeded generator
// passed in the parameters (deterministic, habit 13).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem {

/// Report of one staged operation.
struct StageReport {
  std::string what;          // sentence: what was done
  std::int64_t steps = 0;    // cycles run
  double ratio = 0.0;        // final unbalanced-force ratio
  Mat3 stress{};             // final cell stress (periodic) [Pa], tension positive
  double porosity = 0.0;     // final porosity (periodic cell) [-]
  std::size_t count = 0;     // items created/changed (balls, bonds, contacts, ...)
  bool converged = true;     // criterion met within the step budget
};

/// Particle size distribution: number density ∝ d⁻³ on [d_min, d_max] × scale (§0.4).
struct PsdParams {
  double d_min = 0.0655e-3;  // [m] smallest diameter (§0.3)
  double d_max = 0.181e-3;   // [m] largest diameter (§0.3)
  double scale = 1.0;        // [-] upscaling factor (1, 1.3, 1.5; §0.3)
};
/// Inverse CDF of density ∝ d⁻³: d = (d_min⁻² − u(d_min⁻² − d_max⁻²))^(−1/2), u ∈ [0,1) (§0.4).
double psd_diameter(const PsdParams& p, double u);

/// Specimen preparation counts its rules in critical steps t_c (the §1.8 step without the safety
/// factor), never in steps (docs/theory.md §4.11): an interval of q t_c is round(q / f) steps of
/// the automatic step f t_c, f = the world's dt_safety, at least one step. Changing f then changes
/// how finely the same physical procedure is integrated, not the procedure.
std::int64_t steps_for(const World& w, double tc);

/// Deterministic uniform generator (splitmix64): identical on every platform. Its k-th draw
/// (from 0) is a function of the seed and k alone, at(seed, k): splitmix64 is a counter (the
/// state after k + 1 draws is seed + (k + 1) γ) hashed, so any draw can be made anywhere, in any
/// order, on any rank, without the draws before it.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : s_(seed) {}
  std::uint64_t next() { return mix(s_ += kGamma); }
  double uniform() { return to_unit(next()); }  // [0, 1)
  static std::uint64_t at(std::uint64_t seed, std::uint64_t k) { return mix(seed + (k + 1) * kGamma); }
  static double uniform_at(std::uint64_t seed, std::uint64_t k) { return to_unit(at(seed, k)); }
 private:
  static constexpr std::uint64_t kGamma = 0x9e3779b97f4a7c15ULL;
  static std::uint64_t mix(std::uint64_t z) {
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ULL;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebULL;
    return z ^ (z >> 31);
  }
  static double to_unit(std::uint64_t u) { return double(u >> 11) * 0x1.0p-53; }
  std::uint64_t s_;
};

/// Mean particle volume of the PSD, E[πd³/6] = (π/6)·2(b − a)/(a⁻² − b⁻²), a, b = d_min, d_max × scale.
double psd_mean_volume(const PsdParams& p);
/// Expected number of balls whose solid volume is (1 − porosity)·volume (Table 1 counts, §0.4).
double psd_expected_count(const PsdParams& p, double volume, double porosity);

/// REV generation in the world's periodic cell (§4.3).
struct RevParams {
  PsdParams psd;
  std::uint64_t seed = 1;          // [-] random seed
  std::size_t n_particles = 0;     // [-] number of balls; 0 → draw until the solid volume is (1 − porosity_final) V
  double porosity_final = 0.5195;  // [-] the specimen's final porosity (Table 1, scale 1), sets N_p
  double porosity_target = -1.0;   // [-] n₁ reached by frictionless radius expansion (§4.3); < 0 → porosity_final
  double quench_every = 40.0;      // [t_c] zero all velocities every this many critical steps (0: never)
  double check_every = 40.0;       // [t_c] test the unbalanced ratio every this many critical steps
  double initial_scale = 0.6;      // [-] s₀: initial radii d/2 · s₀
  int increments = 5;              // [-] radius-expansion increments
  double ratio_tol = 1e-3;         // [-] unbalanced ratio after each increment
  double increment_budget = 16000.0;  // [t_c] budget of each increment
  double fric = 0.0;               // [-] μ during generation (§4.3 step 2: μ = 0)
};
/// The scene's REV defaults, [dem.specimen]: RevParams at the paper's upscaling 1.5 (docs/theory.md
/// §0.3; the struct's own 1 is no upscaling), as FamilyInfo::defaults() gives the families'.
inline RevParams scene_rev_defaults() {
  RevParams p;
  p.psd.scale = 1.5;
  return p;
}

/// The [dem.specimen] keys of the REV generation (§4.3), declared once (demfdm/param_table.hpp:
/// the schema's entry, the scene read and validate() below). porosity_target "auto" leaves the
/// field at −1, which generate_rev takes as porosity_final.
template <class V>
void describe(V& v, RevParams& p) {
  v.real("d_min", "m", p.psd.d_min, ParamRange::gt(0.0), "Smallest particle diameter (before upscaling).");
  v.real("d_max", "m", p.psd.d_max, ParamRange::gt(0.0), "Largest particle diameter (before upscaling).");
  v.real("scale", "-", p.psd.scale, ParamRange::ge(0.1).le(10.0), "Particle upscaling factor (1, 1.3, 1.5 in the paper).");
  v.integer("n_particles", "-", p.n_particles, 0, 1000000000,
            "Number of balls; 0: the PSD's expected count at 'porosity' in the cell (Table 1 N_p).");
  v.real("porosity", "-", p.porosity_final, ParamRange::gt(0.0).lt(1.0),
         "Final porosity n of the specimen (Table 1, scale 1); sets N_p.");
  v.real_or_word("porosity_target", "-", p.porosity_target, ParamRange::gt(0.0).lt(1.0), "auto", -1.0,
                 "Porosity reached by frictionless radius expansion (4.3); \"auto\": 'porosity'.");
  v.real("initial_scale", "-", p.initial_scale, ParamRange::gt(0.0).le(1.0), "Initial radii = d/2 * this (4.3).");
  v.integer("increments", "-", p.increments, 1, 1000000, "Radius-expansion increments.");
  v.real("expansion_ratio", "-", p.ratio_tol, ParamRange::gt(0.0),
         "Unbalanced ratio to reach after each expansion increment.");
  v.real("increment_budget", "t_c", p.increment_budget, ParamRange::gt(0.0).le(1e9),
         "Budget of each expansion increment in critical steps t_c (docs/theory.md 4.11; 20,000 steps at "
         "dt_safety 0.8). An increment that does not reach expansion_ratio within it stops the run.");
}
/// Throws std::invalid_argument naming the scene key (dem.specimen.<key>) on a value outside its
/// declared range, or d_min >= d_max.
void validate(const RevParams& p);

/// Ball i of an REV of np balls (0 <= i < np) as generate_rev draws it, keyed by its index
/// (issue 17 item 2: the same ball whoever draws it, in whatever order): its diameter from draw
/// i of the seed, its position in the cell [o, o + L) from draws np + 3i, np + 3i + 1 and
/// np + 3i + 2 (the draws of one generator that draws the np diameters first, then the
/// positions ball by ball).
struct RevBall {
  double d;  // [m] diameter (the PSD's, before the initial scale s0)
  Vec3 x;    // [m] centre
};
RevBall rev_ball(const RevParams& p, std::size_t np, const Vec3& o, const Vec3& L, std::size_t i);

/// Generate balls in the periodic cell of `w` (which must be empty and periodic and step on the
/// automatic step, dt_fixed = 0). The quench interval, the check interval and the budgets are
/// counted in critical steps (steps_for). `converged` is false when an increment ran out of its
/// budget; the caller decides (the DEM node stops the run).
StageReport generate_rev(World& w, const RevParams& p);

/// generate_rev in two halves (the DEM on MPI ranks runs the second on the ranks: dist.hpp's
/// generate_rev): generate_rev_balls checks `p`, draws the balls into the empty periodic World
/// (rev_ball), sets the generation's contact parameters (friction p.fric, no unbonded moments) and
/// prepares it; it returns what the expansion needs: the porosity to reach and the final contact
/// parameters (the World's before). The expansion is detail::expand_rev_on (specimen_steps.hpp).
struct RevStart {
  double n1 = 0.0;        // [-] porosity the expansion reaches
  double mu_final = 0.0;  // [-] the ball-ball friction after the generation
  UnbondedMoments moments_final = UnbondedMoments::kNone;
};
RevStart generate_rev_balls(World& w, const RevParams& p);

/// Servo stiffness estimate (§4.5, U15).
enum class ServoStiffness : std::uint8_t {
  kAffine = 0,    ///< default: (1/V)Σ(ℓ·e)²[K_n(n̂·e)² + K_s(1−(n̂·e)²)]
  kApparent = 1,  ///< (1/V)Σ K_n (ℓ·e)²
};

/// Strain-rate servo of the periodic cell (§4.5).
struct ServoParams {
  Vec3 target{6.25e3, 6.25e3, 12.5e3};  // [Pa] compressive targets (σ_h, σ_h, σ_v)
  std::array<bool, 3> active{true, true, true};  // [-] servo-controlled axes
  double gain = 0.375;        // [1/t_c] α_s: share of the stress error closed per critical step
                              // (0.3 per step at dt_safety 0.8; §4.5 quotes 0.3–0.5 per step)
  double max_face_step = 1.25e-4;  // [1/t_c] face displacement per critical step / d_min
  ServoStiffness stiffness = ServoStiffness::kAffine;
  bool coupled = true;        // [-] use the full 3×3 affine stiffness (axes coupled)
  double quench_every = 0.0;  // [t_c] servo_until zeroes all velocities every this many critical steps
                              // (0: never); removes the free flight that local damping cannot stop (§1.3)
};

/// The REV servo as a scene sets it ([dem.specimen] servo_*, §4.5, §4.11): the servo (its targets
/// k0 σ_v, k0 σ_v, σ_v come from the scene reader), servo_until's tolerances and budget, and the
/// friction of the compaction.
struct ServoSettings {
  ServoParams p;
  double tol = 0.005;        // [-] |s − s*| / s* on the active axes
  double ratio = 1e-4;       // [-] unbalanced-ratio criterion
  double budget = 320000.0;  // [t_c] budget at low friction (then half of it at the final friction)
  double fric = 0.1;         // [-] μ during servo compaction (§4.3 step 4: 0 to 0.1)
};
template <class V>
void describe(V& v, ServoSettings& s) {
  v.real("servo_tol", "-", s.tol, ParamRange::gt(0.0), "Servo stress tolerance |s - s*| / s*.");
  v.real("servo_ratio", "-", s.ratio, ParamRange::gt(0.0), "Servo unbalanced-ratio criterion.");
  v.real("servo_gain", "1/t_c", s.p.gain, ParamRange::gt(0.0).le(1.0),
         "Servo gain alpha_s: share of the stress error closed per critical step t_c (4.5, 4.11; 0.3 per step at "
         "dt_safety 0.8).");
  v.real("servo_budget", "t_c", s.budget, ParamRange::gt(0.0).le(1e9),
         "Budget of the servo at low friction in critical steps t_c (then half of it at the final friction; "
         "4.11). A servo that does not reach servo_tol and servo_ratio within it stops the run.");
  v.real("servo_fric", "-", s.fric, ParamRange::ge(0.0), "Friction during servo compaction (4.3 step 4: 0 to 0.1).");
}
/// Throws std::invalid_argument naming the scene key (dem.specimen.<key>) on a value outside its
/// declared range.
void validate(const ServoSettings& s);

/// What pair contact c gives the periodic servo's sums (§4.5): its force on A and its branch
/// vector (the cell stress), and, when it is active or bonded (`stiff`), its law's translational
/// stiffnesses (the affine stiffness K; the rotational springs do not strain the cell).
struct ServoTerm {
  Vec3 F{}, l{};
  double kn = 0.0, ks = 0.0;
  bool stiff = false;
};
ServoTerm servo_term(const World& w, std::size_t c);
/// The servo's two sums over the pair contacts, each added in contact order from +0: the cell
/// stress's Σ −F ⊗ ℓ (for_each_stress_increment) and the affine stiffness K (times V). One World adds
/// its contacts in list order; the ranks add every rank's terms in one World's order (DistDem).
struct ServoSums {
  Mat3 s{};
  double K[3][3] = {};
  void add(const ServoTerm& t, ServoStiffness kind);
};
/// The increments a contact's term makes to the servo's 18 sums, in add()'s order: f(k, v) for
/// column k (0-8: the stress's Σ −F ⊗ ℓ, row by row; 9-17: K, row by row); a diagonal of K gets
/// two with the full stiffness. add() adds them in this order; servo_columns collects them.
template <class F>
void for_each_servo_increment(const ServoTerm& t, ServoStiffness kind, F&& f) {
  for_each_stress_increment(t.F, t.l, f);
  if (!t.stiff) return;
  const Vec3& l = t.l;
  const Vec3 n = l * (1.0 / norm(l));
  for (int a = 0; a < 3; ++a) {
    if (kind == ServoStiffness::kApparent) {
      f(9 + 4 * a, t.kn * l[a] * l[a]);
      continue;
    }
    for (int b = 0; b < 3; ++b) f(9 + 3 * a + b, (t.kn - t.ks) * l[a] * n[a] * n[b] * l[b]);
    f(9 + 4 * a, t.ks * l[a] * l[a]);
  }
}
/// Under WorldParams::order_free_sums the servo's sums are order-free sums (order_free_sum.hpp)
/// of each contact's contribution to each column (its increments added from +0): bits that do not
/// depend on the contacts' order nor on the ranks they lie on (one World and DistDem alike). The
/// servo forms only the columns it reads (servo_columns_read: the stress's diagonal, K's diagonal
/// and, when coupled, the rest of K); the others stay 0 in its sums (its last_stress() then holds
/// the diagonal only). cell_stress forms the stress's nine.
constexpr int kServoColumns = 18;
void servo_columns(const ServoTerm& t, ServoStiffness kind, double* out);
std::vector<int> servo_columns_read(const ServoParams& p);
/// The sums from `sums[j]`, the sum of column cols[j] (j < m; all 18 in order when cols is null).
ServoSums servo_sums_of_columns(const double* sums, const int* cols = nullptr, int m = kServoColumns);

/// Effect that sets the cell strain rate each step from the last stress (kPreStep). Its sums
/// are the World's own contacts', or, with a `Reduce` set (DistDem::add_periodic_servo: every
/// rank's World runs the servo), what it returns: every rank's contacts' in one World's order.
class PeriodicServo final : public Effect {
 public:
  /// (the columns to form under order-free sums: servo_columns_read)
  using Reduce = std::function<ServoSums(World&, ServoStiffness, const std::vector<int>& columns)>;
  explicit PeriodicServo(const ServoParams& p, double d_min) : p_(p), d_min_(d_min) {}
  unsigned phases() const override { return kPreStep; }
  void apply(World& w, Phase) override;
  const char* name() const override { return "periodic_servo"; }
  const Mat3& last_stress() const { return stress_; }
  const ServoParams& params() const { return p_; }
  void set_reduce(Reduce r) { reduce_ = std::move(r); }
 private:
  ServoParams p_;
  double d_min_;
  Mat3 stress_{};
  Reduce reduce_;
  std::vector<int> columns_;  // servo_columns_read(p_), formed at the first step
};

/// Stress servo of a planar wall along its normal (a platen, as in the UCS test's seating):
/// every step, once the step length is fixed, the wall's velocity closes a fraction `gain` of
/// the force error with the stiffness of its active contacts (the form of §4.5), limited to
/// `vmax`. An effect next to PeriodicServo (kKinematics): a world without it pays nothing.
struct PlatenServoParams {
  int wall = -1;        // [-] index of the planar wall (World::add_plane)
  double stress = 0.0;  // [Pa] target compressive stress
  double area = 0.0;    // [m^2] area the stress acts on (0 → 4 half1 half2 of the wall)
  double gain = 0.3;    // [-] under-relaxation α_s (cf. §4.5)
  double vmax = 1.0;    // [m/s] speed limit
};
class PlatenServo final : public Effect {
 public:
  explicit PlatenServo(const PlatenServoParams& p) : p_(p) {}
  unsigned phases() const override { return kKinematics; }
  void apply(World& w, Phase) override;
  const char* name() const override { return "platen_servo"; }
  const PlatenServoParams& params() const { return p_; }
 private:
  PlatenServoParams p_;
};

/// Servo until |s − s*| ≤ stress_tol·s* on active axes and ratio < ratio_tol for `hold` critical
/// steps in a row (checked every 8 t_c), or `budget` critical steps are spent (steps_for; the world
/// must step on the automatic step).
/// `overshoot` (optional) receives the largest excursion past the target, relative to the
/// target, on the side opposite to the starting stress (0 if the target is never crossed).
StageReport servo_until(World& w, const ServoParams& p, double stress_tol, double ratio_tol,
                        double hold, double budget, double* overshoot = nullptr);

/// Bond ball–ball contacts with gap in [gap_lo, gap_hi] (§4.6).
StageReport install_bonds(World& w, double gap_lo, double gap_hi);

/// Smallest bond gap g_hi such that bonding every ball–ball pair with gap ≤ g_hi (together
/// with the contacts already active) gives the coordination number 2 N_c/N_p ≥ z_target.
/// Only pairs in the contact list (within the Verlet skin) are candidates; throws if they are
/// too few. `gap_floor` is the smallest value returned (the §4.6 tolerance).
double gap_for_coordination(World& w, double z_target, double gap_floor);
/// install_bonds(w, −∞, gap_for_coordination(w, z_target, gap_floor)) (PFC "bond gap", U15).
StageReport install_bonds_to_coordination(World& w, double z_target, double gap_floor);

/// Brick replication α×β×γ of a periodic cell (§4.7). With keep_periodic the result is a
/// periodic cell of size (α L_x, β L_y, γ L_z); otherwise periodicity is switched off and
/// contacts across the outer faces are dropped.
struct ReplicateParams {
  int nx = 1, ny = 1, nz = 5;   // [-] copies along x, y, z
  bool keep_periodic = false;   // [-] result stays periodic
  bool spatial_order = false;   // [-] the block's rows renumbered in Morton order (World::reorder_spatially)
};
StageReport replicate(World& w, const ReplicateParams& p);

/// replicate's copies, written once for one World and for the ranks (DistDem's replicate, which
/// builds each rank's part of the block without the block): copy c (0 <= c < count(), x fastest)
/// of the REV lies at offset(c) from it. Copy 0 is the REV's own rows; REV ball b's copy c > 0 has
/// the id next_id + (c - 1) n + b (the REV's next id and ball count; ids in (copy, row) order) and
/// the density replica_density(b). A REV pair (a, b, shift s) of copy c joins copy c's a and copy
/// partner(c, s)'s b; on a free face of the block it is dropped. The constructor checks the
/// REV (periodic) and the copy counts, with replicate's messages.
class ReplicaLayout {
 public:
  ReplicaLayout(const World& rev, const ReplicateParams& p);
  int count() const { return n_[0] * n_[1] * n_[2]; }
  int copies(int axis) const { return n_[axis]; }
  /// Copy c's index along each axis.
  void coords(int c, int ci[3]) const {
    ci[0] = c % n_[0];
    ci[1] = (c / n_[0]) % n_[1];
    ci[2] = c / (n_[0] * n_[1]);
  }
  int index(const int ci[3]) const { return (ci[2] * n_[1] + ci[1]) * n_[0] + ci[0]; }
  Vec3 offset(int c) const;
  /// The copy that holds the partner B of a pair of copy c whose REV shift is `s`, and the pair's
  /// shift in the block (`out`); -1 when the pair is dropped (it crosses a free face).
  int partner(int c, const std::array<std::int8_t, 4>& s, std::array<std::int8_t, 4>& out) const;
  /// How many copies keep a REV pair whose shift is `s` (the others drop it).
  std::int64_t kept(const std::array<std::int8_t, 4>& s) const;
  /// The block's cell: the REV's origin and n times its length.
  Vec3 length() const { return {n_[0] * L_.x, n_[1] * L_.y, n_[2] * L_.z}; }
  /// replicate's report sentence.
  std::string what(std::size_t rev_balls, std::size_t block_balls, std::int64_t kept, std::int64_t dropped) const;

 private:
  int n_[3];
  Vec3 L_;
  bool keep_;
};
/// The density REV ball b's copies get (their mass and moment of inertia follow from it, as
/// World::add_ball makes them).
double replica_density(const Particles& pt, std::size_t b);

/// Depth scaling of contact forces (§4.9, U7).
enum class DepthScaling : std::uint8_t {
  kDepthRatio = 0,    ///< default: f = (z_top − z_c)/H_D
  kPaperLiteral = 1,  ///< f = (z_c − z_bottom)/H_D, with z_bottom = z_top − H_D
};
struct DepthScaleParams {
  DepthScaling mode = DepthScaling::kDepthRatio;
  double z_top = 0.0;     // [m] top of the DEM block
  double height = 0.0;    // [m] H_D
};
/// Scale F_n, F_s, M of every ball–ball contact (and bond forces) by f(z_c) clamped to
/// [0,1], switching them to incremental mode (§4.9).
StageReport depth_scale(World& w, const DepthScaleParams& p);

/// §2.6/§4.9 [RECON]: initial normal force of the bonded ball–facet contacts (shear and
/// moment start at 0), in compression.
enum class InterfaceBondForce : std::uint8_t {
  /// Default. Traction-consistent: the geostatic stress σ_zz = −γ d, σ_xx = σ_yy = K0 σ_zz
  /// (d = z_top − z, γ = ρ_b N g0) is integrated over each plane face of the interface
  /// (the facets sharing one normal): F_face = Σ_facets A n·σ·n at the facet centroid
  /// (exact for a stress linear in z). F_face is split over the bonds on that face in
  /// proportion to n·σ·n at each bond's contact point. The bonds then carry the block's
  /// weight (bottom) and its lateral thrust (sides) from the first step.
  kTraction = 0,
  /// The paper's wording: the mean normal force of active ball–ball contacts within ±band of
  /// the bond's height whose normals are within 30° of the facet normal (all contacts in the
  /// band if none; global mean if the band is empty).
  kMeanContact = 1,
};
struct InterfaceBondParams {
  InterfaceBondForce mode = InterfaceBondForce::kTraction;
  double band = 0.0;         // [m] kMeanContact: half-height of the averaging band
  double z_top = 0.0;        // [m] kTraction: top of the DEM block (zero stress)
  double unit_weight = 0.0;  // [N/m^3] kTraction: γ = ρ_b N g0 of the block
  double k0 = 0.5;           // [-] kTraction: σ_h / σ_v
};
/// The [dem.specimen] key of the interface-bond forces (the other fields follow from the block and
/// from dem.specimen.k0 and d50, which the scene reader maps), declared once.
template <class V>
void describe(V& v, InterfaceBondParams& p) {
  v.choice("interface_bond_force", p.mode,
           {{"traction", InterfaceBondForce::kTraction}, {"mean_contact", InterfaceBondForce::kMeanContact}},
           "Initial normal force of the ball-facet bonds (4.9, a reconstruction; docs/paper-study.md): traction "
           "(default) splits the geostatic traction n.sigma.n of each plane face of the interface (sigma_zz = "
           "-rho_b N g0 depth, sigma_h = k0 sigma_zz, rho_b = ball mass / block volume) over the bonds on that "
           "face, so the bonds carry the block's weight and lateral thrust from the start; mean_contact: the "
           "mean normal force of the ball-ball contacts within d50 of the bond's height (the paper's wording).");
}
StageReport assign_interface_bond_forces(World& w, const InterfaceBondParams& p);
/// kMeanContact with the given band.
StageReport assign_interface_bond_forces(World& w, double band);

/// Gravity on or off (§4.9 step 5).
StageReport set_gravity(World& w, bool on, double g_level);

/// Cycle until the unbalanced ratio < ratio_tol or the budget is spent.
StageReport cycle_to_equilibrium(World& w, double ratio_tol, std::int64_t budget);

/// Unconfined compression between two rectangular platens (paper Fig. 1, §8.16).
struct UcsParams {
  double strain_rate = 0.5;     // [1/s] platen approach rate / specimen height (each platen half)
  double max_strain = 0.01;     // [-] stop at this axial strain
  double stop_fraction = 0.7;   // [-] stop once stress < stop_fraction · peak, at a strain ≥ 1.2 × the
                                // peak's, for a peak above 4 × seat_stress
  int sample_every = 100;       // [steps]
  double settle_ratio = 1e-4;   // [-] before loading: cycle the free specimen to this unbalanced ratio
  std::int64_t settle_steps = 20000;  // [steps] budget of that settling
  double seat_stress = 0.0;     // [Pa] > 0: seat the platens on the rough ends with a stress servo to
                                // this stress before loading (strain and E50 count from there); 0: no seating
  double seat_speed = 20.0;     // [-] seating speed limit / loading platen speed
  std::int64_t seat_steps = 200000;  // [steps] budget of the seating
};
/// The ucs stage's keys ([[stage]] strain_rate, max_strain), declared once.
template <class V>
void describe(V& v, UcsParams& p) {
  v.real("strain_rate", "1/s", p.strain_rate, ParamRange::gt(0.0), "ucs: platen approach rate / specimen height.");
  v.real("max_strain", "-", p.max_strain, ParamRange::gt(0.0), "ucs: stop at this axial strain.");
}
/// Throws std::invalid_argument naming the stage key on a value outside its declared range.
void validate(const UcsParams& p);
struct UcsSample { double strain, stress; };
struct UcsResult {
  std::vector<UcsSample> curve;  // axial strain, axial compressive stress [Pa]
  double peak = 0.0;             // [Pa] UCS
  double e50 = 0.0;              // [Pa] secant modulus at 50 % of the peak
  double peak_strain = 0.0;      // [-] axial strain at the peak
  StageReport settle;            // the settling before loading
  StageReport seat;              // the platen seating before loading
  StageReport report;
};
/// The world must be non-periodic; platens are added at z_min and z_max of the balls.
UcsResult unconfined_compression(World& w, const UcsParams& p);

/// Unconfined compression without platens (docs/ucs-study.md): the periodic REV is opened in x
/// and y (contacts across those faces dropped, the cell widened `lateral_factor` times so that
/// lateral images never meet) and stays periodic in z, an endless column loaded by the cell's
/// axial strain rate. Axial stress = Love–Weber σ_zz of the cell × cell area / REV area
/// (engineering stress on the REV's cross-section); no end effects, no seating. The seat_*
/// fields of UcsParams are not used.
UcsResult unconfined_compression_column(World& w, const UcsParams& p, double lateral_factor = 3.0);

}  // namespace demfdm::dem
