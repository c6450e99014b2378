// A rank of the DEM on ranks dies (issue 17 item 3: node-death detection with a dead rank). The
// ranks step a free lattice (DistDem); after 200 steps the last rank prints the time and kills
// itself with SIGKILL, as an out-of-memory kill or a crashed host would. tests/dist/dead_rank.sh
// checks that mpirun ends the job with a non-zero code naming the dead rank within 5 s.
#include <mpi.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <random>

#include "demfdm/dem/dist.hpp"
#include "tests/dem/lattice.hpp"

using namespace demfdm::dem;

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  constexpr int kSide = 10;
  constexpr double kR = 1e-4, kS = 1.96 * kR;
  WorldParams p;
  p.threads = 1;
  p.dt_fixed = 5e-8;
  World full(p);
  std::mt19937_64 rng(5);
  test::add_jittered_lattice(full, kSide, kS, kR, 0.03 * kR, 0.04, rng);
  full.prepare();
  BrickGrid g;
  g.len = {kSide * kS, kSide * kS, kSide * kS};
  g.n[0] = size;
  DistDem d(MPI_COMM_WORLD, full.params(), g);
  d.load(full);
  for (long k = 0; k < 100000000; ++k) {
    d.step(1);
    if (k == 200 && rank == size - 1) {
      const double t = std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
      std::printf("dead_rank: rank %d kills itself at %.3f\n", rank, t);
      std::fflush(stdout);
      std::raise(SIGKILL);
    }
  }
  MPI_Finalize();
  return 0;
}
