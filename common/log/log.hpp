// One spdlog logger per process: a file <run_dir>/<name>.log (everything from info up) and
// stderr (warnings and errors, prefixed with the process name so that launch/run's combined
// output says who spoke). Without a run dir only stderr is used.
#pragma once
#include <memory>
#include <string>

#include <spdlog/spdlog.h>

namespace demfdm::log {
std::shared_ptr<spdlog::logger> setup(const std::string& name, const std::string& run_dir,
                                      bool verbose = false);
}
