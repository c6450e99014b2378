// fem_node: quasi-static implicit linear-elastic FEM (fem_model.hpp) as the bus's continuum
// role. A drop-in replacement for fdm_node: choose it with `[continuum] executable = "fem_node"`.
//
// Same scene keys as fdm_node ([continuum.mesh], [[continuum.material]] elastic only,
// boundary = "strongbox", [gravity]); keys that only make sense for an explicit solver
// (mode, damping, timestep_safety, static_mass_factor, averaging) are read by fdm_node and
// ignored here. Rejected with one clear error: a mohr_coulomb material, large_strain = true,
// boundary = "none" (a free body has a singular stiffness) and [continuum.punch].
//
// Each coupling step: apply the DEM's interface forces as nodal loads, one back-substitution
// with the factor computed at start-up, relax the update (continuum.relaxation: a scalar
// u_k = u_{k-1} + omega (u_static - u_{k-1}), or by default interface springs from the DEM's
// interface stiffness, see relaxation_factor()), send x0 + u_k and (u_k - u_{k-1}) / dt
// (dt = the coupling step; m/step when dt = 0), i.e. the velocity of the relaxed state. The
// stage criterion (equilibrium / geostatic / couple) is the out-of-balance ratio
// |K u_k - f| / |f| below the stage's ratio (met after every unrelaxed solve); penetrate has
// its consent. Outputs: fem.h5 + mesh.xmf (displacement, velocity, zone stress) and
// fem_history.csv in the run folder; frame times are the model time of docs/output.md
// (io::ModelClock).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <sstream>

#include <spdlog/spdlog.h>

#include "demfdm/io/csv_series.hpp"
#include "demfdm/io/model_time.hpp"
#include "demfdm/io/results_output.hpp"
#include "fem_model.hpp"
#include "fdm_node/scene_params.hpp"
#include "messages/node_runtime.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {


fem::Params fem_params(const config::Scene& s) {
  fem::Params p;
  p.mesh = fdm::mesh_from_scene(s);

  p.materials.clear();
  std::size_t n = s.count("continuum.material");
  if (n == 0) p.materials.push_back(fem::ElasticGroup{});
  for (std::size_t i = 0; i < n; ++i) {
    auto e = s.at("continuum.material", i);
    if (e.string("model") != "elastic")
      e.fail("model", "\"elastic\" (fem_node is a linear-elastic solver; use fdm_node for plasticity)",
             "\"" + e.string("model") + "\"");
    fem::ElasticGroup g;
    g.density = e.real("density");
    g.young = e.real("young");
    g.poisson = e.real("poisson");
    g.region = fdm::region_from_scene(e);
    p.materials.push_back(g);
  }
  if (s.boolean("continuum.large_strain"))
    s.fail("continuum.large_strain", "false (fem_node is a small-strain solver)", "true");
  if (s.string("continuum.boundary") != "strongbox")
    s.fail("continuum.boundary", "\"strongbox\" (fem_node needs supports: a free body has a singular stiffness)",
           "\"" + s.string("continuum.boundary") + "\"");
  if (s.has("continuum.punch"))
    s.fail("continuum.punch", "no [continuum.punch] section (fem_node has no prescribed-displacement punch)",
           "a [continuum.punch] section");
  double g = s.has("gravity") ? s.real("gravity.level") * s.real("gravity.g0") : 0.0;
  p.gravity = {0.0, 0.0, -g};
  p.strongbox = true;
  p.solver = fem::linear_solver_from_name(s.string("continuum.linear_solver"));
  return p;
}

class FemParticipant : public node::Participant {
 public:
  explicit FemParticipant(const node::Context& ctx) : ctx_(ctx), model_(fem_params(ctx.scene)) {
    const auto& s = ctx.scene;
    frame_every_ = s.integer("continuum.output.frame_every");
    history_every_ = s.integer("continuum.output.history_every");
    relaxation_ = s.real("continuum.relaxation");
    // Frame times: the model time, 0 at the beginning of the first stage that is not specimen
    // preparation (docs/output.md "Time").
    const auto stages = schema::stages(s);
    std::vector<std::string_view> actions;
    for (const auto& st : stages) {
      actions.push_back(st.action);
      stage_prefixes_.push_back(st.view.prefix());
    }
    clock_ = io::ModelClock(actions);
    u_prev_ = model_.interface_displacements();
    spdlog::info("fem: {} gridpoints, {} zones, {} free dofs, {} interface points; K factorised in {:.3f} s ({})",
                 model_.num_points(), model_.num_zones(), model_.num_free_dofs(),
                 model_.mesh().interface_points.size(), model_.factorisation_s(), model_.solver_name());
  }

