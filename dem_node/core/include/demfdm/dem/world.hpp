// DEM world: the PFC cycle over its units. The balls are a Particles store (particles.hpp); the
// ball-ball contacts and each wall kind (planes, interface facets, the footing) are contact sets
// behind one interface (src/contact_set.hpp: rebuild, force pass, gather, stiffness for the
// critical step, energy, reorder), the pairs found by the neighbour grid (neighbour_grid.hpp),
// the wall kinds as geometries of one wall-contact set (src/wall_set.hpp); effects (gravity,
// servos) plug into declared phases.
//
// Cycle (docs/theory.md §1.2, PFC order): pre-step effects → timestep → law of motion with
// local damping → kinematics effects (wall servos) → wall motion → time advance → neighbour check/rebuild → force–displacement
// for every contact family → fixed-order sums onto balls (thread buffers, then wall contacts) → force effects (gravity) →
// end-of-step effects.
//
// Determinism (same scene, seed and thread count give the same bits): the ball–ball pass splits the sorted contact list into
// one static block per thread; each thread adds into its own force buffer and the buffers
// are summed in thread order. Results are bit-identical from run to run for a given thread
// count (sums are associated differently for different thread counts).
//
// Contact history is keyed by the stable particle / wall ids and carried across rebuilds
// (contact histories follow the pair, not the list slot). Bonded contacts are never dropped by a rebuild.
#pragma once

#include <array>
#include <functional>
#include <omp.h>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "demfdm/dem/contact_kernels.hpp"
#include "demfdm/dem/order_free_sum.hpp"
#include "demfdm/dem/params.hpp"
#include "demfdm/dem/particles.hpp"
#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

/// Ball–ball contacts (half list, A = lower index). Hot arrays first.
struct PairContacts {
  std::vector<std::uint32_t> a, b;             // particle rows
  std::vector<std::array<std::int8_t, 4>> shift;  // periodic image of B (cells), [3] unused
  std::vector<ContactHist> h;
  std::vector<BondHist> bond;                  // empty unless the family can bond
  std::size_t size() const { return a.size(); }
};

/// Ball–wall contacts (A = ball, B = wall).
struct WallContacts {
  std::vector<std::uint32_t> ball, wall;       // particle row, wall index within its type
  std::vector<ContactHist> h;
  std::vector<BondHist> bond;
  std::vector<std::int32_t> facet;             // facet walls: current facet
  std::vector<std::uint32_t> cand_off, cand;   // facet walls: candidate facets (CSR)
  std::vector<Vec3> F, M, TA, xc;              // force and moment on the wall, torque on ball,
                                               // contact point
  std::vector<Vec3> bary;                      // facet walls: barycentric weights of x_c
  std::size_t size() const { return ball.size(); }
};

/// One wall contact's share of its wall's sums (World::wall_sum_records, World::set_wall_sums;
/// a facet contact's record is what its terms are formed from, FacetSumShare):
/// what a rank of the DEM on MPI ranks (dem_node/dist) passes to every rank, so that each sums
/// the contacts of every rank in the order of one World.
struct WallSumRec {
  std::uint64_t ball = 0;   // ball id
  std::uint32_t wall = 0;   // wall index within its kind
  std::int32_t facet = 0;   // facet walls: the contact's facet
  std::uint8_t kind = 0;    // 0 planes, 1 facets, 2 footing
  std::uint8_t active = 0;  // carries a force (facets: or bonded)
  Vec3 F{}, M{}, xc{}, bary{};
  double k = 0.0;  // planes: K_n (servo gain); facets: the vertex stiffness K (docs/theory.md 6.5)
};

/// One acting facet contact's share of its wall's vertex sums as the force pass formed it: its
/// equivalent vertex forces, force and vertex stiffness shares (docs/theory.md 6.4, 6.5;
/// World::facet_sum_shares, World::set_facet_sums). What a rank of the DEM on MPI ranks sends
/// rank 0, which then only adds the shares in one World's contact order.
struct FacetSumShare {
  std::uint64_t ball = 0;   // ball id
  std::uint32_t wall = 0;   // facet wall index
  std::int32_t facet = 0;   // the contact's facet
  std::uint8_t loaded = 0;  // carries a force or moment: vertex forces and the wall's total
  std::array<Vec3, 3> f{};  // equivalent vertex forces
  Vec3 F{};                 // the force on the wall
  double k[3] = {0.0, 0.0, 0.0};  // vertex stiffness shares
};

