// The neighbour search as a unit (neighbour_grid.hpp): the cell grid finds exactly the pairs a
// brute-force search over all pairs finds, with the same image shifts, sorted by (a, b); in a
// free domain, a periodic cell and a cell only just above twice the cut-off.
#include <gtest/gtest.h>

#include <random>
#include <tuple>
#include <vector>

#include "demfdm/dem/neighbour_grid.hpp"

using namespace demfdm::dem;

namespace {

struct Packing {
  std::vector<Vec3> x;
  std::vector<double> r;
};

// n balls of radius in [r0, 2 r0] at uniform positions in the box [0, L)^3.
Packing random_packing(std::size_t n, double L, double r0, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Packing p;
  for (std::size_t i = 0; i < n; ++i) {
    p.x.push_back({L * u(rng), L * u(rng), L * u(rng)});
    p.r.push_back(r0 * (1.0 + u(rng)));
  }
  return p;
}

// Every pair (a < b) tested directly, with the search's criterion and minimum image.
std::vector<PairCandidate> brute_force(const Packing& p, double skin, const PeriodicParams& per) {
  std::vector<PairCandidate> out;
  const Vec3 L = per.length, half = 0.5 * per.length;
  for (std::uint32_t a = 0; a < p.x.size(); ++a)
    for (std::uint32_t b = a + 1; b < p.x.size(); ++b) {
      Vec3 d = p.x[b] - p.x[a];
      std::array<std::int8_t, 4> s{0, 0, 0, 0};
      if (per.enabled)
        for (int k = 0; k < 3; ++k) {
          const double e = d[k];
          d[k] = e > half[k] ? e - L[k] : (e < -half[k] ? e + L[k] : e);
          s[k] = static_cast<std::int8_t>(e > half[k] ? -1 : (e < -half[k] ? 1 : 0));
        }
      const double rc = p.r[a] + skin + p.r[b];
      if (norm2(d) < rc * rc) out.push_back({a, b, s});
    }
  return out;
}

bool same(const std::vector<PairCandidate>& x, const std::vector<PairCandidate>& y) {
  if (x.size() != y.size()) return false;
  for (std::size_t c = 0; c < x.size(); ++c)
    if (x[c].a != y[c].a || x[c].b != y[c].b || x[c].s != y[c].s) return false;
  return true;
}

}  // namespace

TEST(NeighbourGrid, FindsExactlyTheBruteForcePairsInAFreeDomain) {
  const auto p = random_packing(1500, 1.0, 0.02, 3);
  const auto got = find_pair_candidates(p.x, p.r, 0.01, PeriodicParams{});
  const auto want = brute_force(p, 0.01, PeriodicParams{});
  EXPECT_GT(want.size(), 1000u) << "a test with pairs to find";
  EXPECT_TRUE(same(got, want)) << got.size() << " pairs found, " << want.size() << " by brute force";
  for (std::size_t c = 1; c < got.size(); ++c)
    ASSERT_LT(std::tie(got[c - 1].a, got[c - 1].b), std::tie(got[c].a, got[c].b)) << "sorted by (a, b)";
}

TEST(NeighbourGrid, FindsExactlyTheBruteForcePairsAndImagesInAPeriodicCell) {
  PeriodicParams per;
  per.enabled = true;
  per.length = {1.0, 1.0, 1.0};
  const auto p = random_packing(1500, 1.0, 0.02, 5);
  const auto got = find_pair_candidates(p.x, p.r, 0.01, per);
  const auto want = brute_force(p, 0.01, per);
  std::size_t across = 0;
  for (const auto& c : want) across += c.s[0] != 0 || c.s[1] != 0 || c.s[2] != 0;
  EXPECT_GT(across, 20u) << "pairs across the cell's faces";
  EXPECT_TRUE(same(got, want)) << got.size() << " pairs found, " << want.size() << " by brute force";
  // Large balls: the cut-off 2 R_max + skin is close to half the cell, so the grid has two cells
  // per axis and a cell's left and right neighbours are the same cell (searched once).
  const auto q = random_packing(60, 1.0, 0.1, 7);
  EXPECT_TRUE(same(find_pair_candidates(q.x, q.r, 0.05, per), brute_force(q, 0.05, per)));
  // A cell thinner than twice the cut-off is refused naming the axis.
  per.length = {1.0, 1.0, 0.5};
  try {
    (void)find_pair_candidates(q.x, q.r, 0.05, per);
    ADD_FAILURE() << "a cell thinner than twice the cut-off was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("periodic.length[2]"), std::string::npos) << e.what();
  }
}
