// Writes a small but complete run folder with the output library, for the Python checks
// (check_sample_run.py, check_plot_png.py):
//   dem.h5 + particles.xmf + bonds.xmf   3 frames, 6/5/4 particles, 5/4/3 bonds
//     + footing.xmf                      the footing's surface: none in frame 0, then an
//                                        8-segment cylinder (18 vertices, 32 triangles) moving down
//   fdm.h5 + mesh.xmf                    2 frames on a 3 x 2 x 2 hexahedron brick
//   history.h5                           50 rows of time / displacement / load
//   load_displacement_a.csv, _b.csv      two "runs" of a load-displacement curve
//   expected_shapes.json                 what was handed to the writers: file -> dataset ->
//                                        [shape, dtype], from the input arrays' sizes
// Usage: io_sample_writer <run folder>   (the folder is emptied first)
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <string>
#include <vector>

#include "demfdm/io/csv_series.hpp"
#include "demfdm/io/h5_frames.hpp"
#include "demfdm/io/results_output.hpp"

using namespace demfdm::io;

namespace {

struct Expect {
  std::map<std::string, std::map<std::string, std::string>> files;
  void add(const std::string& file, const std::string& path, std::vector<std::size_t> shape, const char* dtype) {
    std::string s = "[[";
    for (std::size_t i = 0; i < shape.size(); ++i) {
      if (i) s += ", ";
      s += std::to_string(shape[i]);
    }
    s += "], \"" + std::string(dtype) + "\"]";
    files[file][path] = s;
  }
  void save(const std::filesystem::path& p) const {
    std::ofstream o(p);
    o << "{\n";
    std::size_t fi = 0;
    for (const auto& [file, ds] : files) {
      o << "  \"" << file << "\": {\n";
      std::size_t di = 0;
      for (const auto& [path, v] : ds) o << "    \"" << path << "\": " << v << (++di < ds.size() ? ",\n" : "\n");
      o << "  }" << (++fi < files.size() ? ",\n" : "\n");
    }
    o << "}\n";
  }
};

std::string frame(int k) { return H5Frames::frame_group(static_cast<std::size_t>(k)); }

void write_dem(const std::filesystem::path& dir, Expect& ex) {
  ParticleOutput out(dir, FileInfo{"dem_node", "sample", "feedbeef", {}}, {}, {"bonds"}, "dem.h5", {"footing"});
  for (int k = 0; k < 3; ++k) {
    const std::size_t np = 6 - k;
    std::vector<double> x, r;
    std::vector<float> v;
    std::vector<std::int64_t> id;
    std::vector<std::int32_t> bonds;
    std::vector<std::uint8_t> state;
    std::vector<double> force;
    for (std::size_t i = 0; i < np; ++i) {
      x.insert(x.end(), {0.02 * static_cast<double>(i), 0.0, -0.001 * k});
      r.push_back(0.01);
      v.insert(v.end(), {0.0f, 0.0f, -0.5f * static_cast<float>(k)});
      id.push_back(static_cast<std::int64_t>(i) + 1);
    }
    for (std::size_t b = 0; b + 1 < np; ++b) {
      bonds.insert(bonds.end(), {static_cast<std::int32_t>(b), static_cast<std::int32_t>(b + 1)});
      state.push_back(static_cast<std::uint8_t>(b % 3));
      force.insert(force.end(), {1.0, 2.0, 3.0});
    }
    ParticleFrame pf;
    pf.position = ArrayView(x, 3);
    pf.point_arrays = {{"radius", ArrayView(r)}, {"velocity", ArrayView(v, 3)}, {"id", ArrayView(id)}};
    pf.links = {LinkFrame{"bonds", ArrayView(bonds, 2), {{"state", ArrayView(state)}, {"force", ArrayView(force, 3)}}}};
    const TriangleSurface footing =
        k == 0 ? TriangleSurface{} : cylinder_surface({0.05, 0.0, 0.01 - 0.001 * k}, 0.02, 0.01, 8);
    pf.surfaces = {SurfaceFrame{"footing", ArrayView(footing.vertices, 3), ArrayView(footing.triangles, 3)}};
    out.write_frame(100 * k, 0.001 * k, pf);
    const std::string g = frame(k);
    ex.add("dem.h5", g + "/particles/position", {np, 3}, "float64");
    ex.add("dem.h5", g + "/particles/radius", {np}, "float64");
    ex.add("dem.h5", g + "/particles/velocity", {np, 3}, "float32");
    ex.add("dem.h5", g + "/particles/id", {np}, "int64");
    ex.add("dem.h5", g + "/bonds/nodes", {np - 1, 2}, "int32");
    ex.add("dem.h5", g + "/bonds/state", {np - 1}, "uint8");
    ex.add("dem.h5", g + "/bonds/force", {np - 1, 3}, "float64");
    ex.add("dem.h5", g + "/footing/vertices", {footing.vertices.size() / 3, 3}, "float64");
    ex.add("dem.h5", g + "/footing/triangles", {footing.triangles.size() / 3, 3}, "int32");
  }
  ex.add("dem.h5", "/xdmf/vertex_index", {6}, "int32");
}

void write_fdm(const std::filesystem::path& dir, Expect& ex) {
  const int nx = 3, ny = 2, nz = 2;  // zones; nodes (nx+1)(ny+1)(nz+1) = 36
  auto node = [&](int i, int j, int k) { return static_cast<std::int64_t>(i + (nx + 1) * (j + (ny + 1) * k)); };
  std::vector<double> coords;
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) coords.insert(coords.end(), {0.5 * i, 0.5 * j, -0.5 * (nz - k)});
  std::vector<std::int64_t> zones;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        zones.insert(zones.end(), {node(i, j, k), node(i + 1, j, k), node(i + 1, j + 1, k), node(i, j + 1, k),
                                   node(i, j, k + 1), node(i + 1, j, k + 1), node(i + 1, j + 1, k + 1),
                                   node(i, j + 1, k + 1)});
  const std::size_t nn = coords.size() / 3, nzones = zones.size() / 8;
  MeshOutput out(dir, FileInfo{"fdm_node", "sample", "feedbeef", {}}, ArrayView(coords, 3), ArrayView(zones, 8));
  for (int f = 0; f < 2; ++f) {
    std::vector<double> disp(nn * 3, 0.0), vel(nn * 3, 0.0), stress(nzones * 6, 0.0);
    for (std::size_t n = 0; n < nn; ++n) disp[3 * n + 2] = -1e-3 * f * (coords[3 * n + 2] + 1.0);
    for (std::size_t z = 0; z < nzones; ++z) stress[6 * z + 2] = -2.0e4 * (f + 1) * static_cast<double>(z + 1);
    std::vector<std::uint8_t> plastic(nzones, static_cast<std::uint8_t>(f));
    MeshFrame mf;
    mf.node_arrays = {{"displacement", ArrayView(disp, 3)}, {"velocity", ArrayView(vel, 3)}};
    mf.zone_arrays = {{"stress", ArrayView(stress, 6)}, {"plastic_state", ArrayView(plastic)}};
    out.write_frame(50 * f, 0.0005 * (f + 1), mf);
    const std::string g = frame(f);
    ex.add("fdm.h5", g + "/nodes/displacement", {nn, 3}, "float64");
    ex.add("fdm.h5", g + "/nodes/velocity", {nn, 3}, "float64");
    ex.add("fdm.h5", g + "/zones/stress", {nzones, 6}, "float64");
    ex.add("fdm.h5", g + "/zones/plastic_state", {nzones}, "uint8");
  }
  ex.add("fdm.h5", "/mesh/node_coords", {nn, 3}, "float64");
  ex.add("fdm.h5", "/mesh/zone_nodes", {nzones, 8}, "int64");
}

