#include "demfdm/fem/model.hpp"

#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace demfdm::fem {

namespace {
constexpr double kGauss = 0.57735026918962576451;  // 1/sqrt(3)
// Natural coordinates of the 8 corners in fdm::Mesh unit-cube order.
constexpr int kCorner[8][3] = {{-1, -1, -1}, {1, -1, -1}, {1, 1, -1}, {-1, 1, -1},
                               {-1, -1, 1},  {1, -1, 1},  {1, 1, 1},  {-1, 1, 1}};

// Isotropic elasticity, Voigt order xx yy zz xy yz xz with engineering shear strains.
void elasticity(double E, double nu, double D[6][6]) {
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) D[i][j] = 0;
  double lam = E * nu / ((1 + nu) * (1 - 2 * nu)), G = E / (2 * (1 + nu));
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) D[i][j] = lam;
    D[i][i] = lam + 2 * G;
    D[3 + i][3 + i] = G;
  }
}

// B (6 x 24) from shape-function gradients.
void strain_matrix(const double dN[8][3], double B[6][24]) {
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 24; ++j) B[i][j] = 0;
  for (int a = 0; a < 8; ++a) {
    double gx = dN[a][0], gy = dN[a][1], gz = dN[a][2];
    B[0][3 * a] = gx;
    B[1][3 * a + 1] = gy;
    B[2][3 * a + 2] = gz;
    B[3][3 * a] = gy, B[3][3 * a + 1] = gx;      // xy
    B[4][3 * a + 1] = gz, B[4][3 * a + 2] = gy;  // yz
    B[5][3 * a] = gz, B[5][3 * a + 2] = gx;      // xz
  }
}
}  // namespace

bool have_cholmod() {
#ifdef DEMFDM_HAVE_CHOLMOD
  return true;
#else
  return false;
#endif
}

LinearSolver linear_solver_from_name(const std::string& name) {
  if (name == "auto") return LinearSolver::kAuto;
  if (name == "cholmod") return LinearSolver::kCholmod;
  if (name == "ldlt") return LinearSolver::kLdlt;
  throw std::invalid_argument("fem: linear solver must be \"auto\", \"cholmod\" or \"ldlt\", found \"" + name + "\"");
}

Model::Model(const Params& p) : p_(p), mesh_(fdm::generate_mesh(p.mesh)) {
  if (p_.solver == LinearSolver::kCholmod && !have_cholmod())
    throw std::invalid_argument(
        "fem: continuum.linear_solver = \"cholmod\" but this build has no CHOLMOD (install libsuitesparse-dev and "
        "rebuild, or use \"ldlt\")");
  use_cholmod_ = p_.solver == LinearSolver::kCholmod || (p_.solver == LinearSolver::kAuto && have_cholmod());
  if (p_.materials.empty()) throw std::invalid_argument("fem: at least one material group is needed");
  const std::size_t n = mesh_.num_points(), nz = mesh_.num_zones();
  // Materials by zone centroid, later groups override earlier ones (as fdm::Model).
  zone_mat_.assign(nz, Mat{0, 0, 0});
  std::vector<bool> assigned(nz, false);
  for (const auto& g : p_.materials) {
    if (!(g.young > 0) || !(g.poisson > -1 && g.poisson < 0.5) || !(g.density >= 0)) {
      std::ostringstream os;
      os << "fem: material needs young > 0, poisson in (-1, 0.5), density >= 0; found " << g.young << ", " << g.poisson
         << ", " << g.density;
      throw std::invalid_argument(os.str());
    }
    for (std::size_t z = 0; z < nz; ++z) {
      std::array<double, 3> c{0, 0, 0};
      for (int k = 0; k < 8; ++k)
        for (int d = 0; d < 3; ++d) c[d] += mesh_.points[3 * mesh_.zones[8 * z + k] + d] / 8;
      if (!g.region || g.region->contains(c)) {
        zone_mat_[z] = Mat{g.density, g.young, g.poisson};
        assigned[z] = true;
      }
    }
  }
  for (std::size_t z = 0; z < nz; ++z)
    if (!assigned[z]) throw std::invalid_argument("fem: zone " + std::to_string(z) + " is in no material group");

  // Supports: strongbox (base fixed, rollers on x and y sides), as fdm::Model.
  fix_.assign(3 * n, 0);
  const int nx = static_cast<int>(mesh_.grid_x.size()) - 1, ny = static_cast<int>(mesh_.grid_y.size()) - 1;
  for (std::size_t g = 0; g < n; ++g) {
    const std::int32_t* ijk = &mesh_.point_ijk[3 * g];
    if (ijk[2] == 0) {
      fix_[3 * g] = fix_[3 * g + 1] = fix_[3 * g + 2] = 1;
      base_.push_back(static_cast<std::int32_t>(g));
    }
    if (ijk[0] == 0 || ijk[0] == nx) fix_[3 * g] = 1;
    if (ijk[1] == 0 || ijk[1] == ny) fix_[3 * g + 1] = 1;
  }
  free_of_.assign(3 * n, -1);
  for (std::size_t i = 0; i < 3 * n; ++i)
    if (!fix_[i]) free_of_[i] = nfree_++;

  fgrav_.assign(3 * n, 0.0);
  f0_.assign(3 * n, 0.0);
  fif_.assign(3 * mesh_.interface_points.size(), 0.0);
  fapp_.assign(3 * n, 0.0);
  u_.assign(3 * n, 0.0);
  sigma0_.assign(nz * 8 * 6, 0.0);
  assemble();
}

