// ParticleOutput and MeshOutput: the results layout of common/io/README.md on top of
// H5Frames and XdmfSidecar.
#include "demfdm/io/results_output.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <stdexcept>
#include <system_error>

#include "demfdm/io/error.hpp"

namespace demfdm::io {

namespace {

constexpr const char* kVertexIndex = "/xdmf/vertex_index";

void check_name(const std::string& what, const std::string& name) {
  if (name.empty() || name.find('/') != std::string::npos || name == "." || name == "..")
    throw std::invalid_argument(what + " name must be a plain non-empty name without '/', found '" + name + "'");
}

// Refuses to start when any target exists: an earlier run's results are never overwritten
// (the HDF5 create is exclusive anyway; this also protects the sidecars and fails before
// anything is written).
void refuse_existing(const std::vector<std::filesystem::path>& files) {
  for (const auto& f : files) {
    std::error_code ec;
    if (std::filesystem::exists(f, ec))
      throw IoError("refusing to overwrite '" + f.string() +
                    "' (exists): results are never overwritten, choose a new run folder or remove the old files");
  }
}

// Link and surface sets name the frame's groups and the sidecars: distinct, not "particles".
void check_sets(const std::vector<std::string>& link_sets, const std::vector<std::string>& surface_sets) {
  std::set<std::string> seen{"particles"};
  for (const auto& l : link_sets) {
    check_name("link set", l);
    if (!seen.insert(l).second)
      throw std::invalid_argument("ParticleOutput: link set '" + l + "' is given twice or clashes with 'particles'");
  }
  for (const auto& l : surface_sets) {
    check_name("surface set", l);
    if (!seen.insert(l).second)
      throw std::invalid_argument("ParticleOutput: surface set '" + l +
                                  "' is given twice or clashes with 'particles' or a link set");
  }
}

H5Frames create_dem_file(const std::filesystem::path& dir, const FileInfo& info, const H5StorageParams& storage,
                         const std::vector<std::string>& link_sets, const std::string& h5_name,
                         const std::vector<std::string>& surface_sets) {
  check_sets(link_sets, surface_sets);
  std::vector<std::filesystem::path> targets{dir / h5_name, dir / "particles.xmf"};
  for (const auto& l : link_sets) targets.push_back(dir / (l + ".xmf"));
  for (const auto& l : surface_sets) targets.push_back(dir / (l + ".xmf"));
  refuse_existing(targets);
  return H5Frames::create(dir / h5_name, info, storage);
}

// New frame times: one per frame written, finite, strictly increasing.
void check_new_times(const std::string& who, std::span<const double> times, std::size_t frames) {
  if (times.size() != frames)
    throw std::invalid_argument(who + "::retime_frames: " + std::to_string(times.size()) + " times for " +
                                std::to_string(frames) + " frames (one per frame written)");
  for (std::size_t i = 0; i < times.size(); ++i) {
    if (!std::isfinite(times[i])) throw std::invalid_argument(who + "::retime_frames: times must be finite");
    if (i > 0 && !(times[i] > times[i - 1]))
      throw std::invalid_argument(who + "::retime_frames: times must increase strictly; frame " + std::to_string(i) +
                                  " gets " + std::to_string(times[i]) + " s after " + std::to_string(times[i - 1]) +
                                  " s");
  }
}

FileInfo with_fdm_attrs(FileInfo info) {
  // fdm.h5 root attributes of docs/output.md O6; sign convention of docs/theory.md §0.2 (FLAC3D).
  info.extra.emplace_back("stress_unit", "Pa");
  info.extra.emplace_back("stress_components", "xx yy zz xy yz xz");
  info.extra.emplace_back("stress_sign", "tension positive");
  return info;
}

void check_rows(const std::string& what, const ArrayView& a, std::size_t rows) {
  if (a.rows != rows)
    throw std::invalid_argument(what + " has " + std::to_string(a.rows) + " rows, expected " + std::to_string(rows));
  if (a.size() > 0 && a.data == nullptr) throw std::invalid_argument(what + " has a null data pointer");
}

void check_fields(const std::string& what, const std::vector<FieldArray>& fields, std::size_t rows,
                  std::set<std::string> taken) {
  for (const auto& f : fields) {
    check_name(what, f.name);
    if (!taken.insert(f.name).second)
      throw std::invalid_argument(what + " '" + f.name + "' is given twice or clashes with a reserved name");
    check_rows(what + " '" + f.name + "'", f.data, rows);
  }
}

template <class I>
void check_index_range(const std::string& what, const I* v, std::size_t n, std::size_t limit) {
  for (std::size_t k = 0; k < n; ++k)
    if (v[k] < 0 || static_cast<std::size_t>(v[k]) >= limit)
      throw std::invalid_argument(what + ": entry " + std::to_string(k) + " (row " + std::to_string(k / 2) +
                                  ") is " + std::to_string(v[k]) + ", outside [0, " + std::to_string(limit) + ")");
}


template <class I>
void check_hex(const ArrayView& coords, const I* zn, std::size_t nz, std::size_t nn) {
  check_index_range("MeshOutput zone_nodes", zn, nz * 8, nn);
  const double* x = static_cast<const double*>(coords.data);
  for (std::size_t z = 0; z < nz; ++z) {
    const I* n = zn + 8 * z;
    auto d = [&](int a, int c) { return x[3 * n[a] + c] - x[3 * n[0] + c]; };
    // Corner Jacobian at node 0 in VTK order: edges 0->1, 0->3, 0->4 form a right-handed frame.
    const double e1[3] = {d(1, 0), d(1, 1), d(1, 2)}, e3[3] = {d(3, 0), d(3, 1), d(3, 2)},
                 e4[3] = {d(4, 0), d(4, 1), d(4, 2)};
    const double jac = (e1[1] * e3[2] - e1[2] * e3[1]) * e4[0] + (e1[2] * e3[0] - e1[0] * e3[2]) * e4[1] +
                       (e1[0] * e3[1] - e1[1] * e3[0]) * e4[2];
    if (!(jac > 0.0))
      throw std::invalid_argument("MeshOutput zone_nodes: zone " + std::to_string(z) +
                                  " is not in VTK hexahedron order (corner Jacobian at node 0 is " +
                                  std::to_string(jac) + ", must be > 0)");
  }
}


// Validates the mesh, then creates the file: nothing is written for a bad mesh.
H5Frames create_fdm_file(const std::filesystem::path& dir, const FileInfo& info, const H5StorageParams& storage,
                         const std::string& h5_name, const ArrayView& node_coords, const ArrayView& zone_nodes) {
  if (node_coords.cols != 3 || node_coords.dtype != DType::kFloat64)
    throw std::invalid_argument("MeshOutput node_coords must be [Nn,3] float64");
  if (zone_nodes.cols != 8 || !(zone_nodes.dtype == DType::kInt64 || zone_nodes.dtype == DType::kInt32))
    throw std::invalid_argument("MeshOutput zone_nodes must be [Nz,8] int64 (or int32)");
  check_rows("MeshOutput node_coords", node_coords, node_coords.rows);
  check_rows("MeshOutput zone_nodes", zone_nodes, zone_nodes.rows);
  if (zone_nodes.dtype == DType::kInt64)
    check_hex(node_coords, static_cast<const std::int64_t*>(zone_nodes.data), zone_nodes.rows, node_coords.rows);
  else
    check_hex(node_coords, static_cast<const std::int32_t*>(zone_nodes.data), zone_nodes.rows, node_coords.rows);
  refuse_existing({dir / h5_name, dir / "mesh.xmf"});
  return H5Frames::create(dir / h5_name, with_fdm_attrs(info), storage);
}

// Resume with no frame kept: the sidecars go, as they did not exist before a first frame.
void remove_sidecar(const XdmfSidecar& s) {
  std::error_code ec;
  std::filesystem::remove(s.path(), ec);
  if (ec) throw IoError("remove failed for '" + s.path().string() + "': " + ec.message());
}

// Appends a rebuilt grid; a grid the sidecar refuses means the file is not what the writer
// wrote, which is the file's fault rather than the caller's.
void append_rebuilt(XdmfSidecar& s, XdmfGrid g, const std::string& file) {
  try {
    s.append(std::move(g));
  } catch (const std::invalid_argument& e) {
    throw IoError("'" + file + "' cannot be resumed: " + e.what());
  }
}

bool starts_with_dir(const std::string& name, const std::string& dir) {
  return name.size() > dir.size() + 1 && name.compare(0, dir.size(), dir) == 0 && name[dir.size()] == '/' &&
         name.find('/', dir.size() + 1) == std::string::npos;
}

}  // namespace

// ---------------------------------------------------------------------------------------

ParticleOutput::ParticleOutput(const std::filesystem::path& dir, const FileInfo& info, const H5StorageParams& storage,
                               std::vector<std::string> link_sets, const std::string& h5_name,
                               std::vector<std::string> surface_sets)
    : ParticleOutput(create_dem_file(dir, info, storage, link_sets, h5_name, surface_sets), dir, link_sets,
                     surface_sets) {}

ParticleOutput::ParticleOutput(H5Frames h5, const std::filesystem::path& dir, std::vector<std::string> link_sets,
                               std::vector<std::string> surface_sets)
    : h5_(std::move(h5)),
      dir_(dir),
      particles_xmf_(dir / "particles.xmf", "particles"),
      link_sets_(std::move(link_sets)),
      surface_sets_(std::move(surface_sets)) {
  for (const auto& l : link_sets_) links_xmf_.emplace_back(dir / (l + ".xmf"), l);
  for (const auto& l : surface_sets_) surfaces_xmf_.emplace_back(dir / (l + ".xmf"), l);
}

ParticleOutput ParticleOutput::resume(const std::filesystem::path& dir, const H5StorageParams& storage,
                                      std::vector<std::string> link_sets, std::size_t frames,
                                      const std::string& h5_name, std::vector<std::string> surface_sets) {
  check_sets(link_sets, surface_sets);
  ParticleOutput out(H5Frames::reopen(dir / h5_name, frames, storage), dir, std::move(link_sets),
                     std::move(surface_sets));
  out.rebuild_sidecars();
  return out;
}

void ParticleOutput::retime_frames(std::span<const double> times) {
  check_new_times("ParticleOutput", times, h5_.frame_count());
  if (times.empty()) return;
  h5_.set_frame_times(times);
  // The sidecars again from the file, as a resume builds them (the same bytes as frames
  // written with these times from the start).
  particles_xmf_ = XdmfSidecar(dir_ / "particles.xmf", "particles");
  for (std::size_t i = 0; i < link_sets_.size(); ++i) links_xmf_[i] = XdmfSidecar(dir_ / (link_sets_[i] + ".xmf"), link_sets_[i]);
  for (std::size_t i = 0; i < surface_sets_.size(); ++i)
    surfaces_xmf_[i] = XdmfSidecar(dir_ / (surface_sets_[i] + ".xmf"), surface_sets_[i]);
  rebuild_sidecars();
}

void ParticleOutput::rebuild_sidecars() {
  const std::string file = h5_.file().string();
  // The grids write_frame() appended, from the kept frames. Each frame's Polyvertex index
  // reference had the index's length after that frame: the running maximum of Np.
  std::size_t index_len = 0;
  for (const FrameRecord& r : h5_.read_frames()) {
    const std::string where = "frame at step " + std::to_string(r.step) + " of '" + file + "': ";
    std::size_t k = 0;
    const auto next_is = [&](const std::string& name) { return k < r.names.size() && r.names[k] == name; };
    if (!next_is("particles/position"))
      throw IoError("ParticleOutput::resume: " + where + "particles/position is not its first dataset");
    XdmfGrid g;
    g.time = r.time;
    g.topology = XdmfTopology::kPolyvertex;
    g.geometry = r.datasets[k++];
    g.elements = g.geometry.rows;
    index_len = std::max(index_len, g.elements);
    g.connectivity = DatasetRef{h5_.file(), kVertexIndex, DType::kInt32, index_len, 1};
    for (; k < r.names.size() && starts_with_dir(r.names[k], "particles"); ++k)
      g.attributes.push_back(XdmfAttribute::node(r.names[k].substr(10), r.datasets[k]));
    std::vector<XdmfGrid> link_grids;
    for (const auto& l : link_sets_) {
      if (!next_is(l + "/nodes"))
        throw IoError("ParticleOutput::resume: " + where + "link set '" + l +
                      "' is not next in its datasets (the run's link sets differ?)");
      XdmfGrid lg;
      lg.time = r.time;
      lg.topology = XdmfTopology::kPolyline;
      lg.connectivity = r.datasets[k++];
      lg.elements = lg.connectivity.rows;
      lg.geometry = g.geometry;
      for (; k < r.names.size() && starts_with_dir(r.names[k], l); ++k)
        lg.attributes.push_back(XdmfAttribute::cell(r.names[k].substr(l.size() + 1), r.datasets[k]));
      link_grids.push_back(std::move(lg));
    }
    std::vector<XdmfGrid> surface_grids;
    for (const auto& l : surface_sets_) {
      if (!next_is(l + "/vertices") || !(k + 1 < r.names.size() && r.names[k + 1] == l + "/triangles"))
        throw IoError("ParticleOutput::resume: " + where + "surface set '" + l +
                      "' is not next in its datasets (the run's surface sets differ?)");
      XdmfGrid sg;
      sg.time = r.time;
      sg.topology = XdmfTopology::kTriangle;
      sg.geometry = r.datasets[k++];
      sg.connectivity = r.datasets[k++];
      sg.elements = sg.connectivity.rows;
      surface_grids.push_back(std::move(sg));
    }
    if (k != r.names.size())
      throw IoError("ParticleOutput::resume: " + where + "dataset '" + r.names[k] +
                    "' belongs to no declared link or surface set (the run's sets differ?)");
    append_rebuilt(particles_xmf_, std::move(g), file);
    for (std::size_t i = 0; i < link_grids.size(); ++i) append_rebuilt(links_xmf_[i], std::move(link_grids[i]), file);
    for (std::size_t i = 0; i < surface_grids.size(); ++i)
      append_rebuilt(surfaces_xmf_[i], std::move(surface_grids[i]), file);
    has_time_ = true;
    last_time_ = r.time;
  }
  if (index_len > 0) {
    std::size_t have = 0;
    try {
      have = h5_.ref(kVertexIndex).rows;
    } catch (const std::out_of_range&) {
    }
    if (have < index_len)
      throw IoError("ParticleOutput::resume: " + std::string(kVertexIndex) + " of '" + file + "' holds " +
                    std::to_string(have) + " entries, fewer than the largest kept frame's " +
                    std::to_string(index_len) + " particles");
  }
  // Entries only the dropped frames needed would otherwise reach the sidecars of the
  // frames written next (their index Dimensions) and the final index length.
  h5_.truncate_index(kVertexIndex, index_len);

  if (particles_xmf_.frames() == 0) {
    remove_sidecar(particles_xmf_);
    for (const auto& s : links_xmf_) remove_sidecar(s);
    for (const auto& s : surfaces_xmf_) remove_sidecar(s);
  } else {
    particles_xmf_.write();
    for (const auto& s : links_xmf_) s.write();
    for (const auto& s : surfaces_xmf_) s.write();
  }
}

void ParticleOutput::check_time(const std::string& where, double time) const {
  if (!std::isfinite(time)) throw std::invalid_argument(where + "time must be finite");
  if (has_time_ && !(time > last_time_))
    throw std::invalid_argument(where + "frame times must increase strictly; last " + std::to_string(last_time_) +
                                " s, now " + std::to_string(time) + " s");
}

std::size_t ParticleOutput::write_frame(std::int64_t step, double time, const ParticleFrame& fr) {
  // Validate the arrays before touching the file, so a bad frame leaves no partial group (the
  // time, the link sets' names and the surfaces: begin_blocks, also before touching it).
  const std::string where = "ParticleOutput::write_frame (step " + std::to_string(step) + "): ";
  const ArrayView& pos = fr.position;
  if (pos.cols != 3 || !(pos.dtype == DType::kFloat64 || pos.dtype == DType::kFloat32))
    throw std::invalid_argument(where + "position must be [Np,3] float64 (or float32), found " +
                                std::to_string(pos.rows) + "x" + std::to_string(pos.cols) + " " +
                                std::string(dtype_name(pos.dtype)));
  const std::size_t np = pos.rows;
  check_rows(where + "position", pos, np);
  check_fields(where + "point array", fr.point_arrays, np, {"position"});
  for (const LinkFrame& l : fr.links) {
    if (l.nodes.cols != 2 || l.nodes.dtype != DType::kInt32)
      throw std::invalid_argument(where + l.name + "/nodes must be [Nb,2] int32");
    check_rows(where + l.name + "/nodes", l.nodes, l.nodes.rows);
    // docs/output.md O4: link nodes are rows of this frame's particle arrays, not ids.
    check_index_range(where + l.name + "/nodes", static_cast<const std::int32_t*>(l.nodes.data), l.nodes.size(), np);
    check_fields(where + l.name + " cell array", l.cell_arrays, l.nodes.rows, {"nodes"});
  }
  // The whole frame as one block of each dataset.
  FrameShape shape;
  shape.particles = np;
  for (const auto& f : fr.point_arrays) shape.point_arrays.push_back({f.name, f.data.dtype, f.data.cols});
  for (const auto& l : fr.links) {
    FrameShape::Links ls{l.name, l.nodes.rows, {}};
    for (const auto& f : l.cell_arrays) ls.cell_arrays.push_back({f.name, f.data.dtype, f.data.cols});
    shape.links.push_back(std::move(ls));
  }
  shape.surfaces = fr.surfaces;
  begin_blocks(step, time, shape, pos.dtype);
  write_rows("particles/position", 0, pos);
  for (const auto& f : fr.point_arrays) write_rows("particles/" + f.name, 0, f.data);
  for (const auto& l : fr.links) {
    write_rows(l.name + "/nodes", 0, l.nodes);
    for (const auto& f : l.cell_arrays) write_rows(l.name + "/" + f.name, 0, f.data);
  }
  return end_blocks();
}

std::size_t ParticleOutput::begin_blocks(std::int64_t step, double time, const FrameShape& shape) {
  return begin_blocks(step, time, shape, DType::kFloat64);
}

std::size_t ParticleOutput::begin_blocks(std::int64_t step, double time, const FrameShape& shape, DType position) {
  // Validate everything before touching the file, so a bad shape leaves no partial group.
  const std::string where = "ParticleOutput::begin_blocks (step " + std::to_string(step) + "): ";
  if (blocks_.open) throw std::logic_error(where + "the frame of step " + std::to_string(blocks_.step) + " is open");
  check_time(where, time);
  auto check_arrays = [&](const std::string& what, const std::vector<FrameShape::Array>& arrays, const char* reserved) {
    std::set<std::string> taken{reserved};
    for (const auto& a : arrays) {
      check_name(what, a.name);
      if (a.cols == 0) throw std::invalid_argument(what + " '" + a.name + "' has 0 columns");
      if (!taken.insert(a.name).second)
        throw std::invalid_argument(what + " '" + a.name + "' is given twice or clashes with a reserved name");
    }
  };
  check_arrays(where + "point array", shape.point_arrays, "position");
  if (shape.links.size() != link_sets_.size())
    throw std::invalid_argument(where + std::to_string(shape.links.size()) + " link sets given, " +
                                std::to_string(link_sets_.size()) + " declared at construction");
  for (std::size_t i = 0; i < shape.links.size(); ++i) {
    const FrameShape::Links& l = shape.links[i];
    if (l.name != link_sets_[i])
      throw std::invalid_argument(where + "link set " + std::to_string(i) + " is '" + l.name + "', expected '" +
                                  link_sets_[i] + "' (declaration order)");
    check_arrays(where + l.name + " cell array", l.cell_arrays, "nodes");
  }
  if (shape.surfaces.size() != surface_sets_.size())
    throw std::invalid_argument(where + std::to_string(shape.surfaces.size()) + " surfaces given, " +
                                std::to_string(surface_sets_.size()) + " declared at construction");
  for (std::size_t i = 0; i < shape.surfaces.size(); ++i) {
    const SurfaceFrame& sf = shape.surfaces[i];
    if (sf.name != surface_sets_[i])
      throw std::invalid_argument(where + "surface " + std::to_string(i) + " is '" + sf.name + "', expected '" +
                                  surface_sets_[i] + "' (declaration order)");
    if (sf.vertices.cols != 3 || sf.vertices.dtype != DType::kFloat64)
      throw std::invalid_argument(where + sf.name + "/vertices must be [Nv,3] float64");
    if (sf.triangles.cols != 3 || sf.triangles.dtype != DType::kInt32)
      throw std::invalid_argument(where + sf.name + "/triangles must be [Nt,3] int32");
    check_rows(where + sf.name + "/vertices", sf.vertices, sf.vertices.rows);
    check_rows(where + sf.name + "/triangles", sf.triangles, sf.triangles.rows);
    check_index_range(where + sf.name + "/triangles", static_cast<const std::int32_t*>(sf.triangles.data),
                      sf.triangles.size(), sf.vertices.rows);
  }

  blocks_ = Blocks{};
  blocks_.step = step;
  blocks_.time = time;
  blocks_.shape = shape;
  blocks_.index = h5_.begin_frame(step, time);
  blocks_.open = true;
  blocks_.vertex_index = h5_.ensure_index(kVertexIndex, shape.particles);
  auto create = [&](const std::string& name, DType t, std::size_t rows, std::size_t cols) {
    h5_.create(name, t, rows, cols);
    blocks_.rows[name] = {0, rows};
  };
  const std::size_t np = shape.particles;
  create("particles/position", position, np, 3);
  for (const auto& f : shape.point_arrays) create("particles/" + f.name, f.dtype, np, f.cols);
  for (const auto& l : shape.links) {
    create(l.name + "/nodes", DType::kInt32, l.rows, 2);
    for (const auto& f : l.cell_arrays) create(l.name + "/" + f.name, f.dtype, l.rows, f.cols);
  }
  for (const auto& sf : shape.surfaces) {
    h5_.write(sf.name + "/vertices", sf.vertices);
    h5_.write(sf.name + "/triangles", sf.triangles);
  }
  return blocks_.index;
}

void ParticleOutput::write_rows(const std::string& name, std::size_t row0, const ArrayView& block) {
  const std::string where = "ParticleOutput::write_rows (step " + std::to_string(blocks_.step) + ", '" + name + "'): ";
  if (!blocks_.open) throw std::logic_error(where + "no frame is open (begin_blocks)");
  const auto it = blocks_.rows.find(name);
  if (it == blocks_.rows.end()) throw std::invalid_argument(where + "the frame has no such dataset");
  auto& [written, total] = it->second;
  if (row0 != written)
    throw std::invalid_argument(where + "rows are written in order: the next is " + std::to_string(written) +
                                ", the block begins at " + std::to_string(row0));
  if (block.rows > total - written)
    throw std::invalid_argument(where + std::to_string(block.rows) + " rows from row " + std::to_string(row0) +
                                " exceed its " + std::to_string(total));
  check_rows(where + "block", block, block.rows);
  // docs/output.md O4: link nodes are rows of this frame's particle arrays, not ids.
  if (name.size() > 6 && name.compare(name.size() - 6, 6, "/nodes") == 0 && name.rfind("particles/", 0) != 0) {
    if (block.dtype != DType::kInt32) throw std::invalid_argument(where + "link nodes must be int32");
    check_index_range(where + "block", static_cast<const std::int32_t*>(block.data), block.size(),
                      blocks_.shape.particles);
  }
  h5_.write_rows(name, row0, block);
  written += block.rows;
}

std::size_t ParticleOutput::end_blocks() {
  const std::string where = "ParticleOutput::end_blocks (step " + std::to_string(blocks_.step) + "): ";
  if (!blocks_.open) throw std::logic_error(where + "no frame is open (begin_blocks)");
  blocks_.open = false;
  h5_.end_frame();
  for (const auto& [name, rows] : blocks_.rows)
    if (rows.first != rows.second)
      throw std::logic_error(where + "'" + name + "' got " + std::to_string(rows.first) + " of its " +
                             std::to_string(rows.second) + " rows");
  const FrameShape& shape = blocks_.shape;
  const double time = blocks_.time;
  XdmfGrid g;
  g.time = time;
  g.topology = XdmfTopology::kPolyvertex;
  g.elements = shape.particles;
  g.connectivity = blocks_.vertex_index;
  g.geometry = h5_.ref("particles/position");
  for (const auto& f : shape.point_arrays)
    g.attributes.push_back(XdmfAttribute::node(f.name, h5_.ref("particles/" + f.name)));
  particles_xmf_.append(g);
  for (std::size_t i = 0; i < shape.links.size(); ++i) {
    const FrameShape::Links& l = shape.links[i];
    XdmfGrid lg;
    lg.time = time;
    lg.topology = XdmfTopology::kPolyline;
    lg.elements = l.rows;
    lg.connectivity = h5_.ref(l.name + "/nodes");
    lg.geometry = g.geometry;  // the same frame's particle positions
    for (const auto& f : l.cell_arrays)
      lg.attributes.push_back(XdmfAttribute::cell(f.name, h5_.ref(l.name + "/" + f.name)));
    links_xmf_[i].append(std::move(lg));
  }
  for (std::size_t i = 0; i < shape.surfaces.size(); ++i) {
    const SurfaceFrame& sf = shape.surfaces[i];
    XdmfGrid sg;
    sg.time = time;
    sg.topology = XdmfTopology::kTriangle;
    sg.elements = sf.triangles.rows;
    sg.connectivity = h5_.ref(sf.name + "/triangles");
    sg.geometry = h5_.ref(sf.name + "/vertices");
    surfaces_xmf_[i].append(std::move(sg));
  }
  particles_xmf_.write();
  for (const auto& s : links_xmf_) s.write();
  for (const auto& s : surfaces_xmf_) s.write();
  has_time_ = true;
  last_time_ = time;
  blocks_.shape.surfaces.clear();  // (views of the caller's arrays)
  return blocks_.index;
}

// ---------------------------------------------------------------------------------------


MeshOutput::MeshOutput(const std::filesystem::path& dir, const FileInfo& info, const ArrayView& node_coords,
                       const ArrayView& zone_nodes, const H5StorageParams& storage, const std::string& h5_name)
    : MeshOutput(create_fdm_file(dir, info, storage, h5_name, node_coords, zone_nodes), dir, node_coords.rows,
                 zone_nodes.rows) {
  h5_.write_static("/mesh/node_coords", node_coords);
  h5_.write_static("/mesh/zone_nodes", zone_nodes);
  h5_.set_attribute("/mesh/zone_nodes", "zone_type", "hexahedron8-vtk-order");
}

MeshOutput::MeshOutput(H5Frames h5, const std::filesystem::path& dir, std::size_t nodes, std::size_t zones)
    : h5_(std::move(h5)), dir_(dir), mesh_xmf_(dir / "mesh.xmf", "mesh"), nodes_(nodes), zones_(zones) {}

void MeshOutput::retime_frames(std::span<const double> times) {
  check_new_times("MeshOutput", times, h5_.frame_count());
  if (times.empty()) return;
  h5_.set_frame_times(times);
  mesh_xmf_ = XdmfSidecar(dir_ / "mesh.xmf", "mesh");
  rebuild_sidecar();
}

MeshOutput MeshOutput::resume(const std::filesystem::path& dir, std::size_t frames, const H5StorageParams& storage,
                              const std::string& h5_name) {
  H5Frames h5 = H5Frames::reopen(dir / h5_name, frames, storage);
  const std::string file = h5.file().string();
  DatasetRef coords, zones;
  try {
    coords = h5.ref("/mesh/node_coords");
    zones = h5.ref("/mesh/zone_nodes");
  } catch (const std::out_of_range&) {
    throw IoError("MeshOutput::resume: '" + file + "' has no /mesh/node_coords and /mesh/zone_nodes");
  }
  if (coords.cols != 3 || coords.dtype != DType::kFloat64 || zones.cols != 8 ||
      !(zones.dtype == DType::kInt64 || zones.dtype == DType::kInt32))
    throw IoError("MeshOutput::resume: the mesh of '" + file +
                  "' is not node_coords [Nn,3] float64 and zone_nodes [Nz,8] int64 (or int32)");
  MeshOutput out(std::move(h5), dir, coords.rows, zones.rows);
  out.rebuild_sidecar();
  return out;
}

void MeshOutput::rebuild_sidecar() {
  const std::string file = h5_.file().string();
  for (const FrameRecord& r : h5_.read_frames()) {
    XdmfGrid g;
    g.time = r.time;
    g.topology = XdmfTopology::kHexahedron;
    g.elements = zones_;
    g.connectivity = h5_.ref("/mesh/zone_nodes");
    g.geometry = h5_.ref("/mesh/node_coords");
    // write_frame() wrote node arrays, then zone arrays, and made attributes in that order.
    for (std::size_t k = 0; k < r.names.size(); ++k) {
      const std::string& n = r.names[k];
      if (n == "nodes/position")
        g.geometry = r.datasets[k];
      else if (starts_with_dir(n, "nodes"))
        g.attributes.push_back(XdmfAttribute::node(n.substr(6), r.datasets[k]));
      else if (starts_with_dir(n, "zones"))
        g.attributes.push_back(XdmfAttribute::cell(n.substr(6), r.datasets[k]));
      else
        throw IoError("MeshOutput::resume: frame at step " + std::to_string(r.step) + " of '" + file +
                      "' holds '" + n + "', neither a node nor a zone array");
    }
    append_rebuilt(mesh_xmf_, std::move(g), file);
    has_time_ = true;
    last_time_ = r.time;
  }
  if (mesh_xmf_.frames() == 0)
    remove_sidecar(mesh_xmf_);
  else
    mesh_xmf_.write();
}

std::size_t MeshOutput::write_frame(std::int64_t step, double time, const MeshFrame& fr) {
  const std::string where = "MeshOutput::write_frame (step " + std::to_string(step) + "): ";
  if (!std::isfinite(time)) throw std::invalid_argument(where + "time must be finite");
  if (has_time_ && !(time > last_time_))
    throw std::invalid_argument(where + "frame times must increase strictly; last " + std::to_string(last_time_) +
                                " s, now " + std::to_string(time) + " s");
  check_fields(where + "node array", fr.node_arrays, nodes_, {});
  check_fields(where + "zone array", fr.zone_arrays, zones_, {});
  bool moving = false;
  for (const auto& f : fr.node_arrays)
    if (f.name == "position") {
      if (f.data.cols != 3 || f.data.dtype != DType::kFloat64)
        throw std::invalid_argument(where + "node array 'position' must be [Nn,3] float64");
      moving = true;
    }

  const std::size_t index = h5_.begin_frame(step, time);
  for (const auto& f : fr.node_arrays) h5_.write("nodes/" + f.name, f.data);
  for (const auto& f : fr.zone_arrays) h5_.write("zones/" + f.name, f.data);
  h5_.end_frame();

  XdmfGrid g;
  g.time = time;
  g.topology = XdmfTopology::kHexahedron;
  g.elements = zones_;
  g.connectivity = h5_.ref("/mesh/zone_nodes");
  g.geometry = moving ? h5_.ref("nodes/position") : h5_.ref("/mesh/node_coords");
  for (const auto& f : fr.node_arrays)
    if (f.name != "position") g.attributes.push_back(XdmfAttribute::node(f.name, h5_.ref("nodes/" + f.name)));
  for (const auto& f : fr.zone_arrays) g.attributes.push_back(XdmfAttribute::cell(f.name, h5_.ref("zones/" + f.name)));
  mesh_xmf_.append(std::move(g));
  mesh_xmf_.write();
  has_time_ = true;
  last_time_ = time;
  return index;
}

// ---------------------------------------------------------------------------------------

TriangleSurface cylinder_surface(const std::array<double, 3>& c, double diameter, double height, int segments) {
  if (!(diameter > 0) || !(height > 0) || !std::isfinite(diameter) || !std::isfinite(height))
    throw std::invalid_argument("cylinder_surface: diameter and height must be finite and > 0, found " +
                                std::to_string(diameter) + " and " + std::to_string(height));
  if (segments < 3) throw std::invalid_argument("cylinder_surface: segments must be >= 3, found " + std::to_string(segments));
  for (double v : c)
    if (!std::isfinite(v)) throw std::invalid_argument("cylinder_surface: the bottom centre must be finite");
  TriangleSurface s;
  const int n = segments;
  const double r = diameter / 2, pi = std::acos(-1.0);
  auto vertex = [&](double x, double y, double z) { s.vertices.insert(s.vertices.end(), {x, y, z}); };
  vertex(c[0], c[1], c[2]);           // 0: bottom centre
  vertex(c[0], c[1], c[2] + height);  // 1: top centre
  for (int level = 0; level < 2; ++level)
    for (int k = 0; k < n; ++k) {
      const double a = 2 * pi * k / n;
      vertex(c[0] + r * std::cos(a), c[1] + r * std::sin(a), c[2] + level * height);
    }
  auto tri = [&](int a, int b, int d) { s.triangles.insert(s.triangles.end(), {a, b, d}); };
  for (int k = 0; k < n; ++k) {
    const int k1 = (k + 1) % n;
    const int b0 = 2 + k, b1 = 2 + k1, t0 = 2 + n + k, t1 = 2 + n + k1;
    tri(0, b1, b0);   // bottom cap, normal -z
    tri(1, t0, t1);   // top cap, normal +z
    tri(b0, b1, t1);  // side, normal outwards
    tri(b0, t1, t0);
  }
  return s;
}

}  // namespace demfdm::io
