// The coordinator's stage machine, independent of the transport.
//
// A run is a list of stages (scene [[stage]]). For each stage the runner sends STAGE_BEGIN to
// the stage's nodes, grants coupling steps in blocks of steps_per_grant (the nodes report every
// step's values in the grant's report) until the budget is used or, with until = "done", every node has
// reported its exit criterion met, then sends STAGE_END. The coupling-step length sent with
// every grant is the smallest stable step the stage's nodes reported (each node advances
// exactly that much per coupling step). The step counter is global over the run, so step k of
// every node always pairs the same interface data.
//
// Grant window: in coupled stages up to 'window' grants are outstanding at once (the nodes
// are paced by their interface data, not by the coordinator's round trips). The runner refills
// the window to full whenever at least half of it has been collected (with a window of 4: two
// grants back to back, one wake-up of each node for both), before it collects the next report,
// so which grants were posted when a report is read does not depend on timing, and grant p is
// always posted after grant p - window was collected: with until = "done" a stage whose
// criterion is met at step j ends after step j + window - 1, the same in every run.
#pragma once
#include <chrono>
#include <deque>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/schema/scene_schema.hpp"

namespace demfdm::coord {

enum class Cmd : std::int32_t { StageBegin = 1, Grant = 2, StageEnd = 3, Shutdown = 4 };
enum class Status : std::int32_t { Ok = 0, Failed = 1, StageDone = 2 };

struct NodeReport {
  Status status = Status::Ok;
  double time = 0, dt_stable = 0, compute_s = 0, wait_s = 0;
  std::map<std::string, double> values;
  // Multi-step grants: the values of every step, by step (values holds the last step's).
  std::vector<std::pair<std::int64_t, std::map<std::string, double>>> rows;
  std::string text;
};

// Transport: post() sends a command to 'targets'; collect() waits for each one's report to
// that command (resending outstanding commands as needed). Several grants may be posted
// before their reports are collected (the grant window). Throws on a dead or failed node
// (the message names it).
class Driver {
 public:
  virtual ~Driver() = default;
  virtual void post(Cmd cmd, const std::vector<std::string>& targets, std::int64_t step,
                    std::int32_t stage_index, const std::string& stage_name, double dt,
                    const std::vector<double>& values) = 0;
  virtual std::map<std::string, NodeReport> collect(Cmd cmd, const std::vector<std::string>& targets,
                                                    std::int64_t step, std::int32_t stage_index) = 0;
  std::map<std::string, NodeReport> command(Cmd cmd, const std::vector<std::string>& targets, std::int64_t step,
                                            std::int32_t stage_index, const std::string& stage_name, double dt,
                                            const std::vector<double>& values) {
    post(cmd, targets, step, stage_index, stage_name, dt, values);
    return collect(cmd, targets, step, stage_index);
  }
};

struct StageSummary {
  std::string name, action;
  std::int64_t first_step = 0, last_step = -1;  // global coupling steps run
  double wall_s = 0;
  bool criterion_met = false;
  std::string ended_by;                          // "steps", "done", "budget"
  std::map<std::string, NodeReport> begin, end;  // STAGE_BEGIN / STAGE_END reports
  std::map<std::string, double> compute_s, wait_s;  // per role, summed over the stage's grants
};

struct RunSummary {
  std::vector<StageSummary> stages;
  double wall_s = 0;
  std::int64_t steps = 0;
};

struct StageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Where the grant being posted lies in its stage, for kinematics that depend on the stage's
// time (the footing's speed ramp). Steps are global over the run (see above): a stage's first
// step is not 0 unless it is the run's first stage.
struct GrantClock {
  std::int32_t stage_index = 0;
  std::int64_t stage_first_step = 0;           // global step of the stage's first step
  std::int64_t first_step = 0, last_step = 0;  // the grant's steps (global, inclusive)
  double dt = 0;                               // the grant's coupling step [s]
  // Time since the start of the stage at the start of the grant [s]: the earlier grants of the
  // stage summed, each with its own dt (dt follows the nodes' stable steps).
  double t_begin = 0;
  // Time since the start of the stage at the middle of the grant's steps [s].
  double t_mid() const { return t_begin + 0.5 * dt * static_cast<double>(last_step - first_step + 1); }
};

// Where a run stands between two steps: what the runner needs to continue it (checkpoints,
// resume, branch; docs/checkpoint-format.md).
struct RunnerState {
  std::size_t stage = 0;            // the stage being run, or the next one to begin
  bool in_stage = false;            // inside stage 'stage' (its STAGE_BEGIN was answered)
  std::int64_t step = 0;            // next global coupling step
  GrantClock clock;                 // inside a stage: its clock after the last grant
  StageSummary current;             // inside a stage: its summary so far (wall_s so far)
  std::vector<StageSummary> done;   // the finished stages
  std::map<std::string, double> dt_stable;  // the nodes' stable steps the next grant uses
  // Inside a stage: grants posted so far, and the stable steps reported with collected grants
  // that the next grants do not use yet (by the grant's index in the stage, see Runner::run).
  std::int64_t grants_posted = 0;
  std::vector<std::pair<std::int64_t, std::map<std::string, double>>> pending_dt;
  double wall_s = 0;                // run wall time so far
};

class Runner {
 public:
  // Called after every grant with the step and every node's report (for histories).
  using Observer = std::function<void(const schema::Stage&, std::int64_t step, const std::map<std::string, NodeReport>&)>;
  // Values sent with each grant (e.g. footing kinematics); empty by default.
  using Kinematics = std::function<std::vector<double>(const schema::Stage&, std::int64_t step, double dt)>;

  Runner(std::vector<schema::Stage> stages, Driver& driver, std::map<std::string, double> dt_stable,
         std::int64_t window = 1);
  void set_observer(Observer o) { observer_ = std::move(o); }
  void set_kinematics(Kinematics k) { kinematics_ = std::move(k); }
  // The grant being posted; valid inside the kinematics callback.
  const GrantClock& grant_clock() const { return clock_; }
  // Checkpoints: take(state) is called after every stage end and, inside a stage, whenever
  // due() says so after a collected grant; the runner first collects every outstanding grant
  // (without posting more), so the nodes stand at one step. When the window holds grants
  // posted after the criterion was met, the mid-stage checkpoint is skipped (the stage ends
  // soon). Where checkpoints fall changes no result: the grants posted and the step at which
  // a stage ends are those of a run without checkpoints.
  using Checkpoint = std::function<void(const RunnerState&)>;
  void set_checkpoints(std::function<bool()> due, Checkpoint take) {
    due_ = std::move(due);
    take_ = std::move(take);
  }
  // Continue a run from a saved state (the nodes were restored to it) instead of its start.
  void start_from(RunnerState s) { start_ = std::move(s); }
  RunSummary run();

 private:
  double stage_dt(const schema::Stage& st) const;
  std::vector<schema::Stage> stages_;
  Driver& driver_;
  std::map<std::string, double> dt_stable_;
  std::int64_t window_ = 1;
  Observer observer_;
  Kinematics kinematics_;
  GrantClock clock_;
  std::function<bool()> due_;
  Checkpoint take_;
  std::optional<RunnerState> start_;
};

}  // namespace demfdm::coord
