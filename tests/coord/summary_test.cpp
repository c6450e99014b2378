// The run summary (summary.txt, summary.json) with the effects the nodes report, driven by a
// fake transport whose STAGE_END reports carry effect_s.<name> values (no LCM, no nodes).
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>

#include <unistd.h>

#include "coordinator/core/summary.hpp"

using namespace demfdm;

namespace {
// Every command: compute 1 s, wait 0.5 s per node. STAGE_END adds the effects of 'effects'
// (stage name -> role -> values) to the report.
class EffectDriver : public coord::Driver {
 public:
  std::map<std::string, std::map<std::string, std::map<std::string, double>>> effects;
  std::string stage;
  void post(coord::Cmd, const std::vector<std::string>&, std::int64_t, std::int32_t, const std::string& name, double,
            const std::vector<double>&) override {
    stage = name;
  }
  std::map<std::string, coord::NodeReport> collect(coord::Cmd cmd, const std::vector<std::string>& targets,
                                                   std::int64_t, std::int32_t) override {
    std::map<std::string, coord::NodeReport> out;
    for (auto& t : targets) {
      coord::NodeReport r;
      r.compute_s = 1.0;
      r.wait_s = 0.5;
      r.values["ratio"] = 1e-3;  // an ordinary value: not an effect
      if (cmd == coord::Cmd::StageEnd)
        for (auto& [k, v] : effects[stage][t]) r.values[std::string(coord::kEffectPrefix) + k] = v;
      out[t] = r;
    }
    return out;
  }
};

coord::RunSummary run_two_stages(EffectDriver& d) {
  auto sc = config::Scene::parse(
      "[dem]\n[continuum]\n[coupling]\n"
      "[[stage]]\nname = \"settle\"\nnodes = [\"dem\"]\nsteps = 2\n"
      "[[stage]]\nname = \"load\"\nsteps = 3\ncoupled = true\n",
      "test.toml", schema::scene_schema());
  coord::Runner r(schema::stages(sc), d, {}, 1);
  return r.run();
}

coord::RunInfo info() {
  coord::RunInfo i;
  i.scene = "scenes/x \"quoted\".toml";
  i.hash = 0xabc;
  i.nodes = {{"continuum", "fdm", "host", "b1", 12}, {"dem", "dem", "host", "b1", 11}};
  return i;
}

// Python's json module as the independent parser: exit 0 when 'text' is valid JSON and
// the expression 'check' (over the parsed object j) holds.
bool python_json_check(const std::string& text, const std::string& check) {
  auto path = std::filesystem::temp_directory_path() / ("demfdm-summary-" + std::to_string(getpid()) + ".json");
  std::ofstream(path) << text;
  std::string cmd = "/usr/bin/python3 -c \"import json,sys; j = json.load(open(sys.argv[1])); sys.exit(0 if (" + check +
                    ") else 1)\" " + path.string();
  int rc = std::system(cmd.c_str());
  std::filesystem::remove(path);
  return rc == 0;
}
}  // namespace

TEST(Summary, EffectsComeFromStageEndValuesOnly) {
  coord::NodeReport r;
  r.values = {{"effect_s.gravity", 0.25}, {"effect_s.", 9.0}, {"effect_sx", 1.0}, {"ratio", 2.0}};
  auto e = coord::effects_of(r);
  ASSERT_EQ(e.size(), 1u);
  EXPECT_DOUBLE_EQ(e.at("gravity"), 0.25);
}

