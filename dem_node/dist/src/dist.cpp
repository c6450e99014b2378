// The DEM on MPI ranks (dist.hpp, docs/scaling.md).
#include "demfdm/dem/dist.hpp"
#include "demfdm/dem/checkpoint.hpp"
#include <exception>
#include "demfdm/dem/guard.hpp"

#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/specimen_steps.hpp"
#include "demfdm/dem/specimen.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <tuple>
#include <numeric>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace demfdm::dem {

// ------------------------------------------------------------------------------------------
// brick grid

namespace {

// Position of x along axis k relative to the grid, wrapped into [0, len) on a periodic axis.
double along(const BrickGrid& g, const Vec3& x, int k) {
  double u = x[k] - g.lo[k];
  if (g.periodic[k]) {
    u -= std::floor(u / g.len[k]) * g.len[k];
    if (u >= g.len[k]) u = 0.0;  // rounding of the wrap
  }
  return u;
}

}  // namespace

// RCB: the inner nodes in preorder. A node of p ranks starting at rank r0, with index i: its low
// child has p / 2 ranks from r0 and index i + 1, its high child p - p / 2 ranks from r0 + p / 2
// and index i + p / 2 (after the low child's p / 2 - 1 inner nodes); a child of one rank is a leaf.

namespace {

// The axis a node of RCB cuts: its box's longest side, the lowest axis of equal ones.
int longest_axis(const double* a0, const double* a1) {
  int k = 0;
  for (int j = 1; j < 3; ++j)
    if (a1[j] - a0[j] > a1[k] - a0[k]) k = j;
  return k;
}

// From the root down to one leaf of g's RCB tree: at each inner node `low(cut, r0, left)` says
// whether to take the low side (the node's ranks start at r0, its low child has `left`).
// Returns the leaf's rank.
template <class Low>
int rcb_leaf(const BrickGrid& g, Low low) {
  int i = 0, r0 = 0, p = g.parts;
  while (p > 1) {
    const BrickGrid::Cut& c = g.rcb[static_cast<std::size_t>(i)];
    const int left = p / 2;
    if (low(c, r0, left)) {
      i += 1;
      p = left;
    } else {
      i += left;
      r0 += left;
      p -= left;
    }
  }
  return r0;
}

}  // namespace

void BrickGrid::set_rcb(int p) {
  if (p < 1) throw std::invalid_argument("BrickGrid::set_rcb: at least one part");
  parts = p;
  rcb.assign(static_cast<std::size_t>(p - 1), Cut{});
  auto build = [&](auto&& self, int i, int np, const double* a0, const double* a1) -> void {
    if (np < 2) return;
    const int k = longest_axis(a0, a1);
    const int left = np / 2;
    const double at = a0[k] + (a1[k] - a0[k]) * left / np;
    rcb[static_cast<std::size_t>(i)] = {k, at};
    double m1[3] = {a1[0], a1[1], a1[2]}, m0[3] = {a0[0], a0[1], a0[2]};
    m1[k] = at;
    m0[k] = at;
    self(self, i + 1, left, a0, m1);
    self(self, i + left, np - left, m0, a1);
  };
  const double a0[3] = {0.0, 0.0, 0.0}, a1[3] = {len[0], len[1], len[2]};
  build(build, 0, p, a0, a1);
}

void BrickGrid::box(int r, double a0[3], double a1[3]) const {
  if (parts > 0) {
    for (int k = 0; k < 3; ++k) a0[k] = 0.0, a1[k] = len[k];
    rcb_leaf(*this, [&](const Cut& c, int r0, int left) {
      const bool lo = r < r0 + left;
      (lo ? a1 : a0)[c.axis] = c.at;
      return lo;
    });
    return;
  }
  const int idx[3] = {r % n[0], (r / n[0]) % n[1], r / (n[0] * n[1])};
  for (int k = 0; k < 3; ++k) a0[k] = edge(k, idx[k]), a1[k] = edge(k, idx[k] + 1);
}

int BrickGrid::owner(const Vec3& x) const {
  if (parts > 0) return rcb_leaf(*this, [&](const Cut& c, int, int) { return along(*this, x, c.axis) < c.at; });
  int idx[3];
  for (int k = 0; k < 3; ++k) {
    const double u = along(*this, x, k);
    int i;
    if (cuts[k].empty()) {
      i = static_cast<int>(std::floor(u / (len[k] / n[k])));
    } else {  // the bricks whose start is at or below u
      i = static_cast<int>(std::upper_bound(cuts[k].begin(), cuts[k].end(), u) - cuts[k].begin());
    }
    idx[k] = std::clamp(i, 0, n[k] - 1);
  }
  return idx[0] + n[0] * (idx[1] + n[1] * idx[2]);
}

void BrickGrid::follow_cell(const Vec3& origin, const Vec3& length) {
  for (int k = 0; k < 3; ++k) {
    if (!periodic[k] || len[k] == length[k]) continue;
    const double f = length[k] / len[k];
    lo[k] = origin[k] + (lo[k] - origin[k]) * f;
    for (double& c : cuts[k]) c *= f;
    for (Cut& c : rcb)
      if (c.axis == k) c.at *= f;
    len[k] = length[k];
  }
}

