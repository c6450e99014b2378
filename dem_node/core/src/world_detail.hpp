// Internals shared by world.cpp and walls.cpp (not installed): the history key of a contact,
// the phase lap timer, the ball-wall candidate record and the wall distance functions.
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <tuple>

#include "demfdm/dem/geometry.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem::detail {

// A contact's history key: (lower id, higher id) for pairs, (ball id, wall id) for walls.
struct Key {
  std::uint64_t lo, hi;
  std::uint32_t idx;
  bool operator<(const Key& o) const { return std::tie(lo, hi) < std::tie(o.lo, o.hi); }
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