void Model::element_geometry(std::size_t z, double xi, double eta, double zeta, double dNdx[8][3],
                             double& detJ) const {
  double dN[8][3];
  for (int a = 0; a < 8; ++a) {
    double sx = kCorner[a][0], sy = kCorner[a][1], sz = kCorner[a][2];
    dN[a][0] = sx * (1 + sy * eta) * (1 + sz * zeta) / 8;
    dN[a][1] = sy * (1 + sx * xi) * (1 + sz * zeta) / 8;
    dN[a][2] = sz * (1 + sx * xi) * (1 + sy * eta) / 8;
  }
  double J[3][3] = {};  // J[i][j] = d x_j / d xi_i
  for (int a = 0; a < 8; ++a) {
    const double* x = &mesh_.points[3 * mesh_.zones[8 * z + a]];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) J[i][j] += dN[a][i] * x[j];
  }
  detJ = J[0][0] * (J[1][1] * J[2][2] - J[1][2] * J[2][1]) - J[0][1] * (J[1][0] * J[2][2] - J[1][2] * J[2][0]) +
         J[0][2] * (J[1][0] * J[2][1] - J[1][1] * J[2][0]);
  if (!(detJ > 0))
    throw std::invalid_argument("fem: zone " + std::to_string(z) + " has a non-positive Jacobian (inverted hexahedron)");
  double inv[3][3];
  inv[0][0] = (J[1][1] * J[2][2] - J[1][2] * J[2][1]) / detJ;
  inv[0][1] = (J[0][2] * J[2][1] - J[0][1] * J[2][2]) / detJ;
  inv[0][2] = (J[0][1] * J[1][2] - J[0][2] * J[1][1]) / detJ;
  inv[1][0] = (J[1][2] * J[2][0] - J[1][0] * J[2][2]) / detJ;
  inv[1][1] = (J[0][0] * J[2][2] - J[0][2] * J[2][0]) / detJ;
  inv[1][2] = (J[0][2] * J[1][0] - J[0][0] * J[1][2]) / detJ;
  inv[2][0] = (J[1][0] * J[2][1] - J[1][1] * J[2][0]) / detJ;
  inv[2][1] = (J[0][1] * J[2][0] - J[0][0] * J[2][1]) / detJ;
  inv[2][2] = (J[0][0] * J[1][1] - J[0][1] * J[1][0]) / detJ;
  // dN/dx_j = sum_i dN/dxi_i * (J^-1)[j][i]
  for (int a = 0; a < 8; ++a)
    for (int j = 0; j < 3; ++j) dNdx[a][j] = inv[j][0] * dN[a][0] + inv[j][1] * dN[a][1] + inv[j][2] * dN[a][2];
}

