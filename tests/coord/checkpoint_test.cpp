// Coordinated checkpoints: coordinator.state, manifests, the run folder ledger, branch rules.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <map>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "coordinator/core/checkpoint.hpp"
#include "demfdm/io/state_file.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {

// A scratch folder per test, removed at its end.
class Checkpoint : public ::testing::Test {
 protected:
  fs::path dir;
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir = fs::temp_directory_path() /
          ("demfdm_ckpt_test_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

void write_file(const fs::path& p, const std::string& bytes) {
  fs::create_directories(p.parent_path());
  std::ofstream f(p, std::ios::binary | std::ios::trunc);
  f << bytes;
}
std::string read_file(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}
bool contains(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

coord::NodeReport report(double base, const std::string& text) {
  coord::NodeReport n;
  n.status = coord::Status::StageDone;
  n.time = base + 0.125;
  n.dt_stable = base * 1e-9 + 3e-17;
  n.compute_s = base + 1.0 / 3.0;
  n.wait_s = base + 0.1;
  n.values = {{"fz", -base * 1.5e3}, {"sigma_v", 1.0 / 7.0}, {"porosity", 0.42}};
  n.text = text;
  return n;
}
coord::StageSummary stage_summary(const std::string& name, std::int64_t first, std::int64_t last) {
  coord::StageSummary s;
  s.name = name;
  s.action = name + "-action";
  s.first_step = first;
  s.last_step = last;
  s.wall_s = 12.3456789;
  s.criterion_met = true;
  s.ended_by = "done";
  s.begin = {{"dem", report(1, "generated 240 balls")}, {"continuum", report(2, "")}};
  s.end = {{"dem", report(3, "end")}};
  s.compute_s = {{"dem", 1.5}, {"continuum", 2.25}};
  s.wait_s = {{"dem", 0.75}};
  return s;
}

coord::CheckpointRecord sample_record() {
  coord::CheckpointRecord rec;
  auto& s = rec.runner;
  s.stage = 2;
  s.in_stage = true;
  s.step = 1237;
  s.clock.stage_index = 2;
  s.clock.stage_first_step = 461;
  s.clock.first_step = 1233;
  s.clock.last_step = 1236;
  s.clock.dt = 1.234567e-7;
  s.clock.t_begin = 9.87654321e-5;
  s.current = stage_summary("penetrate", 461, -1);
  s.current.criterion_met = false;
  s.current.ended_by = "";
  s.done = {stage_summary("servo", 0, 0), stage_summary("gravity", 1, 460)};
  s.dt_stable = {{"dem", 1.1e-7}, {"continuum", 2.2e-6}};
  s.wall_s = 321.5;
  rec.history.index = 3;
  rec.history.current = "penetrate";
  rec.history.file = "history_2_penetrate.csv";
  rec.history.cols = {{"dem", "fz"}, {"continuum", "uz"}};
  rec.history.bytes = 123456789012ULL;
  rec.scene_text = "[run]\nseed = 3\n# ünïcode and \"quotes\"\n";
  rec.nodes = {{"dem", "dem_node"}, {"continuum", "fdm_node"}};
  rec.participated = {"dem", "continuum"};
  rec.outputs = {{"dem_history.csv", 4096}, {"history_0_servo.csv", 17}};
  rec.run_id = -42;
  return rec;
}

void expect_eq(const coord::NodeReport& a, const coord::NodeReport& b) {
  EXPECT_EQ(a.status, b.status);
  EXPECT_EQ(a.time, b.time);
  EXPECT_EQ(a.dt_stable, b.dt_stable);
  EXPECT_EQ(a.compute_s, b.compute_s);
  EXPECT_EQ(a.wait_s, b.wait_s);
  EXPECT_EQ(a.values, b.values);
  EXPECT_EQ(a.text, b.text);
}
void expect_eq(const std::map<std::string, coord::NodeReport>& a, const std::map<std::string, coord::NodeReport>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (auto& [k, v] : a) {
    ASSERT_TRUE(b.count(k)) << k;
    SCOPED_TRACE("report " + k);
    expect_eq(v, b.at(k));
  }
}
void expect_eq(const coord::StageSummary& a, const coord::StageSummary& b) {
  SCOPED_TRACE("stage " + a.name);
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.action, b.action);
  EXPECT_EQ(a.first_step, b.first_step);
  EXPECT_EQ(a.last_step, b.last_step);
  EXPECT_EQ(a.wall_s, b.wall_s);
  EXPECT_EQ(a.criterion_met, b.criterion_met);
  EXPECT_EQ(a.ended_by, b.ended_by);
  expect_eq(a.begin, b.begin);
  expect_eq(a.end, b.end);
  EXPECT_EQ(a.compute_s, b.compute_s);
  EXPECT_EQ(a.wait_s, b.wait_s);
}

// Writes a checkpoint folder <run>/checkpoints/<tag>/ with node files, coordinator.state and a
// manifest.
fs::path write_checkpoint(const fs::path& run, const std::string& tag, std::uint64_t hash, std::int64_t run_id = 7,
                          std::uint64_t record_hash = 0) {
  const auto d = run / "checkpoints" / tag;
  write_file(d / "dem.state", "dem state of " + tag);
  write_file(d / "continuum.state", "continuum state of " + tag);
  auto rec = sample_record();
  rec.run_id = run_id;
  write_file(d / "coordinator.state", coord::record_bytes(rec, record_hash ? record_hash : hash));
  coord::Manifest m;
  m.code_version = "demfdm test";
  m.tag = tag;
  m.scene_hash = hash;
  m.run_id = run_id;
  coord::write_manifest(d, m);
  return d;
}

}  // namespace

// ---- coordinator.state ----

TEST_F(Checkpoint, RecordRoundTripsEveryField) {
  const auto rec = sample_record();
  const std::uint64_t hash = 0x0123456789abcdefULL;
  write_file(dir / "coordinator.state", coord::record_bytes(rec, hash));
  const auto got = coord::load_record(dir / "coordinator.state", hash);
  const auto &a = rec.runner, &b = got.runner;
  EXPECT_EQ(a.stage, b.stage);
  EXPECT_EQ(a.in_stage, b.in_stage);
  EXPECT_EQ(a.step, b.step);
  EXPECT_EQ(a.clock.stage_index, b.clock.stage_index);
  EXPECT_EQ(a.clock.stage_first_step, b.clock.stage_first_step);
  EXPECT_EQ(a.clock.first_step, b.clock.first_step);
  EXPECT_EQ(a.clock.last_step, b.clock.last_step);
  EXPECT_EQ(a.clock.dt, b.clock.dt);
  EXPECT_EQ(a.clock.t_begin, b.clock.t_begin);
  expect_eq(a.current, b.current);
  ASSERT_EQ(a.done.size(), b.done.size());
  for (std::size_t i = 0; i < a.done.size(); ++i) expect_eq(a.done[i], b.done[i]);
  EXPECT_EQ(a.dt_stable, b.dt_stable);
  EXPECT_EQ(a.wall_s, b.wall_s);
  EXPECT_EQ(rec.history.index, got.history.index);
  EXPECT_EQ(rec.history.current, got.history.current);
  EXPECT_EQ(rec.history.file, got.history.file);
  EXPECT_EQ(rec.history.cols, got.history.cols);
  EXPECT_EQ(rec.history.bytes, got.history.bytes);
  EXPECT_EQ(rec.scene_text, got.scene_text);
  EXPECT_EQ(rec.nodes, got.nodes);
  EXPECT_EQ(rec.participated, got.participated);
  ASSERT_EQ(rec.outputs.size(), got.outputs.size());
  for (std::size_t i = 0; i < rec.outputs.size(); ++i) {
    EXPECT_EQ(rec.outputs[i].name, got.outputs[i].name);
    EXPECT_EQ(rec.outputs[i].size, got.outputs[i].size);
  }
  EXPECT_EQ(rec.run_id, got.run_id);
}

TEST_F(Checkpoint, RecordRoundTripsAnEmptyRecord) {
  coord::CheckpointRecord rec;
  write_file(dir / "coordinator.state", coord::record_bytes(rec, 1));
  const auto got = coord::load_record(dir / "coordinator.state", 1);
  EXPECT_EQ(got.runner.stage, 0u);
  EXPECT_FALSE(got.runner.in_stage);
  EXPECT_EQ(got.runner.current.last_step, -1);
  EXPECT_TRUE(got.runner.done.empty());
  EXPECT_TRUE(got.outputs.empty());
  EXPECT_TRUE(got.scene_text.empty());
}

TEST_F(Checkpoint, RecordOfAnotherSceneIsRefused) {
  write_file(dir / "coordinator.state", coord::record_bytes(sample_record(), 0x1111));
  EXPECT_THROW(coord::load_record(dir / "coordinator.state", 0x2222), io::StateFileError);
}

// ---- manifest ----

TEST_F(Checkpoint, ManifestVerifiesAndReadsBack) {
  write_file(dir / "a.state", std::string("binary\0data\n", 12));
  write_file(dir / "b.state", "");
  write_file(dir / "coordinator.state", "xyz");
  coord::Manifest m;
  m.code_version = "demfdm 1.2 gcc 13";
  m.tag = "penetrate-832";
  m.stage_name = "penetrate";
  m.scene_hash = 0xfedcba9876543210ULL;
  m.run_id = 99;
  m.step = 832;
  m.stage = 5;
  m.in_stage = true;
  const auto w = coord::write_manifest(dir, m);
  ASSERT_EQ(w.files.size(), 3u);
  EXPECT_EQ(w.files[0].first.name, "a.state");
  EXPECT_EQ(w.files[0].first.size, 12u);
  const auto v = coord::verify_checkpoint(dir);
  EXPECT_EQ(v.format_version, coord::kCheckpointFormatVersion);
  EXPECT_EQ(v.code_version, m.code_version);
  EXPECT_EQ(v.tag, m.tag);
  EXPECT_EQ(v.stage_name, m.stage_name);
  EXPECT_EQ(v.scene_hash, m.scene_hash);
  EXPECT_EQ(v.run_id, m.run_id);
  EXPECT_EQ(v.step, m.step);
  EXPECT_EQ(v.stage, m.stage);
  EXPECT_EQ(v.in_stage, m.in_stage);
  ASSERT_EQ(v.files.size(), w.files.size());
  for (std::size_t i = 0; i < v.files.size(); ++i) {
    EXPECT_EQ(v.files[i].first.name, w.files[i].first.name);
    EXPECT_EQ(v.files[i].first.size, w.files[i].first.size);
    EXPECT_EQ(v.files[i].second, w.files[i].second);
  }
}

namespace {
std::string refusal(const fs::path& d) {
  try {
    coord::verify_checkpoint(d);
  } catch (const coord::CheckpointError& e) {
    return e.what();
  }
  return "(accepted)";
}
fs::path manifest_folder(const fs::path& d) {
  write_file(d / "dem.state", "0123456789");
  write_file(d / "coordinator.state", "abcdef");
  coord::Manifest m;
  m.tag = "gravity-460-end";
  m.stage_name = "gravity";
  m.step = 460;
  coord::write_manifest(d, m);
  return d;
}
}  // namespace

TEST_F(Checkpoint, FlippedByteFailsTheFileChecksum) {
  const auto d = manifest_folder(dir / "ck");
  auto bytes = read_file(d / "dem.state");
  bytes[3] ^= 0x01;
  write_file(d / "dem.state", bytes);
  const auto msg = refusal(d);
  EXPECT_TRUE(contains(msg, d.string())) << msg;
  EXPECT_TRUE(contains(msg, "dem.state")) << msg;
  EXPECT_TRUE(contains(msg, "checksum")) << msg;
}

TEST_F(Checkpoint, TruncatedFileFailsItsSize) {
  const auto d = manifest_folder(dir / "ck");
  fs::resize_file(d / "coordinator.state", 2);
  const auto msg = refusal(d);
  EXPECT_TRUE(contains(msg, d.string())) << msg;
  EXPECT_TRUE(contains(msg, "coordinator.state")) << msg;
  EXPECT_TRUE(contains(msg, "2 bytes")) << msg;
  EXPECT_TRUE(contains(msg, "6")) << msg;
}

TEST_F(Checkpoint, MissingFileIsNamed) {
  const auto d = manifest_folder(dir / "ck");
  fs::remove(d / "dem.state");
  const auto msg = refusal(d);
  EXPECT_TRUE(contains(msg, "dem.state")) << msg;
  EXPECT_TRUE(contains(msg, "missing")) << msg;
}

TEST_F(Checkpoint, FolderWithoutManifestIsIncomplete) {
  const auto d = manifest_folder(dir / "ck");
  fs::remove(d / "manifest.txt");
  const auto msg = refusal(d);
  EXPECT_TRUE(contains(msg, d.string())) << msg;
  EXPECT_TRUE(contains(msg, "incomplete")) << msg;
}

TEST_F(Checkpoint, EditedManifestFailsItsChecksum) {
  const auto d = manifest_folder(dir / "ck");
  auto text = read_file(d / "manifest.txt");
  auto pos = text.find("step 460");
  ASSERT_NE(pos, std::string::npos);
  text.replace(pos, 8, "step 461");
  write_file(d / "manifest.txt", text);
  const auto msg = refusal(d);
  EXPECT_TRUE(contains(msg, d.string())) << msg;
  EXPECT_TRUE(contains(msg, "manifest.txt fails its checksum")) << msg;
}

TEST_F(Checkpoint, ManifestOfAnotherFormatVersionIsRefused) {
  const auto d = manifest_folder(dir / "ck");
  auto text = read_file(d / "manifest.txt");
  const std::string v1 = "demfdm checkpoint 1\n";
  ASSERT_EQ(text.rfind(v1, 0), 0u) << text;
  text.replace(0, v1.size(), "demfdm checkpoint 2\n");
  auto body = text.substr(0, text.rfind("checksum "));
  char hex[17];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(io::fnv1a64(body.data(), body.size())));
  write_file(d / "manifest.txt", body + "checksum " + hex + "\n");
  const auto msg = refusal(d);
  EXPECT_TRUE(contains(msg, d.string())) << msg;
  EXPECT_TRUE(contains(msg, "format version 2")) << msg;
  // The recomputed checksum itself is right: version 1 with the same procedure is accepted.
  body.replace(0, v1.size(), v1);
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(io::fnv1a64(body.data(), body.size())));
  write_file(d / "manifest.txt", body + "checksum " + hex + "\n");
  EXPECT_EQ(refusal(d), "(accepted)");
}

