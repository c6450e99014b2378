// H5Frames: see the header for the layout; output-recipe.md §3 and §5 for why.
#include "demfdm/io/h5_frames.hpp"

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <system_error>

#include "demfdm/io/error.hpp"
#include "h5_util.hpp"

namespace demfdm::io {

using detail::check;
using detail::check_id;
using detail::H5Handle;
using detail::QuietErrors;

namespace {

constexpr std::int64_t kFormatVersion = 1;
constexpr hsize_t kIndexChunkRows = 65536;  // recipe §3: /xdmf/vertex_index chunk length

void require_relative_name(std::string_view name) {
  if (name.empty() || name.front() == '/' || name.back() == '/')
    throw std::invalid_argument("frame dataset name must be a relative path such as \"particles/position\", found '" +
                                std::string(name) + "'");
}

bool is_reserved_root(std::string_view path) {
  auto under = [&](std::string_view root) {
    return path == root || (path.size() > root.size() && path.substr(0, root.size()) == root &&
                            path[root.size()] == '/');
  };
  return under("/frames") || under("/history");
}

std::string abs_string(const std::filesystem::path& p) {
  return std::filesystem::absolute(p).lexically_normal().string();
}

}  // namespace

void H5StorageParams::validate() const {
  if (deflate_level < 1 || deflate_level > 9)
    throw std::invalid_argument("H5StorageParams.deflate_level must be in 1..9, found " +
                                std::to_string(deflate_level));
  if (chunk_rows < 1)
    throw std::invalid_argument("H5StorageParams.chunk_rows must be >= 1, found " + std::to_string(chunk_rows));
  if (history_chunk_rows < 1)
    throw std::invalid_argument("H5StorageParams.history_chunk_rows must be >= 1, found " +
                                std::to_string(history_chunk_rows));
  if (history_flush_rows < 1)
    throw std::invalid_argument("H5StorageParams.history_flush_rows must be >= 1, found " +
                                std::to_string(history_flush_rows));
}

// ---------------------------------------------------------------------------------------
// Opening discipline: the file is open only inside a frame or for the duration of one call.

class H5Frames::OpenScope {
 public:
  explicit OpenScope(H5Frames& f) : f_(f), owned_(f.fid_ < 0) {
    if (owned_) f_.open_rdwr();
  }
  // Exception path only: close without reporting (the original error is in flight).
  ~OpenScope() {
    if (owned_ && f_.fid_ >= 0) {
      H5Fclose(f_.fid_);
      f_.fid_ = -1;
    }
  }
  OpenScope(const OpenScope&) = delete;
  OpenScope& operator=(const OpenScope&) = delete;
  /// Normal path: close the file (if this scope opened it) and report a failing close.
  void commit() {
    if (owned_) f_.close_file();
  }
  /// Success path of begin_frame(): leave the file open for the frame.
  void keep_open() noexcept { owned_ = false; }
  hid_t fid() const noexcept { return f_.fid_; }

 private:
  H5Frames& f_;
  bool owned_;
};

std::int64_t H5Frames::open_rdwr() {
  QuietErrors quiet;
  H5Handle fapl = detail::make_fapl(file_.string());
  const hid_t fid = H5Fopen(file_.c_str(), H5F_ACC_RDWR, fapl.get());
  if (fid < 0)
    detail::throw_h5("H5Fopen(H5F_ACC_RDWR)", file_.string(), "",
                     "cannot reopen the results file (deleted, or locked by a reader that keeps it open?)");
  fid_ = fid;
  return fid_;
}

void H5Frames::close_file() {
  if (fid_ < 0) return;
  QuietErrors quiet;
  const hid_t fid = fid_;
  fid_ = -1;
  check(H5Fclose(fid), "H5Fclose", file_.string(), "");
}

H5Frames::H5Frames(std::filesystem::path file, const H5StorageParams& storage)
    : file_(std::move(file)), storage_(storage) {}

H5Frames::H5Frames(H5Frames&& o) noexcept
    : file_(std::move(o.file_)),
      storage_(o.storage_),
      fid_(o.fid_),
      closed_(o.closed_),
      frame_open_(o.frame_open_),
      frame_count_(o.frame_count_),
      frame_path_(std::move(o.frame_path_)),
      frame_refs_(std::move(o.frame_refs_)),
      static_refs_(std::move(o.static_refs_)),
      history_(std::move(o.history_)),
      history_rows_on_disk_(o.history_rows_on_disk_),
      history_buffer_(std::move(o.history_buffer_)) {
  o.fid_ = -1;
  o.closed_ = true;
  o.frame_open_ = false;
}

H5Frames& H5Frames::operator=(H5Frames&& o) noexcept {
  if (this != &o) {
    this->~H5Frames();
    new (this) H5Frames(std::move(o));
  }
  return *this;
}

H5Frames::~H5Frames() {
  if (closed_) return;
  try {
    close();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "demfdm::io::H5Frames: closing '%s' failed: %s\n", file_.c_str(), e.what());
    if (fid_ >= 0) H5Fclose(fid_);
    fid_ = -1;
  }
}

