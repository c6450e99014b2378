// Ball-ball neighbour search (neighbour_grid.hpp; docs/theory.md 1.4).
//
// The balls are copied into cell order as separate x, y, z, R and row arrays (structure of
// arrays); cells are a quarter of the cut-off along x, one cut-off along y and z. A ball searches
// the cells within its own reach R_i + skin + R_max on each axis, so each x-row of its search is
// one contiguous range (two when a periodic wrap splits it), with no search for the first
// j > i: every candidate gets the branch-free test (j > i) & (d2 < rc^2), four at a time where
// AVX2 is available, and the rare hits are taken from the lane mask (docs/speed.md, issue 16
// item 3). The arithmetic of the test is the same sequence of operations in every build (no
// fused multiply-add: the project compiles with -ffp-contract=off and the AVX2 region uses
// separate multiplies and adds), so every build finds the same pairs as a brute-force test of
// every pair (tests/dem/neighbour_grid_test.cpp).
#include "demfdm/dem/neighbour_grid.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#if defined(__x86_64__) || defined(__i386__)
#include <immintrin.h>
#define DEMFDM_GRID_X86 1
#endif

namespace demfdm::dem {

namespace {

// A contiguous run of the cell-ordered arrays: the cells first .. first + count - 1 of one
// x-row of the stencil (consecutive cell numbers).
struct Run {
  std::uint32_t first, count;
};

// The cell-ordered copy of the balls and what a ball's row of pairs needs from it.
struct Sorted {
  // x, y, z, R and the row number (as a double: exact below 2^53, compared in the same lanes)
  // in cell order, 4 padding entries at the end (row -1: never j > i) so that a block of four
  // may run past a range's end; the lanes past it are masked.
  std::vector<double> x, y, z, r, row;
  std::vector<std::uint32_t> cell_start;  // cell c holds sorted entries [cell_start[c], cell_start[c+1])
  std::vector<std::uint32_t> cell_last;   // the largest row in cell c (0 for an empty cell)
};

// The work arrays of a search.
struct Scratch {
  Sorted s;
  std::vector<std::int32_t> cell_of;
  std::vector<std::uint32_t> fill, rank, order;
  std::vector<double> hits, hit_row;
};

// One ball's row: the hits (rows j > i) of the runs, their places in the cell-ordered arrays
// written to `hits` in the order found (as doubles; the caller sorts them by row and works out
// the image shifts). `hits` has room for every candidate of the row plus 4.
struct RowArgs {
  const Sorted* s;
  const Run* runs;
  int nruns;
  std::uint32_t i;
  Vec3 xi;
  double ri;  // R_i + skin
  Vec3 L, halfL;
  double* hits;
};

// The image shift of a hit, as the scalar search has always worked it out.
inline std::array<std::int8_t, 4> image_shift(const Vec3& pj, const Vec3& xi, const Vec3& halfL) {
  std::array<std::int8_t, 4> s{0, 0, 0, 0};
  for (int a = 0; a < 3; ++a) {
    const double e = pj[a] - xi[a];
    s[a] = static_cast<std::int8_t>(int(e < -halfL[a]) - int(e > halfL[a]));  // -1, 0 or 1 (not both)
  }
  return s;
}

// The range [begin, end) of the cell-ordered arrays a run covers for ball i: cells at the ends
// of the run whose balls all come before i (or that are empty) are left out.
inline bool trim(const Sorted& s, const Run& run, std::uint32_t i, std::uint32_t& begin, std::uint32_t& end) {
  std::uint32_t c0 = run.first, c1 = run.first + run.count;
  while (c0 < c1 && s.cell_last[c0] <= i) ++c0;
  while (c1 > c0 && s.cell_last[c1 - 1] <= i) --c1;
  begin = s.cell_start[c0];
  end = s.cell_start[c1];
  return begin < end;
}

// Baseline: one candidate at a time, the same operations as the vector lanes. Returns the
// number of hits.
template <bool Per>
std::size_t row_scalar(const RowArgs& a) {
  const Sorted& s = *a.s;
  const double fi = static_cast<double>(a.i);
  std::size_t nh = 0;
  for (int q = 0; q < a.nruns; ++q) {
    std::uint32_t b, e;
    if (!trim(s, a.runs[q], a.i, b, e)) continue;
    for (std::uint32_t k = b; k < e; ++k) {
      double dx = s.x[k] - a.xi.x, dy = s.y[k] - a.xi.y, dz = s.z[k] - a.xi.z;
      // minimum image as selects
      if constexpr (Per) {
        dx = dx > a.halfL.x ? dx - a.L.x : (dx < -a.halfL.x ? dx + a.L.x : dx);
        dy = dy > a.halfL.y ? dy - a.L.y : (dy < -a.halfL.y ? dy + a.L.y : dy);
        dz = dz > a.halfL.z ? dz - a.L.z : (dz < -a.halfL.z ? dz + a.L.z : dz);
      }
      const double d2 = dx * dx + dy * dy + dz * dz;
      const double rc = a.ri + s.r[k];
      if ((s.row[k] > fi) & (d2 < rc * rc)) a.hits[nh++] = static_cast<double>(k);
    }
  }
  return nh;
}

// The rank of each of a row's nh hits by row number (how many are smaller; each j once):
// rank[h] for the rows j[0..nh), which are followed by 4 entries +inf.
void rank_scalar(const double* j, std::size_t nh, std::uint32_t* rank) {
  for (std::size_t h = 0; h < nh; ++h) {
    std::uint32_t r = 0;
    for (std::size_t g = 0; g < nh; ++g) r += j[g] < j[h];
    rank[h] = r;
  }
}

#ifdef DEMFDM_GRID_X86
#pragma GCC push_options
#pragma GCC target("avx2")
// The minimum image as selects: d > h ? d - L : (d < -h ? d + L : d).
[[gnu::always_inline]] inline __m256d image(__m256d d, __m256d L, __m256d h, __m256d mh) {
  const __m256d over = _mm256_cmp_pd(d, h, _CMP_GT_OQ), under = _mm256_cmp_pd(d, mh, _CMP_LT_OQ);
  const __m256d low = _mm256_blendv_pd(d, _mm256_add_pd(d, L), under);
  return _mm256_blendv_pd(low, _mm256_sub_pd(d, L), over);
}

// Moves the lanes of a 4-bit mask to the front: 32-bit lane indices for a permute of four
// doubles (lanes 2l and 2l + 1 for double l).
alignas(32) constexpr std::int32_t kCompress[16][8] = {
    {0, 1, 0, 1, 0, 1, 0, 1}, {0, 1, 0, 1, 0, 1, 0, 1}, {2, 3, 0, 1, 0, 1, 0, 1}, {0, 1, 2, 3, 0, 1, 0, 1},
    {4, 5, 0, 1, 0, 1, 0, 1}, {0, 1, 4, 5, 0, 1, 0, 1}, {2, 3, 4, 5, 0, 1, 0, 1}, {0, 1, 2, 3, 4, 5, 0, 1},
    {6, 7, 0, 1, 0, 1, 0, 1}, {0, 1, 6, 7, 0, 1, 0, 1}, {2, 3, 6, 7, 0, 1, 0, 1}, {0, 1, 2, 3, 6, 7, 0, 1},
    {4, 5, 6, 7, 0, 1, 0, 1}, {0, 1, 4, 5, 6, 7, 0, 1}, {2, 3, 4, 5, 6, 7, 0, 1}, {0, 1, 2, 3, 4, 5, 6, 7}};

// trim() for a run of at most 8 cells: the cells with a row after i, as one mask.
[[gnu::always_inline]] inline bool trim_avx2(const Sorted& s, const Run& run, std::uint32_t i, std::uint32_t& begin,
                                              std::uint32_t& end) {
  if (run.count > 8) return trim(s, run, i, begin, end);
  const __m256i sign = _mm256_set1_epi32(static_cast<int>(0x80000000u));
  const __m256i last = _mm256_xor_si256(
      _mm256_loadu_si256(reinterpret_cast<const __m256i*>(s.cell_last.data() + run.first)), sign);
  const __m256i after = _mm256_cmpgt_epi32(last, _mm256_xor_si256(_mm256_set1_epi32(static_cast<int>(i)), sign));
  const unsigned m = static_cast<unsigned>(_mm256_movemask_ps(_mm256_castsi256_ps(after))) & ((1u << run.count) - 1u);
  if (m == 0) return false;
  begin = s.cell_start[run.first + static_cast<unsigned>(__builtin_ctz(m))];
  end = s.cell_start[run.first + 32u - static_cast<unsigned>(__builtin_clz(m))];
  return true;
}

// AVX2: four candidates per block. Multiplies and adds are separate instructions (no FMA is
// enabled here), in the order of the scalar test: ((dx dx + dy dy) + dz dz) < (ri + R_j)^2.
// The hit lanes' rows are moved to the front and stored without a branch.
template <bool Per>
std::size_t row_avx2(const RowArgs& a) {
  const Sorted& s = *a.s;
  std::size_t nh = 0;
  const __m256d xi = _mm256_set1_pd(a.xi.x), yi = _mm256_set1_pd(a.xi.y), zi = _mm256_set1_pd(a.xi.z);
  const __m256d ri = _mm256_set1_pd(a.ri), fi = _mm256_set1_pd(static_cast<double>(a.i));
  const __m256d Lx = _mm256_set1_pd(a.L.x), Ly = _mm256_set1_pd(a.L.y), Lz = _mm256_set1_pd(a.L.z);
  const __m256d hx = _mm256_set1_pd(a.halfL.x), hy = _mm256_set1_pd(a.halfL.y), hz = _mm256_set1_pd(a.halfL.z);
  const __m256d mhx = _mm256_set1_pd(-a.halfL.x), mhy = _mm256_set1_pd(-a.halfL.y),
                mhz = _mm256_set1_pd(-a.halfL.z);
  const __m256d lane = _mm256_set_pd(3.0, 2.0, 1.0, 0.0);
  const double* px = s.x.data();
  const double* py = s.y.data();
  const double* pz = s.z.data();
  const double* pr = s.r.data();
  const double* pj = s.row.data();
  for (int q = 0; q < a.nruns; ++q) {
    std::uint32_t b, e;
    if (!trim_avx2(s, a.runs[q], a.i, b, e)) continue;
    const __m256d ev = _mm256_set1_pd(static_cast<double>(e));
    for (std::uint32_t k = b; k < e; k += 4) {
      const __m256d kv = _mm256_add_pd(_mm256_set1_pd(static_cast<double>(k)), lane);
      __m256d dx = _mm256_sub_pd(_mm256_loadu_pd(px + k), xi);
      __m256d dy = _mm256_sub_pd(_mm256_loadu_pd(py + k), yi);
      __m256d dz = _mm256_sub_pd(_mm256_loadu_pd(pz + k), zi);
      if constexpr (Per) {
        dx = image(dx, Lx, hx, mhx);
        dy = image(dy, Ly, hy, mhy);
        dz = image(dz, Lz, hz, mhz);
      }
      const __m256d d2 =
          _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)), _mm256_mul_pd(dz, dz));
      const __m256d rc = _mm256_add_pd(ri, _mm256_loadu_pd(pr + k));
      const __m256d jv = _mm256_loadu_pd(pj + k);
      __m256d hit = _mm256_and_pd(_mm256_cmp_pd(jv, fi, _CMP_GT_OQ),
                                  _mm256_cmp_pd(d2, _mm256_mul_pd(rc, rc), _CMP_LT_OQ));
      // lanes past the range's end belong to the next cells (or the padding): not candidates here
      hit = _mm256_and_pd(hit, _mm256_cmp_pd(kv, ev, _CMP_LT_OQ));
      const unsigned m = static_cast<unsigned>(_mm256_movemask_pd(hit));
      const __m256i perm = _mm256_load_si256(reinterpret_cast<const __m256i*>(kCompress[m]));
      _mm256_storeu_pd(a.hits + nh, _mm256_castps_pd(_mm256_permutevar8x32_ps(_mm256_castpd_ps(kv), perm)));
      nh += static_cast<unsigned>(__builtin_popcount(m));
    }
  }
  return nh;
}
// rank_scalar four hits at a time: every g compared with a block of four h, counts summed in
// the lanes (exact small integers). Every block runs nh steps: no branch varies within a row.
void rank_avx2(const double* j, std::size_t nh, std::uint32_t* rank) {
  const __m256d one = _mm256_set1_pd(1.0);
  for (std::size_t h = 0; h < nh; h += 4) {
    const __m256d jh = _mm256_loadu_pd(j + h);
    __m256d r = _mm256_setzero_pd();
    for (std::size_t g = 0; g < nh; ++g)
      r = _mm256_add_pd(r, _mm256_and_pd(_mm256_cmp_pd(_mm256_broadcast_sd(j + g), jh, _CMP_LT_OQ), one));
    const __m128i r32 = _mm256_cvttpd_epi32(r);
    _mm_storeu_si128(reinterpret_cast<__m128i*>(rank + h), r32);
  }
}
#pragma GCC pop_options
#endif

