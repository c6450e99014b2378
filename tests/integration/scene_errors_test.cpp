// Bad input gets one clear line `file:line:col: key: expected ..., found ...` and exit code 2
// before anything starts; launch/run never overwrites an earlier run folder.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <thread>

#include "tests/integration/process.hpp"
#include "tests/integration/scratch.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;

const std::string kGood =
    "[dem]\nexecutable = \"chain_dem\"\n[continuum]\nexecutable = \"chain_continuum\"\n"
    "[coupling]\nscheme = \"serial\"\n[chain]\nn_masses = 20\nsplit = 10\n"
    "[[stage]]\nname = \"wave\"\nsteps = 10\ncoupled = true\n";

struct Check {
  int code;
  std::string out;
};

Check check_text(const std::string& name, const std::string& text) {
  auto dir = scratch("demfdm-scenes-" + std::to_string(getpid()));
  fs::create_directories(dir);
  auto path = dir / (name + ".toml");
  std::ofstream(path) << text;
  auto out = dir / (name + ".out");
  fs::remove(out);
  auto p = spawn({kBin + "/coordinator", path.string(), "--check"}, {}, out.string());
  auto st = wait_for(p, 30);
  EXPECT_TRUE(st.has_value());
  return {st ? exit_code(*st) : -1, read_file(out.string())};
}

std::string replace(std::string s, const std::string& from, const std::string& to) {
  auto i = s.find(from);
  EXPECT_NE(i, std::string::npos) << from;
  return s.replace(i, from.size(), to);
}

struct Case {
  const char* name;
  std::string text;
  const char* position;  // ":line:col:" expected
  const char* message;   // expected substring
};
}  // namespace

TEST(SceneErrors, GoodSceneValidates) {
  auto c = check_text("good", kGood);
  EXPECT_EQ(c.code, 0) << c.out;
}

TEST(SceneErrors, EachKindOfBadSceneGivesOneLineAndExitTwo) {
  std::vector<Case> cases = {
      {"unknown_key", replace(kGood, "scheme =", "schem ="), ":6:1:", "coupling.schem: unknown key; did you mean 'scheme'?"},
      {"unknown_section", replace(kGood, "[coupling]", "[coupler]"), ":5:2:", "coupler: unknown section; did you mean 'coupling'?"},
      {"wrong_type", replace(kGood, "n_masses = 20", "n_masses = \"twenty\""), ":8:12:", "chain.n_masses: expected"},
      {"real_for_int", replace(kGood, "n_masses = 20", "n_masses = 20.5"), ":8:12:", "found"},
      {"out_of_range", replace(kGood, "n_masses = 20", "n_masses = 1"), ":8:12:", "chain.n_masses: expected"},
      {"bad_choice", replace(kGood, "\"serial\"", "\"implicit\""), ":6:10:", "expected one of 'serial', 'parallel'"},
      {"missing_required_key", replace(kGood, "steps = 10\n", ""), ":10:1:", "stage[0].steps: missing required key"},
      {"missing_required_section", replace(kGood, "[[stage]]\nname = \"wave\"\nsteps = 10\ncoupled = true\n", ""), ":1:1:", "stage"},
      {"toml_syntax", replace(kGood, "split = 10", "split = = 10"), ":9:", "TOML syntax error"},
      {"coupling_without_continuum", replace(kGood, "[continuum]\nexecutable = \"chain_continuum\"\n", ""), ":3:1:",
       "coupling: expected both [dem] and [continuum]"},
      {"unknown_role", replace(kGood, "coupled = true", "coupled = true\nnodes = [\"fem\"]"), ":14:", "stage[0].nodes: expected roles present"},
      {"split_too_large", replace(kGood, "split = 10", "split = 20"), ":9:9:", "chain.split: expected an integer in [1, n_masses-1]"},
      {"list_of_wrong_type", replace(kGood, "coupled = true", "coupled = true\nnodes = \"dem\""), ":14:", "stage[0].nodes: expected"},
      {"no_node_at_all", "[[stage]]\nname = \"x\"\nsteps = 1\n", ":1:1:", "expected a [dem] or a [continuum] section"},
  };
  for (auto& c : cases) {
    auto r = check_text(c.name, c.text);
    SCOPED_TRACE(c.name);
    EXPECT_EQ(r.code, 2) << r.out;
    EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << "one line expected, got:\n" << r.out;
    EXPECT_NE(r.out.find(std::string(c.name) + ".toml" + c.position), std::string::npos) << r.out;
    EXPECT_NE(r.out.find(c.message), std::string::npos) << r.out;
  }
}

TEST(SceneErrors, MissingSceneFileIsNamed) {
  auto out = scratch("demfdm-missing-" + std::to_string(getpid()) + ".out");
  auto p = spawn({kBin + "/coordinator", "/nonexistent/scene.toml", "--check"}, {}, out.string());
  auto st = wait_for(p, 10);
  ASSERT_TRUE(st);
  EXPECT_EQ(exit_code(*st), 2);
  EXPECT_NE(read_file(out.string()).find("/nonexistent/scene.toml"), std::string::npos);
}

