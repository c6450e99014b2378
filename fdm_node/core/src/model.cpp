// Explicit FLAC3D-style continuum: see model.hpp for the design notes.
#include "demfdm/fdm/model.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <type_traits>

#include "demfdm/fdm/tet.hpp"
#include "zone_block.hpp"

namespace demfdm::fdm {
namespace {

// An imposed dt may exceed the critical one by this relative round-off (a caller dividing a
// coupling step into n sub-steps lands within a few ulps of it); the safety factor of
// docs/theory.md 5.7 covers it.
constexpr double kDtTolerance = 1.0 + 1e-9;

// Geometry of the 10 tetrahedra of a zone from its 8 corner positions: out[t*10 + 0..9] =
// g2, g3, g4, V (tet.hpp).
inline void zone_geometry(const double (*p)[3], double* out) {
  for (int t = 0; t < kTetsPerZone; ++t) {
    const auto& n = kZoneTets[t];
    const Vec3 p1{p[n[0]][0], p[n[0]][1], p[n[0]][2]};
    const Vec3 p2{p[n[1]][0], p[n[1]][1], p[n[1]][2]};
    const Vec3 p3{p[n[2]][0], p[n[2]][1], p[n[2]][2]};
    const Vec3 p4{p[n[3]][0], p[n[3]][1], p[n[3]][2]};
    tet_gradients(p1, p2, p3, p4, out + 10 * t);
  }
}

}  // namespace

Model::Model(const ModelParams& params) : Model(generate_mesh(params.mesh), params) {}

Model::Model(Mesh mesh, const ModelParams& params) : params_(params), mesh_(std::move(mesh)) {
  validate(params_);
  build();
}

void Model::build() {
  n_ = mesh_.num_points();
  nz_ = mesh_.num_zones();
  if (nz_ == 0) throw std::invalid_argument("mesh: expected at least one zone, found 0");
  x0_ = mesh_.points;
  x_ = x0_;
  u_.assign(3 * n_, 0.0);
  v_.assign(3 * n_, 0.0);
  fzone_.assign(3 * n_, 0.0);
  fext_.assign(3 * n_, 0.0);
  fapplied_.assign(3 * n_, 0.0);
  vfix_.assign(3 * n_, 0.0);
  fix_.assign(n_, 0);
  stress_.assign(nz_ * kTetsPerZone * 6, 0.0);
  zone_slot_.assign(nz_ * 24, 0.0);
  plastic_.assign(nz_, 0);
  gravity_ = {0.0, 0.0, -params_.gravity_level * kStandardGravity};

  // Materials: later groups override earlier ones (params.hpp).
  for (const auto& g : params_.materials) materials_.push_back(make_constants(g.material));
  zone_material_.assign(nz_, -1);
  for (std::size_t z = 0; z < nz_; ++z) {
    Vec3 c{0.0, 0.0, 0.0};
    for (int k = 0; k < 8; ++k)
      for (int d = 0; d < 3; ++d) c[d] += x0_[3 * mesh_.zones[8 * z + k] + d] / 8.0;
    for (std::size_t gi = 0; gi < params_.materials.size(); ++gi) {
      const auto& r = params_.materials[gi].region;
      if (!r || r->contains(c)) zone_material_[z] = static_cast<std::int32_t>(gi);
    }
    if (zone_material_[z] < 0) {
      std::ostringstream os;
      os << "materials: zone " << z << " (centroid " << c[0] << ", " << c[1] << ", " << c[2]
         << " m) is not covered by any material group; expected the groups to cover every zone";
      throw std::invalid_argument(os.str());
    }
    const auto model = params_.materials[zone_material_[z]].material.model;
    (model == Constitutive::kElastic ? elastic_zones_ : mc_zones_).push_back(static_cast<std::int32_t>(z));
  }

  // Gridpoint -> (zone, corner) table in ascending zone order: the fixed gather order.
  gp_zone_offset_.assign(n_ + 1, 0);
  for (std::int32_t id : mesh_.zones) ++gp_zone_offset_[id + 1];
  for (std::size_t g = 0; g < n_; ++g) gp_zone_offset_[g + 1] += gp_zone_offset_[g];
  gp_zone_entry_.assign(mesh_.zones.size(), 0);
  {
    std::vector<std::int32_t> fill(gp_zone_offset_.begin(), gp_zone_offset_.end() - 1);
    for (std::size_t e = 0; e < mesh_.zones.size(); ++e)
      gp_zone_entry_[fill[mesh_.zones[e]]++] = static_cast<std::int32_t>(e);
  }
  for (std::size_t g = 0; g < n_; ++g)
    if (mesh_.point_ijk[3 * g + 2] == 0) base_points_.push_back(static_cast<std::int32_t>(g));

  gp_interface_.assign(n_, -1);
  for (std::size_t l = 0; l < mesh_.interface_points.size(); ++l)
    gp_interface_[mesh_.interface_points[l]] = static_cast<std::int32_t>(l);
  fcouple_.assign(3 * mesh_.interface_points.size(), 0.0);
  kcouple_.assign(mesh_.interface_points.size(), 0.0);

  compute_geometry(x0_);
  compute_masses();
  rebuild_external_forces();
  zone_critical_dt_ = zone_critical_timestep();
  update_interface_critical_timestep();
  dt_ = params_.mode == Mode::kStatic ? 1.0 : critical_timestep();
  if (params_.strongbox_boundary) apply_strongbox_boundary();
  zone_pass(false);
}

void Model::compute_geometry(const std::vector<double>& pos) {
  geom_.assign(nz_ * kTetsPerZone * 10, 0.0);
  for (std::size_t z = 0; z < nz_; ++z) {
    double p[8][3];
    for (int k = 0; k < 8; ++k)
      for (int d = 0; d < 3; ++d) p[k][d] = pos[3 * mesh_.zones[8 * z + k] + d];
    zone_geometry(p, &geom_[z * 100]);
    for (int t = 0; t < kTetsPerZone; ++t)
      if (!(geom_[z * 100 + 10 * t + 9] > 0.0)) {
        std::ostringstream os;
        os << "mesh: zone " << z << " tetrahedron " << t << " has volume " << geom_[z * 100 + 10 * t + 9]
           << " m^3; expected > 0 (inverted or degenerate hexahedron)";
        throw std::invalid_argument(os.str());
      }
  }
}

void Model::compute_masses() {
  // Gravitational mass: rho V_t / 4 per tetrahedron node, averaged over the 2 overlays
  // (docs/theory.md 5.5). Static inertial mass: alpha1 max_f |a_f|^2 / (9 V_t) per tetrahedron
  // node, averaged over the overlays (docs/theory.md 5.6, U10). With |a_f| = 3V|g_f|:
  // alpha1 * V * max_l |g_l|^2.
  gmass_.assign(n_, 0.0);
  std::vector<double> smass(n_, 0.0);
  for (std::size_t z = 0; z < nz_; ++z) {
    const MaterialConstants& m = materials_[zone_material_[z]];
    const double* G = &geom_[z * 100];
    for (int t = 0; t < kTetsPerZone; ++t) {
      const double* g = G + 10 * t;
      const double V = g[9];
      double g1[3];
      for (int i = 0; i < 3; ++i) g1[i] = -(g[i] + g[3 + i] + g[6 + i]);
      double gmax = g1[0] * g1[0] + g1[1] * g1[1] + g1[2] * g1[2];
      for (int l = 0; l < 3; ++l)
        gmax = std::max(gmax, g[3 * l] * g[3 * l] + g[3 * l + 1] * g[3 * l + 1] + g[3 * l + 2] * g[3 * l + 2]);
      for (int l = 0; l < 4; ++l) {
        const std::int32_t gp = mesh_.zones[8 * z + kZoneTets[t][l]];
        gmass_[gp] += 0.5 * m.density * V / 4.0;
        smass[gp] += 0.5 * m.alpha1 * V * gmax;
      }
    }
  }
  zone_stiffness_ = smass;  // diagonal zone stiffness per gridpoint [N/m] (docs/theory.md 6.5)
  if (params_.mode == Mode::kStatic) {
    mass_base_.resize(n_);
    for (std::size_t g = 0; g < n_; ++g) mass_base_[g] = params_.static_mass_factor * smass[g];
    mass_ = mass_base_;
  } else {
    mass_ = gmass_;
  }
}

void Model::rebuild_external_forces() {
  for (std::size_t g = 0; g < n_; ++g)
    for (int d = 0; d < 3; ++d) fext_[3 * g + d] = gmass_[g] * gravity_[d] + fapplied_[3 * g + d];
}

double Model::critical_timestep() const { return std::min(zone_critical_dt_, interface_critical_dt_); }

void Model::update_interface_critical_timestep() {
  // Coupling stiffness (dynamic mode, docs/theory.md 6.5 option A): dt <= 0.5 sqrt(m_g / (k_gp +
  // k_zone)) at the interface gridpoints that carry contact stiffness. O(n_if).
  interface_critical_dt_ = std::numeric_limits<double>::infinity();
  if (params_.mode != Mode::kDynamic) return;
  for (std::size_t l = 0; l < kcouple_.size(); ++l) {
    if (kcouple_[l] <= 0.0) continue;
    const std::int32_t g = mesh_.interface_points[l];
    interface_critical_dt_ =
        std::min(interface_critical_dt_, 0.5 * std::sqrt(gmass_[g] / (kcouple_[l] + zone_stiffness_[g])));
  }
}

double Model::zone_critical_timestep() const {
  // dt = safety * min_t h_t / C_p, h_t = 3V / max|a| = 1 / max_l |g_l| (docs/theory.md 5.7).
  double best = std::numeric_limits<double>::infinity();
  std::vector<double> local;
  const std::vector<double>* geom = &geom_;
  if (params_.large_strain) {
    local.resize(nz_ * 100);
    for (std::size_t z = 0; z < nz_; ++z) {
      double p[8][3];
      for (int k = 0; k < 8; ++k)
        for (int d = 0; d < 3; ++d) p[k][d] = x_[3 * mesh_.zones[8 * z + k] + d];
      zone_geometry(p, &local[z * 100]);
    }
    geom = &local;
  }
  for (std::size_t z = 0; z < nz_; ++z) {
    const MaterialConstants& m = materials_[zone_material_[z]];
    const double cp = std::sqrt(m.alpha1 / m.density);
    for (int t = 0; t < kTetsPerZone; ++t) {
      const double* g = &(*geom)[z * 100 + 10 * t];
      double g1[3];
      for (int i = 0; i < 3; ++i) g1[i] = -(g[i] + g[3 + i] + g[6 + i]);
      double gmax = g1[0] * g1[0] + g1[1] * g1[1] + g1[2] * g1[2];
      for (int l = 0; l < 3; ++l)
        gmax = std::max(gmax, g[3 * l] * g[3 * l] + g[3 * l + 1] * g[3 * l + 1] + g[3 * l + 2] * g[3 * l + 2]);
      best = std::min(best, 1.0 / (std::sqrt(gmax) * cp));
    }
  }
  return params_.timestep_safety * best;
}

void Model::set_timestep(double dt) {
  if (params_.mode == Mode::kStatic)
    throw std::logic_error("set_timestep: the static (mass-scaled) mode runs with dt = 1");
  const double crit = critical_timestep();
  if (!(dt > 0.0) || dt > crit * kDtTolerance) {
    std::ostringstream os;
    os << "timestep: expected a value in (0, " << crit << "] s (critical timestep with safety factor "
       << params_.timestep_safety << "), found " << dt;
    throw std::invalid_argument(os.str());
  }
  dt_ = dt;
  dt_imposed_ = true;
}

// ---- zone kernel -------------------------------------------------------------------------

template <class Law, bool Large, bool ZoneAvg>
void Model::zone_kernel(std::span<const std::int32_t> zones, bool update_stress) {
  const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(zones.size());
  const std::ptrdiff_t min_parallel = params_.parallel_threshold;
  const zone::Ctx k{mesh_.zones.data(), v_.data(), geom_.data(), stress_.data(), zone_slot_.data(),
                    plastic_.data(), materials_.data(), zone_material_.data(), dt_};
  const std::int32_t* list = zones.data();
  // The lane kernel where there is one (elastic, small strain, stresses updated): kLanes zones
  // at a time, the last count mod kLanes zone by zone; the same bits as zone by zone.
  zone::Fn lanes = nullptr;
  if constexpr (std::is_same_v<Law, zone::ElasticLaw> && !Large) {
    if (update_stress && zone_kernel_ != ZoneKernel::kScalar) {
      const simd::Isa isa = zone_kernel_ == ZoneKernel::kBaseline ? simd::Isa::kBaseline
                            : zone_kernel_ == ZoneKernel::kAvx2   ? simd::Isa::kAvx2
                            : zone_kernel_ == ZoneKernel::kAvx512 ? simd::Isa::kAvx512
                                                                  : simd::best_isa();
      if (!simd::isa_available(isa))
        throw std::runtime_error(std::string("zone kernel: this CPU has no ") + simd::isa_name(isa));
      lanes = zone::elastic_kernel(isa, ZoneAvg);
    }
  }
  const std::ptrdiff_t blocks = lanes ? count / zone::kLanes : 0;
  const std::ptrdiff_t rest = blocks * zone::kLanes;
#pragma omp parallel if (count >= min_parallel)
  {
#pragma omp for schedule(static) nowait
    for (std::ptrdiff_t bi = 0; bi < blocks; ++bi) lanes(k, list + bi * zone::kLanes);
#pragma omp for schedule(static)
    for (std::ptrdiff_t zi = rest; zi < count; ++zi) {
      const std::int32_t z = list[zi];
      if constexpr (Large) {
        const std::int32_t* c = k.conn + 8 * static_cast<std::size_t>(z);
        double p[8][3];
        for (int q = 0; q < 8; ++q)
          for (int d = 0; d < 3; ++d) p[q][d] = x_[3 * static_cast<std::size_t>(c[q]) + d];
        double local_geom[100];
        zone_geometry(p, local_geom);
        zone::zone_body<Law, Large, ZoneAvg>(zone::ZoneRef{k, z, local_geom}, k.dt, update_stress);
      } else {
        zone::zone_body<Law, Large, ZoneAvg>(zone::ZoneRef{k, z, k.geom + 100 * static_cast<std::size_t>(z)}, k.dt,
                                             update_stress);
      }
    }
  }
}

void Model::zone_pass(bool update_stress) {
  const bool zavg = params_.averaging == VolumetricAveraging::kPerZone;
  auto run = [&]<class Law>(const std::vector<std::int32_t>& list) {
    if (list.empty()) return;
    if (params_.large_strain) {
      if (zavg) zone_kernel<Law, true, true>(list, update_stress);
      else zone_kernel<Law, true, false>(list, update_stress);
    } else {
      if (zavg) zone_kernel<Law, false, true>(list, update_stress);
      else zone_kernel<Law, false, false>(list, update_stress);
    }
  };
  run.template operator()<zone::ElasticLaw>(elastic_zones_);
  run.template operator()<zone::MohrCoulombLaw>(mc_zones_);
  gather_zone_forces();
}

void Model::gather_zone_forces() {
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(n_);
  const std::ptrdiff_t min_parallel = params_.parallel_threshold;
#pragma omp parallel for schedule(static) if (n >= min_parallel)
  for (std::ptrdiff_t g = 0; g < n; ++g) {
    double f[3] = {0.0, 0.0, 0.0};
    for (std::int32_t e = gp_zone_offset_[g]; e < gp_zone_offset_[g + 1]; ++e) {
      const double* s = &zone_slot_[3 * static_cast<std::size_t>(gp_zone_entry_[e])];
      f[0] += s[0];
      f[1] += s[1];
      f[2] += s[2];
    }
    for (int d = 0; d < 3; ++d) fzone_[3 * g + d] = f[d];
  }
}

// ---- stepping ------------------------------------------------------------------------------

void Model::step() {
  if (dt_imposed_ && dt_ > critical_timestep() * kDtTolerance) {
    std::ostringstream os;
    os << "step: the imposed dt = " << dt_ << " s exceeds the critical timestep " << critical_timestep()
       << " s (coupling stiffness or large-strain deformation lowered it, docs/theory.md 5.7, 6.5); "
       << "call set_timestep() with a smaller value";
    throw std::runtime_error(os.str());
  }
  using Clock = std::chrono::steady_clock;
  auto seconds = [](Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); };
  const auto t0 = Clock::now();
  // Coupling forces join the zone-force sum for this law of motion only; the zone pass
  // below overwrites fzone_ with the new zone forces.
  if (has_coupling_)
    for (std::size_t l = 0; l < mesh_.interface_points.size(); ++l)
      for (int d = 0; d < 3; ++d) fzone_[3 * mesh_.interface_points[l] + d] += fcouple_[3 * l + d];

