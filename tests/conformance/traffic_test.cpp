// Tests of the traffic tools (demfdm_log summary / export / merge / compare) and of
// demfdm_replay, on small logs recorded in the tests themselves (every process tees its own
// publications, DEMFDM_TRAFFIC_DIR, merged into one lossless log): a 12-step scripted coupled
// run of fdm_node driven by the conformance harness (in-process coordinator and DEM), with
// faults injected into the solver (one duplicated kin, the first hello dropped); and a
// 200-step run next to CPU hogs, recorded on the wire by lcm-logger as well. Damaged copies of
// the first log (truncated, bit-flipped, empty, garbage) must be refused by every tool with one
// message naming the file, byte and event, and never reach a solver.
#include <hdf5.h>
#include <lcm/eventlog.h>

#include <algorithm>
#include <csignal>
#include <map>
#include <set>
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
    // The lossless record (every process tees its publications; merged afterwards): a wire
    // capture by lcm-logger loses messages when the machine is loaded.
    setenv("DEMFDM_TRAFFIC_DIR", (dir_ / "parts").c_str(), 1);
    {
      Harness h({kBin + "/fdm_node"}, column_scene(false, 1e-7),
                {"DEMFDM_FAULT=dup:DEMFDM_IFACE_KIN:5,drop:DEMFDM_HELLO:1"});
      recorded_ = scripted_run(h);
      EXPECT_EQ(h.shutdown(2.0), 0);
    }
    unsetenv("DEMFDM_TRAFFIC_DIR");
    auto [code, out] = run_cmd({kBin + "/demfdm_log", "merge", log_, (dir_ / "parts").string()},
                               (dir_ / "merge.txt").string());
    EXPECT_EQ(code, 0) << out;
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

// The events of a log as framed in the file (LCM event log: sync, eventnum, timestamp, channel
// length, data length, channel, data; big-endian).
struct Framed {
  std::size_t offset = 0, data_at = 0, data_len = 0;
  std::string channel;
};
std::vector<Framed> frames(const std::string& b) {
  auto u32 = [&](std::size_t at) {
    return (std::uint32_t(std::uint8_t(b[at])) << 24) | (std::uint32_t(std::uint8_t(b[at + 1])) << 16) |
           (std::uint32_t(std::uint8_t(b[at + 2])) << 8) | std::uint32_t(std::uint8_t(b[at + 3]));
  };
  std::vector<Framed> out;
  for (std::size_t o = 0; o + 28 <= b.size();) {
    Framed f;
    f.offset = o;
    std::size_t cl = u32(o + 20), dl = u32(o + 24);
    f.channel = b.substr(o + 28, cl);
    f.data_at = o + 28 + cl;
    f.data_len = dl;
    out.push_back(f);
    o = f.data_at + dl;
  }
  return out;
}
void write_bytes(const fs::path& p, const std::string& b) { std::ofstream(p, std::ios::binary) << b; }
int lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

