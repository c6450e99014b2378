// The DEM on MPI ranks (issue 17; docs/scaling.md): space cut into bricks (a grid, or the leaves
// of an RCB tree), one brick per rank. A rank's World holds the balls whose centres lie in its
// brick (owned) and copies of the balls within reach of it (ghosts), every row in ball-id order
// (with newton on: the owned rows in id order, then the ghosts in id order, which the World does
// not integrate), and the ball-ball pairs that have an owned ball. A pair of an owned ball and a ghost is
// computed on both ranks, from the same inputs, so both keep the same history (LAMMPS's
// `newton off` for pairs). With set_newton(true) it is computed once, on the owner of its ball
// A, and its force on the ghost goes back to the ghost's owner (`newton on`; not one World's
// bits, see set_newton).
//
// Every step: the World's first half (integration), then the ghosts' x, v, ω from their owners
// (point to point with the ranks that share ghosts with this one), then the rebuild test over
// every rank's own balls, then at a rebuild the migration (balls to
// the rank of their brick, with their contacts' histories) and new ghosts, then the World's
// second half (rebuild, force pass). Rows in id order make each owned ball's sums those of one
// World holding every ball (docs/scaling.md), so positions, velocities, forces and histories are
// the same bits at any rank count (tests/dist).
//
// Walls, facets and the footing are on every rank, each moving them itself; a rank holds the
// wall contacts of its own balls (they migrate with them). At the end of step(n) each wall's sums
// (reactions, servo gains, facet vertex forces and stiffness) are formed on rank 0 from every
// rank's contacts, merged in the order of one World, and sent to every rank (reduce_walls): the
// sums of one World, on every rank.
//
// What this version covers: balls, ball-ball and ball-wall contacts of every law, periodic cells
// (also strained) and free space, gravity, the fixed or the automatic step (the smallest over
// the ranks), dynamic balancing, the node's measurements, and one World again from the ranks'
// parts (unload: output, checkpoints, the next stage's set-up), platen servos (every rank runs
// them on the walls' sums, reduced after every step then), and the specimen procedures: the
// REV's expansion and periodic servo, the bonding, the replication (each rank building its part
// of the block), the depth scaling and the interface bonds, each with one World's bits (the free
// functions at the end). Not yet: the other effects (load refuses them).
#pragma once

#include <mpi.h>

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <vector>

#include "demfdm/dem/balance_cost.hpp"
#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem {

/// A brick grid over [lo, lo + len): n[0] x n[1] x n[2] bricks; brick (i, j, k) is rank
/// i + n0 (j + n1 k). On a periodic axis a point is wrapped into the cell first; on a free axis a
/// point outside [lo, lo + len) belongs to the nearest brick. The cuts along an axis are even
/// unless `cuts` gives them (shifted by DistDem's balancing).
///
/// Or, with `parts` > 0, recursive coordinate bisection (RCB, as LAMMPS's `balance rcb`): the box
/// [lo, lo + len) is cut in two across one axis, the low side taking the first p / 2 of the
/// node's p ranks, and each side again, until every part is one rank. `rcb` holds the inner
/// nodes' cuts in preorder: a node's low child (if inner) follows it, its high child comes after
/// the low child's p / 2 - 1 inner nodes. A point at a cut belongs to the high side, as at a grid
/// cut. `n` and `cuts` are then unused.
struct BrickGrid {
  Vec3 lo{}, len{};
  int n[3] = {1, 1, 1};
  bool periodic[3] = {false, false, false};
  /// Per axis: empty (even cuts), or the n[k] - 1 inner cuts, increasing, in (0, len[k]) from lo.
  std::vector<double> cuts[3];
  struct Cut {
    int axis = 0;
    double at = 0.0;  // from lo, as `cuts`
  };
  std::vector<Cut> rcb;  // parts - 1 inner nodes, preorder (empty with parts == 0: the grid)
  int parts = 0;
  int count() const { return parts > 0 ? parts : n[0] * n[1] * n[2]; }
  /// RCB over `p` ranks (p >= 1) with geometric cuts: each node cut across its box's longest side
  /// (the lowest axis of equal ones) at the share of its low child, p / 2 of p.
  void set_rcb(int p);
  /// Rank r's brick along each axis, from lo: [a0[k], a1[k]) (on a free axis the end bricks also
  /// own what lies beyond 0 and len[k]).
  void box(int r, double a0[3], double a1[3]) const;
  /// Start of brick i along axis k, from lo (edge(k, 0) = 0, edge(k, n[k]) = len[k]).
  double edge(int k, int i) const {
    if (i <= 0) return 0.0;
    if (i >= n[k]) return len[k];
    return cuts[k].empty() ? i * (len[k] / n[k]) : cuts[k][static_cast<std::size_t>(i - 1)];
  }
  int owner(const Vec3& x) const;
  /// A periodic cell that strained (the servo): on each periodic axis the grid is mapped as the
  /// World maps the positions, affinely about the cell's origin, onto [origin, origin + length):
  /// the bricks keep their share of the cell and their balls (DistDem::step, before an exchange).
  void follow_cell(const Vec3& origin, const Vec3& length);
  /// Every rank whose brick, grown by `halo` on each side, holds x or (periodic axes) an image of
  /// x; ascending, without repeats.
  void near(const Vec3& x, double halo, std::vector<int>& out) const;
};

