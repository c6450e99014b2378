// The footing result read back from a stage history (coordinator/core/results.hpp) and the
// progress line (coordinator/core/progress.hpp), against hand-made histories and reports.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "coordinator/core/progress.hpp"
#include "coordinator/core/results.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {
fs::path write_history(const std::string& name, const std::string& text) {
  auto p = fs::temp_directory_path() / ("demfdm-results-" + std::to_string(getpid()) + "-" + name + ".csv");
  std::ofstream(p) << text;
  return p;
}

config::Scene scene(const std::string& stages) {
  return config::Scene::parse("[dem]\n[dem.footing]\ndiameter = 1e-3\n[continuum]\n[coupling]\n" + stages, "test.toml",
                              schema::scene_schema());
}
}  // namespace

TEST(FootingResult, PeakFinalAndElasticSlopeOfAKnownCurve) {
  // F = 2e5 s for 6 loaded rows before the first bond failure, then softening.
  std::string t = "step,dem.time_s,dem.footing_disp_m,dem.footing_fz_N,dem.bond_failures\n";
  const double s[] = {0, 1e-6, 2e-6, 3e-6, 4e-6, 5e-6, 6e-6, 7e-6, 8e-6, 9e-6, 10e-6};
  const double f[] = {0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.5, 1.1, 0.9, 0.95};
  const int fail[] = {0, 0, 0, 0, 0, 0, 0, 3, 7, 9, 12};
  for (int i = 0; i < 11; ++i)
    t += std::to_string(i) + ",0," + std::to_string(s[i]) + "," + std::to_string(f[i]) + "," + std::to_string(fail[i]) + "\n";
  auto p = write_history("known", t);
  auto r = coord::footing_result(p.string(), "penetrate", 1e-3, 1e-5);
  EXPECT_DOUBLE_EQ(r.peak_N, 1.5);
  EXPECT_DOUBLE_EQ(r.settlement_at_peak_m, 7e-6);
  EXPECT_DOUBLE_EQ(r.final_N, 0.95);
  EXPECT_DOUBLE_EQ(r.final_settlement_m, 10e-6);
  EXPECT_EQ(r.elastic_rows, 6);  // rows 1..6: first load to the last row before the first failure
  EXPECT_NEAR(r.k_e_N_m, 2e5, 1e-6 * 2e5);
  EXPECT_TRUE(r.target_reached);
  r.bonds_broken_tension = 4;
  r.bonds_broken_shear = 8;
  auto text = coord::result_text(r);
  EXPECT_NE(text.find("peak load           1.5 N at settlement 0.007 mm"), std::string::npos) << text;
  EXPECT_NE(text.find("k_e 2e+05 N/m"), std::string::npos) << text;
  EXPECT_NE(text.find("4 in tension, 8 in shear"), std::string::npos) << text;
  EXPECT_NE(text.find("reached"), std::string::npos);
  auto js = coord::result_json(r);
  EXPECT_NE(js.find("\"peak_N\": 1.5"), std::string::npos) << js;
  EXPECT_NE(js.find("\"target_reached\": true"), std::string::npos) << js;
  fs::remove(p);
}

TEST(FootingResult, TargetMissedShortBranchAndRefusals) {
  auto p = write_history("short", "step,dem.footing_disp_m,dem.footing_fz_N,dem.bond_failures\n0,0,0,0\n1,1e-6,0.5,0\n"
                                  "2,2e-6,0.4,1\n");
  auto r = coord::footing_result(p.string(), "penetrate", 1e-3, 1e-5);
  EXPECT_FALSE(r.target_reached);
  EXPECT_TRUE(std::isnan(r.k_e_N_m)) << "fewer than 5 elastic rows";
  EXPECT_NE(coord::result_text(r).find("NOT reached"), std::string::npos);
  EXPECT_NE(coord::result_json(r).find("\"k_e_N_m\": null"), std::string::npos);
  fs::remove(p);
  auto q = write_history("nocol", "step,dem.ratio\n0,1\n");
  EXPECT_THROW(coord::footing_result(q.string(), "x", 1e-3, 1e-5), std::runtime_error);
  fs::remove(q);
  auto e = write_history("empty", "step,dem.footing_disp_m,dem.footing_fz_N\n");
  EXPECT_THROW(coord::footing_result(e.string(), "x", 1e-3, 1e-5), std::invalid_argument);
  fs::remove(e);
  auto n = write_history("nan", "step,dem.footing_disp_m,dem.footing_fz_N\n0,0,nan\n");
  EXPECT_THROW(coord::footing_result(n.string(), "x", 1e-3, 1e-5), std::invalid_argument);
  fs::remove(n);
  EXPECT_THROW(coord::footing_result("/nonexistent/h.csv", "x", 1e-3, 1e-5), std::runtime_error);
}

