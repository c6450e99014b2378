// The coordinator's stage histories (coordinator/core/history.hpp) through io::CsvSeries: the
// bytes of the hand-written writer they replaced (the golden data of tests/golden fix them),
// and resume from a checkpoint's position.
#include "coordinator/core/history.hpp"
#include "demfdm/io/error.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <sstream>

namespace demfdm::coord {
namespace {

namespace fs = std::filesystem;

struct Dir {
  fs::path path;
  Dir() {
    const auto* t = ::testing::UnitTest::GetInstance()->current_test_info();
    path = fs::temp_directory_path() / ("demfdm_history_" + std::string(t->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~Dir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

schema::Stage stage(const std::string& name) {
  schema::Stage st;
  st.name = name;
  return st;
}

// Reports of step k: the DEM reports three values (dt_s missing at odd steps), the continuum
// none; times and values with long decimal expansions, a negative zero, a large count.
std::map<std::string, NodeReport> reports(std::int64_t k) {
  std::map<std::string, NodeReport> r;
  r["dem"].time = 0.1 * static_cast<double>(k) + 1e-9;
  r["dem"].values = {{"ratio", 1.0 / (3.0 + static_cast<double>(k))}, {"balls", 38075.0}, {"footing_fz_N", -0.0}};
  if (k % 2 == 0) r["dem"].values["dt_s"] = 1.7847616300250014e-08;
  r["continuum"].time = 2.9800340176287996e-05 * static_cast<double>(k);
  return r;
}

// The writer the class replaced (coordinator/main.cpp before issue 15 item 4), as the reference.
std::string reference(std::int64_t first, std::int64_t last) {
  std::ostringstream out;
  const auto r0 = reports(first);
  std::vector<std::pair<std::string, std::string>> cols;
  for (auto& [role, r] : r0)
    for (auto& [k, v] : r.values) cols.push_back({role, k});
  out << "step";
  for (auto& [role, r] : r0) out << "," << role << ".time_s";
  for (auto& [role, k] : cols) out << "," << role << "." << k;
  out << "\n";
  for (std::int64_t s = first; s <= last; ++s) {
    const auto reps = reports(s);
    out << s;
    out << std::setprecision(17);
    for (auto& [role, r] : reps) out << "," << r.time;
    for (auto& [role, k] : cols) {
      double v = std::nan("");
      auto it = reps.find(role);
      if (it != reps.end()) {
        auto jt = it->second.values.find(k);
        if (jt != it->second.values.end()) v = jt->second;
      }
      out << "," << v;
    }
    out << "\n";
  }
  return out.str();
}

TEST(StageHistory, WritesTheBytesOfTheGoldenData) {
  Dir d;
  StageHistory h(d.path.string());
  for (std::int64_t k = 4; k <= 9; ++k) h.record(stage("gravity"), k, reports(k));
  const std::string text = slurp(d.path / "history_0_gravity.csv");
  EXPECT_EQ(text, reference(4, 9));
  EXPECT_EQ(text.substr(0, text.find('\n')),
            "step,continuum.time_s,dem.time_s,dem.balls,dem.dt_s,dem.footing_fz_N,dem.ratio");
  EXPECT_NE(text.find(",nan,"), std::string::npos) << "a value missing from a later report";
  // The next stage begins the next file.
  h.record(stage("penetrate"), 10, reports(10));
  EXPECT_TRUE(fs::exists(d.path / "history_1_penetrate.csv"));
  EXPECT_EQ(h.state().file, "history_1_penetrate.csv");
}

TEST(StageHistory, ResumeFromACheckpointGivesTheUninterruptedFile) {
  Dir d;
  HistoryState at;
  {
    StageHistory h(d.path.string());
    for (std::int64_t k = 0; k <= 3; ++k) h.record(stage("cycle"), k, reports(k));
    at = h.state();
    EXPECT_EQ(at.bytes, fs::file_size(d.path / "history_0_cycle.csv"));
    for (std::int64_t k = 4; k <= 5; ++k) h.record(stage("cycle"), k, reports(k));  // lost with a crash
  }
  StageHistory resumed(d.path.string());
  resumed.restore(at);
  EXPECT_EQ(fs::file_size(d.path / "history_0_cycle.csv"), at.bytes);
  for (std::int64_t k = 4; k <= 8; ++k) resumed.record(stage("cycle"), k, reports(k));
  EXPECT_EQ(slurp(d.path / "history_0_cycle.csv"), reference(0, 8));
}

TEST(StageHistory, RestoreRefusesAFileThatIsNotTheCheckpoints) {
  Dir d;
  HistoryState at;
  {
    StageHistory h(d.path.string());
    for (std::int64_t k = 0; k <= 2; ++k) h.record(stage("cycle"), k, reports(k));
    at = h.state();
  }
  const std::string before = slurp(d.path / "history_0_cycle.csv");
  HistoryState other = at;
  other.cols[1].second = "dt_critical_s";
  EXPECT_THROW(StageHistory(d.path.string()).restore(other), CheckpointError);
  other = at;
  other.bytes += 1;  // rows the checkpoint counts are missing
  EXPECT_THROW(StageHistory(d.path.string()).restore(other), io::IoError);
  other = at;
  other.file = "history_0_absent.csv";
  EXPECT_THROW(StageHistory(d.path.string()).restore(other), CheckpointError);
  EXPECT_EQ(slurp(d.path / "history_0_cycle.csv"), before) << "a refused restore leaves the file as found";
}

}  // namespace
}  // namespace demfdm::coord
