// Parameter validation: every error names the field, the expected range and the value found.
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

#include "demfdm/fdm/params.hpp"

namespace demfdm::fdm {
namespace {

void require(bool ok, const char* field, const char* range, double value) {
  if (ok) return;
  std::ostringstream os;
  os << field << ": expected " << range << ", found " << value;
  throw std::invalid_argument(os.str());
}

}  // namespace

void validate(const MeshParams& p) {
  require(p.length > 0.0 && std::isfinite(p.length), "mesh.length", "a finite value > 0 m", p.length);
  require(p.width > 0.0 && std::isfinite(p.width), "mesh.width", "a finite value > 0 m", p.width);
  require(p.height > 0.0 && std::isfinite(p.height), "mesh.height", "a finite value > 0 m", p.height);
  const double ext[3] = {p.length, p.width, p.height};
  static const char* kSize[3] = {"mesh.inner_size[0] (L_D)", "mesh.inner_size[1] (W_D)", "mesh.inner_size[2] (H_D)"};
  const bool any = p.inner_size[0] > 0.0 || p.inner_size[1] > 0.0 || p.inner_size[2] > 0.0;
  for (int d = 0; d < 3; ++d) {
    if (any) {
      require(p.inner_size[d] > 0.0 && p.inner_size[d] <= ext[d], kSize[d],
              "a value in (0, box extent] (all three zero for no inner box)", p.inner_size[d]);
    } else {
      require(p.inner_size[d] == 0.0, kSize[d], "0 when the other inner sizes are 0", p.inner_size[d]);
    }
  }
  require(!(p.pocket && !any), "mesh.pocket", "false when inner_size is zero (no pocket to open)", 1.0);
  require(p.size_near > 0.0 && std::isfinite(p.size_near), "mesh.size_near", "a finite value > 0 m", p.size_near);
  require(p.size_far >= p.size_near && std::isfinite(p.size_far), "mesh.size_far", "a finite value >= size_near", p.size_far);
  require(p.growth >= 1.0 && p.growth <= 2.0, "mesh.growth", "a ratio in [1, 2]", p.growth);
  // Guard against meshes that would not fit in memory by mistake (about 2e7 zones).
  const double nmax = (p.length / p.size_near + 1) * (p.width / p.size_near + 1) * (p.height / p.size_near + 1);
  require(nmax < 2e7, "mesh.size_near", "a size giving fewer than 2e7 zones", p.size_near);
}

void validate(const Material& m) {
  require(m.density > 0.0 && std::isfinite(m.density), "material.density", "a finite value > 0 kg/m^3", m.density);
  require(m.young > 0.0 && std::isfinite(m.young), "material.young", "a finite value > 0 Pa", m.young);
  require(m.poisson > -1.0 && m.poisson < 0.5, "material.poisson", "a value in (-1, 0.5)", m.poisson);
  if (m.model == Constitutive::kMohrCoulomb) {
    require(m.cohesion >= 0.0 && std::isfinite(m.cohesion), "material.cohesion", "a finite value >= 0 Pa", m.cohesion);
    require(m.friction_deg >= 0.0 && m.friction_deg < 90.0, "material.friction_deg", "an angle in [0, 90) deg", m.friction_deg);
    require(m.dilation_deg >= 0.0 && m.dilation_deg <= m.friction_deg, "material.dilation_deg",
            "an angle in [0, friction_deg] deg", m.dilation_deg);
    require(std::isnan(m.tension) || m.tension >= 0.0, "material.tension", "NaN (apex) or a value >= 0 Pa", m.tension);
    require(!(m.friction_deg == 0.0 && std::isnan(m.tension) && m.cohesion == 0.0), "material.cohesion",
            "a value > 0 Pa when friction_deg = 0 (no strength at all otherwise)", m.cohesion);
  }
}

void validate(const ModelParams& p) {
  require(!p.materials.empty(), "materials", "at least one material group", 0.0);
  for (const auto& g : p.materials) validate(g.material);
  require(p.damping >= 0.0 && p.damping < 1.0, "damping", "a value in [0, 1)", p.damping);
  require(p.gravity_level >= 0.0 && std::isfinite(p.gravity_level), "gravity_level", "a finite value >= 0", p.gravity_level);
  require(p.timestep_safety > 0.0 && p.timestep_safety <= 1.0, "timestep_safety", "a value in (0, 1]", p.timestep_safety);
  require(p.static_mass_factor > 0.0 && std::isfinite(p.static_mass_factor), "static_mass_factor",
          "a finite value > 0", p.static_mass_factor);
  require(p.history_every >= 0, "history_every", "a step count >= 0", p.history_every);
  require(p.parallel_threshold >= 0, "parallel_threshold", "a count >= 0", p.parallel_threshold);
}

}  // namespace demfdm::fdm
