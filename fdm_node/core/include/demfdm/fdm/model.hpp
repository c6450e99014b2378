// Explicit Lagrangian finite-difference continuum, FLAC3D style (docs/theory.md section 5).
//
// Design notes
//  * One step (docs/theory.md 5.6, 6.8 steps 3 and 8): law of motion for every gridpoint with the
//    force sum of the previous step (zone forces + gravity + applied loads + coupling forces),
//    then strain rates -> stresses -> zone nodal forces for the next step.
//  * Zones are processed by a templated kernel per (constitutive law, strain mode,
//    averaging) combination, chosen once per pass: no virtual or switch per zone. Each zone
//    writes its 8 nodal forces to its own slot; a gather over gridpoints then sums the slots
//    of the zones around each gridpoint in ascending zone order. The result is bit-identical
//    for any OpenMP thread count.
//  * Small strain (default): tetrahedron geometry (barycentric gradients and volumes) is
//    computed once from the reference positions; gridpoint positions are still advanced every
//    step (x = x0 + u) so that the coupling sees the moving interface (docs/theory.md 5.8).
//    Large strain recomputes the geometry from the current positions every step and applies
//    the Jaumann correction (docs/theory.md 5.8).
//  * Stresses are stored per tetrahedron (10 per zone), tension positive, as
//    (xx, yy, zz, xy, yz, xz).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "demfdm/fdm/constitutive.hpp"
#include "demfdm/fdm/mesh.hpp"
#include "demfdm/fdm/params.hpp"
#include "demfdm/fdm/tet.hpp"

namespace demfdm::fdm {

// Velocity-fixity bits per gridpoint.
enum Fix : std::uint8_t { kFixX = 1, kFixY = 2, kFixZ = 4, kFixAll = 7 };

// Unbalanced-force ratios (docs/theory.md 5.11), computed over free velocity components.
struct Ratios {
  double average = 0.0;  // [-] R_avg = sum |F_unb| / sum F_app
  double max = 0.0;      // [-] R_max = max |F_unb| / mean F_app
  double local = 0.0;    // [-] R_local = max (|F_unb| / F_app)
};

// Wall time [s] spent in each phase of step() since the last reset_phase_times(): the
// interface forces joining the force sum, the gridpoint law of motion (which includes gravity
// and local damping: they are fused into the same loop and have no separate cost), and the
// zone pass (strain rates, constitutive law, nodal forces, gather).
struct PhaseTimes {
  double interface = 0.0;
  double gridpoints = 0.0;
  double zones = 0.0;
};

// One line of the time series.
struct HistoryRecord {
  std::int64_t step = 0;         // [-]
  double time = 0.0;             // [s] (static mode: number of steps)
  Ratios ratios{};               // [-]
  double kinetic_energy = 0.0;   // [J] 1/2 sum m_I v^2 (static mode: with the scaled masses)
  std::array<double, 3> base_reaction{0.0, 0.0, 0.0};  // [N] sum of reactions at z = 0
};

/// How the zone pass runs the elastic small-strain zones: on vector lanes with the CPU's best
/// instruction set (kAuto), a given one (tests and benches; a CPU without it is an error), or
/// zone by zone (kScalar). Every choice gives the same bits.
enum class ZoneKernel { kAuto, kScalar, kBaseline, kAvx2, kAvx512 };

class Model {
 public:
  // Builds the mesh from params.mesh, assigns materials, applies the strongbox boundary if
  // requested. Throws std::invalid_argument on bad parameters.
  explicit Model(const ModelParams& params);
  // Same with a given mesh (params.mesh is ignored).
  Model(Mesh mesh, const ModelParams& params);

  // ---- stepping -------------------------------------------------------------------------
  void step();                  // one explicit step
  void step(std::int64_t n);    // n steps
  void set_zone_kernel(ZoneKernel k) { zone_kernel_ = k; }
  [[nodiscard]] ZoneKernel zone_kernel() const { return zone_kernel_; }
  [[nodiscard]] std::int64_t step_count() const { return step_; }
  [[nodiscard]] double time() const { return time_; }  // [s]; static mode: steps
  [[nodiscard]] double timestep() const { return dt_; }  // [s] in use (1 in static mode)
  // [s] stable timestep (cached, O(1)): the smaller of safety * min_t h_t / C_p over all
  // tetrahedra (docs/theory.md 5.7) and the coupling-stiffness limit (see set_interface_stiffness).
  // The zone part is computed at construction and, in large-strain dynamic runs, refreshed
  // every 100 steps from the deformed geometry.
  [[nodiscard]] double critical_timestep() const;
  // Impose dt (dynamic mode). Throws std::invalid_argument if dt <= 0 or dt exceeds
  // critical_timestep(), and std::logic_error in static mode. If the critical timestep later
  // drops below an imposed dt (stiffer coupling, deformed zones), step() throws
  // std::runtime_error until a smaller dt is imposed. Without set_timestep(), dt follows
  // critical_timestep().
  void set_timestep(double dt);

