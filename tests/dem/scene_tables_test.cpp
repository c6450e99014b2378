// The DEM's specimen, servo, footing, interface-bond and ucs-stage tables (specimen.hpp,
// world.hpp; issue 15 item 5: every parameter declared once): each key reads from a scene
// into its own field only, and the schema and the engine's validate() refuse the same
// out-of-range value under the same scene key (tests/dem/table_walk.hpp walks the tables).
#include <gtest/gtest.h>

#include <string>

#include "common/schema/scene_schema.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/scene_params.hpp"
#include "demfdm/dem/specimen.hpp"
#include "table_walk.hpp"

using namespace demfdm;

namespace {

// A DEM-only scene with a specimen, a footing and a ucs stage; `key = value` is added to
// `table` (or to the ucs stage when table is empty).
config::Scene scene(const std::string& table, const std::string& key, const std::string& value) {
  std::string specimen = "[dem.specimen]\n", footing = "[dem.footing]\n", stage;
  const std::string line = key.empty() ? "" : key + " = " + value + "\n";
  if (table == "dem.specimen") specimen += line;
  if (table == "dem.footing") footing += line;
  if (table.empty()) stage = line;
  const std::string text = "[dem]\n" + specimen + footing +
                           "[[stage]]\nname = \"c\"\naction = \"cycle\"\nsteps = 1\n"
                           "[[stage]]\nname = \"u\"\naction = \"ucs\"\nsteps = 1\n" + stage;
  return config::Scene::parse(text, "t.toml", schema::scene_schema());
}
auto in(const std::string& table) {
  return [table](const std::string& k, const std::string& v) { return scene(table, k, v); };
}
auto named(const std::string& prefix) {
  return [prefix](const std::string& k) { return prefix + k; };
}

}  // namespace

TEST(SceneTables, EverySpecimenFootingAndUcsKeyReadsIntoItsOwnFieldOnly) {
  using table_walk::every_key_reads_into_its_own_field;
  int keys = 0;
  keys += every_key_reads_into_its_own_field<dem::RevParams>(dem::scene_rev_defaults(), in("dem.specimen"),
                                                            [](const config::Scene& s) { return dem::scene::rev(s); });
  keys += every_key_reads_into_its_own_field<dem::ServoSettings>(
      dem::ServoSettings{}, in("dem.specimen"),
      [](const config::Scene& s) { return dem::scene::servo(s, dem::scene::block(s)); });
  keys += every_key_reads_into_its_own_field<dem::InterfaceBondParams>(
      dem::InterfaceBondParams{}, in("dem.specimen"),
      [](const config::Scene& s) { return dem::scene::interface_bonds(s, dem::scene::block(s), 1.0); });
  keys += every_key_reads_into_its_own_field<dem::FootingParams>(
      dem::FootingParams{}, in("dem.footing"),
      [](const config::Scene& s) { return dem::scene::footing(s, dem::scene::block(s)); });
  keys += every_key_reads_into_its_own_field<dem::UcsParams>(
      dem::UcsParams{}, in(""), [](const config::Scene& s) { return dem::scene::ucs(s.at("stage", 1)); });
  EXPECT_EQ(keys, 10 + 5 + 1 + 2 + 2);
}

TEST(SceneTables, SchemaAndEngineRefuseTheSameOutOfRangeSpecimenFootingAndUcsValue) {
  using table_walk::schema_and_engine_refuse_the_same_values;
  int probes = 0;
  probes += schema_and_engine_refuse_the_same_values<dem::RevParams>(
      dem::scene_rev_defaults(), in("dem.specimen"), [](const dem::RevParams& p) { dem::validate(p); },
      named("dem.specimen."), named("dem.specimen."));
  probes += schema_and_engine_refuse_the_same_values<dem::ServoSettings>(
      dem::ServoSettings{}, in("dem.specimen"), [](const dem::ServoSettings& p) { dem::validate(p); },
      named("dem.specimen."), named("dem.specimen."));
  probes += schema_and_engine_refuse_the_same_values<dem::FootingParams>(
      dem::FootingParams{}, in("dem.footing"), [](const dem::FootingParams& p) { dem::validate(p); },
      named("dem.footing."), named("dem.footing."));
  probes += schema_and_engine_refuse_the_same_values<dem::UcsParams>(
      dem::UcsParams{}, in(""), [](const dem::UcsParams& p) { dem::validate(p); }, named("stage[1]."), named(""));
  EXPECT_GT(probes, 20);
}

// The scene's values reach the structs the node hands to the engine (one line per reader).
TEST(SceneTables, TheReadersApplyTheTables) {
  const auto s = scene("dem.specimen", "porosity_target", "0.4");
  EXPECT_EQ(dem::scene::rev(s).porosity_target, 0.4);
  EXPECT_EQ(dem::scene::rev(scene("dem.specimen", "", "")).porosity_target, -1.0);  // "auto": porosity_final
  EXPECT_EQ(dem::scene::rev(scene("dem.specimen", "", "")).psd.scale, 1.5);
  const auto sv = dem::scene::servo(scene("dem.specimen", "servo_gain", "0.25"), dem::scene::block(s));
  EXPECT_EQ(sv.p.gain, 0.25);
  EXPECT_EQ(sv.p.target.x, 0.5 * sv.p.target.z);  // k0 (the schema's default) times sigma_v
}
