// The coordinator's stage machine, driven by a fake transport (no LCM).
#include <gtest/gtest.h>

#include "coordinator/core/runner.hpp"

using namespace demfdm;

namespace {
struct Sent {
  coord::Cmd cmd;
  std::vector<std::string> targets;
  std::int64_t step;
  std::int32_t stage;
  double dt;
  std::vector<double> values;
};

class FakeDriver : public coord::Driver {
 public:
  std::vector<Sent> sent;
  std::int64_t done_from = -1;           // nodes report StageDone for grants reaching this step
  std::map<std::string, double> dt_of;  // dt_stable each node reports
  int max_outstanding = 0, outstanding = 0;
  void post(coord::Cmd cmd, const std::vector<std::string>& targets, std::int64_t step, std::int32_t stage,
            const std::string&, double dt, const std::vector<double>& values) override {
    sent.push_back({cmd, targets, step, stage, dt, values});
    max_outstanding = std::max(max_outstanding, ++outstanding);
  }
  std::map<std::string, coord::NodeReport> collect(coord::Cmd cmd, const std::vector<std::string>& targets,
                                                   std::int64_t step, std::int32_t, const std::vector<double>& = {}) {
    --outstanding;
    std::map<std::string, coord::NodeReport> out;
    for (auto& t : targets) {
      coord::NodeReport r;
      r.dt_stable = dt_of.count(t) ? dt_of[t] : 0;
      if (cmd == coord::Cmd::Grant && done_from >= 0 && step >= done_from) r.status = coord::Status::StageDone;
      r.compute_s = 0.5;
      r.wait_s = 0.25;
      out[t] = r;
    }
    return out;
  }
  std::map<std::string, coord::NodeReport> collect(coord::Cmd cmd, const std::vector<std::string>& targets,
                                                   std::int64_t step, std::int32_t stage) override {
    return collect(cmd, targets, step, stage, {});
  }
};

config::Scene scene(const std::string& stages) {
  return config::Scene::parse("[dem]\n[continuum]\n[coupling]\n" + stages, "test.toml", schema::scene_schema());
}
}  // namespace

TEST(Runner, GrantsBlocksAndCountsStepsGloballyOverStages) {
  auto sc = scene(
      "[[stage]]\nname = \"a\"\nnodes = [\"dem\"]\nsteps = 10\nsteps_per_grant = 4\n"
      "[[stage]]\nname = \"b\"\nsteps = 3\ncoupled = true\n");
  FakeDriver d;
  coord::Runner r(schema::stages(sc), d, {});
  auto sum = r.run();
  std::vector<std::pair<coord::Cmd, std::int64_t>> got;
  for (auto& s : d.sent) got.push_back({s.cmd, s.step});
  using C = coord::Cmd;
  std::vector<std::pair<coord::Cmd, std::int64_t>> want = {
      {C::StageBegin, -1}, {C::Grant, 3}, {C::Grant, 7}, {C::Grant, 9}, {C::StageEnd, 9},
      {C::StageBegin, 9},  {C::Grant, 10}, {C::Grant, 11}, {C::Grant, 12}, {C::StageEnd, 12}};
  EXPECT_EQ(got, want);
  EXPECT_EQ(d.sent[1].targets, std::vector<std::string>{"dem"});
  EXPECT_EQ(d.sent[6].targets, (std::vector<std::string>{"dem", "continuum"}));
  EXPECT_EQ(sum.steps, 13);
  ASSERT_EQ(sum.stages.size(), 2u);
  EXPECT_EQ(sum.stages[0].last_step, 9);
  EXPECT_EQ(sum.stages[1].first_step, 10);
  EXPECT_DOUBLE_EQ(sum.stages[0].compute_s.at("dem"), 2.5);  // begin + 3 grants + end, 0.5 s each
  EXPECT_EQ(sum.stages[0].ended_by, "steps");
}

TEST(Runner, UntilDoneStopsAtTheFirstGrantWhereEveryNodeIsDone) {
  auto sc = scene("[[stage]]\nname = \"eq\"\nsteps = 100\nuntil = \"done\"\nsteps_per_grant = 5\n");
  FakeDriver d;
  d.done_from = 12;
  coord::Runner r(schema::stages(sc), d, {});
  auto sum = r.run();
  EXPECT_EQ(sum.stages[0].last_step, 14);  // grants end at 4, 9, 14
  EXPECT_TRUE(sum.stages[0].criterion_met);
  EXPECT_EQ(sum.stages[0].ended_by, "done");
}

