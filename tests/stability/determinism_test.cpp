// Determinism of a whole coupled run (DEVELOPERS.md: same scene + same seed + same thread count
// = same results, bit for bit): scenes/footing_small.toml (generation, servo, bonds,
// replication, coupled gravity, penetration; three processes over the bus) run twice with two
// OpenMP threads per node; every CSV of the two run folders (node histories, stress profiles,
// the coordinator's per-step histories, specimen stages) must be identical byte for byte.
#include <gtest/gtest.h>

#include "tests/stability/scene_run.hpp"

using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
}  // namespace

TEST(Determinism, CoupledFootingRunIsBitIdenticalWithTwoThreads) {
  auto text = slurp(kSrc + "/scenes/footing_small.toml");
  replace_once(text, "threads = 1", "threads = 2");
  auto a = run_scene_text(kSrc, kBin, "determinism-a", text, 80);
  ASSERT_EQ(a.code, 0) << a.output;
  auto b = run_scene_text(kSrc, kBin, "determinism-b", text, 80);
  ASSERT_EQ(b.code, 0) << b.output;
  int compared = 0;
  for (auto& e : fs::directory_iterator(a.dir)) {
    if (e.path().extension() != ".csv") continue;
    auto other = b.dir / e.path().filename();
    ASSERT_TRUE(fs::exists(other)) << e.path().filename() << " only in the first run";
    EXPECT_EQ(slurp(e.path()), slurp(other)) << e.path().filename() << " differs between the two runs";
    ++compared;
  }
  std::cout << "[ figures  ] " << compared << " CSV files identical byte for byte\n";
  EXPECT_GE(compared, 8);
  if (!::testing::Test::HasFailure()) {
    a.clean();
    b.clean();
  }
}
