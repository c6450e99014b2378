// Parameter validation: every error names the field, the expected range and the value.
#include "demfdm/dem/params.hpp"

#include <cmath>
#include <sstream>

#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/procedures.hpp"
#include <stdexcept>
#include <utility>

namespace demfdm::dem {

const char* to_string(ContactModel m) { return law_name(m); }

const char* to_string(BondState s) {
  switch (s) {
    case BondState::kNeverBonded: return "never_bonded";
    case BondState::kIntact: return "intact";
    case BondState::kSoftening: return "softening";
    case BondState::kBrokenTension: return "broken_tension";
    case BondState::kBrokenShear: return "broken_shear";
  }
  return "?";
}

namespace {
void require(bool ok, const std::string& field, const char* range, double value) {
  if (ok) return;
  std::ostringstream s;
  s << "DEM parameter '" << field << "' must be " << range << ", found " << value << ".";
  throw std::invalid_argument(s.str());
}
}  // namespace

namespace {
// The range checks of a parameter table (params.hpp), named as the scene names the key.
RangeCheck range_check(std::string prefix) { return RangeCheck{"DEM", std::move(prefix)}; }
}  // namespace

void validate(const ContactFamilyParams& p, const std::string& family) {
  auto& f = const_cast<ContactFamilyParams&>(p);  // the tables bind fields; RangeCheck only reads
  RangeCheck family_keys = range_check("dem." + family + ".");
  describe_family(family_keys, f);
  for_each_law([&](auto law) {
    RangeCheck law_keys = range_check("dem." + family + "." + decltype(law)::kName + ".");
    decltype(law)::params(law_keys, f);
  });
  // Not scene keys: benchmarks' fixed stiffness.
  require(p.linear.kn_fixed >= 0.0, "dem." + family + " kn_fixed", ">= 0 N/m", p.linear.kn_fixed);
  // Cross-field: the soft bond's only stiffness set is the linear part.
  if (p.model == ContactModel::kSoftBond)
    require(p.linear.emod > 0.0 || p.linear.kn_fixed > 0.0, "dem." + family + ".emod",
            "> 0 for the soft bond (its only stiffness set)", p.linear.emod);
}

void validate(const WorldParams& p) {
  RangeCheck world_keys = range_check("dem.");
  describe(world_keys, const_cast<WorldParams&>(p));  // the table binds fields; RangeCheck only reads
  // Not scene keys here (gravity comes from [gravity], the skin from skin_factor).
  require(p.g0 >= 0.0, "g0", ">= 0 m/s^2", p.g0);
  require(p.g_level >= 0.0, "g_level", ">= 0", p.g_level);
  require(p.skin >= 0.0, "skin", ">= 0 m", p.skin);
  require(p.threads >= 0, "threads", ">= 0", p.threads);
  if (p.periodic.enabled) {
    for (int k = 0; k < 3; ++k)
      require(p.periodic.length[k] > 0.0, std::string("periodic.length[") + char('0' + k) + "]",
              "> 0 m", p.periodic.length[k]);
  }
  validate(p.ball_ball, "ball_ball");
  validate(p.ball_wall, "ball_wall");
  validate(p.ball_facet, "ball_facet");
  validate(p.ball_footing, "ball_footing");
}

void validate(const FootingParams& f) {
  FootingParams keys = f;  // the table binds fields; the check only reads them
  RangeCheck check = range_check("dem.footing.");
  describe(check, keys);
}

}  // namespace demfdm::dem
