// Stability suite (issue 7 item 2, docs/stability.md): hard cases on the reduced coupled
// footing scene (scenes/footing_small.toml: 476 balls in a 1 x 1 x 2 mm block, 4 mm FDM box,
// 100 g), each run end to end through launch/run. Every case that must run asserts:
//  * the blow-up guard stayed clean (exit 0, no blowup_*.txt), every value of dem_history.csv
//    and fdm_history.csv is finite;
//  * bounded kinetic energy: DEM KE <= W_dem H_block + F_max d_max (its whole weight falling
//    through the block height plus the largest footing work), continuum KE <= (W_dem + W_fdm)
//    H_box + F_max d_max;
//  * interface force balance: continuum.iface_imbalance < 1e-12 in every coupled row;
//  * timestep: in every row, each node's dt <= its critical dt (the coordinator grants the
//    smallest stable step of the nodes: the stiff-continuum case has the FDM as the limit).
// Cases that must stop assert exit code 3 and an error naming the cause and the step.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <regex>

#include "tests/stability/scene_run.hpp"

using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
constexpr double kBlockHeight = 2e-3, kBoxHeight = 4e-3;  // [m] footing_small.toml

std::string base_scene() { return slurp(kSrc + "/scenes/footing_small.toml"); }

SceneRun run(const std::string& tag, const std::string& text) {
  return run_scene_text(kSrc, kBin, "stability-" + tag, text, 55);
}

// Values of a node's STAGE_END report, from its log line "stage N 'name' ends after step S;
// values: k=v ...".
std::map<std::string, double> stage_values(const fs::path& log, const std::string& stage) {
  std::istringstream is(slurp(log));
  std::string line;
  std::map<std::string, double> v;
  const std::string key = "'" + stage + "' ends after step ";
  while (std::getline(is, line)) {
    auto p = line.find(key);
    if (p == std::string::npos) continue;
    auto q = line.find("values:", p);
    std::istringstream vs(line.substr(q + 7));
    std::string kv;
    while (vs >> kv) {
      auto e = kv.find('=');
      v[kv.substr(0, e)] = std::stod(kv.substr(e + 1));
    }
  }
  if (v.empty()) throw std::runtime_error("no end of stage '" + stage + "' in " + log.string());
  return v;
}

double max_of(const std::vector<double>& v) {
  double m = -INFINITY;
  for (double x : v) m = std::max(m, x);
  return m;
}

void expect_all_finite(const fs::path& csv) {
  auto c = read_columns(csv);
  ASSERT_FALSE(c.empty()) << csv;
  for (auto& [name, col] : c)
    for (std::size_t i = 0; i < col.size(); ++i) ASSERT_TRUE(std::isfinite(col[i])) << csv << " " << name << " row " << i;
}

struct Figures {
  double ke_dem = 0, ke_fdm = 0, ke_bound_dem = 0, ke_bound_fdm = 0, imbalance = 0, worst_dt_ratio = 0;
  double fdm_limited_rows = 0;
};

// The invariants every case that must run shares (see the file comment).
Figures check_clean_run(const SceneRun& r) {
  Figures f;
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(fs::exists(r.dir / "blowup_dem.txt"));
  EXPECT_FALSE(fs::exists(r.dir / "blowup_continuum.txt"));
  if (r.code != 0) return f;
  expect_all_finite(r.dir / "dem_history.csv");
  expect_all_finite(r.dir / "fdm_history.csv");
  auto g = read_columns(r.dir / "history_4_gravity.csv");
  auto p = read_columns(r.dir / "history_5_penetrate.csv");
  const double w_dem = g.at("dem.weight_N").back(), w_fdm = g.at("continuum.weight_N").back();
  const double footing_work = std::max(0.0, max_of(p.at("dem.footing_fz_N"))) * max_of(p.at("dem.footing_disp_m"));
  auto dem = read_columns(r.dir / "dem_history.csv");
  auto fdm = read_columns(r.dir / "fdm_history.csv");
  f.ke_dem = max_of(dem.at("kinetic_J"));
  f.ke_fdm = max_of(fdm.at("kinetic_J"));
  f.ke_bound_dem = w_dem * kBlockHeight + footing_work;
  f.ke_bound_fdm = (w_dem + w_fdm) * kBoxHeight + footing_work;
  EXPECT_LE(f.ke_dem, f.ke_bound_dem);
  EXPECT_LE(f.ke_fdm, f.ke_bound_fdm);
  for (auto* h : {&g, &p}) {
    f.imbalance = std::max(f.imbalance, max_of(h->at("continuum.iface_imbalance")));
    const auto& dd = h->at("dem.dt_s");
    const auto& dc = h->at("dem.dt_critical_s");
    const auto& fd = h->at("continuum.dt_s");
    const auto& fc = h->at("continuum.dt_critical_s");
    for (std::size_t i = 0; i < dd.size(); ++i) {
      f.worst_dt_ratio = std::max({f.worst_dt_ratio, dd[i] / dc[i], fd[i] / fc[i]});
      if (fc[i] < dc[i]) ++f.fdm_limited_rows;
    }
  }
  EXPECT_LT(f.imbalance, 1e-12);
  EXPECT_LE(f.worst_dt_ratio, 1.0 + 1e-12);
  std::cout << "[ figures  ] max KE: DEM " << f.ke_dem << " J (bound " << f.ke_bound_dem << "), continuum " << f.ke_fdm
            << " J (bound " << f.ke_bound_fdm << "); interface imbalance " << f.imbalance
            << "; largest dt / critical dt " << f.worst_dt_ratio << "\n";
  return f;
}

