// Parameter validation: every error names the field, the expected range and the value.
#include "demfdm/dem/params.hpp"

#include <sstream>

#include "demfdm/dem/laws/registry.hpp"
#include <stdexcept>

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

void validate(const ContactFamilyParams& p, const std::string& w) {
  require(p.linear.emod >= 0.0, w + ".linear.emod", ">= 0 Pa", p.linear.emod);
  require(p.linear.kratio > 0.0, w + ".linear.kratio", "> 0", p.linear.kratio);
  require(p.linear.fric >= 0.0, w + ".linear.fric", ">= 0", p.linear.fric);
  require(p.linear.kn_fixed >= 0.0, w + ".linear.kn_fixed", ">= 0 N/m", p.linear.kn_fixed);
  require(p.pbond.emod >= 0.0, w + ".pbond.emod", ">= 0 Pa", p.pbond.emod);
  require(p.pbond.kratio > 0.0, w + ".pbond.kratio", "> 0", p.pbond.kratio);
  require(p.pbond.rmul > 0.0, w + ".pbond.rmul", "> 0", p.pbond.rmul);
  require(p.pbond.mcf >= 0.0 && p.pbond.mcf <= 1.0, w + ".pbond.mcf", "in [0, 1]", p.pbond.mcf);
  require(p.pbond.ten >= 0.0, w + ".pbond.ten", ">= 0 Pa", p.pbond.ten);
  require(p.pbond.coh >= 0.0, w + ".pbond.coh", ">= 0 Pa", p.pbond.coh);
  require(p.pbond.fa_deg >= 0.0 && p.pbond.fa_deg < 90.0, w + ".pbond.fa_deg", "in [0, 90) deg",
          p.pbond.fa_deg);
  const auto& s = p.softbond;
  require(s.rmul > 0.0, w + ".softbond.rmul", "> 0", s.rmul);
  require(s.mcf > 0.0 && s.mcf <= 1.0, w + ".softbond.mcf", "in (0, 1]", s.mcf);
  require(s.bmul >= 0.0, w + ".softbond.bmul", ">= 0", s.bmul);
  require(s.ten >= 0.0, w + ".softbond.ten", ">= 0 Pa", s.ten);
  require(s.coh >= 0.0, w + ".softbond.coh", ">= 0 Pa", s.coh);
  require(s.fa_deg >= 0.0 && s.fa_deg < 90.0, w + ".softbond.fa_deg", "in [0, 90) deg", s.fa_deg);
  require(s.soft >= 0.0, w + ".softbond.soft (zeta)", ">= 0", s.soft);
  require(s.cut >= 0.0, w + ".softbond.cut (gamma)", ">= 0", s.cut);
  require(s.twist_factor >= 0.0, w + ".softbond.twist_factor", ">= 0", s.twist_factor);
  require(p.hertz.shear > 0.0 && std::isfinite(p.hertz.shear), w + ".hertz.shear", "> 0 Pa and finite", p.hertz.shear);
  require(p.hertz.poisson >= 0.0 && p.hertz.poisson < 0.5, w + ".hertz.poisson", "in [0, 0.5)", p.hertz.poisson);
  if (p.model == ContactModel::kSoftBond)
    require(p.linear.emod > 0.0 || p.linear.kn_fixed > 0.0, w + ".linear.emod",
            "> 0 for the soft bond (its only stiffness set)", p.linear.emod);
}

void validate(const WorldParams& p) {
  require(p.density > 0.0, "density", "> 0 kg/m^3", p.density);
  require(p.local_damping >= 0.0 && p.local_damping < 1.0, "local_damping", "in [0, 1)",
          p.local_damping);
  require(p.g0 >= 0.0, "g0", ">= 0 m/s^2", p.g0);
  require(p.g_level >= 0.0, "g_level", ">= 0", p.g_level);
  require(p.dt_safety > 0.0 && p.dt_safety <= 1.0, "dt_safety", "in (0, 1]", p.dt_safety);
  require(p.dt_interval >= 1, "dt_interval", ">= 1 step", p.dt_interval);
  require(p.dt_fixed >= 0.0, "dt_fixed", ">= 0 s", p.dt_fixed);
  require(p.skin >= 0.0, "skin", ">= 0 m", p.skin);
  require(p.skin_factor > 0.0, "skin_factor", "> 0", p.skin_factor);
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

}  // namespace demfdm::dem
