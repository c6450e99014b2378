// fdm_node: the FLAC3D-style continuum (fdm_core) as the bus's continuum role.
//
// A thin adapter: scene keys -> fdm::ModelParams, stage actions -> model calls, coupling hooks
// -> interface arrays, results -> fdm.h5 + mesh.xmf + fdm_history.csv in the run folder (frame
// times: the model time of docs/output.md, io::ModelClock).
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <optional>
#include <sstream>

#include <spdlog/spdlog.h>

#include "demfdm/fdm/checkpoint.hpp"
#include "demfdm/fdm/guard.hpp"
#include "demfdm/fdm/model.hpp"
#include "fdm_node/scene_params.hpp"
#include "demfdm/io/csv_series.hpp"
#include "demfdm/io/model_time.hpp"
#include "demfdm/io/results_output.hpp"
#include "messages/node_runtime.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {


fdm::ModelParams model_params(const config::Scene& s) {
  fdm::ModelParams p;
  p.mesh = fdm::mesh_from_scene(s);

  p.materials.clear();
  std::size_t n = s.count("continuum.material");
  if (n == 0) p.materials.push_back(fdm::MaterialGroup{});
  for (std::size_t i = 0; i < n; ++i) {
    auto e = s.at("continuum.material", i);
    fdm::MaterialGroup g;
    auto& mat = g.material;
    mat.model = e.string("model") == "mohr_coulomb" ? fdm::Constitutive::kMohrCoulomb : fdm::Constitutive::kElastic;
    mat.density = e.real("density");
    mat.young = e.real("young");
    mat.poisson = e.real("poisson");
    mat.cohesion = e.real("cohesion");
    mat.friction_deg = e.real("friction_deg");
    mat.dilation_deg = e.real("dilation_deg");
    mat.tension = e.real("tension") < 0 ? fdm::kNaN : e.real("tension");
    g.region = fdm::region_from_scene(e);
    p.materials.push_back(g);
  }
  p.mode = s.string("continuum.mode") == "static" ? fdm::Mode::kStatic : fdm::Mode::kDynamic;
  p.damping = s.real("continuum.damping");
  p.gravity_level = s.has("gravity") ? s.real("gravity.level") * s.real("gravity.g0") / fdm::kStandardGravity : 0.0;
  p.large_strain = s.boolean("continuum.large_strain");
  p.averaging = s.string("continuum.averaging") == "zone" ? fdm::VolumetricAveraging::kPerZone
                                                          : fdm::VolumetricAveraging::kPerOverlay;
  p.timestep_safety = s.real("continuum.timestep_safety");
  p.static_mass_factor = s.real("continuum.static_mass_factor");
  p.strongbox_boundary = s.string("continuum.boundary") == "strongbox";
  try {
    fdm::validate(p);
  } catch (const std::invalid_argument& e) {
    s.fail("continuum", "a valid FDM model", e.what());
  }
  return p;
}

class FdmParticipant : public node::Participant {
 public:
  explicit FdmParticipant(const node::Context& ctx)
      : ctx_(ctx), model_(model_params(ctx.scene)), energy_jump_(ctx.scene) {
    const auto& s = ctx.scene;
    omp_set_num_threads(static_cast<int>(s.integer("run.threads")));
    frame_every_ = s.integer("continuum.output.frame_every");
    history_every_ = s.integer("continuum.output.history_every");
    // Frame times: the model time, 0 at the beginning of the first stage that is not specimen
    // preparation (docs/output.md "Time").
    const auto stages = schema::stages(s);
    std::vector<std::string_view> actions;
    for (const auto& st : stages) {
      actions.push_back(st.action);
      stage_prefixes_.push_back(st.view.prefix());
    }
    clock_ = io::ModelClock(actions);
    if (s.string("continuum.boundary") == "symmetry") setup_symmetry(s);
    if (s.has("continuum.punch")) setup_punch(s);
    spdlog::info("fdm: {} gridpoints, {} zones, {} interface points, {} interface triangles; critical dt {:.3e} s",
                 model_.num_gridpoints(), model_.num_zones(), model_.interface_gridpoints().size(),
                 model_.interface_triangles().size() / 3, model_.critical_timestep());
  }

