// The stepping halves of specimen preparation (docs/theory.md §4.3, §4.5, §4.11), written once for
// one World (specimen.cpp) and for the DEM on MPI ranks (DistDem, dist.cpp): the REV's radius
// expansion (expand_rev_on, with cycle_on) and its servo (servo_until_on, servo_specimen_on).
// A system S gives:
//   const World& world()       the World whose parameters and cell the rules read (on the ranks:
//                              this rank's part; every rank's parameters and cell are the same)
//   void step(std::int64_t n), void quench()        n steps; every velocity and spin zeroed
//   void scale_radii(double f)  every radius times f, then prepare and refresh the contact constants
//   void set_contact_params(double mu, UnbondedMoments m)   the ball-ball friction and the soft
//                              bond's unbonded moments, the contact constants refreshed
//   double friction(), void set_friction(double)   the ball-ball friction (constants refreshed)
//   PeriodicServo* add_servo(const ServoParams&, double d_min), void remove_servo(PeriodicServo*)
//   void stop_cell()           the cell's strain rate set to 0
//   double ratio(), Mat3 stress(), double porosity(), double min_diameter(), size_t num_balls()
//                              the unbalanced ratio, cell_stress, cell_porosity, the smallest
//                              diameter and the ball count of the whole packing (on the ranks:
//                              collective, one World's bits)
// and, for the bonding (§4.6) and the depth scaling (§4.9):
//   World& part()              the World this process holds (one World: the World; on the ranks
//                              this rank's part, whose list also holds the pairs of its balls
//                              with another rank's ball A)
//   void prepare()             World::prepare of the whole packing (on the ranks: collective)
//   std::int64_t total(std::int64_t)   the sum over the ranks (one World: the value)
//   double kth_smallest(std::vector<double>& v, std::int64_t k)   the k-th smallest (1-based)
//                              of every rank's v together (v may be reordered)
//   Coordination coordination()   measure.hpp's coordination of the whole packing
//   void in_order(std::vector<T>& v)   every rank's records v, on every rank, in one World's
//                              order (by T::key(); one World: v as it is, already in that order)
// A count takes only the pairs whose ball A is no ghost (owned_a), so each pair counts once.
// On the ranks every rank runs the loops: every decision reads values that are the same bits on
// every rank, so the ranks take the same branches and meet in the same collectives.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/specimen.hpp"

