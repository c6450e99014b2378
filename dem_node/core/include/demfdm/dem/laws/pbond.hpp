// Linear parallel bond (docs/theory.md §2, Potyondy & Cundall 2004): the linear contact (§1.7)
// in parallel with an elastic, brittle cemented disc that carries force and moment until its
// tensile or shear strength is exceeded. Scalar only (no lane kernel yet).
#pragma once

#include <cmath>

#include "demfdm/dem/laws/linear.hpp"

namespace demfdm::dem {

/// §2.4–2.5 parallel bond, bonded state. Returns false if the bond broke this step.
/// Adds the bond force/moment on B into (F, M).
[[gnu::always_inline]] inline void pbond_update(BondHist& b, const LawConst& c, double dun, const Vec3& dus, double dtt,
                         const Vec3& dtb, const Vec3& n, Vec3& F, Vec3& M) {
  const double A = b.area(), iA = 1.0 / A;
  const double rb_I = 4.0 * std::numbers::pi * b.rb * iA * iA;  // R̄/I = 4πR̄/A²
  b.nb += b.kn * A * dun;
  b.fsb -= ((b.kn * c.ks_kn) * A) * dus;
  b.mt -= (b.kn * c.ks_kn) * b.polar() * dtt;
  b.mb -= (b.kn * b.inertia()) * dtb;
  const double sigma = b.nb * iA + c.beta * norm(b.mb) * rb_I;
  const double tau = norm(b.fsb) * iA + c.beta * std::abs(b.mt) * (0.5 * rb_I);
  // Strictly greater: a bond loaded exactly to its strength survives (U15).
  if (sigma > c.sigc) {
    b.state = BondState::kBrokenTension;
  } else if (tau > c.coh - (b.nb * iA) * c.tanphi) {
    b.state = BondState::kBrokenShear;
  }
  if (b.state != BondState::kIntact) {  // §2.5: force, moment and stiffness removed
    // The bond's elastic energy leaves with it: book it as bond dissipation (§8.18), so that
    // the energy balance closes across breakage.
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
  /// A bond across a gap carries load: never skipped.
  static bool idle(double, double, const ContactHist&, const BondHist*) { return false; }
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
  static pairblock::Fn lane_kernel(pairblock::Isa, const LawConst&) { return nullptr; }
  static bool lane_needs_scalar(const BondHist*) { return true; }
  static void store_lane(ContactHist&, BondHist*, const pairblock::Out&, int) {}
};

}  // namespace demfdm::dem
