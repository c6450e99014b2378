// Staged specimen generation (docs/theory.md §4). See specimen.hpp.
#include "demfdm/dem/specimen.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include "demfdm/dem/order_free_sum.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/specimen_steps.hpp"

namespace demfdm::dem {

namespace {
constexpr double kPi = 3.14159265358979323846;

using detail::quench;
using detail::require_automatic_step;

// The preparation's system: one World (specimen_steps.hpp).
struct OneWorld {
  World& w;
  const World& world() const { return w; }
  PeriodicServo* add_servo(const ServoParams& p, double d_min) {
    return static_cast<PeriodicServo*>(w.add_effect(std::make_unique<PeriodicServo>(p, d_min)));
  }
  void remove_servo(PeriodicServo* e) { w.remove_effect(e); }
  void step(std::int64_t n) { w.step(n); }
  void scale_radii(double f) {
    for (std::size_t i = 0; i < w.num_balls(); ++i) w.set_radius(i, w.balls().r[i] * f);
    w.prepare();
    w.refresh_contact_constants();
  }
  void set_contact_params(double mu, UnbondedMoments m) { detail::set_contact_params(w, mu, m); }
  std::size_t num_balls() const { return w.num_balls(); }
  void quench() { detail::quench(w); }
  void stop_cell() { w.set_strain_rate({}); }
  double friction() const { return w.params().ball_ball.linear.fric; }
  void set_friction(double mu) { detail::set_friction(w, mu); }
  double ratio() const { return w.unbalanced_ratio(); }
  Mat3 stress() const { return cell_stress(w); }
  double porosity() const { return cell_porosity(w); }
  double min_diameter() const { return detail::min_diameter(w); }
  World& part() { return w; }
  void prepare() { w.prepare(); }
  std::int64_t total(std::int64_t v) const { return v; }
  double kth_smallest(std::vector<double>& v, std::int64_t k) const {
    std::nth_element(v.begin(), v.begin() + (k - 1), v.end());
    return v[static_cast<std::size_t>(k - 1)];
  }
  Coordination coordination() const { return dem::coordination(w); }
  template <class T>
  void in_order(std::vector<T>&) const {}  // (one World's records are in its order)
};

void fill_report(World& w, StageReport& r) {
  OneWorld sys{w};
  detail::fill_report_on(sys, r);
}
}  // namespace

void validate(const RevParams& p) {
  RevParams keys = p;  // the table binds fields; the check only reads them
  RangeCheck check{"DEM", "dem.specimen."};
  describe(check, keys);
  if (!(p.psd.d_min < p.psd.d_max)) check.fail("d_min", "< d_max = " + std::to_string(p.psd.d_max) + " m", p.psd.d_min);
}

void validate(const ServoSettings& s) {
  ServoSettings keys = s;
  RangeCheck check{"DEM", "dem.specimen."};
  describe(check, keys);
}

void validate(const UcsParams& p) {
  UcsParams keys = p;
  RangeCheck check{"DEM", ""};  // a stage key: the scene names it within its stage
  describe(check, keys);
}

std::int64_t steps_for(const World& w, double tc) {
  if (!(tc > 0.0)) return 0;
  return std::max<std::int64_t>(1, std::llround(tc / w.params().dt_safety));
}

double psd_diameter(const PsdParams& p, double u) {
  const double a = p.d_min * p.scale, b = p.d_max * p.scale;
  const double ia = 1.0 / (a * a), ib = 1.0 / (b * b);
  return 1.0 / std::sqrt(ia - u * (ia - ib));
}

RevBall rev_ball(const RevParams& p, std::size_t np, const Vec3& o, const Vec3& L, std::size_t i) {
  const std::uint64_t k = np + 3 * static_cast<std::uint64_t>(i);
  return RevBall{psd_diameter(p.psd, Rng::uniform_at(p.seed, i)),
                 {o.x + Rng::uniform_at(p.seed, k) * L.x, o.y + Rng::uniform_at(p.seed, k + 1) * L.y,
                  o.z + Rng::uniform_at(p.seed, k + 2) * L.z}};
}

double psd_mean_volume(const PsdParams& p) {
  const double a = p.d_min * p.scale, b = p.d_max * p.scale;
  return kPi / 6.0 * 2.0 * (b - a) / (1.0 / (a * a) - 1.0 / (b * b));
}

double psd_expected_count(const PsdParams& p, double volume, double porosity) {
  return (1.0 - porosity) * volume / psd_mean_volume(p);
}

RevStart generate_rev_balls(World& w, const RevParams& p) {
  if (!w.periodic())
    throw std::invalid_argument("generate_rev: the world must have a periodic cell (periodic.enabled = true).");
  if (w.num_balls() != 0)
    throw std::invalid_argument("generate_rev: the world must be empty, found balls in it.");
  if (!(p.porosity_final > 0.0 && p.porosity_final < 1.0)) {
    std::ostringstream s;
    s << "generate_rev: 'porosity' (final porosity) must be in (0, 1), found " << p.porosity_final << ".";
    throw std::invalid_argument(s.str());
  }
  const double n1 = p.porosity_target < 0.0 ? p.porosity_final : p.porosity_target;
  if (!(n1 > 0.0 && n1 < 1.0)) {
    std::ostringstream s;
    s << "generate_rev: 'porosity_target' must be in (0, 1) (or negative: the final porosity), found "
      << p.porosity_target << ".";
    throw std::invalid_argument(s.str());
  }
  if (!(p.increment_budget > 0.0) || !(p.check_every > 0.0) || !(p.quench_every >= 0.0)) {
    std::ostringstream s;
    s << "generate_rev: 'increment_budget' and 'check_every' must be > 0 and 'quench_every' >= 0 critical steps, found "
      << p.increment_budget << ", " << p.check_every << " and " << p.quench_every << ".";
    throw std::invalid_argument(s.str());
  }
  require_automatic_step(w, "generate_rev");
  if (!(p.initial_scale > 0.0 && p.initial_scale <= 1.0) || p.increments < 1) {
    std::ostringstream s;
    s << "generate_rev: 'initial_scale' must be in (0, 1] and 'increments' >= 1, found "
      << p.initial_scale << " and " << p.increments << ".";
    throw std::invalid_argument(s.str());
  }
  const Vec3 o = w.cell_origin(), L = w.cell_length();
  const double V = w.cell_volume();
  // N_p: the given count, or the PSD's expected count at the final porosity (§0.4); the radius
  // expansion then reaches n₁ exactly whatever the sampled volume.
  const std::size_t np = p.n_particles ? p.n_particles
                                       : static_cast<std::size_t>(std::llround(psd_expected_count(p.psd, V, p.porosity_final)));
  if (np == 0) throw std::invalid_argument("generate_rev: the cell holds no ball at this PSD and porosity.");
  for (std::size_t i = 0; i < np; ++i) {  // each ball's draws keyed by its index (rev_ball)
    const RevBall b = rev_ball(p, np, o, L, i);
    w.add_ball(b.x, 0.5 * b.d * p.initial_scale);
  }
  // low friction during generation (§4.3 step 2); restored afterwards
  const double mu_final = w.params().ball_ball.linear.fric;
  w.mutable_params().ball_ball.linear.fric = p.fric;
  // The expansion is a granular set-up, not the material: its contacts are plain linear ones
  // whatever the ball-ball model (as PFC users generate with the linear model and assign the
  // bond model afterwards). An unbonded soft bond without the §3.5 moment law is exactly that, so
  // a soft-bond and a parallel-bond REV of one seed are the same packing (tests/coupled). After
  // the expansion no two balls touch (touching coordination 0), so restoring the moment law
  // changes no force.
  const UnbondedMoments moments_final = w.params().ball_ball.softbond.moments;
  w.mutable_params().ball_ball.softbond.moments = UnbondedMoments::kNone;
  w.prepare();
  w.refresh_contact_constants();
  return RevStart{n1, mu_final, moments_final};
}

StageReport generate_rev(World& w, const RevParams& p) {
  const RevStart st = generate_rev_balls(w, p);
  OneWorld sys{w};
  return detail::expand_rev_on(sys, p, st);
}

// §4.5: ε̇ = −α_s K⁻¹(s* − s)/t_c, |ε̇_a| ≤ max_face_step d_min/(L_a t_c), with t_c = Δt/f the
// critical step: the gain and the limit are per critical step, so the servo is the same
// controller in physical time at any step factor f (§4.11).
// K is the affine stiffness (U15). For an affine strain increment Δε (diagonal), contact c
// sees Δu = Δε ∘ ℓ, so Δσ_aa = Σ_b K_ab Δε_b with
//   K_ab = (1/V) Σ_c [ (K_n − K_s) ℓ_a n_a n_b ℓ_b + K_s ℓ_a² δ_ab ],
// whose diagonal is U15's (1/V)Σ(ℓ·e_a)²[K_n(n̂·e_a)² + K_s(1−(n̂·e_a)²)]. With `coupled` the
// 3×3 system is solved (the lateral servo anticipates the Poisson effect of the vertical
// one); otherwise only the diagonal is used. A rate above the limit scales the whole vector.
// The platen stress servo (kKinematics, after the step length is fixed): close a fraction α_s
// of the normal force error per step with the wall's contact stiffness, speed-limited.
void PlatenServo::apply(World& w, Phase) {
  PlaneWall& pw = w.plane(p_.wall);
  const double area = p_.area > 0.0 ? p_.area : 4.0 * pw.p.half1 * pw.p.half2;
  const double err = p_.stress * area - (-dot(pw.reaction, pw.p.normal));
  double vn = pw.k_sum > 0.0 ? p_.gain * err / (pw.k_sum * w.dt()) : (err > 0.0 ? p_.vmax : -p_.vmax);
  vn = std::clamp(vn, -p_.vmax, p_.vmax);
  pw.p.velocity = vn * pw.p.normal;
}

ServoTerm servo_term(const World& w, std::size_t c) {
  const auto& pc = w.pair_contacts();
  ServoTerm t;
  t.F = w.pair_force(c);
  t.l = w.branch(c);
  const ContactHist& h = pc.h[c];
  const BondHist* bh = pc.bond.empty() ? nullptr : &pc.bond[c];
  t.stiff = (h.flags & ContactHist::kActive) || (bh && bonded(bh->state));
  if (t.stiff) {
    const ContactFamilyParams& fam = w.params().ball_ball;
    const ContactStiffness st = visit_law(fam.model, [&](auto law) {
      return decltype(law)::stiffness(h, bh, fam, w.balls().r[pc.a[c]], w.balls().r[pc.b[c]]);
    });
    t.kn = st.k;
    t.ks = st.ks;
  }
  return t;
}

void ServoSums::add(const ServoTerm& t, ServoStiffness kind) {
  // (s -= F l is s += -(F l), bit for bit)
  for_each_servo_increment(t, kind, [&](int k, double v) { (k < 9 ? s[k] : K[(k - 9) / 3][(k - 9) % 3]) += v; });
}

void servo_columns(const ServoTerm& t, ServoStiffness kind, double* out) {
  std::fill(out, out + kServoColumns, 0.0);
  for_each_servo_increment(t, kind, [&](int k, double v) { out[k] += v; });
}

std::vector<int> servo_columns_read(const ServoParams& p) {
  std::vector<int> c{0, 4, 8, 9, 13, 17};  // the stress's and K's diagonals
  if (p.coupled)
    for (int k : {10, 11, 12, 14, 15, 16}) c.push_back(k);
  return c;
}

ServoSums servo_sums_of_columns(const double* sums, const int* cols, int m) {
  double all[kServoColumns] = {};
  for (int j = 0; j < m; ++j) all[cols ? cols[j] : j] = sums[j];
  ServoSums r;
  std::copy(all, all + 9, r.s.begin());
  std::copy(all + 9, all + 18, &r.K[0][0]);
  return r;
}

void PeriodicServo::apply(World& w, Phase) {
  ServoSums sums;
  if (columns_.empty()) columns_ = servo_columns_read(p_);
  if (reduce_) {
    sums = reduce_(w, p_.stiffness, columns_);
  } else if (w.params().order_free_sums) {  // the columns it reads, each one's order-free sum (DistDem's bits)
    const std::size_t n = w.pair_contacts().size(), m = columns_.size();
    std::vector<double> v(m * n);  // column j of contact c at v[j n + c]
    double t[kServoColumns];
    for (std::size_t c = 0; c < n; ++c) {
      servo_columns(servo_term(w, c), p_.stiffness, t);
      for (std::size_t j = 0; j < m; ++j) v[j * n + c] = t[columns_[j]];
    }
    double total[kServoColumns];
    for (std::size_t j = 0; j < m; ++j) total[j] = order_free_total(&v[j * n], n);
    sums = servo_sums_of_columns(total, columns_.data(), static_cast<int>(m));
  } else {
    const std::size_t nc = w.pair_contacts().size();
    for (std::size_t c = 0; c < nc; ++c) sums.add(servo_term(w, c), p_.stiffness);
  }
  const double V = w.cell_volume();
  stress_ = cell_stress_of(sums.s, V);
  const Vec3 L = w.cell_length();
  const auto& K = sums.K;
  const double tc = (w.dt() > 0.0 ? w.dt() : 1.0) / w.params().dt_safety;
  double err[3] = {0, 0, 0};
  int idx[3], na = 0;
  for (int a = 0; a < 3; ++a)
    if (p_.active[a]) {
      err[a] = p_.target[a] - (-stress_[4 * a]);
      idx[na++] = a;
    }
  Vec3 ed{};
  // Solve the active sub-system K_sub x = −α err/Δt (Gaussian elimination, ≤ 3×3).
  double M[3][4] = {};
  bool ok = true;
  for (int i = 0; i < na; ++i) {
    for (int j = 0; j < na; ++j)
      M[i][j] = (p_.coupled || i == j) ? K[idx[i]][idx[j]] / V : 0.0;
    M[i][3] = -p_.gain * err[idx[i]] / tc;
  }
  for (int i = 0; i < na && ok; ++i) {
    int piv = i;
    for (int r = i + 1; r < na; ++r)
      if (std::abs(M[r][i]) > std::abs(M[piv][i])) piv = r;
    if (!(std::abs(M[piv][i]) > 0.0)) { ok = false; break; }
    for (int k = 0; k < 4; ++k) std::swap(M[i][k], M[piv][k]);
    for (int r = 0; r < na; ++r) {
      if (r == i) continue;
      const double f = M[r][i] / M[i][i];
      for (int k = i; k < 4; ++k) M[r][k] -= f * M[i][k];
    }
  }
  double scale = 1.0;
  for (int i = 0; i < na; ++i) {
    const int a = idx[i];
    const double emax = p_.max_face_step * d_min_ / (L[a] * tc);
    // no contacts yet: compress (or expand) at the limit rate
    ed[a] = ok ? M[i][3] / M[i][i] : (err[a] > 0.0 ? -emax : emax);
    if (std::abs(ed[a]) > emax) scale = std::min(scale, emax / std::abs(ed[a]));
  }
  w.set_strain_rate(ed * scale);
}

StageReport servo_until(World& w, const ServoParams& p, double stress_tol, double ratio_tol,
                        double hold, double budget_tc, double* overshoot) {
  OneWorld sys{w};
  return detail::servo_until_on(sys, p, stress_tol, ratio_tol, hold, budget_tc, overshoot);
}

StageReport servo_specimen(World& w, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                           double budget, double compaction_fric) {
  OneWorld sys{w};
  return detail::servo_specimen_on(sys, p, stress_tol, ratio_tol, hold, budget, compaction_fric);
}

StageReport install_bonds(World& w, double lo, double hi) {
  OneWorld sys{w};
  return detail::install_bonds_on(sys, lo, hi);
}

double gap_for_coordination(World& w, double z_target, double gap_floor) {
  OneWorld sys{w};
  return detail::gap_for_coordination_on(sys, z_target, gap_floor);
}

StageReport install_bonds_to_coordination(World& w, double z_target, double gap_floor) {
  OneWorld sys{w};
  return detail::install_bonds_to_coordination_on(sys, z_target, gap_floor);
}

void bond_specimen(World& w, StageReport& r, double bond_coordination, double gap_floor) {
  OneWorld sys{w};
  detail::bond_specimen_on(sys, r, bond_coordination, gap_floor);
}

ReplicaLayout::ReplicaLayout(const World& rev, const ReplicateParams& p)
    : n_{p.nx, p.ny, p.nz}, L_(rev.cell_length()), keep_(p.keep_periodic) {
  if (!rev.periodic()) throw std::invalid_argument("replicate: the world must have a periodic cell.");
  if (p.nx < 1 || p.ny < 1 || p.nz < 1) {
    std::ostringstream s;
    s << "replicate: copies 'nx', 'ny', 'nz' must be >= 1, found " << p.nx << ", " << p.ny << ", " << p.nz << ".";
    throw std::invalid_argument(s.str());
  }
}

Vec3 ReplicaLayout::offset(int c) const {
  int ci[3];
  coords(c, ci);
  return {ci[0] * L_.x, ci[1] * L_.y, ci[2] * L_.z};
}

int ReplicaLayout::partner(int c, const std::array<std::int8_t, 4>& s, std::array<std::int8_t, 4>& out) const {
  int ci[3], cj[3];
  coords(c, ci);
  out = {0, 0, 0, 0};
  for (int a = 0; a < 3; ++a) {
    cj[a] = ci[a] + s[static_cast<std::size_t>(a)];
    if (cj[a] < 0 || cj[a] >= n_[a]) {
      if (!keep_) return -1;
      const int wrap = cj[a] < 0 ? -1 : 1;
      cj[a] -= wrap * n_[a];
      out[static_cast<std::size_t>(a)] = static_cast<std::int8_t>(wrap);
    }
  }
  return index(cj);
}

std::int64_t ReplicaLayout::kept(const std::array<std::int8_t, 4>& s) const {
  if (keep_) return count();
  std::int64_t k = 1;
  for (int a = 0; a < 3; ++a) k *= std::max(0, n_[a] - std::abs(static_cast<int>(s[static_cast<std::size_t>(a)])));
  return k;
}

std::string ReplicaLayout::what(std::size_t rev_balls, std::size_t block_balls, std::int64_t kept,
                                std::int64_t dropped) const {
  std::ostringstream s;
  s << "replicated " << rev_balls << " balls " << n_[0] << "x" << n_[1] << "x" << n_[2] << " into " << block_balls
    << " balls; " << kept << " contacts copied, " << dropped << " dropped on new boundaries";
  return s.str();
}

double replica_density(const Particles& pt, std::size_t b) {
  return pt.m[b] / (4.0 / 3.0 * kPi * pt.r[b] * pt.r[b] * pt.r[b]);
}

StageReport replicate(World& w, const ReplicateParams& p) {
  const ReplicaLayout lay(w, p);
  w.prepare();  // wrap positions into the cell and refresh the image shifts
  const std::size_t n = w.num_balls();
  const Vec3 o = w.cell_origin();
  const int ncopy = lay.count();
  // snapshot of the original contacts
  const PairContacts old = w.pair_contacts();
  auto& pt = w.balls();
  for (int c = 1; c < ncopy; ++c) {
    const Vec3 off = lay.offset(c);
    for (std::size_t b = 0; b < n; ++b) {
      const std::size_t row = w.add_ball(pt.x[b] + off, pt.r[b], replica_density(pt, b));
      pt.v[row] = pt.v[b];
      pt.w[row] = pt.w[b];
      pt.fix[row] = pt.fix[b];
    }
  }
  w.clear_contacts();
  std::int64_t kept = 0, dropped = 0;
  for (int c = 0; c < ncopy; ++c)
    for (std::size_t q = 0; q < old.size(); ++q) {
      std::array<std::int8_t, 4> s{};
      const int c2 = lay.partner(c, old.shift[q], s);
      if (c2 < 0) {
        ++dropped;
        continue;
      }
      const auto a = static_cast<std::uint32_t>(static_cast<std::size_t>(c) * n + old.a[q]);
      const auto b = static_cast<std::uint32_t>(static_cast<std::size_t>(c2) * n + old.b[q]);
      w.append_pair(a, b, s, old.h[q], old.bond.empty() ? nullptr : &old.bond[q]);
      ++kept;
    }
  if (p.keep_periodic) {
    w.set_cell(o, lay.length());
  } else {
    w.mutable_params().periodic.enabled = false;
  }
  // Rows in copy order lie far apart in space; along a space-filling curve a contact's two balls
  // are near each other in memory (the ball-ball pass of the default scene 0.70-0.77 of its time
  // at one thread, docs/speed.md session 36). The sums then run in another order.
  if (p.spatial_order) w.reorder_spatially();
  w.prepare();
  StageReport r;
  r.count = w.num_balls();
  fill_report(w, r);
  r.what = lay.what(n, r.count, kept, dropped);
  return r;
}

StageReport depth_scale(World& w, const DepthScaleParams& p) {
  OneWorld sys{w};
  return detail::depth_scale_on(sys, p);
}

StageReport assign_interface_bond_forces(World& w, const InterfaceBondParams& p) {
  OneWorld sys{w};
  return detail::assign_interface_bond_forces_on(sys, p);
}

StageReport assign_interface_bond_forces(World& w, double band) {
  InterfaceBondParams p;
  p.mode = InterfaceBondForce::kMeanContact;
  p.band = band;
  return assign_interface_bond_forces(w, p);
}

StageReport set_gravity(World& w, bool on, double g_level) {
  w.set_gravity(on, g_level);
  StageReport r;
  fill_report(w, r);
  std::ostringstream s;
  s << "gravity " << (on ? "on" : "off") << " at " << g_level << " g";
  r.what = s.str();
  return r;
}

StageReport cycle_to_equilibrium(World& w, double ratio_tol, std::int64_t budget) {
  StageReport r;
  bool ok;
  OneWorld sys{w};
  r.steps = detail::cycle_on(sys, ratio_tol, budget, ok);
  r.converged = ok;
  fill_report(w, r);
  std::ostringstream s;
  s << "cycled " << r.steps << " steps to ratio " << r.ratio << (ok ? " (converged)" : " (budget spent)");
  r.what = s.str();
  return r;
}

UcsResult unconfined_compression(World& w, const UcsParams& p) {
  if (w.periodic())
    throw std::invalid_argument("unconfined_compression: the world must not be periodic (replicate with keep_periodic = false first).");
  if (!(p.strain_rate > 0.0) || !(p.max_strain > 0.0) || p.sample_every < 1) {
    std::ostringstream s;
    s << "unconfined_compression: 'strain_rate' and 'max_strain' must be > 0 and 'sample_every' >= 1, found "
      << p.strain_rate << ", " << p.max_strain << ", " << p.sample_every << ".";
    throw std::invalid_argument(s.str());
  }
  UcsResult res;
  // Opening the periodic cell releases the confinement: let the free specimen settle first
  // so that the transient does not enter the stress-strain curve.
  // Local damping does not conserve momentum: zero the velocities before and after settling so
  // that the specimen does not drift into one platen as a rigid body.
  quench(w);
  res.settle = cycle_to_equilibrium(w, p.settle_ratio, p.settle_steps);
  quench(w);
  const auto& pt = w.balls();
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < pt.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], pt.x[i][k] - pt.r[i]);
      hi[k] = std::max(hi[k], pt.x[i][k] + pt.r[i]);
    }
  double H0 = hi.z - lo.z;
  const double area = (hi.x - lo.x) * (hi.y - lo.y);
  const double v = 0.5 * p.strain_rate * H0;
  const bool seat = p.seat_stress > 0.0;
  PlaneWallParams bot, top;
  bot.point = {0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), lo.z};
  bot.normal = {0, 0, 1};
  bot.velocity = {0, 0, v};
  top.point = {bot.point.x, bot.point.y, hi.z};
  top.normal = {0, 0, -1};
  top.velocity = {0, 0, -v};
  const int ib = w.add_plane(bot), it = w.add_plane(top);
  std::vector<Effect*> seating;
  if (seat)
    for (int i : {ib, it}) {
      PlatenServoParams sp;
      sp.wall = i;
      sp.stress = p.seat_stress;
      sp.area = area;
      sp.vmax = p.seat_speed * v;
      seating.push_back(w.add_effect(std::make_unique<PlatenServo>(sp)));
    }
  auto platen_stress = [&] { return 0.5 * (-w.plane(ib).reaction.z + w.plane(it).reaction.z) / area; };
  if (seat) {
    // Seating: both platens servo onto the rough ends until each carries seat_stress within 5 %
    // for 5 consecutive checks (only the tallest grains touch a platen placed at the extremes).
    int held = 0;
    while (res.seat.steps < p.seat_steps) {
      w.step(p.sample_every);
      res.seat.steps += p.sample_every;
      const double sb = -w.plane(ib).reaction.z / area, st = w.plane(it).reaction.z / area;
      const bool in = std::abs(sb / p.seat_stress - 1.0) < 0.05 && std::abs(st / p.seat_stress - 1.0) < 0.05;
      held = in ? held + 1 : 0;
      if (held >= 5) break;
    }
    res.seat.converged = held >= 5;
    res.seat.ratio = w.unbalanced_ratio();
    std::ostringstream s;
    s << "platens seated at " << platen_stress() << " Pa in " << res.seat.steps << " steps"
      << (res.seat.converged ? "" : " (budget spent)");
    res.seat.what = s.str();
    for (Effect* e : seating) w.remove_effect(e);
    w.plane(ib).p.velocity = {0, 0, v};
    w.plane(it).p.velocity = {0, 0, -v};
    H0 = w.plane(it).p.point.z - w.plane(ib).p.point.z;
  }
  const double s_seat = seat ? platen_stress() : 0.0;
  std::int64_t steps = 0;
  bool past_peak = false;
  while (true) {
    w.step(p.sample_every);
    steps += p.sample_every;
    const double H = w.plane(it).p.point.z - w.plane(ib).p.point.z;
    const double strain = (H0 - H) / H0;
    const double stress = platen_stress();
    res.curve.push_back({strain, stress});
    if (stress > res.peak) {
      res.peak = stress;
      res.peak_strain = strain;
    } else if (stress < p.stop_fraction * res.peak && res.peak > 4.0 * s_seat && res.peak > 0.0 &&
               strain >= 1.2 * res.peak_strain) {
      past_peak = true;
    }
    if (past_peak || strain >= p.max_strain) break;
  }
  for (std::size_t k = 0; k < res.curve.size(); ++k)
    if (res.curve[k].stress >= 0.5 * res.peak) {
      res.e50 = (res.curve[k].stress - s_seat) / res.curve[k].strain;
      break;
    }
  res.report.steps = steps;
  res.report.converged = past_peak;
  res.report.ratio = w.unbalanced_ratio();
  std::ostringstream s;
  s << "unconfined compression (after settling: " << res.settle.what << "; " << res.seat.what << "): peak " << res.peak << " Pa at strain "
    << res.peak_strain << ", E50 " << res.e50 << " Pa in " << steps << " steps"
    << (past_peak ? "" : " (stopped at max_strain before the post-peak drop)");
  res.report.what = s.str();
  return res;
}