/// Planar wall: infinite plane, or a bounded rectangle (half1, half2 finite).
struct PlaneWallParams {
  Vec3 point{};          // [m] a point on the plane (rectangle centre)
  Vec3 normal{0, 0, 1};  // [-] unit normal pointing towards the balls
  Vec3 axis1{1, 0, 0};   // [-] first in-plane axis (orthogonalised against normal)
  double half1 = 0.0;    // [m] rectangle half-extent along axis1; 0 = infinite
  double half2 = 0.0;    // [m] rectangle half-extent along axis2 = normal × axis1; 0 = infinite
  Vec3 velocity{};       // [m/s] prescribed velocity (a PlatenServo effect sets it every step)
};

struct PlaneWall {
  PlaneWallParams p;
  Vec3 axis2{};
  Vec3 disp{};      // [m] displacement since the last rebuild
  Vec3 reaction{};  // [N] total force of the balls on the wall (last pass)
  double k_sum = 0.0;  // [N/m] Σ K_n of active contacts (the PlatenServo's gain)
  std::uint64_t id = 0;
};

/// Interface wall made of triangles whose vertices are set from outside (§6.2).
/// Winding: (p2−p1)×(p3−p1) points towards the balls (the DEM side).
struct FacetWall {
  std::vector<Vec3> pos, vel;                 // [m], [m/s] vertex positions / velocities
  std::vector<std::array<std::int32_t, 3>> tri;
  std::vector<Vec3> tri_normal, tri_spin;     // unit normal, facet angular velocity (§6.2)
  std::vector<Vec3> pos_ref;                  // vertex positions at the last rebuild
  std::vector<Vec3> vforce;                   // [N] equivalent vertex forces (§6.4) [nv,3]
  std::vector<double> vstiff;                 // [N/m] stiffness contributions (§6.5) [nv]
  Vec3 total_force{};                         // [N] Σ force on the facets
  std::uint64_t id = 0;
};

/// Rigid flat-bottomed cylindrical footing, axis along z (§0.3, §6.3).
struct FootingParams {
  double diameter = 1.2e-3;  // [m] D_f
  double height = 0.6e-3;    // [m] H_f
  Vec3 bottom_centre{};      // [m] centre of the bottom disc
  Vec3 velocity{};           // [m/s] prescribed velocity
};
/// The [dem.footing] keys of the footing's shape (its axis, dem.footing.centre, is a list the
/// scene reader maps), declared once (demfdm/param_table.hpp).
template <class V>
void describe(V& v, FootingParams& f) {
  v.real("diameter", "m", f.diameter, ParamRange::gt(0.0), "Footing diameter D_f.");
  v.real("height", "m", f.height, ParamRange::gt(0.0), "Footing height H_f.");
}
/// Throws std::invalid_argument naming the scene key (dem.footing.<key>) on a value outside its
/// declared range.
void validate(const FootingParams& f);

struct Footing {
  FootingParams p;
  bool enabled = false;
  Vec3 disp{};
  Vec3 reaction{};  // [N] force of the balls on the footing (last pass)
  std::uint64_t id = 0;
};

/// Implementation of the contact passes (ball–ball and wall contacts) and of the law of motion.
/// All give bit-identical results (checked by tests/dem/simd_kernel_test.cpp). kAuto: vectorised
/// blocks with the best instruction set of the CPU (pair_block.hpp); kScalar: one contact / row
/// at a time (the reference); kBlock*: blocks with a given instruction set. rescale_shear = false
/// and the soft bond's secant unloading always use the scalar passes.
enum class PairKernel : std::uint8_t { kAuto, kScalar, kBlockBaseline, kBlockAvx2, kBlockAvx512 };

class World;
// The contact sets the cycle drives (one interface, src/contact_set.hpp): the ball-ball pairs and
// one wall-contact set per wall kind (src/wall_set.hpp).
class ContactSet;
class PairSet;
template <class Kind>
class WallSet;
struct PlaneKind;
struct FacetKind;
struct FootingKind;
struct SetContext;

/// Optional effect with declared phases (a registry of sub-models, as LAMMPS's granular models). Lists per phase are
/// built when effects are added; an absent effect costs nothing.
class Effect {
 public:
  /// kPreStep: before the step length is fixed; kForce: after the force passes (gravity);
  /// kEndOfStep: last; kKinematics: after the step length is fixed and the balls have moved,
  /// before the walls move (wall servos set the step's wall velocities).
  enum Phase : unsigned { kPreStep = 1, kForce = 2, kEndOfStep = 4, kKinematics = 8 };
  virtual ~Effect() = default;
  virtual unsigned phases() const = 0;
  virtual void apply(World& w, Phase ph) = 0;
  virtual const char* name() const = 0;
};

