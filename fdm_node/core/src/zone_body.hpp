// One zone of the zone pass (docs/theory.md 5.3-5.5, 5.8), written once: Model::zone_kernel
// runs it zone by zone, the lane loops of zone_block_body.inc run it on kLanes zones at once
// (one zone per vector lane, the same operations in the same order, so the same bits).
#pragma once

#include <cstdint>

#include "demfdm/fdm/constitutive.hpp"
#include "demfdm/fdm/tet.hpp"

namespace demfdm::fdm::zone {

struct ElasticLaw {
  static constexpr std::uint8_t kNow = 0;  // never plastic
  [[gnu::always_inline]] static std::uint8_t update(const MaterialConstants& m, const double* de, double* s) {
    elastic_update(m, de, s);
    return kNow;
  }
};

struct MohrCoulombLaw {
  static std::uint8_t update(const MaterialConstants& m, const double* de, double* s) {
    return mohr_coulomb_update(m, de, s);
  }
};

// What the zone pass reads and writes (Model's arrays).
struct Ctx {
  const std::int32_t* conn;        // [nz, 8] corner gridpoints
  const double* vel;               // [n, 3]
  const double* geom;              // [nz*10, 10] g2, g3, g4, V (reference geometry)
  double* stress;                  // [nz*10, 6]
  double* slot;                    // [nz, 8, 3] nodal forces of each zone
  std::uint8_t* plastic;           // [nz] PlasticState bits
  const MaterialConstants* mats;   // per group
  const std::int32_t* zmat;        // [nz] group of each zone
  double dt;
};

// A zone's PlasticState bits after a step whose law returned `now` (the "now" bits; the "past"
// bits keep every state the zone has been in).
[[gnu::always_inline]] inline std::uint8_t plastic_bits(std::uint8_t old, std::uint8_t now) {
  return static_cast<std::uint8_t>((old & (kShearPast | kTensionPast)) | now | (now << 2));
}

// One zone in Model's arrays, as zone_body reads and writes it (the lane loops have their own
// view of the same values, zone_block_body.inc).
struct ZoneRef {
  const Ctx& k;
  std::int32_t z;
  const double* G;  // the zone's 10 x 10 geometry values (reference, or current in large strain)
  double vel(int q, int d) const { return k.vel[3 * static_cast<std::size_t>(k.conn[8 * static_cast<std::size_t>(z) + q]) + d]; }
  double g(int i) const { return G[i]; }
  double& s(int i) const { return k.stress[60 * static_cast<std::size_t>(z) + i]; }
  const MaterialConstants& mat() const { return k.mats[k.zmat[z]]; }
  void set_plastic(std::uint8_t now) const { k.plastic[z] = plastic_bits(k.plastic[z], now); }
  double& f(int i) const { return k.slot[24 * static_cast<std::size_t>(z) + i]; }
};

// Velocity gradient L_ij = sum_{l=2..4} (v^l - v^1)_i g_l,j (tet.hpp), g = the tetrahedron's
// g2, g3, g4 starting at a.g(g0).
template <class V, class A>
[[gnu::always_inline]] inline void tet_gradient(const V& v, const std::array<int, 4>& n, const A& a, int g0, double* L) {
  double dv[3][3];
#pragma GCC unroll 3
  for (int l = 0; l < 3; ++l)
#pragma GCC unroll 3
    for (int i = 0; i < 3; ++i) dv[l][i] = v[n[l + 1]][i] - v[n[0]][i];
#pragma GCC unroll 3
  for (int i = 0; i < 3; ++i)
#pragma GCC unroll 3
    for (int j = 0; j < 3; ++j)
      L[3 * i + j] = dv[0][i] * a.g(g0 + j) + dv[1][i] * a.g(g0 + 3 + j) + dv[2][i] * a.g(g0 + 6 + j);
}

// The same from a plain array of 10 x 10 geometry values (Model::tet_velocity_gradients).
inline void tet_gradient(const double (*v)[3], const std::array<int, 4>& n, const double* g, double* L) {
  struct Plain {
    const double* G;
    double g(int i) const { return G[i]; }
  };
  tet_gradient(v, n, Plain{g}, 0, L);
}

// One zone (a: ZoneRef or a lane of the lane loops): strain increments of its 10 tetrahedra
// with the mixed discretisation's volumetric averaging (per overlay, or per zone with ZoneAvg),
// the Jaumann correction (Large), the law's stress update, and the nodal forces
// f^l = -V sigma g_l averaged over the two overlays into the zone's slot.
template <class Law, bool Large, bool ZoneAvg, class A>
[[gnu::always_inline]] inline void zone_body(const A& a, double dt, bool update_stress) {
  if (update_stress) {
    double vz[8][3];
#pragma GCC unroll 8
    for (int q = 0; q < 8; ++q)
#pragma GCC unroll 3
      for (int d = 0; d < 3; ++d) vz[q][d] = a.vel(q, d);
    const MaterialConstants& m = a.mat();
    double L[kTetsPerZone][9];
    double tr[kTetsPerZone];
#pragma GCC unroll 10
    for (int t = 0; t < kTetsPerZone; ++t) {
      tet_gradient(vz, kZoneTets[t], a, 10 * t, L[t]);
      tr[t] = L[t][0] + L[t][4] + L[t][8];
    }
    // Mixed discretisation: volume-weighted mean volumetric strain rate (docs/theory.md 5.3).
    double avg[2];
    if constexpr (ZoneAvg) {
      double vs = 0.0, ts = 0.0;
#pragma GCC unroll 10
      for (int t = 0; t < kTetsPerZone; ++t) {
        vs += a.g(10 * t + 9);
        ts += a.g(10 * t + 9) * tr[t];
      }
      avg[0] = avg[1] = ts / vs;
    } else {
#pragma GCC unroll 2
      for (int o = 0; o < 2; ++o) {
        double vs = 0.0, ts = 0.0;
#pragma GCC unroll 5
        for (int t = 5 * o; t < 5 * o + 5; ++t) {
          vs += a.g(10 * t + 9);
          ts += a.g(10 * t + 9) * tr[t];
        }
        avg[o] = ts / vs;
      }
    }
    std::uint8_t now = 0;
#pragma GCC unroll 10
    for (int t = 0; t < kTetsPerZone; ++t) {
      const double* l = L[t];
      double s[6];
#pragma GCC unroll 6
      for (int j = 0; j < 6; ++j) s[j] = a.s(6 * t + j);
      const double corr = (avg[t / 5] - tr[t]) / 3.0;
      double de[6];
      de[0] = (l[0] + corr) * dt;
      de[1] = (l[4] + corr) * dt;
      de[2] = (l[8] + corr) * dt;
      de[3] = 0.5 * (l[1] + l[3]) * dt;
      de[4] = 0.5 * (l[5] + l[7]) * dt;
      de[5] = 0.5 * (l[2] + l[6]) * dt;
      if constexpr (Large) {
        // Jaumann correction sigma += (w sigma - sigma w) dt, w = (L - L^T)/2 (docs/theory.md 5.8).
        const double w01 = 0.5 * (l[1] - l[3]) * dt, w02 = 0.5 * (l[2] - l[6]) * dt,
                     w12 = 0.5 * (l[5] - l[7]) * dt;
        const double sxx = s[0], syy = s[1], szz = s[2], sxy = s[3], syz = s[4], sxz = s[5];
        // (w s - s w) is symmetric; with w = [[0,w01,w02],[-w01,0,w12],[-w02,-w12,0]]:
        s[0] += 2.0 * (w01 * sxy + w02 * sxz);
        s[1] += 2.0 * (-w01 * sxy + w12 * syz);
        s[2] += 2.0 * (-w02 * sxz - w12 * syz);
        s[3] += w01 * (syy - sxx) + w02 * syz + w12 * sxz;
        s[4] += w12 * (szz - syy) - w01 * sxz - w02 * sxy;
        s[5] += w02 * (szz - sxx) + w01 * syz - w12 * sxy;
      }
      now |= Law::update(m, de, s);
#pragma GCC unroll 6
      for (int j = 0; j < 6; ++j) a.s(6 * t + j) = s[j];
    }
    a.set_plastic(now);
  }

  // Nodal forces f^l = -V sigma g_l, averaged over the two overlays (docs/theory.md 5.5).
  double f[8][3] = {};
#pragma GCC unroll 10
  for (int t = 0; t < kTetsPerZone; ++t) {
    const double hv = -0.5 * a.g(10 * t + 9);
    double s[6];
#pragma GCC unroll 6
    for (int j = 0; j < 6; ++j) s[j] = a.s(6 * t + j);
    const auto& n = kZoneTets[t];
#pragma GCC unroll 3
    for (int l = 0; l < 3; ++l) {
      const double g0 = a.g(10 * t + 3 * l), g1 = a.g(10 * t + 3 * l + 1), g2 = a.g(10 * t + 3 * l + 2);
      const double fx = hv * (s[0] * g0 + s[3] * g1 + s[5] * g2);
      const double fy = hv * (s[3] * g0 + s[1] * g1 + s[4] * g2);
      const double fz = hv * (s[5] * g0 + s[4] * g1 + s[2] * g2);
      f[n[l + 1]][0] += fx;
      f[n[l + 1]][1] += fy;
      f[n[l + 1]][2] += fz;
      f[n[0]][0] -= fx;
      f[n[0]][1] -= fy;
      f[n[0]][2] -= fz;
    }
  }
#pragma GCC unroll 8
  for (int q = 0; q < 8; ++q)
#pragma GCC unroll 3
    for (int d = 0; d < 3; ++d) a.f(3 * q + d) = f[q][d];
}

}  // namespace demfdm::fdm::zone
