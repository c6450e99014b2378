// coordinator: validates the scene, starts the protocol, runs the stages, ends the run.
//
//   coordinator SCENE --check              validate only (exit 0, or 2 with one error line): the
//                                          schema, then every role's `EXE --check SCENE` (the
//                                          node's own mapping and engine checks)
//   coordinator SCENE --check --set-executable=ROLE=EXE ...   the same with another executable
//   coordinator SCENE --print-nodes        "role executable" lines for launch/run
//   coordinator --help-scene [--markdown]  every scene key with unit, default and doc
//   coordinator SCENE --run-id=N [--lcm-url=URL] [--run-dir=DIR] [-v]
//   coordinator SCENE --resume --run-dir=DIR ...   continue the run in DIR from its latest
//                                                  complete checkpoint (docs/checkpoint-format.md)
//   coordinator SCENE --from=CHECKPOINT [--check] ...  a new run from a saved stage-end state
//   coordinator SCENE --set table.key=value ... [--check | --print-effective | ...]
//                                          override scene keys (config::Scene::parse overrides);
//                                          --print-effective writes the scene in effect (TOML)
//
// Exit codes: 0 finished, 2 bad command line or scene, 3 a node failed, died or went silent
// (named in the message), 130 interrupted.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <csignal>
#include <fstream>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <variant>

#include "common/log/log.hpp"
#include "git_commit.hpp"
#include "coordinator/core/centrifuge.hpp"
#include "coordinator/core/checkpoint.hpp"
#include "coordinator/core/history.hpp"
#include "coordinator/core/node_check.hpp"
#include "coordinator/core/progress.hpp"
#include "coordinator/core/quasi_static.hpp"
#include "coordinator/core/results.hpp"
#include "coordinator/core/runner.hpp"
#include "coordinator/core/summary.hpp"
#include "common/node/node_runtime.hpp"
#include "messages/protocol.hpp"

using namespace demfdm;

namespace {

const char* kUsage =
    "usage: coordinator SCENE [--check | --print-nodes | --print-effective] [--run-id=N] [--lcm-url=URL]\n"
    "                         [--run-dir=DIR] [-v] [--resume | --from=CHECKPOINT_DIR] [--set table.key=value ...]\n"
    "                         [--set-executable=ROLE=EXE ...]\n"
    "       coordinator --help-scene [--markdown]\n";

// Adapts the bus endpoint to the stage machine's transport interface.
class BusDriver : public coord::Driver {
 public:
  explicit BusDriver(proto::CoordinatorEndpoint& ep) : ep_(ep) {}
  void post(coord::Cmd cmd, const std::vector<std::string>& targets, std::int64_t step, std::int32_t stage_index,
            const std::string& stage_name, double dt, const std::vector<double>& values) override {
    ep_.post(static_cast<std::int32_t>(cmd), targets, step, stage_index, stage_name, dt, values);
  }
  std::map<std::string, coord::NodeReport> collect(coord::Cmd cmd, const std::vector<std::string>& targets,
                                                   std::int64_t step, std::int32_t stage_index) override {
    auto raw = ep_.collect(static_cast<std::int32_t>(cmd), targets, step, stage_index);
    std::map<std::string, coord::NodeReport> out;
    for (auto& [role, r] : raw) {
      coord::NodeReport n;
      n.status = static_cast<coord::Status>(r.status);
      n.time = r.time;
      n.dt_stable = r.dt_stable;
      n.compute_s = r.compute_s;
      n.wait_s = r.wait_s;
      for (int i = 0; i < r.n_values; ++i) n.values[r.names[i]] = r.values[i];
      for (int j = 0; j < r.n_rows; ++j) {
        std::map<std::string, double> row;
        for (int i = 0; i < r.n_values && i < static_cast<int>(r.rows[j].size()); ++i) row[r.names[i]] = r.rows[j][i];
        n.rows.emplace_back(r.row_steps[j], std::move(row));
      }
      n.text = r.text;
      out[role] = n;
    }
    return out;
  }

