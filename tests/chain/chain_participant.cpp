// Protocol test participants (preCICE "solver dummies" with real physics): chain_dem and
// chain_continuum each hold one part of a 1-D mass-spring chain (chain_model.hpp) and run as
// separate processes over the bus, through the same node runtime as the real engines.
// Each writes its masses' displacement history to <run_dir>/chain_<role>.csv.
#include <cmath>
#include <fstream>
#include <iomanip>

#include "common/node/node_runtime.hpp"
#include "tests/chain/chain_model.hpp"

using namespace demfdm;

namespace {

class ChainPart : public node::Participant {
 public:
  ChainPart(const node::Context& ctx, bool dem) : dem_(dem) {
    const auto& s = ctx.scene;
    if (!s.has("chain")) throw std::invalid_argument("chain participants need a [chain] section in the scene");
    p_.n = static_cast<int>(s.integer("chain.n_masses"));
    p_.split = static_cast<int>(s.integer("chain.split"));
    p_.m = s.real("chain.mass");
    p_.k = s.real("chain.stiffness");
    p_.dt = s.real("chain.dt");
    p_.v0 = s.real("chain.v0");
    every_ = s.integer("chain.record_every");
    first_ = dem ? 0 : p_.split;
    count_ = dem ? p_.split : p_.n - p_.split;
    x_.assign(count_, 0.0);
    v_.assign(count_, 0.0);
    if (dem) v_[0] = p_.v0;
    if (!ctx.options.run_dir.empty()) {
      csv_.open(ctx.options.run_dir + "/chain_" + ctx.role + ".csv");
      csv_ << "step";
      for (int i = 0; i < count_; ++i) csv_ << ",u" << first_ + i << "_m";
      csv_ << "\n" << std::setprecision(17);
      record(0);
    }
  }
  double dt_stable() const override { return p_.dt; }
  double time() const override { return t_; }
  proto::Values stage_begin(const schema::Stage&, std::int64_t) override { return {{"masses", count_}}; }
  void advance(const schema::Stage&, std::int64_t step, double dt, const std::vector<double>&) override {
    if (dt != p_.dt) throw std::runtime_error("coordinator granted dt " + std::to_string(dt) + " s, the chain needs " + std::to_string(p_.dt));
    std::vector<double> f(count_, 0.0);
    for (int i = 0; i + 1 < count_; ++i) {
      double t = p_.k * (x_[i + 1] - x_[i]);
      f[i] += t;
      f[i + 1] -= t;
    }
    if (dem_) {
      f[count_ - 1] += iface_tension_;  // spring to the continuum's interface mass
    } else {
      f[0] += f_iface_;  // force from the DEM side on the interface mass
    }
    for (int i = 0; i < count_; ++i) {
      v_[i] += dt * f[i] / p_.m;
      x_[i] += dt * v_[i];
    }
    t_ += dt;
    if (csv_.is_open() && step % every_ == 0) record(step);
  }
  proto::Values step_values() override {
    double e = 0;
    for (int i = 0; i < count_; ++i) e += 0.5 * p_.m * v_[i] * v_[i];
    return {{dem_ ? "u0_m" : "u_iface_m", x_[0]}, {"kinetic_J", e}};
  }
  proto::Values stage_end(const schema::Stage&, std::int64_t) override { return step_values(); }
  void finish() override { csv_.flush(); }

  // continuum side: the interface point is its first mass.
  proto::InterfaceMesh interface_mesh() override {
    proto::InterfaceMesh m;
    m.point_ids = {p_.split};
    m.positions = {static_cast<double>(p_.split), 0, 0};
    m.n_walls = 0;
    return m;
  }
  proto::Kinematics interface_kinematics() override {
    proto::Kinematics k;
    k.positions = {x_[0], 0, 0};  // displacement stands for position in this 1-D test
    k.velocities = {v_[0], 0, 0};
    return k;
  }
  void apply_interface_forces(const proto::Forces& f) override {
    if (f.forces.size() != 3) throw std::runtime_error("expected forces on 1 interface point");
    f_iface_ = f.forces[0];
  }
  // DEM side: the interface kinematics arrive before each step, with our own positions still
  // at the start of the step, so the spring tension (and the reaction sent back) is computed
  // here from x(t) exactly as the monolithic scheme does.
  void set_interface_mesh(const proto::InterfaceMesh& m) override {
    if (m.n_points() != 1) throw std::runtime_error("expected 1 interface point");
  }
  void set_interface_kinematics(const proto::Kinematics& k) override {
    iface_tension_ = p_.k * (k.positions[0] - x_[count_ - 1]);
  }
  proto::Forces interface_forces() override {
    proto::Forces f;
    f.forces = {-iface_tension_, 0, 0};  // the spring pulls the interface mass back
    f.stiffness = {p_.k};
    f.total = {-iface_tension_, 0, 0};
    return f;
  }

 private:
  void record(std::int64_t step) {
    csv_ << step;
    for (int i = 0; i < count_; ++i) csv_ << "," << x_[i];
    csv_ << "\n";
  }
  bool dem_;
  testing::ChainParams p_;
  std::int64_t every_ = 1;
  int first_ = 0, count_ = 0;
  std::vector<double> x_, v_;
  double t_ = 0, iface_tension_ = 0, f_iface_ = 0;
  std::ofstream csv_;
};

}  // namespace

int main(int argc, char** argv) {
  const bool dem = std::string(CHAIN_ROLE) == "dem";
  return node::run_node(argc, argv, CHAIN_ROLE, dem ? "chain_dem" : "chain_continuum",
                        [dem](const node::Context& ctx) { return std::make_unique<ChainPart>(ctx, dem); });
}
