// ModelClock: the model time of the results frames (see the header; docs/output.md "Time").
#include "demfdm/io/model_time.hpp"

namespace demfdm::io {

ModelClock::ModelClock(const std::vector<bool>& preparation) : first_(preparation.size()) {
  for (std::size_t i = 0; i < preparation.size(); ++i)
    if (!preparation[i]) {
      first_ = i;
      break;
    }
}

bool ModelClock::stage_begins(std::size_t stage_index, double node_time) {
  if (known_ || stage_index < first_) return false;
  known_ = true;
  origin_ = node_time;
  model_ = 0;
  node_ref_ = node_time;
  return true;
}

void ModelClock::catch_up(double node_time) {
  if (node_time != node_ref_) {
    model_ += node_time - node_ref_;
    node_ref_ = node_time;
  }
}

void ModelClock::advanced(double node_before, double dt, double node_after) {
  if (!known_) return;
  catch_up(node_before);
  model_ += dt > 0 ? dt : node_after - node_before;
  node_ref_ = node_after;
}

double ModelClock::frame_time(double node_time) {
  if (!known_) {
    pending_.push_back(node_time);
    return node_time;
  }
  catch_up(node_time);
  return model_;
}

std::vector<double> ModelClock::take_pending_times() {
  std::vector<double> t;
  t.reserve(pending_.size());
  for (double n : pending_) t.push_back(known_ ? n - origin_ : n);
  pending_.clear();
  return t;
}

void ModelClock::set_state(const State& s) {
  known_ = s.known;
  origin_ = s.origin;
  model_ = s.model;
  node_ref_ = s.node_ref;
  pending_ = s.pending;
}

}  // namespace demfdm::io
