// Specimen preparation (generate, servo, bond, replicate) runs on its own step factor and damping
// (dem.specimen.dt_safety, dem.specimen.damping) and counts its rules in critical steps
// (docs/theory.md 4.11). So the run's knobs, which act from the first later stage, leave the
// bonded block bit-identical: positions, radii, velocities, the bond list with states and forces,
// and the time at the end of the replicate stage. The specimen's own step factor does change it
// (the comparison can fail), and a preparation procedure that misses its criterion stops the run
// with a non-zero exit naming the procedure, its criterion and what it reached.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "tests/integration/process.hpp"
#include "tests/io/io_test_util.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;
using demfdm::io::test::H5Reader;
using demfdm::io::test::slurp;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;
const fs::path kRoot = fs::temp_directory_path() / ("demfdm-specimen-" + std::to_string(getpid()));

std::string scene_text() {
  std::ifstream f(kSrc + "/tests/specimen/prep.toml");
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void replace_once(std::string& s, const std::string& from, const std::string& to) {
  const auto at = s.find(from);
  if (at == std::string::npos) throw std::runtime_error("prep.toml has no '" + from + "'");
  s.replace(at, from.size(), to);
}

struct RunResult {
  fs::path dir;
  int code = -1;
  std::string output;
};

// The scene with each (from, to) replaced once, run through launch/run.
RunResult run_variant(const std::string& name, const std::vector<std::pair<std::string, std::string>>& edits) {
  auto text = scene_text();
  for (auto& [from, to] : edits) replace_once(text, from, to);
  fs::create_directories(kRoot);
  const auto scene = kRoot / (name + ".toml");
  std::ofstream(scene) << text;
  RunResult r;
  r.dir = kRoot / name;
  const auto out = kRoot / (name + ".out");
  auto p = spawn({"/bin/bash", kSrc + "/launch/run", scene.string(), "--no-build", "--run-dir", r.dir.string()},
                 {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()}, out.string());
  auto st = wait_for(p, 60);
  if (!st) {
    kill_and_reap(p);
    throw std::runtime_error(name + ": the run did not finish in 60 s");
  }
  r.code = exit_code(*st);
  r.output = read_file(out.string());
  return r;
}

// Frame 2 of dem.h5 is the end of the replicate stage (generate, servo, replicate: one frame each).
constexpr const char* kBlock = "/frames/000002";
const char* const kF64[] = {"particles/position", "particles/radius", "particles/velocity", "bonds/force"};

// Every dataset of the frame, and its time, bit for bit; returns the first difference or "".
std::string block_difference(const fs::path& a, const fs::path& b, const std::string& frame) {
  H5Reader ra(a / "dem.h5"), rb(b / "dem.h5");
  const double ta = ra.attr_f64(frame, "time"), tb = rb.attr_f64(frame, "time");
  if (std::memcmp(&ta, &tb, sizeof(double)) != 0)
    return frame + "@time: " + std::to_string(ta) + " against " + std::to_string(tb);
  for (const char* d : kF64) {
    const auto x = ra.read_f64(frame + "/" + d), y = rb.read_f64(frame + "/" + d);
    if (x.size() != y.size()) return frame + "/" + d + ": " + std::to_string(x.size()) + " against " + std::to_string(y.size()) + " values";
    for (std::size_t i = 0; i < x.size(); ++i)
      if (std::memcmp(&x[i], &y[i], sizeof(double)) != 0) {
        std::ostringstream s;
        s.precision(17);
        s << frame << "/" << d << "[" << i << "]: " << x[i] << " against " << y[i];
        return s.str();
      }
  }
  if (ra.read_i32(frame + "/bonds/nodes") != rb.read_i32(frame + "/bonds/nodes")) return frame + "/bonds/nodes differ";
  if (ra.read_u8(frame + "/bonds/state") != rb.read_u8(frame + "/bonds/state")) return frame + "/bonds/state differs";
  if (ra.read_i64(frame + "/particles/id") != rb.read_i64(frame + "/particles/id")) return frame + "/particles/id differ";
  return "";
}

class SpecimenInvariance : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    base_ = run_variant("base", {});
    // The run's step factor, damping and a fixed step, and a later stage's damping.
    knobs_ = run_variant("knobs", {{"dt_safety = 0.8\ndamping = 0.7", "dt_safety = 0.4\ndamping = 0.3\ndt_fixed = 2e-8"},
                                   {"steps = 200\n", "steps = 200\ndamping = 0.05\n"}});
    // The specimen's own step factor: another integration of the same procedure.
    own_ = run_variant("own", {{"servo_budget = 16000", "servo_budget = 16000\ndt_safety = 0.4"}});
  }
  static void TearDownTestSuite() {
    if (!::testing::UnitTest::GetInstance()->Failed()) fs::remove_all(kRoot);
  }
  static RunResult base_, knobs_, own_;
};
RunResult SpecimenInvariance::base_, SpecimenInvariance::knobs_, SpecimenInvariance::own_;

TEST_F(SpecimenInvariance, RunKnobsLeaveTheBondedBlockBitIdentical) {
  ASSERT_EQ(base_.code, 0) << base_.output;
  ASSERT_EQ(knobs_.code, 0) << knobs_.output;
  EXPECT_EQ(block_difference(base_.dir, knobs_.dir, kBlock), "");
  // The knobs do act after the replicate stage (frame 3: end of the settle stage).
  EXPECT_NE(block_difference(base_.dir, knobs_.dir, "/frames/000003"), "");
  // specimen_stages.csv (steps, ratios, porosity, Z, stresses of each procedure) is the same text.
  EXPECT_EQ(slurp(base_.dir / "specimen_stages.csv"), slurp(knobs_.dir / "specimen_stages.csv"));
}

TEST_F(SpecimenInvariance, TheSpecimenStepFactorChangesTheBlock) {
  ASSERT_EQ(own_.code, 0) << own_.output;
  EXPECT_NE(block_difference(base_.dir, own_.dir, kBlock), "");
}

// A procedure that misses its criterion within its budget stops the run (exit != 0) and says
// which procedure, which criterion and what it reached; no later stage runs.
TEST(SpecimenPreparation, MissedCriterionStopsTheRun) {
  auto gen = run_variant("gen_budget", {{"servo_budget = 16000", "servo_budget = 16000\nincrement_budget = 2"}});
  EXPECT_NE(gen.code, 0) << gen.output;
  const auto log = slurp(gen.dir / "dem.log");
  EXPECT_NE(log.find("specimen preparation did not reach its criterion"), std::string::npos) << log;
  EXPECT_NE(log.find("did not reach the unbalanced ratio"), std::string::npos) << log;
  EXPECT_FALSE(fs::exists(gen.dir / "history_1_servo.csv"));

  auto servo = run_variant("servo_budget", {{"servo_budget = 16000", "servo_budget = 8"}});
  EXPECT_NE(servo.code, 0) << servo.output;
  const auto slog = slurp(servo.dir / "dem.log");
  EXPECT_NE(slog.find("servo to (6250, 6250, 12500) Pa did not converge"), std::string::npos) << slog;
  EXPECT_NE(slog.find("reached ratio"), std::string::npos) << slog;
  EXPECT_FALSE(fs::exists(servo.dir / "history_2_replicate.csv"));
}
}  // namespace