TEST(Progress, PenetrationLineHasSettlementLoadRateAndEta) {
  auto sc = scene("[[stage]]\nname = \"penetrate\"\naction = \"penetrate\"\ncoupled = true\nsteps = 1000\n"
                  "until = \"done\"\ndepth_ratio = 0.1\n");
  auto st = schema::stages(sc).at(0);
  coord::Progress p(1.0);
  p.set_footing_diameter(1e-3);
  auto t0 = std::chrono::steady_clock::time_point{} + std::chrono::seconds(100);
  auto rep = [](double disp, double load) {
    std::map<std::string, coord::NodeReport> m;
    m["dem"].values = {{"footing_disp_m", disp}, {"footing_fz_N", load}};
    return m;
  };
  EXPECT_FALSE(p.observe(st, 50, 50, rep(0, 0), t0)) << "the first report starts the stage's clock";
  EXPECT_FALSE(p.observe(st, 50, 60, rep(1e-6, 0.1), t0 + std::chrono::milliseconds(500))) << "not due yet";
  auto l1 = p.observe(st, 50, 149, rep(2e-5, 0.25), t0 + std::chrono::seconds(1));
  ASSERT_TRUE(l1);
  EXPECT_NE(l1->find("penetrate  step 100 of 1,000"), std::string::npos) << *l1;
  EXPECT_NE(l1->find("settlement 0.02 D_f of 0.1 (20 %)"), std::string::npos) << *l1;
  EXPECT_NE(l1->find("load 0.25 N"), std::string::npos) << *l1;
  EXPECT_NE(l1->find("99 steps/s"), std::string::npos) << *l1;
  // 2e-5 m more in 2 s: 1e-5 m/s, 6e-5 m left: 6 s.
  auto l2 = p.observe(st, 50, 349, rep(4e-5, 0.3), t0 + std::chrono::seconds(3));
  ASSERT_TRUE(l2);
  EXPECT_NE(l2->find("ETA 0:00:06"), std::string::npos) << *l2;
}

TEST(Progress, EquilibriumLineShowsTheLargestRatioAndABoundedEta) {
  auto sc = scene("[[stage]]\nname = \"gravity\"\naction = \"couple\"\ncoupled = true\nsteps = 10000\n"
                  "until = \"done\"\nratio = 1e-3\n");
  auto st = schema::stages(sc).at(0);
  coord::Progress p(1.0);
  auto t0 = std::chrono::steady_clock::time_point{} + std::chrono::seconds(5);
  std::map<std::string, coord::NodeReport> m;
  m["dem"].values = {{"ratio", 0.5}, {"ratio_skeleton", 4e-3}};
  m["continuum"].values = {{"ratio", 2e-3}};
  EXPECT_FALSE(p.observe(st, 0, 0, m, t0));
  auto l = p.observe(st, 0, 999, m, t0 + std::chrono::seconds(2));
  ASSERT_TRUE(l);
  EXPECT_NE(l->find("ratio 4.00e-03 -> 1.0e-03"), std::string::npos) << *l;
  EXPECT_NE(l->find("500 steps/s"), std::string::npos) << *l;
  EXPECT_NE(l->find("ETA <= 0:00:18"), std::string::npos) << *l;  // 9000 steps left at 500/s
  EXPECT_EQ(coord::clock_text(3725), "1:02:05");
  EXPECT_EQ(coord::clock_text(std::nan("")), "-");
}
