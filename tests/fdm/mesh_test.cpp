// Mesh generation and interface numbering (docs/theory.md 5.1, 6.2).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>

#include "demfdm/fdm/mesh.hpp"
#include "demfdm/fdm/tet.hpp"

namespace demfdm::fdm {
namespace {

bool contains(const std::vector<double>& g, double v) {
  return std::any_of(g.begin(), g.end(), [&](double x) { return std::abs(x - v) < 1e-15; });
}

// Grid lines pass through the inner box faces; sizes <= size_near inside, neighbour ratio <=
// growth outside, no size above size_far, exact total length.
TEST(GradedAxis, HonoursInnerFacesGrowthAndCap) {
  const double L = 16e-3, a = 6e-3, b = 10e-3;
  const auto g = graded_axis(L, a, b, 0.5e-3, 2e-3, 1.2);
  EXPECT_DOUBLE_EQ(g.front(), 0.0);
  EXPECT_DOUBLE_EQ(g.back(), L);
  EXPECT_TRUE(contains(g, a));
  EXPECT_TRUE(contains(g, b));
  for (std::size_t i = 1; i < g.size(); ++i) {
    const double h = g[i] - g[i - 1];
    EXPECT_GT(h, 0.0);
    EXPECT_LE(h, 2e-3 * (1 + 1e-12));
    if (g[i] <= b + 1e-15 && g[i - 1] >= a - 1e-15) {
      EXPECT_LE(h, 0.5e-3 * (1 + 1e-12));
    }
    if (i >= 2) {
      const double h0 = g[i - 1] - g[i - 2];
      EXPECT_LE(std::max(h, h0) / std::min(h, h0), 1.2 * (1 + 1e-9)) << "at line " << i;
    }
  }
}

TEST(GradedAxis, UniformWithoutInnerInterval) {
  const auto g = graded_axis(1.0, 0.0, 0.0, 0.3, 0.3, 1.0);
  ASSERT_EQ(g.size(), 5u);  // ceil(1/0.3) = 4 zones
  for (std::size_t i = 1; i < g.size(); ++i) EXPECT_NEAR(g[i] - g[i - 1], 0.25, 1e-15);
}

double zone_volume(const Mesh& m, std::size_t z) {
  Vec3 p[8];
  for (int k = 0; k < 8; ++k)
    for (int d = 0; d < 3; ++d) p[k][d] = m.points[3 * m.zones[8 * z + k] + d];
  double v = 0.0;
  for (int t = 0; t < 5; ++t) {
    const auto& n = kZoneTets[t];
    v += tet_volume(p[n[0]], p[n[1]], p[n[2]], p[n[3]]);
  }
  return v;
}

// The paper's default: 16 mm box, 4x4x10 mm pocket at the top centre, 0.5 mm near the pocket.
TEST(PocketMesh, DefaultGeometryVolumeAndInterface) {
  const MeshParams p;  // defaults (docs/theory.md 0.3, 5.1)
  const Mesh m = generate_mesh(p);
  EXPECT_TRUE(m.has_pocket);
  EXPECT_NEAR(m.pocket.lo[0], 6e-3, 1e-15);
  EXPECT_NEAR(m.pocket.hi[1], 10e-3, 1e-15);
  EXPECT_NEAR(m.pocket.lo[2], 6e-3, 1e-15);
  EXPECT_DOUBLE_EQ(m.pocket.hi[2], 16e-3);
  // Volume of the zones = box - pocket.
  double vol = 0.0;
  for (std::size_t z = 0; z < m.num_zones(); ++z) vol += zone_volume(m, z);
  EXPECT_NEAR(vol, 16e-3 * 16e-3 * 16e-3 - 4e-3 * 4e-3 * 10e-3, 1e-15);
  // No gridpoint strictly inside the pocket.
  for (std::size_t g = 0; g < m.num_points(); ++g) {
    const double* x = &m.points[3 * g];
    const bool inside = x[0] > 6e-3 + 1e-12 && x[0] < 10e-3 - 1e-12 && x[1] > 6e-3 + 1e-12 &&
                        x[1] < 10e-3 - 1e-12 && x[2] > 6e-3 + 1e-12;
    EXPECT_FALSE(inside) << "gridpoint " << g;
  }
  // Interface: 8x8 bottom quads + 4 sides of 8x20 quads at 0.5 mm, two triangles each.
  EXPECT_EQ(m.num_interface_triangles(), 2u * (64 + 4 * 160));
  EXPECT_TRUE(std::is_sorted(m.interface_points.begin(), m.interface_points.end()));
  // Triangle normals point into the pocket; areas add up to the pocket's wetted surface.
  double area = 0.0;
  for (std::size_t t = 0; t < m.num_interface_triangles(); ++t) {
    Vec3 q[3];
    for (int c = 0; c < 3; ++c)
      for (int d = 0; d < 3; ++d) q[c][d] = m.points[3 * m.interface_points[m.interface_triangles[3 * t + c]] + d];
    const Vec3 n = cross(sub(q[1], q[0]), sub(q[2], q[0]));
    const double a2 = std::sqrt(dot(n, n));
    area += 0.5 * a2;
    Vec3 probe;
    for (int d = 0; d < 3; ++d) probe[d] = (q[0][d] + q[1][d] + q[2][d]) / 3.0 + 1e-5 * n[d] / a2;
    EXPECT_TRUE(m.pocket.contains(probe)) << "triangle " << t;
    for (int c = 0; c < 3; ++c) EXPECT_TRUE(m.pocket.contains(q[c]));
  }
  EXPECT_NEAR(area, 4e-3 * 4e-3 + 4 * 4e-3 * 10e-3, 1e-15);
  // Deterministic: a second build is identical.
  const Mesh m2 = generate_mesh(p);
  EXPECT_EQ(m.points, m2.points);
  EXPECT_EQ(m.zones, m2.zones);
  EXPECT_EQ(m.interface_triangles, m2.interface_triangles);
}

// The boundary of the meshed region is closed: the outward area vectors sum to zero, and the
// boundary faces include every interface face.
TEST(PocketMesh, BoundaryFacesClosedSurface) {
  MeshParams p;
  p.size_near = 1e-3;
  p.size_far = 3e-3;
  p.inner_origin = {2e-3, 5e-3, kNaN};  // off-centre pocket
  const Mesh m = generate_mesh(p);
  const auto faces = boundary_faces(m);
  Vec3 sum{0.0, 0.0, 0.0};
  std::size_t pocket_faces = 0;
  for (const auto& f : faces) {
    Vec3 q[4];
    for (int c = 0; c < 4; ++c)
      for (int d = 0; d < 3; ++d) q[c][d] = m.points[3 * f.points[c] + d];
    const Vec3 a = cross(sub(q[2], q[0]), sub(q[3], q[1]));
    for (int d = 0; d < 3; ++d) sum[d] += 0.5 * a[d];
    bool on_pocket = true;
    for (int c = 0; c < 4; ++c) on_pocket = on_pocket && m.pocket.contains(q[c]);
    pocket_faces += on_pocket ? 1 : 0;
  }
  for (int d = 0; d < 3; ++d) EXPECT_NEAR(sum[d], 0.0, 1e-18);
  EXPECT_EQ(pocket_faces, m.num_interface_triangles() / 2);
}

TEST(MeshParamsValidation, NamesTheField) {
  MeshParams p;
  p.growth = 3.0;
  try {
    (void)generate_mesh(p);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("mesh.growth"), std::string::npos) << e.what();
  }
  MeshParams q;
  q.inner_origin = {14e-3, kNaN, kNaN};  // pocket sticks out of the box in x
  EXPECT_THROW((void)generate_mesh(q), std::invalid_argument);
}

}  // namespace
}  // namespace demfdm::fdm
