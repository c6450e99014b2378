// fem_core: quasi-static, implicit, linear-elastic finite elements on the FDM node's
// hexahedral mesh (fdm::generate_mesh), so that the coupling interface (points, triangles,
// walls) is identical to fdm_node's.
//
// Element: 8-node trilinear hexahedron (unit-cube corner order of fdm::Mesh), full 2x2x2
// Gauss integration, isotropic linear elasticity (small strain). The 5-tet split of the FDM
// is not used: the full-integration hexahedron is the textbook choice for an implicit code
// and is exact for the axis-aligned boxes the mesh generator produces under uniform stress.
//
// Equilibrium: K u = f_gravity + f_interface + f_applied - f_0, where f_0 = sum B^T sigma_0
// is the internal force of the initial (geostatic) stress. K (free dofs only; strongbox: base
// fixed, rollers on the 4 sides) is factorised once, with CHOLMOD's supernodal Cholesky
// (Eigen::CholmodSupernodalLLT, METIS/AMD ordering, BLAS-3 kernels) when the build has
// CHOLMOD, or with Eigen::SimplicialLDLT (AMD ordering, column by column); every solve is
// one back-substitution. The model has no history: u is a function of the current loads.
#pragma once

#include <Eigen/Sparse>
#ifdef DEMFDM_HAVE_CHOLMOD
#include <Eigen/CholmodSupport>
#endif

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "demfdm/fdm/mesh.hpp"
#include "demfdm/io/state_file.hpp"

namespace demfdm::fem {

struct ElasticGroup {
  double density = 1272.0;  // [kg/m^3]
  double young = 2.0e9;     // [Pa]
  double poisson = 0.25;    // [-]
  std::optional<fdm::Box> region;  // zones whose centroid lies in it; nullopt: all
};

// Sparse direct solver for K (scene key continuum.linear_solver).
enum class LinearSolver {
  kAuto,     // CHOLMOD when built with it, else SimplicialLDLT
  kCholmod,  // CHOLMOD supernodal LL^T (error when the build has no CHOLMOD)
  kLdlt,     // Eigen::SimplicialLDLT
};
// True when this build links CHOLMOD.
bool have_cholmod();
// "auto", "cholmod", "ldlt" (scene values); throws std::invalid_argument otherwise.
LinearSolver linear_solver_from_name(const std::string& name);

struct Params {
  fdm::MeshParams mesh{};
  LinearSolver solver = LinearSolver::kAuto;
  std::vector<ElasticGroup> materials = std::vector<ElasticGroup>(1);
  std::array<double, 3> gravity{0.0, 0.0, 0.0};  // [m/s^2] acceleration vector (0, 0, -N g0)
  bool strongbox = true;
};

class Model {
 public:
  explicit Model(const Params& p);

  const fdm::Mesh& mesh() const { return mesh_; }
  std::size_t num_points() const { return mesh_.num_points(); }
  std::size_t num_zones() const { return mesh_.num_zones(); }
  std::size_t num_free_dofs() const { return static_cast<std::size_t>(nfree_); }
  double assembly_s() const { return assembly_s_; }      // wall time of the assembly [s]
  double factorisation_s() const { return factor_s_; }   // wall time of the factorisation [s]
  bool uses_cholmod() const { return use_cholmod_; }
  const char* solver_name() const { return use_cholmod_ ? "cholmod-supernodal" : "simplicial-ldlt"; }

  // Geostatic initial stress (same rule as fdm::Model): sigma_zz = -rho |g| (z_top - z),
  // sigma_xx = sigma_yy = K0 sigma_zz; k0 NaN: nu/(1-nu) of each zone. Evaluated per Gauss point.
  void set_geostatic_stress(double k0);
  void clear_initial_stress();

  // External nodal loads [N] on the interface points [n_if,3] (replaces the previous ones).
  void set_interface_forces(const std::vector<double>& f);
  // Extra nodal loads [N] on any gridpoints [n,3] (tests); replaces the previous ones.
  void set_applied_forces(const std::vector<double>& f);

  // One back-substitution with the current loads: u_static = K^-1 f. With omega = 1, u = u_static;
  // with 0 < omega < 1 the update is under-relaxed, u_k = u_{k-1} + omega (u_static - u_{k-1})
  // (interface relaxation of a partitioned coupling, docs/continuum-solvers.md). Repeated solves
  // with fixed loads converge geometrically, with factor (1 - omega), to the same static answer.
  void solve(double omega = 1.0);
  // Interface springs [N/m] per interface point (on its free dofs), D: from now on a solve
  // answers (K + D) u_s = f + D u_{k-1} instead of K u_s = f, i.e. u_s = u_{k-1} +
  // (K + D)^-1 (f - K u_{k-1}). The fixed point is the same static answer K u = f; D makes the
  // update of a coupling with contacts of stiffness k <= 2 D contractive (docs/continuum-
  // solvers.md). Refactorises K + D (cost of the start-up factorisation). Empty: D = 0.
  void set_interface_springs(const std::vector<double>& k);
  std::int64_t refactorisations() const { return refactorisations_; }
  double refactorisation_s() const { return refactor_s_; }  // total wall time [s]

