// H5Frames: see the header for the layout; docs/output.md O1-O17 for why.
#include "demfdm/io/h5_frames.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <numeric>
#include <optional>
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
constexpr hsize_t kIndexChunkRows = 65536;  // docs/output.md O17: /xdmf/vertex_index chunk length

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

// 1-D attribute of fixed-length, null-padded ASCII strings (the frame dataset order and the
// history column order); h5py reads it as an array of bytes. Replaces an existing one.
void write_attr_strings(hid_t obj, const char* name, const std::vector<std::string>& values, const std::string& file,
                        const std::string& object) {
  std::size_t len = 1;  // HDF5 refuses a zero-size string type
  for (const auto& v : values) len = std::max(len, v.size());
  H5Handle type = check_id(H5Tcopy(H5T_C_S1), H5Tclose, "H5Tcopy", file, object);
  check(H5Tset_size(type.get(), len), "H5Tset_size", file, object);
  check(H5Tset_strpad(type.get(), H5T_STR_NULLPAD), "H5Tset_strpad", file, object);
  check(H5Tset_cset(type.get(), H5T_CSET_ASCII), "H5Tset_cset", file, object);
  std::string buf(values.size() * len, '\0');
  for (std::size_t i = 0; i < values.size(); ++i) buf.replace(i * len, values[i].size(), values[i]);
  const hsize_t n = values.size();
  H5Handle space = check_id(H5Screate_simple(1, &n, nullptr), H5Sclose, "H5Screate_simple", file, object);
  const std::string where = object + "@" + name;
  const htri_t e = H5Aexists(obj, name);
  if (e < 0) detail::throw_h5("H5Aexists", file, where);
  if (e > 0) check(H5Adelete(obj, name), "H5Adelete", file, where);
  H5Handle attr = check_id(H5Acreate2(obj, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose,
                           "H5Acreate2", file, where);
  check(H5Awrite(attr.get(), type.get(), buf.data()), "H5Awrite", file, where);
}

// Reads a fixed-length string attribute, scalar or 1-D, as its list of values (trailing
// NULs removed). No value when the attribute does not exist.
std::optional<std::vector<std::string>> read_attr_strings(hid_t obj, const char* name, const std::string& file,
                                                          const std::string& object) {
  const std::string where = object + "@" + name;
  const htri_t e = H5Aexists(obj, name);
  if (e < 0) detail::throw_h5("H5Aexists", file, where);
  if (e == 0) return std::nullopt;
  H5Handle attr = check_id(H5Aopen(obj, name, H5P_DEFAULT), H5Aclose, "H5Aopen", file, where);
  H5Handle ftype = check_id(H5Aget_type(attr.get()), H5Tclose, "H5Aget_type", file, where);
  if (H5Tget_class(ftype.get()) != H5T_STRING || H5Tis_variable_str(ftype.get()) != 0)
    throw IoError("attribute '" + where + "' in '" + file + "' is not a fixed-length string");
  const std::size_t len = H5Tget_size(ftype.get());
  H5Handle space = check_id(H5Aget_space(attr.get()), H5Sclose, "H5Aget_space", file, where);
  if (H5Sget_simple_extent_ndims(space.get()) > 1)
    throw IoError("attribute '" + where + "' in '" + file + "' has more than one dimension");
  const hssize_t n = H5Sget_simple_extent_npoints(space.get());
  if (n < 0) detail::throw_h5("H5Sget_simple_extent_npoints", file, where);
  H5Handle mtype = check_id(H5Tcopy(H5T_C_S1), H5Tclose, "H5Tcopy", file, where);
  check(H5Tset_size(mtype.get(), len), "H5Tset_size", file, where);
  check(H5Tset_strpad(mtype.get(), H5T_STR_NULLPAD), "H5Tset_strpad", file, where);
  std::string buf(static_cast<std::size_t>(n) * len, '\0');
  if (n > 0) check(H5Aread(attr.get(), mtype.get(), buf.data()), "H5Aread", file, where);
  std::vector<std::string> out;
  for (std::size_t i = 0; i < static_cast<std::size_t>(n); ++i) {
    std::string v = buf.substr(i * len, len);
    v.resize(std::min(v.find('\0'), v.size()));
    out.push_back(std::move(v));
  }
  return out;
}

template <class T>
T read_attr_scalar(hid_t obj, const char* name, hid_t mem_type, const std::string& file, const std::string& object) {
  const std::string where = object + "@" + name;
  H5Handle attr = check_id(H5Aopen(obj, name, H5P_DEFAULT), H5Aclose, "H5Aopen", file, where);
  H5Handle space = check_id(H5Aget_space(attr.get()), H5Sclose, "H5Aget_space", file, where);
  if (H5Sget_simple_extent_npoints(space.get()) != 1)
    throw IoError("attribute '" + where + "' in '" + file + "' is not a single value");
  T v{};
  check(H5Aread(attr.get(), mem_type, &v), "H5Aread", file, where);
  return v;
}

// The DatasetRef of an existing dataset: its dtype from the file type, its shape.
DatasetRef read_ref(hid_t fid, const std::filesystem::path& file, const std::string& abs_path) {
  const std::string f = file.string();
  H5Handle dset = check_id(H5Dopen2(fid, abs_path.c_str(), H5P_DEFAULT), H5Dclose, "H5Dopen2", f, abs_path);
  H5Handle type = check_id(H5Dget_type(dset.get()), H5Tclose, "H5Dget_type", f, abs_path);
  const H5T_class_t cls = H5Tget_class(type.get());
  const std::size_t size = H5Tget_size(type.get());
  const bool is_signed = cls == H5T_INTEGER && H5Tget_sign(type.get()) == H5T_SGN_2;
  DatasetRef ref{file, abs_path, DType::kFloat64, 0, 1};
  if (cls == H5T_FLOAT && size == 8) ref.dtype = DType::kFloat64;
  else if (cls == H5T_FLOAT && size == 4) ref.dtype = DType::kFloat32;
  else if (cls == H5T_INTEGER && is_signed && size == 4) ref.dtype = DType::kInt32;
  else if (cls == H5T_INTEGER && is_signed && size == 8) ref.dtype = DType::kInt64;
  else if (cls == H5T_INTEGER && !is_signed && size == 1) ref.dtype = DType::kUInt8;
  else
    throw IoError("dataset '" + abs_path + "' in '" + f +
                  "' has an element type H5Frames does not write (float64, float32, int32, int64, uint8)");
  H5Handle space = check_id(H5Dget_space(dset.get()), H5Sclose, "H5Dget_space", f, abs_path);
  const int rank = H5Sget_simple_extent_ndims(space.get());
  if (rank != 1 && rank != 2)
    throw IoError("dataset '" + abs_path + "' in '" + f + "' has rank " + std::to_string(rank) + ", expected 1 or 2");
  hsize_t dims[2] = {0, 1};
  check(H5Sget_simple_extent_dims(space.get(), dims, nullptr), "H5Sget_simple_extent_dims", f, abs_path);
  ref.rows = static_cast<std::size_t>(dims[0]);
  ref.cols = static_cast<std::size_t>(dims[1]);
  return ref;
}

// Paths (relative to `group`) of every dataset below `group`, in HDF5's name order.
// `skip(relative path)` prunes names before they are opened.
template <class Skip>
std::vector<std::string> list_datasets(hid_t group, const std::string& file, const std::string& object, Skip&& skip) {
  struct Visit {
    Skip& skip;
    std::vector<std::string> names;
  } visit{skip, {}};
  auto cb = [](hid_t g, const char* name, const H5L_info_t* info, void* data) -> herr_t {
    auto& v = *static_cast<Visit*>(data);
    if (info->type != H5L_TYPE_HARD || v.skip(std::string_view(name))) return 0;
    const hid_t o = H5Oopen(g, name, H5P_DEFAULT);
    if (o < 0) return -1;
    const bool dataset = H5Iget_type(o) == H5I_DATASET;
    H5Oclose(o);
    if (dataset) v.names.emplace_back(name);
    return 0;
  };
  check(H5Lvisit(group, H5_INDEX_NAME, H5_ITER_INC, cb, &visit), "H5Lvisit", file, object);
  return std::move(visit.names);
}

// Frame `index` of an open file: attributes, and datasets in write order from the
// "datasets" attribute, checked against the datasets the group really holds.
FrameRecord read_frame_record(hid_t fid, const std::filesystem::path& file, std::size_t index) {
  const std::string f = file.string();
  const std::string gpath = H5Frames::frame_group(index);
  H5Handle g = check_id(H5Gopen2(fid, gpath.c_str(), H5P_DEFAULT), H5Gclose, "H5Gopen2", f, gpath);
  FrameRecord r;
  r.time = read_attr_scalar<double>(g.get(), "time", H5T_NATIVE_DOUBLE, f, gpath);
  r.step = read_attr_scalar<std::int64_t>(g.get(), "step", H5T_NATIVE_INT64, f, gpath);
  const std::vector<std::string> present = list_datasets(g.get(), f, gpath, [](std::string_view) { return false; });
  auto order = read_attr_strings(g.get(), "datasets", f, gpath);
  if (!order && !present.empty())
    throw IoError("frame " + gpath + " of '" + f +
                  "' has no 'datasets' attribute (written before H5Frames recorded the write order), so it cannot be "
                  "resumed");
  r.names = order ? std::move(*order) : std::vector<std::string>{};
  bool same = r.names.size() == present.size();
  for (std::size_t i = 0; same && i < r.names.size(); ++i)
    same = std::find(present.begin(), present.end(), r.names[i]) != present.end();
  if (!same)
    throw IoError("frame " + gpath + " of '" + f + "': its 'datasets' attribute lists " +
                  std::to_string(r.names.size()) + " name(s) that differ from the " + std::to_string(present.size()) +
                  " dataset(s) it holds");
  for (const auto& n : r.names) r.datasets.push_back(read_ref(fid, file, gpath + "/" + n));
  return r;
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
      frame_order_(std::move(o.frame_order_)),
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
  // H5F_ACC_EXCL: an earlier run's results are never overwritten (docs/output.md O9).
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

H5Frames H5Frames::reopen(const std::filesystem::path& file, std::size_t frames, const H5StorageParams& storage,
                          std::size_t history_rows) {
  storage.validate();
  const std::string path = abs_string(file);
  QuietErrors quiet;
  H5Frames out(path, storage);
  OpenScope scope(out);
  const hid_t fid = scope.fid();

  // Everything is checked before anything is deleted: a refused reopen leaves the file as found.
  {
    H5Handle root = check_id(H5Gopen2(fid, "/", H5P_DEFAULT), H5Gclose, "H5Gopen2", path, "/");
    const auto format = read_attr_strings(root.get(), "format", path, "/");
    if (!format || format->size() != 1 || format->front() != "demfdm-results")
      throw IoError("H5Frames::reopen: '" + path + "' is not a demfdm results file (root attribute format is " +
                    (format && format->size() == 1 ? "'" + format->front() + "'" : std::string("missing")) +
                    ", expected 'demfdm-results')");
    if (H5Aexists(root.get(), "format_version") > 0) {
      const auto version = read_attr_scalar<std::int64_t>(root.get(), "format_version", H5T_NATIVE_INT64, path, "/");
      if (version != kFormatVersion)
        throw IoError("H5Frames::reopen: '" + path + "' has format_version " + std::to_string(version) +
                      ", this writer writes " + std::to_string(kFormatVersion));
    }
  }

  // Frame groups by index; anything else under /frames is not this writer's.
  std::vector<std::pair<std::size_t, std::string>> stored;
  H5Handle frames_group;
  if (detail::link_exists(fid, "/frames")) {
    frames_group = check_id(H5Gopen2(fid, "/frames", H5P_DEFAULT), H5Gclose, "H5Gopen2", path, "/frames");
    std::vector<std::string> names;
    auto cb = [](hid_t, const char* name, const H5L_info_t*, void* data) -> herr_t {
      static_cast<std::vector<std::string>*>(data)->emplace_back(name);
      return 0;
    };
    check(H5Literate(frames_group.get(), H5_INDEX_NAME, H5_ITER_INC, nullptr, cb, &names), "H5Literate", path,
          "/frames");
    for (const auto& n : names) {
      const bool digits = n.size() == 6 && std::all_of(n.begin(), n.end(), [](char c) { return c >= '0' && c <= '9'; });
      if (!digits)
        throw IoError("H5Frames::reopen: '" + path + "' holds /frames/" + n +
                      ", not a frame group NNNNNN of this writer");
      stored.emplace_back(static_cast<std::size_t>(std::stoul(n)), n);
    }
  }
  const std::size_t kept = static_cast<std::size_t>(
      std::count_if(stored.begin(), stored.end(), [&](const auto& s) { return s.first < frames; }));
  if (kept != frames)
    throw IoError("H5Frames::reopen: '" + path + "' holds " + std::to_string(kept) + " of the frames 0.." +
                  std::to_string(frames) + "-1 the checkpoint counts (" + std::to_string(stored.size()) +
                  " frame groups in all); it cannot be resumed at frame " + std::to_string(frames));

  // History columns in declaration order, each long enough for the checkpoint's rows.
  H5Handle history_group;
  std::vector<H5Handle> history_sets;
  if (detail::link_exists(fid, "/history")) {
    history_group = check_id(H5Gopen2(fid, "/history", H5P_DEFAULT), H5Gclose, "H5Gopen2", path, "/history");
    const auto columns = read_attr_strings(history_group.get(), "columns", path, "/history");
    if (!columns)
      throw IoError("H5Frames::reopen: /history of '" + path +
                    "' has no 'columns' attribute (written before H5Frames recorded the column order), so it cannot "
                    "be resumed");
    for (const auto& name : *columns) {
      const std::string dpath = "/history/" + name;
      H5Handle d = check_id(H5Dopen2(history_group.get(), name.c_str(), H5P_DEFAULT), H5Dclose, "H5Dopen2", path,
                            dpath);
      const auto unit = read_attr_strings(d.get(), "unit", path, dpath);
      if (!unit || unit->size() != 1) throw IoError("H5Frames::reopen: " + dpath + " of '" + path + "' has no unit");
      const DatasetRef r = read_ref(fid, path, dpath);
      if (r.cols != 1 || r.dtype != DType::kFloat64)
        throw IoError("H5Frames::reopen: " + dpath + " of '" + path + "' is not a 1-D float64 history");
      if (r.rows < history_rows)
        throw IoError("H5Frames::reopen: " + dpath + " of '" + path + "' holds " + std::to_string(r.rows) +
                      " rows, the checkpoint counts " + std::to_string(history_rows));
      out.history_.push_back(HistoryColumn{name, unit->front()});
      history_sets.push_back(std::move(d));
    }
  } else if (history_rows > 0) {
    throw IoError("H5Frames::reopen: '" + path + "' has no /history, the checkpoint counts " +
                  std::to_string(history_rows) + " history rows");
  }

  // Drop what the crashed run wrote after the checkpoint.
  for (const auto& [index, name] : stored)
    if (index >= frames)
      check(H5Ldelete(frames_group.get(), name.c_str(), H5P_DEFAULT), "H5Ldelete", path, "/frames/" + name);
  for (std::size_t c = 0; c < history_sets.size(); ++c) {
    const hsize_t len = history_rows;
    check(H5Dset_extent(history_sets[c].get(), &len), "H5Dset_extent", path, "/history/" + out.history_[c].name);
  }
  history_sets.clear();
  history_group.reset();
  frames_group.reset();
  out.history_rows_on_disk_ = history_rows;

  // What the object tracks: static datasets, the last kept frame's datasets.
  const std::vector<std::string> statics = list_datasets(fid, path, "/", [](std::string_view n) {
    return n == "frames" || n == "history" || n.starts_with("frames/") || n.starts_with("history/");
  });
  for (const auto& n : statics) out.static_refs_["/" + n] = read_ref(fid, out.file_, "/" + n);
  out.frame_count_ = frames;
  if (frames > 0) {
    FrameRecord last = read_frame_record(fid, out.file_, frames - 1);
    out.frame_path_ = frame_group(frames - 1);
    for (std::size_t i = 0; i < last.names.size(); ++i) out.frame_refs_[last.names[i]] = last.datasets[i];
    out.frame_order_ = std::move(last.names);
  }
  scope.commit();
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

void H5Frames::create_dataset(std::int64_t fid, const std::string& abs_path, DType dtype, std::size_t rows,
                              std::size_t cols, bool allow_compress) {
  const std::string file = file_.string();
  if (cols == 0) throw std::invalid_argument("dataset '" + abs_path + "': cols must be >= 1");
  const auto [parent, leaf] = detail::split_abs_path(abs_path);
  H5Handle group = detail::require_group(fid, parent, file);
  const htri_t exists = H5Lexists(group.get(), leaf.c_str(), H5P_DEFAULT);
  if (exists < 0) detail::throw_h5("H5Lexists", file, abs_path);
  if (exists > 0) throw std::logic_error("H5Frames: dataset '" + abs_path + "' in '" + file + "' is already written");

  const int rank = cols == 1 ? 1 : 2;
  const hsize_t dims[2] = {static_cast<hsize_t>(rows), static_cast<hsize_t>(cols)};
  H5Handle space = check_id(H5Screate_simple(rank, dims, nullptr), H5Sclose, "H5Screate_simple", file, abs_path);
  H5Handle dcpl = detail::make_dcpl(file);
  // Chunk only when compressing: chunks without a filter store partial edge chunks in full
  // (+25 % in the benchmark, docs/output.md O16). A zero-row dataset stays contiguous (chunk
  // dimensions must be positive and there is nothing to compress).
  if (allow_compress && storage_.compress && rows > 0) {
    const hsize_t chunk[2] = {std::min<hsize_t>(rows, storage_.chunk_rows), dims[1]};
    check(H5Pset_chunk(dcpl.get(), rank, chunk), "H5Pset_chunk", file, abs_path);
    check(H5Pset_shuffle(dcpl.get()), "H5Pset_shuffle", file, abs_path);
    check(H5Pset_deflate(dcpl.get(), static_cast<unsigned>(storage_.deflate_level)), "H5Pset_deflate", file,
          abs_path);
  }
  H5Handle dset = check_id(H5Dcreate2(group.get(), leaf.c_str(), detail::file_type(dtype), space.get(), H5P_DEFAULT,
                                      dcpl.get(), H5P_DEFAULT),
                           H5Dclose, "H5Dcreate2", file, abs_path);
}

void H5Frames::write_rows_of(std::int64_t fid, const std::string& abs_path, std::size_t row0, const ArrayView& data) {
  const std::string file = file_.string();
  if (data.size() > 0 && data.data == nullptr)
    throw std::invalid_argument("dataset '" + abs_path + "': null data pointer for " + std::to_string(data.size()) +
                                " elements");
  if (data.rows == 0) return;
  H5Handle dset = check_id(H5Dopen2(fid, abs_path.c_str(), H5P_DEFAULT), H5Dclose, "H5Dopen2", file, abs_path);
  H5Handle fspace = check_id(H5Dget_space(dset.get()), H5Sclose, "H5Dget_space", file, abs_path);
  const int rank = H5Sget_simple_extent_ndims(fspace.get());
  hsize_t dims[2] = {0, 1};
  if (rank < 1 || rank > 2 || H5Sget_simple_extent_dims(fspace.get(), dims, nullptr) < 0)
    detail::throw_h5("H5Sget_simple_extent_dims", file, abs_path);
  if (data.cols != (rank == 1 ? 1 : dims[1]) || row0 + data.rows > dims[0])
    throw std::invalid_argument("dataset '" + abs_path + "': rows [" + std::to_string(row0) + ", " +
                                std::to_string(row0 + data.rows) + ") of " + std::to_string(data.cols) +
                                " columns do not fit its " + std::to_string(dims[0]) + " x " +
                                std::to_string(rank == 1 ? 1 : dims[1]));
  const hsize_t start[2] = {static_cast<hsize_t>(row0), 0}, count[2] = {static_cast<hsize_t>(data.rows), dims[1]};
  check(H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start, nullptr, count, nullptr), "H5Sselect_hyperslab", file,
        abs_path);
  H5Handle mspace = check_id(H5Screate_simple(rank, count, nullptr), H5Sclose, "H5Screate_simple", file, abs_path);
  check(H5Dwrite(dset.get(), detail::mem_type(data.dtype), mspace.get(), fspace.get(), H5P_DEFAULT, data.data),
        "H5Dwrite", file, abs_path);
}

void H5Frames::write_dataset(std::int64_t fid, const std::string& abs_path, const ArrayView& data,
                             bool allow_compress) {
  if (data.size() > 0 && data.data == nullptr)
    throw std::invalid_argument("dataset '" + abs_path + "': null data pointer for " + std::to_string(data.size()) +
                                " elements");
  create_dataset(fid, abs_path, data.dtype, data.rows, data.cols, allow_compress);
  write_rows_of(fid, abs_path, 0, data);
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
    // docs/output.md O17: chunked 65536, shuffle + gzip 1 (the index compresses to almost nothing).
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

void H5Frames::truncate_index(std::string_view abs_path, std::size_t n) {
  if (closed_) throw std::logic_error("H5Frames::truncate_index on closed file '" + file_.string() + "'");
  const std::string path(abs_path);
  auto known = static_refs_.find(path);
  if (known == static_refs_.end() || known->second.rows <= n) return;
  if (known->second.cols != 1 || known->second.dtype != DType::kInt32)
    throw std::invalid_argument("H5Frames::truncate_index: '" + path + "' in '" + file_.string() +
                                "' is not a 1-D int32 index dataset");
  const std::string file = file_.string();
  QuietErrors quiet;
  OpenScope scope(*this);
  {
    H5Handle dset = check_id(H5Dopen2(scope.fid(), path.c_str(), H5P_DEFAULT), H5Dclose, "H5Dopen2", file, path);
    const hsize_t len = n;
    // Fails for a contiguous (non-extendible) dataset: only ensure_index() datasets qualify.
    check(H5Dset_extent(dset.get(), &len), "H5Dset_extent", file, path);
  }
  scope.commit();
  known->second.rows = n;
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

void H5Frames::set_frame_times(std::span<const double> times) {
  if (closed_) throw std::logic_error("H5Frames::set_frame_times on closed file '" + file_.string() + "'");
  if (frame_open_)
    throw std::logic_error("H5Frames::set_frame_times: frame " + frame_path_ + " of '" + file_.string() +
                           "' is open");
  if (times.size() > frame_count_)
    throw std::invalid_argument("H5Frames::set_frame_times: " + std::to_string(times.size()) + " times for " +
                                std::to_string(frame_count_) + " frames of '" + file_.string() + "'");
  for (double t : times)
    if (!std::isfinite(t)) throw std::invalid_argument("H5Frames::set_frame_times: times must be finite");
  if (times.empty()) return;
  QuietErrors quiet;
  OpenScope scope(*this);
  const std::string file = file_.string();
  for (std::size_t i = 0; i < times.size(); ++i)
    with_object(scope.fid(), frame_group(i), file,
                [&](hid_t o, const std::string& obj) { detail::write_attr_f64(o, "time", times[i], file, obj); });
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
  frame_order_.clear();
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
  frame_order_.emplace_back(name);
}

void H5Frames::create(std::string_view name, DType dtype, std::size_t rows, std::size_t cols) {
  if (!frame_open_)
    throw std::logic_error("H5Frames::create('" + std::string(name) + "') outside a frame of '" + file_.string() +
                           "'; call begin_frame() first");
  require_relative_name(name);
  const std::string abs = frame_path_ + "/" + std::string(name);
  QuietErrors quiet;
  create_dataset(fid_, abs, dtype, rows, cols, /*allow_compress=*/true);
  frame_refs_[std::string(name)] = DatasetRef{file_, abs, dtype, rows, cols};
  frame_order_.emplace_back(name);
}

void H5Frames::write_rows(std::string_view name, std::size_t row0, const ArrayView& block) {
  if (!frame_open_)
    throw std::logic_error("H5Frames::write_rows('" + std::string(name) + "') outside a frame of '" + file_.string() +
                           "'; call begin_frame() first");
  const auto it = frame_refs_.find(std::string(name));
  if (it == frame_refs_.end())
    throw std::logic_error("H5Frames::write_rows: dataset '" + std::string(name) + "' of the open frame of '" +
                           file_.string() + "' was not created");
  if (block.dtype != it->second.dtype)
    throw std::invalid_argument("H5Frames::write_rows: dataset '" + std::string(name) + "' holds " +
                                std::string(dtype_name(it->second.dtype)) + ", the block is " +
                                std::string(dtype_name(block.dtype)));
  QuietErrors quiet;
  write_rows_of(fid_, it->second.path, row0, block);
}

void H5Frames::end_frame() {
  if (!frame_open_)
    throw std::logic_error("H5Frames::end_frame without an open frame in '" + file_.string() + "'");
  frame_open_ = false;
  QuietErrors quiet;
  try {
    if (!frame_order_.empty()) {
      H5Handle g = check_id(H5Gopen2(fid_, frame_path_.c_str(), H5P_DEFAULT), H5Gclose, "H5Gopen2", file_.string(),
                            frame_path_);
      write_attr_strings(g.get(), "datasets", frame_order_, file_.string(), frame_path_);
    }
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
    // Also "<name>_unit" on /history: the form a plain h5py script reads (docs/output.md O8).
    detail::write_attr_string(group.get(), c.name + "_unit", c.unit, file, "/history");
  }
  std::vector<std::string> names;
  for (const auto& c : columns) names.push_back(c.name);
  write_attr_strings(group.get(), "columns", names, file, "/history");
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

std::vector<FrameRecord> H5Frames::read_frames() {
  if (closed_) throw std::logic_error("H5Frames::read_frames on closed file '" + file_.string() + "'");
  if (frame_open_)
    throw std::logic_error("H5Frames::read_frames: frame " + frame_path_ + " of '" + file_.string() +
                           "' is still open; call end_frame() first");
  std::vector<FrameRecord> out;
  out.reserve(frame_count_);
  QuietErrors quiet;
  OpenScope scope(*this);
  for (std::size_t i = 0; i < frame_count_; ++i) out.push_back(read_frame_record(scope.fid(), file_, i));
  scope.commit();
  return out;
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