  // Result files only when the scene has [continuum.output] (a scene writes only what it asks
  // for), created at the first stage; a resumed run reopens them where its checkpoint left them.
  static std::vector<std::string> history_columns() {
    return {"step_unit", "time_s", "residual_unit", "base_fx_N", "base_fy_N", "base_fz_N", "iface_fz_N", "solve_s"};
  }
  bool writes_outputs() const { return !ctx_.options.run_dir.empty() && ctx_.scene.has("continuum.output"); }
  void open_outputs() {
    if (outputs_open_) return;
    outputs_open_ = true;
    if (!writes_outputs()) return;
    fs::path dir = ctx_.options.run_dir;
    io::FileInfo info{"fem_node", std::to_string(ctx_.options.run_id), std::to_string(ctx_.scene.hash()), {}};
    std::vector<std::int64_t> conn(model_.mesh().zones.begin(), model_.mesh().zones.end());
    out_.emplace(dir, info, io::ArrayView(model_.mesh().points, 3), io::ArrayView(conn, 8), io::H5StorageParams{},
                 "fem.h5");
    if (clock_.known()) out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
    if (history_every_ > 0) history_.emplace(io::CsvSeries::create(dir / "fem_history.csv", history_columns()));
  }

  // At the top of every stage_begin, before any solve: the model-time origin at the first stage
  // that is not preparation (io::ModelClock); frames written before it get their model times.
  void begin_model_time(const schema::Stage& st) {
    const auto at = std::find(stage_prefixes_.begin(), stage_prefixes_.end(), st.view.prefix());
    if (!clock_.stage_begins(static_cast<std::size_t>(at - stage_prefixes_.begin()), time_)) return;
    const auto times = clock_.take_pending_times();
    if (!out_) return;
    node::Timed t(effect_s_["output.h5"]);
    out_->retime_frames(times);
    out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
  }

  // Checkpoints (docs/checkpoint-format.md): the model (section "fem_model"; the factorisation
  // is rebuilt on restore) and this adapter (section "fem_node") in the node file.
  bool can_checkpoint() const override { return true; }
  void save(const fs::path&, io::StateWriter& w, const io::StateMeta&) override {
    model_.save_state(w);
    w.begin("fem_node");
    for (const auto* v : {&u_prev_, &u_ref_, &stiffness_, &springs_}) w.f64s(*v);
    for (double v : {omega_, gain_, time_, dt_, last_solve_s_, total_solve_s_, last_frame_time_, max_imbalance_, iface_fz_})
      w.f64(v);
    for (bool b : {gain_checked_, coupled_, solved_, has_frame_}) w.b(b);
    w.i64(last_frame_);
    w.i64(solves_);
    node::OutputCheckpoint{outputs_open_, out_ ? out_->h5().frame_count() : 0, history_ ? history_->bytes() : 0,
                           history_ ? history_->rows() : 0}
        .save(w, clock_.state());
    w.end();
  }
  void restore(io::StateReader& r, const node::Restore& how) override {
    auto m = r.section("fem_model");
    model_.load_state(m);
    auto sec = r.section("fem_node");
    for (auto* v : {&u_prev_, &u_ref_, &stiffness_, &springs_}) *v = sec.f64s();
    for (double* v : {&omega_, &gain_, &time_, &dt_, &last_solve_s_, &total_solve_s_, &last_frame_time_, &max_imbalance_,
                      &iface_fz_})
      *v = sec.f64();
    for (bool* b : {&gain_checked_, &coupled_, &solved_, &has_frame_}) *b = sec.b();
    last_frame_ = sec.i64();
    solves_ = sec.i64();
    io::ModelClock::State c;
    const auto o = node::OutputCheckpoint::load(sec, c);
    const bool was_open = o.open;
    const auto frames = o.frames, bytes = o.bytes, rows = o.rows;
    sec.done();
    clock_.set_state(c);
    if (how.branch) {  // a new run folder: new result files from the branch point on
      has_frame_ = false;
      last_frame_time_ = 0;
      last_frame_ = -2;
      clock_.forget_pending();
      return;
    }
    outputs_open_ = was_open;
    if (was_open && writes_outputs()) {
      fs::path dir = ctx_.options.run_dir;
      out_.emplace(io::MeshOutput::resume(dir, frames, io::H5StorageParams{}, "fem.h5"));
      if (history_every_ > 0) history_.emplace(io::CsvSeries::resume(dir / "fem_history.csv", history_columns(), bytes, rows));
    }
  }

