// The contact families' parameter tables (dem_node/core params.hpp, issue: every parameter
// declared once): one declaration per key gives the schema entry (default, range), the read of a
// scene into the struct field and the engine's range check. These tests walk the tables
// themselves, so a key added to a table is covered without a new test line.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "common/schema/scene_schema.hpp"
#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/scene_params.hpp"
#include "table_walk.hpp"

using namespace demfdm;

namespace {

// A DEM-only scene whose stages bond nothing, so every law may be chosen for every family.
const char* kScene = R"([dem]
[[stage]]
name = "c"
action = "cycle"
steps = 1
)";

config::Scene parse(const std::vector<std::string>& sets) {
  return config::Scene::parse(kScene, "t.toml", schema::scene_schema(), ".", sets);
}

using table_walk::Collect;
using table_walk::Count;
using table_walk::exact;
using table_walk::Mutate;

// Every bound field's value of a family and its laws' tables, in table order (the model first).
std::vector<std::string> all_fields(dem::ContactFamilyParams f) {
  Collect c;
  c.v.push_back(std::to_string(static_cast<int>(f.model)));
  dem::describe_family(c, f);
  dem::for_each_law([&](auto law) { decltype(law)::params(c, f); });
  return c.v;
}

// The real keys of a table with their ranges, named "<key>" or "<law>.<key>".
struct Bounds {
  std::vector<std::pair<std::string, dem::ParamRange>> keys;
  std::string table;
  void real(const char* k, const char*, double&, const dem::ParamRange& r, const char*) {
    keys.emplace_back(table + k, r);
  }
  void real_or_word(const char* k, const char* u, double& f, const dem::ParamRange& r, const char*, double,
                    const char* d) {
    real(k, u, f, r, d);
  }
  void flag(const char*, bool&, const char*) {}
  template <class E>
  void choice(const char*, E&, std::initializer_list<dem::ParamOption<E>>, const char*) {}
};

// Sets the real key named "<key>" or "<law>.<key>" to a value.
struct Assign {
  std::string key;
  double value;
  std::string table;
  void real(const char* k, const char*, double& fld, const dem::ParamRange&, const char*) {
    if (table + k == key) fld = value;
  }
  void real_or_word(const char* k, const char* u, double& fld, const dem::ParamRange& r, const char*, double,
                    const char* d) {
    real(k, u, fld, r, d);
  }
  void flag(const char*, bool&, const char*) {}
  template <class E>
  void choice(const char*, E&, std::initializer_list<dem::ParamOption<E>>, const char*) {}
};

}  // namespace

// Defaults: the scene's families read from a scene that writes none of their keys are the
// FamilyInfo defaults, field for field (the schema's defaults are the structs' initial values).
TEST(SceneParams, AnAbsentFamilyReadsAsItsDefaults) {
  const auto s = parse({});
  for (const auto& info : dem::kFamilies) {
    SCOPED_TRACE(info.name);
    EXPECT_EQ(all_fields(dem::scene::family(s, info)), all_fields(info.defaults()));
  }
}

// The read: every key of every table, set to another value, lands in its own field and in no
// other, for every family (the family's model set to the law whose table it is).
TEST(SceneParams, EveryKeyReadsIntoItsOwnFieldOnly) {
  int keys = 0;
  for (const auto& info : dem::kFamilies) {
    const std::string fam = std::string("dem.") + info.name;
    // The family-wide keys.
    {
      Count c;
      auto d = info.defaults();
      dem::describe_family(c, d);
      for (int i = 0; i < c.n; ++i) {
        auto expected = info.defaults();
        Mutate m;
        m.target = i;
        dem::describe_family(m, expected);
        const std::string set = fam + "." + m.key + "=" + m.text;
        SCOPED_TRACE(set);
        EXPECT_EQ(all_fields(dem::scene::family(parse({set}), info)), all_fields(expected));
        ++keys;
      }
    }
    dem::for_each_law([&](auto law) {
      using Law = decltype(law);
      Count c;
      auto d = info.defaults();
      Law::params(c, d);
      for (int i = 0; i < c.n; ++i) {
        auto expected = info.defaults();
        expected.model = Law::kModel;
        Mutate m;
        m.target = i;
        Law::params(m, expected);
        const std::string set = fam + "." + Law::kName + "." + m.key + "=" + m.text;
        SCOPED_TRACE(set);
        EXPECT_EQ(all_fields(dem::scene::family(parse({fam + ".model=" + Law::kName, set}), info)), all_fields(expected));
        ++keys;
      }
    });
  }
  // 4 families x (4 family keys + 8 pbond + 14 softbond + 2 hertz).
  EXPECT_EQ(keys, 4 * (4 + 8 + 14 + 2));
}

