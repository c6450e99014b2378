#include "common/node/node_runtime.hpp"

#include <cmath>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <sys/resource.h>
#include <time.h>
#include <unistd.h>

#include "common/log/log.hpp"

namespace demfdm::node {

proto::InterfaceMesh Participant::interface_mesh() {
  throw std::logic_error("this solver cannot play the continuum side of a coupled stage");
}
proto::Kinematics Participant::interface_kinematics() {
  throw std::logic_error("this solver cannot play the continuum side of a coupled stage");
}
void Participant::apply_interface_forces(const proto::Forces&) {
  throw std::logic_error("this solver cannot play the continuum side of a coupled stage");
}
void Participant::set_interface_mesh(const proto::InterfaceMesh&) {
  throw std::logic_error("this solver cannot play the DEM side of a coupled stage");
}
void Participant::set_interface_kinematics(const proto::Kinematics&) {
  throw std::logic_error("this solver cannot play the DEM side of a coupled stage");
}
proto::Forces Participant::interface_forces() {
  throw std::logic_error("this solver cannot play the DEM side of a coupled stage");
}

void Participant::save(const std::filesystem::path&, io::StateWriter&, const io::StateMeta&) {
  throw std::logic_error("this solver cannot save its state");
}
void Participant::restore(io::StateReader&, const Restore&) {
  throw std::logic_error("this solver cannot restore a saved state");
}

void EnergyJump::save(io::StateWriter& w) const {
  w.f64s(std::vector<double>(last_.begin(), last_.end()));
  w.u64(at_.size());
  for (auto a : at_) w.u64(a);
  w.u64(n_);
}
void EnergyJump::load(io::SectionReader& r) {
  auto last = r.f64s();
  auto n_at = r.count(8);
  if (n_at != last.size()) r.fail("energy-jump window: " + std::to_string(last.size()) + " values, " + std::to_string(n_at) + " indices");
  last_.assign(last.begin(), last.end());
  at_.clear();
  for (std::uint64_t i = 0; i < n_at; ++i) at_.push_back(r.u64());
  n_ = r.u64();
}

EnergyJump::EnergyJump(const config::Scene& s)
    : EnergyJump(s.real("run.guard_energy_jump"), s.real("run.guard_energy_floor"),
                 static_cast<std::size_t>(s.integer("run.guard_energy_window"))) {}

std::optional<std::string> EnergyJump::check(double e) {
  if (factor_ <= 0) return std::nullopt;
  while (!at_.empty() && at_.front() + window_ < n_) {
    at_.pop_front();
    last_.pop_front();
  }
  const double ref = std::max(floor_, last_.empty() ? 0.0 : last_.front());
  if (e > factor_ * ref) {
    std::ostringstream os;
    os << "kinetic energy jumped to " << e << " J, above " << factor_ << " x " << ref
       << " J (the largest of the previous " << window_ << " checks, floor " << floor_ << " J)";
    return os.str();
  }
  while (!last_.empty() && last_.back() <= e) {
    last_.pop_back();
    at_.pop_back();
  }
  last_.push_back(e);
  at_.push_back(n_++);
  return std::nullopt;
}

namespace {
// A guard report stops the run: the text names the cause and the step.
struct BlowUp : std::runtime_error {
  using std::runtime_error::runtime_error;
};

void guard(Participant& part, std::int64_t step, std::int64_t every, const std::string& role, const Options& opt) {
  if (every <= 0 || step % every != 0) return;
  auto h = part.check_health(step);
  if (!h) return;
  std::string where = "no run folder";
  if (!opt.run_dir.empty()) {
    auto path = opt.run_dir + "/blowup_" + role + ".txt";
    std::ofstream f(path);
    f << "blow-up guard of the " << role << " node at step " << step << " (time " << part.time() << " s)\n"
      << "cause: " << h->cause << "\n\n"
      << h->detail << (h->detail.empty() || h->detail.back() == '\n' ? "" : "\n");
    where = "report in " + path;
  }
  throw BlowUp("blow-up guard: " + h->cause + " (" + where + ")");
}

// CPU time of the whole process (every thread, user + system) [s]: the STAGE_END report's
// "cpu_s" is its increase over the stage, from which the summary gives each node's CPU
// utilisation (cores kept busy).
double process_cpu_s() {
  timespec ts{};
  if (clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts) != 0) return 0.0;
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
}  // namespace

double process_peak_rss_mb() {
  rusage ru{};
  if (getrusage(RUSAGE_SELF, &ru) != 0) return 0.0;
  return static_cast<double>(ru.ru_maxrss) / 1024.0;  // (Linux: kilobytes)
}

Options parse_options(int argc, char** argv, std::vector<std::string>* positional,
                      const std::vector<std::string>& flags) {
  Options o;
  auto value = [](const std::string& a, const std::string& key, std::string& out) {
    if (a.rfind(key + "=", 0) == 0) {
      out = a.substr(key.size() + 1);
      return true;
    }
    return false;
  };
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i], v;
    if (value(a, "--lcm-url", v)) {
      o.url = v;
    } else if (value(a, "--run-id", v)) {
      char* end = nullptr;
      o.run_id = std::strtoll(v.c_str(), &end, 10);
      if (v.empty() || *end != '\0')
        throw std::invalid_argument("--run-id: expected an integer, found '" + v + "'");
    } else if (value(a, "--run-dir", v)) {
      o.run_dir = v;
    } else if (a == "-v" || a == "--verbose") {
      o.verbose = true;
    } else if (std::find(flags.begin(), flags.end(), a) != flags.end() && positional) {
      positional->push_back(a);
    } else if (!a.empty() && a[0] == '-') {
      throw std::invalid_argument("unknown option '" + a + "'");
    } else if (positional) {
      positional->push_back(a);
    } else {
      throw std::invalid_argument("unexpected argument '" + a + "'");
    }
  }
  return o;
}

