// bench_dist: the DEM on MPI ranks (dem_dist, issue 17 item 5) on the reference packing of
// bench_dem (25,835 balls, periodic), cut into P bricks.
//
// Usage: mpirun -np P bench_dist [packing] [linear|softbond] [steps] [strong|weak|footing] [balance]
//   strong:  the packing as it is, shared by the P ranks, cut along x;
//   weak:    the packing repeated P times along x (P x 25,835 balls), one copy's worth per rank
//            (BENCH_DIST_AXIS: along that axis, cut across it);
//   footing: penetration: the packing in a box of five planes (floor and sides), gravity (100 g),
//            and the footing (diameter half the width) pushed into the top by two mean radii in
//            the run; cut along z, so the top brick holds the work under the footing.
//            Before the timed steps the packing settles for BENCH_DIST_RELAX steps (default 2,000;
//            the velocities zeroed four times on the way, stopping the rattlers that the
//            released overlaps shoot off the free top). One DistDem::step call per step, as the
//            DEM node makes at coupling.interval = 1, so the walls' sums are formed every step.
//            BENCH_DIST_REPLICATE=K: K x K x K copies of the periodic packing first (a wider block).
//   balance: DistDem's dynamic balancing every that many exchanges (0, the default: even cuts),
//            the first cut balanced too (BENCH_DIST_BALANCE_AFTER_LOAD=1: not, as before session 25);
//            BENCH_DIST_WEIGHT=time weighs balls by their rank's measured time, not contacts.
// BENCH_DIST_NEWTON=1: `newton on` (DistDem::set_newton; refused with BENCH_DIST_WEIGHT=time and
// balancing on: its results follow the cuts): each pair across a face computed once,
// the ghosts' forces sent back to their owners.
// BENCH_DIST_FROM_ROOT=1: rank 0 alone holds the packing and sends each rank its part
// (DistDem::load_from_root, as the DEM node does) instead of every rank cutting its own (load);
// the last column, load_ms, is the wall time of either.
// BENCH_DIST_DECOMP=rcb: recursive coordinate bisection (BrickGrid::set_rcb) instead of the cut
// along one axis; `balance` then moves every cut of the tree. BENCH_DIST_AXIS=x|y|z: strong and
// footing cut across that axis instead, and weak repeats the packing along it (the cell's z side is
// half its x and y sides, so a cut across z doubles the ghosts of one across x at the same ranks
// and balls per rank).
// BENCH_DIST_MODEL_GRID=nx,ny,nz: also print the imbalance of the final state cut by a model grid
// of that many bricks, with even cuts, shifted cuts and RCB (model_grid below).
// bench_dist --state FILE SCENE_HASH nx,ny,nz: the same for a World saved in a checkpoint.
// mpirun -np P bench_dist --run DIR [steps] [balance]: a run's checkpoint (its DEM World) stepped
// on the ranks as the DEM node steps it (run_state below).
// bench_dist --merge P N: rank 0's merge of the walls' shares, P runs of N (merge_bench below).
// mpirun -np P bench_dist --rev N [seed]: the REV's preparation on the ranks (rev_bench below): N
// balls of the paper's PSD at upscaling 1.5 drawn into a cube at porosity 0.52042, their radius
// expansion (5 increments), bonds to Z = 6.82 on the ranks, and the soft-bond REV's servo (compaction
// at friction 0.1, then the final one, to (6.25, 6.25, 12.5) kPa), as the DEM node runs them with
// dem.ranks = P. One line per phase: phase, ranks, balls, steps, wall_s, particle_steps_per_s,
// converged; on one rank also both phases on one World without DistDem (as the node at
// dem.ranks = 1), the same steps; then each rank's phase times (motion, which runs the servo's
// sums, forces, forward, reduce, exchange) [s]. BENCH_REV_ORDER_FREE=1: with run.order_free_sums
// (the servo's sums and the cell stress order-free, each rank folding its own contacts).
// mpirun -np P bench_dist --replicate N nx ny nz: the replication on the ranks against the whole
// block on rank 0 (replicate_bench below).
// strong and weak strain the cell in plane strain at the rate of bench_dem's `moving` run (the
// cell edge moves by skin/3 in 30 steps), so lists are rebuilt and balls cross the cuts during
// the run. Ball ids follow a Morton order of the packing (rows in id order are then local in
// space, as bench_dem's sorted rows). One thread per rank unless OMP_NUM_THREADS says otherwise.
//
// Output (rank 0), one CSV line: ranks, mode, model, balls, steps, wall_s, particle_steps_per_s,
// then the times per step averaged over the ranks [ms]: motion, forces, forward, reduce,
// exchange, walls; comm_share (forward + reduce + exchange + walls over the step, mean over
// ranks); imbalance (largest compute time over the mean); ghosts per owned ball; ghost states
// received per step and rank; rebuilds; balls that changed rank; rebalances; owned balls per
// rank (min/max); weight_imbalance (the balancing's weight, contact_weights: the modelled cost of
// the own balls, ContactCost or BENCH_DIST_COST, at the end: largest over mean; free of timing
// noise); the footing force [N]
// (footing mode); the World's rebuild and ball-ball pass [ms]; the `newton` reverse [ms] (its communication, counted in
// comm_share); the pairs listed over the ranks at the end (one World's count with newton on); the
// wall time of the load [ms] (every rank cutting its part, or rank 0 sending them: BENCH_DIST_FROM_ROOT).
#include <mpi.h>
#include <unistd.h>
#include <omp.h>

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>

#include "coordinator/core/checkpoint.hpp"
#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/dist.hpp"
#include "demfdm/dem/guard.hpp"
#include "demfdm/dem/procedures.hpp"
#include "packing.hpp"

using namespace demfdm::dem;