  // Result files only when the scene has [continuum.output] (a scene writes only what it asks
  // for), created at the first stage; a resumed run reopens them where its checkpoint left them.
  static std::vector<std::string> history_columns() {
    return {"step_unit", "time_s", "ratio_avg_unit", "ratio_max_unit", "kinetic_J", "base_fx_N", "base_fy_N",
            "base_fz_N", "punch_fz_N", "punch_disp_m"};
  }
  bool writes_outputs() const { return !ctx_.options.run_dir.empty() && ctx_.scene.has("continuum.output"); }
  void open_outputs() {
    if (outputs_open_) return;
    outputs_open_ = true;
    if (!writes_outputs()) return;
    fs::path dir = ctx_.options.run_dir;
    io::FileInfo info{"fdm_node", std::to_string(ctx_.options.run_id), std::to_string(ctx_.scene.hash()), {}};
    std::vector<std::int64_t> conn(model_.connectivity().begin(), model_.connectivity().end());
    out_.emplace(dir, info, io::ArrayView(model_.mesh().points, 3), io::ArrayView(conn, 8));
    if (clock_.known()) out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
    if (history_every_ > 0) history_.emplace(io::CsvSeries::create(dir / "fdm_history.csv", history_columns()));
  }

  // At the top of every stage_begin, before any step: the model-time origin at the first stage
  // that is not preparation (io::ModelClock); frames written before it get their model times.
  void begin_model_time(const schema::Stage& st) {
    const auto at = std::find(stage_prefixes_.begin(), stage_prefixes_.end(), st.view.prefix());
    if (!clock_.stage_begins(static_cast<std::size_t>(at - stage_prefixes_.begin()), model_.time())) return;
    const auto times = clock_.take_pending_times();
    spdlog::info("fdm: model time 0 at stage '{}' (continuum time {} s)", st.name, clock_.origin());
    if (!out_) return;
    node::Timed t(effect_s_["output.h5"]);
    out_->retime_frames(times);
    out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
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
    node::OutputCheckpoint{outputs_open_, out_ ? out_->h5().frame_count() : 0, history_ ? history_->bytes() : 0,
                           history_ ? history_->rows() : 0}
        .save(w, clock_.state());
    w.end();
  }
  void restore(io::StateReader& r, const node::Restore& how) override {
    fdm::load_state_file(model_, how.dir / "continuum.model.state", how.saved_scene_hash);
    omp_set_num_threads(static_cast<int>(ctx_.scene.integer("run.threads")));
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
      out_.emplace(io::MeshOutput::resume(dir, frames));
      if (history_every_ > 0) history_.emplace(io::CsvSeries::resume(dir / "fdm_history.csv", history_columns(), bytes, rows));
    }
  }

  double dt_stable() const override {
    return model_.params().mode == fdm::Mode::kStatic ? 0.0 : model_.critical_timestep();
  }
  double time() const override { return model_.time(); }

  proto::Values stage_begin(const schema::Stage& st, std::int64_t) override {
    open_outputs();
    begin_model_time(st);
    const auto& a = st.action;
    if (a != "cycle" && a != "equilibrium" && a != "geostatic" && a != "couple" && a != "penetrate")
      throw std::invalid_argument("fdm_node does not support stage action '" + a + "'");
    // couple: the interface is being set up; the continuum starts from its geostatic state.
    if (a == "geostatic" || a == "couple") {
      fdm::GeostaticStress g;
      double k0 = st.view.real("k0");
      g.k0 = k0 < 0 ? fdm::kNaN : k0;
      model_.set_geostatic_stress(g);
      spdlog::info("fdm: geostatic stresses assigned (K0 {})", k0 < 0 ? std::string("nu/(1-nu)") : std::to_string(k0));
    }
    if (st.view.boolean("reset_displacements")) {
      model_.reset_displacements();
      punch_disp_ = 0;
    }
    model_.reset_phase_times();
    effect_s_.clear();
    return {{"zones", static_cast<double>(model_.num_zones())},
            {"gridpoints", static_cast<double>(model_.num_gridpoints())}};
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
    if (history_ && history_every_ > 0 && step % history_every_ == 0) {
      node::Timed t(effect_s_["output.history"]);
      auto b = model_.base_reaction();
      history_->append({static_cast<double>(step), model_.time(), last_ratios_.average, last_ratios_.max,
                        model_.kinetic_energy(), b[0], b[1], b[2], punch_force(), punch_disp_});
    }
    if (out_ && frame_every_ > 0 && step % frame_every_ == 0) write_frame(step);
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
    if (coupled_) {
      // Largest relative difference so far between the force sum the continuum applied and the
      // DEM's own total of the same step (action = reaction, docs/theory.md 6.9).
      v.push_back({"iface_imbalance", max_imbalance_});
      v.push_back({"iface_fz_N", iface_fz_});
    }
    if (!punch_.empty()) {
      v.push_back({"punch_fz_N", punch_force()});
      v.push_back({"punch_disp_m", punch_disp_});
    }
    return v;
  }
  // Equilibrium actions: the FLAC3D ratio-average below the stage's 'ratio'. Actions whose
  // end the continuum does not decide (penetrate: the footing depth) have its consent.
  bool criterion_met(const schema::Stage& st) override {
    const auto& a = st.action;
    if (a == "equilibrium" || a == "geostatic" || a == "couple") return last_ratios_.average < st.view.real("ratio");
    return a == "penetrate";
  }
  proto::Values stage_end(const schema::Stage& st, std::int64_t last) override {
    if (out_ && last != last_frame_) write_frame(last);
    if (out_ && model_.params().gravity_level > 0) {
      node::Timed t(effect_s_["output.profile"]);
      write_profile(st);
    }
    auto v = step_values();
    const auto& pt = model_.phase_times();
    effect_s_["zones"] = pt.zones;
    effect_s_["gridpoints"] = pt.gridpoints;  // with gravity and local damping (fused loop)
    if (coupled_) effect_s_["interface"] = pt.interface + effect_s_["interface"];
    for (auto& [name, sec] : effect_s_) v.push_back({"effect_s." + name, sec});
    return v;
  }

  // Blow-up guard (docs/stability.md): non-finite gridpoint or zone state, kinetic-energy jump.
  std::optional<node::HealthReport> check_health(std::int64_t) override {
    node::Timed t(effect_s_["guard"]);
    if (auto f = fdm::check_finite(model_)) return node::HealthReport{f->cause, f->detail};
    if (model_.params().mode != fdm::Mode::kDynamic) return std::nullopt;  // static: scaled masses
    if (auto jump = energy_jump_.check(model_.kinetic_energy())) {
      const auto v = model_.velocities();
      const auto m = model_.inertial_masses();
      std::size_t worst = 0;
      double e_worst = -1;
      for (std::size_t g = 0; g < model_.num_gridpoints(); ++g) {
        double e = 0.5 * m[g] * (v[3 * g] * v[3 * g] + v[3 * g + 1] * v[3 * g + 1] + v[3 * g + 2] * v[3 * g + 2]);
        if (e > e_worst) e_worst = e, worst = g;
      }
      const auto g = static_cast<std::int32_t>(worst);
      return node::HealthReport{"continuum " + *jump + "; fastest gridpoint " + std::to_string(g),
                                fdm::describe_gridpoint(model_, g) + "\nzones around it:\n" + fdm::zones_around(model_, g)};
    }
    return std::nullopt;
  }
  void finish() override {
    if (history_) history_->close();
  }

  // Coupling (continuum role).
  proto::InterfaceMesh interface_mesh() override {
    proto::InterfaceMesh m;
    auto ids = model_.interface_gridpoints();
    m.point_ids.assign(ids.begin(), ids.end());
    m.positions = model_.interface_positions();
    auto tri = model_.interface_triangles();
    m.triangles.assign(tri.begin(), tri.end());
    const auto& side = model_.mesh().interface_triangle_side;
    m.wall_of_triangle.assign(side.begin(), side.end());
    m.n_walls = 6;
    return m;
  }
  proto::Kinematics interface_kinematics() override {
    node::Timed t(effect_s_["interface"]);
    proto::Kinematics k;
    k.positions = model_.interface_positions();
    k.velocities = model_.interface_velocities();
    return k;
  }
  void apply_interface_forces(const proto::Forces& f) override {
    node::Timed t(effect_s_["interface"]);
    if (f.forces.size() != 3 * model_.interface_gridpoints().size())
      throw std::runtime_error("interface forces for " + std::to_string(f.forces.size() / 3) + " points, the mesh has " +
                               std::to_string(model_.interface_gridpoints().size()));
    // Action-reaction: the sum we apply must equal the DEM's total to round-off.
    std::array<double, 3> sum{0, 0, 0};
    for (std::size_t i = 0; i < f.forces.size(); ++i) sum[i % 3] += f.forces[i];
    double scale = std::max({std::abs(f.total[0]), std::abs(f.total[1]), std::abs(f.total[2]), 1e-300});
    double imbalance = std::max({std::abs(sum[0] - f.total[0]), std::abs(sum[1] - f.total[1]), std::abs(sum[2] - f.total[2])});
    max_imbalance_ = std::max(max_imbalance_, imbalance / scale);
    coupled_ = true;
    iface_fz_ = sum[2];
    model_.set_interface_forces(f.forces);
    model_.set_interface_stiffness(f.stiffness);
  }

 private:
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
  // Upward force the punch exerts on... the soil pushes back: reaction on the punch gridpoints.
  double punch_force() const { return punch_.empty() ? 0.0 : model_.reaction_sum(punch_)[2]; }

  double weight() const {
    return model_.total_gravitational_mass() * model_.params().gravity_level * fdm::kStandardGravity;
  }

  // Vertical stress profile (Fig. 3): zone stresses averaged per horizontal layer of zones
  // (weighted by zone volume), with the line rho N g depth from the mesh top, rho the density of
  // the first material group. Written to fdm_profile_<stage>.csv.
  void write_profile(const schema::Stage& st) {
    const auto& m = model_.mesh();
    const std::size_t nk = m.grid_z.size() - 1;
    std::vector<double> vol(nk, 0.0), szz(nk, 0.0), sxx(nk, 0.0);
    std::vector<std::size_t> count(nk, 0);
    auto stress = model_.zone_stress();
    for (std::size_t z = 0; z < model_.num_zones(); ++z) {
      auto i = m.zone_ijk[3 * z], j = m.zone_ijk[3 * z + 1], k = m.zone_ijk[3 * z + 2];
      double v = (m.grid_x[i + 1] - m.grid_x[i]) * (m.grid_y[j + 1] - m.grid_y[j]) * (m.grid_z[k + 1] - m.grid_z[k]);
      vol[k] += v;
      szz[k] += v * stress[6 * z + 2];
      sxx[k] += v * stress[6 * z];
      ++count[k];
    }
    const double top = m.grid_z.back(), g = model_.params().gravity_level * fdm::kStandardGravity;
    const double rho = model_.params().materials.front().material.density;
    auto csv = io::CsvSeries::create(fs::path(ctx_.options.run_dir) / ("fdm_profile_" + st.name + ".csv"),
                                     {"depth_m", "szz_Pa", "sxx_Pa", "zones_1", "selfweight_szz_Pa", "rho_kg_m3"});
    for (std::size_t k = nk; k-- > 0;) {
      if (count[k] == 0) continue;
      double d = top - 0.5 * (m.grid_z[k] + m.grid_z[k + 1]);
      csv.append({d, szz[k] / vol[k], sxx[k] / vol[k], static_cast<double>(count[k]), -rho * g * d, rho});
    }
    csv.close();
  }

  void write_frame(std::int64_t step) {
    node::Timed t(effect_s_["output.h5"]);
    auto stress = model_.zone_stress();
    io::MeshFrame f;
    f.node_arrays.push_back({"displacement", io::ArrayView(model_.displacements(), 3)});
    f.node_arrays.push_back({"velocity", io::ArrayView(model_.velocities(), 3)});
    f.zone_arrays.push_back({"stress", io::ArrayView(stress, 6)});
    f.zone_arrays.push_back({"plastic", io::ArrayView(model_.plastic_state())});
    // Frame times must increase strictly: a repeated time (two frames of one step) is skipped.
    if (has_frame_ && model_.time() <= last_frame_time_) return;
    out_->write_frame(step, clock_.frame_time(model_.time()), f);  // model time (docs/output.md)
    has_frame_ = true;
    last_frame_time_ = model_.time();
    last_frame_ = step;
  }

  node::Context ctx_;
  fdm::Model model_;
  std::optional<io::MeshOutput> out_;
  std::optional<io::CsvSeries> history_;
  std::int64_t frame_every_ = 0, history_every_ = 1, last_step_ = -1, last_frame_ = -2;
  bool outputs_open_ = false;
  bool has_frame_ = false;
  double last_frame_time_ = 0;                // continuum (node) time of the last frame
  io::ModelClock clock_;                      // the frames' model time
  std::vector<std::string> stage_prefixes_;   // "stage[i]" of every stage: its scene index
  fdm::Ratios last_ratios_{};
  std::vector<std::int32_t> punch_;
  double punch_velocity_ = 0, punch_disp_ = 0, release_after_ = 0;
  bool released_ = false;
  double max_imbalance_ = 0, iface_fz_ = 0;
  bool coupled_ = false;
  node::EnergyJump energy_jump_;
  std::map<std::string, double> effect_s_;  // [s] wall time of each effect in the current stage
};

}  // namespace

int main(int argc, char** argv) {
  return node::run_node(argc, argv, "continuum", "fdm_node",
                        [](const node::Context& ctx) { return std::make_unique<FdmParticipant>(ctx); });
}
