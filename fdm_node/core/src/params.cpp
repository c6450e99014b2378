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
  Material keys = m;  // the table's ranges (params.hpp), named as the scene names the keys
  RangeCheck check{"FDM", "continuum.material."};
  describe(check, keys);
  if (m.model == Constitutive::kMohrCoulomb) {
    require(m.dilation_deg <= m.friction_deg, "material.dilation_deg", "an angle in [0, friction_deg] deg",
            m.dilation_deg);
    require(!(m.friction_deg == 0.0 && std::isnan(m.tension) && m.cohesion == 0.0), "material.cohesion",
            "a value > 0 Pa when friction_deg = 0 (no strength at all otherwise)", m.cohesion);
  }
}

void validate(const ModelParams& p) {
  require(!p.materials.empty(), "materials", "at least one material group", 0.0);
  for (const auto& g : p.materials) validate(g.material);
  RangeCheck check{"FDM", "continuum."};  // the table's ranges (params.hpp)
  describe(check, const_cast<ModelParams&>(p));  // the table binds fields; RangeCheck only reads
  // Not scene keys (gravity_level comes from [gravity]).
  require(p.gravity_level >= 0.0 && std::isfinite(p.gravity_level), "gravity_level", "a finite value >= 0", p.gravity_level);
  require(p.history_every >= 0, "history_every", "a step count >= 0", p.history_every);
  require(p.parallel_threshold >= 0, "parallel_threshold", "a count >= 0", p.parallel_threshold);
}

}  // namespace demfdm::fdm