namespace {

// The axis BENCH_DIST_AXIS names (x, y or z), else `fallback`.
int axis_from_env(int fallback) {
  const char* ax = std::getenv("BENCH_DIST_AXIS");
  return ax ? std::clamp(ax[0] - 'x', 0, 2) : fallback;
}

// BENCH_DIST_COST=ball,bonded,touching,apart,facet,plane: the balancing's costs (ContactCost: a
// row, an end of a bonded / touching / apart pair, a facet, a plane or footing contact) instead of
// the model's; e.g. 1,1,1,1,5,1 for session 28's weights.
ContactCost bench_cost() {
  ContactCost c;
  if (const char* s = std::getenv("BENCH_DIST_COST"); s && *s) {
    std::int64_t v[6];
    const int got = std::sscanf(s, "%" SCNd64 ",%" SCNd64 ",%" SCNd64 ",%" SCNd64 ",%" SCNd64 ",%" SCNd64,
                                &v[0], &v[1], &v[2], &v[3], &v[4], &v[5]);
    if (got != 6 || v[0] < 1 || *std::min_element(v + 1, v + 6) < 0)
      throw std::invalid_argument(std::string("BENCH_DIST_COST: expected six integers (a row's >= 1, the others >= 0), found '") +
                                  s + "'");
    c = {v[0], v[1], v[2], v[3], v[4], v[5]};
  }
  return c;
}

// The projection's imbalance (docs/scaling.md): the balancing weight of every ball (contact_weights,
// its modelled cost) of the final state, gathered on rank 0 and cut by a model grid of nx x ny x nz
// bricks over the same box, three ways: even cuts; shifted cuts (DistDem's balancing: per axis,
// equal-weight slabs from a 2,048-bin histogram); recursive coordinate bisection (RCB, LAMMPS's
// tiled balance: the longest side halved at the weighted median, recursively; any brick count).
// Prints the largest brick weight over the mean for each, and for RCB as DistDem cuts it
// (rcb_cuts: each cut at the end of one of 2,048 bins, imbalance_rcb_code), and for those cuts
// the largest brick's modelled cost (the model's ContactCost, whatever BENCH_DIST_COST weighs the
// cuts by) over the mean, cost_imbalance_rcb_code: with BENCH_DIST_COST=1,1,1,1,5,1 the time
// imbalance the model expects of session 28's weights.
struct WB {
  Vec3 x;
  std::int64_t w, cost;
};

void model_imbalance(const std::vector<WB>& all, const Vec3& lo, const Vec3& len, const char* spec);

void model_grid(const DistDem& d, const BrickGrid& g, const char* spec) {
  std::vector<std::int64_t> wt, ct;
  contact_weights(d.world(), wt, bench_cost());
  contact_weights(d.world(), ct);
  const World& w = d.world();
  const auto& gh = w.ghost_rows();
  std::vector<WB> mine;
  for (std::size_t i = 0; i < w.num_balls(); ++i)
    if (gh.empty() || !gh[i]) mine.push_back({w.balls().x[i], wt[i], ct[i]});
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const std::vector<WB> all = gather_on_root(MPI_COMM_WORLD, mine);
  if (rank == 0) model_imbalance(all, g.lo, g.len, spec);
}

void model_imbalance(const std::vector<WB>& all, const Vec3& lo, const Vec3& len, const char* spec) {
  int n[3] = {1, 1, 1};
  if (std::sscanf(spec, "%d,%d,%d", &n[0], &n[1], &n[2]) != 3) {
    std::fprintf(stderr, "model grid '%s': expected nx,ny,nz\n", spec);
    return;
  }
  const int B = n[0] * n[1] * n[2];
  std::int64_t total = 0;
  for (const WB& b : all) total += b.w;
  const double mean = double(total) / B;
  auto imbalance = [&](const std::vector<std::int64_t>& s) {
    return double(*std::max_element(s.begin(), s.end())) / mean;
  };
  auto unit = [&](const Vec3& x, int k) { return std::clamp((x[k] - lo[k]) / len[k], 0.0, 1.0 - 1e-12); };
  // even and shifted cuts
  std::vector<double> cuts[3];
  for (int k = 0; k < 3; ++k) {
    const int bins = 2048;
    std::vector<std::int64_t> h(bins, 0);
    for (const WB& b : all) h[static_cast<std::size_t>(unit(b.x, k) * bins)] += b.w;
    cuts[k] = equal_weight_cuts(h, n[k], 1.0);
  }
  std::vector<std::int64_t> even(static_cast<std::size_t>(B), 0), shift(static_cast<std::size_t>(B), 0);
  for (const WB& b : all) {
    int ie[3], is[3];
    for (int k = 0; k < 3; ++k) {
      const double u = unit(b.x, k);
      ie[k] = std::min(static_cast<int>(u * n[k]), n[k] - 1);
      is[k] = static_cast<int>(std::upper_bound(cuts[k].begin(), cuts[k].end(), u) - cuts[k].begin());
    }
    even[static_cast<std::size_t>(ie[0] + n[0] * (ie[1] + n[1] * ie[2]))] += b.w;
    shift[static_cast<std::size_t>(is[0] + n[0] * (is[1] + n[1] * is[2]))] += b.w;
  }
  // RCB into B parts
  std::vector<std::int64_t> rcb;
  std::vector<WB> v = all;
  auto bisect = [&](auto&& self, std::size_t lo, std::size_t hi, int parts) -> void {
    if (parts == 1) {
      std::int64_t s = 0;
      for (std::size_t i = lo; i < hi; ++i) s += v[i].w;
      rcb.push_back(s);
      return;
    }
    Vec3 a = v[lo].x, b = v[lo].x;
    for (std::size_t i = lo; i < hi; ++i)
      for (int k = 0; k < 3; ++k) a[k] = std::min(a[k], v[i].x[k]), b[k] = std::max(b[k], v[i].x[k]);
    int k = 0;
    for (int j = 1; j < 3; ++j)
      if (b[j] - a[j] > b[k] - a[k]) k = j;
    std::sort(v.begin() + static_cast<std::ptrdiff_t>(lo), v.begin() + static_cast<std::ptrdiff_t>(hi),
              [k](const WB& p, const WB& q) { return p.x[k] < q.x[k]; });
    const int left = parts / 2;
    std::int64_t s = 0, want = 0;
    for (std::size_t i = lo; i < hi; ++i) want += v[i].w;
    want = want * left / parts;
    std::size_t m = lo;
    while (m < hi && s + v[m].w <= want) s += v[m++].w;
    self(self, lo, m, left);
    self(self, m, hi, parts - left);
  };
  bisect(bisect, 0, v.size(), B);
  // RCB as DistDem cuts (rcb_cuts: 2,048 bins per node, the cut at a bin end)
  BrickGrid g;
  g.lo = lo;
  g.len = len;
  g.set_rcb(B);
  std::vector<Vec3> xs;
  std::vector<std::int64_t> ws;
  for (const WB& b : all) xs.push_back(b.x), ws.push_back(b.w);
  rcb_cuts(g, xs, ws, {}, 2048, [](std::vector<std::int64_t>&) {});
  std::vector<std::int64_t> code(static_cast<std::size_t>(B), 0), cost(static_cast<std::size_t>(B), 0);
  std::int64_t cost_total = 0;
  for (const WB& b : all) {
    const auto o = static_cast<std::size_t>(g.owner(b.x));
    code[o] += b.w;
    cost[o] += b.cost;
    cost_total += b.cost;
  }
  const double cost_imb = double(*std::max_element(cost.begin(), cost.end())) * B / double(cost_total);
  std::printf("model_grid,%dx%dx%d,balls,%zu,balls_per_brick,%.0f,imbalance_even,%.4f,imbalance_shift,%.4f,imbalance_rcb,%.4f,"
              "imbalance_rcb_code,%.4f,cost_imbalance_rcb_code,%.4f\n",
              n[0], n[1], n[2], all.size(), double(all.size()) / B, imbalance(even), imbalance(shift), imbalance(rcb),
              imbalance(code), cost_imb);
}

// BENCH_DIST_NEWTON onto `d`, and the balancing of every `every` exchanges with BENCH_DIST_WEIGHT's
// weights (set by the caller, before or after the load).
DistDem::Balance newton_and_balance(DistDem& d, int every) {
  if (const char* nw = std::getenv("BENCH_DIST_NEWTON")) d.set_newton(std::string(nw) == "1");
  DistDem::Balance bal;
  bal.every = every;
  bal.cost = bench_cost();
  if (const char* wgt = std::getenv("BENCH_DIST_WEIGHT"); wgt && std::string(wgt) == "time")
    bal.weight = DistDem::Weight::kTime;
  return bal;
}

// One CSV line on rank 0 (the columns of the header comment) from the ranks' times since
// reset_times and the counters since ex0 / mig0.
struct Run {
  int P = 1, rank = 0;
  std::string mode, model;
  std::size_t balls = 0;
  long steps = 0;
  double wall = 0.0, load_s = 0.0;
  std::int64_t ex0 = 0, mig0 = 0;
};

void report(const DistDem& d, const Run& r) {
  const int P = r.P;
  const long steps = r.steps;
  const double wall = r.wall;
  const DistDem::Times& t = d.times();
  // the forces phase split: the neighbour rebuild and the ball-ball pass of the rank's World
  const PhaseTimes& pt = d.world().phase_times();
  double mine[12] = {t.motion,   t.forces, t.forward, t.reduce, t.exchange, t.walls, double(d.ghosts()) / double(d.owned()),
                     double(t.forwarded), pt.rebuild, pt.pair, t.reverse,
                     double(d.world().pair_contacts().size())};
  double sum[12], cmax = 0.0;
  MPI_Reduce(mine, sum, 12, MPI_DOUBLE, MPI_SUM, 0, MPI_COMM_WORLD);
  const double comp = t.compute();
  MPI_Reduce(&comp, &cmax, 1, MPI_DOUBLE, MPI_MAX, 0, MPI_COMM_WORLD);
  long long mig = d.migrated() - r.mig0, mig_sum = 0, own = static_cast<long long>(d.owned()), own_min = 0, own_max = 0;
  MPI_Reduce(&mig, &mig_sum, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  MPI_Reduce(&own, &own_min, 1, MPI_LONG_LONG, MPI_MIN, 0, MPI_COMM_WORLD);
  MPI_Reduce(&own, &own_max, 1, MPI_LONG_LONG, MPI_MAX, 0, MPI_COMM_WORLD);
  long long wgt = static_cast<long long>(d.weight()), wgt_max = 0, wgt_sum = 0;
  MPI_Reduce(&wgt, &wgt_max, 1, MPI_LONG_LONG, MPI_MAX, 0, MPI_COMM_WORLD);
  MPI_Reduce(&wgt, &wgt_sum, 1, MPI_LONG_LONG, MPI_SUM, 0, MPI_COMM_WORLD);
  if (r.rank == 0) {
    const double ms = 1e3 / double(steps) / P;
    const double total = sum[0] + sum[1] + sum[2] + sum[3] + sum[4] + sum[5] + sum[10];
    std::printf("ranks,mode,model,balls,steps,wall_s,particle_steps_per_s,motion_ms,forces_ms,forward_ms,reduce_ms,"
                "exchange_ms,walls_ms,comm_share,imbalance,ghosts_per_owned,ghosts_recv_per_step,rebuilds,migrations,"
                "rebalances,owned_min,owned_max,weight_imbalance,footing_fz_N,rebuild_ms,pair_ms,reverse_ms,"
                "pairs_listed,load_ms\n");
    std::printf("%d,%s,%s,%zu,%ld,%.4f,%.4e,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.1f,%lld,%lld,%lld,%lld,%lld,%.4f,%.4g,"
                "%.4f,%.4f,%.4f,%.0f,%.1f\n",
                P, r.mode.c_str(), r.model.c_str(), r.balls, steps, wall,
                double(r.balls) * double(steps) / wall, sum[0] * ms, sum[1] * ms, sum[2] * ms, sum[3] * ms,
                sum[4] * ms, sum[5] * ms, (sum[2] + sum[3] + sum[4] + sum[5] + sum[10]) / total, cmax / ((sum[0] + sum[1]) / P),
                sum[6] / P, sum[7] / double(steps) / P, static_cast<long long>(d.exchanges() - r.ex0), mig_sum,
                static_cast<long long>(d.rebalances()), own_min, own_max, double(wgt_max) / (double(wgt_sum) / P),
                d.world().footing_reaction().z, sum[8] * ms, sum[9] * ms, sum[10] * ms, sum[11], r.load_s * 1e3);
  }
}

// `bench_dist --state FILE SCENE_HASH nx,ny,nz`: the model grid over a World saved in a
// checkpoint (dem.world.state of a run folder's checkpoint), over its balls' bounding box.
int model_state(const char* file, const char* hash, const char* spec) {
  World w(WorldParams{});
  load_state_file(w, file, std::stoull(hash, nullptr, 16));
  std::vector<WB> all;
  std::vector<std::int64_t> wt, ct;
  contact_weights(w, wt, bench_cost());
  contact_weights(w, ct);
  Vec3 lo = w.balls().x[0], hi = lo;
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    all.push_back({w.balls().x[i], wt[i], ct[i]});
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], w.balls().x[i][k]), hi[k] = std::max(hi[k], w.balls().x[i][k]);
  }
  std::printf("state,%s,step,%lld,footing_z,%.6g\n", file, static_cast<long long>(w.step_count()),
              w.has_footing() ? w.footing().p.bottom_centre.z : 0.0);
  model_imbalance(all, lo, hi - lo, spec);
  return 0;
}