  const auto t1 = Clock::now();
  // Law of motion with local damping (docs/theory.md 5.6).
  const double dt = dt_;
  const double alpha = params_.damping;
  const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(n_);
  const std::ptrdiff_t min_parallel = params_.parallel_threshold;
#pragma omp parallel for schedule(static) if (n >= min_parallel)
  for (std::ptrdiff_t g = 0; g < n; ++g) {
    const std::uint8_t fx = fix_[g];
    const double inv_m = 1.0 / mass_[g];
    for (int d = 0; d < 3; ++d) {
      const std::size_t i = 3 * static_cast<std::size_t>(g) + d;
      double v = v_[i];
      if (fx & (1u << d)) {
        v = vfix_[i];
      } else {
        const double F = fzone_[i] + fext_[i];
        const double Fd = v > 0.0 ? -alpha * std::abs(F) : (v < 0.0 ? alpha * std::abs(F) : 0.0);
        v += dt * (F + Fd) * inv_m;
      }
      v_[i] = v;
      u_[i] += v * dt;
      x_[i] += v * dt;
    }
  }
  const auto t2 = Clock::now();
  zone_pass(true);
  const auto t3 = Clock::now();
  phase_times_.interface += seconds(t0, t1);
  phase_times_.gridpoints += seconds(t1, t2);
  phase_times_.zones += seconds(t2, t3);
  ++step_;
  time_ += dt_;
  if (params_.large_strain && params_.mode == Mode::kDynamic && step_ % kTimestepCheckInterval == 0) {
    // Zones deform in large strain: refresh the critical step (docs/theory.md 5.7). An automatic
    // step follows it; an imposed one that became too large stops the next step().
    zone_critical_dt_ = zone_critical_timestep();
    if (!dt_imposed_) dt_ = critical_timestep();
  }
  if (params_.history_every > 0 && step_ % params_.history_every == 0) history_.push_back(sample());
}