namespace demfdm::dem::detail {

// Specimen preparation steps on the automatic step f t_c (steps_for converts its rules).
inline void require_automatic_step(const World& w, const char* what) {
  if (w.params().dt_fixed > 0.0) {
    std::ostringstream s;
    s << what << ": specimen preparation counts its rules in critical steps and must run on the automatic step "
      << "(dt_fixed = 0), found dt_fixed = " << w.params().dt_fixed << " s.";
    throw std::invalid_argument(s.str());
  }
}

// Cycle until ratio < tol (checked every `every` steps) or budget; returns steps run. With
// quench_every > 0 the velocities are zeroed every quench_every steps (a multiple of the check
// interval is used).
template <class S>
std::int64_t cycle_on(S& sys, double tol, std::int64_t budget, bool& ok, std::int64_t every = 50,
                      std::int64_t quench_every = 0) {
  std::int64_t s = 0;
  ok = false;
  if (quench_every > 0) every = std::min(every, quench_every);
  while (s < budget) {
    const std::int64_t k = std::min<std::int64_t>(every, budget - s);
    sys.step(k);
    s += k;
    if (sys.ratio() < tol) { ok = true; break; }
    if (quench_every > 0 && s % quench_every == 0) sys.quench();
  }
  return s;
}

// Every ball's velocity and spin zeroed; the smallest ball diameter (+inf without balls).
inline void quench(World& w) {
  auto& pt = w.balls();
  std::fill(pt.v.begin(), pt.v.end(), Vec3{});
  std::fill(pt.w.begin(), pt.w.end(), Vec3{});
}
inline double min_diameter(const World& w) {
  double d = std::numeric_limits<double>::infinity();
  for (double r : w.balls().r) d = std::min(d, 2.0 * r);
  return d;
}

// The ball-ball friction, and with it the soft bond's unbonded moments, of a World, its contact
// constants refreshed (the systems' set_friction and set_contact_params).
inline void set_friction(World& w, double mu) {
  w.mutable_params().ball_ball.linear.fric = mu;
  w.refresh_contact_constants();
}
inline void set_contact_params(World& w, double mu, UnbondedMoments m) {
  w.mutable_params().ball_ball.linear.fric = mu;
  w.mutable_params().ball_ball.softbond.moments = m;
  w.refresh_contact_constants();
}

template <class S>
void fill_report_on(S& s, StageReport& r) {
  r.ratio = s.ratio();
  if (s.world().periodic()) {
    r.stress = s.stress();
    r.porosity = s.porosity();
  }
}

template <class S>
StageReport servo_until_on(S& sys, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                           double budget_tc, double* overshoot) {
  const World& w = sys.world();
  if (!w.periodic()) throw std::invalid_argument("servo_until: the world must have a periodic cell.");
  require_automatic_step(w, "servo_until");
  // §4.11: the check interval (8 t_c: 10 steps at f = 0.8), the hold and the budget in critical steps.
  const std::int64_t every = steps_for(w, 8.0), hold_steps = steps_for(w, hold), budget = steps_for(w, budget_tc),
                     quench_steps = steps_for(w, p.quench_every);
  for (int a = 0; a < 3; ++a)
    if (p.active[a] && !(p.target[a] > 0.0)) {
      std::ostringstream s;
      s << "servo_until: 'target[" << a << "]' must be > 0 Pa (compressive), found " << p.target[a] << ".";
      throw std::invalid_argument(s.str());
    }
  PeriodicServo* servo = sys.add_servo(p, sys.min_diameter());
  StageReport r;
  std::int64_t held = 0;
  double over = 0.0;
  // Overshoot: excursion past the target on the side opposite to the starting stress.
  double side[3] = {0, 0, 0};
  {
    const Mat3 s0 = sys.stress();
    for (int a = 0; a < 3; ++a) side[a] = (-s0[4 * a] <= p.target[a]) ? 1.0 : -1.0;
  }
  r.converged = false;
  while (r.steps < budget) {
    sys.step(1);
    ++r.steps;
    const Mat3& s = servo->last_stress();
    bool in = true;
    for (int a = 0; a < 3; ++a) {
      if (!p.active[a]) continue;
      const double rel = (-s[4 * a] - p.target[a]) / p.target[a];
      over = std::max(over, side[a] * rel);
      in &= std::abs(rel) <= stress_tol;
    }
    if (quench_steps > 0 && r.steps % quench_steps == 0) sys.quench();
    if (r.steps % every == 0) {
      if (in && sys.ratio() < ratio_tol) held += every;
      else held = 0;
      if (held >= hold_steps) { r.converged = true; break; }
    }
  }
  sys.remove_servo(servo);
  sys.stop_cell();
  fill_report_on(sys, r);
  if (overshoot) *overshoot = over;
  std::ostringstream o;
  o << "servo to (" << p.target.x << ", " << p.target.y << ", " << p.target.z << ") Pa "
    << (r.converged ? "converged" : "did not converge") << " in " << r.steps << " steps";
  if (!r.converged)
    o << " (criterion: |s - s*| <= " << stress_tol << " s* and unbalanced ratio < " << ratio_tol << " for " << hold
      << " critical steps within " << budget_tc << " critical steps; reached ratio " << sys.ratio() << ")";
  r.what = o.str();
  return r;
}

// generate_rev's radius expansion (§4.3) of the balls that generate_rev_balls placed: `increments`
// equal factors to the porosity n1, each cycled to the unbalanced ratio; the REV ends at rest with
// the final contact parameters. Returns generate_rev's report.
template <class S>
StageReport expand_rev_on(S& sys, const RevParams& p, const RevStart& st) {
  const World& w = sys.world();
  const double n0 = sys.porosity();
  const double mtot = std::cbrt((1.0 - st.n1) / (1.0 - n0));
  const double minc = std::pow(mtot, 1.0 / p.increments);
  StageReport r;
  bool ok_all = true;
  // §4.11: the intervals and the budget in critical steps (50, 50 and 20,000 steps at f = 0.8).
  const std::int64_t budget = steps_for(w, p.increment_budget), every = steps_for(w, p.check_every),
                     quench_steps = steps_for(w, p.quench_every);
  int failed = -1;
  for (int k = 0; k < p.increments; ++k) {
    sys.scale_radii(minc);
    bool ok;
    r.steps += cycle_on(sys, p.ratio_tol, budget, ok, every, quench_steps);
    if (!ok && failed < 0) failed = k;
    ok_all &= ok;
  }
  sys.quench();  // the REV starts at rest
  sys.set_contact_params(st.mu_final, st.moments_final);
  fill_report_on(sys, r);
  r.count = sys.num_balls();
  r.converged = ok_all;
  std::ostringstream s;
  s << "generated " << r.count << " balls (seed " << p.seed << ", PSD scale " << p.psd.scale
    << ") and expanded radii from porosity " << n0 << " to " << r.porosity << " in "
    << p.increments << " increments";
  if (failed >= 0)
    s << "; increment " << failed + 1 << " of " << p.increments << " did not reach the unbalanced ratio "
      << p.ratio_tol << " within " << p.increment_budget << " critical steps (" << budget << " steps)";
  r.what = s.str();
  return r;
}

// servo_specimen (procedures.hpp): compaction at the lowered friction, then at the final one.
template <class S>
StageReport servo_specimen_on(S& sys, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                              double budget, double compaction_fric) {
  const double mu = sys.friction();
  sys.set_friction(std::min(mu, compaction_fric));
  auto r1 = servo_until_on(sys, p, stress_tol, ratio_tol, hold, budget, nullptr);
  if (!r1.converged) return r1;
  sys.set_friction(mu);
  auto r2 = servo_until_on(sys, p, stress_tol, ratio_tol, hold, budget / 2, nullptr);
  r2.steps += r1.steps;
  r2.what = "servo to sigma_v " + std::to_string(p.target.z) + " Pa, sigma_h " + std::to_string(p.target.x) +
            " Pa: " + r1.what + "; at final friction: " + r2.what;
  return r2;
}

// Whether pair c's ball A is this process's own (not a ghost row): each pair counts once.
inline bool owned_a(const World& w, std::size_t c) {
  const auto& gh = w.ghost_rows();
  return gh.empty() || !gh[w.pair_contacts().a[c]];
}
inline std::int64_t owned_intact(const World& w) {
  const auto& pc = w.pair_contacts();
  std::int64_t n = 0;
  for (std::size_t c = 0; c < pc.bond.size(); ++c) n += owned_a(w, c) && pc.bond[c].state == BondState::kIntact;
  return n;
}

// install_bonds (specimen.hpp): every pair of the packing with its gap in [lo, hi] bonded.
template <class S>
StageReport install_bonds_on(S& sys, double lo, double hi) {
  World& w = sys.part();
  if (!w.counters().prepared) sys.prepare();
  const std::int64_t before = owned_intact(w);
  w.bond_ball_ball(lo, hi);  // (each rank its list: a pair held by two ranks is bonded on both)
  StageReport r;
  r.count = static_cast<std::size_t>(sys.total(owned_intact(w) - before));
  fill_report_on(sys, r);
  const std::size_t n = sys.num_balls();
  std::ostringstream s;
  s << "installed " << r.count << " " << to_string(w.params().ball_ball.model) << " bonds ("
    << (n ? 2.0 * double(r.count) / double(n) : 0.0) << " per ball) on gaps in [" << lo << ", " << hi << "] m";
  r.what = s.str();
  return r;
}

// gap_for_coordination (specimen.hpp).
template <class S>
double gap_for_coordination_on(S& sys, double z_target, double gap_floor) {
  if (!(z_target > 0.0)) {
    std::ostringstream s;
    s << "gap_for_coordination: target coordination number must be > 0, found " << z_target << ".";
    throw std::invalid_argument(s.str());
  }
  sys.prepare();
  const World& w = sys.world();
  const auto& pc = w.pair_contacts();
  const auto& pt = w.balls();
  std::int64_t have = 0;
  std::vector<double> gaps;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (!owned_a(w, c)) continue;
    const bool bd = !pc.bond.empty() && bonded(pc.bond[c].state);
    const Vec3 d = w.branch(c);
    const double gap = norm(d) - pt.r[pc.a[c]] - pt.r[pc.b[c]];
    if (bd || (pc.h[c].flags & ContactHist::kActive) || gap <= 0.0) { ++have; continue; }
    gaps.push_back(gap);
  }
  have = sys.total(have);
  const std::int64_t separated = sys.total(static_cast<std::int64_t>(gaps.size()));
  const auto need = static_cast<std::int64_t>(std::ceil(0.5 * z_target * double(sys.num_balls())));
  if (need <= have) return gap_floor;
  const std::int64_t extra = need - have;
  if (extra > separated) {
    std::ostringstream s;
    s << "gap_for_coordination: Z = " << z_target << " needs " << extra << " more pairs but only " << separated
      << " separated pairs lie within the Verlet skin (" << w.skin() << " m); the packing is too loose for this Z.";
    throw std::invalid_argument(s.str());
  }
  return std::max(gap_floor, sys.kth_smallest(gaps, extra));
}

