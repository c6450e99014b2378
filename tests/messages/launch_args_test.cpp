// launch/run's command line: a second scene, an option without its value and a runs root that
// is missing and cannot be created, or cannot be written, are each one line naming the cause
// and exit 2, before anything is built, checked or started. A valid command line still works.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>

#include "tests/integration/process.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {

const std::string kSrc = DEMFDM_SOURCE_DIR;
const std::string kScene = kSrc + "/scenes/chain_serial.toml";

struct Result {
  int code = -1;
  std::string out;
};

Result launch(const std::vector<std::string>& args) {
  static int n = 0;
  fs::path out = fs::temp_directory_path() / ("demfdm-launch-args-" + std::to_string(::getpid()) + "-" +
                                              std::to_string(n++) + ".out");
  std::vector<std::string> argv{"/bin/bash", kSrc + "/launch/run"};
  argv.insert(argv.end(), args.begin(), args.end());
  auto p = spawn(argv, {"DEMFDM_BUILD=" + fs::path(DEMFDM_BIN_DIR).parent_path().string()}, out.string());
  auto st = wait_for(p, 30);
  if (!st) kill_and_reap(p);
  Result r{st ? exit_code(*st) : -1, read_file(out.string())};
  fs::remove(out);
  return r;
}

// One line with exactly this text's substring, and exit 2.
void expect_one_error(const Result& r, const std::string& what) {
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_EQ(std::count(r.out.begin(), r.out.end(), '\n'), 1) << "one line expected:\n" << r.out;
  EXPECT_NE(r.out.find(what), std::string::npos) << "expected '" << what << "' in:\n" << r.out;
}

}  // namespace

TEST(LaunchRunArgs, SecondSceneIsRefused) {
  auto other = kSrc + "/scenes/chain_parallel.toml";
  expect_one_error(launch({kScene, other, "--no-build"}),
                   "launch/run: two scenes given ('" + kScene + "' and '" + other + "')");
  expect_one_error(launch({kScene, "--no-build", "--check", other}), "two scenes given");
}

TEST(LaunchRunArgs, OptionWithoutItsValueIsNamed) {
  expect_one_error(launch({kScene, "--no-build", "--run-dir"}), "launch/run: --run-dir needs a value (--run-dir DIR)");
  expect_one_error(launch({kScene, "--run-dir", "--no-build"}),
                   "launch/run: --run-dir needs a value (--run-dir DIR), found the option '--no-build' instead");
  expect_one_error(launch({kScene, "--no-build", "--runs-root="}), "launch/run: --runs-root needs a value");
  expect_one_error(launch({kScene, "--no-build", "--seeds"}), "launch/run: --seeds needs a value (--seeds SPEC)");
  expect_one_error(launch({kScene, "--no-build", "--set-executable"}), "launch/run: --set-executable needs a value");
}

TEST(LaunchRunArgs, RunsRootMissingReadOnlyOrAFile) {
  // /proc accepts no new folder: missing and cannot be created.
  expect_one_error(launch({kScene, "--no-build", "--runs-root", "/proc/demfdm-no-such/runs"}),
                   "launch/run: runs root '/proc/demfdm-no-such/runs' does not exist and cannot be created");
  // Exists, cannot be written: /sys as root (root ignores permission bits), else a 0555 folder.
  fs::path ro = fs::temp_directory_path() / ("demfdm-ro-root-" + std::to_string(::getpid()));
  std::string root = "/sys";
  if (::geteuid() != 0) {
    fs::create_directories(ro);
    ::chmod(ro.c_str(), 0555);
    root = ro.string();
  }
  expect_one_error(launch({kScene, "--no-build", "--runs-root", root}),
                   "launch/run: runs root '" + root + "' is not writable");
  ::chmod(ro.c_str(), 0755);
  fs::remove_all(ro);
  fs::path file = fs::temp_directory_path() / ("demfdm-root-file-" + std::to_string(::getpid()));
  std::ofstream(file) << "not a folder\n";
  expect_one_error(launch({kScene, "--no-build", "--runs-root", file.string()}),
                   "launch/run: runs root '" + file.string() + "' is not a folder");
  fs::remove(file);
  // The --opt=value form.
  expect_one_error(launch({kScene, "--no-build", "--runs-root=/proc/demfdm-no-such"}),
                   "does not exist and cannot be created");
}

TEST(LaunchRunArgs, ValidCommandLinesStillWork) {
  // --check starts nothing and needs no runs root.
  auto r = launch({kScene, "--no-build", "--check", "--runs-root", "/proc/demfdm-no-such"});
  EXPECT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("chain_serial.toml: OK"), std::string::npos) << r.out;
  auto r2 = launch({"--no-build", "--check", "--run-dir=/tmp/unused", kScene});
  EXPECT_EQ(r2.code, 0) << r2.out;
  auto r3 = launch({kScene, "--no-build", "--frobnicate"});
  expect_one_error(r3, "launch/run: unknown option '--frobnicate'");
}
