// Parameter structs of the DEM engine (no parsing here: the node adapter maps scene keys
// onto these fields). Every field: [unit] meaning (docs/theory.md section). Defaults are the
// paper's values where the paper gives them (docs/theory.md §0.3) and the documented proposals
// otherwise. Validation (validate_*) throws std::invalid_argument naming field, range, value.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>

#include "demfdm/dem/vec3.hpp"
#include "demfdm/param_table.hpp"

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

// ---------------------------------------------------------------------------------------------
// Parameter tables (demfdm/param_table.hpp): each scene key of a contact family is declared once,
// beside its field, by a describe() function that names the key, its unit, its range and its doc,
// and binds the field. The same table drives the scene schema (common/schema: unit, default = the
// field's initial value, range, doc, --help-scene), the read of a scene into these structs
// (dem_node/core scene_params.cpp) and the range checks of validate() below, which name the
// scene key. The family-wide keys (the linear part) are declared by describe_family(); each
// law's own keys by its law type's params() (laws/*.hpp), in the scene table
// [dem.<family>.<law name>].
using demfdm::ParamOption;
using demfdm::ParamRange;

template <class V>
void describe(V& v, LinearParams& p) {
  v.real("emod", "Pa", p.emod, ParamRange::ge(0.0),
         "Deformability modulus E* of the linear part (soft bond: its only stiffness; docs/theory.md 1.7).");
  v.real("kratio", "-", p.kratio, ParamRange::gt(0.0), "Normal-to-shear stiffness ratio kappa* (1.7).");
  v.real("fric", "-", p.fric, ParamRange::ge(0.0), "Friction coefficient mu of unbonded contacts (1.7).");
  v.choice("wall_length", p.wall_length, {{"radius", WallLength::kRadius}, {"diameter", WallLength::kDiameter}},
           "Deformability length L of ball-wall contacts: R_ball (default) or 2 R_ball (1.7, U6).");
}

template <class V>
void describe(V& v, ParallelBondParams& p) {
  v.real("emod", "Pa", p.emod, ParamRange::ge(0.0), "Parallel bond modulus E-bar* (2.2).");
  v.real("kratio", "-", p.kratio, ParamRange::gt(0.0), "Parallel bond stiffness ratio kappa-bar* (2.2).");
  v.real("rmul", "-", p.rmul, ParamRange::gt(0.0), "Parallel bond radius multiplier lambda-bar (2.2).");
  v.real("mcf", "-", p.mcf, ParamRange::ge(0.0).le(1.0), "Parallel bond moment contribution factor beta-bar (2.5).");
  v.real_or_word("ten", "Pa", p.ten, ParamRange::ge(0.0), "unbreakable", INFINITY,
                 "Parallel bond tensile strength sigma-bar_c (2.5); \"unbreakable\": no tensile failure.");
  v.real_or_word("coh", "Pa", p.coh, ParamRange::ge(0.0), "unbreakable", INFINITY,
                 "Parallel bond cohesion c-bar (2.5); \"unbreakable\": no shear failure.");
  v.real("fa", "deg", p.fa_deg, ParamRange::ge(0.0).lt(90.0), "Parallel bond friction angle phi-bar (2.5).");
  v.flag("zero_linear", p.zero_linear,
         "Give the linear part zero stiffness when bonding (interface bonds: no repulsion from initial overlaps, "
         "docs/theory.md 2.6).");
}

template <class V>
void describe(V& v, SoftBondParams& p) {
  v.real("rmul", "-", p.rmul, ParamRange::gt(0.0), "Soft bond radius multiplier lambda (3.3).");
  v.real("mcf", "-", p.mcf, ParamRange::gt(0.0).le(1.0), "Soft bond moment contribution factor beta (3.3).");
  v.real("bmul", "-", p.bmul, ParamRange::ge(0.0), "Soft bond bending-friction multiplier lambda_b (3.5).");
  v.real("ten", "Pa", p.ten, ParamRange::ge(0.0), "Soft bond tensile strength sigma_c (3.2).");
  v.real("coh", "Pa", p.coh, ParamRange::ge(0.0), "Soft bond cohesion c (3.2).");
  v.real("fa", "deg", p.fa_deg, ParamRange::ge(0.0).lt(90.0), "Soft bond friction angle phi (3.2).");
  v.real("soft", "-", p.soft, ParamRange::ge(0.0), "Softening factor zeta: softening slope -k_n/zeta (3.3; 0: brittle).");
  v.real("cut", "-", p.cut, ParamRange::ge(0.0), "Softening tensile-strength factor gamma: break at gamma sigma_c (3.3).");
  v.real("twist", "-", p.twist_factor, ParamRange::ge(0.0),
         "Unbonded twisting limit factor: |M_t| <= f mu F_n R (3.5, U3).");
  v.choice("return", p.ret, {{"associated", SoftReturn::kAssociated}, {"radial", SoftReturn::kRadial}},
           "Return while softening (3.3; a reconstruction, default associated).");
  v.choice("unload", p.unload, {{"elastic", SoftUnload::kElastic}, {"secant", SoftUnload::kSecant}},
           "Unloading from the softening branch (3.3, U1; default elastic with plastic offset).");
  v.choice("cohesion_softening", p.cohesion,
           {{"none", CohesionSoftening::kNone}, {"proportional", CohesionSoftening::kProportional}},
           "Cohesion while softening in tension (3.4; default untouched).");
  v.flag("bending_in_softening", p.bending_in_softening,
         "Bending drives softening with the normal opening (PFC); false: normal only (Ma & Huang; 3.3).");
  v.choice("unbonded_moments", p.moments, {{"jiang", UnbondedMoments::kJiang}, {"none", UnbondedMoments::kNone}},
           "Moment limits of unbonded soft-bond contacts (3.5, U3).");
}