TEST(Runner, BudgetExhaustedFailsOrContinuesAsTheSceneSays) {
  FakeDriver d;
  coord::Runner fail(schema::stages(scene("[[stage]]\nname = \"eq\"\nsteps = 5\nuntil = \"done\"\n")), d, {});
  try {
    fail.run();
    FAIL() << "expected StageError";
  } catch (const coord::StageError& e) {
    EXPECT_NE(std::string(e.what()).find("stage 'eq' (#0) used its budget of 5 steps"), std::string::npos) << e.what();
  }
  FakeDriver d2;
  coord::Runner cont(schema::stages(scene("[[stage]]\nname = \"eq\"\nsteps = 5\nuntil = \"done\"\non_budget = \"continue\"\n"
                                          "[[stage]]\nname = \"next\"\nsteps = 1\n")),
                     d2, {});
  auto sum = cont.run();
  EXPECT_EQ(sum.stages.size(), 2u);
  EXPECT_EQ(sum.stages[0].ended_by, "budget");
  EXPECT_FALSE(sum.stages[0].criterion_met);
}

TEST(Runner, CouplingStepIsTheSmallestStableStepOfTheStageNodes) {
  auto sc = scene("[[stage]]\nname = \"a\"\nsteps = 2\ncoupled = true\n[[stage]]\nname = \"b\"\nnodes = [\"continuum\"]\nsteps = 1\n");
  FakeDriver d;
  d.dt_of = {{"dem", 1e-8}, {"continuum", 5e-8}};
  coord::Runner r(schema::stages(sc), d, {{"dem", 2e-8}, {"continuum", 6e-8}});
  std::vector<std::int64_t> kin_steps;
  r.set_kinematics([&](const schema::Stage&, std::int64_t step, double dt) {
    kin_steps.push_back(step);
    return std::vector<double>{static_cast<double>(step), dt};
  });
  r.run();
  EXPECT_DOUBLE_EQ(d.sent[0].dt, 2e-8);  // from the hellos
  EXPECT_DOUBLE_EQ(d.sent[1].dt, 1e-8);  // updated by the STAGE_BEGIN reports
  EXPECT_EQ(d.sent[1].values, (std::vector<double>{0, 1e-8}));
  // Stage b has only the continuum: its own step.
  EXPECT_DOUBLE_EQ(d.sent.back().dt, 5e-8);
  EXPECT_EQ(kin_steps, (std::vector<std::int64_t>{0, 1, 2}));
}

TEST(Runner, GrantWindowKeepsGrantsOutstandingAndEndsDeterministically) {
  auto sc = scene("[[stage]]\nname = \"load\"\nsteps = 100\ncoupled = true\nuntil = \"done\"\n");
  FakeDriver d;
  d.done_from = 20;
  coord::Runner r(schema::stages(sc), d, {}, 4);
  auto sum = r.run();
  EXPECT_EQ(d.max_outstanding, 4);
  // Criterion met in the report of step 20: grants up to 23 were already posted.
  EXPECT_EQ(sum.stages[0].last_step, 23);
  EXPECT_EQ(d.sent.back().cmd, coord::Cmd::StageEnd);
  EXPECT_EQ(d.sent.back().step, 23);
}

// ---- Checkpoints and resume (Runner::set_checkpoints, Runner::start_from) ----

#include <memory>
#include <optional>
#include <tuple>

