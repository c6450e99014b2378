#include "demfdm/dem/scene_params.hpp"

#include <stdexcept>

#include "common/schema/scene_read.hpp"
#include "common/schema/scene_schema.hpp"
#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/procedures.hpp"

namespace demfdm::dem::scene {

namespace {
using schema::read_table;
using schema::SceneRead;

// Validates what the scene gave a struct (validate() of the table's core header); a bad value is
// reported under `key` (its message names the scene key).
template <class P>
void checked(const config::Scene& s, const std::string& key, const P& p) {
  try {
    validate(p);
  } catch (const std::invalid_argument& e) {
    s.fail(key, "valid DEM parameters", e.what());
  }
}
}  // namespace

Block block(const config::Scene& s) {
  const schema::DemBlock d = schema::dem_block(s);  // one definition for the checks and the node
  Block b;
  b.origin = {d.origin[0], d.origin[1], d.origin[2]};
  b.cell = {d.cell[0], d.cell[1], d.cell[2]};
  b.nx = d.n[0];
  b.ny = d.n[1];
  b.nz = d.n[2];
  return b;
}

ContactFamilyParams family(const config::Scene& s, const FamilyInfo& info) {
  const std::string base = std::string("dem.") + info.name;
  ContactFamilyParams f = info.defaults();
  // The laws are looked up by name in the registry; the schema's choice lists the same names.
  if (!law_from_name(s.string(base + ".model"), f.model))
    s.fail(base + ".model", "the name of a registered contact law", "'" + s.string(base + ".model") + "'");
  SceneRead family_keys{s, base + "."};
  describe_family(family_keys, f);
  for_each_law([&](auto law) {
    SceneRead law_keys{s, base + "." + decltype(law)::kName + "."};
    decltype(law)::params(law_keys, f);
  });
  return f;
}

WorldParams world(const config::Scene& s, const Block& b) {
  WorldParams p;
  read_table(s, "dem.", p);
  p.dt_fixed = 0.0;  // dem.dt_fixed is checked, then applied, at the first stage that begins with balls
  p.threads = schema::run_threads(s);
  p.thread_independent = s.boolean("run.thread_independent");
  p.order_free_sums = s.boolean("run.order_free_sums");
  p.gravity = false;
  for (const auto& f : kFamilies) p.*f.member = family(s, f);
  // A scene that generates its specimen starts with the REV's periodic cell.
  for (const auto& st : schema::stages(s))
    if (st.kind == schema::Action::kGenerate) {
      p.periodic.enabled = true;
      p.periodic.origin = b.origin;
      p.periodic.length = b.cell;
    }
  try {
    validate(p);
  } catch (const std::invalid_argument& e) {
    s.fail("dem", "valid DEM parameters", e.what());
  }
  return p;
}

RevParams rev(const config::Scene& s) {
  RevParams p = scene_rev_defaults();
  read_table(s, "dem.specimen.", p);
  p.seed = static_cast<std::uint64_t>(s.integer("run.seed"));
  checked(s, "dem.specimen", p);
  return p;
}

double sigma_v(const config::Scene& s, const Block& b) {
  if (const auto sv = s.real_or_word("dem.specimen.sigma_v")) return *sv;
  const double rho_b = s.real_or_word("dem.specimen.bulk_density").value_or(0.48 * s.real("dem.density"));
  const double g = s.has("gravity") ? s.real("gravity.level") * s.real("gravity.g0") : 9.81;
  return rho_b * g * b.height();
}

ServoSettings servo(const config::Scene& s, const Block& b) {
  ServoSettings r;
  read_table(s, "dem.specimen.", r);
  checked(s, "dem.specimen", r);
  const double sv = sigma_v(s, b), sh = s.real("dem.specimen.k0") * sv;
  r.p.target = {sh, sh, sv};
  return r;
}

double bond_gap(const config::Scene& s) {
  return s.real_or_word("dem.specimen.bond_gap").value_or(1e-3 * s.real("dem.specimen.d_min") * s.real("dem.specimen.scale"));
}

FootingParams footing(const config::Scene& s, const Block& b) {
  FootingParams f;
  read_table(s, "dem.footing.", f);
  checked(s, "dem.footing", f);
  const auto c = s.reals("dem.footing.centre");
  f.bottom_centre = c.size() == 2 ? Vec3{c[0], c[1], 0} : b.centre();
  return f;
}

InterfaceBondParams interface_bonds(const config::Scene& s, const Block& b, double unit_weight) {
  InterfaceBondParams ib;
  read_table(s, "dem.specimen.", ib);
  ib.band = s.real("dem.specimen.d50") * s.real("dem.specimen.scale");
  ib.z_top = b.z_top();
  ib.unit_weight = unit_weight;
  ib.k0 = s.real("dem.specimen.k0");
  return ib;
}

bool depth_scaling(const config::Scene& s, const Block& b, DepthScaleParams& p) {
  const auto mode = s.string("dem.specimen.depth_scaling");
  if (mode == "none") return false;
  p.mode = mode == "paper_literal" ? DepthScaling::kPaperLiteral : DepthScaling::kDepthRatio;
  p.z_top = b.z_top();
  p.height = b.height();
  return true;
}

UcsParams ucs(const config::Scene& stage) {
  UcsParams p;
  read_table(stage, "", p);
  checked(stage, "strain_rate", p);
  return p;
}

}  // namespace demfdm::dem::scene
