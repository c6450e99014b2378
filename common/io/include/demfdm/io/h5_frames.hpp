// One HDF5 results file per producing process, written frame by frame.
//
// Layout (docs/output.md O1-O8 and O17, verified with ParaView 5.11 and h5py 3.7):
//   /                       attrs format="demfdm-results", format_version=1 (int64), producer,
//                           run_id, scene_hash, length_unit="m", time_unit="s", FileInfo::extra
//   /frames/NNNNNN          one group per output frame, NNNNNN = 6-digit output index from 0
//                           (so name order = chronological order); attrs time (float64, s),
//                           step (int64), datasets (1-D fixed-length ASCII strings: the
//                           frame's dataset names relative to the group, in write order;
//                           absent when the frame holds no dataset)
//   /frames/NNNNNN/<a>/<b>  per-frame arrays [rows] or [rows, cols], written once each
//   /<static path>          datasets written once (e.g. /mesh/node_coords, /xdmf/vertex_index)
//   /history/<name>         1-D float64 time histories, unlimited, chunked, appended per row;
//                           attr unit on the dataset and <name>_unit on /history; attr
//                           columns on /history (1-D fixed-length ASCII strings: the column
//                           names in declaration order, i.e. the order of a history row)
//
// The two order attributes (frame datasets, history columns) exist for reopen(): HDF5 lists
// links by name unless creation order is tracked, and the sidecars and history rows need
// the write order back when a crashed run is resumed.
//
// File discipline (docs/output.md O9-O13):
// * created with H5F_ACC_EXCL: an existing file is never overwritten;
// * libver bounds EARLIEST..V18, so any HDF5 >= 1.8 reads the file;
// * object-time tracking off in every group/dataset creation plist: two identical runs give
//   byte-identical files;
// * the file is open only between begin_frame() and end_frame() (and during a static write,
//   attribute write or history flush): HDF5 1.10 locks open files, so readers such as h5py or
//   ParaView can read the file between frames.
//
// Not thread-safe: one H5Frames per file, used by one thread.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "demfdm/io/array_view.hpp"
#include "demfdm/io/params.hpp"

namespace demfdm::io {

/// Where a dataset lives and what it holds; what an XDMF DataItem needs to point at it.
struct DatasetRef {
  std::filesystem::path file;  // absolute path of the HDF5 file
  std::string path;            // absolute HDF5 path, e.g. "/frames/000002/particles/position"
  DType dtype = DType::kFloat64;
  std::size_t rows = 0;
  std::size_t cols = 1;        // 1 means a 1-D dataset [rows]
};

/// What one frame of the file holds, as read back by H5Frames::read_frames().
struct FrameRecord {
  std::int64_t step = 0;
  double time = 0.0;                 // [s]
  std::vector<std::string> names;    // dataset names relative to the frame group, write order
  std::vector<DatasetRef> datasets;  // datasets[i] is names[i]
};

/// One column of the /history time series.
struct HistoryColumn {
  std::string name;  // dataset name under /history, e.g. "load"
  std::string unit;  // unit text, e.g. "N" ("1" for dimensionless ratios)
};

class H5Frames {
 public:
  /// Creates `file` (H5F_ACC_EXCL) with its root attributes and closes it again.
  /// Throws IoError when the file exists ("refusing to overwrite") or cannot be created,
  /// std::invalid_argument on bad parameters.
  static H5Frames create(const std::filesystem::path& file, const FileInfo& info,
                         const H5StorageParams& storage = {});