void BrickGrid::near(const Vec3& x, double halo, std::vector<int>& out) const {
  out.clear();
  if (parts > 0) {
    // Per axis the point and, on a periodic axis, its images within the halo of the cell; every
    // combination walks down the tree into each side whose brick, grown by the halo, holds it
    // (a brick's bounds are its ancestors' cuts; the cell's faces bound only the images).
    double im[3][3];
    int ni[3];
    for (int k = 0; k < 3; ++k) {
      const double u = along(*this, x, k);
      ni[k] = 0;
      im[k][ni[k]++] = u;
      if (periodic[k]) {
        if (u - len[k] >= -halo) im[k][ni[k]++] = u - len[k];
        if (u + len[k] < len[k] + halo) im[k][ni[k]++] = u + len[k];
      }
    }
    auto walk = [&](auto&& self, const double* v, int i, int r0, int p) -> void {
      if (p < 2) {
        out.push_back(r0);
        return;
      }
      const Cut& c = rcb[static_cast<std::size_t>(i)];
      const int left = p / 2;
      const double u = v[c.axis];
      if (u < c.at + halo) self(self, v, i + 1, r0, left);
      if (u >= c.at - halo) self(self, v, i + left, r0 + left, p - left);
    };
    for (int a = 0; a < ni[0]; ++a)
      for (int b = 0; b < ni[1]; ++b)
        for (int c = 0; c < ni[2]; ++c) {
          const double v[3] = {im[0][a], im[1][b], im[2][c]};
          walk(walk, v, 0, 0, parts);
        }
    if (out.size() > 1) {
      std::sort(out.begin(), out.end());
      out.erase(std::unique(out.begin(), out.end()), out.end());
    }
    return;
  }
  // per axis, the bricks that hold x (once per ball per exchange: no allocation once warm)
  thread_local std::vector<int> ax[3];
  for (int k = 0; k < 3; ++k) {
    ax[k].clear();
    if (n[k] == 1) {  // one brick along the axis: it holds x (and its images)
      ax[k].push_back(0);
      continue;
    }
    const double u = along(*this, x, k);
    for (int i = 0; i < n[k]; ++i) {
      // brick i grown by the halo; on a free axis the end bricks reach to infinity
      const double lo_i = (!periodic[k] && i == 0) ? -INFINITY : edge(k, i) - halo;
      const double hi_i = (!periodic[k] && i == n[k] - 1) ? INFINITY : edge(k, i + 1) + halo;
      bool in = u >= lo_i && u < hi_i;
      if (periodic[k]) in = in || (u - len[k] >= lo_i && u - len[k] < hi_i) || (u + len[k] >= lo_i && u + len[k] < hi_i);
      if (in) ax[k].push_back(i);
    }
  }
  for (int k2 : ax[2])
    for (int k1 : ax[1])
      for (int k0 : ax[0]) out.push_back(k0 + n[0] * (k1 + n[1] * k2));
  if (out.size() < 2) return;
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

// ------------------------------------------------------------------------------------------
// records

namespace {

static_assert(std::is_trivially_copyable_v<Vec3> && std::is_trivially_copyable_v<ContactHist> &&
              std::is_trivially_copyable_v<BondHist>);

// One ball, all of its row.
struct BallRec {
  std::uint64_t id;
  Vec3 x, v, w, f, t, fa, ta, xr;
  double r, m, inertia;
  std::uint8_t fix;
};

// One ball-ball contact, its balls by id (a: the lower id, which is the lower row on every rank).
struct PairRec {
  std::uint64_t ia, ib;
  std::array<std::int8_t, 4> s;
  ContactHist h;
  BondHist b;
};

// One ball-wall contact, its ball by id: the history goes with the ball to its new owner (a
// rank keeps the wall contacts of its own balls only).
struct WallRec {
  std::uint64_t id;
  std::uint32_t wall;
  std::int32_t facet;
  std::uint8_t kind;  // 0 planes, 1 facets, 2 footing (World::swap_balls)
  ContactHist h;
  BondHist b;
};

// A run of records in a byte message: its count, then the records (read back by get_recs).
template <class T>
void put_recs(std::vector<char>& out, const std::vector<T>& v) {
  const std::uint64_t n = v.size();
  const std::size_t at = out.size();
  out.resize(at + sizeof n + n * sizeof(T));
  std::memcpy(out.data() + at, &n, sizeof n);
  if (n) std::memcpy(out.data() + at + sizeof n, v.data(), n * sizeof(T));
}

template <class T>
const char* get_recs(const char* q, std::vector<T>& v) {
  std::uint64_t n = 0;
  std::memcpy(&n, q, sizeof n);
  q += sizeof n;
  const std::size_t at = v.size();
  v.resize(at + n);
  if (n) std::memcpy(static_cast<void*>(v.data() + at), q, n * sizeof(T));
  return q + n * sizeof(T);
}

bool by_kind_ball_wall(const WallSumRec& x, const WallSumRec& y) {
  if (x.kind != y.kind) return x.kind < y.kind;
  return x.ball != y.ball ? x.ball < y.ball : x.wall < y.wall;
}
bool by_kind_ball_wall(const FacetSumShare& x, const FacetSumShare& y) {  // (one kind)
  return x.ball != y.ball ? x.ball < y.ball : x.wall < y.wall;
}

}  // namespace

void radix_order(const std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& order) {
  const std::size_t n = keys.size();
  order.resize(n);
  for (std::size_t j = 0; j < n; ++j) order[j] = static_cast<std::uint32_t>(j);
  std::uint64_t top = 0;
  for (std::uint64_t k : keys) top |= k;
  constexpr int kBits = 11;
  constexpr std::size_t kBuckets = std::size_t{1} << kBits;
  thread_local std::vector<std::uint32_t> tmp;
  tmp.resize(n);
  std::uint32_t count[kBuckets];
  for (int shift = 0; shift < 64 && (top >> shift) != 0; shift += kBits) {
    std::fill(count, count + kBuckets, 0u);
    for (std::size_t j = 0; j < n; ++j) ++count[(keys[order[j]] >> shift) & (kBuckets - 1)];
    std::uint32_t run = 0;
    for (std::size_t b = 0; b < kBuckets; ++b) {
      const std::uint32_t c = count[b];
      count[b] = run;
      run += c;
    }
    for (std::size_t j = 0; j < n; ++j) tmp[count[(keys[order[j]] >> shift) & (kBuckets - 1)]++] = order[j];
    order.swap(tmp);
  }
}

// One World's order, (ball id, wall). The ranks' runs are sorted: up to 8 runs they are merged
// pairwise (merge_runs); from there the O(n log P) branchy comparisons of 128-byte records cost
// more than a radix order of one key per share and one copy per share (bench_dist --merge: 16.1
// against 11.2 ns per share at 8 runs, 4.8 against 10.5 at 2). Both are stable: equal keys keep
// rank order. Keys that do not fit 63 bits are merged.
template <class T>
void order_wall_shares(std::vector<T>& v, const std::vector<std::size_t>& starts) {
  const auto less = [](const T& x, const T& y) { return by_kind_ball_wall(x, y); };
  if (starts.size() < 3) return;  // one run: already in order
  if (starts.size() - 1 < 8) {
    merge_runs(v, starts, less);
    return;
  }
  const std::size_t first = starts.front(), m = starts.back() - first;
  std::uint32_t wall_max = 0;
  std::uint64_t ball_max = 0;
  for (std::size_t j = first; j < first + m; ++j) wall_max = std::max(wall_max, v[j].wall), ball_max = std::max(ball_max, v[j].ball);
  int wb = 1;
  while (wb < 32 && (std::uint64_t{wall_max} >> wb) != 0) ++wb;
  if ((ball_max >> (63 - wb)) != 0) {
    merge_runs(v, starts, less);
    return;
  }
  thread_local std::vector<std::uint64_t> keys;
  thread_local std::vector<std::uint32_t> ord;
  thread_local std::vector<T> tmp;
  keys.resize(m);
  for (std::size_t j = 0; j < m; ++j) keys[j] = v[first + j].ball << wb | v[first + j].wall;
  radix_order(keys, ord);
  tmp.resize(m);
  for (std::size_t j = 0; j < m; ++j) tmp[j] = v[first + ord[j]];
  std::copy(tmp.begin(), tmp.end(), v.begin() + static_cast<std::ptrdiff_t>(first));
}
template void order_wall_shares(std::vector<WallSumRec>&, const std::vector<std::size_t>&);
template void order_wall_shares(std::vector<FacetSumShare>&, const std::vector<std::size_t>&);

namespace {

// Empty every array, keeping its memory (refilled at the next exchange).
void clear_keep(WallContacts& c) {
  c.ball.clear(), c.wall.clear(), c.h.clear(), c.bond.clear(), c.facet.clear(), c.cand_off.clear(), c.cand.clear();
  c.F.clear(), c.M.clear(), c.TA.clear(), c.xc.clear(), c.bary.clear();
}

// Append one wall contact of the ball in `row` with a given history; its facet is its only
// candidate until the rebuild that follows (World::swap_balls). F, M and the rest are results of
// the next pass.
void push_wall(WallContacts& wc, std::uint32_t row, std::uint32_t wall, std::int32_t facet, const ContactHist& h,
               const BondHist* b) {
  if (wc.cand_off.empty()) wc.cand_off.push_back(0);
  wc.ball.push_back(row);
  wc.wall.push_back(wall);
  wc.facet.push_back(facet);
  wc.cand.push_back(static_cast<std::uint32_t>(facet));
  wc.cand_off.push_back(static_cast<std::uint32_t>(wc.cand.size()));
  wc.h.push_back(h);
  if (b) wc.bond.push_back(*b);
  wc.F.emplace_back(), wc.M.emplace_back(), wc.TA.emplace_back(), wc.xc.emplace_back(), wc.bary.emplace_back();
}

// The wall-contact lists of a World, by kind (World::swap_balls's order).
std::array<const WallContacts*, 3> wall_lists(const World& w) {
  return {&w.plane_contacts(), &w.facet_contacts(), &w.footing_contacts()};
}

// Whether a kind's law keeps bond histories.
bool kind_bonds(const WorldParams& p, int kind) {
  const ContactFamilyParams& f = kind == 0 ? p.ball_wall : kind == 1 ? p.ball_facet : p.ball_footing;
  return law_has_bond(f.model);
}

// Entries j = 0 .. src.size() - 1 of `out`: in[src[j]] where src[j] >= 0, else the field `m`
// of the record recs[~src[j]]; one pass per array (the exchange's merges).
template <class T, class Rec>
void fill_column(std::vector<T>& out, const std::vector<T>& in, const std::vector<Rec>& recs,
                 const std::vector<std::int64_t>& src, T Rec::*m) {
  out.resize(src.size());
  T* o = out.data();
  const T* a = in.data();
  for (std::size_t j = 0; j < src.size(); ++j) {
    const std::int64_t s = src[j];
    o[j] = s >= 0 ? a[s] : recs[static_cast<std::size_t>(~s)].*m;
  }
}
void fill_rows(Particles& q, const Particles& pt, const std::vector<BallRec>& bin, const std::vector<std::int64_t>& src) {
  fill_column(q.id, pt.id, bin, src, &BallRec::id);
  for (auto [p, m] : {std::pair{&Particles::x, &BallRec::x}, {&Particles::v, &BallRec::v}, {&Particles::w, &BallRec::w},
                      {&Particles::f, &BallRec::f}, {&Particles::t, &BallRec::t}, {&Particles::fa, &BallRec::fa},
                      {&Particles::ta, &BallRec::ta}, {&Particles::x_ref, &BallRec::xr}})
    fill_column(q.*p, pt.*p, bin, src, m);
  for (auto [p, m] : {std::pair{&Particles::r, &BallRec::r}, {&Particles::m, &BallRec::m},
                      {&Particles::inertia, &BallRec::inertia}})
    fill_column(q.*p, pt.*p, bin, src, m);
  fill_column(q.fix, pt.fix, bin, src, &BallRec::fix);
}

// The row of ball `id` in rows whose ids ascend in [0, split) and in [split, n) (DistDem::split_;
// one run when split = n), or -1.
std::int64_t find_row(const std::vector<std::uint64_t>& ids, std::size_t split, std::uint64_t id) {
  auto in = [&](std::size_t lo, std::size_t hi) -> std::int64_t {
    const auto b = ids.begin() + static_cast<std::ptrdiff_t>(lo), e = ids.begin() + static_cast<std::ptrdiff_t>(hi);
    const auto it = std::lower_bound(b, e, id);
    return (it != e && *it == id) ? it - ids.begin() : -1;
  };
  const std::int64_t r = in(0, std::min(split, ids.size()));
  return r >= 0 || split >= ids.size() ? r : in(split, ids.size());
}

// Rows given by their sources `src` with their ghost flags put as [owned | ghosts], each part in
// the order it had (a stable partition; `ghost` follows). Returns the owned count. `tmp`: scratch.
std::size_t put_ghosts_last(std::vector<std::int64_t>& src, std::vector<std::uint8_t>& ghost,
                            std::vector<std::int64_t>& tmp) {
  tmp.clear();
  for (std::size_t r = 0; r < src.size(); ++r)
    if (!ghost[r]) tmp.push_back(src[r]);
  const std::size_t split = tmp.size();
  for (std::size_t r = 0; r < src.size(); ++r)
    if (ghost[r]) tmp.push_back(src[r]);
  src.swap(tmp);
  std::fill(ghost.begin(), ghost.begin() + static_cast<std::ptrdiff_t>(split), std::uint8_t{0});
  std::fill(ghost.begin() + static_cast<std::ptrdiff_t>(split), ghost.end(), std::uint8_t{1});
  return split;
}

// A pair list sorted by (A row, B id) within each A's run, put in (A row, B row) order, where the
// rows of the partners below `split` ascend with their ids and so do those from `split` on: in
// each run, stably, the partners below `split` first (the ghosts in rows of their own come after
// the owned rows). `b` and `src` (each pair's source) move together; `tb`, `ts` are scratch.
void partners_by_row(const std::vector<std::uint32_t>& a, std::vector<std::uint32_t>& b, std::vector<std::int64_t>& src,
                     std::size_t split, std::vector<std::uint32_t>& tb, std::vector<std::int64_t>& ts) {
  const std::size_t m = a.size();
  for (std::size_t c0 = 0; c0 < m;) {
    std::size_t c1 = c0 + 1;
    while (c1 < m && a[c1] == a[c0]) ++c1;
    tb.clear(), ts.clear();
    std::size_t w = c0;
    for (std::size_t c = c0; c < c1; ++c) {
      if (b[c] < split) {
        b[w] = b[c], src[w] = src[c], ++w;
      } else {
        tb.push_back(b[c]), ts.push_back(src[c]);
      }
    }
    std::copy(tb.begin(), tb.end(), b.begin() + static_cast<std::ptrdiff_t>(w));
    std::copy(ts.begin(), ts.end(), src.begin() + static_cast<std::ptrdiff_t>(w));
    c0 = c1;
  }
}

BallRec ball_rec(const Particles& pt, std::size_t i) {
  return BallRec{pt.id[i], pt.x[i], pt.v[i], pt.w[i], pt.f[i], pt.t[i], pt.fa[i], pt.ta[i], pt.x_ref[i],
                 pt.r[i],  pt.m[i], pt.inertia[i], pt.fix[i]};
}

void push_ball(Particles& pt, const BallRec& b) {
  pt.id.push_back(b.id);
  pt.x.push_back(b.x);
  pt.v.push_back(b.v);
  pt.w.push_back(b.w);
  pt.f.push_back(b.f);
  pt.t.push_back(b.t);
  pt.fa.push_back(b.fa);
  pt.ta.push_back(b.ta);
  pt.x_ref.push_back(b.xr);
  pt.r.push_back(b.r);
  pt.m.push_back(b.m);
  pt.inertia.push_back(b.inertia);
  pt.fix.push_back(b.fix);
}

// All-to-all of trivially copyable records: out[r] goes to rank r; `in` gets what every rank
// sent here, in rank order. The byte buffers and `in` keep their capacity from call to call (a
// fresh allocation of this size per exchange cost more in page faults than the exchange).
template <class T>
void all_to_all(MPI_Comm comm, const std::vector<std::vector<T>>& out, std::vector<T>& in, std::vector<char>& sb,
                std::vector<char>& rb) {
  const int P = static_cast<int>(out.size());
  std::vector<int> sc(P), rc(P), sd(P), rd(P);
  int stotal = 0;
  for (int r = 0; r < P; ++r) {
    sc[r] = static_cast<int>(out[r].size() * sizeof(T));
    sd[r] = stotal;
    stotal += sc[r];
  }
  MPI_Alltoall(sc.data(), 1, MPI_INT, rc.data(), 1, MPI_INT, comm);
  if (sb.size() < static_cast<std::size_t>(stotal)) sb.resize(static_cast<std::size_t>(stotal));
  for (int r = 0; r < P; ++r)
    if (sc[r]) std::memcpy(sb.data() + sd[r], out[r].data(), static_cast<std::size_t>(sc[r]));
  int total = 0;
  for (int r = 0; r < P; ++r) {
    rd[r] = total;
    total += rc[r];
  }
  if (rb.size() < static_cast<std::size_t>(total)) rb.resize(static_cast<std::size_t>(total));
  MPI_Alltoallv(sb.data(), sc.data(), sd.data(), MPI_BYTE, rb.data(), rc.data(), rd.data(), MPI_BYTE, comm);
  in.resize(static_cast<std::size_t>(total) / sizeof(T));
  if (total) std::memcpy(static_cast<void*>(in.data()), rb.data(), static_cast<std::size_t>(total));
}

}  // namespace

// ------------------------------------------------------------------------------------------
// DistDem

// A wall contact's share as sent to rank 0 (DistDem::reduce_walls): planes and the footing send
// only what they sum; a facet sends its FacetSumShare (the terms its rank's pass formed).
struct PlaneShare {
  std::uint64_t ball;
  std::uint32_t wall;
  std::uint8_t active;
  Vec3 F;
  double k;
};
struct FootingShare {
  std::uint64_t ball;
  Vec3 F;
};

struct DistDem::Buffers {
  // the node's measurements, every step: each rank's terms, rank 0's gathered terms, the values
  // of order-free sums; the kept merge orders of ordered_sums (ball terms, contact terms)
  std::vector<World::ContactTerm> m_terms, m_all;
  std::vector<double> m_vals, m_rows, m_bound, m_res;
  std::vector<OrderFreeSum> m_folds;
  std::vector<int> m_counts, m_displ;
  OrderCache order_cache[4];
  // the exchange's per-row and per-destination arrays, kept from one exchange to the next (a
  // fresh allocation of each cost page faults at every rebuild)
  std::vector<int> own, old_owner, holders, dest, near_all;
  std::vector<std::uint32_t> hold_off, off, near_off, fill;
  std::vector<std::uint8_t> keep;
  std::vector<std::int64_t> new_row, src, psrc, src2, ts;
  // with the ghosts in rows of their own: the old rows and contacts in id order, and scratch
  std::vector<std::uint32_t> ido, cord, tb;
  std::vector<std::vector<std::uint64_t>> kout;
  std::vector<std::uint64_t> kin;
  std::vector<std::uint32_t> order, order2;
  std::vector<PlaneShare> plane_shares;
  std::vector<FacetSumShare> facet_shares, all_facet_shares;
  std::vector<std::size_t> run_starts;  // reduce_walls: where each rank's records of a kind begin
  // reduce_walls with order-free sums: the terms, bounds, sums and folds
  std::vector<World::WallTerm> of_terms;
  std::vector<double> of_bound, of_folds;
  std::vector<OrderFreeSum> of_sums;
  std::vector<FootingShare> footing_shares;
  std::vector<std::vector<BallRec>> bout;
  std::vector<std::vector<PairRec>> pout;
  std::vector<std::vector<WallRec>> wout;
  std::vector<BallRec> bin;
  std::vector<PairRec> pin;
  std::vector<WallRec> win;
  std::array<WallContacts, 3> wall;
  std::vector<WallSumRec> sums, all_sums;
  std::vector<double> packed;
};

DistDem::DistDem(MPI_Comm comm, const WorldParams& p, const BrickGrid& grid)
    : comm_(comm), grid_(grid), p_(p), buf_(std::make_unique<Buffers>()) {
  MPI_Comm_rank(comm_, &rank_);
  MPI_Comm_size(comm_, &size_);
  if (size_ != grid_.count())
    throw std::invalid_argument("DistDem: the brick grid has " + std::to_string(grid_.count()) + " bricks but " +
                                std::to_string(size_) + " ranks run.");
}

DistDem::~DistDem() = default;

std::size_t DistDem::owned() const {
  const auto& g = w_->ghost_rows();
  return w_->num_balls() - static_cast<std::size_t>(std::count(g.begin(), g.end(), std::uint8_t{1}));
}

std::size_t DistDem::ghosts() const { return w_->num_balls() - owned(); }

namespace {

// The effects the ranks run (load): gravity comes with the parameters; a platen servo runs on
// every rank, reading its wall's reaction and stiffness sum, which the ranks then reduce after
// every step (step), so every rank sets the same wall velocity as one World. No other effect runs
// on the ranks yet. Also refuses rows out of id order.
std::vector<PlatenServoParams> loadable(const World& full) {
  const Particles& fp = full.balls();
  for (std::size_t i = 1; i < fp.size(); ++i)
    if (!(fp.id[i - 1] < fp.id[i])) throw std::invalid_argument("DistDem::load: the rows must be in id order.");
  std::vector<PlatenServoParams> platens;
  for (const Effect* e : full.effects()) {
    if (std::string(e->name()) == "gravity") continue;
    if (const auto* ps = dynamic_cast<const PlatenServo*>(e)) {
      platens.push_back(ps->params());
      continue;
    }
    const std::string name = e->name();
    throw std::invalid_argument("DistDem::load: the world has the effect '" + name +
                                "', which the DEM on MPI ranks cannot take with the world (docs/scaling.md)" +
                                (name == "periodic_servo" ? "; add it on the ranks after the load "
                                                            "(DistDem::add_periodic_servo)."
                                                          : "; run it on one rank."));
  }
  return platens;
}

}  // namespace

// Which rows, pairs and wall contacts of `full` go to every rank (all_ranks) or to this one, in
// one pass over the balls, the pairs and the wall contacts (halo_, grid_ and newton_
// set): a rank's rows are its brick's balls, the balls within the halo, and the partners of a
// contact with one of its balls (a bonded pair may be stretched beyond the halo), in id order.
DistDem::Cut DistDem::cut(const World& full, bool all_ranks) const {
  const Particles& fp = full.balls();
  const std::size_t n = fp.size(), P = static_cast<std::size_t>(size_);
  Cut k;
  k.own.resize(n);
  k.rows.resize(P);
  k.pairs.resize(P);
  for (auto& w : k.walls) w.resize(P);
  auto wanted = [&](int r) { return all_ranks || r == rank_; };
  // One rank: its rows as a mask (in row order without a sort); every rank: lists, sorted after
  // the partners are added.
  std::vector<std::uint8_t> mask(all_ranks ? 0 : n, 0);
  auto add = [&](int r, std::uint32_t i) {
    if (all_ranks)
      k.rows[static_cast<std::size_t>(r)].push_back(i);
    else if (r == rank_)
      mask[i] = 1;
  };
  std::vector<int> nb;
  for (std::size_t i = 0; i < n; ++i) {
    const int o = grid_.owner(fp.x[i]);
    k.own[i] = o;
    grid_.near(fp.x[i], halo_, nb);
    bool has_o = false;
    for (int r : nb) {
      has_o = has_o || r == o;
      add(r, static_cast<std::uint32_t>(i));
    }
    if (!has_o) add(o, static_cast<std::uint32_t>(i));
  }
  const PairContacts& fc = full.pair_contacts();
  for (std::size_t c = 0; c < fc.size(); ++c) {  // (each rank's pairs in full's order)
    const std::uint32_t a = fc.a[c], b = fc.b[c];
    const int oa = k.own[a], ob = k.own[b];
    if (wanted(oa)) {  // A's owner computes the pair (and B is its partner)
      k.pairs[static_cast<std::size_t>(oa)].push_back(static_cast<std::uint32_t>(c));
      add(oa, b);
    }
    if (!newton_ && ob != oa && wanted(ob)) {  // newton off: B's owner computes it too
      k.pairs[static_cast<std::size_t>(ob)].push_back(static_cast<std::uint32_t>(c));
      add(ob, a);
    }
  }
  if (all_ranks) {
    for (auto& rows : k.rows) {
      std::sort(rows.begin(), rows.end());
      rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
    }
  } else {
    for (std::size_t i = 0; i < n; ++i)
      if (mask[i]) k.rows[static_cast<std::size_t>(rank_)].push_back(static_cast<std::uint32_t>(i));
  }
  const auto fw = wall_lists(full);
  for (std::size_t q = 0; q < 3; ++q) {
    const WallContacts& f = *fw[q];
    for (std::size_t c = 0; c < f.size(); ++c)
      if (wanted(k.own[f.ball[c]])) k.walls[q][static_cast<std::size_t>(k.own[f.ball[c]])].push_back(static_cast<std::uint32_t>(c));
  }
  return k;
}

// Rank r's part of `full` as cut by `k`: its rows, the ball-ball pairs r computes and the wall
// contacts of r's balls, in a World with full's walls, cell, effects and counters
// (`mark_ghosts`: its rows of other ranks' balls marked as ghosts; unmarked, it can be saved).
std::unique_ptr<World> DistDem::part_of(const World& full, const Cut& k, int r,
                                        const std::vector<PlatenServoParams>& platens, bool mark_ghosts) const {
  const Particles& fp = full.balls();
  const std::size_t n = fp.size();
  const std::vector<int>& own = k.own;
  const std::vector<std::uint32_t>& rows = k.rows[static_cast<std::size_t>(r)];
  Particles pt;
  std::vector<std::uint8_t> ghost;
  // full's row -> this part's row: `k.row`, all -1 between calls (only this part's entries are
  // set and reset, so that cutting for every rank stays O(N) in all)
  std::vector<std::int64_t>& row = k.row;
  if (row.size() != n) row.assign(n, -1);
  for (std::uint32_t i : rows) {
    row[i] = static_cast<std::int64_t>(pt.size());
    push_ball(pt, ball_rec(fp, i));
    ghost.push_back(own[i] != r);
  }
  struct Reset {
    std::vector<std::int64_t>& row;
    const std::vector<std::uint32_t>& rows;
    ~Reset() {
      for (std::uint32_t i : rows) row[i] = -1;
    }
  } reset{row, rows};
  PairContacts pc;
  const PairContacts& fc = full.pair_contacts();
  const bool has_bond = !fc.bond.empty();
  for (std::uint32_t c : k.pairs[static_cast<std::size_t>(r)]) {  // in full's order
    pc.a.push_back(static_cast<std::uint32_t>(row[fc.a[c]]));
    pc.b.push_back(static_cast<std::uint32_t>(row[fc.b[c]]));
    pc.shift.push_back(fc.shift[c]);
    pc.h.push_back(fc.h[c]);
    if (has_bond) pc.bond.push_back(fc.bond[c]);
  }
  // The walls, the same on every rank (each moves them itself), and the wall contacts of r's
  // balls.
  std::array<WallContacts, 3> wc;
  const auto fw = wall_lists(full);
  for (std::size_t q = 0; q < 3; ++q) {
    const WallContacts& f = *fw[q];
    for (std::uint32_t c : k.walls[q][static_cast<std::size_t>(r)]) {  // every field, its candidate facets and last forces too
        WallContacts& d = wc[q];
        push_wall(d, static_cast<std::uint32_t>(row[f.ball[c]]), f.wall[c], f.facet[c], f.h[c],
                  f.bond.empty() ? nullptr : &f.bond[c]);
        if (!f.cand_off.empty()) {
          d.cand.pop_back();
          d.cand.insert(d.cand.end(), f.cand.begin() + f.cand_off[c], f.cand.begin() + f.cand_off[c + 1]);
          d.cand_off.back() = static_cast<std::uint32_t>(d.cand.size());
        }
        d.F.back() = f.F[c], d.M.back() = f.M[c], d.TA.back() = f.TA[c], d.xc.back() = f.xc[c], d.bary.back() = f.bary[c];
      }
  }
  for (WallContacts& d : wc)  // a list without contacts has its one offset, as a World's has
    if (d.cand_off.empty()) d.cand_off.push_back(0);
  auto w = std::make_unique<World>(p_);
  w->set_wall_sums_by_caller(size_ > 1);  // reduce_walls forms them from every rank's shares
  w->set_pair_kernel(full.pair_kernel());
  w->set_cell(full.cell_origin(), full.cell_length());
  w->set_strain_rate(full.strain_rate());
  for (int i = 0; i < full.num_planes(); ++i) w->plane(w->add_plane(full.plane(i).p)) = full.plane(i);
  for (int i = 0; i < full.num_facet_walls(); ++i) {
    const FacetWall& f = full.facet_wall(i);
    std::vector<double> v;
    std::vector<std::int32_t> t;
    for (const Vec3& x : f.pos) v.insert(v.end(), {x.x, x.y, x.z});
    for (const auto& tr : f.tri) t.insert(t.end(), tr.begin(), tr.end());
    w->facet_wall(w->add_facet_wall(v, t)) = f;
  }
  if (full.has_footing()) w->set_footing(full.footing().p);
  w->copy_walls(full);  // every field, the walls' ids too (histories are carried by them)
  for (const PlatenServoParams& ps : platens) w->add_effect(std::make_unique<PlatenServo>(ps));
  if (!mark_ghosts) ghost.clear();
  w->swap_balls(pt, pc, wc, ghost);
  // One World's counters (time, step, the step's schedule, ...). The counts and energies that
  // are sums over the ranks' contacts start from the full world's on rank 0 and from 0 elsewhere.
  World::Counters kc = full.counters();
  if (r != 0) kc.bond_failures = 0, kc.e_damp = kc.e_slip_dead = kc.e_soft_dead = 0.0;
  w->set_counters(kc);
  return w;
}

// The parameters and the halo of the ranks' Worlds, from the whole World.
void DistDem::params_from(const World& full, double rmax_given) {
  const int threads = p_.threads;  // this rank's own, as the constructor set it (see load_from_root)
  p_ = full.params();
  p_.threads = threads;
  p_.skin = full.skin();  // the full world's skin, not one from this rank's smallest ball
  // Inside a rank the ball sums keep the one-thread order: the bits of one World at any rank and
  // thread count.
  p_.thread_independent = true;
  double rmax = rmax_given;
  if (rmax < 0.0) {
    rmax = 0.0;
    for (double r : full.balls().r) rmax = std::max(rmax, r);
  }
  halo_ = 2.0 * rmax + p_.skin;
}

void DistDem::load(const World& full) {
  const std::vector<PlatenServoParams> platens = loadable(full);
  params_from(full);
  balance_at_load(rank_ == 0 ? &full : nullptr);  // (every rank holds `full`: rank 0's weights count)
  take(part_of(full, cut(full, false), rank_, platens), !platens.empty());
}

namespace {
constexpr int kTagPart = 7303;                 // load_from_root's parts
}  // namespace

namespace {
// Rank 0's verdict is every rank's: its refusal (empty: none) broadcast, and thrown on every
// rank with rank 0's words (collective).
void share_verdict(MPI_Comm comm, std::string refused) {
  int len = static_cast<int>(refused.size());
  MPI_Bcast(&len, 1, MPI_INT, 0, comm);
  if (len == 0) return;
  refused.resize(static_cast<std::size_t>(len));
  MPI_Bcast(refused.data(), len, MPI_CHAR, 0, comm);
  throw std::invalid_argument(refused);
}
}  // namespace

// Rank 0 cuts `full` (one pass, cut) and sends each rank its part as a World's state file in
// memory (the checkpoint format, dem/checkpoint.hpp: every field, bit for bit). The receiving
// rank takes it as its World, the rows of other ranks' balls marked as ghosts, and steps as
// load(full) would have it.
void DistDem::load_from_root(const World& full) {
  // Rank 0's verdict on `full` first (a refusal is every rank's), then the halo.
  std::string refused;
  std::vector<PlatenServoParams> platens;
  double hk[2] = {0.0, 0.0};
  if (rank_ == 0) {
    try {
      platens = loadable(full);
      params_from(full);
      hk[0] = halo_;
      hk[1] = static_cast<double>(static_cast<int>(full.pair_kernel()));
    } catch (const std::invalid_argument& e) {
      refused = e.what();
    }
  }
  share_verdict(comm_, refused);
  MPI_Bcast(hk, 2, MPI_DOUBLE, 0, comm_);
  halo_ = hk[0];
  balance_at_load(rank_ == 0 ? &full : nullptr);
  if (rank_ == 0) {
    // (a failure while cutting reaches the ranks still waiting as a size of -1)
    auto fail_from = [&](int r) {
      const long long bad = -1;
      for (int q = r; q < size_; ++q) MPI_Send(&bad, 1, MPI_LONG_LONG, q, kTagPart, comm_);
    };
    Cut k;
    try {
      k = cut(full, true);
    } catch (...) {
      fail_from(1);
      throw;
    }
    for (int r = 1; r < size_; ++r) {
      std::string bytes;
      try {
        bytes = state_bytes(*part_of(full, k, r, platens, false), CheckpointMeta{});
      } catch (...) {
        fail_from(r);
        throw;
      }
      const long long nb = static_cast<long long>(bytes.size());
      MPI_Send(&nb, 1, MPI_LONG_LONG, r, kTagPart, comm_);
      for (long long at = 0; at < nb; at += chunk_)  // (an int counts at most 2 GiB)
        MPI_Send(bytes.data() + at, static_cast<int>(std::min(chunk_, nb - at)), MPI_CHAR, r, kTagPart, comm_);
    }
    take(part_of(full, k, 0, platens), !platens.empty());
    return;
  }
  long long nb = 0;
  MPI_Recv(&nb, 1, MPI_LONG_LONG, 0, kTagPart, comm_, MPI_STATUS_IGNORE);
  if (nb < 0) throw std::runtime_error("DistDem::load_from_root: rank 0 could not cut its World (see rank 0's error).");
  std::string bytes(static_cast<std::size_t>(nb), '\0');
  for (long long at = 0; at < nb; at += chunk_)
    MPI_Recv(bytes.data() + at, static_cast<int>(std::min(chunk_, nb - at)), MPI_CHAR, 0, kTagPart, comm_,
             MPI_STATUS_IGNORE);
  // The part as rank 0 cut it, with the rows of other ranks' balls marked as ghosts.
  // (this rank's thread count, from the parameters it constructed the DistDem with: its host's
  // cores may differ from rank 0's; the bits do not depend on it)
  const int threads = p_.threads;
  auto part = std::make_unique<World>(p_);
  load_state_bytes(*part, std::move(bytes), 0, "rank 0's part for rank " + std::to_string(rank_));
  platens = loadable(*part);
  part->mutable_params().threads = threads;
  p_ = part->params();  // (its skin and thread_independent are rank 0's)
  const World::Counters kc = part->counters();
  Particles pt;
  PairContacts pc;
  std::array<WallContacts, 3> wc;
  std::vector<std::uint8_t> ghost;
  part->swap_balls(pt, pc, wc, ghost);
  ghost.resize(pt.size());
  for (std::size_t i = 0; i < pt.size(); ++i) ghost[i] = grid_.owner(pt.x[i]) != rank_;
  part->swap_balls(pt, pc, wc, ghost);
  part->set_counters(kc);
  part->set_wall_sums_by_caller(size_ > 1);
  part->set_pair_kernel(static_cast<PairKernel>(static_cast<int>(hk[1])));
  take(std::move(part), !platens.empty());
}

// replicate's block without the block (docs/scaling.md, "the specimen procedures and the coupled
// set-up on the ranks"): this rank builds the copies of the REV's balls that its part of the
// block holds and the copied pairs with one of its balls, in the block's orders (rows by copy
// then REV row: by id; pairs by copy then REV pair), into `rev` itself, then cuts its part from
// that as load(block) would: the copies it builds are a superset of the part's rows, and its
// pairs every pair the part computes.
// Only the copies near this brick are visited (their boxes, grown by the halo, meet the brick,
// and those a pair away), so the work is this brick's share of the block, not the block.
DistDem::Replicated DistDem::load_replicated(World& rev, const ReplicateParams& p) {
  // (its pairs are listed as newton off lists them: on both ranks of a pair across a cut)
  if (newton_) throw std::logic_error("DistDem::load_replicated: newton on is not supported; replicate, unload and load");
  const ReplicaLayout lay(rev, p);
  const std::vector<PlatenServoParams> platens = loadable(rev);
  const Particles& rp = rev.balls();
  const PairContacts& rc = rev.pair_contacts();
  const std::size_t n = rp.size();
  const int ncopy = lay.count();
  double rmax = 0.0;
  for (double r : rp.r) rmax = std::max(rmax, r);
  halo_ = 2.0 * rmax + rev.skin();  // (params_from's rule; set again below with the block's parameters)
  // The copies whose box (the REV's cell, a little grown: its balls are wrapped into it) grown by
  // the halo meets this brick (on a periodic axis of the grid: every copy), then those a pair's
  // shift away (their balls may be partners of this brick's).
  const Vec3 o = rev.cell_origin(), L = rev.cell_length();
  double a0[3], a1[3];
  grid_.box(rank_, a0, a1);
  int reach[3] = {0, 0, 0};  // the largest |shift| of a REV pair per axis
  for (const auto& sh : rc.shift)
    for (int k = 0; k < 3; ++k) reach[k] = std::max(reach[k], std::abs(static_cast<int>(sh[static_cast<std::size_t>(k)])));
  std::vector<int> local(static_cast<std::size_t>(ncopy), -1);  // copy -> its index among those visited
  std::vector<std::uint8_t> near_brick(static_cast<std::size_t>(ncopy), 0);
  int lo[3], hi[3];
  for (int k = 0; k < 3; ++k) {
    lo[k] = 0, hi[k] = lay.copies(k) - 1;
    if (grid_.periodic[k]) continue;
    const double tol = 1e-9 * L[k], lk = L[k];
    const double b0 = a0[k] <= 0.0 ? -std::numeric_limits<double>::infinity() : a0[k] - halo_;
    const double b1 = a1[k] >= grid_.len[k] ? std::numeric_limits<double>::infinity() : a1[k] + halo_;
    // copy i spans [o + i L, o + (i + 1) L] from the grid's lo, grown by tol
    const double base = o[k] - grid_.lo[k];
    int first = hi[k] + 1, last = -1;
    for (int i = 0; i <= hi[k]; ++i)
      if (base + i * lk - tol <= b1 && base + (i + 1) * lk + tol >= b0) first = std::min(first, i), last = i;
    lo[k] = first, hi[k] = last;
  }
  std::vector<int> visit;  // ascending
  for (int c = 0; c < ncopy; ++c) {
    int ci[3];
    lay.coords(c, ci);
    bool in = true, near = true;
    for (int k = 0; k < 3; ++k) {
      in = in && ci[k] >= lo[k] - reach[k] && ci[k] <= hi[k] + reach[k];
      near = near && ci[k] >= lo[k] && ci[k] <= hi[k];
    }
    if (!in) continue;
    local[static_cast<std::size_t>(c)] = static_cast<int>(visit.size());
    near_brick[static_cast<std::size_t>(c)] = near;
    visit.push_back(c);
  }
  // Per visited copy and REV row: 0 not in this rank's share, 1 in it, 2 owned by this rank.
  std::vector<std::uint8_t> state(visit.size() * n, 0);
  auto at = [&](int c, std::size_t b) -> std::uint8_t& {
    return state[static_cast<std::size_t>(local[static_cast<std::size_t>(c)]) * n + b];
  };
  std::vector<int> nb;
  for (int c : visit) {
    if (!near_brick[static_cast<std::size_t>(c)]) continue;
    const Vec3 off = lay.offset(c);
    for (std::size_t b = 0; b < n; ++b) {
      const Vec3 x = rp.x[b] + off;
      if (grid_.owner(x) == rank_) {
        at(c, b) = 2;
        continue;
      }
      grid_.near(x, halo_, nb);
      if (std::find(nb.begin(), nb.end(), rank_) != nb.end()) at(c, b) = 1;
    }
  }
  // The pairs with one of this rank's balls, and their partners.
  auto owned = [&](int c, std::size_t b) {
    return local[static_cast<std::size_t>(c)] >= 0 && near_brick[static_cast<std::size_t>(c)] && at(c, b) == 2;
  };
  struct Copied {
    int c, c2;
    std::uint32_t q;
    std::array<std::int8_t, 4> s;
  };
  std::vector<Copied> pairs;
  std::int64_t kept = 0;
  for (std::size_t q = 0; q < rc.size(); ++q) kept += lay.kept(rc.shift[q]);
  for (int c : visit)
    for (std::size_t q = 0; q < rc.size(); ++q) {
      std::array<std::int8_t, 4> s{};
      const int c2 = lay.partner(c, rc.shift[q], s);
      if (c2 < 0) continue;
      const bool oa = owned(c, rc.a[q]), ob = owned(c2, rc.b[q]);
      if (!oa && !ob) continue;
      // (a partner of an owned ball lies in a visited copy: its copy is a shift away)
      if (oa && at(c2, rc.b[q]) == 0) at(c2, rc.b[q]) = 1;
      if (ob && at(c, rc.a[q]) == 0) at(c, rc.a[q]) = 1;
      pairs.push_back({c, c2, static_cast<std::uint32_t>(q), s});
    }
  // This rank's share of the block, as a World: the REV's walls, effects and counters (its next
  // id past every copy's), the block's parameters and cell; not prepared (take prepares it).
  Particles q;
  std::vector<std::int64_t> row(state.size(), -1);
  const std::uint64_t next = rev.counters().next_id;
  for (int c : visit) {
    const Vec3 off = lay.offset(c);
    for (std::size_t b = 0; b < n; ++b) {
      if (at(c, b) == 0) continue;
      row[static_cast<std::size_t>(local[static_cast<std::size_t>(c)]) * n + b] = static_cast<std::int64_t>(q.size());
      if (c == 0) {
        push_ball(q, ball_rec(rp, b));
        continue;
      }
      const std::uint64_t id = next + static_cast<std::uint64_t>(c - 1) * n + b;
      const std::size_t i = q.add(rp.x[b] + off, rp.r[b], replica_density(rp, b), id);
      q.v[i] = rp.v[b];
      q.w[i] = rp.w[b];
      q.fix[i] = rp.fix[b];
    }
  }
  auto row_of = [&](int c, std::size_t b) {
    return static_cast<std::uint32_t>(row[static_cast<std::size_t>(local[static_cast<std::size_t>(c)]) * n + b]);
  };
  PairContacts pc;
  const bool has_bond = !rc.bond.empty();
  for (const Copied& x : pairs) {
    pc.a.push_back(row_of(x.c, rc.a[x.q]));
    pc.b.push_back(row_of(x.c2, rc.b[x.q]));
    pc.shift.push_back(x.s);
    pc.h.push_back(rc.h[x.q]);
    if (has_bond) pc.bond.push_back(rc.bond[x.q]);
  }
  const std::int64_t listed = static_cast<std::int64_t>(ncopy) * static_cast<std::int64_t>(rc.size());
  World::Counters kc = rev.counters();
  kc.next_id = next + static_cast<std::uint64_t>(ncopy - 1) * n;
  kc.prepared = false;
  std::array<WallContacts, 3> wc;
  for (WallContacts& d : wc) d.cand_off.push_back(0);
  std::vector<std::uint8_t> ghost;
  World& share = rev;
  share.swap_balls(q, pc, wc, ghost);
  share.set_counters(kc);
  if (p.keep_periodic) {
    share.set_cell(o, lay.length());
  } else {
    share.mutable_params().periodic.enabled = false;
  }
  params_from(share, rmax);
  take(part_of(share, cut(share, false), rank_, platens), !platens.empty());
  return {kept, listed - kept};
}

// The rank's World from its part: the step's reduction over the ranks, the forward lists, the
// newton hooks, and the walls' sums of every rank.
void DistDem::take(std::unique_ptr<World> w, bool platens) {
  w_ = std::move(w);
  servo_ = nullptr;  // (a periodic servo is added after the load)
  ++layout_gen_;  // (ordered_sums' kept merge orders)
  walls_every_step_ = platens;
  const World::Counters k = w_->counters();
  // The automatic step: its ratios the smallest over the ranks (minima, so the same bits at any
  // count), the no-contact fallback only where no rank has a contact (World::contact_scan).
  w_->set_step_reduction([this](double q) {
    MPI_Allreduce(MPI_IN_PLACE, &q, 1, MPI_DOUBLE, MPI_MIN, comm_);
    return q;
  });
  // A prepared World: its lists, histories and last forces are this rank's state as they are
  // (a checkpoint's load is the same), so the ranks continue with one World's bits; preparing
  // again would run another force pass, which is not the identity on every law's history.
  // Otherwise: prepared here, as `full.prepare()` would.
  run_disp2_ = 0.0;
  // The forward lists (with newton, reversed, they send the ghosts' forces and stiffness sums
  // back to their owners, from a prepare's force pass on), after the ghosts are put last.
  ghosts_last();
  build_forward();
  if (newton_)
    w_->set_newton([this](Vec3* f, Vec3* t) { reverse(&f->x, &t->x, 3); },
                   [this](double* kt, double* kr) { reverse(kt, kr, 1); });
  if (k.prepared) {
    run_disp2_ = k.max_disp2;
  } else {
    w_->prepare();
  }
  reduce_walls();
  exchanges_ = 0;
}

// With own_first(): the part's rows, in id order, become [owned | ghosts], each part in id
// order. The pairs' rows are renamed and each ball A's partners put in row order again (its
// owned partners first: partners_by_row); the wall contacts' rows are renamed (only owned balls
// have them, so their order stays). Histories and last forces move with their rows and
// contacts, and the World's counters stay as they were: a prepared part steps on as it was.
void DistDem::ghosts_last() {
  const Particles& pt = w_->balls();
  const std::size_t n = pt.size();
  split_ = n;
  if (!own_first()) return;
  const auto& gh = w_->ghost_rows();
  auto ghost_at = [&](std::size_t i) { return !gh.empty() && gh[i] != 0; };
  Buffers& bf = *buf_;
  std::vector<std::int64_t>& src = bf.src;
  src.resize(n);
  std::iota(src.begin(), src.end(), std::int64_t{0});
  std::vector<std::uint8_t> ghost(n, 0);
  if (!gh.empty()) ghost = gh;
  const std::size_t split = put_ghosts_last(src, ghost, bf.src2);
  std::vector<std::int64_t>& to = bf.new_row;
  to.assign(n, -1);
  for (std::size_t j = 0; j < n; ++j) to[static_cast<std::size_t>(src[j])] = static_cast<std::int64_t>(j);
  Particles q;
  fill_rows(q, pt, {}, src);
  const PairContacts& pc = w_->pair_contacts();
  PairContacts nc;
  std::vector<std::int64_t>& psrc = bf.psrc;
  psrc.resize(pc.size());
  std::iota(psrc.begin(), psrc.end(), std::int64_t{0});
  nc.a.resize(pc.size());
  nc.b.resize(pc.size());
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (ghost_at(pc.a[c]))
      throw std::logic_error("DistDem: rank " + std::to_string(rank_) + " lists a pair of ball " +
                             std::to_string(pt.id[pc.a[c]]) + ", a ghost, as its ball A with newton on.");
    nc.a[c] = static_cast<std::uint32_t>(to[pc.a[c]]);
    nc.b[c] = static_cast<std::uint32_t>(to[pc.b[c]]);
  }
  partners_by_row(nc.a, nc.b, psrc, split, bf.tb, bf.ts);
  const std::vector<PairRec> none;
  fill_column(nc.shift, pc.shift, none, psrc, &PairRec::s);
  fill_column(nc.h, pc.h, none, psrc, &PairRec::h);
  if (!pc.bond.empty()) fill_column(nc.bond, pc.bond, none, psrc, &PairRec::b);
  std::array<WallContacts, 3> wc;
  const auto wl = wall_lists(*w_);
  for (std::size_t k = 0; k < 3; ++k) {
    wc[k] = *wl[k];
    for (std::uint32_t& i : wc[k].ball) i = static_cast<std::uint32_t>(to[i]);
  }
  const World::Counters kc = w_->counters();
  w_->swap_balls(q, nc, wc, ghost);
  w_->set_counters(kc);
  w_->set_moving_rows(split);
  split_ = split;
}

