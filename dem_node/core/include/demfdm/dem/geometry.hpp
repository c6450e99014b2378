// Geometric kernels for ball–wall contacts (docs/theory.md §1.4, §6.4).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>

#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

/// Closest point of triangle (a, b, c) to p with its barycentric weights (Ericson 2005,
/// Real-Time Collision Detection §5.1.5, Voronoi regions of face, edges and vertices).
/// Returns the region: 0 = face interior, 1 = edge, 2 = vertex.
inline int closest_point_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                                  Vec3& q, Vec3& w) {
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) { q = a; w = {1, 0, 0}; return 2; }
  const Vec3 bp = p - b;
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) { q = b; w = {0, 1, 0}; return 2; }
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
    const double v = d1 / (d1 - d3);
    q = a + v * ab; w = {1 - v, v, 0}; return 1;
  }
  const Vec3 cp = p - c;
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) { q = c; w = {0, 0, 1}; return 2; }
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
    const double t = d2 / (d2 - d6);
    q = a + t * ac; w = {1 - t, 0, t}; return 1;
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0) {
    const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    q = b + t * (c - b); w = {0, 1 - t, t}; return 1;
  }
  const double den = 1.0 / (va + vb + vc);
  const double v = vb * den, t = vc * den;
  q = a + v * ab + t * ac; w = {1 - v - t, v, t};
  return 0;
}

/// §6.4: equivalent force system on the three vertices of a facet for a force F acting at
/// x_c plus a moment M. The vertex forces f[i] have resultant F and resultant moment (about
/// any point) equal to that of (F at x_c, M). The normal is (p2−p1)×(p3−p1)/‖…‖.
inline void facet_equivalent_forces(const std::array<Vec3, 3>& p, const Vec3& xc, const Vec3& F,
                                    const Vec3& M, std::array<Vec3, 3>& f) {
  Vec3 q, w;
  closest_point_triangle(xc, p[0], p[1], p[2], q, w);  // projection clamped into the triangle
  // 1. barycentric split: resultant F, zero moment about q
  for (int i = 0; i < 3; ++i) f[i] = w[i] * F;
  // 2. moment still to represent, about q
  const Vec3 dM = M + cross(xc - q, F);
  Vec3 nf = cross(p[1] - p[0], p[2] - p[0]);
  nf *= 1.0 / norm(nf);
  const Vec3 xg = (1.0 / 3.0) * (p[0] + p[1] + p[2]);
  Vec3 t1 = p[1] - p[0];
  t1 *= 1.0 / norm(t1);
  const Vec3 t2 = cross(nf, t1);  // t1 × t2 = n̂
  std::array<Vec3, 3> r;
  double a[3], b[3], rr = 0.0;
  for (int i = 0; i < 3; ++i) {
    r[i] = p[i] - xg;
    a[i] = dot(r[i], t1);
    b[i] = dot(r[i], t2);
    rr += norm2(r[i]);
  }
  // 3. in-plane moment → normal forces g_i n̂: [1 1 1; b; −a] g = [0; ΔM·t1; ΔM·t2]
  const double m1 = dot(dM, t1), m2 = dot(dM, t2);
  // Solve with Cramer's rule (3×3, non-singular for a non-degenerate triangle).
  const double A[3][3] = {{1, 1, 1}, {b[0], b[1], b[2]}, {-a[0], -a[1], -a[2]}};
  const double rhs[3] = {0.0, m1, m2};
  auto det3 = [](const double m[3][3]) {
    return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
           m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
           m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
  };
  const double D = det3(A);
  for (int k = 0; k < 3; ++k) {
    double Ak[3][3];
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) Ak[i][j] = (j == k) ? rhs[i] : A[i][j];
    f[k] += (det3(Ak) / D) * nf;
  }
  // 4. normal moment → in-plane forces c (n̂ × r_i)
  const double cc = dot(dM, nf) / rr;
  for (int i = 0; i < 3; ++i) f[i] += cc * cross(nf, r[i]);
}

/// Closest point of a solid vertical cylinder (bottom centre c, radius R, height H) to p.
/// Returns the signed distance (negative inside) and the unit normal pointing from p to the
/// surface point (for a point inside: opposite to the outward normal of the nearest face).
inline double closest_point_cylinder(const Vec3& p, const Vec3& c, double R, double H, Vec3& q,
                                     Vec3& n) {
  const Vec3 rel = p - c;
  const double r = std::sqrt(rel.x * rel.x + rel.y * rel.y);
  const double h = rel.z;
  const bool inside = r <= R && h >= 0.0 && h <= H;
  const Vec3 er = r > 0.0 ? Vec3{rel.x / r, rel.y / r, 0.0} : Vec3{1.0, 0.0, 0.0};
  if (!inside) {
    const double rc = std::min(r, R), hc = std::clamp(h, 0.0, H);
    q = c + rc * er + Vec3{0, 0, hc};
    const Vec3 d = q - p;
    const double dist = norm(d);
    n = d * (1.0 / dist);
    return dist;
  }
  const double db = h, dtp = H - h, ds = R - r;
  if (db <= dtp && db <= ds) { q = Vec3{p.x, p.y, c.z}; n = {0, 0, 1}; return -db; }
  if (dtp <= ds) { q = Vec3{p.x, p.y, c.z + H}; n = {0, 0, -1}; return -dtp; }
  q = c + R * er + Vec3{0, 0, h};
  n = -er;
  return -ds;
}

}  // namespace demfdm::dem