  /// Reopens a results file written by this class for a run resumed from a checkpoint
  /// that recorded frame_count() == `frames` and history_rows() == `history_rows`. Frame
  /// groups /frames/NNNNNN with index >= frames (written by the crashed run after the
  /// checkpoint) are deleted and every /history dataset is cut back to `history_rows` rows,
  /// so the next begin_frame() creates frame `frames` and later writes give the datasets an
  /// uninterrupted run writes. What the object tracks is rebuilt from the file: static and
  /// index datasets (ref(), ensure_index()), the datasets of frame frames-1 (ref() of a
  /// relative path) and the history columns in declaration order (do not declare them
  /// again). `storage` should be the one the file was created with: it applies to the
  /// datasets created from now on. Throws IoError when the file is not a demfdm results
  /// file (root attribute format), holds fewer than `frames` frames or a history shorter
  /// than `history_rows`, or cannot be opened; the file is not changed then.
  static H5Frames reopen(const std::filesystem::path& file, std::size_t frames, const H5StorageParams& storage = {},
                         std::size_t history_rows = 0);

  H5Frames(H5Frames&&) noexcept;
  H5Frames& operator=(H5Frames&&) noexcept;
  H5Frames(const H5Frames&) = delete;
  H5Frames& operator=(const H5Frames&) = delete;
  /// Flushes buffered history rows and closes the file; errors are reported on stderr
  /// because a destructor cannot throw. Call close() to receive them as exceptions.
  ~H5Frames();

  /// Writes a dataset that does not change between frames, at an absolute path outside
  /// /frames and /history (e.g. "/mesh/zone_nodes"). Each path may be written once.
  void write_static(std::string_view abs_path, const ArrayView& data);
  template <class T, std::size_t E>
  void write_static(std::string_view abs_path, std::span<T, E> data, std::size_t cols = 1) {
    write_static(abs_path, ArrayView(data, cols));
  }
  template <class T>
  void write_static(std::string_view abs_path, const std::vector<T>& data, std::size_t cols = 1) {
    write_static(abs_path, ArrayView(data, cols));
  }

  /// Makes the int32 dataset `abs_path` (unlimited, chunked 65536, shuffle+gzip 1) hold at
  /// least 0, 1, ..., n-1, growing it when n exceeds its length. This is the static vertex
  /// index whose first N entries give the XDMF3 readers one Polyvertex cell per particle
  /// (docs/output.md O17, O19). Returns the reference with the current length.
  DatasetRef ensure_index(std::string_view abs_path, std::size_t n);

  /// Cuts the index dataset `abs_path` (written by ensure_index()) back to its first n
  /// entries when it is longer; does nothing when it is not longer or does not exist. For
  /// a resumed run: entries only frames after the checkpoint needed are dropped, so the
  /// index has the length an uninterrupted run had at that frame.
  void truncate_index(std::string_view abs_path, std::size_t n);

  /// String / int64 / float64 attribute on an existing object ("/" for the root).
  /// An existing attribute of the same name is replaced.
  void set_attribute(std::string_view object_path, std::string_view name, std::string_view value);
  void set_attribute(std::string_view object_path, std::string_view name, std::int64_t value);
  void set_attribute(std::string_view object_path, std::string_view name, double value);

  /// Replaces the attribute time of frames 0 .. times.size()-1 (in one open of the file),
  /// e.g. when the origin of the model time becomes known after those frames were written
  /// (docs/output.md). `times` must be finite; the caller keeps them increasing. Throws
  /// std::invalid_argument when more times than frames are given, std::logic_error while a
  /// frame is open.
  void set_frame_times(std::span<const double> times);

  /// Opens the file and creates /frames/NNNNNN (NNNNNN = frame_count()) with attributes
  /// time [s] and step. Returns the frame index. Throws std::logic_error when a frame is open.
  std::size_t begin_frame(std::int64_t step, double time);
  /// Writes `data` at `name` relative to the open frame group ("particles/position").
  /// Intermediate groups are created as needed. Each name may be written once per frame.
  void write(std::string_view name, const ArrayView& data);
  template <class T, std::size_t E>
  void write(std::string_view name, std::span<T, E> data, std::size_t cols = 1) {
    write(name, ArrayView(data, cols));
  }
  template <class T>
  void write(std::string_view name, const std::vector<T>& data, std::size_t cols = 1) {
    write(name, ArrayView(data, cols));
  }
  /// A dataset of the open frame written in blocks of rows (a frame larger than one block of
  /// memory): create() makes `name` [rows] or [rows, cols] of `dtype`, with the storage write()
  /// gives a dataset of that shape; write_rows() writes rows [row0, row0 + block.rows) of it.
  /// The caller writes every row before end_frame(). Each name may be created once per frame.
  void create(std::string_view name, DType dtype, std::size_t rows, std::size_t cols);
  void write_rows(std::string_view name, std::size_t row0, const ArrayView& block);
  /// Closes the file. Throws std::logic_error when no frame is open.
  void end_frame();