// ---- finding checkpoints ----

TEST_F(Checkpoint, CheckpointsLatestFirstByStepEndAfterMidStage) {
  const auto root = dir / "checkpoints";
  for (const char* tag : {"gravity-460-end", "gravity-460", "penetrate-1236", "penetrate-832", "penetrate-3549-end",
                          "servo-1-end"})
    manifest_folder(root / tag);
  write_file(root / "penetrate-4000" / "dem.state", "no manifest: incomplete");
  write_file(root / "stray.txt", "not a folder");
  std::vector<std::string> got;
  for (auto& p : coord::checkpoints_latest_first(dir)) got.push_back(p.filename().string());
  EXPECT_EQ(got, (std::vector<std::string>{"penetrate-3549-end", "penetrate-1236", "penetrate-832", "gravity-460-end",
                                           "gravity-460", "servo-1-end"}));
  EXPECT_TRUE(coord::checkpoints_latest_first(dir / "nothing").empty());
}

TEST_F(Checkpoint, LatestValidSkipsACorruptNewestOne) {
  const std::uint64_t hash = 0xabc;
  write_checkpoint(dir, "gravity-460-end", hash, 1);
  const auto newest = write_checkpoint(dir, "penetrate-832", hash, 2);
  auto bytes = read_file(newest / "dem.state");
  bytes[0] ^= 0x20;
  write_file(newest / "dem.state", bytes);
  std::vector<std::string> refused;
  auto got = coord::latest_valid_checkpoint(dir, hash, [&](const std::string& m) { refused.push_back(m); });
  ASSERT_EQ(refused.size(), 1u);
  EXPECT_TRUE(contains(refused[0], "penetrate-832")) << refused[0];
  EXPECT_EQ(got.dir.filename(), "gravity-460-end");
  EXPECT_TRUE(got.dir.is_absolute());
  EXPECT_EQ(got.manifest.tag, "gravity-460-end");
  EXPECT_EQ(got.record.run_id, 1);
  EXPECT_EQ(got.record.runner.step, sample_record().runner.step);
}

