#include "h5_util.hpp"

#include <stdexcept>
#include <string>

#include "demfdm/io/error.hpp"

namespace demfdm::io {

std::size_t dtype_size(DType t) noexcept {
  switch (t) {
    case DType::kFloat64: return 8;
    case DType::kFloat32: return 4;
    case DType::kInt32: return 4;
    case DType::kInt64: return 8;
    case DType::kUInt8: return 1;
  }
  return 0;
}

std::string_view dtype_name(DType t) noexcept {
  switch (t) {
    case DType::kFloat64: return "float64";
    case DType::kFloat32: return "float32";
    case DType::kInt32: return "int32";
    case DType::kInt64: return "int64";
    case DType::kUInt8: return "uint8";
  }
  return "?";
}

namespace detail {

QuietErrors::QuietErrors() noexcept {
  H5Eget_auto2(H5E_DEFAULT, &func_, &data_);
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
}
QuietErrors::~QuietErrors() { H5Eset_auto2(H5E_DEFAULT, func_, data_); }

namespace {

// Collects "function: description" of each entry of the default error stack, innermost
// last, so the message shows both what the API call said and why the library refused.
herr_t collect_error(unsigned n, const H5E_error2_t* err, void* client) {
  auto* out = static_cast<std::string*>(client);
  if (n >= 4) return 0;  // the outer frames repeat the same story
  if (!out->empty()) out->append("; ");
  out->append(err->func_name != nullptr ? err->func_name : "?");
  out->append(": ");
  // Some descriptions embed a ctime() stamp with its newline: keep the message on one line.
  std::string desc = err->desc != nullptr ? err->desc : "?";
  for (char& c : desc)
    if (c == '\n') c = ' ';
  out->append(desc);
  return 0;
}

}  // namespace

void throw_h5(std::string_view call, const std::string& file, std::string_view object,
              std::string_view what) {
  std::string stack;
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, collect_error, &stack);
  H5Eclear2(H5E_DEFAULT);
  std::string msg = std::string(call) + " failed for '" + file + "'";
  if (!object.empty()) msg += " object '" + std::string(object) + "'";
  if (!what.empty()) msg += ": " + std::string(what);
  if (!stack.empty()) msg += " (HDF5: " + stack + ")";
  throw IoError(msg);
}

H5Handle check_id(hid_t id, H5Handle::Closer closer, std::string_view call, const std::string& file,
                  std::string_view object) {
  if (id < 0) throw_h5(call, file, object);
  return H5Handle(id, closer);
}

void check(herr_t status, std::string_view call, const std::string& file, std::string_view object) {
  if (status < 0) throw_h5(call, file, object);
}

hid_t file_type(DType t) noexcept {
  switch (t) {
    case DType::kFloat64: return H5T_IEEE_F64LE;
    case DType::kFloat32: return H5T_IEEE_F32LE;
    case DType::kInt32: return H5T_STD_I32LE;
    case DType::kInt64: return H5T_STD_I64LE;
    case DType::kUInt8: return H5T_STD_U8LE;
  }
  return H5I_INVALID_HID;
}

hid_t mem_type(DType t) noexcept {
  switch (t) {
    case DType::kFloat64: return H5T_NATIVE_DOUBLE;
    case DType::kFloat32: return H5T_NATIVE_FLOAT;
    case DType::kInt32: return H5T_NATIVE_INT32;
    case DType::kInt64: return H5T_NATIVE_INT64;
    case DType::kUInt8: return H5T_NATIVE_UINT8;
  }
  return H5I_INVALID_HID;
}

H5Handle make_fapl(const std::string& file) {
  H5Handle fapl = check_id(H5Pcreate(H5P_FILE_ACCESS), H5Pclose, "H5Pcreate(H5P_FILE_ACCESS)", file, "");
  check(H5Pset_libver_bounds(fapl.get(), H5F_LIBVER_EARLIEST, H5F_LIBVER_V18), "H5Pset_libver_bounds",
        file, "");
  // Strong close: H5Fclose really closes the file even if an identifier leaked, so the
  // lock is released between frames whatever happened (docs/output.md O12).
  check(H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG), "H5Pset_fclose_degree", file, "");
  return fapl;
}

H5Handle make_gcpl(const std::string& file) {
  H5Handle p = check_id(H5Pcreate(H5P_GROUP_CREATE), H5Pclose, "H5Pcreate(H5P_GROUP_CREATE)", file, "");
  check(H5Pset_obj_track_times(p.get(), 0), "H5Pset_obj_track_times", file, "");
  return p;
}

H5Handle make_dcpl(const std::string& file) {
  H5Handle p = check_id(H5Pcreate(H5P_DATASET_CREATE), H5Pclose, "H5Pcreate(H5P_DATASET_CREATE)", file, "");
  check(H5Pset_obj_track_times(p.get(), 0), "H5Pset_obj_track_times", file, "");
  return p;
}

bool link_exists(hid_t fid, std::string_view path) {
  if (path == "/") return true;
  // H5Lexists fails (negative) when an intermediate group is missing: walk down.
  std::string partial;
  std::size_t pos = 1;
  while (pos <= path.size()) {
    std::size_t next = path.find('/', pos);
    if (next == std::string_view::npos) next = path.size();
    partial = std::string(path.substr(0, next));
    if (H5Lexists(fid, partial.c_str(), H5P_DEFAULT) <= 0) return false;
    pos = next + 1;
  }
  return true;
}

