// Linear contact law (docs/theory.md §1.7): no tension, Coulomb friction, normal force absolute
// (K_n times the overlap) or incremental, stiffnesses from the deformability method.
// The formula is written once (linear_core, branch-free over doubles); the scalar law and the
// vector lanes (pair_block_body.inc) both call it. See contact_state.hpp for the rule.
#pragma once

#include <algorithm>
#include <stdexcept>

#include "demfdm/dem/contact_state.hpp"
#include "demfdm/dem/pair_block.hpp"

namespace demfdm::dem {

/// Shear force after the increment −k_s Δu_s, limited by Coulomb (|F_s| ≤ μ F_n), and the slip
/// work booked when it slides: the force at the limit times the slip displacement
/// (f − f_max)/k_s (§8.18). Inputs: the rotated shear force (fx, fy, fz), the in-plane
/// increment (dsx, dsy, dsz), k_s, the limit f_max = μ F_n and the slip work so far.
struct ShearStep {
  double x, y, z, e_slip;
  bool slip;
};
[[gnu::always_inline]] inline ShearStep coulomb_shear(double fx, double fy, double fz, double dsx, double dsy,
                                                      double dsz, double ks, double fmax, double es) {
  const double gx = fx - ks * dsx, gy = fy - ks * dsy, gz = fz - ks * dsz;
  const double f2 = gx * gx + gy * gy + gz * gz;
  const bool slip = f2 > fmax * fmax;
  const double f = __builtin_sqrt(f2);
  const double s = fmax / f;
  ShearStep o;
  o.e_slip = sel(slip & (ks > 0.0), es + fmax * (f - fmax) / ks, es);
  o.x = sel(slip, gx * s, gx);
  o.y = sel(slip, gy * s, gy);
  o.z = sel(slip, gz * s, gz);
  o.slip = slip;
  return o;
}

/// New normal and shear force of a contact with a normal law and Coulomb shear. Inactive
/// (gs > 0): F_n = 0 and F_s = 0, the slip work unchanged.
struct NormalShear {
  double fn, fx, fy, fz, e_slip;
  bool active, slip;
};

/// §1.7 on components. `gs` = g − g_r, `dun` = Δu·n̂ (opening +), (dsx, dsy, dsz) the in-plane
/// Δu, (fx, fy, fz) the shear force rotated into the current plane, `incr` the incremental
/// normal mode.
[[gnu::always_inline]] inline NormalShear linear_core(double gs, double dun, double dsx, double dsy, double dsz,
                                                      double hfn, double fx, double fy, double fz, double kn,
                                                      double ks, double mu, double es, bool incr) {
  const double fnp = sel(incr, hfn - kn * dun, -kn * gs);
  const double fn = fnp < 0.0 ? 0.0 : fnp;  // no tension: std::max(fnp, 0.0)
  const ShearStep s = coulomb_shear(fx, fy, fz, dsx, dsy, dsz, ks, mu * fn, es);
  const bool active = !(gs > 0.0);
  NormalShear o;
  o.fn = sel(active, fn, 0.0);
  o.fx = sel(active, s.x, 0.0);
  o.fy = sel(active, s.y, 0.0);
  o.fz = sel(active, s.z, 0.0);
  o.e_slip = sel(active, s.e_slip, es);
  o.active = active;
  o.slip = active & s.slip;
  return o;
}

/// Store a NormalShear in the history (flags kActive / kSlip) and return the force on B.
[[gnu::always_inline]] inline Vec3 store_normal_shear(ContactHist& h, const NormalShear& r, const Vec3& n) {
  h.fn = r.fn;
  h.fs = {r.fx, r.fy, r.fz};
  h.e_slip = r.e_slip;
  std::uint8_t fl = static_cast<std::uint8_t>(h.flags & ~(ContactHist::kActive | ContactHist::kSlip));
  if (r.active) fl |= ContactHist::kActive;
  if (r.slip) fl |= ContactHist::kSlip;
  h.flags = fl;
  if (!r.active) return Vec3{};
  return r.fn * n + h.fs;
}

/// §1.7 linear model on one contact: updates (fn, fs) in place and returns the force on B.
[[gnu::always_inline]] inline Vec3 linear_update(ContactHist& h, double gs, double dun, const Vec3& dus, const Vec3& n) {
  const NormalShear r = linear_core(gs, dun, dus.x, dus.y, dus.z, h.fn, h.fs.x, h.fs.y, h.fs.z, h.kn, h.ks, h.mu,
                                    h.e_slip, (h.flags & ContactHist::kIncremental) != 0);
  return store_normal_shear(h, r, n);
}

/// The common start of an unbonded law's update (linear, Hertz–Mindlin): an untouched contact
/// (separated, force-free) is cleared and returns false; otherwise the shear force is rotated
/// into the current plane (§1.6), the normal stored, and the increment split into its normal
/// part `dun` (opening +) and in-plane part `dus` (§1.5); `gs` = g − g_r.
[[gnu::always_inline]] inline bool unbonded_kinematics(const Kin& k, ContactHist& h, const LawConst& c, double& gs,
                                                       double& dun, Vec3& dus) {
  const Vec3& n = k.n;
  gs = k.gap - c.rgap;
  if (gs > 0.0 && h.fn == 0.0) {  // untouched, nothing to carry
    h.n_old = n;
    h.flags |= ContactHist::kHasNormal;
    h.fs = Vec3{};
    h.flags &= static_cast<std::uint8_t>(~(ContactHist::kActive | ContactHist::kSlip));
    return false;
  }
  if (h.flags & ContactHist::kHasNormal) rotate_into_plane(h.fs, h.n_old, n, k.wmean, k.dt, c.rescale);
  h.n_old = n;
  h.flags |= ContactHist::kHasNormal;
  dun = dot(k.du, n);
  dus = k.du - dun * n;
  return true;
}

/// Stiffnesses a contact adds to its balls for the critical step (§1.8): translational normal
/// and shear, rotational (bond moments).
struct ContactStiffness {
  double k = 0.0, ks = 0.0, krot = 0.0;
};

/// Per-contact constants of the deformability method shared by the linear part of every
/// linear-spring law (§1.7): K_n = A E*/L and K_s = K_n/κ* with A = π R̄², or k_n_fixed.
inline void deformability_springs(double rbar, double L, const LinearParams& lp, double& kn, double& ks) {
  const double area = std::numbers::pi * rbar * rbar;
  kn = lp.kn_fixed > 0.0 ? lp.kn_fixed : lp.emod / L * area;
  ks = lp.kn_fixed > 0.0 ? kn / lp.kratio : lp.emod / L / lp.kratio * area;
}

/// The registered type of the linear law (laws/registry.hpp).
struct LinearLaw : LawDefaults {
  static constexpr ContactModel kModel = ContactModel::kLinear;
  static constexpr const char* kName = "linear";
  static constexpr const char* kTitle = "linear springs, no tension, Coulomb friction (docs/theory.md 1.7)";