  // ---- boundary conditions ----------------------------------------------------------------
  // Fix the velocity components in `mask` (Fix bits) of gridpoint gp at `velocity` [m/s]
  // (static mode: [m/step]).
  void fix_velocity(std::int32_t gp, std::uint8_t mask, const Vec3& velocity = {0.0, 0.0, 0.0});
  void free_velocity(std::int32_t gp, std::uint8_t mask);
  // Fixed base (all components at z = 0) and rollers on x = 0, x = L, y = 0, y = W
  // (docs/theory.md 5.10). Top free.
  void apply_strongbox_boundary();
  // Gridpoint ids on the plane coordinate[axis] == value of the structured grid (value must
  // be a grid line).
  [[nodiscard]] std::vector<std::int32_t> gridpoints_on_plane(int axis, double value) const;

  // ---- applied loads ----------------------------------------------------------------------
  void add_point_load(std::int32_t gp, const Vec3& force);  // [N], added to earlier loads
  // Uniform pressure p [Pa] (positive pushes into the material) on boundary faces
  // (outward-wound quads, see BoundaryFace): each face gives -p * area vector / 4 to each of
  // its 4 gridpoints, using the reference geometry.
  void add_face_pressure(std::span<const BoundaryFace> faces, double pressure);
  void clear_applied_loads();

  // ---- coupling interface (docs/theory.md 6.2, 6.4, 6.5) ------------------------------------------
  [[nodiscard]] std::span<const std::int32_t> interface_gridpoints() const { return mesh_.interface_points; }
  // [nt,3] indices into interface_gridpoints(), normal into the pocket.
  [[nodiscard]] std::span<const std::int32_t> interface_triangles() const { return mesh_.interface_triangles; }
  // External forces [N] on the interface gridpoints, [n_if,3]; added to the force sum of every
  // later step until replaced.
  void set_interface_forces(std::span<const double> forces);
  // Stiffness [N/m] per interface gridpoint [n_if] (docs/theory.md 6.5), O(n_if), may be called
  // every step. Static mode: added to the inertial mass (m_I += k dt^2, dt = 1). Dynamic mode:
  // critical_timestep() also obeys dt <= 0.5 sqrt(m_g / (k + k_zone)) at those gridpoints; an
  // automatic dt follows it, an imposed dt is checked by step().
  void set_interface_stiffness(std::span<const double> stiffness);
  [[nodiscard]] std::vector<double> interface_positions() const;      // [m] [n_if,3]
  [[nodiscard]] std::vector<double> interface_velocities() const;     // [m/s] [n_if,3] (static mode: m/step)
  [[nodiscard]] std::vector<double> interface_displacements() const;  // [m] [n_if,3]

  // ---- stresses and state -------------------------------------------------------------------
  void set_geostatic_stress(const GeostaticStress& g);  // docs/theory.md 5.9
  void set_uniform_stress(const std::array<double, 6>& sigma);  // every tetrahedron
  void set_zone_stress(std::int32_t zone, const std::array<double, 6>& sigma);
  void reset_displacements();                       // u = 0 (positions unchanged)
  void reset_velocities();                          // v = 0 on free components
  void set_velocity(std::int32_t gp, const Vec3& v);

  // ---- diagnostics ------------------------------------------------------------------------
  [[nodiscard]] Ratios ratios() const;
  [[nodiscard]] double kinetic_energy() const;
  // Reaction [N] = force the supports exert = -(zone + gravity + applied + coupling forces) on
  // the fixed components, summed over the given gridpoints.
  [[nodiscard]] Vec3 reaction_sum(std::span<const std::int32_t> gps) const;
  [[nodiscard]] Vec3 base_reaction() const { return reaction_sum(base_points_); }
  [[nodiscard]] HistoryRecord sample() const;
  [[nodiscard]] const std::vector<HistoryRecord>& history() const { return history_; }
  // Net force sum of the zones on each gridpoint, [n,3] (for tests: interior balance).
  [[nodiscard]] std::span<const double> zone_forces() const;
  // Velocity gradient of every tetrahedron [nz*10, 9] (row-major dv_i/dx_j) from the current
  // velocities and geometry, before mixed discretisation (for the patch test).
  [[nodiscard]] std::vector<double> tet_velocity_gradients() const;
  [[nodiscard]] std::span<const double> tet_stresses() const { return stress_; }  // [nz*10, 6]
  [[nodiscard]] double total_gravitational_mass() const;  // [kg]
  [[nodiscard]] std::uint64_t state_hash() const;  // FNV-1a over x, v, u, stresses (bitwise)
  [[nodiscard]] const PhaseTimes& phase_times() const { return phase_times_; }
  void reset_phase_times() { phase_times_ = {}; }

