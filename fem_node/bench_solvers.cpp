// fem_bench: CPU cost of the two continuum solvers on one mesh, measured in one process
// (a command, not a test). For each mesh: the FEM's assembly + factorisation and one solve,
// the FDM's static-mode step and the number of steps it needs, from rest under gravity, to
// reach the equilibrium ratio 1e-5 (the state the FEM reaches in one solve).
//
//   fem_bench            footing_small mesh and the paper mesh (physics.md 0.3 defaults)
#include <ctime>
#include <cstdio>

#include "demfdm/fdm/model.hpp"
#include "fem_model.hpp"

using namespace demfdm;

namespace {
double cpu() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void bench(const char* name, const fdm::MeshParams& mesh, double young) {
  fem::Params fp;
  fp.mesh = mesh;
  fp.materials[0] = fem::ElasticGroup{1272.0, young, 0.25, std::nullopt};
  fp.gravity = {0, 0, -100 * 9.81};
  double t0 = cpu();
  fem::Model fem(fp);
  double t_setup = cpu() - t0;
  int n = 0;
  t0 = cpu();
  do {
    fem.solve();
    ++n;
  } while (cpu() - t0 < 1.0 && n < 1000);
  double t_solve = (cpu() - t0) / n;

  fdm::ModelParams dp;
  dp.mesh = mesh;
  dp.materials[0].material.young = young;
  dp.materials[0].material.poisson = 0.25;
  dp.mode = fdm::Mode::kStatic;
  dp.gravity_level = 100;
  fdm::Model fdm(dp);
  t0 = cpu();
  std::int64_t steps = 0;
  const std::int64_t cap = 200000;
  do {
    fdm.step(100);
    steps += 100;
  } while (fdm.ratios().average > 1e-5 && steps < cap);
  double t_fdm = cpu() - t0;
  // Agreement of the two static answers: top-centre settlement.
  double uf = 0, ud = 0;
  auto top = fdm.gridpoints_on_plane(2, mesh.height);
  for (auto g : top) {
    uf = std::min(uf, fem.displacements()[3 * g + 2]);
    ud = std::min(ud, fdm.displacements()[3 * g + 2]);
  }
  std::printf("%s: %zu gridpoints, %zu zones, %zu free dofs\n", name, fem.num_points(), fem.num_zones(),
              fem.num_free_dofs());
  std::printf("  fem: assembly + factorisation %.4f s CPU, one solve %.6f s CPU\n", t_setup, t_solve);
  std::printf("  fdm: one static step %.6f s CPU; %lld steps to ratio 1e-5%s = %.3f s CPU\n", t_fdm / steps,
              static_cast<long long>(steps), steps >= cap ? " (cap reached)" : "", t_fdm);
  std::printf("  one fem solve = %.1f fdm steps; equilibrium from rest: fem %.1fx faster (incl. set-up %.1fx)\n",
              t_solve / (t_fdm / steps), t_fdm / t_solve, t_fdm / (t_setup + t_solve));
  std::printf("  max top settlement under 100 g: fem %.6e m, fdm %.6e m (%.2f %%)\n", uf, ud, 100 * (ud - uf) / uf);
}
}  // namespace

int main() {
  fdm::MeshParams small;
  small.length = small.width = small.height = 4e-3;
  small.inner_size = {1e-3, 1e-3, 2e-3};
  small.size_near = 0.5e-3;
  small.size_far = 1e-3;
  bench("footing_small mesh", small, 1.0e8);
  bench("paper mesh (MeshParams defaults: 16 mm box, 4 x 4 x 10 mm pocket)", fdm::MeshParams{}, 1.0e8);
  return 0;
}
