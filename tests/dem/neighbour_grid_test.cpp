// The neighbour search as a unit (neighbour_grid.hpp): the cell grid finds exactly the pairs a
// brute-force search over all pairs finds, with the same image shifts, sorted by (a, b); in a
// free domain, a periodic cell and a cell only just above twice the cut-off.
#include <gtest/gtest.h>

#include <cmath>
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

namespace {

const SearchIsa kIsas[] = {SearchIsa::kBaseline, SearchIsa::kAvx2, SearchIsa::kBest};

const char* isa_name(SearchIsa isa) {
  return isa == SearchIsa::kBaseline ? "baseline" : (isa == SearchIsa::kAvx2 ? "avx2" : "best");
}

// A polydisperse packing like the bench's (radii over a factor 2.75, dense: several balls per
// cell, many pairs), rows in random order with respect to the cells.
Packing polydisperse(std::size_t n, const Vec3& box, double rmin, double rmax, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Packing p;
  for (std::size_t i = 0; i < n; ++i) {
    p.x.push_back({box.x * u(rng), box.y * u(rng), box.z * u(rng)});
    p.r.push_back(rmin + (rmax - rmin) * u(rng) * u(rng));
  }
  return p;
}

}  // namespace

// Every instruction set of the candidate test finds the brute-force list: a dense polydisperse
// periodic packing (flat cell, pairs across every face), a free cluster, small counts that leave
// partial blocks of four, and two cells per axis (a row's left and right cells the same cell).
TEST(NeighbourGrid, EveryInstructionSetFindsTheBruteForcePairs) {
  PeriodicParams per;
  per.enabled = true;
  per.length = {0.6, 0.6, 0.3};
  const auto dense = polydisperse(6000, per.length, 0.008, 0.022, 11);
  const auto want_dense = brute_force(dense, 0.004, per);
  EXPECT_GT(want_dense.size(), 8000u);
  const auto cluster = polydisperse(3000, {0.2, 0.15, 0.1}, 0.004, 0.011, 13);
  const auto want_cluster = brute_force(cluster, 0.002, PeriodicParams{});
  EXPECT_GT(want_cluster.size(), 5000u);
  PeriodicParams per2;
  per2.enabled = true;
  per2.length = {1.0, 1.0, 1.0};
  const auto two = random_packing(61, 1.0, 0.1, 17);
  const auto want_two = brute_force(two, 0.05, per2);
  for (SearchIsa isa : kIsas) {
    SCOPED_TRACE(isa_name(isa));
    const auto got = find_pair_candidates(dense.x, dense.r, 0.004, per, 0, isa);
    EXPECT_TRUE(same(got, want_dense)) << got.size() << " pairs found, " << want_dense.size() << " by brute force";
    const auto gotc = find_pair_candidates(cluster.x, cluster.r, 0.002, PeriodicParams{}, 0, isa);
    EXPECT_TRUE(same(gotc, want_cluster)) << gotc.size() << " pairs found, " << want_cluster.size();
    EXPECT_TRUE(same(find_pair_candidates(two.x, two.r, 0.05, per2, 0, isa), want_two));
    for (std::size_t m : {0u, 1u, 2u, 3u, 5u, 7u}) {
      Packing q = random_packing(m, 0.05, 0.01, 19 + static_cast<unsigned>(m));
      EXPECT_TRUE(same(find_pair_candidates(q.x, q.r, 0.01, PeriodicParams{}, 0, isa), brute_force(q, 0.01, {})))
          << m << " balls";
    }
  }
}

