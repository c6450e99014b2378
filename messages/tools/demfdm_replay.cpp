// demfdm_replay: drive a continuum solver from a recorded traffic log, with no DEM node.
//
//   demfdm_replay LOG --solver EXE [--out STEPS.csv] [--lcm-url URL] [--expect-identical]
//
// Starts EXE as the continuum node of a new run (fresh run id, its outputs in a temporary
// folder), plays the recorded coordinator (scene, then every STAGE_BEGIN / GRANT / STAGE_END
// addressed to the continuum, in log order, with the recorded dt and values) and the recorded
// DEM (the iface_force of every step, sent before the grant that needs it, as the DEM would),
// collects the solver's iface_kin answers and compares them with the recorded ones.
// Reports the largest absolute difference of positions and velocities per step (stdout, or
// STEPS.csv with --out) and a summary line:
//   replay: N steps compared, I bit-identical, max |dx| = ..., max |dv| = ...
// Run it inside a private network namespace (launch/replay does) or give --lcm-url.
// The whole log is read and checked before the solver starts (traffic_log.hpp: event framing,
// every payload decoded, the checksums of demfdm_log merge): an empty, truncated or corrupt log
// is reported as such ("demfdm_replay: FILE: corrupt log: event 7 at byte 2345 ...; nothing was
// replayed", exit 2) and nothing of it reaches the solver. A log without checksums (a wire
// capture, a log merged before they existed) is replayed with a warning: a damaged number in
// it cannot be told from a solver difference.
// Exit codes: 0 replayed (1 with --expect-identical when any answer differs), 2 bad command
// line / empty, truncated or corrupt log / log without a scene, 3 the solver failed or the
// protocol broke, 4 the log lacks the DEM forces of a step (the steps before it are still
// compared and reported).
#include <fcntl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <random>
#include <set>
#include <thread>

#include "common/schema/scene_schema.hpp"
#include "messages/protocol.hpp"
#include "traffic_log.hpp"

using namespace demfdm;
namespace fs = std::filesystem;