TEST_F(Checkpoint, LatestValidRefusesAnotherSceneAndThrowsWhenNoneIsLeft) {
  const std::uint64_t hash = 0xabc;
  write_checkpoint(dir, "gravity-460-end", hash, 1);
  write_checkpoint(dir, "penetrate-832", 0xdef, 2);  // manifest of another scene
  std::vector<std::string> refused;
  auto got = coord::latest_valid_checkpoint(dir, hash, [&](const std::string& m) { refused.push_back(m); });
  ASSERT_EQ(refused.size(), 1u);
  EXPECT_TRUE(contains(refused[0], "penetrate-832")) << refused[0];
  EXPECT_TRUE(contains(refused[0], "another scene")) << refused[0];
  EXPECT_EQ(got.dir.filename(), "gravity-460-end");

  // A record of another scene under a right manifest is refused too.
  write_checkpoint(dir, "penetrate-900", hash, 3, 0x999);
  refused.clear();
  got = coord::latest_valid_checkpoint(dir, hash, [&](const std::string& m) { refused.push_back(m); });
  ASSERT_EQ(refused.size(), 2u);
  EXPECT_TRUE(contains(refused[0], "penetrate-900")) << refused[0];
  EXPECT_EQ(got.dir.filename(), "gravity-460-end");

  fs::remove(dir / "checkpoints" / "gravity-460-end" / "continuum.state");
  refused.clear();
  EXPECT_THROW(coord::latest_valid_checkpoint(dir, hash, [&](const std::string& m) { refused.push_back(m); }),
               coord::CheckpointError);
  EXPECT_EQ(refused.size(), 3u);
  EXPECT_THROW(coord::latest_valid_checkpoint(dir / "empty", hash, [](const std::string&) {}), coord::CheckpointError);
}

