// bench_dist: the DEM on MPI ranks (dem_dist, issue 17 item 5) on the reference packing of
// bench_dem (25,835 balls, periodic), cut into P bricks along x.
//
// Usage: mpirun -np P bench_dist [packing] [linear|softbond] [steps] [strong|weak]
//   strong: the packing as it is, shared by the P ranks;
//   weak:   the packing repeated P times along x (P x 25,835 balls), one copy's worth per rank.
// The cell is strained in plane strain at the rate of bench_dem's `moving` run (the cell edge
// moves by skin/3 in 30 steps), so lists are rebuilt and balls cross the cuts during the run.
// Ball ids follow a Morton order of the packing (rows in id order are then local in space, as
// bench_dem's sorted rows). One thread per rank unless OMP_NUM_THREADS says otherwise.
//
// Output (rank 0), one CSV line: ranks, mode, model, balls, steps, wall_s, particle_steps_per_s,
// then the times per step averaged over the ranks [ms]: motion, forces, forward, reduce,
// exchange; comm_share (forward + reduce + exchange over the step, mean over ranks); imbalance
// (largest compute time over the mean); ghosts per owned ball; ghost states received per step and
// rank; rebuilds; balls that changed rank.
#include <mpi.h>
#include <omp.h>

#include <algorithm>
#include <cstdio>
#include <numeric>
#include <string>

#include "demfdm/dem/dist.hpp"
#include "packing.hpp"

using namespace demfdm::dem;

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, P = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &P);
  const std::string file = argc > 1 ? argv[1] : DEMFDM_BENCH_PACKING;
  const std::string model = argc > 2 ? argv[2] : "linear";
  const long steps = argc > 3 ? std::stol(argv[3]) : 1000;
  const std::string mode = argc > 4 ? argv[4] : "strong";
  if ((model != "linear" && model != "softbond") || (mode != "strong" && mode != "weak")) {
    if (rank == 0) std::fprintf(stderr, "usage: bench_dist [packing] [linear|softbond] [steps] [strong|weak]\n");
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  const Packing pk = load(file);
  const int copies = mode == "weak" ? P : 1;
  const Vec3 L0 = pk.hi - pk.lo;
  // the balls of one copy in Morton order (ids, hence rows, local in space)
  Particles probe;
  for (std::size_t i = 0; i < pk.x.size(); ++i) probe.add(pk.x[i], pk.r[i], 2650.0, i);
  const std::vector<std::uint32_t> new_row = morton_rows(probe);
  std::vector<std::size_t> order(pk.x.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[new_row.empty() ? i : new_row[i]] = i;
  WorldParams p;
  p.density = 2650.0;
  p.threads = omp_get_max_threads();
  p.periodic.enabled = true;
  p.periodic.origin = pk.lo;
  p.periodic.length = {L0.x * copies, L0.y, L0.z};
  p.ball_ball.model = model == "softbond" ? ContactModel::kSoftBond : ContactModel::kLinear;
  p.ball_ball.linear.kn_fixed = 2.55e5;
  p.ball_ball.linear.kratio = 2.4;
  p.ball_ball.linear.fric = 0.6248693519093275;
  p.skin = 0.1 * 2.0 * 0.058e-3;
  World full(p);
  for (int c = 0; c < copies; ++c)
    for (std::size_t k : order) full.add_ball(pk.x[k] + Vec3{c * L0.x, 0.0, 0.0}, pk.r[k]);
  full.prepare();
  if (p.ball_ball.model == ContactModel::kSoftBond) full.bond_ball_ball(-1.0, 0.0);
  const double edot = p.skin / 3.0 / (30.0 * full.dt() * p.periodic.length.x);
  full.set_strain_rate({edot, -edot, 0.0});
  BrickGrid g;
  g.lo = p.periodic.origin;
  g.len = p.periodic.length;
  g.n[0] = P;
  g.periodic[0] = g.periodic[1] = g.periodic[2] = true;
  DistDem d(MPI_COMM_WORLD, p, g);
  d.load(full);
  d.step(20);  // warm-up
  d.reset_times();
  const std::int64_t ex0 = d.exchanges(), mig0 = d.migrated();
  MPI_Barrier(MPI_COMM_WORLD);
  const double t0 = MPI_Wtime();
  d.step(steps);
  MPI_Barrier(MPI_COMM_WORLD);
  const double wall = MPI_Wtime() - t0;
  const DistDem::Times& t = d.times();
  double mine[7] = {t.motion, t.forces, t.forward, t.reduce, t.exchange, double(d.ghosts()) / double(d.owned()),
                    double(t.forwarded)};
  double sum[7], cmax = 0.0;
  MPI_Reduce(mine, sum, 7, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  const double comp = t.compute();
  MPI_Reduce(&comp, &cmax, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
  long long mig = d.migrated() - mig0, mig_sum = 0;
  MPI_Reduce(&mig, &mig_sum, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (rank == 0) {
    const double ms = 1e3 / double(steps) / P;
    const double total = sum[0] + sum[1] + sum[2] + sum[3] + sum[4];
    std::printf("ranks,mode,model,balls,steps,wall_s,particle_steps_per_s,motion_ms,forces_ms,forward_ms,reduce_ms,"
                "exchange_ms,comm_share,imbalance,ghosts_per_owned,ghosts_recv_per_step,rebuilds,migrations\n");
    std::printf("%d,%s,%s,%zu,%ld,%.4f,%.4e,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.1f,%lld,%lld\n", P, mode.c_str(),
                model.c_str(), full.num_balls(), steps, wall, double(full.num_balls()) * double(steps) / wall,
                sum[0] * ms, sum[1] * ms, sum[2] * ms, sum[3] * ms, sum[4] * ms, (sum[2] + sum[3] + sum[4]) / total,
                cmax / ((sum[0] + sum[1]) / P), sum[5] / P, sum[6] / double(steps) / P,
                static_cast<long long>(d.exchanges() - ex0), mig_sum);
  }
  MPI_Finalize();
  return 0;
}
