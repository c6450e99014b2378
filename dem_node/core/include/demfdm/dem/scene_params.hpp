// The DEM part of a scene mapped onto the engine's parameter structs (library dem_scene: the
// DEM core plus the scene reader, no bus). The DEM node and the unit tests call these; every
// scene key with a field is read through its declaration beside the struct (params.hpp,
// specimen.hpp, procedures.hpp; demfdm/param_table.hpp), so the schema, the read and the range
// check cannot disagree; the keys without a single field (lists, "auto" values derived from other
// keys) are declared in the schema and read with its defaults. Errors are config::Error naming the scene key.
#pragma once

#include <string>

#include "common/config/config.hpp"
#include "demfdm/dem/params.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem::scene {

/// Geometry of the DEM block (schema::dem_block): REV cell, replication, placement.
struct Block {
  Vec3 origin{}, cell{};
  int nx = 1, ny = 1, nz = 1;
  double height() const { return cell.z * nz; }
  double z_top() const { return origin.z + height(); }
  double width_x() const { return cell.x * nx; }
  double width_y() const { return cell.y * ny; }
  Vec3 centre() const { return {origin.x + cell.x * nx / 2, origin.y + cell.y * ny / 2, origin.z + height() / 2}; }
};
Block block(const config::Scene& s);

/// One contact family, [dem.<family>] and its law tables [dem.<family>.<law>] (params.hpp).
ContactFamilyParams family(const config::Scene& s, const FamilyInfo& f);

/// The world of a scene with [dem]: densities, step rule, threads (run.threads), the four
/// families, and the REV's periodic cell when a stage generates the specimen. dt_fixed and
/// gravity are left off: the node applies them at the first stage after preparation.
/// Validated (params.cpp); a bad value is reported under its scene key.
WorldParams world(const config::Scene& s, const Block& b);

/// Radius-expansion generation of the REV (dem.specimen, docs/theory.md 4.3).
RevParams rev(const config::Scene& s);

/// sigma_v at the bottom of the DEM block for the scene's g-level (docs/theory.md 4.5, 7.4):
/// dem.specimen.sigma_v, or "auto" = rho_b N g0 H_D.
double sigma_v(const config::Scene& s, const Block& b);

/// The REV servo (4.5): targets (k0 sigma_v, k0 sigma_v, sigma_v), gain, tolerances, budget and
/// the compaction friction.
using dem::ServoSettings;  // specimen.hpp, beside its table
ServoSettings servo(const config::Scene& s, const Block& b);

/// Gap below which the bond stage bonds a pair [m]: dem.specimen.bond_gap, or "auto" =
/// 1e-3 d_min (upscaled; 4.6).
double bond_gap(const config::Scene& s);

/// The footing of dem.footing, its axis at dem.footing.centre (z = 0) or the block's centre
/// (the placement then finds the block's top under it).
FootingParams footing(const config::Scene& s, const Block& b);

/// Interface-bond forces of the couple stage (4.9); unit_weight is the block's, from its balls.
InterfaceBondParams interface_bonds(const config::Scene& s, const Block& b, double unit_weight);

/// Depth scaling of the couple stage and the DEM-only box (4.9); false when "none".
bool depth_scaling(const config::Scene& s, const Block& b, DepthScaleParams& p);

/// The UCS test of a ucs stage (stage keys strain_rate, max_strain).
UcsParams ucs(const config::Scene& stage);

}  // namespace demfdm::dem::scene