// The DEM node's per-step work on the ranks after a step (dem_node/main.cpp, check_health and the
// history row of a stage under gravity): the guard's finite and escape tests on each rank's rows
// and a maximum over the ranks, the kinetic energy, the mean contact force, the critical step
// (the node's dt_stable) and both ratios. Returns the values (their bits: the same whatever the
// code path).
struct NodeMeasures {
  double kinetic, fc, dt, unbalanced, skeleton;
  std::size_t rattlers;
  int bad;
};
NodeMeasures node_measures(const DistDem& d, const Vec3& lo, const Vec3& hi, double margin) {
  NodeMeasures m{};
  const DistDem::Screen sc = d.screen(lo, hi, true);
  m.bad = !sc.finite || sc.outside > margin;
  m.kinetic = sc.kinetic;
  m.fc = d.mean_contact_force();
  m.dt = d.safe_step();
  const BallRatios r = d.ball_ratios(m.fc);
  m.unbalanced = r.unbalanced;
  m.skeleton = r.skeleton.ratio;
  m.rattlers = r.skeleton.rattlers;
  return m;
}

// `mpirun -np P bench_dist --run DIR [steps] [balance]`: a run's own state on the ranks, as the DEM
// node steps it: the World of a checkpoint folder (DIR/dem.world.state; the folder verified and
// its scene hash read by coord::verify_checkpoint) held by rank 0 alone and sent to the ranks
// (DistDem::load_from_root), cut by RCB over its balls' bounding box (slabs across the longest
// side with BENCH_DIST_DECOMP=slabs, across BENCH_DIST_AXIS=x|y|z if given), free axes unless
// the World is periodic; one DistDem::step(1) per step, the walls (facets,
// footing) and effects of the state moving as they were saved (a footing keeps its last
// velocity; facet vertices stand still: no continuum). The same CSV line as the other modes,
// mode "run", model the ball-ball law. BENCH_DIST_ORDER_FREE=1 (0): run.order_free_sums on (off)
// whatever the state says; BENCH_DIST_PER_RANK=1: a line per rank first (its own times and counts);
// BENCH_DIST_MEASURE=1: after every step the node's measurements (node_measures), timed apart,
// and a line with their time per step and the last step's values in hexadecimal (their bits).
int run_state(int argc, char** argv) {
  int rank = 0, P = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &P);
  const std::filesystem::path dir = argv[2];
  const long steps = argc > 3 ? std::stol(argv[3]) : 1000;
  const int balance = argc > 4 ? std::stoi(argv[4]) : 0;
  World full{WorldParams{}};
  if (rank == 0)  // (the folder checked whole: its manifest, every file's checksum)
    load_state_file(full, dir / "dem.world.state", demfdm::coord::verify_checkpoint(dir).scene_hash);
  if (const char* of = std::getenv("BENCH_DIST_ORDER_FREE"))  // run.order_free_sums on or off
    full.mutable_params().order_free_sums = std::string(of) == "1";
  // rank 0's parameters and box for every rank's DistDem (the others hold no ball)
  double box[7] = {0, 0, 0, 0, 0, 0, 0};
  if (rank == 0) {
    Vec3 lo = full.balls().x[0], hi = lo;
    for (std::size_t i = 0; i < full.num_balls(); ++i)
      for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], full.balls().x[i][k]), hi[k] = std::max(hi[k], full.balls().x[i][k]);
    if (full.periodic()) lo = full.cell_origin(), hi = full.cell_origin() + full.cell_length();
    box[0] = full.periodic() ? 1.0 : 0.0;
    for (int k = 0; k < 3; ++k) box[1 + k] = lo[k], box[4 + k] = hi[k] - lo[k];
  }
  MPI_Bcast(box, 7, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  BrickGrid g;
  g.lo = {box[1], box[2], box[3]};
  g.len = {box[4], box[5], box[6]};
  for (bool& per : g.periodic) per = box[0] != 0.0;
  const char* decomp = std::getenv("BENCH_DIST_DECOMP");
  if (decomp && std::string(decomp) == "slabs") {
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (g.len[k] > g.len[axis]) axis = k;
    g.n[axis_from_env(axis)] = P;  // (the longest side unless named)
  } else {
    g.set_rcb(P);
  }
  WorldParams p = full.params();
  p.threads = omp_get_max_threads();
  DistDem d(MPI_COMM_WORLD, p, g);
  const DistDem::Balance bal = newton_and_balance(d, balance);
  d.set_balance(bal);  // (before the load: its first cut balanced too)
  MPI_Barrier(MPI_COMM_WORLD);
  const double tl0 = MPI_Wtime();
  d.load_from_root(full);
  MPI_Barrier(MPI_COMM_WORLD);
  const double load_s = MPI_Wtime() - tl0;
  d.step(1);  // warm-up
  d.reset_times();
  d.world().reset_phase_times();
  const std::int64_t ex0 = d.exchanges(), mig0 = d.migrated();
  MPI_Barrier(MPI_COMM_WORLD);
  const bool measure = std::getenv("BENCH_DIST_MEASURE") && std::string(std::getenv("BENCH_DIST_MEASURE")) == "1";
  // the guard's box: the balls' bounding box at the load, widened by its own size (margin: 0)
  const Vec3 blo{box[1] - box[4], box[2] - box[5], box[3] - box[6]};
  const Vec3 bhi{box[1] + 2 * box[4], box[2] + 2 * box[5], box[3] + 2 * box[6]};
  if (measure) d.world().keep_force_norms(true);  // (as the node's ranks do)
  NodeMeasures last{};
  double measure_s = 0.0;
  const double t0 = MPI_Wtime();
  for (long k = 0; k < steps; ++k) {
    d.step(1);
    if (measure) {
      const double tm = MPI_Wtime();
      last = node_measures(d, blo, bhi, 0.0);
      measure_s += MPI_Wtime() - tm;
    }
  }
  MPI_Barrier(MPI_COMM_WORLD);
  const double wall = MPI_Wtime() - t0;
  if (measure && rank == 0)
    std::printf("measure,ms_per_step,%.4f,kinetic,%a,fc,%a,dt,%a,unbalanced,%a,skeleton,%a,rattlers,%zu,bad,%d\n",
                measure_s * 1e3 / double(steps), last.kinetic, last.fc, last.dt, last.unbalanced, last.skeleton,
                last.rattlers, last.bad);
  const std::size_t balls = d.num_balls();
  if (std::getenv("BENCH_DIST_PER_RANK")) {  // each rank's own compute and counts, in rank order
    for (int r = 0; r < P; ++r) {
      if (r == rank) {
        const PhaseTimes& pt = d.world().phase_times();
        // the listed pairs by what the pass does with them: a bond (intact or softening: vector lanes),
        // an unbonded contact that touches (the scalar law), an unbonded pair apart (skipped)
        const PairContacts& pc = d.world().pair_contacts();
        std::size_t bonded_n = 0, touching = 0;
        for (std::size_t c = 0; c < pc.size(); ++c) {
          if (!pc.bond.empty() && bonded(pc.bond[c].state)) ++bonded_n;
          else if (pc.h[c].flags & ContactHist::kActive) ++touching;
        }
        std::printf("rank,%d,bonded,%zu,unbonded_touching,%zu,unbonded_apart,%zu\n", rank, bonded_n, touching,
                    pc.size() - bonded_n - touching);
        std::printf("rank,%d,owned,%zu,ghosts,%zu,pairs,%zu,facet_contacts,%zu,motion_ms,%.4f,forces_ms,%.4f,pair_ms,%.4f,"
                    "facet_ms,%.4f,rebuild_ms,%.4f,walls_ms,%.4f\n",
                    rank, d.owned(), d.ghosts(), d.world().pair_contacts().size(), d.world().facet_contacts().size(),
                    d.times().motion * 1e3 / double(steps), d.times().forces * 1e3 / double(steps), pt.pair * 1e3 / double(steps),
                    pt.facet * 1e3 / double(steps), pt.rebuild * 1e3 / double(steps), d.times().walls * 1e3 / double(steps));
        std::fflush(stdout);
      }
      MPI_Barrier(MPI_COMM_WORLD);
    }
  }
  report(d, {P, rank, "run", to_string(p.ball_ball.model), balls, steps, wall, load_s, ex0, mig0});
  return 0;
}

}  // namespace

