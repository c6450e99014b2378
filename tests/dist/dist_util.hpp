// Shared by the DEM-on-ranks tests (tests/dist): the rank of this process, bit comparison, and
// one verdict for every rank (rank 0 compares with its reference World; the others learn the
// result, so that every rank passes or fails together).
#pragma once

#include <gtest/gtest.h>
#include <mpi.h>

#include <unistd.h>

#include <array>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/dist.hpp"
#include "demfdm/io/state_file.hpp"
#include "demfdm/dem/vec3.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem::test {

inline int g_rank = 0, g_size = 1;

template <class T>
bool same_bits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

/// Every ball gathered from the ranks against one World's, bit for bit (rank 0); `owned`: the
/// owned balls summed over the ranks.
inline void expect_same_balls(const DistDem::Balls& got, const World& ref, std::size_t owned) {
  const Particles& r = ref.balls();
  EXPECT_EQ(owned, r.size()) << "every ball owned once";
  EXPECT_EQ(got.id, r.id);
  EXPECT_TRUE(same_bits(got.x, r.x)) << "positions differ";
  EXPECT_TRUE(same_bits(got.v, r.v)) << "velocities differ";
  EXPECT_TRUE(same_bits(got.w, r.w)) << "spins differ";
  EXPECT_TRUE(same_bits(got.f, r.f)) << "forces differ";
  EXPECT_TRUE(same_bits(got.t, r.t)) << "torques differ";
}

/// DistDem::stream_snapshot's blocks of `block` rows joined on rank 0 (empty elsewhere), each
/// block checked to begin where the last ended and to be at most `block` rows long.
inline Snapshot streamed_snapshot(const DistDem& d, std::size_t block) {
  Snapshot all;
  std::size_t balls = 0, pairs = 0;
  DistDem::SnapshotSink sink;
  sink.begin = [&](std::size_t nb, std::size_t np) { balls = nb, pairs = np; };
  sink.balls = [&](std::size_t row0, const Snapshot& b) {
    EXPECT_EQ(row0, all.id.size());
    EXPECT_LE(b.id.size(), block);
    all.position.insert(all.position.end(), b.position.begin(), b.position.end());
    all.velocity.insert(all.velocity.end(), b.velocity.begin(), b.velocity.end());
    all.radius.insert(all.radius.end(), b.radius.begin(), b.radius.end());
    all.id.insert(all.id.end(), b.id.begin(), b.id.end());
  };
  sink.pairs = [&](std::size_t row0, const Snapshot& b) {
    EXPECT_EQ(row0, all.state.size());
    EXPECT_LE(b.state.size(), block);
    all.pair.insert(all.pair.end(), b.pair.begin(), b.pair.end());
    all.force.insert(all.force.end(), b.force.begin(), b.force.end());
    all.state.insert(all.state.end(), b.state.begin(), b.state.end());
  };
  d.stream_snapshot(sink, block);
  if (d.rank() == 0) {
    EXPECT_EQ(balls, all.id.size());
    EXPECT_EQ(pairs, all.state.size());
  }
  return all;
}