struct Case {
  const char* name;
  std::vector<std::pair<std::string, std::string>> edits;  // replace_once(from, to) on the base scene
};

void PrintTo(const Case& c, std::ostream* os) { *os << c.name; }

std::string edited(const Case& c) {
  auto s = base_scene();
  for (auto& [from, to] : c.edits) replace_once(s, from, to);
  return s;
}

class HardCase : public ::testing::TestWithParam<Case> {};

}  // namespace

TEST_P(HardCase, RunsWithoutNaNWithBoundedEnergyAndBalancedInterface) {
  const auto& c = GetParam();
  auto r = run(c.name, edited(c));
  auto f = check_clean_run(r);
  if (r.code != 0) return;
  auto pen = stage_values(r.dir / "dem.log", "penetrate");
  const double broken = pen.at("bonds_broken_tension") + pen.at("bonds_broken_shear");
  const double bonds = broken + pen.at("bonds_intact") + pen.at("bonds_softening");
  std::cout << "[ figures  ] " << c.name << ": bonds broken " << broken << " of " << bonds << "\n";
  const std::string name = c.name;
  if (name == "stiff_continuum") {
    EXPECT_GT(f.fdm_limited_rows, 0) << "the FDM's critical step must be the limit";
  }
  if (name == "bond_cascade") {
    EXPECT_GT(broken, 0.5 * bonds) << "the weak bonds must break in a cascade";
  }
  if (testing::Test::HasFailure()) return;
  r.clean();
}

INSTANTIATE_TEST_SUITE_P(
    Stability, HardCase,
    ::testing::Values(
        Case{"g200", {{"\nlevel = 100\n", "\nlevel = 200\n"}}},
        Case{"g1000", {{"\nlevel = 100\n", "\nlevel = 1000\n"}}},
        // 100:1 stiffness contrast against the DEM block's E50 ~ 1.1e9 Pa, both ways.
        Case{"soft_continuum", {{"young = 1.083e9", "young = 1.083e7"}}},
        Case{"stiff_continuum", {{"young = 1.083e9", "young = 1.083e11"}}},
        // 10 x the inertial-number rule's footing speed.
        Case{"fast_footing", {{"mean_stress = 1e6", "mean_stress = 1e6\nspeed_factor = 10"}}},
        // Soft bonds 100 x weaker than Table 1: most break under the footing.
        Case{"bond_cascade", {{"[dem.specimen]", "[dem.ball_ball.softbond]\nten = 4.5e3\ncoh = 4.5e3\n\n[dem.specimen]"}}}),
    [](const auto& info) { return std::string(info.param.name); });

// Undamped DEM (dem.damping = 0, depth scaling off so that every contact force derives from
// the strain energy): kinetic + strain + dissipated - work of gravity, facets and footing is
// conserved within 15 % of the largest energy flow in the gravity stage (measured 6.5-7.3 %) and
// 30 % in the penetration (measured 16-20 %: the strain energy of the ~370 bonds that break is
// dropped with them and booked nowhere).
TEST(Stability, UndampedCyclingKeepsTheEnergyBalance) {
  auto s = base_scene();
  replace_once(s, "[dem]\n", "[dem]\ndamping = 0.0\n");
  replace_once(s, "servo_budget = 16000", "servo_budget = 16000\ndepth_scaling = \"none\"");
  auto r = run("undamped", s);
  check_clean_run(r);
  ASSERT_EQ(r.code, 0);
  auto g = stage_values(r.dir / "dem.log", "gravity");
  auto p = stage_values(r.dir / "dem.log", "penetrate");
  std::cout << "[ figures  ] energy balance error: gravity " << g.at("energy_balance_error") << " (work "
            << g.at("energy_work_J") << " J), penetrate " << p.at("energy_balance_error") << " (work "
            << p.at("energy_work_J") << " J)\n";
  // Measured 2026-12-03: gravity -1.1 %, penetration -4.8 % (+16.8 % before the soft bond's
  // softening return booked its plastic work instead of rim stress times disc area).
  EXPECT_LT(std::abs(g.at("energy_balance_error")), 0.03);
  EXPECT_LT(std::abs(p.at("energy_balance_error")), 0.08);
  if (!testing::Test::HasFailure()) r.clean();
}

