// Per-process results writers: the HDF5 file of one producer plus its XDMF sidecars,
// in the layout of common/io/README.md (docs/output.md for what a run folder holds).
//
//   ParticleOutput (dem_node): <dir>/dem.h5, <dir>/particles.xmf, <dir>/<link set>.xmf,
//                              <dir>/<surface set>.xmf
//     /xdmf/vertex_index                 int32 0..Nmax-1 (Polyvertex connectivity)
//     /frames/NNNNNN/particles/position  [Np,3] float64 m
//     /frames/NNNNNN/particles/<array>   [Np] or [Np,k] (radius, velocity, id, ...)
//     /frames/NNNNNN/<links>/nodes       [Nb,2] int32, rows into this frame's particles
//     /frames/NNNNNN/<links>/<array>     [Nb] or [Nb,k] (state uint8, force, ...)
//     /frames/NNNNNN/<surface>/vertices  [Nv,3] float64 m, a rigid body's surface (footing)
//     /frames/NNNNNN/<surface>/triangles [Nt,3] int32, rows into this frame's vertices
//   MeshOutput (fdm_node): <dir>/fdm.h5, <dir>/mesh.xmf
//     /mesh/node_coords                  [Nn,3] float64 m, reference coordinates
//     /mesh/zone_nodes                   [Nz,8] int64, VTK hexahedron order
//     /frames/NNNNNN/nodes/<array>       [Nn] or [Nn,k] (displacement, velocity, ...)
//     /frames/NNNNNN/zones/<array>       [Nz] or [Nz,k] (stress [Nz,6] xx yy zz xy yz xz, ...)
//
// Each write_frame() writes one HDF5 frame (file opened and closed around it) and then
// atomically rewrites the sidecars. Frame times must increase strictly (a temporal
// collection). The nodes write the model time of docs/output.md ("Time": 0 at the beginning
// of the run's first stage that is not specimen preparation, io::ModelClock), so that frames
// of the same moment carry the same time in every file; frames written before that moment is
// known get their times afterwards through retime_frames(). Existing files (HDF5 or
// sidecar) are never overwritten, except by resume().
//
// resume() continues the files of a run resumed from a checkpoint that recorded
// h5().frame_count(): frames the crashed run wrote after it are dropped (H5Frames::reopen),
// the sidecars are rebuilt for the kept frames from the HDF5 file alone (frame attribute
// time, dataset shapes and dtypes, and the frame's "datasets" attribute, which lists its
// datasets in write order: position, point arrays, then per link set nodes and cell arrays;
// node arrays, then zone arrays), and the frames written from then on give the same HDF5
// datasets and the same sidecar bytes as an uninterrupted run.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <map>
#include <span>
#include <string>
#include <vector>

#include "demfdm/io/array_view.hpp"
#include "demfdm/io/h5_frames.hpp"
#include "demfdm/io/params.hpp"
#include "demfdm/io/xdmf_sidecar.hpp"