  // ---- output arrays (flat, row-major) ---------------------------------------------------
  [[nodiscard]] std::size_t num_gridpoints() const { return n_; }
  [[nodiscard]] std::size_t num_zones() const { return nz_; }
  [[nodiscard]] std::span<const double> positions() const { return x_; }          // [n,3] m
  [[nodiscard]] std::span<const std::int32_t> connectivity() const { return mesh_.zones; }  // [nz,8] VTK order
  [[nodiscard]] std::span<const double> displacements() const { return u_; }      // [n,3] m
  [[nodiscard]] std::span<const double> velocities() const { return v_; }         // [n,3] m/s
  [[nodiscard]] std::vector<double> zone_stress() const;  // [nz,6] Pa, volume average of 10 tets
  [[nodiscard]] std::span<const std::uint8_t> plastic_state() const { return plastic_; }  // [nz] PlasticState bits
  [[nodiscard]] const Mesh& mesh() const { return mesh_; }
  [[nodiscard]] const ModelParams& params() const { return params_; }
  [[nodiscard]] std::span<const double> inertial_masses() const { return mass_; }  // [n] kg
  [[nodiscard]] std::span<const double> gravitational_masses() const { return gmass_; }  // [n] kg

 private:
  friend struct CheckpointAccess;  // state save/load (checkpoint.cpp, docs/checkpoint-format.md)
  void build();
  void compute_geometry(const std::vector<double>& pos);
  void compute_masses();
  void rebuild_external_forces();
  void zone_pass(bool update_stress);
  void gather_zone_forces();
  template <class Law, bool Large, bool ZoneAvg>
  void zone_kernel(std::span<const std::int32_t> zones, bool update_stress);
  void net_force(std::size_t g, double* f) const;  // zone + external + coupling
  [[nodiscard]] double zone_critical_timestep() const;  // full pass over the tetrahedra
  void update_interface_critical_timestep();

  ModelParams params_;
  Mesh mesh_;
  std::size_t n_ = 0, nz_ = 0;
  std::vector<double> x0_, x_, u_, v_;           // [n,3]
  std::vector<double> mass_, gmass_, mass_base_; // [n] inertial, gravitational, static base
  std::vector<double> zone_stiffness_;           // [n] N/m, alpha1 V max|g|^2 summed (6.5)
  std::vector<double> fzone_;                    // [n,3] gathered zone forces
  std::vector<double> fext_;                     // [n,3] gravity + applied loads
  std::vector<double> fapplied_;                 // [n,3] applied loads only
  std::vector<double> vfix_;                     // [n,3] prescribed velocities
  std::vector<std::uint8_t> fix_;                // [n] Fix bits
  std::vector<double> geom_;                     // [nz*10, 10] g2, g3, g4, V (reference)
  std::vector<double> stress_;                   // [nz*10, 6]
  std::vector<double> zone_slot_;                // [nz, 8, 3] nodal forces of each zone
  std::vector<std::uint8_t> plastic_;            // [nz]
  std::vector<std::int32_t> zone_material_;      // [nz]
  std::vector<MaterialConstants> materials_;     // per group
  std::vector<std::int32_t> elastic_zones_, mc_zones_;
  std::vector<std::int32_t> gp_zone_offset_;     // [n+1] CSR of (zone*8 + corner) around each gp
  std::vector<std::int32_t> gp_zone_entry_;
  std::vector<std::int32_t> base_points_;
  ZoneKernel zone_kernel_ = ZoneKernel::kAuto;
  std::vector<std::int32_t> gp_interface_;       // [n] interface index of each gridpoint, -1: none
  std::vector<double> fcouple_;                  // [n_if,3]
  std::vector<double> kcouple_;                  // [n_if]
  bool has_coupling_ = false;
  bool forces_valid_ = false;
  std::int64_t step_ = 0;
  double time_ = 0.0;
  double dt_ = 1.0;
  bool dt_imposed_ = false;  // set_timestep() was called (dynamic mode)
  double zone_critical_dt_ = 0.0;       // [s] cached zone part of critical_timestep()
  double interface_critical_dt_ = 0.0;  // [s] cached coupling-stiffness part
  // Large-strain dynamic runs re-check the critical timestep every this many steps.
  static constexpr std::int64_t kTimestepCheckInterval = 100;
  Vec3 gravity_{0.0, 0.0, 0.0};
  std::vector<HistoryRecord> history_;
  PhaseTimes phase_times_;
};

}  // namespace demfdm::fdm