  /// Creates /history/<name> for each column (once per file). Columns are appended together.
  void declare_history(const std::vector<HistoryColumn>& columns);
  /// Appends one sample (row.size() == number of declared columns). Rows are buffered and
  /// written every H5StorageParams::history_flush_rows rows, or by flush_history()/close().
  void append_history(std::span<const double> row);
  void flush_history();
  /// The declared history columns (empty before declare_history()).
  const std::vector<HistoryColumn>& history_columns() const noexcept { return history_; }
  /// History rows appended so far, including rows still buffered: flush_history() before
  /// recording this in a checkpoint, or a crash loses the buffered rows and reopen()
  /// refuses the file.
  std::size_t history_rows() const noexcept {
    return history_rows_on_disk_ + (history_.empty() ? 0 : history_buffer_.size() / history_.size());
  }

  /// Reads frames 0 .. frame_count()-1 back from the file: attributes and datasets in write
  /// order (what a resumed writer rebuilds its sidecars from). Throws std::logic_error while
  /// a frame is open, IoError when a frame lacks its attributes or its dataset list.
  std::vector<FrameRecord> read_frames();

  /// Flushes history and closes the file if open. Further calls throw std::logic_error.
  void close();

  /// Reference to a dataset written by this object: an absolute path names a static or
  /// index dataset, a relative path one of the current (or most recently ended) frame.
  /// Throws std::out_of_range when no such dataset was written.
  DatasetRef ref(std::string_view path) const;

  const std::filesystem::path& file() const noexcept { return file_; }
  /// Number of frames begun so far (the next frame's index).
  std::size_t frame_count() const noexcept { return frame_count_; }
  bool frame_open() const noexcept { return frame_open_; }
  /// "/frames/NNNNNN" of frame `index`.
  static std::string frame_group(std::size_t index);

 private:
  H5Frames(std::filesystem::path file, const H5StorageParams& storage);

  class OpenScope;  // opens the file for one call unless a frame holds it open
  std::int64_t open_rdwr();
  void close_file();
  void write_dataset(std::int64_t fid, const std::string& abs_path, const ArrayView& data,
                     bool allow_compress);
  void create_dataset(std::int64_t fid, const std::string& abs_path, DType dtype, std::size_t rows, std::size_t cols,
                      bool allow_compress);
  void write_rows_of(std::int64_t fid, const std::string& abs_path, std::size_t row0, const ArrayView& data);
  void flush_history_open(std::int64_t fid);

  std::filesystem::path file_;
  H5StorageParams storage_;
  std::int64_t fid_ = -1;  // hid_t while open (hid_t is int64_t in HDF5 1.10), -1 when closed
  bool closed_ = false;
  bool frame_open_ = false;
  std::size_t frame_count_ = 0;
  std::string frame_path_;                          // group of the current/last frame
  std::map<std::string, DatasetRef> frame_refs_;    // by name relative to frame_path_
  std::vector<std::string> frame_order_;            // frame_refs_ names in write order
  std::map<std::string, DatasetRef> static_refs_;   // by absolute path
  std::vector<HistoryColumn> history_;
  std::size_t history_rows_on_disk_ = 0;
  std::vector<double> history_buffer_;  // row-major, history_.size() values per row
};

}  // namespace demfdm::io
