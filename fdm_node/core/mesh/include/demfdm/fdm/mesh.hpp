// Structured hexahedral mesh with an optional open pocket for the DEM block
// (docs/theory.md 5.1, 6.2): its parameters, the generator and the numbering rules. Library
// fdm_mesh, shared by fdm_core and fem_core so that both continuum solvers present the same
// coupling interface.
//
// Numbering (stable and deterministic):
//  * gridpoints: lexicographic in (k, j, i) of the structured grid, skipping grid nodes that no
//    zone uses (those strictly inside the pocket);
//  * zones: lexicographic in (k, j, i) over the kept cells; corners in unit-cube order
//    0:(0,0,0) 1:(1,0,0) 2:(1,1,0) 3:(0,1,0) 4:(0,0,1) 5:(1,0,1) 6:(1,1,1) 7:(0,1,1)
//    (docs/theory.md 5.2), which is also the VTK_HEXAHEDRON order;
//  * interface: the zone faces shared with the pocket. Interface gridpoints are listed in
//    ascending gridpoint id; each quad face gives two triangles (q0,q1,q2), (q0,q2,q3) with the
//    fixed diagonal q0-q2, wound so that the normal points out of the zone, i.e. into the
//    pocket (towards the DEM). Faces are ordered by the Side of the zone face, i.e. by the
//    direction of the normal (-z, -x, +x, -y, +y, +z; the pocket bottom is +z), then by zone id.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <vector>

#include "demfdm/param_table.hpp"

namespace demfdm::fdm {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Axis-aligned box [lo, hi] used for the inner (pocket / refinement) region and for
// material-group regions.
struct Box {
  std::array<double, 3> lo{0.0, 0.0, 0.0};  // [m] minimum corner
  std::array<double, 3> hi{0.0, 0.0, 0.0};  // [m] maximum corner
  [[nodiscard]] bool contains(const std::array<double, 3>& p) const {
    return p[0] >= lo[0] && p[0] <= hi[0] && p[1] >= lo[1] && p[1] <= hi[1] && p[2] >= lo[2] &&
           p[2] <= hi[2];
  }
};

// Structured hexahedral mesh of the box [0,L]x[0,W]x[0,H] (docs/theory.md 5.1).
// Grid lines pass through the faces of an inner box; zones have size `size_near` inside and
// next to it and grow by `growth` per zone up to `size_far` towards the outer boundary.
// With `pocket` the inner box is left open (the DEM block) and its faces shared with zones
// form the coupling interface (docs/theory.md 6.2).
struct MeshParams {
  double length = 16e-3;  // [m] L, extent in x (docs/theory.md 0.3)
  double width = 16e-3;   // [m] W, extent in y (docs/theory.md 0.3)
  double height = 16e-3;  // [m] H, extent in z (docs/theory.md 0.3)
  // [m] L_D, W_D, H_D of the inner box (docs/theory.md 0.3: 4 x 4 x 10 mm). All three zero: no
  // inner box, the grid is uniform with spacing <= size_near on every axis.
  std::array<double, 3> inner_size{4e-3, 4e-3, 10e-3};
  // [m] minimum corner of the inner box; NaN components take the default position: centred
  // in x and y, top face flush with z = H (docs/theory.md 5.1 [RECON]).
  std::array<double, 3> inner_origin{kNaN, kNaN, kNaN};
  bool pocket = true;        // [-] true: inner box left open for the DEM block; false: meshed
  double size_near = 0.5e-3; // [m] zone size inside and next to the inner box (docs/theory.md 5.1)
  double size_far = 2e-3;    // [m] largest zone size towards the outer boundary
  double growth = 1.2;       // [-] zone-to-zone size ratio outside the inner box, in [1, 2]

