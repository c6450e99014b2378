// Scratch paths of a test process under the system temp folder (run folders, scenes, captured
// output), removed when every test of the process passed and kept for inspection otherwise.
#pragma once

#include <gtest/gtest.h>

#include <filesystem>
#include <string>
#include <vector>

namespace demfdm::testing {

inline std::vector<std::filesystem::path>& scratch_paths() {
  static std::vector<std::filesystem::path> paths;
  return paths;
}

// temp_directory_path() / name, registered for removal at the end of a passing run.
inline std::filesystem::path scratch(const std::string& name) {
  auto p = std::filesystem::temp_directory_path() / name;
  scratch_paths().push_back(p);
  return p;
}

class RemoveScratchPaths : public ::testing::Environment {
 public:
  void TearDown() override {
    if (!::testing::UnitTest::GetInstance()->Passed()) return;
    std::error_code ec;
    for (const auto& p : scratch_paths()) std::filesystem::remove_all(p, ec);
  }
};

inline ::testing::Environment* const kRemoveScratchPaths =
    ::testing::AddGlobalTestEnvironment(new RemoveScratchPaths);

}  // namespace demfdm::testing
