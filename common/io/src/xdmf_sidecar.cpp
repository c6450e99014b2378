// XdmfSidecar: emits the sidecars of docs/output.md O18-O26.
#include "demfdm/io/xdmf_sidecar.hpp"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <stdexcept>
#include <utility>

#include "demfdm/io/error.hpp"

namespace demfdm::io {

namespace {

std::string escape_xml(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default: out += c;
    }
  }
  return out;
}

// 17 significant digits, like printf("%.17g") but independent of the C locale.
std::string time_text(double t) {
  char buf[64];
  auto res = std::to_chars(buf, buf + sizeof buf, t, std::chars_format::general, 17);
  return std::string(buf, res.ptr);
}

const char* number_type(DType t) {
  switch (t) {
    case DType::kFloat64:
    case DType::kFloat32: return "Float";
    case DType::kInt32:
    case DType::kInt64: return "Int";
    case DType::kUInt8: return "UChar";
  }
  return "?";
}

std::string dims_text(std::size_t rows, std::size_t cols) {
  return cols == 1 ? std::to_string(rows) : std::to_string(rows) + " " + std::to_string(cols);
}

bool is_int(DType t) { return t == DType::kInt32 || t == DType::kInt64; }
bool is_float(DType t) { return t == DType::kFloat64 || t == DType::kFloat32; }

const char* topology_name(XdmfTopology t) {
  switch (t) {
    case XdmfTopology::kPolyvertex: return "Polyvertex";
    case XdmfTopology::kPolyline: return "Polyline";
    case XdmfTopology::kTriangle: return "Triangle";
    case XdmfTopology::kHexahedron: return "Hexahedron";
  }
  return "?";
}

const char* attribute_type_name(XdmfAttributeType t) {
  switch (t) {
    case XdmfAttributeType::kScalar: return "Scalar";
    case XdmfAttributeType::kVector: return "Vector";
    case XdmfAttributeType::kMatrix: return "Matrix";
  }
  return "?";
}

}  // namespace

XdmfAttributeType attribute_type_for(std::size_t cols) noexcept {
  if (cols == 1) return XdmfAttributeType::kScalar;
  if (cols == 3) return XdmfAttributeType::kVector;
  return XdmfAttributeType::kMatrix;
}

XdmfAttribute XdmfAttribute::node(std::string name, DatasetRef data) {
  const auto type = attribute_type_for(data.cols);
  return XdmfAttribute{std::move(name), XdmfCenter::kNode, type, std::move(data)};
}

XdmfAttribute XdmfAttribute::cell(std::string name, DatasetRef data) {
  const auto type = attribute_type_for(data.cols);
  return XdmfAttribute{std::move(name), XdmfCenter::kCell, type, std::move(data)};
}

XdmfSidecar::XdmfSidecar(std::filesystem::path xmf_path, std::string grid_name)
    : path_(std::filesystem::absolute(xmf_path).lexically_normal()),
      dir_(path_.parent_path()),
      name_(std::move(grid_name)) {
  if (name_.empty()) throw std::invalid_argument("XdmfSidecar: grid name must be non-empty");
  if (!path_.has_filename()) throw std::invalid_argument("XdmfSidecar: '" + xmf_path.string() + "' names no file");
}

void XdmfSidecar::append(XdmfGrid g) {
  const std::string where = "XdmfSidecar '" + path_.string() + "' frame " + std::to_string(grids_.size()) + ": ";
  auto fail = [&](const std::string& what) { throw std::invalid_argument(where + what); };
  if (!std::isfinite(g.time)) fail("time must be finite, found " + time_text(g.time));
  if (!grids_.empty() && !(g.time > grids_.back().time))
    fail("frame times must increase strictly, found " + time_text(g.time) + " after " +
         time_text(grids_.back().time));
  if (g.geometry.cols != 3 || !is_float(g.geometry.dtype))
    fail("geometry '" + g.geometry.path + "' must be [points, 3] float64 or float32, found " +
         dims_text(g.geometry.rows, g.geometry.cols) + " " + std::string(dtype_name(g.geometry.dtype)));
  const DatasetRef& c = g.connectivity;
  if (!is_int(c.dtype)) fail("connectivity '" + c.path + "' must be int32 or int64");
  switch (g.topology) {
    case XdmfTopology::kPolyvertex:
      if (c.cols != 1 || c.rows < g.elements)
        fail("the Polyvertex index '" + c.path + "' must be 1-D with at least " + std::to_string(g.elements) +
             " entries, found " + dims_text(c.rows, c.cols));
      if (g.geometry.rows != g.elements)
        fail("Polyvertex needs one element per point: " + std::to_string(g.elements) + " elements, " +
             std::to_string(g.geometry.rows) + " points");
      break;
    case XdmfTopology::kPolyline:
      if (c.cols != 2 || c.rows != g.elements)
        fail("Polyline connectivity '" + c.path + "' must be [" + std::to_string(g.elements) + ", 2], found " +
             dims_text(c.rows, c.cols));
      break;
    case XdmfTopology::kTriangle:
      if (c.cols != 3 || c.rows != g.elements)
        fail("Triangle connectivity '" + c.path + "' must be [" + std::to_string(g.elements) + ", 3], found " +
             dims_text(c.rows, c.cols));
      break;
    case XdmfTopology::kHexahedron:
      if (c.cols != 8 || c.rows != g.elements)
        fail("Hexahedron connectivity '" + c.path + "' must be [" + std::to_string(g.elements) + ", 8], found " +
             dims_text(c.rows, c.cols));
      break;
  }
  for (const auto& a : g.attributes) {
    if (a.name.empty()) fail("attribute names must be non-empty");
    const std::size_t want = a.center == XdmfCenter::kNode ? g.geometry.rows : g.elements;
    if (a.data.rows != want)
      fail("attribute '" + a.name + "' has " + std::to_string(a.data.rows) + " rows, expected " +
           std::to_string(want) + (a.center == XdmfCenter::kNode ? " (one per point)" : " (one per cell)"));
    if ((a.type == XdmfAttributeType::kScalar && a.data.cols != 1) ||
        (a.type == XdmfAttributeType::kVector && a.data.cols != 3))
      fail("attribute '" + a.name + "' declared " + attribute_type_name(a.type) + " has " +
           std::to_string(a.data.cols) + " columns");
  }
  grids_.push_back(std::move(g));
}