H5Frames H5Frames::create(const std::filesystem::path& file, const FileInfo& info,
                          const H5StorageParams& storage) {
  storage.validate();
  static const char* const kStandard[] = {"format", "format_version", "producer", "run_id",
                                          "scene_hash", "length_unit", "time_unit"};
  for (std::size_t i = 0; i < info.extra.size(); ++i) {
    const std::string& name = info.extra[i].first;
    if (name.empty()) throw std::invalid_argument("FileInfo.extra: attribute names must be non-empty");
    for (const char* s : kStandard)
      if (name == s)
        throw std::invalid_argument("FileInfo.extra: '" + name + "' is a standard root attribute set by H5Frames");
    for (std::size_t j = 0; j < i; ++j)
      if (info.extra[j].first == name)
        throw std::invalid_argument("FileInfo.extra: attribute '" + name + "' is given twice");
  }

  const std::string path = abs_string(file);
  QuietErrors quiet;
  H5Handle fapl = detail::make_fapl(path);
  // H5F_ACC_EXCL: an earlier run's results are never overwritten (recipe §3).
  const hid_t fid = H5Fcreate(path.c_str(), H5F_ACC_EXCL, H5P_DEFAULT, fapl.get());
  if (fid < 0) {
    std::error_code ec;
    if (std::filesystem::exists(path, ec))
      detail::throw_h5("H5Fcreate(H5F_ACC_EXCL)", path, "",
                       "the file already exists; results are never overwritten, choose a new run folder or remove the old file");
    detail::throw_h5("H5Fcreate(H5F_ACC_EXCL)", path, "", "cannot create the results file (does its folder exist and is it writable?)");
  }
  H5Frames out(path, storage);
  out.fid_ = fid;
  {
    H5Handle root = check_id(H5Gopen2(fid, "/", H5P_DEFAULT), H5Gclose, "H5Gopen2", path, "/");
    detail::write_attr_string(root.get(), "format", "demfdm-results", path, "/");
    detail::write_attr_i64(root.get(), "format_version", kFormatVersion, path, "/");
    detail::write_attr_string(root.get(), "producer", info.producer, path, "/");
    detail::write_attr_string(root.get(), "run_id", info.run_id, path, "/");
    detail::write_attr_string(root.get(), "scene_hash", info.scene_hash, path, "/");
    detail::write_attr_string(root.get(), "length_unit", "m", path, "/");
    detail::write_attr_string(root.get(), "time_unit", "s", path, "/");
    for (const auto& [name, value] : info.extra) detail::write_attr_string(root.get(), name, value, path, "/");
  }
  out.close_file();
  return out;
}

std::string H5Frames::frame_group(std::size_t index) {
  if (index > 999999)
    throw std::out_of_range("H5Frames: at most 1000000 frames fit the 6-digit /frames/NNNNNN names, asked for index " +
                            std::to_string(index));
  char buf[32];
  std::snprintf(buf, sizeof buf, "/frames/%06zu", index);
  return buf;
}

