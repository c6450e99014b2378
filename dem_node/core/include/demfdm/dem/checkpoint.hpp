// Bit-exact save and load of a DEM World (issue 13; file layout: docs/checkpoint-format.md).
//
// A World loaded from a state saved after step N continues with the same bits as the world
// that was saved: every array the next steps read is stored as it is, including what
// prepare() and rebuild() derive (contact lists in their order, image shifts, Verlet
// reference positions, the wall candidate lists, the cached step and its recompute counter,
// the last pass's forces), so nothing is rebuilt in another order after a load.
//
// Saved (kind "dem", sections in this order):
//  * params    — WorldParams field by field (also what mutable_params(), set_cell(),
//                set_gravity() and the cell strain changed: the current cell length);
//  * counters  — step, time, dt, skin, rebuild count, last dt step, bond-failure count,
//                prepared/dirty flags, cell strain rate, cell strain, cell length at the last
//                rebuild, next ball and wall ids, damping energy, largest squared displacement
//                since the rebuild, energies of dropped contacts;
//  * effects   — gravity (on/off and its vector): the only effect that can be saved;
//  * balls     — x, v, w, f, t, fa, ta, x_ref, r, m, inertia, id, fix;
//  * pairs     — ball–ball list: a, b, image shift, ContactHist and BondHist field by field;
//  * plane_contacts, facet_contacts, footing_contacts — WallContacts (ball, wall, histories,
//                current facet, candidate facets, force, moment, ball torque, contact point,
//                barycentric weights);
//  * planes    — plane walls incl. servo settings, servo-set velocity, displacement since the
//                rebuild, reaction and contact stiffness (the servo's input of the next step);
//  * facet_walls — vertices, velocities, triangles, normals, facet spins, reference vertices,
//                vertex forces and stiffnesses, total force;
//  * footing   — parameters, enabled, displacement, reaction, id.
// Not saved: phase timers, the pair-kernel choice (every kernel gives the same bits), scratch
// buffers (per-thread force buffers are zero between passes). The World holds no random-number
// state: the generator of generate_rev() lives only inside that call.
//
// Effects: GravityEffect and the platen servos (PlatenServo) are saved. save_state() throws
// std::invalid_argument naming any other effect present (e.g. "periodic_servo", which exists
// only inside servo_until(), so a checkpoint between steps of a coupled stage never sees it;
// "measurement_recorder" is an observer whose samples belong to the caller). load_state()
// replaces the target's gravity effect and platen servos and keeps its other effects
// (observers the caller added).
//
// Threads: WorldParams::threads is restored too (the ball–ball sums are associated per thread
// block, so the same count is needed for the same bits; with threads = 0 the OpenMP default
// of the loading process decides).
#pragma once

#include <cstdint>
#include <filesystem>
#include <array>
#include <iosfwd>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "demfdm/dem/world.hpp"
#include "demfdm/io/state_file.hpp"

namespace demfdm::dem {

/// What is written into the header next to the state.
using CheckpointMeta = io::StateMeta;

/// The state file of `w` in memory. Throws std::invalid_argument if `w` has an effect that
/// cannot be saved (named in the message).
std::string state_bytes(const World& w, const CheckpointMeta& meta);
/// Writes state_bytes() to `out`.
void save_state(const World& w, std::ostream& out, const CheckpointMeta& meta = {});
/// Writes state_bytes() to `path` atomically (io::write_atomically).
void save_state_file(const World& w, const std::filesystem::path& path, const CheckpointMeta& meta);

/// Replace the state of `w` by the saved one. `w` may be a freshly constructed World (any
/// parameters: they are replaced). Refuses (io::StateFileError, message starting with
/// `source`) a file of another kind or scene hash, a damaged, truncated or foreign file, and
/// unknown or missing sections; the world is left untouched then. Returns the header.
io::StateHeader load_state(World& w, std::istream& in, std::uint64_t scene_hash, std::string_view source = "<stream>");
io::StateHeader load_state_bytes(World& w, std::string bytes, std::uint64_t scene_hash, std::string_view source);
io::StateHeader load_state_file(World& w, const std::filesystem::path& path, std::uint64_t scene_hash);

/// A World's state file written in pieces (io::StateFileWriter): the bytes state_bytes() gives
/// of a World whose balls and ball-ball contacts arrive in blocks of rows, in its row order, so
/// that this World is never held whole in memory (DistDem::save_state_file: the ranks' parts
/// merged on rank 0, which keeps a block at a time). The balls and pairs sections are reserved
/// at their final size and each block is written into its columns in place; the sections after
/// them are written at commit().
class StateStream {
 public:
  /// `frame`: the World's other state (parameters, counters, effects, walls; its own balls and
  /// contacts are not written). The streamed World holds `balls` balls and `pairs` ball-ball
  /// contacts, with bond histories when the frame's ball-ball law bonds (law_has_bond).
  StateStream(const std::filesystem::path& path, const World& frame, std::uint64_t balls, std::uint64_t pairs,
              const CheckpointMeta& meta);
  ~StateStream();
  /// The next rows of the balls (every column of Particles).
  void balls(const Particles& rows);
  /// The next ball-ball contacts; a and b are rows of the streamed balls.
  void pairs(const PairContacts& rows);
  /// The plane, facet and footing contact lists (their balls: rows of the streamed balls); then
  /// the file is complete and takes its name. Throws std::logic_error unless every row came. A
  /// stream destroyed before commit() leaves no file.
  void commit(const WallContacts& planes, const WallContacts& facets, const WallContacts& footing);

 private:
  struct Impl;
  std::unique_ptr<Impl> p_;
};

/// A World's state file read in pieces (io::StateFileReader), the reverse of StateStream: its
/// container checked on opening (load_state's refusals), the World's other state (parameters,
/// counters, effects, walls) as a World without balls (frame_bytes, load_frame), its balls and
/// ball-ball contacts a block of rows at a time, its wall contacts whole (they grow with the
/// walls, not with the block). The contents are checked as load_state checks them (counts,
/// enums, rows in range), a block at a time. DistDem::load_state_file: rank 0 reads the World
/// this way and sends each rank its share.
class StateSource {
 public:
  StateSource(const std::filesystem::path& path, std::uint64_t scene_hash);
  ~StateSource();
  /// A state file in memory of the World without its balls and contacts: every other section as
  /// the file holds it. load_frame() loads it into `frame` (load_state_bytes: its checks).
  const std::string& frame_bytes() const;
  void load_frame(World& frame) const;
  std::uint64_t balls() const;
  std::uint64_t pairs() const;
  /// Rows [r0, r0 + n) of the balls (every column), into `out` (replaced).
  void read_balls(std::uint64_t r0, std::size_t n, Particles& out) const;
  /// Only the positions, radii and ids of rows [r0, r0 + n).
  void read_positions(std::uint64_t r0, std::size_t n, std::vector<Vec3>& x, std::vector<double>& r,
                      std::vector<std::uint64_t>& id) const;
  /// Contacts [c0, c0 + n) of the ball-ball list into `out` (replaced), their rows checked
  /// against balls().
  void read_pairs(std::uint64_t c0, std::size_t n, PairContacts& out) const;
  /// Only their ball rows (a and b), checked the same way.
  void read_pair_rows(std::uint64_t c0, std::size_t n, std::vector<std::uint32_t>& a, std::vector<std::uint32_t>& b) const;
  /// The plane, facet and footing contact lists, checked against balls() and the frame's walls.
  std::array<WallContacts, 3> read_wall_contacts() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> p_;
};

}  // namespace demfdm::dem
