// Tests of the traffic tools (demfdm_log summary / export) and of demfdm_replay, on a small
// log recorded in the test itself: lcm-logger records a 12-step scripted coupled run of
// fdm_node driven by the conformance harness (in-process coordinator and DEM), with faults
// injected into the solver (one duplicated kin, the first hello dropped).
#include <csignal>
#include <fstream>
#include <regex>
#include <sstream>

#include "tests/conformance/harness.hpp"

using namespace demfdm;
using namespace demfdm::conformance;

namespace {

std::string g_skip;
const std::string kBin = DEMFDM_BIN_DIR;

std::string which(const std::string& prog) {
  std::stringstream path(std::getenv("PATH") ? std::getenv("PATH") : "/usr/bin:/bin");
  std::string d;
  while (std::getline(path, d, ':'))
    if (!d.empty() && ::access((d + "/" + prog).c_str(), X_OK) == 0) return d + "/" + prog;
  return "";
}

// Runs a program to the end (30 s at most); returns (exit code, stdout+stderr).
std::pair<int, std::string> run_cmd(const std::vector<std::string>& argv, const std::string& out_file) {
  std::remove(out_file.c_str());
  auto p = demfdm::testing::spawn(argv, {}, out_file);
  auto st = demfdm::testing::wait_for(p, 30.0);
  if (!st) {
    demfdm::testing::kill_and_reap(p);
    return {-1, demfdm::testing::read_file(out_file)};
  }
  return {demfdm::testing::exit_code(*st), demfdm::testing::read_file(out_file)};
}

class TrafficLog : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!g_skip.empty()) return;
    dir_ = fs::temp_directory_path() / ("demfdm-traffic-" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    log_ = (dir_ / "traffic.lcmlog").string();
    std::string logger = which("lcm-logger");
    ASSERT_FALSE(logger.empty()) << "lcm-logger not found in PATH";
    std::mt19937_64 rng(std::random_device{}());
    std::string url = "udpm://239.255.76.67:" + std::to_string(20000 + rng() % 40000) + "?ttl=0";
    auto lp = demfdm::testing::spawn({logger, "--lcm-url=" + url + "&recv_buf_size=4194304", "-q", log_}, {},
                                     (dir_ / "logger.out").string());
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    {
      Harness h({kBin + "/fdm_node"}, column_scene(false, 1e-7),
                {"DEMFDM_FAULT=dup:DEMFDM_IFACE_KIN:5,drop:DEMFDM_HELLO:1"}, url);
      recorded_ = scripted_run(h);
      EXPECT_EQ(h.shutdown(2.0), 0);
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    ::kill(lp.pid, SIGINT);
    if (!demfdm::testing::wait_for(lp, 3.0)) demfdm::testing::kill_and_reap(lp);
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    if (!dir_.empty()) fs::remove_all(dir_, ec);
  }
  void SetUp() override {
    if (!g_skip.empty()) GTEST_SKIP() << g_skip;
    ASSERT_TRUE(fs::exists(log_)) << "no traffic log recorded";
    ASSERT_EQ(recorded_.size(), 13u);
  }
  static inline fs::path dir_;
  static inline std::string log_;
  static inline std::vector<proto::Kinematics> recorded_;  // kin(-1..11) as the harness received them
};

TEST_F(TrafficLog, SummaryCountsStepsGapsResendsAndLatency) {
  auto [code, out] = run_cmd({kBin + "/demfdm_log", "summary", log_}, (dir_ / "summary.txt").string());
  ASSERT_EQ(code, 0) << out;
  std::cout << out;
  EXPECT_NE(out.find("interface: 13 steps with kinematics, 12 steps with forces"), std::string::npos) << out;
  // sender table row: name messages seq-range gaps resends foreign
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out, m, std::regex(R"(\ncontinuum\s+(\d+)\s+\d+-\d+\s+(\d+)\s+(\d+)\s+(\d+))"))) << out;
  EXPECT_EQ(std::stoi(m[2]), 1) << "the dropped first hello is one seq gap";
  EXPECT_GE(std::stoi(m[3]), 1) << "the duplicated kin is a resend";
  ASSERT_TRUE(std::regex_search(out, m, std::regex(R"(\ndem\s+(\d+)\s+\d+-\d+\s+(\d+)\s+(\d+))"))) << out;
  EXPECT_EQ(std::stoi(m[2]), 0) << "the DEM lost nothing";
  EXPECT_NE(out.find("DEMFDM_IFACE_FORCE"), std::string::npos);
  ASSERT_TRUE(std::regex_search(out, m, std::regex(R"(continuum force\(k\) -> kin\(k\):\s+(\d+) steps)"))) << out;
  EXPECT_EQ(std::stoi(m[1]), 12);
}