  // max |u_static - u_{k-1}| / max |u_static| of the last solve: how far the previous state was
  // from the static answer (0 when omega = 1 reaches it; 1 on the first solve from rest).
  double relaxation_gap() const { return gap_; }

  // Interface displacements [n_if,3] under the given interface loads alone (no gravity, no
  // initial stress), i.e. the interface compliance C applied to f; does not change the state.
  std::vector<double> interface_response(const std::vector<double>& f_if) const;
  // Largest eigenvalue of C D (D = diag of the per-point stiffness k [n_if], on each of the 3
  // dofs of a point): the gain of one unrelaxed coupling step of a continuum that answers forces
  // statically against contacts of stiffness k. Power iteration on the symmetric D^1/2 C D^1/2
  // from a fixed start vector, until the Rayleigh quotient changes by < tol (relative) or after
  // max_iterations solves. The Rayleigh quotient never exceeds the true value.
  double coupling_gain(const std::vector<double>& k, int max_iterations = 40, double tol = 1e-4,
                       int* iterations = nullptr) const;

  const std::vector<double>& displacements() const { return u_; }  // [n,3] total
  std::vector<double> interface_positions() const;                 // x0 + u
  std::vector<double> interface_displacements() const;

  // Residual of the free equations after the last solve, |K u - f|_inf / max(|f|_inf, tiny).
  double residual_ratio() const { return residual_; }
  // Reaction [N] the supports exert on the given gridpoints at the last solve: f_int - f_ext summed.
  std::array<double, 3> reaction_sum(const std::vector<std::int32_t>& gps) const;
  std::array<double, 3> base_reaction() const { return reaction_sum(base_); }
  // Zone stress at the centroid [nz,6] (xx yy zz xy yz xz, tension positive), incl. sigma_0.
  std::vector<double> zone_stress() const;
  // Total gravity load [N].
  std::array<double, 3> gravity_load() const;

  // Checkpoints (docs/checkpoint-format.md, section "fem_model"): the state a model built from
  // the same Params continues from with the same bits: displacements, loads (interface,
  // applied, geostatic), Gauss-point initial stresses, the last solve's unbalanced forces,
  // residual and gap, the interface springs and the refactorisation count. The factorisation is
  // not stored: load_state() rebuilds K + D from the saved springs, the same matrix as before.
  void save_state(io::StateWriter& w) const;
  void load_state(io::SectionReader& r);

 private:
  struct Mat {
    double rho, young, nu;
  };
  void element_geometry(std::size_t z, double xi, double eta, double zeta, double dNdx[8][3], double& detJ) const;
  void assemble();
  std::vector<double> rhs_full() const;

  Params p_;
  fdm::Mesh mesh_;
  std::vector<Mat> zone_mat_;
  std::vector<std::uint8_t> fix_;      // [3n] 1: fixed dof
  std::vector<std::int32_t> free_of_;  // [3n] free index or -1
  std::int32_t nfree_ = 0;
  std::vector<std::int32_t> base_;
  Eigen::SparseMatrix<double> kfull_;  // [3n x 3n], all dofs
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> ldlt_;
#ifdef DEMFDM_HAVE_CHOLMOD
  Eigen::CholmodSupernodalLLT<Eigen::SparseMatrix<double>, Eigen::Lower> cholmod_;
#endif
  bool use_cholmod_ = false;
  std::vector<double> fgrav_, f0_, fif_, fapp_, u_;
  std::vector<double> unbalanced_;  // [3n] K u - (f_ext - f_0) at the last solve
  std::vector<double> sigma0_;  // [nz*8*6] initial stress at the Gauss points
  double residual_ = 0, gap_ = 0, assembly_s_ = 0, factor_s_ = 0, refactor_s_ = 0;
  std::int64_t refactorisations_ = 0;
  Eigen::SparseMatrix<double> kff_;  // [nfree x nfree] K of the free dofs
  std::vector<double> springs_;      // [3 n_if] interface springs on free dofs (0 on fixed ones)
  void factorise(const Eigen::SparseMatrix<double>& a);
  Eigen::VectorXd solve_free(const Eigen::VectorXd& b) const;
};

}  // namespace demfdm::fem