namespace {
void refuse_newton_time(bool newton, const DistDem::Balance& b) {
  if (newton && b.every > 0 && b.weight == DistDem::Weight::kTime)
    throw std::invalid_argument(
        "DistDem: newton on with cuts balanced by measured time: newton's results follow the cuts, and "
        "time-weighted cuts differ from run to run (balance by contacts instead).");
}
}  // namespace

void DistDem::set_newton(bool on) {
  if (w_) throw std::logic_error("DistDem::set_newton: call it before load.");
  refuse_newton_time(on, bal_);
  newton_ = on;
}

void DistDem::set_balance(const Balance& b) {
  refuse_newton_time(newton_, b);
  bal_ = b;
}

// Point to point with the ranks that share ghosts (the counts are known from the forward lists,
// so no count exchange): to each rank r, `per_row` doubles of every row of out_rows[r] (pack(i,
// dst)); from each rank r, those of every row of in_rows[r], applied (unpack(i, src)) in ascending
// r and row order. No message to the other ranks, whatever their number.
template <class Pack, class Unpack>
void DistDem::rows_message(const std::vector<std::vector<std::uint32_t>>& out_rows,
                           const std::vector<std::vector<std::uint32_t>>& in_rows, std::size_t per_row, int tag,
                           Pack pack, Unpack unpack) {
  const std::size_t P = static_cast<std::size_t>(size_);
  std::vector<std::size_t> at(P + 1, 0);
  for (std::size_t r = 0; r < P; ++r) at[r + 1] = at[r] + per_row * in_rows[r].size();
  msg_in_.resize(at.back());
  msg_out_.resize(P);
  std::vector<MPI_Request>& req = msg_req_;
  req.clear();
  for (std::size_t r = 0; r < P; ++r) {
    if (in_rows[r].empty()) continue;
    req.emplace_back();
    MPI_Irecv(msg_in_.data() + at[r], static_cast<int>(at[r + 1] - at[r]), MPI_DOUBLE, static_cast<int>(r), tag, comm_,
              &req.back());
  }
  for (std::size_t r = 0; r < P; ++r) {
    if (out_rows[r].empty()) continue;
    std::vector<double>& o = msg_out_[r];
    o.resize(per_row * out_rows[r].size());
    double* d = o.data();
    for (std::uint32_t i : out_rows[r]) d = pack(i, d);
    req.emplace_back();
    MPI_Isend(o.data(), static_cast<int>(o.size()), MPI_DOUBLE, static_cast<int>(r), tag, comm_, &req.back());
  }
  MPI_Waitall(static_cast<int>(req.size()), req.data(), MPI_STATUSES_IGNORE);
  for (std::size_t r = 0; r < P; ++r) {
    const double* q = msg_in_.data() + at[r];
    for (std::uint32_t i : in_rows[r]) q = unpack(i, q);
  }
}

// The forward exchange reversed: each ghost row's values to the rank that forwards it (its
// owner), which adds them to its own row in ascending source rank, each rank's rows in id
// order (a fixed order: the same bits for the same cuts).
void DistDem::reverse(double* a, double* b, int w) {
  const double t0 = MPI_Wtime();
  const std::size_t W = static_cast<std::size_t>(w);
  rows_message(
      recv_rows_, send_rows_, 2 * W, 7302,
      [&](std::uint32_t i, double* d) {
        d = std::copy(a + i * W, a + (i + 1) * W, d);
        return std::copy(b + i * W, b + (i + 1) * W, d);
      },
      [&](std::uint32_t i, const double* q) {
        for (std::size_t k = 0; k < W; ++k) a[i * W + k] += *q++;
        for (std::size_t k = 0; k < W; ++k) b[i * W + k] += *q++;
        return q;
      });
  times_.reverse += MPI_Wtime() - t0;
}

// Every rank's wall-contact shares go to rank 0, which merges them in (kind, ball id, wall)
// order, one World's contact order (each rank's shares are already in that order), sums them as
// one World does, and sends every rank the sums. A share carries only what its kind sums.
void DistDem::reduce_walls() {
  // one rank: its own sums are already those (the same contacts in the same order)
  if (size_ == 1 || (w_->num_planes() == 0 && w_->num_facet_walls() == 0 && !w_->has_footing())) return;
  if (p_.order_free_sums) {  // every rank folds its own shares: two allreduces, no gather
    std::vector<World::WallTerm>& terms = buf_->of_terms;
    terms.clear();
    w_->wall_sum_terms(terms);
    const std::size_t S = w_->wall_sum_slots();
    std::vector<double>& bound = buf_->of_bound;
    slot_bounds(terms, S, bound);
    MPI_Allreduce(MPI_IN_PLACE, bound.data(), static_cast<int>(S), MPI_DOUBLE, MPI_MAX, comm_);
    std::vector<OrderFreeSum>& sums = buf_->of_sums;
    slot_folds(terms, bound, sums);
    sum_folds(sums.data(), S, nullptr);
    std::vector<double>& v = buf_->packed;
    v.resize(S);
    for (std::size_t k = 0; k < S; ++k) v[k] = sums[k].result();
    w_->unpack_wall_sums(v);
    return;
  }
  std::vector<WallSumRec>& mine = buf_->sums;
  mine.clear();
  w_->wall_sum_records(mine);  // the planes and the footing; the facets' shares below
  // compact shares by kind
  auto& ps = buf_->plane_shares;
  auto& fs = buf_->facet_shares;
  auto& gs = buf_->footing_shares;
  ps.clear(), fs.clear(), gs.clear();
  for (const WallSumRec& r : mine) {
    if (r.kind == 0) ps.push_back({r.ball, r.wall, r.active, r.F, r.k});
    else gs.push_back({r.ball, r.F});
  }
  w_->facet_sum_shares(fs);
  // one message per rank: three counts, then the shares of each kind
  std::vector<char>& out = sbuf_;
  out.clear();
  auto put = [&](const void* p, std::size_t n) {
    out.insert(out.end(), static_cast<const char*>(p), static_cast<const char*>(p) + n);
  };
  const std::uint64_t cnt[3] = {ps.size(), fs.size(), gs.size()};
  put(cnt, sizeof cnt);
  put(ps.data(), ps.size() * sizeof(PlaneShare));
  put(fs.data(), fs.size() * sizeof(FacetSumShare));
  put(gs.data(), gs.size() * sizeof(FootingShare));
  const int bytes = static_cast<int>(out.size());
  std::vector<int> counts(static_cast<std::size_t>(size_)), displ(static_cast<std::size_t>(size_) + 1, 0);
  MPI_Gather(&bytes, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm_);
  for (int r = 0; r < size_; ++r)
    displ[static_cast<std::size_t>(r) + 1] = displ[static_cast<std::size_t>(r)] + counts[static_cast<std::size_t>(r)];
  if (rank_ == 0) rbuf_.resize(static_cast<std::size_t>(displ.back()));
  MPI_Gatherv(out.data(), bytes, MPI_BYTE, rbuf_.data(), counts.data(), displ.data(), MPI_BYTE, 0, comm_);
  std::vector<WallSumRec>& all = buf_->all_sums;
  std::vector<FacetSumShare>& fall = buf_->all_facet_shares;
  if (rank_ == 0) {
    // per kind, the ranks' runs one after the other, then put in one World's order
    // (order_wall_shares); the facets' shares apart
    all.clear();
    fall.clear();
    std::vector<std::size_t>& starts = buf_->run_starts;
    for (int kind = 0; kind < 3; ++kind) {
      starts.clear();
      for (int r = 0; r < size_; ++r) {
        starts.push_back(kind == 1 ? fall.size() : all.size());
        const char* q = rbuf_.data() + displ[static_cast<std::size_t>(r)];
        std::uint64_t c[3];
        std::memcpy(c, q, sizeof c);
        q += sizeof c;
        if (kind > 0) q += c[0] * sizeof(PlaneShare);
        if (kind > 1) q += c[1] * sizeof(FacetSumShare);
        if (kind == 1) {
          const std::size_t at = fall.size();
          fall.resize(at + c[1]);
          if (c[1] > 0) std::memcpy(&fall[at], q, c[1] * sizeof(FacetSumShare));
          continue;
        }
        for (std::uint64_t j = 0; j < c[kind]; ++j) {
          WallSumRec rec;
          if (kind == 0) {
            PlaneShare x;
            std::memcpy(&x, q + j * sizeof x, sizeof x);
            rec.ball = x.ball, rec.wall = x.wall, rec.active = x.active, rec.F = x.F, rec.k = x.k;
          } else {
            FootingShare x;
            std::memcpy(&x, q + j * sizeof x, sizeof x);
            rec.ball = x.ball, rec.F = x.F;
          }
          rec.kind = static_cast<std::uint8_t>(kind);
          all.push_back(rec);
        }
      }
      if (kind == 1) {
        starts.push_back(fall.size());
        order_wall_shares(fall, starts);
      } else {
        starts.push_back(all.size());
        order_wall_shares(all, starts);
      }
    }
  }
  // the sums back: every rank has the same walls, so the same array length
  std::vector<double>& packed = buf_->packed;
  if (rank_ == 0) {
    w_->set_wall_sums(all);  // (the planes and the footing)
    if (w_->num_facet_walls() > 0) w_->set_facet_sums(fall);
  }
  w_->pack_wall_sums(packed);
  MPI_Bcast(packed.data(), static_cast<int>(packed.size()), MPI_DOUBLE, 0, comm_);
  if (rank_ != 0) w_->unpack_wall_sums(packed);
}

double DistDem::owned_max_disp2() const {
  const Particles& pt = w_->balls();
  const auto& g = w_->ghost_rows();
  double d = 0.0;
  const std::size_t end = own_first() ? split_ : pt.size();  // (the ghosts in rows of their own: after)
  for (std::size_t i = 0; i < end; ++i)
    if (g.empty() || !g[i]) d = std::max(d, norm2(pt.x[i] - pt.x_ref[i]));
  return d;
}

void DistDem::step(std::int64_t n) {
  for (std::int64_t k = 0; k < n; ++k) {
    double t0 = MPI_Wtime();
    w_->step_motion();
    double t1 = MPI_Wtime();
    times_.motion += t1 - t0;
    forward();
    t0 = MPI_Wtime();
    times_.forward += t0 - t1;
    run_disp2_ = std::max(run_disp2_, owned_max_disp2());
    double g = 0.0;
    MPI_Allreduce(&run_disp2_, &g, 1, MPI_DOUBLE, MPI_MAX, comm_);
    const bool rebuild = w_->need_rebuild(g);
    t1 = MPI_Wtime();
    times_.reduce += t1 - t0;
    if (rebuild) {
      if (w_->periodic()) grid_.follow_cell(w_->cell_origin(), w_->cell_length());
      if (bal_.every > 0 && (exchanges_ + 1) % bal_.every == 0) rebalance();
      exchange();
      run_disp2_ = 0.0;
    }
    t0 = MPI_Wtime();
    times_.exchange += t0 - t1;
    const double rev0 = times_.reverse;
    w_->step_forces(rebuild);
    t1 = MPI_Wtime();
    times_.forces += (t1 - t0) - (times_.reverse - rev0);  // (`newton`: its reverse is communication)
    if (walls_every_step_) {  // a platen servo reads them at the next step's kinematics
      reduce_walls();
      times_.walls += MPI_Wtime() - t1;
    }
  }
  if (walls_every_step_) return;
  // The walls' sums of the last step only: within the call nothing else reads them (gravity
  // does not).
  const double t0 = MPI_Wtime();
  reduce_walls();
  times_.walls += MPI_Wtime() - t0;
}

// The ghosts' x, v and ω from their owners (rows_message).
void DistDem::forward() {
  Particles& q = w_->balls();
  rows_message(
      send_rows_, recv_rows_, 9, 7301,
      [&](std::uint32_t i, double* d) {
        for (const Vec3* v : {&q.x[i], &q.v[i], &q.w[i]}) *d++ = v->x, *d++ = v->y, *d++ = v->z;
        return d;
      },
      [&](std::uint32_t i, const double* p) {
        for (Vec3* v : {&q.x[i], &q.v[i], &q.w[i]}) v->x = *p++, v->y = *p++, v->z = *p++;
        return p;
      });
  for (const auto& rows : recv_rows_) times_.forwarded += static_cast<std::int64_t>(rows.size());
}

// Migration and ghosts, incremental (as LAMMPS's exchange + borders, in id order). The rows a
// rank holds after the exchange are fixed by the owners: each owner sends each of its balls to
// the rank of its brick, to the ranks within the halo and to the owners of its contacts'
// partners (so that a bonded pair stretched beyond the halo stays complete). A rank that holds
// the ball already (its old owner, or a rank it was a ghost on: the forward lists say which)
// gets only the ball's id, and keeps its row (a ghost's x, v, ω are this step's, forwarded; its
// other fields do not change); any other rank gets the whole row. A rank drops every row no
// owner named. A contact goes to a new owner of either ball that did not own either before, a
// wall contact to its ball's new owner. The kept rows and the new ones are merged in id order,
// the kept and new contacts in (ball id, partner id) order: the rows and lists of a full
// re-distribution, so the same bits.
// The bricks whose extent, grown by the halo and the skin, meets this rank's brick (periodic
// axes: also across the cell's faces); ascending, without this rank. The relation is symmetric,
// so two ranks agree on whether they exchange.
const std::vector<int>& DistDem::peer_ranks() {
  const double reach = reach_ >= 0.0 ? reach_ : halo_ + p_.skin;
  double a0[3], a1[3], b0[3], b1[3];
  grid_.box(rank_, a0, a1);
  peers_.clear();
  for (int r = 0; r < grid_.count(); ++r) {
    if (r == rank_) continue;
    grid_.box(r, b0, b1);
    bool meet = true;
    for (int k = 0; k < 3 && meet; ++k) {
      const double c0 = b0[k] - reach, c1 = b1[k] + reach, len = grid_.len[k];
      bool m = c0 < a1[k] && a0[k] < c1;
      if (grid_.periodic[k]) m = m || (c0 - len < a1[k] && a0[k] < c1 - len) || (c0 + len < a1[k] && a0[k] < c1 + len);
      meet = m;
    }
    if (meet) peers_.push_back(r);
  }
  return peers_;
}

namespace {

// One message to and from each peer (possibly empty): the ids, rows, pairs and wall contacts for
// it; what arrives is appended in ascending source rank, as the all-to-all gives it.
void neighbour_exchange(MPI_Comm comm, const std::vector<int>& peers, const std::vector<std::vector<std::uint64_t>>& kout,
                        const std::vector<std::vector<BallRec>>& bout, const std::vector<std::vector<PairRec>>& pout,
                        const std::vector<std::vector<WallRec>>& wout, std::vector<std::uint64_t>& kin,
                        std::vector<BallRec>& bin, std::vector<PairRec>& pin, std::vector<WallRec>& win,
                        std::vector<std::vector<char>>& out, std::vector<char>& in) {
  constexpr int kTag = 7302;
  out.resize(peers.size());
  std::vector<MPI_Request> req(peers.size());
  for (std::size_t j = 0; j < peers.size(); ++j) {
    const auto r = static_cast<std::size_t>(peers[j]);
    out[j].clear();
    put_recs(out[j], kout[r]);
    put_recs(out[j], bout[r]);
    put_recs(out[j], pout[r]);
    put_recs(out[j], wout[r]);
    MPI_Isend(out[j].data(), static_cast<int>(out[j].size()), MPI_BYTE, peers[j], kTag, comm, &req[j]);
  }
  kin.clear(), bin.clear(), pin.clear(), win.clear();
  for (int src : peers) {
    MPI_Status st;
    MPI_Probe(src, kTag, comm, &st);
    int bytes = 0;
    MPI_Get_count(&st, MPI_BYTE, &bytes);
    if (in.size() < static_cast<std::size_t>(bytes)) in.resize(static_cast<std::size_t>(bytes));
    MPI_Recv(in.data(), bytes, MPI_BYTE, src, kTag, comm, MPI_STATUS_IGNORE);
    const char* q = in.data();
    q = get_recs(q, kin);
    q = get_recs(q, bin);
    q = get_recs(q, pin);
    get_recs(q, win);
  }
  MPI_Waitall(static_cast<int>(req.size()), req.data(), MPI_STATUSES_IGNORE);
}
}  // namespace