TEST(SceneErrors, BrokenSceneThroughLaunchRun) {
  auto out = scratch("demfdm-broken-" + std::to_string(getpid()) + ".out");
  auto runs = scratch("demfdm-broken-runs-" + std::to_string(getpid()));
  auto p = spawn({"/bin/bash", kSrc + "/launch/run", kSrc + "/scenes/broken.toml", "--no-build", "--runs-root", runs.string()},
                 {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()}, out.string());
  auto st = wait_for(p, 30);
  ASSERT_TRUE(st);
  EXPECT_EQ(exit_code(*st), 2);
  auto text = read_file(out.string());
  EXPECT_NE(text.find("broken.toml:13:1: coupling.schem: unknown key; did you mean 'scheme'?"), std::string::npos) << text;
  EXPECT_FALSE(fs::exists(runs) && !fs::is_empty(runs)) << "nothing may start for a broken scene";
}

TEST(LaunchRun, WritesACompleteRunFolderAndNeverOverwritesOne) {
  auto runs = scratch("demfdm-launch-" + std::to_string(getpid()));
  fs::remove_all(runs);
  auto dir = runs / "one";
  fs::create_directories(runs);
  auto out = runs / "launch.out";
  std::vector<std::string> env = {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()};
  auto p = spawn({"/bin/bash", kSrc + "/launch/run", kSrc + "/scenes/chain_serial.toml", "--no-build", "--run-dir", dir.string()},
                 env, out.string());
  auto st = wait_for(p, 60);
  ASSERT_TRUE(st);
  ASSERT_EQ(exit_code(*st), 0) << read_file(out.string());
  for (auto f : {"scene.toml", "coordinator.log", "dem.log", "continuum.log", "traffic.lcmlog", "summary.txt",
                 "chain_dem.csv", "chain_continuum.csv"})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  EXPECT_GT(fs::file_size(dir / "traffic.lcmlog"), 1000u);
  auto summary = read_file((dir / "summary.txt").string());
  // A second run into the same folder is refused and the first run's files stay as they were.
  auto p2 = spawn({"/bin/bash", kSrc + "/launch/run", kSrc + "/scenes/chain_serial.toml", "--no-build", "--run-dir", dir.string()},
                  env, (runs / "launch2.out").string());
  auto st2 = wait_for(p2, 30);
  ASSERT_TRUE(st2);
  EXPECT_EQ(exit_code(*st2), 2);
  EXPECT_NE(read_file((runs / "launch2.out").string()).find("never overwritten"), std::string::npos);
  EXPECT_EQ(read_file((dir / "summary.txt").string()), summary);
}

TEST(LaunchRun, CtrlCStopsEveryProcess) {
  auto runs = scratch("demfdm-sigint-" + std::to_string(getpid()));
  fs::remove_all(runs);
  fs::create_directories(runs);
  auto dir = runs / "run";
  auto scene = runs / "long.toml";
  std::ofstream(scene) << "[dem]\nexecutable = \"chain_dem\"\n[continuum]\nexecutable = \"chain_continuum\"\n"
                          "[coupling]\n[chain]\nrecord_every = 1000\n[[stage]]\nname = \"long\"\nsteps = 100000000\ncoupled = true\n";
  auto p = spawn({"/bin/bash", kSrc + "/launch/run", scene.string(), "--no-build", "--run-dir", dir.string()},
                 {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()}, (runs / "out.txt").string());
  std::this_thread::sleep_for(std::chrono::milliseconds(2500));
  ::kill(p.pid, SIGINT);
  auto t0 = std::chrono::steady_clock::now();
  auto st = wait_for(p, 10);
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(st) << "launch/run did not stop after SIGINT";
  EXPECT_EQ(exit_code(*st), 130) << read_file((runs / "out.txt").string());
  EXPECT_LT(s, 5.0);
  // No process of this run is left.
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  EXPECT_NE(std::system(("pgrep -f '[r]un-dir=" + dir.string() + "' >/dev/null").c_str()), 0) << "orphaned processes";
}

