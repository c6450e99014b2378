// Coordinated checkpoints end to end (issue 13; docs/checkpoint-format.md): the reduced coupled
// footing scene (scenes/footing_small.toml, all six stages) through launch/run, as a user runs
// it.
//  * Checkpoints change nothing: a run with checkpoints inside the stages writes the same
//    results as one with stage-end checkpoints only.
//  * Resume after kill -9: the DEM node is killed in the middle of the coupled penetration,
//    the newest checkpoint is damaged on purpose, and `launch/run --resume` continues from the
//    previous one: every CSV and sidecar has the same bytes and every HDF5 dataset the same
//    type, shape and bits as the uninterrupted run.
//  * Branch: `launch/run SCENE --from <gravity stage-end checkpoint>` with the same scene gives
//    the uninterrupted run's penetration history byte for byte; with another footing rate it
//    runs and differs; a changed seed or mesh is refused at --check naming the key and both
//    values.
#include <dirent.h>
#include <gtest/gtest.h>
#include <hdf5.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <regex>
#include <set>
#include <thread>

#include "tests/integration/process.hpp"
#include "tests/integration/scratch.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {
const std::string kBin = DEMFDM_BIN_DIR;
const std::string kSrc = DEMFDM_SOURCE_DIR;

fs::path root() {
  static fs::path r = [] {
    auto p = scratch("demfdm-checkpoint-" + std::to_string(getpid()));
    fs::remove_all(p);
    fs::create_directories(p);
    return p;
  }();
  return r;
}

// footing_small.toml (or another scene) with extra [run] keys.
fs::path scene_with(const std::string& name, const std::string& run_keys, const std::string& replace_from = "",
                    const std::string& replace_to = "", const std::string& base = "footing_small.toml") {
  std::string text = read_file(kSrc + "/scenes/" + base);
  auto at = text.find("[run]\n");
  text.insert(at + 6, run_keys);
  if (!replace_from.empty()) {
    auto p = text.find(replace_from);
    EXPECT_NE(p, std::string::npos) << replace_from;
    if (p != std::string::npos) text.replace(p, replace_from.size(), replace_to);
  }
  auto path = root() / (name + ".toml");
  std::ofstream(path) << text;
  return path;
}

std::vector<std::string> launch_args(std::vector<std::string> extra) {
  std::vector<std::string> a{"/bin/bash", kSrc + "/launch/run", "--no-build"};
  a.insert(a.end(), extra.begin(), extra.end());
  return a;
}
std::vector<std::string> env() { return {"DEMFDM_BUILD=" + fs::path(kBin).parent_path().string()}; }

// Runs launch/run to the end; returns its exit code (-1 on timeout) and leaves its output in out.
int launch(const std::vector<std::string>& extra, const fs::path& out, double timeout_s = 300) {
  auto p = spawn(launch_args(extra), env(), out.string());
  auto st = wait_for(p, timeout_s);
  if (!st) {
    kill_and_reap(p);
    return -1;
  }
  return exit_code(*st);
}

// pid of the process whose command line holds every one of `words`, or -1.
pid_t find_process(const std::vector<std::string>& words) {
  for (auto& e : fs::directory_iterator("/proc")) {
    auto name = e.path().filename().string();
    if (name.find_first_not_of("0123456789") != std::string::npos) continue;
    std::string cmd = read_file((e.path() / "cmdline").string());
    for (auto& c : cmd)
      if (c == '\0') c = ' ';
    bool all = true;
    for (auto& w : words) all = all && cmd.find(w) != std::string::npos;
    if (all) return static_cast<pid_t>(std::stol(name));
  }
  return -1;
}

// Checkpoint folders inside stages ("<stage>-<step>", no "-end") of a run folder.
std::vector<fs::path> inside_checkpoints(const fs::path& run, const std::string& stage) {
  std::vector<fs::path> out;
  if (!fs::exists(run / "checkpoints")) return out;
  std::regex re(stage + "-[0-9]+");
  for (auto& e : fs::directory_iterator(run / "checkpoints"))
    if (std::regex_match(e.path().filename().string(), re) && fs::exists(e.path() / "manifest.txt"))
      out.push_back(e.path());
  return out;
}