void DistDem::exchange() {
  if (size_ == 1) {  // no ghosts and no other rank: the rows stay, the World's rebuild does the rest
    ++exchanges_;
    ++layout_gen_;
    return;
  }
  const Particles& pt = w_->balls();
  const std::size_t n = pt.size();
  const auto& gh = w_->ghost_rows();
  auto mine = [&](std::size_t i) { return gh.empty() || !gh[i]; };
  const std::size_t P = static_cast<std::size_t>(size_);
  Buffers& bf = *buf_;
  std::vector<int>& own = bf.own;
  std::vector<int> nb;
  own.resize(n);
  for (std::size_t i = 0; i < n; ++i) own[i] = grid_.owner(pt.x[i]);
  // the old owner of every row (this rank, or the rank that forwards the ghost's state) and the
  // ranks that hold each own row as a ghost
  std::vector<int>& old_owner = bf.old_owner;
  old_owner.assign(n, rank_);
  std::vector<std::uint32_t>& hold_off = bf.hold_off;
  hold_off.assign(n + 1, 0);
  for (std::size_t r = 0; r < P; ++r) {
    for (std::uint32_t i : recv_rows_[r]) old_owner[i] = static_cast<int>(r);
    for (std::uint32_t i : send_rows_[r]) ++hold_off[i + 1];
  }
  for (std::size_t i = 0; i < n; ++i) hold_off[i + 1] += hold_off[i];
  std::vector<int>& holders = bf.holders;
  holders.resize(hold_off[n]);
  {
    std::vector<std::uint32_t>& f = bf.fill;
    f.assign(hold_off.begin(), hold_off.end() - 1);
    for (std::size_t r = 0; r < P; ++r)
      for (std::uint32_t i : send_rows_[r]) holders[f[i]++] = static_cast<int>(r);
  }
  // Destinations of each own row (counting sort by row): its owner, the ranks within the halo,
  // the owners of its contacts' partners.
  const PairContacts& pc = w_->pair_contacts();
  // from the law, not from this rank's list: a rank without pairs still receives bonded ones
  // (with `!pc.bond.empty()` it dropped their bond histories, and its next rebuild read past
  // the empty array: tests/dist, Dist.StretchedBonds* at 3 ranks)
  const bool has_bond = law_has_bond(p_.ball_ball.model);
  std::vector<std::uint32_t>& off = bf.off;
  std::vector<std::uint32_t>& near_off = bf.near_off;
  off.assign(n + 1, 0);
  near_off.assign(n + 1, 0);
  std::vector<int>& near_all = bf.near_all;
  near_all.clear();
  for (std::size_t i = 0; i < n; ++i) {
    if (mine(i)) {
      grid_.near(pt.x[i], halo_, nb);
      near_all.insert(near_all.end(), nb.begin(), nb.end());
      off[i + 1] += static_cast<std::uint32_t>(1 + nb.size());
    }
    near_off[i + 1] = static_cast<std::uint32_t>(near_all.size());
  }
  // `newton`: a pair lives on the owner of its ball A, which must hold B. B's owner sends B to
  // the bricks within the halo of B; where A's new owner is not one of them (a bond stretched
  // beyond the halo), this rank asks B's owner for it (a need record: B's id, the rank), in a
  // round of its own, made only when some rank has one.
  std::vector<std::uint64_t> needs;  // (id, rank) pairs received: rank needs my ball id
  if (newton_) {
    std::vector<std::vector<std::uint64_t>> ask(P);
    bool any = false;
    for (std::size_t c = 0; c < pc.size(); ++c) {
      const std::uint32_t a = pc.a[c], b = pc.b[c];
      if (mine(b)) continue;  // the partner rule below
      const int ra = own[a];
      if (ra == own[b]) continue;
      grid_.near(pt.x[b], halo_, nb);
      if (std::binary_search(nb.begin(), nb.end(), ra)) continue;
      ask[static_cast<std::size_t>(old_owner[b])].insert(ask[static_cast<std::size_t>(old_owner[b])].end(),
                                                         {pt.id[b], static_cast<std::uint64_t>(ra)});
      any = true;
    }
    int mine_any = any, all_any = 0;
    MPI_Allreduce(&mine_any, &all_any, 1, MPI_INT, MPI_MAX, comm_);
    if (all_any) all_to_all(comm_, ask, needs, sbuf_, rbuf_);
  }
  std::vector<std::pair<std::uint32_t, int>> need_rows;  // (own row, rank that needs it)
  for (std::size_t k = 0; k + 1 < needs.size(); k += 2) {
    const std::int64_t r = find_row(pt.id, split_, needs[k]);
    const std::size_t i = static_cast<std::size_t>(r);
    if (r < 0 || !mine(i))
      throw std::logic_error("DistDem::exchange: rank " + std::to_string(rank_) + " was asked for ball " +
                             std::to_string(needs[k]) + ", which it does not own.");
    need_rows.emplace_back(static_cast<std::uint32_t>(i), static_cast<int>(needs[k + 1]));
    ++off[i + 1];
  }
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (!newton_ && mine(pc.a[c])) ++off[pc.a[c] + 1];
    if (mine(pc.b[c])) ++off[pc.b[c] + 1];
  }
  for (std::size_t i = 0; i < n; ++i) off[i + 1] += off[i];
  std::vector<int>& dest = bf.dest;
  dest.resize(off[n]);
  std::vector<std::uint32_t>& fill = bf.fill;
  fill.assign(off.begin(), off.end() - 1);
  for (std::size_t i = 0; i < n; ++i) {
    if (!mine(i)) continue;
    if (own[i] != rank_) ++migrated_;
    dest[fill[i]++] = own[i];
    for (std::uint32_t k = near_off[i]; k < near_off[i + 1]; ++k) dest[fill[i]++] = near_all[k];
  }
  for (const auto& [i, r] : need_rows) dest[fill[i]++] = r;
  // contacts: the partner rule, and the records for a new owner that did not own either ball
  std::vector<std::vector<PairRec>>& pout = buf_->pout;
  pout.resize(P);
  for (auto& o : pout) o.clear();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const std::uint32_t a = pc.a[c], b = pc.b[c];
    if (!newton_ && mine(a)) dest[fill[a]++] = own[b];
    if (mine(b)) dest[fill[b]++] = own[a];
    auto put = [&](int d) {
      pout[static_cast<std::size_t>(d)].push_back(
          PairRec{pt.id[a], pt.id[b], pc.shift[c], pc.h[c], has_bond ? pc.bond[c] : BondHist{}});
    };
    if (newton_) {  // the pair goes with its ball A (always this rank's: the list's rule)
      if (own[a] != rank_) put(own[a]);
      continue;
    }
    if (!(mine(a) || mine(b))) continue;
    const int oa = old_owner[a], ob = old_owner[b];
    auto send = [&](int d) {
      if (d == rank_ || d == oa || d == ob) return;  // an old owner of a or b: it has the pair
      put(d);
    };
    send(own[a]);
    if (own[b] != own[a]) send(own[b]);
  }
  // balls: an id to a rank that holds the row, the whole row to any other
  std::vector<std::vector<BallRec>>& bout = buf_->bout;
  bout.resize(P);
  for (auto& o : bout) o.clear();
  std::vector<std::vector<std::uint64_t>>& kout = buf_->kout;
  kout.resize(P);
  for (auto& o : kout) o.clear();
  std::vector<std::uint8_t>& keep = bf.keep;
  keep.assign(n, 0);
  for (std::size_t i = 0; i < n; ++i) {
    if (!mine(i)) continue;
    int* d0 = dest.data() + off[i];
    int* d1 = dest.data() + off[i + 1];
    if (std::all_of(d0, d1, [&](int d) { return d == rank_; })) {  // stays here, goes nowhere else
      keep[i] = 1;
      continue;
    }
    std::sort(d0, d1);
    for (int* d = d0; d < d1; ++d) {
      if (d != d0 && *d == d[-1]) continue;
      if (*d == rank_) {
        keep[i] = 1;
      } else if (std::find(holders.begin() + hold_off[i], holders.begin() + hold_off[i + 1], *d) !=
                 holders.begin() + hold_off[i + 1]) {
        kout[static_cast<std::size_t>(*d)].push_back(pt.id[i]);
      } else {
        bout[static_cast<std::size_t>(*d)].push_back(ball_rec(pt, i));
      }
    }
  }
  // wall contacts to their ball's new owner; the others stay
  std::vector<std::vector<WallRec>>& wout = buf_->wout;
  wout.resize(P);
  for (auto& o : wout) o.clear();
  const auto wl = wall_lists(*w_);
  for (int k = 0; k < 3; ++k) {
    const WallContacts& wc = *wl[static_cast<std::size_t>(k)];
    for (std::size_t c = 0; c < wc.size(); ++c) {
      const std::uint32_t i = wc.ball[c];
      if (own[i] == rank_) continue;
      wout[static_cast<std::size_t>(own[i])].push_back(WallRec{pt.id[i], wc.wall[c], wc.facet[c],
                                                               static_cast<std::uint8_t>(k), wc.h[c],
                                                               wc.bond.empty() ? BondHist{} : wc.bond[c]});
    }
  }
  std::vector<BallRec>& bin = buf_->bin;
  std::vector<PairRec>& pin = buf_->pin;
  std::vector<WallRec>& win = buf_->win;
  std::vector<std::uint64_t>& kin = buf_->kin;
  // Neighbour bricks only when every record goes to one (the usual case: a ball moves less than
  // the skin between exchanges); else, after cuts moved far or for a bond stretched across a
  // brick, every rank with every rank. One flag decides it for all ranks. Either way the records
  // arrive in source-rank order, so the merge below sees the same input.
  const std::vector<int>& peers = peer_ranks();
  int far = 0;
  for (std::size_t r = 0; r < P && !far; ++r) {
    if (static_cast<int>(r) == rank_ || std::binary_search(peers.begin(), peers.end(), static_cast<int>(r))) continue;
    far = !kout[r].empty() || !bout[r].empty() || !pout[r].empty() || !wout[r].empty();
  }
  int any_far = 0;
  MPI_Allreduce(&far, &any_far, 1, MPI_INT, MPI_MAX, comm_);
  if (any_far) {
    all_to_all(comm_, kout, kin, sbuf_, rbuf_);
    all_to_all(comm_, bout, bin, sbuf_, rbuf_);
    all_to_all(comm_, pout, pin, sbuf_, rbuf_);
    all_to_all(comm_, wout, win, sbuf_, rbuf_);
  } else {
    neighbour_exchange(comm_, peers, kout, bout, pout, wout, kin, bin, pin, win, nbr_out_, rbuf_);
    ++sparse_exchanges_;
  }
  // the rows kept: own rows that stay, and the rows some owner named
  for (std::uint64_t id : kin) {
    const std::int64_t r = find_row(pt.id, split_, id);
    if (r < 0)
      throw std::logic_error("DistDem::exchange: rank " + std::to_string(rank_) + " was asked to keep ball " +
                             std::to_string(id) + ", which it does not hold.");
    keep[static_cast<std::size_t>(r)] = 1;
  }
  // the new rows: one copy per id (every sender sends the same bits)
  std::vector<std::uint32_t>& bo = buf_->order;
  bo.resize(bin.size());
  std::iota(bo.begin(), bo.end(), 0u);
  std::sort(bo.begin(), bo.end(), [&](std::uint32_t x, std::uint32_t y) { return bin[x].id < bin[y].id; });
  // merge the kept rows and the new ones in id order; new_row[old row] for the kept. First the
  // order (src[j]: the old row of row j, or ~k for the new record bin[k]), then each array
  // filled in one pass. With the ghosts in rows of their own the old rows are read in id order
  // (ido: the owned and the ghost rows merged), and the new rows become [owned | ghosts].
  const bool two = split_ < n;
  std::vector<std::uint32_t>& ido = bf.ido;
  if (two) {
    ido.resize(n);
    std::size_t x = 0, y = split_, at = 0;
    while (x < split_ || y < n)
      ido[at++] = static_cast<std::uint32_t>((y >= n || (x < split_ && pt.id[x] < pt.id[y])) ? x++ : y++);
  }
  auto old_at = [&](std::size_t j) -> std::size_t { return two ? ido[j] : j; };
  Particles& q = q_;
  std::vector<std::uint8_t>& ghost = ghost_buf_;
  ghost.clear();
  std::vector<std::int64_t>& new_row = bf.new_row;
  new_row.assign(n, -1);
  std::vector<std::int64_t>& src = bf.src;
  src.clear();
  std::size_t j = 0, k = 0;
  std::uint64_t last = 0;
  bool any = false;
  while (j < n || k < bo.size()) {
    while (j < n && !keep[old_at(j)]) ++j;
    if (j >= n && k >= bo.size()) break;
    const std::size_t i = j < n ? old_at(j) : 0;
    if (k >= bo.size() || (j < n && pt.id[i] < bin[bo[k]].id)) {
      new_row[i] = static_cast<std::int64_t>(src.size());
      src.push_back(static_cast<std::int64_t>(i));
      ghost.push_back(own[i] != rank_);
      last = pt.id[i], any = true;
      ++j;
    } else {
      if (j < n && pt.id[i] == bin[bo[k]].id)
        throw std::logic_error("DistDem::exchange: rank " + std::to_string(rank_) + " got ball " +
                               std::to_string(pt.id[i]) + " whole, but holds it.");
      const BallRec& b = bin[bo[k]];
      if (!(any && b.id == last)) {  // one copy per id
        src.push_back(~static_cast<std::int64_t>(bo[k]));
        ghost.push_back(grid_.owner(b.x) != rank_);
        last = b.id, any = true;
      }
      ++k;
    }
  }
  std::size_t split = src.size();
  if (own_first()) {  // the owned rows first, then the ghosts, each in id order
    split = put_ghosts_last(src, ghost, bf.src2);
    for (std::size_t r = 0; r < src.size(); ++r)
      if (src[r] >= 0) new_row[static_cast<std::size_t>(src[r])] = static_cast<std::int64_t>(r);
  }
  fill_rows(q, pt, bin, src);
  auto row_of = [&](std::uint64_t id) { return find_row(q.id, split, id); };
  // contacts: the kept ones (an own ball after the exchange, both balls kept), in (a, b) order,
  // merged with the received ones (one copy per pair)
  std::vector<std::uint32_t>& po = buf_->order2;
  po.resize(pin.size());
  std::iota(po.begin(), po.end(), 0u);
  std::sort(po.begin(), po.end(), [&](std::uint32_t x, std::uint32_t y) {
    return pin[x].ia != pin[y].ia ? pin[x].ia < pin[y].ia : pin[x].ib < pin[y].ib;
  });
  // First the list (rows a, b and psrc: the old contact, or ~k for the record pin[k]), then the
  // shifts and histories copied in one pass per array. With the ghosts in rows of their own the
  // kept contacts are read in (A id, B id) order (cord: each A's owned and ghost partners
  // merged), and each A's new partners put in row order after the merge (partners_by_row).
  std::vector<std::uint32_t>& cord = bf.cord;
  if (two) {
    cord.resize(pc.size());
    std::size_t at = 0;
    for (std::size_t c0 = 0; c0 < pc.size();) {
      std::size_t c1 = c0 + 1;
      while (c1 < pc.size() && pc.a[c1] == pc.a[c0]) ++c1;
      std::size_t y = c0;
      while (y < c1 && pc.b[y] < split_) ++y;
      std::size_t x = c0;
      const std::size_t s = y;
      while (x < s || y < c1)
        cord[at++] = static_cast<std::uint32_t>((y >= c1 || (x < s && pt.id[pc.b[x]] < pt.id[pc.b[y]])) ? x++ : y++);
      c0 = c1;
    }
  }
  auto old_c = [&](std::size_t c) -> std::size_t { return two ? cord[c] : c; };
  PairContacts& nc = nc_;
  nc.a.clear(), nc.b.clear();
  std::vector<std::int64_t>& psrc = bf.psrc;
  psrc.clear();
  auto push_pair = [&](std::int64_t a, std::int64_t b, std::int64_t from) {
    if (ghost[static_cast<std::size_t>(a)] && (newton_ || ghost[static_cast<std::size_t>(b)])) return;
    nc.a.push_back(static_cast<std::uint32_t>(a));
    nc.b.push_back(static_cast<std::uint32_t>(b));
    psrc.push_back(from);
  };
  std::size_t c = 0, kk = 0;
  const PairRec* prev = nullptr;
  while (c < pc.size() || kk < po.size()) {
    // the next kept contact
    while (c < pc.size() && (new_row[pc.a[old_c(c)]] < 0 || new_row[pc.b[old_c(c)]] < 0)) ++c;
    const bool have_c = c < pc.size();
    const bool have_r = kk < po.size();
    if (!have_c && !have_r) break;
    bool take_c = have_c;
    if (have_c && have_r) {
      const PairRec& r = pin[po[kk]];
      const std::size_t oc = old_c(c);
      const std::uint64_t ia = pt.id[pc.a[oc]], ib = pt.id[pc.b[oc]];
      if (r.ia == ia && r.ib == ib) {  // also received: the same pair, one copy
        ++kk;
        continue;
      }
      take_c = ia != r.ia ? ia < r.ia : ib < r.ib;
    }
    if (take_c) {
      const std::size_t oc = old_c(c);
      push_pair(new_row[pc.a[oc]], new_row[pc.b[oc]], static_cast<std::int64_t>(oc));
      ++c;
    } else {
      const std::uint32_t rk = po[kk++];
      const PairRec& r = pin[rk];
      if (prev && r.ia == prev->ia && r.ib == prev->ib) continue;
      prev = &r;
      const std::int64_t a = row_of(r.ia), b = row_of(r.ib);
      if (a < 0 || b < 0)
        throw std::logic_error("DistDem::exchange: rank " + std::to_string(rank_) + " got a contact of ball " +
                               std::to_string(a < 0 ? r.ia : r.ib) + " without the ball.");
      push_pair(a, b, ~static_cast<std::int64_t>(rk));
    }
  }
  if (own_first()) partners_by_row(nc.a, nc.b, psrc, split, bf.tb, bf.ts);
  fill_column(nc.shift, pc.shift, pin, psrc, &PairRec::s);
  fill_column(nc.h, pc.h, pin, psrc, &PairRec::h);
  if (has_bond) fill_column(nc.bond, pc.bond, pin, psrc, &PairRec::b);
  else nc.bond.clear();

  // wall contacts: the kept ones (own balls that stay) merged with the received, by kind in
  // (ball id, wall) order
  std::sort(win.begin(), win.end(), [](const WallRec& x, const WallRec& y) {
    if (x.kind != y.kind) return x.kind < y.kind;
    return x.id != y.id ? x.id < y.id : x.wall < y.wall;
  });
  std::array<WallContacts, 3>& wc = buf_->wall;
  for (auto& l : wc) clear_keep(l);
  std::size_t w = 0;
  for (int kind = 0; kind < 3; ++kind) {
    const WallContacts& old = *wl[static_cast<std::size_t>(kind)];
    const bool bonds = kind_bonds(p_, kind);
    WallContacts& out = wc[static_cast<std::size_t>(kind)];
    std::size_t c2 = 0;
    while (true) {
      while (c2 < old.size() && own[old.ball[c2]] != rank_) ++c2;
      const bool have_c = c2 < old.size(), have_r = w < win.size() && win[w].kind == kind;
      if (!have_c && !have_r) break;
      bool take_c = have_c;
      if (have_c && have_r) {
        const std::uint64_t id = pt.id[old.ball[c2]];
        take_c = id != win[w].id ? id < win[w].id : old.wall[c2] < win[w].wall;
      }
      if (take_c) {
        push_wall(out, static_cast<std::uint32_t>(new_row[old.ball[c2]]), old.wall[c2], old.facet[c2], old.h[c2],
                  bonds ? &old.bond[c2] : nullptr);
        ++c2;
      } else {
        const WallRec& r = win[w++];
        const std::int64_t row = row_of(r.id);
        if (row < 0 || ghost[static_cast<std::size_t>(row)])
          throw std::logic_error("DistDem::exchange: rank " + std::to_string(rank_) +
                                 " got a wall contact of ball " + std::to_string(r.id) + ", which it does not own.");
        push_wall(out, static_cast<std::uint32_t>(row), r.wall, r.facet, r.h, bonds ? &r.b : nullptr);
      }
    }
  }
  w_->swap_balls(q, nc, wc, ghost);  // q_, nc_, the wall lists, ghost_buf_ now hold the old arrays
  split_ = split;
  if (own_first()) w_->set_moving_rows(split);
  ++exchanges_;
  ++layout_gen_;
  build_forward();
}

void contact_weights(const World& w, std::vector<std::int64_t>& wt, const ContactCost& cost) {
  wt.assign(w.num_balls(), cost.ball);
  const PairContacts& pc = w.pair_contacts();
  const bool bonds = !pc.bond.empty();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const std::int64_t e = bonds && bonded(pc.bond[c].state)       ? cost.bonded_end
                           : (pc.h[c].flags & ContactHist::kActive) ? cost.touching_end
                                                                    : cost.apart_end;
    wt[pc.a[c]] += e;
    wt[pc.b[c]] += e;
  }
  const auto wl = wall_lists(w);  // planes, facets, the footing
  for (int k = 0; k < 3; ++k)
    for (std::uint32_t i : wl[static_cast<std::size_t>(k)]->ball) wt[i] += k == 1 ? cost.facet : cost.plane;
}

std::vector<double> equal_weight_cuts(const std::vector<std::int64_t>& hist, int n, double len) {
  const int B = static_cast<int>(hist.size());
  std::int64_t total = 0;
  for (std::int64_t v : hist) total += v;
  std::vector<double> cuts;
  std::int64_t run = 0;
  int b = 0, last = 0;
  for (int j = 1; j < n; ++j) {
    const std::int64_t target = (total * j + n - 1) / n;
    while (b < B && run + hist[static_cast<std::size_t>(b)] < target) run += hist[static_cast<std::size_t>(b++)];
    const int e = std::clamp(b + 1, last + 1, B - (n - j));  // the cut: the end of bin b
    cuts.push_back(e * (len / B));
    last = e;
  }
  return cuts;
}

std::int64_t DistDem::weight() const {
  std::vector<std::int64_t> wt;
  contact_weights(*w_, wt, bal_.cost);
  const auto& gh = w_->ghost_rows();
  std::int64_t s = 0;
  for (std::size_t i = 0; i < wt.size(); ++i)
    if (gh.empty() || !gh[i]) s += wt[i];
  return s;
}

void DistDem::rebalance() {
  const Particles& pt = w_->balls();
  const std::size_t n = pt.size();
  std::vector<std::int64_t> wt;
  if (bal_.weight == Weight::kTime) {  // this rank's time since the last balancing, per own ball
    const double t = times_.compute() - compute_at_balance_;
    compute_at_balance_ = times_.compute();
    const std::size_t mine = owned();
    const auto per = static_cast<std::int64_t>(std::llround(mine ? t * 1e9 / double(mine) : 0.0));
    wt.assign(n, std::max<std::int64_t>(per, 1));
  } else {
    contact_weights(*w_, wt, bal_.cost);
  }
  balance_cuts(pt.x, wt, w_->ghost_rows());
  ++rebalances_;
}

