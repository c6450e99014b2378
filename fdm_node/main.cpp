// fdm_node: the FLAC3D-style continuum (fdm_core) as the bus's continuum role.
//
// A thin adapter on continuum::NodeBase (continuum_base.hpp: coupling interface, result files,
// model clock, balance check, equilibrium criterion): scene keys -> fdm::ModelParams, stage
// actions -> model calls, results -> fdm.h5 + mesh.xmf + fdm_history.csv in the run folder,
// and what only this solver has: sub-cycling, the symmetry boundary, the rigid punch, the
// kinetic-energy guard and the stress profiles.
#include <omp.h>

#include <cmath>
#include <filesystem>
#include <optional>
#include <sstream>

#include <spdlog/spdlog.h>

#include "demfdm/fdm/checkpoint.hpp"
#include "demfdm/fdm/guard.hpp"
#include "demfdm/fdm/model.hpp"
#include "demfdm/fdm/profile.hpp"
#include "fdm_node/continuum_base.hpp"
#include "fdm_node/scene_params.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {

fdm::ModelParams model_params(const config::Scene& s) {
  fdm::ModelParams p;
  p.mesh = continuum::mesh_from_scene(s);
  p.materials = continuum::material_groups<fdm::MaterialGroup>(s, continuum::material_from_scene);
  continuum::model_keys_from_scene(s, p);
  p.gravity_level = s.has("gravity") ? s.real("gravity.level") * s.real("gravity.g0") / fdm::kStandardGravity : 0.0;
  p.strongbox_boundary = s.string("continuum.boundary") == "strongbox";
  // Alone, the continuum has the machine's cores: split its loops from a few hundred zones. In a
  // coupled run the DEM node takes measurements on one thread while the continuum steps (its
  // forces have gone out), so a second continuum thread competes with it for a core: there the
  // engine's default (4,096) holds, and the paper's 2,780-zone box steps on one thread. Default
  // scene, 3,000-step windows, 10 alternated pairs (docs/speed.md, session 22): the zone pass
  // 0.70-0.90 ms per step on one thread against 0.79-1.25 ms on two, lower in every pair. Results
  // do not depend on it (fdm/params.hpp).
  if (!s.has("coupling")) p.parallel_threshold = 512;
  try {
    fdm::validate(p);
  } catch (const std::invalid_argument& e) {
    s.fail("continuum", "a valid FDM model", e.what());
  }
  return p;
}

class FdmNode : public continuum::NodeBase {
 public:
  explicit FdmNode(const node::Context& ctx)
      : NodeBase(ctx, {"fdm_node", "fdm", "fdm.h5", "fdm_history.csv",
                       {"step_unit", "time_s", "ratio_avg_unit", "ratio_max_unit", "kinetic_J", "base_fx_N",
                        "base_fy_N", "base_fz_N", "punch_fz_N", "punch_disp_m"}}),
        model_(model_params(ctx.scene)),
        energy_jump_(ctx.scene) {
    const auto& s = ctx.scene;
    omp_set_num_threads(schema::run_threads(s));
    spdlog::info("fdm: {} OpenMP threads (run.threads)", schema::run_threads(s));
    if (s.string("continuum.boundary") == "symmetry") setup_symmetry(s);
    if (s.has("continuum.punch")) setup_punch(s);
    spdlog::info("fdm: {} gridpoints, {} zones, {} interface points, {} interface triangles; critical dt {:.3e} s",
                 model_.num_gridpoints(), model_.num_zones(), model_.interface_gridpoints().size(),
                 model_.interface_triangles().size() / 3, model_.critical_timestep());
  }

