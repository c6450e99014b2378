// Contact state shared by every contact law (docs/theory.md §1.4–1.6): the per-contact
// histories, the kinematics handed to a law, the family constants, and the plane rotation of
// history vectors (§1.6). The laws themselves are in laws/*.hpp, listed in laws/registry.hpp.
//
// One formula source: every formula that the vectorised pass also evaluates is written once,
// as a branch-free inline function over plain doubles and bools (`sel` instead of if/else).
// The scalar law calls it for one contact; the lane loops of pair_block_body.inc call it per
// lane inside `#pragma omp simd`, where the compiler turns it into vector code. IEEE +, −, ×,
// ÷ and √ are exact per lane and the build forbids FMA contraction, so both paths give the
// same bits (tests/dem/simd_kernel_test.cpp, tests/golden).
//
// Sign conventions (§0.2): n̂ points from A to B; F is the force on B from A; F_n = F·n̂ is
// compression positive; bond routines use N = −F_n (tension positive). B receives F and M,
// A receives −F and −M (plus the lever-arm torques).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>

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

/// A bond that carries load: intact or softening (§3.6).
constexpr bool bonded(BondState s) { return s == BondState::kIntact || s == BondState::kSoftening; }

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
  static double disc_area(double r) { return std::numbers::pi * r * r; }               // A = π R̄²
  static double disc_inertia(double r) { return 0.25 * disc_area(r) * r * r; }        // I = π R̄⁴/4
  static double disc_polar(double r) { return 0.5 * disc_area(r) * r * r; }           // J = 2I
  double area() const { return disc_area(rb); }
  double inertia() const { return disc_inertia(rb); }
  double polar() const { return disc_polar(rb); }
};

/// Kinematics of one contact over one step (§1.4, §1.5).
struct Kin {
  Vec3 n{};       // unit normal A→B at the current geometry
  double gap = 0.0;  // [m] surface gap (negative = overlap)
  Vec3 la{};      // [m] lever arm x_c − x_A
  Vec3 du{};      // [m] relative displacement increment of B w.r.t. A at x_c (§1.5)
  Vec3 dtheta{};  // [rad] relative rotation increment (ω_B − ω_A)Δt
  Vec3 wmean{};   // [rad/s] ½(ω_A + ω_B), spin used by the plane rotation (§1.6 step 2)
  double dt = 0.0;
  double reff = 0.0;  // [m] R* = R_A R_B/(R_A + R_B), or R_ball against a wall (set for laws
                      // with kNeedsReff only, docs/theory.md §1.9)
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
  double hz_e = 0.0;       // [Pa] Hertz effective modulus E* of the family (§1.9)
  double hz_g = 0.0;       // [Pa] Mindlin effective shear modulus G* of the family (§1.9)
};

/// The traits of a contact law (laws/registry.hpp) that most laws share; a law's type derives
/// from this and states only what differs.
struct LawDefaults {
  static constexpr bool kBond = false;             // per-contact BondHist storage
  static constexpr bool kNeedsReff = false;        // Kin::reff read by update()
  static constexpr bool kStiffnessVaries = false;  // stiffness grows with the overlap: step rechecked every step
  static constexpr bool kHasParams = false;        // own scene keys, table [dem.<family>.<kName>]
  /// The law's own scene keys (params.hpp "Parameter tables"); none by default.
  template <class V> static void params(V& /*v*/, ContactFamilyParams& /*f*/) {}
};

/// Select without a branch (a vector blend inside `omp simd` loops).
[[gnu::always_inline]] inline double sel(bool c, double a, double b) { return c ? a : b; }

/// §1.6 on components, branch-free: carry the in-plane vector (vx, vy, vz) from the plane of
/// n_old into the plane of n. Step 1 tilts by a = n_old × n, step 2 spins by the mean spin w
/// about n, step 3 projects onto the new plane and restores the magnitude from before step 1
/// with the series 1 − δ/2 + 3δ²/8 of (1+δ)^(−1/2), δ = k2/m2 − 1 (truncation error < 5|δ|³/16,
/// below half an ulp for |δ| < 1e-6). Applied only when `apply` and the vector is not zero;
/// `rescale` false skips step 3's magnitude. Returns true when the rotation was too large for
/// the series (|δ| ≥ 1e-6 and k2 > 0): the vector is then left projected but not rescaled, and
/// the caller applies the exact factor √(m2/k2) (rotate_into_plane) or redoes the lane.
[[gnu::always_inline]] inline bool rotate_xyz(double& vx, double& vy, double& vz, double ox, double oy, double oz,
                                              double nx, double ny, double nz, double wx, double wy, double wz,
                                              double dt, bool apply, bool rescale, double& m2_out, double& k2_out) {
  const double m2 = vx * vx + vy * vy + vz * vz;
  const double im2 = 1.0 / m2;  // off the critical path (m2 is known before the rotation)
  const double ax = oy * nz - oz * ny, ay = oz * nx - ox * nz, az = ox * ny - oy * nx;
  double x = vx - (vy * az - vz * ay);
  double y = vy - (vz * ax - vx * az);
  double z = vz - (vx * ay - vy * ax);
  const double s = (wx * nx + wy * ny + wz * nz) * dt;
  const double bx = s * nx, by = s * ny, bz = s * nz;
  const double x2 = x - (y * bz - z * by);
  const double y2 = y - (z * bx - x * bz);
  const double z2 = z - (x * by - y * bx);
  const double q = x2 * nx + y2 * ny + z2 * nz;
  x = x2 - q * nx;
  y = y2 - q * ny;
  z = z2 - q * nz;
  const double k2 = x * x + y * y + z * z;
  const double dl = (k2 - m2) * im2;
  const bool small = __builtin_fabs(dl) < 1e-6;
  const double t = 1.0 + dl * (-0.5 + 0.375 * dl);
  const bool use = apply & (m2 != 0.0);
  const bool series = rescale & small;
  vx = sel(use, sel(series, x * t, x), vx);
  vy = sel(use, sel(series, y * t, y), vy);
  vz = sel(use, sel(series, z * t, z), vz);
  m2_out = m2;
  k2_out = k2;
  return use & rescale & !small & (k2 > 0.0);
}

/// §1.6 for one history vector of the scalar law (the same formula, plus the exact rescale of
/// a large rotation).
[[gnu::always_inline]] inline void rotate_into_plane(Vec3& v, const Vec3& n_old, const Vec3& n_new, const Vec3& wmean,
                                                     double dt, bool rescale) {
  double m2, k2;
  if (rotate_xyz(v.x, v.y, v.z, n_old.x, n_old.y, n_old.z, n_new.x, n_new.y, n_new.z, wmean.x, wmean.y, wmean.z, dt,
                 true, rescale, m2, k2))
    v *= std::sqrt(m2 / k2);
}

}  // namespace demfdm::dem