void Model::assemble() {
  auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = mesh_.num_points(), nz = mesh_.num_zones();
  std::vector<Eigen::Triplet<double>> all, freefree;
  all.reserve(nz * 576);
  freefree.reserve(nz * 576);
  for (std::size_t z = 0; z < nz; ++z) {
    double D[6][6];
    elasticity(zone_mat_[z].young, zone_mat_[z].nu, D);
    double Ke[24][24] = {};
    double vol = 0;
    double Ne_int[8] = {};
    for (int gp = 0; gp < 8; ++gp) {
      double xi = kCorner[gp][0] * kGauss, eta = kCorner[gp][1] * kGauss, zeta = kCorner[gp][2] * kGauss;
      double dNdx[8][3], detJ;
      element_geometry(z, xi, eta, zeta, dNdx, detJ);
      double B[6][24];
      strain_matrix(dNdx, B);
      double DB[6][24];
      for (int i = 0; i < 6; ++i)
        for (int j = 0; j < 24; ++j) {
          double s = 0;
          for (int k = 0; k < 6; ++k) s += D[i][k] * B[k][j];
          DB[i][j] = s;
        }
      for (int i = 0; i < 24; ++i)
        for (int j = 0; j < 24; ++j) {
          double s = 0;
          for (int k = 0; k < 6; ++k) s += B[k][i] * DB[k][j];
          Ke[i][j] += s * detJ;
        }
      for (int a = 0; a < 8; ++a)
        Ne_int[a] += (1 + kCorner[a][0] * xi) * (1 + kCorner[a][1] * eta) * (1 + kCorner[a][2] * zeta) / 8 * detJ;
      vol += detJ;
    }
    (void)vol;
    const std::int32_t* c = &mesh_.zones[8 * z];
    for (int a = 0; a < 8; ++a) {
      // Consistent gravity load: int N_a rho g dV.
      for (int d = 0; d < 3; ++d) fgrav_[3 * c[a] + d] += Ne_int[a] * zone_mat_[z].rho * p_.gravity[d];
      for (int b = 0; b < 8; ++b)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) {
            double v = Ke[3 * a + i][3 * b + j];
            int r = 3 * c[a] + i, s = 3 * c[b] + j;
            all.emplace_back(r, s, v);
            if (free_of_[r] >= 0 && free_of_[s] >= 0) freefree.emplace_back(free_of_[r], free_of_[s], v);
          }
    }
  }
  kfull_.resize(static_cast<Eigen::Index>(3 * n), static_cast<Eigen::Index>(3 * n));
  kfull_.setFromTriplets(all.begin(), all.end());
  kff_.resize(nfree_, nfree_);
  kff_.setFromTriplets(freefree.begin(), freefree.end());
  auto t1 = std::chrono::steady_clock::now();
  assembly_s_ = std::chrono::duration<double>(t1 - t0).count();
  factorise(kff_);
  factor_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
}

void Model::factorise(const Eigen::SparseMatrix<double>& a) {
  Eigen::ComputationInfo info;
#ifdef DEMFDM_HAVE_CHOLMOD
  if (use_cholmod_) {
    cholmod_.compute(a);
    info = cholmod_.info();
  } else
#endif
  {
    ldlt_.compute(a);
    info = ldlt_.info();
  }
  if (info != Eigen::Success)
    throw std::runtime_error("fem: the stiffness matrix could not be factorised (singular: check the supports)");
}

