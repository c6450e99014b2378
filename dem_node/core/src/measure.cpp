#include "demfdm/dem/measure.hpp"

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "demfdm/dem/order_free_sum.hpp"

namespace demfdm::dem {

namespace {
constexpr double kPi = 3.14159265358979323846;
void symmetrise(Mat3& s) {
  for (int i = 0; i < 3; ++i)
    for (int j = i + 1; j < 3; ++j) {
      const double m = 0.5 * (s[3 * i + j] + s[3 * j + i]);
      s[3 * i + j] = s[3 * j + i] = m;
    }
}
}  // namespace

Mat3 cell_stress(const World& w) {
  Mat3 s{};
  const auto& pc = w.pair_contacts();
  if (w.params().order_free_sums) {  // each component's order-free sum (the servo's columns: DistDem's bits)
    const std::size_t n = pc.size();
    std::vector<double> v(9 * n, 0.0);  // component k of contact c at v[k n + c]
    for (std::size_t c = 0; c < n; ++c)
      for_each_stress_increment(w.pair_force(c), w.branch(c),
                                [&](int k, double x) { v[static_cast<std::size_t>(k) * n + c] += x; });
    for (std::size_t k = 0; k < 9; ++k) s[k] = order_free_total(&v[k * n], n);
    return cell_stress_of(s, w.cell_volume());
  }
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const Vec3 F = w.pair_force(c);
    if (F.x == 0.0 && F.y == 0.0 && F.z == 0.0) continue;
    for_each_stress_increment(F, w.branch(c), [&](int k, double x) { s[k] += x; });  // (s -= F l, bit for bit)
  }
  return cell_stress_of(s, w.cell_volume());
}

Mat3 cell_stress_of(Mat3 s, double volume) {
  for (double& x : s) x /= volume;
  symmetrise(s);
  return s;
}

bool Region::contains(const Vec3& x) const {
  if (kind == Kind::kSphere) return norm2(x - centre) <= radius * radius;
  return x.x >= lo.x && x.x <= hi.x && x.y >= lo.y && x.y <= hi.y && x.z >= lo.z && x.z <= hi.z;
}
double Region::volume() const {
  if (kind == Kind::kSphere) return 4.0 / 3.0 * kPi * radius * radius * radius;
  return (hi.x - lo.x) * (hi.y - lo.y) * (hi.z - lo.z);
}

Mat3 region_stress(const World& w, const Region& r) {
  Mat3 s{};
  const auto& pt = w.balls();
  const auto& pc = w.pair_contacts();
  std::vector<char> in(pt.size());
  for (std::size_t i = 0; i < pt.size(); ++i) in[i] = r.contains(pt.x[i]);
  auto add = [&](const Vec3& arm, const Vec3& F) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) s[3 * i + j] += arm[i] * F[j];
  };
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const Vec3 F = w.pair_force(c);
    if (F.x == 0.0 && F.y == 0.0 && F.z == 0.0) continue;
    const std::uint32_t a = pc.a[c], b = pc.b[c];
    if (!in[a] && !in[b]) continue;
    Vec3 arm_a, arm_b;
    pair_stress_arms(w, c, arm_a, arm_b);
    if (in[a]) add(arm_a, -F);   // force on A is −F
    if (in[b]) add(arm_b, F);
  }
  for (const WallContacts* wc : {&w.plane_contacts(), &w.facet_contacts(), &w.footing_contacts()})
    for (std::size_t c = 0; c < wc->size(); ++c) {
      const std::uint32_t i = wc->ball[c];
      if (!in[i]) continue;
      add(wc->xc[c] - pt.x[i], -wc->F[c]);
    }
  const double V = r.volume();
  for (double& x : s) x /= V;
  symmetrise(s);
  return s;
}

double porosity(const World& w, const Region& r) {
  const auto& pt = w.balls();
  double vs = 0.0;
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (r.contains(pt.x[i])) vs += ball_volume_term(pt.r[i]);
  return 1.0 - vs / r.volume();
}