// ---- run folder ledger ----

TEST_F(Checkpoint, RunFolderFilesLeaveOutLogsOutputsSummaryAndCheckpoints) {
  write_file(dir / "dem_history.csv", "a,b\n1,2\n");
  write_file(dir / "history_0_servo.csv", "x\n");
  write_file(dir / "dem.h5", std::string(100, 'h'));
  for (const char* f : {"coordinator.log", "dem.out", "summary.txt", "summary.json", "scene.toml"}) write_file(dir / f, "x");
  write_file(dir / "checkpoints" / "servo-1-end" / "manifest.txt", "m");
  write_file(dir / "traffic.parts" / "part0", "t");
  const auto files = coord::run_folder_files(dir);
  std::vector<std::pair<std::string, std::uint64_t>> got;
  for (auto& f : files) got.push_back({f.name, f.size});
  EXPECT_EQ(got, (std::vector<std::pair<std::string, std::uint64_t>>{
                     {"dem.h5", 100}, {"dem_history.csv", 8}, {"history_0_servo.csv", 2}}));
}

TEST_F(Checkpoint, DropFilesAfterDeletesNewFilesAndKeepsTheRest) {
  write_file(dir / "dem_history.csv", "a,b\n1,2\n");
  write_file(dir / "history_0_servo.csv", "x\n");
  const auto ledger = coord::run_folder_files(dir);
  // After the checkpoint: the history grows, new result files and a log appear.
  write_file(dir / "dem_history.csv", "a,b\n1,2\n3,4\n");
  write_file(dir / "history_1_gravity.csv", "y\n");
  write_file(dir / "dem.h5", "frames");
  write_file(dir / "coordinator.log", "log");
  write_file(dir / "checkpoints" / "gravity-460" / "dem.state", "s");
  const auto dropped = coord::drop_files_after(dir, ledger);
  EXPECT_EQ(dropped, (std::vector<std::string>{"dem.h5", "history_1_gravity.csv"}));
  EXPECT_FALSE(fs::exists(dir / "dem.h5"));
  EXPECT_FALSE(fs::exists(dir / "history_1_gravity.csv"));
  EXPECT_TRUE(fs::exists(dir / "dem_history.csv"));
  EXPECT_TRUE(fs::exists(dir / "history_0_servo.csv"));
  EXPECT_TRUE(fs::exists(dir / "coordinator.log"));
  EXPECT_TRUE(fs::exists(dir / "checkpoints" / "gravity-460" / "dem.state"));
}