std::string XdmfSidecar::xml() const {
  // The Polyvertex index dataset only grows; every frame must state its current length.
  std::map<std::pair<std::string, std::string>, std::size_t> index_len;
  for (const auto& g : grids_)
    if (g.topology == XdmfTopology::kPolyvertex) {
      auto& n = index_len[{g.connectivity.file.string(), g.connectivity.path}];
      n = std::max(n, g.connectivity.rows);
    }

  auto h5_name = [&](const DatasetRef& r) {
    std::filesystem::path rel = r.file.lexically_relative(dir_);
    const std::string f = rel.empty() ? r.file.generic_string() : rel.generic_string();
    return escape_xml(f + ":" + r.path);
  };
  auto data_item = [&](const DatasetRef& r, std::size_t rows, const std::string& indent) {
    return indent + "<DataItem Dimensions=\"" + dims_text(rows, r.cols) + "\" NumberType=\"" + number_type(r.dtype) +
           "\" Precision=\"" + std::to_string(dtype_size(r.dtype)) + "\" Format=\"HDF\">" + h5_name(r) +
           "</DataItem>\n";
  };

  const std::string name = escape_xml(name_);
  std::string x;
  x.reserve(1024 + grids_.size() * 1536);
  x += "<?xml version=\"1.0\" ?>\n<Xdmf Version=\"3.0\">\n  <Domain>\n";
  x += "    <Grid Name=\"" + name + "\" GridType=\"Collection\" CollectionType=\"Temporal\">\n";
  for (const auto& g : grids_) {
    const std::string in = "        ";
    x += "      <Grid Name=\"" + name + "\" GridType=\"Uniform\">\n";
    x += in + "<Time Value=\"" + time_text(g.time) + "\"/>\n";
    const std::string n = std::to_string(g.elements);
    x += in + "<Topology TopologyType=\"" + topology_name(g.topology) + "\" NumberOfElements=\"" + n + "\"";
    if (g.topology == XdmfTopology::kPolyvertex) {
      const DatasetRef& c = g.connectivity;
      const std::size_t len = index_len[{c.file.string(), c.path}];
      x += " NodesPerElement=\"1\">\n";
      x += in + "  <DataItem ItemType=\"HyperSlab\" Dimensions=\"" + n + "\" NumberType=\"" + number_type(c.dtype) +
           "\" Precision=\"" + std::to_string(dtype_size(c.dtype)) + "\">\n";
      // start, stride, count: the first N entries of 0..Nmax-1.
      x += in + "    <DataItem Dimensions=\"3 1\" Format=\"XML\">0 1 " + n + "</DataItem>\n";
      x += data_item(c, len, in + "    ");
      x += in + "  </DataItem>\n";
    } else {
      if (g.topology == XdmfTopology::kPolyline) x += " NodesPerElement=\"2\"";
      x += ">\n";
      x += data_item(g.connectivity, g.connectivity.rows, in + "  ");
    }
    x += in + "</Topology>\n";
    x += in + "<Geometry GeometryType=\"XYZ\">\n";
    x += data_item(g.geometry, g.geometry.rows, in + "  ");
    x += in + "</Geometry>\n";
    for (const auto& a : g.attributes) {
      x += in + "<Attribute Name=\"" + escape_xml(a.name) + "\" AttributeType=\"" + attribute_type_name(a.type) +
           "\" Center=\"" + (a.center == XdmfCenter::kNode ? "Node" : "Cell") + "\">\n";
      x += data_item(a.data, a.data.rows, in + "  ");
      x += in + "</Attribute>\n";
    }
    x += "      </Grid>\n";
  }
  x += "    </Grid>\n  </Domain>\n</Xdmf>\n";
  return x;
}

void XdmfSidecar::write() const {
  const std::string text = xml();
  const std::string target = path_.string();
  const std::string tmp = target + ".tmp";
  auto fail = [&](const char* call, const std::string& file) {
    const int err = errno;
    throw IoError(std::string(call) + " failed for '" + file + "': " + std::strerror(err));
  };
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (f == nullptr) fail("fopen", tmp);
  const std::size_t n = std::fwrite(text.data(), 1, text.size(), f);
  if (n != text.size()) {
    const int err = errno;
    std::fclose(f);
    std::remove(tmp.c_str());
    errno = err;
    fail("fwrite", tmp);
  }
  if (std::fclose(f) != 0) {
    const int err = errno;
    std::remove(tmp.c_str());
    errno = err;
    fail("fclose", tmp);
  }
  // rename() replaces the target atomically on POSIX: readers see the old or the new file.
  if (std::rename(tmp.c_str(), target.c_str()) != 0) {
    const int err = errno;
    std::remove(tmp.c_str());
    errno = err;
    fail("rename", tmp + "' -> '" + target);
  }
}

}  // namespace demfdm::io
