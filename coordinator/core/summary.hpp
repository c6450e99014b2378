// The run summary: summary.txt (for people) and summary.json (for studies), built from the
// stage machine's RunSummary, independent of the transport.
//
// Effects: a node reports, in its STAGE_END values, one entry `effect_s.<name>` per effect that
// ran in the stage (seconds spent on it). The summary lists them per stage and node with their
// share of the node's compute time in the stage, and sums them over the run per node. An effect
// the scene does not enable is never reported, so it appears nowhere.
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "coordinator/core/quasi_static.hpp"
#include "coordinator/core/runner.hpp"

namespace demfdm::coord {

inline constexpr const char* kEffectPrefix = "effect_s.";
// CPU utilisation: a node reports, in its STAGE_END values, `cpu_s`, the CPU time of its whole
// process (all threads, user + system) over the stage. The summary divides it by the stage's
// wall time (cores the node kept busy) and adds the nodes up against the machine's cores.
inline constexpr const char* kCpuKey = "cpu_s";
// Peak memory: a node reports, in its STAGE_END values, `peak_rss_mb`, the largest resident set of
// its process so far; the DEM on MPI ranks also `peak_rss_mb_other_ranks`, the largest of its
// other ranks' (rank 0's is the node's). The summary gives the largest over the stages.
inline constexpr const char* kPeakKey = "peak_rss_mb";
inline constexpr const char* kPeakRanksKey = "peak_rss_mb_other_ranks";

struct NodeInfo {
  std::string role, solver, host, build_id;
  std::int64_t pid = 0;
};

struct RunInfo {
  std::string scene;          // scene file
  std::uint64_t hash = 0;     // scene hash
  std::vector<NodeInfo> nodes;
  std::string bus;            // one line of the coordinator's bus counters (text summary only)
  std::string checkpoints;    // one line: checkpoints written, size, time (text summary only)
  std::string resumed;        // "resumed from <checkpoint>" / "branched from <checkpoint>", or ""
  // Further top-level members of summary.json, in order: name -> JSON value text (the run's
  // identity, its result, the centrifuge report).
  std::vector<std::pair<std::string, std::string>> extra_json;
  // Footing rate and quasi-static measures of each penetrate stage, by index in
  // RunSummary::stages (coordinator/core/quasi_static.hpp). The text summary ends with a
  // "WARNING: not quasi-static:" line for each stage above its limit.
  std::map<std::size_t, RateMeasures> rates;
  // Logical CPUs of the coordinator's host (0: unknown): the denominator of "cores busy".
  int host_cores = 0;
};

// effect name -> seconds, from one node's STAGE_END values.
std::map<std::string, double> effects_of(const NodeReport& end);

// A node's CPU seconds of one stage (its STAGE_END `cpu_s`); negative when not reported.
double cpu_of(const NodeReport& end);

// role -> effect -> seconds summed over the run; role -> compute seconds summed over the run;
// role -> CPU seconds over the stages that reported them, and the wall time of those stages.
struct RunTotals {
  std::map<std::string, std::map<std::string, double>> effects;
  std::map<std::string, double> compute_s, wait_s, cpu_s, cpu_wall_s;
  std::map<std::string, double> peak_mb, peak_ranks_mb;  // role -> the largest reported [MB]
};
RunTotals run_totals(const RunSummary& sum);

std::string summary_text(const RunInfo& info, const RunSummary& sum);
std::string summary_json(const RunInfo& info, const RunSummary& sum);

// JSON string literal (quotes, backslashes and control characters escaped).
std::string json_string(const std::string& s);
// JSON number with 10 significant digits; null when not finite (JSON has no NaN).
std::string json_number(double v);

}  // namespace demfdm::coord
