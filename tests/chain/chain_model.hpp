// 1-D chain of equal masses joined by equal springs, free at both ends, integrated with the
// PFC centred-difference scheme (docs/theory.md 1.2): v(t+dt/2) = v(t-dt/2) + dt F(x(t))/m,
// x(t+dt) = x(t) + dt v(t+dt/2). Mass 0 starts with half-step velocity v0, the others at rest.
//
// Used three ways: monolithically (the reference), and split at mass 'split' between a
// DEM-role process (masses 0..split-1 and the spring to mass 'split') and a continuum-role
// process (masses split..n-1, mass 'split' being its interface gridpoint). In the serial
// scheme the split run is the monolithic one to round-off; in the parallel scheme the
// continuum sees the interface force one step late.
#pragma once
#include <cstddef>
#include <vector>

namespace demfdm::testing {

struct ChainParams {
  int n = 20, split = 10;
  double m = 1.0, k = 100.0, dt = 0.01, v0 = 1.0;
};

// Monolithic reference: returns u[step][i] (displacements) for steps 0..n_steps.
inline std::vector<std::vector<double>> chain_reference(const ChainParams& p, int n_steps) {
  std::vector<double> x(p.n, 0.0), v(p.n, 0.0), f(p.n);
  v[0] = p.v0;
  std::vector<std::vector<double>> out{x};
  for (int s = 0; s < n_steps; ++s) {
    for (int i = 0; i < p.n; ++i) f[i] = 0;
    for (int i = 0; i + 1 < p.n; ++i) {
      double t = p.k * (x[i + 1] - x[i]);  // spring tension
      f[i] += t;
      f[i + 1] -= t;
    }
    for (int i = 0; i < p.n; ++i) {
      v[i] += p.dt * f[i] / p.m;
      x[i] += p.dt * v[i];
    }
    out.push_back(x);
  }
  return out;
}

}  // namespace demfdm::testing
