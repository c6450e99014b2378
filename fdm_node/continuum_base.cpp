#include "fdm_node/continuum_base.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include <spdlog/spdlog.h>

namespace demfdm::continuum {

NodeBase::NodeBase(const node::Context& ctx, Names names) : ctx_(ctx), names_(std::move(names)) {
  const auto& s = ctx_.scene;
  frame_every_ = s.integer("continuum.output.frame_every");
  history_every_ = s.integer("continuum.output.history_every");
  // Frame times: the model time, 0 at the beginning of the first stage that is not specimen
  // preparation (docs/output.md "Time").
  const auto stages = schema::stages(s);
  std::vector<bool> preparation;
  for (const auto& st : stages) {
    preparation.push_back(schema::action_info(st.kind).preparation);
    stage_prefixes_.push_back(st.view.prefix());
  }
  clock_ = io::ModelClock(preparation);
}

bool NodeBase::writes_outputs() const {
  return !ctx_.options.run_dir.empty() && ctx_.scene.has("continuum.output");
}

void NodeBase::open_outputs() {
  if (outputs_open_) return;
  outputs_open_ = true;
  if (!writes_outputs()) return;
  const std::filesystem::path dir = run_dir();
  io::FileInfo info{names_.solver, std::to_string(ctx_.options.run_id), std::to_string(ctx_.scene.hash()), {}};
  const auto& m = mesh();
  std::vector<std::int64_t> conn(m.zones.begin(), m.zones.end());
  out_.emplace(dir, info, io::ArrayView(m.points, 3), io::ArrayView(conn, 8), io::H5StorageParams{}, names_.h5);
  if (clock_.known()) out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
  if (history_every_ > 0) history_.emplace(io::CsvSeries::create(dir / names_.history, names_.history_columns));
}

bool NodeBase::begin_model_time(const schema::Stage& st, double node_time) {
  const auto at = std::find(stage_prefixes_.begin(), stage_prefixes_.end(), st.view.prefix());
  if (!clock_.stage_begins(static_cast<std::size_t>(at - stage_prefixes_.begin()), node_time)) return false;
  const auto times = clock_.take_pending_times();
  if (!out_) return true;
  node::Timed t(effect_s_["output.h5"]);
  out_->retime_frames(times);
  out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
  return true;
}

void NodeBase::require_action(const schema::Stage& st) const {
  // The stage-action table says where a continuum acts (refused at --check elsewhere).
  if (!schema::action_info(st.kind).continuum)
    throw std::invalid_argument(names_.solver + " does not act in stage action '" + st.action + "'");
}

proto::Values NodeBase::begin_stage(const schema::Stage& st) {
  if (st.kind == schema::Action::kGeostatic || st.kind == schema::Action::kCouple) {
    const auto k0_in = st.view.real_or_word("k0");  // "auto": nu/(1-nu) of each zone
    const double k0 = k0_in ? *k0_in : -1.0;
    set_geostatic_stress(k0 < 0 ? fdm::kNaN : k0);
    spdlog::info("{}: geostatic stresses assigned (K0 {})", names_.log,
                 k0 < 0 ? std::string("nu/(1-nu)") : std::to_string(k0));
  }
  if (st.view.boolean("reset_displacements")) reset_displacements();
  effect_s_.clear();
  return {{"zones", static_cast<double>(mesh().num_zones())},
          {"gridpoints", static_cast<double>(mesh().num_points())}};
}

void NodeBase::record_step(std::int64_t step) {
  if (history_ && history_every_ > 0 && step % history_every_ == 0) {
    node::Timed t(effect_s_["output.history"]);
    history_->append(history_row(step));
  }
  if (out_ && frame_every_ > 0 && step % frame_every_ == 0) write_frame(step);
}

void NodeBase::put_frame(std::int64_t step, double node_time, const io::MeshFrame& frame) {
  out_->write_frame(step, clock_.frame_time(node_time), frame);
  has_frame_ = true;
  last_frame_time_ = node_time;
  last_frame_ = step;
}

void NodeBase::write_last_frame(std::int64_t last) {
  if (out_ && last != last_frame_) write_frame(last);
}

void NodeBase::add_effect_times(proto::Values& v) const {
  for (const auto& [name, sec] : effect_s_) v.push_back({"effect_s." + name, sec});
}

void NodeBase::add_coupling_values(proto::Values& v) const {
  if (!coupled_) return;
  v.push_back({"iface_imbalance", max_imbalance_});
  v.push_back({"iface_fz_N", iface_fz_});
}

bool NodeBase::criterion_met(const schema::Stage& st) {
  switch (st.kind) {
    case schema::Action::kEquilibrium:
    case schema::Action::kGeostatic:
    case schema::Action::kCouple: {
      const auto r = equilibrium_ratio();
      return r && *r < st.view.real("ratio");
    }
    case schema::Action::kPenetrate: return true;
    default: return false;  // cycle; the DEM's actions (not run here: require_action)
  }
}

void NodeBase::finish() {
  if (history_) history_->close();
}

proto::InterfaceMesh NodeBase::interface_mesh() {
  const auto& g = mesh();
  proto::InterfaceMesh m;
  m.point_ids.assign(g.interface_points.begin(), g.interface_points.end());
  m.positions = interface_positions();
  m.triangles.assign(g.interface_triangles.begin(), g.interface_triangles.end());
  m.wall_of_triangle.assign(g.interface_triangle_side.begin(), g.interface_triangle_side.end());
  m.n_walls = 6;
  return m;
}

proto::Kinematics NodeBase::interface_kinematics() {
  node::Timed t(effect_s_["interface"]);
  proto::Kinematics k;
  k.positions = interface_positions();
  k.velocities = interface_velocities();
  return k;
}

void NodeBase::apply_interface_forces(const proto::Forces& f) {
  node::Timed t(effect_s_["interface"]);
  // Action-reaction: the sum we apply must equal the DEM's total to round-off.
  std::array<double, 3> sum{0, 0, 0};
  for (std::size_t i = 0; i < f.forces.size(); ++i) sum[i % 3] += f.forces[i];
  const double scale = std::max({std::abs(f.total[0]), std::abs(f.total[1]), std::abs(f.total[2]), 1e-300});
  const double imbalance =
      std::max({std::abs(sum[0] - f.total[0]), std::abs(sum[1] - f.total[1]), std::abs(sum[2] - f.total[2])});
  max_imbalance_ = std::max(max_imbalance_, imbalance / scale);
  coupled_ = true;
  iface_fz_ = sum[2];
  take_interface_forces(f);
}

void NodeBase::save_outputs(io::StateWriter& w) {
  node::OutputCheckpoint{outputs_open_, out_ ? out_->h5().frame_count() : 0, history_ ? history_->bytes() : 0,
                         history_ ? history_->rows() : 0}
      .save(w, clock_.state());
}

void NodeBase::restore_outputs(io::SectionReader& sec, const node::Restore& how) {
  io::ModelClock::State c;
  const auto o = node::OutputCheckpoint::load(sec, c);
  sec.done();
  clock_.set_state(c);
  if (how.branch) {  // a new run folder: new result files from the branch point on
    has_frame_ = false;
    last_frame_time_ = 0;
    last_frame_ = -2;
    clock_.forget_pending();
    return;
  }
  outputs_open_ = o.open;
  if (o.open && writes_outputs()) {
    const std::filesystem::path dir = run_dir();
    out_.emplace(io::MeshOutput::resume(dir, o.frames, io::H5StorageParams{}, names_.h5));
    if (history_every_ > 0)
      history_.emplace(io::CsvSeries::resume(dir / names_.history, names_.history_columns, o.bytes, o.rows));
  }
}

}  // namespace demfdm::continuum