namespace {
// FakeDriver that counts grants posted and collected, ends stages by stage index, and reports
// stable steps that change with the step (so the grant clock must sum each grant's own dt).
class CkDriver : public FakeDriver {
 public:
  std::map<std::int32_t, std::int64_t> done_at;  // stage index -> first step reported StageDone
  bool vary_dt = false;                          // dt_stable changes with the report's step
  int grants_posted = 0, grants_collected = 0;
  void post(coord::Cmd cmd, const std::vector<std::string>& targets, std::int64_t step, std::int32_t stage,
            const std::string& name, double dt, const std::vector<double>& values) override {
    if (cmd == coord::Cmd::Grant) ++grants_posted;
    FakeDriver::post(cmd, targets, step, stage, name, dt, values);
  }
  std::map<std::string, coord::NodeReport> collect(coord::Cmd cmd, const std::vector<std::string>& targets,
                                                   std::int64_t step, std::int32_t stage) override {
    auto out = FakeDriver::collect(cmd, targets, step, stage, {});
    if (cmd == coord::Cmd::Grant) ++grants_collected;
    for (auto& [t, r] : out) {
      if (vary_dt && dt_of.count(t)) r.dt_stable = dt_of[t] * (1.0 + 0.25 * static_cast<double>(((step % 5) + 5) % 5));
      auto it = done_at.find(stage);
      if (cmd == coord::Cmd::Grant && it != done_at.end() && step >= it->second) r.status = coord::Status::StageDone;
    }
    return out;
  }
};

using SentKey = std::tuple<coord::Cmd, std::vector<std::string>, std::int64_t, std::int32_t, double, std::vector<double>>;
std::vector<SentKey> keys(const std::vector<Sent>& v, std::size_t from = 0) {
  std::vector<SentKey> out;
  for (std::size_t i = from; i < v.size(); ++i)
    out.emplace_back(v[i].cmd, v[i].targets, v[i].step, v[i].stage, v[i].dt, v[i].values);
  return out;
}

// Stages: a (dem only, budget in blocks of 4), b (coupled, until done, budget ends it),
// c (coupled, until done, criterion met mid-stage), d (coupled, fixed steps).
std::string ck_stages(int spg) {
  const std::string p = "steps_per_grant = " + std::to_string(spg) + "\n";
  return "[[stage]]\nname = \"a\"\nnodes = [\"dem\"]\nsteps = 10\nsteps_per_grant = 4\n"
         "[[stage]]\nname = \"b\"\ncoupled = true\nsteps = 40\nuntil = \"done\"\non_budget = \"continue\"\n" + p +
         "[[stage]]\nname = \"c\"\ncoupled = true\nsteps = 200\nuntil = \"done\"\n" + p +
         "[[stage]]\nname = \"d\"\ncoupled = true\nsteps = 3\n" + p;
}

struct Take {
  coord::RunnerState state;
  std::size_t sent_before;  // commands posted before take()
  int outstanding;          // FakeDriver's posts minus collects at take()
  int grants_outstanding;   // grants posted minus grants collected at take()
};
struct CkRun {
  std::vector<Sent> sent;
  coord::RunSummary sum;
  std::vector<Take> takes;
};

CkRun ck_run(int spg, std::int64_t window, bool vary_dt, std::function<bool()> due,
             std::optional<coord::RunnerState> from = {}) {
  CkDriver d;
  d.vary_dt = vary_dt;
  d.dt_of = {{"dem", 1e-3}, {"continuum", 3e-3}};
  d.done_at = {{2, 50 + 37}};  // stage c begins at step 50
  coord::Runner r(schema::stages(scene(ck_stages(spg))), d, {{"dem", 2e-3}, {"continuum", 3e-3}}, window);
  r.set_kinematics([&r](const schema::Stage&, std::int64_t, double) {
    const auto& c = r.grant_clock();
    return std::vector<double>{c.t_mid(), static_cast<double>(c.stage_first_step), c.t_begin,
                               static_cast<double>(c.first_step), static_cast<double>(c.stage_index)};
  });
  CkRun out;
  if (due)
    r.set_checkpoints(due, [&](const coord::RunnerState& s) {
      out.takes.push_back({s, d.sent.size(), d.outstanding, d.grants_posted - d.grants_collected});
    });
  if (from) r.start_from(*from);
  out.sum = r.run();
  out.sent = d.sent;
  return out;
}

void expect_same_summary(const coord::RunSummary& a, const coord::RunSummary& b) {
  EXPECT_EQ(a.steps, b.steps);
  ASSERT_EQ(a.stages.size(), b.stages.size());
  for (std::size_t i = 0; i < a.stages.size(); ++i) {
    SCOPED_TRACE("stage " + std::to_string(i));
    EXPECT_EQ(a.stages[i].name, b.stages[i].name);
    EXPECT_EQ(a.stages[i].first_step, b.stages[i].first_step);
    EXPECT_EQ(a.stages[i].last_step, b.stages[i].last_step);
    EXPECT_EQ(a.stages[i].ended_by, b.stages[i].ended_by);
    EXPECT_EQ(a.stages[i].criterion_met, b.stages[i].criterion_met);
    EXPECT_EQ(a.stages[i].compute_s, b.stages[i].compute_s);
    EXPECT_EQ(a.stages[i].wait_s, b.stages[i].wait_s);
  }
}

std::function<bool()> every(int n) {
  auto calls = std::make_shared<int>(0);
  return [calls, n] { return ++*calls % n == 0; };
}
}  // namespace

