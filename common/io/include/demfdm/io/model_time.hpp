// The time written into the results frames: one model time for every node (docs/output.md,
// "Time").
//
// Rule: model time t = 0 at the beginning of the run's first stage that is not specimen
// preparation (the actions the stage-action table marks so, schema::actions(): generate, servo,
// bond, replicate, the specimen-generation stages of dem_node, docs/stages.md). Every node writes frame time = node time - node time at that
// moment, so DEM and continuum frames of the same step carry the same time and ParaView's
// time slider lines them up. DEM frames written during the preparation get negative times
// (still strictly increasing); they are written before the origin is known and are given
// their times when it becomes known (ParticleOutput/MeshOutput::retime_frames).
//
// After the origin, the node time elapsed is counted in the coordinator's granted step
// lengths: each coupling step adds its dt (the same double in every node), and time the node
// advanced on its own (steps inside a stage's set-up, such as a UCS test, or a grant without
// a length) adds the node clock's own advance. Nodes granted the same steps therefore write
// bit-identical times, also when one of them sub-cycles a step (the continuum) or its own
// clock is far from 0 (the DEM after a long preparation), where node time minus origin would
// differ in the last bits.
//
// A node that takes no part in the first model stage: its origin is its time at its first
// later stage, which is its time at the model origin (it did not step in between).
#pragma once

#include <cstddef>
#include <vector>

namespace demfdm::io {

class ModelClock {
 public:
  ModelClock() = default;
  /// `preparation`: for every [[stage]] of the scene, in order, whether its action is specimen
  /// preparation.
  explicit ModelClock(const std::vector<bool>& preparation);

  /// Index of the first stage that is not preparation (the number of stages when all are).
  std::size_t first_model_stage() const noexcept { return first_; }

  /// At the beginning of the stage with scene index `stage_index`, before the node steps in
  /// it. Sets the origin to `node_time` at the first such call with stage_index >=
  /// first_model_stage(); returns true then (the caller gives its earlier frames their times:
  /// take_pending_times()).
  bool stage_begins(std::size_t stage_index, double node_time);

  /// After one granted step of length `dt` that took the node clock from `node_before` to
  /// `node_after`: the model time advances by dt (by node_after - node_before when dt <= 0).
  void advanced(double node_before, double dt, double node_after);

  /// The time of a frame written now, at node time `node_time`: the model time once the
  /// origin is known (catching up on steps the node took on its own since the last grant);
  /// before, `node_time` itself, remembered until take_pending_times().
  double frame_time(double node_time);

  /// When the origin has just become known: the model times of the frames written before,
  /// in write order (node time - origin); forgets them.
  std::vector<double> take_pending_times();
  /// A new results folder (a branched run): frames written before are not in it.
  void forget_pending() { pending_.clear(); }

  bool known() const noexcept { return known_; }
  /// Node time at model time 0 [s] (valid when known()).
  double origin() const noexcept { return origin_; }

  // Checkpoint state (the adapters save and restore these in their own section).
  struct State {
    bool known = false;
    double origin = 0, model = 0, node_ref = 0;
    std::vector<double> pending;  // node times of frames written before the origin was known
  };
  State state() const { return {known_, origin_, model_, node_ref_, pending_}; }
  void set_state(const State& s);

 private:
  void catch_up(double node_time);

  std::size_t first_ = 0;
  bool known_ = false;
  double origin_ = 0;    // node time at model time 0
  double model_ = 0;     // model time at node time node_ref_
  double node_ref_ = 0;  // node time model_ refers to
  std::vector<double> pending_;
};

}  // namespace demfdm::io