  // Checkpoints (docs/checkpoint-format.md): the Model in continuum.model.state, this adapter's
  // fields and its result writers' positions in the node file's section "fdm_node".
  bool can_checkpoint() const override { return true; }
  void save(const fs::path& dir, io::StateWriter& w, const io::StateMeta& meta) override {
    fdm::save_state_file(model_, dir / "continuum.model.state", meta);
    w.begin("fdm_node");
    w.i64(last_step_);
    w.i64(last_frame_);
    w.b(has_frame_);
    w.f64(last_frame_time_);
    for (double v : {last_ratios_.average, last_ratios_.max, last_ratios_.local, punch_disp_, max_imbalance_, iface_fz_})
      w.f64(v);
    w.b(released_);
    w.b(coupled_);
    energy_jump_.save(w);
    save_outputs(w);
    w.end();
  }
  void restore(io::StateReader& r, const node::Restore& how) override {
    fdm::load_state_file(model_, how.dir / "continuum.model.state", how.saved_scene_hash);
    omp_set_num_threads(schema::run_threads(ctx_.scene));
    auto sec = r.section("fdm_node");
    last_step_ = sec.i64();
    last_frame_ = sec.i64();
    has_frame_ = sec.b();
    last_frame_time_ = sec.f64();
    for (double* v : {&last_ratios_.average, &last_ratios_.max, &last_ratios_.local, &punch_disp_, &max_imbalance_, &iface_fz_})
      *v = sec.f64();
    released_ = sec.b();
    coupled_ = sec.b();
    energy_jump_.load(sec);
    restore_outputs(sec, how);
  }

  double dt_stable() const override {
    return model_.params().mode == fdm::Mode::kStatic ? 0.0 : model_.critical_timestep();
  }
  double time() const override { return model_.time(); }

  proto::Values stage_begin(const schema::Stage& st, std::int64_t) override {
    open_outputs();
    if (begin_model_time(st, model_.time()))
      spdlog::info("fdm: model time 0 at stage '{}' (continuum time {} s)", st.name, clock_.origin());
    require_action(st);
    model_.reset_phase_times();
    return begin_stage(st);
  }

  void advance(const schema::Stage&, std::int64_t step, double dt, const std::vector<double>&) override {
    const double node_before = model_.time();
    if (model_.params().mode == fdm::Mode::kDynamic) {
      // Sub-cycle when the coupling step is longer than this model's stable step.
      double crit = model_.critical_timestep();
      int n = dt > 0 ? static_cast<int>(std::ceil(dt / crit * (1 - 1e-12))) : 1;
      double h = dt > 0 ? dt / n : crit;
      try {
        if (h != model_.timestep()) model_.set_timestep(h);
        for (int i = 0; i < n; ++i) model_.step();
      } catch (const std::exception& e) {
        std::ostringstream os;
        os.precision(6);
        os << "continuum timestep " << h << " s (coupling step " << dt << " s in " << n
           << " sub-steps) against the critical timestep " << model_.critical_timestep() << " s: " << e.what();
        throw std::runtime_error(os.str());
      }
      if (!punch_.empty() && !released_) punch_disp_ += punch_velocity_ * (dt > 0 ? dt : crit);
      if (!punch_.empty() && release_after_ > 0 && !released_ && model_.time() >= release_after_ * (1 - 1e-12)) {
        for (auto g : punch_) model_.free_velocity(g, fdm::kFixZ);
        released_ = true;
      }
    } else {
      model_.step();
      if (!punch_.empty()) punch_disp_ += punch_velocity_;
    }
    clock_.advanced(node_before, dt, model_.time());
    last_ratios_ = model_.ratios();
    record_step(step);
    last_step_ = step;
  }