void H5Frames::write_dataset(std::int64_t fid, const std::string& abs_path, const ArrayView& data,
                             bool allow_compress) {
  const std::string file = file_.string();
  if (data.size() > 0 && data.data == nullptr)
    throw std::invalid_argument("dataset '" + abs_path + "': null data pointer for " + std::to_string(data.size()) +
                                " elements");
  if (data.cols == 0) throw std::invalid_argument("dataset '" + abs_path + "': cols must be >= 1");
  const auto [parent, leaf] = detail::split_abs_path(abs_path);
  H5Handle group = detail::require_group(fid, parent, file);
  const htri_t exists = H5Lexists(group.get(), leaf.c_str(), H5P_DEFAULT);
  if (exists < 0) detail::throw_h5("H5Lexists", file, abs_path);
  if (exists > 0) throw std::logic_error("H5Frames: dataset '" + abs_path + "' in '" + file + "' is already written");

  const int rank = data.cols == 1 ? 1 : 2;
  const hsize_t dims[2] = {static_cast<hsize_t>(data.rows), static_cast<hsize_t>(data.cols)};
  H5Handle space = check_id(H5Screate_simple(rank, dims, nullptr), H5Sclose, "H5Screate_simple", file, abs_path);
  H5Handle dcpl = detail::make_dcpl(file);
  // Chunk only when compressing: chunks without a filter store partial edge chunks in full
  // (+25 % in the recipe's benchmark, §8). A zero-row dataset stays contiguous (chunk
  // dimensions must be positive and there is nothing to compress).
  if (allow_compress && storage_.compress && data.rows > 0) {
    const hsize_t chunk[2] = {std::min<hsize_t>(data.rows, storage_.chunk_rows), dims[1]};
    check(H5Pset_chunk(dcpl.get(), rank, chunk), "H5Pset_chunk", file, abs_path);
    check(H5Pset_shuffle(dcpl.get()), "H5Pset_shuffle", file, abs_path);
    check(H5Pset_deflate(dcpl.get(), static_cast<unsigned>(storage_.deflate_level)), "H5Pset_deflate", file,
          abs_path);
  }
  H5Handle dset = check_id(H5Dcreate2(group.get(), leaf.c_str(), detail::file_type(data.dtype), space.get(),
                                      H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
                           H5Dclose, "H5Dcreate2", file, abs_path);
  if (data.size() > 0)
    check(H5Dwrite(dset.get(), detail::mem_type(data.dtype), H5S_ALL, H5S_ALL, H5P_DEFAULT, data.data), "H5Dwrite",
          file, abs_path);
}

void H5Frames::write_static(std::string_view abs_path, const ArrayView& data) {
  if (closed_) throw std::logic_error("H5Frames::write_static on closed file '" + file_.string() + "'");
  const std::string path(abs_path);
  detail::split_abs_path(path);
  if (is_reserved_root(path))
    throw std::invalid_argument("H5Frames::write_static: '" + path +
                                "' lies under /frames or /history, which H5Frames manages; choose e.g. /mesh/...");
  QuietErrors quiet;
  OpenScope scope(*this);
  write_dataset(scope.fid(), path, data, /*allow_compress=*/true);
  scope.commit();
  static_refs_[path] = DatasetRef{file_, path, data.dtype, data.rows, data.cols};
}

DatasetRef H5Frames::ensure_index(std::string_view abs_path, std::size_t n) {
  if (closed_) throw std::logic_error("H5Frames::ensure_index on closed file '" + file_.string() + "'");
  const std::string path(abs_path);
  const std::string file = file_.string();
  if (n > static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max()))
    throw std::invalid_argument("H5Frames::ensure_index: " + std::to_string(n) +
                                " entries do not fit the int32 vertex index");
  if (is_reserved_root(path))
    throw std::invalid_argument("H5Frames::ensure_index: '" + path + "' lies under /frames or /history");
  auto known = static_refs_.find(path);
  if (known != static_refs_.end() && known->second.rows >= n) return known->second;

  QuietErrors quiet;
  OpenScope scope(*this);
  const hid_t fid = scope.fid();
  const auto [parent, leaf] = detail::split_abs_path(path);
  H5Handle group = detail::require_group(fid, parent, file);
  const htri_t exists = H5Lexists(group.get(), leaf.c_str(), H5P_DEFAULT);
  if (exists < 0) detail::throw_h5("H5Lexists", file, path);
  H5Handle dset;
  if (exists == 0) {
    const hsize_t zero = 0, unlimited = H5S_UNLIMITED, chunk = kIndexChunkRows;
    H5Handle space = check_id(H5Screate_simple(1, &zero, &unlimited), H5Sclose, "H5Screate_simple", file, path);
    H5Handle dcpl = detail::make_dcpl(file);
    // Recipe §3: chunked 65536, shuffle + gzip 1 (the index compresses to almost nothing).
    check(H5Pset_chunk(dcpl.get(), 1, &chunk), "H5Pset_chunk", file, path);
    check(H5Pset_shuffle(dcpl.get()), "H5Pset_shuffle", file, path);
    check(H5Pset_deflate(dcpl.get(), 1), "H5Pset_deflate", file, path);
    dset = check_id(H5Dcreate2(group.get(), leaf.c_str(), H5T_STD_I32LE, space.get(), H5P_DEFAULT, dcpl.get(),
                               H5P_DEFAULT),
                    H5Dclose, "H5Dcreate2", file, path);
  } else {
    dset = check_id(H5Dopen2(group.get(), leaf.c_str(), H5P_DEFAULT), H5Dclose, "H5Dopen2", file, path);
  }
  hsize_t cur = 0;
  {
    H5Handle space = check_id(H5Dget_space(dset.get()), H5Sclose, "H5Dget_space", file, path);
    if (H5Sget_simple_extent_ndims(space.get()) != 1)
      throw IoError("index dataset '" + path + "' in '" + file + "' is not 1-D");
    check(H5Sget_simple_extent_dims(space.get(), &cur, nullptr), "H5Sget_simple_extent_dims", file, path);
  }
  if (n > cur) {
    const hsize_t newlen = n, count = n - cur;
    check(H5Dset_extent(dset.get(), &newlen), "H5Dset_extent", file, path);
    H5Handle fspace = check_id(H5Dget_space(dset.get()), H5Sclose, "H5Dget_space", file, path);
    check(H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, &cur, nullptr, &count, nullptr), "H5Sselect_hyperslab",
          file, path);
    H5Handle mspace = check_id(H5Screate_simple(1, &count, nullptr), H5Sclose, "H5Screate_simple", file, path);
    std::vector<std::int32_t> values(count);
    std::iota(values.begin(), values.end(), static_cast<std::int32_t>(cur));
    check(H5Dwrite(dset.get(), H5T_NATIVE_INT32, mspace.get(), fspace.get(), H5P_DEFAULT, values.data()), "H5Dwrite",
          file, path);
    cur = newlen;
  }
  dset.reset();
  group.reset();
  scope.commit();
  DatasetRef ref{file_, path, DType::kInt32, static_cast<std::size_t>(cur), 1};
  static_refs_[path] = ref;
  return ref;
}