bool use_avx2(SearchIsa isa) {
#ifdef DEMFDM_GRID_X86
  static const bool has = __builtin_cpu_supports("avx2");
  return isa != SearchIsa::kBaseline && has;
#else
  (void)isa;
  return false;
#endif
}

}  // namespace

bool search_isa_available(SearchIsa isa) {
  return isa == SearchIsa::kBaseline || use_avx2(isa);
}

std::vector<PairCandidate> find_pair_candidates(const std::vector<Vec3>& pos, const std::vector<double>& rad,
                                                double skin, const PeriodicParams& periodic, std::size_t reserve) {
  return find_pair_candidates(pos, rad, skin, periodic, reserve, SearchIsa::kBest);
}

std::vector<PairCandidate> find_pair_candidates(const std::vector<Vec3>& pos, const std::vector<double>& rad,
                                                double skin, const PeriodicParams& periodic, std::size_t reserve,
                                                SearchIsa isa) {
  std::vector<PairCandidate> np;
  find_pair_candidates(pos, rad, skin, periodic, reserve, isa, np);
  return np;
}

void find_pair_candidates(const std::vector<Vec3>& pos, const std::vector<double>& rad, double skin,
                          const PeriodicParams& periodic, std::size_t reserve, SearchIsa isa,
                          std::vector<PairCandidate>& np) {
  np.clear();
  const std::size_t n = pos.size();
  const bool per = periodic.enabled;
  const Vec3 o = periodic.origin, L = periodic.length;
  double rmax = 0.0;
  for (double ri : rad) rmax = std::max(rmax, ri);
  const double cut = 2.0 * rmax + skin;
  // cell grid
  Vec3 lo{}, hi{};
  if (per) {
    lo = o;
    hi = o + L;
    for (int k = 0; k < 3; ++k)
      if (L[k] < 2.0 * cut) {
        std::ostringstream s;
        s << "periodic.length[" << k << "] = " << L[k] << " m must be at least twice the "
          << "neighbour cut-off 2(2 R_max + skin) = " << 2.0 * cut << " m (minimum image, §4.2).";
        throw std::invalid_argument(s.str());
      }
  } else if (n > 0) {
    lo = hi = pos[0];
    for (std::size_t i = 1; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], pos[i][k]);
        hi[k] = std::max(hi[k], pos[i][k]);
      }
  }
  // Cells: kSplitX per cut-off along x, one per cut-off along y and z. A ball's search covers,
  // per axis, the cells of [x_i - reach_i, x_i + reach_i], reach_i = (R_i + skin) + R_max (the
  // largest R_i + skin + R_j), widened by a margin far above the rounding of the cell numbers; the
  // thin x-cells make a ball's x-rows hardly longer than twice its reach.
  constexpr int kSplitX = 4;
  int nc[3];
  double cs[3], margin[3];
  for (int k = 0; k < 3; ++k) {
    const double ext = hi[k] - lo[k];
    const double w = k == 0 ? cut / kSplitX : cut;
    if (per) nc[k] = std::max(1, static_cast<int>(std::floor(ext / w)));
    else nc[k] = std::max(1, std::min(1024, static_cast<int>(std::ceil(ext / w))));
    cs[k] = per ? ext / nc[k] : std::max(w, ext / nc[k]);
    margin[k] = 1e-9 * (cut + std::abs(lo[k]) + std::abs(hi[k]));
  }
  const std::size_t ncell = static_cast<std::size_t>(nc[0]) * nc[1] * nc[2];
  // Work arrays kept from call to call in this thread (a rebuild would otherwise take about
  // 90 bytes per ball of fresh pages from the system each time).
  thread_local Scratch scratch;
  Sorted& s = scratch.s;
  std::vector<std::int32_t>& cell_of = scratch.cell_of;
  cell_of.resize(n);
  s.cell_start.assign(ncell + 1, 0);
  // The cell number along axis k of a coordinate u: floor((u - lo) / cs) up to rounding, as
  // trunc((u - lo) * (1 / cs) + 64) - 64 (no library floor; u is never 64 cells below lo). Any
  // rounding is harmless: the balls' cells and the search ranges come from the same monotone
  // function, and the ranges' margin is far wider than its rounding.
  double inv_cs[3];
  for (int k = 0; k < 3; ++k) inv_cs[k] = 1.0 / cs[k];
  auto cell_floor = [&](double u, int k) { return static_cast<int>((u - lo[k]) * inv_cs[k] + 64.0) - 64; };
  auto cidx = [&](const Vec3& x, int k) { return std::clamp(cell_floor(x[k], k), 0, nc[k] - 1); };
  for (std::size_t i = 0; i < n; ++i) {
    const int c = (cidx(pos[i], 2) * nc[1] + cidx(pos[i], 1)) * nc[0] + cidx(pos[i], 0);
    cell_of[i] = c;
    ++s.cell_start[static_cast<std::size_t>(c) + 1];
  }
  for (std::size_t c = 0; c < ncell; ++c) s.cell_start[c + 1] += s.cell_start[c];
  // the cell-ordered copy; within a cell in ascending row order
  constexpr std::size_t kPad = 4;
  s.x.assign(n + kPad, 0.0);
  s.y.assign(n + kPad, 0.0);
  s.z.assign(n + kPad, 0.0);
  s.r.assign(n + kPad, 0.0);
  s.row.assign(n + kPad, -1.0);
  s.cell_last.assign(ncell + 8, 0);  // 8 more: trim_avx2 loads 8 at a time
  {
    std::vector<std::uint32_t>& fill = scratch.fill;
    fill.assign(s.cell_start.begin(), s.cell_start.end() - 1);
    for (std::size_t i = 0; i < n; ++i) {
      const std::uint32_t k = fill[cell_of[i]]++;
      s.x[k] = pos[i].x;
      s.y[k] = pos[i].y;
      s.z[k] = pos[i].z;
      s.r[k] = rad[i];
      s.row[k] = static_cast<double>(i);
      s.cell_last[cell_of[i]] = static_cast<std::uint32_t>(i);
    }
  }
  const bool vec = use_avx2(isa);
  std::size_t (*row)(const RowArgs&) = per ? &row_scalar<true> : &row_scalar<false>;
  std::size_t (*row_plain)(const RowArgs&) = &row_scalar<false>;  // no minimum image
  void (*rank_of)(const double*, std::size_t, std::uint32_t*) = &rank_scalar;