// `bench_dist --merge P N`: rank 0's merge of the walls' shares (DistDem::reduce_walls) without
// MPI: P sorted runs of N facet shares each (ball ids dealt to the runs at random), put in one
// World's order by order_wall_shares (a radix order of the keys, as reduce_walls does), by
// merge_runs (pairwise, O(n log P)) and, as the reference in the same run, by merging each run
// into the growing front as reduce_walls did before session 20 (O(n P)). Prints the best of 5
// of each, in ns per share.
int merge_bench(int P, long N) {
  std::mt19937_64 rng(5);
  std::vector<std::vector<WallSumRec>> runs(static_cast<std::size_t>(P));
  for (std::uint64_t id = 0; id < static_cast<std::uint64_t>(P) * static_cast<std::uint64_t>(N); ++id) {
    WallSumRec r;
    r.ball = id;
    r.kind = 1;
    r.F = {double(id), 1.0, 2.0};
    runs[rng() % static_cast<std::uint64_t>(P)].push_back(r);
  }
  const auto less = [](const WallSumRec& x, const WallSumRec& y) {
    return x.ball != y.ball ? x.ball < y.ball : x.wall < y.wall;
  };
  std::vector<WallSumRec> all, tmp;
  std::vector<std::size_t> starts;
  auto lay_out = [&] {
    all.clear();
    starts.clear();
    for (const auto& r : runs) {
      starts.push_back(all.size());
      all.insert(all.end(), r.begin(), r.end());
    }
    starts.push_back(all.size());
  };
  double best_new = 1e30, best_old = 1e30, best_pair = 1e30;
  for (int rep = 0; rep < 5; ++rep) {
    lay_out();
    double t0 = MPI_Wtime();
    order_wall_shares(all, starts);
    best_new = std::min(best_new, MPI_Wtime() - t0);
    bool ok = std::is_sorted(all.begin(), all.end(), less);
    lay_out();
    t0 = MPI_Wtime();
    merge_runs(all, starts, less);
    best_pair = std::min(best_pair, MPI_Wtime() - t0);
    ok = ok && std::is_sorted(all.begin(), all.end(), less);
    // the reference: each run appended, then merged with the front through a buffer
    all.clear();
    t0 = MPI_Wtime();
    for (const auto& r : runs) {
      const std::size_t mid = all.size();
      all.insert(all.end(), r.begin(), r.end());
      if (mid > 0 && all.size() > mid) {
        tmp.resize(all.size());
        std::merge(all.begin(), all.begin() + static_cast<std::ptrdiff_t>(mid), all.begin() + static_cast<std::ptrdiff_t>(mid),
                   all.end(), tmp.begin(), less);
        std::copy(tmp.begin(), tmp.end(), all.begin());
      }
    }
    best_old = std::min(best_old, MPI_Wtime() - t0);
    if (!ok || !std::is_sorted(all.begin(), all.end(), less)) {
      std::fprintf(stderr, "merge bench: not sorted\n");
      return 1;
    }
  }
  const double n = double(P) * double(N);
  std::printf("merge,ranks,%d,shares,%.0f,bytes_per_share,%zu,radix_ns_per_share,%.2f,pairwise_ns_per_share,%.2f,"
              "front_ns_per_share,%.2f,front_over_radix,%.2f\n",
              P, n, sizeof(WallSumRec), best_new / n * 1e9, best_pair / n * 1e9, best_old / n * 1e9, best_old / best_new);
  return 0;
}