TEST_F(Checkpoint, DropFilesAfterRefusesAShorterOrMissingLedgerFile) {
  write_file(dir / "dem_history.csv", "a,b\n1,2\n");
  write_file(dir / "history_0_servo.csv", "x\n");
  const auto ledger = coord::run_folder_files(dir);
  write_file(dir / "new.csv", "n");
  write_file(dir / "dem_history.csv", "a,b\n");
  try {
    coord::drop_files_after(dir, ledger);
    FAIL() << "expected CheckpointError";
  } catch (const coord::CheckpointError& e) {
    EXPECT_TRUE(contains(e.what(), "dem_history.csv")) << e.what();
  }
  EXPECT_TRUE(fs::exists(dir / "new.csv"));  // nothing deleted when refused
  write_file(dir / "dem_history.csv", "a,b\n1,2\n");
  fs::remove(dir / "history_0_servo.csv");
  try {
    coord::drop_files_after(dir, ledger);
    FAIL() << "expected CheckpointError";
  } catch (const coord::CheckpointError& e) {
    EXPECT_TRUE(contains(e.what(), "history_0_servo.csv")) << e.what();
    EXPECT_TRUE(contains(e.what(), "missing")) << e.what();
  }
}

// ---- branch ----

namespace {
struct SceneText {
  std::string seed = "3", threads = "1", dem_damping = "", diameter = "0.4e-3", interval = "1", size_near = "0.5e-3",
              servo_steps = "1", inertial = "1e-2", dem_ranks = "";
  bool last_stage = true;
  std::string text() const {
    std::string t = "[run]\nname = \"b\"\nseed = " + seed + "\nthreads = " + threads + "\n[gravity]\nlevel = 100\n[dem]\n" +
                    (dem_damping.empty() ? "" : "damping = " + dem_damping + "\n") +
                    (dem_ranks.empty() ? "" : "ranks = " + dem_ranks + "\n") +
                    "[dem.specimen]\nscale = 1.5\ncell = [1e-3, 1e-3, 1e-3]\nreplicate = [1, 1, 2]\nporosity = 0.52\n"
                    "[dem.footing]\ndiameter = " + diameter + "\nheight = 0.2e-3\n"
                    "[continuum]\n[continuum.mesh]\nsize = [4e-3, 4e-3, 4e-3]\ninner_size = [1e-3, 1e-3, 2e-3]\n"
                    "size_near = " + size_near + "\nsize_far = 1e-3\n"
                    "[[continuum.material]]\nyoung = 1e9\npoisson = 0.3\ndensity = 1272.0\n"
                    "[coupling]\ninterval = " + interval + "\n"
                    "[[stage]]\nname = \"generate\"\naction = \"generate\"\nnodes = [\"dem\"]\nsteps = 1\n"
                    "[[stage]]\nname = \"servo\"\naction = \"servo\"\nnodes = [\"dem\"]\nsteps = " + servo_steps + "\n"
                    "[[stage]]\nname = \"gravity\"\naction = \"couple\"\ncoupled = true\nsteps = 40\nuntil = \"done\"\n";
    if (last_stage)
      t += "[[stage]]\nname = \"penetrate\"\naction = \"penetrate\"\ncoupled = true\nsteps = 200\nuntil = \"done\"\n"
           "inertial_number = " + inertial + "\n";
    return t;
  }
  config::Scene scene() const { return config::Scene::parse(text(), "x.toml", schema::scene_schema()); }
};

struct Branch {
  coord::CheckpointRecord rec;
  coord::Manifest man;
  explicit Branch(std::vector<std::string> participated, std::size_t ran = 3) {
    rec.runner.stage = ran;
    rec.runner.in_stage = false;
    rec.participated = std::move(participated);
    rec.nodes = {{"dem", "dem_node"}, {"continuum", "fdm_node"}};
    man.tag = "gravity-40-end";
    man.stage_name = "gravity";
    man.in_stage = false;
  }
  std::vector<std::string> conflicts(const SceneText& changed) const {
    return coord::branch_conflicts(SceneText{}.scene(), changed.scene(), rec, man);
  }
};
std::string joined(const std::vector<std::string>& v) {
  std::string s;
  for (auto& l : v) s += l + "\n";
  return s;
}
}  // namespace