TEST(Summary, TextListsEffectsPerStageAndNodeWithShares) {
  EffectDriver d;
  d.effects["settle"]["dem"] = {{"gravity", 0.5}, {"bonds", 1.0}};
  d.effects["load"]["dem"] = {{"gravity", 1.0}, {"coupling", 2.0}};
  d.effects["load"]["continuum"] = {{"gravity", 0.25}};
  auto sum = run_two_stages(d);
  // settle: begin + 2 grants + end = 4 s compute for dem; load: begin + 3 grants + end = 5 s.
  ASSERT_DOUBLE_EQ(sum.stages[0].compute_s.at("dem"), 4.0);
  ASSERT_DOUBLE_EQ(sum.stages[1].compute_s.at("dem"), 5.0);
  auto t = coord::summary_text(info(), sum);
  std::cout << t;
  EXPECT_NE(t.find("      effects: bonds 1.000 s (25.0 %), gravity 0.500 s (12.5 %)\n"), std::string::npos) << t;
  EXPECT_NE(t.find("      effects: coupling 2.000 s (40.0 %), gravity 1.000 s (20.0 %)\n"), std::string::npos) << t;
  EXPECT_NE(t.find("      effects: gravity 0.250 s (5.0 %)\n"), std::string::npos) << t;
  // Run totals: dem computed 9 s; gravity 1.5 s = 16.7 %, coupling 2 s = 22.2 %, bonds 1 s = 11.1 %.
  auto totals = t.substr(t.find("run totals per node"));
  EXPECT_NE(totals.find("  dem: compute 9.000 s, bus wait 4.500 s\n"), std::string::npos) << totals;
  EXPECT_NE(totals.find("    gravity                    1.500 s   16.7 %\n"), std::string::npos) << totals;
  EXPECT_NE(totals.find("    coupling                   2.000 s   22.2 %\n"), std::string::npos) << totals;
  EXPECT_NE(totals.find("  continuum: compute 5.000 s, bus wait 2.500 s\n"), std::string::npos) << totals;
  // Unchanged stage line (bench/bus parses it).
  EXPECT_NE(t.find("  load [cycle]: steps 2..4 (3), wall "), std::string::npos) << t;
}

TEST(Summary, NodeWithoutEffectsListsNone) {
  EffectDriver d;
  auto t = coord::summary_text(info(), run_two_stages(d));
  EXPECT_EQ(t.find("effects:"), std::string::npos) << t;
  EXPECT_NE(t.find("(no effects reported)"), std::string::npos) << t;
}

TEST(Summary, JsonIsValidAndCarriesStagesTotalsAndNodes) {
  EffectDriver d;
  d.effects["settle"]["dem"] = {{"gravity", 0.5}};
  d.effects["load"]["dem"] = {{"gravity", 1.0}, {"coupling", 2.0}};
  auto sum = run_two_stages(d);
  auto j = coord::summary_json(info(), sum);
  std::cout << j;
  EXPECT_TRUE(python_json_check(j, "j['scene'] == 'scenes/x \\\"quoted\\\".toml' and j['hash'] == 'abc'")) << j;
  EXPECT_TRUE(python_json_check(j, "[n['role'] for n in j['nodes']] == ['continuum', 'dem'] and j['nodes'][1]['pid'] == 11"));
  EXPECT_TRUE(python_json_check(
      j, "[(s['name'], s['action'], s['steps']) for s in j['stages']] == [('settle', 'cycle', 2), ('load', 'cycle', 3)]"));
  EXPECT_TRUE(python_json_check(j, "list(j['stages'][0]['nodes']) == ['dem'] and j['stages'][0]['nodes']['dem']"
                                   "['effects'] == {'gravity': {'s': 0.5, 'share': 0.125}}"));
  EXPECT_TRUE(python_json_check(j, "j['stages'][1]['nodes']['continuum']['effects'] == {} and "
                                   "j['stages'][1]['nodes']['dem']['compute_s'] == 5 and "
                                   "j['stages'][1]['nodes']['dem']['wait_s'] == 2.5"));
  EXPECT_TRUE(python_json_check(j, "j['totals']['steps'] == 5 and j['totals']['nodes']['dem']['compute_s'] == 9 and "
                                   "j['totals']['nodes']['dem']['effects']['gravity']['s'] == 1.5 and "
                                   "abs(j['totals']['nodes']['dem']['effects']['coupling']['share'] - 2 / 9) < 1e-9"));
}

TEST(Summary, JsonStringEscapes) {
  EXPECT_EQ(coord::json_string("a\"b\\c\n\x01"), "\"a\\\"b\\\\c\\n\\u0001\"");
}

// A coupled stage "gravity" of steps 0-9 in 10 s: the continuum computed 1 s and waited 9 s, the
// DEM computed 9 s and waited 1 s.
static coord::StageSummary gravity_stage() {
  coord::StageSummary a;
  a.name = "gravity";
  a.action = "couple";
  a.first_step = 0;
  a.last_step = 9;
  a.wall_s = 10.0;
  a.ended_by = "steps";
  a.compute_s = {{"continuum", 1.0}, {"dem", 9.0}};
  a.wait_s = {{"continuum", 9.0}, {"dem", 1.0}};
  return a;
}

