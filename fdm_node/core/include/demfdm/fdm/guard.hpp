// Blow-up guard of the FDM continuum (issue 7 item 4, docs/stability.md): an O(n) scan of the
// gridpoint and zone state after a step; the detailed report (the offending gridpoint or zone,
// its position and values, the zones around it) is built only when the scan finds something.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "demfdm/fdm/model.hpp"

namespace demfdm::fdm {

struct GuardFinding {
  std::string cause;            // one line: what, which gridpoint / zone, its value
  std::string detail;           // multi-line: where, values, neighbourhood
  std::int32_t gridpoint = -1;  // offending gridpoint, or -1
  std::int32_t zone = -1;       // offending zone, or -1
};

/// The first gridpoint (in id order) with a non-finite position, velocity, displacement or
/// zone force, and the first zone with a non-finite stress in one of its tetrahedra (both
/// named when both exist). O(n) over the gridpoint arrays when everything is finite: a
/// non-finite stress reaches the zone forces of its corners in the same zone pass.
std::optional<GuardFinding> check_finite(const Model& m);

/// The gridpoint with the largest kinetic energy 1/2 m |v|^2 (inertial mass), the first one on
/// a tie: the one a kinetic-energy jump report names.
std::int32_t fastest_gridpoint(const Model& m);

/// Position, velocity, displacement, zone force and fixity of gridpoint g, one line.
std::string describe_gridpoint(const Model& m, std::int32_t g);
/// Centre, volume-averaged stress and plastic state of zone z, one line.
std::string describe_zone(const Model& m, std::int32_t z);
/// The zones around gridpoint g (described), one per line.
std::string zones_around(const Model& m, std::int32_t g);
/// The 8 gridpoints of zone z and the zones sharing a gridpoint with it, one per line.
std::string zone_neighbourhood(const Model& m, std::int32_t z);

}  // namespace demfdm::fdm
