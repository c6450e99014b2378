// Physics checks of the coupled DEM-FDM footing model (issue 5) on reduced scenes of this
// folder, each run end to end through launch/run (three processes):
//  * gravity equilibrium (gravity_small.toml): base reaction = DEM + FDM weight within 0.5 %,
//    FDM layer-averaged sigma_zz below the DEM block = rho N g depth within 2 %, interface
//    action = reaction to round-off, DEM slab sigma_zz = rho_b N g depth within 10 % below the
//    top two particle layers;
//  * footing (footing_stiffness.toml, stopped at 0.05 D_f): finite load-displacement curve that
//    meets resistance; initial stiffness (k50 and k_e) at 1 g and 200 g within 10 %; soft bond and
//    parallel bond initial stiffness (k_e) within 10 % on the same sample.
// Elastic initial stiffness k_e: least-squares slope of load against displacement from the first
// contact (first row with load > 0) to the last row before the first ball-ball bond leaves the
// intact state (dem.bond_failures rises): the footing's response before any particle-scale
// failure, where a soft bond and a parallel bond across a gap are the same springs (docs/theory.md
// 2.2, 3.1). Used for the soft bond against parallel bond check.
// Initial stiffness k50: least-squares slope of load against displacement over the rising branch,
// from the first contact (first row with load > 0) to the first row at half the first peak load
// (first peak: the largest load before the load first falls below half of the largest so far,
// within 0.02 D_f of the first contact), the footing analogue of the UCS test's E50. The first
// particle-scale bond failure ends the rising branch and the load then drops by up to 100 %, so
// a slope over a fixed window depends on where that failure falls (docs/paper-study.md). launch/py/paper_figures.py uses the same rule.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

#include "tests/integration/process.hpp"
#include "tests/stability/scene_run.hpp"  // slurp, read_columns, replace_once

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
constexpr double kPeakWindow = 0.02;  // [D_f] how far after the first contact the first peak is sought

// Run folders of this process, removed at the end if every test passed (kept for inspection
// otherwise).
std::vector<fs::path>& roots() {
  static std::vector<fs::path> r;
  return r;
}
class RemoveRunFolders : public ::testing::Environment {
  void TearDown() override {
    if (::testing::UnitTest::GetInstance()->Passed())
      for (const auto& r : roots()) fs::remove_all(r);
  }
};
[[maybe_unused]] const auto* const kRemoveRunFolders = ::testing::AddGlobalTestEnvironment(new RemoveRunFolders);

// Runs a scene text through launch/run; returns the run folder.
fs::path run_scene(const std::string& name, const std::string& text) {
  auto root = fs::temp_directory_path() / ("demfdm-coupled-" + name + "-" + std::to_string(getpid()));
  fs::remove_all(root);
  roots().push_back(root);
  fs::create_directories(root);
  auto scene = root / (name + ".toml");
  std::ofstream(scene) << text;
  auto dir = root / "run";
  auto p = spawn({"/bin/bash", kSrc + "/launch/run", scene.string(), "--no-build", "--run-dir", dir.string()},
                 {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()}, (root / "out.txt").string());
  auto st = wait_for(p, 110);
  if (!st) {
    kill_and_reap(p);
    throw std::runtime_error(name + ": the run did not finish in 110 s");
  }
  if (exit_code(*st) != 0) throw std::runtime_error(name + ": launch/run failed:\n" + read_file((root / "out.txt").string()));
  return dir;
}

struct Curve {
  std::vector<double> disp, load, failed;
};
Curve footing_curve(const fs::path& dir) {
  auto h = read_columns(dir / "history_4_penetrate.csv");
  return {h.at("dem.footing_disp_m"), h.at("dem.footing_fz_N"), h.at("dem.bond_failures")};
}

// Rows [i0, ie] of the elastic branch: first contact to the last row before the first bond failure.
std::pair<std::size_t, std::size_t> elastic_branch(const Curve& c) {
  std::size_t i0 = 0;
  while (i0 < c.load.size() && !(c.load[i0] > 0)) ++i0;
  if (i0 == c.load.size()) throw std::runtime_error("the footing never met resistance");
  std::size_t ie = i0;
  while (ie + 1 < c.load.size() && c.failed[ie + 1] <= c.failed[i0]) ++ie;
  return {i0, ie};
}

