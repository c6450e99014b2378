// Tetrahedron geometry for the mixed discretisation (docs/theory.md 5.2, 5.3).
//
// For a positively oriented tetrahedron (p1..p4) with volume V, the barycentric gradients
// g_l = grad(lambda_l) relate to the outward face area vectors of docs/theory.md 5.3 by
// a^(l) = -3V g_l. So
//   grad v = -(1/3V) sum_l v^l (x) a^(l) = sum_l v^l (x) g_l = sum_{l=2..4} (v^l - v^1) (x) g_l,
//   f^l = (1/3) sigma a^(l) = -V sigma g_l,    sum_l g_l = 0.
// The engine stores g_2, g_3, g_4 and V per tetrahedron (g_1 = -(g_2+g_3+g_4)).
#pragma once

#include <array>

namespace demfdm::fdm {

using Vec3 = std::array<double, 3>;

// Hexahedron -> 2 overlays x 5 tetrahedra (docs/theory.md 5.2), local corner ids in unit-cube
// order, each ordered so that its signed volume is positive on a right-handed hexahedron.
// Tetrahedra 0..4 form overlay A (central one first), 5..9 overlay B.
inline constexpr int kTetsPerZone = 10;
inline constexpr std::array<std::array<int, 4>, kTetsPerZone> kZoneTets{{
    {1, 3, 4, 6}, {0, 1, 3, 4}, {2, 1, 6, 3}, {5, 1, 4, 6}, {7, 3, 6, 4},  // overlay A
    {0, 2, 7, 5}, {1, 0, 5, 2}, {3, 0, 2, 7}, {4, 0, 7, 5}, {6, 2, 5, 7},  // overlay B
}};

inline Vec3 sub(const Vec3& a, const Vec3& b) { return {a[0] - b[0], a[1] - b[1], a[2] - b[2]}; }
inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return {a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]};
}
inline double dot(const Vec3& a, const Vec3& b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// Signed volume (1/6)(p2-p1).((p3-p1)x(p4-p1)) (docs/theory.md 5.3).
inline double tet_volume(const Vec3& p1, const Vec3& p2, const Vec3& p3, const Vec3& p4) {
  return dot(sub(p2, p1), cross(sub(p3, p1), sub(p4, p1))) / 6.0;
}

// Barycentric gradients g_2, g_3, g_4 (9 values) and the signed volume V, written to out[10].
inline void tet_gradients(const Vec3& p1, const Vec3& p2, const Vec3& p3, const Vec3& p4, double* out) {
  const Vec3 e2 = sub(p2, p1), e3 = sub(p3, p1), e4 = sub(p4, p1);
  const Vec3 c2 = cross(e3, e4), c3 = cross(e4, e2), c4 = cross(e2, e3);
  const double six_v = dot(e2, c2);
  const double inv = 1.0 / six_v;
  for (int i = 0; i < 3; ++i) {
    out[i] = c2[i] * inv;
    out[3 + i] = c3[i] * inv;
    out[6 + i] = c4[i] * inv;
  }
  out[9] = six_v / 6.0;
}

// Outward area vectors a^(1..4) of docs/theory.md 5.3, computed face by face:
// a^(l) = 1/2 (p_j - p_i) x (p_k - p_i) over the face opposite l, flipped if needed so that
// a^(l).(p_l - p_i) < 0. Independent of tet_gradients (tests compare the two).
inline std::array<Vec3, 4> tet_area_vectors(const Vec3& p1, const Vec3& p2, const Vec3& p3, const Vec3& p4) {
  const std::array<const Vec3*, 4> p{&p1, &p2, &p3, &p4};
  std::array<Vec3, 4> a{};
  for (int l = 0; l < 4; ++l) {
    const Vec3& pi = *p[(l + 1) % 4];
    const Vec3& pj = *p[(l + 2) % 4];
    const Vec3& pk = *p[(l + 3) % 4];
    Vec3 c = cross(sub(pj, pi), sub(pk, pi));
    const double sgn = dot(c, sub(*p[l], pi)) < 0.0 ? 0.5 : -0.5;
    for (int d = 0; d < 3; ++d) a[l][d] = sgn * c[d];
  }
  return a;
}

}  // namespace demfdm::fdm
