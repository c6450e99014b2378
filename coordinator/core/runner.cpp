#include "coordinator/core/runner.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace demfdm::coord {
namespace {
double seconds_since(std::chrono::steady_clock::time_point t) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}
}  // namespace

Runner::Runner(std::vector<schema::Stage> stages, Driver& driver, std::map<std::string, double> dt_stable,
               std::int64_t window)
    : stages_(std::move(stages)), driver_(driver), dt_stable_(std::move(dt_stable)), window_(std::max<std::int64_t>(1, window)) {}

double Runner::stage_dt(const schema::Stage& st) const {
  double dt = std::numeric_limits<double>::infinity();
  for (auto& r : st.nodes) {
    auto it = dt_stable_.find(r);
    if (it != dt_stable_.end() && it->second > 0) dt = std::min(dt, it->second);
  }
  return std::isfinite(dt) ? dt : 0.0;
}

RunSummary Runner::run() {
  RunSummary sum;
  auto run_start = std::chrono::steady_clock::now();
  std::int64_t step = 0;  // next global coupling step
  for (std::size_t si = 0; si < stages_.size(); ++si) {
    const auto& st = stages_[si];
    auto idx = static_cast<std::int32_t>(si);
    StageSummary ss;
    ss.name = st.name;
    ss.action = st.action;
    ss.first_step = step;
    auto t0 = std::chrono::steady_clock::now();
    ss.begin = driver_.command(Cmd::StageBegin, st.nodes, step - 1, idx, st.name, stage_dt(st), {});
    for (auto& [r, rep] : ss.begin) {
      if (rep.dt_stable > 0) dt_stable_[r] = rep.dt_stable;
      ss.compute_s[r] += rep.compute_s;  // set-up procedures (generation, servo) run here
      ss.wait_s[r] += rep.wait_s;
    }
    clock_ = GrantClock{};
    clock_.stage_index = idx;
    clock_.stage_first_step = step;
    std::int64_t end = step + st.steps;  // exclusive
    const std::int64_t window = st.coupled ? window_ : 1;
    std::deque<std::int64_t> outstanding;  // last step of each posted, uncollected grant
    std::int64_t next = step;              // first step not yet granted
    bool done = false;
    while (next < end || !outstanding.empty()) {
      // Fill the window (not after the criterion was met).
      while (!done && next < end && static_cast<std::int64_t>(outstanding.size()) < window) {
        std::int64_t last = std::min(end - 1, next + st.steps_per_grant - 1);
        double dt = stage_dt(st);
        std::vector<double> values;
        clock_.first_step = next;
        clock_.last_step = last;
        clock_.dt = dt;
        if (kinematics_) values = kinematics_(st, last, dt);
        clock_.t_begin += dt * static_cast<double>(last - next + 1);
        driver_.post(Cmd::Grant, st.nodes, last, idx, st.name, dt, values);
        outstanding.push_back(last);
        next = last + 1;
      }
      if (outstanding.empty()) break;
      std::int64_t last = outstanding.front();
      outstanding.pop_front();
      auto reps = driver_.collect(Cmd::Grant, st.nodes, last, idx);
      step = last + 1;
      bool all_done = true;
      for (auto& [r, rep] : reps) {
        if (rep.dt_stable > 0) dt_stable_[r] = rep.dt_stable;
        ss.compute_s[r] += rep.compute_s;
        ss.wait_s[r] += rep.wait_s;
        if (rep.status != Status::StageDone) all_done = false;
      }
      if (observer_) {
        bool rows = false;
        for (auto& [r, rep] : reps) rows = rows || !rep.rows.empty();
        if (!rows) {
          observer_(st, last, reps);
        } else {
          // One observation per step of the block, each node's values of that step.
          for (std::int64_t k = last - st.steps_per_grant + 1; k <= last; ++k) {
            std::map<std::string, NodeReport> per;
            for (auto& [r, rep] : reps) {
              NodeReport n = rep;
              n.rows.clear();
              for (auto& [ks, v] : rep.rows)
                if (ks == k) {
                  n.values = v;
                  auto t = n.values.find("time_s");
                  if (t != n.values.end()) {
                    n.time = t->second;
                    n.values.erase(t);
                  }
                }
              per[r] = n;
            }
            bool any = false;
            for (auto& [r, rep] : reps)
              for (auto& [ks, v] : rep.rows) any = any || ks == k;
            if (any) observer_(st, k, per);
          }
        }
      }
      if (st.until_done && all_done) done = true;  // collect what is still outstanding, post nothing more
    }
    ss.last_step = step - 1;
    ss.criterion_met = done || !st.until_done;
    ss.ended_by = st.until_done ? (done ? "done" : "budget") : "steps";
    ss.end = driver_.command(Cmd::StageEnd, st.nodes, step - 1, idx, st.name, stage_dt(st), {});
    for (auto& [r, rep] : ss.end) {
      ss.compute_s[r] += rep.compute_s;
      ss.wait_s[r] += rep.wait_s;
    }
    ss.wall_s = seconds_since(t0);
    sum.stages.push_back(ss);
    if (st.until_done && !done && st.fail_on_budget)
      throw StageError("stage '" + st.name + "' (#" + std::to_string(si) + ") used its budget of " +
                       std::to_string(st.steps) + " steps without every node reporting its exit criterion met");
  }
  sum.steps = step;
  sum.wall_s = seconds_since(run_start);
  return sum;
}

}  // namespace demfdm::coord