TEST(RunnerCheckpoints, ReferenceRunEndsStagesAsExpected) {
  // The scenario the checkpoint tests rely on: a ends by steps, b by its budget, c by its criterion.
  for (int spg : {1, 4})
    for (std::int64_t w : {1, 3}) {
      SCOPED_TRACE("spg " + std::to_string(spg) + " window " + std::to_string(w));
      auto a = ck_run(spg, w, false, nullptr);
      ASSERT_EQ(a.sum.stages.size(), 4u);
      EXPECT_EQ(a.sum.stages[0].ended_by, "steps");
      EXPECT_EQ(a.sum.stages[1].ended_by, "budget");
      EXPECT_EQ(a.sum.stages[1].last_step, 49);
      EXPECT_EQ(a.sum.stages[2].ended_by, "done");
      const std::int64_t met = spg == 1 ? 87 : 89;  // first grant reaching step 87
      EXPECT_EQ(a.sum.stages[2].last_step, met + (w - 1) * spg);
      EXPECT_EQ(a.sum.stages[3].ended_by, "steps");
      EXPECT_EQ(a.sum.steps, met + (w - 1) * spg + 1 + 3);
    }
}

TEST(RunnerCheckpoints, CheckpointsChangeNoCommandAndNoResult) {
  for (int spg : {1, 4})
    for (std::int64_t w : {1, 3}) {
      for (bool vary : {false, true}) {
      auto ref = ck_run(spg, w, vary, nullptr);
      for (int n : {1, 2, 3}) {
        SCOPED_TRACE("spg " + std::to_string(spg) + " window " + std::to_string(w) + " due every " + std::to_string(n) +
                     (vary ? " varying dt" : ""));
        auto ck = ck_run(spg, w, vary, every(n));
        EXPECT_EQ(keys(ck.sent), keys(ref.sent));
        expect_same_summary(ck.sum, ref.sum);
        int mid = 0, ends = 0;
        for (auto& t : ck.takes) (t.state.in_stage ? mid : ends)++;
        EXPECT_EQ(ends, 4);  // after every stage end
        EXPECT_GT(mid, 2);
      }
      }
    }
}

TEST(RunnerCheckpoints, MidStageStateStandsAtOneStepWithTheStageClock) {
  for (int spg : {1, 4})
    for (std::int64_t w : {1, 3})
      for (int n : {1, 3}) {
        SCOPED_TRACE("spg " + std::to_string(spg) + " window " + std::to_string(w) + " due every " + std::to_string(n));
        auto ck = ck_run(spg, w, true, every(n));  // no reference run here: dt may vary
        for (auto& t : ck.takes) {
          const auto& s = t.state;
          SCOPED_TRACE("checkpoint at step " + std::to_string(s.step) + (s.in_stage ? "" : " (stage end)"));
          EXPECT_EQ(t.outstanding, 0);
          EXPECT_EQ(t.grants_outstanding, 0);
          // The last command posted before the checkpoint.
          ASSERT_GT(t.sent_before, 0u);
          const auto& last = ck.sent[t.sent_before - 1];
          if (!s.in_stage) {
            EXPECT_EQ(last.cmd, coord::Cmd::StageEnd);
            EXPECT_EQ(s.stage, static_cast<std::size_t>(last.stage) + 1);
            EXPECT_EQ(s.step, last.step + 1);
            ASSERT_EQ(s.done.size(), s.stage);
            EXPECT_EQ(s.done.back().last_step, last.step);
            continue;
          }
          ASSERT_EQ(last.cmd, coord::Cmd::Grant);
          EXPECT_EQ(s.stage, static_cast<std::size_t>(last.stage));
          EXPECT_EQ(s.step, last.step + 1);  // the next step
          EXPECT_EQ(s.clock.stage_index, last.stage);
          EXPECT_EQ(s.current.first_step, s.clock.stage_first_step);
          EXPECT_EQ(s.done.size(), s.stage);
          // t_begin: every grant of the stage so far, each its dt times its steps.
          double tsum = 0;
          std::int64_t prev = s.clock.stage_first_step - 1;
          int grants = 0;
          for (std::size_t i = 0; i < t.sent_before; ++i) {
            const auto& c = ck.sent[i];
            if (c.cmd != coord::Cmd::Grant || c.stage != last.stage) continue;
            tsum += c.dt * static_cast<double>(c.step - prev);
            prev = c.step;
            ++grants;
          }
          EXPECT_GT(grants, 0);
          EXPECT_EQ(prev, s.step - 1);
          EXPECT_DOUBLE_EQ(s.clock.t_begin, tsum);
          EXPECT_EQ(s.clock.last_step, s.step - 1);
        }
      }
}