// The test is strict (a pair exactly at R_a + skin + R_b is not a pair) and sums the radii as
// (R_a + skin) + R_b with a the lower row: radii chosen so that the two orders of the sum round
// differently, and a ball placed at exactly the smaller sum, are found as a pair only when the
// larger sum is R_lower + skin first. Many far-away balls put these pairs in all lanes of a block.
TEST(NeighbourGrid, TheCutOffIsStrictAndSumsTheRadiiInRowOrder) {
  std::mt19937_64 rng(23);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const double skin = 0.0173;
  Packing p;
  std::size_t hits = 0, misses = 0;
  for (int c = 0; c < 40; ++c) {
    // two radii whose sums in the two orders differ in the last bit
    double ra = 0, rb = 0, up = 0, down = 0;
    do {
      ra = 0.01 + 0.02 * u(rng);
      rb = 0.01 + 0.02 * u(rng);
      up = (ra + skin) + rb;
      down = (rb + skin) + ra;
    } while (up == down || up * up == down * down);
    const double gap = std::min(up, down);
    // a at x = 0 (so that d_x = gap exactly), the pairs 0.5 apart in y and z
    const Vec3 base{0.0, 0.5 * (c % 8), 0.5 * (c / 8)};
    // rows: a = lower row with radius ra, b with rb, b at exactly `gap` along x
    p.x.push_back(base);
    p.r.push_back(ra);
    p.x.push_back(base + Vec3{gap, 0.0, 0.0});
    p.r.push_back(rb);
    // a pair iff gap^2 < ((ra + skin) + rb)^2, i.e. iff up > down (else exactly at the cut-off)
    (up > down ? hits : misses) += 1;
  }
  EXPECT_GT(hits, 5u);
  EXPECT_GT(misses, 5u);
  const auto want = brute_force(p, skin, PeriodicParams{});
  std::size_t gap_pairs = 0;
  for (const auto& c : want) gap_pairs += c.b == c.a + 1 && c.a % 2 == 0;
  EXPECT_EQ(gap_pairs, hits);
  for (SearchIsa isa : kIsas) {
    SCOPED_TRACE(isa_name(isa));
    const auto got = find_pair_candidates(p.x, p.r, skin, PeriodicParams{}, 0, isa);
    EXPECT_TRUE(same(got, want)) << got.size() << " pairs found, " << want.size() << " by brute force";
  }
}

// Pairs just inside the cut-off in every direction, of the largest balls (the reach of a search
// is R_i + skin + R_max: it has no slack for them), next to pairs just outside it: a search that
// reaches any less far, or cells that miss a neighbour, loses pairs here. Periodic (pairs across
// the faces) and free.
TEST(NeighbourGrid, FindsPairsOfTheLargestBallsJustInsideTheCutOff) {
  std::mt19937_64 rng(29);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  const double R = 0.02, skin = 0.004, cut = 2.0 * R + skin;
  PeriodicParams per;
  per.enabled = true;
  per.length = {0.7, 0.6, 0.5};
  Packing p;
  for (int c = 0; c < 1500; ++c) {
    Vec3 dir{g(rng), g(rng), g(rng)};
    dir = (1.0 / norm(dir)) * dir;
    const double dist = cut * (c % 2 == 0 ? 1.0 - 1e-9 : 1.0 + 1e-9);
    const Vec3 a{per.length.x * u(rng), per.length.y * u(rng), per.length.z * u(rng)};
    Vec3 b = a + dist * dir;
    for (int k = 0; k < 3; ++k) b[k] -= per.length[k] * std::floor(b[k] / per.length[k]);  // wrapped
    p.x.push_back(a);
    p.r.push_back(R);
    p.x.push_back(b);
    p.r.push_back(R);
  }
  const auto want = brute_force(p, skin, per);
  std::size_t across = 0;
  for (const auto& c : want) across += c.s[0] != 0 || c.s[1] != 0 || c.s[2] != 0;
  EXPECT_GT(want.size(), 700u);
  EXPECT_GT(across, 50u);
  // the same balls in a free domain (no images)
  const auto want_free = brute_force(p, skin, PeriodicParams{});
  for (SearchIsa isa : kIsas) {
    SCOPED_TRACE(isa_name(isa));
    const auto got = find_pair_candidates(p.x, p.r, skin, per, 0, isa);
    EXPECT_TRUE(same(got, want)) << got.size() << " pairs found, " << want.size() << " by brute force";
    const auto got_free = find_pair_candidates(p.x, p.r, skin, PeriodicParams{}, 0, isa);
    EXPECT_TRUE(same(got_free, want_free)) << got_free.size() << " pairs found, " << want_free.size();
  }
}