TEST_F(Checkpoint, BranchWithTheSameSceneHasNoConflict) {
  Branch b({"dem", "continuum"});
  EXPECT_TRUE(b.conflicts(SceneText{}).empty()) << joined(b.conflicts(SceneText{}));
}

TEST_F(Checkpoint, BranchRefusesAnotherSeedOnceAStageRan) {
  SceneText s;
  s.seed = "4";
  Branch b({"dem"});
  const auto c = b.conflicts(s);
  ASSERT_EQ(c.size(), 1u) << joined(c);
  EXPECT_TRUE(contains(c[0], "run.seed")) << c[0];
  EXPECT_TRUE(contains(c[0], "3")) << c[0];
  EXPECT_TRUE(contains(c[0], "4")) << c[0];
  // Before any stage ran the seed is free.
  Branch none({}, 0);
  EXPECT_TRUE(none.conflicts(s).empty()) << joined(none.conflicts(s));
}

TEST_F(Checkpoint, BranchMayChangeLaterStagesAndFreeKeys) {
  Branch b({"dem", "continuum"});
  SceneText later;
  later.inertial = "5e-3";  // stage[3] has not run
  EXPECT_TRUE(b.conflicts(later).empty()) << joined(b.conflicts(later));
  SceneText fr;
  fr.diameter = "0.6e-3";
  fr.dem_damping = "0.5";
  fr.interval = "2";
  fr.threads = "4";
  fr.dem_ranks = "3";  // the DEM's rank count changes no bit (docs/scaling.md)
  EXPECT_TRUE(b.conflicts(fr).empty()) << joined(b.conflicts(fr));
}

