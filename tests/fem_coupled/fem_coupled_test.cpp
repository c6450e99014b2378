// fem_node's interface relaxation in a coupled run (docs/continuum-solvers.md). Scene:
// soft_gravity_fem.toml (tests/coupled/gravity_small.toml with fem_node, E = 1e8 Pa, nu = 0.25,
// ratio 1e-3 in 4000 steps), run end to end through launch/run.
//  * Unrelaxed (continuum.relaxation = 1): the static continuum's coupling gain exceeds 1 (the
//    node warns), the partitioned iteration diverges: either the DEM's blow-up guard stops the
//    run (exit 3, blowup report), or the block is thrown off the walls and the interface force
//    is exactly 0 in more than half of the steps - the case is hard, so the next test can fail.
//  * Automatic relaxation (the default): exit 0, no blow-up report, every history value finite;
//    the gravity stage ends on its criterion before the budget (DEM ratio and FEM out-of-balance
//    ratio < 1e-3); the interface springs were installed; the interface force is never exactly 0
//    after the first tenth of the stage (the block keeps contact with the walls); base reaction =
//    DEM + FEM weight within 1 %; interface action = reaction to 1e-12.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "tests/stability/scene_run.hpp"

using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
constexpr double kBudget = 4000;  // gravity stage steps in soft_gravity_fem.toml

std::string scene() { return slurp(kSrc + "/tests/fem_coupled/soft_gravity_fem.toml"); }

std::size_t zero_rows(const std::vector<double>& v, std::size_t from) {
  std::size_t n = 0;
  for (std::size_t i = from; i < v.size(); ++i) n += v[i] == 0.0;
  return n;
}
}  // namespace

TEST(FemCoupled, UnrelaxedSoftContinuumFails) {
  auto text = scene();
  replace_once(text, "executable = \"fem_node\"", "executable = \"fem_node\"\nrelaxation = 1.0");
  auto r = run_scene_text(kSrc, kBin, "fem-unrelaxed", text, 55);
  ASSERT_TRUE(r.code == 0 || r.code == 3) << r.output;
  if (r.code == 3) {
    EXPECT_TRUE(fs::exists(r.dir / "blowup_dem.txt") || fs::exists(r.dir / "blowup_continuum.txt")) << r.output;
  } else {
    auto h = read_columns(r.dir / "history_3_gravity.csv");
    const auto& fz = h.at("continuum.iface_fz_N");
    const std::size_t zero = zero_rows(fz, 0);
    std::printf("[ figures  ] unrelaxed: interface force exactly 0 in %zu of %zu rows, coupling gain %.4g\n", zero,
                fz.size(), h.at("continuum.coupling_gain").back());
    EXPECT_GT(zero, fz.size() / 2) << "the block should lose contact with the walls";
    EXPECT_GT(h.at("continuum.coupling_gain").back(), 1.0) << "omega = 1 is beyond 2 / (1 + lambda)";
  }
  EXPECT_NE(slurp(r.dir / "continuum.log").find("beyond the stability limit"), std::string::npos);
  if (!HasFailure()) r.clean();
}

TEST(FemCoupled, AutomaticRelaxationConvergesTheGravityStage) {
  auto r = run_scene_text(kSrc, kBin, "fem-relaxed", scene(), 55);
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_FALSE(fs::exists(r.dir / "blowup_dem.txt"));
  EXPECT_FALSE(fs::exists(r.dir / "blowup_continuum.txt"));
  auto h = read_columns(r.dir / "history_3_gravity.csv");
  for (auto& [name, col] : h)
    for (std::size_t i = 0; i < col.size(); ++i) ASSERT_TRUE(std::isfinite(col[i])) << name << " row " << i;
  const auto& step = h.at("step");
  const auto n = step.size();
  ASSERT_GT(n, 10u);
  const double steps = step.back() - step.front() + 1;
  std::printf("[ figures  ] gravity stage: %.0f steps of a %.0f budget\n", steps, kBudget);
  EXPECT_LT(steps, kBudget) << "the stage must end on its criterion, not on its budget";
  EXPECT_LT(h.at("dem.ratio").back(), 1e-3);
  EXPECT_LT(h.at("continuum.ratio").back(), 1e-3);

  const double refactorisations = h.at("continuum.refactorisations").back();
  std::printf("[ figures  ] K + D refactorised %.0f times\n", refactorisations);
  EXPECT_GE(refactorisations, 1.0) << "the interface springs must have been installed";

  const auto& fz = h.at("continuum.iface_fz_N");
  const std::size_t zero = zero_rows(fz, n / 10);
  std::printf("[ figures  ] rows with zero interface force after the first tenth: %zu of %zu\n", zero, n - n / 10);
  EXPECT_EQ(zero, 0u) << "the DEM block lost contact with the continuum's walls";

  const double base = h.at("continuum.base_fz_N").back();
  const double w = h.at("continuum.weight_N").back() + h.at("dem.weight_N").back();
  std::printf("[ figures  ] base reaction %.6g N, DEM + FEM weight %.6g N, error %.3g\n", base, w, (base - w) / w);
  EXPECT_LT(std::abs(base - w), 0.01 * w);
  double imbalance = 0;
  for (double v : h.at("continuum.iface_imbalance")) imbalance = std::max(imbalance, v);
  EXPECT_LT(imbalance, 1e-12);
  if (!HasFailure()) r.clean();
}