void Model::step(std::int64_t n) {
  for (std::int64_t i = 0; i < n; ++i) step();
}

// ---- boundary conditions and loads -------------------------------------------------------------

void Model::fix_velocity(std::int32_t gp, std::uint8_t mask, const Vec3& velocity) {
  if (gp < 0 || static_cast<std::size_t>(gp) >= n_)
    throw std::invalid_argument("fix_velocity: gridpoint id out of range [0, " + std::to_string(n_) +
                                "), found " + std::to_string(gp));
  fix_[gp] |= mask;
  for (int d = 0; d < 3; ++d)
    if (mask & (1u << d)) {
      vfix_[3 * gp + d] = velocity[d];
      v_[3 * gp + d] = velocity[d];
    }
}

void Model::free_velocity(std::int32_t gp, std::uint8_t mask) {
  if (gp < 0 || static_cast<std::size_t>(gp) >= n_)
    throw std::invalid_argument("free_velocity: gridpoint id out of range [0, " + std::to_string(n_) +
                                "), found " + std::to_string(gp));
  fix_[gp] &= static_cast<std::uint8_t>(~mask);
}

void Model::apply_strongbox_boundary() {
  const int nx = static_cast<int>(mesh_.grid_x.size()) - 1;
  const int ny = static_cast<int>(mesh_.grid_y.size()) - 1;
  for (std::size_t g = 0; g < n_; ++g) {
    const std::int32_t* ijk = &mesh_.point_ijk[3 * g];
    std::uint8_t mask = 0;
    if (ijk[2] == 0) mask |= kFixAll;
    if (ijk[0] == 0 || ijk[0] == nx) mask |= kFixX;
    if (ijk[1] == 0 || ijk[1] == ny) mask |= kFixY;
    if (mask) fix_velocity(static_cast<std::int32_t>(g), mask);
  }
}

