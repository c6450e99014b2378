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
