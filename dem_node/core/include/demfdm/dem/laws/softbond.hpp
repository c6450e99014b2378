// Soft bond (docs/theory.md §3, a reconstruction): one linear spring set in normal, shear,
// bending and twisting; past the tensile strength the bond softens with slope −k_n/ζ until its
// strength has fallen to γσ_c; a brittle shear break on the mean normal stress; unbonded
// contacts keep the §3.5 moment limits. The elastic predictor and the shear test are written
// once (softbond_predict, softbond_shear_exceeded) and shared with the vector lanes, which
// send every lane that leaves the elastic range to the scalar law.
#pragma once

#include <algorithm>
#include <cmath>

#include "demfdm/dem/laws/linear.hpp"

namespace demfdm::dem {

/// §3.3 step 1, the elastic predictor of a bonded contact on components: normal force
/// N = −F_n + k_n,eff A Δu_n (tension +), shear force, twisting and bending moment after the
/// increments, and the peripheral stress σ = N/A + β R̄ ‖M_b‖/I that is tested against σ_t.
struct SoftPredict {
  double N, fx, fy, fz, mt, mx, my, mz, mbn, sig, iA, rb_I;
};
[[gnu::always_inline]] inline SoftPredict softbond_predict(double hfn, double fx, double fy, double fz, double ks,
                                                           double dun, double dsx, double dsy, double dsz, double dtt,
                                                           double dbx, double dby, double dbz, double mt, double mx,
                                                           double my, double mz, double kne, double bkn, double rb,
                                                           const LawConst& c) {
  SoftPredict p;
  // One division for the disc: 1/A; R̄/I = 4π R̄/A² and R̄/J = 2π R̄/A² (A = π R̄²).
  const double A = std::numbers::pi * rb * rb, iA = 1.0 / A;
  const double rb_I = 4.0 * std::numbers::pi * rb * iA * iA;
  p.N = -hfn + kne * A * dun;
  p.fx = fx - ks * dsx;
  p.fy = fy - ks * dsy;
  p.fz = fz - ks * dsz;
  const double polar = 0.5 * A * rb * rb, inertia = 0.25 * A * rb * rb;
  p.mt = mt - (bkn * c.ks_kn) * polar * dtt;
  const double kI = kne * inertia;
  p.mx = mx - kI * dbx;
  p.my = my - kI * dby;
  p.mz = mz - kI * dbz;
  p.mbn = __builtin_sqrt(p.mx * p.mx + p.my * p.my + p.mz * p.mz);
  // bend_soft ? β R̄/I : 0 as a product with 1 or 0 (exact; a select on a loop-invariant bool
  // blocks the vectoriser).
  const double cm = c.beta * rb_I * (c.bend_soft ? 1.0 : 0.0);
  p.sig = p.N * iA + cm * p.mbn;
  p.iA = iA;
  p.rb_I = rb_I;
  return p;
}

/// §3.4 brittle shear break on the mean normal stress: τ = ‖F_s‖/A + β |M_t| R̄/J against
/// c_eff − (N/A) tan φ, with c_eff = c (CohNone) or c σ_t/σ_c.
template <bool CohNone>
[[gnu::always_inline]] inline bool softbond_shear_exceeded(double fx, double fy, double fz, double mt, double N,
                                                           double sigma_t, double iA, double rb_I, const LawConst& c) {
  const double tau = __builtin_sqrt(fx * fx + fy * fy + fz * fz) * iA + c.beta * __builtin_fabs(mt) * (0.5 * rb_I);
  const double ceff = CohNone ? c.coh : c.coh * sigma_t / c.sigc;
  return tau > ceff - (N * iA) * c.tanphi;
}

/// Set the unbonded limits of §3.5 on (fn ≥ 0, fs, M): used after a soft-bond break.
inline void softbond_clamp_unbonded(ContactHist& h, BondHist& b, const LawConst& c, const Vec3& n) {
  h.fn = std::max(h.fn, 0.0);
  const double fmax = h.mu * h.fn;
  const double f = norm(h.fs);
  if (f > fmax) h.fs *= (f > 0.0 ? fmax / f : 0.0);
  if (c.moments == UnbondedMoments::kNone) {
    b.mb = Vec3{};
    b.mt = 0.0;
    return;
  }
  const double mbl = c.bmul * h.fn * b.rb * 0.25;
  const double mbn = norm(b.mb);
  if (mbn > mbl) b.mb *= (mbn > 0.0 ? mbl / mbn : 0.0);
  const double mtl = c.twist * h.mu * h.fn * b.rb;
  if (std::abs(b.mt) > mtl) b.mt = std::copysign(mtl, b.mt);
  (void)n;
}

/// Plastic elongation measure of the soft bond from its current strength (§3.3).
/// Elastic unloading: σ_t = σ_c + H u_p with H = −k_n/(ζ+1). Secant: u_max on the envelope.
inline double softbond_plastic_elongation(const BondHist& b, const LawConst& c) {
  if (b.state != BondState::kSoftening && b.state != BondState::kIntact) return 0.0;
  const double ds = c.sigc - b.sigma_t;
  if (c.unload == SoftUnload::kElastic) return ds * (c.zeta + 1.0) / b.kn;
  const double umax = c.sigc / b.kn + c.zeta * ds / b.kn;
  return umax - b.sigma_t / b.kn;
}

/// §3.3–3.5 soft bond: complete update for any state. Returns the force on B; the moment on
/// B is written to M. `gs` is g − g_r, the rest as in linear_update.
[[gnu::always_inline]] inline Vec3 softbond_update(ContactHist& h, BondHist& b, const LawConst& c, double gs, double dun,
                            const Vec3& dus, double dtt, const Vec3& dtb, const Vec3& n,
                            Vec3& M) {
  if (b.state == BondState::kIntact || b.state == BondState::kSoftening) {
    // Effective normal stiffness: k_n, or the secant stiffness while softening (U1).
    double kne = b.kn;
    if (c.unload == SoftUnload::kSecant && b.state == BondState::kSoftening) {
      const double umax = c.sigc / b.kn + c.zeta * (c.sigc - b.sigma_t) / b.kn;
      kne = b.sigma_t / umax;
    }
    // 1. elastic predictor (the formula shared with the vector lanes)
    const SoftPredict p = softbond_predict(h.fn, h.fs.x, h.fs.y, h.fs.z, h.ks, dun, dus.x, dus.y, dus.z, dtt, dtb.x,
                                           dtb.y, dtb.z, b.mt, b.mb.x, b.mb.y, b.mb.z, kne, b.kn, b.rb, c);
    double N = p.N;
    h.fs = {p.fx, p.fy, p.fz};
    b.mt = p.mt;
    b.mb = {p.mx, p.my, p.mz};
    const double iA = p.iA, rb_I = p.rb_I, mbn = p.mbn, sig = p.sig;
    if (sig > b.sigma_t) {
      if (c.zeta == 0.0) {
        b.state = BondState::kBrokenTension;
      } else {
        // 3. envelope step: σ_t drops by (k_n/ζ)·(excess elongation), §3.3.
        const double st_new = b.sigma_t - (b.kn / c.zeta) * (sig - b.sigma_t) / kne;
        const double x = (sig - st_new) / kne;  // plastic peripheral elongation this step
        // Bond dissipation (§8.18): the plastic work of the return, N̄ Δu_p + M̄_b Δθ_p, with
        // the rim stress on the plastic path taken as the mean σ̄ of the old and the new
        // strength (the pair (N, M_b) on that path as the return moves it).
        const double sbar = 0.5 * (b.sigma_t + std::max(st_new, 0.0));
        const double A = b.area(), I = b.inertia();
        b.sigma_t = st_new;
        b.state = BondState::kSoftening;
        // 4. return to σ = σ_t
        if (c.ret == SoftReturn::kAssociated || !(N > 0.0)) {
          if (c.ret == SoftReturn::kAssociated) {
            // Flow along ∂σ/∂(N, M_b) = (1/A, βR̄/I): Δu_p = λ/A, Δθ_p = βR̄λ/I, so the plastic
            // work is λ σ̄ (λ (σ̄ − βR̄|M_b|/I) when the moment does not soften: then Δθ_p = 0).
            const double cmm = (mbn > 0.0 && c.bend_soft) ? c.beta * c.beta * b.rb * b.rb / I : 0.0;
            const double lam = x / (1.0 / A + cmm);
            b.e_soft += lam * (cmm > 0.0 ? sbar : sbar - c.beta * mbn * b.rb / I);
            N -= kne * lam;
            if (cmm > 0.0) b.mb -= (kne * c.beta * b.rb * lam / mbn) * b.mb;
          } else {  // radial with N ≤ 0: reduce only the moment
            const double mnew = std::max(st_new - N / A, 0.0) * I / (c.beta * b.rb);
            // Δθ_p = (|M_b| − M_new)/(k I), at the mean moment M̄ = (σ̄ − N/A) I/(βR̄).
            b.e_soft += std::max(sbar - N / A, 0.0) * I / (c.beta * b.rb) * std::max(mbn - mnew, 0.0) / (kne * I);
            if (mbn > 0.0) b.mb *= mnew / mbn;
          }
        } else {  // radial, N > 0
          const double s = st_new / sig;
          // (N, M_b) scaled by s: Δu_p = N(1 − s)/(k A), Δθ_p = |M_b|(1 − s)/(k I), at the mean
          // forces (σ̄/σ)(N, |M_b|).
          b.e_soft += sbar / sig * (1.0 - s) * (N * N / (kne * A) + mbn * mbn / (kne * I));
          N *= s;
          b.mb *= s;
        }
        // 5. break when the strength has fallen to γσ_c
        if (b.sigma_t <= c.gamma * c.sigc) b.state = BondState::kBrokenTension;
      }
    }
    h.fn = -N;
    if (b.state == BondState::kIntact || b.state == BondState::kSoftening) {
      // 6. brittle shear break, mean normal stress (§3.4)
      const bool brk = c.cohesion == CohesionSoftening::kNone
                           ? softbond_shear_exceeded<true>(h.fs.x, h.fs.y, h.fs.z, b.mt, N, b.sigma_t, iA, rb_I, c)
                           : softbond_shear_exceeded<false>(h.fs.x, h.fs.y, h.fs.z, b.mt, N, b.sigma_t, iA, rb_I, c);
      if (brk) b.state = BondState::kBrokenShear;
    }
    if (b.state == BondState::kBrokenShear || b.state == BondState::kBrokenTension) {
      // Elastic energy removed by the break (clamp to the unbonded limits, or release of an
      // open contact) is booked as bond dissipation (§8.18), measured with the same springs
      // as World::energy().
      const double ks_b = b.kn * c.ks_kn;
      auto stored = [&] {
        double e = norm2(b.mb) / (b.kn * b.inertia()) + b.mt * b.mt / (ks_b * b.polar());
        if (h.kn > 0.0) e += h.fn * h.fn / h.kn;
        if (h.ks > 0.0) e += norm2(h.fs) / h.ks;
        return 0.5 * e;
      };
      const double e0 = stored();
      softbond_clamp_unbonded(h, b, c, n);  // §3.5: keep the state, clamp to limits
      if (gs > 0.0) { h.fn = 0.0; h.fs = Vec3{}; b.mb = Vec3{}; b.mt = 0.0; }
      b.e_soft += e0 - stored();
    }
    M = b.mt * n + b.mb;
    return h.fn * n + h.fs;
  }
  // Unbonded (never bonded or broken), §3.5.
  if (gs > 0.0) {
    h.fn = 0.0;
    h.fs = Vec3{};
    b.mb = Vec3{};
    b.mt = 0.0;
    h.flags &= static_cast<std::uint8_t>(~(ContactHist::kActive | ContactHist::kSlip));
    M = Vec3{};
    return Vec3{};
  }
  const Vec3 F = linear_update(h, gs, dun, dus, n);
  if (c.moments == UnbondedMoments::kNone) {
    M = Vec3{};
    return F;
  }
  const double kb = b.kn * b.inertia(), kt = (b.kn * c.ks_kn) * b.polar();
  b.mb -= kb * dtb;
  b.mt -= kt * dtt;
  const double mbl = c.bmul * h.fn * b.rb * 0.25;
  const double mbn = norm(b.mb);
  b.slip_b = mbn > mbl;
  // A moment scaled back to its limit has slipped by (|M*| − M_lim)/k: its work M_lim times
  // that is booked with the contact's frictional slip (§3.5, §8.18), as coulomb_shear does.
  if (b.slip_b) {
    b.mb *= (mbn > 0.0 ? mbl / mbn : 0.0);
    if (kb > 0.0) h.e_slip += mbl * (mbn - mbl) / kb;
  }
  const double mtl = c.twist * h.mu * h.fn * b.rb;
  const double mta = std::abs(b.mt);
  b.slip_t = mta > mtl;
  if (b.slip_t) {
    b.mt = std::copysign(mtl, b.mt);
    if (kt > 0.0) h.e_slip += mtl * (mta - mtl) / kt;
  }
  M = b.mt * n + b.mb;
  return F;
}


/// The registered type of the soft-bond law (laws/registry.hpp).
struct SoftBondLaw : LawDefaults {
  static constexpr ContactModel kModel = ContactModel::kSoftBond;
  static constexpr const char* kName = "softbond";
  static constexpr const char* kTitle = "soft bond: one spring set, softening in tension (docs/theory.md 3)";
  static constexpr bool kHasParams = true;
  /// Its scene keys, [dem.<family>.softbond] (params.hpp).
  template <class V> static void params(V& v, ContactFamilyParams& f) { describe(v, f.softbond); }
  static constexpr bool kBond = true;