double slope(const Curve& c, std::size_t i0, std::size_t i1) {
  double sx = 0, sy = 0, sxx = 0, sxy = 0, n = 0;
  for (std::size_t i = i0; i <= i1; ++i, ++n)
    sx += c.disp[i], sy += c.load[i], sxx += c.disp[i] * c.disp[i], sxy += c.disp[i] * c.load[i];
  if (n < 5) throw std::runtime_error("fewer than 5 points on the rising branch of the curve");
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

double elastic_stiffness(const Curve& c) {
  auto [i0, ie] = elastic_branch(c);
  return slope(c, i0, ie);
}

double initial_stiffness(const Curve& c, double d_f) {
  std::size_t i0 = 0;
  while (i0 < c.load.size() && !(c.load[i0] > 0)) ++i0;
  if (i0 == c.load.size()) throw std::runtime_error("the footing never met resistance");
  // First peak: the largest load before the load first falls below half of the largest so far
  // (the first particle-scale failure), within kPeakWindow D_f of the first contact.
  std::size_t ip = i0;
  for (std::size_t i = i0; i < c.load.size() && c.disp[i] <= c.disp[i0] + kPeakWindow * d_f; ++i) {
    if (c.load[i] > c.load[ip]) ip = i;
    else if (c.load[i] < 0.5 * c.load[ip]) break;
  }
  std::size_t ih = i0;  // first row at half the first peak load
  while (c.load[ih] < 0.5 * c.load[ip]) ++ih;
  return slope(c, i0, ih);
}

// The reduced footing scene at a g-level with a ball-ball model (defaults otherwise). The REV's
// expansion uses plain linear contacts whatever the model (dem_core generate_rev), so one seed
// gives the same sample for both models (same balls, same positions), and only the bonds differ.
std::string footing_scene(double level, const std::string& model) {
  auto s = slurp(kSrc + "/tests/coupled/footing_stiffness.toml");
  std::ostringstream lv;
  lv << "\nlevel = " << level << "\n";
  replace_once(s, "\nlevel = 100\n", lv.str());
  // The initial part is all these checks need: stop at 0.05 D_f (the scene's own stop is 0.2 D_f).
  replace_once(s, "inertial_number = 2.5e-3", "inertial_number = 2.5e-3\ndepth_ratio = 0.05");
  replace_once(s, "[dem.specimen]",
               "[dem.ball_ball]\nmodel = \"" + model + "\"\n\n[dem.specimen]");
  return s;
}

void expect_finite_curve(const Curve& c, double d_f) {
  ASSERT_FALSE(c.disp.empty());
  for (std::size_t i = 0; i < c.disp.size(); ++i)
    ASSERT_TRUE(std::isfinite(c.disp[i]) && std::isfinite(c.load[i])) << "row " << i;
  EXPECT_GE(c.disp.back(), 0.05 * d_f * (1 - 1e-9));
  double peak = 0;
  for (double f : c.load) peak = std::max(peak, f);
  EXPECT_GT(peak, 0.0) << "the footing must meet resistance";
}

class GravityEquilibrium : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { dir_ = run_scene("gravity", slurp(kSrc + "/tests/coupled/gravity_small.toml")); }
  static fs::path dir_;
};
fs::path GravityEquilibrium::dir_;

}  // namespace

// Base reaction = total weight, FDM profile, interface balance: one run, three invariants.
TEST_F(GravityEquilibrium, BaseReactionFdmProfileAndInterfaceBalance) {
  auto h = read_columns(dir_ / "history_3_gravity.csv");
  double base = h.at("continuum.base_fz_N").back();
  double w = h.at("continuum.weight_N").back() + h.at("dem.weight_N").back();
  double err = (base - w) / w;
  std::cout << "[ figures  ] base reaction " << base << " N, DEM + FDM weight " << w << " N, error " << err << "\n";
  EXPECT_LT(std::abs(err), 5e-3);

  double imbalance = 0;
  for (double v : h.at("continuum.iface_imbalance")) imbalance = std::max(imbalance, v);
  std::cout << "[ figures  ] largest relative interface imbalance " << imbalance << "\n";
  EXPECT_LT(imbalance, 1e-12);

  // FDM: layers below the DEM block (depth > 2 mm), where the whole DEM weight has joined in.
  auto f = read_columns(dir_ / "fdm_profile_gravity.csv");
  int checked = 0;
  double worst = 0, worst_side = 0;
  for (std::size_t i = 0; i < f.at("depth_m").size(); ++i) {
    double e = f["szz_Pa"][i] / f["selfweight_szz_Pa"][i] - 1;
    if (f["depth_m"][i] > 2e-3) {
      worst = std::max(worst, std::abs(e));
      ++checked;
    } else {
      worst_side = std::max(worst_side, std::abs(e));
    }
  }
  std::cout << "[ figures  ] FDM layer sigma_zz against rho N g depth: below the block " << worst
            << " (largest relative error, " << checked << " layers), beside the block " << worst_side << "\n";
  EXPECT_GE(checked, 3);
  EXPECT_LT(worst, 0.02);
}

