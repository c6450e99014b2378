// dem_node: the DEM engine (dem_core) as the bus's DEM role.
//
// A thin adapter: scene keys -> dem::WorldParams, stage actions -> the staged operations of
// dem_core (docs/theory.md 4), coupling hooks -> facet walls driven by the continuum's interface
// gridpoints (6.2-6.5), footing kinematics from the coordinator's grants (7.1), results ->
// dem.h5 + particles.xmf + bonds.xmf (+ footing.xmf when a stage places the footing) +
// dem_history.csv in the run folder, frame times in the model time of docs/output.md.
//
// Procedures that converge by themselves (REV generation, servo, UCS test) run inside the
// stage's STAGE_BEGIN with their own budgets from the scene; the stage's grants then only
// cycle. Gravity (if the scene has [gravity]) is switched on by the first stage that is not a
// specimen-generation stage (generate, servo, bond, replicate): a periodic REV has no weight.
#include <mpi.h>
#include <omp.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <sstream>
#include <thread>
#include <tuple>
#include <type_traits>
#include <cstring>
#include <cstdlib>
#include <cstdio>

#include <spdlog/spdlog.h>

#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/dist.hpp"
#include "demfdm/dem/guard.hpp"
#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/scene_params.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"
#include "demfdm/io/csv_series.hpp"
#include "demfdm/io/model_time.hpp"
#include "demfdm/io/results_output.hpp"
#include "common/node/node_runtime.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {

using Block = dem::scene::Block;

// Specimen preparation (the stage-action table, schema::actions()): the periodic REV on its own
// step rule, no gravity, before model time 0.
bool is_generation(const schema::Stage& st) { return schema::action_info(st.kind).preparation; }

// The DEM on MPI ranks (dem.ranks > 1, started by launch/run under mpirun; docs/scaling.md).
// Rank 0 speaks on the bus and tells the other ranks every call it gets (RankedParticipant);
// each rank runs the same adapter. The specimen procedures run on the ranks (the REV's expansion,
// bonding and servo, their REV assembled on rank 0 between them); the replicate stage leaves each
// rank its part of the block (dem::DistDem), and the ranks stay live from there to the run's end:
// the later stages' set-ups (gravity, the footing, the interface), their steps, reports and frames
// run on the parts (ranks_carry), and rank 0 keeps no ball meanwhile (drop_world). A checkpoint
// merges the parts' rows into the state file on rank 0 block by block (DistDem::save_state_file),
// and a resume or branch of the block loads the parts from it (DistDem::load_state_file).
// Rank 0 assembles the whole World (DistDem::unload, sync_full) only for a guard's finding or a
// stage that needs it (a specimen procedure); such a stage is set
// up on it and cut into bricks again at its first step (enter_dist, DistDem::load_from_root). The
// other ranks never hold more than their part. Only rank 0 writes files.
struct Ranks {
  MPI_Comm comm = MPI_COMM_NULL;
  int rank = 0, size = 1;
  bool root_dir = false;  // rank 0 has a run folder (writes results)
  int local = 1;          // ranks of this job on this host
};
Ranks g_ranks;

// The DEM's threads: run.threads; "auto" on ranks shares the host's CPUs among its ranks.
int dem_threads(const config::Scene& s) {
  const int n = schema::run_threads(s);
  if (g_ranks.size > 1 && !s.integer_or_word("run.threads")) return std::max(1, n / g_ranks.local);
  return n;
}

class DemParticipant : public node::Participant {
 public:
  explicit DemParticipant(const node::Context& ctx)
      : ctx_(ctx), s_(ctx_.scene), block_(dem::scene::block(ctx.scene)), world_(world_params()), energy_jump_(ctx.scene) {
    interval_ = s_.has("coupling") ? s_.integer("coupling.interval") : 1;
    spdlog::info("dem: {} OpenMP threads (run.threads)", world_.params().threads);
    user_dt_ = s_.real("dem.dt_fixed");
    escape_margin_ = s_.real("dem.escape_margin") * s_.real("dem.specimen.d_max") * s_.real("dem.specimen.scale");
    kick_ = s_.reals("dem.kick");
    if (!kick_.empty() && kick_.size() != 3) s_.fail("dem.kick", "an empty list or [vx, vy, vz] in m/s", std::to_string(kick_.size()) + " numbers");
    // dem.dt_fixed against the largest critical step a packing of this PSD that holds a ball of
    // the smallest size can have (at --check, before any ball exists; every stage begin checks
    // the real one).
    if (user_dt_ > 0 && s_.string("dem.dt_above_critical") == "error") {
      const double bound = largest_critical_step();
      if (user_dt_ > bound) {
        std::ostringstream os;
        os.precision(6);
        os << "a step <= " << bound << " s, the largest critical step of a packing of this PSD (docs/theory.md "
           << "1.8: the smallest ball with a single contact; more contacts or bonds only lower it)";
        std::ostringstream found;
        found << user_dt_ << " s";
        s_.fail("dem.dt_fixed", os.str(), found.str());
      }
    }
    frame_every_ = s_.integer("dem.output.frame_every");
    history_every_ = s_.integer("dem.output.history_every");
    gravity_level_ = s_.has("gravity") ? s_.real("gravity.level") : 0.0;
    if (!ctx.options.run_dir.empty()) dir_ = ctx.options.run_dir;
    // Whether rank 0 writes results (a call that needs every rank, e.g. the measurements of a
    // history row, is made on every rank when it does).
    outputs_ = g_ranks.size > 1 ? g_ranks.root_dir : !dir_.empty();
    if (g_ranks.size > 1 && s_.integer("dem.ranks") != g_ranks.size)
      s_.fail("dem.ranks", std::to_string(g_ranks.size) + ", the ranks mpirun started",
              std::to_string(s_.integer("dem.ranks")));
    // Frame times (docs/output.md "Time"): the model time of io::ModelClock, 0 at the
    // beginning of the first stage that is not specimen preparation. The footing's surface
    // (footing.xmf) is written when a stage places a footing.
    const auto stages = schema::stages(s_);
    std::vector<bool> preparation;
    for (const auto& st : stages) {
      preparation.push_back(is_generation(st));
      stage_prefixes_.push_back(st.view.prefix());
      footing_output_ = footing_output_ || st.kind == schema::Action::kPenetrate;
    }
    clock_ = io::ModelClock(preparation);
  }

  // Result files only when the scene has [dem.output] (a scene writes only what it asks for),
  // created at the first stage; a resumed run reopens them where its checkpoint left them.
  static std::vector<std::string> history_columns() {
    return {"step_unit", "time_s", "ratio_unit", "kinetic_J", "footing_fz_N", "footing_disp_m", "facet_fz_N"};
  }
  void open_outputs() {
    if (outputs_open_) return;
    outputs_open_ = true;
    if (dir_.empty() || !s_.has("dem.output")) return;
    io::FileInfo info{"dem_node", std::to_string(ctx_.options.run_id), std::to_string(s_.hash()), {}};
    out_.emplace(dir_, info, io::H5StorageParams{}, std::vector<std::string>{"bonds"}, "dem.h5", surface_sets());
    if (clock_.known()) out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
    if (history_every_ > 0) history_.emplace(io::CsvSeries::create(dir_ / "dem_history.csv", history_columns()));
  }
  // specimen_stages.csv: one row per staged operation, for the studies (docs/ucs-study.md), in
  // the bytes its readers and the golden data know (docs/output.md "CSV files": 10 digits, the
  // operation's sentence in a text column). Written whenever the run has a folder.
  static std::vector<std::string> stage_columns() {
    return {"balls_unit", "steps_unit", "ratio_unit", "porosity_unit", "coordination_unit", "coordination_no_rattlers_unit",
            "sxx_Pa", "syy_Pa", "szz_Pa", "converged_unit", "what"};
  }
  static io::CsvFormat stage_format() {
    io::CsvFormat f;
    f.digits = 10;
    f.text_columns = {"what"};
    return f;
  }
  std::vector<std::string> surface_sets() const {
    return footing_output_ ? std::vector<std::string>{"footing"} : std::vector<std::string>{};
  }
  // At the top of every stage_begin, before any step: the model-time origin at the first
  // stage that is not preparation; the frames written before it get their model times.
  void begin_model_time(const schema::Stage& st) {
    const auto at = std::find(stage_prefixes_.begin(), stage_prefixes_.end(), st.view.prefix());
    const auto index = static_cast<std::size_t>(at - stage_prefixes_.begin());
    if (!clock_.stage_begins(index, live().time())) return;
    const auto times = clock_.take_pending_times();
    spdlog::info("dem: model time 0 at stage '{}' (DEM time {} s); {} earlier frames get their model times (<= 0)", st.name,
                 clock_.origin(), times.size());
    if (!out_) return;
    node::Timed t(effect_s_["output.h5"]);
    out_->retime_frames(times);
    out_->h5().set_attribute("/", "model_time_origin", clock_.origin());
  }