// A user dt_fixed: above the critical step it is refused at the begin of the first stage after
// specimen preparation (preparation runs on its own automatic step, docs/theory.md 4.11) with an
// error naming the key, the value and the critical value (exit 3), or
// reduced with a warning when dem.dt_above_critical = "reduce"; at 0.9 x critical it runs
// stably. The critical step is read from a first run (its smallest value over the run).
TEST(Stability, DtFixedAboveCriticalIsRefusedOrReducedAndBelowRunsStably) {
  auto base = run("dt-base", base_scene());
  ASSERT_EQ(base.code, 0) << base.output;
  double crit_min = INFINITY, crit_max = 0;
  for (const char* h : {"history_4_gravity.csv", "history_5_penetrate.csv"}) {
    auto c = read_columns(base.dir / h);
    for (double v : c.at("dem.dt_critical_s")) crit_min = std::min(crit_min, v), crit_max = std::max(crit_max, v);
  }
  base.clean();
  std::ostringstream above, below;
  above.precision(17);
  below.precision(17);
  above << "[dem]\ndt_fixed = " << 3 * crit_max << "\n";
  below << "[dem]\ndt_fixed = " << 0.9 * crit_min << "\n";

  auto s = base_scene();
  replace_once(s, "[dem]\n", above.str());
  auto refused = run("dt-above", s);
  EXPECT_EQ(refused.code, 3) << refused.output;
  std::smatch m;
  EXPECT_TRUE(std::regex_search(refused.output, m,
                                std::regex("dem at step [0-9]+: dem.dt_fixed = [0-9.e+-]+ s exceeds the critical "
                                           "timestep [0-9.e+-]+ s .*begin of stage 'gravity'")))
      << refused.output;
  std::cout << "[ figures  ] dt_fixed " << 3 * crit_max << " s refused; critical " << crit_min << ".." << crit_max << " s\n";
  if (!testing::Test::HasFailure()) refused.clean();

  auto r = base_scene();
  replace_once(r, "[dem]\n", above.str() + "dt_above_critical = \"reduce\"\n");
  auto reduced = run("dt-reduce", r);
  check_clean_run(reduced);
  EXPECT_NE(slurp(reduced.dir / "dem.log").find("reduced to dt_safety x critical"), std::string::npos);
  if (!testing::Test::HasFailure()) reduced.clean();

  auto b = base_scene();
  replace_once(b, "[dem]\n", below.str());
  auto stable = run("dt-0.9", b);
  check_clean_run(stable);
  if (stable.code == 0) {
    auto h = read_columns(stable.dir / "history_5_penetrate.csv");
    EXPECT_LE(max_of(h.at("dem.dt_s")), 0.9 * crit_min * (1 + 1e-9));
  }
  if (!testing::Test::HasFailure()) stable.clean();
}

// A ball leaving the domain (dem.escape_margin, default 5 d_max): the top ball, kicked upwards at
// 200 m/s at the gravity stage, breaks its bonds and flies out; the DEM node stops the run at
// that step with blowup_dem.txt naming the ball, its position and its neighbours, and the
// coordinator exits 3 with the cause and the step.
TEST(Stability, ParticleLeavingTheDomainStopsTheRunNamingIt) {
  auto s = base_scene();
  replace_once(s, "[dem]\n", "[dem]\nkick = [0.0, 0.0, 200.0]\n");
  auto r = run("escape", s);
  EXPECT_EQ(r.code, 3) << r.output;
  ASSERT_TRUE(fs::exists(r.dir / "blowup_dem.txt")) << r.output;
  auto report = slurp(r.dir / "blowup_dem.txt");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(report, m, std::regex("ball id ([0-9]+) left the DEM domain"))) << report;
  const std::string id = m[1];
  EXPECT_NE(report.find("10 nearest balls"), std::string::npos);
  EXPECT_TRUE(std::regex_search(r.output, std::regex("dem at step [0-9]+: blow-up guard: ball id " + id +
                                                     " left the DEM domain")))
      << r.output;
  // The kick names the same ball.
  EXPECT_NE(slurp(r.dir / "dem.log").find("kick: ball id " + id + " "), std::string::npos);
  if (!testing::Test::HasFailure()) r.clean();
}