void Model::set_interface_springs(const std::vector<double>& k) {
  const auto& ip = mesh_.interface_points;
  if (!k.empty() && k.size() != ip.size())
    throw std::invalid_argument("fem: interface springs for " + std::to_string(k.size()) + " points, the mesh has " +
                                std::to_string(ip.size()));
  auto t0 = std::chrono::steady_clock::now();
  springs_.assign(3 * ip.size(), 0.0);
  Eigen::SparseMatrix<double> a = kff_;
  for (std::size_t p = 0; p < k.size(); ++p) {
    if (!(k[p] >= 0) || !std::isfinite(k[p]))
      throw std::invalid_argument("fem: interface spring " + std::to_string(p) + " must be finite and >= 0, found " +
                                  std::to_string(k[p]));
    for (int d = 0; d < 3; ++d) {
      const auto j = free_of_[3 * ip[p] + d];
      if (j < 0) continue;
      springs_[3 * p + d] = k[p];
      a.coeffRef(j, j) += k[p];
    }
  }
  factorise(a);
  ++refactorisations_;
  refactor_s_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

void Model::set_geostatic_stress(double k0) {
  const std::size_t nz = mesh_.num_zones();
  const double ztop = mesh_.grid_z.back();
  const double g = std::sqrt(p_.gravity[0] * p_.gravity[0] + p_.gravity[1] * p_.gravity[1] +
                             p_.gravity[2] * p_.gravity[2]);
  std::fill(f0_.begin(), f0_.end(), 0.0);
  for (std::size_t z = 0; z < nz; ++z) {
    const Mat& m = zone_mat_[z];
    double K0 = std::isnan(k0) ? m.nu / (1 - m.nu) : k0;
    const std::int32_t* c = &mesh_.zones[8 * z];
    for (int gp = 0; gp < 8; ++gp) {
      double xi = kCorner[gp][0] * kGauss, eta = kCorner[gp][1] * kGauss, zeta = kCorner[gp][2] * kGauss;
      double zp = 0;
      for (int a = 0; a < 8; ++a)
        zp += (1 + kCorner[a][0] * xi) * (1 + kCorner[a][1] * eta) * (1 + kCorner[a][2] * zeta) / 8 *
              mesh_.points[3 * c[a] + 2];
      double szz = -m.rho * g * (ztop - zp);
      double* s = &sigma0_[(z * 8 + gp) * 6];
      s[0] = s[1] = K0 * szz;
      s[2] = szz;
      s[3] = s[4] = s[5] = 0;
      double dNdx[8][3], detJ;
      element_geometry(z, xi, eta, zeta, dNdx, detJ);
      double B[6][24];
      strain_matrix(dNdx, B);
      for (int a = 0; a < 8; ++a)
        for (int d = 0; d < 3; ++d) {
          double f = 0;
          for (int k = 0; k < 6; ++k) f += B[k][3 * a + d] * s[k];
          f0_[3 * c[a] + d] += f * detJ;
        }
    }
  }
}

void Model::clear_initial_stress() {
  std::fill(f0_.begin(), f0_.end(), 0.0);
  std::fill(sigma0_.begin(), sigma0_.end(), 0.0);
}

void Model::set_interface_forces(const std::vector<double>& f) {
  if (f.size() != fif_.size())
    throw std::invalid_argument("fem: interface forces for " + std::to_string(f.size() / 3) + " points, the mesh has " +
                                std::to_string(fif_.size() / 3));
  fif_ = f;
}

void Model::set_applied_forces(const std::vector<double>& f) {
  if (f.size() != fapp_.size()) throw std::invalid_argument("fem: applied forces must have 3 values per gridpoint");
  fapp_ = f;
}

std::vector<double> Model::rhs_full() const {
  std::vector<double> r(fgrav_.size());
  for (std::size_t i = 0; i < r.size(); ++i) r[i] = fgrav_[i] + fapp_[i] - f0_[i];
  const auto& ip = mesh_.interface_points;
  for (std::size_t k = 0; k < ip.size(); ++k)
    for (int d = 0; d < 3; ++d) r[3 * ip[k] + d] += fif_[3 * k + d];
  return r;
}

Eigen::VectorXd Model::solve_free(const Eigen::VectorXd& b) const {
#ifdef DEMFDM_HAVE_CHOLMOD
  if (use_cholmod_) return cholmod_.solve(b);
#endif
  return ldlt_.solve(b);
}

void Model::solve(double omega) {
  if (!(omega > 0 && omega <= 1))
    throw std::invalid_argument("fem: relaxation factor must be in (0, 1], found " + std::to_string(omega));
  auto r = rhs_full();
  Eigen::VectorXd b(nfree_);
  for (std::size_t i = 0; i < r.size(); ++i)
    if (free_of_[i] >= 0) b[free_of_[i]] = r[i];
  // Interface springs D: (K + D) u_s = f + D u_{k-1} (set_interface_springs).
  const auto& ip = mesh_.interface_points;
  for (std::size_t k = 0; k < springs_.size(); ++k)
    if (springs_[k] > 0) b[free_of_[3 * ip[k / 3] + k % 3]] += springs_[k] * u_[3 * ip[k / 3] + k % 3];
  Eigen::VectorXd x = solve_free(b);
  double fmax = 0, umax = 0, dmax = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    if (free_of_[i] < 0) {
      u_[i] = 0.0;
      continue;
    }
    const double us = x[free_of_[i]];
    umax = std::max(umax, std::abs(us));
    dmax = std::max(dmax, std::abs(us - u_[i]));
    u_[i] = omega == 1.0 ? us : u_[i] + omega * (us - u_[i]);
    fmax = std::max(fmax, std::abs(r[i]));
  }
  gap_ = dmax / std::max(umax, 1e-300);
  // Out-of-balance force of every dof, K u - (f_ext - f_0): the residual on free dofs (not 0
  // while an under-relaxed state approaches the static answer), the support reactions on
  // fixed ones. One sparse product per solve, kept for reaction_sum().
  Eigen::Map<const Eigen::VectorXd> u(u_.data(), static_cast<Eigen::Index>(u_.size()));
  Eigen::VectorXd ku = kfull_ * u;
  unbalanced_.resize(r.size());
  double res = 0;
  for (std::size_t i = 0; i < r.size(); ++i) {
    unbalanced_[i] = ku[static_cast<Eigen::Index>(i)] - r[i];
    if (free_of_[i] >= 0) res = std::max(res, std::abs(unbalanced_[i]));
  }
  residual_ = res / std::max(fmax, 1e-300);
}

