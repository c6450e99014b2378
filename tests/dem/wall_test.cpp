// Interface facets (docs/theory.md §1.4, §6.2–6.5) and the rigid cylindrical footing.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <set>

#include "demfdm/dem/geometry.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
constexpr double kPi = 3.14159265358979323846;

// A horizontal square [−h, h]² at z = 0 made of two triangles, normal +z.
int add_square(World& w, double h, double z = 0.0) {
  const std::vector<double> v = {-h, -h, z, h, -h, z, h, h, z, -h, h, z};
  const std::vector<std::int32_t> t = {0, 1, 2, 0, 2, 3};
  return w.add_facet_wall(v, t);
}

// The paper's interface (docs/theory.md 2.6): ball-facet parallel bonds without a linear part
// while bonded, of tensile and cohesive strength `strength` [Pa].
WorldParams bonded_interface(double strength) {
  WorldParams p;
  p.ball_facet.model = ContactModel::kLinearPBond;
  p.ball_facet.pbond.zero_linear = true;
  p.ball_facet.pbond.ten = strength;
  p.ball_facet.pbond.coh = strength;
  return p;
}
}  // namespace

// §6.4: the equivalent vertex forces have the exact resultant and moment (1e-12 relative).
TEST(Facet, EquivalentForceSystemIdentity) {
  std::mt19937_64 rng(12345);
  std::uniform_real_distribution<double> U(-1.0, 1.0);
  double err_f = 0, err_m = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    std::array<Vec3, 3> p;
    for (auto& q : p) q = {U(rng), U(rng), U(rng)};
    if (norm(cross(p[1] - p[0], p[2] - p[0])) < 1e-3) continue;
    const Vec3 xc{U(rng), U(rng), U(rng)}, F{U(rng), U(rng), U(rng)}, M{U(rng), U(rng), U(rng)};
    std::array<Vec3, 3> f;
    facet_equivalent_forces(p, xc, F, M, f);
    const Vec3 sf = f[0] + f[1] + f[2];
    const Vec3 sm = cross(p[0], f[0]) + cross(p[1], f[1]) + cross(p[2], f[2]);
    const Vec3 mref = cross(xc, F) + M;
    err_f = std::max(err_f, norm(sf - F) / norm(F));
    err_m = std::max(err_m, norm(sm - mref) / (norm(M) + norm(xc) * norm(F)));
  }
  EXPECT_LT(err_f, 1e-12);
  EXPECT_LT(err_m, 1e-12);
  std::printf("equivalent forces: max rel err F %.1e M %.1e\n", err_f, err_m);
}

// §8.2 on a facet wall: δ = m N g0/k_n; vertex forces sum to the facet load, which balances
// the ball weight; stiffness contributions sum to K_n + K_s (Σw = 1).
TEST(Facet, BallRestingOnFacetsForceBalance) {
  WorldParams p;
  p.ball_facet.linear.fric = 0.5;
  const double R = 1e-4, N = 50;
  World w(p);
  const int wall = add_square(w, 1e-3);
  w.add_ball({2e-4, 1e-4, R}, R);
  w.set_gravity(true, N);
  w.step(20000);
  const double m = w.balls().m[0];
  const double kn = kPi * R * p.ball_facet.linear.emod;
  EXPECT_NEAR((R - w.balls().x[0].z) / (m * N * p.g0 / kn), 1.0, 1e-6);
  auto vf = w.vertex_forces(wall);
  Vec3 s{};
  for (std::size_t i = 0; i < vf.size() / 3; ++i) s += Vec3{vf[3 * i], vf[3 * i + 1], vf[3 * i + 2]};
  const Vec3 tot = w.facet_wall_force(wall);
  EXPECT_LT(norm(s - tot), 1e-12 * norm(tot));
  // force on the facets + force of the facets on the ball = 0 (Newton's third law, §6.9)
  Vec3 on_ball{};
  const auto& fc = w.facet_contacts();
  for (std::size_t c = 0; c < fc.size(); ++c) on_ball -= fc.F[c];
  EXPECT_LT(norm(tot + on_ball), 1e-15 * norm(tot));
  EXPECT_NEAR(tot.z / (-m * N * p.g0), 1.0, 1e-6);
  double ks = 0;
  for (double k : w.vertex_stiffness(wall)) ks += k;
  EXPECT_NEAR(ks / (kn + kn / p.ball_facet.linear.kratio), 1.0, 1e-12);
}