// The cuts that give every brick (RCB) or slab (a grid) its share of the weights `wt` of the
// points `x` (those marked in `skip` left out), summed over the ranks (collective).
void DistDem::balance_cuts(const std::vector<Vec3>& x, const std::vector<std::int64_t>& wt,
                           const std::vector<std::uint8_t>& skip) {
  const std::size_t n = x.size();
  const int B = std::max(bal_.bins, 2);
  if (grid_.parts > 0) {  // the owned balls' weights, summed over the ranks level by level
    rcb_cuts(grid_, x, wt, skip, B, [this](std::vector<std::int64_t>& h) {
      MPI_Allreduce(MPI_IN_PLACE, h.data(), static_cast<int>(h.size()), MPI_INT64_T, MPI_SUM, comm_);
    });
    return;
  }
  std::vector<std::int64_t> h(static_cast<std::size_t>(B)), g(static_cast<std::size_t>(B));
  for (int k = 0; k < 3; ++k) {
    const int nk = grid_.n[k];
    if (nk < 2) continue;
    std::fill(h.begin(), h.end(), 0);
    const double L = grid_.len[k];
    for (std::size_t i = 0; i < n; ++i) {
      if (!skip.empty() && skip[i]) continue;
      const double u = along(grid_, x[i], k);
      const int b = std::clamp(static_cast<int>(std::floor(u / L * B)), 0, B - 1);
      h[static_cast<std::size_t>(b)] += wt[i];
    }
    MPI_Allreduce(h.data(), g.data(), B, MPI_INT64_T, MPI_SUM, comm_);
    grid_.cuts[k] = equal_weight_cuts(g, nk, L);
  }
}

// With balancing on, the first cut already balanced: rank 0's whole World weighed by its contacts
// (a measured time does not exist yet), the other ranks adding nothing (collective). Not counted
// in rebalances().
void DistDem::balance_at_load(const World* full) {
  if (bal_.every <= 0 || size_ < 2) return;
  std::vector<std::int64_t> wt;
  if (full) {
    contact_weights(*full, wt, bal_.cost);
    balance_cuts(full->balls().x, wt, {});
  } else {
    balance_cuts({}, {}, {});
  }
}

// RCB's cuts, one tree level at a time from the root: every inner node of the level cuts across
// its box's longest side (as set_rcb); the weights of the points in each such node go into `bins`
// even bins along that side, and `reduce` sums the bins of all the level's nodes over the ranks
// (integers: exact, so every rank finds the same cuts); the cut goes to the end of the first bin
// where the running weight reaches the low child's share, p / 2 of p (equal_weight_cuts over p
// slabs: at least one bin per slab); then every point walks on into its child. A node without
// weight takes the geometric cut (set_rcb's).
void rcb_cuts(BrickGrid& g, const std::vector<Vec3>& x, const std::vector<std::int64_t>& wt,
              const std::vector<std::uint8_t>& skip, int bins, const std::function<void(std::vector<std::int64_t>&)>& reduce) {
  const int P = g.parts, B = std::max(bins, 2);
  if (P < 2) return;  // one brick: no cut
  const std::size_t n = x.size();
  struct Node {
    int i, p;  // index in preorder, ranks
    double a0[3], a1[3];
    int axis;
  };
  std::vector<Node> level{{0, P, {0.0, 0.0, 0.0}, {g.len[0], g.len[1], g.len[2]}, 0}};
  std::vector<int> at(n, 0);  // each point's slot in `level`, -1 once in a leaf (or skipped)
  for (std::size_t j = 0; j < n; ++j)
    if (!skip.empty() && skip[j]) at[j] = -1;
  std::vector<std::int64_t> h;
  std::vector<Node> next;
  std::vector<int> slot_low, slot_high;
  while (!level.empty()) {
    for (Node& nd : level) nd.axis = longest_axis(nd.a0, nd.a1);
    const std::size_t L = level.size(), UB = static_cast<std::size_t>(B);
    h.assign(L * UB, 0);
    for (std::size_t j = 0; j < n; ++j) {
      if (at[j] < 0) continue;
      const Node& nd = level[static_cast<std::size_t>(at[j])];
      const double u = along(g, x[j], nd.axis);
      const double side = nd.a1[nd.axis] - nd.a0[nd.axis];
      const int b = std::clamp(static_cast<int>(std::floor((u - nd.a0[nd.axis]) / side * B)), 0, B - 1);
      h[static_cast<std::size_t>(at[j]) * UB + static_cast<std::size_t>(b)] += wt[j];
    }
    reduce(h);
    next.clear();
    slot_low.assign(L, -1);
    slot_high.assign(L, -1);
    for (std::size_t s = 0; s < L; ++s) {
      const Node& nd = level[s];
      const int k = nd.axis, left = nd.p / 2;
      const double side = nd.a1[k] - nd.a0[k];
      const std::vector<std::int64_t> hs(h.begin() + static_cast<std::ptrdiff_t>(s * UB),
                                         h.begin() + static_cast<std::ptrdiff_t>((s + 1) * UB));
      std::int64_t total = 0;
      for (std::int64_t v : hs) total += v;
      const double cut = nd.a0[k] + (total > 0 ? equal_weight_cuts(hs, nd.p, side)[static_cast<std::size_t>(left - 1)]
                                               : side * left / nd.p);
      g.rcb[static_cast<std::size_t>(nd.i)] = {k, cut};
      Node lo = nd, hi = nd;
      lo.i = nd.i + 1, lo.p = left, lo.a1[k] = cut;
      hi.i = nd.i + left, hi.p = nd.p - left, hi.a0[k] = cut;
      if (lo.p > 1) slot_low[s] = static_cast<int>(next.size()), next.push_back(lo);
      if (hi.p > 1) slot_high[s] = static_cast<int>(next.size()), next.push_back(hi);
    }
    for (std::size_t j = 0; j < n; ++j) {
      if (at[j] < 0) continue;
      const std::size_t s = static_cast<std::size_t>(at[j]);
      const BrickGrid::Cut& c = g.rcb[static_cast<std::size_t>(level[s].i)];
      at[j] = along(g, x[j], c.axis) < c.at ? slot_low[s] : slot_high[s];
    }
    level.swap(next);
  }
}

// Forward lists: every rank asks each owner for the ghosts it holds, in id order (its rows' order).
void DistDem::build_forward() {
  const Particles& q = w_->balls();
  const auto& ghost = w_->ghost_rows();
  std::vector<std::vector<std::uint64_t>> ask(static_cast<std::size_t>(size_));
  recv_rows_.assign(static_cast<std::size_t>(size_), {});
  for (std::size_t i = 0; i < q.size(); ++i)
    if (!ghost.empty() && ghost[i]) {
      const int r = grid_.owner(q.x[i]);
      ask[static_cast<std::size_t>(r)].push_back(q.id[i]);
      recv_rows_[static_cast<std::size_t>(r)].push_back(static_cast<std::uint32_t>(i));
    }
  // the counts first, so that each owner knows which requests came from which rank
  std::vector<int> cnt(static_cast<std::size_t>(size_)), rcnt(static_cast<std::size_t>(size_));
  for (int r = 0; r < size_; ++r) cnt[static_cast<std::size_t>(r)] = static_cast<int>(ask[static_cast<std::size_t>(r)].size());
  MPI_Alltoall(cnt.data(), 1, MPI_INT, rcnt.data(), 1, MPI_INT, comm_);
  std::vector<std::uint64_t> req;
  all_to_all(comm_, ask, req, sbuf_, rbuf_);
  send_rows_.assign(static_cast<std::size_t>(size_), {});
  std::size_t k = 0;
  for (int r = 0; r < size_; ++r)
    for (int j = 0; j < rcnt[static_cast<std::size_t>(r)]; ++j) {
      const std::uint64_t id = req[k++];
      const std::int64_t row = find_row(q.id, split_, id);
      const std::size_t i = static_cast<std::size_t>(row);
      if (row < 0 || (!ghost.empty() && ghost[i]))
        throw std::logic_error("DistDem: rank " + std::to_string(r) + " asked rank " + std::to_string(rank_) +
                               " for ball " + std::to_string(id) + ", which it does not own.");
      send_rows_[static_cast<std::size_t>(r)].push_back(static_cast<std::uint32_t>(i));
    }
}

void DistDem::sum_folds(OrderFreeSum* sums, std::size_t S, double* extra) const {
  constexpr int F = OrderFreeSum::kFolds;
  std::vector<double>& f = buf_->of_folds;
  f.resize(S * F + 1);
  for (std::size_t k = 0; k < S; ++k)
    for (int j = 0; j < F; ++j) f[k * F + static_cast<std::size_t>(j)] = sums[k].fold[j];
  f[S * F] = extra ? *extra : 0.0;
  // each fold's sum over the ranks is exact in any order (order_free_sum.hpp)
  MPI_Allreduce(MPI_IN_PLACE, f.data(), static_cast<int>(f.size()), MPI_DOUBLE, MPI_SUM, comm_);
  for (std::size_t k = 0; k < S; ++k)
    for (int j = 0; j < F; ++j) sums[k].fold[j] = f[k * F + static_cast<std::size_t>(j)];
  if (extra) *extra = f[S * F];
}

void DistDem::ordered_sums(std::size_t n, const double* vals, int K, const KeyFill& keys, int which, bool positive,
                           double* sums, std::int64_t* count, double* also_max, int n_max) const {
  const std::size_t k = static_cast<std::size_t>(K);
  if (p_.order_free_sums) {  // each column's order-free sum (order_free_sum.hpp): no keys, no gather
    // the columns' bounds and the maxima asked for in one maximum-allreduce (a NaN anywhere: NaN)
    std::vector<double>& col = buf_->m_vals;
    std::vector<double>& b = buf_->m_bound;
    b.assign(k + static_cast<std::size_t>(n_max), 0.0);
    col.resize(n);
    for (std::size_t c = 0; c < k; ++c) {
      for (std::size_t j = 0; j < n; ++j) col[j] = vals[j * k + c];
      b[c] = positive ? max_positive_of(col.data(), n) : max_abs_of(col.data(), n);
    }
    for (int m = 0; m < n_max; ++m) b[k + static_cast<std::size_t>(m)] = also_max[m];
    MPI_Allreduce(MPI_IN_PLACE, b.data(), static_cast<int>(b.size()), MPI_DOUBLE, MPI_MAX, comm_);
    for (int m = 0; m < n_max; ++m) also_max[m] = b[k + static_cast<std::size_t>(m)];
    std::vector<OrderFreeSum>& f = buf_->m_folds;
    f.clear();
    double c_pos = 0.0;
    for (std::size_t c = 0; c < k; ++c) {
      for (std::size_t j = 0; j < n; ++j) col[j] = vals[j * k + c];
      f.push_back(fold_terms(col.data(), n, b[c], positive));
      if (positive) c_pos += static_cast<double>(count_positive(col.data(), n));
    }
    sum_folds(f.data(), k, positive ? &c_pos : nullptr);  // (an integer count below 2^53 adds exactly)
    for (std::size_t c = 0; c < k; ++c) sums[c] = f[c].result();
    if (count) *count = static_cast<std::int64_t>(c_pos);
    return;
  }
  std::vector<double>& res = buf_->m_res;
  res.assign(k + 1, 0.0);
  ordered_fold(n, vals, K, keys, which, also_max, n_max, [&](const double* v, const std::vector<std::uint32_t>& perm) {
    if (positive) {  // the mean's rule (K = 1): only the terms that carry a force
      // (adding +0 for the others leaves the sum's bits: it starts at +0 and never is -0)
      double s = 0.0;
      std::int64_t c = 0;
      for (std::uint32_t j : perm) {
        const bool on = v[j] > 0.0;
        s += on ? v[j] : 0.0;
        c += on;
      }
      res[0] = s;
      res[1] = static_cast<double>(c);
    } else if (K == 1) {
      double s = 0.0;
      for (std::uint32_t j : perm) s += v[j];
      res[0] = s;
    } else {  // K chains of additions side by side, each in key order from +0
      double s[kMaxColumns] = {};
      for (std::uint32_t j : perm)
        for (std::size_t c = 0; c < k; ++c) s[c] += v[j * k + c];
      for (std::size_t c = 0; c < k; ++c) res[c] = s[c];
    }
  });
  MPI_Bcast(res.data(), static_cast<int>(res.size()), MPI_DOUBLE, 0, comm_);
  for (std::size_t c = 0; c < k; ++c) sums[c] = res[c];
  if (count) *count = static_cast<std::int64_t>(res[k]);
}

// ordered_sums' gather and merge, for any fold of the terms in one World's order (the periodic
// servo's sums: servo_sums).
void DistDem::ordered_fold(std::size_t n, const double* vals, int K, const KeyFill& keys, int which, double* also_max,
                           int n_max, const Fold& fold) const {
  const std::size_t k = static_cast<std::size_t>(K);
  // The merge order is formed again only when the terms' keys may have changed: the owned balls
  // change only at an exchange or a load (layout_gen_), the contacts also at a rebuild, and a
  // rank whose count changed makes every rank form it again (one maximum-allreduce decides, with
  // the maxima asked for). Else only the values travel (8 bytes a term and column, not the
  // 32-byte keyed terms) and rank 0 adds them in the kept order: the same additions.
  OrderCache& oc = buf_->order_cache[which];
  const std::int64_t key[2] = {layout_gen_, which != kBallTerms ? w_->rebuild_count() : 0};
  std::vector<double>& mx = buf_->m_bound;
  mx.assign(1 + static_cast<std::size_t>(n_max), 0.0);
  mx[0] = which == kOnceTerms || key[0] != oc.key[0] || key[1] != oc.key[1] || n != oc.local ? 1.0 : 0.0;
  for (int m = 0; m < n_max; ++m) mx[1 + static_cast<std::size_t>(m)] = also_max[m];
  MPI_Allreduce(MPI_IN_PLACE, mx.data(), static_cast<int>(mx.size()), MPI_DOUBLE, MPI_MAX, comm_);
  for (int m = 0; m < n_max; ++m) also_max[m] = mx[1 + static_cast<std::size_t>(m)];
  if (mx[0] != 0.0) {
    using T = World::ContactTerm;
    const auto key_less = [](const T& x, const T& y) { return std::tie(x.set, x.a, x.b) < std::tie(y.set, y.a, y.b); };
    std::vector<T>& t = buf_->m_terms;
    t.clear();
    keys(t);  // this rank's keys, in the values' order
    // In key order (they nearly always are: rows and lists in id order); else the permutation
    // that sorts them, kept with the merge order.
    oc.lperm.clear();
    if (!std::is_sorted(t.begin(), t.end(), key_less)) {
      oc.lperm.resize(n);
      for (std::size_t j = 0; j < n; ++j) oc.lperm[j] = static_cast<std::uint32_t>(j);
      std::sort(oc.lperm.begin(), oc.lperm.end(), [&](std::uint32_t x, std::uint32_t y) { return key_less(t[x], t[y]); });
      std::vector<T>& sorted = buf_->m_all;
      sorted.resize(n);
      for (std::size_t j = 0; j < n; ++j) sorted[j] = t[oc.lperm[j]];
      t.swap(sorted);
    }
    // rank 0 merges the ranks' runs pairwise: O(n log ranks), not a sort of every term
    std::vector<std::size_t> at;
    std::vector<T>& all = buf_->m_all;
    gather_on_root(comm_, t, all, &at);
    oc.key[0] = key[0], oc.key[1] = key[1];
    oc.local = n;
    if (rank_ == 0) {
      oc.counts.resize(static_cast<std::size_t>(size_));
      oc.displ.resize(static_cast<std::size_t>(size_));
      for (std::size_t r = 0; r < static_cast<std::size_t>(size_); ++r) {  // (where each rank's terms begin)
        oc.displ[r] = static_cast<int>(at[r]);
        oc.counts[r] = static_cast<int>(at[r + 1] - at[r]);
      }
      oc.perm.resize(all.size());
      for (std::size_t j = 0; j < all.size(); ++j) oc.perm[j] = static_cast<std::uint32_t>(j);
      merge_runs(oc.perm, at, [&](std::uint32_t x, std::uint32_t y) { return key_less(all[x], all[y]); });
    }
  }
  // this rank's values in key order, gathered on rank 0 (K per term)
  const double* mine = vals;
  if (!oc.lperm.empty()) {
    oc.mine.resize(n * k);
    for (std::size_t j = 0; j < n; ++j)
      for (std::size_t c = 0; c < k; ++c) oc.mine[j * k + c] = vals[oc.lperm[j] * k + c];
    mine = oc.mine.data();
  }
  std::vector<int>& cnt = buf_->m_counts;
  std::vector<int>& dsp = buf_->m_displ;
  if (rank_ == 0) {
    oc.all.resize(oc.perm.size() * k);
    cnt.resize(static_cast<std::size_t>(size_));
    dsp.resize(static_cast<std::size_t>(size_));
    for (std::size_t r = 0; r < static_cast<std::size_t>(size_); ++r) cnt[r] = oc.counts[r] * K, dsp[r] = oc.displ[r] * K;
  }
  MPI_Gatherv(mine, static_cast<int>(n * k), MPI_DOUBLE, oc.all.data(), cnt.data(), dsp.data(), MPI_DOUBLE, 0, comm_);
  if (rank_ == 0) fold(oc.all.data(), oc.perm);
}

void DistDem::owned_sums(const std::vector<double>& v, int K, double* sums, double* also_max, int n_max) const {
  const auto& g = w_->ghost_rows();
  const Particles& pt = w_->balls();
  const KeyFill keys = [&](std::vector<World::ContactTerm>& out) {
    for (std::size_t i = 0; i < pt.size(); ++i)
      if (g.empty() || !g[i]) out.push_back({0, pt.id[i], 0, 0.0});
  };
  ordered_sums(v.size() / static_cast<std::size_t>(K), v.data(), K, keys, kBallTerms, false, sums, nullptr, also_max, n_max);
}

template <int K, class Terms>
void DistDem::ball_sums(Terms terms, double* sums) const {
  static_assert(K >= 1 && K <= kMaxColumns);
  const auto& g = w_->ghost_rows();
  const std::size_t n = w_->num_balls();
  std::vector<double>& v = buf_->m_rows;
  v.resize(n * K);
  double* out = v.data();
  for (std::size_t i = 0; i < n; ++i)
    if (g.empty() || !g[i]) {
      terms(i, out);
      out += K;
    }
  v.resize(static_cast<std::size_t>(out - v.data()));
  owned_sums(v, K, sums);
}

SkeletonRatio DistDem::skeleton_ratio(double fc) const { return ball_ratios(fc).skeleton; }

BallRatios DistDem::ball_ratios(double fc) const {
  // dem::ball_ratios's terms (procedures.hpp: unbalanced_term), three sums in id order at once:
  // the unbalanced forces, the skeleton terms (+0 for a rattler) and the rattlers (a sum of ones:
  // exact, like the integer count)
  const Vec3 g = w_->gravity();
  double s[3];
  ball_sums<3>(
      [&](std::size_t i, double* t) {
        bool r = false;
        t[0] = dem::unbalanced_term(*w_, i, g, r);
        t[1] = r ? 0.0 : t[0];
        t[2] = r ? 1.0 : 0.0;
      },
      s);
  const std::size_t n = num_balls();
  if (n == 0) return {0.0, skeleton_ratio_of(s[1], static_cast<std::size_t>(s[2]), 0, fc)};
  return {World::unbalanced_ratio_of(s[0], n, fc), skeleton_ratio_of(s[1], static_cast<std::size_t>(s[2]), n, fc)};
}

DistDem::Screen DistDem::screen(const Vec3& lo, const Vec3& hi, bool box) const {
  // dem::screen_balls's tests on every row of this rank (ghosts: bit copies of their owners'
  // rows), the owned rows' kinetic terms summed as kinetic_energy() sums them, the verdicts'
  // maxima carried by its collective
  std::vector<double>& v = buf_->m_rows;
  const BallScreen sc = screen_rows(*w_, lo, hi, box, w_->ghost_rows(), v);
  double mx[2] = {sc.finite ? 0.0 : 1.0, sc.outside};
  Screen out;
  owned_sums(v, 1, &out.kinetic, mx, 2);
  out.finite = mx[0] == 0.0;
  out.outside = mx[1];
  return out;
}

double DistDem::safe_step() const {
  return w_->contact_scan(true, false).dt;  // (the scan reduces its ratios over the ranks: take)
}

double DistDem::kinetic_energy() const {
  double s = 0.0;
  ball_sums<1>([this](std::size_t i, double* t) { t[0] = w_->kinetic_energy_of(i); }, &s);
  return s;
}

std::size_t DistDem::num_balls() const {
  // the count changes only where the rows do (a load; an exchange only moves balls): kept with
  // the layout it was summed for
  if (balls_gen_ == layout_gen_) return balls_;
  unsigned long long mine = owned(), all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm_);
  balls_gen_ = layout_gen_;
  balls_ = static_cast<std::size_t>(all);
  return balls_;
}

BondCounts DistDem::bond_counts() const {
  const BondCounts b = dem::bond_counts(*w_);
  unsigned long long mine[5] = {b.never_bonded, b.intact, b.softening, b.broken_tension, b.broken_shear}, all[5];
  MPI_Allreduce(mine, all, 5, MPI_UNSIGNED_LONG_LONG, MPI_SUM, comm_);
  return BondCounts{all[0], all[1], all[2], all[3], all[4]};
}

std::int64_t DistDem::bond_failures() const {
  long long mine = w_->bond_failures(), all = 0;
  MPI_Allreduce(&mine, &all, 1, MPI_LONG_LONG, MPI_SUM, comm_);
  return all;
}

// World::contact_scan's rule: Σ ‖F‖ over the contacts that carry a force, over their count. The
// norms without their keys every step (World::contact_force_norms), the keys only when the merge
// order is formed again.
double DistDem::mean_contact_force() const {
  std::vector<double>& v = buf_->m_rows;
  v.clear();
  w_->contact_force_norms(v);
  const KeyFill keys = [this](std::vector<World::ContactTerm>& out) { w_->contact_force_keys(out); };
  std::int64_t n = 0;
  double s = 0.0;
  ordered_sums(v.size(), v.data(), 1, keys, kContactTerms, true, &s, &n);
  return n ? s / double(n) : 0.0;
}

// World::unbalanced_ratio's rule.
double DistDem::unbalanced_ratio(double fc) const {
  const std::size_t n = num_balls();
  if (n == 0) return 0.0;
  double s = 0.0;
  ball_sums<1>([this](std::size_t i, double* t) { t[0] = w_->unbalanced_force_of(i); }, &s);
  return World::unbalanced_ratio_of(s, n, fc);
}

// ------------------------------------------------------------------------------------------
// specimen preparation on the ranks: the periodic servo and its measurements