UcsResult unconfined_compression_column(World& w, const UcsParams& p, double lateral_factor) {
  if (!w.periodic())
    throw std::invalid_argument("unconfined_compression_column: the world must have a periodic cell (the servoed REV).");
  if (!(p.strain_rate > 0.0) || !(p.max_strain > 0.0) || p.sample_every < 1 || !(lateral_factor >= 2.0)) {
    std::ostringstream s;
    s << "unconfined_compression_column: 'strain_rate' and 'max_strain' must be > 0, 'sample_every' >= 1 and "
         "the lateral factor >= 2, found "
      << p.strain_rate << ", " << p.max_strain << ", " << p.sample_every << ", " << lateral_factor << ".";
    throw std::invalid_argument(s.str());
  }
  w.prepare();  // wrap positions into the cell, current image shifts
  const Vec3 o = w.cell_origin(), L = w.cell_length();
  const PairContacts old = w.pair_contacts();
  w.clear_contacts();
  std::size_t kept = 0, dropped = 0;
  for (std::size_t q = 0; q < old.size(); ++q) {
    if (old.shift[q][0] != 0 || old.shift[q][1] != 0) { ++dropped; continue; }
    w.append_pair(old.a[q], old.b[q], old.shift[q], old.h[q], old.bond.empty() ? nullptr : &old.bond[q]);
    ++kept;
  }
  const double f = lateral_factor;
  w.set_cell({o.x - 0.5 * (f - 1.0) * L.x, o.y - 0.5 * (f - 1.0) * L.y, o.z}, {f * L.x, f * L.y, L.z});
  w.prepare();
  UcsResult res;
  quench(w);
  res.settle = cycle_to_equilibrium(w, p.settle_ratio, p.settle_steps);
  quench(w);
  const double area_ratio = f * f;  // cell cross-section / REV cross-section
  const double Lz0 = w.cell_length().z;
  std::int64_t steps = 0;
  bool past_peak = false;
  w.set_strain_rate({0.0, 0.0, -p.strain_rate});
  while (true) {
    w.step(p.sample_every);
    steps += p.sample_every;
    const double strain = 1.0 - w.cell_length().z / Lz0;
    const double stress = -cell_stress(w)[8] * area_ratio;
    res.curve.push_back({strain, stress});
    if (stress > res.peak) {
      res.peak = stress;
      res.peak_strain = strain;
    } else if (res.peak > 0.0 && stress < p.stop_fraction * res.peak && strain >= 1.2 * res.peak_strain) {
      past_peak = true;
    }
    if (past_peak || strain >= p.max_strain) break;
  }
  w.set_strain_rate({});
  // E50: secant from the start of loading to the first sample at half the peak (the settled
  // column starts near zero axial stress).
  const double s0 = 0.0;
  for (const auto& c : res.curve)
    if (c.stress >= 0.5 * res.peak) {
      res.e50 = (c.stress - s0) / c.strain;
      break;
    }
  res.report.steps = steps;
  res.report.converged = past_peak;
  res.report.ratio = w.unbalanced_ratio();
  std::ostringstream s;
  s << "unconfined compression of a z-periodic column (" << kept << " contacts kept, " << dropped
    << " across the lateral faces dropped; settling: " << res.settle.what << "): peak " << res.peak
    << " Pa at strain " << res.peak_strain << ", E50 " << res.e50 << " Pa in " << steps << " steps"
    << (past_peak ? "" : " (stopped at max_strain before the post-peak drop)");
  res.report.what = s.str();
  return res;
}

}  // namespace demfdm::dem
