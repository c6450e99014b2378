// Contact state and the stateless contact kernels (docs/theory.md §1.4–1.7, §2, §3).
//
// Design (as LAMMPS's granular sub-model kernels): every formula lives in one inline function over plain
// values. The passes in world.cpp are templates on the ContactModel; one switch per pass
// picks the instantiation, so there is no branch on the model type inside a contact loop.
// The same functions are called by the unit tests, so tests and hot loops cannot drift.
//
// Sign conventions (§0.2): n̂ points from A to B; F is the force on B from A; F_n = F·n̂ is
// compression positive; bond routines use N = −F_n (tension positive). B receives F and M,
// A receives −F and −M (plus the lever-arm torques).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "demfdm/dem/params.hpp"
#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

/// Per-contact history of the linear part (hot, touched every step). 96 bytes.
struct ContactHist {
  Vec3 fs{};        // [N] shear force on B (global vector, in the contact plane)
  double fn = 0.0;  // [N] normal force on B, compression positive
  Vec3 n_old{};     // [-] normal at the last update (for the plane rotation §1.6)
  double kn = 0.0;  // [N/m] normal stiffness K_n (deformability §1.7, precomputed)
  double ks = 0.0;  // [N/m] shear stiffness K_s
  double mu = 0.0;  // [-] friction coefficient
  double e_slip = 0.0;  // [J] frictional dissipation accumulated on this contact (§8.18)
  std::uint8_t flags = 0;  // kIncremental | kSlip | kActive | kHasNormal
  static constexpr std::uint8_t kIncremental = 1, kSlip = 2, kActive = 4, kHasNormal = 8;
};

/// Per-contact bond / moment state (only allocated for families that can bond).
struct BondHist {
  Vec3 fsb{};         // [N] parallel-bond shear force (PBM); unused for soft bond
  double nb = 0.0;    // [N] parallel-bond normal force, tension positive (PBM)
  Vec3 mb{};          // [N m] bending moment on B (PBM bond or soft-bond contact)
  double mt = 0.0;    // [N m] twisting moment about n̂ on B
  double rb = 0.0;    // [m] bond radius R̄ = λ min(R_A, R_B) (§2.2, §3.3)
  double kn = 0.0;    // [Pa/m] bond normal stiffness per area k_n = E/L (§1.7, §2.2);
                      // k_s = k_n/κ and the strengths are family constants (LawConst)
  double sigma_t = 0.0; // [Pa] current tensile strength (soft bond, §3.3)
  double e_soft = 0.0;  // [J] bond dissipation (§8.18): softening, and the elastic energy released at breakage
  BondState state = BondState::kNeverBonded;
  std::uint8_t slip_b = 0, slip_t = 0;  // soft-bond unbonded moment slip flags (§3.5)
  // Disc geometry derived from R̄ (cheaper than storing it: the loop is memory bound).
  double area() const { return 3.14159265358979323846 * rb * rb; }  // A = π R̄²
  double inertia() const { return 0.25 * area() * rb * rb; }        // I = π R̄⁴/4
  double polar() const { return 0.5 * area() * rb * rb; }           // J = 2I
};

/// Whether the contact's own spring set (h.kn, h.ks) carries load now, for stiffness estimates
/// (critical step, servo): a parallel bond's linear part only while its contact is active (a
/// bond across a gap has none, §2.1); the linear and soft-bond springs of any counted contact.
inline bool linear_spring_acts(const ContactHist& h, ContactModel m) {
  return (h.flags & ContactHist::kActive) || m != ContactModel::kLinearPBond;
}

/// Kinematics of one contact over one step (§1.4, §1.5).
struct Kin {
  Vec3 n{};       // unit normal A→B at the current geometry
  double gap = 0.0;  // [m] surface gap (negative = overlap)
  Vec3 la{};      // [m] lever arm x_c − x_A
  Vec3 du{};      // [m] relative displacement increment of B w.r.t. A at x_c (§1.5)
  Vec3 dtheta{};  // [rad] relative rotation increment (ω_B − ω_A)Δt
  Vec3 wmean{};   // [rad/s] ½(ω_A + ω_B), spin used by the plane rotation (§1.6 step 2)
  double dt = 0.0;
};

/// Family-level constants of a law (per-contact constants live in the histories).
struct LawConst {
  double rgap = 0.0;       // [m] reference gap
  double ks_kn = 1.0;      // [-] bond k_s/k_n = 1/κ (§2.2, §3.3)
  double sigc = 0.0;       // [Pa] bond tensile strength
  double coh = 0.0;        // [Pa] bond cohesion
  double tanphi = 0.0;     // [-] tan of the bond friction angle
  double beta = 1.0;       // [-] moment contribution factor
  double bmul = 1.0;       // [-] soft-bond bending friction multiplier
  double twist = 2.0 / 3.0;  // [-] soft-bond twist limit factor
  double zeta = 0.0;       // [-] soft-bond softening factor
  double gamma = 0.0;      // [-] soft-bond cut factor
  bool rescale = true;     // keep ‖F_s‖ through the rotation
  SoftReturn ret = SoftReturn::kAssociated;
  SoftUnload unload = SoftUnload::kElastic;
  CohesionSoftening cohesion = CohesionSoftening::kNone;
  bool bend_soft = true;
  UnbondedMoments moments = UnbondedMoments::kJiang;
};