TEST_F(Checkpoint, BranchRefusesAChangedStageThatRan) {
  SceneText s;
  s.servo_steps = "2";
  Branch b({"dem"});
  const auto c = b.conflicts(s);
  ASSERT_EQ(c.size(), 1u) << joined(c);
  EXPECT_TRUE(contains(c[0], "stage[1].steps")) << c[0];
}

TEST_F(Checkpoint, BranchRefusesContinuumKeysOnlyWhenItTookPart) {
  SceneText s;
  s.size_near = "0.25e-3";
  Branch dem_only({"dem"});
  EXPECT_TRUE(dem_only.conflicts(s).empty()) << joined(dem_only.conflicts(s));
  Branch both({"dem", "continuum"});
  const auto c = both.conflicts(s);
  ASSERT_EQ(c.size(), 1u) << joined(c);
  EXPECT_TRUE(contains(c[0], "continuum.mesh.size_near")) << c[0];
}

TEST_F(Checkpoint, BranchStartsOnlyFromAStageEndCheckpoint) {
  Branch b({"dem", "continuum"});
  b.man.in_stage = true;
  b.man.tag = "gravity-20";
  const auto c = b.conflicts(SceneText{});
  ASSERT_EQ(c.size(), 1u) << joined(c);
  EXPECT_TRUE(contains(c[0], "stage-end checkpoint")) << c[0];
  EXPECT_TRUE(contains(c[0], "gravity-20")) << c[0];
}