// Every dataset of an HDF5 file: path -> (type class and size, shape, raw bytes).
struct Dataset {
  std::string type;
  std::vector<hsize_t> shape;
  std::string bytes;
  bool operator==(const Dataset&) const = default;
};
herr_t visit(hid_t obj, const char* name, const H5O_info_t* info, void* data) {
  if (info->type != H5O_TYPE_DATASET) return 0;
  auto& out = *static_cast<std::map<std::string, Dataset>*>(data);
  hid_t d = H5Dopen2(obj, name, H5P_DEFAULT);
  hid_t t = H5Dget_type(d), nt = H5Tget_native_type(t, H5T_DIR_ASCEND), s = H5Dget_space(d);
  Dataset ds;
  ds.type = std::to_string(H5Tget_class(t)) + "/" + std::to_string(H5Tget_size(t));
  ds.shape.resize(static_cast<std::size_t>(H5Sget_simple_extent_ndims(s)));
  H5Sget_simple_extent_dims(s, ds.shape.data(), nullptr);
  hsize_t n = 1;
  for (auto v : ds.shape) n *= v;
  ds.bytes.resize(n * H5Tget_size(nt));
  if (n > 0) H5Dread(d, nt, H5S_ALL, H5S_ALL, H5P_DEFAULT, ds.bytes.data());
  H5Sclose(s);
  H5Tclose(nt);
  H5Tclose(t);
  H5Dclose(d);
  out[name] = std::move(ds);
  return 0;
}
std::map<std::string, Dataset> datasets(const fs::path& file) {
  std::map<std::string, Dataset> out;
  hid_t f = H5Fopen(file.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  EXPECT_GE(f, 0) << file;
  if (f < 0) return out;
  H5Ovisit(f, H5_INDEX_NAME, H5_ITER_INC, visit, &out);
  H5Fclose(f);
  return out;
}

// Result files of a run folder: CSV, XMF and HDF5 (logs, summary, traffic and checkpoints are
// not results: they hold wall times and the run id).
std::set<std::string> result_files(const fs::path& run) {
  std::set<std::string> out;
  for (auto& e : fs::directory_iterator(run)) {
    auto ext = e.path().extension().string();
    if (e.is_regular_file() && (ext == ".csv" || ext == ".xmf" || ext == ".h5")) out.insert(e.path().filename().string());
  }
  return out;
}

// A CSV without the columns whose names end in `drop` (wall times, which no two runs share).
std::string csv_without(const fs::path& p, const std::string& drop) {
  std::ifstream f(p);
  std::string line, out;
  std::vector<bool> keep;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (keep.empty())
      for (auto& c : cells) keep.push_back(c.size() < drop.size() || c.compare(c.size() - drop.size(), drop.size(), drop) != 0);
    for (std::size_t i = 0; i < cells.size(); ++i)
      if (i >= keep.size() || keep[i]) out += cells[i] + ",";
    out += "\n";
  }
  return out;
}

// Compares every result file of two run folders; returns the number of differences. CSV
// columns ending in `drop_columns` (e.g. "solve_s": the FEM's wall time per solve) are left out.
int compare_results(const fs::path& a, const fs::path& b, const std::string& drop_columns = "") {
  int bad = 0;
  auto fa = result_files(a), fb = result_files(b);
  EXPECT_EQ(fa, fb) << "result files of " << a << " and " << b;
  for (auto& f : fa) {
    if (!fb.count(f)) continue;
    if (fs::path(f).extension() == ".h5") {
      auto da = datasets(a / f), db = datasets(b / f);
      EXPECT_FALSE(da.empty()) << f;
      std::set<std::string> na, nb;
      for (auto& [k, v] : da) na.insert(k);
      for (auto& [k, v] : db) nb.insert(k);
      EXPECT_EQ(na, nb) << f;
      for (auto& [k, v] : da) {
        auto it = db.find(k);
        if (it == db.end()) continue;
        if (!(it->second == v)) {
          ++bad;
          ADD_FAILURE() << f << ": dataset " << k << " differs";
        }
      }
    } else if (!drop_columns.empty() && fs::path(f).extension() == ".csv") {
      if (csv_without(a / f, drop_columns) != csv_without(b / f, drop_columns)) {
        ++bad;
        ADD_FAILURE() << f << " differs between " << a << " and " << b << " (without the *" << drop_columns << " columns)";
      }
    } else if (read_file((a / f).string()) != read_file((b / f).string())) {
      ++bad;
      ADD_FAILURE() << f << " differs between " << a << " and " << b;
    }
  }
  return bad;
}