namespace {
template <class WriteFn>
void with_object(hid_t fid, std::string_view object_path, const std::string& file, WriteFn&& fn) {
  const std::string obj(object_path);
  H5Handle o = check_id(H5Oopen(fid, obj.c_str(), H5P_DEFAULT), H5Oclose, "H5Oopen", file, obj);
  fn(o.get(), obj);
}
}  // namespace

void H5Frames::set_attribute(std::string_view object_path, std::string_view name, std::string_view value) {
  if (closed_) throw std::logic_error("H5Frames::set_attribute on closed file '" + file_.string() + "'");
  QuietErrors quiet;
  OpenScope scope(*this);
  const std::string file = file_.string();
  with_object(scope.fid(), object_path, file,
              [&](hid_t o, const std::string& obj) { detail::write_attr_string(o, name, value, file, obj); });
  scope.commit();
}

void H5Frames::set_attribute(std::string_view object_path, std::string_view name, std::int64_t value) {
  if (closed_) throw std::logic_error("H5Frames::set_attribute on closed file '" + file_.string() + "'");
  QuietErrors quiet;
  OpenScope scope(*this);
  const std::string file = file_.string();
  with_object(scope.fid(), object_path, file,
              [&](hid_t o, const std::string& obj) { detail::write_attr_i64(o, name, value, file, obj); });
  scope.commit();
}

