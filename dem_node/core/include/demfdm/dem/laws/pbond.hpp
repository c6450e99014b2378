// Linear parallel bond (docs/theory.md §2, Potyondy & Cundall 2004): the linear contact (§1.7)
// in parallel with an elastic, brittle cemented disc that carries force and moment until its
// tensile or shear strength is exceeded. The bond's formula is written once (pbond_core, on
// components, branch-free); the scalar law and the vector lanes (pair_block_body.inc) call it.
#pragma once

#include <cmath>

#include "demfdm/dem/laws/linear.hpp"

namespace demfdm::dem {

/// §2.4–2.5 on components: the bond force and moment after the increments (Δu_n, Δu_s, Δθ_t,
/// Δθ_b), and whether the bond breaks. Inputs: the bond's normal force `nb` (tension +), its
/// shear force (sx, sy, sz) and bending moment (mx, my, mz) rotated into the current plane, its
/// twisting moment `mt`, radius `rb` and normal stiffness per area `kn`. Strictly greater: a
/// bond loaded exactly to its strength survives (U15).
struct PBondStep {
  double nb, sx, sy, sz, mt, mx, my, mz;
  bool broken_t, broken_s;
};
[[gnu::always_inline]] inline PBondStep pbond_core(double nb, double sx, double sy, double sz, double mt, double mx,
                                                   double my, double mz, double rb, double kn, const LawConst& c,
                                                   double dun, double dsx, double dsy, double dsz, double dtt,
                                                   double dbx, double dby, double dbz) {
  const double A = BondHist::disc_area(rb), iA = 1.0 / A;
  const double rb_I = 4.0 * std::numbers::pi * rb * iA * iA;  // R̄/I = 4πR̄/A²
  const double ks = kn * c.ks_kn;
  const double kA = ks * A, J = BondHist::disc_polar(rb), kI = kn * BondHist::disc_inertia(rb);
  PBondStep o;
  o.nb = nb + kn * A * dun;
  o.sx = sx - kA * dsx;
  o.sy = sy - kA * dsy;
  o.sz = sz - kA * dsz;
  o.mt = mt - ks * J * dtt;
  o.mx = mx - kI * dbx;
  o.my = my - kI * dby;
  o.mz = mz - kI * dbz;
  const double mb = __builtin_sqrt(o.mx * o.mx + o.my * o.my + o.mz * o.mz);
  const double fs = __builtin_sqrt(o.sx * o.sx + o.sy * o.sy + o.sz * o.sz);
  const double sigma = o.nb * iA + c.beta * mb * rb_I;
  const double tau = fs * iA + c.beta * __builtin_fabs(o.mt) * (0.5 * rb_I);
  o.broken_t = sigma > c.sigc;
  o.broken_s = !o.broken_t & (tau > c.coh - (o.nb * iA) * c.tanphi);
  return o;
}

/// §2.4–2.5 parallel bond, bonded state, on the history (pbond_core). Adds the bond force and
/// moment on B into (F, M); a broken bond leaves with its elastic energy and adds nothing.
[[gnu::always_inline]] inline void pbond_update(BondHist& b, const LawConst& c, double dun, const Vec3& dus, double dtt,
                         const Vec3& dtb, const Vec3& n, Vec3& F, Vec3& M) {
  const PBondStep p = pbond_core(b.nb, b.fsb.x, b.fsb.y, b.fsb.z, b.mt, b.mb.x, b.mb.y, b.mb.z, b.rb, b.kn, c, dun,
                                 dus.x, dus.y, dus.z, dtt, dtb.x, dtb.y, dtb.z);
  b.nb = p.nb;
  b.fsb = {p.sx, p.sy, p.sz};
  b.mt = p.mt;
  b.mb = {p.mx, p.my, p.mz};
  if (p.broken_t) {
    b.state = BondState::kBrokenTension;
  } else if (p.broken_s) {
    b.state = BondState::kBrokenShear;
  }
  if (b.state != BondState::kIntact) {  // §2.5: force, moment and stiffness removed
    // The bond's elastic energy leaves with it: book it as bond dissipation (§8.18), so that
    // the energy balance closes across breakage.
    const double iA = 1.0 / b.area();
    const double ks = b.kn * c.ks_kn;
    b.e_soft += 0.5 * (b.nb * b.nb * iA / b.kn + norm2(b.fsb) * iA / ks + b.mt * b.mt / (ks * b.polar()) +
                       norm2(b.mb) / (b.kn * b.inertia()));
    b.nb = 0.0;
    b.fsb = Vec3{};
    b.mt = 0.0;
    b.mb = Vec3{};
    return;
  }
  F += (-b.nb) * n + b.fsb;
  M += b.mt * n + b.mb;
}


/// The registered type of the parallel-bond law (laws/registry.hpp).
struct PBondLaw : LawDefaults {
  static constexpr ContactModel kModel = ContactModel::kLinearPBond;
  static constexpr const char* kName = "pbond";
  static constexpr const char* kTitle = "linear contact with a linear parallel bond (docs/theory.md 2)";
  static constexpr bool kHasParams = true;
  /// Its scene keys, [dem.<family>.pbond] (params.hpp).
  template <class V> static void params(V& v, ContactFamilyParams& f) { describe(v, f.pbond); }
  static constexpr bool kBond = true;