/// DistDem::save_state_file (blocks of `block` rows, from a frame World without balls) against
/// the state file of the World that unload assembles on rank 0, byte for byte; `make()` builds
/// the World the ranks were loaded from. The file loaded on the ranks (load_state_file, blocks
/// of `block` rows) gives every rank the part that load_from_root cuts from the assembled World,
/// and both step on with the same bits. Then a folder that does not exist: every rank throws,
/// rank 0 naming the file, and nothing is left; loading from it, every rank throws. Collective.
template <class Make>
inline void expect_same_state_file(const DistDem& d, Make make, std::size_t block) {
  int pid = static_cast<int>(::getpid());
  MPI_Bcast(&pid, 1, MPI_INT, 0, MPI_COMM_WORLD);
  const auto file = std::filesystem::temp_directory_path() / ("demfdm_dist_state_" + std::to_string(pid) + ".state");
  const CheckpointMeta meta{0x5eedULL, "v-dist"};
  std::unique_ptr<World> frame = make();
  frame->drop_balls();  // (rank 0's World in the node while the ranks step)
  d.save_state_file(*frame, file, meta, block);
  std::unique_ptr<World> assembled = make();
  d.unload(*assembled, true);
  if (d.rank() == 0) {
    const std::string want = state_bytes(*assembled, meta);
    EXPECT_TRUE(io::read_whole_file(file) == want) << "the state file written from the parts differs from the assembled World's ("
                                                   << want.size() << " bytes)";
  }
  // The file loaded on the ranks without a whole World (DistDem::load_state_file) and the
  // assembled World loaded from rank 0 (load_from_root), on the same bricks, step on with the
  // same bits: their assembled states after 25 steps have one state file.
  {
    World frame(d.world().params());
    DistDem e1(MPI_COMM_WORLD, d.world().params(), d.grid()), e2(MPI_COMM_WORLD, d.world().params(), d.grid());
    e1.set_newton(d.newton());
    e2.set_newton(d.newton());
    std::vector<std::uint64_t> ids;
    e1.load_state_file(frame, file, meta.scene_hash, &ids, block);
    e2.load_from_root(*assembled);
    EXPECT_EQ(frame.num_balls(), 0u);
    // every rank's part the same: its rows (ghosts marked), pairs and wall contacts
    const World &p1 = e1.world(), &p2 = e2.world();
    int differ = !(p1.balls().id == p2.balls().id && p1.ghost_rows() == p2.ghost_rows() &&
                   p1.pair_contacts().a == p2.pair_contacts().a && p1.pair_contacts().b == p2.pair_contacts().b &&
                   p1.plane_contacts().ball == p2.plane_contacts().ball && p1.facet_contacts().ball == p2.facet_contacts().ball &&
                   p1.footing_contacts().ball == p2.footing_contacts().ball);
    MPI_Allreduce(MPI_IN_PLACE, &differ, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
    EXPECT_EQ(differ, 0) << "a rank's part loaded from the file differs from the part cut from the whole World";
    if (d.rank() == 0) {
      EXPECT_EQ(ids, assembled->balls().id);
      EXPECT_EQ(frame.step_count(), assembled->step_count());
    }
    e1.step(25);
    e2.step(25);
    std::unique_ptr<World> a1 = make(), a2 = make();
    e1.unload(*a1, true);
    e2.unload(*a2, true);
    if (d.rank() == 0) {
      EXPECT_TRUE(state_bytes(*a1, meta) == state_bytes(*a2, meta)) << "the ranks loaded from the file step on with other bits";
      EXPECT_EQ(a1->step_count(), assembled->step_count() + 25);
    }
  }
  if (d.rank() == 0) std::filesystem::remove(file);
  const auto bad = std::filesystem::temp_directory_path() / ("demfdm_no_such_folder_" + std::to_string(pid)) / "x.state";
  std::string what;
  try {
    d.save_state_file(*frame, bad, meta, block);
  } catch (const std::exception& e) {
    what = e.what();
  }
  EXPECT_NE(what.find(d.rank() == 0 ? "x.state" : "rank 0 could not write"), std::string::npos) << what;
  EXPECT_FALSE(std::filesystem::exists(bad.parent_path()));
  // Loading that missing file: refused on every rank too (rank 0 naming it, the others naming
  // rank 0's error), none left waiting.
  what.clear();
  try {
    World frame(d.world().params());
    DistDem e(MPI_COMM_WORLD, d.world().params(), d.grid());
    e.load_state_file(frame, bad, meta.scene_hash, nullptr, block);
  } catch (const std::exception& e) {
    what = e.what();
  }
  EXPECT_NE(what.find("x.state"), std::string::npos) << what;
  if (d.rank() != 0) {
    EXPECT_NE(what.find("rank 0 could not load the state"), std::string::npos) << what;
  }
}

/// Two snapshots (a frame's arrays), bit for bit.
inline void expect_same_snapshot(const Snapshot& got, const Snapshot& want) {
  EXPECT_EQ(got.id, want.id);
  EXPECT_TRUE(same_bits(got.position, want.position)) << "frame positions differ";
  EXPECT_TRUE(same_bits(got.velocity, want.velocity)) << "frame velocities differ";
  EXPECT_TRUE(same_bits(got.radius, want.radius)) << "frame radii differ";
  EXPECT_EQ(got.pair, want.pair);
  EXPECT_TRUE(same_bits(got.force, want.force)) << "frame pair forces differ";
  EXPECT_EQ(got.state, want.state);
  EXPECT_GT(want.state.size(), 0u);
}

/// The node's measurements on the ranks (DistDem::kinetic_energy, mean_contact_force,
/// unbalanced_ratio) against one World's, bit for bit (rank 0).
inline void expect_same_measures(const World& ref, double ke, double fc, double ratio) {
  const double want[3] = {ref.kinetic_energy(), ref.mean_contact_force(), 0.0};
  const double r = ref.unbalanced_ratio(want[1]);
  EXPECT_EQ(std::memcmp(&want[0], &ke, sizeof ke), 0) << "kinetic energy " << ke << " vs " << want[0];
  EXPECT_EQ(std::memcmp(&want[1], &fc, sizeof fc), 0) << "mean contact force " << fc << " vs " << want[1];
  EXPECT_EQ(std::memcmp(&r, &ratio, sizeof r), 0) << "unbalanced ratio " << ratio << " vs " << r;
  EXPECT_GT(want[0], 0.0);
  EXPECT_GT(want[1], 0.0);
}

/// `w`'s contacts by kind, and the weight that contact_weights should give every row from them
/// (`cost`: a row, both ends of every listed pair by what the pass does with it, every wall
/// contact), with its total.
struct CostCounts {
  std::size_t bonded = 0, touching = 0, apart = 0, planes = 0, facets = 0;
  std::vector<std::int64_t> row;
  std::int64_t total = 0;
};
inline CostCounts cost_counts(const World& w, const ContactCost& cost = {}) {
  CostCounts n;
  n.row.assign(w.num_balls(), cost.ball);
  const PairContacts& pc = w.pair_contacts();
  for (std::size_t c = 0; c < pc.size(); ++c) {
    std::int64_t e = cost.apart_end;
    if (!pc.bond.empty() && bonded(pc.bond[c].state)) ++n.bonded, e = cost.bonded_end;
    else if (pc.h[c].flags & ContactHist::kActive) ++n.touching, e = cost.touching_end;
    else ++n.apart;
    n.row[pc.a[c]] += e;
    n.row[pc.b[c]] += e;
  }
  for (const WallContacts* wc : {&w.plane_contacts(), &w.footing_contacts()})
    for (std::uint32_t i : wc->ball) n.row[i] += cost.plane, ++n.planes;
  for (std::uint32_t i : w.facet_contacts().ball) n.row[i] += cost.facet, ++n.facets;
  for (std::int64_t v : n.row) n.total += v;
  return n;
}

/// contact_weights of `w` with `cost`.
inline std::vector<std::int64_t> weights(const World& w, const ContactCost& cost = {}) {
  std::vector<std::int64_t> wt;
  contact_weights(w, wt, cost);
  return wt;
}

/// Costs of six different orders of magnitude: a row's weight then shows each of its counts.
inline constexpr ContactCost kDistinctCosts{1, 10, 100, 1000, 100000, 10000};

/// Call on every rank after rank 0 has run its EXPECTs.
inline void share_verdict() {
  int ok = g_rank == 0 ? !::testing::Test::HasFailure() : 1;
  MPI_Bcast(&ok, 1, MPI_INT, 0, MPI_COMM_WORLD);
  if (g_rank != 0) {
    EXPECT_TRUE(ok) << "rank 0 found a difference";
  }
}

}  // namespace demfdm::dem::test
