// Vectorised ball–ball pass, wall passes and law of motion (issue 3 item 12, issue 16 item 1):
// the contact law evaluated for a block of kLanes live contacts at a time, the law of motion for
// kLanes rows at a time. The wall contacts (planes, facets, the footing; WallIn below) use the
// same lane code for the laws (linear, Hertz–Mindlin, parallel bond) with their own kinematics.
//
// Stage 1 (PairSet::pass_law, scalar, contact order): idle test, branch vector d, lane list.
// Stage 2 (here, one lane loop compiled for the baseline ISA, AVX2 and AVX-512, chosen at run
// time): kinematics and the law for all lanes with branch-free selects. Every lane calls the
// formula functions of the scalar law (laws/*.hpp: linear_core, softbond_predict, hertz_core,
// pbond_core, rotate_xyz), so a formula is written once; IEEE +, −, ×, ÷ and √
// are exact per lane and the build forbids FMA contraction (-ffp-contract=off), so each lane is
// bit-identical to the scalar law. Rare paths (soft bond: peak exceeded, softening step,
// breakage, shear break; unbonded soft-bond contacts; a breaking parallel bond; a plane rotation large enough to need
// the exact rescale √(m2/k2)) set `scalar` and are redone by the scalar law in stage 3, which
// starts from the untouched history.
// Stage 3 (PairSet::pass_law, scalar, contact order): histories written back, forces and
// torques added onto the balls in the order of the scalar pass.
// Measured on bench/dem (results_2core_kvm.csv): see the figures there.
#pragma once

#include <cstdint>

#include "demfdm/dem/contact_state.hpp"
#include "demfdm/simd/isa.hpp"
#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem::pairblock {

constexpr int kLanes = 8;

/// Stage 1 output: the live contacts of one block in contact order. Lanes n..kLanes−1 repeat
/// lane 0 (valid indices, results ignored).
struct In {
  int n = 0;
  std::int64_t c[kLanes], a[kLanes], b[kLanes];  // contact index, rows of A and B
  double dx[kLanes], dy[kLanes], dz[kLanes], d2[kLanes];  // branch vector x_B − x_A (image), ‖d‖²
  std::int64_t hasn[kLanes], incr[kLanes];  // ContactHist::kHasNormal, kIncremental set
  std::int64_t scalar[kLanes];              // lane known to need the scalar law (stage 1)
  std::int64_t intact[kLanes];              // laws with bond state: BondState::kIntact (a byte
                                            // load in the lane loop would stop GCC vectorising it)
};

/// Stage 2 output per lane: the new history and the contributions to the ball sums.
struct Out {
  double F[3][kLanes];   // force on B
  double TA[3][kLanes];  // torque added to A (ℓ_A × (−F) − M)
  double TB[3][kLanes];  // torque added to B (ℓ_B × F + M)
  double n[3][kLanes];   // unit normal (new n_old)
  double fs[3][kLanes], fn[kLanes], e_slip[kLanes];
  double mb[3][kLanes], mt[kLanes];  // soft bond, parallel bond
  double fsb[3][kLanes], nb[kLanes];  // parallel bond: shear and normal force
  double kn[kLanes], ks[kLanes];     // Hertz–Mindlin: tangent stiffnesses
  std::int64_t active[kLanes], slip[kLanes];  // new kActive / kSlip flags (linear)
  std::int64_t scalar[kLanes];  // lane must be redone by the scalar law
};

/// Read-only inputs of stage 2.
struct Ctx {
  const Vec3* V;
  const Vec3* W;
  const double* R;
  const ContactHist* H;
  const BondHist* BD;
  LawConst lc;
  double dt;
  Vec3 ed;        // cell strain rate (used when `strained`)
  bool strained;  // periodic cell with a non-zero strain rate
};

using Fn = void (*)(const Ctx&, const In&, Out&);

/// Wall contacts (WallSet::pass_law, walls.cpp): ball A against a wall's surface point, the
/// contact's B. Stage 1 (scalar) finds each contact's surface (normal, centre distance, the
/// point's velocity and spin); stage 2 (here) runs the kinematics of walls.cpp's wall_contact
/// and the law per lane; stage 3 stores the histories and runs the kind's after_law. Outputs in
/// Out: F (force on the wall), TA (torque on the ball, ℓ × F − M), n (the normal) and the law's
/// history fields; in WallOut the moment on the wall and the contact point.
struct WallIn {
  int n = 0;
  std::int64_t c[kLanes], a[kLanes];                        // contact index, ball row
  double nx[kLanes], ny[kLanes], nz[kLanes], dist[kLanes];  // unit normal ball → wall, centre distance
  double vx[kLanes], vy[kLanes], vz[kLanes];                // the surface point's velocity
  double wx[kLanes], wy[kLanes], wz[kLanes];                // and spin
  std::int64_t hasn[kLanes], incr[kLanes], intact[kLanes];  // as In
  std::int64_t scalar[kLanes];  // lane known to need the scalar law (stage 1, Law::lane_needs_scalar)
};
struct WallCtx : Ctx {  // Ctx's balls, histories and law (no cell strain) and the positions
  const Vec3* X = nullptr;
};
struct WallOut {
  double M[3][kLanes], xc[3][kLanes];
};
using WallFn = void (*)(const WallCtx&, const WallIn&, Out&, WallOut&);

/// Law of motion with local damping (World::integrate_rows, §1.2–1.3) for kLanes rows
/// without fixity, lane by lane with the scalar operations. The damping-work terms are
/// returned per row and component (v.x, ω.x, v.y, ω.y, v.z, ω.z: the order in which the caller
/// sums them), with ‖x − x_ref‖² for the neighbour check.
struct MotionCtx {
  Vec3* X;
  Vec3* V;
  Vec3* W;
  const Vec3* Fc;
  const Vec3* Tc;
  const Vec3* Fa;
  const Vec3* Ta;
  const Vec3* X0;
  const double* M;
  const double* I;
  double alpha, dt;
  Vec3 o, sc;     // periodic: x ← o + (x − o) ⊙ sc
  bool periodic;
};
struct MotionOut {
  double e[6][kLanes];  // damping work f_d · ½(v0 + v) Δt per component
  double d2[kLanes];
};
using MotionFn = void (*)(const MotionCtx&, std::size_t i0, MotionOut&);

/// Instruction sets the lane loop is compiled for (common/simd).
using simd::Isa;
using simd::isa_available;
using simd::best_isa;
/// Stage 2 kernels. Linear: every lane. Soft bond: requires SoftUnload::kElastic and
/// rescale (PairSet::pass_law falls back to the scalar pass otherwise).
Fn linear_kernel(Isa isa);
Fn softbond_kernel(Isa isa);
Fn hertz_kernel(Isa isa);
/// Parallel bond: every lane (requires rescale).
Fn pbond_kernel(Isa isa);
MotionFn motion_kernel(Isa isa);
/// Stage 2 of the wall contacts (WallIn): every law (requires rescale; the soft bond also
/// SoftUnload::kElastic; the bonded laws a BondHist per contact).
WallFn linear_wall_kernel(Isa isa);
WallFn hertz_wall_kernel(Isa isa);
WallFn softbond_wall_kernel(Isa isa);
WallFn pbond_wall_kernel(Isa isa);

}  // namespace demfdm::dem::pairblock