  static LawConst constants(const ContactFamilyParams& f, bool rescale, bool /*wall*/) {
    LawConst c;
    c.rgap = f.linear.rgap;
    c.rescale = rescale;
    c.beta = f.pbond.mcf;
    c.ks_kn = 1.0 / f.pbond.kratio;
    c.sigc = f.pbond.ten;
    c.coh = f.pbond.coh;
    c.tanphi = std::tan(f.pbond.fa_deg * std::numbers::pi / 180.0);
    return c;
  }
  /// Linear springs as LinearLaw (zero once bonded with zero_linear, §2.6); bond radius
  /// R̄ = λ̄ R̄_contact and per-area stiffness Ē*/L (§2.2).
  static void init(double rbar, double L, ContactHist& h, BondHist* b, const ContactFamilyParams& f) {
    double kn, ks;
    deformability_springs(rbar, L, f.linear, kn, ks);
    const bool zero_lin = b && f.pbond.zero_linear && bonded(b->state);
    h.kn = zero_lin ? 0.0 : kn;
    h.ks = zero_lin ? 0.0 : ks;
    b->rb = f.pbond.rmul * rbar;
    b->kn = f.pbond.emod / L;
    h.mu = f.linear.fric;
    if (f.linear.mode == NormalMode::kIncremental) h.flags |= ContactHist::kIncremental;
  }
  [[gnu::always_inline]] static Vec3 update(const Kin& k, ContactHist& h, BondHist* b, const LawConst& c, Vec3& Mo) {
    const Vec3& n = k.n;
    const double gs = k.gap - c.rgap;
    if (h.flags & ContactHist::kHasNormal) {
      rotate_into_plane(h.fs, h.n_old, n, k.wmean, k.dt, c.rescale);
      rotate_into_plane(b->mb, h.n_old, n, k.wmean, k.dt, c.rescale);
      rotate_into_plane(b->fsb, h.n_old, n, k.wmean, k.dt, c.rescale);
    }
    h.n_old = n;
    h.flags |= ContactHist::kHasNormal;
    const double dun = dot(k.du, n);
    const Vec3 dus = k.du - dun * n;
    Vec3 F = linear_update(h, gs, dun, dus, n);
    Mo = Vec3{};
    if (b->state == BondState::kIntact) {
      const double dtt = dot(k.dtheta, n);
      const Vec3 dtb = k.dtheta - dtt * n;
      pbond_update(*b, c, dun, dus, dtt, dtb, n, F, Mo);
    }
    return F;
  }
  /// An intact bond across a gap carries load: never skipped. Without an intact bond (never
  /// bonded, or broken: its force and moment were zeroed, §2.5) the contact is the linear one,
  /// and a separated, force-free one needs no update (LinearLaw::idle): F_n = 0 implies F_s = 0,
  /// and the bond's zero vectors are left as they are by a rotation.
  static bool idle(double d2, double reach, const ContactHist& h, const BondHist* b) {
    return (b->state != BondState::kIntact) & (d2 > reach * reach) & (h.fn == 0.0);
  }
  /// The linear springs count only while the contact is active (a bond across a gap has none,
  /// §2.1); an intact bond adds k̄_n A, k̄_s A and k̄_n I.
  static ContactStiffness stiffness(const ContactHist& h, const BondHist* b, const ContactFamilyParams& f, double /*ra*/, double /*rb*/) {
    const bool lin = (h.flags & ContactHist::kActive) != 0;
    const bool bd = b && bonded(b->state);
    ContactStiffness s;
    s.k = lin ? h.kn : 0.0;
    s.ks = lin ? h.ks : 0.0;
    if (bd) {
      s.k += b->kn * b->area();
      s.krot += b->kn * b->inertia();
      s.ks += b->kn / f.pbond.kratio * b->area();
    }
    return s;
  }
  static double reference_stiffness(double r, const ContactFamilyParams& f) {
    return LinearLaw::reference_stiffness(r, f);
  }
  static void add_strain(double& e, const ContactHist& h, const BondHist* b, const ContactFamilyParams& f) {
    LinearLaw::add_strain(e, h, b, f);
    if (!b || b->kn <= 0.0) return;
    const double ks_kn = 1.0 / f.pbond.kratio;
    e += 0.5 * b->nb * b->nb / (b->kn * b->area()) + 0.5 * norm2(b->fsb) / (b->kn * ks_kn * b->area());
    e += 0.5 * b->mt * b->mt / (b->kn * ks_kn * b->polar()) + 0.5 * norm2(b->mb) / (b->kn * b->inertia());
  }
  static Vec3 force(const ContactHist& h, const BondHist* b) {
    Vec3 F = h.fn * h.n_old + h.fs;
    if (b->state == BondState::kIntact) F += (-b->nb) * h.n_old + b->fsb;
    return F;
  }
  static Vec3 moment(const ContactHist& h, const BondHist* b) { return b->mt * h.n_old + b->mb; }
  /// §2.3: the bond force starts at 0; interface bonds drop the linear part (§2.6).
  static void install_bond(ContactHist& h, BondHist& b, const ContactFamilyParams& f) {
    b.sigma_t = f.pbond.ten;
    b.nb = 0.0; b.fsb = Vec3{}; b.mt = 0.0; b.mb = Vec3{};
    if (f.pbond.zero_linear) { h.kn = h.ks = 0.0; h.fn = 0.0; h.fs = Vec3{}; }
  }
  // Vectorised pass (pair_block.hpp): every contact has a lane; a breaking bond or a large
  // rotation sends its lane to the scalar law.
  /// The wall contacts' lane kernel (pair_block.hpp WallIn), or null: scalar wall passes.
  static pairblock::WallFn wall_lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale ? pairblock::pbond_wall_kernel(isa) : nullptr;
  }
  static pairblock::Fn lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale ? pairblock::pbond_kernel(isa) : nullptr;
  }
  static bool lane_needs_scalar(const BondHist* /*b*/) { return false; }
  /// kActive from the linear part; a lane whose bond breaks is redone by the scalar law.
  static unsigned lane_key(const pairblock::Out& out, int l, unsigned k0) { return LinearLaw::lane_key(out, l, k0); }
  static void store_lane(ContactHist& h, BondHist* b, const pairblock::Out& out, int l) {
    LinearLaw::store_lane(h, b, out, l);
    b->nb = out.nb[l];
    b->fsb = {out.fsb[0][l], out.fsb[1][l], out.fsb[2][l]};
    b->mt = out.mt[l];
    b->mb = {out.mb[0][l], out.mb[1][l], out.mb[2][l]};
  }
};

}  // namespace demfdm::dem
