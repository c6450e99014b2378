// Tests of scene overrides (config::Scene::parse / load with "table.key=value" texts, as
// launch/run --set passes them): each kind of bad override gives one error line that names
// the override; stage keys by name and by index; the effective scene of an overridden scene
// parses to the same values (it is the text the nodes get); the real scene schema on a
// shipped scene.
#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

#include "common/schema/scene_schema.hpp"
#include "config/config.hpp"

namespace cfg = demfdm::config;
using cfg::Presence;

namespace {

cfg::Schema make_schema() {
  cfg::Schema s;
  auto& r = s.root();
  auto& run = r.section("run", "Run identity", Presence::Optional);
  run.string("name", std::string("run"), "Name");
  run.integer("seed", "", 1, "Seed").min(0);
  auto& dem = r.section("dem", "DEM node", Presence::Required);
  dem.real("dt", "s", std::nullopt, "Time step").min(0, true);
  dem.real("damping", "", 0.7, "Local damping").min(0).max(1, true);
  dem.reals("gravity", "m/s^2", std::vector<double>{0, 0, -9.81}, "Gravity").length(3);
  auto& spec = dem.section("specimen", "Specimen", Presence::Optional);
  spec.integers("replicate", "", std::vector<std::int64_t>{1, 1, 1}, "Copies per axis").length(3).min(1);
  spec.choice("shape", {"box", "cylinder"}, "box", "Shape");
  auto& bonds = dem.section("bonds", "Bonds", Presence::Optional);
  bonds.real("ten", "Pa", std::nullopt, "Tensile strength").min(0, true);
  bonds.real("coh", "Pa", 0.0, "Cohesion").min(0);
  auto& out = r.section("output", "Output", Presence::Optional);
  out.boolean("traffic_log", true, "Record traffic");
  auto& mat = r.array("material", "Groups (no name key)", Presence::Optional);
  mat.real("young", "Pa", 1e9, "Young's modulus").min(0, true);
  auto& st = r.array("stage", "Stages", Presence::Required);
  st.string("name", std::nullopt, "Stage name");
  st.integer("steps", "", std::nullopt, "Step budget").min(1);
  st.real("inertial_number", "", 1e-2, "Inertial number").min(0, true);
  // A cross-field check: the stages' budgets are ordered (to check where a check points).
  s.check([](const cfg::Scene& sc, cfg::CheckContext& ctx) {
    if (sc.count("stage") >= 2 && sc.integer("stage[1].steps") < sc.integer("stage[0].steps"))
      ctx.fail("stage[1].steps", "a budget >= stage[0].steps", std::to_string(sc.integer("stage[1].steps")));
  });
  return s;
}

const char* const kScene =
    "[run]\n"
    "name = \"base\"\n"
    "[dem]\n"
    "dt = 1e-6\n"
    "[dem.specimen]\n"
    "replicate = [1, 1, 2]\n"
    "[[material]]\n"
    "[[stage]]\n"
    "name = \"gravity\"\n"
    "steps = 10\n"
    "[[stage]]\n"
    "name = \"penetrate\"\n"
    "steps = 20\n";

cfg::Scene with(const std::vector<std::string>& sets) {
  static const cfg::Schema schema = make_schema();
  return cfg::Scene::parse(kScene, "scene.toml", schema, ".", sets);
}

// The one-line message of the Error, or "no error".
std::string error_of(const std::vector<std::string>& sets) {
  try {
    with(sets);
  } catch (const cfg::Error& e) {
    return e.what();
  }
  return "no error";
}

}  // namespace

