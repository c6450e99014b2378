// Test helpers: a jittered cubic lattice of polydisperse balls, the set-up that several DEM tests
// share, and the state of every ball after a run. Ball (i, j, k) sits at ((i, j, k) + ½) s plus pos_jitter u, radius R (1 + rad_jitter u),
// u uniform in [−1, 1] drawn from `rng`; the draws are made in one fixed expression, so a test
// that switches to this helper keeps its balls bit for bit.
#pragma once

#include <random>
#include <vector>

#include "demfdm/dem/world.hpp"

namespace demfdm::dem::test {

inline void add_jittered_lattice(World& w, int ns, double s, double R, double pos_jitter, double rad_jitter,
                                 std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < ns; ++k)
    for (int j = 0; j < ns; ++j)
      for (int i = 0; i < ns; ++i)
        w.add_ball({(i + 0.5) * s + pos_jitter * u(rng), (j + 0.5) * s + pos_jitter * u(rng),
                    (k + 0.5) * s + pos_jitter * u(rng)},
                   R * (1.0 + rad_jitter * u(rng)));
}

// The state of every ball after a run, row order (the tests compare these bit for bit).
struct BallState {
  std::vector<Vec3> x, v, w, f, t;
};

inline BallState ball_state(const World& w) {
  const Particles& p = w.balls();
  return BallState{p.x, p.v, p.w, p.f, p.t};
}

}  // namespace demfdm::dem::test