  // Checkpoints (docs/checkpoint-format.md): the World in dem.world.state, this adapter's
  // fields and its result writers' positions in the node file's section "dem_node".
  bool can_checkpoint() const override { return true; }
  // The adapter's own fields in that section, after the DEM block, in their order there: one
  // list for save() and restore().
  template <class F>
  void adapter_fields(F&& f) {
    f(has_frame_, last_frame_time_, wall_, n_iface_, coupling_setup_pending_, penetrating_, box_done_, preparing_,
      kicked_, energy_pending_, footing_z0_, target_disp_, weight_, stage_ratio_, user_dt_);
  }
  void save(const fs::path& dir, io::StateWriter& w, const io::StateMeta& meta) override {
    write_history_row();  // (none is due between grants; the checkpoint counts the rows written)
    if (dist_live_ && !synced_) {  // the ranks' parts merged into the file by rank 0, which never holds the block
      const auto t0 = std::chrono::steady_clock::now();
      dist_->save_state_file(world_, dir / "dem.world.state", meta);
      const std::size_t n = num_balls();  // (collective)
      spdlog::info("dem: checkpoint {}: {} balls written from the {} ranks' parts, merged on rank 0 ({:.3f} s)",
                   dir.filename().string(), n, g_ranks.size,
                   std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    } else if (g_ranks.rank == 0)
      dem::save_state_file(world_, dir / "dem.world.state", meta);
    // A balance begun on the ranks: its positions in the checkpoint's form (the saved World's rows,
    // in id order)
    if (ranked_energy_) energy_.x_begin = positions_on_root();
    w.begin("dem_node");
    for (double v : {block_.origin.x, block_.origin.y, block_.origin.z, block_.cell.x, block_.cell.y, block_.cell.z}) w.f64(v);
    for (int n : {block_.nx, block_.ny, block_.nz}) w.i32(n);
    adapter_fields([&](auto&... v) { io::save_fields(w, v...); });
    energy_.save(w);
    energy_jump_.save(w);
    if (ranked_energy_) energy_.x_begin.clear();
    // specimen_stages.csv bytes, then the result writers and the frames' model time.
    w.u64(stages_ ? stages_->bytes() : 0);
    node::OutputCheckpoint{outputs_open_, out_ ? out_->h5().frame_count() : 0, history_ ? history_->bytes() : 0,
                           history_ ? history_->rows() : 0}
        .save(w, clock_.state());
    w.end();
    if (dist_live_) drop_world();  // (the ranks hold the state again)
  }
  void restore(io::StateReader& r, const node::Restore& how) override {
    history_due_ = -1;
    dist_live_ = false;
    dist_.reset();
    const bool was_preparing = preparing_;
    auto sec = r.section("dem_node");
    Block saved;
    saved.origin = {sec.f64(), sec.f64(), sec.f64()};
    saved.cell = {sec.f64(), sec.f64(), sec.f64()};
    saved.nx = sec.i32(), saved.ny = sec.i32(), saved.nz = sec.i32();
    auto same = [](const dem::Vec3& a, const dem::Vec3& b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
    if (!same(saved.origin, block_.origin) || !same(saved.cell, block_.cell) || saved.nx != block_.nx ||
        saved.ny != block_.ny || saved.nz != block_.nz)
      s_.fail("dem.specimen.origin", "the DEM block of the saved state (origin " + fmt::format("({}, {}, {})", saved.origin.x, saved.origin.y, saved.origin.z) +
                                         " m; it follows dem.specimen.cell, replicate, origin and continuum.mesh.size)",
              fmt::format("origin ({}, {}, {}) m", block_.origin.x, block_.origin.y, block_.origin.z));
    adapter_fields([&](auto&... v) { io::load_fields(sec, v...); });
    energy_.load(sec);
    energy_jump_.load(sec);
    // The World. On ranks, the block (not a periodic REV being prepared) is loaded into the ranks'
    // parts without a whole World on any rank (DistDem::load_state_file), and the ranks are live
    // from here on as after the replication; else rank 0 loads the whole World, which the next
    // stage cuts into bricks at its first step (enter_dist). With dem.newton, whose results
    // follow the cuts, the whole World as before.
    const fs::path world_file = how.dir / "dem.world.state";
    bool on_ranks = g_ranks.size > 1 && !s_.boolean("dem.newton");
    std::unique_ptr<dem::StateSource> src;  // (rank 0: the World's file, opened and checked once)
    if (on_ranks && !part_only()) {
      src = std::make_unique<dem::StateSource>(world_file, how.saved_scene_hash);
      src->load_frame(world_);  // (is it the block? and its cell for ranks_grid, its parameters for the ranks)
      on_ranks = !preparing_ || !world_.periodic();
    }
    if (g_ranks.size > 1) {
      int f = on_ranks ? 1 : 0;
      MPI_Bcast(&f, 1, MPI_INT, 0, g_ranks.comm);
      on_ranks = f != 0;
    }
    std::vector<std::uint64_t> ids;  // (rank 0, on ranks: the balls' ids in row order)
    if (!on_ranks && !part_only()) dem::load_state_file(world_, world_file, how.saved_scene_hash);
    // The thread count is the scene's (a branch may change it; a resume has the same).
    auto scene_threads = [&] {
      world_.mutable_params().threads = dem_threads(s_);
      world_.mutable_params().thread_independent = s_.boolean("run.thread_independent");
      world_.mutable_params().order_free_sums = s_.boolean("run.order_free_sums");
    };
    scene_threads();
    if (on_ranks) {
      dist_ = std::make_unique<dem::DistDem>(g_ranks.comm, world_.params(), ranks_grid());
      configure_dist(*dist_);
      {
        node::Timed t(effect_s_["ranks.load"]);
        dist_->load_state(world_, src.get(), world_file.string(), how.saved_scene_hash, part_only() ? nullptr : &ids);
      }
      scene_threads();
      went_live("loaded from the checkpoint into");
    } else {
      world_.keep_force_norms(!was_preparing);
    }
    omp_set_num_threads(world_.params().threads);
    // On ranks the balance goes on from the parts: its positions as records of the saved balls
    // (by id, in row order), which the ranks' gravity_work finds wherever they are.
    ranked_energy_ = g_ranks.size > 1 && !energy_pending_;
    x_begin_.clear();
    if (ranked_energy_ && !part_only()) {
      const auto& row_ids = on_ranks ? ids : world_.balls().id;
      for (std::size_t i = 0; i < row_ids.size() && i < energy_.x_begin.size(); ++i)
        x_begin_.push_back({row_ids[i], energy_.x_begin[i]});
      energy_.x_begin.clear();
    }
    const auto stages_bytes = sec.u64();
    io::ModelClock::State c;
    const auto o = node::OutputCheckpoint::load(sec, c);
    const bool was_open = o.open;
    const auto frames = o.frames, bytes = o.bytes, rows = o.rows;
    sec.done();
    clock_.set_state(c);
    ratio_valid_ = skeleton_valid_ = fc_valid_ = ke_valid_ = false;
    safe_dt_key_ = {-1, -1, -1};
    if (how.branch) {
      // A new run folder: new result files from the branch point on.
      has_frame_ = false;
      last_frame_time_ = 0;
      clock_.forget_pending();
      return;
    }
    // Resume: the result writers continue where the checkpoint left them.
    outputs_open_ = was_open;
    if (was_open && !dir_.empty() && s_.has("dem.output")) {
      out_.emplace(io::ParticleOutput::resume(dir_, io::H5StorageParams{}, std::vector<std::string>{"bonds"}, frames,
                                              "dem.h5", surface_sets()));
      if (history_every_ > 0) history_.emplace(io::CsvSeries::resume(dir_ / "dem_history.csv", history_columns(), bytes, rows));
    }
    // The checkpoint has the bytes of specimen_stages.csv, not its rows: they are counted.
    const auto stages_csv = dir_ / "specimen_stages.csv";
    if (!dir_.empty() && stages_bytes > 0)
      stages_.emplace(io::CsvSeries::resume(stages_csv, stage_columns(), stages_bytes, std::nullopt, stage_format()));
    else if (!dir_.empty())
      fs::remove(stages_csv);  // written after the checkpoint
  }

  // A user dt_fixed (checked against the critical step at every stage begin) is the node's
  // step; else dt_safety x critical. The coordinator grants the smallest dt_stable of the nodes.
  double dt_stable() const override {
    if (!dist_live_ && world_.num_balls() == 0) return 0.0;  // (on the ranks rank 0 answers)
    if (user_dt_ > 0 && !preparing_) return interval_ * user_dt_;
    return interval_ * safe_dt();
  }
  // dt_safety x the critical step of 1.8 [s], computed once per state (O(contacts)).
  double safe_dt() const {
    if (safe_dt_key() != safe_dt_key_) {
      safe_dt_ = dist_live_ ? dist_->safe_step() : world_.contact_scan(true, false).dt;
      safe_dt_key_ = safe_dt_key();
    }
    return safe_dt_;
  }
  std::array<std::int64_t, 3> safe_dt_key() const {
    // (the same on every rank while the ranks step, where the step is a collective: not rank 0's
    // World's count, which a checkpoint fills and empties again)
    return {live().step_count(), live().rebuild_count(), dist_live_ ? -1 : static_cast<std::int64_t>(world_.num_balls())};
  }
  // Upper bound of the critical step of 1.8 [s] for a packing of the scene's PSD (upscaled) that
  // holds a ball of the smallest size (dem::largest_critical_step).
  double largest_critical_step() const {
    const double sc = s_.real("dem.specimen.scale");
    return dem::largest_critical_step(world_.params(), 0.5 * sc * s_.real("dem.specimen.d_min"),
                                      0.5 * sc * s_.real("dem.specimen.d_max"));
  }
  // Critical step of 1.8 without the safety factor [s].
  double critical_dt() const { return safe_dt() / live().params().dt_safety; }
  double time() const override { return live().time(); }

  proto::Values stage_begin(const schema::Stage& st, std::int64_t) override {
    // On ranks the parts carry the state into the stage when its set-up runs on them (they stay
    // live from the replicate stage to the run's end); else the set-up acts on the whole World.
    const bool carry = ranks_carry(st);
    if (!carry) leave_dist();
    // The stage's flags: the scene's, on every rank.
    stage_ratio_ = st.view.real("ratio");
    coupled_stage_ = st.coupled;
    ratio_valid_ = skeleton_valid_ = fc_valid_ = ke_valid_ = false;
    has_ranked_phases_ = false;
    preparing_ = is_generation(st);
    penetrating_ = st.kind == schema::Action::kPenetrate;
    if (penetrating_) target_disp_ = st.view.real("depth_ratio") * s_.real("dem.footing.diameter");
    energy_pending_ = true;  // the stage's energy balance starts at its first step
    stage_params(world_, st);
    if (part_only() && !carry) {
      // Rank 0 sets the stage up on the whole World and sends this rank its part at the first
      // step of a stage on the ranks (enter_dist); the REV's expansion and servo step on every
      // rank, the block is replicated on every rank, and the coupled set-up runs on the ranks
      // when the interface mesh arrives.
      effect_s_.clear();
      if (st.kind == schema::Action::kCouple && st.coupled) coupling_setup_pending_ = true;
      if (st.kind == schema::Action::kGenerate) generate();
      if (st.kind == schema::Action::kServo) servo_on_ranks();
      if (st.kind == schema::Action::kReplicate) replicate_on_ranks();
      if (dist_live_) dist_->prepare();  // (the replicated block, as rank 0 below)
      return {};
    }
    if (!part_only()) {
      open_outputs();
      begin_model_time(st);
    }
    effect_s_.clear();
    world_.reset_phase_times();
    if (carry) {  // the stage's phases and communication from here on
      dist_->world().reset_phase_times();
      dist_->reset_times();
      stage_params(dist_->world(), st);
    }
    if (!preparing_) check_dt_fixed(st);
    if (!preparing_ && gravity_level_ > 0 && !live().gravity_on()) {
      const double level = gravity_level_ * s_.real("gravity.g0") / world_.params().g0;
      if (carry) {
        world_.set_gravity(true, level);  // (rank 0's World: a checkpoint's frame, DistDem::save_state_file)
        dist_->world().set_gravity(true, level);
        spdlog::info("dem: gravity on at {} g, on the ranks' parts", level);
      } else {
        auto r = dem::set_gravity(world_, true, level);
        spdlog::info("dem: {}", r.what);
      }
    }
    if (!preparing_ && !box_done_ && s_.string("dem.specimen.box") == "walls") box_walls();
    proto::Values v;
    switch (st.kind) {
      case schema::Action::kGenerate: v = report(generate()); break;
      case schema::Action::kServo: v = report(g_ranks.size > 1 ? servo_on_ranks() : servo()); break;
      case schema::Action::kBond:
        v = report(dem::install_bonds(world_, -std::numeric_limits<double>::infinity(), dem::scene::bond_gap(s_)));
        break;
      case schema::Action::kReplicate:
        v = report(g_ranks.size > 1 ? replicate_on_ranks() : dem::replicate(world_, replication()));
        break;
      case schema::Action::kCouple:
        if (!st.coupled) throw std::invalid_argument("stage '" + st.name + "': action 'couple' needs coupled = true");
        coupling_setup_pending_ = true;  // done when the interface mesh arrives (set_interface_mesh)
        break;
      case schema::Action::kPenetrate: v = place_footing(); break;
      case schema::Action::kUcs: v = ucs(st); break;
      case schema::Action::kCycle:
      case schema::Action::kEquilibrium: break;
      case schema::Action::kGeostatic:  // the table says the DEM does not act in it (refused at --check)
        throw std::invalid_argument("dem_node does not act in stage action '" + st.action + "'");
    }
    if (!preparing_ && !kick_.empty() && !kicked_) kick(carry);
    if (dist_live_) {
      dist_->prepare();
    } else {
      world_.prepare();
    }
    if (user_dt_ > 0 && !preparing_ && num_balls() > 0) check_dt_fixed("end of the set-up of stage '" + st.name + "'");
    return part_only() ? proto::Values{} : v;
  }
  // Whether the ranks' parts, live since an earlier stage, carry the state into stage `st`: its
  // set-up runs on them (gravity, the DEM-only box, the footing, the interface, the kick; not a
  // specimen procedure of rank 0's World). Rank 0 decides (it knows what its World still
  // needs) and sends its set-up flags with it (the stages it set up alone set them there); every
  // rank calls it.
  bool ranks_carry(const schema::Stage& st) {
    if (!dist_live_) return false;
    int f[3] = {0, box_done_ ? 1 : 0, kicked_ ? 1 : 0};
    if (!part_only()) {
      const bool kind = st.kind == schema::Action::kCouple || st.kind == schema::Action::kPenetrate ||
                        st.kind == schema::Action::kCycle || st.kind == schema::Action::kEquilibrium;
      f[0] = kind ? 1 : 0;
    }
    MPI_Bcast(f, 3, MPI_INT, 0, g_ranks.comm);
    box_done_ = f[1] != 0, kicked_ = f[2] != 0;
    return f[0] != 0;
  }
  // The stage's step factor and local damping (docs/theory.md 1.3, 4.11) on `w`. Specimen
  // preparation has its own, on the automatic step, so that the run's dem.dt_safety,
  // dem.damping and dem.dt_fixed change nothing before the first later stage. The node measures
  // the mean contact force after every step (step_values): the pass keeps the contacts' force
  // norms for it (the same bits as reading the histories again); not in specimen preparation,
  // whose procedures measure seldom.
  void stage_params(dem::World& w, const schema::Stage& st) {
    auto& wp = w.mutable_params();
    const auto alpha = st.view.real_or_word("damping");
    wp.dt_safety = s_.real(preparing_ ? "dem.specimen.dt_safety" : "dem.dt_safety");
    wp.local_damping = alpha ? *alpha : s_.real(preparing_ ? "dem.specimen.damping" : "dem.damping");
    if (preparing_) wp.dt_fixed = 0.0;
    w.keep_force_norms(!preparing_);
    safe_dt_key_ = {-1, -1, -1};  // the cached critical step holds the previous factor
  }
  // The balls of the current state (on ranks while they step: a sum over the ranks, collective).
  std::size_t num_balls() const { return dist_live_ ? dist_->num_balls() : world_.num_balls(); }

  // Blow-up guard (docs/stability.md): non-finite ball state, a ball out of the domain, a
  // kinetic-energy jump.
  std::optional<node::HealthReport> check_health(std::int64_t) override {
    node::Timed t(effect_s_["guard"]);
    if (dist_live_) {
      // Each rank screens its rows in one pass, with the kinetic energy (DistDem::screen: the
      // verdicts travel in its collectives); a finding is reported from the whole World (its
      // neighbourhood and the same words as one process), assembled only then.
      const bool box = escape_margin_ > 0 && !live().periodic();
      dem::Vec3 lo{}, hi{};
      if (box) std::tie(lo, hi) = domain();
      const dem::DistDem::Screen sc = dist_->screen(lo, hi, box);
      ke_ = sc.kinetic;
      ke_valid_ = true;
      if (!sc.finite || (box && sc.outside > escape_margin_)) sync_full();
    }
    if (!dist_live_ || synced_) {
      // One pass over the balls for the finite test, the escape distance and the kinetic energy
      // (dem::screen_balls); the reports only on a finding.
      const bool box = escape_margin_ > 0 && !world_.periodic();
      dem::Vec3 lo{}, hi{};
      if (box) std::tie(lo, hi) = domain();
      const dem::BallScreen sc = dem::screen_balls(world_, lo, hi, box, screen_scratch_);
      if (!dist_live_ && !ke_valid_) {
        ke_ = sc.kinetic;
        ke_valid_ = true;
      }
      if (!sc.finite)
        if (auto f = dem::check_finite(world_)) return node::HealthReport{f->cause, f->detail};
      if (box && sc.outside > escape_margin_)
        if (auto f = dem::check_escape(world_, lo, hi, escape_margin_)) return node::HealthReport{f->cause, f->detail};
    }
    const double ke = kinetic_energy();
    // On the ranks rank 0's test decides (the other ranks' has not seen the specimen stages,
    // which rank 0 runs alone), and the World for its report is assembled there.
    std::optional<std::string> jump;
    if (!part_only()) jump = energy_jump_.check(ke);
    if (dist_live_) {
      int found = jump ? 1 : 0;
      MPI_Bcast(&found, 1, MPI_INT, 0, g_ranks.comm);
      if (found) sync_full();
    }
    if (jump) {
      sync_full();
      const auto f = dem::energy_jump_finding(world_, *jump);
      return node::HealthReport{f.cause, f.detail};
    }
    return std::nullopt;
  }

  // The first DEM step's motion needs no interface data (the facets' vertices only enter its
  // rebuild decision and force pass): on one rank it runs here, while the continuum steps
  // (World::step = step_motion, then step_forces; the same calls in the same order).
  void advance_early(const schema::Stage& st, std::int64_t step, double dt, const std::vector<double>& values) override {
    early_step_ = -1;
    if (g_ranks.size > 1 || world_.num_balls() == 0) return;
    begin_step(st, values, dt);  // (one rank: never on a DistDem)
    early_node_before_ = world_.time();
    world_.step_motion();
    early_step_ = step;
  }

  void advance(const schema::Stage& st, std::int64_t step, double dt, const std::vector<double>& values) override {
    if (early_step_ == step) {
      early_step_ = -1;
      const double node_before = early_node_before_;
      world_.step_forces_now();
      world_.step(interval_ - 1);
      end_step(step, dt, node_before);
      return;
    }
    early_step_ = -1;
    if (part_only() && is_generation(st) && !dist_live_) return;  // rank 0 steps the whole World
    begin_step(st, values, dt);
    dem::World& w = live();
    const double node_before = w.time();
    if (dist_live_) {
      dist_->step(interval_);
    } else {
      world_.step(interval_);  // its phases are reported by add_phase_times()
    }
    end_step(step, dt, node_before);
  }

  // What a coupling step does before its DEM steps.
  void begin_step(const schema::Stage& st, const std::vector<double>& values, double dt) {
    if (!dist_live_ && !part_only() && world_.num_balls() == 0)
      throw std::runtime_error("no particles: the scene's stages generate none before cycling");
    ratio_valid_ = skeleton_valid_ = fc_valid_ = ke_valid_ = false;
    if (energy_pending_) {
      // Energy balance of the stage (docs/stability.md) from the state before its first step,
      // after every set-up (interface bonds and depth scaling are installed after STAGE_BEGIN),
      // kept by rank 0. While the ranks step, from their parts: each keeps its balls' positions
      // (DistDem::owned_positions, for gravity's work).
      energy_pending_ = false;
      ranked_energy_ = dist_live_;
      if (ranked_energy_) {
        energy_.begin_with(dist_->energy());
        x_begin_ = dist_->owned_positions();
      } else if (!part_only()) {
        energy_.begin(world_);
      }
    }
    enter_dist();
    dem::World& w = live();
    if (penetrating_) {
      if (values.empty()) throw std::runtime_error("penetrate: the coordinator sent no footing speed");
      w.set_footing_velocity({0.0, 0.0, -values[0]});
    }
    // A user dt_fixed must stay below the critical step as contacts change (O(contacts) per
    // step, only when dem.dt_fixed is set).
    if (user_dt_ > 0 && !preparing_ && user_dt_ > critical_dt()) check_dt_fixed("a step of stage '" + st.name + "'");
    // Exactly 'interval' DEM steps per coupling step of length dt.
    if (dt > 0) w.mutable_params().dt_fixed = dt / static_cast<double>(interval_);
    synced_ = false;
  }

  // What a coupling step does after its DEM steps.
  void end_step(std::int64_t step, double dt, double node_before) {
    dem::World& w = live();
    clock_.advanced(node_before, dt, w.time());
    energy_.add_work(w, interval_);
    // The history row of this step is written by step_values, after the forces have gone out
    // (its ratio needs the contact scan; the continuum steps meanwhile).
    if (outputs_ && s_.has("dem.output") && history_every_ > 0 && step % history_every_ == 0) history_due_ = step;
    if (outputs_ && s_.has("dem.output") && frame_every_ > 0 && step % frame_every_ == 0) write_frame(step);
  }

  // The history row of the last step, if it is due (advance): the state is still that step's
  // (the guard and the interface forces only read it). A row's measurements need every rank:
  // made wherever rank 0 writes one.
  void write_history_row() {
    if (history_due_ < 0) return;
    const std::int64_t step = history_due_;
    history_due_ = -1;
    node::Timed t(effect_s_["output.history"]);
    const dem::World& w = live();
    auto fz = w.has_footing() ? w.footing_reaction().z : 0.0;
    auto facet = w.num_facet_walls() > 0 ? w.facet_walls_total_force().z : 0.0;
    const std::vector<double> row{static_cast<double>(step), w.time(), ratio(), kinetic_energy(), fz, footing_disp(), facet};
    if (history_) history_->append(row);
  }

  proto::Values step_values() override {
    write_history_row();
    node::Timed t(effect_s_["measurements"]);
    // In a coupled stage the continuum steps meanwhile (the forces went out first): on one
    // thread the measurements leave it the other cores. Their bits do not depend on the thread
    // count (ordered sums, tests/dem/contact_scan_test.cpp).
    const int threads = world_.params().threads;
    if (coupled_stage_ && !dist_live_) world_.mutable_params().threads = 1;
    struct Restore {
      dem::World& w;
      int n;
      ~Restore() { w.mutable_params().threads = n; }
    } restore{world_, threads};
    // The report of this step needs both O(contacts) measurements of the state (the ratios'
    // mean contact force and, for dt_stable, the critical step): one pass over the contacts.
    if (!dist_live_ && !fc_valid_ && safe_dt_key() != safe_dt_key_ && world_.num_balls() > 0) {
      const auto scan = world_.contact_scan(true, true);
      safe_dt_ = scan.dt;
      safe_dt_key_ = safe_dt_key();
      fc_ = scan.fc;
      fc_valid_ = true;
    }
    proto::Values v{{"ratio", ratio()}, {"dt_s", live().dt()}, {"dt_critical_s", critical_dt()}};
    if (live().gravity_on()) {
      auto sk = skeleton();
      v.push_back({"ratio_skeleton", sk.ratio});
      v.push_back({"rattlers", static_cast<double>(sk.rattlers)});
      v.push_back({"weight_N", weight()});
    }
    if (live().has_footing()) {
      v.push_back({"footing_fz_N", live().footing_reaction().z});
      v.push_back({"footing_disp_m", footing_disp()});
      // Ball-ball bonds that have left the intact state so far (a cumulative count of the contact
      // pass, O(1) here): the end of the footing's elastic branch (k_e, docs/paper-study.md).
      v.push_back({"bond_failures", static_cast<double>(dist_live_ ? dist_->bond_failures() : world_.bond_failures())});
    }
    return v;
  }
  bool criterion_met(const schema::Stage& st) override {
    if (penetrating_) return footing_disp() >= target_disp_ * (1 - 1e-12);
    if (st.kind == schema::Action::kCycle) return false;
    return (live().gravity_on() ? skeleton().ratio : ratio()) < stage_ratio_;
  }
  proto::Values stage_end(const schema::Stage& st, std::int64_t last) override {
    write_history_row();
    if (outputs_) write_frame(last);  // (on ranks: from the ranks' parts)
    // On ranks that stay live the report comes from the parts (every rank takes part in its
    // collectives); else from the whole World, on rank 0.
    const bool ranked = dist_live_;
    if (ranked) {
      account_ranks();
    } else {
      leave_dist();  // (nothing steps on the ranks)
    }
    // On the ranks: the largest peak memory of the ranks other than 0 (rank 0's is the node's,
    // "peak_rss_mb"), for the summary.
    double others = 0.0;
    if (g_ranks.size > 1) {
      const double mine = part_only() ? node::process_peak_rss_mb() : 0.0;
      MPI_Reduce(&mine, &others, 1, MPI_DOUBLE, MPI_MAX, 0, g_ranks.comm);
    }
    if (part_only() && !ranked) return {};
    const dem::World& w = live();
    if (outputs_ && s_.has("dem.output") && w.gravity_on() && !is_generation(st)) write_profile(st);
    const std::size_t balls = num_balls();
    const double crit = balls > 0 ? critical_dt() : 0.0;
    double ratio = 0.0;
    dem::Coordination coord;
    dem::BondCounts bonds;
    if (ranked) {  // measure()'s values, one World's bits (tests/dist)
      ratio = balls > 0 ? dist_->unbalanced_ratio(dist_->mean_contact_force()) : 0.0;
      coord = dist_->coordination();
      bonds = dist_->bond_counts();
    } else {
      const auto m = dem::measure(world_);
      ratio = m.ratio, coord = m.coord, bonds = m.bonds;
    }
    std::optional<dem::StageEnergy::Balance> b;
    if (!is_generation(st) && !energy_pending_) b = energy_balance();
    if (part_only()) return {};
    proto::Values v{{"balls", static_cast<double>(balls)},
                    {"ratio", ratio},
                    {"coordination", coord.z},
                    {"bonds_intact", static_cast<double>(bonds.intact)},
                    {"bonds_softening", static_cast<double>(bonds.softening)},
                    {"bonds_broken_tension", static_cast<double>(bonds.broken_tension)},
                    {"bonds_broken_shear", static_cast<double>(bonds.broken_shear)}};
    if (w.num_facet_walls() > 0) v.push_back({"facet_fz_N", w.facet_walls_total_force().z});
    v.push_back({"dt_s", w.dt()});
    v.push_back({"dt_critical_s", crit});
    if (b) {
      v.push_back({"energy_kinetic_J", b->kinetic});
      v.push_back({"energy_strain_J", b->strain});
      v.push_back({"energy_dissipated_J", b->dissipated});
      v.push_back({"energy_work_J", b->work});
      v.push_back({"energy_balance_error", b->error});
    }
    add_phase_times();
    for (auto& [name, sec] : effect_s_) v.push_back({"effect_s." + name, sec});
    if (g_ranks.size > 1) v.push_back({"peak_rss_mb_other_ranks", others});
    spdlog::info("dem: stage '{}' ends: {} balls, ratio {:.3e}, Z {:.3f}, bonds intact {} softening {} broken T {} S {}{}",
                 st.name, balls, ratio, coord.z, bonds.intact, bonds.softening, bonds.broken_tension,
                 bonds.broken_shear, ranked ? " (the ranks stay live)" : "");
    return v;
  }
  // The stage's energy balance (docs/stability.md) now: from the ranks' parts when it began there,
  // else from the whole World (assembled on rank 0 for it while the ranks step). Every rank calls
  // it while they step; rank 0's value counts.
  dem::StageEnergy::Balance energy_balance() {
    if (ranked_energy_ && dist_live_) return energy_.balance_with(dist_->energy(), dist_->gravity_work(x_begin_));
    sync_full();
    if (part_only()) return {};
    return energy_.balance(world_);
  }
  void finish() override {
    // A row still due (a run stopped between the step and its report, e.g. by the guard); not
    // on ranks, where its measurements would wait on ranks that may have stopped.
    if (!dist_live_) write_history_row();
    if (history_) history_->close();
    if (stages_) stages_->close();
  }

  // Coupling (DEM role).
  void set_interface_mesh(const proto::InterfaceMesh& m) override {
    ratio_valid_ = skeleton_valid_ = fc_valid_ = ke_valid_ = false;
    interface_setup(m);  // (on ranks: every rank)
  }
  // The interface wall and, in the couple stage, its set-up (docs/theory.md 4.9): the ball-facet
  // contacts found and bonded, the depth scaling, the interface bonds' forces from the block's
  // weight. On ranks rank 0's World gets the wall (every rank learns its index), and so does every
  // part when the ranks already step; the set-up runs on the ranks (docs/scaling.md, "the
  // specimen procedures and the coupled set-up on the ranks"), the World cut into bricks first
  // unless they step (enter_dist), each step on the ranks giving one World's bits.
  void interface_setup(const proto::InterfaceMesh& m) {
    const bool ranked = g_ranks.size > 1;
    // (rank 0's World gets the wall too while the ranks step: it is a checkpoint's frame, and the
    // parts' walls are copied into it)
    if (!part_only()) wall_ = world_.add_facet_wall(m.positions, m.triangles);
    if (ranked) MPI_Bcast(&wall_, 1, MPI_INT, 0, g_ranks.comm);
    if (dist_live_ && dist_->world().add_facet_wall(m.positions, m.triangles) != wall_)
      throw std::logic_error("dem: the interface wall's index differs between rank 0's World and the ranks' parts");
    n_iface_ = m.n_points();
    spdlog::info("dem: interface wall of {} points, {} triangles", m.n_points(), m.triangles.size() / 3);
    if (!coupling_setup_pending_) return;
    coupling_setup_pending_ = false;
    if (ranked) enter_dist();
    auto prepare = [&] { ranked ? dist_->prepare() : world_.prepare(); };
    const double gap = 1e-3 * s_.real("dem.specimen.d_min") * s_.real("dem.specimen.scale");
    prepare();  // detect the ball-facet contacts before bonding them
    const std::size_t nb = ranked ? dem::bond_ball_facet(*dist_, gap) : world_.bond_ball_facet(gap);
    spdlog::info("dem: {} ball-facet bonds installed", nb);
    scale_with_depth();
    if (ranked) weight_ = dist_->ball_weight();  // (weight(): one World's bits)
    const auto ib = dem::scene::interface_bonds(s_, block_, weight() / (block_.cell.x * block_.nx * block_.cell.y * block_.ny * block_.height()));
    spdlog::info("dem: {}", (ranked ? dem::assign_interface_bond_forces(*dist_, ib) : dem::assign_interface_bond_forces(world_, ib)).what);
    prepare();
    if (ranked) {
      synced_ = false;
      ratio_valid_ = skeleton_valid_ = fc_valid_ = ke_valid_ = false;
      safe_dt_key_ = {-1, -1, -1};
    }
  }
  void set_interface_kinematics(const proto::Kinematics& k) override {
    node::Timed t(effect_s_["coupling"]);
    if (wall_ < 0) throw std::runtime_error("interface kinematics before the interface mesh");
    if (part_only() && !dist_live_) return;  // rank 0's whole World takes them into the parts
    live().set_vertex_kinematics(wall_, k.positions, k.velocities);
  }
  proto::Forces interface_forces() override {
    node::Timed timed(effect_s_["coupling"]);
    proto::Forces f;
    // the walls' sums: those of the whole World on every rank (DistDem::step)
    auto vf = live().vertex_forces(wall_);
    auto vk = live().vertex_stiffness(wall_);
    f.forces.assign(vf.begin(), vf.end());
    f.stiffness.assign(vk.begin(), vk.end());
    auto t = live().facet_wall_force(wall_);
    f.total = {t.x, t.y, t.z};
    return f;
  }

 private:
  // A rank other than 0 of the DEM on ranks: it holds only its part of the World, while the ranks
  // step; rank 0 holds the whole World, sets the stages up, measures them and writes.
  static bool part_only() { return g_ranks.size > 1 && g_ranks.rank != 0; }
  // The World that steps: a rank's brick while the ranks step, else the whole World.
  dem::World& live() { return dist_live_ ? dist_->world() : world_; }
  const dem::World& live() const { return dist_live_ ? dist_->world() : world_; }
  // The kinetic energy of the current state, computed once per state (the history row and the
  // guard both read it; on ranks it is a gather).
  double kinetic_energy() {
    if (!ke_valid_) {
      ke_ = dist_live_ ? dist_->kinetic_energy() : world_.kinetic_energy();
      ke_valid_ = true;
    }
    return ke_;
  }
  // At the first step of a stage that is not specimen preparation, on more than one rank: the
  // whole World, set up, cut into bricks (dem.decomposition: RCB, or slabs across the block's
  // longest axis).
  void enter_dist() {
    if (g_ranks.size <= 1 || dist_live_ || preparing_) return;
    dist_ = std::make_unique<dem::DistDem>(g_ranks.comm, world_.params(), ranks_grid());
    configure_dist(*dist_);
    {
      node::Timed t(effect_s_["ranks.load"]);
      dist_->load_from_root(world_);  // the other ranks hold only their part
    }
    went_live("cut into");
  }
  // The bricks of rank 0's World: its periodic cell, or the block; with rank 0's step (the other
  // ranks did not set the stages up). Collective.
  dem::BrickGrid ranks_grid() {
    double c[8] = {world_.periodic() ? 1.0 : 0.0, world_.cell_origin().x, world_.cell_origin().y, world_.cell_origin().z,
                   world_.cell_length().x, world_.cell_length().y, world_.cell_length().z, user_dt_};
    MPI_Bcast(c, 8, MPI_DOUBLE, 0, g_ranks.comm);
    user_dt_ = c[7];
    return c[0] != 0.0 ? block_grid({c[1], c[2], c[3]}, {c[4], c[5], c[6]}, true)
                       : block_grid(block_.origin, {block_.width_x(), block_.width_y(), block_.height()}, false);
  }
  // The scene's options of the ranks' steps (dem.newton, dem.balance_every), before a load.
  void configure_dist(dem::DistDem& d) const {
    d.set_newton(s_.boolean("dem.newton"));
    // (auto: measured time, but contacts with newton on, whose results follow the cuts)
    const std::string weight = s_.string("dem.balance_weight");
    const bool by_time = weight == "time" || (weight == "auto" && !s_.boolean("dem.newton"));
    const std::vector<std::int64_t> k = s_.integers("dem.balance_costs");  // (six, checked by the schema)
    d.set_balance({static_cast<int>(s_.integer("dem.balance_every")), 2048,
                   by_time ? dem::DistDem::Weight::kTime : dem::DistDem::Weight::kContacts,
                   dem::ContactCost{k[0], k[1], k[2], k[3], k[4], k[5]}});
  }
  // The ranks' DistDem `dist_` holds the state from here on, and rank 0 drops its World's balls
  // (the state is the ranks'; a stage that needs the whole World assembles it again, sync_full;
  // a checkpoint merges the parts' rows into its file, DistDem::save_state_file).
  void went_live(const char* how) {
    drop_world();
    const dem::BrickGrid& g = dist_->grid();
    // The pass keeps its force norms for the measurements' mean contact force, as world_ does
    // (the same bits as the scan's, tests/dem/contact_scan_test.cpp).
    dist_->world().keep_force_norms(!preparing_);
    // (the cuts as the load left them: balanced by contacts when dem.balance_every > 0)
    spdlog::info("dem: the block {} {} bricks ({}){}{}", how, g_ranks.size,
                 g.parts > 0 ? "recursive coordinate bisection" : "slabs", describe_cuts(dist_->grid()),
                 s_.boolean("dem.newton") ? "; newton on: each pair across two bricks computed once" : "");
    dist_live_ = true;
    synced_ = false;
    safe_dt_key_ = {-1, -1, -1};
  }
  // The stage's begin positions in the saved World's row order (ball id), from the ranks'
  // records; empty on the other ranks. Collective.
  std::vector<dem::Vec3> positions_on_root() {
    std::vector<dem::DistDem::IdPos> all = dem::gather_on_root(g_ranks.comm, x_begin_);
    std::vector<dem::Vec3> out;
    if (part_only()) return out;
    std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.id < b.id; });
    for (const auto& b : all) out.push_back(b.x);
    return out;
  }
  // Rank 0's World without its balls and contacts (its walls, effects and counters kept): the
  // memory of the whole block is the ranks', not rank 0's, while they step.
  void drop_world() {
    synced_ = false;  // (on every rank: sync_full is a collective)
    if (part_only() || world_.num_balls() == 0) return;
    world_.drop_balls();
  }
  // The bricks of a block [lo, lo + len) on the ranks (dem.decomposition: RCB, or slabs across
  // its longest axis).
  dem::BrickGrid block_grid(const dem::Vec3& lo, const dem::Vec3& len, bool periodic) const {
    dem::BrickGrid g;
    g.lo = lo;
    g.len = len;
    g.periodic[0] = g.periodic[1] = g.periodic[2] = periodic;
    if (s_.string("dem.decomposition") == "rcb") {
      g.set_rcb(g_ranks.size);
    } else {
      int axis = 0;
      for (int k = 1; k < 3; ++k)
        if (g.len[k] > g.len[axis]) axis = k;
      g.n[axis] = g_ranks.size;
    }
    return g;
  }
  // The ranks' state into world_ on rank 0 (a guard finding, a stage that needs the whole World).
  void sync_full() {
    if (!dist_live_ || synced_) return;
    node::Timed t(effect_s_["ranks.unload"]);
    dist_->unload(world_, true);  // on rank 0, which writes and sets the next stage up
    spdlog::info("dem: the ranks' parts assembled into rank 0's World ({} balls)", world_.num_balls());
    synced_ = true;
  }
  // The cuts of an RCB tree, each as its axis and its place along the block (a fraction), for a
  // log line; empty for slabs or more than 16 bricks.
  static std::string describe_cuts(const dem::BrickGrid& g) {
    if (g.parts == 0 || g.parts > 16) return "";
    std::string out = "; cuts";
    for (const auto& c : g.rcb) out += fmt::format(" {} at {:.3f}", "xyz"[c.axis], c.at / g.len[c.axis]);
    return out;
  }
  // The end of the ranks' steps: world_ is the state from here on.
  void leave_dist() {
    if (!dist_live_) return;
    sync_full();
    account_ranks();
    dist_live_ = false;
    dist_.reset();
    safe_dt_key_ = {-1, -1, -1};
  }
  // The stage's rebalances, the ranks' communication as effects and the phases of this rank's
  // part (at a stage's end, whether the ranks stay live or not).
  void account_ranks() {
    if (dist_->rebalances() > 0)
      spdlog::info("dem: {} rebalances of the ranks' cuts in the stage ({} exchanges){}", dist_->rebalances(),
                   dist_->exchanges(), describe_cuts(dist_->grid()));
    const auto& t = dist_->times();  // the ranks' communication, as effects of the stage
    effect_s_["ranks.forward"] += t.forward;
    effect_s_["ranks.reduce"] += t.reduce;
    effect_s_["ranks.exchange"] += t.exchange;
    effect_s_["ranks.walls"] += t.walls;
    if (dist_->newton()) effect_s_["ranks.reverse"] += t.reverse;
    ranked_phases_ = dist_->world().phase_times();
    has_ranked_phases_ = true;
  }