// Every term goes to rank 0 whatever WorldParams::order_free_sums says: one World's servo and its
// cell measurements add in list order (specimen.cpp, measure.cpp), so the ranks do too.
ServoSums DistDem::servo_sums(ServoStiffness kind, const std::vector<int>* columns) const {
  const World& w = *w_;
  const auto& pc = w.pair_contacts();
  const auto& g = w.ghost_rows();
  const Particles& pt = w.balls();
  auto mine = [&](std::size_t c) { return g.empty() || !g[pc.a[c]]; };  // (contact_force_keys' rule)
  const KeyFill keys = [&](std::vector<World::ContactTerm>& out) {
    for (std::size_t c = 0; c < pc.size(); ++c)
      if (mine(c)) out.push_back({0, pt.id[pc.a[c]], pt.id[pc.b[c]], 0.0});
  };
  std::vector<double>& v = buf_->m_rows;
  v.clear();
  if (p_.order_free_sums) {  // each column's order-free sum of the contacts' contributions, as one World's
    std::vector<int> all(kServoColumns);
    std::iota(all.begin(), all.end(), 0);
    const std::vector<int>& cols = columns ? *columns : all;
    const std::size_t m = cols.size();
    std::size_t n = 0;
    double t[kServoColumns];
    for (std::size_t c = 0; c < pc.size(); ++c) {
      if (!mine(c)) continue;
      servo_columns(servo_term(w, c), kind, t);
      for (int k : cols) v.push_back(t[k]);
      ++n;
    }
    double total[kServoColumns];
    ordered_sums(n, v.data(), static_cast<int>(m), keys, kServoTerms, false, total);  // (its order-free branch)
    return servo_sums_of_columns(total, cols.data(), static_cast<int>(m));
  }
  constexpr int K = 9;  // a term's doubles: F, l, k_n, k_s, stiff
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (!mine(c)) continue;
    const ServoTerm t = servo_term(w, c);
    v.insert(v.end(), {t.F.x, t.F.y, t.F.z, t.l.x, t.l.y, t.l.z, t.kn, t.ks, t.stiff ? 1.0 : 0.0});
  }
  ServoSums sums;
  ordered_fold(v.size() / K, v.data(), K, keys, kServoTerms, nullptr, 0,
               [&](const double* all, const std::vector<std::uint32_t>& perm) {
                 for (std::uint32_t j : perm) {
                   const double* q = all + K * static_cast<std::size_t>(j);
                   ServoTerm t;
                   t.F = {q[0], q[1], q[2]};
                   t.l = {q[3], q[4], q[5]};
                   t.kn = q[6];
                   t.ks = q[7];
                   t.stiff = q[8] != 0.0;
                   sums.add(t, kind);
                 }
               });
  double b[18];  // the stress's 9 sums, then K's
  std::copy(sums.s.begin(), sums.s.end(), b);
  std::copy(&sums.K[0][0], &sums.K[0][0] + 9, b + 9);
  MPI_Bcast(b, 18, MPI_DOUBLE, 0, comm_);
  std::copy(b, b + 9, sums.s.begin());
  std::copy(b + 9, b + 18, &sums.K[0][0]);
  return sums;
}

PeriodicServo* DistDem::add_periodic_servo(const ServoParams& p, double d_min) {
  if (servo_) throw std::logic_error("DistDem::add_periodic_servo: the ranks run a periodic servo already.");
  if (!w_->periodic()) throw std::invalid_argument("DistDem::add_periodic_servo: the world must have a periodic cell.");
  auto e = std::make_unique<PeriodicServo>(p, d_min);
  e->set_reduce([this](World&, ServoStiffness kind, const std::vector<int>& cols) { return servo_sums(kind, &cols); });
  servo_ = static_cast<PeriodicServo*>(w_->add_effect(std::move(e)));
  return servo_;
}

void DistDem::remove_periodic_servo() {
  if (servo_) w_->remove_effect(servo_);
  servo_ = nullptr;
}

Mat3 DistDem::cell_stress() const {
  // the stress half of the servo's sums (the stiffness half adds nothing to it; under order-free
  // sums not formed)
  static const std::vector<int> stress{0, 1, 2, 3, 4, 5, 6, 7, 8};
  return cell_stress_of(servo_sums(ServoStiffness::kApparent, &stress).s, w_->cell_volume());
}

double DistDem::cell_porosity() const {
  const auto& g = w_->ghost_rows();
  const Particles& pt = w_->balls();
  std::vector<double>& v = buf_->m_vals;
  v.clear();
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (g.empty() || !g[i]) v.push_back(ball_volume_term(pt.r[i]));
  const KeyFill keys = [&](std::vector<World::ContactTerm>& out) {
    for (std::size_t i = 0; i < pt.size(); ++i)
      if (g.empty() || !g[i]) out.push_back({0, pt.id[i], 0, 0.0});
  };
  double solid = 0.0;
  ordered_fold(v.size(), v.data(), 1, keys, kBallTerms, nullptr, 0,
               [&](const double* all, const std::vector<std::uint32_t>& perm) {
                 for (std::uint32_t j : perm) solid += all[j];
               });
  MPI_Bcast(&solid, 1, MPI_DOUBLE, 0, comm_);
  return cell_porosity_of(solid, w_->cell_volume());
}

double DistDem::min_diameter() const {
  double d = detail::min_diameter(*w_);  // (a minimum: exact in any order)
  MPI_Allreduce(MPI_IN_PLACE, &d, 1, MPI_DOUBLE, MPI_MIN, comm_);
  return d;
}

void DistDem::quench() { detail::quench(*w_); }

void DistDem::scale_radii(double f) {
  World& w = *w_;
  double rmax = 0.0;
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    w.set_radius(i, w.balls().r[i] * f);  // (a ghost's too: the same bits as its owner's)
    rmax = std::max(rmax, w.balls().r[i]);
  }
  MPI_Allreduce(MPI_IN_PLACE, &rmax, 1, MPI_DOUBLE, MPI_MAX, comm_);
  halo_ = 2.0 * rmax + p_.skin;  // (params_from's rule with the new radii)
  prepare();  // the ghosts within the new halo, a rebuild and a force pass, as one World's
  w.refresh_contact_constants();
}

void DistDem::prepare() {
  exchange();
  run_disp2_ = 0.0;
  w_->prepare();
  reduce_walls();
}

Coordination DistDem::coordination() {
  const World& w = *w_;
  const auto& pc = w.pair_contacts();
  const auto& gh = w.ghost_rows();
  const std::size_t n = w.num_balls();
  std::vector<double> cnt(n, 0.0);  // (doubles: newton's reverse sends them; exact as counts)
  std::int64_t k[3] = {0, 0, 0};     // active pairs, rattlers, contact ends on the other balls
  for (std::size_t c = 0; c < pc.size(); ++c)
    if (pair_active(w, c)) {
      cnt[pc.a[c]] += 1.0;
      cnt[pc.b[c]] += 1.0;
      k[0] += detail::owned_a(w, c);
    }
  if (newton_ && size_ > 1) {
    std::vector<double> none(n, 0.0);
    reverse(cnt.data(), none.data(), 1);
  }
  for (std::size_t i = 0; i < n; ++i) {
    if (!gh.empty() && gh[i]) continue;
    if (cnt[i] < 2.0)
      ++k[1];
    else
      k[2] += static_cast<std::int64_t>(cnt[i]);
  }
  MPI_Allreduce(MPI_IN_PLACE, k, 3, MPI_INT64_T, MPI_SUM, comm_);
  return coordination_of(num_balls(), static_cast<std::size_t>(k[0]), static_cast<std::size_t>(k[1]),
                         static_cast<std::size_t>(k[2]));
}

namespace {
// The preparation's system on the ranks (specimen_steps.hpp).
struct Ranks {
  DistDem& d;
  const World& world() const { return d.world(); }
  PeriodicServo* add_servo(const ServoParams& p, double d_min) { return d.add_periodic_servo(p, d_min); }
  void remove_servo(PeriodicServo*) { d.remove_periodic_servo(); }
  void step(std::int64_t n) { d.step(n); }
  void scale_radii(double f) { d.scale_radii(f); }
  void set_contact_params(double mu, UnbondedMoments m) { detail::set_contact_params(d.world(), mu, m); }
  std::size_t num_balls() const { return d.num_balls(); }
  void quench() { d.quench(); }
  void stop_cell() { d.world().set_strain_rate({}); }
  double friction() const { return d.world().params().ball_ball.linear.fric; }
  void set_friction(double mu) { detail::set_friction(d.world(), mu); }  // (every rank's World)
  double ratio() const { return d.unbalanced_ratio(d.mean_contact_force()); }
  Mat3 stress() const { return d.cell_stress(); }
  double porosity() const { return d.cell_porosity(); }
  double min_diameter() const { return d.min_diameter(); }
  World& part() { return d.world(); }
  void prepare() { d.prepare(); }
  std::int64_t total(std::int64_t v) const {
    MPI_Allreduce(MPI_IN_PLACE, &v, 1, MPI_INT64_T, MPI_SUM, d.comm());
    return v;
  }
  // The k-th smallest of every rank's values (all > 0, so ordered as their bits): the smallest
  // bit pattern at or below which k values lie over the ranks, by bisection (63 integer sums).
  double kth_smallest(std::vector<double>& v, std::int64_t k) const {
    std::sort(v.begin(), v.end());
    auto value = [](std::uint64_t b) {
      double x;
      std::memcpy(&x, &b, sizeof x);
      return x;
    };
    const double inf = std::numeric_limits<double>::infinity();
    std::uint64_t lo = 0, hi = 0;  // at or below lo fewer than k values lie, at or below hi at least k
    std::memcpy(&hi, &inf, sizeof hi);
    while (hi - lo > 1) {
      const std::uint64_t mid = lo + (hi - lo) / 2;
      const auto at = static_cast<std::int64_t>(std::upper_bound(v.begin(), v.end(), value(mid)) - v.begin());
      (total(at) >= k ? hi : lo) = mid;
    }
    return value(hi);
  }
  Coordination coordination() { return d.coordination(); }
  // Every rank's records on every rank (an all-gather), in one World's order: by key (unique).
  template <class T>
  void in_order(std::vector<T>& v) const {
    int P = 1;
    MPI_Comm_size(d.comm(), &P);
    const int bytes = static_cast<int>(v.size() * sizeof(T));
    std::vector<int> counts(static_cast<std::size_t>(P)), displ(static_cast<std::size_t>(P));
    MPI_Allgather(&bytes, 1, MPI_INT, counts.data(), 1, MPI_INT, d.comm());
    int total = 0;
    for (int r = 0; r < P; ++r) displ[static_cast<std::size_t>(r)] = total, total += counts[static_cast<std::size_t>(r)];
    std::vector<T> all(static_cast<std::size_t>(total) / sizeof(T));
    MPI_Allgatherv(v.data(), bytes, MPI_BYTE, all.data(), counts.data(), displ.data(), MPI_BYTE, d.comm());
    std::sort(all.begin(), all.end(), [](const T& a, const T& b) { return a.key() < b.key(); });
    v.swap(all);
  }
};
}  // namespace

StageReport servo_until(DistDem& d, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                        double budget, double* overshoot) {
  Ranks sys{d};
  return detail::servo_until_on(sys, p, stress_tol, ratio_tol, hold, budget, overshoot);
}

StageReport servo_specimen(DistDem& d, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                           double budget, double compaction_fric) {
  Ranks sys{d};
  return detail::servo_specimen_on(sys, p, stress_tol, ratio_tol, hold, budget, compaction_fric);
}

StageReport install_bonds(DistDem& d, double lo, double hi) {
  Ranks sys{d};
  return detail::install_bonds_on(sys, lo, hi);
}

double gap_for_coordination(DistDem& d, double z_target, double gap_floor) {
  Ranks sys{d};
  return detail::gap_for_coordination_on(sys, z_target, gap_floor);
}

StageReport install_bonds_to_coordination(DistDem& d, double z_target, double gap_floor) {
  Ranks sys{d};
  return detail::install_bonds_to_coordination_on(sys, z_target, gap_floor);
}

void bond_specimen(DistDem& d, StageReport& r, double bond_coordination, double gap_floor) {
  Ranks sys{d};
  detail::bond_specimen_on(sys, r, bond_coordination, gap_floor);
}

StageReport depth_scale(DistDem& d, const DepthScaleParams& p) {
  Ranks sys{d};
  return detail::depth_scale_on(sys, p);
}

StageReport assign_interface_bond_forces(DistDem& d, const InterfaceBondParams& p) {
  Ranks sys{d};
  return detail::assign_interface_bond_forces_on(sys, p);
}

std::size_t bond_ball_facet(DistDem& d, double hi) {
  std::int64_t n = static_cast<std::int64_t>(d.world().bond_ball_facet(hi));  // (a rank's balls' contacts)
  MPI_Allreduce(MPI_IN_PLACE, &n, 1, MPI_INT64_T, MPI_SUM, d.comm());
  return static_cast<std::size_t>(n);
}

double DistDem::ball_weight() const {
  double m = 0.0;
  ball_sums<1>([&](std::size_t i, double* out) { out[0] = w_->balls().m[i]; }, &m);
  return m * std::abs(w_->gravity().z);
}

StageReport generate_rev(DistDem& d, World& full, const RevParams& p) {
  // Rank 0 draws; its verdict, the porosity to reach and the final contact parameters are every
  // rank's (a failure of any kind there is every rank's error, not a rank left waiting).
  RevStart st;
  std::string refused;
  if (d.rank() == 0) {
    try {
      st = generate_rev_balls(full, p);
    } catch (const std::exception& e) {
      refused = e.what();
      if (refused.empty()) refused = "generate_rev: rank 0 failed";
    }
  }
  share_verdict(d.comm(), refused);
  double v[3] = {st.n1, st.mu_final, static_cast<double>(static_cast<int>(st.moments_final))};
  MPI_Bcast(v, 3, MPI_DOUBLE, 0, d.comm());
  st = RevStart{v[0], v[1], static_cast<UnbondedMoments>(static_cast<int>(v[2]))};
  d.load_from_root(full);
  Ranks sys{d};
  const StageReport r = detail::expand_rev_on(sys, p, st);
  d.unload(full, true);
  // the final contact parameters on the assembled REV too, as on one World
  if (d.rank() == 0) detail::set_contact_params(full, st.mu_final, st.moments_final);
  return r;
}

StageReport replicate(DistDem& d, World& rev, const ReplicateParams& p) {
  // Rank 0's checks and its REV prepared (replicate's first step), then every rank's from its bytes.
  std::string refused, bytes;
  if (d.rank() == 0) {
    try {
      const ReplicaLayout check(rev, p);
      rev.prepare();
      bytes = state_bytes(rev, CheckpointMeta{});
    } catch (const std::exception& e) {
      refused = e.what();
      if (refused.empty()) refused = "replicate: rank 0 failed";
    }
  }
  share_verdict(d.comm(), refused);
  long long nb = static_cast<long long>(bytes.size());
  MPI_Bcast(&nb, 1, MPI_LONG_LONG, 0, d.comm());
  bytes.resize(static_cast<std::size_t>(nb));
  constexpr long long kChunk = 1LL << 30;
  for (long long at = 0; at < nb; at += kChunk)
    MPI_Bcast(bytes.data() + at, static_cast<int>(std::min(kChunk, nb - at)), MPI_CHAR, 0, d.comm());
  // (a state file does not carry thread_independent and order_free_sums: the target keeps its
  // own, the caller's on every rank)
  World share(rev.params());
  load_state_bytes(share, std::move(bytes), 0, "rank 0's REV");
  const std::size_t rev_balls = share.num_balls();
  const ReplicaLayout lay(share, p);
  const DistDem::Replicated k = d.load_replicated(share, p);
  StageReport r;
  r.count = d.num_balls();
  Ranks sys{d};
  detail::fill_report_on(sys, r);
  r.what = lay.what(rev_balls, r.count, k.kept, k.dropped);
  return r;
}

DistDem::Balls DistDem::gather() const {
  struct Rec {
    std::uint64_t id;
    Vec3 x, v, w, f, t;
  };
  const Particles& pt = w_->balls();
  const auto& g = w_->ghost_rows();
  std::vector<Rec> mine;
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (g.empty() || !g[i]) mine.push_back(Rec{pt.id[i], pt.x[i], pt.v[i], pt.w[i], pt.f[i], pt.t[i]});
  std::vector<Rec> all = gather_on_root(comm_, mine);
  Balls out;
  if (rank_ != 0) return out;
  std::sort(all.begin(), all.end(), [](const Rec& a, const Rec& b) { return a.id < b.id; });
  for (const Rec& r : all) {
    out.id.push_back(r.id);
    out.x.push_back(r.x);
    out.v.push_back(r.v);
    out.w.push_back(r.w);
    out.f.push_back(r.f);
    out.t.push_back(r.t);
  }
  return out;
}

// ------------------------------------------------------------------------------------------
// the stage's measurements on the ranks: energy, gravity's work, stress profile, footing

namespace {

// Every rank's records to rank dest(record), by one all-to-all of counts and one of bytes.
template <class T, class Dest>
std::vector<T> send_to(MPI_Comm comm, int size, const std::vector<T>& recs, Dest dest) {
  std::vector<std::vector<T>> out(static_cast<std::size_t>(size));
  for (const T& r : recs) out[static_cast<std::size_t>(dest(r))].push_back(r);
  std::vector<int> sc(static_cast<std::size_t>(size)), rc(static_cast<std::size_t>(size)),
      sd(static_cast<std::size_t>(size) + 1, 0), rd(static_cast<std::size_t>(size) + 1, 0);
  std::vector<T> flat;
  for (int q = 0; q < size; ++q) {
    const auto& o = out[static_cast<std::size_t>(q)];
    sc[static_cast<std::size_t>(q)] = static_cast<int>(o.size() * sizeof(T));
    sd[static_cast<std::size_t>(q) + 1] = sd[static_cast<std::size_t>(q)] + sc[static_cast<std::size_t>(q)];
    flat.insert(flat.end(), o.begin(), o.end());
  }
  MPI_Alltoall(sc.data(), 1, MPI_INT, rc.data(), 1, MPI_INT, comm);
  for (int q = 0; q < size; ++q) rd[static_cast<std::size_t>(q) + 1] = rd[static_cast<std::size_t>(q)] + rc[static_cast<std::size_t>(q)];
  std::vector<T> in(static_cast<std::size_t>(rd.back()) / sizeof(T));
  MPI_Alltoallv(flat.data(), sc.data(), sd.data(), MPI_BYTE, in.data(), rc.data(), rd.data(), MPI_BYTE, comm);
  return in;
}

// Σ of one value per rank, added in rank order on rank 0 and sent to every rank (K values).
void sum_in_rank_order(MPI_Comm comm, int rank, int size, double* v, int K) {
  std::vector<double> all(static_cast<std::size_t>(size * K));
  MPI_Gather(v, K, MPI_DOUBLE, all.data(), K, MPI_DOUBLE, 0, comm);
  if (rank == 0)
    for (int k = 0; k < K; ++k) {
      double s = 0.0;
      for (int r = 0; r < size; ++r) s += all[static_cast<std::size_t>(r * K + k)];
      v[k] = s;
    }
  MPI_Bcast(v, K, MPI_DOUBLE, 0, comm);
}

}  // namespace

Energy DistDem::energy() const {
  Energy e = w_->energy();  // (its contacts' terms; the kinetic energy of every row, replaced below)
  double s[4] = {e.strain, e.damping, e.friction, e.softening};
  sum_in_rank_order(comm_, rank_, size_, s, 4);
  e.strain = s[0], e.damping = s[1], e.friction = s[2], e.softening = s[3];
  e.kinetic = kinetic_energy();
  return e;
}

std::vector<DistDem::IdPos> DistDem::owned_positions() const {
  const Particles& pt = w_->balls();
  const auto& g = w_->ghost_rows();
  std::vector<IdPos> out;
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (g.empty() || !g[i]) out.push_back({pt.id[i], pt.x[i]});
  std::sort(out.begin(), out.end(), [](const IdPos& a, const IdPos& b) { return a.id < b.id; });
  return out;
}

double DistDem::gravity_work(const std::vector<IdPos>& begin) const {
  if (!w_->gravity_on()) return 0.0;
  struct Now {
    std::uint64_t id;
    double m;
    Vec3 x;
  };
  const Particles& pt = w_->balls();
  const auto& gh = w_->ghost_rows();
  std::vector<Now> now;
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (gh.empty() || !gh[i]) now.push_back({pt.id[i], pt.m[i], pt.x[i]});
  const auto home = [this](std::uint64_t id) { return static_cast<int>(id % static_cast<std::uint64_t>(size_)); };
  std::vector<Now> a = send_to(comm_, size_, now, [&](const Now& r) { return home(r.id); });
  std::vector<IdPos> b = send_to(comm_, size_, begin, [&](const IdPos& r) { return home(r.id); });
  std::sort(a.begin(), a.end(), [](const Now& x, const Now& y) { return x.id < y.id; });
  std::sort(b.begin(), b.end(), [](const IdPos& x, const IdPos& y) { return x.id < y.id; });
  const Vec3 g = w_->gravity();
  double work = 0.0;
  std::size_t j = 0;
  for (const Now& r : a) {  // (procedures.cpp's gravity_work: the same term)
    while (j < b.size() && b[j].id < r.id) ++j;
    if (j < b.size() && b[j].id == r.id) work += r.m * dot(g, r.x - b[j].x);
  }
  sum_in_rank_order(comm_, rank_, size_, &work, 1);
  return work;
}

std::vector<ProfileSlab> stress_profile(const DistDem& d, const ProfileBox& box, int slabs) {
  const World& w = d.world();
  // (a ghost across a periodic face is an image outside the slabs: a block's profile only)
  if (w.periodic()) throw std::invalid_argument("stress_profile on ranks: the world must not be periodic");
  const auto sl = profile_slabs(box, slabs);
  const std::uint64_t S = sl.size();
  const Particles& pt = w.balls();
  const auto& gh = w.ghost_rows();
  auto ghost = [&](std::size_t i) { return !gh.empty() && gh[i]; };
  // The balls in each slab (a centre on the face between two is in both), then the terms: per
  // contact and slab, ball A's increment before B's, each a key of its own: (set, A id, (B id x 2
  // + side) x S + slab) for a pair, (1 + kind, ball id, wall x S + slab) for a wall contact.
  std::vector<std::uint64_t> count(S, 0);
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (!ghost(i))
      for (std::uint64_t k = 0; k < S; ++k) count[k] += sl[k].first.contains(pt.x[i]) ? 1 : 0;
  MPI_Allreduce(MPI_IN_PLACE, count.data(), static_cast<int>(S), MPI_UINT64_T, MPI_SUM, d.comm());
  std::vector<double> vals;
  std::vector<World::ContactTerm> keys;
  auto term = [&](std::uint64_t set, std::uint64_t a, std::uint64_t b, std::uint64_t k, const Vec3& arm, const Vec3& F) {
    keys.push_back({set, a, b * S + k, 0.0});
    vals.insert(vals.end(), {static_cast<double>(k), arm[0] * F[0], arm[1] * F[1], arm[2] * F[2]});
  };
  const PairContacts& pc = w.pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const std::uint32_t a = pc.a[c], b = pc.b[c];
    if (ghost(a)) continue;
    const Vec3 F = w.pair_force(c);
    if (F.x == 0.0 && F.y == 0.0 && F.z == 0.0) continue;
    Vec3 arm_a, arm_b;
    bool armed = false;
    for (int side = 0; side < 2; ++side) {
      const std::uint32_t i = side == 0 ? a : b;
      for (std::uint64_t k = 0; k < S; ++k) {
        if (!sl[k].first.contains(pt.x[i])) continue;
        if (!armed) pair_stress_arms(w, c, arm_a, arm_b), armed = true;
        term(0, pt.id[a], 2 * pt.id[b] + static_cast<std::uint64_t>(side), k, side == 0 ? arm_a : arm_b, side == 0 ? -F : F);
      }
    }
  }
  const WallContacts* wl[3] = {&w.plane_contacts(), &w.facet_contacts(), &w.footing_contacts()};
  for (std::uint64_t kind = 0; kind < 3; ++kind)
    for (std::size_t c = 0; c < wl[kind]->size(); ++c) {
      const std::uint32_t i = wl[kind]->ball[c];
      if (ghost(i)) continue;
      for (std::uint64_t k = 0; k < S; ++k)
        if (sl[k].first.contains(pt.x[i])) term(kind + 1, pt.id[i], wl[kind]->wall[c], k, wl[kind]->xc[c] - pt.x[i], -wl[kind]->F[c]);
    }
  // rank 0 adds each slab's terms in one World's order (region_stress's), then divides
  std::vector<double> sig(3 * S, 0.0);
  d.ordered_fold(keys.size(), vals.data(), 4, [&](std::vector<World::ContactTerm>& out) { out = keys; },
                 DistDem::kOnceTerms, nullptr, 0, [&](const double* v, const std::vector<std::uint32_t>& perm) {
                   for (std::uint32_t j : perm) {
                     const std::size_t k = static_cast<std::size_t>(v[4 * j]);
                     for (int q = 0; q < 3; ++q) sig[3 * k + static_cast<std::size_t>(q)] += v[4 * j + 1 + static_cast<std::size_t>(q)];
                   }
                 });
  MPI_Bcast(sig.data(), static_cast<int>(sig.size()), MPI_DOUBLE, 0, d.comm());
  std::vector<ProfileSlab> out;
  for (std::uint64_t k = 0; k < S; ++k) {
    ProfileSlab s = sl[k].second;
    const double V = sl[k].first.volume();
    s.balls = static_cast<std::size_t>(count[k]);
    s.sxx = sig[3 * k] / V;
    s.syy = sig[3 * k + 1] / V;
    s.szz = sig[3 * k + 2] / V;
    out.push_back(s);
  }
  return out;
}

