// fem_bench: cost of the two continuum solvers on one mesh, measured in one process (a
// command, not a test). For each mesh: the FEM's assembly, factorisation and one solve with
// each linear solver (CHOLMOD supernodal and Eigen SimplicialLDLT; wall and CPU seconds, CPU
// counts every BLAS thread) and the largest difference of their displacements; the FDM's
// static-mode step and the number of steps it needs, from rest under gravity, to reach the
// equilibrium ratio 1e-5 (the state the FEM reaches in one solve).
//
//   fem_bench [--no-ldlt] [--no-fdm]   footing_small mesh, the paper scenes' mesh and a finer one
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <cstdio>
#include <memory>

#include "demfdm/fdm/model.hpp"
#include "demfdm/fem/model.hpp"

using namespace demfdm;

namespace {
double cpu() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

bool g_ldlt = true, g_fdm = true;

double wall() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

struct FemRun {
  std::unique_ptr<fem::Model> model;  // solved
  double solve_cpu_s = 0;             // one back-substitution [s CPU]
};

// Builds the FEM with one linear solver, prints its costs, returns it (solved).
FemRun fem_run(const fdm::MeshParams& mesh, double young, fem::LinearSolver solver) {
  fem::Params fp;
  fp.mesh = mesh;
  fp.solver = solver;
  fp.materials[0] = fem::ElasticGroup{1272.0, young, 0.25, std::nullopt};
  fp.gravity = {0, 0, -100 * 9.81};
  double c0 = cpu(), w0 = 0;
  auto fem = std::make_unique<fem::Model>(fp);
  double c_setup = cpu() - c0;
  int n = 0;
  c0 = cpu();
  w0 = wall();
  do {
    fem->solve();
    ++n;
  } while (wall() - w0 < 1.0 && n < 1000);
  double w_solve = (wall() - w0) / n, c_solve = (cpu() - c0) / n;
  std::printf("  fem %-18s: assembly %.3f s, factorisation %.3f s wall (set-up %.3f s CPU); one solve %.6f s wall, "
              "%.6f s CPU; residual %.1e\n",
              fem->solver_name(), fem->assembly_s(), fem->factorisation_s(), c_setup, w_solve, c_solve,
              fem->residual_ratio());
  return FemRun{std::move(fem), c_solve};
}

void bench(const char* name, const fdm::MeshParams& mesh, double young) {
  std::printf("%s\n", name);
  FemRun ref;
  if (fem::have_cholmod()) ref = fem_run(mesh, young, fem::LinearSolver::kCholmod);
  if (g_ldlt || !ref.model) {
    FemRun ldlt = fem_run(mesh, young, fem::LinearSolver::kLdlt);
    if (ref.model) {
      double du = 0, umax = 0;
      const auto &a = ref.model->displacements(), &b = ldlt.model->displacements();
      for (std::size_t i = 0; i < a.size(); ++i) {
        du = std::max(du, std::abs(a[i] - b[i]));
        umax = std::max(umax, std::abs(a[i]));
      }
      std::printf("  cholmod vs ldlt: max |du| = %.3e m (%.2e of max |u|)\n", du, du / umax);
    } else {
      ref = std::move(ldlt);
    }
  }
  const fem::Model& fem = *ref.model;
  std::printf("  %zu gridpoints, %zu zones, %zu free dofs\n", fem.num_points(), fem.num_zones(), fem.num_free_dofs());
  if (!g_fdm) return;
  const double t_solve = ref.solve_cpu_s, t_setup = fem.assembly_s() + fem.factorisation_s();
  double t0;
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
  std::printf("  fdm: one static step %.6f s CPU; %lld steps to ratio 1e-5%s = %.3f s CPU\n", t_fdm / steps,
              static_cast<long long>(steps), steps >= cap ? " (cap reached)" : "", t_fdm);
  std::printf("  one fem solve (%s) = %.1f fdm steps; equilibrium from rest: fem %.1fx faster (incl. set-up %.1fx)\n",
              fem.solver_name(),
              t_solve / (t_fdm / steps), t_fdm / t_solve, t_fdm / (t_setup + t_solve));
  std::printf("  max top settlement under 100 g: fem %.6e m, fdm %.6e m (%.2f %%)\n", uf, ud, 100 * (ud - uf) / uf);
}
}  // namespace

int main(int argc, char** argv) {
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--no-ldlt")) {
      g_ldlt = false;
    } else if (!std::strcmp(argv[i], "--no-fdm")) {
      g_fdm = false;
    } else {
      std::fprintf(stderr, "fem_bench: unknown argument '%s' (options: --no-ldlt --no-fdm)\n", argv[i]);
      return 2;
    }
  }
  fdm::MeshParams small;
  small.length = small.width = small.height = 4e-3;
  small.inner_size = {1e-3, 1e-3, 2e-3};
  small.size_near = 0.5e-3;
  small.size_far = 1e-3;
  bench("footing_small mesh", small, 1.0e8);
  fdm::MeshParams paper;  // scenes/paper_*.toml: 16 mm box, 4 x 4 x 10 mm pocket, 1 mm / 4 mm zones
  paper.size_near = 1e-3;
  paper.size_far = 4e-3;
  bench("paper scenes' mesh (16 mm box, 4 x 4 x 10 mm pocket, size_near 1 mm, size_far 4 mm)", paper, 1.0e8);
  bench("fine paper mesh (MeshParams defaults: size_near 0.5 mm, size_far 2 mm)", fdm::MeshParams{}, 1.0e8);
  return 0;
}
