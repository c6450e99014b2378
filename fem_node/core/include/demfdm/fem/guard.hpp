// Blow-up guard of the FEM continuum (docs/stability.md): a scan of the displacements after a
// solve; the detailed report (the gridpoint, its position, the zones around it with their
// corner displacements) is built only when the scan finds a non-finite value.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "demfdm/fem/model.hpp"

namespace demfdm::fem {

struct GuardFinding {
  std::string cause;            // one line: which gridpoint, where
  std::string detail;           // multi-line: position, displacement, zones around it
  std::int32_t gridpoint = -1;  // offending gridpoint
};

/// The first gridpoint (in id order) with a non-finite displacement component, or nothing.
std::optional<GuardFinding> check_finite(const Model& m);

/// The zones that have gridpoint g as a corner, one per line: each corner's id and displacement.
std::string zones_around(const Model& m, std::int32_t g);

}  // namespace demfdm::fem