std::pair<Vec3, Vec3> add_box_walls(DistDem& d) {
  auto [lo, hi] = ball_bounds(d.world());
  double v[6] = {-lo.x, -lo.y, -lo.z, hi.x, hi.y, hi.z};  // (the minima as maxima of the negatives)
  MPI_Allreduce(MPI_IN_PLACE, v, 6, MPI_DOUBLE, MPI_MAX, d.comm());
  lo = {-v[0], -v[1], -v[2]};
  hi = {v[3], v[4], v[5]};
  add_box_planes(d.world(), lo, hi);
  return {lo, hi};
}

Kicked kick_highest_ball(DistDem& d, const Vec3& v) {
  struct Top {
    double h;
    std::uint64_t id;
    Vec3 x;
  };
  const Particles& b = d.world().balls();
  const auto& g = d.world().ghost_rows();
  Top mine{-std::numeric_limits<double>::infinity(), std::numeric_limits<std::uint64_t>::max(), {0.0, 0.0, 0.0}};
  bool any = false;
  auto higher = [](const Top& a, const Top& t) { return a.h > t.h || (a.h == t.h && a.id < t.id); };
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (!g.empty() && g[i]) continue;
    const Top t{b.x[i].z + b.r[i], b.id[i], b.x[i]};
    if (!any || higher(t, mine)) mine = t;
    any = true;
  }
  std::vector<Top> all(static_cast<std::size_t>(d.grid().count()));
  MPI_Allgather(&mine, sizeof(Top), MPI_BYTE, all.data(), sizeof(Top), MPI_BYTE, d.comm());
  Top top = all[0];
  for (const Top& t : all)
    if (higher(t, top)) top = t;
  if (top.id == std::numeric_limits<std::uint64_t>::max()) throw std::invalid_argument("kick: the world has no balls");
  Particles& p = d.world().balls();
  for (std::size_t i = 0; i < p.size(); ++i)
    if (p.id[i] == top.id) p.v[i] = v;
  return {top.id, top.x};
}

double place_footing_at_first_contact(DistDem& d, FootingParams f) {
  double z = footing_contact_height(d.world(), f);
  MPI_Allreduce(MPI_IN_PLACE, &z, 1, MPI_DOUBLE, MPI_MAX, d.comm());
  set_footing_at(d.world(), f, z);
  return z;
}

// ------------------------------------------------------------------------------------------
// stream_snapshot: a frame's rows merged on rank 0 in blocks

namespace {

constexpr int kTagFrameBalls = 7304, kTagFramePairs = 7305;

struct FrameBall {
  std::uint64_t id;
  Vec3 x, v;
  double r;
};
struct FramePair {
  std::uint64_t a, b;  // ball ids
  Vec3 f;
  std::uint8_t state;
};

// A rank's sorted records, a block at a time: `next(buf, n)` replaces buf's content by the next
// at most n records (none: the end).
template <class R>
using RecordSource = std::function<void(std::vector<R>&, std::size_t)>;

// The records of a sorted vector, a block at a time.
template <class R>
RecordSource<R> source_of(const std::vector<R>& v) {
  return [&v, at = std::size_t{0}](std::vector<R>& buf, std::size_t n) mutable {
    const std::size_t k = std::min(n, v.size() - at);
    buf.assign(v.begin() + static_cast<std::ptrdiff_t>(at), v.begin() + static_cast<std::ptrdiff_t>(at + k));
    at += k;
  };
}

// Rank 0's side of one rank's records, sorted: they arrive in blocks of at most `block` as the
// merge reaches them (rank 0's own from its source).
template <class R>
struct FrameStream {
  std::vector<R> buf;
  std::size_t at = 0;
  std::uint64_t left = 0;  // records still on their rank (or in rank 0's source)
  int rank = 0;
  RecordSource<R>* local = nullptr;  // rank 0's own records
  const R* head(MPI_Comm comm, int tag, std::size_t block) {
    if (at == buf.size()) {
      if (left == 0) return nullptr;
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(block, left));
      if (local) {
        (*local)(buf, n);
        if (buf.size() != n) throw std::logic_error("merge_on_root: rank 0's records ran out before their count");
      } else {
        buf.resize(n);
        MPI_Recv(buf.data(), static_cast<int>(n * sizeof(R)), MPI_BYTE, rank, tag, comm, MPI_STATUS_IGNORE);
      }
      left -= n;
      at = 0;
    }
    return &buf[at];
  }
};

// Runs calls until the first throws, keeping that exception (rank 0's part of a collective
// that must go on to its end on every rank before anyone throws).
struct FirstError {
  std::exception_ptr failed;
  template <class F>
  void operator()(F&& f) {
    if (failed) return;
    try {
      f();
    } catch (...) {
      failed = std::current_exception();
    }
  }
};

// Rank 0's error, if any, on every rank: rank 0 rethrows its own, the others throw `what_failed`
// and its message. Collective.
void share_failure(MPI_Comm comm, int rank, const std::exception_ptr& failed, const std::string& what_failed) {
  std::string what;
  if (rank == 0 && failed) {
    try {
      std::rethrow_exception(failed);
    } catch (const std::exception& e) {
      what = e.what();
    } catch (...) {
      what = "an unknown error";
    }
    if (what.empty()) what = "an error";
  }
  int len = static_cast<int>(what.size());
  MPI_Bcast(&len, 1, MPI_INT, 0, comm);
  if (len == 0) return;
  what.resize(static_cast<std::size_t>(len));
  MPI_Bcast(what.data(), len, MPI_CHAR, 0, comm);  // (before rank 0 throws: the others wait for it)
  if (rank == 0) std::rethrow_exception(failed);
  throw std::runtime_error(what_failed + ": " + what);
}

// Every rank's numbers of balls and pairs on rank 0, with their totals (empty elsewhere).
struct RowCounts {
  std::vector<std::uint64_t> balls, pairs;
  std::uint64_t total_balls = 0, total_pairs = 0;
};
RowCounts row_counts(MPI_Comm comm, int rank, int size, std::uint64_t balls, std::uint64_t pairs) {
  const std::uint64_t mine[2] = {balls, pairs};
  std::vector<std::uint64_t> counts(2 * static_cast<std::size_t>(size));
  MPI_Gather(mine, 2, MPI_UINT64_T, counts.data(), 2, MPI_UINT64_T, 0, comm);
  RowCounts n;
  n.balls.resize(static_cast<std::size_t>(size)), n.pairs.resize(static_cast<std::size_t>(size));
  for (std::size_t r = 0; r < static_cast<std::size_t>(size) && rank == 0; ++r) {
    n.balls[r] = counts[2 * r], n.pairs[r] = counts[2 * r + 1];
    n.total_balls += n.balls[r], n.total_pairs += n.pairs[r];
  }
  return n;
}

// Merges the ranks' sorted records on rank 0 (k-way, a heap of the streams' heads), calling
// `out(record)` in `less` order; the other ranks send theirs in blocks of `block`. `counts`:
// every rank's number of records (rank 0). A rank holds a block of its own records at a time,
// rank 0 one of every rank's. Collective.
template <class R, class Less, class Out>
void merge_on_root(MPI_Comm comm, int rank, int size, int tag, std::size_t block, RecordSource<R> mine,
                   std::uint64_t my_count, const std::vector<std::uint64_t>& counts, Less less, Out out) {
  if (rank != 0) {
    std::vector<R> buf;
    for (std::uint64_t r0 = 0; r0 < my_count; r0 += block) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(block, my_count - r0));
      mine(buf, n);
      if (buf.size() != n) throw std::logic_error("merge_on_root: a rank's records ran out before their count");
      MPI_Send(buf.data(), static_cast<int>(n * sizeof(R)), MPI_BYTE, 0, tag, comm);
    }
    return;
  }
  std::vector<FrameStream<R>> st(static_cast<std::size_t>(size));
  for (int r = 0; r < size; ++r) st[static_cast<std::size_t>(r)].rank = r, st[static_cast<std::size_t>(r)].left = counts[static_cast<std::size_t>(r)];
  st[0].local = &mine;
  std::vector<std::pair<const R*, int>> heap;  // (head, stream); a min-heap by `less`
  auto later = [&](const std::pair<const R*, int>& x, const std::pair<const R*, int>& y) { return less(*y.first, *x.first); };
  for (int r = 0; r < size; ++r)
    if (const R* h = st[static_cast<std::size_t>(r)].head(comm, tag, block)) heap.push_back({h, r});
  std::make_heap(heap.begin(), heap.end(), later);
  while (!heap.empty()) {
    std::pop_heap(heap.begin(), heap.end(), later);
    auto [h, r] = heap.back();
    heap.pop_back();
    out(*h);
    FrameStream<R>& s = st[static_cast<std::size_t>(r)];
    ++s.at;
    if (const R* next = s.head(comm, tag, block)) {
      heap.push_back({next, r});
      std::push_heap(heap.begin(), heap.end(), later);
    }
  }
}
// The same with a rank's records in a sorted vector.
template <class R, class Less, class Out>
void merge_on_root(MPI_Comm comm, int rank, int size, int tag, std::size_t block, const std::vector<R>& mine,
                   const std::vector<std::uint64_t>& counts, Less less, Out out) {
  merge_on_root<R>(comm, rank, size, tag, block, source_of(mine), mine.size(), counts, less, out);
}

}  // namespace

void DistDem::stream_snapshot(const SnapshotSink& sink, std::size_t block) const {
  // (a block's bytes must fit an int; 64 MiB messages at most)
  block = std::max<std::size_t>(1, std::min<std::size_t>(block, (std::size_t{64} << 20) / sizeof(FrameBall)));
  const Particles& pt = w_->balls();
  const auto& g = w_->ghost_rows();
  auto owned_row = [&](std::size_t i) { return g.empty() || !g[i]; };
  // this rank's rows in one World's orders (unload's): balls by id, pairs by (A, B) id, the pairs
  // whose ball A it owns, active or ever bonded (snapshot's rows)
  std::vector<FrameBall> balls;
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (owned_row(i)) balls.push_back(FrameBall{pt.id[i], pt.x[i], pt.v[i], pt.r[i]});
  std::sort(balls.begin(), balls.end(), [](const FrameBall& x, const FrameBall& y) { return x.id < y.id; });
  std::vector<FramePair> pairs;
  const PairContacts& pc = w_->pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    if (!owned_row(pc.a[c])) continue;
    const BondState st = pc.bond.empty() ? BondState::kNeverBonded : pc.bond[c].state;
    if (!pair_active(*w_, c) && st == BondState::kNeverBonded) continue;
    pairs.push_back(FramePair{pt.id[pc.a[c]], pt.id[pc.b[c]], w_->pair_force(c), static_cast<std::uint8_t>(st)});
  }
  auto pair_less = [](const FramePair& x, const FramePair& y) { return std::tie(x.a, x.b) < std::tie(y.a, y.b); };
  std::sort(pairs.begin(), pairs.end(), pair_less);
  const RowCounts n = row_counts(comm_, rank_, size_, balls.size(), pairs.size());
  const std::vector<std::uint64_t>&nb = n.balls, &np = n.pairs;
  if (rank_ == 0 && sink.begin) sink.begin(n.total_balls, n.total_pairs);

  // the balls, merged by id; rank 0 keeps the ids (8 bytes a ball) to turn a pair's ids into rows
  std::vector<std::uint64_t> ids;
  if (rank_ == 0) ids.reserve(n.total_balls);
  Snapshot out;
  std::size_t row0 = 0;
  auto flush_balls = [&] {
    if (out.id.empty()) return;
    if (sink.balls) sink.balls(row0, out);
    row0 += out.id.size();
    out.position.clear(), out.velocity.clear(), out.radius.clear(), out.id.clear();
  };
  merge_on_root(comm_, rank_, size_, kTagFrameBalls, block, balls, nb,
                [](const FrameBall& x, const FrameBall& y) { return x.id < y.id; },
                [&](const FrameBall& b) {
                  out.position.insert(out.position.end(), {b.x.x, b.x.y, b.x.z});
                  out.velocity.insert(out.velocity.end(), {b.v.x, b.v.y, b.v.z});
                  out.radius.push_back(b.r);
                  out.id.push_back(b.id);
                  ids.push_back(b.id);
                  if (out.id.size() == block) flush_balls();
                });
  flush_balls();
  // the pairs, merged by (A, B) id, their ends as rows of the frame
  auto row_of = [&](std::uint64_t id) {
    const auto it = std::lower_bound(ids.begin(), ids.end(), id);
    if (it == ids.end() || *it != id)
      throw std::logic_error("DistDem::stream_snapshot: a pair's ball " + std::to_string(id) + " is no rank's");
    return static_cast<std::uint32_t>(it - ids.begin());
  };
  row0 = 0;
  auto flush_pairs = [&] {
    if (out.state.empty()) return;
    if (sink.pairs) sink.pairs(row0, out);
    row0 += out.state.size();
    out.pair.clear(), out.force.clear(), out.state.clear();
  };
  merge_on_root(comm_, rank_, size_, kTagFramePairs, block, pairs, np, pair_less, [&](const FramePair& c) {
    out.pair.insert(out.pair.end(), {row_of(c.a), row_of(c.b)});
    out.force.insert(out.force.end(), {c.f.x, c.f.y, c.f.z});
    out.state.push_back(c.state);
    if (out.state.size() == block) flush_pairs();
  });
  flush_pairs();
}


// ------------------------------------------------------------------------------------------
// unload: one World from the ranks' parts

namespace {

// One wall contact with every field one World holds (its candidate facets follow the record).
struct WallFullRec {
  std::uint64_t id;
  std::uint32_t wall, ncand;
  std::int32_t facet;
  std::uint8_t kind;
  ContactHist h;
  BondHist b;
  Vec3 F, M, TA, xc, bary;
};

// A ball-ball list from pair records in their order, their ends turned into rows by `row_of`
// (ids or file rows, as the records hold them); bond histories when the law bonds.
template <class RowOf>
PairContacts pair_list(const std::vector<PairRec>& recs, bool bonds, RowOf row_of) {
  PairContacts pc;
  for (const PairRec& c : recs) {
    pc.a.push_back(row_of(c.ia));
    pc.b.push_back(row_of(c.ib));
    pc.shift.push_back(c.s);
    pc.h.push_back(c.h);
    if (bonds) pc.bond.push_back(c.b);
  }
  return pc;
}

// Wall contacts from their records, appended to their kinds' lists in the order given: each
// record's candidate facets from `cand`, its ball a row (`row_of`). close_walls then gives a
// list without contacts its one offset, as a World's has.
template <class RowOf>
void append_wall(std::array<WallContacts, 3>& nwc, const WorldParams& p, const WallFullRec& c, const std::uint32_t* cand,
                 RowOf row_of) {
  WallContacts& wc = nwc[c.kind];
  if (wc.cand_off.empty()) wc.cand_off.push_back(0);
  wc.ball.push_back(row_of(c.id));
  wc.wall.push_back(c.wall);
  wc.facet.push_back(c.facet);
  wc.cand.insert(wc.cand.end(), cand, cand + c.ncand);
  wc.cand_off.push_back(static_cast<std::uint32_t>(wc.cand.size()));
  wc.h.push_back(c.h);
  if (kind_bonds(p, c.kind)) wc.bond.push_back(c.b);
  wc.F.push_back(c.F), wc.M.push_back(c.M), wc.TA.push_back(c.TA), wc.xc.push_back(c.xc), wc.bary.push_back(c.bary);
}
void close_walls(std::array<WallContacts, 3>& nwc) {
  for (WallContacts& wc : nwc)
    if (wc.cand_off.empty()) wc.cand_off.push_back(0);
}

}  // namespace

// This rank's wall contacts (with their candidate facets), its energies of damping and dropped
// contacts, and its bond failures: the part of unload's and save_state_file's records that
// rank 0 reads whole (wall contacts scale with the walls, not with the block).
void DistDem::put_part_tail(std::vector<char>& out) const {
  const Particles& pt = w_->balls();
  std::vector<WallFullRec> walls;
  std::vector<std::uint32_t> cands;
  const auto lists = wall_lists(*w_);
  for (int kind = 0; kind < 3; ++kind) {
    const WallContacts& wc = *lists[static_cast<std::size_t>(kind)];
    for (std::size_t c = 0; c < wc.size(); ++c) {
      const std::uint32_t c0 = wc.cand_off.empty() ? 0 : wc.cand_off[c], c1 = wc.cand_off.empty() ? 0 : wc.cand_off[c + 1];
      walls.push_back(WallFullRec{pt.id[wc.ball[c]], wc.wall[c], c1 - c0, wc.facet[c], static_cast<std::uint8_t>(kind),
                                  wc.h[c], wc.bond.empty() ? BondHist{} : wc.bond[c], wc.F[c], wc.M[c], wc.TA[c],
                                  wc.xc[c], wc.bary[c]});
      cands.insert(cands.end(), wc.cand.begin() + c0, wc.cand.begin() + c1);
    }
  }
  const World::Counters mine = w_->counters();
  put_recs(out, walls);
  put_recs(out, cands);
  put_recs(out, std::vector<double>{mine.e_damp, mine.e_slip_dead, mine.e_soft_dead});
  put_recs(out, std::vector<std::int64_t>{mine.bond_failures});
}

// Every rank's tails, read in rank order (rank 0).
struct DistDem::Tails {
  std::vector<WallFullRec> walls;
  std::vector<std::uint32_t> cands;
  std::vector<std::size_t> cand_at;  // per wall record: where its candidates start in cands
  World::Counters k;                 // rank 0's, with the ranks' energies and bond failures summed
  explicit Tails(const World::Counters& mine) : k(mine) {
    k.bond_failures = 0, k.e_damp = k.e_slip_dead = k.e_soft_dead = 0.0;
  }
  const char* read(const char* q) {
    const std::size_t w0 = walls.size();
    q = get_recs(q, walls);
    const std::size_t c0 = cands.size();
    q = get_recs(q, cands);
    std::size_t at = c0;
    for (std::size_t j = w0; j < walls.size(); ++j) cand_at.push_back(at), at += walls[j].ncand;
    std::vector<double> e;
    q = get_recs(q, e);
    std::vector<std::int64_t> f;
    q = get_recs(q, f);
    // the ranks' energies in rank order (not one World's order: docs/scaling.md)
    k.e_damp += e[0], k.e_slip_dead += e[1], k.e_soft_dead += e[2];
    k.bond_failures += f[0];
    return q;
  }
  // One World's wall-contact lists: by (kind, ball id, wall), their balls as rows (`row_of`).
  template <class RowOf>
  std::array<WallContacts, 3> lists(const WorldParams& p, RowOf row_of) const {
    std::vector<std::uint32_t> wo(walls.size());
    std::iota(wo.begin(), wo.end(), 0u);
    std::sort(wo.begin(), wo.end(), [&](std::uint32_t x, std::uint32_t y) {
      return std::tie(walls[x].kind, walls[x].id, walls[x].wall) < std::tie(walls[y].kind, walls[y].id, walls[y].wall);
    });
    std::array<WallContacts, 3> nwc;
    for (std::uint32_t j : wo) append_wall(nwc, p, walls[j], cands.data() + cand_at[j], row_of);
    close_walls(nwc);
    return nwc;
  }
};

// What unload gives `full` besides its balls and contacts: the walls, the stepped World's
// parameters (with `full`'s own thread settings and skin) and the counters `k`.
void DistDem::finish_full(World& full, World::Counters k, double max_disp2) const {
  const World::Counters mine = w_->counters();
  full.copy_walls(*w_);
  // The full world's own parameters, but the step and the cell of the stepped one.
  const WorldParams own = full.params();
  full.mutable_params() = w_->params();
  full.mutable_params().threads = own.threads;
  full.mutable_params().thread_independent = own.thread_independent;
  full.mutable_params().order_free_sums = own.order_free_sums;
  full.mutable_params().skin = own.skin;
  const World::Counters before = full.counters();
  // (the ranks add no ball, but a replicated block's next id is past its copies: load_replicated)
  k.next_id = std::max(before.next_id, mine.next_id), k.next_wall_id = before.next_wall_id;
  k.max_disp2 = max_disp2;
  full.set_counters(k);
}