namespace {
void on_signal(int s) { proto::request_interrupt(s); }
}  // namespace

namespace {
// NODE --check SCENE [--set table.key=value]...: everything this node checks when it receives the
// scene (the declared schema, then the adapter's mapping onto the engine's parameters and the
// engine's own validation, which runs when the participant is built), without a bus. Exit 0 with
// nothing printed, or 2 with one line naming file, line, key, expected and found.
int check_only(int argc, char** argv, const std::string& role, const std::string& solver, const Factory& make) {
  std::string scene;
  std::vector<std::string> sets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--check") continue;
    if (a == "--set" && i + 1 < argc) {
      sets.push_back(argv[++i]);
    } else if (a.rfind("--set=", 0) == 0) {
      sets.push_back(a.substr(6));
    } else if (!a.empty() && a[0] != '-' && scene.empty()) {
      scene = a;
    } else {
      std::cerr << solver << ": --check: unexpected argument '" << a << "'\nusage: " << solver
                << " --check SCENE [--set table.key=value]...\n";
      return 2;
    }
  }
  if (scene.empty()) {
    std::cerr << solver << ": --check needs a scene file\n";
    return 2;
  }
  spdlog::set_level(spdlog::level::warn);  // the participant's set-up notes are not wanted here
  try {
    Context ctx{Options{}, config::Scene::load(scene, schema::scene_schema(), sets), role};
    make(ctx);
  } catch (const config::Error& e) {
    std::cerr << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << scene << ": " << role << " (" << solver << ") rejects the scene: " << e.what() << "\n";
    return 2;
  }
  return 0;
}
}  // namespace