/// The balancing's weight of every row of `w`: its modelled cost per step (ContactCost): the row
/// itself, half of each listed pair by what the pass does with it (a bond, a contact that touches,
/// a pair apart) and each of its wall contacts (a facet contact, a plane or the footing).
void contact_weights(const World& w, std::vector<std::int64_t>& wt, const ContactCost& cost = {});

/// The inner cuts of `n` slabs of equal weight along an axis of length `len`, from the weights of
/// `hist.size()` even bins: cut j at the end of the first bin where the running weight reaches
/// j/n of the total, at least one bin per slab (DistDem's balancing, bench_dist's model grids).
std::vector<double> equal_weight_cuts(const std::vector<std::int64_t>& hist, int n, double len);

/// RCB cuts of `g` (g.parts > 0) by weight: each cut of the tree, level by level from the root,
/// across the longest side of its node's box, at the end of the first of `bins` even bins along it
/// where the weight of the points `x` (weights `wt`; `skip`, if not empty: points left out) in
/// the node reaches the low child's share, p / 2 of p. `reduce` sums a level's bins over the
/// ranks (an integer allreduce; nothing on one process), so every rank finds the same cuts.
void rcb_cuts(BrickGrid& g, const std::vector<Vec3>& x, const std::vector<std::int64_t>& wt,
              const std::vector<std::uint8_t>& skip, int bins,
              const std::function<void(std::vector<std::int64_t>&)>& reduce);

/// Merges the sorted runs v[starts[j], starts[j + 1]) (starts ascending, its last entry the end
/// of the last run) into one sorted run, pairwise from the bottom up: O(n log runs), where
/// merging each run into the growing front would cost O(n runs). Stable: equal keys keep the
/// order of their runs. (Rank 0 merges the ranks' records in one World's order with it.)
template <class T, class Less>
void merge_runs(std::vector<T>& v, const std::vector<std::size_t>& starts, Less less) {
  if (starts.size() < 3) return;
  const std::size_t runs = starts.size() - 1;
  for (std::size_t width = 1; width < runs; width *= 2)
    for (std::size_t r = 0; r + width < runs; r += 2 * width) {
      const std::size_t hi = std::min(r + 2 * width, runs);
      std::inplace_merge(v.begin() + static_cast<std::ptrdiff_t>(starts[r]),
                         v.begin() + static_cast<std::ptrdiff_t>(starts[r + width]),
                         v.begin() + static_cast<std::ptrdiff_t>(starts[hi]), less);
    }
}

/// The stable order of `keys` (order[j]: the index of the j-th smallest; equal keys in index
/// order), by a least-significant-digit radix sort of 11-bit digits over the bits the largest key
/// uses: O(n) per digit. (Rank 0 orders the walls' shares of every rank with it: merging the
/// ranks' sorted runs cost 53 ns per share at 64 ranks and 120 ns at 1,024, docs/scaling.md.)
void radix_order(const std::vector<std::uint64_t>& keys, std::vector<std::uint32_t>& order);

/// The walls' shares v[starts.front(), starts.back()) of one kind, sorted runs that begin at
/// `starts` (one per rank), put in one World's order, (ball id, wall), stably (radix_order; the
/// walls' sums of reduce_walls). T: WallSumRec or FacetSumShare.
template <class T>
void order_wall_shares(std::vector<T>& v, const std::vector<std::size_t>& starts);

/// Every rank's records on rank 0, in rank order (the other ranks get an empty array); `starts`
/// (rank 0): where each rank's records begin, and their end. Collective.
template <class T>
void gather_on_root(MPI_Comm comm, const std::vector<T>& mine, std::vector<T>& all, std::vector<std::size_t>* starts = nullptr);
template <class T>
std::vector<T> gather_on_root(MPI_Comm comm, const std::vector<T>& mine, std::vector<std::size_t>* starts = nullptr) {
  std::vector<T> all;
  gather_on_root(comm, mine, all, starts);
  return all;
}
/// The same into `all` (rank 0; the others get it empty), whose memory a caller can keep from
/// call to call.
template <class T>
void gather_on_root(MPI_Comm comm, const std::vector<T>& mine, std::vector<T>& all, std::vector<std::size_t>* starts) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const int bytes = static_cast<int>(mine.size() * sizeof(T));
  std::vector<int> counts(static_cast<std::size_t>(size)), displ(static_cast<std::size_t>(size));
  MPI_Gather(&bytes, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm);
  int total = 0;
  for (int r = 0; r < size; ++r) {
    displ[static_cast<std::size_t>(r)] = total;
    total += counts[static_cast<std::size_t>(r)];
  }
  if (starts && rank == 0) {
    starts->clear();
    for (int r = 0; r < size; ++r) starts->push_back(static_cast<std::size_t>(displ[static_cast<std::size_t>(r)]) / sizeof(T));
    starts->push_back(static_cast<std::size_t>(total) / sizeof(T));
  }
  all.resize(rank == 0 ? static_cast<std::size_t>(total) / sizeof(T) : 0);
  MPI_Gatherv(mine.data(), bytes, MPI_BYTE, all.data(), counts.data(), displ.data(), MPI_BYTE, 0, comm);
}