// The uninterrupted reference (stage-end checkpoints only), shared by the tests.
const fs::path& reference() {
  static fs::path ref = [] {
    auto dir = root() / "reference";
    int rc = launch({scene_with("reference", "checkpoint_every_s = 0\n").string(), "--run-dir", dir.string()},
                    root() / "reference.out");
    EXPECT_EQ(rc, 0) << read_file((root() / "reference.out").string());
    return dir;
  }();
  return ref;
}
}  // namespace

TEST(Checkpoint, ResumeAfterKillNineIsBitExactAndSkipsADamagedCheckpoint) {
  const auto& ref = reference();
  ASSERT_TRUE(fs::exists(ref / "checkpoints" / "gravity-460-end" / "manifest.txt"))
      << "stage-end checkpoints of the reference run";
  // Checkpoints inside the stages every 0.2 s of wall time: the same results.
  auto scene = scene_with("periodic", "checkpoint_every_s = 0.2\n");
  auto full = root() / "periodic";
  ASSERT_EQ(launch({scene.string(), "--run-dir", full.string()}, root() / "periodic.out"), 0);
  auto periodic_inside = inside_checkpoints(full, "penetrate");
  ASSERT_GE(periodic_inside.size(), 1u);
  EXPECT_LE(periodic_inside.size(), 2u) << "run.checkpoint_keep = 2";
  EXPECT_EQ(compare_results(ref, full), 0) << "checkpoints changed the results";
  // A checkpoint inside a stage is for resume, not for a branch.
  EXPECT_EQ(launch({scene.string(), "--from", periodic_inside[0].string(), "--check"}, root() / "inside.out"), 2);
  EXPECT_NE(read_file((root() / "inside.out").string()).find("a branch starts from a stage-end checkpoint"), std::string::npos);

  // The same scene, killed (kill -9 of the DEM node) once two checkpoints inside the
  // penetration exist.
  auto run = root() / "killed";
  auto p = spawn(launch_args({scene.string(), "--run-dir", run.string()}), env(), (root() / "killed.out").string());
  auto t0 = std::chrono::steady_clock::now();
  while (inside_checkpoints(run, "penetrate").size() < 2 &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 120)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_GE(inside_checkpoints(run, "penetrate").size(), 2u) << read_file((root() / "killed.out").string());
  pid_t dem = find_process({"dem_node", "--run-dir=" + run.string()});
  ASSERT_GT(dem, 0);
  ::kill(dem, SIGKILL);
  auto st = wait_for(p, 30);
  ASSERT_TRUE(st);
  EXPECT_NE(exit_code(*st), 0) << "a run whose DEM node was killed must fail";
  EXPECT_FALSE(fs::exists(run / "summary.json")) << "the killed run did not finish";

  // Damage the newest checkpoint: the resume names it and uses the previous one.
  auto inside = inside_checkpoints(run, "penetrate");
  std::sort(inside.begin(), inside.end(), [](const fs::path& a, const fs::path& b) {
    auto step = [](const fs::path& p) { return std::stoll(p.filename().string().substr(p.filename().string().rfind('-') + 1)); };
    return step(a) > step(b);
  });
  {
    std::fstream f(inside[0] / "dem.world.state", std::ios::in | std::ios::out | std::ios::binary);
    f.seekp(1000);
    f.put('\x5a');
  }
  ASSERT_EQ(launch({"--resume", run.string()}, root() / "resumed.out"), 0) << read_file((root() / "resumed.out").string());
  auto log = read_file((run / "coordinator.log").string());
  EXPECT_NE(log.find(inside[0].filename().string() + ": file dem.world.state fails its checksum"), std::string::npos) << log;
  EXPECT_NE(log.find("resuming run " + run.string() + " from " + inside[1].string()), std::string::npos) << log;
  EXPECT_EQ(compare_results(ref, run), 0) << "the resumed run differs from the uninterrupted one";
  EXPECT_NE(read_file((run / "summary.txt").string()).find("resumed from " + inside[1].string()), std::string::npos);
}

