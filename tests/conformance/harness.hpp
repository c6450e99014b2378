// Test harness of the conformance kit: one continuum solver process driven by an in-process
// coordinator (CoordinatorEndpoint) and DEM (NodeEndpoint, role "dem") on one shared LCM
// instance. Used by conformance_test.cpp and traffic_test.cpp.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <random>
#include <set>

#include "common/config/config.hpp"
#include "common/schema/scene_schema.hpp"
#include "messages/protocol.hpp"
#include "tests/integration/process.hpp"

namespace demfdm::conformance {
namespace fs = std::filesystem;


inline constexpr double kE = 1.0e8, kNu = 0.25;
// Box 2 x 2 x 3 mm; pocket = the top 1 mm over the whole footprint (a column of 2 mm).
inline std::string column_scene(bool gravity, double ratio) {
  std::string s = R"(
[run]
name = "conformance-column"
threads = 1
)";
  if (gravity) s += "\n[gravity]\nlevel = 100\n";
  s += R"(
[dem]
[dem.specimen]
cell = [2e-3, 2e-3, 1e-3]
replicate = [1, 1, 1]

[continuum]
mode = "static"
[continuum.mesh]
size = [2e-3, 2e-3, 3e-3]
inner_size = [2e-3, 2e-3, 1e-3]
size_near = 0.5e-3
size_far = 0.5e-3

[[continuum.material]]
model = "elastic"
young = 1.0e8
poisson = 0.25
density = 1000.0

[coupling]
scheme = "serial"
interval = 1

[[stage]]
name = "load"
action = "equilibrium"
coupled = true
until = "done"
)";
  char buf[64];
  std::snprintf(buf, sizeof buf, "ratio = %.3g\nsteps = 100000\n", ratio);
  s += buf;
  return s;
}

// A box with an interior pocket open at the top (as in the footing scenes).
inline std::string pocket_scene() {
  return R"(
[run]
name = "conformance-pocket"
threads = 1

[dem]
[dem.specimen]
cell = [1e-3, 1e-3, 1.5e-3]
replicate = [1, 1, 1]

[continuum]
mode = "static"
[continuum.mesh]
size = [3e-3, 3e-3, 3e-3]
inner_size = [1e-3, 1e-3, 1.5e-3]
size_near = 0.5e-3
size_far = 1e-3

[[continuum.material]]
young = 1.0e8
poisson = 0.25

[coupling]
scheme = "serial"

[[stage]]
name = "couple"
action = "couple"
coupled = true
steps = 100
)";
}