// install_bonds_to_coordination (specimen.hpp).
template <class S>
StageReport install_bonds_to_coordination_on(S& sys, double z_target, double gap_floor) {
  const double g = gap_for_coordination_on(sys, z_target, gap_floor);
  StageReport r = install_bonds_on(sys, -std::numeric_limits<double>::infinity(), g);
  std::ostringstream s;
  s << r.what << " (gap chosen for Z = " << z_target << ")";
  r.what = s.str();
  return r;
}

// bond_specimen (procedures.hpp): the generate stage's bonding half.
template <class S>
void bond_specimen_on(S& sys, StageReport& r, double bond_coordination, double gap_floor) {
  if (!(bond_coordination > 0)) return;
  const double z0 = sys.coordination().z;  // touching contacts only
  const auto b = install_bonds_to_coordination_on(sys, bond_coordination, gap_floor);
  std::ostringstream z;
  z.setf(std::ios::fixed);
  z.precision(3);
  z << "; Z " << sys.coordination().z << " (touching before bonding: ";
  z << z0 << ")";
  r.what += "; " + b.what + z.str();
  r.count = sys.num_balls();
}

// depth_scale (specimen.hpp): every listed pair's forces (on the ranks: every pair a rank holds,
// from the same inputs on both ranks of a pair across a cut) times its depth factor.
template <class S>
StageReport depth_scale_on(S& sys, const DepthScaleParams& p) {
  if (!(p.height > 0.0)) {
    std::ostringstream s;
    s << "depth_scale: 'height' (H_D) must be > 0 m, found " << p.height << ".";
    throw std::invalid_argument(s.str());
  }
  World& w = sys.part();
  auto& pc = w.pair_contacts();
  const auto& pt = w.balls();
  std::int64_t cnt = 0;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const Vec3 d = w.branch(c);
    const double dist = norm(d);
    const double gap = dist - pt.r[pc.a[c]] - pt.r[pc.b[c]];
    const double zc = pt.x[pc.a[c]].z + (pt.r[pc.a[c]] + 0.5 * gap) * d.z / dist;
    double f = p.mode == DepthScaling::kDepthRatio ? (p.z_top - zc) / p.height
                                                   : (zc - (p.z_top - p.height)) / p.height;
    f = std::clamp(f, 0.0, 1.0);
    ContactHist& h = pc.h[c];
    h.fn *= f;
    h.fs *= f;
    h.flags |= ContactHist::kIncremental;  // otherwise K_n·overlap comes back (§4.9)
    if (!pc.bond.empty()) {
      BondHist& b = pc.bond[c];
      b.nb *= f;
      b.fsb *= f;
      b.mt *= f;
      b.mb *= f;
    }
    cnt += owned_a(w, c);
  }
  StageReport r;
  r.count = static_cast<std::size_t>(sys.total(cnt));
  fill_report_on(sys, r);
  r.what = std::string("scaled ") + std::to_string(r.count) + " ball-ball contact forces by the " +
           (p.mode == DepthScaling::kDepthRatio ? "depth ratio (z_top - z)/H_D" : "paper-literal ratio z/H_D");
  return r;
}

