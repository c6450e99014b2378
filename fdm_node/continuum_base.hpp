// What every continuum node adapter (fdm_node, fem_node) does the same way, whatever its solver:
// the coupling interface of the shared mesh (gridpoints, triangles, kinematics out, forces in)
// with the action-reaction balance check, the result files (frames file + mesh.xmf, history
// CSV) and their model clock (io::ModelClock, docs/output.md "Time"), their checkpoint part, the
// stage actions a continuum takes part in, the geostatic set-up and the equilibrium criterion.
//
// A solver's adapter derives from NodeBase, implements the solver hooks below and the
// Participant calls that are its own (time, stepping, step values, health, checkpoints of its
// fields), and composes the protected helpers in the order its stage logic needs.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "demfdm/fdm/mesh.hpp"
#include "demfdm/io/csv_series.hpp"
#include "demfdm/io/model_time.hpp"
#include "demfdm/io/results_output.hpp"
#include "common/node/node_runtime.hpp"

namespace demfdm::continuum {

// The names that differ between solvers.
struct Names {
  std::string solver;   // executable, e.g. "fdm_node": frames-file attribute, error messages
  std::string log;      // log-line prefix, e.g. "fdm"
  std::string h5;       // frames file in the run folder, e.g. "fdm.h5" (with mesh.xmf)
  std::string history;  // history file in the run folder, e.g. "fdm_history.csv"
  std::vector<std::string> history_columns;
};

class NodeBase : public node::Participant {
 public:
  // Coupling (continuum role).
  proto::InterfaceMesh interface_mesh() override;         // mesh()'s interface at interface_positions()
  proto::Kinematics interface_kinematics() override;      // interface_positions(), interface_velocities()
  void apply_interface_forces(const proto::Forces& f) override;  // balance check, then take_interface_forces()
  // Equilibrium actions: equilibrium_ratio() below the stage's 'ratio'. Actions whose end the
  // continuum does not decide (penetrate: the footing depth) have its consent.
  bool criterion_met(const schema::Stage& st) override;
  void finish() override;  // closes the history file

 protected:
  // Reads [continuum.output] and the stages (for the model clock); opens no file.
  NodeBase(const node::Context& ctx, Names names);

  // Solver hooks.
  virtual const fdm::Mesh& mesh() const = 0;
  virtual std::vector<double> interface_positions() const = 0;   // [n_if,3] m
  virtual std::vector<double> interface_velocities() const = 0;  // [n_if,3] m/s (m/step without time)
  // The DEM's interface forces [n_if,3] and stiffness [n_if], after the balance check.
  virtual void take_interface_forces(const proto::Forces& f) = 0;
  // The out-of-balance ratio the equilibrium actions compare with their 'ratio'; nothing while
  // the stage has none yet.
  virtual std::optional<double> equilibrium_ratio() const = 0;
  virtual void set_geostatic_stress(double k0) = 0;  // K0, NaN: nu/(1-nu) of each zone
  virtual void reset_displacements() = 0;            // the stage's reset_displacements
  virtual std::vector<double> history_row(std::int64_t step) = 0;  // one row of history_columns
  virtual void write_frame(std::int64_t step) = 0;                 // see frame_due(), put_frame()

  // Stage begin. Throws std::invalid_argument unless the action is one a continuum takes part
  // in (cycle, equilibrium, geostatic, couple, penetrate).
  void require_action(const schema::Stage& st) const;
  // Result files only when the scene has [continuum.output] (a scene writes only what it asks
  // for), created at the first stage; later calls do nothing.
  void open_outputs();
  // At the top of every stage_begin, before any step: the model-time origin at the first stage
  // that is not preparation (io::ModelClock); frames written before it get their model times.
  // True when the origin was set at this stage. node_time: the solver's time now.
  bool begin_model_time(const schema::Stage& st, double node_time);
  // The action's set-up: geostatic and couple stages assign the geostatic stresses (the
  // continuum starts from its geostatic state) and log it, reset_displacements, and the effect
  // times start at zero. Returns the STAGE_BEGIN values (zones, gridpoints).
  proto::Values begin_stage(const schema::Stage& st);

  // Stepping: a history row every history_every steps and a frame every frame_every steps.
  void record_step(std::int64_t step);
  // Frame times must increase strictly: a repeated time (two frames of one step) is skipped.
  bool frame_due(double node_time) const { return !(has_frame_ && node_time <= last_frame_time_); }
  // Writes a frame at the model time of node_time (docs/output.md).
  void put_frame(std::int64_t step, double node_time, const io::MeshFrame& frame);

  // Stage end: the last step's frame unless written; the effect times as effect_s.<name>.
  void write_last_frame(std::int64_t last);
  void add_effect_times(proto::Values& v) const;
  // iface_imbalance and iface_fz_N once the interface carries forces.
  void add_coupling_values(proto::Values& v) const;

  // Checkpoints (docs/checkpoint-format.md): what every adapter section ends with, the result
  // writers' positions and the model clock. restore_outputs() reads it, closes the section and
  // reopens the result files where the checkpoint left them (a branch starts new ones).
  void save_outputs(io::StateWriter& w);
  void restore_outputs(io::SectionReader& sec, const node::Restore& how);

  std::filesystem::path run_dir() const { return ctx_.options.run_dir; }

  node::Context ctx_;
  Names names_;
  std::optional<io::MeshOutput> out_;
  std::optional<io::CsvSeries> history_;
  std::int64_t frame_every_ = 0, history_every_ = 1, last_frame_ = -2;
  bool outputs_open_ = false;
  bool has_frame_ = false;
  double last_frame_time_ = 0;               // solver time of the last frame
  io::ModelClock clock_;                     // the frames' model time
  std::vector<std::string> stage_prefixes_;  // "stage[i]" of every stage: its scene index
  // Largest relative difference so far between the force sum the continuum applied and the
  // DEM's own total of the same step (action = reaction, docs/theory.md 6.9); the last sum's z.
  double max_imbalance_ = 0, iface_fz_ = 0;
  bool coupled_ = false;                     // forces have arrived
  std::map<std::string, double> effect_s_;   // [s] wall time of each effect in the current stage

 private:
  bool writes_outputs() const;
};

}  // namespace demfdm::continuum
