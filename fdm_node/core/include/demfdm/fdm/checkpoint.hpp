// Bit-exact save and load of an FDM Model (issue 13; file layout: docs/checkpoint-format.md).
//
// The Model to load into is constructed by the caller from the same ModelParams (or the same
// Mesh and ModelParams) as the saved one: the mesh, the tetrahedron geometry, the masses and
// the gather tables are rebuilt by that constructor, not stored. A fingerprint of what the
// constructor derives (mesh, geometry, gravitational and static masses, zone stiffness,
// materials and each zone's law, mode, damping, gravity, averaging, strain mode, timestep
// safety, history interval) is saved and compared, so a model built differently is refused
// by name.
//
// Saved (kind "fdm", sections in this order):
//  * model     — the fingerprint and the counts (gridpoints, zones, interface gridpoints);
//  * counters  — step, time, dt, imposed-dt flag, cached zone and interface critical steps,
//                coupling-present flag;
//  * gridpoints — x, u, v, inertial mass (static mode: changed by the interface stiffness),
//                zone force sum of the last pass (the next law of motion reads it), external
//                forces (gravity + applied), applied loads, prescribed velocities, fixity;
//  * zones     — stresses of the 10 tetrahedra of each zone, plastic state bits, the nodal
//                force slots of the last pass (read by ratios());
//  * interface — coupling forces and stiffness per interface gridpoint;
//  * history   — the HistoryRecords sampled so far.
// There is no damping memory (local damping uses the current velocity's sign, docs/theory.md
// 5.6) and no strain state besides u (strain increments are formed from velocities each
// step). Phase timers are not saved.
#pragma once

#include <cstdint>
#include <filesystem>
#include <iosfwd>
#include <string>
#include <string_view>

#include "demfdm/fdm/model.hpp"
#include "demfdm/io/state_file.hpp"

namespace demfdm::fdm {

using CheckpointMeta = io::StateMeta;

std::string state_bytes(const Model& m, const CheckpointMeta& meta);
void save_state(const Model& m, std::ostream& out, const CheckpointMeta& meta = {});
void save_state_file(const Model& m, const std::filesystem::path& path, const CheckpointMeta& meta);

/// Replace the state of `m` (built from the same parameters) by the saved one. Refuses with
/// io::StateFileError (message starting with `source`) a file of another kind or scene hash, a
/// damaged, truncated or foreign file, unknown or missing sections, or a model built from other
/// parameters; `m` is left untouched then. Returns the header.
io::StateHeader load_state(Model& m, std::istream& in, std::uint64_t scene_hash, std::string_view source = "<stream>");
io::StateHeader load_state_bytes(Model& m, std::string bytes, std::uint64_t scene_hash, std::string_view source);
io::StateHeader load_state_file(Model& m, const std::filesystem::path& path, std::uint64_t scene_hash);

}  // namespace demfdm::fdm