// The --rev and --replicate benches' REV of n balls (`rp`: its count and porosity set here): a
// periodic cube of edge L at the default scene's porosity, soft bond law, one thread per rank.
WorldParams rev_bench_world(RevParams& rp, long n, double& L) {
  rp.n_particles = static_cast<std::size_t>(n);
  rp.porosity_final = 0.52042;
  L = std::cbrt(static_cast<double>(n) / psd_expected_count(rp.psd, 1.0, rp.porosity_final));
  WorldParams p;
  p.periodic.enabled = true;
  p.periodic.length = {L, L, L};
  p.ball_ball.model = ContactModel::kSoftBond;
  p.skin_factor = 0.8;  // (the default scene's)
  p.dt_fixed = 0.0;
  p.threads = 1;
  p.thread_independent = true;
  return p;
}

// `mpirun -np P bench_dist --rev N [seed]` (above).
int rev_bench(long n, std::uint64_t seed) {
  int rank = 0, P = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &P);
  RevParams rp = scene_rev_defaults();
  rp.seed = seed;
  double L = 0.0;
  WorldParams p = rev_bench_world(rp, n, L);
  // BENCH_REV_ORDER_FREE=1: run.order_free_sums (the servo's sums folded by every rank, not on rank 0)
  const char* of = std::getenv("BENCH_REV_ORDER_FREE");
  p.order_free_sums = of && std::string(of) == "1";
  World full(p);
  BrickGrid g;
  g.lo = {0.0, 0.0, 0.0};
  g.len = {L, L, L};
  for (bool& q : g.periodic) q = true;
  g.set_rcb(P);
  DistDem d(MPI_COMM_WORLD, p, g);
  MPI_Barrier(MPI_COMM_WORLD);
  double t0 = MPI_Wtime();
  StageReport gen = generate_rev(d, full, rp);
  const double t_gen = MPI_Wtime() - t0;
  const DistDem::Times tg = d.times();
  // bonds to the paper's Z on the ranks, the REV assembled on rank 0 (as the node's generate stage)
  bond_specimen(d, gen, 6.82, 1e-3 * rp.psd.d_min * rp.psd.scale);
  d.unload(full, true);
  DistDem s(MPI_COMM_WORLD, p, g);
  s.load_from_root(full);
  MPI_Barrier(MPI_COMM_WORLD);
  t0 = MPI_Wtime();
  const StageReport sv = servo_specimen(s, ServoParams{}, 0.005, 1e-4, 160.0, 16000.0, 0.1);
  const double t_servo = MPI_Wtime() - t0;
  const DistDem::Times ts = s.times();
  // where each phase's time went on this rank [s]: motion (the servo's sums inside), forces,
  // forward, reduce, exchange; rank 0 prints every rank's
  const double mine[10] = {tg.motion, tg.forces, tg.forward, tg.reduce, tg.exchange,
                           ts.motion, ts.forces, ts.forward, ts.reduce, ts.exchange};
  std::vector<double> all(rank == 0 ? 10 * static_cast<std::size_t>(P) : 0);
  MPI_Gather(mine, 10, MPI_DOUBLE, all.data(), 10, MPI_DOUBLE, 0, MPI_COMM_WORLD);
  if (rank == 0) {
    std::printf("phase,ranks,balls,steps,wall_s,particle_steps_per_s,converged\n");
    if (P == 1) {  // one World without DistDem (the node at dem.ranks = 1): the ranks' overhead at 1 rank
      World w(p);
      double t1 = MPI_Wtime();
      StageReport wg = generate_rev(w, rp);
      const double tw_gen = MPI_Wtime() - t1;
      bond_specimen(w, wg, 6.82, 1e-3 * rp.psd.d_min * rp.psd.scale);
      t1 = MPI_Wtime();
      const StageReport ws = servo_specimen(w, ServoParams{}, 0.005, 1e-4, 160.0, 16000.0, 0.1);
      const double tw_servo = MPI_Wtime() - t1;
      std::printf("expansion_one_world,1,%zu,%" PRId64 ",%.3f,%.4g,%d\n", wg.count, wg.steps, tw_gen,
                  static_cast<double>(wg.count) * static_cast<double>(wg.steps) / tw_gen, wg.converged ? 1 : 0);
      std::printf("servo_one_world,1,%zu,%" PRId64 ",%.3f,%.4g,%d\n", wg.count, ws.steps, tw_servo,
                  static_cast<double>(wg.count) * static_cast<double>(ws.steps) / tw_servo, ws.converged ? 1 : 0);
    }
    std::printf("expansion,%d,%zu,%" PRId64 ",%.3f,%.4g,%d\n", P, gen.count, gen.steps, t_gen,
                static_cast<double>(gen.count) * static_cast<double>(gen.steps) / t_gen, gen.converged ? 1 : 0);
    std::printf("servo,%d,%zu,%" PRId64 ",%.3f,%.4g,%d\n", P, gen.count, sv.steps, t_servo,
                static_cast<double>(gen.count) * static_cast<double>(sv.steps) / t_servo, sv.converged ? 1 : 0);
    for (int r = 0; r < P; ++r) {
      const double* a = all.data() + 10 * r;
      std::printf("times,rank,%d,expansion_motion_forces_forward_reduce_exchange_s,%.3f,%.3f,%.3f,%.3f,%.3f,"
                  "servo_motion_forces_forward_reduce_exchange_s,%.3f,%.3f,%.3f,%.3f,%.3f\n",
                  r, a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7], a[8], a[9]);
    }
  }
  return 0;
}