// DEM slabs (particle-based stress over the block's footprint, about 1.5 d_max thick) below the top
// two particle layers against rho_b N g depth. Measured (docs/paper-study.md): 6-9 % low on this
// 2 x 2 mm block with the traction-consistent interface bond forces (mean_contact: 8-13 % low).
// What remains is the band about one ball radius wide along each side face, where cutting the
// periodic REV removed the contacts across the face: it carries less vertical stress from the
// first step, and the side bonds take the difference in shear. The band's share scales with
// perimeter / area: on a 1 x 1 mm block the same measure is 13-21 % low.
TEST_F(GravityEquilibrium, DemSlabStressMatchesSelfWeight) {
  auto p = read_columns(dir_ / "dem_profile_gravity.csv");
  double worst = 0;
  int checked = 0;
  for (std::size_t i = 0; i < p.at("depth_m").size(); ++i) {
    if (p["depth_top_m"][i] < 2 * p["d_max_m"][i]) continue;  // top two particle layers
    double e = p["szz_Pa"][i] / p["selfweight_szz_Pa"][i] - 1;
    std::cout << "[ figures  ] DEM slab at " << p["depth_m"][i] << " m: " << p["szz_Pa"][i] << " Pa against "
              << p["selfweight_szz_Pa"][i] << " Pa (" << e << ")\n";
    worst = std::max(worst, std::abs(e));
    ++checked;
  }
  EXPECT_GE(checked, 2);
  EXPECT_LT(worst, 0.10);
}

TEST(CoupledFootingChecks, InitialStiffnessIndependentOfGLevel) {
  const double d_f = 0.8e-3;
  auto c1 = footing_curve(run_scene("g1", footing_scene(1, "softbond")));
  auto c200 = footing_curve(run_scene("g200", footing_scene(200, "softbond")));
  expect_finite_curve(c1, d_f);
  expect_finite_curve(c200, d_f);
  double k1 = initial_stiffness(c1, d_f), k200 = initial_stiffness(c200, d_f);
  double e1 = elastic_stiffness(c1), e200 = elastic_stiffness(c200);
  std::cout << "[ figures  ] initial stiffness k50 1 g " << k1 << " N/m, 200 g " << k200 << " N/m, ratio " << k200 / k1
            << "; k_e 1 g " << e1 << " N/m, 200 g " << e200 << " N/m, ratio " << e200 / e1 << "\n";
  EXPECT_GT(k1, 0);
  EXPECT_LT(std::abs(k200 / k1 - 1), 0.10);
  EXPECT_GT(e1, 0);
  EXPECT_LT(std::abs(e200 / e1 - 1), 0.10);
}

// Same seed = same sample for both models: the expansion uses linear contacts (the soft bond's
// unbonded law without moments, with bit-identical K_n, K_s), the servo and the critical step
// count a parallel bond's linear part only where its contact is active, and a bond across a gap
// is the same spring set in both models. So up to the first
// bond failure the two footing curves are the same curve, and k_e must agree; after it the soft
// bond softens and the parallel bond breaks. Measured on this scene (seed 3): k_e 6.742e5 N/m in
// both (23 rows, 0.29 um, first failure at 0.204 N), k50 9.70e5 against 1.05e6 N/m (+7.8 %).
// Seeds 1, 2, 4, 5, 6: k_e equal to 4 digits in each; k50 ratios 1.22, 1.05, 3.42, 0.98, 1.00:
// k50 runs past the first failure, where the two laws differ by design (docs/paper-study.md).
TEST(CoupledFootingChecks, SoftBondAndParallelBondInitialStiffnessAgree) {
  const double d_f = 0.8e-3;
  auto sb = footing_curve(run_scene("sbm", footing_scene(100, "softbond")));
  auto pb = footing_curve(run_scene("pbm", footing_scene(100, "pbond")));
  expect_finite_curve(sb, d_f);
  expect_finite_curve(pb, d_f);
  auto [s0, se] = elastic_branch(sb);
  auto [p0, pe] = elastic_branch(pb);
  double ks = slope(sb, s0, se), kp = slope(pb, p0, pe);
  // The elastic branches row by row: same footing displacement, same load.
  double worst = 0;
  const std::size_t rows = std::min(se - s0, pe - p0) + 1;
  for (std::size_t k = 0; k < rows; ++k) {
    worst = std::max(worst, std::abs(sb.load[s0 + k] - pb.load[p0 + k]) / std::max(sb.load[s0 + k], 1e-12));
    worst = std::max(worst, std::abs(sb.disp[s0 + k] - pb.disp[p0 + k]) / std::max(std::abs(sb.disp[s0 + k]), 1e-30));
  }
  std::cout << "[ figures  ] elastic branch: SBM " << se - s0 + 1 << " rows to " << sb.load[se] << " N, PBM "
            << pe - p0 + 1 << " rows to " << pb.load[pe] << " N; largest relative load or displacement difference " << worst << "\n";
  std::cout << "[ figures  ] initial stiffness k_e SBM " << ks << " N/m, PBM " << kp << " N/m, ratio " << kp / ks
            << "; k50 SBM " << initial_stiffness(sb, d_f) << ", PBM " << initial_stiffness(pb, d_f) << " N/m\n";
  EXPECT_GT(ks, 0);
  EXPECT_LT(std::abs(kp / ks - 1), 0.10);
  EXPECT_LT(worst, 1e-6) << "the two models must give the same curve before any bond fails";
}