  dem::WorldParams world_params() {
    dem::WorldParams p = dem::scene::world(s_, block_);
    p.threads = dem_threads(s_);
    omp_set_num_threads(p.threads);
    return p;
  }

  // dem.dt_fixed above the critical step (1.8, without dt_safety): refused, or reduced to
  // dt_safety x critical when dem.dt_above_critical = "reduce".
  void check_dt_fixed(const schema::Stage& st) {
    if (user_dt_ <= 0 || num_balls() == 0) return;
    if (dist_live_) {  // contacts of the current state
      dist_->prepare();
    } else {
      world_.prepare();
    }
    check_dt_fixed("begin of stage '" + st.name + "'");
  }
  void check_dt_fixed(const std::string& when) {
    const double crit = critical_dt();
    if (user_dt_ <= crit) {
      world_.mutable_params().dt_fixed = user_dt_;
      live().mutable_params().dt_fixed = user_dt_;
      return;
    }
    const double safe = live().params().dt_safety * crit;
    std::ostringstream os;
    os.precision(6);
    os << "dem.dt_fixed = " << user_dt_ << " s exceeds the critical timestep " << crit << " s (docs/theory.md 1.8) at the "
       << when;
    if (s_.string("dem.dt_above_critical") != "reduce")
      throw std::invalid_argument(os.str() + "; use a smaller dt_fixed, or dem.dt_above_critical = \"reduce\"");
    spdlog::warn("dem: {}; reduced to dt_safety x critical = {} s (dem.dt_above_critical = \"reduce\")", os.str(), safe);
    user_dt_ = safe;
    world_.mutable_params().dt_fixed = safe;
    live().mutable_params().dt_fixed = safe;
  }