  static LawConst constants(const ContactFamilyParams& f, bool rescale, bool /*wall*/) {
    const auto& s = f.softbond;
    LawConst c;
    c.rgap = f.linear.rgap;
    c.rescale = rescale;
    c.beta = s.mcf;
    c.bmul = s.bmul;
    c.twist = s.twist_factor;
    c.zeta = s.soft;
    c.gamma = s.cut;
    c.ret = s.ret;
    c.unload = s.unload;
    c.cohesion = s.cohesion;
    c.bend_soft = s.bending_in_softening;
    c.moments = s.moments;
    c.ks_kn = 1.0 / f.linear.kratio;
    c.sigc = s.ten;
    c.coh = s.coh;
    c.tanphi = std::tan(s.fa_deg * std::numbers::pi / 180.0);
    return c;
  }
  /// One stiffness set (§3.1): per-area k_n = E*/L (or k_n_fixed/A), contact K_n = k_n A with
  /// A = π R̄², R̄ = λ R̄_contact.
  static void init(double rbar, double L, ContactHist& h, BondHist* b, const ContactFamilyParams& f) {
    const double rb = f.softbond.rmul * rbar;
    const double area = std::numbers::pi * rb * rb;
    const double kna = f.linear.kn_fixed > 0.0 ? f.linear.kn_fixed / area : f.linear.emod / L;
    b->rb = rb;
    b->kn = kna;
    h.kn = kna * area;
    h.ks = kna / f.linear.kratio * area;
    h.mu = f.linear.fric;
    if (f.linear.mode == NormalMode::kIncremental) h.flags |= ContactHist::kIncremental;
  }
  [[gnu::always_inline]] static Vec3 update(const Kin& k, ContactHist& h, BondHist* b, const LawConst& c, Vec3& Mo) {
    const Vec3& n = k.n;
    const double gs = k.gap - c.rgap;
    if (h.flags & ContactHist::kHasNormal) {
      rotate_into_plane(h.fs, h.n_old, n, k.wmean, k.dt, c.rescale);
      // bond moments: rotate the bending part; the twist keeps its scalar about the new n̂
      rotate_into_plane(b->mb, h.n_old, n, k.wmean, k.dt, c.rescale);
    }
    h.n_old = n;
    h.flags |= ContactHist::kHasNormal;
    const double dun = dot(k.du, n);
    const Vec3 dus = k.du - dun * n;
    const double dtt = dot(k.dtheta, n);
    const Vec3 dtb = k.dtheta - dtt * n;
    return softbond_update(h, *b, c, gs, dun, dus, dtt, dtb, n, Mo);
  }
  /// Separated and force-free without a bond: the §3.5 moment limits are proportional to F_n,
  /// so the result would be F = M = 0.
  static bool idle(double d2, double reach, const ContactHist& h, const BondHist* b) {
    return (d2 > reach * reach) & (h.fn == 0.0) & !bonded(b->state);
  }
  /// The springs of every counted contact; bending and twisting where a moment can act (a
  /// bond, or the §3.5 limits of an unbonded contact).
  static ContactStiffness stiffness(const ContactHist& h, const BondHist* b, const ContactFamilyParams& f, double /*ra*/, double /*rb*/) {
    ContactStiffness s{h.kn, h.ks, 0.0};
    if (b && (bonded(b->state) || f.softbond.moments != UnbondedMoments::kNone)) s.krot += b->kn * b->inertia();
    return s;
  }
  static double reference_stiffness(double r, const ContactFamilyParams& f) {
    return LinearLaw::reference_stiffness(r, f);
  }
  static void add_strain(double& e, const ContactHist& h, const BondHist* b, const ContactFamilyParams& f) {
    LinearLaw::add_strain(e, h, b, f);
    if (!b || b->kn <= 0.0) return;
    const double ks_kn = 1.0 / f.linear.kratio;
    e += 0.5 * b->mt * b->mt / (b->kn * ks_kn * b->polar()) + 0.5 * norm2(b->mb) / (b->kn * b->inertia());
  }
  static Vec3 force(const ContactHist& h, const BondHist*) { return h.fn * h.n_old + h.fs; }
  static Vec3 moment(const ContactHist& h, const BondHist* b) { return b->mt * h.n_old + b->mb; }
  static void install_bond(ContactHist&, BondHist& b, const ContactFamilyParams& f) { b.sigma_t = f.softbond.ten; }
  /// The wall contacts' lane kernel (pair_block.hpp WallIn), or null: scalar wall passes.
  static pairblock::WallFn wall_lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale && c.unload == SoftUnload::kElastic ? pairblock::softbond_wall_kernel(isa) : nullptr;
  }
  static pairblock::Fn lane_kernel(pairblock::Isa isa, const LawConst& c) {
    return c.rescale && c.unload == SoftUnload::kElastic ? pairblock::softbond_kernel(isa) : nullptr;
  }
  /// Unbonded soft-bond contacts take the scalar law (§3.5 moment limits).
  static bool lane_needs_scalar(const BondHist* b) { return !bonded(b->state); }
  /// A lane keeps the flags' kActive and the bond state (every change of state is a scalar lane).
  static unsigned lane_key(const pairblock::Out& /*out*/, int /*l*/, unsigned k0) { return k0; }
  static void store_lane(ContactHist& h, BondHist* b, const pairblock::Out& out, int l) {
    h.fs = {out.fs[0][l], out.fs[1][l], out.fs[2][l]};
    h.fn = out.fn[l];
    h.n_old = {out.n[0][l], out.n[1][l], out.n[2][l]};
    h.flags |= ContactHist::kHasNormal;
    b->mb = {out.mb[0][l], out.mb[1][l], out.mb[2][l]};
    b->mt = out.mt[l];
  }
};

}  // namespace demfdm::dem
