// Constitutive laws (docs/theory.md 5.4).
#include "demfdm/fdm/constitutive.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

namespace demfdm::fdm {

MaterialConstants make_constants(const Material& mat) {
  MaterialConstants m;
  m.bulk = mat.young / (3.0 * (1.0 - 2.0 * mat.poisson));
  m.shear = mat.young / (2.0 * (1.0 + mat.poisson));
  m.alpha1 = m.bulk + 4.0 * m.shear / 3.0;
  m.alpha2 = m.bulk - 2.0 * m.shear / 3.0;
  m.density = mat.density;
  if (mat.model == Constitutive::kMohrCoulomb) {
    const double phi = mat.friction_deg * std::numbers::pi / 180.0;
    const double psi = mat.dilation_deg * std::numbers::pi / 180.0;
    m.cohesion = mat.cohesion;
    m.n_phi = (1.0 + std::sin(phi)) / (1.0 - std::sin(phi));
    m.n_psi = (1.0 + std::sin(psi)) / (1.0 - std::sin(psi));
    m.sqrt_n_phi = std::sqrt(m.n_phi);
    // sigma^t <= c / tan(phi): the cut-off cannot lie beyond the apex of the shear cone.
    const double apex = phi > 0.0 ? mat.cohesion / std::tan(phi) : std::numeric_limits<double>::infinity();
    m.tension = std::isnan(mat.tension) ? apex : std::min(mat.tension, apex);
    m.alpha_p = std::sqrt(1.0 + m.n_phi * m.n_phi) + m.n_phi;
    m.sigma_p = m.tension * m.n_phi - 2.0 * m.cohesion * m.sqrt_n_phi;
  }
  return m;
}

std::array<double, 3> principal_values(const double* s) {
  // Closed form for symmetric 3x3 (trigonometric solution of the characteristic cubic).
  const double p1 = s[3] * s[3] + s[4] * s[4] + s[5] * s[5];
  const double q = (s[0] + s[1] + s[2]) / 3.0;
  const double d0 = s[0] - q, d1 = s[1] - q, d2 = s[2] - q;
  const double p2 = d0 * d0 + d1 * d1 + d2 * d2 + 2.0 * p1;
  if (p2 <= 0.0) return {q, q, q};
  const double p = std::sqrt(p2 / 6.0);
  // det((A - qI)/p)/2
  const double b00 = d0 / p, b11 = d1 / p, b22 = d2 / p, b01 = s[3] / p, b12 = s[4] / p, b02 = s[5] / p;
  const double det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02);
  const double r = std::clamp(0.5 * det, -1.0, 1.0);
  const double phi = std::acos(r) / 3.0;
  const double e3 = q + 2.0 * p * std::cos(phi);
  const double e1 = q + 2.0 * p * std::cos(phi + 2.0 * std::numbers::pi / 3.0);
  const double e2 = 3.0 * q - e1 - e3;
  return {e1, e2, e3};
}

