// A/B comparison inside one run (bench_dem BENCH_DEM_AB, bench_measure BENCH_MEASURE_HOSTED=ab):
// the two variants alternate in blocks of steps, A B B A A B B A ..., so that a drift of the
// host's speed favours neither; each pair of neighbouring blocks (A B or B A) gives one ratio of
// A's time to B's (docs/speed.md, session 35).
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

namespace demfdm::bench {

/// Whether block `blk` runs variant A (blocks A B B A A B B A ...).
inline bool ab_block_is_a(int blk) { return ((blk + 1) / 2) % 2 == 0; }

struct AbRatios {
  double mean = 0.0, se = 0.0;  // of A's time over B's, per pair of neighbouring blocks
  std::size_t pairs = 0;
  double a = 0.0, b = 0.0;  // the two variants' times, summed over the pairs
};

/// The ratios of the complete pairs (0, 1), (2, 3), ... of `block_time` (one time per block, in
/// block order).
inline AbRatios ab_ratios(const std::vector<double>& block_time) {
  AbRatios r;
  std::vector<double> q;
  for (std::size_t blk = 0; blk + 1 < block_time.size(); blk += 2) {
    const bool a_first = ab_block_is_a(static_cast<int>(blk));
    const double ta = a_first ? block_time[blk] : block_time[blk + 1];
    const double tb = a_first ? block_time[blk + 1] : block_time[blk];
    q.push_back(ta / tb);
    r.a += ta, r.b += tb;
  }
  const double n = static_cast<double>(q.size());
  r.pairs = q.size();
  for (double x : q) r.mean += x / n;
  double v = 0.0;
  for (double x : q) v += (x - r.mean) * (x - r.mean) / (n - 1.0);
  r.se = q.size() > 1 ? std::sqrt(v / n) : 0.0;
  return r;
}

}  // namespace demfdm::bench
