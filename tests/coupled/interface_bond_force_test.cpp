// Initial force of the DEM-FDM interface bonds (docs/theory.md 4.9, dem::assign_interface_bond_forces
// with InterfaceBondForce::kTraction), in isolation: fixed balls bonded to the five faces of an
// open box (the continuum's pocket). The geostatic stress sigma_zz = -gamma (z_top - z),
// sigma_h = K0 sigma_zz integrates to gamma H A on the bottom and K0 gamma H^2 W / 2 on each side;
// the bonds must carry exactly these face forces (round-off), in compression along the face
// normal, each side bond in proportion to its depth, and keep them while nothing moves.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
// Open box [0, L]^2 x [0, H], facet normals pointing inwards, each face split into n x n
// squares of two triangles (so a face holds facets with and without bonds).
void box_mesh(double L, double H, int n, std::vector<double>& v, std::vector<std::int32_t>& t) {
  auto quad = [&](Vec3 o, Vec3 a, Vec3 b) {  // face o + s a + r b, normal a x b
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const Vec3 p0 = o + (double(i) / n) * a + (double(j) / n) * b;
        const Vec3 pa = (1.0 / n) * a, pb = (1.0 / n) * b;
        const auto base = static_cast<std::int32_t>(v.size() / 3);
        for (const Vec3& q : {p0, p0 + pa, p0 + pa + pb, p0 + pb}) v.insert(v.end(), {q.x, q.y, q.z});
        t.insert(t.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
      }
  };
  quad({0, 0, 0}, {L, 0, 0}, {0, L, 0});  // bottom, +z
  quad({0, 0, 0}, {0, L, 0}, {0, 0, H});  // x = 0, +x
  quad({L, 0, 0}, {0, 0, H}, {0, L, 0});  // x = L, -x
  quad({0, 0, 0}, {0, 0, H}, {L, 0, 0});  // y = 0, +y
  quad({0, L, 0}, {L, 0, 0}, {0, 0, H});  // y = L, -y
}
}  // namespace

TEST(InterfaceBondForce, TractionConsistentFaceForces) {
  WorldParams p;
  p.local_damping = 0.7;
  p.ball_facet.model = ContactModel::kLinearPBond;
  p.ball_facet.pbond.zero_linear = true;
  p.ball_facet.pbond.ten = 1e300;  // unbreakable (docs/theory.md 2.6)
  p.ball_facet.pbond.coh = 1e300;
  const double L = 2e-3, H = 3e-3, R = 1e-4;
  World w(p);
  std::vector<double> v;
  std::vector<std::int32_t> t;
  box_mesh(L, H, 3, v, t);
  const int wall = w.add_facet_wall(v, t);
  // Balls half a radius into one face each, at least 3R from every other face.
  int n_bottom = 0, n_side = 0;
  for (double a = 4 * R; a <= L - 4 * R + 1e-12; a += 3 * R)
    for (double b = 4 * R; b <= L - 4 * R + 1e-12; b += 3 * R, ++n_bottom) w.add_ball({a, b, 0.5 * R}, R);
  for (double a = 4 * R; a <= L - 4 * R + 1e-12; a += 3 * R)
    for (double z = 4 * R; z <= H - 1e-12; z += 3 * R) {
      w.add_ball({0.5 * R, a, z}, R);
      w.add_ball({L - 0.5 * R, a, z}, R);
      w.add_ball({a, 0.5 * R, z}, R);
      w.add_ball({a, L - 0.5 * R, z}, R);
      n_side += 4;
    }
  for (std::size_t i = 0; i < w.num_balls(); ++i) w.balls().fix[i] = kFixAll;
  w.prepare();
  ASSERT_EQ(w.bond_ball_facet(0.0), static_cast<std::size_t>(n_bottom + n_side));

  InterfaceBondParams ip;
  ip.mode = InterfaceBondForce::kTraction;
  ip.z_top = H;
  ip.unit_weight = 1272.0 * 100 * 9.81;  // rho_b N g0 at 100 g
  ip.k0 = 0.5;
  EXPECT_EQ(assign_interface_bond_forces(w, ip).count, static_cast<std::size_t>(n_bottom + n_side));
  w.step(10);

  // Force of the balls on each face, from the contacts on facets of that face's normal.
  const auto& fc = w.facet_contacts();
  const FacetWall& fw = w.facet_wall(wall);
  Vec3 bottom{}, xlo{};
  std::vector<double> per_depth;  // x = 0 face: |F| / depth of each bond
  for (std::size_t c = 0; c < fc.size(); ++c) {
    const Vec3 n = fw.tri_normal[static_cast<std::size_t>(fc.facet[c])];
    if (std::abs(n.z) > 0.5) bottom = bottom + fc.F[c];
    if (std::abs(n.x) > 0.5 && fc.xc[c].x < 0.5 * L) {
      xlo = xlo + fc.F[c];
      per_depth.push_back(norm(fc.F[c]) / (H - fc.xc[c].z));
    }
  }
  const double gamma = ip.unit_weight;
  const double f_bottom = gamma * H * L * L, f_side = ip.k0 * gamma * H * H / 2 * L;
  std::printf("interface bonds: bottom %.6e N (exact %.6e), side x=0 %.6e N (exact %.6e)\n", -bottom.z, f_bottom,
              -xlo.x, f_side);
  EXPECT_NEAR(-bottom.z / f_bottom, 1.0, 1e-12);  // pushed down, in compression
  EXPECT_NEAR(bottom.x, 0.0, 1e-12 * f_bottom);
  EXPECT_NEAR(-xlo.x / f_side, 1.0, 1e-12);       // pushed outwards (-x)
  EXPECT_NEAR(xlo.z, 0.0, 1e-12 * f_side);        // no shear at the start
  ASSERT_FALSE(per_depth.empty());
  for (double q : per_depth) EXPECT_NEAR(q / per_depth.front(), 1.0, 1e-12);
  // Whole wall: the weight-bearing bottom and four balanced sides.
  const Vec3 total = w.facet_wall_force(wall);
  EXPECT_NEAR(total.z / -f_bottom, 1.0, 1e-12);
  EXPECT_NEAR(total.x, 0.0, 1e-12 * f_side);
  EXPECT_NEAR(total.y, 0.0, 1e-12 * f_side);
}

// Bad input gets one clear error.
TEST(InterfaceBondForce, RejectsNegativeUnitWeight) {
  WorldParams p;
  p.ball_facet.model = ContactModel::kLinearPBond;
  p.ball_facet.pbond.zero_linear = true;
  World w(p);
  InterfaceBondParams ip;
  ip.unit_weight = -1.0;
  EXPECT_THROW(assign_interface_bond_forces(w, ip), std::invalid_argument);
}