/// Energy bookkeeping (§8.18).
struct Energy {
  double kinetic = 0.0;    // [J]
  double strain = 0.0;     // [J] linear springs and bonds (current)
  double damping = 0.0;    // [J] dissipated by local damping (cumulative)
  double friction = 0.0;   // [J] dissipated by Coulomb slip (cumulative, live contacts)
  double softening = 0.0;  // [J] bond dissipation: soft-bond softening plus the elastic energy released when
                           //     a bond breaks (cumulative, live and dead contacts)
};

/// Cumulative wall-clock time [s] per phase of the cycle since construction or the last
/// World::reset_phase_times() (steady clock, always on: one clock read per phase boundary,
/// about 10 per step; cost measured in bench/dem/results_2core_kvm.csv). The phases
/// partition the work done inside step() and prepare(), so their sum is at most the wall
/// time spent in those calls (the remainder is loop and call overhead).
struct PhaseTimes {
  double rebuild = 0.0;  // neighbour check and, when needed, the neighbour-list rebuild
  double pair = 0.0;     // ball–ball force pass (contact model: `pair_model`)
  double plane = 0.0;    // ball–plane pass; exactly 0 while the world has no planar wall
  double facet = 0.0;    // ball–facet pass incl. §6.4/6.5 vertex sums; 0 without facet walls
  double footing = 0.0;  // ball–footing pass; exactly 0 without a footing
  double gather = 0.0;   // wall-contact forces and torques added onto the balls
  double motion = 0.0;   // law of motion + local damping, timestep estimate, wall motion
  double effects_total = 0.0;  // all effects (pre-step, force, end-of-step phases)
  /// One entry per effect name (Effect::name()), in order of first addition; effects that
  /// share a name (gravity switched off and on) share the entry.
  std::vector<std::pair<std::string, double>> effect;
  std::int64_t steps = 0;           // step() calls timed
  std::int64_t facets_hosted = 0;   // force passes that ran the facets inside the ball-ball pass
  const char* pair_model = "";      // to_string(params().ball_ball.model)
  /// Sum of the phases above (effects counted once, through effects_total).
  double total() const { return rebuild + pair + plane + facet + footing + gather + motion + effects_total; }
};

class World {
 public:
  explicit World(const WorldParams& p);
  ~World();
  World(const World&) = delete;
  World& operator=(const World&) = delete;

  const WorldParams& params() const { return p_; }
  /// Change contact-family parameters: existing contacts keep their constants until
  /// refresh_contact_constants() (e.g. switching μ after compaction, §4.3 step 4).
  WorldParams& mutable_params() { return p_; }

  // ---- particles ----
  /// Add a ball; density from params unless `density` > 0. Returns its row.
  std::size_t add_ball(const Vec3& x, double radius, double density = 0.0);
  Particles& balls() { return pt_; }
  const Particles& balls() const { return pt_; }
  std::size_t num_balls() const { return pt_.size(); }
  /// Recompute mass and inertia from radius and density (after a radius change).
  void set_radius(std::size_t i, double r);
  /// Reorder the particle rows along a space-filling order of cells (cache locality of the
  /// contact loop). Ids and all histories are kept; returns new_row[old_row]. Rows held by
  /// the caller must be remapped with the returned table.
  std::vector<std::uint32_t> reorder_spatially();
  /// Recompute the precomputed constants (K_n, K_s, μ, bond geometry) of all contacts.
  void refresh_contact_constants();

  // ---- walls ----
  int add_plane(const PlaneWallParams& p);
  PlaneWall& plane(int i);
  const PlaneWall& plane(int i) const;
  int num_planes() const;
  /// Interface wall from vertex positions [nv*3] and triangles [nt*3].
  int add_facet_wall(std::span<const double> vertices, std::span<const std::int32_t> triangles);
  /// Set the vertex positions and velocities [nv*3] of a facet wall (positions at t+Δt).
  void set_vertex_kinematics(int wall, std::span<const double> pos, std::span<const double> vel);
  /// Equivalent vertex forces [nv*3] of the last pass (force of the DEM on the wall, §6.4).
  std::span<const double> vertex_forces(int wall) const;
  /// Stiffness contributions [nv] (§6.5).
  std::span<const double> vertex_stiffness(int wall) const;
  /// Total force the DEM applied to the facets of one wall, and to all facet walls.
  Vec3 facet_wall_force(int wall) const;
  Vec3 facet_walls_total_force() const;
  FacetWall& facet_wall(int i);
  const FacetWall& facet_wall(int i) const;
  int num_facet_walls() const;