std::vector<std::int32_t> Model::gridpoints_on_plane(int axis, double value) const {
  if (axis < 0 || axis > 2) throw std::invalid_argument("gridpoints_on_plane: axis must be 0, 1 or 2");
  const auto& grid = axis == 0 ? mesh_.grid_x : axis == 1 ? mesh_.grid_y : mesh_.grid_z;
  const double tol = 1e-9 * (grid.back() - grid.front());
  int index = -1;
  for (std::size_t i = 0; i < grid.size(); ++i)
    if (std::abs(grid[i] - value) <= tol) index = static_cast<int>(i);
  if (index < 0) {
    std::ostringstream os;
    os << "gridpoints_on_plane: value " << value << " m is not a grid line of axis " << axis;
    throw std::invalid_argument(os.str());
  }
  std::vector<std::int32_t> out;
  for (std::size_t g = 0; g < n_; ++g)
    if (mesh_.point_ijk[3 * g + axis] == index) out.push_back(static_cast<std::int32_t>(g));
  return out;
}

void Model::add_point_load(std::int32_t gp, const Vec3& force) {
  if (gp < 0 || static_cast<std::size_t>(gp) >= n_)
    throw std::invalid_argument("add_point_load: gridpoint id out of range");
  for (int d = 0; d < 3; ++d) fapplied_[3 * gp + d] += force[d];
  rebuild_external_forces();
}