  double dt_stable() const override { return 0.0; }  // implicit: no limit
  double time() const override { return time_; }

  proto::Values stage_begin(const schema::Stage& st, std::int64_t) override {
    const auto& a = st.action;
    if (a != "cycle" && a != "equilibrium" && a != "geostatic" && a != "couple" && a != "penetrate")
      throw std::invalid_argument("fem_node does not support stage action '" + a + "'");
    open_outputs();
    begin_model_time(st);
    if (a == "geostatic" || a == "couple") {
      double k0 = st.view.real("k0");
      model_.set_geostatic_stress(k0 < 0 ? fdm::kNaN : k0);
      spdlog::info("fem: geostatic stresses assigned (K0 {})", k0 < 0 ? std::string("nu/(1-nu)") : std::to_string(k0));
    }
    if (st.view.boolean("reset_displacements")) u_ref_ = model_.displacements();
    effect_s_.clear();
    return {{"zones", static_cast<double>(model_.num_zones())},
            {"gridpoints", static_cast<double>(model_.num_points())}};
  }

  void advance(const schema::Stage&, std::int64_t step, double dt, const std::vector<double>&) override {
    auto t0 = std::chrono::steady_clock::now();
    u_prev_ = model_.interface_displacements();
    omega_ = relaxation_factor();
    model_.solve(omega_);
    last_solve_s_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    effect_s_["solve"] += last_solve_s_;
    total_solve_s_ += last_solve_s_;
    ++solves_;
    dt_ = dt;
    const double node_before = time_;
    time_ += dt > 0 ? dt : 1.0;
    clock_.advanced(node_before, dt, time_);
    solved_ = true;
    if (history_ && history_every_ > 0 && step % history_every_ == 0) {
      node::Timed t(effect_s_["output.history"]);
      auto b = model_.base_reaction();
      history_->append({static_cast<double>(step), time_, model_.residual_ratio(), b[0], b[1], b[2], iface_fz_,
                        last_solve_s_});
    }
    if (out_ && frame_every_ > 0 && step % frame_every_ == 0) write_frame(step);
  }

  proto::Values step_values() override {
    auto b = model_.base_reaction();
    proto::Values v{{"ratio", model_.residual_ratio()}, {"base_fz_N", b[2]}, {"solve_s", last_solve_s_},
                    {"relax_omega", omega_}, {"relax_gap", model_.relaxation_gap()},
                    {"weight_N", -model_.gravity_load()[2]}};
    if (coupled_) {
      v.push_back({"iface_imbalance", max_imbalance_});
      v.push_back({"iface_fz_N", iface_fz_});
      if (relaxation_ > 0) v.push_back({"coupling_gain", gain_});
      if (relaxation_ == 0) v.push_back({"refactorisations", static_cast<double>(model_.refactorisations())});
    }
    return v;
  }
  bool criterion_met(const schema::Stage& st) override {
    const auto& a = st.action;
    if (a == "equilibrium" || a == "geostatic" || a == "couple")
      return solved_ && model_.residual_ratio() < st.view.real("ratio");
    return a == "penetrate";
  }
  proto::Values stage_end(const schema::Stage&, std::int64_t last) override {
    if (out_ && last != last_frame_) write_frame(last);
    solved_ = false;
    auto v = step_values();
    v.push_back({"solves", static_cast<double>(solves_)});
    v.push_back({"solve_total_s", total_solve_s_});
    v.push_back({"refactorisation_s", model_.refactorisation_s()});
    for (auto& [name, sec] : effect_s_) v.push_back({"effect_s." + name, sec});
    return v;
  }

  // Blow-up guard (docs/stability.md): the first gridpoint with a non-finite displacement,
  // named with its position and the zones around it (their corner displacements).
  std::optional<node::HealthReport> check_health(std::int64_t) override {
    node::Timed t(effect_s_["guard"]);
    const auto& u = model_.displacements();
    for (std::size_t i = 0; i < u.size(); ++i) {
      if (std::isfinite(u[i])) continue;
      const auto g = static_cast<std::int32_t>(i / 3);
      return node::HealthReport{"non-finite displacement of gridpoint " + std::to_string(g) + " at " + point(g) + " m",
                                "gridpoint " + std::to_string(g) + " at " + point(g) + " m, displacement " +
                                    disp(g) + " m\nzones around it:\n" + zones_around(g)};
    }
    return std::nullopt;
  }
  void finish() override {
    spdlog::info("fem: {} solves, {:.3f} s in back-substitutions, {:.3f} s factorisation", solves_, total_solve_s_,
                 model_.factorisation_s());
    if (history_) history_->close();
  }