int run_node(int argc, char** argv, const std::string& role, const std::string& solver, const Factory& make) {
  for (int i = 1; i < argc; ++i)
    if (std::string(argv[i]) == "--check") return check_only(argc, argv, role, solver, make);
  Options opt;
  try {
    opt = parse_options(argc, argv);
  } catch (const std::exception& e) {
    std::cerr << solver << ": " << e.what() << "\nusage: " << solver
              << " --run-id=N [--lcm-url=URL] [--run-dir=DIR] [-v]\n       " << solver
              << " --check SCENE [--set table.key=value]...\n";
    return 2;
  }
  auto log = log::setup(role, opt.run_dir, opt.verbose);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);

  std::unique_ptr<bus::Bus> bus;
  std::unique_ptr<proto::NodeEndpoint> ep;
  std::unique_ptr<Participant> part;
  std::int64_t step = -1;
  std::int64_t cmd_step = -1;  // header.step of the command being worked on (for a FAILED report)
  std::int32_t stage_index = -1;
  try {
    bus = std::make_unique<bus::Bus>(bus::resolve_url(opt.url), opt.run_id, role);
    log->info("{} ({}) on {} run {} pid {}", role, solver, bus->url(), opt.run_id, ::getpid());
    proto::Timeouts t;
    ep = std::make_unique<proto::NodeEndpoint>(*bus, role, solver, t);
    std::string text = ep->wait_scene();
    Context ctx{opt, config::Scene(), role};
    try {
      ctx.scene = config::Scene::parse(text, ep->scene_origin(), schema::scene_schema());
    } catch (const config::Error& e) {
      log->error("scene rejected: {}", e.what());
      ep->report(-1, demfdm::report_t::FAILED, -1, 0.0, 0.0, 0.0, 0.0, {},
                 role + " (" + solver + ") rejected the scene: " + e.what());
      bus->pump(0.05);
      return 2;
    }
    log->info("scene {} (hash {:016x}) received", ep->scene_origin(), ctx.scene.hash());
    ep->set_timeouts(ctx.scene.real("bus.peer_timeout_s"), ctx.scene.real("bus.resend_after_s"));
    part = make(ctx);
    auto stages = schema::stages(ctx.scene);
    std::string scheme = ctx.scene.has("coupling") ? ctx.scene.string("coupling.scheme") : "serial";
    bool parallel = scheme == "parallel";
    const std::int64_t guard_every = ctx.scene.integer("run.guard_every");
    bool mesh_done = false;
    std::int64_t kin_applied = -2;  // DEM: step of the continuum kinematics last applied
    bool in_stage = false;          // between a STAGE_BEGIN and its STAGE_END
    double stage_cpu0 = process_cpu_s();  // process CPU time at the stage's begin (or restore)
    ep->hello(part->dt_stable());

    for (;;) {
      auto c = ep->next_command();
      // Waiting for the command counts as bus wait, not compute.
      double cmd_wait = ep->take_wait_s();
      cmd_step = c.header.step;
      auto t0 = std::chrono::steady_clock::now();
      auto compute = [&] {
        return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      };
      if (c.command == demfdm::command_t::SHUTDOWN) {
        log->info("shutdown: {}", c.text);
        part->finish();
        ep->heartbeat().stop();
        return 0;
      }
      if (c.stage_index < 0 || c.stage_index >= static_cast<std::int32_t>(stages.size()))
        throw proto::ProtocolError("command names stage " + std::to_string(c.stage_index) + ", the scene has " +
                                   std::to_string(stages.size()));
      const auto& st = stages[static_cast<std::size_t>(c.stage_index)];
      if (c.command == demfdm::command_t::CHECKPOINT) {
        // The whole node state after step header.step, in <run dir>/<text>/<role>.state (+ the
        // engine's files). Answered with state_saved = 0 by a solver that cannot save.
        proto::Values values{{"state_saved", 0.0}};
        if (part->can_checkpoint()) {
          if (opt.run_dir.empty()) throw std::runtime_error("a checkpoint needs a run folder (--run-dir)");
          // A node idle in the last stages stands at its own last step; none may be ahead.
          if (step > c.header.step)
            throw proto::ProtocolError("checkpoint after step " + std::to_string(c.header.step) + ", this node is after step " +
                                       std::to_string(step));
          const std::filesystem::path dir = std::filesystem::path(opt.run_dir) / c.text;
          std::filesystem::create_directories(dir);
          io::StateMeta meta;
          meta.scene_hash = ctx.scene.hash();
          io::StateWriter w("node", meta.code_version, meta.scene_hash);
          w.begin("runtime");
          w.str(role);
          w.str(solver);
          w.i64(step);
          w.i32(stage_index);
          w.b(in_stage);
          w.b(mesh_done);
          w.i64(kin_applied);
          w.end();
          part->save(dir, w, meta);
          auto bytes = w.bytes();
          io::write_atomically(dir / (role + ".state"), bytes);
          values = {{"state_saved", 1.0}, {"seconds", compute()}};
          log->info("checkpoint after step {} in {} ({:.3f} s)", step, dir.string(), compute());
        }
        double w = ep->take_wait_s();
        ep->report(c.header.step, demfdm::report_t::OK, c.stage_index, part->time(), part->dt_stable(), compute() - w,
                   w + cmd_wait, values);
        continue;
      }
      if (c.command == demfdm::command_t::RESTORE) {
        // text: "<checkpoint folder>\n<saved scene hash, decimal>\n<resume|branch>".
        std::istringstream ts(c.text);
        std::string dir_text, hash_text, mode;
        std::getline(ts, dir_text);
        std::getline(ts, hash_text);
        std::getline(ts, mode);
        Restore how{dir_text, std::stoull(hash_text), mode == "branch"};
        const auto path = how.dir / (role + ".state");
        io::StateReader r(io::read_whole_file(path), path.string(), "node", how.saved_scene_hash);
        auto rt = r.section("runtime");
        auto saved_role = rt.str(), saved_solver = rt.str();
        if (saved_role != role || saved_solver != solver)
          throw std::runtime_error(path.string() + ": saved by " + saved_role + " (" + saved_solver + "), this node is " + role +
                                   " (" + solver + ")");
        step = rt.i64();
        stage_index = rt.i32();
        in_stage = rt.b();
        mesh_done = rt.b();
        kin_applied = rt.i64();
        rt.done();
        part->restore(r, how);
        r.finish();
        stage_cpu0 = process_cpu_s();
        log->info("restored the state after step {} (stage {}, {}) from {}", step, stage_index,
                  in_stage ? "inside the stage" : "at its end", how.dir.string());
        // Inside a coupled stage the interface data of the saved step is in flight: the
        // continuum sends kin(step) again, and in the parallel scheme the DEM force(step).
        if (in_stage && stages[static_cast<std::size_t>(stage_index)].coupled) {
          if (role == "continuum") {
            auto k = part->interface_kinematics();
            k.step = step;
            ep->send_kin(k);
          } else if (parallel) {
            auto f = part->interface_forces();
            f.step = step;
            ep->send_forces(f);
          }
        }
        double w = ep->take_wait_s();
        ep->report(c.header.step, demfdm::report_t::OK, c.stage_index, part->time(), part->dt_stable(), compute() - w,
                   w + cmd_wait, {{"step", static_cast<double>(step)}});
        continue;
      }
      stage_index = c.stage_index;
      if (c.command == demfdm::command_t::STAGE_BEGIN) {
        in_stage = true;
        stage_cpu0 = process_cpu_s();
        log->info("stage {} '{}' ({}) begins after step {}", c.stage_index, st.name, st.action, c.header.step);
        auto values = part->stage_begin(st, c.header.step + 1);
        step = c.header.step;
        if (st.coupled) {
          if (role == "continuum") {
            if (!mesh_done) ep->send_mesh(part->interface_mesh());
            auto k = part->interface_kinematics();
            k.step = step;
            ep->send_kin(k);
          } else {
            if (!mesh_done) part->set_interface_mesh(ep->wait_mesh());
            if (parallel) {
              part->set_interface_kinematics(ep->wait_kin(step));
              kin_applied = step;
              auto f = part->interface_forces();
              f.step = step;
              ep->send_forces(f);
            }
          }
          mesh_done = true;
        }
        double w = ep->take_wait_s();
        ep->report(c.header.step, demfdm::report_t::OK, c.stage_index, part->time(), part->dt_stable(),
                   compute() - w, w + cmd_wait, values);
      } else if (c.command == demfdm::command_t::GRANT) {
        const bool block = c.header.step > step + 1;  // a multi-step grant reports one row per step
        std::vector<std::pair<std::int64_t, std::vector<double>>> rows;
        proto::Values last_values;
        for (std::int64_t k = step + 1; k <= c.header.step; ++k) {
          if (st.coupled && role == "dem" && kin_applied != k - 1) {
            part->advance_early(st, k, c.dt, c.values);  // overlaps the continuum's step k - 1
            part->set_interface_kinematics(ep->wait_kin(k - 1));
            kin_applied = k - 1;
          }
          if (st.coupled && role == "continuum") part->apply_interface_forces(ep->wait_forces(parallel ? k - 1 : k));
          part->advance(st, k, c.dt, c.values);
          guard(*part, k, guard_every, role, opt);
          ep->heartbeat().tick();
          if (st.coupled && role == "dem") {
            auto f = part->interface_forces();
            f.step = k;
            ep->send_forces(f);
          }
          if (st.coupled && role == "continuum") {
            auto kin = part->interface_kinematics();
            kin.step = k;
            ep->send_kin(kin);
          }
          step = k;
          if (block) {
            last_values = part->step_values();
            last_values.insert(last_values.begin(), {"time_s", part->time()});
            std::vector<double> row;
            for (auto& kv : last_values) row.push_back(kv.second);
            rows.emplace_back(k, std::move(row));
          }
        }
        // Bus waits inside the grant (interface data) are not compute time.
        double w = ep->take_wait_s();
        auto status = part->criterion_met(st) ? demfdm::report_t::STAGE_DONE : demfdm::report_t::OK;
        ep->report(c.header.step, status, c.stage_index, part->time(), part->dt_stable(), compute() - w, w + cmd_wait,
                   block ? last_values : part->step_values(), {}, rows);
      } else if (c.command == demfdm::command_t::STAGE_END) {
        in_stage = false;
        auto values = part->stage_end(st, c.header.step);
        values.push_back({"cpu_s", process_cpu_s() - stage_cpu0});
        values.push_back({"peak_rss_mb", process_peak_rss_mb()});
        std::ostringstream vs;
        vs.precision(10);
        for (auto& [k, v] : values) vs << " " << k << "=" << v;
        log->info("stage {} '{}' ends after step {}; values:{}", c.stage_index, st.name, c.header.step, vs.str());
        double w = ep->take_wait_s();
        ep->report(c.header.step, demfdm::report_t::OK, c.stage_index, part->time(), part->dt_stable(),
                   compute() - w, w + cmd_wait, values);
      }
    }
  } catch (const proto::ShutdownRequested& e) {
    log->warn("{}", e.what());
    if (part) part->finish();
    return proto::interrupted() ? 130 : 0;
  } catch (const std::exception& e) {
    log->error("{} failed at step {}: {}", role, step + 1, e.what());
    if (ep) {
      try {
        ep->report(cmd_step, demfdm::report_t::FAILED, stage_index, part ? part->time() : 0.0, 0.0, 0.0, 0.0, {},
                   role + " at step " + std::to_string(step + 1) + ": " + e.what());
        bus->pump(0.05);
      } catch (...) {
      }
    }
    if (part) {
      try {
        part->finish();
      } catch (...) {
      }
    }
    return 3;
  }
}

}  // namespace demfdm::node