void Model::add_face_pressure(std::span<const BoundaryFace> faces, double pressure) {
  for (const auto& f : faces) {
    Vec3 p[4];
    for (int c = 0; c < 4; ++c)
      for (int d = 0; d < 3; ++d) p[c][d] = x0_[3 * f.points[c] + d];
    // Area vector of a planar or warped quad: 1/2 (p2 - p0) x (p3 - p1), outward.
    const Vec3 a = cross(sub(p[2], p[0]), sub(p[3], p[1]));
    for (int c = 0; c < 4; ++c)
      for (int d = 0; d < 3; ++d) fapplied_[3 * f.points[c] + d] += -pressure * 0.5 * a[d] / 4.0;
  }
  rebuild_external_forces();
}

void Model::clear_applied_loads() {
  std::fill(fapplied_.begin(), fapplied_.end(), 0.0);
  rebuild_external_forces();
}

// ---- coupling interface -----------------------------------------------------------------------

void Model::set_interface_forces(std::span<const double> forces) {
  if (forces.size() != fcouple_.size())
    throw std::invalid_argument("set_interface_forces: expected " + std::to_string(fcouple_.size()) +
                                " values (3 per interface gridpoint), found " + std::to_string(forces.size()));
  std::copy(forces.begin(), forces.end(), fcouple_.begin());
  has_coupling_ = true;
}

