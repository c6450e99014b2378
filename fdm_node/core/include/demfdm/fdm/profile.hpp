// Vertical stress profile of the FDM continuum (stress against depth after equilibrium, the
// node's fdm_profile_<stage>.csv): zone stresses averaged per horizontal layer of zones.
#pragma once

#include <cstddef>
#include <vector>

#include "demfdm/fdm/model.hpp"

namespace demfdm::fdm {

struct ProfileLayer {
  double depth = 0;       // [m] of the layer's mid-plane below the top of the mesh
  double szz = 0;         // [Pa] sigma_zz averaged over the layer's zones (tension positive)
  double sxx = 0;         // [Pa] sigma_xx, likewise
  std::size_t zones = 0;  // [-] zones in the layer
};

/// One entry per horizontal layer of the structured grid that holds zones, top layer first.
/// The averages weight each zone's stress (zone_stress()) by its reference volume (the product
/// of its grid spacings).
std::vector<ProfileLayer> stress_profile(const Model& m);

}  // namespace demfdm::fdm