  proto::InterfaceMesh interface_mesh() override {
    const auto& mesh = model_.mesh();
    proto::InterfaceMesh m;
    m.point_ids.assign(mesh.interface_points.begin(), mesh.interface_points.end());
    m.positions = model_.interface_positions();
    m.triangles.assign(mesh.interface_triangles.begin(), mesh.interface_triangles.end());
    m.wall_of_triangle.assign(mesh.interface_triangle_side.begin(), mesh.interface_triangle_side.end());
    m.n_walls = 6;
    return m;
  }
  proto::Kinematics interface_kinematics() override {
    node::Timed t(effect_s_["interface"]);
    proto::Kinematics k;
    k.positions = model_.interface_positions();
    auto u = model_.interface_displacements();
    k.velocities.resize(u.size());
    double h = dt_ > 0 ? dt_ : 1.0;
    for (std::size_t i = 0; i < u.size(); ++i) k.velocities[i] = (u[i] - u_prev_[i]) / h;
    return k;
  }
  void apply_interface_forces(const proto::Forces& f) override {
    node::Timed t(effect_s_["interface"]);
    std::array<double, 3> sum{0, 0, 0};
    for (std::size_t i = 0; i < f.forces.size(); ++i) sum[i % 3] += f.forces[i];
    double scale = std::max({std::abs(f.total[0]), std::abs(f.total[1]), std::abs(f.total[2]), 1e-300});
    double imbalance =
        std::max({std::abs(sum[0] - f.total[0]), std::abs(sum[1] - f.total[1]), std::abs(sum[2] - f.total[2])});
    max_imbalance_ = std::max(max_imbalance_, imbalance / scale);
    coupled_ = true;
    iface_fz_ = sum[2];
    model_.set_interface_forces(f.forces);  // throws naming the sizes on a mismatch
    if (!f.stiffness.empty() && f.stiffness.size() != model_.mesh().interface_points.size())
      throw std::invalid_argument("fem: interface stiffness for " + std::to_string(f.stiffness.size()) +
                                  " points, the mesh has " + std::to_string(model_.mesh().interface_points.size()));
    stiffness_ = f.stiffness;
  }

 private:
  // The interface update of this step (docs/continuum-solvers.md); returns omega.
  // * continuum.relaxation = omega in (0, 1]: scalar under-relaxation, u_k = u_{k-1} + omega
  //   (u_static - u_{k-1}); 1 is the unrelaxed static continuum. The DEM's contacts answer an
  //   interface displacement du with dF = -k du within one step (k per point, docs/theory.md 6.5), so
  //   the error modes of this iteration are multiplied by 1 - omega (1 + lambda_i), lambda_i the
  //   eigenvalues of C k (C the interface compliance): contractive iff omega < 2 / (1 + lambda_max).
  //   At the first coupled step with stiffness the node estimates lambda_max (power iteration,
  //   Model::coupling_gain), reports it and warns when omega is beyond that limit.
  // * 0 (automatic): interface springs D = the DEM's stiffness, floored at kFloor max k, so that
  //   a solve answers (K + D) u_k = f + D u_{k-1}: u_k = u_{k-1} + (K + D)^-1 K (u_static -
  //   u_{k-1}), an under-relaxation whose factor (K + D)^-1 K is ~1 away from the contacts and
  //   ~K/k at stiff ones. Error factor (K + D)^-1 (D - k): contractive for every k <= 2 D, so K + D
  //   is refactorised only when some k exceeds kRefresh D, or when max k drops below kDrop max D
  //   (D then over-damps the interface), or D = 0 when the DEM reports no stiffness (scripted
  //   forces: the static answer in one step, omega = 1).
  double relaxation_factor() {
    double kmax = 0;
    for (double k : stiffness_) kmax = std::max(kmax, k);
    if (relaxation_ > 0) {
      if (kmax > 0 && !gain_checked_) {
        node::Timed t(effect_s_["relax.gain"]);
        gain_checked_ = true;
        gain_ = model_.coupling_gain(stiffness_);
        const double limit = 2.0 / (1.0 + gain_);
        if (relaxation_ >= limit)
          spdlog::warn("fem: continuum.relaxation = {} is beyond the stability limit 2 / (1 + lambda) = {:.4g} of the "
                       "interface iteration (coupling gain lambda = {:.4g} for the DEM's interface stiffness); the "
                       "coupled run will diverge or lose contact. Use 0 (automatic) or omega < {:.4g}",
                       relaxation_, limit, gain_, limit);
      }
      return relaxation_;
    }
    constexpr double kFloor = 0.25, kRefresh = 1.5, kDrop = 0.5;
    double dmax = 0;
    bool refresh = false;
    for (std::size_t i = 0; i < springs_.size(); ++i) {
      dmax = std::max(dmax, springs_[i]);
      if (i < stiffness_.size() && stiffness_[i] > kRefresh * springs_[i]) refresh = true;
    }
    if (springs_.size() != stiffness_.size() || kmax < kDrop * dmax) refresh = kmax > 0 || dmax > 0;
    if (refresh) {
      node::Timed t(effect_s_["relax.refactorise"]);
      springs_.assign(stiffness_.size(), 0.0);
      if (kmax > 0)
        for (std::size_t i = 0; i < stiffness_.size(); ++i) springs_[i] = std::max(stiffness_[i], kFloor * kmax);
      model_.set_interface_springs(kmax > 0 ? springs_ : std::vector<double>{});
      if (!(kmax > 0)) springs_.clear();
    }
    return 1.0;
  }