// One solver process with an in-process coordinator and DEM on one shared LCM instance.
class Harness {
 public:
  Harness(const std::vector<std::string>& solver, const std::string& scene_text,
          const std::vector<std::string>& solver_env = {}, const std::string& url = {}) {
    static std::mt19937_64 rng(std::random_device{}());
    run_id_ = static_cast<std::int64_t>(rng() % 1000000000000ULL) + 1;
    int port = 20000 + static_cast<int>(rng() % 40000);
    url_ = url.empty() ? "udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0" : url;
    dir_ = fs::temp_directory_path() / ("demfdm-conformance-" + std::to_string(run_id_));
    fs::create_directories(dir_);
    scene_ = config::Scene::parse(scene_text, "conformance.toml", schema::scene_schema());
    auto argv = solver;
    argv.push_back("--lcm-url=" + url_);
    argv.push_back("--run-id=" + std::to_string(run_id_));
    argv.push_back("--run-dir=" + dir_.string());
    lcm_ = std::make_shared<lcm::LCM>(bus::resolve_url(url_));
    coord_bus_ = std::make_unique<bus::Bus>(lcm_, run_id_, "coordinator");
    dem_bus_ = std::make_unique<bus::Bus>(lcm_, run_id_, "dem");
    probe_ = std::make_unique<bus::Bus>(lcm_, run_id_, "probe");
    probe_->subscribe<demfdm::hello_t>(bus::channel::kHello, [this](const demfdm::hello_t& h) { hellos_.push_back(h); });
    coord_ = std::make_unique<proto::CoordinatorEndpoint>(*coord_bus_);
    dem_ = std::make_unique<proto::NodeEndpoint>(*dem_bus_, "dem", "conformance-kit");
    proc_ = demfdm::testing::spawn(argv, solver_env, (dir_ / "solver.out").string());
    coord_->start(scene_.text(), scene_.origin(), scene_.hash(), {"continuum"});
  }
  ~Harness() {
    if (proc_.pid > 0 && !demfdm::testing::wait_for(proc_, 0.0)) {
      coord_->shutdown("test ended");
      if (!demfdm::testing::wait_for(proc_, 2.0)) demfdm::testing::kill_and_reap(proc_);
    }
    dem_.reset();
    coord_.reset();
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  std::string solver_output() const { return demfdm::testing::read_file((dir_ / "solver.out").string()); }

  const std::string& url() const { return url_; }
  const std::vector<demfdm::hello_t>& hellos() const { return hellos_; }
  std::uint64_t hash() const { return scene_.hash(); }

  // STAGE_BEGIN of stage 0: returns the mesh and kin(-1).
  std::pair<proto::InterfaceMesh, proto::Kinematics> begin() {
    auto r = coord_->command(demfdm::command_t::STAGE_BEGIN, {"continuum"}, -1, 0, "load", 0.0, {});
    mesh_ = dem_->wait_mesh();
    auto k = dem_->wait_kin(-1);
    step_ = -1;
    return {mesh_, k};
  }
  // Sends force(k) for the next n steps (the same forces each step), grants them in one
  // command (or one command per step) and returns the last report and kin(last).
  std::pair<demfdm::report_t, proto::Kinematics> steps(const std::vector<double>& f, int n, bool one_grant = true) {
    demfdm::report_t rep;
    for (int i = 1; i <= n; ++i) {
      proto::Forces F;
      F.step = step_ + i;
      F.forces = f;
      F.stiffness.assign(f.size() / 3, 0.0);
      for (std::size_t j = 0; j < f.size(); ++j) F.total[j % 3] += f[j];
      dem_->send_forces(F);
      if (!one_grant) rep = grant(step_ + i);
    }
    if (one_grant) rep = grant(step_ + n);
    step_ += n;
    return {rep, dem_->wait_kin(step_)};
  }
  demfdm::report_t grant(std::int64_t k) {
    auto r = coord_->command(demfdm::command_t::GRANT, {"continuum"}, k, 0, "load", 1e-6, {});
    return r.at("continuum");
  }
  // Grants in blocks until the solver reports STAGE_DONE (or max_steps); returns the report.
  std::pair<demfdm::report_t, proto::Kinematics> until_done(const std::vector<double>& f, int block, int max_steps) {
    std::pair<demfdm::report_t, proto::Kinematics> r;
    for (int done = 0; done < max_steps; done += block) {
      r = steps(f, block);
      if (r.first.status == demfdm::report_t::STAGE_DONE) break;
    }
    return r;
  }
  // SHUTDOWN; returns the exit code, or -1 if the solver did not exit within timeout_s.
  int shutdown(double timeout_s) {
    coord_->shutdown("conformance test done");
    auto st = demfdm::testing::wait_for(proc_, timeout_s);
    if (!st) return -1;
    proc_.pid = -1;
    return demfdm::testing::exit_code(*st);
  }

 private:
  std::int64_t run_id_ = 0;
  std::string url_;
  fs::path dir_;
  config::Scene scene_;
  std::shared_ptr<lcm::LCM> lcm_;
  std::unique_ptr<bus::Bus> coord_bus_, dem_bus_, probe_;
  std::unique_ptr<proto::CoordinatorEndpoint> coord_;
  std::unique_ptr<proto::NodeEndpoint> dem_;
  demfdm::testing::Proc proc_;
  proto::InterfaceMesh mesh_;
  std::int64_t step_ = -1;
  std::vector<demfdm::hello_t> hellos_;
};

inline double value(const demfdm::report_t& r, const std::string& name) {
  for (std::size_t i = 0; i < r.names.size(); ++i)
    if (r.names[i] == name) return r.values[i];
  ADD_FAILURE() << "report has no value '" << name << "'";
  return std::nan("");
}

inline std::array<double, 3> tri_normal(const proto::InterfaceMesh& m, std::size_t t, double* area = nullptr) {
  const double* a = &m.positions[3 * m.triangles[3 * t]];
  const double* b = &m.positions[3 * m.triangles[3 * t + 1]];
  const double* c = &m.positions[3 * m.triangles[3 * t + 2]];
  double u[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  std::array<double, 3> n{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (area) *area = len / 2;
  for (auto& x : n) x /= len;
  return n;
}

// Nodal forces of a uniform pressure p on the interface triangles (pushing the continuum away
// from the pocket): each triangle's p A n_out is split over its corners by corner angle / pi,
// which gives A/4 per corner of a rectangular face cut into two triangles.
inline std::vector<double> pressure_forces(const proto::InterfaceMesh& m, double p) {
  std::vector<double> f(m.positions.size(), 0.0);
  for (std::size_t t = 0; t < m.triangles.size() / 3; ++t) {
    double area;
    auto n = tri_normal(m, t, &area);
    for (int c = 0; c < 3; ++c) {
      const double* x0 = &m.positions[3 * m.triangles[3 * t + c]];
      const double* x1 = &m.positions[3 * m.triangles[3 * t + (c + 1) % 3]];
      const double* x2 = &m.positions[3 * m.triangles[3 * t + (c + 2) % 3]];
      double a[3], b[3], dot = 0, la = 0, lb = 0;
      for (int d = 0; d < 3; ++d) {
        a[d] = x1[d] - x0[d];
        b[d] = x2[d] - x0[d];
        dot += a[d] * b[d];
        la += a[d] * a[d];
        lb += b[d] * b[d];
      }
      double angle = std::acos(dot / std::sqrt(la * lb));
      for (int d = 0; d < 3; ++d) f[3 * m.triangles[3 * t + c] + d] += -p * area * angle / M_PI * n[d];
    }
  }
  return f;
}

// A scripted 12-step load history, one grant per step; returns every kin(k).
inline std::vector<proto::Kinematics> scripted_run(Harness& h) {
  auto [m, kin0] = h.begin();
  std::vector<proto::Kinematics> out{kin0};
  for (int k = 0; k < 12; ++k) {
    auto f = pressure_forces(m, 1e4 * (1 + k));
    auto [rep, kin] = h.steps(f, 1, false);
    out.push_back(kin);
  }
  return out;
}

}  // namespace demfdm::conformance
