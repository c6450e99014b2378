// Helpers shared by the io tests: scratch folders and HDF5 read-back through the C API
// (independent of the writer code under test).
#pragma once

#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace demfdm::io::test {

/// A fresh, empty folder per test, removed afterwards.
class ScratchDir {
 public:
  ScratchDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string("demfdm_io_") + info->test_suite_name() + "_" + info->name() + "_" +
                       std::to_string(::getpid());
    for (char& c : name)
      if (c == '/') c = '_';
    path_ = std::filesystem::temp_directory_path() / name;
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& f) const { return path_ / f; }

 private:
  std::filesystem::path path_;
};

inline std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

/// Read-only file handle for checks.
class H5Reader {
 public:
  explicit H5Reader(const std::filesystem::path& p) {
    fid_ = H5Fopen(p.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (fid_ < 0) throw std::runtime_error("test: cannot open " + p.string());
  }
  ~H5Reader() {
    if (fid_ >= 0) H5Fclose(fid_);
  }
  H5Reader(const H5Reader&) = delete;
  H5Reader& operator=(const H5Reader&) = delete;
  hid_t id() const { return fid_; }

  bool exists(const std::string& path) const {
    // Walk component by component: H5Lexists fails on a missing parent.
    std::size_t pos = 1;
    while (pos <= path.size()) {
      std::size_t next = path.find('/', pos);
      if (next == std::string::npos) next = path.size();
      if (H5Lexists(fid_, path.substr(0, next).c_str(), H5P_DEFAULT) <= 0) return false;
      pos = next + 1;
    }
    return true;
  }

  std::vector<hsize_t> dims(const std::string& path) const {
    hid_t d = H5Dopen2(fid_, path.c_str(), H5P_DEFAULT);
    if (d < 0) throw std::runtime_error("test: no dataset " + path);
    hid_t s = H5Dget_space(d);
    const int rank = H5Sget_simple_extent_ndims(s);
    std::vector<hsize_t> out(static_cast<std::size_t>(rank));
    H5Sget_simple_extent_dims(s, out.data(), nullptr);
    H5Sclose(s);
    H5Dclose(d);
    return out;
  }

  /// H5T class and size of a dataset's file type, and whether it is little-endian.
  void file_type(const std::string& path, H5T_class_t& cls, std::size_t& size, bool& little) const {
    hid_t d = H5Dopen2(fid_, path.c_str(), H5P_DEFAULT);
    hid_t t = H5Dget_type(d);
    cls = H5Tget_class(t);
    size = H5Tget_size(t);
    little = H5Tget_order(t) == H5T_ORDER_LE || size == 1;
    H5Tclose(t);
    H5Dclose(d);
  }

  template <class T>
  std::vector<T> read(const std::string& path, hid_t mem_type) const {
    hid_t d = H5Dopen2(fid_, path.c_str(), H5P_DEFAULT);
    if (d < 0) throw std::runtime_error("test: no dataset " + path);
    hid_t s = H5Dget_space(d);
    const hssize_t n = H5Sget_simple_extent_npoints(s);
    std::vector<T> out(static_cast<std::size_t>(n));
    if (n > 0 && H5Dread(d, mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data()) < 0)
      throw std::runtime_error("test: H5Dread " + path);
    H5Sclose(s);
    H5Dclose(d);
    return out;
  }
  std::vector<double> read_f64(const std::string& p) const { return read<double>(p, H5T_NATIVE_DOUBLE); }
  std::vector<float> read_f32(const std::string& p) const { return read<float>(p, H5T_NATIVE_FLOAT); }
  std::vector<std::int32_t> read_i32(const std::string& p) const { return read<std::int32_t>(p, H5T_NATIVE_INT32); }
  std::vector<std::int64_t> read_i64(const std::string& p) const { return read<std::int64_t>(p, H5T_NATIVE_INT64); }
  std::vector<std::uint8_t> read_u8(const std::string& p) const { return read<std::uint8_t>(p, H5T_NATIVE_UINT8); }

  double attr_f64(const std::string& obj, const std::string& name) const {
    double v = 0;
    hid_t a = H5Aopen_by_name(fid_, obj.c_str(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0) throw std::runtime_error("test: no attribute " + obj + "@" + name);
    H5Aread(a, H5T_NATIVE_DOUBLE, &v);
    H5Aclose(a);
    return v;
  }
  std::int64_t attr_i64(const std::string& obj, const std::string& name) const {
    std::int64_t v = 0;
    hid_t a = H5Aopen_by_name(fid_, obj.c_str(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0) throw std::runtime_error("test: no attribute " + obj + "@" + name);
    H5Aread(a, H5T_NATIVE_INT64, &v);
    H5Aclose(a);
    return v;
  }
  /// Fixed-length string attribute; also reports whether it is null-padded ASCII.
  std::string attr_str(const std::string& obj, const std::string& name, bool* nullpad_ascii = nullptr) const {
    hid_t a = H5Aopen_by_name(fid_, obj.c_str(), name.c_str(), H5P_DEFAULT, H5P_DEFAULT);
    if (a < 0) throw std::runtime_error("test: no attribute " + obj + "@" + name);
    hid_t t = H5Aget_type(a);
    const std::size_t n = H5Tget_size(t);
    if (nullpad_ascii != nullptr)
      *nullpad_ascii = H5Tget_class(t) == H5T_STRING && !H5Tis_variable_str(t) &&
                       H5Tget_strpad(t) == H5T_STR_NULLPAD && H5Tget_cset(t) == H5T_CSET_ASCII;
    std::string v(n, '\0');
    H5Aread(a, t, v.data());
    H5Tclose(t);
    H5Aclose(a);
    v.resize(v.find('\0') == std::string::npos ? v.size() : v.find('\0'));
    return v;
  }

 private:
  hid_t fid_ = -1;
};

/// Minimal XML well-formedness check: balanced, properly nested tags (ignoring the
/// declaration and comments), quoted attribute values. Returns "" when well-formed, else
/// a description of the first problem.
inline std::string xml_problem(const std::string& x) {
  std::vector<std::string> stack;
  std::size_t i = 0;
  while ((i = x.find('<', i)) != std::string::npos) {
    if (x.compare(i, 2, "<?") == 0) {
      i = x.find("?>", i);
      if (i == std::string::npos) return "unterminated declaration";
      continue;
    }
    if (x.compare(i, 4, "<!--") == 0) {
      i = x.find("-->", i);
      if (i == std::string::npos) return "unterminated comment";
      continue;
    }
    const std::size_t end = x.find('>', i);
    if (end == std::string::npos) return "unterminated tag at " + std::to_string(i);
    std::string tag = x.substr(i + 1, end - i - 1);
    if (std::count(tag.begin(), tag.end(), '"') % 2 != 0) return "unbalanced quotes in <" + tag + ">";
    if (!tag.empty() && tag[0] == '/') {
      const std::string name = tag.substr(1);
      if (stack.empty() || stack.back() != name) return "closing </" + name + "> does not match";
      stack.pop_back();
    } else if (!tag.empty() && tag.back() == '/') {
      // self-closing
    } else {
      stack.push_back(tag.substr(0, tag.find_first_of(" \t\n")));
    }
    i = end + 1;
  }
  if (!stack.empty()) return "unclosed <" + stack.back() + ">";
  return "";
}

/// One dataset or attribute as stored: its file type, shape and raw bytes.
struct StoredArray {
  std::string type;  // class, size, sign and byte order of the file type
  std::vector<hsize_t> dims;
  std::string bytes;  // the elements in the file type, as read back
  bool operator==(const StoredArray&) const = default;
};

inline std::string type_text(hid_t t) {
  std::string s = std::to_string(static_cast<int>(H5Tget_class(t))) + ":" + std::to_string(H5Tget_size(t));
  if (H5Tget_class(t) == H5T_INTEGER) s += H5Tget_sign(t) == H5T_SGN_2 ? ":signed" : ":unsigned";
  if (H5Tget_class(t) == H5T_INTEGER || H5Tget_class(t) == H5T_FLOAT)
    s += H5Tget_order(t) == H5T_ORDER_LE ? ":LE" : ":BE";
  return s;
}

/// Every dataset ("/path") and every attribute ("/path@name") of every object below one
/// of `roots` (e.g. "/frames"), as stored; for comparing two files content by content
/// (their bytes may differ: free space, object addresses).
inline std::map<std::string, StoredArray> stored_contents(const std::filesystem::path& file,
                                                          const std::vector<std::string>& roots) {
  H5Reader r(file);
  std::vector<std::string> names;
  auto visit = [](hid_t, const char* name, const H5L_info_t*, void* data) -> herr_t {
    static_cast<std::vector<std::string>*>(data)->push_back(std::string("/") + name);
    return 0;
  };
  if (H5Lvisit(r.id(), H5_INDEX_NAME, H5_ITER_INC, visit, &names) < 0) throw std::runtime_error("test: H5Lvisit");
  std::map<std::string, StoredArray> out;
  for (const auto& n : names) {
    const bool wanted = std::any_of(roots.begin(), roots.end(), [&](const std::string& root) {
      return n == root || n.rfind(root + "/", 0) == 0;
    });
    if (!wanted) continue;
    hid_t o = H5Oopen(r.id(), n.c_str(), H5P_DEFAULT);
    if (H5Iget_type(o) == H5I_DATASET) {
      StoredArray a;
      hid_t t = H5Dget_type(o), sp = H5Dget_space(o);
      a.type = type_text(t);
      a.dims.resize(static_cast<std::size_t>(H5Sget_simple_extent_ndims(sp)));
      H5Sget_simple_extent_dims(sp, a.dims.data(), nullptr);
      a.bytes.resize(static_cast<std::size_t>(H5Sget_simple_extent_npoints(sp)) * H5Tget_size(t));
      if (!a.bytes.empty()) H5Dread(o, t, H5S_ALL, H5S_ALL, H5P_DEFAULT, a.bytes.data());
      H5Sclose(sp);
      H5Tclose(t);
      out[n] = a;
    }
    std::vector<std::string> attrs;
    auto attr_name = [](hid_t, const char* name, const H5A_info_t*, void* data) -> herr_t {
      static_cast<std::vector<std::string>*>(data)->emplace_back(name);
      return 0;
    };
    H5Aiterate2(o, H5_INDEX_NAME, H5_ITER_INC, nullptr, attr_name, &attrs);
    for (const auto& an : attrs) {
      StoredArray a;
      hid_t at = H5Aopen(o, an.c_str(), H5P_DEFAULT);
      hid_t t = H5Aget_type(at), sp = H5Aget_space(at);
      a.type = type_text(t);
      a.dims.resize(static_cast<std::size_t>(H5Sget_simple_extent_ndims(sp)));
      H5Sget_simple_extent_dims(sp, a.dims.data(), nullptr);
      a.bytes.resize(static_cast<std::size_t>(H5Sget_simple_extent_npoints(sp)) * H5Tget_size(t));
      if (!a.bytes.empty()) H5Aread(at, t, a.bytes.data());
      H5Sclose(sp);
      H5Tclose(t);
      H5Aclose(at);
      out[n + "@" + an] = a;
    }
    H5Oclose(o);
  }
  return out;
}

/// Names of the entries that differ between two stored_contents() maps (empty when equal).
inline std::string contents_diff(const std::map<std::string, StoredArray>& a,
                                 const std::map<std::string, StoredArray>& b) {
  std::string d;
  for (const auto& [k, v] : a) {
    auto it = b.find(k);
    if (it == b.end()) d += " missing:" + k;
    else if (!(it->second == v)) d += " differs:" + k;
  }
  for (const auto& [k, v] : b)
    if (!a.count(k)) d += " extra:" + k;
  return d;
}

inline std::size_t count_substr(const std::string& s, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t p = s.find(what); p != std::string::npos; p = s.find(what, p + what.size())) ++n;
  return n;
}

}  // namespace demfdm::io::test