namespace demfdm::io {

/// Pairs of particles of one frame drawn as line cells (bonds, contacts).
struct LinkFrame {
  std::string name;                     // link set, declared at construction: "bonds", "contacts"
  ArrayView nodes;                      // [Nb,2] int32, 0-based rows of this frame's particle arrays
  // Per-link arrays [Nb] or [Nb,k]. Bonds: "state" uint8; dem_node writes its BondState
  // codes (0 never bonded, 1 intact, 2 softening, 3 broken in tension, 4 broken in shear;
  // docs/output.md), which launch/paraview/open_run.py colours as categories.
  std::vector<FieldArray> cell_arrays;
};

/// A triangulated surface of one frame (the footing): drawn as Triangle cells in its own
/// sidecar <name>.xmf. A frame in which the body does not exist (yet) gives 0 vertices and 0
/// triangles: an empty grid at that time.
struct SurfaceFrame {
  std::string name;    // surface set, declared at construction: "footing"
  ArrayView vertices;  // [Nv,3] float64 [m]
  ArrayView triangles; // [Nt,3] int32, 0-based rows of `vertices`, counter-clockwise seen from outside
};

/// One DEM output frame. Array names become dataset and ParaView array names; the names the
/// tools expect: radius [Np] (m), velocity [Np,3] (m/s), id [Np] int64 (persistent particle id).
struct ParticleFrame {
  ArrayView position;                    // [Np,3] float64 [m] particle centres
  std::vector<FieldArray> point_arrays;  // per-particle arrays, rows = Np
  std::vector<LinkFrame> links;          // exactly the link sets declared at construction
  std::vector<SurfaceFrame> surfaces;    // exactly the surface sets declared at construction
};

/// The shape of a frame written in blocks of rows (ParticleOutput::begin_blocks): a frame too
/// large for one block of memory, e.g. the DEM on MPI ranks merging its ranks' rows on rank 0.
struct FrameShape {
  struct Array {
    std::string name;
    DType dtype = DType::kFloat64;
    std::size_t cols = 1;
  };
  struct Links {
    std::string name;                 // a declared link set
    std::size_t rows = 0;             // Nb
    std::vector<Array> cell_arrays;   // after "nodes" ([Nb,2] int32)
  };
  std::size_t particles = 0;          // Np; "position" [Np,3] float64 comes first
  std::vector<Array> point_arrays;
  std::vector<Links> links;           // exactly the link sets declared at construction
  std::vector<SurfaceFrame> surfaces; // written whole by begin_blocks (a few vertices)
};

/// Closed triangulated surface of an upright cylinder (axis along z): `segments` vertices on
/// each rim, one centre vertex per cap; 4 x segments triangles with outward normals. Vertices:
/// bottom centre, top centre, bottom rim (angle 2 pi k / segments from +x), top rim.
struct TriangleSurface {
  std::vector<double> vertices;         // [Nv,3] flat, m
  std::vector<std::int32_t> triangles;  // [Nt,3] flat
};
TriangleSurface cylinder_surface(const std::array<double, 3>& bottom_centre, double diameter, double height,
                                 int segments = 48);

class ParticleOutput {
 public:
  /// Creates <dir>/<h5_name> (exclusive) with root attribute producer=info.producer.
  /// `link_sets` are the names of the link sets every frame carries; each gets <name>.xmf.
  /// `surface_sets` likewise for the triangulated surfaces (e.g. {"footing"}).
  /// Throws IoError when a target file already exists, std::invalid_argument on bad names.
  ParticleOutput(const std::filesystem::path& dir, const FileInfo& info, const H5StorageParams& storage = {},
                 std::vector<std::string> link_sets = {"bonds"}, const std::string& h5_name = "dem.h5",
                 std::vector<std::string> surface_sets = {});

  /// Continues <dir>/<h5_name> and the sidecars of a run resumed at output frame `frames`
  /// (the checkpoint's h5().frame_count()): see the file comment. `storage`, `link_sets`
  /// and `surface_sets` must be the ones the run started with. The sidecars are rewritten
  /// for frames 0..frames-1 (removed when frames is 0, as before a first frame), and the
  /// vertex index is cut back to the length those frames needed. Throws IoError when the
  /// file cannot be resumed (H5Frames::reopen) or its frames do not hold exactly those sets.
  static ParticleOutput resume(const std::filesystem::path& dir, const H5StorageParams& storage,
                               std::vector<std::string> link_sets, std::size_t frames,
                               const std::string& h5_name = "dem.h5", std::vector<std::string> surface_sets = {});

  /// Writes one frame and rewrites the sidecars; returns the frame index.
  /// Validates all counts, and that every link node and triangle row is in range, before writing.
  std::size_t write_frame(std::int64_t step, double time, const ParticleFrame& frame);

  /// The same frame written in blocks of rows: begin_blocks() validates the shape and creates
  /// the frame's datasets; write_rows() writes rows [row0, row0 + block.rows) of one of them
  /// ("particles/position", "particles/<array>", "<links>/nodes", "<links>/<array>"), each
  /// dataset's rows in increasing order without gaps (link nodes are checked against Np);
  /// end_blocks() checks that every row was written, closes the frame and rewrites the
  /// sidecars. The file holds the same datasets as write_frame() of the whole frame writes.
  std::size_t begin_blocks(std::int64_t step, double time, const FrameShape& shape);
  void write_rows(const std::string& name, std::size_t row0, const ArrayView& block);
  std::size_t end_blocks();

  /// Gives frames 0..times.size()-1 new times (attribute time of each frame group) and
  /// rewrites the sidecars; `times` holds one time per frame written so far, finite and
  /// strictly increasing. For a node whose model-time origin became known after it wrote
  /// these frames (docs/output.md "Time"). Throws std::invalid_argument otherwise.
  void retime_frames(std::span<const double> times);