void DistDem::unload(World& full, bool root_only) const {
  const Particles& pt = w_->balls();
  const auto& g = w_->ghost_rows();
  auto owned_row = [&](std::size_t i) { return g.empty() || !g[i]; };
  // this rank's part: its balls, the pairs whose ball A it owns, its balls' wall contacts
  std::vector<BallRec> balls;
  for (std::size_t i = 0; i < pt.size(); ++i)
    if (owned_row(i)) balls.push_back(ball_rec(pt, i));
  std::vector<PairRec> pairs;
  const PairContacts& pc = w_->pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c)
    if (owned_row(pc.a[c]))
      pairs.push_back(PairRec{pt.id[pc.a[c]], pt.id[pc.b[c]], pc.shift[c], pc.h[c], pc.bond.empty() ? BondHist{} : pc.bond[c]});
  std::vector<char> out;
  put_recs(out, balls);
  put_recs(out, pairs);
  put_part_tail(out);
  // every rank gets every part (root_only: rank 0 alone, each part in messages of at most 1 GiB,
  // so that a whole World beyond 2 GiB, which an int cannot count, is assembled)
  std::vector<long long> displ(static_cast<std::size_t>(size_) + 1, 0);
  std::vector<char> in;
  double run = run_disp2_, max_disp2 = 0.0;
  if (root_only) {
    long long bytes = static_cast<long long>(out.size());
    std::vector<long long> counts(static_cast<std::size_t>(size_));
    MPI_Gather(&bytes, 1, MPI_LONG_LONG, counts.data(), 1, MPI_LONG_LONG, 0, comm_);
    if (rank_ != 0) {
      for (long long at = 0; at < bytes; at += chunk_)
        MPI_Send(out.data() + at, static_cast<int>(std::min(chunk_, bytes - at)), MPI_BYTE, 0, kTagPart, comm_);
      MPI_Reduce(&run, &max_disp2, 1, MPI_DOUBLE, MPI_MAX, 0, comm_);
      return;
    }
    for (int r = 0; r < size_; ++r)
      displ[static_cast<std::size_t>(r) + 1] = displ[static_cast<std::size_t>(r)] + counts[static_cast<std::size_t>(r)];
    in.resize(static_cast<std::size_t>(displ.back()));
    std::copy(out.begin(), out.end(), in.begin());
    for (int r = 1; r < size_; ++r)
      for (long long at = 0; at < counts[static_cast<std::size_t>(r)]; at += chunk_)
        MPI_Recv(in.data() + displ[static_cast<std::size_t>(r)] + at,
                 static_cast<int>(std::min(chunk_, counts[static_cast<std::size_t>(r)] - at)), MPI_BYTE, r, kTagPart,
                 comm_, MPI_STATUS_IGNORE);
    MPI_Reduce(&run, &max_disp2, 1, MPI_DOUBLE, MPI_MAX, 0, comm_);
  } else {
    const int bytes = static_cast<int>(out.size());
    std::vector<int> counts(static_cast<std::size_t>(size_)), di(static_cast<std::size_t>(size_) + 1, 0);
    MPI_Allgather(&bytes, 1, MPI_INT, counts.data(), 1, MPI_INT, comm_);
    for (int r = 0; r < size_; ++r) {
      di[static_cast<std::size_t>(r) + 1] = di[static_cast<std::size_t>(r)] + counts[static_cast<std::size_t>(r)];
      displ[static_cast<std::size_t>(r) + 1] = di[static_cast<std::size_t>(r) + 1];
    }
    in.resize(static_cast<std::size_t>(displ.back()));
    MPI_Allgatherv(out.data(), bytes, MPI_BYTE, in.data(), counts.data(), di.data(), MPI_BYTE, comm_);
    MPI_Allreduce(&run, &max_disp2, 1, MPI_DOUBLE, MPI_MAX, comm_);
  }

  std::vector<BallRec> ab;
  std::vector<PairRec> ap;
  Tails tails(w_->counters());
  for (int r = 0; r < size_; ++r) {
    const char* q = in.data() + displ[static_cast<std::size_t>(r)];
    q = get_recs(q, ab);
    q = get_recs(q, ap);
    tails.read(q);
  }
  // One World's orders: balls by id, pairs by (A, B) id, wall contacts by (kind, ball id, wall).
  std::sort(ab.begin(), ab.end(), [](const BallRec& x, const BallRec& y) { return x.id < y.id; });
  std::sort(ap.begin(), ap.end(), [](const PairRec& x, const PairRec& y) { return std::tie(x.ia, x.ib) < std::tie(y.ia, y.ib); });
  Particles np;
  std::vector<std::uint64_t> ids;
  for (const BallRec& b : ab) push_ball(np, b), ids.push_back(b.id);
  auto row_of = [&](std::uint64_t id) {
    return static_cast<std::uint32_t>(std::lower_bound(ids.begin(), ids.end(), id) - ids.begin());
  };
  PairContacts npc = pair_list(ap, law_has_bond(w_->params().ball_ball.model), row_of);
  std::array<WallContacts, 3> nwc = tails.lists(w_->params(), row_of);
  std::vector<std::uint8_t> ghost;
  full.swap_balls(np, npc, nwc, ghost);
  finish_full(full, tails.k, max_disp2);
}

// ------------------------------------------------------------------------------------------
// save_state_file: one World's state file from the ranks' parts, merged on rank 0 in blocks

namespace {
constexpr int kTagStateBalls = 7306, kTagStatePairs = 7307;
}  // namespace

void DistDem::save_state_file(World& full, const std::filesystem::path& path, const CheckpointMeta& meta,
                              std::size_t block) const {
  // (a block's bytes must fit an int; 64 MiB messages at most)
  block = std::max<std::size_t>(1, std::min<std::size_t>(block, (std::size_t{64} << 20) / sizeof(PairRec)));
  const Particles& pt = w_->balls();
  const auto& g = w_->ghost_rows();
  auto owned_row = [&](std::size_t i) { return g.empty() || !g[i]; };
  // this rank's rows in one World's orders (unload's): its balls by id, the pairs whose ball A it
  // owns by (A, B) id. They are already in these orders where the rows are in id order (newton
  // off) and the pair list follows its rows: then they are made a block at a time from the part's
  // rows, not copied whole; else they are copied and sorted.
  const PairContacts& pc = w_->pair_contacts();
  auto pair_rec = [&](std::size_t c) {
    return PairRec{pt.id[pc.a[c]], pt.id[pc.b[c]], pc.shift[c], pc.h[c], pc.bond.empty() ? BondHist{} : pc.bond[c]};
  };
  auto pair_less = [](const PairRec& x, const PairRec& y) { return std::tie(x.ia, x.ib) < std::tie(y.ia, y.ib); };
  std::uint64_t nballs = 0, npairs = 0;
  bool in_order = true;
  {
    std::uint64_t last = 0;
    for (std::size_t i = 0; i < pt.size(); ++i)
      if (owned_row(i)) {
        in_order = in_order && (nballs == 0 || pt.id[i] > last);
        last = pt.id[i], ++nballs;
      }
    std::pair<std::uint64_t, std::uint64_t> lastp{0, 0};
    for (std::size_t c = 0; c < pc.size(); ++c)
      if (owned_row(pc.a[c])) {
        const std::pair<std::uint64_t, std::uint64_t> k{pt.id[pc.a[c]], pt.id[pc.b[c]]};
        in_order = in_order && (npairs == 0 || k > lastp);
        lastp = k, ++npairs;
      }
  }
  std::vector<BallRec> balls;
  std::vector<PairRec> pairs;
  RecordSource<BallRec> ball_src;
  RecordSource<PairRec> pair_src;
  if (in_order) {
    ball_src = [&, i = std::size_t{0}](std::vector<BallRec>& buf, std::size_t n) mutable {
      buf.clear();
      for (; i < pt.size() && buf.size() < n; ++i)
        if (owned_row(i)) buf.push_back(ball_rec(pt, i));
    };
    pair_src = [&, c = std::size_t{0}](std::vector<PairRec>& buf, std::size_t n) mutable {
      buf.clear();
      for (; c < pc.size() && buf.size() < n; ++c)
        if (owned_row(pc.a[c])) buf.push_back(pair_rec(c));
    };
  } else {
    for (std::size_t i = 0; i < pt.size(); ++i)
      if (owned_row(i)) balls.push_back(ball_rec(pt, i));
    std::sort(balls.begin(), balls.end(), [](const BallRec& x, const BallRec& y) { return x.id < y.id; });
    for (std::size_t c = 0; c < pc.size(); ++c)
      if (owned_row(pc.a[c])) pairs.push_back(pair_rec(c));
    std::sort(pairs.begin(), pairs.end(), pair_less);
    ball_src = source_of(balls);
    pair_src = source_of(pairs);
  }
  // counts, the tails (wall contacts, energies, failures) and the largest displacement on rank 0
  const RowCounts counted = row_counts(comm_, rank_, size_, nballs, npairs);
  const std::vector<std::uint64_t>&nb = counted.balls, &np = counted.pairs;
  const std::uint64_t total_balls = counted.total_balls, total_pairs = counted.total_pairs;
  std::vector<char> tail, tails_in;
  put_part_tail(tail);
  std::vector<std::size_t> starts;
  gather_on_root(comm_, tail, tails_in, &starts);
  double run = run_disp2_, max_disp2 = 0.0;
  MPI_Reduce(&run, &max_disp2, 1, MPI_DOUBLE, MPI_MAX, 0, comm_);
  // Rank 0 writes; after its first error it only drains the merges, and every rank then throws
  // (the others name rank 0's error, which rank 0 throws).
  std::unique_ptr<StateStream> st;
  FirstError guarded;  // (rank 0's first error; the calls after it are skipped)
  std::exception_ptr& failed = guarded.failed;
  Tails tails(w_->counters());
  if (rank_ == 0)
    guarded([&] {
      for (int r = 0; r < size_; ++r) tails.read(tails_in.data() + starts[static_cast<std::size_t>(r)]);
      finish_full(full, tails.k, max_disp2);
      st = std::make_unique<StateStream>(path, full, total_balls, total_pairs, meta);
    });
  // the balls, merged by id; rank 0 keeps the ids (8 bytes a ball) to turn ids into rows
  std::vector<std::uint64_t> ids;
  if (rank_ == 0) ids.reserve(total_balls);
  Particles rows;
  auto flush_balls = [&] {
    if (rows.size() == 0) return;
    guarded([&] { st->balls(rows); });
    rows = Particles{};
  };
  merge_on_root<BallRec>(comm_, rank_, size_, kTagStateBalls, block, std::move(ball_src), nballs, nb,
                [](const BallRec& x, const BallRec& y) { return x.id < y.id; },
                [&](const BallRec& b) {
                  ids.push_back(b.id);
                  if (failed) return;
                  push_ball(rows, b);
                  if (rows.size() == block) flush_balls();
                });
  flush_balls();
  auto row_of = [&](std::uint64_t id) {
    const auto it = std::lower_bound(ids.begin(), ids.end(), id);
    if (it == ids.end() || *it != id)
      throw std::logic_error("DistDem::save_state_file: a contact's ball " + std::to_string(id) + " is no rank's");
    return static_cast<std::uint32_t>(it - ids.begin());
  };
  const bool pair_bonds = law_has_bond(w_->params().ball_ball.model);
  PairContacts prow;
  auto flush_pairs = [&] {
    if (prow.size() == 0) return;
    guarded([&] { st->pairs(prow); });
    prow = PairContacts{};
  };
  merge_on_root<PairRec>(comm_, rank_, size_, kTagStatePairs, block, std::move(pair_src), npairs, np, pair_less, [&](const PairRec& c) {
    if (failed) return;
    guarded([&] {
      prow.a.push_back(row_of(c.ia));
      prow.b.push_back(row_of(c.ib));
    });
    prow.shift.push_back(c.s);
    prow.h.push_back(c.h);
    if (pair_bonds) prow.bond.push_back(c.b);
    if (prow.size() == block) flush_pairs();
  });
  flush_pairs();
  if (rank_ == 0)
    guarded([&] {
      const std::array<WallContacts, 3> nwc = tails.lists(w_->params(), row_of);
      st->commit(nwc[0], nwc[1], nwc[2]);
    });
  share_failure(comm_, rank_, failed, "DistDem::save_state_file: rank 0 could not write " + path.string());
}

// ------------------------------------------------------------------------------------------
// load_state_file: the ranks' parts from one World's state file, read by rank 0 in blocks

namespace {
constexpr int kTagLoadBalls = 7308, kTagLoadPairs = 7309, kTagLoadWalls = 7310;
constexpr const char* kLoadFailed = "rank 0 could not load the state";

struct BallLoadRec {
  std::uint64_t row;  // the ball's row in the file
  BallRec b;
};

// Rank 0 sends `recs` (rank r's records of one phase) to rank r; an empty vector is the phase's end.
template <class R>
void send_recs(MPI_Comm comm, int r, int tag, const std::vector<R>& recs) {
  MPI_Send(recs.data(), static_cast<int>(recs.size() * sizeof(R)), MPI_BYTE, r, tag, comm);
}
// A rank's records of one phase, appended to `out` until the phase's end.
template <class R>
void recv_recs(MPI_Comm comm, int tag, std::vector<R>& out) {
  for (;;) {
    MPI_Status st;
    MPI_Probe(0, tag, comm, &st);
    int bytes = 0;
    MPI_Get_count(&st, MPI_BYTE, &bytes);
    const std::size_t n = static_cast<std::size_t>(bytes) / sizeof(R), at = out.size();
    out.resize(at + n);
    MPI_Recv(out.data() + at, bytes, MPI_BYTE, 0, tag, comm, MPI_STATUS_IGNORE);
    if (n == 0) return;
  }
}
// One phase of records from rank 0 to the ranks: rank 0 runs `produce(out, flush)` under
// `guarded`, which fills out[r] with rank r's records and calls flush() after each block (rank
// r's are sent, rank 0's kept in `mine`), then ends the phase on every rank, also after an
// error; the other ranks receive theirs into `mine`. Collective.
template <class R, class Guarded, class Produce>
void scatter_from_root(MPI_Comm comm, int rank, int size, int tag, Guarded& guarded, Produce produce, std::vector<R>& mine) {
  if (rank != 0) {
    recv_recs(comm, tag, mine);
    return;
  }
  std::vector<std::vector<R>> out(static_cast<std::size_t>(size));
  auto flush = [&] {
    for (int r = 1; r < size; ++r)
      if (!out[static_cast<std::size_t>(r)].empty())
        send_recs(comm, r, tag, out[static_cast<std::size_t>(r)]), out[static_cast<std::size_t>(r)].clear();
    mine.insert(mine.end(), out[0].begin(), out[0].end());
    out[0].clear();
  };
  guarded([&] { produce(out, flush); });
  for (int r = 1; r < size; ++r) send_recs(comm, r, tag, std::vector<R>{});
}
}  // namespace

void DistDem::load_state_file(World& frame, const std::filesystem::path& path, std::uint64_t scene_hash,
                              std::vector<std::uint64_t>* ids, std::size_t block) {
  std::unique_ptr<StateSource> src;
  FirstError opened;
  if (rank_ == 0) opened([&] { src = std::make_unique<StateSource>(path, scene_hash); });
  share_failure(comm_, rank_, opened.failed, kLoadFailed);
  load_state(frame, src.get(), path.string(), scene_hash, ids, block);
}

void DistDem::load_state(World& frame, const StateSource* src, const std::string& source, std::uint64_t scene_hash,
                         std::vector<std::uint64_t>* ids, std::size_t block) {
  block = std::max<std::size_t>(1, std::min<std::size_t>(block, (std::size_t{64} << 20) / sizeof(BallLoadRec)));
  const std::size_t P = static_cast<std::size_t>(size_);
  FirstError guarded;  // (rank 0's first error; the calls after it are skipped)
  std::exception_ptr& failed = guarded.failed;
  // Rank 0: the frame, the largest radius (the halo), each ball's owner and the rows of the
  // balls its pairs need on another rank (a pair's partner: cut's rule), from the positions,
  // radii, ids and the pairs' rows alone.
  std::string frame_bytes;
  double rmax = 0.0;
  std::vector<std::int32_t> owner;                          // per file row (4 bytes a ball)
  std::vector<std::pair<std::uint64_t, std::int32_t>> extra;  // (row, rank): a partner on another rank
  if (rank_ == 0)
    guarded([&] {
      if (!src) throw std::logic_error("DistDem::load_state: rank 0 has no state to read");
      frame_bytes = src->frame_bytes();
      const std::uint64_t n = src->balls(), m = src->pairs();
      owner.reserve(static_cast<std::size_t>(n));
      if (ids) ids->clear(), ids->reserve(static_cast<std::size_t>(n));
      std::vector<Vec3> x;
      std::vector<double> r;
      std::vector<std::uint64_t> id;
      std::uint64_t last = 0;
      for (std::uint64_t r0 = 0; r0 < n; r0 += block) {
        src->read_positions(r0, static_cast<std::size_t>(std::min<std::uint64_t>(block, n - r0)), x, r, id);
        for (std::size_t i = 0; i < x.size(); ++i) {
          if (r0 + i > 0 && !(id[i] > last))
            throw std::invalid_argument(source + ": the balls' rows are not in id order (DistDem::load_state)");
          last = id[i];
          rmax = std::max(rmax, r[i]);
          owner.push_back(grid_.owner(x[i]));
          if (ids) ids->push_back(id[i]);
        }
      }
      std::vector<std::uint32_t> a, b;
      for (std::uint64_t c0 = 0; c0 < m; c0 += block) {
        src->read_pair_rows(c0, static_cast<std::size_t>(std::min<std::uint64_t>(block, m - c0)), a, b);
        for (std::size_t c = 0; c < a.size(); ++c) {
          const std::int32_t oa = owner[a[c]], ob = owner[b[c]];
          if (ob == oa) continue;
          extra.push_back({b[c], oa});
          if (!newton_) extra.push_back({a[c], ob});
        }
      }
      std::sort(extra.begin(), extra.end());
      extra.erase(std::unique(extra.begin(), extra.end()), extra.end());
    });
  share_failure(comm_, rank_, failed, kLoadFailed);
  // Every rank: the frame (parameters, counters, effects, walls) and the halo.
  long long fb = static_cast<long long>(frame_bytes.size());
  MPI_Bcast(&fb, 1, MPI_LONG_LONG, 0, comm_);
  frame_bytes.resize(static_cast<std::size_t>(fb));
  for (long long at = 0; at < fb; at += chunk_)
    MPI_Bcast(frame_bytes.data() + at, static_cast<int>(std::min(chunk_, fb - at)), MPI_CHAR, 0, comm_);
  double hk[2] = {rmax, static_cast<double>(static_cast<int>(frame.pair_kernel()))};
  MPI_Bcast(hk, 2, MPI_DOUBLE, 0, comm_);
  rmax = hk[0];
  load_state_bytes(frame, frame_bytes, scene_hash, source);
  auto share = std::make_unique<World>(frame.params());
  load_state_bytes(*share, std::move(frame_bytes), scene_hash, source);
  share->set_pair_kernel(static_cast<PairKernel>(static_cast<int>(hk[1])));
  params_from(*share, rmax);
  // The balls: each to every rank whose part holds it (cut's rule: within the halo of the
  // rank's brick, its owner, a partner of the rank's pairs), with its file row.
  std::vector<BallLoadRec> mine;
  scatter_from_root<BallLoadRec>(comm_, rank_, size_, kTagLoadBalls, guarded, [&](auto& out, auto flush) {
    const std::uint64_t n = src->balls();
    Particles b;
    std::vector<int> nb;
    std::size_t e = 0;
    for (std::uint64_t r0 = 0; r0 < n; r0 += block) {
      src->read_balls(r0, static_cast<std::size_t>(std::min<std::uint64_t>(block, n - r0)), b);
      for (std::size_t i = 0; i < b.size(); ++i) {
        const std::uint64_t row = r0 + i;
        const int o = owner[row];
        grid_.near(b.x[i], halo_, nb);
        if (std::find(nb.begin(), nb.end(), o) == nb.end()) nb.push_back(o);
        for (; e < extra.size() && extra[e].first == row; ++e)
          if (std::find(nb.begin(), nb.end(), extra[e].second) == nb.end()) nb.push_back(extra[e].second);
        for (int r : nb) out[static_cast<std::size_t>(r)].push_back(BallLoadRec{row, ball_rec(b, i)});
      }
      flush();
    }
  }, mine);
  share_failure(comm_, rank_, failed, kLoadFailed);
  // The pairs: to the owner of ball A, and with newton off to the owner of ball B too; their
  // ends as file rows (PairRec's ia, ib).
  std::vector<PairRec> pairs;
  scatter_from_root<PairRec>(comm_, rank_, size_, kTagLoadPairs, guarded, [&](auto& out, auto flush) {
    const std::uint64_t m = src->pairs();
    PairContacts b;
    for (std::uint64_t c0 = 0; c0 < m; c0 += block) {
      src->read_pairs(c0, static_cast<std::size_t>(std::min<std::uint64_t>(block, m - c0)), b);
      for (std::size_t c = 0; c < b.size(); ++c) {
        const int oa = owner[b.a[c]], ob = owner[b.b[c]];
        const PairRec rec{b.a[c], b.b[c], b.shift[c], b.h[c], b.bond.empty() ? BondHist{} : b.bond[c]};
        out[static_cast<std::size_t>(oa)].push_back(rec);
        if (!newton_ && ob != oa) out[static_cast<std::size_t>(ob)].push_back(rec);
      }
      flush();
    }
  }, pairs);
  share_failure(comm_, rank_, failed, kLoadFailed);
  // The wall contacts (whole on rank 0): each to its ball's owner, with its candidate facets.
  std::vector<char> walls_in;
  if (rank_ == 0) {
    std::vector<std::vector<WallFullRec>> recs(P);
    std::vector<std::vector<std::uint32_t>> cands(P);
    guarded([&] {
      const std::array<WallContacts, 3> wl = src->read_wall_contacts();
      for (int kind = 0; kind < 3; ++kind) {
        const WallContacts& wc = wl[static_cast<std::size_t>(kind)];
        for (std::size_t c = 0; c < wc.size(); ++c) {
          const std::size_t r = static_cast<std::size_t>(owner[wc.ball[c]]);
          const std::uint32_t c0 = wc.cand_off[c], c1 = wc.cand_off[c + 1];
          recs[r].push_back(WallFullRec{wc.ball[c], wc.wall[c], c1 - c0, wc.facet[c], static_cast<std::uint8_t>(kind), wc.h[c],
                                        wc.bond.empty() ? BondHist{} : wc.bond[c], wc.F[c], wc.M[c], wc.TA[c], wc.xc[c],
                                        wc.bary[c]});
          cands[r].insert(cands[r].end(), wc.cand.begin() + c0, wc.cand.begin() + c1);
        }
      }
    });
    for (std::size_t r = 0; r < P; ++r) {
      std::vector<char> bytes;
      put_recs(bytes, recs[r]);
      put_recs(bytes, cands[r]);
      if (r == 0) walls_in = std::move(bytes);
      else send_recs(comm_, static_cast<int>(r), kTagLoadWalls, bytes);
    }
  } else {
    MPI_Status st;
    MPI_Probe(0, kTagLoadWalls, comm_, &st);
    int bytes = 0;
    MPI_Get_count(&st, MPI_BYTE, &bytes);
    walls_in.resize(static_cast<std::size_t>(bytes));
    MPI_Recv(walls_in.data(), bytes, MPI_BYTE, 0, kTagLoadWalls, comm_, MPI_STATUS_IGNORE);
  }
  share_failure(comm_, rank_, failed, kLoadFailed);
  owner = {};
  extra = {};
  // This rank's share of the World: its balls in file order, its pairs and wall contacts with
  // their ends as rows of the share. Cut as load cuts the whole World, it gives the same part.
  std::vector<std::uint64_t> rows;
  Particles pt;
  for (const BallLoadRec& b : mine) rows.push_back(b.row), push_ball(pt, b.b);
  mine = {};
  auto row_of = [&](std::uint64_t row) {
    const auto it = std::lower_bound(rows.begin(), rows.end(), row);
    if (it == rows.end() || *it != row) throw std::logic_error("DistDem::load_state_file: a contact's ball is not in the rank's share");
    return static_cast<std::uint32_t>(it - rows.begin());
  };
  PairContacts pc = pair_list(pairs, law_has_bond(share->params().ball_ball.model), row_of);
  pairs = {};
  std::vector<WallFullRec> wr;
  std::vector<std::uint32_t> wcand;
  get_recs(get_recs(walls_in.data(), wr), wcand);
  std::array<WallContacts, 3> wc;
  std::size_t at = 0;
  for (const WallFullRec& c : wr) {  // (in the file's order, kind by kind)
    append_wall(wc, share->params(), c, wcand.data() + at, row_of);
    at += c.ncand;
  }
  close_walls(wc);
  const World::Counters k = share->counters();
  std::vector<std::uint8_t> no_ghosts;
  share->swap_balls(pt, pc, wc, no_ghosts);
  share->set_counters(k);
  const std::vector<PlatenServoParams> platens = loadable(*share);
  take(part_of(*share, cut(*share, false), rank_, platens), !platens.empty());
}

}  // namespace demfdm::dem
