// Scene keys -> fdm_core parameters shared by every continuum node built on fdm_core's mesh
// (fdm_node, fem_node), so that both read [continuum.mesh] and [[continuum.material]] regions
// the same way and their interfaces match. Errors are config::Error at the offending key.
#pragma once
#include <optional>

#include "common/config/config.hpp"
#include "demfdm/fdm/params.hpp"

namespace demfdm::fdm {

// [continuum.mesh], validated (a bad combination fails at "continuum.mesh").
MeshParams mesh_from_scene(const config::Scene& s);
// region_lo / region_hi of one [[continuum.material]] element: nullopt = every zone.
std::optional<Box> region_from_scene(const config::Scene& element);

}  // namespace demfdm::fdm