  void set_footing(const FootingParams& p);
  void remove_footing();
  bool has_footing() const;
  void set_footing_velocity(const Vec3& v);
  void set_footing_position(const Vec3& bottom_centre);
  const Footing& footing() const;
  Vec3 footing_reaction() const;

  // ---- effects ----
  Effect* add_effect(std::unique_ptr<Effect> e);
  void remove_effect(const Effect* e);
  /// The names of the effects present, in the order they were added (gravity included).
  std::vector<std::string> effect_names() const;
  /// The effects present, in the order they were added (gravity included).
  std::vector<const Effect*> effects() const;
  /// Turn the gravity effect on or off (g = (0,0,−N g0), §0.1).
  void set_gravity(bool on, double g_level);
  bool gravity_on() const { return gravity_ != nullptr; }
  Vec3 gravity() const;

  // ---- stepping ----
  void step();
  void step(std::int64_t n);
  /// step() in two halves, for a driver that acts between them (a rank of the DEM on MPI
  /// ranks, dem_node/dist; the DEM node, which sets the facets' vertices in between):
  /// step_motion() (time step, integration, wall motion), then step_forces(rebuild) (the
  /// neighbour rebuild if asked, the force pass). step() is step_motion(); step_forces_now().
  void step_motion();
  void step_forces(bool rebuild);
  /// step_forces with step()'s own rebuild test (the balls' displacement and the walls' travel).
  void step_forces_now();
  /// The rebuild test of step() for a given largest squared displacement of a ball since the
  /// last rebuild (a rank passes the largest over every rank's own balls).
  bool need_rebuild(double max_disp2) const;
  /// Rows that are ghosts, copies of balls another rank owns (1 = ghost; empty: none): a pair
  /// of two ghosts is not kept in the list (it acts on ghosts only).
  const std::vector<std::uint8_t>& ghost_rows() const { return ghost_; }
  /// Rows [0, n) are integrated, the rows from n on are not (default: every row). A rank's
  /// World whose ghosts are rows of their own after the owned ones (DistDem with `newton`)
  /// leaves them out: their x, v and ω are replaced by their owners' before anything reads them.
  void set_moving_rows(std::size_t n) { moving_rows_ = n; }
  std::size_t moving_rows() const { return std::min(moving_rows_, pt_.size()); }
  /// The state's counters and flags (time, step, the cached step and its recompute counter, the
  /// rebuild test's reference, the energies of local damping and of dropped contacts, ...): what
  /// a checkpoint saves besides the arrays (checkpoint.cpp), and what DistDem::unload sets when
  /// it assembles one World from the ranks' parts.
  struct Counters {
    double time = 0.0, dt = 0.0, skin = 0.0;
    std::int64_t step = 0, rebuilds = 0, last_dt_step = -1, bond_failures = 0;
    bool prepared = false, dirty = true;
    Vec3 edot{}, cell_strain{}, cell_len_ref{};
    std::uint64_t next_id = 0, next_wall_id = 1;
    double e_damp = 0.0, max_disp2 = 0.0, e_slip_dead = 0.0, e_soft_dead = 0.0;
  };
  Counters counters() const;
  void set_counters(const Counters& k);
  /// Every field of the walls of `o` (planes, facet walls, the footing, their last pass's sums
  /// too), a World with the same walls in the same order (DistDem::unload: each rank moves every
  /// wall itself, so a rank's walls are every rank's).
  void copy_walls(const World& o);
  /// Replace every ball, the ball-ball list and the wall contacts of each kind (planes, facets,
  /// footing; all in the rows of `pt`) and the ghost rows by exchange, e.g. after balls moved
  /// between ranks: the arguments get the World's previous arrays (a caller that refills them
  /// each time reuses their memory). The next step_forces(true) searches the contacts again and
  /// carries these histories across by ball and wall id. A ghost row has no wall contacts.
  void swap_balls(Particles& pt, PairContacts& pc, std::array<WallContacts, 3>& wall,
                  std::vector<std::uint8_t>& ghost);
  /// No ball and no contact left; the walls, effects, parameters and counters kept (a World that
  /// holds the rest of a state whose balls live elsewhere: the ranks' parts, a state file read or
  /// written in pieces).
  void drop_balls();
  /// Every plane and footing contact's share of its wall's sums (reactions, servo gains),
  /// appended to `out` kind by kind (planes, footing) in contact order. (The facets' shares:
  /// facet_sum_shares.)
  void wall_sum_records(std::vector<WallSumRec>& out) const;
  /// The acting facet contacts' shares of their walls' vertex sums as this World's last force
  /// pass formed them (in contact order; formed from the contacts' records if no pass ran on this
  /// list yet, e.g. a World just loaded), appended to `out`.
  void facet_sum_shares(std::vector<FacetSumShare>& out) const;
  /// The facet walls' sums (vertex forces and stiffness, total force) from `shares`, sorted by
  /// (ball id, wall): every rank's shares merged, which are one World's facet contacts in its
  /// order; the additions of the pass's own sums (FacetKind::end).
  void set_facet_sums(std::span<const FacetSumShare> shares);
  /// Recompute the planes' and the footing's sums from `recs`, sorted by (kind, ball id, wall):
  /// the records of every rank merged, which are the contacts of one World (rows in id order) in
  /// its order. The same arithmetic as the force pass's own sums.
  void set_wall_sums(std::span<const WallSumRec> recs);
  /// The walls' sums as one array (planes: reaction, servo gain; facet walls: vertex forces,
  /// vertex stiffness, total force; the footing's reaction), and back: what one rank sends the
  /// others after set_wall_sums.
  void pack_wall_sums(std::vector<double>& out) const;
  void unpack_wall_sums(std::span<const double> in);
  /// One term of the walls' sums: its slot in pack_wall_sums' array, and its value.
  struct WallTerm {
    std::uint32_t slot;
    double v;
  };
  /// Every term that set_wall_sums would add for this World's own wall contacts (their
  /// wall_sum_records), after a force pass, appended to `out` (in any order).
  void wall_sum_terms(std::vector<WallTerm>& out) const;
  /// The number of values pack_wall_sums gives.
  std::size_t wall_sum_slots() const;
  /// The walls' sums of this World's own contacts as order-free sums (WorldParams::
  /// order_free_sums; order_free_sum.hpp): the force pass calls it after the sets' passes,
  /// unless a caller forms them from several Worlds' contacts (a rank's World: DistDem).
  void set_wall_sums_by_caller(bool by_caller) { wall_sums_by_caller_ = by_caller; }
  /// The critical step on MPI ranks (contact_scan): `reduce(q)` returns the minimum of q over
  /// every rank. A rank passes its smallest mass-over-stiffness ratio (a ghost's
  /// partial stiffness sum gives a ratio no smaller than its owner's), and, only when no rank has
  /// an active contact, its smallest ratio of the no-contact fallback: one World's step. Collective
  /// for such a caller: every rank scans for the step at the same steps.
  void set_step_reduction(std::function<double(double)> reduce);
  /// A rank's World with `newton` on (DistDem::set_newton, docs/scaling.md): a ball-ball pair
  /// is listed only where its ball A (the lower row, so the lower id) is not a ghost, and its
  /// force on a ghost B stays in the ghost's row; `reverse` is called right after the pair pass
  /// to add the ghosts' forces and torques into their owners' rows (LAMMPS's reverse
  /// communication). `stiffness` does the same for the critical step's per-ball stiffness sums
  /// (contact_scan). Both are collective for such a caller. Off: every pair with an own ball is
  /// listed and computed on both sides (the rank-count independent bits).
  /// Empty functions: off.
  void set_newton(std::function<void(Vec3* f, Vec3* t)> reverse, std::function<void(double* kt, double* kr)> stiffness);
  double time() const { return time_; }
  std::int64_t step_count() const { return step_; }
  double dt() const { return dt_; }
  double skin() const { return skin_; }
  /// Critical-step estimate of §1.8 (without the safety factor applied: returns f_s·min).
  double critical_timestep();
  /// The O(contacts) measurements of one state in one pass over the contacts: the critical step
  /// (as critical_timestep()) and the mean contact force (as mean_contact_force()), each only if
  /// asked for (the other is then 0). Same bits as the separate calls, at any thread count.
  struct ContactScan {
    double dt = 0.0, fc = 0.0;
  };
  ContactScan contact_scan(bool critical_step, bool mean_contact_force) const;
  /// Have every ball–ball pass write each contact's ||F|| (off by default): a contact_scan of the
  /// mean contact force right after a step then sums them instead of reading every contact's
  /// history again (the same bits). For a caller that measures after every step (the DEM node);
  /// it costs a square root per live contact in the pass.
  void keep_force_norms(bool on);
  /// Whether a contact_scan now would take the pass's force norms (tests).
  bool force_norms_kept() const;
  /// Every ball's stiffness sums (translational, rotational) of the last contact_scan that
  /// computed the critical step, by row (tests compare them with a serial loop).
  const std::vector<double>& stiffness_sums_translational() const { return scratch_kt_; }
  const std::vector<double>& stiffness_sums_rotational() const { return scratch_kr_; }
  /// Force a neighbour rebuild and a force pass with zero increments (after edits).
  void prepare();
  std::int64_t rebuild_count() const { return rebuilds_; }
  /// Ball-ball bonds that have left the intact state (to softening or broken) in the contact
  /// pass since construction: a cumulative event count, O(1) to read (the footing's elastic
  /// branch ends at its first increase, docs/paper-study.md).
  std::int64_t bond_failures() const { return bond_failures_; }
  /// Choose the implementation of the contact passes and the law of motion (throws
  /// std::invalid_argument if this CPU lacks the instruction set).
  void set_pair_kernel(PairKernel k);
  /// The interface facets' contacts run inside the ball-ball pass, on the threads that finish
  /// their part of it first (World::force_pass; default on). The same bits either way
  /// (tests/dem/simd_kernel_test.cpp compares the two); off: the facets' own pass after it.
  void set_hosted_facets(bool on) { hosted_facets_ = on; }
  /// A thread that has done its part of the threaded ball-ball pass takes blocks of the others'
  /// parts (default on); their ball sums still run in contact order, so the bits are the same
  /// either way (tests/dem/simd_kernel_test.cpp). `hold_s` > 0 (tests): the owner of the first
  /// part starts that late in every pass, so that another thread takes most of it.
  void set_pair_stealing(bool on, double hold_s = 0.0);
  /// Blocks of that pass taken by another thread so far, of the blocks it had (both cumulative).
  std::pair<std::uint64_t, std::uint64_t> pair_blocks_stolen() const;
  PairKernel pair_kernel() const { return kernel_; }
  /// True if `k` can run on this CPU.
  static bool pair_kernel_available(PairKernel k);
  /// Per-phase wall times (see PhaseTimes); reset keeps the effect names, zeroes the times.
  const PhaseTimes& phase_times() const;
  void reset_phase_times();