  // The engine's phase times of the stage (its set-up procedures included) as effects: only
  // the phases present in this world (no wall, facet or footing pass without one).
  void add_phase_times() {
    const auto& t = has_ranked_phases_ ? ranked_phases_ : world_.phase_times();  // a rank's own, on ranks
    if (t.steps == 0) return;
    effect_s_["neighbour"] = t.rebuild;
    effect_s_[std::string("contacts.ball_ball.") + t.pair_model] = t.pair;
    effect_s_["motion_damping"] = t.motion;
    effect_s_["gather"] = t.gather;
    if (live().num_planes() > 0) effect_s_["walls"] = t.plane;
    if (live().num_facet_walls() > 0) effect_s_["facets"] = t.facet;
    if (live().has_footing() || t.footing > 0) effect_s_["footing"] = t.footing;
    for (auto& [name, sec] : t.effect) effect_s_[name] = sec;
  }

  // Box the balls must stay in: the continuum's pocket if coupled, else the DEM block.
  std::pair<dem::Vec3, dem::Vec3> domain() const {
    dem::Vec3 lo = block_.origin;
    dem::Vec3 hi{lo.x + block_.width_x(), lo.y + block_.width_y(), block_.z_top()};
    return {lo, hi};
  }

  // dem.kick: the highest ball gets the given velocity (stability studies); on the ranks' parts
  // when they carry the stage (every rank calls it then), else on the whole World.
  void kick(bool carry) {
    kicked_ = true;
    if (carry) {
      const dem::Kicked k = dem::kick_highest_ball(*dist_, {kick_[0], kick_[1], kick_[2]});
      spdlog::info("dem: kick: ball id {} at ({}, {}, {}) gets velocity ({}, {}, {}) m/s, on the ranks' parts", k.id, k.x.x,
                   k.x.y, k.x.z, kick_[0], kick_[1], kick_[2]);
      return;
    }
    if (world_.num_balls() == 0) return;
    const std::size_t top = dem::kick_highest_ball(world_, {kick_[0], kick_[1], kick_[2]});
    const auto& b = world_.balls();
    spdlog::info("dem: kick: ball id {} at ({}, {}, {}) gets velocity ({}, {}, {}) m/s", b.id[top], b.x[top].x,
                 b.x[top].y, b.x[top].z, kick_[0], kick_[1], kick_[2]);
  }

