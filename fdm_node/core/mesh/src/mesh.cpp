// Structured mesh generation with an open pocket (docs/theory.md 5.1) and the coupling interface
// faces (docs/theory.md 6.2). See mesh.hpp for the numbering rules.
#include "demfdm/fdm/mesh.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>

namespace demfdm::fdm {
namespace {

[[noreturn]] void fail(const std::string& what) { throw std::invalid_argument(what); }

void require(bool ok, const char* field, const char* range, double value) {
  if (ok) return;
  std::ostringstream os;
  os << field << ": expected " << range << ", found " << value;
  throw std::invalid_argument(os.str());
}

// Sizes growing away from the inner interval: near * growth^k capped at far, as many as
// needed to cover `len`, then scaled down (factor <= 1) to fit exactly.
std::vector<double> graded_sizes(double len, double near, double far, double growth) {
  std::vector<double> sizes;
  if (len <= 0.0) return sizes;
  double sum = 0.0;
  double s = near;
  // Relative slack so that a segment that is an exact multiple of `near` is not given an
  // extra sliver zone by round-off.
  const double target = len * (1.0 - 1e-12);
  while (sum < target) {
    const double si = std::min(s, far);
    sizes.push_back(si);
    sum += si;
    s *= growth;
  }
  const double scale = len / sum;
  for (double& v : sizes) v *= scale;
  return sizes;
}

}  // namespace

void validate(const MeshParams& p) {
  require(p.length > 0.0 && std::isfinite(p.length), "mesh.length", "a finite value > 0 m", p.length);
  require(p.width > 0.0 && std::isfinite(p.width), "mesh.width", "a finite value > 0 m", p.width);
  require(p.height > 0.0 && std::isfinite(p.height), "mesh.height", "a finite value > 0 m", p.height);
  const double ext[3] = {p.length, p.width, p.height};
  static const char* kSize[3] = {"mesh.inner_size[0] (L_D)", "mesh.inner_size[1] (W_D)", "mesh.inner_size[2] (H_D)"};
  const bool any = p.inner_size[0] > 0.0 || p.inner_size[1] > 0.0 || p.inner_size[2] > 0.0;
  for (int d = 0; d < 3; ++d) {
    if (any) {
      require(p.inner_size[d] > 0.0 && p.inner_size[d] <= ext[d], kSize[d],
              "a value in (0, box extent] (all three zero for no inner box)", p.inner_size[d]);
    } else {
      require(p.inner_size[d] == 0.0, kSize[d], "0 when the other inner sizes are 0", p.inner_size[d]);
    }
  }
  require(!(p.pocket && !any), "mesh.pocket", "false when inner_size is zero (no pocket to open)", 1.0);
  MeshParams keys = p;  // the table's ranges (mesh.hpp), named as the scene names the keys
  RangeCheck check{"FDM", "continuum.mesh."};
  describe(check, keys);
  require(p.size_far >= p.size_near, "mesh.size_far", "a finite value >= size_near", p.size_far);
  // Guard against meshes that would not fit in memory by mistake (about 2e7 zones).
  const double nmax = (p.length / p.size_near + 1) * (p.width / p.size_near + 1) * (p.height / p.size_near + 1);
  require(nmax < 2e7, "mesh.size_near", "a size giving fewer than 2e7 zones", p.size_near);
}

std::vector<double> graded_axis(double length, double a, double b, double size_near,
                                double size_far, double growth) {
  if (!(length > 0.0)) fail("graded_axis: length must be > 0 m, found " + std::to_string(length));
  if (!(a >= 0.0 && a <= b && b <= length))
    fail("graded_axis: inner interval must satisfy 0 <= a <= b <= length, found a=" +
         std::to_string(a) + " b=" + std::to_string(b) + " length=" + std::to_string(length));
  std::vector<double> xs;
  if (b - a <= 0.0) {
    const int n = std::max(1, static_cast<int>(std::ceil(length / size_near * (1.0 - 1e-12))));
    for (int i = 0; i <= n; ++i) xs.push_back(length * static_cast<double>(i) / n);
    xs.back() = length;
    return xs;
  }
  // Left segment [0, a]: sizes grow from a towards 0.
  const std::vector<double> left = graded_sizes(a, size_near, size_far, growth);
  xs.push_back(0.0);
  {
    double x = a;
    std::vector<double> rev;
    for (double s : left) {
      x -= s;
      rev.push_back(x);
    }
    // rev holds a - s0, a - s0 - s1, ..., ~0 (the last one is 0 up to round-off).
    for (auto it = rev.rbegin(); it != rev.rend(); ++it)
      if (it != rev.rbegin()) xs.push_back(*it);
  }
  // Inner segment [a, b], uniform.
  const int n_in = std::max(1, static_cast<int>(std::ceil((b - a) / size_near * (1.0 - 1e-12))));
  if (a > 0.0) xs.push_back(a);
  for (int i = 1; i < n_in; ++i) xs.push_back(a + (b - a) * static_cast<double>(i) / n_in);
  xs.push_back(b);
  // Right segment [b, length].
  const std::vector<double> right = graded_sizes(length - b, size_near, size_far, growth);
  double x = b;
  for (std::size_t i = 0; i < right.size(); ++i) {
    x += right[i];
    xs.push_back(i + 1 == right.size() ? length : x);
  }
  return xs;
}

Mesh mesh_from_grid(std::vector<double> xs, std::vector<double> ys, std::vector<double> zs,
                    const std::array<int, 6>* pocket_cells) {
  for (const auto* g : {&xs, &ys, &zs}) {
    if (g->size() < 2) fail("mesh_from_grid: each axis needs at least 2 grid lines");
    for (std::size_t i = 1; i < g->size(); ++i)
      if (!((*g)[i] > (*g)[i - 1])) fail("mesh_from_grid: grid lines must be strictly increasing");
  }
  Mesh m;
  const int nx = static_cast<int>(xs.size()) - 1;
  const int ny = static_cast<int>(ys.size()) - 1;
  const int nz = static_cast<int>(zs.size()) - 1;
  auto in_pocket = [&](int i, int j, int k) {
    if (pocket_cells == nullptr) return false;
    const auto& p = *pocket_cells;
    return i >= p[0] && i < p[1] && j >= p[2] && j < p[3] && k >= p[4] && k < p[5];
  };
  auto cell_kept = [&](int i, int j, int k) {
    return i >= 0 && j >= 0 && k >= 0 && i < nx && j < ny && k < nz && !in_pocket(i, j, k);
  };
  // Gridpoints used by at least one kept cell, numbered in (k, j, i) order.
  const std::size_t nnode = static_cast<std::size_t>(nx + 1) * (ny + 1) * (nz + 1);
  std::vector<std::int32_t> node_id(nnode, -1);
  auto nidx = [&](int i, int j, int k) {
    return (static_cast<std::size_t>(k) * (ny + 1) + j) * (nx + 1) + i;
  };
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) {
        bool used = false;
        for (int dk = -1; dk <= 0 && !used; ++dk)
          for (int dj = -1; dj <= 0 && !used; ++dj)
            for (int di = -1; di <= 0 && !used; ++di) used = cell_kept(i + di, j + dj, k + dk);
        if (!used) continue;
        node_id[nidx(i, j, k)] = static_cast<std::int32_t>(m.points.size() / 3);
        m.points.insert(m.points.end(), {xs[i], ys[j], zs[k]});
        m.point_ijk.insert(m.point_ijk.end(), {i, j, k});
      }
  static constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                        {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        if (!cell_kept(i, j, k)) continue;
        for (const auto& c : kCorner) m.zones.push_back(node_id[nidx(i + c[0], j + c[1], k + c[2])]);
        m.zone_ijk.insert(m.zone_ijk.end(), {i, j, k});
      }
  // Interface: faces of kept cells whose neighbour is a pocket cell.
  if (pocket_cells != nullptr) {
    const auto& p = *pocket_cells;
    m.has_pocket = true;
    m.pocket = Box{{xs[p[0]], ys[p[2]], zs[p[4]]}, {xs[p[1]], ys[p[3]], zs[p[5]]}};
    static constexpr int kOffset[6][3] = {{0, 0, -1}, {-1, 0, 0}, {1, 0, 0},
                                          {0, -1, 0}, {0, 1, 0},  {0, 0, 1}};
    std::vector<std::array<std::int32_t, 4>> quads;
    std::vector<std::int8_t> quad_side;
    for (int s = 0; s < 6; ++s)
      for (std::size_t z = 0; z < m.num_zones(); ++z) {
        const int i = m.zone_ijk[3 * z] + kOffset[s][0];
        const int j = m.zone_ijk[3 * z + 1] + kOffset[s][1];
        const int k = m.zone_ijk[3 * z + 2] + kOffset[s][2];
        if (i < 0 || j < 0 || k < 0 || i >= nx || j >= ny || k >= nz || !in_pocket(i, j, k)) continue;
        std::array<std::int32_t, 4> q{};
        for (int c = 0; c < 4; ++c) q[c] = m.zones[8 * z + kHexFaces[s][c]];
        quads.push_back(q);
        quad_side.push_back(static_cast<std::int8_t>(s));
      }
    for (const auto& q : quads) m.interface_points.insert(m.interface_points.end(), q.begin(), q.end());
    std::sort(m.interface_points.begin(), m.interface_points.end());
    m.interface_points.erase(std::unique(m.interface_points.begin(), m.interface_points.end()),
                             m.interface_points.end());
    std::vector<std::int32_t> local(m.num_points(), -1);
    for (std::size_t l = 0; l < m.interface_points.size(); ++l)
      local[m.interface_points[l]] = static_cast<std::int32_t>(l);
    for (std::size_t f = 0; f < quads.size(); ++f) {
      const auto& q = quads[f];
      // Fixed diagonal q0-q2; both triangles keep the quad's winding (normal into the pocket).
      m.interface_triangles.insert(m.interface_triangles.end(),
                                   {local[q[0]], local[q[1]], local[q[2]], local[q[0]], local[q[2]], local[q[3]]});
      m.interface_triangle_side.insert(m.interface_triangle_side.end(), {quad_side[f], quad_side[f]});
    }
  }
  m.grid_x = std::move(xs);
  m.grid_y = std::move(ys);
  m.grid_z = std::move(zs);
  return m;
}

