// Parameter structs of the DEM engine (no parsing here: the node adapter maps scene keys
// onto these fields). Every field: [unit] meaning (docs/theory.md section). Defaults are the
// paper's values where the paper gives them (docs/theory.md §0.3) and the documented proposals
// otherwise. Validation (validate_*) throws std::invalid_argument naming field, range, value.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>

#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

/// Contact model of a contact family (docs/theory.md §1.7, §2, §3).
enum class ContactModel : std::uint8_t {
  kLinear = 0,       ///< linear, no tension, Coulomb friction (§1.7)
  kLinearPBond = 1,  ///< linear + parallel bond (§2, Potyondy & Cundall 2004)
  kSoftBond = 2,     ///< soft bond, linear softening in tension (§3, [RECON])
  kHertz = 3,        ///< Hertz–Mindlin, no bond (§1.9)
};

/// Normal-force update of the linear model (§1.7 lin_mode).
enum class NormalMode : std::uint8_t { kAbsolute = 0, kIncremental = 1 };

/// Deformability length L for ball–wall contacts (§1.7, Uncertain U6).
enum class WallLength : std::uint8_t { kRadius = 0, kDiameter = 1 };

/// Bond state recorded per contact (§3.6). Output code via pfc_state_code().
enum class BondState : std::uint8_t {
  kNeverBonded = 0,
  kIntact = 1,
  kSoftening = 2,
  kBrokenTension = 3,
  kBrokenShear = 4,
};

/// Soft-bond return mapping while softening (§3.3).
enum class SoftReturn : std::uint8_t {
  kAssociated = 0,  ///< default: associated flow on σ(N, M_b), reduces N and M_b
  kRadial = 1,      ///< scale N and M_b by σ_t/σ* (N>0); else reduce only ‖M_b‖
};
/// Soft-bond unloading from the softening branch (§3.3, U1).
enum class SoftUnload : std::uint8_t {
  kElastic = 0,  ///< default: slope k_n, plastic offset kept
  kSecant = 1,   ///< damage-type: secant stiffness σ_t/(σ_t/k_n + u_p) while SOFTENING
};
/// Cohesion while softening in tension (§3.4).
enum class CohesionSoftening : std::uint8_t {
  kNone = 0,          ///< default: c_eff = c
  kProportional = 1,  ///< c_eff = c σ_t/σ_c
};
/// Moment limits of the unbonded soft-bond contact (§3.5, U3).
enum class UnbondedMoments : std::uint8_t {
  kJiang = 0,  ///< default: ‖M_b‖ ≤ λ_b F_n R̄/4, |M_t| ≤ twist_factor μ F_n R̄
  kNone = 1,   ///< no moment transmitted when unbonded (PBM-like linear part)
};

/// Linear contact part (§1.7). Also the stiffness set of the soft bond (§3.1: one set).
struct LinearParams {
  double emod = 2.8e9;                          // [Pa] E*, deformability modulus (§1.7, §0.3)
  double kratio = 2.4;                          // [-] κ* = k_n/k_s (§1.7)
  double fric = 0.6248693519093275;             // [-] μ = tan 32° (§0.3 proposal)
  NormalMode mode = NormalMode::kAbsolute;      // [-] lin_mode (§1.7); bonding forces incremental
  double rgap = 0.0;                            // [m] reference gap g_r (§1.4)
  WallLength wall_length = WallLength::kRadius; // [-] L = R_ball or 2R_ball for ball–wall (U6)
  double kn_fixed = 0.0;  // [N/m] if > 0: k_n for every contact instead of A E*/L (benchmarks)
};

/// Linear parallel bond (§2).
struct ParallelBondParams {
  double emod = 2.8e9;        // [Pa] Ē* (§2.2)
  double kratio = 2.4;        // [-] κ̄* = k̄_n/k̄_s (§2.2)
  double rmul = 1.0;          // [-] λ̄, bond radius multiplier (§2.2)
  double mcf = 1.0;           // [-] β̄, moment contribution factor (§2.5)
  double ten = 0.45e6;        // [Pa] σ̄_c, tensile strength (§2.5)
  double coh = 0.45e6;        // [Pa] c̄, cohesion (§2.5)
  double fa_deg = 32.0;       // [deg] φ̄, friction angle of the bond shear strength (§2.5)
  bool zero_linear = false;   // [-] set linear k_n = k_s = 0 on bonding (interface bonds, §2.6)
};