/// §1.6: carry an in-plane history vector from the old contact plane into the new one.
/// Step 1 tilts by a = n_old × n_new, step 2 spins by the mean spin about n_new, step 3
/// projects onto the new plane and (optionally) restores the magnitude from before step 1.
[[gnu::always_inline]] inline void rotate_into_plane(Vec3& v, const Vec3& n_old, const Vec3& n_new, const Vec3& wmean,
                              double dt, bool rescale) {
  const double m2 = norm2(v);
  if (m2 == 0.0) return;
  const double im2 = 1.0 / m2;  // off the critical path (m2 is known before the rotation)
  const Vec3 a = cross(n_old, n_new);
  v -= cross(v, a);
  const Vec3 b = (dot(wmean, n_new) * dt) * n_new;
  v -= cross(v, b);
  v -= dot(v, n_new) * n_new;
  if (rescale) {
    const double k2 = norm2(v);
    // √(m2/k2) = (1+δ)^(−1/2) with δ = k2/m2 − 1, which is O(rotation²) per step. For
    // |δ| < 1e-6 the series 1 − δ/2 + 3δ²/8 has a truncation error < 5|δ|³/16 < 4e-19
    // (below half an ulp) and avoids the divide–square-root latency chain; otherwise
    // (and for k2 = 0) the exact form is used.
    const double dl = (k2 - m2) * im2;
    if (std::abs(dl) < 1e-6) {
      v *= 1.0 + dl * (-0.5 + 0.375 * dl);
    } else if (k2 > 0.0) {
      v *= std::sqrt(m2 / k2);
    }
  }
}

