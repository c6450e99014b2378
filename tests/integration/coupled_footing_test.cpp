// The reduced coupled footing scene (scenes/footing_small.toml) end to end through launch/run:
// three processes, all six stages of the paper's procedure, a load-displacement curve, and
// action = reaction at the interface to round-off.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <map>

#include "tests/integration/process.hpp"
#include "tests/integration/scratch.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;

// Reads a CSV with a header into columns by name.
std::map<std::string, std::vector<double>> read_columns(const fs::path& p) {
  std::ifstream f(p);
  std::string line;
  std::getline(f, line);
  std::vector<std::string> names;
  std::stringstream hs(line);
  std::string cell;
  while (std::getline(hs, cell, ',')) names.push_back(cell);
  std::map<std::string, std::vector<double>> cols;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    for (std::size_t i = 0; std::getline(ss, cell, ','); ++i) cols[names.at(i)].push_back(std::stod(cell));
  }
  return cols;
}
}  // namespace

TEST(CoupledFooting, SmallSceneRunsAllStagesWithBalancedInterfaceForces) {
  auto runs = scratch("demfdm-footing-" + std::to_string(getpid()));
  fs::remove_all(runs);
  fs::create_directories(runs);
  auto dir = runs / "run";
  auto p = spawn({"/bin/bash", kSrc + "/launch/run", kSrc + "/scenes/footing_small.toml", "--no-build", "--run-dir", dir.string()},
                 {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()}, (runs / "out.txt").string());
  auto st = wait_for(p, 300);
  ASSERT_TRUE(st) << "the run did not finish in 300 s";
  ASSERT_EQ(exit_code(*st), 0) << read_file((runs / "out.txt").string());
  for (auto f : {"dem.h5", "particles.xmf", "bonds.xmf", "fdm.h5", "mesh.xmf", "dem_history.csv", "fdm_history.csv",
                 "traffic.lcmlog", "summary.txt", "history_5_penetrate.csv"})
    EXPECT_TRUE(fs::exists(dir / f)) << f;
  auto h = read_columns(dir / "history_5_penetrate.csv");
  ASSERT_TRUE(h.count("dem.footing_disp_m") && h.count("dem.footing_fz_N") && h.count("continuum.iface_imbalance"));
  const double d_f = 0.4e-3;
  auto& disp = h["dem.footing_disp_m"];
  auto& load = h["dem.footing_fz_N"];
  // The stage ends when the footing has moved 0.2 D_f (within one coupling step's travel).
  EXPECT_GE(disp.back(), 0.2 * d_f * (1 - 1e-9));
  EXPECT_LT(disp.back(), 0.2 * d_f * 1.01);
  double peak = 0;
  for (std::size_t i = 0; i < load.size(); ++i) {
    ASSERT_TRUE(std::isfinite(load[i]) && std::isfinite(disp[i])) << "row " << i;
    peak = std::max(peak, load[i]);
  }
  EXPECT_GT(peak, 0.0) << "the footing must meet resistance";
  double imbalance = 0;
  for (double v : h["continuum.iface_imbalance"]) imbalance = std::max(imbalance, v);
  std::cout << "[ figures  ] footing_small: peak load " << peak << " N at 0.2 D_f travel " << disp.back()
            << " m; largest relative interface imbalance " << imbalance << "\n";
  EXPECT_LT(imbalance, 1e-12) << "sum of forces received must equal the DEM's total to round-off";
}