TEST_F(TrafficLog, ExportWritesTheRecordedInterfaceData) {
  std::string csv = (dir_ / "steps.csv").string();
  auto [code, out] = run_cmd({kBin + "/demfdm_log", "export", log_, "--steps", "3:5", "--out", csv},
                         (dir_ / "export.txt").string());
  ASSERT_EQ(code, 0) << out;
  std::ifstream f(csv);
  std::string line;
  std::getline(f, line);
  EXPECT_EQ(line, "step,kind,point,x,y,z,vx,vy,vz,fx,fy,fz,stiffness");
  const std::size_t n = recorded_[0].positions.size() / 3;
  std::size_t kin_rows = 0, force_rows = 0;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    std::vector<std::string> c;
    std::string cell;
    while (std::getline(ss, cell, ',')) c.push_back(cell);
    long step = std::stol(c[0]);
    std::size_t p = std::stoul(c[2]);
    ASSERT_TRUE(step >= 3 && step <= 5) << line;
    if (c[1] == "kin") {
      ++kin_rows;
      const auto& k = recorded_[static_cast<std::size_t>(step + 1)];
      for (int d = 0; d < 3; ++d) {
        EXPECT_EQ(std::stod(c[3 + d]), k.positions[3 * p + d]) << line;  // 17 digits: exact round trip
        EXPECT_EQ(std::stod(c[6 + d]), k.velocities[3 * p + d]) << line;
      }
    } else {
      ASSERT_EQ(c[1], "force");
      ++force_rows;
    }
  }
  EXPECT_EQ(kin_rows, 3 * n);
  EXPECT_EQ(force_rows, 3 * n);
  auto [bad, msg] = run_cmd({kBin + "/demfdm_log", "export", log_, "--steps", "5:3", "--out", csv},
                        (dir_ / "bad.txt").string());
  EXPECT_EQ(bad, 2);
  EXPECT_NE(msg.find("--steps"), std::string::npos) << msg;
}

TEST_F(TrafficLog, ReplayIsBitIdenticalForTheSameSolverAndReportsADifferenceForAnother) {
  auto [code, out] = run_cmd({kBin + "/demfdm_replay", log_, "--solver", kBin + "/fdm_node", "--expect-identical"},
                         (dir_ / "replay_fdm.txt").string());
  std::cout << out;
  EXPECT_EQ(code, 0) << out;
  EXPECT_NE(out.find("replay: 13 steps compared, 13 bit-identical, max |dx| = 0 m, max |dv| = 0"), std::string::npos)
      << out;
  auto [code2, out2] = run_cmd({kBin + "/demfdm_replay", log_, "--solver", kBin + "/fem_node"},
                           (dir_ / "replay_fem.txt").string());
  std::cout << out2;
  EXPECT_EQ(code2, 0) << out2;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(out2, m, std::regex(R"(replay: 13 steps compared, (\d+) bit-identical, max \|dx\| = (\S+) m)")))
      << out2;
  EXPECT_LT(std::stoi(m[1]), 13);
  EXPECT_GT(std::stod(m[2]), 0.0);
  // The FDM in static mode has not converged after 12 steps; the FEM answer is exact, so the
  // difference is bounded by the static displacement scale p_max Hc / M (p_max = 1.2e5 Pa).
  EXPECT_LT(std::stod(m[2]), 1.2e5 * 2e-3 / (kE * (1 - kNu) / ((1 + kNu) * (1 - 2 * kNu))));
  auto [code3, out3] = run_cmd({kBin + "/demfdm_replay", log_, "--solver", kBin + "/fem_node", "--expect-identical"},
                           (dir_ / "replay_fem2.txt").string());
  EXPECT_EQ(code3, 1) << out3;
}

// launch/run honours [output]: traffic_channels limits the recorded channels, traffic_log =
// false records nothing (chain protocol scene: about a second per run).
TEST(LaunchRunTraffic, ChannelsAndOff) {
  if (!g_skip.empty()) GTEST_SKIP() << g_skip;
  fs::path dir = fs::temp_directory_path() / ("demfdm-launch-traffic-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::string base = demfdm::testing::read_file(std::string(DEMFDM_SOURCE_DIR) + "/scenes/chain_serial.toml");
  ASSERT_FALSE(base.empty());
  std::ofstream(dir / "limited.toml") << base << "\n[output]\ntraffic_channels = [\"DEMFDM_IFACE_.*\", \"DEMFDM_COMMAND\"]\n";
  std::ofstream(dir / "off.toml") << base << "\n[output]\ntraffic_log = false\n";
  std::string run = std::string(DEMFDM_SOURCE_DIR) + "/launch/run";
  setenv("DEMFDM_BUILD", fs::path(kBin).parent_path().c_str(), 1);
  auto [c1, o1] = run_cmd({"/bin/bash", run, (dir / "limited.toml").string(), "--no-build", "--run-dir",
                           (dir / "limited").string()}, (dir / "limited.out").string());
  ASSERT_EQ(c1, 0) << o1;
  auto [c2, o2] = run_cmd({kBin + "/demfdm_log", "summary", (dir / "limited" / "traffic.lcmlog").string()},
                          (dir / "limited.sum").string());
  ASSERT_EQ(c2, 0) << o2;
  EXPECT_NE(o2.find("DEMFDM_IFACE_KIN"), std::string::npos) << o2;
  EXPECT_NE(o2.find("DEMFDM_IFACE_FORCE"), std::string::npos) << o2;
  EXPECT_NE(o2.find("DEMFDM_COMMAND"), std::string::npos) << o2;
  EXPECT_EQ(o2.find("DEMFDM_REPORT"), std::string::npos) << o2;
  EXPECT_EQ(o2.find("DEMFDM_HEARTBEAT"), std::string::npos) << o2;
  EXPECT_EQ(o2.find("DEMFDM_SCENE"), std::string::npos) << o2;
  auto [c3, o3] = run_cmd({"/bin/bash", run, (dir / "off.toml").string(), "--no-build", "--run-dir",
                           (dir / "off").string()}, (dir / "off.out").string());
  ASSERT_EQ(c3, 0) << o3;
  EXPECT_TRUE(fs::exists(dir / "off" / "scene.toml"));
  EXPECT_FALSE(fs::exists(dir / "off" / "traffic.lcmlog"));
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  g_skip = demfdm::testing::enter_private_network();
  return RUN_ALL_TESTS();
}
