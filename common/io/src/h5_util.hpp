// Internal HDF5 helpers: owned handles, error reporting, quiet creation plists.
// Not installed; include only from common/io/src.
#pragma once

#include <hdf5.h>

#include <string>
#include <string_view>

#include "demfdm/io/array_view.hpp"

namespace demfdm::io::detail {

/// Owns one HDF5 identifier and closes it with the matching H5?close.
class H5Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  H5Handle() = default;
  H5Handle(hid_t id, Closer closer) noexcept : id_(id), closer_(closer) {}
  H5Handle(H5Handle&& o) noexcept : id_(o.id_), closer_(o.closer_) { o.id_ = H5I_INVALID_HID; }
  H5Handle& operator=(H5Handle&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      closer_ = o.closer_;
      o.id_ = H5I_INVALID_HID;
    }
    return *this;
  }
  H5Handle(const H5Handle&) = delete;
  H5Handle& operator=(const H5Handle&) = delete;
  ~H5Handle() { reset(); }
  void reset() noexcept {
    if (id_ >= 0 && closer_ != nullptr) closer_(id_);
    id_ = H5I_INVALID_HID;
  }
  hid_t get() const noexcept { return id_; }

 private:
  hid_t id_ = H5I_INVALID_HID;
  Closer closer_ = nullptr;
};

/// Switches HDF5's automatic error-stack printing off for its lifetime (docs/output.md O13):
/// we report one clear IoError instead of HDF5's multi-line dump on stderr.
class QuietErrors {
 public:
  QuietErrors() noexcept;
  ~QuietErrors();
  QuietErrors(const QuietErrors&) = delete;
  QuietErrors& operator=(const QuietErrors&) = delete;

 private:
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
};

/// Throws IoError: "<call> failed for '<file>'[ object '<object>'][: <what>] (HDF5: <stack>)".
/// Must be called right after the failing call, before another HDF5 call clears the stack.
[[noreturn]] void throw_h5(std::string_view call, const std::string& file, std::string_view object,
                           std::string_view what = {});

/// Checks an identifier-returning call; wraps it into an owning handle.
H5Handle check_id(hid_t id, H5Handle::Closer closer, std::string_view call, const std::string& file,
                  std::string_view object);
/// Checks a status-returning call.
void check(herr_t status, std::string_view call, const std::string& file, std::string_view object);

/// File (little-endian) and memory (native) type of `t`.
hid_t file_type(DType t) noexcept;
hid_t mem_type(DType t) noexcept;

/// File access plist: libver EARLIEST..V18 (readable by HDF5 >= 1.8), strong close.
H5Handle make_fapl(const std::string& file);
/// Group / dataset creation plists with object time tracking off (bit-identical files).
H5Handle make_gcpl(const std::string& file);
H5Handle make_dcpl(const std::string& file);

/// Opens the group at absolute `path` (e.g. "/frames/000001/particles"), creating each
/// missing component with the quiet gcpl. (H5Pset_create_intermediate_group would create
/// the parents with default, time-stamped plists; docs/output.md O11.)
H5Handle require_group(hid_t fid, std::string_view path, const std::string& file);

/// True when a link `path` exists (all parents must exist or the answer is false).
bool link_exists(hid_t fid, std::string_view path);

/// Scalar attribute writers; an existing attribute of that name is deleted first.
void write_attr_string(hid_t obj, std::string_view name, std::string_view value,
                       const std::string& file, std::string_view object);
void write_attr_i64(hid_t obj, std::string_view name, std::int64_t value, const std::string& file,
                    std::string_view object);
void write_attr_f64(hid_t obj, std::string_view name, double value, const std::string& file,
                    std::string_view object);

/// Splits "/a/b/c" into parent "/a/b" and leaf "c". Throws std::invalid_argument on an
/// empty, relative or "."/".." containing path.
std::pair<std::string, std::string> split_abs_path(std::string_view path);

}  // namespace demfdm::io::detail
