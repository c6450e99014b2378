#include "common/log/log.hpp"

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>

namespace demfdm::log {
std::shared_ptr<spdlog::logger> setup(const std::string& name, const std::string& run_dir, bool verbose) {
  std::vector<spdlog::sink_ptr> sinks;
  auto err = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
  err->set_level(verbose ? spdlog::level::info : spdlog::level::warn);
  err->set_pattern("[" + name + "] %^%l%$: %v");
  sinks.push_back(err);
  if (!run_dir.empty()) {
    auto file = std::make_shared<spdlog::sinks::basic_file_sink_mt>(run_dir + "/" + name + ".log", false);
    file->set_level(spdlog::level::info);
    file->set_pattern("%Y-%m-%d %H:%M:%S.%e %l %v");
    sinks.push_back(file);
  }
  auto logger = std::make_shared<spdlog::logger>(name, sinks.begin(), sinks.end());
  logger->set_level(spdlog::level::info);
  logger->flush_on(spdlog::level::info);
  spdlog::set_default_logger(logger);
  return logger;
}
}  // namespace demfdm::log