// assign_interface_bond_forces (specimen.hpp), kMeanContact: every bonded ball-facet contact (on
// the ranks: each rank its balls') gets the mean normal force of the ball-ball contacts in its
// band, summed in one World's pair order. Returns the bonds assigned here.
struct PairForceRec {
  std::uint64_t ia, ib;
  double z;
  Vec3 n;
  double fn;
  std::pair<std::uint64_t, std::uint64_t> key() const { return {ia, ib}; }
};
template <class S>
std::int64_t mean_contact_bond_forces_on(S& sys, double band) {
  World& w = sys.part();
  auto& fc = w.facet_contacts();
  const auto& pc = w.pair_contacts();
  const auto& pt = w.balls();
  std::vector<PairForceRec> cs;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (!owned_a(w, c)) continue;
    const double fn = pc.h[c].fn + (pc.bond.empty() ? 0.0 : -pc.bond[c].nb);
    if (!(fn > 0.0)) continue;
    const Vec3 d = w.branch(c);
    const Vec3 n = d * (1.0 / norm(d));
    cs.push_back({pt.id[pc.a[c]], pt.id[pc.b[c]], pt.x[pc.a[c]].z + 0.5 * d.z, n, fn});
  }
  sys.in_order(cs);
  double gsum = 0.0;
  for (const auto& e : cs) gsum += e.fn;
  const double gmean = cs.empty() ? 0.0 : gsum / double(cs.size());
  const double cos30 = std::cos(3.14159265358979323846 / 6.0);
  std::int64_t cnt = 0;
  for (std::size_t c = 0; c < fc.size(); ++c) {
    if (!bonded(fc.bond[c].state)) continue;
    const Vec3 nf = w.facet_wall(static_cast<int>(fc.wall[c])).tri_normal[static_cast<std::size_t>(fc.facet[c])];
    const double z = fc.xc[c].z;
    double s1 = 0, s2 = 0;
    std::size_t n1 = 0, n2 = 0;
    for (const auto& e : cs) {
      if (std::abs(e.z - z) > band) continue;
      s2 += e.fn; ++n2;
      if (std::abs(dot(e.n, nf)) >= cos30) { s1 += e.fn; ++n1; }
    }
    const double mean = n1 ? s1 / double(n1) : (n2 ? s2 / double(n2) : gmean);
    fc.bond[c].nb = -mean;  // compression (tension positive in the bond routine)
    ++cnt;
  }
  return cnt;
}

