// Internals shared by world.cpp, pair_set.cpp and walls.cpp (not installed): the history key of a contact and
// the one routine that carries history across a rebuild, the phase lap timer, the ball-wall candidate record and the wall distance functions.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <tuple>
#include <utility>
#include <vector>

#include "demfdm/dem/geometry.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem::detail {

// A contact's history key: (lower id, higher id) for pairs, (ball id, wall id) for walls.
struct Key {
  std::uint64_t lo, hi;
  std::uint32_t idx;
  bool operator<(const Key& o) const { return std::tie(lo, hi) < std::tie(o.lo, o.hi); }
};

// Carries contact history across a neighbour rebuild, for the ball-ball pairs and every wall
// kind alike (world.hpp: history keyed by ids). While the new contact set is built, each new
// contact takes the old contact of its key, if any (take); then the old contacts no one took
// are kept when bonded (a bond never disappears in a rebuild) or retired, their dissipated
// slip and softening energies moved to the world's totals of dead contacts (rest).
//
// KeyOf(c) gives old contact c's key (lo, hi). `ordered`: the old keys and the queries both
// come in increasing order (the ball-ball list after a plain rebuild, keyed by rows), so one
// linear merge finds each; otherwise the old keys are sorted and each query is a binary search.
template <class KeyOf>
class HistoryCarry {
 public:
  HistoryCarry(std::size_t n, bool ordered, KeyOf key_of) : n_(n), ordered_(ordered), key_of_(key_of), used_(n, 0) {
    if (ordered_) return;
    keys_.resize(n);
    for (std::size_t c = 0; c < n; ++c) {
      const auto [lo, hi] = key_of_(c);
      keys_[c] = {lo, hi, static_cast<std::uint32_t>(c)};
    }
    std::sort(keys_.begin(), keys_.end());
  }
  /// The old contact with key (lo, hi), now taken; -1 when there is none (or it was taken).
  std::int64_t take(std::uint64_t lo, std::uint64_t hi) {
    std::int64_t found = -1;
    if (ordered_) {
      const auto k = std::make_pair(lo, hi);
      while (cursor_ < n_ && key_of_(cursor_) < k) ++cursor_;
      if (cursor_ < n_ && key_of_(cursor_) == k) found = static_cast<std::int64_t>(cursor_);
    } else {
      const Key k{lo, hi, 0};
      auto it = std::lower_bound(keys_.begin(), keys_.end(), k);
      if (it != keys_.end() && it->lo == lo && it->hi == hi && !used_[it->idx]) found = it->idx;
    }
    if (found >= 0) used_[static_cast<std::size_t>(found)] = 1;
    return found;
  }
  /// After the last take: for each old contact no one took, in order, keep(c) when it is
  /// bonded, else its energies go to the dead totals if counts(c) (a rank's world: the rank that
  /// owns the contact's ball A counts it, docs/scaling.md).
  template <class Keep, class Counts>
  void rest(const std::vector<ContactHist>& h, const std::vector<BondHist>& bond, bool has_bond, Keep keep,
            double& e_slip_dead, double& e_soft_dead, Counts counts) const {
    for (std::size_t c = 0; c < n_; ++c) {
      if (used_[c]) continue;
      if (has_bond && bonded(bond[c].state)) {
        keep(c);
      } else if (counts(c)) {
        e_slip_dead += h[c].e_slip;
        if (has_bond) e_soft_dead += bond[c].e_soft;
      }
    }
  }

 private:
  std::size_t n_;
  bool ordered_;
  KeyOf key_of_;
  std::vector<char> used_;
  std::vector<Key> keys_;
  std::size_t cursor_ = 0;
};

// Lap timer of the phase accounting (World::phase_times): each call adds the time since the
// previous call (or construction) to `acc`, so consecutive phases cost one clock read each.
class Lap {
 public:
  Lap() : t_(std::chrono::steady_clock::now()) {}
  void operator()(double& acc) {
    const auto t = std::chrono::steady_clock::now();
    acc += std::chrono::duration<double>(t - t_).count();
    t_ = t;
  }

 private:
  std::chrono::steady_clock::time_point t_;
};

// One ball–wall candidate found by the search.
struct WallCand {
  std::uint32_t ball, wall;
  std::int32_t facet;
};

// Signed distance ball centre → facet with a one-sided normal in the face region (§1.4).
inline double facet_distance(const Vec3& x, const FacetWall& fw, std::size_t t, Vec3& n, Vec3& w) {
  const auto& tr = fw.tri[t];
  Vec3 q;
  const int reg = closest_point_triangle(x, fw.pos[tr[0]], fw.pos[tr[1]], fw.pos[tr[2]], q, w);
  const Vec3& nf = fw.tri_normal[t];
  if (reg == 0) {
    n = -nf;
    return dot(x - q, nf);
  }
  const Vec3 d = q - x;
  const double dist = norm(d);
  n = dist > 0.0 ? d * (1.0 / dist) : -nf;
  return dist;
}

// Geometry of a ball and a planar wall (§1.4); one-sided inside the rectangle.
inline double plane_distance(const Vec3& x, const PlaneWall& pw, Vec3& n) {
  const Vec3 rel = x - pw.p.point;
  const double s = dot(rel, pw.p.normal);
  const double u1 = dot(rel, pw.p.axis1), u2 = dot(rel, pw.axis2);
  const bool in1 = pw.p.half1 == 0.0 || std::abs(u1) <= pw.p.half1;
  const bool in2 = pw.p.half2 == 0.0 || std::abs(u2) <= pw.p.half2;
  if (in1 && in2) {
    n = -pw.p.normal;
    return s;
  }
  const double c1 = pw.p.half1 == 0.0 ? u1 : std::clamp(u1, -pw.p.half1, pw.p.half1);
  const double c2 = pw.p.half2 == 0.0 ? u2 : std::clamp(u2, -pw.p.half2, pw.p.half2);
  const Vec3 q = pw.p.point + c1 * pw.p.axis1 + c2 * pw.axis2;
  const Vec3 d = q - x;
  const double dist = norm(d);
  n = dist > 0.0 ? d * (1.0 / dist) : -pw.p.normal;
  return dist;
}

}  // namespace demfdm::dem::detail