TEST(Checkpoint, BranchFromTheGravityStateRepeatsOrChangesThePenetration) {
  const auto& ref = reference();
  auto ckpt = ref / "checkpoints" / "gravity-460-end";
  ASSERT_TRUE(fs::exists(ckpt / "manifest.txt"));
  // The same scene: the penetration history of the uninterrupted run, byte for byte.
  auto same = root() / "branch-same";
  ASSERT_EQ(launch({(ref / "scene.toml").string(), "--from", ckpt.string(), "--run-dir", same.string()},
                   root() / "branch-same.out"),
            0)
      << read_file((root() / "branch-same.out").string());
  EXPECT_FALSE(fs::exists(same / "history_0_generate.csv")) << "a branch does not run the saved stages again";
  ASSERT_TRUE(fs::exists(same / "history_5_penetrate.csv"));
  EXPECT_EQ(read_file((same / "history_5_penetrate.csv").string()), read_file((ref / "history_5_penetrate.csv").string()));
  EXPECT_EQ(read_file((same / "dem_profile_penetrate.csv").string()), read_file((ref / "dem_profile_penetrate.csv").string()));

  // Another footing rate and damping: runs from the same state and gives another curve.
  auto slower = scene_with("slower", "checkpoint_every_s = 0\n", "inertial_number = 1e-2", "inertial_number = 5e-3\ndamping = 0.3");
  auto other = root() / "branch-slower";
  ASSERT_EQ(launch({slower.string(), "--from", ckpt.string(), "--run-dir", other.string()}, root() / "branch-slower.out"), 0)
      << read_file((root() / "branch-slower.out").string());
  EXPECT_NE(read_file((other / "history_5_penetrate.csv").string()), read_file((ref / "history_5_penetrate.csv").string()));

  // Keys that would make the saved state inconsistent are refused at --check.
  auto bad = scene_with("bad", "checkpoint_every_s = 0\n", "size_far = 1e-3", "size_far = 0.9e-3");
  {
    std::string text = read_file(bad.string());
    text.replace(text.find("seed = 3"), 8, "seed = 4");
    std::ofstream(bad) << text;
  }
  auto out = root() / "bad.out";
  EXPECT_EQ(launch({bad.string(), "--from", ckpt.string(), "--check"}, out), 2);
  auto msg = read_file(out.string());
  EXPECT_NE(msg.find("run.seed: the saved state has 3, the scene 4"), std::string::npos) << msg;
  EXPECT_NE(msg.find("continuum.mesh.size_far: the saved state has 0.001"), std::string::npos) << msg;
}

// The implicit FEM continuum (fem_node) saves its model and rebuilds its factorisation: killing
// the continuum node in the middle of the penetration and resuming gives the uninterrupted
// run's results (its history's solve_s column is a wall time and is left out).
TEST(Checkpoint, FemContinuumKilledAndResumedGivesTheUninterruptedResults) {
  auto ref = root() / "fem-reference";
  ASSERT_EQ(launch({scene_with("fem-reference", "checkpoint_every_s = 0\n", "", "", "footing_small_fem.toml").string(),
                    "--run-dir", ref.string()},
                   root() / "fem-reference.out"),
            0)
      << read_file((root() / "fem-reference.out").string());
  auto scene = scene_with("fem-periodic", "checkpoint_every_s = 0.2\n", "", "", "footing_small_fem.toml");
  auto run = root() / "fem-killed";
  auto p = spawn(launch_args({scene.string(), "--run-dir", run.string()}), env(), (root() / "fem-killed.out").string());
  auto t0 = std::chrono::steady_clock::now();
  while (inside_checkpoints(run, "penetrate").empty() &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < 120)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  ASSERT_FALSE(inside_checkpoints(run, "penetrate").empty()) << read_file((root() / "fem-killed.out").string());
  pid_t fem = find_process({"fem_node", "--run-dir=" + run.string()});
  ASSERT_GT(fem, 0);
  ::kill(fem, SIGKILL);
  auto st = wait_for(p, 30);
  ASSERT_TRUE(st);
  EXPECT_NE(exit_code(*st), 0);
  ASSERT_EQ(launch({"--resume", run.string()}, root() / "fem-resumed.out"), 0)
      << read_file((root() / "fem-resumed.out").string());
  EXPECT_TRUE(fs::exists(run / "fem.h5"));
  EXPECT_EQ(compare_results(ref, run, "solve_s"), 0);
}