Mesh generate_mesh(const MeshParams& p) {
  validate(p);
  const bool has_inner = p.inner_size[0] > 0.0 || p.inner_size[1] > 0.0 || p.inner_size[2] > 0.0;
  std::array<double, 3> lo{0.0, 0.0, 0.0};
  std::array<double, 3> hi{0.0, 0.0, 0.0};
  const std::array<double, 3> ext{p.length, p.width, p.height};
  if (has_inner) {
    lo[0] = std::isnan(p.inner_origin[0]) ? 0.5 * (p.length - p.inner_size[0]) : p.inner_origin[0];
    lo[1] = std::isnan(p.inner_origin[1]) ? 0.5 * (p.width - p.inner_size[1]) : p.inner_origin[1];
    lo[2] = std::isnan(p.inner_origin[2]) ? p.height - p.inner_size[2] : p.inner_origin[2];
    for (int d = 0; d < 3; ++d) {
      hi[d] = lo[d] + p.inner_size[d];
      // The default top-flush placement must end exactly on the boundary.
      if (std::abs(hi[d] - ext[d]) <= 1e-12 * ext[d]) hi[d] = ext[d];
      if (lo[d] < 0.0 || hi[d] > ext[d]) {
        std::ostringstream os;
        os << "mesh.inner_origin/inner_size: the inner box must lie inside the model box on axis "
           << "xyz"[d] << ", found [" << lo[d] << ", " << hi[d] << "] m outside [0, " << ext[d] << "] m";
        fail(os.str());
      }
    }
  }
  std::vector<double> g[3];
  for (int d = 0; d < 3; ++d)
    g[d] = graded_axis(ext[d], has_inner ? lo[d] : 0.0, has_inner ? hi[d] : 0.0, p.size_near,
                       p.size_far, p.growth);
  if (!(has_inner && p.pocket)) return mesh_from_grid(std::move(g[0]), std::move(g[1]), std::move(g[2]));
  std::array<int, 6> cells{};
  for (int d = 0; d < 3; ++d) {
    const auto& ax = g[d];
    cells[2 * d] = static_cast<int>(std::find(ax.begin(), ax.end(), lo[d]) - ax.begin());
    cells[2 * d + 1] = static_cast<int>(std::find(ax.begin(), ax.end(), hi[d]) - ax.begin());
  }
  return mesh_from_grid(std::move(g[0]), std::move(g[1]), std::move(g[2]), &cells);
}