std::vector<double> Model::interface_response(const std::vector<double>& f_if) const {
  const auto& ip = mesh_.interface_points;
  if (f_if.size() != 3 * ip.size())
    throw std::invalid_argument("fem: interface loads for " + std::to_string(f_if.size() / 3) +
                                " points, the mesh has " + std::to_string(ip.size()));
  Eigen::VectorXd b = Eigen::VectorXd::Zero(nfree_);
  for (std::size_t k = 0; k < ip.size(); ++k)
    for (int d = 0; d < 3; ++d) {
      const auto j = free_of_[3 * ip[k] + d];
      if (j >= 0) b[j] += f_if[3 * k + d];
    }
  Eigen::VectorXd x = solve_free(b);
  std::vector<double> out(3 * ip.size(), 0.0);
  for (std::size_t k = 0; k < ip.size(); ++k)
    for (int d = 0; d < 3; ++d) {
      const auto j = free_of_[3 * ip[k] + d];
      if (j >= 0) out[3 * k + d] = x[j];
    }
  return out;
}

double Model::coupling_gain(const std::vector<double>& k, int max_iterations, double tol, int* iterations) const {
  const std::size_t n = mesh_.interface_points.size();
  if (k.size() != n)
    throw std::invalid_argument("fem: interface stiffness for " + std::to_string(k.size()) + " points, the mesh has " +
                                std::to_string(n));
  std::vector<double> sq(3 * n), x(3 * n), y(3 * n);
  double norm = 0;
  for (std::size_t i = 0; i < 3 * n; ++i) {
    sq[i] = std::sqrt(std::max(k[i / 3], 0.0));
    x[i] = sq[i];  // start: D^1/2 1, deterministic and in the span of every loaded dof
    norm += x[i] * x[i];
  }
  if (iterations) *iterations = 0;
  if (!(norm > 0)) return 0.0;
  double lambda = 0;
  for (int it = 1; it <= max_iterations; ++it) {
    norm = std::sqrt(norm);
    for (auto& v : x) v /= norm;
    for (std::size_t i = 0; i < 3 * n; ++i) y[i] = sq[i] * x[i];
    auto cy = interface_response(y);
    double rq = 0, yy = 0;
    for (std::size_t i = 0; i < 3 * n; ++i) {
      y[i] = sq[i] * cy[i];  // y = D^1/2 C D^1/2 x
      rq += x[i] * y[i];
      yy += y[i] * y[i];
    }
    if (iterations) *iterations = it;
    const bool done = it > 1 && std::abs(rq - lambda) <= tol * std::abs(rq);
    lambda = rq;
    if (done || !(yy > 0)) break;
    x = y;
    norm = yy;
  }
  return lambda;
}

std::vector<double> Model::interface_positions() const {
  const auto& ip = mesh_.interface_points;
  std::vector<double> x(3 * ip.size());
  for (std::size_t k = 0; k < ip.size(); ++k)
    for (int d = 0; d < 3; ++d) x[3 * k + d] = mesh_.points[3 * ip[k] + d] + u_[3 * ip[k] + d];
  return x;
}

std::vector<double> Model::interface_displacements() const {
  const auto& ip = mesh_.interface_points;
  std::vector<double> x(3 * ip.size());
  for (std::size_t k = 0; k < ip.size(); ++k)
    for (int d = 0; d < 3; ++d) x[3 * k + d] = u_[3 * ip[k] + d];
  return x;
}

std::array<double, 3> Model::reaction_sum(const std::vector<std::int32_t>& gps) const {
  std::array<double, 3> s{0, 0, 0};
  if (unbalanced_.empty()) return s;  // nothing solved yet
  for (auto g : gps)
    for (int d = 0; d < 3; ++d) s[d] += unbalanced_[3 * g + d];
  return s;
}