// §1.4: one contact per (ball, wall); the history follows the ball across a shared edge.
TEST(Facet, HistoryMovesAcrossFacets) {
  WorldParams p;
  p.local_damping = 0.0;
  p.ball_facet.linear.fric = 0.3;
  const double R = 1e-4;
  World w(p);
  add_square(w, 1e-3);
  const double m = p.density * 4.0 / 3.0 * kPi * R * R * R;
  const double kn = kPi * R * p.ball_facet.linear.emod;
  w.add_ball({3e-4, -3e-4, R - m * p.g0 / kn}, R);  // below the diagonal x = y
  w.set_gravity(true, 1.0);
  w.balls().fix[0] = kFixVx | kFixVy | kFixRot;
  w.balls().v[0] = {-0.5, 0.5, 0};  // crosses the diagonal
  std::set<int> facets;
  double err = 0;
  for (int k = 0; w.balls().x[0].x > -3e-4; ++k) {
    w.step();
    const auto& fc = w.facet_contacts();
    ASSERT_EQ(fc.size(), 1u);
    facets.insert(fc.facet[0]);
    if (k > 20) err = std::max(err, std::abs(norm(fc.h[0].fs) - 0.3 * fc.h[0].fn) / (0.3 * fc.h[0].fn));
  }
  EXPECT_EQ(facets.size(), 2u);
  EXPECT_LT(err, 1e-9);
  std::printf("facet change: sliding |Fs|/(mu Fn) max rel err %.1e\n", err);
}

// §6.2: the kinematic facet spin of a rigidly rotating triangle is its angular velocity.
TEST(Facet, KinematicSpinOfRigidRotation) {
  World w(WorldParams{});
  const std::vector<double> v = {0.1, 0.2, 0.3, 1.0, 0.1, 0.4, 0.2, 0.9, 0.7};
  const int wall = w.add_facet_wall(v, std::vector<std::int32_t>{0, 1, 2});
  const Vec3 om{0.3, -1.2, 0.7};
  std::vector<double> vel(9);
  for (int i = 0; i < 3; ++i) {
    const Vec3 vi = cross(om, Vec3{v[3 * i], v[3 * i + 1], v[3 * i + 2]});
    vel[3 * i] = vi.x; vel[3 * i + 1] = vi.y; vel[3 * i + 2] = vi.z;
  }
  w.set_vertex_kinematics(wall, v, vel);
  EXPECT_LT(norm(w.facet_wall(wall).tri_spin[0] - om), 1e-12 * norm(om));
}

// Footing: reaction = K_n × overlap for the bottom disc and the side (L = R, §1.7).
TEST(Footing, ReactionBottomAndSide) {
  WorldParams p;
  const double R = 1e-4;
  World w(p);
  w.add_ball({0, 0, 0}, R);          // under the bottom disc
  w.add_ball({1.0e-3, 0, 4e-4}, R);  // beside the side wall
  w.balls().fix[0] = w.balls().fix[1] = kFixAll;
  FootingParams fp;
  fp.diameter = 1.2e-3;
  fp.height = 0.6e-3;
  fp.bottom_centre = {0, 0, R + 1e-6};
  fp.velocity = {0, 0, -0.1};
  w.set_footing(fp);
  const double kn = kPi * R * p.ball_footing.linear.emod;
  while (w.footing().p.bottom_centre.z > R - 2e-6) w.step();
  const double pen = R - w.footing().p.bottom_centre.z;
  EXPECT_GT(pen, 0.0);
  // ball 1: surface of the side at x = 0.6 mm, ball centre at 1.0 mm: gap 0.3 mm, inactive
  EXPECT_NEAR(w.footing_reaction().z / (kn * pen), 1.0, 1e-9);
  EXPECT_NEAR(w.footing_reaction().x, 0.0, 1e-15);
  // move the footing sideways into ball 1
  w.set_footing_position({1.0e-3 - 0.6e-3 - R + 2e-6, 0, 2e-4});
  w.set_footing_velocity({0, 0, 0});
  w.step();
  EXPECT_NEAR(w.footing_reaction().x / (-kn * 2e-6), 1.0, 1e-6);
  EXPECT_NEAR(w.footing_reaction().z, 0.0, 1e-12);
}

// docs/theory.md §2.6, §6.3: an interface (ball-facet) parallel bond has no linear part while it
// is bonded (no repulsion from the initial overlaps), but once it breaks the contact is an
// ordinary linear contact again, starting from the configuration at the break, so the ball
// cannot cross the interface. A ball bonded to a facet floor is driven sideways and down: the
// bond breaks in shear, and the ball is then stopped by the floor (without the restored linear
// part it fell through the wall).
TEST(Interface, BrokenInterfaceBondStopsTheBallAtTheWall) {
  WorldParams p = bonded_interface(1e5);
  p.local_damping = 0.0;
  const double R = 1e-4;
  World w(p);
  add_square(w, 2e-3);
  w.add_ball({0, 0, R}, R);  // touching the floor
  w.prepare();
  ASSERT_EQ(w.bond_ball_facet(1e-9), 1u);
  w.balls().v[0] = {0.5, 0.0, -0.05};  // shear the bond and press into the floor
  double zmin = R;
  bool broke = false, stiff_after_break = true;
  for (int s = 0; s < 5000 && std::abs(w.balls().x[0].x) < 1.5e-3; ++s) {
    w.step();
    zmin = std::min(zmin, w.balls().x[0].z);
    const auto& fc = w.facet_contacts();
    if (fc.size() == 1 && (fc.bond[0].state == BondState::kBrokenShear || fc.bond[0].state == BondState::kBrokenTension)) {
      broke = true;
      stiff_after_break &= fc.h[0].kn > 0.0;
    }
  }
  EXPECT_TRUE(broke) << "the bond did not break: the test does not test anything";
  EXPECT_TRUE(stiff_after_break) << "the broken interface bond left a contact without stiffness";
  std::printf("lowest ball centre after the break: %.4g R (floor at 0)\n", zmin / R);
  EXPECT_GT(zmin, 0.9 * R) << "the ball sank into the interface wall after the break";
}