class DistDem {
 public:
  /// The ranks of `comm` must number grid.count().
  DistDem(MPI_Comm comm, const WorldParams& p, const BrickGrid& grid);
  ~DistDem();

  /// Take the balls and ball-ball contacts of `full`, the same World on every rank (built the
  /// same way): each rank keeps its own balls, their ghosts and their pairs, in id order (with
  /// newton on, the ghosts after the owned balls). A
  /// prepared `full` (stepped or not since) is taken as it is, lists, histories, wall candidates
  /// and last forces included, so the ranks step on as `full` would; an unprepared one is
  /// prepared on the ranks, as `full.prepare()` would. A rank's thread count is the one of the
  /// parameters it constructed this DistDem with, not `full`'s.
  void load(const World& full);
  /// As load(full), with the whole World on rank 0 only (collective): the other ranks' `full` is
  /// not read (an empty World will do), so a rank other than 0 never holds more than its part.
  /// Rank 0 cuts `full` into each rank's part (its rows, pairs, wall contacts, the walls, the
  /// cell, the effects and the counters) and sends it as a World's state file in memory (the
  /// checkpoint format, bit for bit), one rank at a time. The same bits as load(full) on every
  /// rank. A `full` that load refuses is refused on every rank, with rank 0's message. A rank's
  /// thread count is the one of the parameters it constructed this DistDem with.
  void load_from_root(const World& full);
  /// The block that replicate(rev, p) (specimen.hpp) would make of the REV `rev`, loaded as
  /// load(block) would load it, without the block: each rank builds only the copies of the REV's
  /// balls that its part holds (its brick's, those within the halo, the partners of its pairs)
  /// and the copied pairs it computes, from the copy's index and the REV's rows and pairs
  /// (ReplicaLayout), and prepares them on the ranks as block.prepare() would. The same bits as
  /// replicate then load, on every rank (docs/scaling.md). `rev`: the prepared REV, the same bits
  /// on every rank; it is taken (it becomes this rank's share of the block, from which the part
  /// is cut). The grid is the block's (the REV's cell origin, n times its length; periodic axes
  /// with keep_periodic). The first cut is the grid's as constructed: balancing starts at the
  /// first rebalancing (set_balance). Returns the block's counts of REV pairs copied and dropped
  /// on its free faces (replicate's report). Collective.
  struct Replicated {
    std::int64_t kept = 0, dropped = 0;
  };
  Replicated load_replicated(World& rev, const ReplicateParams& p);
  /// One World holding every ball, on every rank (collective): `full` gets the state one World
  /// stepped as this one was would have (balls, contact lists in that World's orders with their
  /// histories and last forces, wall contacts with their candidates, the walls, the counters), so
  /// that it steps on with the same bits, is saved, measured or written as output, or set up for
  /// the next stage and loaded again. `full` must be the World this one was loaded from (its
  /// parameters and ids of walls and balls are kept where the ranks do not change them). Not the
  /// same bits as one World: the energies of local damping and of dropped contacts, summed rank by
  /// rank (docs/scaling.md).
  /// With `root_only`, `full` is assembled on rank 0 only (a gather, not an all-gather); the
  /// other ranks' `full` is left as it was.
  void unload(World& full, bool root_only = false) const;
  /// The state file (dem/checkpoint.hpp) of the World that unload(full, true) would assemble on
  /// rank 0, written by rank 0 to `path`, byte for byte save_state_file of that World, without
  /// assembling it: every rank gives its balls by id and the pairs whose ball A it owns by
  /// (A, B) id (made a block at a time from its rows when these are in those orders, as with
  /// newton off; else from a sorted copy); rank 0 merges the ranks' rows as they arrive, in
  /// blocks of `block` rows, and
  /// writes each block into the file's columns in place (StateStream); it keeps the balls' ids
  /// (8 bytes a ball) to turn a contact's ids into rows, and reads the wall contacts whole
  /// (they grow with the walls, not with the block). Rank 0's `full` gets what unload gives it
  /// besides the balls and contacts (the walls, the parameters, the counters); its own balls and
  /// contacts are not written (rank 0's World holds none while the ranks step). Collective; when
  /// rank 0 cannot write, every rank throws (rank 0 its error, the others naming it), and no
  /// file is left under `path`'s name.
  void save_state_file(World& full, const std::filesystem::path& path, const CheckpointMeta& meta,
                       std::size_t block = 16384) const;
  /// The parts of the World saved in the state file `path` (checkpoint.hpp), as load(that World)
  /// would make them, without the World on any rank: rank 0 reads the file in blocks of `block`
  /// rows (StateSource), finds each ball's owner, and sends every rank the balls its part holds
  /// (cut's rule: within the halo of its brick, its own, the partners of its pairs), the pairs it
  /// computes and its balls' wall contacts; each rank cuts its part from that share. Rank 0 keeps
  /// 4 bytes a ball (the owners) and the pairs across bricks. Every rank's `frame` gets the
  /// World's other state (parameters, counters, effects, walls; no ball), as the node's World
  /// while the ranks step; with `ids`, rank 0 gets the balls' ids in row order. The first cut is
  /// the grid's as constructed (a balanced one at the next rebalancing: the results are the
  /// same). The file's rows must be in id order (as a checkpoint of the ranks writes them).
  /// Collective; a refused file is refused on every rank (rank 0 its error, the others naming it).
  void load_state_file(World& frame, const std::filesystem::path& path, std::uint64_t scene_hash,
                       std::vector<std::uint64_t>* ids = nullptr, std::size_t block = 16384);
  /// The same from a file rank 0 has opened already (`src`: rank 0's, null elsewhere; `source`
  /// names it in errors).
  void load_state(World& frame, const StateSource* src, const std::string& source, std::uint64_t scene_hash,
                  std::vector<std::uint64_t>* ids = nullptr, std::size_t block = 16384);
  /// n steps; the walls' sums are those of the last (reduced after every step where a platen
  /// servo reads them at the next one, else once at the end: within the call nothing reads them).
  void step(std::int64_t n = 1);