  // ---- periodic cell (§4.2, §4.5) ----
  bool periodic() const { return p_.periodic.enabled; }
  Vec3 cell_origin() const { return p_.periodic.origin; }
  Vec3 cell_length() const { return p_.periodic.length; }
  double cell_volume() const;
  /// Strain rate of the cell axes [1/s]; positions are mapped affinely each step.
  void set_strain_rate(const Vec3& edot) { edot_ = edot; }
  Vec3 strain_rate() const { return edot_; }
  /// Replace the cell (used by replication); positions are not touched.
  void set_cell(const Vec3& origin, const Vec3& length);

  // ---- bonds (§2.3, §3, §4.6) ----
  /// Bond every ball–ball contact with gap in [gap_lo, gap_hi]. Returns the count.
  std::size_t bond_ball_ball(double gap_lo, double gap_hi);
  /// Bond ball–facet contacts of all facet walls with gap ≤ gap_hi (§2.6, §4.8).
  std::size_t bond_ball_facet(double gap_hi);
  /// Bond ball–footing / ball–plane contacts are not provided (no use in the paper).

  // ---- contacts (expert access for specimen operations and measurements) ----
  PairContacts& pair_contacts();
  const PairContacts& pair_contacts() const;
  WallContacts& plane_contacts();
  WallContacts& facet_contacts();
  WallContacts& footing_contacts();
  const WallContacts& plane_contacts() const;
  const WallContacts& facet_contacts() const;
  const WallContacts& footing_contacts() const;
  /// Force on B of ball–ball contact c after the last pass, rebuilt from the history
  /// (F = F_n n̂ + F_s, plus −N̄ n̂ + F̄_s for a parallel bond): nothing is stored per step.
  Vec3 pair_force(std::size_t c) const;
  /// Moment on B of ball–ball contact c (bond models; zero for the linear model).
  Vec3 pair_moment(std::size_t c) const;
  /// Branch vector x_B − x_A (minimum image) of ball–ball contact c.
  Vec3 branch(std::size_t c) const;
  /// Remove every contact and history (e.g. after moving balls by hand).
  void clear_contacts();
  /// Append a ball–ball contact with a given state (replication). Marks the list dirty.
  void append_pair(std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& shift,
                   const ContactHist& h, const BondHist* bond);