template <class V>
void describe(V& v, HertzParams& p) {
  v.real("shear", "Pa", p.shear, ParamRange::gt(0.0), "Shear modulus G of the grain material (1.9).");
  v.real("poisson", "-", p.poisson, ParamRange::ge(0.0).lt(0.5), "Poisson ratio nu of the grain material (1.9).");
}

/// Everything that defines the law of one contact family (ball–ball, ball–wall, …).
struct ContactFamilyParams {
  ContactModel model = ContactModel::kLinear;  // [-] model of the family
  LinearParams linear;                         // linear part / soft-bond stiffness
  ParallelBondParams pbond;                    // used when model == kLinearPBond
  SoftBondParams softbond;                     // used when model == kSoftBond
  HertzParams hertz;                           // used when model == kHertz
};

/// The family-wide scene keys of a family: its linear part (the law's name, `model`, is declared
/// from the registry, laws/registry.hpp).
template <class V>
void describe_family(V& v, ContactFamilyParams& f) {
  describe(v, f.linear);
}

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
  bool thread_independent = false;  // [-] same bits at any thread count (PairSet::pass_law); not
                                    // in checkpoints: the scene's, as threads
  bool order_free_sums = false;  // [-] the measurements' sums order-free (order_free_sum.hpp): the
                                 // same bits at any grouping; not in checkpoints: the scene's
  PeriodicParams periodic;      // periodic cell (§4.2)
  ContactFamilyParams ball_ball;     // family ball–ball
  ContactFamilyParams ball_wall;     // family ball–planar wall (platens, boxes)
  ContactFamilyParams ball_facet;    // family ball–interface facet (§6.3)
  ContactFamilyParams ball_footing;  // family ball–footing (§0.3: μ = 0.5)
};

/// The world's own scene keys, [dem] (the families have their tables above; run.threads, the
/// periodic cell and gravity come from elsewhere in the scene). dt_fixed is the scene's fixed
/// step, which the DEM node checks and applies only from the first stage after preparation.
template <class V>
void describe(V& v, WorldParams& p) {
  v.real("density", "kg/m^3", p.density, ParamRange::gt(0.0), "Grain density rho_s (docs/theory.md 0.3).");
  v.real("damping", "-", p.local_damping, ParamRange::ge(0.0).lt(1.0),
         "Local (non-viscous) damping alpha (docs/theory.md 1.3).");
  v.real("dt_safety", "-", p.dt_safety, ParamRange::gt(0.0).le(1.0), "Time step = safety * critical step (1.8).");
  v.integer("dt_interval", "steps", p.dt_interval, 1, 1000000000, "Recompute the critical step every n steps (1.8).");
  v.real("dt_fixed", "s", p.dt_fixed, ParamRange::ge(0.0),
         "Fixed time step instead of the automatic one (0: automatic); checked against the critical step once "
         "balls exist (see dt_above_critical); specimen generation always uses the automatic one.");
  v.real("skin_factor", "-", p.skin_factor, ParamRange::gt(0.0), "Verlet skin as a fraction of d_min (1.4).");
  v.flag("facet_spin", p.facet_spin, "Kinematic facet spin for ball-facet contacts (6.2).");
  v.flag("track_energy", p.track_energy, "Accumulate dissipated energies (damping, friction, softening).");
}

/// The contact families of a scene ([dem.<name>]): their WorldParams member and the scene's
/// defaults, which differ from a default-constructed ContactFamilyParams in the model, the
/// friction and the interface bonds' zero_linear (docs/theory.md 0.3, 2.6).
struct FamilyInfo {
  const char* name;
  const char* doc;
  ContactFamilyParams WorldParams::*member;
  ContactModel model;
  double fric;
  bool zero_linear;
  ContactFamilyParams defaults() const {
    ContactFamilyParams f;
    f.model = model;
    f.linear.fric = fric;
    f.pbond.zero_linear = zero_linear;
    return f;
  }
};
inline constexpr FamilyInfo kFamilies[] = {
    {"ball_ball", "Ball-ball contacts.", &WorldParams::ball_ball, ContactModel::kSoftBond, 0.6248693519093275, false},
    {"ball_wall", "Ball-platen contacts (UCS test, boxes).", &WorldParams::ball_wall, ContactModel::kLinear, 0.0, false},
    {"ball_facet", "Ball-interface facet contacts (DEM-continuum coupling, docs/theory.md 6.3).",
     &WorldParams::ball_facet, ContactModel::kLinearPBond, 0.6248693519093275, true},
    {"ball_footing", "Ball-footing contacts (docs/theory.md 0.3: mu = 0.5).", &WorldParams::ball_footing,
     ContactModel::kLinear, 0.5, false},
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

/// Throws std::invalid_argument naming the scene key (dem.<family>.<key>, or
/// dem.<family>.<law>.<key> for a law's own key) on a value outside its declared range, or on a
/// broken cross-field invariant.
void validate(const ContactFamilyParams& p, const std::string& family);
void validate(const WorldParams& p);

}  // namespace demfdm::dem