  /// Dynamic balancing (as LAMMPS's `fix balance ... shift`): at every `every`-th exchange (0:
  /// never) the cuts along each axis with more than one brick move so that the slabs between
  /// them carry equal weight. A ball's weight is, by `weight`:
  ///   kContacts: contact_weights: its modelled cost, from its listed contacts by kind and its
  ///              wall contacts (`cost`; the passes' work grows with them);
  ///   kTime: its rank's compute time (motion and forces) since the last balancing, shared
  ///          evenly by the rank's own balls (LAMMPS's `weight time`), in nanoseconds.
  /// With RCB (BrickGrid::parts) every cut of the tree moves instead, level by level, so that each
  /// node's low side carries its share p / 2 of p of the node's weight (rcb_cuts), and the
  /// bricks, not only the slabs, carry equal weight.
  /// The cuts fall on the edges of `bins` even slabs per axis; the weights are integers, summed
  /// exactly, so every rank finds the same cuts. Balancing moves balls between ranks, never a
  /// bit of the results (rows stay in id order), even when the cuts follow measured times.
  /// With `every` > 0 the first cut (load, load_from_root) is balanced too, by contacts (no time
  /// is measured yet), from rank 0's whole World; rebalances() does not count it.
  enum class Weight : std::uint8_t { kContacts, kTime };
  struct Balance {
    int every = 0;
    int bins = 2048;
    Weight weight = Weight::kContacts;
    ContactCost cost;  // kContacts' costs
  };
  /// Refused with `newton` on and time weights: newton's results follow the cuts, and cuts that
  /// follow measured times differ from run to run.
  void set_balance(const Balance& b);
  /// `newton on` (LAMMPS's name; before load): a pair across a brick face is computed once, on
  /// the rank that owns its lower-id ball (its ball A), and the forces and torques it puts on a
  /// ghost go back to the ghost's owner after the pair pass (reverse communication), as do the
  /// ghost's stiffness sums for the critical step. A pair's history lives on A's owner and
  /// migrates with A. The ghosts are rows of their own after the owned rows, and the World does
  /// not integrate them (own_first). It saves the ghost pairs' second computation and the ghosts'
  /// motion, but a ball's sum then adds its remote pairs after its local ones and its ghost
  /// partners after its owned ones: the results depend on the rank count and the cuts (within
  /// round-off at first), unlike `newton off` (the default), whose bits are one World's.
  void set_newton(bool on);
  /// The largest message [bytes] of load_from_root's parts and of unload to rank 0 (default
  /// 1 GiB: an MPI count is an int); tests set a small one to send a part in many messages.
  void set_part_chunk(long long bytes) { chunk_ = std::max(1LL, bytes); }
  bool newton() const { return newton_; }
  const BrickGrid& grid() const { return grid_; }
  std::int64_t rebalances() const { return rebalances_; }
  /// This rank's load as the balancing weighs it: Σ over its own balls of contact_weights
  /// (Balance::cost).
  std::int64_t weight() const;

  World& world() { return *w_; }
  const World& world() const { return *w_; }
  int rank() const { return rank_; }
  std::size_t owned() const;
  std::size_t ghosts() const;
  /// Exchanges so far (one per rebuild step), and the balls this rank sent to a new owner in them.
  std::int64_t exchanges() const { return exchanges_; }
  /// Of those, the ones made with the neighbour bricks only (point to point): every record went
  /// to a brick within the halo and the skin of the sender's. The others were all-to-all.
  std::int64_t neighbour_exchanges() const { return sparse_exchanges_; }
  /// How far a brick reaches for the neighbour exchange [m]: its extent grown by this meets its
  /// peers' (default, < 0: the halo plus the skin, which a ball's records never exceed between
  /// two exchanges unless cuts moved or a bond is stretched across a brick). Smaller values make
  /// more exchanges fall back to all-to-all (tests/dist checks that path with 0).
  void set_neighbour_reach(double reach) { reach_ = reach; }
  std::int64_t migrated() const { return migrated_; }