TEST(ConfigOverride, ValuesOfEveryForm) {
  const cfg::Scene s = with({"dem.damping=0.1", "dem.specimen.replicate=[2,2,4]", "run.name=\"x\"",
                             "dem.gravity = [0, 0, -981]"});
  EXPECT_EQ(s.real("dem.damping"), 0.1);
  EXPECT_EQ(s.integers("dem.specimen.replicate"), (std::vector<std::int64_t>{2, 2, 4}));
  EXPECT_EQ(s.string("run.name"), "x");
  EXPECT_EQ(s.reals("dem.gravity"), (std::vector<double>{0, 0, -981}));
  EXPECT_TRUE(s.explicitly_set("dem.damping"));
  EXPECT_EQ(s.where("dem.damping"), "--set dem.damping=0.1");
  EXPECT_EQ(s.where("dem.dt"), "scene.toml:4:6");  // the file's keys keep their positions
  EXPECT_EQ(s.overrides().size(), 4u);
  // A value the shell stripped of its quotes is a string; a later override wins.
  const cfg::Scene t = with({"run.name=y", "dem.specimen.shape=cylinder", "dem.damping=0.2", "dem.damping=0.3"});
  EXPECT_EQ(t.string("run.name"), "y");
  EXPECT_EQ(t.string("dem.specimen.shape"), "cylinder");
  EXPECT_EQ(t.real("dem.damping"), 0.3);
  // Without overrides the text is the file's, with them the effective scene.
  EXPECT_EQ(with({}).text(), kScene);
  EXPECT_EQ(s.text(), s.effective_toml());
  EXPECT_NE(s.hash(), with({}).hash());
}

TEST(ConfigOverride, StageKeyByNameAndByIndex) {
  const cfg::Scene a = with({"stage.penetrate.inertial_number=1e-3", "stage.gravity.steps=5"});
  EXPECT_EQ(a.real("stage[1].inertial_number"), 1e-3);
  EXPECT_EQ(a.real("stage[0].inertial_number"), 1e-2);
  EXPECT_EQ(a.integer("stage[0].steps"), 5);
  EXPECT_EQ(a.where("stage[1].inertial_number"), "--set stage.penetrate.inertial_number=1e-3");
  const cfg::Scene b = with({"stage[1].inertial_number=1e-3", "stage[0].steps=5"});
  EXPECT_EQ(b.real("stage[1].inertial_number"), 1e-3);
  EXPECT_EQ(b.integer("stage[0].steps"), 5);
  EXPECT_EQ(a.effective_toml().substr(a.effective_toml().find("\n[")),
            b.effective_toml().substr(b.effective_toml().find("\n[")));  // the same scene
  // An array of tables without a name key is indexed.
  EXPECT_EQ(with({"material[0].young=2e9"}).real("material[0].young"), 2e9);
}

TEST(ConfigOverride, CreatesAnAbsentOptionalSection) {
  EXPECT_FALSE(with({}).has("output"));
  const cfg::Scene s = with({"output.traffic_log=false"});
  EXPECT_TRUE(s.has("output"));
  EXPECT_FALSE(s.boolean("output.traffic_log"));
  // Its required keys are then enforced, naming the override that created it.
  EXPECT_EQ(error_of({"dem.bonds.coh=1"}),
            "--set dem.bonds.coh=1: dem.bonds.ten: missing required key; expected a number > 0 Pa");
  EXPECT_EQ(with({"dem.bonds.coh=1", "dem.bonds.ten=2e6"}).real("dem.bonds.ten"), 2e6);
}