// Damaged copies of the fixture's log: every tool refuses them (exit 2) with one line naming
// the file, the kind of damage, the byte and the event; replay never starts the solver.
TEST_F(TrafficLog, DamagedLogsAreRefusedByEveryTool) {
  const std::string good = demfdm::testing::read_file(log_);
  auto ev = frames(good);
  ASSERT_GT(ev.size(), 50u);
  ASSERT_EQ(ev.front().channel, "DEMFDM_LOG_CHECK");
  ASSERT_EQ(ev.back().channel, "DEMFDM_LOG_CHECK");
  const Framed* force = nullptr;  // an interface force event in the middle of the log
  for (std::size_t i = ev.size() / 2; i < ev.size() && !force; ++i)
    if (ev[i].channel == "DEMFDM_IFACE_FORCE") force = &ev[i];
  ASSERT_NE(force, nullptr);
  const std::size_t force_index = static_cast<std::size_t>(force - ev.data());

  struct Case {
    std::string name, bytes, expect;
  };
  std::vector<Case> cases;
  // Cut inside an event, and cut after a whole event (the end block is missing).
  cases.push_back({"truncated", good.substr(0, force->data_at + force->data_len / 2),
                   ": truncated log: event " + std::to_string(force_index) + " at byte " +
                       std::to_string(force->offset) + " (channel DEMFDM_IFACE_FORCE) announces"});
  cases.push_back({"cut", good.substr(0, force->data_at + force->data_len),
                   ": truncated log: the file ends at byte " + std::to_string(force->data_at + force->data_len) +
                       " after event " + std::to_string(force_index) + " without the closing checksum block"});
  // One bit of one force value: the payload still decodes, only the checksum tells.
  std::string flipped = good;
  flipped[force->data_at + force->data_len - 20] ^= 0x04;
  cases.push_back({"flipped", flipped,
                   ": corrupt log: event " + std::to_string(force_index) + " at byte " + std::to_string(force->offset) +
                       " (channel DEMFDM_IFACE_FORCE, " + std::to_string(force->data_len) +
                       " bytes) does not match its checksum"});
  cases.push_back({"empty", "", ": empty log: the file is empty (0 bytes)"});
  std::string garbage(4096, '\0');
  std::mt19937 rng(7);
  for (auto& c : garbage) c = static_cast<char>(rng());
  garbage[0] = 'x';
  cases.push_back({"garbage", garbage, ": not an LCM event log: the file starts with 0x78"});

  const std::string traffic = std::string(DEMFDM_SOURCE_DIR) + "/launch/traffic";
  const std::string replay = std::string(DEMFDM_SOURCE_DIR) + "/launch/replay";
  setenv("DEMFDM_BUILD", fs::path(kBin).parent_path().c_str(), 1);
  for (const auto& c : cases) {
    SCOPED_TRACE(c.name);
    fs::path run = dir_ / ("damaged-" + c.name);
    fs::create_directories(run);
    const std::string file = (run / "traffic.lcmlog").string();
    write_bytes(file, c.bytes);
    const std::string want = file + c.expect;
    auto check = [&](const std::string& tool, std::pair<int, std::string> r) {
      EXPECT_EQ(r.first, 2) << tool << ": " << r.second;
      EXPECT_NE(r.second.find(want), std::string::npos) << tool << " should say\n  " << want << "\nbut said\n" << r.second;
      EXPECT_EQ(lines(r.second), 1) << tool << ": one line\n" << r.second;
    };
    check("summary", run_cmd({kBin + "/demfdm_log", "summary", file}, (run / "summary.txt").string()));
    check("verify", run_cmd({kBin + "/demfdm_log", "verify", file}, (run / "verify.txt").string()));
    check("export", run_cmd({kBin + "/demfdm_log", "export", file, "--steps", "1:2", "--out", (run / "x.csv").string()},
                            (run / "export.txt").string()));
    check("launch/traffic", run_cmd({"/bin/bash", traffic, run.string()}, (run / "traffic.txt").string()));
    auto r = run_cmd({kBin + "/demfdm_replay", file, "--solver", kBin + "/fdm_node"}, (run / "replay.txt").string());
    check("demfdm_replay", r);
    EXPECT_NE(r.second.find("; nothing was replayed"), std::string::npos) << r.second;
    EXPECT_EQ(r.second.find("replays"), std::string::npos) << "the solver must not be started\n" << r.second;
    check("launch/replay", run_cmd({"/bin/bash", replay, run.string(), "--solver", kBin + "/fdm_node"},
                                   (run / "launch_replay.txt").string()));
  }
}

