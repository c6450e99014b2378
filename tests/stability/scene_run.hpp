// Helpers for tests that run a scene end to end through launch/run and read its run folder
// (tests/stability; usable by any test folder that adds PROJECT_SOURCE_DIR to its includes).
#pragma once

#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "tests/integration/process.hpp"

namespace demfdm::testing {

namespace fs = std::filesystem;
using Columns = std::map<std::string, std::vector<double>>;

inline std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  if (!f) throw std::runtime_error("cannot open " + p.string());
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// CSV with a header row; "nan" cells read as NaN.
inline Columns read_columns(const fs::path& p) {
  std::istringstream f(slurp(p));
  std::string line, cell;
  std::getline(f, line);
  std::vector<std::string> names;
  std::stringstream hs(line);
  while (std::getline(hs, cell, ',')) names.push_back(cell);
  Columns cols;
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    for (std::size_t i = 0; std::getline(ss, cell, ','); ++i) cols[names.at(i)].push_back(std::stod(cell));
  }
  return cols;
}

inline void replace_once(std::string& s, const std::string& from, const std::string& to) {
  auto i = s.find(from);
  if (i == std::string::npos) throw std::runtime_error("scene text has no '" + from + "'");
  s.replace(i, from.size(), to);
}

struct SceneRun {
  int code = -1;        // launch/run's exit code
  fs::path root, dir;   // temporary folder, run folder inside it
  std::string output;   // launch/run's stdout + stderr
  // Removes the temporary folder (call when the checks passed; kept for inspection otherwise).
  void clean() const { fs::remove_all(root); }
};

// Runs a scene text through launch/run (bin_dir: the build's bin folder) with a deadline.
inline SceneRun run_scene_text(const std::string& source_dir, const std::string& bin_dir, const std::string& tag,
                               const std::string& text, double timeout_s = 55) {
  SceneRun r;
  r.root = fs::temp_directory_path() / ("demfdm-" + tag + "-" + std::to_string(getpid()));
  fs::remove_all(r.root);
  fs::create_directories(r.root);
  auto scene = r.root / (tag + ".toml");
  std::ofstream(scene) << text;
  r.dir = r.root / "run";
  auto out = r.root / "out.txt";
  auto p = spawn({"/bin/bash", source_dir + "/launch/run", scene.string(), "--no-build", "--run-dir", r.dir.string()},
                 {"DEMFDM_BUILD=" + fs::path(bin_dir).parent_path().string()}, out.string());
  auto st = wait_for(p, timeout_s);
  if (!st) {
    kill_and_reap(p);
    throw std::runtime_error(tag + ": the run did not finish in " + std::to_string(timeout_s) + " s");
  }
  r.code = exit_code(*st);
  r.output = read_file(out.string());
  return r;
}

}  // namespace demfdm::testing