  /// Wall time [s] of this rank's steps by part: the World's two halves (compute), the ghosts'
  /// forward exchange, the rebuild test's reduction, the migrations and the walls' sums
  /// (communication).
  struct Times {
    double motion = 0.0, forces = 0.0, forward = 0.0, reduce = 0.0, exchange = 0.0, walls = 0.0;
    double reverse = 0.0;        // `newton`: the ghosts' forces and stiffness sums sent back (not in forces)
    std::int64_t forwarded = 0;  // ghost states received
    double compute() const { return motion + forces; }
    double comm() const { return forward + reduce + exchange + walls + reverse; }
  };
  const Times& times() const { return times_; }
  void reset_times() {
    times_ = Times{};
    compute_at_balance_ = 0.0;
  }

  /// The node's measurements (collective): World::kinetic_energy, mean_contact_force and
  /// unbalanced_ratio of one World holding every ball, the same bits. Each term is formed on the
  /// rank that owns its ball (a pair: its ball A, the lower id), the terms are merged on rank 0
  /// in one World's order (ball id; set, then ids, for contacts), summed there in that order and
  /// broadcast.
  double kinetic_energy() const;
  double mean_contact_force() const;
  double unbalanced_ratio(double mean_contact_force) const;
  /// The skeleton ratio (procedures.hpp) of one World, the same bits (collective).
  SkeletonRatio skeleton_ratio(double mean_contact_force) const;
  /// unbalanced_ratio and skeleton_ratio together: their bits, one pass over the balls and one
  /// gather of three values per ball (dem::ball_ratios of one World; collective).
  BallRatios ball_ratios(double mean_contact_force) const;
  /// The guard's per-step screen (guard.hpp: screen_balls) of one World: whether every rank's
  /// rows are finite, the largest distance of a centre outside [lo, hi] (with `box`) and the
  /// kinetic energy (kinetic_energy()'s bits), in the kinetic energy's collectives.
  struct Screen {
    bool finite = true;
    double outside = 0.0;  // [m]
    double kinetic = 0.0;  // [J]
  };
  Screen screen(const Vec3& lo, const Vec3& hi, bool box) const;
  /// World::contact_scan's step (dt_safety x the critical step) of one World: the scan's ratios
  /// are the smallest over the ranks (World::set_step_reduction; a ball's stiffness sums are
  /// complete on the rank that owns it and a ghost's partial ones only give a longer step), and
  /// the no-contact fallback is taken only when no rank has an active contact (collective).
  double safe_step() const;
  /// The number of balls over every rank.
  std::size_t num_balls() const;

  /// Specimen preparation on the ranks (docs/scaling.md, "the REV's expansion and servo on the
  /// ranks"): the periodic servo (§4.5) runs on every rank's World, its sums (ServoSums: the cell
  /// stress and the affine stiffness) formed from every rank's pair contacts in one World's order
  /// on rank 0 and broadcast at every step, so every rank sets one World's strain rate; under
  /// WorldParams::order_free_sums each rank folds its own contacts into the 18 columns'
  /// order-free sums (servo_columns), reduced in one allreduce, as one World sums them. Returns
  /// this rank's effect (last_stress). Call it on every rank after a load (the effect's steps are
  /// collective); remove_periodic_servo takes it off again.
  PeriodicServo* add_periodic_servo(const ServoParams& p, double d_min);
  void remove_periodic_servo();
  /// The servo's sums of one World holding every ball, the same bits (collective).
  /// (`columns`: under order-free sums only those columns, servo_columns_read; null: all 18)
  ServoSums servo_sums(ServoStiffness kind, const std::vector<int>* columns = nullptr) const;
  /// cell_stress, cell_porosity and the smallest ball diameter of one World, the same bits
  /// (collective).
  Mat3 cell_stress() const;
  double cell_porosity() const;
  double min_diameter() const;
  /// Every row's velocity and spin set to zero (a ghost's are its owner's, zero too).
  void quench();
  /// Every radius times f (the REV's radius expansion), the halo grown with them, the ghosts
  /// exchanged again, then every rank's World prepared (a rebuild and a force pass) and its contact
  /// constants refreshed, as one World does it (collective).
  void scale_radii(double f);
  /// Every rank's World prepared as one World's prepare (World::prepare): the ghosts exchanged,
  /// a rebuild and a force pass, the step (collective).
  void prepare();
  /// measure.hpp's coordination of one World (collective): each rank counts the active pairs
  /// whose ball A it owns, and its own balls' active contacts (with newton on, a ghost's counts
  /// go back to its owner).
  Coordination coordination();
  /// procedures.hpp's ball_weight (Σ m |g|) of one World, the same bits (collective).
  double ball_weight() const;
  MPI_Comm comm() const { return comm_; }
  /// Bond counts by state (measure.hpp's bond_counts) and World::bond_failures() of one World:
  /// each rank counts the pairs whose ball A it owns; integer sums (collective).
  BondCounts bond_counts() const;
  std::int64_t bond_failures() const;
  /// World::energy of one World over the ranks: the kinetic energy with one World's bits
  /// (kinetic_energy); the contacts' terms (each rank's: those of its balls, of the pairs whose
  /// ball A it owns) and the energies dissipated so far added in rank order, so that their last
  /// bits depend on the rank count (docs/scaling.md). Collective.
  Energy energy() const;
  /// A ball's id and position (the positions at a stage's begin, StageEnergy).
  struct IdPos {
    std::uint64_t id;
    Vec3 x;
  };
  /// The owned balls' records, in id order.
  std::vector<IdPos> owned_positions() const;
  /// procedures.hpp's gravity_work of one World since the positions `begin` (records on any
  /// ranks, each ball's once; a ball without one adds nothing): each ball's term m g·(x - x_begin)
  /// is formed on rank (id mod ranks), where its record and its begin record meet, and added
  /// there in id order, the ranks' sums in rank order (the last bits depend on the rank count).
  /// 0 without gravity. Collective.
  double gravity_work(const std::vector<IdPos>& begin) const;

