// The continuum's tables (fdm_node/core mesh.hpp and params.hpp; issue 15 item 5: every
// parameter declared once): each [continuum.mesh], [[continuum.material]] and [continuum] key
// reads from a scene into its own field only (fdm_node/scene_params, as fdm_node and fem_node
// read them), and the schema and fdm::validate() refuse the same out-of-range value under the
// same key (tests/dem/table_walk.hpp walks the tables).
#include <gtest/gtest.h>

#include <string>

#include "../dem/table_walk.hpp"
#include "common/schema/scene_schema.hpp"
#include "demfdm/fdm/params.hpp"
#include "fdm_node/scene_params.hpp"

using namespace demfdm;

namespace {

// A continuum-only scene with one material element; `key = value` is added to `table`.
config::Scene scene(const std::string& table, const std::string& key, const std::string& value) {
  std::string cont = "[continuum]\n", mesh = "[continuum.mesh]\n", mat = "[[continuum.material]]\n";
  const std::string line = key.empty() ? "" : key + " = " + value + "\n";
  if (table == "continuum") cont += line;
  if (table == "continuum.mesh") mesh += line;
  if (table == "continuum.material") mat += line;
  return config::Scene::parse(cont + mesh + mat + "[[stage]]\nname = \"c\"\naction = \"cycle\"\nsteps = 1\n", "t.toml",
                              schema::scene_schema());
}
auto in(const std::string& table) {
  return [table](const std::string& k, const std::string& v) { return scene(table, k, v); };
}
auto named(const std::string& prefix) {
  return [prefix](const std::string& k) { return prefix + k; };
}

}  // namespace

TEST(ContinuumSceneTables, EveryMeshMaterialAndModelKeyReadsIntoItsOwnFieldOnly) {
  using table_walk::every_key_reads_into_its_own_field;
  int keys = 0;
  keys += every_key_reads_into_its_own_field<fdm::MeshParams>(
      fdm::MeshParams{}, in("continuum.mesh"), [](const config::Scene& s) { return continuum::mesh_from_scene(s); });
  keys += every_key_reads_into_its_own_field<fdm::Material>(
      fdm::Material{}, in("continuum.material"),
      [](const config::Scene& s) { return continuum::material_from_scene(s.at("continuum.material", 0)).material; });
  keys += every_key_reads_into_its_own_field<fdm::ModelParams>(fdm::ModelParams{}, in("continuum"),
                                                              [](const config::Scene& s) {
                                                                fdm::ModelParams p;
                                                                continuum::model_keys_from_scene(s, p);
                                                                return p;
                                                              });
  EXPECT_EQ(keys, 4 + 8 + 6);
}

TEST(ContinuumSceneTables, SchemaAndEngineRefuseTheSameOutOfRangeValue) {
  using table_walk::schema_and_engine_refuse_the_same_values;
  int probes = 0;
  probes += schema_and_engine_refuse_the_same_values<fdm::MeshParams>(
      fdm::MeshParams{}, in("continuum.mesh"), [](const fdm::MeshParams& p) { fdm::validate(p); },
      named("continuum.mesh."), named("continuum.mesh."));
  probes += schema_and_engine_refuse_the_same_values<fdm::Material>(
      fdm::Material{}, in("continuum.material"), [](const fdm::Material& p) { fdm::validate(p); },
      named("continuum.material[0]."), named("continuum.material."));
  probes += schema_and_engine_refuse_the_same_values<fdm::ModelParams>(
      fdm::ModelParams{}, in("continuum"), [](const fdm::ModelParams& p) { fdm::validate(p); }, named("continuum."),
      named("continuum."));
  EXPECT_GT(probes, 20);
}

// fem_node reads the elastic constants as fdm_node does (one declaration, two solvers).
TEST(ContinuumSceneTables, TheElasticConstantsOfBothSolversComeFromTheMaterialTable) {
  const auto s = scene("continuum.material", "young", "3e9");
  const auto el = continuum::elastic_from_scene(s.at("continuum.material", 0));
  EXPECT_EQ(el.young, 3e9);
  EXPECT_EQ(el.density, fdm::Material{}.density);
  EXPECT_EQ(el.poisson, fdm::Material{}.poisson);
}