  proto::Values step_values() override {
    auto b = model_.base_reaction();
    proto::Values v{{"ratio", last_ratios_.average}, {"base_fz_N", b[2]}, {"kinetic_J", model_.kinetic_energy()}};
    if (model_.params().mode == fdm::Mode::kDynamic) {
      v.push_back({"dt_s", model_.timestep()});
      v.push_back({"dt_critical_s", model_.critical_timestep()});
    }
    if (model_.params().gravity_level > 0) v.push_back({"weight_N", weight()});
    add_coupling_values(v);
    if (!punch_.empty()) {
      v.push_back({"punch_fz_N", punch_force()});
      v.push_back({"punch_disp_m", punch_disp_});
    }
    return v;
  }
  proto::Values stage_end(const schema::Stage& st, std::int64_t last) override {
    write_last_frame(last);
    if (out_ && model_.params().gravity_level > 0) {
      node::Timed t(effect_s_["output.profile"]);
      write_profile(st);
    }
    auto v = step_values();
    const auto& pt = model_.phase_times();
    effect_s_["zones"] = pt.zones;
    effect_s_["gridpoints"] = pt.gridpoints;  // with gravity and local damping (fused loop)
    if (coupled_) effect_s_["interface"] = pt.interface + effect_s_["interface"];
    add_effect_times(v);
    return v;
  }

  // Blow-up guard (docs/stability.md): non-finite gridpoint or zone state, kinetic-energy jump.
  std::optional<node::HealthReport> check_health(std::int64_t) override {
    node::Timed t(effect_s_["guard"]);
    if (auto f = fdm::check_finite(model_)) return node::HealthReport{f->cause, f->detail};
    if (model_.params().mode != fdm::Mode::kDynamic) return std::nullopt;  // static: scaled masses
    if (auto jump = energy_jump_.check(model_.kinetic_energy())) {
      const auto g = fdm::fastest_gridpoint(model_);
      return node::HealthReport{"continuum " + *jump + "; fastest gridpoint " + std::to_string(g),
                                fdm::describe_gridpoint(model_, g) + "\nzones around it:\n" + fdm::zones_around(model_, g)};
    }
    return std::nullopt;
  }

 private:
  // continuum::NodeBase hooks.
  const fdm::Mesh& mesh() const override { return model_.mesh(); }
  std::vector<double> interface_positions() const override { return model_.interface_positions(); }
  std::vector<double> interface_velocities() const override { return model_.interface_velocities(); }
  void take_interface_forces(const proto::Forces& f) override {
    if (f.forces.size() != 3 * model_.interface_gridpoints().size())
      throw std::runtime_error("interface forces for " + std::to_string(f.forces.size() / 3) + " points, the mesh has " +
                               std::to_string(model_.interface_gridpoints().size()));
    model_.set_interface_forces(f.forces);
    model_.set_interface_stiffness(f.stiffness);
  }
  // The FLAC3D ratio-average of the last step.
  std::optional<double> equilibrium_ratio() const override { return last_ratios_.average; }
  void set_geostatic_stress(double k0) override {
    fdm::GeostaticStress g;
    g.k0 = k0;
    model_.set_geostatic_stress(g);
  }
  void reset_displacements() override {
    model_.reset_displacements();
    punch_disp_ = 0;
  }
  std::vector<double> history_row(std::int64_t step) override {
    auto b = model_.base_reaction();
    return {static_cast<double>(step), model_.time(), last_ratios_.average, last_ratios_.max,
            model_.kinetic_energy(), b[0], b[1], b[2], punch_force(), punch_disp_};
  }
  void write_frame(std::int64_t step) override {
    node::Timed t(effect_s_["output.h5"]);
    auto stress = model_.zone_stress();
    io::MeshFrame f;
    f.node_arrays.push_back({"displacement", io::ArrayView(model_.displacements(), 3)});
    f.node_arrays.push_back({"velocity", io::ArrayView(model_.velocities(), 3)});
    f.zone_arrays.push_back({"stress", io::ArrayView(stress, 6)});
    f.zone_arrays.push_back({"plastic", io::ArrayView(model_.plastic_state())});
    if (frame_due(model_.time())) put_frame(step, model_.time(), f);
  }