  std::string triple(const std::vector<double>& a, std::int32_t g) const {
    std::ostringstream os;
    os.precision(9);
    const auto i = 3 * static_cast<std::size_t>(g);
    os << "(" << a[i] << ", " << a[i + 1] << ", " << a[i + 2] << ")";
    return os.str();
  }
  std::string point(std::int32_t g) const { return triple(model_.mesh().points, g); }
  std::string disp(std::int32_t g) const { return triple(model_.displacements(), g); }
  std::string zones_around(std::int32_t g) const {
    const auto& z = model_.mesh().zones;
    std::ostringstream os;
    for (std::size_t k = 0; k < z.size() / 8; ++k) {
      if (std::find(z.begin() + 8 * k, z.begin() + 8 * k + 8, g) == z.begin() + 8 * k + 8) continue;
      os << "  zone " << k << ":";
      for (int c = 0; c < 8; ++c) os << " gp " << z[8 * k + c] << " u " << disp(z[8 * k + c]);
      os << "\n";
    }
    return os.str();
  }

  void write_frame(std::int64_t step) {
    if (has_frame_ && time_ <= last_frame_time_) return;
    node::Timed t(effect_s_["output.h5"]);
    const auto& u = model_.displacements();
    std::vector<double> disp(u.size()), vel(u.size(), 0.0);
    for (std::size_t i = 0; i < u.size(); ++i) disp[i] = u[i] - (u_ref_.empty() ? 0.0 : u_ref_[i]);
    auto stress = model_.zone_stress();
    io::MeshFrame f;
    f.node_arrays.push_back({"displacement", io::ArrayView(disp, 3)});
    f.zone_arrays.push_back({"stress", io::ArrayView(stress, 6)});
    out_->write_frame(step, clock_.frame_time(time_), f);  // model time (docs/output.md)
    has_frame_ = true;
    last_frame_time_ = time_;
    last_frame_ = step;
  }

  node::Context ctx_;
  fem::Model model_;
  std::optional<io::MeshOutput> out_;
  std::optional<io::CsvSeries> history_;
  std::int64_t frame_every_ = 0, history_every_ = 1, last_frame_ = -2, solves_ = 0;
  std::vector<double> u_prev_, u_ref_;
  std::vector<double> stiffness_, springs_;  // [n_if] DEM interface stiffness [N/m]; interface springs D [N/m]
  double relaxation_ = 0, omega_ = 1, gain_ = 0;
  bool gain_checked_ = false;
  double time_ = 0, dt_ = 0, last_solve_s_ = 0, total_solve_s_ = 0, last_frame_time_ = 0;
  double max_imbalance_ = 0, iface_fz_ = 0;
  bool coupled_ = false, solved_ = false, has_frame_ = false, outputs_open_ = false;
  io::ModelClock clock_;                     // the frames' model time
  std::vector<std::string> stage_prefixes_;  // "stage[i]" of every stage: its scene index
  std::map<std::string, double> effect_s_;  // [s] wall time of each effect in the current stage
};

}  // namespace

int main(int argc, char** argv) {
  return node::run_node(argc, argv, "continuum", "fem_node",
                        [](const node::Context& ctx) { return std::make_unique<FemParticipant>(ctx); });
}