void H5Frames::set_attribute(std::string_view object_path, std::string_view name, double value) {
  if (closed_) throw std::logic_error("H5Frames::set_attribute on closed file '" + file_.string() + "'");
  QuietErrors quiet;
  OpenScope scope(*this);
  const std::string file = file_.string();
  with_object(scope.fid(), object_path, file,
              [&](hid_t o, const std::string& obj) { detail::write_attr_f64(o, name, value, file, obj); });
  scope.commit();
}

std::size_t H5Frames::begin_frame(std::int64_t step, double time) {
  if (closed_) throw std::logic_error("H5Frames::begin_frame on closed file '" + file_.string() + "'");
  if (frame_open_)
    throw std::logic_error("H5Frames::begin_frame: frame " + frame_path_ + " of '" + file_.string() +
                           "' is still open; call end_frame() first");
  const std::string group_path = frame_group(frame_count_);
  const std::string file = file_.string();
  QuietErrors quiet;
  OpenScope scope(*this);  // stays open on success: the frame owns the open file below
  if (detail::link_exists(scope.fid(), group_path))
    throw IoError("frame group " + group_path + " already exists in '" + file + "'");
  {
    H5Handle g = detail::require_group(scope.fid(), group_path, file);
    detail::write_attr_f64(g.get(), "time", time, file, group_path);
    detail::write_attr_i64(g.get(), "step", step, file, group_path);
  }
  // Success: the file stays open until end_frame().
  scope.keep_open();
  frame_open_ = true;
  frame_path_ = group_path;
  frame_refs_.clear();
  return frame_count_++;
}

void H5Frames::write(std::string_view name, const ArrayView& data) {
  if (!frame_open_)
    throw std::logic_error("H5Frames::write('" + std::string(name) + "') outside a frame of '" + file_.string() +
                           "'; call begin_frame() first");
  require_relative_name(name);
  const std::string abs = frame_path_ + "/" + std::string(name);
  QuietErrors quiet;
  write_dataset(fid_, abs, data, /*allow_compress=*/true);
  frame_refs_[std::string(name)] = DatasetRef{file_, abs, data.dtype, data.rows, data.cols};
}

void H5Frames::end_frame() {
  if (!frame_open_)
    throw std::logic_error("H5Frames::end_frame without an open frame in '" + file_.string() + "'");
  frame_open_ = false;
  QuietErrors quiet;
  try {
    if (!history_buffer_.empty()) flush_history_open(fid_);
  } catch (...) {
    if (fid_ >= 0) H5Fclose(fid_);
    fid_ = -1;
    throw;
  }
  close_file();
}

void H5Frames::declare_history(const std::vector<HistoryColumn>& columns) {
  if (closed_) throw std::logic_error("H5Frames::declare_history on closed file '" + file_.string() + "'");
  if (!history_.empty())
    throw std::logic_error("H5Frames::declare_history: the history of '" + file_.string() + "' is already declared");
  if (columns.empty()) throw std::invalid_argument("H5Frames::declare_history: at least one column is needed");
  for (std::size_t i = 0; i < columns.size(); ++i) {
    const std::string& n = columns[i].name;
    if (n.empty() || n.find('/') != std::string::npos || n == "." || n == "..")
      throw std::invalid_argument("H5Frames::declare_history: column name must be a plain name, found '" + n + "'");
    for (std::size_t j = 0; j < i; ++j)
      if (columns[j].name == n)
        throw std::invalid_argument("H5Frames::declare_history: column '" + n + "' is given twice");
  }
  const std::string file = file_.string();
  QuietErrors quiet;
  OpenScope scope(*this);
  H5Handle group = detail::require_group(scope.fid(), "/history", file);
  for (const auto& c : columns) {
    const std::string path = "/history/" + c.name;
    const hsize_t zero = 0, unlimited = H5S_UNLIMITED, chunk = storage_.history_chunk_rows;
    H5Handle space = check_id(H5Screate_simple(1, &zero, &unlimited), H5Sclose, "H5Screate_simple", file, path);
    H5Handle dcpl = detail::make_dcpl(file);
    check(H5Pset_chunk(dcpl.get(), 1, &chunk), "H5Pset_chunk", file, path);
    H5Handle dset = check_id(H5Dcreate2(group.get(), c.name.c_str(), H5T_IEEE_F64LE, space.get(), H5P_DEFAULT,
                                        dcpl.get(), H5P_DEFAULT),
                             H5Dclose, "H5Dcreate2", file, path);
    detail::write_attr_string(dset.get(), "unit", c.unit, file, path);
    // Also "<name>_unit" on /history: the form the recipe's h5py example reads (§7).
    detail::write_attr_string(group.get(), c.name + "_unit", c.unit, file, "/history");
  }
  group.reset();
  scope.commit();
  history_ = columns;
}

