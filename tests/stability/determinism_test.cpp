// Determinism of a whole coupled run (DEVELOPERS.md: same scene + same seed + same thread count
// = same results, bit for bit; issue 17 item 3, with run.thread_independent: the same at any
// thread count):
// scenes/footing_small.toml (generation, servo, bonds, replication, coupled gravity,
// penetration; three processes over the bus) run with two OpenMP threads per node and with one;
// every CSV of the two run folders (node histories, stress profiles, the coordinator's per-step
// histories, specimen stages) must be identical byte for byte.
// The first run is also the golden data of a reduced coupled scene (issue 15 item 1): its CSVs
// must match tests/golden/data/footing_small.golden (per file: size, line count and FNV-1a 64
// of the bytes, and every 200th line in full, so that a difference can be located).
#include <gtest/gtest.h>

#include <algorithm>
#include <cinttypes>

#include "demfdm/io/state_file.hpp"
#include "tests/golden/golden.hpp"
#include "tests/stability/scene_run.hpp"

using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
// Golden text of a run folder's CSV files (sorted by name).
std::string csv_digest(const fs::path& dir) {
  std::vector<fs::path> files;
  for (auto& e : fs::directory_iterator(dir))
    if (e.path().extension() == ".csv") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::ostringstream o;
  o << "# demfdm golden data: the CSV files of scenes/footing_small.toml with threads = 2\n"
    << "# (tests/stability/determinism_test.cpp): size, lines, FNV-1a 64, every 200th line and the last\n";
  for (const fs::path& f : files) {
    const std::string text = slurp(f);
    const auto ls = demfdm::golden::lines(text);
    char h[32];
    std::snprintf(h, sizeof h, "%016" PRIx64, demfdm::io::fnv1a64(text.data(), text.size()));
    const std::string name = f.filename().string();
    o << "file " << name << " bytes " << text.size() << " lines " << ls.size() << " fnv1a64 " << h << "\n";
    for (std::size_t i = 0; i < ls.size(); ++i)
      if (i % 200 == 0 || i + 1 == ls.size()) o << name << ":" << i + 1 << " " << ls[i] << "\n";
  }
  return o.str();
}

}  // namespace

TEST(Determinism, CoupledFootingRunIsBitIdenticalAtOneAndTwoThreads) {
  auto one = slurp(kSrc + "/scenes/footing_small.toml");
  replace_once(one, "threads = 1", "threads = 1\nthread_independent = true");
  auto text = one;
  replace_once(text, "threads = 1", "threads = 2");
  auto a = run_scene_text(kSrc, kBin, "determinism-a", text, 80);
  ASSERT_EQ(a.code, 0) << a.output;
  auto b = run_scene_text(kSrc, kBin, "determinism-b", one, 80);
  ASSERT_EQ(b.code, 0) << b.output;
  int compared = 0;
  for (auto& e : fs::directory_iterator(a.dir)) {
    if (e.path().extension() != ".csv") continue;
    auto other = b.dir / e.path().filename();
    ASSERT_TRUE(fs::exists(other)) << e.path().filename() << " only in the first run";
    EXPECT_EQ(slurp(e.path()), slurp(other)) << e.path().filename() << " differs between 2 threads and 1";
    ++compared;
  }
  const std::string digest = csv_digest(a.dir);
  if (demfdm::golden::update_mode()) {
    demfdm::golden::write("footing_small.golden", digest);
    std::cout << "[ golden   ] wrote " << demfdm::golden::data_dir() << "/footing_small.golden\n";
  } else {
    for (const std::string& d : demfdm::golden::compare("footing_small.golden", digest, 6))
      ADD_FAILURE() << "the reduced coupled footing's histories differ from their golden data: " << d;
  }
  std::cout << "[ figures  ] " << compared << " CSV files identical byte for byte\n";
  EXPECT_GE(compared, 8);
  if (!::testing::Test::HasFailure()) {
    a.clean();
    b.clean();
  }
}
