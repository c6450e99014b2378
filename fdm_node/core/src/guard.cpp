#include "demfdm/fdm/guard.hpp"

#include <cmath>
#include <set>
#include <sstream>

namespace demfdm::fdm {
namespace {

constexpr int kTets = kTetsPerZone;

bool finite3(std::span<const double> a, std::size_t i) {
  return std::isfinite(a[3 * i]) && std::isfinite(a[3 * i + 1]) && std::isfinite(a[3 * i + 2]);
}

std::string vec(std::span<const double> a, std::size_t i) {
  std::ostringstream os;
  os.precision(9);
  os << "(" << a[3 * i] << ", " << a[3 * i + 1] << ", " << a[3 * i + 2] << ")";
  return os.str();
}

// True if every value is finite: x * 0 is 0 for finite x and NaN otherwise, so the sums stay
// 0 unless a value is non-finite (four sums: no reassociation is needed to pipeline them).
bool all_finite(std::span<const double> a) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  std::size_t i = 0;
  for (; i + 4 <= a.size(); i += 4) {
    s0 += a[i] * 0.0;
    s1 += a[i + 1] * 0.0;
    s2 += a[i + 2] * 0.0;
    s3 += a[i + 3] * 0.0;
  }
  for (; i < a.size(); ++i) s0 += a[i] * 0.0;
  return (s0 + s1 + s2 + s3) == 0.0;
}

}  // namespace

std::int32_t fastest_gridpoint(const Model& m) {
  const auto v = m.velocities();
  const auto mass = m.inertial_masses();
  std::size_t worst = 0;
  double e_worst = -1;
  for (std::size_t g = 0; g < m.num_gridpoints(); ++g) {
    double e = 0.5 * mass[g] * (v[3 * g] * v[3 * g] + v[3 * g + 1] * v[3 * g + 1] + v[3 * g + 2] * v[3 * g + 2]);
    if (e > e_worst) e_worst = e, worst = g;
  }
  return static_cast<std::int32_t>(worst);
}

std::string describe_gridpoint(const Model& m, std::int32_t g) {
  const auto gi = static_cast<std::size_t>(g);
  std::ostringstream os;
  os << "gridpoint " << g << " at " << vec(m.positions(), gi) << " m (reference "
     << vec(m.mesh().points, gi) << " m), velocity " << vec(m.velocities(), gi) << " m/s, displacement "
     << vec(m.displacements(), gi) << " m, zone force " << vec(m.zone_forces(), gi) << " N, mass "
     << m.inertial_masses()[gi] << " kg";
  return os.str();
}

std::string describe_zone(const Model& m, std::int32_t z) {
  const auto zi = static_cast<std::size_t>(z);
  const auto pts = m.positions();
  const auto conn = m.connectivity();
  double c[3] = {0, 0, 0};
  for (int k = 0; k < 8; ++k)
    for (int d = 0; d < 3; ++d) c[d] += pts[3 * static_cast<std::size_t>(conn[8 * zi + k]) + d] / 8;
  double s[6] = {0, 0, 0, 0, 0, 0};
  bool bad = false;
  for (int t = 0; t < kTets; ++t)
    for (int i = 0; i < 6; ++i) {
      double v = m.tet_stresses()[6 * (kTets * zi + t) + i];
      bad = bad || !std::isfinite(v);
      s[i] += v / kTets;
    }
  std::ostringstream os;
  os.precision(9);
  os << "zone " << z << " centre (" << c[0] << ", " << c[1] << ", " << c[2] << ") m, stress (xx, yy, zz, xy, yz, xz) ("
     << s[0] << ", " << s[1] << ", " << s[2] << ", " << s[3] << ", " << s[4] << ", " << s[5]
     << ") Pa (mean of its tetrahedra" << (bad ? ", NON-FINITE" : "") << "), plastic state "
     << static_cast<int>(m.plastic_state()[zi]);
  return os.str();
}

std::string zones_around(const Model& m, std::int32_t g) {
  const auto conn = m.connectivity();
  std::ostringstream os;
  for (std::size_t z = 0; z < m.num_zones(); ++z)
    for (int k = 0; k < 8; ++k)
      if (conn[8 * z + k] == g) {
        os << "  " << describe_zone(m, static_cast<std::int32_t>(z)) << "\n";
        break;
      }
  return os.str();
}

std::string zone_neighbourhood(const Model& m, std::int32_t z) {
  const auto conn = m.connectivity();
  const auto zi = static_cast<std::size_t>(z);
  std::set<std::int32_t> corners(conn.begin() + 8 * zi, conn.begin() + 8 * zi + 8);
  std::ostringstream os;
  os << "gridpoints of zone " << z << ":\n";
  for (auto g : corners) os << "  " << describe_gridpoint(m, g) << "\n";
  os << "zones sharing a gridpoint with zone " << z << ":\n";
  for (std::size_t o = 0; o < m.num_zones(); ++o) {
    if (o == zi) continue;
    for (int k = 0; k < 8; ++k)
      if (corners.count(conn[8 * o + k])) {
        os << "  " << describe_zone(m, static_cast<std::int32_t>(o)) << "\n";
        break;
      }
  }
  return os.str();
}

std::optional<GuardFinding> check_finite(const Model& m) {
  // Both the first bad gridpoint and the first bad zone are named: within one step a
  // non-finite value spreads from forces to velocities to stresses, and either may come first.
  GuardFinding r;
  const std::size_t n = m.num_gridpoints();
  const auto x = m.positions(), v = m.velocities(), u = m.displacements(), f = m.zone_forces();
  // Fast path: a non-finite stress makes the zone forces of its corners non-finite in the same
  // zone pass, so the gridpoint arrays are enough to detect a problem (the zones are searched
  // only then).
  if (all_finite(x) && all_finite(v) && all_finite(u) && all_finite(f)) return std::nullopt;
  for (std::size_t g = 0; g < n && r.gridpoint < 0; ++g) {
    const char* what = !finite3(x, g)   ? "position"
                       : !finite3(v, g) ? "velocity"
                       : !finite3(u, g) ? "displacement"
                       : !finite3(f, g) ? "zone force"
                                        : nullptr;
    if (!what) continue;
    const std::string w = what;
    const auto arr = w == "position" ? x : w == "velocity" ? v : w == "displacement" ? u : f;
    r.gridpoint = static_cast<std::int32_t>(g);
    r.cause = "non-finite " + w + " " + vec(arr, g) + " of gridpoint " + std::to_string(g) + " (reference position " +
              vec(m.mesh().points, g) + " m)";
    r.detail = describe_gridpoint(m, r.gridpoint) + "\nzones around it:\n" + zones_around(m, r.gridpoint);
  }
  const auto s = m.tet_stresses();
  for (std::size_t i = 0; i < s.size(); ++i) {
    if (std::isfinite(s[i])) continue;
    r.zone = static_cast<std::int32_t>(i / 6 / kTets);
    r.cause = "non-finite stress in zone " + std::to_string(r.zone) + " (tetrahedron " +
              std::to_string(i / 6 % kTets) + ")" + (r.cause.empty() ? "" : "; " + r.cause);
    r.detail = describe_zone(m, r.zone) + "\n" + zone_neighbourhood(m, r.zone) + (r.detail.empty() ? "" : "\n" + r.detail);
    break;
  }
  if (r.gridpoint < 0 && r.zone < 0) return std::nullopt;
  return r;
}

}  // namespace demfdm::fdm
