// coordinator: validates the scene, starts the protocol, runs the stages, ends the run.
//
//   coordinator SCENE --check              validate only (exit 0, or 2 with one error line)
//   coordinator SCENE --print-nodes        "role executable" lines for launch/run
//   coordinator --help-scene [--markdown]  every scene key with unit, default and doc
//   coordinator SCENE --run-id=N [--lcm-url=URL] [--run-dir=DIR] [-v]
//
// Exit codes: 0 finished, 2 bad command line or scene, 3 a node failed, died or went silent
// (named in the message), 130 interrupted.
#include <unistd.h>

#include <cmath>
#include <csignal>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <optional>
#include <sstream>
#include <variant>

#include "common/log/log.hpp"
#include "coordinator/core/quasi_static.hpp"
#include "coordinator/core/runner.hpp"
#include "coordinator/core/summary.hpp"
#include "messages/node_runtime.hpp"
#include "messages/protocol.hpp"

using namespace demfdm;

namespace {

const char* kUsage =
    "usage: coordinator SCENE [--check | --print-nodes] [--run-id=N] [--lcm-url=URL] [--run-dir=DIR] [-v]\n"
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

// Per-stage history of every value the nodes report, one CSV per stage, one row per grant.
class History {
 public:
  explicit History(std::string dir) : dir_(std::move(dir)) {}
  void record(const schema::Stage& st, std::int64_t step, const std::map<std::string, coord::NodeReport>& reps) {
    if (dir_.empty()) return;
    if (st.name != current_) {
      current_ = st.name;
      out_.close();
      cols_.clear();
      for (auto& [role, r] : reps)
        for (auto& [k, v] : r.values) cols_.push_back({role, k});
      std::string path = dir_ + "/history_" + std::to_string(index_++) + "_" + st.name + ".csv";
      out_.open(path);
      out_ << "step";
      for (auto& [role, r] : reps) out_ << "," << role << ".time_s";
      for (auto& [role, k] : cols_) out_ << "," << role << "." << k;
      out_ << "\n";
    }
    out_ << step;
    out_ << std::setprecision(17);
    for (auto& [role, r] : reps) out_ << "," << r.time;
    for (auto& [role, k] : cols_) {
      auto it = reps.find(role);
      double v = std::nan("");
      if (it != reps.end()) {
        auto jt = it->second.values.find(k);
        if (jt != it->second.values.end()) v = jt->second;
      }
      out_ << "," << v;
    }
    out_ << "\n";
    out_.flush();
  }

 private:
  std::string dir_, current_;
  int index_ = 0;
  std::ofstream out_;
  std::vector<std::pair<std::string, std::string>> cols_;
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
  double rho_b = scene.real("dem.specimen.bulk_density");
  if (rho_b < 0) rho_b = 0.48 * scene.real("dem.density");
  std::optional<double> sigma_c;
  const auto& model = scene.string("dem.ball_ball.model");
  if (model == "softbond") sigma_c = scene.real("dem.ball_ball.sb_ten");
  if (model == "pbond" && scene.real("dem.ball_ball.pb_ten") >= 0) sigma_c = scene.real("dem.ball_ball.pb_ten");
  double speed = stage_speed(scene, st);
  return coord::rate_measures(speed, v.real("inertial_number"),
                              coord::ramp_time(v.real("ramp_depth_ratio"), scene.real("dem.footing.diameter"), speed),
                              young, poisson, rho_b, sigma_c, v.real("quasi_static_limit"));
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> pos;
  node::Options opt;
  try {
    opt = node::parse_options(argc, argv, &pos, {"--check", "--print-nodes", "--help-scene", "--markdown", "--help", "-h"});
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
       markdown = flag("--markdown"), help = flag("--help") || flag("-h");
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
  config::Scene scene;
  try {
    scene = config::Scene::load(pos[0], schema::scene_schema());
  } catch (const config::Error& e) {
    std::cerr << e.what() << "\n";
    return 2;
  }
  auto roles = schema::roles(scene);
  if (check) {
    std::cout << pos[0] << ": OK (" << schema::stages(scene).size() << " stages; nodes:";
    for (auto& r : roles) std::cout << " " << r << "=" << schema::executable(scene, r);
    std::cout << ")\n";
    return 0;
  }
  if (print_nodes) {
    for (auto& r : roles) std::cout << r << " " << schema::executable(scene, r) << "\n";
    return 0;
  }

  auto log = log::setup("coordinator", opt.run_dir, opt.verbose);
  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
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
    BusDriver driver(*ep);
    coord::Runner runner(schema::stages(scene), driver, dt,
                         scene.has("coupling") ? scene.integer("coupling.window") : 1);
    // Footing kinematics (docs/theory.md §7.1): the rate-rule speed v (stage_speed), ramped up
    // from 0 over t_r = 2 ramp_depth_ratio D_f / v at the stage's start, evaluated at the middle
    // of the grant's steps in the stage's own time (steps are global over the run). The rate
    // and quasi-static measures are logged at each penetrate stage's first grant.
    std::map<std::size_t, coord::RateMeasures> rates;
    {
      auto sts = schema::stages(scene);
      for (std::size_t i = 0; i < sts.size(); ++i)
        if (sts[i].action == "penetrate") rates[i] = stage_rates(scene, sts[i]);
    }
    runner.set_kinematics([&runner, &rates, &log](const schema::Stage& st, std::int64_t, double) -> std::vector<double> {
      if (st.action != "penetrate") return {};
      const auto& clock = runner.grant_clock();
      const auto& m = rates.at(static_cast<std::size_t>(clock.stage_index));
      if (clock.first_step == clock.stage_first_step) {
        log->info("stage '{}' footing rate: {}", st.name, coord::describe(m));
        if (auto w = coord::quasi_static_warning(st.name, m); !w.empty()) log->warn("{}", w);
      }
      return {coord::ramped_speed(m.speed, clock.t_mid(), m.ramp_time)};
    });
    History hist(opt.run_dir);
    runner.set_observer([&](const schema::Stage& st, std::int64_t step, const auto& reps) { hist.record(st, step, reps); });
    auto sum = runner.run();
    ep->shutdown("run finished");
    auto info = run_info(scene, *ep, bus->stats());
    info.rates = rates;
    auto text = coord::summary_text(info, sum);
    log->info("run finished\n{}", text);
    if (!opt.run_dir.empty()) {
      std::ofstream(opt.run_dir + "/summary.txt") << text;
      std::ofstream(opt.run_dir + "/summary.json") << coord::summary_json(info, sum);
    }
    std::cout << text;
    return 0;
  } catch (const proto::ShutdownRequested& e) {
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
