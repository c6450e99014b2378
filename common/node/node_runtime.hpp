// The life of a node process, shared by every node executable (dem_node, fdm_node, another
// continuum solver, the protocol test participants), so that each of them is only an adapter
// from the protocol to its engine:
//
//   parse the command line -> open the bus -> receive the scene -> validate it -> build the
//   participant -> hello -> follow commands (stage begin, grants, stage end) -> shutdown.
//
// Coupled stages follow one data schedule for every solver pair (messages/README.md):
//   kin(j)   = continuum interface positions/velocities after its step j,
//   force(j) = DEM interface forces computed in its step j.
//   DEM, step k:        wait kin(k-1), move facets, advance, send force(k).
//   continuum, step k:  wait force(k) (serial) or force(k-1) (parallel), advance, send kin(k).
// At the first coupled stage the continuum sends its interface mesh; at every coupled stage
// begin it sends kin(s0-1), and in the parallel scheme the DEM answers with force(s0-1).
#pragma once

#include <chrono>
#include <deque>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include "common/schema/scene_schema.hpp"
#include "demfdm/io/state_file.hpp"
#include "messages/protocol.hpp"

namespace demfdm::node {

struct Options {
  std::string url;      // LCM URL (--lcm-url, else $LCM_DEFAULT_URL)
  std::int64_t run_id = 0;
  std::string run_dir;  // outputs and the node's log go here ("" = no files)
  bool verbose = false;
};

// What the blow-up guard found (issue 7 item 4): `cause` is one line (what, which object, its
// value), `detail` the full report (where, values, neighbourhood) written by run_node to
// blowup_<role>.txt in the run folder.
struct HealthReport {
  std::string cause;
  std::string detail;
};

// Kinetic-energy jump test shared by the nodes: trips when the energy exceeds `factor` times
// the larger of `floor` and the largest value of the previous `window` checks (scene keys
// run.guard_energy_jump, run.guard_energy_floor, run.guard_energy_window; factor 0 = off).
class EnergyJump {
 public:
  EnergyJump(double factor, double floor, std::size_t window) : factor_(factor), floor_(floor), window_(window) {}
  explicit EnergyJump(const config::Scene& s);
  // Returns the cause text on a jump, and records e otherwise.
  std::optional<std::string> check(double e);
  // The window of previous checks, for checkpoints (a resumed run trips where the original would).
  void save(io::StateWriter& w) const;
  void load(io::SectionReader& r);

 private:
  double factor_, floor_;
  std::size_t window_;
  std::deque<double> last_;  // previous checks (monotone deque of the window's maximum)
  std::deque<std::size_t> at_;
  std::size_t n_ = 0;
};

// Wall time of a scope added to a total [s] (the nodes' STAGE_END values effect_s.<name>).
class Timed {
 public:
  explicit Timed(double& total) : total_(total), t0_(std::chrono::steady_clock::now()) {}
  ~Timed() { total_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }
  Timed(const Timed&) = delete;
  Timed& operator=(const Timed&) = delete;

