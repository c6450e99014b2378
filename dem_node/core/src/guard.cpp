#include "demfdm/dem/guard.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

namespace demfdm::dem {
namespace {

bool finite(const Vec3& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

std::string str(const Vec3& v) {
  std::ostringstream os;
  os.precision(9);
  os << "(" << v.x << ", " << v.y << ", " << v.z << ")";
  return os.str();
}

Vec3 min_image(const World& w, Vec3 d) {
  if (!w.periodic()) return d;
  const Vec3 L = w.cell_length();
  for (int k = 0; k < 3; ++k)
    if (L[k] > 0) d[k] -= L[k] * std::round(d[k] / L[k]);
  return d;
}

// True if every component of x, v, ω, F and T of every ball is finite: x * 0 is 0 for finite x
// and NaN for NaN or inf, and NaN == 0 is false. An or of flags has no order, so one loop over
// the balls reads the five arrays, vectorises (no branch, no chain of additions) and splits over
// the World's threads.
bool all_finite(const World& w) {
  const auto& b = w.balls();
  const std::int64_t n = static_cast<std::int64_t>(b.size());
  static_assert(sizeof(Vec3) == 3 * sizeof(double));
  const double* a[5] = {reinterpret_cast<const double*>(b.x.data()), reinterpret_cast<const double*>(b.v.data()),
                        reinterpret_cast<const double*>(b.w.data()), reinterpret_cast<const double*>(b.f.data()),
                        reinterpret_cast<const double*>(b.t.data())};
  const int nt = w.thread_count();
  unsigned bad = 0;
  // One parallel region for the five arrays (a region per array cost a wake-up of the team each).
#pragma omp parallel num_threads(nt) if (nt > 1 && n > 4096) reduction(| : bad)
  for (const double* p : a) {
#pragma omp for simd schedule(static) nowait
    for (std::int64_t i = 0; i < 3 * n; ++i) bad |= !(p[i] * 0.0 == 0.0);
  }
  return bad == 0;
}

// How far a centre lies outside the box [lo, hi] (0 inside; a non-finite coordinate gives 0
// here, the finite-value test names it).
[[gnu::always_inline]] inline double outside_box(const Vec3& x, const Vec3& lo, const Vec3& hi) {
  double out = 0;
  for (int k = 0; k < 3; ++k) out = std::max({out, lo[k] - x[k], x[k] - hi[k]});
  return out;
}

// Or-able flag: some component of v is not finite (x * 0 is 0 for finite x, NaN otherwise).
unsigned not_finite(const Vec3& v) { return !(v.x * 0.0 == 0.0) | !(v.y * 0.0 == 0.0) | !(v.z * 0.0 == 0.0); }

GuardFinding finding(const World& w, std::size_t row, std::string cause, std::size_t neighbours) {
  GuardFinding f;
  f.row = row;
  f.id = w.balls().id[row];
  f.cause = std::move(cause);
  f.detail = "ball: " + describe_ball(w, row) + "\n" + std::to_string(neighbours) + " nearest balls:\n" +
             neighbourhood(w, row, neighbours);
  return f;
}

}  // namespace

std::string describe_ball(const World& w, std::size_t i) {
  const auto& b = w.balls();
  std::ostringstream os;
  os.precision(9);
  os << "id " << b.id[i] << " (row " << i << ") at " << str(b.x[i]) << " m, radius " << b.r[i] << " m, velocity "
     << str(b.v[i]) << " m/s, spin " << str(b.w[i]) << " rad/s, force " << str(b.f[i]) << " N, torque "
     << str(b.t[i]) << " N m, fixity " << static_cast<int>(b.fix[i]);
  return os.str();
}

std::string neighbourhood(const World& w, std::size_t row, std::size_t k) {
  const auto& b = w.balls();
  std::vector<std::pair<double, std::size_t>> d;
  d.reserve(b.size());
  const bool here = finite(b.x[row]);
  for (std::size_t j = 0; j < b.size(); ++j) {
    if (j == row) continue;
    double dist = here && finite(b.x[j]) ? norm(min_image(w, b.x[j] - b.x[row])) : std::numeric_limits<double>::infinity();
    d.push_back({dist, j});
  }
  k = std::min(k, d.size());
  std::partial_sort(d.begin(), d.begin() + static_cast<std::ptrdiff_t>(k), d.end());
  std::ostringstream os;
  os.precision(9);
  for (std::size_t n = 0; n < k; ++n)
    os << "  distance " << d[n].first << " m: " << describe_ball(w, d[n].second) << "\n";
  return os.str();
}

std::optional<GuardFinding> check_finite(const World& w, std::size_t neighbours) {
  const auto& b = w.balls();
  const std::size_t n = b.size();
  const bool clean = all_finite(w);
  for (std::size_t i = 0; i < n && !clean; ++i) {
    const char* what = !finite(b.x[i])   ? "position"
                       : !finite(b.v[i]) ? "velocity"
                       : !finite(b.w[i]) ? "spin"
                       : !finite(b.f[i]) ? "force"
                       : !finite(b.t[i]) ? "torque"
                                         : nullptr;
    if (!what) continue;
    const Vec3 v = std::string(what) == "position" ? b.x[i]
                   : std::string(what) == "velocity" ? b.v[i]
                   : std::string(what) == "spin" ? b.w[i]
                   : std::string(what) == "force" ? b.f[i]
                                                  : b.t[i];
    auto f = finding(w, i, std::string("non-finite ") + what + " " + str(v) + " of ball id " + std::to_string(b.id[i]),
                     neighbours);
    // The contact that produced a non-finite force or torque, if a ball-ball one did.
    const auto& pc = w.pair_contacts();
    std::ostringstream os;
    os.precision(9);
    for (std::size_t c = 0; c < pc.size(); ++c) {
      if (pc.a[c] != i && pc.b[c] != i) continue;
      const Vec3 fc = w.pair_force(c), mc = w.pair_moment(c);
      const auto& h = pc.h[c];
      const bool bad = !finite(fc) || !finite(mc) || !std::isfinite(h.fn) || !finite(h.fs);
      if (bad && !f.contact) {
        f.contact = true;
        f.other_id = b.id[pc.a[c] == i ? pc.b[c] : pc.a[c]];
        f.cause += "; first non-finite contact: ball-ball pair " + std::to_string(b.id[pc.a[c]]) + "-" +
                   std::to_string(b.id[pc.b[c]]) + " (" + to_string(w.params().ball_ball.model) + ")";
      }
      os << "  pair " << b.id[pc.a[c]] << "-" << b.id[pc.b[c]] << (bad ? " NON-FINITE" : "") << ": fn " << h.fn
         << " N, fs " << str(h.fs) << " N, kn " << h.kn << " N/m, force on B " << str(fc) << " N, moment "
         << str(mc) << " N m\n";
    }
    f.detail += "ball-ball contacts of ball " + std::to_string(b.id[i]) + " (model " +
                to_string(w.params().ball_ball.model) + "):\n" + os.str();
    return f;
  }
  if (w.has_footing() && !finite(w.footing_reaction())) {
    GuardFinding f;
    f.cause = "non-finite footing reaction " + str(w.footing_reaction());
    f.detail = f.cause + "\n";
    return f;
  }
  return std::nullopt;
}

namespace {
// One row of the screen: its finite test or-ed into `bad`, its distance outside the box into
// `worst`; returns its kinetic energy term (World::kinetic_energy_of).
[[gnu::always_inline]] inline double screen_row(const World& w, std::size_t i, const Vec3& lo, const Vec3& hi, bool box,
                                                unsigned& bad, double& worst) {
  const auto& b = w.balls();
  bad |= not_finite(b.x[i]) | not_finite(b.v[i]) | not_finite(b.w[i]) | not_finite(b.f[i]) | not_finite(b.t[i]);
  if (box) worst = std::max(worst, outside_box(b.x[i], lo, hi));
  return w.kinetic_energy_of(i);
}
}  // namespace

BallScreen screen_balls(const World& w, const Vec3& lo, const Vec3& hi, bool box, std::vector<double>& scratch) {
  const std::int64_t n = static_cast<std::int64_t>(w.balls().size());
  const int nt = w.thread_count();
  unsigned bad = 0;
  double worst = 0.0;
  BallScreen out;
  auto row = [&](std::size_t i, unsigned& bd, double& wo)
                 __attribute__((always_inline)) { return screen_row(w, i, lo, hi, box, bd, wo); };
  // World::ordered_ball_sum's paths (the same additions in the same order; order-free: the terms
  // kept, then their order-free sum).
  const bool par = nt > 1 && n > 4096, order_free = w.params().order_free_sums;
  if (!par && !order_free) {
    for (std::int64_t i = 0; i < n; ++i) out.kinetic += row(static_cast<std::size_t>(i), bad, worst);
  } else {
    scratch.resize(static_cast<std::size_t>(n));
    double* __restrict__ t = scratch.data();
#pragma omp parallel for schedule(static) num_threads(nt) reduction(| : bad) reduction(max : worst) if (par)
    for (std::int64_t i = 0; i < n; ++i) t[i] = row(static_cast<std::size_t>(i), bad, worst);
    if (order_free)
      out.kinetic = order_free_total(t, static_cast<std::size_t>(n));
    else
      for (std::int64_t i = 0; i < n; ++i) out.kinetic += t[i];
  }
  if (w.has_footing()) bad |= not_finite(w.footing_reaction());
  out.finite = bad == 0;
  out.outside = worst;
  return out;
}

BallScreen screen_rows(const World& w, const Vec3& lo, const Vec3& hi, bool box, const std::vector<std::uint8_t>& ghost,
                       std::vector<double>& terms) {
  const std::size_t n = w.balls().size();
  unsigned bad = 0;
  double worst = 0.0;
  terms.clear();
  if (ghost.empty()) {
    terms.resize(n);
    for (std::size_t i = 0; i < n; ++i) terms[i] = screen_row(w, i, lo, hi, box, bad, worst);
  } else {
    for (std::size_t i = 0; i < n; ++i) {
      const double t = screen_row(w, i, lo, hi, box, bad, worst);
      if (!ghost[i]) terms.push_back(t);
    }
  }
  if (w.has_footing()) bad |= not_finite(w.footing_reaction());
  BallScreen out;
  out.finite = bad == 0;
  out.outside = worst;
  return out;
}

std::optional<GuardFinding> check_escape(const World& w, const Vec3& lo, const Vec3& hi, double margin,
                                         std::size_t neighbours) {
  const auto& b = w.balls();
  auto outside = [&](std::size_t i) { return outside_box(b.x[i], lo, hi); };
  // The largest distance first (a maximum has no order: one parallel pass); the first ball in
  // row order beyond the margin only when there is one.
  const std::int64_t n = static_cast<std::int64_t>(b.size());
  const int nt = w.thread_count();
  double worst = 0;
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1 && n > 4096) reduction(max : worst)
  for (std::int64_t i = 0; i < n; ++i) worst = std::max(worst, outside(static_cast<std::size_t>(i)));
  if (!(worst > margin)) return std::nullopt;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const Vec3& x = b.x[i];
    const double out = outside(i);
    if (out > margin) {
      std::ostringstream os;
      os.precision(9);
      os << "ball id " << b.id[i] << " left the DEM domain: centre " << str(x) << " m is " << out
         << " m outside the box " << str(lo) << " - " << str(hi) << " m (limit " << margin << " m), velocity "
         << str(b.v[i]) << " m/s";
      return finding(w, i, os.str(), neighbours);
    }
  }
  return std::nullopt;
}

}  // namespace demfdm::dem