void Model::set_interface_stiffness(std::span<const double> stiffness) {
  if (stiffness.size() != kcouple_.size())
    throw std::invalid_argument("set_interface_stiffness: expected " + std::to_string(kcouple_.size()) +
                                " values (1 per interface gridpoint), found " + std::to_string(stiffness.size()));
  for (double k : stiffness)
    if (!(k >= 0.0) || !std::isfinite(k))
      throw std::invalid_argument("set_interface_stiffness: expected finite values >= 0 N/m, found " + std::to_string(k));
  std::copy(stiffness.begin(), stiffness.end(), kcouple_.begin());
  if (params_.mode == Mode::kStatic) {
    // m_I += k dt^2 with dt = 1 (docs/theory.md 6.5, option B).
    mass_ = mass_base_;
    for (std::size_t l = 0; l < kcouple_.size(); ++l) mass_[mesh_.interface_points[l]] += kcouple_[l];
    return;
  }
  // Dynamic mode: the stiffer interface may lower the stable step (docs/theory.md 6.5, U15). An
  // automatic step follows; an imposed one is checked by step().
  update_interface_critical_timestep();
  if (!dt_imposed_) dt_ = critical_timestep();
}

namespace {
std::vector<double> pick(const std::vector<double>& a, const std::vector<std::int32_t>& ids) {
  std::vector<double> out(3 * ids.size());
  for (std::size_t l = 0; l < ids.size(); ++l)
    for (int d = 0; d < 3; ++d) out[3 * l + d] = a[3 * static_cast<std::size_t>(ids[l]) + d];
  return out;
}
}  // namespace

std::vector<double> Model::interface_positions() const { return pick(x_, mesh_.interface_points); }
std::vector<double> Model::interface_velocities() const { return pick(v_, mesh_.interface_points); }
std::vector<double> Model::interface_displacements() const { return pick(u_, mesh_.interface_points); }

// ---- stresses --------------------------------------------------------------------------------