// kTraction: faces keyed by wall and normal (components rounded to 1e-6); each face's force split
// over its bonds by n.sigma.n at their contact points, the faces' weights summed in one World's
// facet-contact order (ball id, wall). Returns the bonds assigned here; `faces` and `unloaded`
// get the number of plane faces and the force [N] of faces without a bond (not carried by the DEM).
struct FaceWeightRec {
  std::uint64_t id;
  std::uint32_t wall;
  std::int32_t face;
  double snn;
  std::pair<std::uint64_t, std::uint32_t> key() const { return {id, wall}; }
};
template <class S>
std::int64_t traction_bond_forces_on(S& sys, const InterfaceBondParams& p, std::size_t& faces, double& unloaded) {
  World& w = sys.part();
  // n.sigma.n of the geostatic stress at height z (compression as a positive number).
  auto snn = [&](const Vec3& n, double z) {
    const double sv = p.unit_weight * std::max(0.0, p.z_top - z);
    return sv * (p.k0 * (n.x * n.x + n.y * n.y) + n.z * n.z);
  };
  auto key = [](std::uint32_t wall, const Vec3& n) {
    auto q = [](double v) { return static_cast<long long>(std::llround(v * 1e6)); };
    return std::array<long long, 4>{static_cast<long long>(wall), q(n.x), q(n.y), q(n.z)};
  };
  struct Face { double force = 0.0, weight = 0.0; std::size_t bonds = 0; int index = 0; };
  std::map<std::array<long long, 4>, Face> face;
  for (int wi = 0; wi < w.num_facet_walls(); ++wi) {
    const FacetWall& fw = w.facet_wall(wi);
    for (std::size_t t = 0; t < fw.tri.size(); ++t) {
      const Vec3 a = fw.pos[static_cast<std::size_t>(fw.tri[t][0])], b = fw.pos[static_cast<std::size_t>(fw.tri[t][1])],
                 c = fw.pos[static_cast<std::size_t>(fw.tri[t][2])];
      const double area = 0.5 * norm(cross(b - a, c - a));
      face[key(static_cast<std::uint32_t>(wi), fw.tri_normal[t])].force += area * snn(fw.tri_normal[t], (a.z + b.z + c.z) / 3.0);
    }
  }
  std::vector<Face*> by_index;
  for (auto& [k, f] : face) f.index = static_cast<int>(by_index.size()), by_index.push_back(&f);
  auto& fc = w.facet_contacts();
  auto normal_of = [&](std::size_t c) {
    return w.facet_wall(static_cast<int>(fc.wall[c])).tri_normal[static_cast<std::size_t>(fc.facet[c])];
  };
  std::vector<FaceWeightRec> recs;
  for (std::size_t c = 0; c < fc.size(); ++c) {
    if (!bonded(fc.bond[c].state)) continue;
    recs.push_back({w.balls().id[fc.ball[c]], fc.wall[c], face.at(key(fc.wall[c], normal_of(c))).index,
                    snn(normal_of(c), fc.xc[c].z)});
  }
  sys.in_order(recs);
  for (const FaceWeightRec& r : recs) {
    Face& f = *by_index[static_cast<std::size_t>(r.face)];
    f.weight += r.snn;
    ++f.bonds;
  }
  std::int64_t cnt = 0;
  for (std::size_t c = 0; c < fc.size(); ++c) {
    if (!bonded(fc.bond[c].state)) continue;
    const Face& f = face.at(key(fc.wall[c], normal_of(c)));
    const double share = f.weight > 0.0 ? snn(normal_of(c), fc.xc[c].z) / f.weight : 0.0;
    fc.bond[c].nb = -f.force * share;  // compression (tension positive in the bond routine)
    ++cnt;
  }
  faces = face.size();
  unloaded = 0.0;
  for (const auto& [k, f] : face)
    if (f.weight <= 0.0) unloaded += f.force;
  return cnt;
}