// Issue 15 item 6: `--check` runs every check a node would run, cross-field ones included. Each
// bad input is refused with exit 2 and one line that names the key (through an override of the
// default scene: the line names the override).
TEST(SceneErrors, CrossFieldAndNodeChecksRefuseAtCheck) {
  struct Bad {
    const char* set;
    const char* key;  // the key the line must name
    const char* set2 = nullptr;  // a second override, if the check joins two keys
  };
  const Bad cases[] = {
      {"dem.ball_ball.softbond.mcf=0", "dem.ball_ball.softbond.mcf"},           // the engine refused it only at start
      {"dem.ball_ball.emod=inf", "dem.ball_ball.emod"},             // no key accepts infinity
      {"continuum.mesh.size_near=inf", "continuum.mesh.size_near"},
      {"dem.ball_ball.emod=0", "dem.ball_ball.emod"},               // soft bond: its only stiffness
      {"dem.specimen.d_min=0.3e-3", "dem.specimen.d_min"},          // PSD bounds
      {"dem.specimen.d50=1e-300", "dem.specimen.d50"},
      {"gravity.level=0", "dem.specimen.sigma_v"},                  // derived stress without gravity
      {"dem.footing.diameter=5e-3", "dem.footing.diameter"},        // wider than the block's top face
      {"dem.footing.diameter=1e308", "dem.footing.diameter"},
      {"dem.footing.centre=[1.0,1.0]", "dem.footing.centre"},       // 1 m outside the block
      {"dem.footing.centre=[1,2,3,4]", "dem.footing.centre"},       // a centre of four numbers
      {"stage.penetrate.steps=9223372036854775807", "stage.penetrate.steps"},  // overflowing budget
      {"stage.penetrate.inertial_number=1e308", "stage.penetrate.inertial_number"},
      {"stage.servo.depth_ratio=0.3", "stage.servo.depth_ratio"},   // a penetrate key in a servo stage
      {"dem.ball_facet.model=linear", "dem.ball_facet.model"},      // the couple stage bonds to the facets
      {"continuum.mesh.size_near=5e-3", "continuum.mesh.size_near"},  // zones larger than size_far
      {"dem.dt_fixed=1e-3", "dem.dt_fixed"},                        // above any critical step (dem_node --check)
      {"dem.ball_ball.pbond.ten=1e6", "dem.ball_ball.pbond.ten"},   // a table of another law (model softbond)
      {"stage.generate.nodes=[\"dem\", \"continuum\"]", "stage.generate.nodes"},  // a continuum cannot generate
      // newton's results follow the cuts, and time-weighted cuts differ from run to run
      {"dem.balance_weight=\"time\"", "dem.balance_weight", "dem.newton=true"},
      {"dem.balance_costs=[20,27,27,12,250]", "dem.balance_costs"},       // six costs
      {"dem.balance_costs=[0,27,27,12,250,54]", "dem.balance_costs"},     // a ball that weighs nothing
      {"dem.balance_costs=[20,27,27,-12,250,54]", "dem.balance_costs"},   // a negative cost
  };
  const auto dir = scratch("demfdm-crossfield-" + std::to_string(getpid()));
  fs::create_directories(dir);
  int i = 0;
  for (const Bad& b : cases) {
    SCOPED_TRACE(b.set);
    const auto out = dir / ("case" + std::to_string(i++) + ".out");
    std::vector<std::string> args{kBin + "/coordinator", kSrc + "/scenes/default.toml", "--check", "--set", b.set};
    if (b.set2) args.insert(args.end(), {"--set", b.set2});
    auto p = spawn(args, {}, out.string());
    auto st = wait_for(p, 30);
    ASSERT_TRUE(st.has_value());
    const std::string text = read_file(out.string());
    EXPECT_EQ(exit_code(*st), 2) << text;
    EXPECT_NE(text.find(b.key), std::string::npos) << text;
    EXPECT_NE(text.find("expected"), std::string::npos) << text;
    EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1) << "one line: " << text;
  }
  // The default scene itself passes, nodes included.
  const auto out = dir / "good.out";
  auto p = spawn({kBin + "/coordinator", kSrc + "/scenes/default.toml", "--check"}, {}, out.string());
  auto st = wait_for(p, 30);
  ASSERT_TRUE(st.has_value());
  EXPECT_EQ(exit_code(*st), 0) << read_file(out.string());
}

// A node executable runs its own checks without a bus: `dem_node --check SCENE [--set ...]`.
TEST(SceneErrors, NodeExecutablesCheckTheSceneAlone) {
  const auto dir = scratch("demfdm-nodecheck-" + std::to_string(getpid()));
  fs::create_directories(dir);
  auto run = [&](const std::vector<std::string>& args, const std::string& tag) {
    const auto out = dir / (tag + ".out");
    auto p = spawn(args, {}, out.string());
    auto st = wait_for(p, 30);
    EXPECT_TRUE(st.has_value());
    return std::make_pair(st ? exit_code(*st) : -1, read_file(out.string()));
  };
  auto [c1, o1] = run({kBin + "/dem_node", "--check", kSrc + "/scenes/default.toml"}, "dem-ok");
  EXPECT_EQ(c1, 0) << o1;
  auto [c2, o2] = run({kBin + "/fdm_node", "--check", kSrc + "/scenes/default.toml"}, "fdm-ok");
  EXPECT_EQ(c2, 0) << o2;
  auto [c3, o3] = run({kBin + "/dem_node", "--check", kSrc + "/scenes/default.toml", "--set", "dem.dt_fixed=1e-3"}, "dem-bad");
  EXPECT_EQ(c3, 2) << o3;
  EXPECT_NE(o3.find("dem.dt_fixed"), std::string::npos) << o3;
  auto [c4, o4] = run({kBin + "/fdm_node", "--check"}, "fdm-noscene");
  EXPECT_EQ(c4, 2) << o4;
}

