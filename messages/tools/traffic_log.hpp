// Reading a recorded bus traffic log (standard LCM event log: the merged tee of every process,
// or lcm-logger's wire capture) into the protocol's terms: every event's header, the interface
// mesh, and the interface data of each step reassembled from its chunks; merging per-process
// tee logs into one log; comparing two logs of one run. Shared by demfdm_log and demfdm_replay.
#pragma once

#include <lcm/lcm-cpp.hpp>

#include <array>
#include <cstdint>
#include <set>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "messages/bus.hpp"

namespace demfdm::traffic {

struct Event {
  std::string channel;
  std::int64_t log_us = 0;  // logger's receive time [us]
  std::int64_t bytes = 0;
  bool has_header = false;
  demfdm::header_t header;
  std::vector<std::uint8_t> data;
};

// Interface data of one step, reassembled from chunks (the first copy of each chunk counts;
// resends carry the same data).
struct StepKin {
  std::vector<double> positions, velocities;
  std::int32_t n_chunks = 0;
  std::set<std::int32_t> chunks;
  std::int64_t last_log_us = 0;  // receive time of the chunk that completed it
  bool complete() const { return n_chunks > 0 && static_cast<std::int32_t>(chunks.size()) == n_chunks; }
};
struct StepForce {
  std::vector<double> forces, stiffness;
  std::array<double, 3> total{0, 0, 0};
  std::int32_t n_chunks = 0;
  std::set<std::int32_t> chunks;
  std::int64_t last_log_us = 0;
  bool complete() const { return n_chunks > 0 && static_cast<std::int32_t>(chunks.size()) == n_chunks; }
};

// The interface mesh (first copy of each chunk).
struct IfaceMesh {
  std::vector<std::int64_t> point_ids;
  std::vector<double> positions;
  std::vector<std::int32_t> triangles, wall_of_triangle;
  std::int32_t n_walls = 0, n_chunks = 0;
  std::set<std::int32_t> chunks;
  bool complete() const { return n_chunks > 0 && static_cast<std::int32_t>(chunks.size()) == n_chunks; }
};

struct Log {
  std::vector<Event> events;
  IfaceMesh mesh;
  std::map<std::int64_t, StepKin> kin;      // continuum -> DEM, by step
  std::map<std::int64_t, StepForce> force;  // DEM -> continuum, by step
  std::string scene_text, scene_origin;
  std::int64_t scene_hash = 0;
  std::int64_t run_id = 0;  // run id of the scene broadcast (0: none seen)
};

template <class T>
bool decode(const Event& e, T& msg) {
  try {
    return msg.decode(e.data.data(), 0, static_cast<int>(e.data.size())) >= 0 &&
           msg.header.msg_type == bus::MsgType<T>::id;
  } catch (const std::exception&) {
    return false;
  }
}

// Reads the whole log; throws std::runtime_error naming the file if it cannot be opened.
Log read_log(const std::string& path);

// Merges event logs (files, or folders whose *.lcmlog files are taken) into one standard event
// log at out, ordered by timestamp; ties keep the order of the inputs (inputs sorted by path,
// then the order inside each file), so the result depends only on the inputs. Event numbers
// are renumbered from 0. Returns the number of events written; throws std::runtime_error.
struct MergeResult {
  std::size_t inputs = 0, events = 0;
};
MergeResult merge_logs(const std::vector<std::string>& inputs, const std::string& out);

// Compares a (lossless) log with a wire capture of the same run: every message is identified
// by its channel and exact bytes, counted with multiplicity. LCM's own LCM_SELF_TEST messages
// on the wire are not demfdm traffic and are skipped.
struct ChannelDiff {
  std::int64_t in_log = 0, on_wire = 0, lost_on_wire = 0, only_on_wire = 0;
};
std::map<std::string, ChannelDiff> compare_logs(const Log& log, const Log& wire);

}  // namespace demfdm::traffic
