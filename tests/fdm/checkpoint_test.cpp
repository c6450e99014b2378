// Bit-exact resume of an FDM Model from a saved state (issue 13; docs/checkpoint-format.md):
// run N steps, save, load into a freshly built Model, run M more steps in both and compare
// positions, displacements, velocities, tetrahedron stresses, plastic states, zone forces,
// masses, the timestep, the history and the unbalanced-force ratios bit for bit. Scenes: an
// elastic / Mohr-Coulomb model under 50 g with geostatic stress and interface forces and
// stiffness changing every few steps (zones yield); small and large strain (the large-strain
// critical step is refreshed every 100 steps, N is off that interval); static (mass-scaled)
// mode; 1 and 2 OpenMP threads.
#include <gtest/gtest.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <string>
#include <unistd.h>
#include <vector>

#include "demfdm/fdm/checkpoint.hpp"
#include "demfdm/fdm/model.hpp"
#include "test_util.hpp"

namespace demfdm::fdm {
namespace {

using test::elastic;

constexpr std::uint64_t kSceneHash = 0xfd0c0ffee0000002ULL;

struct Scene {
  bool large_strain = false;
  Mode mode = Mode::kDynamic;
  int history_every = 7;
  double gravity = 50.0;
};

ModelParams params(const Scene& s) {
  ModelParams p;
  p.mesh = test::small_pocket_params();
  p.large_strain = s.large_strain;
  p.mode = s.mode;
  Material mc = elastic(5e7, 0.3, 1800.0);
  mc.model = Constitutive::kMohrCoulomb;
  mc.cohesion = 2e3;
  mc.friction_deg = 25.0;
  mc.dilation_deg = 5.0;
  p.materials = {MaterialGroup{elastic(5e7, 0.3, 1800.0), std::nullopt},
                 MaterialGroup{mc, Box{{0.0, 0.0, 0.0}, {4.0, 4.0, 2.5}}}};
  p.gravity_level = s.gravity;
  p.history_every = s.history_every;
  p.parallel_threshold = 0;  // every loop in a parallel region, even on this small mesh
  return p;
}

std::unique_ptr<Model> make(const Scene& s) {
  auto m = std::make_unique<Model>(params(s));
  m->set_geostatic_stress({});
  m->add_point_load(5, {1e3, -2e3, 0.0});
  // A gridpoint on the top surface pushed down at a prescribed speed (static mode: per step).
  const auto top = m->gridpoints_on_plane(2, 4.0);
  m->fix_velocity(top[top.size() / 3], kFixZ, {0.0, 0.0, s.mode == Mode::kStatic ? -1e-5 : -1e-3});
  return m;
}

// Interface forces and stiffness as a coupled run would send them: they change with the step
// (the stiffness every 10 steps, which moves the dynamic critical step), computed from the
// model's own step count so both runs get the same.
void drive(Model& m) {
  const std::int64_t k = m.step_count();
  const std::size_t n = m.interface_gridpoints().size();
  std::vector<double> f(3 * n);
  for (std::size_t i = 0; i < f.size(); ++i)
    f[i] = (i % 3 == 2 ? -3e4 : 2e3) * std::sin(0.1 * static_cast<double>(i) + 0.01 * static_cast<double>(k));
  m.set_interface_forces(f);
  if (k % 10 == 0) {
    std::vector<double> st(n);
    for (std::size_t i = 0; i < n; ++i) st[i] = 1e6 * (1.0 + 0.5 * std::sin(0.3 * static_cast<double>(i + k)));
    m.set_interface_stiffness(st);
  }
}

void run(Model& m, int steps) {
  for (int i = 0; i < steps; ++i) {
    drive(m);
    m.step();
  }
}

template <class T>
bool same(std::span<const T> a, std::span<const T> b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size_bytes()) == 0;
}
template <class T>
bool same_value(const T& a, const T& b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

// First difference (empty: identical bits), from the public interface, then the saved bytes.
std::string first_difference(const Model& a, const Model& b) {
  if (!same(a.positions(), b.positions())) return "positions";
  if (!same(a.displacements(), b.displacements())) return "displacements";
  if (!same(a.velocities(), b.velocities())) return "velocities";
  if (!same(a.tet_stresses(), b.tet_stresses())) return "tetrahedron stresses";
  if (!same(a.plastic_state(), b.plastic_state())) return "plastic state";
  if (!same(a.zone_forces(), b.zone_forces())) return "zone forces";
  if (!same(a.inertial_masses(), b.inertial_masses())) return "inertial masses";
  if (!same_value(a.step_count(), b.step_count())) return "step";
  if (!same_value(a.time(), b.time())) return "time";
  if (!same_value(a.timestep(), b.timestep())) return "timestep";
  if (!same_value(a.critical_timestep(), b.critical_timestep())) return "critical timestep";
  const Ratios ra = a.ratios(), rb = b.ratios();
  if (!same_value(ra.average, rb.average) || !same_value(ra.max, rb.max) || !same_value(ra.local, rb.local))
    return "ratios";
  const Vec3 qa = a.base_reaction(), qb = b.base_reaction();
  if (!same_value(qa, qb)) return "base reaction";
  if (a.history().size() != b.history().size()) return "history length";
  for (std::size_t i = 0; i < a.history().size(); ++i) {
    const HistoryRecord &x = a.history()[i], &y = b.history()[i];
    if (!same_value(x.step, y.step) || !same_value(x.time, y.time) || !same_value(x.ratios.average, y.ratios.average) ||
        !same_value(x.ratios.max, y.ratios.max) || !same_value(x.ratios.local, y.ratios.local) ||
        !same_value(x.kinetic_energy, y.kinetic_energy) || !same_value(x.base_reaction, y.base_reaction))
      return "history record " + std::to_string(i);
  }
  if (a.state_hash() != b.state_hash()) return "state hash";
  if (state_bytes(a, {kSceneHash, "test"}) != state_bytes(b, {kSceneHash, "test"})) return "saved state bytes";
  return {};
}

std::size_t yielding(const Model& m, std::uint8_t bits) {
  std::size_t n = 0;
  for (auto s : m.plastic_state()) n += (s & bits) != 0;
  return n;
}

std::string resume_check(const Scene& s, int n, int m, const char* name) {
  auto a = make(s);
  run(*a, n);
  const std::size_t past_at_save = yielding(*a, kShearPast | kTensionPast);
  const std::string bytes = state_bytes(*a, {kSceneHash, "test"});
  Model b(params(s));
  load_state_bytes(b, bytes, kSceneHash, name);
  EXPECT_EQ(first_difference(*a, b), "") << name << " after load";
  EXPECT_TRUE(state_bytes(b, {kSceneHash, "test"}) == bytes) << name << ": save(load(save)) != save";
  run(*a, m);
  run(b, m);
  std::printf("%s: N = %d, M = %d: %zu gridpoints, %zu zones; zones yielding now %zu, ever %zu (at save %zu); "
              "dt %.4g; %zu history records; state %zu bytes\n",
              name, n, m, a->num_gridpoints(), a->num_zones(), yielding(*a, kShearNow | kTensionNow),
              yielding(*a, kShearPast | kTensionPast), past_at_save, a->timestep(), a->history().size(), bytes.size());
  EXPECT_GT(yielding(*a, kShearNow | kTensionNow), 0u) << name << ": zones should be yielding";
  return first_difference(*a, b);
}

class ThreadCount {
 public:
  explicit ThreadCount(int n) : saved_(omp_get_max_threads()) { omp_set_num_threads(n); }
  ~ThreadCount() { omp_set_num_threads(saved_); }

 private:
  int saved_;
};

// ---- resume ----------------------------------------------------------------------------------

TEST(FdmCheckpoint, SmallStrainResumesBitExact) {
  for (int threads : {1, 2}) {
    ThreadCount tc(threads);
    for (int n : {1, 33, 95}) {
      SCOPED_TRACE("threads " + std::to_string(threads) + ", N = " + std::to_string(n));
      EXPECT_EQ(resume_check({}, n, 60, "small strain"), "");
    }
  }
}

// Large strain: the critical step is refreshed at steps 100, 200, ...; N = 150 saves between
// two refreshes, and the refresh at 200 happens after the load.
TEST(FdmCheckpoint, LargeStrainResumesBitExact) {
  Scene s;
  s.large_strain = true;
  for (int threads : {1, 2}) {
    ThreadCount tc(threads);
    SCOPED_TRACE("threads " + std::to_string(threads));
    EXPECT_EQ(resume_check(s, 150, 70, "large strain"), "");
  }
}

// Static (mass-scaled) mode: the inertial masses change with the interface stiffness.
TEST(FdmCheckpoint, StaticModeResumesBitExact) {
  Scene s;
  s.mode = Mode::kStatic;
  ThreadCount tc(1);
  EXPECT_EQ(resume_check(s, 47, 60, "static mode"), "");
}

// An imposed timestep is state too.
TEST(FdmCheckpoint, ImposedTimestepIsRestored) {
  ThreadCount tc(1);
  auto a = make({});
  run(*a, 5);
  a->set_timestep(0.5 * a->critical_timestep());
  run(*a, 5);
  Model b(params({}));
  load_state_bytes(b, state_bytes(*a, {kSceneHash, "test"}), kSceneHash, "imposed");
  run(*a, 30);
  run(b, 30);
  EXPECT_EQ(first_difference(*a, b), "");
}

// ---- the comparison can fail ---------------------------------------------------------------

TEST(FdmCheckpoint, OneUlpAfterLoadIsDetected) {
  ThreadCount tc(1);
  auto a = make({});
  run(*a, 20);
  Model b(params({}));
  load_state_bytes(b, state_bytes(*a, {kSceneHash, "test"}), kSceneHash, "ulp");
  // One ulp on the fastest interior gridpoint's vertical velocity (no fixed component there).
  const auto boundary = test::boundary_points(b.mesh());
  const auto v = b.velocities();
  std::int32_t g = -1;
  for (std::int32_t i = 0; i < static_cast<std::int32_t>(b.num_gridpoints()); ++i)
    if (!boundary.count(i) && (g < 0 || std::abs(v[3 * i + 2]) > std::abs(v[3 * g + 2]))) g = i;
  ASSERT_GE(g, 0);
  ASSERT_NE(v[3 * g + 2], 0.0);
  b.set_velocity(g, {v[3 * g], v[3 * g + 1], std::nextafter(v[3 * g + 2], 2.0 * v[3 * g + 2])});
  run(*a, 20);
  run(b, 20);
  EXPECT_NE(first_difference(*a, b), "");
}

// ---- files, refusals -----------------------------------------------------------------------

TEST(FdmCheckpoint, FileAndStreamRoundTrip) {
  ThreadCount tc(1);
  auto a = make({});
  run(*a, 25);
  const auto dir = std::filesystem::temp_directory_path() / ("demfdm_fdm_ckpt_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const auto file = dir / "fdm.state";
  save_state_file(*a, file, {kSceneHash, "v-test"});
  Model b(params({}));
  const auto h = load_state_file(b, file, kSceneHash);
  EXPECT_EQ(h.kind, "fdm");
  EXPECT_EQ(h.code_version, "v-test");
  std::stringstream ss;
  save_state(*a, ss, {kSceneHash, "v-test"});
  Model c(params({}));
  load_state(c, ss, kSceneHash, "stream");
  run(*a, 20);
  run(b, 20);
  run(c, 20);
  EXPECT_EQ(first_difference(*a, b), "");
  EXPECT_EQ(first_difference(*a, c), "");
  std::filesystem::remove_all(dir);
}

// A model built from other parameters (or another mesh), a DEM state, another scene: refused
// by name, the model untouched.
TEST(FdmCheckpoint, RefusesOtherModelsByName) {
  ThreadCount tc(1);
  auto a = make({});
  run(*a, 10);
  const std::string bytes = state_bytes(*a, {kSceneHash, "test"});
  auto refused = [&](Model& m, std::uint64_t hash, const std::string& expect) {
    const std::uint64_t before = m.state_hash();
    try {
      load_state_bytes(m, bytes, hash, "ckpt/fdm-000010.state");
      ADD_FAILURE() << "expected a refusal containing '" << expect << "'";
    } catch (const io::StateFileError& e) {
      const std::string msg = e.what();
      EXPECT_EQ(msg.rfind("ckpt/fdm-000010.state: ", 0), 0u) << msg;
      EXPECT_NE(msg.find(expect), std::string::npos) << msg;
    }
    EXPECT_EQ(m.state_hash(), before);
  };
  Scene other_g;
  other_g.gravity = 49.0;
  Model g(params(other_g));
  refused(g, kSceneHash, "built from other parameters");
  ModelParams pe = params({});
  pe.materials[1].material.model = Constitutive::kElastic;  // same constants, other law
  Model elastic_only(pe);
  refused(elastic_only, kSceneHash, "built from other parameters");
  ModelParams pm = params({});
  pm.mesh.size_near = 0.4;
  Model mesh(pm);
  refused(mesh, kSceneHash, "gridpoints");
  Model same_params(params({}));
  refused(same_params, kSceneHash ^ 1, "scene hash");
}

// Size and time on the continuum of scenes/accuracy_footing.toml (6 mm box, 2 x 2 x 3 mm pocket,
// 0.5 / 1.5 mm zones); run with --gtest_also_run_disabled_tests.
TEST(FdmCheckpoint, SizeAndTimeOfAccuracyFootingMesh) {
  ThreadCount tc(1);
  ModelParams p;
  p.mesh.length = p.mesh.width = p.mesh.height = 6e-3;
  p.mesh.inner_size = {2e-3, 2e-3, 3e-3};
  p.mesh.size_near = 0.5e-3;
  p.mesh.size_far = 1.5e-3;
  p.materials = {MaterialGroup{elastic(1.083e9, 1.0 / 3.0, 1272.0), std::nullopt}};
  p.gravity_level = 100.0;
  Model a(p);
  a.set_geostatic_stress({});
  a.step(20);
  using Clock = std::chrono::steady_clock;
  const int reps = 20;
  std::string bytes;
  const auto t0 = Clock::now();
  for (int k = 0; k < reps; ++k) bytes = state_bytes(a, {kSceneHash, "test"});
  const auto t1 = Clock::now();
  Model b(p);
  for (int k = 0; k < reps; ++k) load_state_bytes(b, bytes, kSceneHash, "timing");
  const auto t2 = Clock::now();
  auto ms = [](auto x, auto y) { return std::chrono::duration<double, std::milli>(y - x).count(); };
  std::printf("accuracy continuum: %zu gridpoints, %zu zones, %zu interface gridpoints; state %zu bytes; "
              "save %.2f ms, load %.2f ms (in memory)\n",
              a.num_gridpoints(), a.num_zones(), a.interface_gridpoints().size(), bytes.size(), ms(t0, t1) / reps,
              ms(t1, t2) / reps);
  a.step(10);
  b.step(10);
  EXPECT_EQ(first_difference(a, b), "");
}

}  // namespace
}  // namespace demfdm::fdm