  /// Every ball's state on rank 0 in id order (the other ranks get empty arrays). Collective.
  struct Balls {
    std::vector<std::uint64_t> id;
    std::vector<Vec3> x, v, w, f, t;
  };
  Balls gather() const;

  /// measure.hpp's snapshot of one World (a frame's arrays), streamed to rank 0 in blocks of at
  /// most `block` rows instead of assembled there. Each rank sorts its own balls by id and the
  /// pairs whose ball A it owns by (A, B) id (unload's orders, one World's); rank 0 merges the
  /// ranks' sorted rows as they arrive and hands `sink` each block: the balls (position,
  /// velocity, radius, id), then the pairs (pair as rows of the whole frame, force, state).
  /// Rank 0 holds a block per rank, the block it hands on, and the frame's ids (8 bytes a ball,
  /// to turn a pair's ids into rows); no rank holds the World. Collective; `sink` is called on
  /// rank 0 only, begin first with the frame's counts.
  struct SnapshotSink {
    std::function<void(std::size_t balls, std::size_t pairs)> begin;
    std::function<void(std::size_t row0, const Snapshot& block)> balls;
    std::function<void(std::size_t row0, const Snapshot& block)> pairs;
  };
  void stream_snapshot(const SnapshotSink& sink, std::size_t block = 65536) const;

  /// Σ of every rank's terms in one World's key order, on every rank, for K value columns at once
  /// (`sums[0..K)`; K at most kMaxColumns, any K under WorldParams::order_free_sums). `vals`: this rank's n terms, K values each, in the order in which `keys`
  /// appends their keys; `keys` is called only when the merge order is formed again (which:
  /// the kind of terms, whose merge order is kept until their keys can change; ball terms: an
  /// exchange or a load; contact terms: also a rebuild). `positive` (K = 1): only terms > 0 are
  /// added, and `count` gets how many. With WorldParams::order_free_sums, each column's
  /// order-free sum instead (no keys, no gather). `also_max[0..n_max)`: replaced by their maxima
  /// over the ranks, in the same collective (a NaN anywhere: NaN). Collective; contact terms need
  /// a loaded World (its rebuild count keys their merge order).
  /// (kOnceTerms: terms whose keys change from call to call, e.g. a stress profile's, whose
  /// merge order is formed at every call)
  enum { kBallTerms = 0, kContactTerms = 1, kServoTerms = 2, kOnceTerms = 3 };
  static constexpr int kMaxColumns = 3;
  using KeyFill = std::function<void(std::vector<World::ContactTerm>&)>;
  void ordered_sums(std::size_t n, const double* vals, int K, const KeyFill& keys, int which, bool positive,
                    double* sums, std::int64_t* count = nullptr, double* also_max = nullptr, int n_max = 0) const;
  /// ordered_sums' gather alone: on rank 0 `fold(v, perm)` gets every rank's terms (K values
  /// each, v[j K + c]) and the order of one World's keys (perm), to add them as it must (the
  /// periodic servo's sums). Collective; nothing is returned to the other ranks.
  using Fold = std::function<void(const double* v, const std::vector<std::uint32_t>& perm)>;
  void ordered_fold(std::size_t n, const double* vals, int K, const KeyFill& keys, int which, double* also_max,
                    int n_max, const Fold& fold) const;