// The good log is still read as before, and says it was verified; one process's part (no
// checksums) is still read; a part whose last event was cut short (a killed process) is merged
// without that event, with a warning.
TEST_F(TrafficLog, GoodLogsAndPartsStillRead) {
  auto [cv, ov] = run_cmd({kBin + "/demfdm_log", "verify", log_}, (dir_ / "verify.txt").string());
  EXPECT_EQ(cv, 0) << ov;
  EXPECT_NE(ov.find(": ok: "), std::string::npos) << ov;
  EXPECT_NE(ov.find("every event verified against the checksums"), std::string::npos) << ov;
  std::string part;
  for (const auto& de : fs::directory_iterator(dir_ / "parts"))
    if (de.path().filename().string().rfind("continuum", 0) == 0) part = de.path().string();
  ASSERT_FALSE(part.empty());
  auto [cs, os] = run_cmd({kBin + "/demfdm_log", "summary", part}, (dir_ / "part.txt").string());
  EXPECT_EQ(cs, 0) << os;
  EXPECT_NE(os.find("no checksums (not written by demfdm_log merge)"), std::string::npos) << os;
  EXPECT_NE(os.find("DEMFDM_IFACE_KIN"), std::string::npos) << os;
  fs::create_directories(dir_ / "cut-parts");
  const std::string bytes = demfdm::testing::read_file(part);
  auto ev = frames(bytes);
  ASSERT_GT(ev.size(), 3u);
  write_bytes(dir_ / "cut-parts" / "a.lcmlog", bytes.substr(0, bytes.size() - 3));
  auto [cm, om] = run_cmd({kBin + "/demfdm_log", "merge", (dir_ / "cut.lcmlog").string(), (dir_ / "cut-parts").string()},
                          (dir_ / "cut-merge.txt").string());
  EXPECT_EQ(cm, 0) << om;
  EXPECT_NE(om.find("merged " + std::to_string(ev.size() - 1) + " messages from 1 logs"), std::string::npos) << om;
  EXPECT_NE(om.find("warning: " + (dir_ / "cut-parts" / "a.lcmlog").string() + ": truncated log: event " +
                    std::to_string(ev.size() - 1) + " at byte " + std::to_string(ev.back().offset)),
            std::string::npos)
      << om;
  auto [c2, o2] = run_cmd({kBin + "/demfdm_log", "verify", (dir_ / "cut.lcmlog").string()}, (dir_ / "cut-verify.txt").string());
  EXPECT_EQ(c2, 0) << o2;
}

