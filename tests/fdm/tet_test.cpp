// Tetrahedron identities (docs/theory.md 5.3, 8.10) and the hexahedron split (5.2).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "demfdm/fdm/tet.hpp"

namespace demfdm::fdm {
namespace {

Vec3 random_point(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  return {u(rng), u(rng), u(rng)};
}

// Sum_l a^(l) = 0 and Sum_l p_l (x) a^(l) = -3V I for random tetrahedra, and a^(l) = -3V g_l
// (the form the engine stores). Tolerance 1e-13 relative to the tetrahedron scale.
TEST(TetIdentities, AreaVectorsSumToZeroAndGiveMinusThreeVolumeIdentity) {
  std::mt19937_64 rng(12345);
  for (int trial = 0; trial < 200; ++trial) {
    std::array<Vec3, 4> p{random_point(rng), random_point(rng), random_point(rng), random_point(rng)};
    double V = tet_volume(p[0], p[1], p[2], p[3]);
    if (std::abs(V) < 1e-3) continue;
    if (V < 0.0) {
      std::swap(p[2], p[3]);  // orientation rule of docs/theory.md 5.3: swap two nodes
      V = -V;
    }
    const auto a = tet_area_vectors(p[0], p[1], p[2], p[3]);
    for (int d = 0; d < 3; ++d) EXPECT_NEAR(a[0][d] + a[1][d] + a[2][d] + a[3][d], 0.0, 1e-13);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double s = 0.0;
        for (int l = 0; l < 4; ++l) s += p[l][i] * a[l][j];
        EXPECT_NEAR(s, i == j ? -3.0 * V : 0.0, 1e-13);
      }
    double g[10];
    tet_gradients(p[0], p[1], p[2], p[3], g);
    EXPECT_NEAR(g[9], V, 1e-15);
    for (int l = 1; l < 4; ++l)
      for (int d = 0; d < 3; ++d) EXPECT_NEAR(a[l][d], -3.0 * V * g[3 * (l - 1) + d], 1e-12 * (1.0 + std::abs(a[l][d])));
  }
}

// Unit cube: central tetrahedra hold 1/3 of the volume, corner ones 1/6; each overlay fills the
// cube exactly (docs/theory.md 5.2); all 10 are positively oriented with the engine's node order.
TEST(TetIdentities, CubeSplitVolumes) {
  const Vec3 c[8] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  double sum[2] = {0.0, 0.0};
  for (int t = 0; t < kTetsPerZone; ++t) {
    const auto& n = kZoneTets[t];
    const double V = tet_volume(c[n[0]], c[n[1]], c[n[2]], c[n[3]]);
    EXPECT_NEAR(V, (t % 5 == 0) ? 1.0 / 3.0 : 1.0 / 6.0, 1e-15) << "tet " << t;
    sum[t / 5] += V;
  }
  EXPECT_NEAR(sum[0], 1.0, 1e-15);
  EXPECT_NEAR(sum[1], 1.0, 1e-15);
}

}  // namespace
}  // namespace demfdm::fdm
