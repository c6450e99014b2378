// Ball-ball neighbour search (docs/theory.md 1.4): a cell grid over the balls, each ball's
// cells within its reach R + skin + R_max searched once (contiguous x-rows of a cell-ordered
// copy; docs/speed.md issue 16 item 3), every pair whose centres are closer than
// R_a + R_b + skin listed. A unit of its own: World::rebuild() calls it, then carries the
// contact history over to the pairs it finds (world_detail.hpp HistoryCarry).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "demfdm/dem/params.hpp"
#include "demfdm/dem/vec3.hpp"

namespace demfdm::dem {

/// A pair found by the search: rows a < b and, in a periodic cell, the image of b across the
/// cell (s[k] in {-1, 0, 1}: b interacts at x_b + s[k] L[k]; s[3] is unused, 0).
struct PairCandidate {
  std::uint32_t a, b;
  std::array<std::int8_t, 4> s;
};

/// Every pair (a < b) with |x_b − x_a| < R_a + skin + R_b (minimum image in a periodic cell),
/// sorted by (a, b). In a periodic cell the positions must lie in [o, o + L) (World wraps them
/// first) and each length L[k] must be at least twice the cut-off 2 R_max + skin, else
/// std::invalid_argument naming the axis. Cells: a quarter of the cut-off along x, about the
/// cut-off along y and z, at most 1024 per axis in a free domain. `reserve`: expected number
/// of pairs (the previous list's size).
std::vector<PairCandidate> find_pair_candidates(const std::vector<Vec3>& x, const std::vector<double>& r, double skin,
                                                const PeriodicParams& periodic, std::size_t reserve = 0);

/// The instruction set of the candidate test: kBest is AVX2 where the processor has it, else the
/// baseline (one candidate at a time). Every choice gives the same list (the same operations in
/// the same order, no fused multiply-add); the choice is for the tests that check this.
enum class SearchIsa { kBest, kBaseline, kAvx2 };

/// Whether `isa` runs as asked on this processor (kAvx2 without AVX2 runs the baseline).
bool search_isa_available(SearchIsa isa);

/// find_pair_candidates with the candidate test's instruction set chosen.
std::vector<PairCandidate> find_pair_candidates(const std::vector<Vec3>& x, const std::vector<double>& r, double skin,
                                                const PeriodicParams& periodic, std::size_t reserve, SearchIsa isa);
/// The same into `out` (cleared; its memory is kept from call to call by a caller that rebuilds
/// often: a fresh array of this size costs page faults at every rebuild).
void find_pair_candidates(const std::vector<Vec3>& x, const std::vector<double>& r, double skin,
                          const PeriodicParams& periodic, std::size_t reserve, SearchIsa isa,
                          std::vector<PairCandidate>& out);

}  // namespace demfdm::dem
