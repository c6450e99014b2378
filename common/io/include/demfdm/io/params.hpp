// Parameters of the output library. Plain structs with documented defaults and units;
// the scene reader maps its keys onto them (no scene parsing here).
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

namespace demfdm::io {

/// How results datasets are stored (docs/output.md O14-O16, O8).
struct H5StorageParams {
  // [-] false: contiguous, no filter (docs/output.md O14: ~5 ms per 100k-particle frame,
  //     fastest ParaView stepping). true: chunked + shuffle + deflate (about 40 % smaller
  //     with bonds, roughly 0.1-0.15 s per 100k-particle frame on one core).
  bool compress = false;
  // [-] gzip level when compress is on, 1..9. Level 1 per docs/output.md O15: levels 4-6
  //     gained under 1 % for 1.2-2x the time.
  int deflate_level = 1;
  // [rows] chunk length of compressed per-frame datasets (chunk = min(rows, chunk_rows)),
  //        >= 1. 65536 rows is 64 KB of uint8 state up to 1.5 MB of float64 positions.
  std::size_t chunk_rows = 65536;
  // [rows] chunk length of the extendible /history/<name> datasets, >= 1 (docs/output.md O8: 1024).
  std::size_t history_chunk_rows = 1024;
  // [rows] history rows buffered in memory before one open-append-close of the file, >= 1.
  //        1 puts every sample on disk at once (a crash loses nothing); larger values
  //        amortise the ~0.2 ms open/close when histories are sampled every few steps.
  std::size_t history_flush_rows = 1;

  /// Throws std::invalid_argument naming the field, the expected range and the value found.
  void validate() const;
};

/// Identity written as root attributes of every results file (fixed-length ASCII strings).
struct FileInfo {
  std::string producer;    // [-] writing process: "dem_node", "fdm_node", "coordinator"
  std::string run_id;      // [-] run identifier chosen by the launcher (may be empty)
  std::string scene_hash;  // [-] hash of the scene file that produced the run (may be empty)
  // [-] further string attributes on "/", e.g. {"stress_unit", "Pa"}; names must be unique
  //     and must not repeat the standard ones (format, producer, run_id, ...).
  std::vector<std::pair<std::string, std::string>> extra;
};

}  // namespace demfdm::io