double cell_porosity(const World& w) {
  const auto& pt = w.balls();
  double vs = 0.0;
  for (std::size_t i = 0; i < pt.size(); ++i) vs += ball_volume_term(pt.r[i]);
  return cell_porosity_of(vs, w.cell_volume());
}

Coordination coordination(const World& w) {
  Coordination z;
  const auto& pc = w.pair_contacts();
  const std::size_t n = w.num_balls();
  std::vector<std::uint32_t> cnt(n, 0);
  for (std::size_t c = 0; c < pc.size(); ++c)
    if (pair_active(w, c)) {
      ++cnt[pc.a[c]];
      ++cnt[pc.b[c]];
      ++z.active;
    }
  std::size_t nc_nr = 0;  // contact ends on non-rattlers
  for (std::size_t i = 0; i < n; ++i) {
    if (cnt[i] < 2) ++z.rattlers;
    else nc_nr += cnt[i];
  }
  return coordination_of(n, z.active, z.rattlers, nc_nr);
}

Coordination coordination_of(std::size_t balls, std::size_t active, std::size_t rattlers, std::size_t ends) {
  Coordination z;
  z.active = active;
  z.rattlers = rattlers;
  z.z = balls ? 2.0 * double(active) / double(balls) : 0.0;
  z.z_no_rattlers = balls > rattlers ? double(ends) / double(balls - rattlers) : 0.0;
  return z;
}

namespace {
// `skip(c)`: leave contact c out.
template <class Skip>
BondCounts count(const std::vector<BondHist>& bs, Skip skip) {
  BondCounts b;
  for (std::size_t c = 0; c < bs.size(); ++c) {
    if (skip(c)) continue;
    switch (bs[c].state) {
      case BondState::kNeverBonded: ++b.never_bonded; break;
      case BondState::kIntact: ++b.intact; break;
      case BondState::kSoftening: ++b.softening; break;
      case BondState::kBrokenTension: ++b.broken_tension; break;
      case BondState::kBrokenShear: ++b.broken_shear; break;
    }
  }
  return b;
}
}  // namespace

BondCounts bond_counts(const World& w) {
  const auto& g = w.ghost_rows();
  const auto& a = w.pair_contacts().a;
  return count(w.pair_contacts().bond, [&](std::size_t c) { return !g.empty() && g[a[c]]; });
}
BondCounts facet_bond_counts(const World& w) {
  return count(w.facet_contacts().bond, [](std::size_t) { return false; });
}

Snapshot snapshot(const World& w) {
  Snapshot s;
  const auto& pt = w.balls();
  const std::size_t n = pt.size();
  s.position.resize(3 * n);
  s.velocity.resize(3 * n);
  s.radius = pt.r;
  s.id = pt.id;
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      s.position[3 * i + k] = pt.x[i][k];
      s.velocity[3 * i + k] = pt.v[i][k];
    }
  const auto& pc = w.pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const BondState st = pc.bond.empty() ? BondState::kNeverBonded : pc.bond[c].state;
    if (!pair_active(w, c) && st == BondState::kNeverBonded) continue;
    s.pair.push_back(pc.a[c]);
    s.pair.push_back(pc.b[c]);
    const Vec3 F = w.pair_force(c);
    for (int k = 0; k < 3; ++k) s.force.push_back(F[k]);
    s.state.push_back(static_cast<std::uint8_t>(st));
  }
  return s;
}

Measurement measure(const World& w) {
  Measurement m;
  m.time = w.time();
  m.step = w.step_count();
  m.ratio = w.unbalanced_ratio();
  m.energy = w.energy();
  m.coord = coordination(w);
  m.bonds = bond_counts(w);
  if (w.periodic()) {
    m.stress = cell_stress(w);
    m.porosity = cell_porosity(w);
  }
  return m;
}

MeasurementRecorder::MeasurementRecorder(std::int64_t interval) : interval_(interval) {
  if (interval < 1) {
    throw std::invalid_argument("MeasurementRecorder: 'interval' must be >= 1 step, found " +
                                std::to_string(interval) + ".");
  }
}

void MeasurementRecorder::apply(World& w, Phase) {
  if (w.step_count() % interval_ == 0) samples_.push_back(measure(w));
}

}  // namespace demfdm::dem
