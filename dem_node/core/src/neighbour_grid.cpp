// Ball-ball neighbour search (neighbour_grid.hpp; docs/theory.md 1.4).
#include "demfdm/dem/neighbour_grid.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace demfdm::dem {

std::vector<PairCandidate> find_pair_candidates(const std::vector<Vec3>& pos, const std::vector<double>& rad,
                                                double skin, const PeriodicParams& periodic, std::size_t reserve) {
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
  int nc[3];
  double cs[3];
  for (int k = 0; k < 3; ++k) {
    const double ext = hi[k] - lo[k];
    if (per) nc[k] = std::max(1, static_cast<int>(std::floor(ext / cut)));
    else nc[k] = std::max(1, std::min(1024, static_cast<int>(std::ceil(ext / cut))));
    cs[k] = per ? ext / nc[k] : std::max(cut, ext / nc[k]);
  }
  const std::size_t ncell = static_cast<std::size_t>(nc[0]) * nc[1] * nc[2];
  std::vector<std::int32_t> cell_of(n);
  std::vector<std::uint32_t> cell_start(ncell + 1, 0), cell_items(n);
  auto cidx = [&](const Vec3& x, int k) {
    int c = static_cast<int>(std::floor((x[k] - lo[k]) / cs[k]));
    return std::clamp(c, 0, nc[k] - 1);
  };
  for (std::size_t i = 0; i < n; ++i) {
    const int c = (cidx(pos[i], 2) * nc[1] + cidx(pos[i], 1)) * nc[0] + cidx(pos[i], 0);
    cell_of[i] = c;
    ++cell_start[static_cast<std::size_t>(c) + 1];
  }
  for (std::size_t c = 0; c < ncell; ++c) cell_start[c + 1] += cell_start[c];
  {
    std::vector<std::uint32_t> fill(cell_start.begin(), cell_start.end() - 1);
    for (std::size_t i = 0; i < n; ++i) cell_items[fill[cell_of[i]]++] = static_cast<std::uint32_t>(i);
  }
  // candidate pairs (i < j), then one sort by (i, j). Positions are wrapped, so the
  // minimum image needs at most one cell shift per axis.
  std::vector<PairCandidate> np;
  np.reserve(reserve);
  const Vec3 halfL = 0.5 * L;  // the same products as 0.5 * L[a]
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t row_begin = np.size();
    const int c = cell_of[i];
    const int ci[3] = {c % nc[0], (c / nc[0]) % nc[1], c / (nc[0] * nc[1])};
    int lists[3][3] = {}, cnt[3] = {};
    for (int k = 0; k < 3; ++k) {
      for (int d = -1; d <= 1; ++d) {
        int q = ci[k] + d;
        if (per) q = (q % nc[k] + nc[k]) % nc[k];
        else if (q < 0 || q >= nc[k]) continue;
        bool dup = false;
        for (int m = 0; m < cnt[k]; ++m) dup |= lists[k][m] == q;
        if (!dup) lists[k][cnt[k]++] = q;
      }
    }
    const Vec3 xi = pos[i];
    const double ri = rad[i] + skin;
    for (int z = 0; z < cnt[2]; ++z)
      for (int y = 0; y < cnt[1]; ++y)
        for (int x = 0; x < cnt[0]; ++x) {
          const std::size_t cc = (static_cast<std::size_t>(lists[2][z]) * nc[1] + lists[1][y]) * nc[0] + lists[0][x];
          // A cell lists its balls in ascending order: start after i (only j > i is a new pair).
          const std::uint32_t* first = cell_items.data() + cell_start[cc];
          const std::uint32_t* last = cell_items.data() + cell_start[cc + 1];
          for (const std::uint32_t* it = std::upper_bound(first, last, static_cast<std::uint32_t>(i)); it != last;
               ++it) {
            const std::uint32_t j = *it;
            Vec3 d = pos[j] - xi;
            // minimum image as selects (no unpredictable branch per candidate); the image
            // shift is only worked out for the few candidates within reach
            if (per)
              for (int a = 0; a < 3; ++a) d[a] = d[a] > halfL[a] ? d[a] - L[a] : (d[a] < -halfL[a] ? d[a] + L[a] : d[a]);
            const double rc = ri + rad[j];
            if (norm2(d) < rc * rc) {
              std::array<std::int8_t, 4> s{0, 0, 0, 0};
              if (per)
                for (int a = 0; a < 3; ++a) {
                  const double e = pos[j][a] - xi[a];
                  s[a] = static_cast<std::int8_t>(e > halfL[a] ? -1 : (e < -halfL[a] ? 1 : 0));
                }
              np.push_back({static_cast<std::uint32_t>(i), j, s});
            }
          }
        }
    // Rows come in order of i, so sorting each row's partners by j sorts the list by (i, j)
    // (each j is found once per i: every cell is visited once).
    std::sort(np.begin() + static_cast<std::ptrdiff_t>(row_begin), np.end(),
              [](const PairCandidate& p, const PairCandidate& q) { return p.b < q.b; });
  }
  return np;
}

}  // namespace demfdm::dem
