// Reading a recorded bus traffic log (standard LCM event log: the merged tee of every process,
// or lcm-logger's wire capture) into the protocol's terms: every event's header, the interface
// mesh, and the interface data of each step reassembled from its chunks; merging per-process
// tee logs into one log; comparing two logs of one run. Shared by demfdm_log and demfdm_replay.
//
// Integrity (docs/traffic.md). Every log is read strictly: the LCM event framing of each event
// (sync word 0xEDA1DA01, event number = the previous one + 1, timestamp, channel length 1..999
// of printable characters, data length within the file) and a decode check of every payload on
// a demfdm channel against its message type. A log written by merge_logs also carries checksums:
// its first event is a DEMFDM_LOG_CHECK "begin" block, after every kCheckBlock events a block
// with the CRC-32 (IEEE, as zlib's crc32) of each event record since the previous block (the
// bytes from its sync word to the end of its data), and its last event an "end" block. Such a
// log is verified event by event and must end with its end block. An empty file, a file that is
// not an event log, a truncated log and a damaged one are a LogError naming the file, the byte
// offset and the event number; nothing of such a log is used.
#pragma once

#include <lcm/lcm-cpp.hpp>

#include <array>
#include <cstdint>
#include <cstdio>
#include <set>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "messages/bus.hpp"

namespace demfdm::traffic {

// Checksum blocks written by merge_logs (not bus traffic; never in Log::events).
inline const std::string kCheckChannel = "DEMFDM_LOG_CHECK";
inline constexpr std::int64_t kCheckBlock = 1000;  // events per checksum block
// The tee records each (scene hash, chunk) of DEMFDM_SCENE once per process; a repeated
// broadcast of it is recorded here: the same scene_t (header, hash, chunk) without its text.
inline const std::string kSceneRepeat = "DEMFDM_SCENE_REPEAT";

// What is wrong with a log file. what(): "<path>: <kind>: <detail>", one line.
struct LogError : std::runtime_error {
  enum class Kind { Empty, NotALog, Truncated, Corrupt };
  Kind kind;
  std::string path;
  std::int64_t offset = -1;    // byte offset of the event concerned (-1: none)
  std::int64_t eventnum = -1;  // its event number (position in the file, from 0; -1: none)
  LogError(Kind k, std::string file, std::int64_t at, std::int64_t event, const std::string& detail);
  static const char* kind_name(Kind k);
};

// One event of a log file as stored.
struct RawEvent {
  std::int64_t eventnum = 0, timestamp = 0, offset = 0;
  std::string channel;
  std::vector<std::uint8_t> data;
};

// Strict sequential reader of an LCM event log (rules above). Checksum blocks are verified and
// not returned. Throws LogError; std::runtime_error if the file cannot be opened.
class EventReader {
 public:
  explicit EventReader(const std::string& path);
  ~EventReader();
  EventReader(const EventReader&) = delete;
  EventReader& operator=(const EventReader&) = delete;
  // The next event; false at the end of a complete log.
  bool next(RawEvent& e);
  bool checksummed() const { return checksummed_; }  // the log carries checksum blocks
  std::int64_t events() const { return data_events_; }  // events returned so far
  std::int64_t file_bytes() const { return size_; }
  const std::string& path() const { return path_; }

 private:
  [[noreturn]] void fail(LogError::Kind k, std::int64_t at, std::int64_t event, const std::string& detail) const;
  void read_exact(void* buf, std::size_t n);
  void check_block(std::int64_t at, const std::vector<std::uint8_t>& payload);
  std::string path_;
  std::FILE* f_ = nullptr;
  std::int64_t size_ = 0, pos_ = 0, index_ = 0, last_eventnum_ = -1, data_events_ = 0;
  bool checksummed_ = false, ended_ = false;
  struct Pending {
    std::int64_t eventnum, offset;
    std::uint32_t crc;
    std::string channel;
    std::size_t bytes;
  };
  std::vector<Pending> pending_;  // events since the last checksum block
};

// CRC-32 (IEEE 802.3, reflected, as zlib's crc32): crc32(crc32(0, a), b) = crc32 of a then b.
std::uint32_t crc32(std::uint32_t crc, const void* data, std::size_t n);

// Empty when the payload decodes as the message type of its demfdm channel (or the channel is not
// a demfdm one), else the name of the type it fails to decode as.
std::string payload_problem(const std::string& channel, const std::vector<std::uint8_t>& data);

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
  bool checksummed = false;  // every event was verified against the checksums merge_logs wrote
  std::int64_t file_bytes = 0;
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

// Reads the whole log strictly (EventReader). Throws LogError for an empty file, a log without
// messages, garbage, a truncated or a corrupt log; std::runtime_error naming the file if it
// cannot be opened.
Log read_log(const std::string& path);

// Merges event logs (files, or folders whose *.lcmlog files are taken) into one standard event
// log at out, ordered by timestamp; ties keep the order of the inputs (inputs sorted by path,
// then the order inside each file), so the result depends only on the inputs. Event numbers
// are renumbered from 0; checksum blocks are written (kCheckChannel, above). Inputs are read
// strictly; an input whose last event is cut short (its process was killed while writing) is
// merged without that event and named in `warnings`; any other damage, and an output that
// cannot be written, throws (LogError / std::runtime_error). Empty input files are allowed.
struct MergeResult {
  std::size_t inputs = 0, events = 0;
  std::vector<std::string> warnings;
};
MergeResult merge_logs(const std::vector<std::string>& inputs, const std::string& out);

// Compares a (lossless) log with a wire capture of the same run: every message is identified
// by its channel and exact bytes, counted with multiplicity; a scene broadcast by its header
// and chunk (the tee keeps each chunk's text once, kSceneRepeat). LCM's own LCM_SELF_TEST
// messages on the wire are not demfdm traffic and are skipped.
struct ChannelDiff {
  std::int64_t in_log = 0, on_wire = 0, lost_on_wire = 0, only_on_wire = 0;
};
std::map<std::string, ChannelDiff> compare_logs(const Log& log, const Log& wire);

}  // namespace demfdm::traffic
