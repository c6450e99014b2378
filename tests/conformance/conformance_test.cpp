// Conformance kit for continuum solvers (issue 6; messages/README.md "Writing another
// continuum solver"). Given only a command line, it starts the solver as a separate process and
// plays the coordinator and the DEM node itself, inside this test process, with the bus
// classes of messages/ (CoordinatorEndpoint, NodeEndpoint as role "dem").
//
//   conformance_tests [gtest flags] -- /path/to/solver [solver args...]
//   or: DEMFDM_CONTINUUM="/path/to/solver" conformance_tests
//
// The solver is started as: SOLVER [args...] --lcm-url=URL --run-id=N --run-dir=DIR
// Checks (tolerances stated at each test):
//  * Handshake: hello with role continuum, protocol version, scene hash and message fingerprints.
//  * Interface mesh: ids unique, triangle rows in range, every triangle on a pocket face with
//    its normal pointing into the pocket, wall index in range, positions = kin(s0-1).
//  * Zero forces, no gravity: zero interface displacement.
//  * Column: uniform pressure p on the bottom of a pocket that spans the whole footprint;
//    displacement p Hc / M (M = K + 4G/3) and base reaction p A.
//  * Faults: dropped / duplicated kin and report messages of the solver (DEMFDM_FAULT in its
//    environment) and a dropped force message of this DEM: the answers are bit-identical to a
//    clean run.
//  * Clean shutdown: exit 0 within 2 s of SHUTDOWN.
#include "tests/conformance/harness.hpp"

using namespace demfdm;

