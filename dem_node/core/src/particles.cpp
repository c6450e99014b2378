// The ball store (particles.hpp).
#include "demfdm/dem/particles.hpp"

#include <algorithm>
#include <utility>

namespace demfdm::dem {

namespace {
constexpr double kPi = 3.14159265358979323846;
}

std::size_t Particles::add(const Vec3& x0, double radius, double rho, std::uint64_t ball_id) {
  const double mass = rho * 4.0 / 3.0 * kPi * radius * radius * radius;
  x.push_back(x0);
  v.push_back({});
  w.push_back({});
  f.push_back({});
  t.push_back({});
  fa.push_back({});
  ta.push_back({});
  x_ref.push_back(x0);
  r.push_back(radius);
  m.push_back(mass);
  inertia.push_back(0.4 * mass * radius * radius);
  id.push_back(ball_id);
  fix.push_back(0);
  return size() - 1;
}

void Particles::set_radius(std::size_t i, double radius) {
  const double rho = m[i] / (4.0 / 3.0 * kPi * r[i] * r[i] * r[i]);
  r[i] = radius;
  m[i] = rho * 4.0 / 3.0 * kPi * radius * radius * radius;
  inertia[i] = 0.4 * m[i] * radius * radius;
}

void Particles::permute(const std::vector<std::uint32_t>& new_row) {
  const std::size_t n = size();
  auto perm = [&](auto& a) {
    auto old = a;
    for (std::size_t i = 0; i < n; ++i) a[new_row[i]] = old[i];
  };
  perm(x); perm(v); perm(w); perm(f); perm(t); perm(fa); perm(ta);
  perm(x_ref); perm(r); perm(m); perm(inertia); perm(id); perm(fix);
}

std::vector<std::uint32_t> morton_rows(const Particles& pt) {
  const std::size_t n = pt.size();
  std::vector<std::uint32_t> newrow(n);
  if (n == 0) return newrow;
  Vec3 lo = pt.x[0], hi = lo;
  double rmax = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    rmax = std::max(rmax, pt.r[i]);
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], pt.x[i][k]);
      hi[k] = std::max(hi[k], pt.x[i][k]);
    }
  }
  // Morton (z-order) key of cells of size 2 R_max.
  const double cs = 2.0 * rmax;
  auto spread = [](std::uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
  };
  std::vector<std::pair<std::uint64_t, std::uint32_t>> key(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t c[3];
    for (int k = 0; k < 3; ++k) c[k] = static_cast<std::uint64_t>((pt.x[i][k] - lo[k]) / cs);
    key[i] = {spread(c[0]) | spread(c[1]) << 1 | spread(c[2]) << 2, static_cast<std::uint32_t>(i)};
  }
  std::sort(key.begin(), key.end());
  for (std::size_t k = 0; k < n; ++k) newrow[key[k].second] = static_cast<std::uint32_t>(k);
  return newrow;
}

}  // namespace demfdm::dem