  // Contact and bond forces scaled with depth below the block top (docs/theory.md 4.9), on the
  // ranks' parts while they step (every rank calls it then), else on the whole World.
  void scale_with_depth() {
    dem::DepthScaleParams p;
    if (!dem::scene::depth_scaling(s_, block_, p)) return;
    spdlog::info("dem: {}", (dist_live_ ? dem::depth_scale(*dist_, p) : dem::depth_scale(world_, p)).what);
  }

  // DEM-only box (dem.specimen.box = "walls"): planes on the bottom and the four sides of the
  // replicated block, normals pointing inwards, then the depth scaling of the coupled set-up.
  // While the ranks step, on their parts (the box from every rank's balls, one World's planes)
  // and on rank 0's World, whose walls a checkpoint takes from the parts; every rank
  // calls it then.
  void box_walls() {
    box_done_ = true;
    if (dist_live_) {
      const auto [lo, hi] = dem::add_box_walls(*dist_);
      if (!part_only()) dem::add_box_planes(world_, lo, hi);
      spdlog::info("dem: DEM-only box: 5 walls around the {} x {} m block (bottom at z = {} m), on the ranks' parts",
                   hi.x - lo.x, hi.y - lo.y, lo.z);
      dist_->prepare();
      scale_with_depth();
      dist_->prepare();
      return;
    }
    const auto [lo, hi] = dem::add_box_walls(world_);
    spdlog::info("dem: DEM-only box: 5 walls around the {} x {} m block (bottom at z = {} m)", hi.x - lo.x, hi.y - lo.y,
                 lo.z);
    world_.prepare();
    scale_with_depth();
    world_.prepare();
  }