// This process's resident set now [MB] (/proc/self/statm).
double resident_mb() {
  long pages = 0, resident = 0;
  if (FILE* f = std::fopen("/proc/self/statm", "r")) {
    if (std::fscanf(f, "%ld %ld", &pages, &resident) != 2) resident = 0;
    std::fclose(f);
  }
  return static_cast<double>(resident) * static_cast<double>(sysconf(_SC_PAGESIZE)) / 1048576.0;
}

// `mpirun -np P bench_dist --replicate N nx ny nz`: a REV of N balls (the --rev scene's, generated
// and bonded to Z = 6.82 on rank 0, not timed) replicated nx x ny x nz into a block cut by RCB:
// (1) on the ranks, each building its part (dem::replicate on a DistDem, as the node's replicate
// stage), then (2) as before session 31: the whole block replicated on rank 0 and cut and sent
// (replicate, load_from_root). One line per way: way, ranks, balls, wall_s, then per rank its
// part's rows and pairs and its resident set after the way [MB] (rank 0 first).
int replicate_bench(long n, int nx, int ny, int nz) {
  int rank = 0, P = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &P);
  RevParams rp = scene_rev_defaults();
  double L = 0.0;
  const WorldParams p = rev_bench_world(rp, n, L);
  std::string rev_bytes;
  if (rank == 0) {
    World rev(p);
    StageReport g = generate_rev(rev, rp);
    bond_specimen(rev, g, 6.82, 1e-3 * rp.psd.d_min * rp.psd.scale);
    rev_bytes = state_bytes(rev, CheckpointMeta{});
  }
  ReplicateParams q;
  q.nx = nx, q.ny = ny, q.nz = nz;
  BrickGrid g;
  g.lo = {0.0, 0.0, 0.0};
  g.len = {nx * L, ny * L, nz * L};
  g.set_rcb(P);
  auto report = [&](const char* way, const DistDem& d, std::size_t balls, double wall) {
    const double mine[3] = {static_cast<double>(d.world().num_balls()), static_cast<double>(d.world().pair_contacts().size()),
                            resident_mb()};
    std::vector<double> all(rank == 0 ? 3 * static_cast<std::size_t>(P) : 0);
    MPI_Gather(mine, 3, MPI_DOUBLE, all.data(), 3, MPI_DOUBLE, 0, MPI_COMM_WORLD);
    if (rank != 0) return;
    std::printf("%s,ranks,%d,balls,%zu,wall_s,%.3f", way, P, balls, wall);
    for (int r = 0; r < P; ++r)
      std::printf(",rank%d_rows_pairs_rss_mb,%.0f,%.0f,%.1f", r, all[3 * r], all[3 * r + 1], all[3 * r + 2]);
    std::printf("\n");
  };
  {
    World rev(p);
    if (rank == 0) load_state_bytes(rev, rev_bytes, 0, "the REV");
    DistDem d(MPI_COMM_WORLD, p, g);
    MPI_Barrier(MPI_COMM_WORLD);
    const double t0 = MPI_Wtime();
    const StageReport r = replicate(d, rev, q);
    MPI_Barrier(MPI_COMM_WORLD);
    report("replicate_on_ranks", d, r.count, MPI_Wtime() - t0);
  }
  {
    World block(p);
    if (rank == 0) load_state_bytes(block, rev_bytes, 0, "the REV");
    DistDem d(MPI_COMM_WORLD, p, g);
    MPI_Barrier(MPI_COMM_WORLD);
    const double t0 = MPI_Wtime();
    StageReport r;
    if (rank == 0) r = replicate(block, q);
    d.load_from_root(block);
    MPI_Barrier(MPI_COMM_WORLD);
    report("replicate_on_rank0_then_cut", d, r.count, MPI_Wtime() - t0);
  }
  return 0;
}