 private:
  double& total_;
  std::chrono::steady_clock::time_point t0_;
};

// What every adapter's checkpoint section ends with (docs/checkpoint-format.md): whether its
// result writers were created, how far they got (HDF5 frames, history CSV bytes and rows), and
// the frames' model clock (io::ModelClock::State: known, origin, model, node_ref, pending).
struct OutputCheckpoint {
  bool open = false;
  std::uint64_t frames = 0, bytes = 0, rows = 0;
  template <class ClockState>
  void save(io::StateWriter& w, const ClockState& c) const {
    w.b(open);
    w.u64(frames);
    w.u64(bytes);
    w.u64(rows);
    w.b(c.known);
    for (double v : {c.origin, c.model, c.node_ref}) w.f64(v);
    w.f64s(c.pending);
  }
  template <class ClockState>
  static OutputCheckpoint load(io::SectionReader& r, ClockState& c) {
    OutputCheckpoint o;
    o.open = r.b();
    o.frames = r.u64();
    o.bytes = r.u64();
    o.rows = r.u64();
    c.known = r.b();
    for (double* v : {&c.origin, &c.model, &c.node_ref}) *v = r.f64();
    c.pending = r.f64s();
    return o;
  }
};

// How a node state is being restored (command RESTORE, docs/checkpoint-format.md).
struct Restore {
  std::filesystem::path dir;        // the checkpoint folder
  std::uint64_t saved_scene_hash;   // hash of the scene the state was saved under
  bool branch = false;              // a new run from a saved state (the scene's later stages may differ)
};

// What an engine adapter implements. Called on the node's main thread only.
class Participant {
 public:
  virtual ~Participant() = default;
  // Largest coupling-step length this node can take now [s] (0: no preference).
  virtual double dt_stable() const = 0;
  virtual double time() const = 0;
  // Stage set-up (the stage's action); returns values for the STAGE_BEGIN report.
  virtual proto::Values stage_begin(const schema::Stage& stage, std::int64_t first_step) = 0;
  // One coupling step of length dt (values: the coordinator's kinematics for this step).
  virtual void advance(const schema::Stage& stage, std::int64_t step, double dt,
                       const std::vector<double>& values) = 0;
  // In a coupled stage, the DEM role: called with the grant of `step` before the node waits for
  // the continuum's interface data of step - 1, then advance() with the same arguments. A node
  // may do here the part of the step that needs none of that data (the DEM: its balls' motion),
  // so that it overlaps the continuum's step; the results must be those of advance() alone.
  virtual void advance_early(const schema::Stage& /*stage*/, std::int64_t /*step*/, double /*dt*/,
                             const std::vector<double>& /*values*/) {}
  // Values reported after each grant (e.g. footing force, unbalanced ratio).
  virtual proto::Values step_values() = 0;
  // With until = "done": has this node met the stage's exit criterion?
  virtual bool criterion_met(const schema::Stage&) { return false; }
  virtual proto::Values stage_end(const schema::Stage& stage, std::int64_t last_step) = 0;
  // Flush outputs; called once before exit (also after an error, best effort).
  virtual void finish() {}
  // Blow-up guard, called after the advance of every run.guard_every-th step: the first
  // non-finite value (or energy jump) found, or nothing. A report stops the run at that step.
  virtual std::optional<HealthReport> check_health(std::int64_t /*step*/) { return std::nullopt; }

  // Checkpoints (issue 13; docs/checkpoint-format.md). A participant that can save its state
  // says so; the runtime then writes <role>.state (its own section "runtime" and the
  // participant's sections) into the checkpoint folder. save() stores the complete state after
  // the last step, engine state files into `dir` named after the role, everything else as
  // sections of `w`, and must not change the state (a run with checkpoints gives the same bits
  // as one without). restore() replaces the state by the saved one, also the positions of the
  // result writers (rows and frames written after the checkpoint are dropped, so they are
  // written once), and checks that the scene still describes the saved state.
  virtual bool can_checkpoint() const { return false; }
  virtual void save(const std::filesystem::path& dir, io::StateWriter& w, const io::StateMeta& meta);
  virtual void restore(io::StateReader& r, const Restore& how);

  // Coupling hooks, continuum role.
  virtual proto::InterfaceMesh interface_mesh();
  virtual proto::Kinematics interface_kinematics();
  virtual void apply_interface_forces(const proto::Forces& f);
  // Coupling hooks, DEM role.
  virtual void set_interface_mesh(const proto::InterfaceMesh& m);
  virtual void set_interface_kinematics(const proto::Kinematics& k);
  virtual proto::Forces interface_forces();
};

struct Context {
  Options options;
  config::Scene scene;
  std::string role;
};

using Factory = std::function<std::unique_ptr<Participant>(const Context&)>;

// Runs a node to the end. Returns the process exit code: 0 finished, 2 bad command line or
// scene, 3 protocol or engine failure (reported to the coordinator and logged), 130 interrupted.
int run_node(int argc, char** argv, const std::string& role, const std::string& solver, const Factory& make);

// The largest resident set of this process so far [MB] (getrusage ru_maxrss): the STAGE_END
// report's "peak_rss_mb", from which the summary gives each node's peak memory.
double process_peak_rss_mb();

// Command-line parsing shared by the node executables and the coordinator.
// Recognises --lcm-url=URL, --run-id=N, --run-dir=DIR, -v; throws std::invalid_argument on
// anything else (the message names the argument).
Options parse_options(int argc, char** argv, std::vector<std::string>* positional = nullptr,
                      const std::vector<std::string>& flags = {});

}  // namespace demfdm::node