namespace {

using namespace demfdm::conformance;
std::vector<std::string> g_solver;  // command line of the solver under test
std::string g_skip;

#define REQUIRE_SOLVER()                                           \
  if (!g_skip.empty()) GTEST_SKIP() << g_skip;                     \
  ASSERT_FALSE(g_solver.empty()) << "no solver given: pass -- /path/to/solver or set DEMFDM_CONTINUUM"

TEST(Conformance, HandshakeAndCleanShutdown) {
  REQUIRE_SOLVER();
  Harness h(g_solver, column_scene(false, 1e-6));
  ASSERT_FALSE(h.hellos().empty()) << h.solver_output();
  const auto& hello = h.hellos().back();
  EXPECT_EQ(hello.role, "continuum");
  EXPECT_EQ(hello.protocol_version, proto::kProtocolVersion);
  EXPECT_EQ(static_cast<std::uint64_t>(hello.scene_hash), h.hash());
  EXPECT_FALSE(hello.solver.empty());
  auto mine = bus::compiled_fingerprints();
  ASSERT_EQ(hello.type_names.size(), mine.size());
  for (std::size_t i = 0; i < mine.size(); ++i) {
    EXPECT_EQ(hello.type_names[i], mine[i].name);
    EXPECT_EQ(hello.fingerprints[i], mine[i].hash) << mine[i].name;
  }
  h.begin();
  auto t0 = std::chrono::steady_clock::now();
  int code = h.shutdown(2.0);
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(code, 0) << "exit code (-1: still running 2 s after SHUTDOWN)\n" << h.solver_output();
  EXPECT_LT(s, 2.0);
}

TEST(Conformance, InterfaceMeshConsistency) {
  REQUIRE_SOLVER();
  Harness h(g_solver, pocket_scene());
  auto [m, kin] = h.begin();
  const std::size_t n = m.point_ids.size(), nt = m.triangles.size() / 3;
  ASSERT_GT(n, 0u);
  ASSERT_GT(nt, 0u);
  ASSERT_EQ(m.positions.size(), 3 * n);
  ASSERT_EQ(m.wall_of_triangle.size(), nt);
  EXPECT_EQ(std::set<std::int64_t>(m.point_ids.begin(), m.point_ids.end()).size(), n) << "point ids not unique";
  for (auto r : m.triangles) ASSERT_TRUE(r >= 0 && static_cast<std::size_t>(r) < n) << "triangle row " << r;
  for (auto w : m.wall_of_triangle) EXPECT_TRUE(w >= 0 && w < m.n_walls) << "wall " << w;
  // Pocket of the scene: centred in x, y, top flush: [1,2] x [1,2] x [1.5,3] mm.
  const double lo[3] = {1e-3, 1e-3, 1.5e-3}, hi[3] = {2e-3, 2e-3, 3e-3}, tol = 1e-9;
  double area_sum = 0;
  for (std::size_t t = 0; t < nt; ++t) {
    double area;
    auto nrm = tri_normal(m, t, &area);
    area_sum += area;
    // The face plane: one coordinate constant and on a pocket face; the normal points into the pocket.
    int axis = -1;
    for (int d = 0; d < 3; ++d)
      if (std::abs(std::abs(nrm[d]) - 1) < 1e-9) axis = d;
    ASSERT_GE(axis, 0) << "triangle " << t << " is not axis-aligned";
    double c = m.positions[3 * m.triangles[3 * t] + axis];
    for (int k = 0; k < 3; ++k) {
      const double* x = &m.positions[3 * m.triangles[3 * t + k]];
      EXPECT_NEAR(x[axis], c, tol);
      for (int d = 0; d < 3; ++d) EXPECT_TRUE(x[d] >= lo[d] - tol && x[d] <= hi[d] + tol) << "point outside the pocket";
    }
    bool on_lo = std::abs(c - lo[axis]) < tol, on_hi = std::abs(c - hi[axis]) < tol;
    ASSERT_TRUE(on_lo || on_hi) << "triangle " << t << " is not on a pocket face";
    EXPECT_EQ(nrm[axis], on_lo ? 1.0 : -1.0) << "triangle " << t << ": normal does not point into the pocket";
  }
  // Open top: walls = bottom 1x1 + 4 sides 1x1.5 mm.
  EXPECT_NEAR(area_sum, 1e-6 + 4 * 1.5e-6, 1e-12);
  EXPECT_EQ(kin.positions, m.positions) << "kin(s0-1) differs from the mesh positions";
  EXPECT_EQ(h.shutdown(2.0), 0);
}

TEST(Conformance, ZeroForcesNoGravityZeroDisplacement) {
  REQUIRE_SOLVER();
  Harness h(g_solver, column_scene(false, 1e-6));
  auto [m, kin0] = h.begin();
  auto [rep, kin] = h.steps(std::vector<double>(m.positions.size(), 0.0), 20);
  double umax = 0, vmax = 0;
  for (std::size_t i = 0; i < kin.positions.size(); ++i) {
    umax = std::max(umax, std::abs(kin.positions[i] - m.positions[i]));
    vmax = std::max(vmax, std::abs(kin.velocities[i]));
  }
  EXPECT_LE(umax, 1e-15) << "interface displacement without load [m]";
  EXPECT_LE(vmax, 1e-15);
  EXPECT_NEAR(value(rep, "base_fz_N"), 0.0, 1e-12);
  EXPECT_EQ(h.shutdown(2.0), 0);
}

// Uniform pressure p on the pocket bottom = top of a 2 mm column with rollers on the sides:
// u_z = -p Hc / M everywhere on the top, base reaction +p A. Tolerance 0.5 % (the explicit
// solver stops at ratio 1e-7; an implicit one is exact to round-off).
TEST(Conformance, ColumnUnderUniformPressure) {
  REQUIRE_SOLVER();
  Harness h(g_solver, column_scene(false, 1e-7));
  auto [m, kin0] = h.begin();
  const double p = 1e5;
  auto f = pressure_forces(m, p);
  double fz = 0;
  for (std::size_t i = 2; i < f.size(); i += 3) fz += f[i];
  const double A = 2e-3 * 2e-3, Hc = 2e-3;
  ASSERT_NEAR(fz, -p * A, 1e-9 * p * A) << "all interface triangles should be on the pocket bottom";
  auto [rep, kin] = h.until_done(f, 200, 40000);
  EXPECT_EQ(rep.status, demfdm::report_t::STAGE_DONE) << "no equilibrium within 40000 steps";
  const double M = kE * (1 - kNu) / ((1 + kNu) * (1 - 2 * kNu));
  const double expected = -p * Hc / M;
  double worst = 0;
  for (std::size_t i = 0; i < kin.positions.size() / 3; ++i) {
    double uz = kin.positions[3 * i + 2] - m.positions[3 * i + 2];
    worst = std::max(worst, std::abs(uz / expected - 1));
    EXPECT_NEAR(kin.positions[3 * i], m.positions[3 * i], 1e-3 * std::abs(expected));
  }
  std::cout << "column: expected u_z " << expected << " m, worst relative error " << worst << "\n";
  EXPECT_LT(worst, 5e-3);
  double base = value(rep, "base_fz_N");
  std::cout << "column: base reaction " << base << " N, expected " << p * A << " N\n";
  EXPECT_NEAR(base, p * A, 5e-3 * p * A);
  EXPECT_EQ(h.shutdown(2.0), 0);
}

TEST(Conformance, DroppedAndDuplicatedMessagesChangeNothing) {
  REQUIRE_SOLVER();
  std::vector<proto::Kinematics> clean, faulty;
  {
    Harness h(g_solver, column_scene(false, 1e-7));
    clean = scripted_run(h);
    EXPECT_EQ(h.shutdown(2.0), 0);
  }
  {
    // The solver loses its 3rd kin and 4th report, and sends its 5th kin and 6th report twice;
    // this DEM loses its 4th force message.
    setenv("DEMFDM_FAULT", "drop:DEMFDM_IFACE_FORCE:4", 1);
    Harness h(g_solver, column_scene(false, 1e-7), {"DEMFDM_FAULT=drop:DEMFDM_IFACE_KIN:3,drop:DEMFDM_REPORT:4,"
                                          "dup:DEMFDM_IFACE_KIN:5,dup:DEMFDM_REPORT:6"});
    unsetenv("DEMFDM_FAULT");
    faulty = scripted_run(h);
    EXPECT_EQ(h.shutdown(2.0), 0) << h.solver_output();
  }
  ASSERT_EQ(clean.size(), faulty.size());
  for (std::size_t k = 0; k < clean.size(); ++k) {
    EXPECT_EQ(clean[k].positions, faulty[k].positions) << "kin(" << k - 1 << ") differs after faults";
    EXPECT_EQ(clean[k].velocities, faulty[k].velocities) << "kin(" << k - 1 << ") differs after faults";
  }
  // The history really moved the interface (otherwise the comparison proves nothing).
  EXPECT_NE(clean.back().positions, clean.front().positions);
}

}  // namespace

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (a == "--") continue;
    g_solver.push_back(a);
  }
  if (g_solver.empty() && std::getenv("DEMFDM_CONTINUUM")) {
    std::stringstream ss(std::getenv("DEMFDM_CONTINUUM"));
    std::string w;
    while (ss >> w) g_solver.push_back(w);
  }
  g_skip = demfdm::testing::enter_private_network();
  return RUN_ALL_TESTS();
}