  // Element-test boundary: rollers on the three coordinate planes through the origin; the
  // confining pressure on the x = L and y = W faces, with the matching hydrostatic initial stress
  // so that the specimen starts in equilibrium.
  void setup_symmetry(const config::Scene& s) {
    for (int axis = 0; axis < 3; ++axis)
      for (auto g : model_.gridpoints_on_plane(axis, 0.0))
        model_.fix_velocity(g, static_cast<std::uint8_t>(1u << axis), {0.0, 0.0, 0.0});
    double p = s.real("continuum.confining");
    if (p > 0) {
      std::vector<fdm::BoundaryFace> faces;
      for (auto& f : fdm::boundary_faces(model_.mesh()))
        if (f.side == fdm::Side::kPlusX || f.side == fdm::Side::kPlusY) faces.push_back(f);
      model_.add_face_pressure(faces, p);
      model_.set_uniform_stress({-p, -p, -p, 0.0, 0.0, 0.0});
    }
    spdlog::info("fdm: symmetry boundary, confining pressure {} Pa", p);
  }

  void setup_punch(const config::Scene& s) {
    release_after_ = s.real("continuum.punch.release_after");
    double a = s.real("continuum.punch.radius");
    punch_velocity_ = s.real("continuum.punch.velocity");
    auto c = s.reals("continuum.punch.centre");
    auto size = s.reals("continuum.mesh.size");
    double cx = c.size() == 2 ? c[0] : size[0] / 2, cy = c.size() == 2 ? c[1] : size[1] / 2;
    auto top = model_.gridpoints_on_plane(2, size[2]);
    auto pos = model_.positions();
    for (auto g : top) {
      double dx = pos[3 * g] - cx, dy = pos[3 * g + 1] - cy;
      if (dx * dx + dy * dy <= a * a * (1 + 1e-9)) punch_.push_back(g);
    }
    if (punch_.empty()) s.fail("continuum.punch.radius", "a radius that covers at least one top gridpoint", std::to_string(a));
    const std::uint8_t mask = s.boolean("continuum.punch.rough") ? fdm::kFixAll : fdm::kFixZ;
    for (auto g : punch_) model_.fix_velocity(g, mask, {0.0, 0.0, -punch_velocity_});
    spdlog::info("fdm: rigid punch radius {} m on {} top gridpoints, speed {} m/s", a, punch_.size(), punch_velocity_);
  }
  // The soil's reaction on the punch gridpoints (upward while the punch pushes down).
  double punch_force() const { return punch_.empty() ? 0.0 : model_.reaction_sum(punch_)[2]; }

  double weight() const {
    return model_.total_gravitational_mass() * model_.params().gravity_level * fdm::kStandardGravity;
  }

  // Vertical stress profile (Fig. 3, fdm::stress_profile) with the line rho N g depth from the
  // mesh top, rho the density of the first material group. Written to fdm_profile_<stage>.csv.
  void write_profile(const schema::Stage& st) {
    const auto layers = fdm::stress_profile(model_);
    const double g = model_.params().gravity_level * fdm::kStandardGravity;
    const double rho = model_.params().materials.front().material.density;
    auto csv = io::CsvSeries::create(run_dir() / ("fdm_profile_" + st.name + ".csv"),
                                     {"depth_m", "szz_Pa", "sxx_Pa", "zones_1", "selfweight_szz_Pa", "rho_kg_m3"});
    for (const auto& l : layers)
      csv.append({l.depth, l.szz, l.sxx, static_cast<double>(l.zones), -rho * g * l.depth, rho});
    csv.close();
  }

  fdm::Model model_;
  std::int64_t last_step_ = -1;
  fdm::Ratios last_ratios_{};
  std::vector<std::int32_t> punch_;
  double punch_velocity_ = 0, punch_disp_ = 0, release_after_ = 0;
  bool released_ = false;
  node::EnergyJump energy_jump_;
};

}  // namespace

int main(int argc, char** argv) {
  return node::run_node(argc, argv, "continuum", "fdm_node",
                        [](const node::Context& ctx) { return std::make_unique<FdmNode>(ctx); });
}