 private:
  /// Where the rows, pairs and wall contacts of a whole World go (load, load_from_root): per
  /// row its owner; per rank its rows (ascending), the pairs it computes and its balls' wall
  /// contacts of each kind, as indices into the whole World's arrays.
  struct Cut {
    std::vector<int> own;
    std::vector<std::vector<std::uint32_t>> rows, pairs;
    std::array<std::vector<std::vector<std::uint32_t>>, 3> walls;
    mutable std::vector<std::int64_t> row;  // part_of's scratch: a whole-World row's row in the part
  };
  /// p_ and halo_ from the whole World (load); `rmax` >= 0: the largest radius, if `full` holds
  /// only some of the balls (load_replicated).
  void params_from(const World& full, double rmax = -1.0);
  /// One pass over `full` for every rank (all_ranks) or this one (halo_, grid_, newton_ set).
  Cut cut(const World& full, bool all_ranks) const;
  /// Rank r's part of `full` as a World (p_ set; load).
  std::unique_ptr<World> part_of(const World& full, const Cut& k, int r, const std::vector<PlatenServoParams>& platens,
                                 bool mark_ghosts = true) const;
  /// This rank's part as its World: the step's reduction, the forward lists, the newton hooks,
  /// the walls' sums (load).
  void take(std::unique_ptr<World> w, bool platens);
  void exchange();  // migration, new ghosts, histories, forward lists; replaces the World's balls
  const std::vector<int>& peer_ranks();  // the bricks within the halo and the skin of this one
  void forward();   // the ghosts' x, v, ω from their owners
  /// `newton`: the forward exchange reversed. Two per-row arrays of `w` doubles per row (the
  /// forces and torques: w = 3; the stiffness sums: w = 1): each ghost row's values are added
  /// into its owner's row, in source-rank and then row order (point to point with the ranks
  /// that share ghosts with this one).
  void reverse(double* a, double* b, int w);
  /// forward's and reverse's messages: per_row doubles of each row of out_rows[r] to rank r
  /// (pack), those of each row of in_rows[r] from rank r (unpack), point to point (dist.cpp).
  template <class Pack, class Unpack>
  void rows_message(const std::vector<std::vector<std::uint32_t>>& out_rows,
                    const std::vector<std::vector<std::uint32_t>>& in_rows, std::size_t per_row, int tag, Pack pack,
                    Unpack unpack);
  void build_forward();  // the forward lists of the current rows
  /// With the ghosts in rows of their own (own_first): rows in id order (take) put as [owned |
  /// ghosts], each part in id order; sets split_ and the World's moving rows.
  void ghosts_last();
  /// `newton` on more than one rank: the ghosts are rows of their own after the owned rows, and
  /// the World does not integrate them (their x, v, ω are forwarded before anything reads them).
  /// With newton off the rows stay in id order: a ball's sums must add its partners in id order.
  bool own_first() const { return newton_ && size_ > 1; }
  void reduce_walls();   // every wall's sums from every rank's contacts, in one World's order
  void rebalance();      // new cuts from the weights of every rank's balls (before an exchange)
  void balance_cuts(const std::vector<Vec3>& x, const std::vector<std::int64_t>& wt, const std::vector<std::uint8_t>& skip);
  void balance_at_load(const World* full);  // load, load_from_root: a balanced first cut
  // unload's and save_state_file's shared parts: this rank's wall contacts, energies and bond
  // failures as records; every rank's read on rank 0; what `full` gets besides balls and contacts
  struct Tails;
  void put_part_tail(std::vector<char>& out) const;
  void finish_full(World& full, World::Counters k, double max_disp2) const;
  double owned_max_disp2() const;
  /// The folds of the S sums (the same boundaries on every rank) added over the ranks, in place,
  /// and `extra`, if given, with them: one sum-allreduce (collective).
  void sum_folds(OrderFreeSum* sums, std::size_t S, double* extra) const;
  /// ordered_sums' kept merge order of one kind of terms: the layout key it holds for, this rank's
  /// term count and the permutation that puts its terms in key order (empty: they are), rank 0's
  /// permutation of the gathered terms and the ranks' counts and offsets.
  struct OrderCache {
    std::int64_t key[2] = {-1, -1};
    std::size_t local = static_cast<std::size_t>(-1);
    std::vector<std::uint32_t> lperm, perm;
    std::vector<int> counts, displ;
    std::vector<double> mine, all;
  };
  /// The owned balls' K terms (`terms(row, out)`) keyed by id (set 0), summed in id order.
  template <int K, class Terms>
  void ball_sums(Terms terms, double* sums) const;
  /// The same from the owned rows' terms `v` (K per row, in row order).
  void owned_sums(const std::vector<double>& v, int K, double* sums, double* also_max = nullptr, int n_max = 0) const;

  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  BrickGrid grid_;
  WorldParams p_;
  std::unique_ptr<World> w_;
  double halo_ = 0.0;
  bool walls_every_step_ = false;  // a platen servo: the walls' sums reduced after every step (load)
  PeriodicServo* servo_ = nullptr;  // add_periodic_servo's effect on this rank's World
  bool newton_ = false;            // set_newton
  long long chunk_ = 1LL << 30;    // set_part_chunk
  double run_disp2_ = 0.0;  // largest squared displacement of an owned ball since the rebuild
  std::int64_t exchanges_ = 0, migrated_ = 0, rebalances_ = 0, sparse_exchanges_ = 0;
  std::int64_t layout_gen_ = 0;  // +1 at every load and exchange: the rows may have changed
  /// The rows' ids ascend in [0, split_) and in [split_, n): the owned rows and the ghosts with
  /// own_first(), else split_ = n (every row in id order).
  std::size_t split_ = 0;
  mutable std::int64_t balls_gen_ = -1;  // num_balls(): the layout its count was summed for
  mutable std::size_t balls_ = 0;
  std::vector<int> peers_;                   // peer_ranks()
  double reach_ = -1.0;                      // set_neighbour_reach
  std::vector<std::vector<char>> nbr_out_;   // neighbour_exchange's messages
  double compute_at_balance_ = 0.0;  // times_.compute() at the last balancing (Weight::kTime)
  Balance bal_;
  Times times_;
  // Forward communication, fixed at each exchange: per rank, my owned rows whose ghosts it holds
  // and my ghost rows it owns, both in id order.
  std::vector<std::vector<std::uint32_t>> send_rows_, recv_rows_;
  // Buffers kept from call to call (a fresh allocation per exchange cost more in page faults than
  // the exchange's own work): the all-to-all's byte buffers, the forward records, the exchange's
  // records, and the arrays the World swaps out at each exchange.
  struct Buffers;  // the exchange's records (dist.cpp)
  std::unique_ptr<Buffers> buf_;
  Particles q_;
  PairContacts nc_;
  std::vector<std::uint8_t> ghost_buf_;
  std::vector<char> sbuf_, rbuf_;
  std::vector<std::vector<double>> msg_out_;  // rows_message: the records per destination rank
  std::vector<double> msg_in_;
  std::vector<MPI_Request> msg_req_;
};