// The size guard: the coordinator repeats the scene every 250 ms until every node has said
// hello; each process records each (scene hash, chunk) once, and a repeat as a text-less stub.
// A scene of two chunks (> 48 KiB), the continuum starting 1.5 s late.
TEST(LaunchRunTraffic, SceneChunksRecordedOncePerProcess) {
  if (!g_skip.empty()) GTEST_SKIP() << g_skip;
  fs::path dir = fs::temp_directory_path() / ("demfdm-scene-once-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::string scene = demfdm::testing::read_file(std::string(DEMFDM_SOURCE_DIR) + "/scenes/chain_serial.toml");
  ASSERT_FALSE(scene.empty());
  for (int i = 0; i < 1400; ++i) scene += "# padding line " + std::to_string(i) + ": the size guard of the traffic log\n";
  ASSERT_GT(scene.size(), 49152u);
  std::ofstream(dir / "big.toml") << scene;
  std::ofstream(dir / "slow.sh") << "#!/bin/sh\nsleep 1.5\nexec " << kBin << "/chain_continuum \"$@\"\n";
  fs::permissions(dir / "slow.sh", fs::perms::owner_all);
  setenv("DEMFDM_BUILD", fs::path(kBin).parent_path().c_str(), 1);
  auto [c, o] = run_cmd({"/bin/bash", std::string(DEMFDM_SOURCE_DIR) + "/launch/run", (dir / "big.toml").string(),
                         "--no-build", "--run-dir", (dir / "run").string(), "--set-executable",
                         "continuum=" + (dir / "slow.sh").string()},
                        (dir / "run.out").string());
  ASSERT_EQ(c, 0) << o;
  const std::string log = (dir / "run" / "traffic.lcmlog").string();
  lcm::LogFile f(log, "r");
  ASSERT_TRUE(f.good());
  std::map<std::pair<std::string, std::int32_t>, int> full;  // (sender, chunk) -> events with the text
  int stubs = 0;
  std::size_t scene_bytes = 0;
  while (const lcm::LogEvent* e = f.readNextEvent()) {
    if (e->channel != "DEMFDM_SCENE" && e->channel != "DEMFDM_SCENE_REPEAT") continue;
    scene_bytes += static_cast<std::size_t>(e->datalen);
    demfdm::scene_t m;
    ASSERT_GE(m.decode(e->data, 0, e->datalen), 0);
    EXPECT_EQ(m.n_chunks, 2);
    if (e->channel == "DEMFDM_SCENE") {
      ++full[{m.header.sender, m.chunk_index}];
      EXPECT_FALSE(m.text.empty());
    } else {
      ++stubs;
      EXPECT_TRUE(m.text.empty());
    }
  }
  EXPECT_EQ(full, (std::map<std::pair<std::string, std::int32_t>, int>{{{"coordinator", 0}, 1}, {{"coordinator", 1}, 1}}));
  EXPECT_GE(stubs, 2 * 4) << "the continuum said hello 1.5 s late: at least 4 repeats of both chunks";
  // The log holds the text once, not once per broadcast (stubs: about 150 bytes).
  EXPECT_LT(scene_bytes, scene.size() + 200u * static_cast<std::size_t>(stubs + 2));
  // Every publication is still in the log: no seq gap for the coordinator.
  auto [cs, os] = run_cmd({kBin + "/demfdm_log", "summary", log}, (dir / "summary.txt").string());
  ASSERT_EQ(cs, 0) << os;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(os, m, std::regex(R"(\ncoordinator\s+(\d+)\s+\d+-\d+\s+(\d+)\s+(\d+))"))) << os;
  EXPECT_EQ(std::stoi(m[2]), 0) << os;
  EXPECT_NE(os.find("DEMFDM_SCENE_REPEAT"), std::string::npos) << os;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// launch/run honours [output]: traffic_channels limits the recorded channels, traffic_log =
// false records nothing, and a failed run's parts are merged too (chain protocol scene:
// about a second per run).
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
  EXPECT_FALSE(fs::exists(dir / "limited" / "traffic.parts")) << "the merged parts are removed";
  auto [c3, o3] = run_cmd({"/bin/bash", run, (dir / "off.toml").string(), "--no-build", "--run-dir",
                           (dir / "off").string()}, (dir / "off.out").string());
  ASSERT_EQ(c3, 0) << o3;
  EXPECT_TRUE(fs::exists(dir / "off" / "scene.toml"));
  EXPECT_FALSE(fs::exists(dir / "off" / "traffic.lcmlog"));
  EXPECT_FALSE(fs::exists(dir / "off" / "traffic.parts"));
  // A failed run (the continuum exits at once; the coordinator gives up after 1 s) still gets
  // its merged log: the scene broadcasts and the DEM's hellos.
  // (The stand-in passes launch/run's `--check` of every node executable, then fails.)
  std::ofstream(dir / "fails.toml") << base << "\n[bus]\nstartup_s = 1\n";
  std::ofstream(dir / "fails.sh") << "#!/bin/sh\n[ \"$1\" = --check ] && exit 0\nexit 1\n";
  fs::permissions(dir / "fails.sh", fs::perms::owner_all);
  auto [c4, o4] = run_cmd({"/bin/bash", run, (dir / "fails.toml").string(), "--no-build", "--run-dir",
                           (dir / "fails").string(), "--set-executable", "continuum=" + (dir / "fails.sh").string()},
                          (dir / "fails.out").string());
  EXPECT_EQ(c4, 3) << o4;
  EXPECT_FALSE(fs::exists(dir / "fails" / "traffic.parts")) << o4;
  auto [c5, o5] = run_cmd({kBin + "/demfdm_log", "summary", (dir / "fails" / "traffic.lcmlog").string()},
                          (dir / "fails.sum").string());
  ASSERT_EQ(c5, 0) << o5;
  EXPECT_NE(o5.find("DEMFDM_SCENE"), std::string::npos) << o5;
  EXPECT_NE(o5.find("DEMFDM_HELLO"), std::string::npos) << o5;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// Writes an event log with the given (timestamp, channel, payload byte) events.
void write_log(const std::string& path, const std::vector<std::tuple<std::int64_t, std::string, std::uint8_t>>& evs) {
  lcm_eventlog_t* w = lcm_eventlog_create(path.c_str(), "w");
  ASSERT_NE(w, nullptr) << path;
  std::int64_t n = 0;
  for (auto [t, ch, byte] : evs) {
    lcm_eventlog_event_t e{};
    e.eventnum = n++;
    e.timestamp = t;
    e.channellen = static_cast<std::int32_t>(ch.size());
    e.datalen = 1;
    e.channel = ch.data();
    e.data = &byte;
    ASSERT_EQ(lcm_eventlog_write_event(w, &e), 0);
  }
  lcm_eventlog_destroy(w);
}

// merge: ordered by timestamp, ties in input path order then file order; event numbers
// renumbered; the same inputs give the same bytes.
TEST(TrafficMerge, OrdersByTimeWithDeterministicTies) {
  fs::path dir = fs::temp_directory_path() / ("demfdm-merge-" + std::to_string(::getpid()));
  fs::create_directories(dir / "parts");
  write_log((dir / "parts" / "b.lcmlog").string(), {{10, "B", 1}, {20, "B", 2}, {20, "B", 3}, {40, "B", 4}});
  write_log((dir / "parts" / "a.lcmlog").string(), {{5, "A", 5}, {20, "A", 6}, {30, "A", 7}});
  std::ofstream(dir / "parts" / "notes.txt") << "not a log\n";
  auto merged = (dir / "m1.lcmlog").string(), again = (dir / "m2.lcmlog").string();
  auto [c1, o1] = run_cmd({kBin + "/demfdm_log", "merge", merged, (dir / "parts").string()}, (dir / "o1").string());
  ASSERT_EQ(c1, 0) << o1;
  EXPECT_NE(o1.find("merged 7 messages from 2 logs"), std::string::npos) << o1;
  lcm::LogFile f(merged, "r");
  ASSERT_TRUE(f.good());
  std::vector<int> payload;
  std::vector<std::int64_t> num;
  std::vector<std::string> check;  // checksum blocks: the first and the last event
  while (const lcm::LogEvent* e = f.readNextEvent()) {
    num.push_back(e->eventnum);
    if (e->channel == "DEMFDM_LOG_CHECK")
      check.push_back(std::to_string(e->eventnum));
    else
      payload.push_back(*static_cast<const std::uint8_t*>(e->data));
  }
  EXPECT_EQ(payload, (std::vector<int>{5, 1, 6, 2, 3, 7, 4}));
  EXPECT_EQ(num, (std::vector<std::int64_t>{0, 1, 2, 3, 4, 5, 6, 7, 8}));
  EXPECT_EQ(check, (std::vector<std::string>{"0", "8"}));
  auto [c2, o2] = run_cmd({kBin + "/demfdm_log", "merge", again, (dir / "parts" / "b.lcmlog").string(),
                           (dir / "parts" / "a.lcmlog").string()}, (dir / "o2").string());
  ASSERT_EQ(c2, 0) << o2;
  EXPECT_EQ(demfdm::testing::read_file(merged), demfdm::testing::read_file(again));
  auto [c3, o3] = run_cmd({kBin + "/demfdm_log", "merge", again, (dir / "missing").string()}, (dir / "o3").string());
  EXPECT_EQ(c3, 2);
  EXPECT_NE(o3.find("missing"), std::string::npos) << o3;
  std::error_code ec;
  fs::remove_all(dir, ec);
}

// Reads a dataset of doubles (or int64) from an HDF5 file; empty when absent.
template <class T>
std::vector<T> read_h5(const std::string& file, const std::string& name, std::vector<hsize_t>* dims = nullptr) {
  std::vector<T> v;
  hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  if (f < 0) return v;
  hid_t d = H5Dopen2(f, name.c_str(), H5P_DEFAULT);
  if (d >= 0) {
    hid_t sp = H5Dget_space(d);
    int rank = H5Sget_simple_extent_ndims(sp);
    std::vector<hsize_t> dd(static_cast<std::size_t>(rank));
    H5Sget_simple_extent_dims(sp, dd.data(), nullptr);
    hsize_t n = 1;
    for (auto x : dd) n *= x;
    v.resize(n);
    H5Dread(d, std::is_same_v<T, double> ? H5T_NATIVE_DOUBLE : H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT,
            v.data());
    if (dims) *dims = dd;
    H5Sclose(sp);
    H5Dclose(d);
  }
  H5Fclose(f);
  return v;
}

// The lossless log: every process (the solver, the in-process coordinator and DEM) tees its
// publications; a 200-step run next to two CPU hogs (and lcm-logger on the wire) is merged.
// Invariants: no seq gap for any sender, every step complete, nothing in the wire capture
// that the merged log lacks, replay with the same solver bit-identical on every step, the
// HDF5 export equal to what the harness received, bit for bit.
TEST(LosslessTraffic, TeeMergeReplayUnderLoad) {
  if (!g_skip.empty()) GTEST_SKIP() << g_skip;
  fs::path dir = fs::temp_directory_path() / ("demfdm-lossless-" + std::to_string(::getpid()));
  fs::create_directories(dir);
  std::vector<demfdm::testing::Proc> hogs;
  for (int i = 0; i < 2; ++i) hogs.push_back(demfdm::testing::spawn({"/bin/sh", "-c", "while :; do :; done"}));
  std::string logger = which("lcm-logger");
  ASSERT_FALSE(logger.empty());
  std::mt19937_64 rng(std::random_device{}());
  std::string url = "udpm://239.255.76.67:" + std::to_string(20000 + rng() % 40000) + "?ttl=0";
  std::string wire = (dir / "traffic_wire.lcmlog").string(), merged = (dir / "traffic.lcmlog").string();
  auto lp = demfdm::testing::spawn({logger, "--lcm-url=" + url + "&recv_buf_size=4194304", "-q", wire}, {},
                                   (dir / "logger.out").string());
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const int kSteps = 200;
  std::vector<proto::Kinematics> got;
  setenv("DEMFDM_TRAFFIC_DIR", (dir / "parts").c_str(), 1);
  {
    Harness h({kBin + "/fdm_node"}, column_scene(false, 1e-7), {}, url);
    auto [m, kin0] = h.begin();
    got.push_back(kin0);
    for (int k = 0; k < kSteps; ++k) got.push_back(h.steps(pressure_forces(m, 1e4 * (1 + k % 7)), 1, false).second);
    EXPECT_EQ(h.shutdown(2.0), 0);
  }
  unsetenv("DEMFDM_TRAFFIC_DIR");
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  ::kill(lp.pid, SIGINT);
  if (!demfdm::testing::wait_for(lp, 3.0)) demfdm::testing::kill_and_reap(lp);
  for (auto& p : hogs) demfdm::testing::kill_and_reap(p);

  auto [cm, om] = run_cmd({kBin + "/demfdm_log", "merge", merged, (dir / "parts").string()}, (dir / "merge.txt").string());
  ASSERT_EQ(cm, 0) << om;
  auto [cs, os] = run_cmd({kBin + "/demfdm_log", "summary", merged}, (dir / "summary.txt").string());
  ASSERT_EQ(cs, 0) << os;
  std::cout << os;
  EXPECT_NE(os.find("interface: " + std::to_string(kSteps + 1) + " steps with kinematics, " + std::to_string(kSteps) +
                    " steps with forces"), std::string::npos) << os;
  EXPECT_NE(os.find("missing in that range: 0 steps without kinematics, 0 without forces"), std::string::npos) << os;
  std::smatch m;
  std::string rest = os;
  int senders = 0;
  const std::regex row(R"(\n(coordinator|dem|continuum|probe)\s+(\d+)\s+\d+-\d+\s+(\d+)\s+(\d+))");
  while (std::regex_search(rest, m, row)) {
    ++senders;
    EXPECT_EQ(std::stoi(m[3]), 0) << "seq gaps of " << m[1] << "\n" << os;
    rest = m.suffix();
  }
  EXPECT_GE(senders, 3) << os;
  auto [cc, oc] = run_cmd({kBin + "/demfdm_log", "compare", merged, wire}, (dir / "compare.txt").string());
  ASSERT_EQ(cc, 0) << oc;
  std::cout << oc;
  ASSERT_TRUE(std::regex_search(oc, m, std::regex(R"(lost on the wire: (\d+) of (\d+) messages; only on the wire: (\d+))")))
      << oc;
  EXPECT_EQ(std::stoi(m[3]), 0) << "the wire holds a message no process teed\n" << oc;
  EXPECT_GT(std::stoi(m[2]), 4 * kSteps);
  auto [cr, orp] = run_cmd({kBin + "/demfdm_replay", merged, "--solver", kBin + "/fdm_node", "--expect-identical"},
                           (dir / "replay.txt").string());
  std::cout << orp;
  EXPECT_EQ(cr, 0) << orp;
  const std::string n = std::to_string(kSteps + 1);
  EXPECT_NE(orp.find("replay: " + n + " steps compared, " + n + " bit-identical, max |dx| = 0 m, max |dv| = 0"),
            std::string::npos) << orp;
  // HDF5 export of steps 3..5 equals what the harness received, and carries the mesh.
  std::string h5 = (dir / "steps.h5").string();
  auto [ce, oe] = run_cmd({kBin + "/demfdm_log", "export", merged, "--steps", "3:5", "--format", "h5", "--out", h5},
                          (dir / "export.txt").string());
  ASSERT_EQ(ce, 0) << oe;
  std::vector<hsize_t> dims;
  auto steps = read_h5<std::int64_t>(h5, "kin/steps");
  auto pos = read_h5<double>(h5, "kin/positions", &dims);
  auto vel = read_h5<double>(h5, "kin/velocities");
  EXPECT_EQ(steps, (std::vector<std::int64_t>{3, 4, 5}));
  const std::size_t np = got[0].positions.size() / 3;
  ASSERT_EQ(dims, (std::vector<hsize_t>{3, np, 3}));
  for (std::size_t s = 0; s < 3; ++s)
    for (std::size_t i = 0; i < 3 * np; ++i) {
      ASSERT_EQ(pos[s * 3 * np + i], got[s + 4].positions[i]) << "step " << s + 3 << " value " << i;
      ASSERT_EQ(vel[s * 3 * np + i], got[s + 4].velocities[i]) << "step " << s + 3 << " value " << i;
    }
  EXPECT_EQ(read_h5<std::int64_t>(h5, "force/steps"), (std::vector<std::int64_t>{3, 4, 5}));
  auto total = read_h5<double>(h5, "force/total", &dims);
  ASSERT_EQ(dims, (std::vector<hsize_t>{3, 3}));
  auto forces = read_h5<double>(h5, "force/forces");
  for (std::size_t s = 0; s < 3; ++s) {  // the recorded total is the sum of the point forces
    double fz = 0;
    for (std::size_t i = 0; i < np; ++i) fz += forces[s * 3 * np + 3 * i + 2];
    EXPECT_NEAR(fz, total[3 * s + 2], 1e-12 * std::abs(total[3 * s + 2])) << "step " << s + 3;
  }
  auto mesh = read_h5<double>(h5, "mesh/positions", &dims);
  ASSERT_EQ(dims, (std::vector<hsize_t>{np, 3}));
  for (std::size_t i = 0; i < 3 * np; ++i) ASSERT_EQ(mesh[i], got[0].positions[i]) << i;  // kin(s0-1) = mesh
  std::error_code ec;
  fs::remove_all(dir, ec);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  g_skip = demfdm::testing::enter_private_network();
  return RUN_ALL_TESTS();
}