TEST(ConfigOverride, BadValuesNameTheOverride) {
  EXPECT_EQ(error_of({"dem.damping=abc"}), "--set dem.damping=abc: expected a number in [0, 1), found string 'abc'");
  EXPECT_EQ(error_of({"dem.damping=1.5"}), "--set dem.damping=1.5: expected a number in [0, 1), found 1.5");
  EXPECT_EQ(error_of({"stage.penetrate.steps=0"}), "--set stage.penetrate.steps=0: expected an integer >= 1, found 0");
  EXPECT_EQ(error_of({"stage.gravity.steps=2.5"}),
            "--set stage.gravity.steps=2.5: expected an integer >= 1, found float 2.5");
  EXPECT_EQ(error_of({"dem.specimen.replicate=[2,0,1]"}),
            "--set dem.specimen.replicate=[2,0,1]: dem.specimen.replicate[1]: expected an integer >= 1, found 0");
  EXPECT_EQ(error_of({"dem.specimen.replicate=[2,2]"}),
            "--set dem.specimen.replicate=[2,2]: dem.specimen.replicate[2]: missing element; expected a list of 3 "
            "integers each >= 1, found 2 elements");
  EXPECT_EQ(error_of({"dem.specimen.shape=sphere"}),
            "--set dem.specimen.shape=sphere: expected one of 'box', 'cylinder', found 'sphere'");
  EXPECT_EQ(error_of({"run.name=1"}), "--set run.name=1: expected a string, found integer 1");
  EXPECT_EQ(error_of({"dem.gravity=[0, 0"}).rfind("--set dem.gravity=[0, 0: the value is not TOML: ", 0), 0u)
      << error_of({"dem.gravity=[0, 0"});
  EXPECT_EQ(error_of({"run.name="}), "--set run.name=: expected a TOML value after '=' (an empty string is \"\")");
  EXPECT_EQ(error_of({"run.seed=1\nrun.name=\"x\""}).rfind("--set run.seed=1", 0), 0u);
  // A cross-field check that fails on an overridden key names the override too.
  EXPECT_EQ(error_of({"stage.penetrate.steps=5"}),
            "--set stage.penetrate.steps=5: expected a budget >= stage[0].steps, found 5");
  // A cross-field check that blames a key of the file names the overrides too.
  EXPECT_EQ(error_of({"stage.gravity.steps=50", "dem.damping=0.2"}),
            "scene.toml:13:9: stage[1].steps: expected a budget >= stage[0].steps, found 20 (with --set "
            "stage.gravity.steps=50, --set dem.damping=0.2)");
  // The overrides' problems in the order given (a later override of the same key wins).
  EXPECT_EQ(error_of({"stage.penetrate.steps=0", "dem.damping=2"}),
            "--set stage.penetrate.steps=0: expected an integer >= 1, found 0");
  EXPECT_EQ(error_of({"dem.damping=2", "dem.damping=0.5"}), "no error");
  // The error's fields.
  try {
    with({"dem.damping=abc"});
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(e.file, "--set dem.damping=abc");
    EXPECT_EQ(e.key, "dem.damping");
    EXPECT_EQ(e.line, 0);
  }
}

TEST(ConfigOverride, BadKeysNameTheOverride) {
  EXPECT_EQ(error_of({"dem.damping"}),
            "--set dem.damping: expected table.key=value (stage keys: stage.NAME.key=value or stage[i].key=value), "
            "found no '='");
  EXPECT_EQ(error_of({"=1"}), "--set =1: expected table.key=value, found no key before '='");
  EXPECT_EQ(error_of({"dem.dampng=0.1"}), "--set dem.dampng=0.1: unknown key 'dem.dampng'; did you mean 'dem.damping'?");
  EXPECT_EQ(error_of({"dme.damping=0.1"}), "--set dme.damping=0.1: unknown section 'dme'; did you mean 'dem'?");
  EXPECT_EQ(error_of({"dem.qqqqqq=1"}), "--set dem.qqqqqq=1: unknown key 'dem.qqqqqq'");
  EXPECT_EQ(error_of({"dem=1"}), "--set dem=1: 'dem' is a section; set one of its keys: dem.key=value");
  EXPECT_EQ(error_of({"dem.damping.x=1"}), "--set dem.damping.x=1: 'dem.damping' is a key, not a table");
  EXPECT_EQ(error_of({"stage=1"}),
            "--set stage=1: 'stage' is an array of tables; set a key of one element: stage.NAME.key=value or "
            "stage[i].key=value");
  EXPECT_EQ(error_of({"stage.unload.steps=1"}),
            "--set stage.unload.steps=1: no [[stage]] named 'unload' (the scene's: gravity, penetrate)");
  EXPECT_EQ(error_of({"stage[4].steps=1"}), "--set stage[4].steps=1: no element stage[4]: the scene has 2 [[stage]] tables");
  EXPECT_EQ(error_of({"stage.penetrate=1"}),
            "--set stage.penetrate=1: expected a key after the element name: stage.penetrate.key=value");
  EXPECT_EQ(error_of({"stage[x].steps=1"}), "--set stage[x].steps=1: bad index in 'stage[x]'; expected name[i] with i = 0, 1, ...");
  EXPECT_EQ(error_of({"dem[0].dt=1"}), "--set dem[0].dt=1: 'dem' is not an array of tables; only [[...]] elements are indexed");
  EXPECT_EQ(error_of({"material.a.young=1"}),
            "--set material.a.young=1: [[material]] elements have no name; index them: material[i].key=value");
  EXPECT_EQ(error_of({"stage.penetrate.inertial=1"}),
            "--set stage.penetrate.inertial=1: unknown key 'stage[1].inertial'; did you mean 'stage[1].inertial_number'?");
}

