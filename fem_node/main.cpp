// fem_node: quasi-static implicit linear-elastic FEM (fem_core, demfdm/fem/model.hpp) as the
// bus's continuum role. A drop-in replacement for fdm_node: choose it with
// `[continuum] executable = "fem_node"`.
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
// its consent. Outputs: fem.h5 + mesh.xmf (displacement, zone stress) and fem_history.csv in
// the run folder; frame times are the model time of docs/output.md (io::ModelClock). What
// does not depend on the solver (interface, result files, model clock, balance check) is
// continuum::NodeBase (fdm_node/continuum_base.hpp).
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <optional>

#include <spdlog/spdlog.h>

#include "demfdm/fem/guard.hpp"
#include "demfdm/fem/model.hpp"
#include "fdm_node/continuum_base.hpp"
#include "fdm_node/scene_params.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {

fem::Params fem_params(const config::Scene& s) {
  fem::Params p;
  p.mesh = continuum::mesh_from_scene(s);
  p.materials = continuum::material_groups<fem::ElasticGroup>(s, [](const config::Scene& e) {
    if (e.string("model") != "elastic")
      e.fail("model", "\"elastic\" (fem_node is a linear-elastic solver; use fdm_node for plasticity)",
             "\"" + e.string("model") + "\"");
    const auto el = continuum::elastic_from_scene(e);
    return fem::ElasticGroup{el.density, el.young, el.poisson, el.region};
  });
  if (s.count("continuum.material") == 0) {  // the scene's material defaults, declared beside fdm::Material
    const fdm::Material rock;
    p.materials = {fem::ElasticGroup{rock.density, rock.young, rock.poisson, std::nullopt}};
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

class FemNode : public continuum::NodeBase {
 public:
  explicit FemNode(const node::Context& ctx)
      : NodeBase(ctx, {"fem_node", "fem", "fem.h5", "fem_history.csv",
                       {"step_unit", "time_s", "residual_unit", "base_fx_N", "base_fy_N", "base_fz_N", "iface_fz_N",
                        "solve_s"}}),
        model_(fem_params(ctx.scene)) {
    relaxation_ = ctx.scene.real("continuum.relaxation");
    u_prev_ = model_.interface_displacements();
    spdlog::info("fem: {} gridpoints, {} zones, {} free dofs, {} interface points; K factorised in {:.3f} s ({})",
                 model_.num_points(), model_.num_zones(), model_.num_free_dofs(),
                 model_.mesh().interface_points.size(), model_.factorisation_s(), model_.solver_name());
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
    save_outputs(w);
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
    restore_outputs(sec, how);
  }

  double dt_stable() const override { return 0.0; }  // implicit: no limit
  double time() const override { return time_; }

  proto::Values stage_begin(const schema::Stage& st, std::int64_t) override {
    require_action(st);
    open_outputs();
    begin_model_time(st, time_);
    return begin_stage(st);
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
    record_step(step);
  }

  proto::Values step_values() override {
    auto b = model_.base_reaction();
    proto::Values v{{"ratio", model_.residual_ratio()}, {"base_fz_N", b[2]}, {"solve_s", last_solve_s_},
                    {"relax_omega", omega_}, {"relax_gap", model_.relaxation_gap()},
                    {"weight_N", -model_.gravity_load()[2]}};
    add_coupling_values(v);
    if (coupled_) {
      if (relaxation_ > 0) v.push_back({"coupling_gain", gain_});
      if (relaxation_ == 0) v.push_back({"refactorisations", static_cast<double>(model_.refactorisations())});
    }
    return v;
  }
  proto::Values stage_end(const schema::Stage&, std::int64_t last) override {
    write_last_frame(last);
    solved_ = false;
    auto v = step_values();
    v.push_back({"solves", static_cast<double>(solves_)});
    v.push_back({"solve_total_s", total_solve_s_});
    v.push_back({"refactorisation_s", model_.refactorisation_s()});
    add_effect_times(v);
    return v;
  }

  // Blow-up guard (docs/stability.md): the first gridpoint with a non-finite displacement,
  // named with its position and the zones around it (their corner displacements).
  std::optional<node::HealthReport> check_health(std::int64_t) override {
    node::Timed t(effect_s_["guard"]);
    if (auto f = fem::check_finite(model_)) return node::HealthReport{f->cause, f->detail};
    return std::nullopt;
  }
  void finish() override {
    spdlog::info("fem: {} solves, {:.3f} s in back-substitutions, {:.3f} s factorisation", solves_, total_solve_s_,
                 model_.factorisation_s());
    NodeBase::finish();
  }

 private:
  // continuum::NodeBase hooks.
  const fdm::Mesh& mesh() const override { return model_.mesh(); }
  std::vector<double> interface_positions() const override { return model_.interface_positions(); }
  // The velocity of the relaxed state: (u_k - u_{k-1}) / dt, per step when dt = 0.
  std::vector<double> interface_velocities() const override {
    auto u = model_.interface_displacements();
    std::vector<double> v(u.size());
    double h = dt_ > 0 ? dt_ : 1.0;
    for (std::size_t i = 0; i < u.size(); ++i) v[i] = (u[i] - u_prev_[i]) / h;
    return v;
  }
  void take_interface_forces(const proto::Forces& f) override {
    model_.set_interface_forces(f.forces);  // throws naming the sizes on a mismatch
    if (!f.stiffness.empty() && f.stiffness.size() != model_.mesh().interface_points.size())
      throw std::invalid_argument("fem: interface stiffness for " + std::to_string(f.stiffness.size()) +
                                  " points, the mesh has " + std::to_string(model_.mesh().interface_points.size()));
    stiffness_ = f.stiffness;
  }
  // |K u - f| / |f| of the last solve; none before the stage's first solve.
  std::optional<double> equilibrium_ratio() const override {
    return solved_ ? std::optional<double>(model_.residual_ratio()) : std::nullopt;
  }
  void set_geostatic_stress(double k0) override { model_.set_geostatic_stress(k0); }
  void reset_displacements() override { u_ref_ = model_.displacements(); }
  std::vector<double> history_row(std::int64_t step) override {
    auto b = model_.base_reaction();
    return {static_cast<double>(step), time_, model_.residual_ratio(), b[0], b[1], b[2], iface_fz_, last_solve_s_};
  }
  void write_frame(std::int64_t step) override {
    if (!frame_due(time_)) return;
    node::Timed t(effect_s_["output.h5"]);
    const auto& u = model_.displacements();
    std::vector<double> disp(u.size());
    for (std::size_t i = 0; i < u.size(); ++i) disp[i] = u[i] - (u_ref_.empty() ? 0.0 : u_ref_[i]);
    auto stress = model_.zone_stress();
    io::MeshFrame f;
    f.node_arrays.push_back({"displacement", io::ArrayView(disp, 3)});
    f.zone_arrays.push_back({"stress", io::ArrayView(stress, 6)});
    put_frame(step, time_, f);
  }

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

  fem::Model model_;
  std::int64_t solves_ = 0;
  std::vector<double> u_prev_, u_ref_;
  std::vector<double> stiffness_, springs_;  // [n_if] DEM interface stiffness [N/m]; interface springs D [N/m]
  double relaxation_ = 0, omega_ = 1, gain_ = 0;
  bool gain_checked_ = false;
  double time_ = 0, dt_ = 0, last_solve_s_ = 0, total_solve_s_ = 0;
  bool solved_ = false;
};

}  // namespace

int main(int argc, char** argv) {
  return node::run_node(argc, argv, "continuum", "fem_node",
                        [](const node::Context& ctx) { return std::make_unique<FemNode>(ctx); });
}
