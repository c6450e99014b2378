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
  double wall_before = 0;  // run wall time before this process (a resumed run)
  std::int64_t step = 0;   // next global coupling step
  std::size_t first = 0;
  std::optional<RunnerState> resume = std::move(start_);
  start_.reset();
  if (resume) {
    sum.stages = resume->done;
    step = resume->step;
    first = resume->stage;
    wall_before = resume->wall_s;
    for (auto& [r, dt] : resume->dt_stable) dt_stable_[r] = dt;
    if (!resume->in_stage) resume.reset();  // at a stage boundary: the next stage begins as usual
  }
  auto run_wall = [&] { return wall_before + seconds_since(run_start); };
  for (std::size_t si = first; si < stages_.size(); ++si) {
    const auto& st = stages_[si];
    auto idx = static_cast<std::int32_t>(si);
    StageSummary ss;
    auto t0 = std::chrono::steady_clock::now();
    double stage_wall_before = 0;
    std::int64_t end;  // exclusive
    // The coupling step of a grant follows the stable steps reported with the grants collected
    // before it was posted. With a window of W grants, grant p (in posting order) is posted
    // after grant p - W was collected, so it sees the reports up to p - W and not the later
    // ones, even when a checkpoint has collected them already: reports wait in pending_dt
    // until the grant that may use them is posted.
    std::int64_t posted = 0;
    std::deque<std::pair<std::int64_t, std::map<std::string, double>>> pending_dt;
    if (resume) {
      // Inside the stage: its STAGE_BEGIN was answered before the checkpoint.
      posted = resume->grants_posted;
      pending_dt.assign(resume->pending_dt.begin(), resume->pending_dt.end());
      ss = resume->current;
      stage_wall_before = ss.wall_s;
      clock_ = resume->clock;
      end = ss.first_step + st.steps;
      resume.reset();
    } else {
      ss.name = st.name;
      ss.action = st.action;
      ss.first_step = step;
      ss.begin = driver_.command(Cmd::StageBegin, st.nodes, step - 1, idx, st.name, stage_dt(st), {});
      for (auto& [r, rep] : ss.begin) {
        if (rep.dt_stable > 0) dt_stable_[r] = rep.dt_stable;
        ss.compute_s[r] += rep.compute_s;  // set-up procedures (generation, servo) run here
        ss.wait_s[r] += rep.wait_s;
      }
      clock_ = GrantClock{};
      clock_.stage_index = idx;
      clock_.stage_first_step = step;
      end = step + st.steps;
    }
    std::deque<std::int64_t> outstanding_index;  // posting index of each outstanding grant
    auto apply_dt_until = [&](std::int64_t index) {
      while (!pending_dt.empty() && pending_dt.front().first <= index) {
        for (auto& [r, dt] : pending_dt.front().second) dt_stable_[r] = dt;
        pending_dt.pop_front();
      }
    };
    auto state_now = [&](bool in_stage) {
      RunnerState s;
      s.stage = in_stage ? si : si + 1;
      s.in_stage = in_stage;
      s.step = step;
      s.clock = clock_;
      s.current = ss;
      s.current.wall_s = stage_wall_before + seconds_since(t0);
      s.done = sum.stages;
      s.dt_stable = dt_stable_;
      s.grants_posted = in_stage ? posted : 0;
      if (in_stage) s.pending_dt.assign(pending_dt.begin(), pending_dt.end());
      s.wall_s = run_wall();
      return s;
    };
    const std::int64_t window = st.coupled ? window_ : 1;
    std::deque<std::int64_t> outstanding;  // last step of each posted, uncollected grant
    std::int64_t next = step;              // first step not yet granted
    // Last step that may be granted: the budget's, or, once every node reported its criterion
    // met at the collected grant g, the last step posted when g was collected in a window that
    // is always full (g + (window - 1) grants): the same whether or not a checkpoint emptied
    // the window in between.
    std::int64_t limit = end - 1;
    bool done = false;
    auto collect_oldest = [&] {
      std::int64_t last = outstanding.front();
      outstanding.pop_front();
      const std::int64_t index = outstanding_index.front();
      outstanding_index.pop_front();
      auto reps = driver_.collect(Cmd::Grant, st.nodes, last, idx);
      step = last + 1;
      bool all_done = true;
      std::map<std::string, double> dts;
      for (auto& [r, rep] : reps)
        if (rep.dt_stable > 0) dts[r] = rep.dt_stable;
      pending_dt.emplace_back(index, std::move(dts));
      for (auto& [r, rep] : reps) {
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
      if (st.until_done && all_done && !done) {
        done = true;
        limit = std::min(limit, last + (window - 1) * st.steps_per_grant);
      }
    };
    // The window is refilled, to full, once at least half of it has been collected: with a
    // window of 4, grants go out two at a time, back to back, and each node wakes once for both
    // (in the chain benchmark, bench/bus, a wake-up costs about as much as the step's physics).
    // Which grants are outstanding when a report is read still never depends on timing, and
    // every grant p is posted after grant p - window was collected, as before, so its coupling
    // step and kinematics are unchanged.
    const std::int64_t refill_at = window - std::max<std::int64_t>(1, window / 2);
    while (next <= limit || !outstanding.empty()) {
      // Fill the window.
      const bool refill = static_cast<std::int64_t>(outstanding.size()) <= refill_at;
      while (refill && next <= limit && static_cast<std::int64_t>(outstanding.size()) < window) {
        std::int64_t last = std::min(limit, next + st.steps_per_grant - 1);
        apply_dt_until(posted - window);
        double dt = stage_dt(st);
        std::vector<double> values;
        clock_.first_step = next;
        clock_.last_step = last;
        clock_.dt = dt;
        if (kinematics_) values = kinematics_(st, last, dt);
        clock_.t_begin += dt * static_cast<double>(last - next + 1);
        driver_.post(Cmd::Grant, st.nodes, last, idx, st.name, dt, values);
        outstanding.push_back(last);
        outstanding_index.push_back(posted++);
        next = last + 1;
      }
      if (outstanding.empty()) break;
      collect_oldest();
      if (!done && next <= limit && take_ && due_ && due_()) {
        while (!outstanding.empty()) collect_oldest();
        if (!done) take_(state_now(true));
      }
    }
    apply_dt_until(std::numeric_limits<std::int64_t>::max());
    ss.last_step = step - 1;
    ss.criterion_met = done || !st.until_done;
    ss.ended_by = st.until_done ? (done ? "done" : "budget") : "steps";
    ss.end = driver_.command(Cmd::StageEnd, st.nodes, step - 1, idx, st.name, stage_dt(st), {});
    for (auto& [r, rep] : ss.end) {
      ss.compute_s[r] += rep.compute_s;
      ss.wait_s[r] += rep.wait_s;
    }
    ss.wall_s = stage_wall_before + seconds_since(t0);
    sum.stages.push_back(ss);
    if (st.until_done && !done && st.fail_on_budget)
      throw StageError("stage '" + st.name + "' (#" + std::to_string(si) + ") used its budget of " +
                       std::to_string(st.steps) + " steps without every node reporting its exit criterion met");
    if (take_) take_(state_now(false));
  }
  sum.steps = step;
  sum.wall_s = run_wall();
  return sum;
}

}  // namespace demfdm::coord