// A bonded wall contact is kept when its ball leaves the candidate range; the rebuilt list is
// still in (ball, wall) order, so that its order is fixed by its contacts alone (a rank of the DEM
// on MPI ranks merges every rank's contacts in this order, World::set_wall_sums).
TEST(Interface, KeptBondedContactIsSortedIn) {
  WorldParams p;
  p.ball_facet.model = ContactModel::kLinearPBond;
  p.ball_facet.pbond.zero_linear = true;
  const double R = 1e-4;
  World w(p);
  add_square(w, 2e-3);
  for (int i = 0; i < 3; ++i) w.add_ball({(i - 1) * 3 * R, 0, R}, R);
  w.prepare();
  ASSERT_EQ(w.bond_ball_facet(1e-9), 3u);
  w.balls().x[0].z += 3.0 * w.skin();  // out of reach, still bonded
  w.balls().x_ref[0] = w.balls().x[0];
  w.prepare();
  const WallContacts& fc = w.facet_contacts();
  ASSERT_EQ(fc.size(), 3u);
  EXPECT_EQ(fc.ball, (std::vector<std::uint32_t>{0, 1, 2}));
  EXPECT_TRUE(bonded(fc.bond[0].state));
}

// The facets' shares of their walls' vertex sums as the force pass formed them (what a rank of the
// DEM on MPI ranks sends rank 0, World::facet_sum_shares), added again in their order
// (World::set_facet_sums): the pass's own sums, bit for bit. Bonded and unbonded balls on a floor
// of facets, sheared and spun, so that the shares carry forces, moments (equivalent vertex
// forces from both) and stiffness on every vertex of the floor's two facets.
TEST(Interface, FacetSharesAddUpToThePassesSums) {
  WorldParams p = bonded_interface(1e7);
  p.gravity = true;
  p.g_level = 100.0;
  const double R = 1e-4;
  World w(p);
  add_square(w, 2e-3);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) w.add_ball({(i - 2.5) * 2.6 * R, (j - 2.5) * 2.6 * R, R}, R);  // touching the floor
  w.prepare();
  ASSERT_EQ(w.bond_ball_facet(1e-9), 36u);
  for (std::size_t b = 0; b < w.num_balls(); ++b) {
    w.balls().v[b] = {0.005 * u(rng), 0.005 * u(rng), -0.002};
    w.balls().w[b] = {20.0 * u(rng), 20.0 * u(rng), 20.0 * u(rng)};
  }
  for (int s = 0; s < 200; ++s) w.step();
  std::vector<FacetSumShare> shares;
  w.facet_sum_shares(shares);
  std::size_t loaded = 0;
  for (std::size_t k = 0; k < shares.size(); ++k) {
    loaded += shares[k].loaded;
    if (k > 0) {
      EXPECT_TRUE(shares[k - 1].ball < shares[k].ball ||
                  (shares[k - 1].ball == shares[k].ball && shares[k - 1].wall < shares[k].wall))
          << "the shares are in one World's contact order";
    }
  }
  std::printf("%zu facet contacts, %zu shares, %zu loaded\n", w.facet_contacts().size(), shares.size(), loaded);
  ASSERT_GT(loaded, 10u) << "the floor must carry load";
  std::vector<double> pass, again;
  w.pack_wall_sums(pass);
  w.set_facet_sums(shares);
  w.pack_wall_sums(again);
  ASSERT_EQ(pass.size(), again.size());
  EXPECT_EQ(std::memcmp(pass.data(), again.data(), pass.size() * sizeof(double)), 0)
      << "the shares added again must give the pass's sums";
  double any = 0.0;
  for (double v : pass) any = std::max(any, std::abs(v));
  EXPECT_GT(any, 0.0);
  // a share of a facet the World does not have is refused by name
  shares.back().facet = 1000;
  EXPECT_THROW(w.set_facet_sums(shares), std::invalid_argument);
}