void write_history(const std::filesystem::path& dir, Expect& ex) {
  H5Frames h = H5Frames::create(dir / "history.h5", FileInfo{"coordinator", "sample", "feedbeef", {}});
  h.declare_history({{"time", "s"}, {"displacement", "m"}, {"load", "N"}});
  CsvSeries a = CsvSeries::create(dir / "load_displacement_a.csv", {"time_s", "displacement_m", "load_N"});
  CsvSeries b = CsvSeries::create(dir / "load_displacement_b.csv", {"time_s", "displacement_m", "load_N"});
  const int n = 50;
  for (int i = 0; i < n; ++i) {
    const double t = 1e-4 * i, u = -1e-5 * i;
    // A softening curve, and a stiffer second "run" for the overlay.
    const double load = 2.0e3 * std::tanh(-u / 2e-4), load_b = 2.6e3 * std::tanh(-u / 1.5e-4);
    h.append_history(std::vector<double>{t, u, load});
    a.append({t, u, load});
    b.append({t, u, load_b});
  }
  h.close();
  for (const char* c : {"time", "displacement", "load"})
    ex.add("history.h5", std::string("/history/") + c, {static_cast<std::size_t>(n)}, "float64");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: io_sample_writer <run folder>\n";
    return 2;
  }
  try {
    const std::filesystem::path dir = argv[1];
    std::filesystem::remove_all(dir);
    std::filesystem::create_directories(dir);
    Expect ex;
    write_dem(dir, ex);
    write_fdm(dir, ex);
    write_history(dir, ex);
    ex.save(dir / "expected_shapes.json");
    std::cout << "io_sample_writer: wrote " << dir.string() << "\n";
  } catch (const std::exception& e) {
    std::cerr << "io_sample_writer: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
