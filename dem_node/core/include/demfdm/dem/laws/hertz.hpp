// Hertz–Mindlin contact law (docs/theory.md §1.9; as PFC's `hertz` and LAMMPS's
// `gran/hertz/history` without damping): normal force F_n = (4/3) E* √R* δ^(3/2), no-slip
// Mindlin shear stiffness k_s = 8 G* a with a = √(R* δ), shear force incremental
// (F_s ← F_s − k_s Δu_s, rotated with the contact plane, §1.6), Coulomb limit μ F_n. No bond.
// The formula is written once (hertz_core) for the scalar law and the vector lanes.
#pragma once

#include <algorithm>
#include <stdexcept>

#include "demfdm/dem/laws/linear.hpp"

namespace demfdm::dem {

/// A NormalShear plus the tangent stiffnesses at the current overlap, K_n = dF_n/dδ = 2 E* a
/// and K_s = 8 G* a, kept in the history for the critical step (§1.8) and the energy.
struct HertzStep {
  NormalShear ns;
  double kn, ks;
};

/// §1.9 on components: `gs` = g − g_r (overlap δ = −gs), `reff` = R*, (dsx, dsy, dsz) the
/// in-plane Δu, (fx, fy, fz) the shear force rotated into the current plane.
[[gnu::always_inline]] inline HertzStep hertz_core(double gs, double reff, double dsx, double dsy, double dsz,
                                                   double fx, double fy, double fz, double e_star, double g_star,
                                                   double mu, double es) {
  const bool active = !(gs > 0.0);
  const double delta = sel(active, -gs, 0.0);
  const double a = __builtin_sqrt(reff * delta);  // contact radius
  const double fn = (4.0 / 3.0) * e_star * a * delta;
  const double ks = 8.0 * g_star * a;
  const ShearStep s = coulomb_shear(fx, fy, fz, dsx, dsy, dsz, ks, mu * fn, es);
  HertzStep o;
  o.ns.fn = sel(active, fn, 0.0);
  o.ns.fx = sel(active, s.x, 0.0);
  o.ns.fy = sel(active, s.y, 0.0);
  o.ns.fz = sel(active, s.z, 0.0);
  o.ns.e_slip = sel(active, s.e_slip, es);
  o.ns.active = active;
  o.ns.slip = active & s.slip;
  o.kn = 2.0 * e_star * a;
  o.ks = ks;
  return o;
}

/// The registered type of the Hertz–Mindlin law (laws/registry.hpp).
struct HertzLaw : LawDefaults {
  static constexpr ContactModel kModel = ContactModel::kHertz;
  static constexpr const char* kName = "hertz";
  static constexpr const char* kTitle = "Hertz-Mindlin without bond (docs/theory.md 1.9)";
  static constexpr bool kHasParams = true;
  /// Its scene keys, [dem.<family>.hertz] (params.hpp).
  template <class V> static void params(V& v, ContactFamilyParams& f) { describe(v, f.hertz); }
  static constexpr bool kNeedsReff = true;
  static constexpr bool kStiffnessVaries = true;
  /// √(δ_ref/R*): the critical step counts every contact at least at the overlap δ_ref = 0.1 % of R*
  /// (and is recomputed every step, kStiffnessVaries).
  static constexpr double kRefOverlapRoot = 0.0316227766016838;