/// §1.7 linear model. Updates (fn, fs) in place and returns the force on B.
/// `gs` = g − g_r; `dun` = Δu·n̂ (opening +); `dus` = in-plane Δu.
[[gnu::always_inline]] inline Vec3 linear_update(ContactHist& h, double gs, double dun, const Vec3& dus, const Vec3& n) {
  if (gs > 0.0) {  // inactive: zero force; incremental mode restarts from 0 (§1.7)
    h.fn = 0.0;
    h.fs = Vec3{};
    h.flags &= static_cast<std::uint8_t>(~(ContactHist::kActive | ContactHist::kSlip));
    return Vec3{};
  }
  h.flags |= ContactHist::kActive;
  double fn = (h.flags & ContactHist::kIncremental) ? h.fn - h.kn * dun : -h.kn * gs;
  fn = std::max(fn, 0.0);  // no tension
  h.fn = fn;
  Vec3 fs = h.fs - h.ks * dus;
  const double fmax = h.mu * fn;
  const double f2 = norm2(fs);
  if (f2 > fmax * fmax) {
    const double f = std::sqrt(f2);
    const double s = fmax / f;
    // slip work: force at the limit times the slip displacement (f − fmax)/k_s (§8.18)
    if (h.ks > 0.0) h.e_slip += fmax * (f - fmax) / h.ks;
    fs *= s;
    h.flags |= ContactHist::kSlip;
  } else {
    h.flags &= static_cast<std::uint8_t>(~ContactHist::kSlip);
  }
  h.fs = fs;
  return fn * n + fs;
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

/// §2.4–2.5 parallel bond, bonded state. Returns false if the bond broke this step.
/// Adds the bond force/moment on B into (F, M).
[[gnu::always_inline]] inline void pbond_update(BondHist& b, const LawConst& c, double dun, const Vec3& dus, double dtt,
                         const Vec3& dtb, const Vec3& n, Vec3& F, Vec3& M) {
  const double A = b.area(), iA = 1.0 / A;
  const double rb_I = 4.0 * 3.14159265358979323846 * b.rb * iA * iA;  // R̄/I = 4πR̄/A²
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
    // One division for the disc: 1/A; R̄/I = 4π R̄/A² and R̄/J = 2π R̄/A² (A = π R̄²).
    const double A = b.area(), iA = 1.0 / A;
    const double rb_I = 4.0 * 3.14159265358979323846 * b.rb * iA * iA;
    // 1. elastic predictor
    double N = -h.fn + kne * A * dun;
    h.fs -= h.ks * dus;
    b.mt -= (b.kn * c.ks_kn) * b.polar() * dtt;
    b.mb -= (kne * b.inertia()) * dtb;
    const double mbn = norm(b.mb);
    const double cm = c.bend_soft ? c.beta * rb_I : 0.0;
    const double sig = N * iA + cm * mbn;
    if (sig > b.sigma_t) {
      if (c.zeta == 0.0) {
        b.state = BondState::kBrokenTension;
      } else {
        // 3. envelope step: σ_t drops by (k_n/ζ)·(excess elongation), §3.3.
        const double st_new = b.sigma_t - (b.kn / c.zeta) * (sig - b.sigma_t) / kne;
        const double x = (sig - st_new) / kne;  // plastic peripheral elongation this step
        b.e_soft += 0.5 * (b.sigma_t + std::max(st_new, 0.0)) * b.area() * x;
        b.sigma_t = st_new;
        b.state = BondState::kSoftening;
        // 4. return to σ = σ_t
        if (c.ret == SoftReturn::kAssociated || !(N > 0.0)) {
          if (c.ret == SoftReturn::kAssociated) {
            const double cmm = (mbn > 0.0 && c.bend_soft) ? c.beta * c.beta * b.rb * b.rb / b.inertia() : 0.0;
            const double lam = x / (1.0 / b.area() + cmm);
            N -= kne * lam;
            if (cmm > 0.0) b.mb -= (kne * c.beta * b.rb * lam / mbn) * b.mb;
          } else {  // radial with N ≤ 0: reduce only the moment
            const double mnew = std::max(st_new - N / b.area(), 0.0) * b.inertia() / (c.beta * b.rb);
            if (mbn > 0.0) b.mb *= mnew / mbn;
          }
        } else {  // radial, N > 0
          const double s = st_new / sig;
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
      const double tau = norm(h.fs) * iA + c.beta * std::abs(b.mt) * (0.5 * rb_I);
      const double ceff =
          c.cohesion == CohesionSoftening::kNone ? c.coh : c.coh * b.sigma_t / c.sigc;
      if (tau > ceff - (N * iA) * c.tanphi) b.state = BondState::kBrokenShear;
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
  b.mb -= (b.kn * b.inertia()) * dtb;
  b.mt -= (b.kn * c.ks_kn) * b.polar() * dtt;
  const double mbl = c.bmul * h.fn * b.rb * 0.25;
  const double mbn = norm(b.mb);
  b.slip_b = mbn > mbl;
  if (b.slip_b) b.mb *= (mbn > 0.0 ? mbl / mbn : 0.0);
  const double mtl = c.twist * h.mu * h.fn * b.rb;
  b.slip_t = std::abs(b.mt) > mtl;
  if (b.slip_t) b.mt = std::copysign(mtl, b.mt);
  M = b.mt * n + b.mb;
  return F;
}

/// Full law of one contact for model M. Rotates the histories into the current plane,
/// splits the increments (§1.5) and evaluates the model. Returns the force on B; the moment
/// on B is written to Mo.
template <ContactModel M>
[[gnu::always_inline]] inline Vec3 contact_law(const Kin& k, ContactHist& h, BondHist* b, const LawConst& c, Vec3& Mo) {
  const Vec3& n = k.n;
  const double gs = k.gap - c.rgap;
  if constexpr (M == ContactModel::kLinear) {
    if (gs > 0.0 && h.fn == 0.0) {  // untouched, nothing to carry
      h.n_old = n;
      h.flags |= ContactHist::kHasNormal;
      h.fs = Vec3{};
      h.flags &= static_cast<std::uint8_t>(~(ContactHist::kActive | ContactHist::kSlip));
      Mo = Vec3{};
      return Vec3{};
    }
  }
  if (h.flags & ContactHist::kHasNormal) {
    rotate_into_plane(h.fs, h.n_old, n, k.wmean, k.dt, c.rescale);
    if constexpr (M != ContactModel::kLinear) {
      // bond moments: rotate the bending part; the twist keeps its scalar about the new n̂
      rotate_into_plane(b->mb, h.n_old, n, k.wmean, k.dt, c.rescale);
      if constexpr (M == ContactModel::kLinearPBond) {
        rotate_into_plane(b->fsb, h.n_old, n, k.wmean, k.dt, c.rescale);
      }
    }
  }
  h.n_old = n;
  h.flags |= ContactHist::kHasNormal;
  const double dun = dot(k.du, n);
  const Vec3 dus = k.du - dun * n;
  if constexpr (M == ContactModel::kLinear) {
    Mo = Vec3{};
    return linear_update(h, gs, dun, dus, n);
  } else if constexpr (M == ContactModel::kLinearPBond) {
    Vec3 F = linear_update(h, gs, dun, dus, n);
    Mo = Vec3{};
    if (b->state == BondState::kIntact) {
      const double dtt = dot(k.dtheta, n);
      const Vec3 dtb = k.dtheta - dtt * n;
      pbond_update(*b, c, dun, dus, dtt, dtb, n, F, Mo);
    }
    return F;
  } else {
    const double dtt = dot(k.dtheta, n);
    const Vec3 dtb = k.dtheta - dtt * n;
    return softbond_update(h, *b, c, gs, dun, dus, dtt, dtb, n, Mo);
  }
}

}  // namespace demfdm::dem