#ifdef DEMFDM_GRID_X86
  if (vec) {
    row = per ? &row_avx2<true> : &row_avx2<false>;
    row_plain = &row_avx2<false>;
    rank_of = &rank_avx2;
  }
#endif
  // The cells of axis k a ball at u with reach `reach` searches, each once, as runs of
  // consecutive cell numbers (first, count); returns the number of runs (at most 2: a periodic
  // wrap splits the range).
  auto axis_runs = [&](int k, double u, double reach, int first[2], int count[2]) {
    int a = cell_floor(u - (reach + margin[k]), k), b = cell_floor(u + (reach + margin[k]), k);
    if (!per) {
      a = std::clamp(a, 0, nc[k] - 1);
      b = std::clamp(b, 0, nc[k] - 1);
    } else if (b - a + 1 >= nc[k]) {
      a = 0;
      b = nc[k] - 1;
    }
    if (a < 0) {  // [a + nc, nc - 1] and [0, b]
      first[0] = a + nc[k], count[0] = -a, first[1] = 0, count[1] = b + 1;
      return 2;
    }
    if (b >= nc[k]) {  // [a, nc - 1] and [0, b - nc]
      first[0] = a, count[0] = nc[k] - a, first[1] = 0, count[1] = b - nc[k] + 1;
      return 2;
    }
    first[0] = a, count[0] = b - a + 1;
    return 1;
  };
  // candidate pairs (i < j), row by row. Positions are wrapped, so the minimum image needs at
  // most one cell shift per axis.
  if (np.capacity() < reserve) np.reserve(reserve + reserve / 4);  // room to grow: see PairSet::rebuild
  RowArgs ra{};
  ra.s = &s;
  ra.L = L;
  ra.halfL = 0.5 * L;  // the same products as 0.5 * L[a]
  std::vector<double>& hits = scratch.hits;  // a row has fewer than n hits
  std::vector<double>& hit_row = scratch.hit_row;
  std::vector<std::uint32_t>& rank = scratch.rank;
  std::vector<std::uint32_t>& order = scratch.order;
  for (auto* v : {&hits, &hit_row}) v->resize(n + kPad);
  for (auto* v : {&rank, &order}) v->resize(n + kPad);
  ra.hits = hits.data();
  Run runs[8 * 8 * 2];
  ra.runs = runs;
  for (std::size_t i = 0; i < n; ++i) {
    const double reach = (rad[i] + skin) + rmax;
    int f[3][2], m[3][2], nrun[3];
    // In a periodic cell, a ball whose searched cells lie within 0.99 L/2 of it on every axis
    // (no wrap) has no candidate farther than L/2: the minimum-image selects would change
    // nothing and every image shift is 0, so the test without them gives the same bits.
    bool plain = true;
    for (int k = 0; k < 3; ++k) {
      nrun[k] = axis_runs(k, pos[i][k], reach, f[k], m[k]);
      if (per) {
        const double below = pos[i][k] - (lo[k] + f[k][0] * cs[k]);
        const double above = (lo[k] + (f[k][0] + m[k][0]) * cs[k]) - pos[i][k];
        plain &= nrun[k] == 1 && below < 0.99 * ra.halfL[k] && above < 0.99 * ra.halfL[k];
      }
    }
    int nr = 0;
    for (int zr = 0; zr < nrun[2]; ++zr)
      for (int z = f[2][zr]; z < f[2][zr] + m[2][zr]; ++z)
        for (int yr = 0; yr < nrun[1]; ++yr)
          for (int y = f[1][yr]; y < f[1][yr] + m[1][yr]; ++y) {
            const std::size_t base = (static_cast<std::size_t>(z) * nc[1] + y) * nc[0];
            for (int xr = 0; xr < nrun[0]; ++xr)
              runs[nr++] = {static_cast<std::uint32_t>(base + f[0][xr]), static_cast<std::uint32_t>(m[0][xr])};
          }
    ra.nruns = nr;
    ra.i = static_cast<std::uint32_t>(i);
    ra.xi = pos[i];
    ra.ri = rad[i] + skin;
    const std::size_t nh = plain ? row_plain(ra) : row(ra);
    // The row's partners in ascending order: each to its rank. Rows come in order of i, so the
    // list is sorted by (i, j).
    for (std::size_t h = 0; h < nh; ++h) hit_row[h] = s.row[static_cast<std::size_t>(hits[h])];
    for (std::size_t h = nh; h < nh + kPad; ++h) hit_row[h] = std::numeric_limits<double>::infinity();
    rank_of(hit_row.data(), nh, rank.data());
    for (std::size_t h = 0; h < nh; ++h) order[rank[h]] = static_cast<std::uint32_t>(hits[h]);
    const std::size_t at = np.size();
    np.resize(at + nh);
    for (std::size_t h = 0; h < nh; ++h) {
      const std::uint32_t k = order[h];
      const std::array<std::int8_t, 4> none{0, 0, 0, 0};
      np[at + h] = {ra.i, static_cast<std::uint32_t>(s.row[k]),
                    plain ? none : image_shift({s.x[k], s.y[k], s.z[k]}, ra.xi, ra.halfL)};
    }
  }
  // A sparse free domain can have far more cells than balls: do not keep such cell arrays.
  if (ncell > 8 * n + 65536) {
    for (auto* v : {&s.cell_start, &s.cell_last, &scratch.fill}) std::vector<std::uint32_t>().swap(*v);
  }
}

}  // namespace demfdm::dem