  // A plain box with uniform zones of size <= `size` and no inner box (verification runs).
  static MeshParams plain_box(double length, double width, double height, double size) {
    MeshParams p;
    p.length = length;
    p.width = width;
    p.height = height;
    p.inner_size = {0.0, 0.0, 0.0};
    p.pocket = false;
    p.size_near = size;
    p.size_far = size;
    p.growth = 1.0;
    return p;
  }
};

// The [continuum.mesh] keys with a field of their own, declared once (demfdm/param_table.hpp:
// the schema's entry, the scene read, validate()'s range checks). The box and inner-box sizes and
// the inner origin are lists, which the scene reader maps onto length, width, height, inner_size
// and inner_origin (their defaults are these fields' initial values).
template <class V>
void describe(V& v, MeshParams& p) {
  v.flag("pocket", p.pocket, "Leave the inner box open for the DEM block (its faces are the coupling interface).");
  v.real("size_near", "m", p.size_near, ParamRange::gt(0.0), "Zone size in and next to the inner box.");
  v.real("size_far", "m", p.size_far, ParamRange::gt(0.0), "Largest zone size towards the outer boundary.");
  v.real("growth", "-", p.growth, ParamRange::ge(1.0).le(2.0), "Zone-to-zone size ratio away from the inner box.");
}

// Pocket / box side identifiers, in interface order.
enum class Side : std::int8_t { kMinusZ = 0, kMinusX = 1, kPlusX = 2, kMinusY = 3, kPlusY = 4, kPlusZ = 5 };

// Local corners of each hexahedron face, counter-clockwise seen from outside the zone,
// indexed by Side.
inline constexpr std::array<std::array<int, 4>, 6> kHexFaces{{
    {0, 3, 2, 1},  // -z
    {0, 4, 7, 3},  // -x
    {1, 2, 6, 5},  // +x
    {0, 1, 5, 4},  // -y
    {3, 7, 6, 2},  // +y
    {4, 5, 6, 7},  // +z
}};

struct Mesh {
  std::vector<double> grid_x, grid_y, grid_z;  // [m] structured grid-line coordinates
  std::vector<double> points;                  // [m] [n,3] gridpoint reference positions
  std::vector<std::int32_t> point_ijk;         // [-] [n,3] structured indices of each gridpoint
  std::vector<std::int32_t> zones;             // [-] [nz,8] corner gridpoint ids (unit-cube order)
  std::vector<std::int32_t> zone_ijk;          // [-] [nz,3] structured indices of each zone cell
  bool has_pocket = false;                     // [-] pocket left open
  Box pocket{};                                // [m] pocket box (inner box) when has_pocket
  std::vector<std::int32_t> interface_points;     // [-] gridpoint ids, ascending
  std::vector<std::int32_t> interface_triangles;  // [-] [nt,3] indices into interface_points
  std::vector<std::int8_t> interface_triangle_side;  // [-] [nt] Side of the zone face (normal direction)

  [[nodiscard]] std::size_t num_points() const { return points.size() / 3; }
  [[nodiscard]] std::size_t num_zones() const { return zones.size() / 8; }
  [[nodiscard]] std::size_t num_interface_triangles() const { return interface_triangles.size() / 3; }
};

// Grid-line coordinates of [0, length] with grid lines at a and b (0 <= a <= b <= length):
// uniform spacing <= size_near in [a, b]; outside, sizes grow geometrically away from the
// inner interval, starting at size_near, by `growth` per zone, capped at size_far, then
// scaled down uniformly so that they fill the segment exactly (ratio and cap are kept).
// a == b: uniform spacing <= size_near over the whole length.
std::vector<double> graded_axis(double length, double a, double b, double size_near,
                                double size_far, double growth);

// Throws std::invalid_argument naming the first bad field.
void validate(const MeshParams& p);

// Builds the mesh (validates the parameters first).
Mesh generate_mesh(const MeshParams& p);

// Builds a mesh from explicit grid-line coordinates (strictly increasing). If `pocket_cells`
// is given as {i0,i1,j0,j1,k0,k1} (half-open cell ranges), those cells are left open.
Mesh mesh_from_grid(std::vector<double> xs, std::vector<double> ys, std::vector<double> zs,
                    const std::array<int, 6>* pocket_cells = nullptr);

// A zone face on the outer or pocket boundary: 4 gridpoint ids, counter-clockwise seen from
// outside the material (so (q1-q0)x(q3-q0) points outward), with the zone and its Side.
struct BoundaryFace {
  std::array<std::int32_t, 4> points{};
  std::int32_t zone = -1;
  Side side = Side::kMinusZ;
};

// Every zone face not shared with another zone, in zone order then Side order.
std::vector<BoundaryFace> boundary_faces(const Mesh& mesh);

}  // namespace demfdm::fdm
