// Parameters of the FDM engine (docs/theory.md section 5). Plain structs with documented
// defaults and units; the scene reader maps its keys onto these fields. Validation lives in
// validate() (throws std::invalid_argument naming the field, the range and the value found).
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include "demfdm/fdm/mesh.hpp"  // MeshParams, Box, kNaN (library fdm_mesh)

namespace demfdm::fdm {

inline constexpr double kStandardGravity = 9.81;  // [m/s^2] g0 (docs/theory.md 0.1)

// Constitutive model of a zone group (docs/theory.md 5.4).
enum class Constitutive : std::uint8_t { kElastic = 0, kMohrCoulomb = 1 };

struct Material {
  Constitutive model = Constitutive::kElastic;  // [-] elastic or Mohr-Coulomb with tension cut-off
  double density = 1272.0;    // [kg/m^3] rho_b = (1-n) rho_s (docs/theory.md 0.3, 7.4)
  double young = 2.0e9;       // [Pa] E (docs/theory.md 5.7 example; calibrate from the DEM, U9)
  double poisson = 0.25;      // [-] nu, in (-1, 0.5)
  double cohesion = 0.0;      // [Pa] c (Mohr-Coulomb only)
  double friction_deg = 30.0; // [deg] phi, in [0, 90) (Mohr-Coulomb only)
  double dilation_deg = 0.0;  // [deg] psi, in [0, phi] (Mohr-Coulomb only)
  // [Pa] tension cut-off sigma^t (tension positive); NaN: the apex value c/tan(phi); values
  // above the apex are limited to it (docs/theory.md 5.4).
  double tension = kNaN;
};

// The keys of one [[continuum.material]] element with a field (its region, region_lo and
// region_hi, are lists the scene reader maps), declared once (demfdm/param_table.hpp).
template <class V>
void describe(V& v, Material& m) {
  v.choice("model", m.model, {{"elastic", Constitutive::kElastic}, {"mohr_coulomb", Constitutive::kMohrCoulomb}},
           "Constitutive model (docs/theory.md 5.4).");
  v.real("density", "kg/m^3", m.density, ParamRange::gt(0.0), "Bulk density rho_b = (1-n) rho_s (docs/theory.md 7.4).");
  v.real("young", "Pa", m.young, ParamRange::gt(0.0), "Young's modulus E (calibrate from the DEM UCS test).");
  v.real("poisson", "-", m.poisson, ParamRange::gt(-1.0).lt(0.5), "Poisson's ratio.");
  v.real("cohesion", "Pa", m.cohesion, ParamRange::ge(0.0), "Mohr-Coulomb cohesion c.");
  v.real("friction_deg", "deg", m.friction_deg, ParamRange::ge(0.0).lt(90.0), "Mohr-Coulomb friction angle.");
  v.real("dilation_deg", "deg", m.dilation_deg, ParamRange::ge(0.0).lt(90.0),
         "Mohr-Coulomb dilation angle (<= friction).");
  v.real_or_word("tension", "Pa", m.tension, ParamRange::ge(0.0), "auto", kNaN,
                 "Tension cut-off (tension positive); \"auto\": the apex value c/tan(phi).");
}

// A material applied to the zones whose centroid lies in `region` (all zones if empty).
// Groups are applied in order, so a later group overrides an earlier one.
struct MaterialGroup {
  Material material{};
  std::optional<Box> region{};  // [m] nullopt: every zone
};

// Integration mode (docs/theory.md 5.6, 6.6).
enum class Mode : std::uint8_t {
  kDynamic = 0,  // real (gravitational) masses, physical timestep (option A)
  kStatic = 1,   // mass-scaled, dt = 1, velocities are displacement per step (option B)
};

// Where the mixed-discretisation volumetric strain rate is averaged (docs/theory.md 5.3, U15).
enum class VolumetricAveraging : std::uint8_t {
  kPerOverlay = 0,  // over the 5 tetrahedra of each overlay (docs/theory.md 5.3, default)
  kPerZone = 1,     // over all 10 tetrahedra of the zone
};

struct ModelParams {
  MeshParams mesh{};                                 // mesh, used by Model(ModelParams)
  // At least one group; the first should cover all zones. Default: one elastic group with the
  // Material defaults everywhere (built in place: avoids a GCC 12 -Wmaybe-uninitialized false
  // positive on copying an initializer_list that holds a std::optional).
  std::vector<MaterialGroup> materials = std::vector<MaterialGroup>(1);
  Mode mode = Mode::kDynamic;                        // [-] docs/theory.md 5.6
  double damping = 0.8;         // [-] local damping alpha_F in [0, 1) (docs/theory.md 5.6)
  double gravity_level = 1.0;   // [-] N, gravity (0, 0, -N g0); 0 switches gravity off (0.1)
  bool large_strain = false;    // [-] recompute geometry each step + Jaumann rate (docs/theory.md 5.8)
  VolumetricAveraging averaging = VolumetricAveraging::kPerOverlay;  // docs/theory.md 5.3, U15
  double timestep_safety = 0.5; // [-] dt = safety * min_t h_t / C_p, in (0, 1] (docs/theory.md 5.7)
  // [-] multiplier on the static-mode inertial mass rule (docs/theory.md 5.6, U10), >= 1 is safe
  double static_mass_factor = 1.0;
  bool strongbox_boundary = true;  // [-] fixed base, rollers on the 4 sides (docs/theory.md 5.10)
  int history_every = 0;        // [steps] append a HistoryRecord every n steps; 0: never
  // [-] loops over fewer zones / gridpoints than this run on one thread (a parallel region
  // costs a barrier, more than a small model's step on a busy machine). Results do not depend
  // on it: every zone writes its own force slot, gathered in a fixed order.
  int parallel_threshold = 4096;
};

// The continuum's own keys ([continuum]) with a field here, declared once. The boundary
// (strongbox_boundary, and the symmetry rollers of the node) and gravity_level (from [gravity])
// are mapped by the scene reader.
template <class V>
void describe(V& v, ModelParams& p) {
  v.choice("mode", p.mode, {{"dynamic", Mode::kDynamic}, {"static", Mode::kStatic}},
           "FDM law of motion: dynamic = real masses and the critical time step (docs/theory.md 6.6 option A); "
           "static = mass-scaled, dt = 1 (option B, pseudo-static only).");
  v.real("damping", "-", p.damping, ParamRange::ge(0.0).lt(1.0), "FDM local damping alpha_F (docs/theory.md 5.6).");
  v.flag("large_strain", p.large_strain, "Recompute zone geometry every step with the Jaumann rate (docs/theory.md 5.8).");
  v.choice("averaging", p.averaging,
           {{"overlay", VolumetricAveraging::kPerOverlay}, {"zone", VolumetricAveraging::kPerZone}},
           "Mixed-discretisation volumetric averaging over each 5-tetrahedron overlay (default) or all 10 "
           "tetrahedra of a zone (docs/theory.md 5.3, U15).");
  v.real("timestep_safety", "-", p.timestep_safety, ParamRange::gt(0.0).le(1.0),
         "FDM time step = safety * min tetrahedron height / P-wave speed (5.7).");
  v.real("static_mass_factor", "-", p.static_mass_factor, ParamRange::ge(1.0),
         "Multiplier on the static-mode inertial masses (5.6).");
}

// Geostatic initial stress (docs/theory.md 4.10, 5.9): sigma_zz = -rho N g0 (z_top - z_c),
// sigma_xx = sigma_yy = K0 sigma_zz, no shear (tension positive).
struct GeostaticStress {
  double z_top = kNaN;  // [m] ground surface; NaN: top of the mesh
  double k0 = kNaN;     // [-] K0; NaN: nu/(1-nu) of each zone's material
};

// Throw std::invalid_argument naming the first bad field: a table key by its scene key
// (continuum.<key>, continuum.material.<key>), with the table's range; then the cross-field rules.
void validate(const Material& m);
void validate(const ModelParams& p);

}  // namespace demfdm::fdm