std::vector<double> Model::zone_stress() const {
  const std::size_t nz = mesh_.num_zones();
  std::vector<double> out(nz * 6, 0.0);
  for (std::size_t z = 0; z < nz; ++z) {
    double D[6][6];
    elasticity(zone_mat_[z].young, zone_mat_[z].nu, D);
    double dNdx[8][3], detJ, B[6][24];
    element_geometry(z, 0, 0, 0, dNdx, detJ);
    strain_matrix(dNdx, B);
    double eps[6] = {};
    const std::int32_t* c = &mesh_.zones[8 * z];
    for (int k = 0; k < 6; ++k)
      for (int a = 0; a < 8; ++a)
        for (int d = 0; d < 3; ++d) eps[k] += B[k][3 * a + d] * u_[3 * c[a] + d];
    for (int i = 0; i < 6; ++i) {
      double s = 0;
      for (int k = 0; k < 6; ++k) s += D[i][k] * eps[k];
      double s0 = 0;
      for (int gp = 0; gp < 8; ++gp) s0 += sigma0_[(z * 8 + gp) * 6 + i] / 8;
      out[6 * z + i] = s + s0;
    }
  }
  return out;
}

std::array<double, 3> Model::gravity_load() const {
  std::array<double, 3> s{0, 0, 0};
  for (std::size_t i = 0; i < fgrav_.size(); ++i) s[i % 3] += fgrav_[i];
  return s;
}

}  // namespace demfdm::fem

namespace demfdm::fem {

void Model::save_state(io::StateWriter& w) const {
  w.begin("fem_model");
  w.u64(num_points());
  w.u64(num_zones());
  w.i64(nfree_);
  for (const auto* v : {&u_, &fif_, &fapp_, &f0_, &sigma0_, &unbalanced_, &springs_}) w.f64s(*v);
  w.f64(residual_);
  w.f64(gap_);
  w.i64(refactorisations_);
  w.end();
}

void Model::load_state(io::SectionReader& r) {
  const auto np = r.u64(), nz = r.u64();
  const auto nf = r.i64();
  if (np != num_points() || nz != num_zones() || nf != nfree_)
    r.fail("the model was saved with " + std::to_string(np) + " gridpoints, " + std::to_string(nz) + " zones and " +
           std::to_string(nf) + " free dofs; this one has " + std::to_string(num_points()) + ", " +
           std::to_string(num_zones()) + " and " + std::to_string(nfree_) + " (another mesh or boundary)");
  std::vector<double> u = r.f64s(), fif = r.f64s(), fapp = r.f64s(), f0 = r.f64s(), sigma0 = r.f64s(),
                      unbalanced = r.f64s(), springs = r.f64s();
  const double residual = r.f64(), gap = r.f64();
  const auto refactorisations = r.i64();
  r.done();
  auto sized = [&](const std::vector<double>& v, std::size_t n, const char* what) {
    if (v.size() != n && !(v.empty() && n == 0))
      r.fail(std::string(what) + ": " + std::to_string(v.size()) + " values, the model has " + std::to_string(n));
  };
  sized(u, u_.size(), "displacements");
  sized(f0, f0_.size(), "geostatic loads");
  sized(sigma0, sigma0_.size(), "initial stresses");
  if (!springs.empty()) sized(springs, 3 * mesh_.interface_points.size(), "interface springs");
  u_ = std::move(u);
  fif_ = std::move(fif);
  fapp_ = std::move(fapp);
  f0_ = std::move(f0);
  sigma0_ = std::move(sigma0);
  unbalanced_ = std::move(unbalanced);
  residual_ = residual;
  gap_ = gap;
  // The factorisation of K + D with the saved springs: the matrix set_interface_springs() built.
  springs_ = std::move(springs);
  if (!springs_.empty()) {
    Eigen::SparseMatrix<double> a = kff_;
    const auto& ip = mesh_.interface_points;
    for (std::size_t p = 0; p < ip.size(); ++p)
      for (int d = 0; d < 3; ++d) {
        const auto j = free_of_[3 * ip[p] + d];
        if (j >= 0) a.coeffRef(j, j) += springs_[3 * p + d];
      }
    factorise(a);
  }
  refactorisations_ = refactorisations;
}

}  // namespace demfdm::fem