  // The generate stage: the REV, then bonds over the gaps that give Table 1's Z (docs/ucs-study.md),
  // at least 1e-3 d_min apart. On ranks the REV's radius expansion and its bonding run on every
  // rank (every rank calls this; the REV is assembled on rank 0).
  dem::StageReport generate() {
    const double z = s_.real_or_word("dem.specimen.bond_coordination").value_or(0.0);
    const double gap_floor = 1e-3 * s_.real("dem.specimen.d_min") * s_.real("dem.specimen.scale");
    if (g_ranks.size <= 1) return dem::generate_specimen(world_, dem::scene::rev(s_), z, gap_floor);
    dem::DistDem d(g_ranks.comm, world_.params(), rev_grid());
    dem::StageReport r = dem::generate_rev(d, world_, dem::scene::rev(s_));
    spdlog::info("dem: the REV's radius expansion ran on {} ranks ({} exchanges)", g_ranks.size, d.exchanges());
    if (z > 0) {  // the bonds on the ranks too, the bonded REV assembled on rank 0 again
      dem::bond_specimen(d, r, z, gap_floor);
      node::Timed t(effect_s_["ranks.unload"]);
      d.unload(world_, true);
    }
    return r;
  }
  // The bricks of the REV's periodic cell on the ranks (RCB), from rank 0's cell.
  dem::BrickGrid rev_grid() {
    double c[6] = {world_.cell_origin().x, world_.cell_origin().y, world_.cell_origin().z,
                   world_.cell_length().x, world_.cell_length().y, world_.cell_length().z};
    MPI_Bcast(c, 6, MPI_DOUBLE, 0, g_ranks.comm);
    dem::BrickGrid g;
    g.lo = {c[0], c[1], c[2]};
    g.len = {c[3], c[4], c[5]};
    g.periodic[0] = g.periodic[1] = g.periodic[2] = true;
    g.set_rcb(g_ranks.size);
    return g;
  }

  // Hold the servo's criterion for 160 critical steps (docs/theory.md 4.11; 200 steps at dt_safety 0.8).
  static constexpr double kServoHold = 160.0;
  dem::StageReport servo() {
    const auto sv = dem::scene::servo(s_, block_);
    return dem::servo_specimen(world_, sv.p, sv.tol, sv.ratio, kServoHold, sv.budget, sv.fric);
  }
  // The REV's servo on the ranks (docs/scaling.md, "the REV's expansion and servo on the ranks"):
  // rank 0's REV cut by RCB over its periodic cell (rev_grid) and sent to the ranks, the servo run
  // by every rank (one World's steps, report and specimen, bit for bit), the REV assembled on
  // rank 0 again, which sets the next stages up. Every rank calls it; the report is rank 0's.
  dem::StageReport servo_on_ranks() {
    dem::DistDem d(g_ranks.comm, world_.params(), rev_grid());
    {
      node::Timed t(effect_s_["ranks.load"]);
      d.load_from_root(world_);
    }
    const auto sv = dem::scene::servo(s_, block_);
    dem::StageReport r = dem::servo_specimen(d, sv.p, sv.tol, sv.ratio, kServoHold, sv.budget, sv.fric);
    {
      node::Timed t(effect_s_["ranks.unload"]);
      d.unload(world_, true);
    }
    spdlog::info("dem: the REV's servo ran on {} ranks ({} exchanges)", g_ranks.size, d.exchanges());
    return r;
  }

  // The replicate stage's copies of the REV (docs/theory.md 4.7): the block's, its faces free.
  dem::ReplicateParams replication() const {
    dem::ReplicateParams p;
    p.nx = block_.nx;
    p.ny = block_.ny;
    p.nz = block_.nz;
    p.keep_periodic = false;
    p.spatial_order = s_.boolean("dem.spatial_order");
    return p;
  }
  // The replicate stage on the ranks (docs/scaling.md, "the specimen procedures and the coupled
  // set-up on the ranks"): rank 0's REV sent to every rank, each rank building only its part of
  // the block (dem::replicate on a DistDem, one World's bits), cut as the later stages cut the
  // block; the block is then assembled on rank 0, which sets the next stages up. Every rank calls
  // it; the report is rank 0's.
  // The ranks' DistDem of the block stays live from here on (dist_): its steps, the later stages'
  // set-ups and their reports run on the parts (ranks_carry); rank 0 keeps no ball.
  dem::StageReport replicate_on_ranks() {
    double c[6] = {world_.cell_origin().x, world_.cell_origin().y, world_.cell_origin().z,
                   world_.cell_length().x, world_.cell_length().y, world_.cell_length().z};
    MPI_Bcast(c, 6, MPI_DOUBLE, 0, g_ranks.comm);
    const dem::ReplicateParams p = replication();
    auto d = std::make_unique<dem::DistDem>(g_ranks.comm, world_.params(),
                                            block_grid({c[0], c[1], c[2]}, {p.nx * c[3], p.ny * c[4], p.nz * c[5]}, false));
    // (dem.newton: the replication lists its pairs as newton off does; the block is assembled on
    // rank 0 and cut again at the first later step, enter_dist)
    const bool newton = s_.boolean("dem.newton");
    if (!newton) configure_dist(*d);
    dem::StageReport r;
    {
      node::Timed t(effect_s_["ranks.load"]);
      r = dem::replicate(*d, world_, p);
    }
    if (newton) {
      node::Timed t(effect_s_["ranks.unload"]);
      d->unload(world_, true);
      return r;
    }
    dist_ = std::move(d);
    // (rank 0's World, the REV's, takes the block's open faces, as an assembly would give it)
    world_.mutable_params().periodic = dist_->world().params().periodic;
    rep_coord_ = dist_->coordination();  // (specimen_stages.csv's, rank 0's report)
    rep_balls_ = dist_->num_balls();
    went_live("replicated on");
    return r;
  }

  proto::Values report(const dem::StageReport& r) {
    spdlog::info("dem: {} ({} steps, ratio {:.3e}, porosity {:.4f}, count {}, converged {})", r.what, r.steps, r.ratio,
                 r.porosity, r.count, r.converged);
    if (!dir_.empty()) {
      if (!stages_) stages_.emplace(io::CsvSeries::create(dir_ / "specimen_stages.csv", stage_columns(), stage_format()));
      const auto c = dist_live_ ? rep_coord_ : dem::coordination(world_);
      stages_->append_cells({dist_live_ ? rep_balls_ : world_.num_balls(), r.steps, r.ratio, r.porosity, c.z, c.z_no_rattlers, r.stress[0],
                             r.stress[4], r.stress[8], r.converged ? 1 : 0, r.what});
    }
    // A preparation procedure that misses its criterion stops the run (docs/theory.md 4.11): the
    // specimen would otherwise depend on the budget, not on the rock.
    if (!r.converged)
      throw std::runtime_error("specimen preparation did not reach its criterion within its budget: " + r.what);
    return {{"steps", static_cast<double>(r.steps)}, {"ratio", r.ratio}, {"porosity", r.porosity},
            {"count", static_cast<double>(r.count)}, {"converged", r.converged ? 1.0 : 0.0},
            {"sxx_Pa", r.stress[0]}, {"syy_Pa", r.stress[4]}, {"szz_Pa", r.stress[8]}};
  }

  proto::Values place_footing() {
    dem::FootingParams f = dem::scene::footing(s_, block_);
    const dem::Vec3 axis = f.bottom_centre;
    double best = 0.0;
    if (dist_live_) {  // on the ranks' parts (a maximum over the ranks), and on rank 0's World
      best = dem::place_footing_at_first_contact(*dist_, f);
      dem::set_footing_at(world_, f, best);
    } else {
      best = dem::place_footing_at_first_contact(world_, f);
    }
    footing_z0_ = best;
    spdlog::info("dem: footing D {} m at ({}, {}), bottom z {} m", f.diameter, axis.x, axis.y, best);
    return {{"footing_z0_m", best}};
  }
  double footing_disp() const {
    return live().has_footing() ? footing_z0_ - live().footing().p.bottom_centre.z : 0.0;
  }

  proto::Values ucs(const schema::Stage& st) {
    const dem::UcsParams p = dem::scene::ucs(st.view);
    const auto m0 = dem::measure(world_);
    const double cpu0 = static_cast<double>(std::clock()) / CLOCKS_PER_SEC;
    const auto t0 = std::chrono::steady_clock::now();
    // A periodic REV is loaded as a z-periodic column (no platens, no end effects); an opened
    // specimen between platens (docs/ucs-study.md).
    const bool column = world_.periodic();
    auto r = column ? dem::unconfined_compression_column(world_, p) : dem::unconfined_compression(world_, p);
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu = static_cast<double>(std::clock()) / CLOCKS_PER_SEC - cpu0;
    const double steps = static_cast<double>(r.report.steps);
    if (!dir_.empty()) {
      auto csv = io::CsvSeries::create(dir_ / "ucs_curve.csv", {"strain_unit", "stress_Pa"});
      for (auto& s : r.curve) csv.append({s.strain, s.stress});
      csv.close();
    }
    const auto m1 = dem::measure(world_);
    spdlog::info("dem: {}", r.report.what);
    spdlog::info("dem: UCS {:.4e} Pa, E50 {:.4e} Pa ({} samples, {} steps, wall {:.1f} s, cpu {:.1f} s, {:.3e} s/step)",
                 r.peak, r.e50, r.curve.size(), r.report.steps, wall, cpu, steps > 0 ? wall / steps : 0.0);
    if (!dir_.empty()) {
      auto res = io::CsvSeries::create(
          dir_ / "ucs_result.csv",
          {"ucs_Pa", "e50_Pa", "peak_strain_unit", "balls_unit", "coordination_unit", "bonds_unit",
           "bonds_broken_tension_unit", "bonds_broken_shear_unit", "ucs_steps_unit", "ucs_wall_s", "ucs_cpu_s",
           "settle_steps_unit", "peak_reached_unit"});
      res.append({r.peak, r.e50, r.peak_strain, static_cast<double>(world_.num_balls()), m0.coord.z,
                  static_cast<double>(m0.bonds.intact + m0.bonds.softening), static_cast<double>(m1.bonds.broken_tension),
                  static_cast<double>(m1.bonds.broken_shear), static_cast<double>(r.report.steps), wall, cpu,
                  static_cast<double>(r.settle.steps), r.report.converged ? 1.0 : 0.0});
      res.close();
    }
    return {{"ucs_Pa", r.peak},
            {"e50_Pa", r.e50},
            {"samples", static_cast<double>(r.curve.size())},
            {"ucs_steps", steps},
            {"ucs_wall_s", wall},
            {"ucs_cpu_s", cpu},
            {"balls", static_cast<double>(world_.num_balls())},
            {"coordination_before", m0.coord.z},
            {"bonds_before", static_cast<double>(m0.bonds.intact + m0.bonds.softening)},
            {"peak_strain", r.peak_strain},
            {"settle_steps", static_cast<double>(r.settle.steps)},
            {"peak_reached", r.report.converged ? 1.0 : 0.0}};
  }