void Model::set_geostatic_stress(const GeostaticStress& gs) {
  const double ztop = std::isnan(gs.z_top) ? mesh_.grid_z.back() : gs.z_top;
  if (!std::isnan(gs.k0) && !(gs.k0 >= 0.0))
    throw std::invalid_argument("geostatic.k0: expected NaN (nu/(1-nu)) or a value >= 0, found " + std::to_string(gs.k0));
  const double gl = params_.gravity_level * kStandardGravity;
  for (std::size_t z = 0; z < nz_; ++z) {
    double zc = 0.0;
    for (int k = 0; k < 8; ++k) zc += x_[3 * mesh_.zones[8 * z + k] + 2] / 8.0;
    const Material& mat = params_.materials[zone_material_[z]].material;
    const double k0 = std::isnan(gs.k0) ? mat.poisson / (1.0 - mat.poisson) : gs.k0;
    // sigma_zz = -rho N g0 (z_top - z_c), sigma_h = K0 sigma_zz (docs/theory.md 5.9, tension positive).
    const double szz = -mat.density * gl * (ztop - zc);
    for (int t = 0; t < kTetsPerZone; ++t) {
      double* s = &stress_[60 * z + 6 * t];
      s[0] = k0 * szz;
      s[1] = k0 * szz;
      s[2] = szz;
      s[3] = s[4] = s[5] = 0.0;
    }
  }
  zone_pass(false);
}

void Model::set_uniform_stress(const std::array<double, 6>& sigma) {
  for (std::size_t t = 0; t < nz_ * kTetsPerZone; ++t)
    for (int i = 0; i < 6; ++i) stress_[6 * t + i] = sigma[i];
  zone_pass(false);
}

void Model::set_zone_stress(std::int32_t zone, const std::array<double, 6>& sigma) {
  if (zone < 0 || static_cast<std::size_t>(zone) >= nz_)
    throw std::invalid_argument("set_zone_stress: zone id out of range");
  for (int t = 0; t < kTetsPerZone; ++t)
    for (int i = 0; i < 6; ++i) stress_[60 * static_cast<std::size_t>(zone) + 6 * t + i] = sigma[i];
  zone_pass(false);
}

void Model::reset_displacements() { std::fill(u_.begin(), u_.end(), 0.0); }

void Model::reset_velocities() {
  for (std::size_t g = 0; g < n_; ++g)
    for (int d = 0; d < 3; ++d)
      if (!(fix_[g] & (1u << d))) v_[3 * g + d] = 0.0;
}

void Model::set_velocity(std::int32_t gp, const Vec3& v) {
  if (gp < 0 || static_cast<std::size_t>(gp) >= n_) throw std::invalid_argument("set_velocity: gridpoint id out of range");
  for (int d = 0; d < 3; ++d) v_[3 * gp + d] = v[d];
}

// ---- diagnostics ---------------------------------------------------------------------------------

void Model::net_force(std::size_t g, double* f) const {
  for (int d = 0; d < 3; ++d) f[d] = fzone_[3 * g + d] + fext_[3 * g + d];
  if (has_coupling_ && gp_interface_[g] >= 0)
    for (int d = 0; d < 3; ++d) f[d] += fcouple_[3 * static_cast<std::size_t>(gp_interface_[g]) + d];
}

Ratios Model::ratios() const {
  double sum_unb = 0.0, sum_app = 0.0, max_unb = 0.0, local = 0.0;
  std::size_t counted = 0;
  auto norm = [](const double* a) { return std::sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]); };
  for (std::size_t g = 0; g < n_; ++g) {
    if (fix_[g] == kFixAll) continue;  // only reactions act there
    double f[3];
    net_force(g, f);
    double fc[3] = {0.0, 0.0, 0.0};  // coupling force on this gridpoint (for F_app)
    if (has_coupling_ && gp_interface_[g] >= 0)
      for (int d = 0; d < 3; ++d) fc[d] = fcouple_[3 * static_cast<std::size_t>(gp_interface_[g]) + d];
    double unb2 = 0.0;
    for (int d = 0; d < 3; ++d)
      if (!(fix_[g] & (1u << d))) unb2 += f[d] * f[d];
    const double unb = std::sqrt(unb2);
    double app = 0.0;
    for (std::int32_t e = gp_zone_offset_[g]; e < gp_zone_offset_[g + 1]; ++e)
      app += norm(&zone_slot_[3 * static_cast<std::size_t>(gp_zone_entry_[e])]);
    const double grav[3] = {gmass_[g] * gravity_[0], gmass_[g] * gravity_[1], gmass_[g] * gravity_[2]};
    app += norm(grav) + norm(&fapplied_[3 * g]) + norm(fc);
    sum_unb += unb;
    sum_app += app;
    max_unb = std::max(max_unb, unb);
    if (app > 0.0) local = std::max(local, unb / app);
    ++counted;
  }
  Ratios r;
  if (counted == 0 || sum_app <= 0.0) return r;
  r.average = sum_unb / sum_app;
  r.max = max_unb / (sum_app / static_cast<double>(counted));
  r.local = local;
  return r;
}