  static LawConst constants(const ContactFamilyParams& f, bool rescale, bool /*wall*/) {
    LawConst c;
    c.rgap = f.linear.rgap;
    c.rescale = rescale;
    return c;
  }
  /// Per-contact constants at contact creation: R̄ = min(R_A, R_B) (R_ball at a wall), L the
  /// deformability length.
  static void init(double rbar, double L, ContactHist& h, BondHist* /*b*/, const ContactFamilyParams& f) {
    deformability_springs(rbar, L, f.linear, h.kn, h.ks);
    h.mu = f.linear.fric;
    if (f.linear.mode == NormalMode::kIncremental) h.flags |= ContactHist::kIncremental;
  }
  /// The full law of one contact: plane rotation of the history (§1.6), the split of the
  /// increment (§1.5), §1.7. Returns the force on B; Mo gets the moment on B (none).
  [[gnu::always_inline]] static Vec3 update(const Kin& k, ContactHist& h, BondHist* /*b*/, const LawConst& c, Vec3& Mo) {
    Mo = Vec3{};
    double gs, dun;
    Vec3 dus;
    if (!unbonded_kinematics(k, h, c, gs, dun, dus)) return Vec3{};
    return linear_update(h, gs, dun, dus, k.n);
  }
  /// A separated, force-free contact needs no update (its result would be F = 0).
  static bool idle(double d2, double reach, const ContactHist& h, const BondHist* /*b*/) {
    return (d2 > reach * reach) & (h.fn == 0.0);
  }
  static ContactStiffness stiffness(const ContactHist& h, const BondHist* /*b*/, const ContactFamilyParams& /*f*/, double /*ra*/, double /*rb*/) {
    return {h.kn, h.ks, 0.0};
  }
  /// Stiffness of a contact with an equal ball when no contact exists yet (§7.2): π R E*/2.
  static double reference_stiffness(double r, const ContactFamilyParams& f) {
    return f.linear.kn_fixed > 0.0 ? f.linear.kn_fixed : std::numbers::pi * r * f.linear.emod * 0.5;
  }
  /// Elastic energy stored in the contact, added term by term to `e` (§8.18).
  static void add_strain(double& e, const ContactHist& h, const BondHist* /*b*/, const ContactFamilyParams& /*f*/) {
    if (h.kn > 0.0) e += 0.5 * h.fn * h.fn / h.kn;
    if (h.ks > 0.0) e += 0.5 * norm2(h.fs) / h.ks;
  }
  static Vec3 force(const ContactHist& h, const BondHist* /*b*/) { return h.fn * h.n_old + h.fs; }
  static Vec3 moment(const ContactHist& /*h*/, const BondHist* /*b*/) { return Vec3{}; }
  static void install_bond(ContactHist&, BondHist&, const ContactFamilyParams&) {
    throw std::logic_error("the linear law has no bond");
  }

  // Vectorised pass (pair_block.hpp): stage 1 marks lanes that need the scalar law, stage 3
  // stores a lane's results.
  /// The wall contacts' lane kernel (pair_block.hpp WallIn), or null: scalar wall passes.
  static pairblock::WallFn wall_lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale ? pairblock::linear_wall_kernel(isa) : nullptr;
  }
  static pairblock::Fn lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale ? pairblock::linear_kernel(isa) : nullptr;
  }
  static bool lane_needs_scalar(const BondHist* /*b*/) { return false; }
  /// The key of PairSet's change marks (kActive | bond state << 8) after store_lane, from the
  /// key before: store_lane sets kActive from the lane's result; no lane changes a bond state.
  static unsigned lane_key(const pairblock::Out& out, int l, unsigned k0) {
    return (k0 & ~unsigned{ContactHist::kActive}) | (out.active[l] ? unsigned{ContactHist::kActive} : 0u);
  }
  static void store_lane(ContactHist& h, BondHist* /*b*/, const pairblock::Out& out, int l) {
    h.fs = {out.fs[0][l], out.fs[1][l], out.fs[2][l]};
    h.fn = out.fn[l];
    h.n_old = {out.n[0][l], out.n[1][l], out.n[2][l]};
    h.e_slip = out.e_slip[l];
    std::uint8_t fl = static_cast<std::uint8_t>((h.flags | ContactHist::kHasNormal) &
                                                ~(ContactHist::kActive | ContactHist::kSlip));
    if (out.active[l]) fl |= ContactHist::kActive;
    if (out.slip[l]) fl |= ContactHist::kSlip;
    h.flags = fl;
  }
};

}  // namespace demfdm::dem