void H5Frames::append_history(std::span<const double> row) {
  if (history_.empty())
    throw std::logic_error("H5Frames::append_history before declare_history on '" + file_.string() + "'");
  if (row.size() != history_.size())
    throw std::invalid_argument("H5Frames::append_history: row has " + std::to_string(row.size()) +
                                " values, the history of '" + file_.string() + "' has " +
                                std::to_string(history_.size()) + " columns");
  history_buffer_.insert(history_buffer_.end(), row.begin(), row.end());
  if (history_buffer_.size() / history_.size() >= storage_.history_flush_rows) flush_history();
}

void H5Frames::flush_history() {
  if (history_buffer_.empty()) return;
  if (closed_) throw std::logic_error("H5Frames::flush_history on closed file '" + file_.string() + "'");
  QuietErrors quiet;
  OpenScope scope(*this);
  flush_history_open(scope.fid());
  scope.commit();
}

void H5Frames::flush_history_open(std::int64_t fid) {
  const std::string file = file_.string();
  const std::size_t ncols = history_.size();
  const hsize_t nrows = history_buffer_.size() / ncols;
  const hsize_t start = history_rows_on_disk_, newlen = start + nrows;
  std::vector<double> column(nrows);
  // Columns are extended one after the other; if a write fails half-way the columns can
  // differ in length by this batch (reported as an IoError, the run should stop).
  for (std::size_t c = 0; c < ncols; ++c) {
    const std::string path = "/history/" + history_[c].name;
    for (hsize_t r = 0; r < nrows; ++r) column[r] = history_buffer_[r * ncols + c];
    H5Handle dset = check_id(H5Dopen2(fid, path.c_str(), H5P_DEFAULT), H5Dclose, "H5Dopen2", file, path);
    check(H5Dset_extent(dset.get(), &newlen), "H5Dset_extent", file, path);
    H5Handle fspace = check_id(H5Dget_space(dset.get()), H5Sclose, "H5Dget_space", file, path);
    check(H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, &start, nullptr, &nrows, nullptr), "H5Sselect_hyperslab",
          file, path);
    H5Handle mspace = check_id(H5Screate_simple(1, &nrows, nullptr), H5Sclose, "H5Screate_simple", file, path);
    check(H5Dwrite(dset.get(), H5T_NATIVE_DOUBLE, mspace.get(), fspace.get(), H5P_DEFAULT, column.data()), "H5Dwrite",
          file, path);
  }
  history_rows_on_disk_ = newlen;
  history_buffer_.clear();
}

void H5Frames::close() {
  if (closed_) throw std::logic_error("H5Frames::close: '" + file_.string() + "' is already closed");
  if (frame_open_) end_frame();
  flush_history();
  close_file();
  closed_ = true;
}

DatasetRef H5Frames::ref(std::string_view path) const {
  const std::string p(path);
  if (!p.empty() && p.front() == '/') {
    auto it = static_refs_.find(p);
    if (it == static_refs_.end())
      throw std::out_of_range("H5Frames::ref: no static dataset '" + p + "' was written to '" + file_.string() + "'");
    return it->second;
  }
  auto it = frame_refs_.find(p);
  if (it == frame_refs_.end())
    throw std::out_of_range("H5Frames::ref: dataset '" + p + "' was not written in frame " + frame_path_ + " of '" +
                            file_.string() + "'");
  return it->second;
}

}  // namespace demfdm::io