namespace {

int usage(const std::string& why) {
  std::cerr << "demfdm_replay: " << why
            << "\nusage: demfdm_replay LOG --solver EXE [--out STEPS.csv] [--lcm-url URL] [--expect-identical] [-v]\n";
  return 2;
}

pid_t spawn(const std::vector<std::string>& argv, const std::string& out_file) {
  pid_t pid = fork();
  if (pid == 0) {
    int fd = ::open(out_file.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (fd >= 0) {
      dup2(fd, 1);
      dup2(fd, 2);
    }
    std::vector<char*> a;
    for (auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
    a.push_back(nullptr);
    execvp(a[0], a.data());
    _exit(127);
  }
  return pid;
}

// Exit status after up to timeout_s, or -1.
int wait_exit(pid_t pid, double timeout_s) {
  auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    int st = 0;
    if (waitpid(pid, &st, WNOHANG) == pid) return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) return -1;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
}

struct LogIncomplete : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct Diff {
  std::int64_t step;
  double dx, dv;
  bool identical;
};

Diff compare(std::int64_t step, const proto::Kinematics& got, const traffic::StepKin& rec) {
  Diff d{step, 0, 0, true};
  if (got.positions.size() != rec.positions.size() || got.velocities.size() != rec.velocities.size()) {
    d.dx = d.dv = INFINITY;
    d.identical = false;
    return d;
  }
  for (std::size_t i = 0; i < got.positions.size(); ++i) {
    d.dx = std::max(d.dx, std::abs(got.positions[i] - rec.positions[i]));
    d.dv = std::max(d.dv, std::abs(got.velocities[i] - rec.velocities[i]));
    // Bit identity (also tells +0 from -0 apart and catches NaN).
    if (std::memcmp(&got.positions[i], &rec.positions[i], sizeof(double)) != 0 ||
        std::memcmp(&got.velocities[i], &rec.velocities[i], sizeof(double)) != 0)
      d.identical = false;
  }
  return d;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage("expected a log file");
  std::string log_path = argv[1], solver, out, url;
  bool expect_identical = false, verbose = false;
  for (int i = 2; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&](const std::string& key) -> std::optional<std::string> {
      if (a == key && i + 1 < argc) return std::string(argv[++i]);
      if (a.rfind(key + "=", 0) == 0) return a.substr(key.size() + 1);
      return std::nullopt;
    };
    if (auto v = value("--solver")) solver = *v;
    else if (auto o = value("--out")) out = *o;
    else if (auto u = value("--lcm-url")) url = *u;
    else if (a == "--expect-identical") expect_identical = true;
    else if (a == "-v") verbose = true;
    else return usage("unknown argument '" + a + "'");
  }
  if (solver.empty()) return usage("--solver EXE is required");

  traffic::Log log;
  config::Scene scene;
  try {
    log = traffic::read_log(log_path);
    if (log.scene_text.empty()) return usage(log_path + ": the log holds no complete scene broadcast (DEMFDM_SCENE)");
    scene = config::Scene::parse(log.scene_text, log.scene_origin, schema::scene_schema());
  } catch (const traffic::LogError& e) {
    std::cerr << "demfdm_replay: " << e.what() << "; nothing was replayed\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "demfdm_replay: " << e.what() << "\n";
    return 2;
  }
  if (!log.checksummed)
    std::cerr << "demfdm_replay: warning: " << log_path
              << " has no checksums (not written by demfdm_log merge): a damaged number in it cannot be told "
                 "from a solver difference\n";
  auto stages = schema::stages(scene);
  bool parallel = scene.has("coupling") && scene.string("coupling.scheme") == "parallel";

  // The recorded coordinator's commands for the continuum, in order, without resends.
  std::vector<demfdm::command_t> commands;
  std::set<std::tuple<std::int32_t, std::int64_t, std::int32_t>> seen;
  for (const auto& e : log.events) {
    if (e.channel != bus::channel::kCommand) continue;
    demfdm::command_t c;
    if (!traffic::decode(e, c) || c.header.run_id != log.run_id || c.header.sender != "coordinator") continue;
    if (c.target != "*" && c.target != "continuum") continue;
    if (c.command == demfdm::command_t::SHUTDOWN) break;
    if (!seen.insert({c.command, c.header.step, c.stage_index}).second) continue;
    commands.push_back(c);
  }

  std::mt19937_64 rng(std::random_device{}());
  std::int64_t run_id = static_cast<std::int64_t>(rng() % 1000000000000ULL) + 1;
  if (url.empty()) url = "udpm://239.255.76.67:" + std::to_string(20000 + rng() % 40000) + "?ttl=0";
  fs::path dir = fs::temp_directory_path() / ("demfdm-replay-" + std::to_string(run_id));
  fs::create_directories(dir);
  pid_t pid = -1;
  int rc = 0;
  std::vector<Diff> diffs;
  try {
    auto lcm = std::make_shared<lcm::LCM>(bus::resolve_url(url));
    bus::Bus coord_bus(lcm, run_id, "coordinator"), dem_bus(lcm, run_id, "dem");
    proto::CoordinatorEndpoint coord(coord_bus);
    proto::NodeEndpoint dem(dem_bus, "dem", "demfdm_replay");
    std::vector<std::string> args{solver, "--lcm-url=" + url, "--run-id=" + std::to_string(run_id),
                                  "--run-dir=" + dir.string()};
    if (verbose) args.push_back("-v");
    pid = spawn(args, (dir / "solver.out").string());
    coord.start(scene.text(), scene.origin(), scene.hash(), {"continuum"});
    std::cerr << "demfdm_replay: " << solver << " (" << coord.nodes().at("continuum").solver << ") replays "
              << commands.size() << " commands of run " << log.run_id << "\n";
    bool mesh_done = false;
    std::int64_t forces_sent_to = std::numeric_limits<std::int64_t>::min(), last = -1;
    auto send_forces_to = [&](std::int64_t k) {
      for (auto it = log.force.upper_bound(forces_sent_to); it != log.force.end() && it->first <= k; ++it) {
        if (!it->second.complete()) continue;
        proto::Forces f;
        f.step = it->first;
        f.forces = it->second.forces;
        f.stiffness = it->second.stiffness;
        f.total = it->second.total;
        dem.send_forces(f);
        forces_sent_to = it->first;
      }
    };
    auto check_kin = [&](std::int64_t k) {
      auto rec = log.kin.find(k);
      if (rec == log.kin.end() || !rec->second.complete()) return;  // nothing recorded to compare with
      diffs.push_back(compare(k, dem.wait_kin(k), rec->second));
    };
    try {
      for (const auto& c : commands) {
        if (verbose)
          std::cerr << "demfdm_replay: command " << c.command << " step " << c.header.step << " stage " << c.stage_index
                    << "\n";
        const auto& st = stages.at(static_cast<std::size_t>(c.stage_index));
        if (c.command == demfdm::command_t::STAGE_BEGIN) {
          coord.command(c.command, {"continuum"}, c.header.step, c.stage_index, c.stage_name, c.dt, c.values);
          if (st.coupled) {
            if (!mesh_done) dem.wait_mesh();
            mesh_done = true;
            check_kin(c.header.step);
            if (parallel) send_forces_to(c.header.step);
          }
          last = c.header.step;
        } else if (c.command == demfdm::command_t::GRANT) {
          if (st.coupled) {
            // Every step of the grant needs the DEM's recorded forces; a log that lost them (the
            // logger drops messages under load: demfdm_log summary shows the seq gaps) ends the replay.
            for (std::int64_t k = last + 1; k <= c.header.step; ++k) {
              auto need = parallel ? k - 1 : k;
              auto it = log.force.find(need);
              if (it == log.force.end() || !it->second.complete())
                throw LogIncomplete("the log lacks the DEM forces of step " + std::to_string(need) +
                                    " (lost by the logger? see demfdm_log summary); replay stopped before step " +
                                    std::to_string(k));
            }
            send_forces_to(parallel ? c.header.step - 1 : c.header.step);
          }
          coord.command(c.command, {"continuum"}, c.header.step, c.stage_index, c.stage_name, c.dt, c.values);
          if (st.coupled)
            for (std::int64_t k = last + 1; k <= c.header.step; ++k) check_kin(k);
          last = c.header.step;
        } else {
          coord.command(c.command, {"continuum"}, c.header.step, c.stage_index, c.stage_name, c.dt, c.values);
        }
      }
    } catch (const LogIncomplete& e) {
      std::cerr << "demfdm_replay: " << e.what() << "\n";
      rc = 4;
    }
    coord.shutdown("replay done");
    int code = wait_exit(pid, 5.0);
    if (code != 0) {
      std::cerr << "demfdm_replay: the solver " << (code < 0 ? "did not exit after SHUTDOWN" : "exited with code " + std::to_string(code)) << "\n";
      rc = 3;
    }
    if (code >= 0) pid = -1;
  } catch (const std::exception& e) {
    std::cerr << "demfdm_replay: " << e.what() << "\n";
    std::ifstream so(dir / "solver.out");
    std::cerr << "--- solver output ---\n" << so.rdbuf() << "\n";
    rc = 3;
  }
  if (pid > 0) {
    kill(pid, SIGKILL);
    waitpid(pid, nullptr, 0);
  }
  std::error_code ec;
  fs::remove_all(dir, ec);

  std::FILE* f = stdout;
  if (!out.empty() && !(f = std::fopen(out.c_str(), "w"))) {
    std::cerr << "demfdm_replay: cannot write " << out << "\n";
    return 2;
  }
  std::fprintf(f, "step,max_abs_dx_m,max_abs_dv,identical\n");
  std::size_t same = 0;
  double dx = 0, dv = 0;
  for (const auto& d : diffs) {
    std::fprintf(f, "%lld,%.17g,%.17g,%d\n", static_cast<long long>(d.step), d.dx, d.dv, d.identical ? 1 : 0);
    same += d.identical;
    dx = std::max(dx, d.dx);
    dv = std::max(dv, d.dv);
  }
  if (f != stdout) std::fclose(f);
  std::printf("replay: %zu steps compared, %zu bit-identical, max |dx| = %.6g m, max |dv| = %.6g\n", diffs.size(), same,
              dx, dv);
  if (rc != 0) return rc;
  if (diffs.empty()) {
    std::cerr << "demfdm_replay: the log holds no interface kinematics to compare\n";
    return 3;
  }
  return expect_identical && same != diffs.size() ? 1 : 0;
}