  // ---- measurements ----
  /// Kinetic and strain energy and the energy dissipated so far. With ghost rows (a rank's part)
  /// the contacts' terms are those of the contacts whose ball (a pair's ball A) it owns; the
  /// kinetic energy is every row's (DistDem::energy sums the owned balls').
  Energy energy() const;
  /// Translational + rotational kinetic energy [J]: O(balls), no contact loop.
  double kinetic_energy() const;
  /// PFC average ratio: mean ‖F_unb‖ over balls / mean ‖F_c‖ over active contacts (§5.11).
  double unbalanced_ratio() const;
  /// The same ratio with the mean contact force given (mean_contact_force() of this state), for
  /// callers that also need it elsewhere (the node's skeleton ratio): one contact loop per state.
  double unbalanced_ratio(double mean_contact_force) const;
  /// The ratio from the sum of the balls' unbalanced forces (its last step, written once).
  static double unbalanced_ratio_of(double sum, std::size_t balls, double mean_contact_force);
  double max_unbalanced_force() const;
  /// OpenMP threads of the passes: WorldParams::threads, or the OpenMP default when 0.
  int thread_count() const { return p_.threads > 0 ? p_.threads : omp_get_max_threads(); }
  /// Σ term(i) over the balls in row order: the terms are computed in parallel (above 4,096
  /// balls), the sum runs in row order, so the bits are those of one serial loop at any thread
  /// count. For the O(balls) measurements of every step (kinetic energy, the ratios).
  /// With WorldParams::order_free_sums, an order-free sum of the terms (order_free_sum.hpp).
  template <class Term>
  double ordered_ball_sum(Term term) const {
    const std::int64_t n = static_cast<std::int64_t>(pt_.size());
    const int nt = thread_count();
    const bool par = nt > 1 && n > 4096;
    double s = 0.0;
    if (!par && !p_.order_free_sums) {
      for (std::int64_t i = 0; i < n; ++i) s += term(static_cast<std::size_t>(i));
      return s;
    }
    scratch_ball_.resize(static_cast<std::size_t>(n));
    double* __restrict__ t = scratch_ball_.data();
#pragma omp parallel for schedule(static) num_threads(nt) if (par)
    for (std::int64_t i = 0; i < n; ++i) t[i] = term(static_cast<std::size_t>(i));
    if (p_.order_free_sums) return order_free_total(t, static_cast<std::size_t>(n));
    for (std::int64_t i = 0; i < n; ++i) s += t[i];
    return s;
  }
  /// Mean ‖F_c‖ over the contacts that carry a force (ball-ball and wall). The per-contact norms
  /// are computed in parallel and summed in contact order: the same bits at any thread count.
  double mean_contact_force() const;
  /// One ball's terms of kinetic_energy() and unbalanced_ratio() (a rank of the DEM on MPI ranks
  /// sums its own balls' terms in id order with every other rank's, dem_node/dist).
  double kinetic_energy_of(std::size_t i) const {
    return 0.5 * pt_.m[i] * norm2(pt_.v[i]) + 0.5 * pt_.inertia[i] * norm2(pt_.w[i]);
  }
  double unbalanced_force_of(std::size_t i) const;
  /// A contact's term of an O(contacts) sum, keyed so that the terms of several ranks merge into
  /// one World's order: set (0 pairs, 1 planes, 2 facets, 3 footing), then ball ids (a pair) or
  /// ball id and wall index (a wall contact).
  struct ContactTerm {
    std::uint64_t set, a, b;
    double v;
  };
  /// ‖F‖ of every contact, the terms of mean_contact_force(), appended in set and contact order
  /// (the pass's norms, formed first if it did not keep them). With ghost rows, a pair whose ball
  /// A is a ghost is left out (its owner has it).
  void contact_force_norms(std::vector<double>& out) const;
  /// The keys of those terms, in the same order (their `v` is 0).
  void contact_force_keys(std::vector<ContactTerm>& out) const;
  /// The same norms without forming the pass's first: for a caller that has just scanned them
  /// (contact_scan with want_fc; the terms of an order-free mean contact force); `pairs` false:
  /// the wall contacts' only.
  void force_norm_values(std::vector<double>& out, bool pairs = true) const;
  Vec3 cell_strain_since_reset() const { return cell_strain_; }