 private:
  proto::CoordinatorEndpoint& ep_;
};

void on_signal(int s) { proto::request_interrupt(s); }

coord::RunInfo run_info(const config::Scene& scene, const proto::CoordinatorEndpoint& ep, const bus::BusStats& bs) {
  coord::RunInfo info;
  info.scene = scene.origin();
  info.hash = scene.hash();
  for (auto& [r, n] : ep.nodes()) info.nodes.push_back({r, n.solver, n.host, n.build_id, static_cast<std::int64_t>(n.pid)});
  std::ostringstream os;
  os << "published " << bs.published << ", accepted " << bs.accepted << ", foreign-run " << bs.foreign_run
     << ", duplicates " << bs.duplicates << ", decode errors " << bs.decode_errors << "; own stalls "
     << ep.heartbeat().stalls() << " (longest " << std::round(ep.heartbeat().longest_stall_s() * 10) / 10 << " s)";
  info.bus = os.str();
  info.host_cores = static_cast<int>(sysconf(_SC_NPROCESSORS_ONLN));
  return info;
}

// The default of a key of one [[continuum.material]] (a scene without that array gets one group
// with the defaults).
double material_default(const char* key) {
  const auto* mat = schema::scene_schema().root().find("continuum")->section->find("material")->section;
  return std::get<double>(*mat->find(key)->param->def);
}

// Footing speed of a penetrate stage (docs/theory.md §7.1): v = I L_p / (d50 sqrt(rho_s / P)),
// L_p = plastic_zone_ratio D_f, with d50 of the upscaled PSD (d50 times the upscaling factor),
// times speed_factor.
double stage_speed(const config::Scene& scene, const schema::Stage& st) {
  const auto& v = st.view;
  return coord::footing_speed(v.real("inertial_number"), v.real("plastic_zone_ratio"), scene.real("dem.footing.diameter"),
                              scene.real("dem.specimen.d50"), scene.real("dem.specimen.scale"), scene.real("dem.density"),
                              v.real("mean_stress"), v.real("speed_factor"));
}

// The footing kinematics of every penetrate stage must be finite and positive (a run that cannot
// move its footing as asked never starts). Throws config::Error naming the stage's key.
void check_kinematics(const config::Scene& scene) {
  for (const auto& st : schema::stages(scene)) {
    if (st.kind != schema::Action::kPenetrate) continue;
    const double v = stage_speed(scene, st);
    if (!std::isfinite(v) || !(v > 0)) {
      std::ostringstream o;
      o << "I = " << st.view.real("inertial_number") << " giving v = " << v << " m/s";
      st.view.fail("inertial_number",
                   "a rate whose footing speed v = I L_p / (d50 sqrt(rho_s / P)) x speed_factor is finite and > 0",
                   o.str());
    }
  }
}

// Rate and quasi-static measures of a penetrate stage (coordinator/core/quasi_static.hpp).
// E, nu: the first [[continuum.material]] with a continuum, else the stage's rock_young and 1/3;
// rho_b: dem.specimen.bulk_density, else 0.48 rho_s (as the DEM's sigma_v); sigma_c: the tensile
// strength of the ball-ball bond (none for linear contacts or an unbreakable parallel bond).
coord::RateMeasures stage_rates(const config::Scene& scene, const schema::Stage& st) {
  const auto& v = st.view;
  double young = v.real("rock_young"), poisson = 1.0 / 3.0;
  if (scene.has("continuum")) {
    if (scene.count("continuum.material") > 0) {
      auto m = scene.at("continuum.material", 0);
      young = m.real("young");
      poisson = m.real("poisson");
    } else {
      young = material_default("young");
      poisson = material_default("poisson");
    }
  }
  const double rho_b = scene.real_or_word("dem.specimen.bulk_density").value_or(0.48 * scene.real("dem.density"));
  std::optional<double> sigma_c;
  const auto& model = scene.string("dem.ball_ball.model");
  if (model == "softbond") sigma_c = scene.real("dem.ball_ball.softbond.ten");
  if (model == "pbond") sigma_c = scene.real_or_word("dem.ball_ball.pbond.ten");  // none: unbreakable
  double speed = stage_speed(scene, st);
  return coord::rate_measures(speed, v.real("inertial_number"),
                              coord::ramp_time(v.real("ramp_depth_ratio"), scene.real("dem.footing.diameter"), speed),
                              young, poisson, rho_b, sigma_c, v.real("quasi_static_limit"));
}

// The saved state a run starts from (resume or branch).
struct Start {
  std::filesystem::path dir;
  coord::Manifest manifest;
  coord::CheckpointRecord record;
  bool branch = false;
};

// Roles that took part in the stages before `st` (and in `st` itself when inside it).
std::vector<std::string> participants(const std::vector<schema::Stage>& stages, const coord::RunnerState& st) {
  std::set<std::string> r;
  for (std::size_t i = 0; i < stages.size() && (i < st.stage || (st.in_stage && i == st.stage)); ++i)
    r.insert(stages[i].nodes.begin(), stages[i].nodes.end());
  return {r.begin(), r.end()};
}

// Branch: the checkpoint, and the keys of the scene that would make its state inconsistent.
Start branch_start(const std::string& from, const config::Scene& scene) {
  Start s;
  s.dir = std::filesystem::absolute(from).lexically_normal();
  s.branch = true;
  s.manifest = coord::verify_checkpoint(s.dir);
  s.record = coord::load_record(s.dir / "coordinator.state", s.manifest.scene_hash);
  auto saved = config::Scene::parse(s.record.scene_text, (s.dir / "coordinator.state").string() + " (saved scene)",
                                    schema::scene_schema());
  auto conflicts = coord::branch_conflicts(saved, scene, s.record, s.manifest);
  if (!conflicts.empty()) {
    std::string msg = "cannot branch from " + s.dir.string() + ":";
    for (auto& c : conflicts) msg += "\n  " + c;
    throw config::Error(msg, scene.origin(), 0, 0, "");
  }
  return s;
}

// Resume: the latest complete checkpoint of the run folder that passes its checks (a refused
// one is named in the log and the previous one is used).
Start resume_start(const std::string& run_dir, const config::Scene& scene, spdlog::logger& log) {
  auto l = coord::latest_valid_checkpoint(run_dir, scene.hash(),
                                          [&](const std::string& why) { log.warn("{}; using the previous checkpoint", why); });
  Start s;
  s.dir = l.dir;
  s.manifest = l.manifest;
  s.record = std::move(l.record);
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> pos;
  node::Options opt;
  std::string from;
  std::vector<std::string> sets;  // --set table.key=value (or --set=table.key=value), in order
  bool print_effective = false;
  std::map<std::string, std::string> executables;  // --set-executable=ROLE=EXE (launch/run's overrides)
  std::vector<char*> args;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    if (a.rfind("--from=", 0) == 0) {
      from = a.substr(7);
    } else if (a == "--set" || a.rfind("--set=", 0) == 0) {
      if (a == "--set" && (i + 1 >= argc || std::string(argv[i + 1]).rfind("--", 0) == 0)) {
        std::cerr << "coordinator: --set needs a value (--set table.key=value)\n" << kUsage;
        return 2;
      }
      sets.push_back(a == "--set" ? argv[++i] : a.substr(6));
    } else if (a == "--print-effective") {
      print_effective = true;
    } else if (a.rfind("--set-executable=", 0) == 0) {
      const std::string v = a.substr(17);
      const auto eq = v.find('=');
      if (eq == std::string::npos || eq == 0 || eq + 1 == v.size()) {
        std::cerr << "coordinator: --set-executable needs ROLE=EXECUTABLE, found '" << v << "'\n" << kUsage;
        return 2;
      }
      executables[v.substr(0, eq)] = v.substr(eq + 1);
    } else {
      args.push_back(argv[i]);
    }
  }
  argc = static_cast<int>(args.size());
  argv = args.data();
  try {
    opt = node::parse_options(argc, argv, &pos,
                              {"--check", "--print-nodes", "--help-scene", "--markdown", "--help", "-h", "--resume"});
  } catch (const std::exception& e) {
    std::cerr << "coordinator: " << e.what() << "\n" << kUsage;
    return 2;
  }
  auto flag = [&](const char* f) {
    for (auto it = pos.begin(); it != pos.end(); ++it)
      if (*it == f) {
        pos.erase(it);
        return true;
      }
    return false;
  };
  bool check = flag("--check"), print_nodes = flag("--print-nodes"), help_scene = flag("--help-scene"),
       markdown = flag("--markdown"), help = flag("--help") || flag("-h"), resume = flag("--resume");
  if (help) {
    std::cout << kUsage;
    return 0;
  }
  if (help_scene) {
    std::cout << (markdown ? schema::scene_schema().markdown() : schema::scene_schema().help_text());
    return 0;
  }
  if (pos.size() != 1) {
    std::cerr << "coordinator: expected one scene file, found " << pos.size() << " arguments\n" << kUsage;
    return 2;
  }
  if (resume && !sets.empty()) {
    std::cerr << "coordinator: --resume continues a run with its own scene; --set is not available (a new run: "
                 "--from=CHECKPOINT with --set)\n";
    return 2;
  }
  config::Scene scene;
  try {
    scene = config::Scene::load(pos[0], schema::scene_schema(), sets);
    check_kinematics(scene);
  } catch (const config::Error& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  auto roles = schema::roles(scene);
  if (resume && !from.empty()) {
    std::cerr << "coordinator: --resume and --from exclude each other\n" << kUsage;
    return 2;
  }
  if (resume && opt.run_dir.empty()) {
    std::cerr << "coordinator: --resume needs the run folder (--run-dir=DIR)\n" << kUsage;
    return 2;
  }
  std::optional<Start> start;
  if (!from.empty()) {
    try {
      start = branch_start(from, scene);
    } catch (const config::Error& e) {
      std::cerr << e.what() << "\n";
      return 2;
    } catch (const std::exception& e) {
      std::cerr << "coordinator: --from=" << from << ": " << e.what() << "\n";
      return 2;
    }
  }
  if (print_effective) {  // the scene in effect (overrides applied), for launch/run's run folder
    std::cout << scene.effective_toml();
    return 0;
  }
  if (check) {
    // Every check a node would run: each role's executable checks the scene without a bus.
    const std::string bin = coord::own_bin_dir();
    for (auto& r : roles) {
      const std::string name = executables.count(r) ? executables[r] : schema::executable(scene, r);
      const std::string exe = coord::resolve_executable(name, bin);
      if (exe.empty()) {
        std::cerr << scene.where(r + ".executable") << ": " << r << ".executable: expected a program in " << bin
                  << " or on PATH, found '" << name << "' (not found)\n";
        return 2;
      }
      if (auto err = coord::check_node(exe, pos[0], sets)) {
        std::cerr << *err << "\n";
        return 2;
      }
    }
    std::cout << pos[0];
    for (auto& s : sets) std::cout << " --set " << s;
    std::cout << ": OK (" << schema::stages(scene).size() << " stages; nodes:";
    for (auto& r : roles) std::cout << " " << r << "=" << schema::executable(scene, r);
    std::cout << ")";
    if (start)
      std::cout << "; branches from " << start->manifest.tag << " (after stage '" << start->manifest.stage_name << "', step "
                << start->manifest.step << ")";
    std::cout << "\n";
    return 0;
  }
  if (print_nodes) {
    for (auto& r : roles) std::cout << r << " " << schema::executable(scene, r) << "\n";
    return 0;
  }

  auto log = log::setup("coordinator", opt.run_dir, opt.verbose);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  if (resume) {
    // The latest complete checkpoint; the run folder's files written after it are dropped
    // (the nodes cut their own files back when they restore, this process its history).
    try {
      start = resume_start(opt.run_dir, scene, *log);
      auto dropped = coord::drop_files_after(opt.run_dir, start->record.outputs);
      log->info("resuming run {} from {} (stage {} '{}', after step {}){}", opt.run_dir, start->dir.string(),
                start->manifest.stage, start->manifest.stage_name, start->manifest.step,
                dropped.empty() ? std::string() : "; dropped files written after it: " + [&] {
                  std::string t;
                  for (auto& d : dropped) t += (t.empty() ? "" : ", ") + d;
                  return t;
                }());
    } catch (const std::exception& e) {
      log->error("cannot resume: {}", e.what());
      std::cerr << "coordinator: cannot resume " << opt.run_dir << ": " << e.what() << "\n";
      return 2;
    }
  }
  std::unique_ptr<bus::Bus> bus;
  std::unique_ptr<proto::CoordinatorEndpoint> ep;
  try {
    bus = std::make_unique<bus::Bus>(bus::resolve_url(opt.url), opt.run_id, "coordinator");
    proto::Timeouts t;
    t.heartbeat_s = scene.real("bus.heartbeat_s");  // defaults apply when [bus] is absent
    t.peer_timeout_s = scene.real("bus.peer_timeout_s");
    t.startup_s = scene.real("bus.startup_s");
    t.resend_after_s = scene.real("bus.resend_after_s");
    log->info("run {} on {}; scene {}; nodes: {}", opt.run_id, bus->url(), pos[0], roles.size());
    ep = std::make_unique<proto::CoordinatorEndpoint>(*bus, t);
    ep->start(scene.text(), scene.origin(), scene.hash(), roles);
    std::map<std::string, double> dt;
    for (auto& [r, n] : ep->nodes()) {
      dt[r] = n.dt_stable;
      log->info("hello from {}: {} pid {} on {} ({})", r, n.solver, n.pid, n.host, n.build_id);
    }
    const auto stage_list = schema::stages(scene);
    coord::StageHistory hist(opt.run_dir);  // history_<i>_<stage>.csv
    if (start) {
      // Every node that took part in a stage gets its saved state back; the others start
      // fresh (they have done nothing yet; a branch may even play them with another solver).
      const auto& m = start->manifest;
      std::vector<std::string> targets;
      for (auto& r : start->record.participated)
        if (std::find(roles.begin(), roles.end(), r) != roles.end()) targets.push_back(r);
      const std::string text = start->dir.string() + "\n" + std::to_string(m.scene_hash) + "\n" +
                               (start->branch ? "branch" : "resume");
      ep->command(static_cast<std::int32_t>(demfdm::command_t::RESTORE), targets, m.step, m.stage, m.stage_name, 0.0, {},
                  text);
      log->info("{} from {}: nodes restored: {}", start->branch ? "branched" : "resumed", start->dir.string(),
                targets.size());
      if (start->branch)
        hist.continue_numbering(start->record.history);
      else
        hist.restore(start->record.history);
    }
    BusDriver driver(*ep);
    coord::Runner runner(stage_list, driver, dt, scene.has("coupling") ? scene.integer("coupling.window") : 1);
    if (start) {
      auto rs = start->record.runner;
      if (start->branch) {
        // The branch's summary and clock start at the branch point.
        rs.done.clear();
        rs.wall_s = 0;
      }
      runner.start_from(rs);
    }
    // Checkpoints (docs/checkpoint-format.md, coord::CheckpointPolicy): after every stage and
    // every run.checkpoint_every_s of wall time inside stages, when the run has a folder and
    // every node can save its state.
    coord::CheckpointPolicy checkpoints(
        opt.run_dir,
        {scene.boolean("run.checkpoint_stage_end"), scene.real("run.checkpoint_every_s"),
         static_cast<std::size_t>(scene.integer("run.checkpoint_keep"))},
        stage_list, scene.hash(), opt.run_id,
        [&](const std::string& rel, std::int64_t last, std::int32_t si, const std::string& name) {
          std::map<std::string, bool> saved;
          for (auto& [role, r] : ep->command(static_cast<std::int32_t>(demfdm::command_t::CHECKPOINT), roles, last, si,
                                             name, 0.0, {}, rel)) {
            bool& ok = saved[role + " (" + ep->nodes().at(role).solver + ")"];
            for (int i = 0; i < r.n_values; ++i) ok = ok || (r.names[i] == "state_saved" && r.values[i] == 1.0);
          }
          return saved;
        },
        [&](const coord::RunnerState& rs) {
          coord::CheckpointRecord rec;
          rec.history = hist.state();
          rec.scene_text = scene.text();
          for (auto& [r, n] : ep->nodes()) rec.nodes.push_back({r, n.solver});
          rec.participated = participants(stage_list, rs);
          return rec;
        },
        [&](const std::string& line) {
          if (line.rfind("checkpoints are off", 0) == 0)
            log->warn("{}", line);
          else
            log->info("{}", line);
        });
    runner.set_checkpoints([&] { return checkpoints.due(); }, [&](const coord::RunnerState& rs) { checkpoints.take(rs); });
    // Footing kinematics (docs/theory.md §7.1): the rate-rule speed v (stage_speed), ramped up
    // from 0 over t_r = 2 ramp_depth_ratio D_f / v at the stage's start, evaluated at the middle
    // of the grant's steps in the stage's own time (steps are global over the run). The rate
    // and quasi-static measures are logged at each penetrate stage's first grant.
    std::map<std::size_t, coord::RateMeasures> rates;
    {
      auto sts = schema::stages(scene);
      for (std::size_t i = 0; i < sts.size(); ++i)
        if (sts[i].kind == schema::Action::kPenetrate) rates[i] = stage_rates(scene, sts[i]);
    }
    runner.set_kinematics([&runner, &rates, &log](const schema::Stage& st, std::int64_t, double) -> std::vector<double> {
      if (st.kind != schema::Action::kPenetrate) return {};
      const auto& clock = runner.grant_clock();
      const auto& m = rates.at(static_cast<std::size_t>(clock.stage_index));
      if (clock.first_step == clock.stage_first_step) {
        log->info("stage '{}' footing rate: {}", st.name, coord::describe(m));
        if (auto w = coord::quasi_static_warning(st.name, m); !w.empty()) log->warn("{}", w);
      }
      return {coord::ramped_speed(m.speed, clock.t_mid(), m.ramp_time)};
    });
    // Progress (coordinator/core/progress.hpp): on a terminal one rewritten line twice a second,
    // else a plain line every 5 s; coordinator.log gets a line every 10 s.
    const bool tty = ::isatty(2) != 0;
    coord::Progress progress(tty ? 0.5 : 5.0), progress_log(10.0);
    const double d_f = scene.has("dem.footing") ? scene.real("dem.footing.diameter") : 0.0;
    progress.set_footing_diameter(d_f);
    progress_log.set_footing_diameter(d_f);
    bool line_open = false;
    auto end_line = [&] {
      if (line_open) std::cerr << "\n" << std::flush;
      line_open = false;
    };
    runner.set_observer([&](const schema::Stage& st, std::int64_t step, const auto& reps) {
      hist.record(st, step, reps);
      const auto now = std::chrono::steady_clock::now();
      const auto first = runner.grant_clock().stage_first_step;
      if (auto l = progress.observe(st, first, step, reps, now)) {
        if (tty) {
          std::cerr << "\r" << *l << "\x1b[K" << std::flush;
          line_open = true;
        } else {
          std::cerr << "progress: " << *l << "\n";
        }
      }
      if (auto l = progress_log.observe(st, first, step, reps, now)) log->info("progress: {}", *l);
    });
    auto sum = runner.run();
    end_line();
    ep->shutdown("run finished");
    auto info = run_info(scene, *ep, bus->stats());
    info.rates = rates;
    info.checkpoints = checkpoints.summary(sum.wall_s);
    if (start)
      info.resumed = std::string(start->branch ? "branched from " : "resumed from ") + start->dir.string() +
                     " (after step " + std::to_string(start->manifest.step) + ")";
    // The run's identity and, for a footing run, its result (coordinator/core/results.hpp), read
    // back from the penetration history: printed last, after the cost summary.
    {
      std::ostringstream id;
      id << "{\"scene\": " << coord::json_string(scene.origin()) << ", \"seed\": " << scene.integer("run.seed")
         << ", \"g_level\": " << (scene.has("gravity") ? scene.real("gravity.level") : 1.0)
         << ", \"footing_diameter_m\": " << (d_f > 0 ? fmt::format("{:.17g}", d_f) : std::string("null"))
         << ", \"threads\": "
         << (scene.integer_or_word("run.threads") ? std::to_string(*scene.integer_or_word("run.threads")) : "\"auto\"")
         << ", \"git_commit\": " << coord::json_string(DEMFDM_GIT_COMMIT)
         << ", \"build_id\": " << coord::json_string(io::default_code_version()) << "}";
      info.extra_json.push_back({"run", id.str()});
    }
    std::string result;
    for (std::size_t i = stage_list.size(); i-- > 0;) {
      const auto& st = stage_list[i];
      if (st.kind != schema::Action::kPenetrate || opt.run_dir.empty() || d_f <= 0) continue;
      const auto path = opt.run_dir + "/history_" + std::to_string(i) + "_" + st.name + ".csv";
      if (!std::filesystem::exists(path)) break;
      try {
        auto r = coord::footing_result(path, st.name, d_f, st.view.real("depth_ratio") * d_f);
        for (auto& ss : sum.stages)
          if (ss.name == st.name)
            if (auto it = ss.end.find("dem"); it != ss.end.end()) {
              auto v = it->second.values;
              if (v.count("bonds_broken_tension")) r.bonds_broken_tension = v["bonds_broken_tension"];
              if (v.count("bonds_broken_shear")) r.bonds_broken_shear = v["bonds_broken_shear"];
            }
        result = coord::result_text(r);
        info.extra_json.push_back({"result", coord::result_json(r)});
        // The centrifuge planning report (coordinator/core/centrifuge.hpp): centrifuge.md and
        // summary.json "centrifuge".
        coord::CentrifugeInput c;
        c.g_level = scene.has("gravity") ? scene.real("gravity.level") : 1.0;
        if (scene.has("gravity")) c.g0_m_s2 = scene.real("gravity.g0");
        c.footing_diameter_m = d_f;
        const auto& m = rates.at(i);
        c.footing_speed_m_s = m.speed;
        c.settlement_m = r.settlement_m;
        c.load_N = r.load_N;
        c.target_settlement_m = r.target_m;
        if (scene.has("continuum")) {
          auto box = scene.reals("continuum.mesh.size");
          for (int k = 0; k < 3; ++k) c.block_size_m[k] = box[static_cast<std::size_t>(k)];
        } else {
          auto cell = scene.reals("dem.specimen.cell");
          auto rep = scene.integers("dem.specimen.replicate");
          for (int k = 0; k < 3; ++k)
            c.block_size_m[k] = cell[static_cast<std::size_t>(k)] * static_cast<double>(rep[static_cast<std::size_t>(k)]);
        }
        c.rock_density_kg_m3 = m.bulk_density;
        c.young_Pa = m.young;
        if (m.bond_strength) c.sigma_c_Pa = *m.bond_strength;
        c.ramp_travel_m = st.view.real("ramp_depth_ratio") * d_f;
        if (m.impedance_ratio) c.impedance_ratio = *m.impedance_ratio;
        c.quasi_static_limit = m.limit;
        c.scene = scene.origin();
        c.stage = st.name;
        auto rep = coord::centrifuge_report(c);
        info.extra_json.push_back({"centrifuge", rep.json});
        if (!opt.run_dir.empty()) {
          std::ofstream(opt.run_dir + "/centrifuge.md") << rep.markdown;
          result += "  centrifuge report   " + opt.run_dir + "/centrifuge.md (prototype footing " +
                    fmt::format("{:.4g}", rep.diameter_proto_m * 1e3) + " mm, peak " +
                    fmt::format("{:.4g}", rep.peak_proto_N) + " N; load cell " +
                    fmt::format("{:g}", rep.load_cell_range_model_N) + " N at model scale)\n";
        }
      } catch (const std::exception& e) {
        log->warn("no footing result: {}", e.what());
      }
      break;
    }
    auto text = coord::summary_text(info, sum) + result;
    log->info("run finished\n{}", text);
    if (!opt.run_dir.empty()) {
      std::ofstream(opt.run_dir + "/summary.txt") << text;
      std::ofstream(opt.run_dir + "/summary.json") << coord::summary_json(info, sum);
    }
    std::cout << text;
    return 0;
  } catch (const proto::ShutdownRequested& e) {
    std::cerr << "\n";
    log->error("{}", e.what());
    if (ep) ep->shutdown(e.what());
    return 130;
  } catch (const std::exception& e) {
    log->error("run failed: {}", e.what());
    std::cerr << "coordinator: run failed: " << e.what() << "\n";
    if (ep) ep->shutdown(std::string("coordinator: ") + e.what());
    if (!opt.run_dir.empty()) std::ofstream(opt.run_dir + "/summary.txt") << "FAILED: " << e.what() << "\n";
    return 3;
  }
}