TEST(ConfigOverride, EffectiveSceneParsesToTheSameValues) {
  static const cfg::Schema schema = make_schema();
  const cfg::Scene a = with({"dem.damping=0.1", "stage.penetrate.inertial_number=1e-3", "run.name=\"x y\"",
                             "output.traffic_log=false"});
  const std::string eff = a.effective_toml();
  EXPECT_NE(eff.find("#   --set dem.damping=0.1\n"), std::string::npos) << eff;
  EXPECT_NE(eff.find("#   --set stage.penetrate.inertial_number=1e-3\n"), std::string::npos) << eff;
  EXPECT_EQ(eff.rfind("# Effective scene: scene.toml (", 0), 0u) << eff;
  const cfg::Scene b = cfg::Scene::parse(eff, "effective.toml", schema, "/nonexistent");
  EXPECT_EQ(b.real("dem.damping"), 0.1);
  EXPECT_EQ(b.real("stage[1].inertial_number"), 1e-3);
  EXPECT_EQ(b.real("stage[0].inertial_number"), 1e-2);
  EXPECT_EQ(b.string("run.name"), "x y");
  EXPECT_FALSE(b.boolean("output.traffic_log"));
  EXPECT_EQ(b.integers("dem.specimen.replicate"), a.integers("dem.specimen.replicate"));
  EXPECT_FALSE(b.has("dem.bonds"));
  // The same values: the effective text of the re-parsed scene equals it below the header.
  const std::string eff2 = b.effective_toml();
  EXPECT_EQ(eff2.substr(eff2.find("\n[")), eff.substr(eff.find("\n[")));
}

TEST(ConfigOverride, RealSchemaOnShippedScenes) {
  const std::string root = DEMFDM_SOURCE_DIR;
  const auto& schema = demfdm::schema::scene_schema();
  const cfg::Scene s = cfg::Scene::load(root + "/scenes/footing_small.toml", schema,
                                        {"stage.penetrate.inertial_number=1e-3", "dem.damping=0.1", "stage[4].steps=7"});
  std::size_t pen = 0;
  for (std::size_t i = 0; i < s.count("stage"); ++i)
    if (s.string("stage[" + std::to_string(i) + "].name") == "penetrate") pen = i;
  EXPECT_EQ(s.real("stage[" + std::to_string(pen) + "].inertial_number"), 1e-3);
  EXPECT_EQ(s.real("dem.damping"), 0.1);
  EXPECT_EQ(s.integer("stage[4].steps"), 7);
  // The effective text is what the nodes get: it parses (paths absolute) to the same values.
  const cfg::Scene n = cfg::Scene::parse(s.text(), "bus", schema, "/nonexistent");
  EXPECT_EQ(n.real("dem.damping"), 0.1);
  EXPECT_EQ(n.integer("stage[4].steps"), 7);
  EXPECT_EQ(n.effective_toml().substr(n.effective_toml().find("\n[")),
            s.effective_toml().substr(s.effective_toml().find("\n[")));
  try {
    cfg::Scene::load(root + "/scenes/chain_serial.toml", schema, {"chain.split=30"});
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(std::string(e.what()).rfind("--set chain.split=30: expected an integer in [1, n_masses-1]", 0), 0u)
        << e.what();
  }
}