 private:
  friend class GravityEffect;
  friend struct CheckpointAccess;  // state save/load (checkpoint.cpp, docs/checkpoint-format.md)
  void rebuild();
  bool need_rebuild() const;
  void force_pass(double dt);
  void order_free_wall_sums();
  /// What the contact sets see of this world for one call.
  SetContext context();
  void gather();  // add the wall-contact forces to the balls (serial, set and contact order)
  void integrate(double dt);
  template <bool Energy, bool Periodic>
  void integrate_rows(std::size_t i0, std::size_t i1, double dt, const Vec3& sc, double& ed, double& dmax);
  std::int64_t dt_interval() const;  // steps between recomputations of the critical step

  WorldParams p_;
  Particles pt_;
  // The contact sets, each the owner of its contacts (and walls); sets_ holds them in the
  // cycle's order (pairs, planes, facets, footing), which fixes the order of every sum over them.
  std::unique_ptr<PairSet> pairs_;
  std::unique_ptr<WallSet<PlaneKind>> planes_;
  std::unique_ptr<WallSet<FacetKind>> facets_;
  std::unique_ptr<WallSet<FootingKind>> footing_;
  std::array<ContactSet*, 4> sets_{};
  std::vector<std::unique_ptr<Effect>> effects_;
  struct EffectSlot {
    Effect* e;
    std::size_t slot;  // index into times_.effect
  };
  std::vector<EffectSlot> by_phase_[4];
  void run_effects(int phase);
  Effect* gravity_ = nullptr;
  double time_ = 0.0, dt_ = 0.0, skin_ = 0.0;
  std::int64_t step_ = 0, rebuilds_ = 0, last_dt_step_ = -1, bond_failures_ = 0;
  bool prepared_ = false, dirty_ = true;
  Vec3 edot_{}, cell_strain_{}, cell_len_ref_{};
  std::uint64_t next_id_ = 0, next_wall_id_ = 1;
  double e_damp_ = 0.0;
  std::vector<double> chunk_e_;
  double max_disp2_ = 0.0;
  std::vector<std::uint8_t> ghost_;  // per row: a ghost of another rank's ball (swap_balls)
  std::size_t moving_rows_ = ~std::size_t{0};  // set_moving_rows
  std::function<double(double)> step_reduction_;  // set_step_reduction
  std::function<void(Vec3*, Vec3*)> newton_reverse_;  // set_newton (set: newton on)
  std::function<void(double*, double*)> newton_stiffness_;
  // Scratch of the O(balls) measurements (kept to avoid an allocation per call).
  mutable std::vector<double> scratch_ball_;       // ordered_ball_sum: per-ball terms
  mutable std::vector<double> scratch_fc_;         // contact_scan, order-free: the force norms
  // order_free_wall_sums: the terms, the facet walls' first slots, the bounds (then the values)
  // and the sums, kept from step to step
  std::vector<WallTerm> of_terms_;
  mutable std::vector<std::uint32_t> scratch_slots_;
  // fn(c, term): each facet contact's share of the vertex sums as the last pass formed it (walls.cpp)
  template <class Fn>
  void for_each_facet_term(Fn fn) const;
  std::vector<double> of_values_;
  std::vector<OrderFreeSum> of_sums_;
  bool wall_sums_by_caller_ = false;
  mutable std::vector<double> scratch_kt_, scratch_kr_;  // critical step: per-ball k_t, k_r
  double e_slip_dead_ = 0.0, e_soft_dead_ = 0.0;
  PhaseTimes times_;
  PairKernel kernel_ = PairKernel::kAuto;
  bool hosted_facets_ = true;  // set_hosted_facets
};

/// Gravity as an optional force effect (§1.2).
class GravityEffect final : public Effect {
 public:
  explicit GravityEffect(Vec3 g) : g_(g) {}
  unsigned phases() const override { return kForce; }
  void apply(World& w, Phase) override;
  const char* name() const override { return "gravity"; }
  Vec3 g() const { return g_; }

 private:
  Vec3 g_;
};

}  // namespace demfdm::dem