TEST(RunnerCheckpoints, ResumeFromAnyCheckpointPostsTheRestOfTheRun) {
  for (int spg : {1, 4})
    for (std::int64_t w : {1, 3})
      for (bool vary : {false, true}) {
      auto a = ck_run(spg, w, vary, every(3));
      ASSERT_FALSE(a.takes.empty());
      int mid = 0, ends = 0;
      for (auto& t : a.takes) {
        SCOPED_TRACE("spg " + std::to_string(spg) + " window " + std::to_string(w) + (vary ? " varying dt" : "") +
                     " resume at step " + std::to_string(t.state.step) +
                     (t.state.in_stage ? " (mid-stage)" : " (stage end)"));
        (t.state.in_stage ? mid : ends)++;
        auto b = ck_run(spg, w, vary, nullptr, t.state);
        EXPECT_EQ(keys(b.sent), keys(a.sent, t.sent_before));
        expect_same_summary(b.sum, a.sum);
        if (!t.state.in_stage && !b.sent.empty()) {
          EXPECT_EQ(b.sent.front().cmd, coord::Cmd::StageBegin);
        }
        if (t.state.in_stage) {
          ASSERT_FALSE(b.sent.empty());
          EXPECT_EQ(b.sent.front().cmd, coord::Cmd::Grant);  // no second STAGE_BEGIN
        }
      }
      EXPECT_GT(mid, 0);
      EXPECT_EQ(ends, 4);
    }
}

TEST(RunnerCheckpoints, ResumedRunTakesTheSameLaterCheckpoints) {
  // Resume from a mid-stage checkpoint with checkpoints on: the later ones are A's later ones.
  auto a = ck_run(4, 3, false, every(1));
  std::size_t k = 0;
  while (k < a.takes.size() && !(a.takes[k].state.in_stage && a.takes[k].state.stage == 2)) ++k;
  ASSERT_LT(k, a.takes.size());
  auto b = ck_run(4, 3, false, every(1), a.takes[k].state);
  EXPECT_EQ(keys(b.sent), keys(a.sent, a.takes[k].sent_before));
  ASSERT_EQ(b.takes.size(), a.takes.size() - k - 1);
  for (std::size_t i = 0; i < b.takes.size(); ++i) {
    const auto &x = b.takes[i].state, &y = a.takes[k + 1 + i].state;
    EXPECT_EQ(x.step, y.step);
    EXPECT_EQ(x.stage, y.stage);
    EXPECT_EQ(x.in_stage, y.in_stage);
    EXPECT_EQ(x.clock.t_begin, y.clock.t_begin);
    EXPECT_EQ(x.dt_stable, y.dt_stable);
  }
}

// With a grant window > 1, a mid-stage checkpoint collects the outstanding grants early; the
// grants posted right after it must still take their coupling step from the dt_stable reports
// a run without the checkpoint had collected by then (the DEM's stable step changes during a
// stage, so otherwise the results would depend on where checkpoints fall).
TEST(RunnerCheckpoints, CheckpointInAWindowKeepsTheCouplingStepOfLaterGrants) {
  auto stages = schema::stages(scene("[[stage]]\nname = \"load\"\ncoupled = true\nsteps = 8\n"));
  auto dts = [&](bool checkpoint) {
    CkDriver d;
    d.vary_dt = true;  // dt_stable = 1e-3 * (1 + 0.25 * (step % 5))
    d.dt_of = {{"dem", 1e-3}};
    coord::Runner r(stages, d, {{"dem", 1e-3}}, 3);
    int calls = 0;
    if (checkpoint) r.set_checkpoints([&] { return ++calls == 1; }, [](const coord::RunnerState&) {});
    r.run();
    std::vector<double> out;
    for (auto& s : d.sent)
      if (s.cmd == coord::Cmd::Grant) out.push_back(s.dt);
    return out;
  };
  EXPECT_EQ(dts(true), dts(false));
}