template <class S>
StageReport assign_interface_bond_forces_on(S& sys, const InterfaceBondParams& p) {
  if (p.mode == InterfaceBondForce::kTraction && (!(p.unit_weight >= 0.0) || !(p.k0 >= 0.0))) {
    std::ostringstream s;
    s << "assign_interface_bond_forces: 'unit_weight' and 'k0' must be >= 0, found " << p.unit_weight << " N/m^3 and "
      << p.k0 << ".";
    throw std::invalid_argument(s.str());
  }
  if (!law_has_bond(sys.world().params().ball_facet.model))
    throw std::invalid_argument("assign_interface_bond_forces: family 'ball_facet' has no bonds (model 'linear').");
  StageReport r;
  std::ostringstream s;
  if (p.mode == InterfaceBondForce::kMeanContact) {
    r.count = static_cast<std::size_t>(sys.total(mean_contact_bond_forces_on(sys, p.band)));
    s << "assigned the depth-wise mean ball-ball normal force to " << r.count << " interface bonds";
  } else {
    std::size_t faces = 0;
    double unloaded = 0.0;
    r.count = static_cast<std::size_t>(sys.total(traction_bond_forces_on(sys, p, faces, unloaded)));
    s << "assigned the geostatic traction (unit weight " << p.unit_weight << " N/m^3, K0 " << p.k0 << ") of " << faces
      << " interface faces to " << r.count << " interface bonds; faces without bonds: " << unloaded << " N unassigned";
  }
  fill_report_on(sys, r);
  r.what = s.str();
  return r;
}

}  // namespace demfdm::dem::detail