  /// The results file, e.g. to add histories or attributes between frames.
  H5Frames& h5() noexcept { return h5_; }
  const XdmfSidecar& particles_sidecar() const noexcept { return particles_xmf_; }
  const XdmfSidecar& link_sidecar(std::size_t i) const { return links_xmf_.at(i); }
  const XdmfSidecar& surface_sidecar(std::size_t i) const { return surfaces_xmf_.at(i); }

 private:
  ParticleOutput(H5Frames h5, const std::filesystem::path& dir, std::vector<std::string> link_sets,
                 std::vector<std::string> surface_sets);
  void rebuild_sidecars();
  void check_time(const std::string& where, double time) const;
  std::size_t begin_blocks(std::int64_t step, double time, const FrameShape& shape, DType position);

  // The frame being written in blocks: its shape and the rows written so far per dataset.
  struct Blocks {
    bool open = false;
    std::int64_t step = 0;
    double time = 0.0;
    std::size_t index = 0;
    DatasetRef vertex_index;
    FrameShape shape;
    std::map<std::string, std::pair<std::size_t, std::size_t>> rows;  // name: (written, total)
  };
  Blocks blocks_;

  H5Frames h5_;
  std::filesystem::path dir_;
  XdmfSidecar particles_xmf_;
  std::vector<std::string> link_sets_;
  std::vector<XdmfSidecar> links_xmf_;
  std::vector<std::string> surface_sets_;
  std::vector<XdmfSidecar> surfaces_xmf_;
  bool has_time_ = false;
  double last_time_ = 0.0;
};

/// One FDM output frame.
struct MeshFrame {
  // Per-node arrays [Nn] or [Nn,k]: displacement [Nn,3] (m; ParaView "Warp By Vector"),
  // velocity [Nn,3] (m/s). A float64 [Nn,3] array named "position" (current coordinates)
  // replaces /mesh/node_coords as the frame's geometry (docs/output.md O7, large deformations).
  std::vector<FieldArray> node_arrays;
  // Per-zone arrays [Nz] or [Nz,k]: stress [Nz,6] (Pa, xx yy zz xy yz xz, tension positive,
  // docs/theory.md §0.2 sign convention), plastic state uint8 [Nz], ...
  std::vector<FieldArray> zone_arrays;
};

class MeshOutput {
 public:
  /// Creates <dir>/<h5_name> (exclusive) with the static mesh: node_coords [Nn,3] float64 and
  /// zone_nodes [Nz,8] int64 (or int32) in VTK hexahedron order (face 0-1-2-3 counter-
  /// clockwise seen from face 4-5-6-7, node 4+i across from node i). Checks every index is
  /// in [0, Nn) and every zone has a positive corner Jacobian at node 0
  /// ((x1-x0) x (x3-x0)) . (x4-x0) > 0 in the reference coordinates, which catches mirrored
  /// (wrong-order) zones.
  MeshOutput(const std::filesystem::path& dir, const FileInfo& info, const ArrayView& node_coords,
             const ArrayView& zone_nodes, const H5StorageParams& storage = {}, const std::string& h5_name = "fdm.h5");

  /// Continues <dir>/<h5_name> and mesh.xmf of a run resumed at output frame `frames` (the
  /// checkpoint's h5().frame_count()): see the file comment. The mesh is taken from the
  /// file (/mesh/node_coords, /mesh/zone_nodes); `storage` must be the run's. mesh.xmf is
  /// rewritten for frames 0..frames-1 (removed when frames is 0). Throws IoError when the
  /// file cannot be resumed (H5Frames::reopen) or is not a mesh results file.
  static MeshOutput resume(const std::filesystem::path& dir, std::size_t frames, const H5StorageParams& storage = {},
                           const std::string& h5_name = "fdm.h5");

  std::size_t write_frame(std::int64_t step, double time, const MeshFrame& frame);

  /// As ParticleOutput::retime_frames.
  void retime_frames(std::span<const double> times);

  H5Frames& h5() noexcept { return h5_; }
  const XdmfSidecar& mesh_sidecar() const noexcept { return mesh_xmf_; }
  std::size_t node_count() const noexcept { return nodes_; }
  std::size_t zone_count() const noexcept { return zones_; }

 private:
  MeshOutput(H5Frames h5, const std::filesystem::path& dir, std::size_t nodes, std::size_t zones);
  void rebuild_sidecar();

  H5Frames h5_;
  std::filesystem::path dir_;
  XdmfSidecar mesh_xmf_;
  std::size_t nodes_ = 0;
  std::size_t zones_ = 0;
  bool has_time_ = false;
  double last_time_ = 0.0;
};

}  // namespace demfdm::io