int main(int argc, char** argv) {
  if (argc == 5 && std::string(argv[1]) == "--state") return model_state(argv[2], argv[3], argv[4]);
  if (argc == 4 && std::string(argv[1]) == "--merge") return merge_bench(std::atoi(argv[2]), std::atol(argv[3]));
  MPI_Init(&argc, &argv);
  if (argc >= 3 && std::string(argv[1]) == "--rev") {
    const int rc = rev_bench(std::atol(argv[2]), argc > 3 ? std::strtoull(argv[3], nullptr, 10) : 1);
    MPI_Finalize();
    return rc;
  }
  if (argc == 6 && std::string(argv[1]) == "--replicate") {
    const int rc = replicate_bench(std::atol(argv[2]), std::atoi(argv[3]), std::atoi(argv[4]), std::atoi(argv[5]));
    MPI_Finalize();
    return rc;
  }
  if (argc >= 3 && std::string(argv[1]) == "--run") {
    int rc = 0;
    try {
      rc = run_state(argc, argv);
    } catch (const std::exception& e) {  // a wrong or unreadable checkpoint: one line, not an abort's trace
      std::fprintf(stderr, "bench_dist --run: %s\n", e.what());
      MPI_Abort(MPI_COMM_WORLD, 2);
    }
    MPI_Finalize();
    return rc;
  }
  int rank = 0, P = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &P);
  const std::string file = argc > 1 ? argv[1] : DEMFDM_BENCH_PACKING;
  const std::string model = argc > 2 ? argv[2] : "linear";
  const long steps = argc > 3 ? std::stol(argv[3]) : 1000;
  const std::string mode = argc > 4 ? argv[4] : "strong";
  const int balance = argc > 5 ? std::stoi(argv[5]) : 0;
  if ((model != "linear" && model != "softbond") || (mode != "strong" && mode != "weak" && mode != "footing") ||
      balance < 0) {
    if (rank == 0)
      std::fprintf(stderr, "usage: bench_dist [packing] [linear|softbond] [steps] [strong|weak|footing] [balance]\n");
    MPI_Abort(MPI_COMM_WORLD, 2);
  }
  const bool footing = mode == "footing";
  Packing pk = load(file);
  const int copies = mode == "weak" ? P : 1;
  const int copy_axis = axis_from_env(0);  // weak: the copies lie along it, the cuts across it
  if (footing && std::getenv("BENCH_DIST_REPLICATE")) {  // K x K x K copies of the periodic packing
    const int K = std::atoi(std::getenv("BENCH_DIST_REPLICATE"));
    const Vec3 L = pk.hi - pk.lo;
    Packing big;
    big.lo = pk.lo;
    big.hi = pk.lo + static_cast<double>(K) * L;
    for (int a = 0; a < K; ++a)
      for (int b = 0; b < K; ++b)
        for (int c = 0; c < K; ++c)
          for (std::size_t i = 0; i < pk.x.size(); ++i) {
            big.x.push_back(pk.x[i] + Vec3{a * L.x, b * L.y, c * L.z});
            big.r.push_back(pk.r[i]);
          }
    pk = std::move(big);
  }
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
  p.periodic.length = L0;
  p.periodic.length[copy_axis] *= copies;
  p.ball_ball.model = model == "softbond" ? ContactModel::kSoftBond : ContactModel::kLinear;
  p.ball_ball.linear.kn_fixed = 2.55e5;
  p.ball_ball.linear.kratio = 2.4;
  p.ball_ball.linear.fric = 0.6248693519093275;
  p.skin = 0.1 * 2.0 * 0.058e-3;
  if (footing) {  // a box of planes (the balls' stiffness) and the footing
    p.periodic.enabled = false;
    p.gravity = true;
    p.g_level = 100.0;
    p.ball_wall.linear.kn_fixed = p.ball_footing.linear.kn_fixed = p.ball_ball.linear.kn_fixed;
  }
  World full(p);
  // footing: the balls that cross the box's planes are left out (a specimen carved from the
  // periodic packing, without explosive initial overlaps with the planes)
  auto inside = [&](std::size_t k) {
    const Vec3& x = pk.x[k];
    const double r = pk.r[k];
    return x.x - r > pk.lo.x && x.x + r < pk.hi.x && x.y - r > pk.lo.y && x.y + r < pk.hi.y && x.z - r > pk.lo.z;
  };
  for (int c = 0; c < copies; ++c) {
    Vec3 shift{};
    shift[copy_axis] = c * L0[copy_axis];
    for (std::size_t k : order)
      if (!footing || inside(k)) full.add_ball(pk.x[k] + shift, pk.r[k]);
  }
  double rmean = 0.0, ztop = -1e300;
  for (std::size_t i = 0; i < pk.r.size(); ++i) {
    rmean += pk.r[i] / double(pk.r.size());
    ztop = std::max(ztop, pk.x[i].z + pk.r[i]);
  }
  if (footing) {
    full.add_plane({pk.lo, {0, 0, 1}});
    full.add_plane({pk.lo, {1, 0, 0}});
    full.add_plane({pk.lo, {0, 1, 0}});
    full.add_plane({pk.hi, {-1, 0, 0}});
    full.add_plane({pk.hi, {0, -1, 0}});
    FootingParams fp;
    fp.diameter = 0.5 * L0.x;
    fp.height = 0.3 * L0.z;
    fp.bottom_centre = {0.5 * (pk.lo.x + pk.hi.x), 0.5 * (pk.lo.y + pk.hi.y), ztop};
    full.set_footing(fp);
  }
  full.prepare();
  if (p.ball_ball.model == ContactModel::kSoftBond) full.bond_ball_ball(-1.0, 0.0);
  if (!footing) {
    const double edot = p.skin / 3.0 / (30.0 * full.dt() * p.periodic.length.x);
    full.set_strain_rate({edot, -edot, 0.0});
  }
  BrickGrid g;
  g.lo = p.periodic.origin;
  g.len = p.periodic.length;
  for (bool& per : g.periodic) per = !footing;
  const char* decomp = std::getenv("BENCH_DIST_DECOMP");
  if (decomp && std::string(decomp) == "rcb") {
    g.set_rcb(P);
  } else {
    const int axis = footing ? 2 : 0;
    g.n[axis_from_env(axis)] = P;  // (weak: across the axis the copies lie along)
  }
  DistDem d(MPI_COMM_WORLD, p, g);
  const DistDem::Balance bal = newton_and_balance(d, balance);
  if (!std::getenv("BENCH_DIST_BALANCE_AFTER_LOAD")) d.set_balance(bal);  // (before the load: its first cut balanced too)
  const char* from_root = std::getenv("BENCH_DIST_FROM_ROOT");
  MPI_Barrier(MPI_COMM_WORLD);
  const double tl0 = MPI_Wtime();
  if (from_root && std::string(from_root) == "1") {
    World none(p);  // the other ranks hold no ball: rank 0 cuts and sends
    d.load_from_root(rank == 0 ? full : none);
  } else {
    d.load(full);
  }
  MPI_Barrier(MPI_COMM_WORLD);
  const double load_s = MPI_Wtime() - tl0;
  d.set_balance(bal);
  if (footing) {  // the packing settles in its box (the footing at rest), then the footing moves
    const char* relax = std::getenv("BENCH_DIST_RELAX");
    const long n_relax = relax ? std::atol(relax) : 2000;
    for (int round = 0; round < 4; ++round) {  // rattlers shot out by the released overlaps are stopped
      d.step(n_relax / 4);
      Particles& b = d.world().balls();
      std::fill(b.v.begin(), b.v.end(), Vec3{});
      std::fill(b.w.begin(), b.w.end(), Vec3{});
    }
    d.world().set_footing_velocity({0, 0, -2.0 * rmean / (double(steps + 20) * d.world().dt())});
  }
  d.step(20);  // warm-up
  d.reset_times();
  d.world().reset_phase_times();
  const std::int64_t ex0 = d.exchanges(), mig0 = d.migrated();
  MPI_Barrier(MPI_COMM_WORLD);
  const double t0 = MPI_Wtime();
  if (footing) {  // one step per call, as the node at coupling.interval = 1: the walls' sums every step
    for (long k = 0; k < steps; ++k) d.step(1);
  } else {
    d.step(steps);
  }
  MPI_Barrier(MPI_COMM_WORLD);
  const double wall = MPI_Wtime() - t0;
  report(d, {P, rank, mode, model, full.num_balls(), steps, wall, load_s, ex0, mig0});
  if (const char* mg = std::getenv("BENCH_DIST_MODEL_GRID")) model_grid(d, g, mg);
  MPI_Finalize();
  return 0;
}