H5Handle require_group(hid_t fid, std::string_view path, const std::string& file) {
  if (path.empty() || path.front() != '/')
    throw std::invalid_argument("HDF5 group path must be absolute, found '" + std::string(path) + "'");
  H5Handle gcpl = make_gcpl(file);
  H5Handle current = check_id(H5Gopen2(fid, "/", H5P_DEFAULT), H5Gclose, "H5Gopen2", file, "/");
  std::size_t pos = 1;
  while (pos < path.size()) {
    std::size_t next = path.find('/', pos);
    if (next == std::string_view::npos) next = path.size();
    const std::string comp(path.substr(pos, next - pos));
    const std::string sofar(path.substr(0, next));
    if (!comp.empty()) {
      const htri_t exists = H5Lexists(current.get(), comp.c_str(), H5P_DEFAULT);
      if (exists < 0) throw_h5("H5Lexists", file, sofar);
      if (exists > 0) {
        current = check_id(H5Gopen2(current.get(), comp.c_str(), H5P_DEFAULT), H5Gclose, "H5Gopen2", file,
                           sofar);
      } else {
        current = check_id(H5Gcreate2(current.get(), comp.c_str(), H5P_DEFAULT, gcpl.get(), H5P_DEFAULT),
                           H5Gclose, "H5Gcreate2", file, sofar);
      }
    }
    pos = next + 1;
  }
  return current;
}

namespace {

void delete_attr_if_present(hid_t obj, const std::string& name, const std::string& file,
                            std::string_view object) {
  const htri_t e = H5Aexists(obj, name.c_str());
  if (e < 0) throw_h5("H5Aexists", file, object, name);
  if (e > 0) check(H5Adelete(obj, name.c_str()), "H5Adelete", file, object);
}

void write_scalar_attr(hid_t obj, std::string_view name, hid_t ftype, hid_t mtype, const void* value,
                       const std::string& file, std::string_view object) {
  const std::string n(name);
  delete_attr_if_present(obj, n, file, object);
  H5Handle space = check_id(H5Screate(H5S_SCALAR), H5Sclose, "H5Screate", file, object);
  H5Handle attr = check_id(H5Acreate2(obj, n.c_str(), ftype, space.get(), H5P_DEFAULT, H5P_DEFAULT),
                           H5Aclose, "H5Acreate2", file, std::string(object) + "@" + n);
  check(H5Awrite(attr.get(), mtype, value), "H5Awrite", file, std::string(object) + "@" + n);
}

}  // namespace

void write_attr_string(hid_t obj, std::string_view name, std::string_view value, const std::string& file,
                       std::string_view object) {
  // Fixed-length ASCII, null-padded (docs/output.md O5); h5py returns it as bytes. HDF5 refuses a
  // zero-size string type, so an empty value is stored as one NUL byte.
  H5Handle type = check_id(H5Tcopy(H5T_C_S1), H5Tclose, "H5Tcopy", file, object);
  const std::size_t len = value.empty() ? 1 : value.size();
  check(H5Tset_size(type.get(), len), "H5Tset_size", file, object);
  check(H5Tset_strpad(type.get(), H5T_STR_NULLPAD), "H5Tset_strpad", file, object);
  check(H5Tset_cset(type.get(), H5T_CSET_ASCII), "H5Tset_cset", file, object);
  std::string buf(value);
  buf.resize(len, '\0');
  write_scalar_attr(obj, name, type.get(), type.get(), buf.data(), file, object);
}

void write_attr_i64(hid_t obj, std::string_view name, std::int64_t value, const std::string& file,
                    std::string_view object) {
  write_scalar_attr(obj, name, H5T_STD_I64LE, H5T_NATIVE_INT64, &value, file, object);
}

void write_attr_f64(hid_t obj, std::string_view name, double value, const std::string& file,
                    std::string_view object) {
  write_scalar_attr(obj, name, H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &value, file, object);
}

std::pair<std::string, std::string> split_abs_path(std::string_view path) {
  if (path.size() < 2 || path.front() != '/' || path.back() == '/')
    throw std::invalid_argument("HDF5 dataset path must be absolute and name a dataset (\"/a/b\"), found '" +
                                std::string(path) + "'");
  std::size_t pos = 1;
  while (pos <= path.size()) {
    std::size_t next = path.find('/', pos);
    if (next == std::string_view::npos) next = path.size();
    const std::string_view comp = path.substr(pos, next - pos);
    if (comp.empty() || comp == "." || comp == "..")
      throw std::invalid_argument("HDF5 path components must be non-empty names other than '.' and '..', found '" +
                                  std::string(path) + "'");
    pos = next + 1;
  }
  const std::size_t slash = path.rfind('/');
  std::string parent = slash == 0 ? std::string("/") : std::string(path.substr(0, slash));
  return {parent, std::string(path.substr(slash + 1))};
}

}  // namespace detail
}  // namespace demfdm::io