// The range: a value just outside a declared bound is refused by the scene (naming the key) and
// by the engine's validate() (naming the same scene key); the bound itself, where closed, passes
// both.
TEST(SceneParams, SchemaAndEngineRefuseTheSameOutOfRangeValueNamingTheSameKey) {
  const auto& info = dem::kFamilies[0];
  int checked = 0;
  auto d = info.defaults();
  Bounds b{{}, ""};
  dem::describe_family(b, d);
  dem::for_each_law([&](auto law) {
    b.table = std::string(decltype(law)::kName) + ".";
    decltype(law)::params(b, d);
  });
  for (const auto& [key, r] : b.keys) {
    std::vector<std::pair<double, bool>> probes;  // value, admissible
    if (r.has_lo()) probes.push_back({r.lo_open ? r.lo : r.lo - 1.0, false});
    if (r.has_hi()) probes.push_back({r.hi_open ? r.hi : r.hi + 1.0, false});
    if (r.has_lo() && !r.lo_open) probes.push_back({r.lo, true});
    for (const auto& [value, ok] : probes) {
      const std::string path = std::string("dem.ball_ball.") + key;
      SCOPED_TRACE(path + "=" + exact(value));
      // The engine, on the struct.
      auto f = info.defaults();
      Assign a{key, value, ""};
      dem::describe_family(a, f);
      dem::for_each_law([&](auto law) {
        a.table = std::string(decltype(law)::kName) + ".";
        decltype(law)::params(a, f);
      });
      std::string engine;
      try {
        dem::validate(f, "ball_ball");
      } catch (const std::invalid_argument& e) {
        engine = e.what();
      }
      // The scene (the family keeps its model: a law table's range is checked either way).
      std::string scene;
      const bool law_key = key.find('.') != std::string::npos;
      std::vector<std::string> sets;
      if (law_key) sets.push_back("dem.ball_ball.model=" + key.substr(0, key.find('.')));
      sets.push_back(path + "=" + exact(value));
      try {
        parse(sets);
      } catch (const config::Error& e) {
        scene = e.what();
      }
      if (ok) {
        // A closed lower bound passes the range of both (the soft bond's emod > 0 is a
        // cross-field rule of both as well).
        if (key == "emod") continue;
        EXPECT_EQ(engine, "");
        EXPECT_EQ(scene, "");
      } else {
        EXPECT_NE(engine.find("'" + path + "'"), std::string::npos) << engine;
        EXPECT_NE(scene.find(path), std::string::npos) << scene;
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 30);
}

// A law's table in a family of another law is refused at --check, and an earlier prefixed key
// is refused with its new place.
TEST(SceneParams, AnotherLawsTableAndAnOldPrefixedKeyAreRefusedNamingTheKey) {
  try {
    parse({"dem.ball_ball.model=softbond", "dem.ball_ball.pbond.ten=1e6"});
    ADD_FAILURE() << "a pbond key in a softbond family was accepted";
  } catch (const config::Error& e) {
    EXPECT_NE(std::string(e.what()).find("dem.ball_ball.pbond.ten"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("model = 'softbond'"), std::string::npos) << e.what();
  }
  // Its default value written out (as a run's effective scene does) is accepted.
  EXPECT_NO_THROW(parse({"dem.ball_ball.model=softbond", "dem.ball_ball.pbond.ten=450000"}));
  try {
    config::Scene::parse("[dem.ball_facet]\npb_ten = \"unbreakable\"\n[[stage]]\nname = \"c\"\nsteps = 1\n", "old.toml",
                         schema::scene_schema());
    ADD_FAILURE() << "an old prefixed key was accepted";
  } catch (const config::Error& e) {
    EXPECT_NE(std::string(e.what()).find("old.toml:2:1: dem.ball_facet.pb_ten: unknown key; it moved: write "
                                         "[dem.ball_facet.pbond] ten"),
              std::string::npos)
        << e.what();
  }
}

// The world of a scene: families in their WorldParams members, run.threads, the step rule.
TEST(SceneParams, WorldCarriesTheFamiliesAndTheStepRule) {
  const auto s = parse({"dem.ball_footing.fric=0.3", "dem.dt_safety=0.5", "run.threads=2"});
  const auto w = dem::scene::world(s, dem::scene::block(s));
  EXPECT_EQ(w.ball_footing.linear.fric, 0.3);
  EXPECT_EQ(w.ball_ball.model, dem::ContactModel::kSoftBond);
  EXPECT_EQ(w.ball_facet.model, dem::ContactModel::kLinearPBond);
  EXPECT_TRUE(w.ball_facet.pbond.zero_linear);
  EXPECT_EQ(w.dt_safety, 0.5);
  EXPECT_EQ(w.threads, 2);
  EXPECT_FALSE(w.periodic.enabled);  // no generate stage
}