void symmetric_eigen(const double* s, std::array<double, 3>& val, std::array<std::array<double, 3>, 3>& vec) {
  double a[3][3] = {{s[0], s[3], s[5]}, {s[3], s[1], s[4]}, {s[5], s[4], s[2]}};
  double v[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  for (int sweep = 0; sweep < 50; ++sweep) {
    const double off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
    const double diag = a[0][0] * a[0][0] + a[1][1] * a[1][1] + a[2][2] * a[2][2];
    // off-diagonal below 1e-15 of the diagonal: converged to round-off.
    if (off <= 1e-30 * diag || off == 0.0) break;
    for (int p = 0; p < 2; ++p)
      for (int q = p + 1; q < 3; ++q) {
        if (a[p][q] == 0.0) continue;
        const double theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
        const double t = (theta >= 0.0 ? 1.0 : -1.0) / (std::abs(theta) + std::sqrt(theta * theta + 1.0));
        const double c = 1.0 / std::sqrt(t * t + 1.0);
        const double sn = t * c;
        // A <- J^T A J with the rotation in the (p, q) plane.
        for (int k = 0; k < 3; ++k) {
          const double akp = a[k][p], akq = a[k][q];
          a[k][p] = c * akp - sn * akq;
          a[k][q] = sn * akp + c * akq;
        }
        for (int k = 0; k < 3; ++k) {
          const double apk = a[p][k], aqk = a[q][k];
          a[p][k] = c * apk - sn * aqk;
          a[q][k] = sn * apk + c * aqk;
        }
        for (int k = 0; k < 3; ++k) {
          const double vkp = v[k][p], vkq = v[k][q];
          v[k][p] = c * vkp - sn * vkq;
          v[k][q] = sn * vkp + c * vkq;
        }
      }
  }
  int idx[3] = {0, 1, 2};
  std::sort(idx, idx + 3, [&](int x, int y) { return a[x][x] < a[y][y] || (a[x][x] == a[y][y] && x < y); });
  for (int k = 0; k < 3; ++k) {
    val[k] = a[idx[k]][idx[k]];
    for (int d = 0; d < 3; ++d) vec[k][d] = v[d][idx[k]];
  }
}

void symmetric_eigen_fast(const double* s, std::array<double, 3>& val, std::array<std::array<double, 3>, 3>& vec) {
  const auto lam = principal_values(s);
  const double spread = lam[2] - lam[0];
  if (!(spread > 1e-9 * (std::abs(lam[0]) + std::abs(lam[2])))) {
    symmetric_eigen(s, val, vec);  // (nearly) isotropic: any basis would do, Jacobi is exact
    return;
  }
  // The eigenvalue farthest from the other two is accurate in closed form (the acos error
  // falls on the close pair), and so is its eigenvector from cross products of the rows of
  // A - lambda I (the gap is at least half the spread).
  const int k = (lam[1] - lam[0]) > (lam[2] - lam[1]) ? 0 : 2;
  const double a[3][3] = {{s[0], s[3], s[5]}, {s[3], s[1], s[4]}, {s[5], s[4], s[2]}};
  double r[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = a[i][j] - (i == j ? lam[k] : 0.0);
  auto crs = [](const double* u, const double* w, double* o) {
    o[0] = u[1] * w[2] - u[2] * w[1];
    o[1] = u[2] * w[0] - u[0] * w[2];
    o[2] = u[0] * w[1] - u[1] * w[0];
  };
  double c[3][3];
  crs(r[0], r[1], c[0]);
  crs(r[0], r[2], c[1]);
  crs(r[1], r[2], c[2]);
  int best = 0;
  double bn = 0.0;
  for (int i = 0; i < 3; ++i) {
    const double n = c[i][0] * c[i][0] + c[i][1] * c[i][1] + c[i][2] * c[i][2];
    if (n > bn) {
      bn = n;
      best = i;
    }
  }
  if (!(bn > 0.0)) {
    symmetric_eigen(s, val, vec);
    return;
  }
  const double inv = 1.0 / std::sqrt(bn);
  const double v[3] = {c[best][0] * inv, c[best][1] * inv, c[best][2] * inv};
  // Orthonormal basis (t1, t2) of the plane normal to v.
  double t1[3];
  if (std::abs(v[0]) <= std::abs(v[1]) && std::abs(v[0]) <= std::abs(v[2])) {
    const double e[3] = {1.0, 0.0, 0.0};
    crs(v, e, t1);
  } else if (std::abs(v[1]) <= std::abs(v[2])) {
    const double e[3] = {0.0, 1.0, 0.0};
    crs(v, e, t1);
  } else {
    const double e[3] = {0.0, 0.0, 1.0};
    crs(v, e, t1);
  }
  const double n1 = 1.0 / std::sqrt(t1[0] * t1[0] + t1[1] * t1[1] + t1[2] * t1[2]);
  for (double& x : t1) x *= n1;
  double t2[3];
  crs(v, t1, t2);
  auto quad = [&](const double* x, const double* y) {
    double q = 0.0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) q += x[i] * a[i][j] * y[j];
    return q;
  };
  const double lv = quad(v, v);  // Rayleigh quotient: accurate to round-off
  const double b11 = quad(t1, t1), b22 = quad(t2, t2), b12 = quad(t1, t2);
  // Exact 2x2 diagonalisation in the plane: rotation angle theta with tan(2 theta) =
  // 2 b12 / (b11 - b22).
  const double theta = 0.5 * std::atan2(2.0 * b12, b11 - b22);
  const double cs = std::cos(theta), sn = std::sin(theta);
  double u1[3], u2[3];
  for (int i = 0; i < 3; ++i) {
    u1[i] = cs * t1[i] + sn * t2[i];
    u2[i] = -sn * t1[i] + cs * t2[i];
  }
  const double m1 = b11 * cs * cs + 2.0 * b12 * cs * sn + b22 * sn * sn;
  const double m2 = b11 * sn * sn - 2.0 * b12 * cs * sn + b22 * cs * cs;
  struct Pair {
    double value;
    const double* dir;
  };
  Pair p[3] = {{lv, v}, {m1, u1}, {m2, u2}};
  std::sort(p, p + 3, [](const Pair& x, const Pair& y) { return x.value < y.value; });
  for (int i = 0; i < 3; ++i) {
    val[i] = p[i].value;
    for (int d = 0; d < 3; ++d) vec[i][d] = p[i].dir[d];
  }
}

std::uint8_t mohr_coulomb_return(const MaterialConstants& m, double* s) {
  // Cheapest check first, with a square root only: every principal value lies within
  // r = sqrt(2/3) |dev sigma| of the mean stress, so sigma1 >= p - r and sigma3 <= p + r.
  // If even these bounds satisfy both criteria, the state is elastic.
  {
    const double p = (s[0] + s[1] + s[2]) / 3.0;
    const double d0 = s[0] - p, d1 = s[1] - p, d2 = s[2] - p;
    const double r = std::sqrt((2.0 / 3.0) * (d0 * d0 + d1 * d1 + d2 * d2 +
                                              2.0 * (s[3] * s[3] + s[4] * s[4] + s[5] * s[5])));
    if ((p - r) - (p + r) * m.n_phi + 2.0 * m.cohesion * m.sqrt_n_phi >= 0.0 && p + r <= m.tension) return 0;
  }
  // Then the closed-form principal values: most tetrahedra stay elastic.
  const auto pv = principal_values(s);
  const double tol = 1e-14 * (std::abs(pv[0]) + std::abs(pv[2]) + m.cohesion);
  const double fs0 = pv[0] - pv[2] * m.n_phi + 2.0 * m.cohesion * m.sqrt_n_phi;
  const double ft0 = m.tension - pv[2];
  if (fs0 >= -tol && ft0 >= -tol) return 0;

  std::array<double, 3> sig{};
  std::array<std::array<double, 3>, 3> e{};
  symmetric_eigen_fast(s, sig, e);
  const double a1 = m.alpha1, a2 = m.alpha2;
  const double fs = sig[0] - sig[2] * m.n_phi + 2.0 * m.cohesion * m.sqrt_n_phi;
  const double ft = m.tension - sig[2];
  const double h = sig[2] - m.tension + m.alpha_p * (sig[0] - m.sigma_p);
  std::uint8_t state = 0;
  if (fs < 0.0 && h <= 0.0) {
    // Shear failure, flow rule g^s = sigma1 - sigma3 N_psi (docs/theory.md 5.4).
    const double A1 = a1 - a2 * m.n_psi, B = a2 * (1.0 - m.n_psi), A3 = a2 - a1 * m.n_psi;
    const double P = A1 - A3 * m.n_phi;
    const double s1 = sig[0], s2 = sig[1], s3 = sig[2];
    const double lam = fs / P;
    sig[0] = s1 - lam * A1;
    sig[1] = s2 - lam * B;
    sig[2] = s3 - lam * A3;
    const double k = 2.0 * m.cohesion * m.sqrt_n_phi;
    if (sig[2] < sig[1]) {
      // Triaxial-compression edge (sigma2 ~ sigma3): planes (1,3) and (1,2) both active,
      // [P Q; Q P][la; lb] = [f13; f12] with the same flow rule on each plane.
      const double Q = A1 - B * m.n_phi;
      const double f12 = s1 - s2 * m.n_phi + k;
      const double det = P * P - Q * Q;
      const double la = (P * fs - Q * f12) / det, lb = (P * f12 - Q * fs) / det;
      sig[0] = s1 - (la + lb) * A1;
      sig[1] = s2 - la * B - lb * A3;
      sig[2] = s3 - la * A3 - lb * B;
    } else if (sig[0] > sig[1]) {
      // Triaxial-extension edge (sigma1 ~ sigma2): planes (1,3) and (2,3) both active,
      // [P R; R P][la; lc] = [f13; f23].
      const double R = B - A3 * m.n_phi;
      const double f23 = s2 - s3 * m.n_phi + k;
      const double det = P * P - R * R;
      const double la = (P * fs - R * f23) / det, lc = (P * f23 - R * fs) / det;
      sig[0] = s1 - la * A1 - lc * B;
      sig[1] = s2 - la * B - lc * A1;
      sig[2] = s3 - (la + lc) * A3;
    }
    state = kShearNow;
  } else if (ft < 0.0 && h > 0.0) {
    // Tensile failure, flow rule g^t = -sigma3 (docs/theory.md 5.4).
    const double t = m.tension;
    const double s1 = sig[0], s2 = sig[1], s3 = sig[2];
    const double l3 = (s3 - t) / a1;
    sig[0] = s1 - l3 * a2;
    sig[1] = s2 - l3 * a2;
    sig[2] = t;
    if (sig[1] > t) {
      // Corner: sigma2 and sigma3 both on the cut-off, [a1 a2; a2 a1][l2; l3] = [s2-t; s3-t].
      const double det = a1 * a1 - a2 * a2;
      const double l2c = (a1 * (s2 - t) - a2 * (s3 - t)) / det;
      const double l3c = (a1 * (s3 - t) - a2 * (s2 - t)) / det;
      sig[0] = s1 - a2 * (l2c + l3c);
      sig[1] = t;
      if (sig[0] > t) sig[0] = t;  // apex: all three on the cut-off
    }
    state = kTensionNow;
  } else {
    return 0;
  }
  // Rebuild sigma = sum_k sigma_k e_k (x) e_k.
  double r[6] = {0, 0, 0, 0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    const auto& v = e[k];
    r[0] += sig[k] * v[0] * v[0];
    r[1] += sig[k] * v[1] * v[1];
    r[2] += sig[k] * v[2] * v[2];
    r[3] += sig[k] * v[0] * v[1];
    r[4] += sig[k] * v[1] * v[2];
    r[5] += sig[k] * v[0] * v[2];
  }
  for (int i = 0; i < 6; ++i) s[i] = r[i];
  return state;
}

}  // namespace demfdm::fdm