// Peak memory: the largest STAGE_END peak_rss_mb of each node over the stages, and for the DEM on
// ranks the largest of its other ranks' (peak_rss_mb_other_ranks), in the text and in the JSON.
TEST(Summary, PeakMemoryPerNodeAndOtherRanks) {
  coord::StageSummary a = gravity_stage();
  a.end["dem"].values = {{"peak_rss_mb", 380.0}, {"peak_rss_mb_other_ranks", 120.0}};
  a.end["continuum"].values = {{"peak_rss_mb", 90.0}};
  coord::StageSummary b = a;
  b.name = "penetrate";
  b.end["dem"].values = {{"peak_rss_mb", 400.0}, {"peak_rss_mb_other_ranks", 110.0}};
  b.end["continuum"].values = {{"ratio", 1.0}};
  coord::RunSummary sum;
  sum.stages = {a, b};
  sum.wall_s = 20.0;
  sum.steps = 20;
  const std::string t = coord::summary_text(info(), sum);
  EXPECT_NE(t.find("Peak memory (resident set): continuum 90 MB, dem 400 MB (rank 0; its other ranks at most 120 MB "
                   "each)\n"),
            std::string::npos)
      << t;
  const std::string j = coord::summary_json(info(), sum);
  EXPECT_TRUE(python_json_check(j, "j['totals']['nodes']['dem']['peak_rss_mb'] == 400 and "
                                   "j['totals']['nodes']['dem']['peak_rss_mb_other_ranks'] == 120 and "
                                   "j['totals']['nodes']['continuum']['peak_rss_mb'] == 90 and "
                                   "'peak_rss_mb_other_ranks' not in j['totals']['nodes']['continuum']"))
      << j;
}

// CPU utilisation (issue 16 item 2): each node's STAGE_END cpu_s over the stage's wall time, per
// stage and over the run (only the stages a node reported CPU time for), and all nodes together
// against the host's cores.
TEST(Summary, CpuUtilisationPerStageAndNodeAndOverTheRun) {
  coord::StageSummary a = gravity_stage();
  a.end["dem"].values = {{"cpu_s", 18.0}};
  a.end["continuum"].values = {{"cpu_s", 1.0}};
  coord::StageSummary b = a;
  b.name = "penetrate";
  b.first_step = 10;
  b.last_step = 19;
  b.wall_s = 30.0;
  b.end["dem"].values = {{"cpu_s", 42.0}};
  b.end["continuum"].values = {{"ratio", 1.0}};  // no CPU time reported (an older solver)
  coord::RunSummary sum;
  sum.stages = {a, b};
  sum.wall_s = 40.0;
  sum.steps = 20;
  auto i = info();
  i.host_cores = 2;
  const std::string t = coord::summary_text(i, sum);
  EXPECT_NE(t.find("dem: compute 9.000 s, bus wait 1.000 s (10.0 %), CPU 18.000 s (1.80 cores)"), std::string::npos) << t;
  EXPECT_NE(t.find("continuum: compute 1.000 s, bus wait 9.000 s (90.0 %), CPU 1.000 s (0.10 cores)"), std::string::npos) << t;
  EXPECT_NE(t.find("dem: compute 9.000 s, bus wait 1.000 s (10.0 %), CPU 42.000 s (1.40 cores)"), std::string::npos) << t;
  EXPECT_NE(t.find("continuum: compute 1.000 s, bus wait 9.000 s (90.0 %)\n"), std::string::npos) << t;
  // dem (18 + 42) / (10 + 30) = 1.50; continuum 1 / 10 = 0.10 (its one reporting stage)
  EXPECT_NE(t.find("CPU utilisation (cores busy over the stages' wall time): continuum 0.10, dem 1.50; together 1.60 of "
                   "the coordinator host's 2 (80 %)"),
            std::string::npos)
      << t;
  const std::string j = coord::summary_json(i, sum);
  EXPECT_TRUE(python_json_check(j, "j['stages'][0]['nodes']['dem']['cpu_cores'] == 1.8 and "
                                   "j['stages'][1]['nodes']['dem']['cpu_s'] == 42 and "
                                   "'cpu_s' not in j['stages'][1]['nodes']['continuum'] and "
                                   "j['totals']['nodes']['dem']['cpu_cores'] == 1.5 and "
                                   "abs(j['totals']['nodes']['continuum']['cpu_cores'] - 0.1) < 1e-12 and "
                                   "j['totals']['host_cores'] == 2"))
      << j;
}