/// servo_until (specimen.hpp) on the ranks: the same steps, report and specimen as one World
/// holding every ball, bit for bit (specimen_steps.hpp: the loop written once). Collective, on a
/// loaded periodic DistDem.
StageReport servo_until(DistDem& d, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                        double budget, double* overshoot = nullptr);
/// generate_rev (specimen.hpp) with its radius expansion on the ranks: rank 0 draws the balls
/// into its empty periodic World `full` (generate_rev_balls; the other ranks' `full` holds the
/// scene's parameters, read for the final contact parameters), cuts it by `d`'s grid and sends the
/// parts (load_from_root); the ranks expand and cycle them (specimen_steps.hpp); the REV is
/// assembled on rank 0 again (unload). The same REV, steps and report as one World, bit for bit.
/// Collective; bad parameters are refused on every rank with rank 0's words.
StageReport generate_rev(DistDem& d, World& full, const RevParams& p);
/// replicate (specimen.hpp) on the ranks: rank 0 prepares its REV `rev` (the other ranks' is
/// not read: an empty World will do) and broadcasts it; every rank builds its part of the block
/// (DistDem::load_replicated). The report is one World's, bit for bit; the block is not held
/// whole anywhere (unload assembles it on rank 0 when a caller needs it). Collective; bad
/// parameters are refused on every rank with rank 0's words.
StageReport replicate(DistDem& d, World& rev, const ReplicateParams& p);
/// The bonding (§4.6) and the depth scaling (§4.9) of specimen.hpp and procedures.hpp on the
/// ranks: the same bonds, forces, reports and gap as one World holding every ball, bit for bit
/// (specimen_steps.hpp: written once). Each rank bonds or scales the pairs it holds (a pair across
/// a cut on both ranks, from the same inputs, with newton off); the counts take each pair on the
/// rank of its ball A; the gap for a coordination number is the k-th smallest separated gap of
/// every rank, found exactly by bisecting its bits with one integer sum over the ranks per bit.
/// Collective.
StageReport install_bonds(DistDem& d, double gap_lo, double gap_hi);
double gap_for_coordination(DistDem& d, double z_target, double gap_floor);
StageReport install_bonds_to_coordination(DistDem& d, double z_target, double gap_floor);
void bond_specimen(DistDem& d, StageReport& r, double bond_coordination, double gap_floor);
StageReport depth_scale(DistDem& d, const DepthScaleParams& p);
/// The coupled set-up's interface bonds on the ranks: World::bond_ball_facet on every rank's balls
/// (the bonds installed over the ranks), and assign_interface_bond_forces (specimen.hpp), whose
/// sums (the faces' weights, the band means over the ball-ball contacts) add every rank's terms in
/// one World's order, gathered on every rank: the same forces and report as one World. The
/// band means need every ball-ball contact's record on every rank (kMeanContact; transient).
/// Collective.
std::size_t bond_ball_facet(DistDem& d, double hi);

/// procedures.hpp's stress_profile of one World, the same bits: each slab's terms (region_stress's
/// per ball in the slab and contact, of the pairs whose ball A a rank owns and of its balls' wall
/// contacts) folded on rank 0 in one World's contact order (ordered_fold); every rank gets the
/// profile. Collective.
std::vector<ProfileSlab> stress_profile(const DistDem& d, const ProfileBox& box, int slabs);
/// procedures.hpp's place_footing_at_first_contact on the ranks: the largest height of first
/// contact of the ranks' balls (a maximum: one World's); the footing set on every rank's part.
/// Collective.
double place_footing_at_first_contact(DistDem& d, FootingParams f);
/// procedures.hpp's kick_highest_ball on the ranks: the highest top (z + r) over every rank's own
/// balls, of equal tops the lowest id (one World's ball); every rank that holds the ball, as its
/// own or as a ghost, gives it velocity `v`. Returns its id and position on every rank.
/// Collective; refused (on every rank) without balls.
struct Kicked {
  std::uint64_t id = 0;
  Vec3 x{0.0, 0.0, 0.0};
};
Kicked kick_highest_ball(DistDem& d, const Vec3& v);
/// procedures.hpp's add_box_walls on the ranks: the bounding box of every rank's balls (a minimum
/// and a maximum over the ranks: one World's), its five planes added to every rank's part.
/// Collective.
std::pair<Vec3, Vec3> add_box_walls(DistDem& d);
StageReport assign_interface_bond_forces(DistDem& d, const InterfaceBondParams& p);
/// servo_specimen (procedures.hpp) on the ranks, the same way (the REV's servo stage of the DEM
/// node on ranks).
StageReport servo_specimen(DistDem& d, const ServoParams& p, double stress_tol, double ratio_tol, double hold,
                           double budget, double compaction_fric);

}  // namespace demfdm::dem