  // The engine's unbalanced-force ratio of the current state, computed once per state (the
  // history row, the step report and the exit criterion all read it; it rebuilds every
  // contact force).
  double ratio() {
    if (!ratio_valid_) {
      if (live().gravity_on() && !skeleton_valid_) {
        ball_ratios();  // the step's report reads both
      } else {
        ratio_ = dist_live_ ? dist_->unbalanced_ratio(mean_contact_force()) : world_.unbalanced_ratio(mean_contact_force());
        ratio_valid_ = true;
      }
    }
    return ratio_;
  }
  // Both ratios of the current state in one pass over the balls (dem::ball_ratios: their bits).
  void ball_ratios() {
    const dem::BallRatios r = dist_live_ ? dist_->ball_ratios(mean_contact_force()) : dem::ball_ratios(world_, mean_contact_force());
    ratio_ = r.unbalanced;
    skeleton_ = r.skeleton;
    ratio_valid_ = skeleton_valid_ = true;
  }
  // The mean contact force of the current state (both ratios divide by it; O(contacts)).
  double mean_contact_force() {
    if (!fc_valid_) {
      fc_ = dist_live_ ? dist_->mean_contact_force() : world_.mean_contact_force();
      fc_valid_ = true;
    }
    return fc_;
  }
  const dem::SkeletonRatio& skeleton() {
    if (!skeleton_valid_) {
      if (!ratio_valid_) {
        ball_ratios();
      } else {
        skeleton_ = dist_live_ ? dist_->skeleton_ratio(mean_contact_force()) : dem::skeleton_ratio(world_, mean_contact_force());
        skeleton_valid_ = true;
      }
    }
    return skeleton_;
  }

  // Weight of the balls [N] under the current gravity (constant while no ball is added).
  double weight() {
    if (weight_ < 0) weight_ = dist_live_ ? dist_->ball_weight() : dem::ball_weight(world_);  // (the same bits)
    return weight_;
  }

  // Vertical stress profile of the DEM block (Fig. 3): particle-based stress (region_stress)
  // in horizontal slabs spanning the block's footprint, about 1.5 d_max thick, with the
  // self-weight line rho_b N g depth, rho_b = ball mass / block volume (the block's own bulk
  // density). Depth is measured from the block top. Written to dem_profile_<stage>.csv.
  void write_profile(const schema::Stage& st) {
    const double h = block_.height();
    const double d_max = s_.real("dem.specimen.d_max") * s_.real("dem.specimen.scale");
    const int n = std::max(4, static_cast<int>(std::lround(h / (1.5 * d_max))));
    const double lx = block_.width_x(), ly = block_.width_y();
    const double g = std::abs(live().gravity().z);
    const double rho_b = g > 0 ? weight() / g / (lx * ly * h) : 0.0;
    dem::ProfileBox box;
    box.x_lo = block_.origin.x;
    box.y_lo = block_.origin.y;
    box.x_hi = block_.origin.x + lx;
    box.y_hi = block_.origin.y + ly;
    box.z_top = block_.z_top();
    box.height = h;
    // (while the ranks step, from their parts, one World's bits: every rank calls this)
    const auto profile = dist_live_ ? dem::stress_profile(*dist_, box, n) : dem::stress_profile(world_, box, n);
    if (!out_) return;
    auto csv = io::CsvSeries::create(dir_ / ("dem_profile_" + st.name + ".csv"),
                                     {"depth_m", "depth_top_m", "depth_bottom_m", "szz_Pa", "sxx_Pa", "syy_Pa",
                                      "balls_1", "selfweight_szz_Pa", "rho_b_kg_m3", "d_max_m"});
    for (const auto& sl : profile)
      csv.append({sl.depth, sl.depth_top, sl.depth_bottom, sl.szz, sl.sxx, sl.syy, static_cast<double>(sl.balls),
                  -rho_b * g * sl.depth, rho_b, d_max});
    csv.close();
  }

  // A frame of the current state (docs/output.md). While the ranks step every rank calls it: the
  // ranks' rows are merged on rank 0 in blocks as they arrive (DistDem::stream_snapshot), and no
  // rank assembles the World for it; else rank 0 writes its whole World. The same datasets either
  // way (tests/dist/node_footing.py).
  void write_frame(std::int64_t step) {
    const bool streamed = dist_live_;
    if (!streamed && !out_) return;
    const double t = live().time();
    int go = out_ && !(has_frame_ && t <= last_frame_time_) ? 1 : 0;  // frame times must increase
    if (streamed) {
      const bool any = dist_->num_balls() > 0;  // (collective: on every rank)
      go = go && any;
      MPI_Bcast(&go, 1, MPI_INT, 0, g_ranks.comm);
    } else {
      go = go && world_.num_balls() > 0;
    }
    if (!go) return;
    node::Timed timed(effect_s_["output.h5"]);
    // The footing's surface, where it is in this frame (none before a stage places it).
    io::TriangleSurface footing;
    io::FrameShape shape;
    if (out_) {
      shape.point_arrays = {{"radius", io::DType::kFloat64, 1}, {"velocity", io::DType::kFloat64, 3}, {"id", io::DType::kInt64, 1}};
      shape.links = {{"bonds", 0, {{"state", io::DType::kUInt8, 1}, {"force", io::DType::kFloat64, 3}}}};
      if (footing_output_) {
        if (live().has_footing()) {
          const auto& p = live().footing().p;
          footing = io::cylinder_surface({p.bottom_centre.x, p.bottom_centre.y, p.bottom_centre.z}, p.diameter, p.height);
        }
        shape.surfaces.push_back({"footing", io::ArrayView(footing.vertices, 3), io::ArrayView(footing.triangles, 3)});
      }
    }
    // Model time (docs/output.md "Time"): negative for frames of the specimen preparation,
    // which get their times once the first later stage begins (begin_model_time).
    auto begin = [&](std::size_t balls, std::size_t pairs) {
      shape.particles = balls;
      shape.links[0].rows = pairs;
      out_->begin_blocks(step, clock_.frame_time(t), shape);
    };
    std::vector<std::int64_t> ids;
    std::vector<std::int32_t> nodes;
    auto balls = [&](std::size_t row0, const dem::Snapshot& b) {
      ids.assign(b.id.begin(), b.id.end());
      out_->write_rows("particles/position", row0, io::ArrayView(b.position, 3));
      out_->write_rows("particles/radius", row0, io::ArrayView(b.radius));
      out_->write_rows("particles/velocity", row0, io::ArrayView(b.velocity, 3));
      out_->write_rows("particles/id", row0, io::ArrayView(ids));
    };
    auto pairs = [&](std::size_t row0, const dem::Snapshot& b) {
      nodes.assign(b.pair.begin(), b.pair.end());
      out_->write_rows("bonds/nodes", row0, io::ArrayView(nodes, 2));
      out_->write_rows("bonds/state", row0, io::ArrayView(b.state));
      out_->write_rows("bonds/force", row0, io::ArrayView(b.force, 3));
    };
    if (streamed) {
      dem::DistDem::SnapshotSink sink;
      if (out_) sink = {begin, balls, pairs};
      dist_->stream_snapshot(sink);
    } else {
      const dem::Snapshot snap = dem::snapshot(world_);  // one block of each
      begin(snap.id.size(), snap.state.size());
      balls(0, snap);
      pairs(0, snap);
    }
    if (!out_) return;
    out_->end_blocks();
    has_frame_ = true;
    last_frame_time_ = t;
  }

  node::Context ctx_;
  const config::Scene& s_;
  Block block_;
  dem::World world_;
  std::int64_t interval_ = 1, frame_every_ = 0, history_every_ = 1;
  bool coupled_stage_ = false;  // the stage exchanges interface data (step_values: one thread)
  double gravity_level_ = 0, stage_ratio_ = 1e-5;
  fs::path dir_;
  std::optional<io::ParticleOutput> out_;
  std::optional<io::CsvSeries> history_;
  std::optional<io::CsvSeries> stages_;  // specimen_stages.csv, from its first row on
  bool outputs_open_ = false;
  bool has_frame_ = false;
  double last_frame_time_ = 0;           // DEM (node) time of the last frame
  io::ModelClock clock_;                 // the frames' model time
  std::vector<std::string> stage_prefixes_;  // "stage[i]" of every stage: its scene index
  bool footing_output_ = false;          // a stage places a footing: footing.xmf
  int wall_ = -1;
  std::size_t n_iface_ = 0;
  bool coupling_setup_pending_ = false, penetrating_ = false, box_done_ = false;
  bool preparing_ = false;  // a specimen-preparation stage (is_generation): its own step and damping
  std::int64_t early_step_ = -1;    // advance_early ran the first DEM step's motion of this coupling step (-1: none)
  double early_node_before_ = 0.0;  // the World's time before it
  double footing_z0_ = 0, target_disp_ = 0;
  double weight_ = -1;
  double ratio_ = 0;           // engine ratio of the current state (ratio())
  bool ratio_valid_ = false;   // cleared by every call that changes the state
  dem::SkeletonRatio skeleton_;     // skeleton ratio of the current state (skeleton())
  bool skeleton_valid_ = false;
  double fc_ = 0.0;            // mean contact force of the state (mean_contact_force())
  bool fc_valid_ = false;
  double ke_ = 0.0;            // kinetic energy of the state (kinetic_energy())
  bool ke_valid_ = false;
  node::EnergyJump energy_jump_;
  double user_dt_ = 0, escape_margin_ = 0;
  std::int64_t history_due_ = -1;  // the step whose history row step_values writes (-1: none)
  std::vector<double> screen_scratch_;  // check_health: dem::screen_balls's per-ball terms
  std::vector<double> kick_;
  bool kicked_ = false;
  std::map<std::string, double> effect_s_;
  mutable std::array<std::int64_t, 3> safe_dt_key_{-1, -1, -1};
  mutable double safe_dt_ = 0;
  dem::StageEnergy energy_;  // the stage's energy balance (docs/stability.md)
  // The DEM on ranks: the slabs that step (between a stage's first step and its end), whether
  // they step now, and whether world_ holds their current state.
  std::unique_ptr<dem::DistDem> dist_;
  bool dist_live_ = false, synced_ = false;
  dem::Coordination rep_coord_;  // the replicated block's coordination and balls (its specimen_stages.csv row)
  std::size_t rep_balls_ = 0;
  // The stage's energy balance began on the ranks' parts: each rank keeps its balls' positions
  // at the stage's begin (gravity's work), rank 0's StageEnergy the rest.
  bool ranked_energy_ = false;
  std::vector<dem::DistDem::IdPos> x_begin_;
  bool outputs_ = false;  // rank 0 writes results
  dem::PhaseTimes ranked_phases_;  // the phases of this rank's slab in the stage
  bool has_ranked_phases_ = false;
  bool energy_pending_ = false;  // the balance begins at the stage's first step (after its set-up)
};

// ------------------------------------------------------------------------------------------
// Ranks: rank 0 tells the others each call it gets (one broadcast per call), then makes it.

