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
