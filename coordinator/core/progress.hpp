// One progress line for long stages (issue 14 item 1), independent of the transport.
//
// The coordinator feeds every observed step's reports; the line says where the stage is:
//   penetrate  step 12,340 of 80,000 | settlement 0.41 of 0.10 D_f target (41 %) | load 0.213 N |
//              2,310 steps/s | ETA 0:02:51
//   gravity    step 812 of 20,000 | ratio 3.2e-03 -> 1.0e-03 | 2,950 steps/s | ETA <= 0:06:30
// The criterion is the stage's own: the footing settlement against depth_ratio D_f for a
// penetration, the largest unbalanced-force ratio of the stage's nodes against its `ratio` for
// a stage that runs until its nodes are done, else the steps against the budget. The ETA
// extrapolates the criterion's progress at the rate of the last interval (settlement per
// second; for an equilibrium only the budget bounds it, shown as "<=").
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "common/schema/scene_schema.hpp"
#include "coordinator/core/runner.hpp"

namespace demfdm::coord {

class Progress {
 public:
  // every_s: the interval between two lines (a terminal gets a rewritten line more often).
  explicit Progress(double every_s) : every_s_(every_s) {}
  // The footing's diameter [m] (0: the scene has none).
  void set_footing_diameter(double d) { d_f_ = d; }
  // A step's reports; returns the line when one is due (or when `force`).
  std::optional<std::string> observe(const schema::Stage& st, std::int64_t stage_first_step, std::int64_t step,
                                     const std::map<std::string, NodeReport>& reps,
                                     std::chrono::steady_clock::time_point now, bool force = false);

 private:
  double every_s_, d_f_ = 0;
  std::string stage_;
  std::chrono::steady_clock::time_point t_last_{};
  std::int64_t step_last_ = 0;
  double crit_last_ = 0;
  bool have_last_ = false;
};

// "0:02:51" for a number of seconds ("-" when not finite or negative).
std::string clock_text(double seconds);

}  // namespace demfdm::coord