std::vector<BoundaryFace> boundary_faces(const Mesh& mesh) {
  const int nx = static_cast<int>(mesh.grid_x.size()) - 1;
  const int ny = static_cast<int>(mesh.grid_y.size()) - 1;
  const int nz = static_cast<int>(mesh.grid_z.size()) - 1;
  std::vector<std::int32_t> cell_zone(static_cast<std::size_t>(nx) * ny * nz, -1);
  for (std::size_t z = 0; z < mesh.num_zones(); ++z) {
    const auto* ijk = &mesh.zone_ijk[3 * z];
    cell_zone[(static_cast<std::size_t>(ijk[2]) * ny + ijk[1]) * nx + ijk[0]] = static_cast<std::int32_t>(z);
  }
  static constexpr int kOffset[6][3] = {{0, 0, -1}, {-1, 0, 0}, {1, 0, 0}, {0, -1, 0}, {0, 1, 0}, {0, 0, 1}};
  std::vector<BoundaryFace> out;
  for (std::size_t z = 0; z < mesh.num_zones(); ++z)
    for (int s = 0; s < 6; ++s) {
      const int i = mesh.zone_ijk[3 * z] + kOffset[s][0];
      const int j = mesh.zone_ijk[3 * z + 1] + kOffset[s][1];
      const int k = mesh.zone_ijk[3 * z + 2] + kOffset[s][2];
      const bool inside = i >= 0 && j >= 0 && k >= 0 && i < nx && j < ny && k < nz;
      if (inside && cell_zone[(static_cast<std::size_t>(k) * ny + j) * nx + i] >= 0) continue;
      BoundaryFace f;
      for (int c = 0; c < 4; ++c) f.points[c] = mesh.zones[8 * z + kHexFaces[s][c]];
      f.zone = static_cast<std::int32_t>(z);
      f.side = static_cast<Side>(s);
      out.push_back(f);
    }
  return out;
}

}  // namespace demfdm::fdm
