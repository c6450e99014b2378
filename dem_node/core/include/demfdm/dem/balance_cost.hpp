// The balancing's cost model: what a ball and each of its contacts cost a rank per step
// (dem_node/dist's contact_weights; the scene key dem.balance_costs). Kept apart from the ranks'
// code (no MPI) so that the scene's schema declares its defaults from it.
#pragma once

#include <cstdint>

namespace demfdm::dem {

/// The balancing's cost model (contact_weights): what one step costs a rank per row and per
/// contact, in nanoseconds of one core, fitted to the per-rank phase times of the default scene's
/// penetration state (soft bond law; session 29: 2 ranks under five cuts, bench_dist --run,
/// AVX2 AMD EPYC; docs/scaling.md): the motion and the per-ball rest of the forces phase 20 ns
/// per ball; the pair pass 51 ns per bonded pair and 22 ns per pair apart, with 3 ns per listed
/// pair for the rebuild (a fit with the owned balls beside it; the pairs alone give 0.5 ns, so
/// the pair ends here are 5-8 % heavier than that fit, within what the runs resolve); the facet
/// pass (the closest point, the law, the equivalent vertex forces) 249 ns per facet contact. A
/// pair's cost is shared by its two balls. Unbonded pairs that touch (0.1 % of that state's
/// pairs) take the bonded figure, plane and footing contacts a pair's law: neither is resolved
/// by that state. Other laws and machines may set their own (DistDem::Balance::cost, the scene
/// key dem.balance_costs; bench/dem/fit_costs.py fits them to a run's own state; LAMMPS's fix
/// balance takes user weights likewise).
struct ContactCost {
  std::int64_t ball = 20;
  std::int64_t bonded_end = 27;    // (51 + 3) / 2
  std::int64_t touching_end = 27;  // as bonded (not resolved)
  std::int64_t apart_end = 12;     // (22 + 3) / 2
  std::int64_t facet = 250;
  std::int64_t plane = 54;  // plane and footing contacts: a pair's law (not resolved)
};

}  // namespace demfdm::dem