// A call and its arguments as bytes.
class Wire {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    append(&v, sizeof v);
  }
  template <class T>
  void put_vec(const std::vector<T>& v) {
    put<std::uint64_t>(v.size());
    append(v.data(), v.size() * sizeof(T));
  }
  void append(const void* p, std::size_t n) {
    const std::size_t at = b_.size();
    b_.resize(at + n);
    if (n) std::memcpy(b_.data() + at, p, n);
  }
  void put_str(const std::string& v) { put_vec(std::vector<char>(v.begin(), v.end())); }
  template <class T>
  T get() {
    T v;
    std::memcpy(&v, b_.data() + at_, sizeof v);
    at_ += sizeof v;
    return v;
  }
  template <class T>
  std::vector<T> get_vec() {
    const auto n = get<std::uint64_t>();
    std::vector<T> v(n);
    std::memcpy(static_cast<void*>(v.data()), b_.data() + at_, n * sizeof(T));
    at_ += n * sizeof(T);
    return v;
  }
  std::string get_str() {
    auto v = get_vec<char>();
    return {v.begin(), v.end()};
  }
  // Rank 0 sends, the others receive (collective). A rank waiting for the next call (rank 0
  // may wait on the bus for long) sleeps between tests instead of spinning: the ranks share the
  // machine's cores with the continuum and the coordinator.
  void bcast() {
    std::uint64_t n = b_.size();
    MPI_Request req;
    MPI_Ibcast(&n, 1, MPI_UINT64_T, 0, g_ranks.comm, &req);
    if (g_ranks.rank == 0) {
      MPI_Wait(&req, MPI_STATUS_IGNORE);
    } else {
      for (int k = 0;; ++k) {
        int done = 0;
        MPI_Test(&req, &done, MPI_STATUS_IGNORE);
        if (done) break;
        if (k > 200) std::this_thread::sleep_for(std::chrono::microseconds(k > 20000 ? 1000 : 20));
      }
    }
    b_.resize(n);
    MPI_Bcast(b_.data(), static_cast<int>(n), MPI_BYTE, 0, g_ranks.comm);
    at_ = 0;
  }
  bool empty() const { return b_.empty(); }

 private:
  std::vector<char> b_;
  std::size_t at_ = 0;
};

enum class Op : std::int32_t {
  kQuit, kDtStable, kStageBegin, kAdvance, kStepValues, kCriterion, kStageEnd, kFinish, kHealth, kSave, kRestore,
  kMesh, kKin
};

Wire call(Op op) {
  Wire w;
  w.put(op);
  return w;
}

// Rank 0's participant: every call that the ranks make together is sent to them first.
class RankedParticipant : public node::Participant {
 public:
  explicit RankedParticipant(const node::Context& ctx) : stages_(schema::stages(ctx.scene)) {
    Wire w;  // the scene and the run, for the other ranks' adapters
    w.put_str(ctx.scene.text());
    w.put_str(ctx.scene.origin());
    w.put(ctx.options.run_id);
    w.put<std::uint8_t>(!ctx.options.run_dir.empty());
    w.bcast();
    g_ranks.root_dir = !ctx.options.run_dir.empty();
    p_ = std::make_unique<DemParticipant>(ctx);
  }
  double dt_stable() const override {
    auto w = call(Op::kDtStable);
    w.bcast();
    return p_->dt_stable();
  }
  double time() const override { return p_->time(); }
  proto::Values stage_begin(const schema::Stage& st, std::int64_t first) override {
    auto w = call(Op::kStageBegin);
    w.put(index(st));
    w.put(first);
    w.bcast();
    return p_->stage_begin(st, first);
  }
  void advance(const schema::Stage& st, std::int64_t step, double dt, const std::vector<double>& values) override {
    auto w = call(Op::kAdvance);
    w.put(index(st));
    w.put(step);
    w.put(dt);
    w.put_vec(values);
    w.bcast();
    p_->advance(st, step, dt, values);
  }
  proto::Values step_values() override {
    call(Op::kStepValues).bcast();
    return p_->step_values();
  }
  bool criterion_met(const schema::Stage& st) override {
    auto w = call(Op::kCriterion);
    w.put(index(st));
    w.bcast();
    return p_->criterion_met(st);
  }
  proto::Values stage_end(const schema::Stage& st, std::int64_t last) override {
    auto w = call(Op::kStageEnd);
    w.put(index(st));
    w.put(last);
    w.bcast();
    return p_->stage_end(st, last);
  }
  void finish() override {
    if (finished_) return;
    finished_ = true;
    call(Op::kFinish).bcast();
    p_->finish();
  }
  std::optional<node::HealthReport> check_health(std::int64_t step) override {
    auto w = call(Op::kHealth);
    w.put(step);
    w.bcast();
    return p_->check_health(step);
  }
  bool can_checkpoint() const override { return true; }
  void save(const fs::path& dir, io::StateWriter& sw, const io::StateMeta& meta) override {
    auto w = call(Op::kSave);
    w.put_str(dir.string());
    w.put(meta.scene_hash);
    w.bcast();
    p_->save(dir, sw, meta);
  }
  void restore(io::StateReader& r, const node::Restore& how) override {
    auto w = call(Op::kRestore);
    w.put_str(how.dir.string());
    w.put(how.saved_scene_hash);
    w.put<std::uint8_t>(how.branch);
    w.bcast();
    p_->restore(r, how);
  }
  void set_interface_mesh(const proto::InterfaceMesh& m) override {
    auto w = call(Op::kMesh);
    w.put_vec(m.positions);
    w.put_vec(m.triangles);
    w.bcast();
    p_->set_interface_mesh(m);
  }
  void set_interface_kinematics(const proto::Kinematics& k) override {
    auto w = call(Op::kKin);
    w.put_vec(k.positions);
    w.put_vec(k.velocities);
    w.bcast();
    p_->set_interface_kinematics(k);
  }
  // The walls' sums are the same on every rank: rank 0 answers alone.
  proto::Forces interface_forces() override { return p_->interface_forces(); }

 private:
  std::int32_t index(const schema::Stage& st) const {
    for (std::size_t i = 0; i < stages_.size(); ++i)
      if (stages_[i].view.prefix() == st.view.prefix()) return static_cast<std::int32_t>(i);
    throw std::logic_error("stage '" + st.name + "' is not one of the scene's");
  }
  std::vector<schema::Stage> stages_;
  std::unique_ptr<DemParticipant> p_;
  bool finished_ = false;
};

// A rank other than 0: the adapter without bus or files, making the calls rank 0 sends.
int follow() {
  spdlog::set_level(spdlog::level::warn);  // rank 0 logs the run
  Wire w;
  w.bcast();
  if (w.empty()) return 0;  // rank 0 ended before it had a scene
  const std::string text = w.get_str(), origin = w.get_str();
  node::Context ctx{node::Options{}, config::Scene::parse(text, origin, schema::scene_schema()), "dem"};
  ctx.options.run_id = w.get<std::int64_t>();
  g_ranks.root_dir = w.get<std::uint8_t>() != 0;
  DemParticipant p(ctx);
  const auto stages = schema::stages(ctx.scene);
  for (;;) {
    Wire c;
    c.bcast();
    if (c.empty()) return 0;
    const Op op = c.get<Op>();
    switch (op) {
      case Op::kQuit: return 0;
      case Op::kDtStable: p.dt_stable(); break;
      case Op::kStageBegin: {
        const auto i = c.get<std::int32_t>();
        p.stage_begin(stages[static_cast<std::size_t>(i)], c.get<std::int64_t>());
        break;
      }
      case Op::kAdvance: {
        const auto i = c.get<std::int32_t>();
        const auto step = c.get<std::int64_t>();
        const auto dt = c.get<double>();
        p.advance(stages[static_cast<std::size_t>(i)], step, dt, c.get_vec<double>());
        break;
      }
      case Op::kStepValues: p.step_values(); break;
      case Op::kCriterion: p.criterion_met(stages[static_cast<std::size_t>(c.get<std::int32_t>())]); break;
      case Op::kStageEnd: {
        const auto i = c.get<std::int32_t>();
        p.stage_end(stages[static_cast<std::size_t>(i)], c.get<std::int64_t>());
        break;
      }
      case Op::kFinish: p.finish(); break;
      case Op::kHealth: p.check_health(c.get<std::int64_t>()); break;
      case Op::kSave: {
        const fs::path dir = c.get_str();
        io::StateMeta meta;
        meta.scene_hash = c.get<std::uint64_t>();
        io::StateWriter sw("node", meta.code_version, meta.scene_hash);  // rank 0 writes the files
        p.save(dir, sw, meta);
        break;
      }
      case Op::kRestore: {
        node::Restore how;
        how.dir = c.get_str();
        how.saved_scene_hash = c.get<std::uint64_t>();
        how.branch = c.get<std::uint8_t>() != 0;
        // The node file's adapter section only: rank 0's runtime reads the runtime section and
        // checks that the file holds nothing else (StateReader::finish).
        const auto path = how.dir / "dem.state";
        io::StateReader r(io::read_whole_file(path), path.string(), "node", how.saved_scene_hash);
        p.restore(r, how);
        break;
      }
      case Op::kMesh: {
        proto::InterfaceMesh m;
        m.positions = c.get_vec<double>();
        m.triangles = c.get_vec<std::int32_t>();
        p.set_interface_mesh(m);
        break;
      }
      case Op::kKin: {
        proto::Kinematics k;
        k.positions = c.get_vec<double>();
        k.velocities = c.get_vec<double>();
        p.set_interface_kinematics(k);
        break;
      }
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  const auto plain = [](const node::Context& ctx) { return std::make_unique<DemParticipant>(ctx); };
  // Under mpirun (Open MPI sets OMPI_COMM_WORLD_SIZE): the DEM on ranks. Otherwise, and for
  // --check, one process without MPI.
  const char* ranks_env = std::getenv("OMPI_COMM_WORLD_SIZE");
  bool check = false;
  for (int i = 1; i < argc; ++i) check = check || std::string(argv[i]) == "--check";
  if (!ranks_env || check) return node::run_node(argc, argv, "dem", "dem_node", plain);
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  g_ranks.comm = MPI_COMM_WORLD;
  MPI_Comm_rank(g_ranks.comm, &g_ranks.rank);
  MPI_Comm_size(g_ranks.comm, &g_ranks.size);
  {
    MPI_Comm host;
    MPI_Comm_split_type(g_ranks.comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &host);
    MPI_Comm_size(host, &g_ranks.local);
    MPI_Comm_free(&host);
  }
  int code = 0;
  if (g_ranks.rank == 0) {
    bool made = false;
    code = node::run_node(argc, argv, "dem", "dem_node", [&](const node::Context& ctx) -> std::unique_ptr<node::Participant> {
      made = true;
      if (g_ranks.size == 1) return std::make_unique<DemParticipant>(ctx);
      return std::make_unique<RankedParticipant>(ctx);
    });
    if (code != 0 && g_ranks.size > 1) {
      // A failed run: the other ranks may wait in any call; the job ends here, with the code.
      spdlog::default_logger()->flush();
      MPI_Abort(g_ranks.comm, code);
    }
    if (g_ranks.size > 1) {
      Wire quit;  // an empty message: the scene (none came) or the end of the calls
      if (made) quit = call(Op::kQuit);
      quit.bcast();
    }
  } else {
    try {
      code = follow();
    } catch (const std::exception& e) {
      // Rank 0 meets the same failure (the same calls on the same state) and reports it; if it
      // does not within 2 s, this rank ends the job.
      std::fprintf(stderr, "dem_node rank %d: %s\n", g_ranks.rank, e.what());
      std::this_thread::sleep_for(std::chrono::seconds(2));
      MPI_Abort(g_ranks.comm, 3);
    }
  }
  MPI_Finalize();
  return code;
}