/// Soft bond (§3, [RECON]); stiffnesses come from the family's LinearParams (§3.1).
struct SoftBondParams {
  double rmul = 1.0;     // [-] λ, bond radius multiplier (§3.3)
  double mcf = 1.0;      // [-] β, moment contribution factor (§3.3)
  double bmul = 1.0;     // [-] λ_b, bending-friction multiplier (§3.5)
  double ten = 0.45e6;   // [Pa] σ_c, tensile strength (§3.2)
  double coh = 0.45e6;   // [Pa] c, cohesion (§3.2)
  double fa_deg = 32.0;  // [deg] φ (§3.2)
  double soft = 100.0;   // [-] ζ ≥ 0, softening factor: slope −k_n/ζ (§3.3); 0 = brittle
  double cut = 0.05;     // [-] γ ≥ 0, break when σ_t ≤ γ σ_c (§3.3)
  double twist_factor = 2.0 / 3.0;  // [-] |M_t| ≤ twist_factor μ F_n R̄ when unbonded (§3.5)
  SoftReturn ret = SoftReturn::kAssociated;                     // §3.3
  SoftUnload unload = SoftUnload::kElastic;                     // §3.3, U1
  CohesionSoftening cohesion = CohesionSoftening::kNone;        // §3.4
  bool bending_in_softening = true;  // [-] false = Ma & Huang: only N drives softening (§3.3)
  UnbondedMoments moments = UnbondedMoments::kJiang;            // §3.5, U3
};

/// Hertz–Mindlin contact (§1.9): the grains' elastic constants; friction from LinearParams::fric.
struct HertzParams {
  double shear = 1.0e9;   // [Pa] G, shear modulus of the grain material
  double poisson = 0.25;  // [-] ν, Poisson ratio of the grain material, in [0, 0.5)
};

/// Everything that defines the law of one contact family (ball–ball, ball–wall, …).
struct ContactFamilyParams {
  ContactModel model = ContactModel::kLinear;  // [-] model of the family
  LinearParams linear;                         // linear part / soft-bond stiffness
  ParallelBondParams pbond;                    // used when model == kLinearPBond
  SoftBondParams softbond;                     // used when model == kSoftBond
  HertzParams hertz;                           // used when model == kHertz
};

/// Axis-aligned periodic cell (§4.2).
struct PeriodicParams {
  bool enabled = false;  // [-] periodic in x, y and z
  Vec3 origin{};         // [m] cell origin o
  Vec3 length{};         // [m] cell lengths L (each > 2 (2 R_max + skin))
};

/// World-level parameters.
struct WorldParams {
  double density = 2650.0;      // [kg/m^3] grain density ρ_s (§0.3)
  double local_damping = 0.7;   // [-] α, local non-viscous damping, 0 ≤ α < 1 (§1.3)
  double g0 = 9.81;             // [m/s^2] g0 (§0.1)
  double g_level = 1.0;         // [-] N, centrifuge level; gravity = (0,0,−N g0) (§0.1)
  bool gravity = false;         // [-] gravity effect present (§1.2)
  double dt_safety = 0.8;       // [-] f_s, safety factor of the critical step (§1.8, U5)
  int dt_interval = 100;        // [steps] recompute the critical step every K steps (§1.8)
  double dt_fixed = 0.0;        // [s] > 0: use this step instead of the automatic one
  double skin = 0.0;            // [m] Verlet skin; 0 → skin_factor × d_min (§1.4)
  double skin_factor = 0.15;    // [-] skin / d_min when skin == 0 (§1.4: 0.1–0.2)
  bool rescale_shear = true;    // [-] keep ‖F_s‖ through the plane rotation (§1.6 step 3)
  bool facet_spin = true;       // [-] kinematic facet spin for ball–facet contacts (§6.2)
  bool track_energy = true;     // [-] accumulate damping/friction/softening dissipation (§8.18)
  int threads = 0;              // [-] OpenMP threads for the force loop; 0 = OpenMP default
  PeriodicParams periodic;      // periodic cell (§4.2)
  ContactFamilyParams ball_ball;     // family ball–ball
  ContactFamilyParams ball_wall;     // family ball–planar wall (platens, boxes)
  ContactFamilyParams ball_facet;    // family ball–interface facet (§6.3)
  ContactFamilyParams ball_footing;  // family ball–footing (§0.3: μ = 0.5)
};

/// Map the bond state to PFC-like integers for output (§2.5: 0 none, 1 tension, 2 shear,
/// 3 bonded; softening = 4 has no PFC equivalent).
constexpr std::uint8_t pfc_state_code(BondState s) {
  switch (s) {
    case BondState::kNeverBonded: return 0;
    case BondState::kBrokenTension: return 1;
    case BondState::kBrokenShear: return 2;
    case BondState::kIntact: return 3;
    case BondState::kSoftening: return 4;
  }
  return 0;
}

const char* to_string(ContactModel m);
const char* to_string(BondState s);

/// Throws std::invalid_argument naming the field (prefixed by `where`) on a bad value.
void validate(const ContactFamilyParams& p, const std::string& where);
void validate(const WorldParams& p);

}  // namespace demfdm::dem