TEST_F(Checkpoint, BranchRefusesFewerStagesThanRan) {
  SceneText s;
  s.last_stage = false;
  Branch b({"dem", "continuum"}, 4);  // all four stages ran
  const auto c = b.conflicts(s);
  ASSERT_FALSE(c.empty());
  EXPECT_TRUE(contains(joined(c), "ran 4 stages, the scene has 3")) << joined(c);
}

// The checkpoint policy of a run (coord::CheckpointPolicy): folder names, the record and the
// manifest, retention of checkpoints inside stages, a node that cannot save, the due timer.
TEST_F(Checkpoint, PolicyNamesKeepsAndStopsAsTheSceneSays) {
  auto sc = config::Scene::parse("[dem]\n[continuum]\n[[stage]]\nname = \"gravity\"\nsteps = 100\n"
                                 "[[stage]]\nname = \"penetrate\"\nsteps = 100\n",
                                 "x.toml", schema::scene_schema());
  auto stages = schema::stages(sc);
  std::vector<std::string> lines;
  bool can_save = true;
  coord::CheckpointPolicy p(
      dir, {true, 0.0, 2}, stages, sc.hash(), 77,
      [&](const std::string& rel, std::int64_t, std::int32_t, const std::string&) {
        write_file(dir / rel / "dem.state", "dem bytes " + rel);
        return std::map<std::string, bool>{{"dem (dem_node)", true}, {"continuum (x)", can_save}};
      },
      [&](const coord::RunnerState&) {
        coord::CheckpointRecord r;
        r.scene_text = sc.text();
        r.participated = {"dem"};
        return r;
      },
      [&](const std::string& l) { lines.push_back(l); });
  EXPECT_FALSE(p.due()) << "every_s = 0: no checkpoint inside stages";
  coord::RunnerState end;
  end.stage = 1;  // after stage 0
  end.step = 40;
  p.take(end);
  auto m = coord::verify_checkpoint(dir / "checkpoints" / "gravity-39-end");
  EXPECT_EQ(m.step, 39);
  EXPECT_FALSE(m.in_stage);
  EXPECT_EQ(m.run_id, 77);
  auto rec = coord::load_record(dir / "checkpoints" / "gravity-39-end" / "coordinator.state", sc.hash());
  EXPECT_EQ(rec.runner.step, 40);
  EXPECT_EQ(rec.participated, std::vector<std::string>{"dem"});
  // Inside the second stage: only the newest two are kept; the stage-end one stays.
  for (std::int64_t step : {50, 60, 70}) {
    coord::RunnerState in;
    in.stage = 1;
    in.in_stage = true;
    in.step = step + 1;
    p.take(in);
  }
  EXPECT_FALSE(fs::exists(dir / "checkpoints" / "penetrate-50"));
  EXPECT_TRUE(fs::exists(dir / "checkpoints" / "penetrate-60" / "manifest.txt"));
  EXPECT_TRUE(fs::exists(dir / "checkpoints" / "penetrate-70" / "manifest.txt"));
  EXPECT_TRUE(fs::exists(dir / "checkpoints" / "gravity-39-end" / "manifest.txt"));
  EXPECT_TRUE(contains(p.summary(100.0), "4 written in")) << p.summary(100.0);
  EXPECT_TRUE(contains(lines.at(0), "checkpoint checkpoints/gravity-39-end: ")) << lines.at(0);
  // A node that cannot save: no folder, checkpoints off for the run, one line naming it.
  can_save = false;
  coord::RunnerState last;
  last.stage = 2;
  last.step = 90;
  p.take(last);
  EXPECT_FALSE(p.on());
  EXPECT_FALSE(fs::exists(dir / "checkpoints" / "penetrate-89-end"));
  EXPECT_TRUE(contains(lines.back(), "node 'continuum (x)' cannot save")) << lines.back();
  // A policy whose run has no folder never checkpoints; a tiny interval is due at once.
  coord::CheckpointPolicy none("", {true, 600, 2}, stages, 0, 0, {}, {}, {});
  EXPECT_FALSE(none.on());
  EXPECT_FALSE(none.due());
  coord::CheckpointPolicy soon(dir, {false, 1e-9, 2}, stages, 0, 0, {}, {}, {});
  EXPECT_TRUE(soon.due());
}