double Model::kinetic_energy() const {
  double e = 0.0;
  for (std::size_t g = 0; g < n_; ++g)
    e += 0.5 * mass_[g] * (v_[3 * g] * v_[3 * g] + v_[3 * g + 1] * v_[3 * g + 1] + v_[3 * g + 2] * v_[3 * g + 2]);
  return e;
}

Vec3 Model::reaction_sum(std::span<const std::int32_t> gps) const {
  Vec3 r{0.0, 0.0, 0.0};
  for (std::int32_t g : gps) {
    double f[3];
    net_force(static_cast<std::size_t>(g), f);
    for (int d = 0; d < 3; ++d)
      if (fix_[g] & (1u << d)) r[d] -= f[d];
  }
  return r;
}

HistoryRecord Model::sample() const {
  HistoryRecord h;
  h.step = step_;
  h.time = time_;
  h.ratios = ratios();
  h.kinetic_energy = kinetic_energy();
  h.base_reaction = base_reaction();
  return h;
}

std::span<const double> Model::zone_forces() const { return fzone_; }

std::vector<double> Model::tet_velocity_gradients() const {
  std::vector<double> out(nz_ * kTetsPerZone * 9);
  for (std::size_t z = 0; z < nz_; ++z) {
    double vz[8][3], p[8][3], local[100];
    for (int k = 0; k < 8; ++k)
      for (int d = 0; d < 3; ++d) {
        vz[k][d] = v_[3 * mesh_.zones[8 * z + k] + d];
        p[k][d] = x_[3 * mesh_.zones[8 * z + k] + d];
      }
    const double* G = &geom_[z * 100];
    if (params_.large_strain) {
      zone_geometry(p, local);
      G = local;
    }
    for (int t = 0; t < kTetsPerZone; ++t) zone::tet_gradient(vz, kZoneTets[t], G + 10 * t, &out[(z * kTetsPerZone + t) * 9]);
  }
  return out;
}

double Model::total_gravitational_mass() const {
  double m = 0.0;
  for (double v : gmass_) m += v;
  return m;
}

std::uint64_t Model::state_hash() const {
  std::uint64_t h = 1469598103934665603ULL;
  auto mix = [&h](const std::vector<double>& a) {
    for (double v : a) {
      std::uint64_t bits;
      std::memcpy(&bits, &v, sizeof bits);
      for (int b = 0; b < 8; ++b) {
        h ^= (bits >> (8 * b)) & 0xffu;
        h *= 1099511628211ULL;
      }
    }
  };
  mix(x_);
  mix(v_);
  mix(u_);
  mix(stress_);
  return h;
}

std::vector<double> Model::zone_stress() const {
  std::vector<double> out(6 * nz_, 0.0);
  for (std::size_t z = 0; z < nz_; ++z) {
    // Weights: tetrahedron volumes of the geometry the stresses live on (current in large strain).
    double local[100];
    const double* G = &geom_[z * 100];
    if (params_.large_strain) {
      double p[8][3];
      for (int k = 0; k < 8; ++k)
        for (int d = 0; d < 3; ++d) p[k][d] = x_[3 * mesh_.zones[8 * z + k] + d];
      zone_geometry(p, local);
      G = local;
    }
    double vs = 0.0;
    for (int t = 0; t < kTetsPerZone; ++t) {
      const double V = G[10 * t + 9];
      vs += V;
      for (int i = 0; i < 6; ++i) out[6 * z + i] += V * stress_[60 * z + 6 * t + i];
    }
    for (int i = 0; i < 6; ++i) out[6 * z + i] /= vs;
  }
  return out;
}

}  // namespace demfdm::fdm