  /// Effective moduli from the grains' shear modulus G and Poisson ratio ν (§1.9): between two
  /// grains E* = G/(1 − ν), G* = G/(2(2 − ν)); against a rigid wall E* = 2G/(1 − ν),
  /// G* = G/(2 − ν).
  static LawConst constants(const ContactFamilyParams& f, bool rescale, bool wall) {
    LawConst c;
    c.rgap = f.linear.rgap;
    c.rescale = rescale;
    const double G = f.hertz.shear, nu = f.hertz.poisson;
    c.hz_e = (wall ? 2.0 : 1.0) * G / (1.0 - nu);
    c.hz_g = (wall ? 1.0 : 0.5) * G / (2.0 - nu);
    return c;
  }
  /// The tangent stiffnesses are set by the first update in contact.
  static void init(double /*rbar*/, double /*L*/, ContactHist& h, BondHist*, const ContactFamilyParams& f) {
    h.kn = 0.0;
    h.ks = 0.0;
    h.mu = f.linear.fric;
  }
  [[gnu::always_inline]] static Vec3 update(const Kin& k, ContactHist& h, BondHist*, const LawConst& c, Vec3& Mo) {
    Mo = Vec3{};
    double gs, dun;
    Vec3 dus;
    if (!unbonded_kinematics(k, h, c, gs, dun, dus)) return Vec3{};
    const HertzStep r = hertz_core(gs, k.reff, dus.x, dus.y, dus.z, h.fs.x, h.fs.y, h.fs.z, c.hz_e, c.hz_g, h.mu,
                                   h.e_slip);
    h.kn = r.kn;
    h.ks = r.ks;
    return store_normal_shear(h, r.ns, k.n);
  }
  static bool idle(double d2, double reach, const ContactHist& h, const BondHist*) {
    return (d2 > reach * reach) & (h.fn == 0.0);
  }
  /// The tangent stiffnesses, but at least those at the overlap δ_ref = 0.1 % of R* (a fresh
  /// contact has no tangent stiffness before its first update, and an impact stiffens it within
  /// a few steps, §1.9): K_n ≥ 2 E* R* √0.001, k_s ≥ 8 G* R* √0.001. rb = 0 marks a wall (R* = ra).
  static ContactStiffness stiffness(const ContactHist& h, const BondHist*, const ContactFamilyParams& f, double ra,
                                    double rb) {
    const bool wall = rb == 0.0;
    const LawConst c = constants(f, true, wall);
    const double rs = wall ? ra : ra * rb / (ra + rb);
    const double a_ref = rs * kRefOverlapRoot;  // √(R* · δ_ref)
    return {std::max(h.kn, 2.0 * c.hz_e * a_ref), std::max(h.ks, 8.0 * c.hz_g * a_ref), 0.0};
  }
  /// No contact yet: the floor of stiffness() against an equal grain (R* = R/2).
  static double reference_stiffness(double r, const ContactFamilyParams& f) {
    return 2.0 * constants(f, true, false).hz_e * (0.5 * r) * kRefOverlapRoot;
  }
  /// Normal: ∫F_n dδ = (2/5) F_n δ = (3/5) F_n²/K_n (δ = 1.5 F_n/K_n); shear: ½ F_s²/k_s (exact
  /// for a shear force built at constant overlap).
  static void add_strain(double& e, const ContactHist& h, const BondHist*, const ContactFamilyParams&) {
    if (h.kn > 0.0) e += 0.6 * h.fn * h.fn / h.kn;
    if (h.ks > 0.0) e += 0.5 * norm2(h.fs) / h.ks;
  }
  static Vec3 force(const ContactHist& h, const BondHist*) { return h.fn * h.n_old + h.fs; }
  static Vec3 moment(const ContactHist&, const BondHist*) { return Vec3{}; }
  static void install_bond(ContactHist&, BondHist&, const ContactFamilyParams&) {
    throw std::logic_error("the Hertz-Mindlin law has no bond");
  }
  /// The wall contacts' lane kernel (pair_block.hpp WallIn), or null: scalar wall passes.
  static pairblock::WallFn wall_lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale ? pairblock::hertz_wall_kernel(isa) : nullptr;
  }
  static pairblock::Fn lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale ? pairblock::hertz_kernel(isa) : nullptr;
  }
  static bool lane_needs_scalar(const BondHist*) { return false; }
  static unsigned lane_key(const pairblock::Out& out, int l, unsigned k0) { return LinearLaw::lane_key(out, l, k0); }
  static void store_lane(ContactHist& h, BondHist* b, const pairblock::Out& out, int l) {
    LinearLaw::store_lane(h, b, out, l);
    h.kn = out.kn[l];
    h.ks = out.ks[l];
  }
};

}  // namespace demfdm::dem
