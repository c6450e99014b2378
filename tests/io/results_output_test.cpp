// ParticleOutput / MeshOutput: a 3-frame particle + bond run and a 2-frame mesh run, read
// back with the HDF5 C API; every HDF DataItem of the sidecars is resolved against the
// HDF5 files (path, rank, sizes and element width must agree).
#include "demfdm/io/results_output.hpp"

#include <cmath>
#include <fstream>
#include <map>
#include <regex>

#include <gtest/gtest.h>

#include "demfdm/io/error.hpp"
#include "io_test_util.hpp"

namespace demfdm::io {
namespace {

using test::H5Reader;
using test::ScratchDir;

// Checks every <DataItem Dimensions=.. NumberType=.. Precision=.. Format="HDF">file:path</DataItem>
// of `xmf` against the HDF5 file it names (relative to the xmf folder). Returns the count.
std::size_t check_data_items(const std::filesystem::path& xmf) {
  const std::string x = test::slurp(xmf);
  EXPECT_EQ(test::xml_problem(x), "") << xmf;
  static const std::regex item(
      R"re(<DataItem Dimensions="([0-9 ]+)" NumberType="(\w+)" Precision="(\d)" Format="HDF">([^:<]+):([^<]+)</DataItem>)re");
  std::size_t n = 0;
  for (auto it = std::sregex_iterator(x.begin(), x.end(), item); it != std::sregex_iterator(); ++it, ++n) {
    const auto& m = *it;
    H5Reader r(xmf.parent_path() / m[4].str());
    const std::string path = m[5].str();
    EXPECT_TRUE(r.exists(path)) << path;
    if (!r.exists(path)) continue;
    std::string dims;
    for (hsize_t d : r.dims(path)) {
      if (!dims.empty()) dims += ' ';
      dims += std::to_string(d);
    }
    EXPECT_EQ(dims, m[1].str()) << path << " in " << xmf;
    H5T_class_t cls;
    std::size_t size;
    bool little;
    r.file_type(path, cls, size, little);
    EXPECT_EQ(std::to_string(size), m[3].str()) << path;
    const std::string want_type = cls == H5T_FLOAT ? "Float" : (size == 1 ? "UChar" : "Int");
    EXPECT_EQ(want_type, m[2].str()) << path;
  }
  return n;
}

struct DemFrame {
  std::vector<double> x, r;
  std::vector<double> v;
  std::vector<std::int64_t> id;
  std::vector<std::int32_t> bonds;
  std::vector<std::uint8_t> state;
  std::vector<double> bond_force;
};

// Frame k: 6 - k particles in a row, bonds between neighbours, the last one broken from k = 1.
DemFrame dem_frame(int k) {
  DemFrame f;
  const int np = 6 - k;
  for (int i = 0; i < np; ++i) {
    f.x.insert(f.x.end(), {0.02 * i, 0.0, 0.01 * k});
    f.r.push_back(0.01);
    f.v.insert(f.v.end(), {0.0, 0.0, -0.1 * k});
    f.id.push_back(i + 1);
  }
  for (int b = 0; b + 1 < np; ++b) {
    f.bonds.insert(f.bonds.end(), {b, b + 1});
    f.state.push_back(static_cast<std::uint8_t>(k > 0 && b + 2 == np ? 1 : 0));
    f.bond_force.insert(f.bond_force.end(), {1.0 * b, -1.0 * k, 0.5});
  }
  return f;
}

void write_dem_run(const std::filesystem::path& dir) {
  ParticleOutput out(dir, FileInfo{"dem_node", "test-run", "0f0f", {}});
  for (int k = 0; k < 3; ++k) {
    const DemFrame f = dem_frame(k);
    ParticleFrame pf;
    pf.position = ArrayView(f.x, 3);
    pf.point_arrays = {{"radius", ArrayView(f.r)}, {"velocity", ArrayView(f.v, 3)}, {"id", ArrayView(f.id)}};
    pf.links = {LinkFrame{"bonds", ArrayView(f.bonds, 2), {{"state", ArrayView(f.state)}, {"force", ArrayView(f.bond_force, 3)}}}};
    EXPECT_EQ(out.write_frame(100 * k, 1e-3 * k, pf), static_cast<std::size_t>(k));
  }
}

TEST(ParticleOutput, ThreeFramesWithBondsReadBackAndSidecarsResolve) {
  ScratchDir dir;
  write_dem_run(dir.path());
  H5Reader r(dir / "dem.h5");
  EXPECT_EQ(r.attr_str("/", "producer"), "dem_node");
  for (int k = 0; k < 3; ++k) {
    const DemFrame f = dem_frame(k);
    const std::string g = "/frames/00000" + std::to_string(k);
    EXPECT_EQ(r.attr_f64(g, "time"), 1e-3 * k);
    EXPECT_EQ(r.read_f64(g + "/particles/position"), f.x);
    EXPECT_EQ(r.read_f64(g + "/particles/velocity"), f.v);
    EXPECT_EQ(r.read_i64(g + "/particles/id"), f.id);
    EXPECT_EQ(r.read_i32(g + "/bonds/nodes"), f.bonds);
    EXPECT_EQ(r.read_u8(g + "/bonds/state"), f.state);
    EXPECT_EQ(r.read_f64(g + "/bonds/force"), f.bond_force);
  }
  EXPECT_EQ(r.dims("/xdmf/vertex_index"), (std::vector<hsize_t>{6}));

  const std::string px = test::slurp(dir / "particles.xmf");
  const std::string bx = test::slurp(dir / "bonds.xmf");
  EXPECT_EQ(test::count_substr(px, R"(GridType="Uniform")"), 3u);
  EXPECT_EQ(test::count_substr(bx, R"(GridType="Uniform")"), 3u);
  for (int k = 0; k < 3; ++k) {
    const std::string np = std::to_string(6 - k), nb = std::to_string(5 - k);
    EXPECT_NE(px.find("NumberOfElements=\"" + np + "\" NodesPerElement=\"1\""), std::string::npos) << k;
    EXPECT_NE(bx.find("NumberOfElements=\"" + nb + "\" NodesPerElement=\"2\""), std::string::npos) << k;
  }
  EXPECT_NE(bx.find(R"(<Attribute Name="force" AttributeType="Vector" Center="Cell">)"), std::string::npos);
  // Frame 2's data items: 1 hyperslab index + position + radius + velocity + id = 5 per frame.
  EXPECT_EQ(check_data_items(dir / "particles.xmf"), 15u);
  // Bonds: nodes + position + state + force = 4 per frame.
  EXPECT_EQ(check_data_items(dir / "bonds.xmf"), 12u);
}

TEST(ParticleOutput, IdenticalRunsGiveIdenticalFiles) {
  ScratchDir dir;
  std::filesystem::create_directories(dir / "a");
  std::filesystem::create_directories(dir / "b");
  write_dem_run(dir / "a");
  write_dem_run(dir / "b");
  for (const char* f : {"dem.h5", "particles.xmf", "bonds.xmf"})
    EXPECT_TRUE(test::slurp(dir / "a" / f) == test::slurp(dir / "b" / f)) << f << " differs between identical runs";
}

// The frames of write_dem_run written in blocks of `block` rows (the DEM on ranks merging its
// ranks' rows): the same files, byte for byte.
void write_dem_run_in_blocks(const std::filesystem::path& dir, std::size_t block) {
  ParticleOutput out(dir, FileInfo{"dem_node", "test-run", "0f0f", {}});
  for (int k = 0; k < 3; ++k) {
    const DemFrame f = dem_frame(k);
    FrameShape shape;
    shape.particles = f.r.size();
    shape.point_arrays = {{"radius", DType::kFloat64, 1}, {"velocity", DType::kFloat64, 3}, {"id", DType::kInt64, 1}};
    shape.links = {{"bonds", f.state.size(), {{"state", DType::kUInt8, 1}, {"force", DType::kFloat64, 3}}}};
    EXPECT_EQ(out.begin_blocks(100 * k, 1e-3 * k, shape), static_cast<std::size_t>(k));
    auto rows = [&](const std::string& name, const auto& v, std::size_t cols) {
      using T = typename std::decay_t<decltype(v)>::value_type;
      const std::size_t n = v.size() / cols;
      for (std::size_t r0 = 0; r0 < n; r0 += block) {
        const std::size_t m = std::min(block, n - r0);
        out.write_rows(name, r0, ArrayView(std::span<const T>(v.data() + r0 * cols, m * cols), cols));
      }
    };
    rows("particles/position", f.x, 3);
    rows("particles/radius", f.r, 1);
    rows("particles/velocity", f.v, 3);
    rows("particles/id", f.id, 1);
    rows("bonds/nodes", f.bonds, 2);
    rows("bonds/state", f.state, 1);
    rows("bonds/force", f.bond_force, 3);
    EXPECT_EQ(out.end_blocks(), static_cast<std::size_t>(k));
  }
}

TEST(ParticleOutput, AFrameWrittenInBlocksGivesTheFilesOfTheWholeFrame) {
  ScratchDir dir;
  for (const char* d : {"whole", "b1", "b2", "b9"}) std::filesystem::create_directories(dir / d);
  write_dem_run(dir / "whole");
  write_dem_run_in_blocks(dir / "b1", 1);
  write_dem_run_in_blocks(dir / "b2", 2);
  write_dem_run_in_blocks(dir / "b9", 9);
  for (const char* d : {"b1", "b2", "b9"})
    for (const char* f : {"dem.h5", "particles.xmf", "bonds.xmf"})
      EXPECT_TRUE(test::slurp(dir / "whole" / f) == test::slurp(dir / d / f)) << f << " differs in blocks of " << d;
}

TEST(ParticleOutput, BlocksOutOfOrderOutOfRangeOrMissingAreRefused) {
  ScratchDir dir;
  ParticleOutput out(dir.path(), FileInfo{"dem_node", "test-run", "0f0f", {}});
  FrameShape shape;
  shape.particles = 3;
  shape.point_arrays = {{"radius", DType::kFloat64, 1}};
  shape.links = {{"bonds", 2, {}}};
  FrameShape twice = shape;
  twice.point_arrays.push_back({"radius", DType::kFloat64, 1});
  EXPECT_THROW(out.begin_blocks(0, 0.0, twice), std::invalid_argument);
  FrameShape other = shape;
  other.links[0].name = "contacts";
  EXPECT_THROW(out.begin_blocks(0, 0.0, other), std::invalid_argument);
  ASSERT_EQ(out.begin_blocks(0, 0.0, shape), 0u);
  EXPECT_THROW(out.begin_blocks(1, 1.0, shape), std::logic_error);  // one frame at a time
  const std::vector<double> x{0, 0, 0, 1, 0, 0, 2, 0, 0}, r{1, 1, 1};
  EXPECT_THROW(out.write_rows("particles/position", 1, ArrayView(std::span<const double>(x.data(), 3), 3)),
               std::invalid_argument);  // row 0 first
  EXPECT_THROW(out.write_rows("particles/velocity", 0, ArrayView(r)), std::invalid_argument);  // no such dataset
  const std::vector<std::int32_t> bad{0, 3}, good{0, 1, 1, 2};
  EXPECT_THROW(out.write_rows("bonds/nodes", 0, ArrayView(bad, 2)), std::invalid_argument);  // row 3 of 3 balls
  const std::vector<double> four{1, 1, 1, 1};
  EXPECT_THROW(out.write_rows("particles/radius", 0, ArrayView(four)), std::invalid_argument);  // 4 rows of 3
  out.write_rows("particles/position", 0, ArrayView(x, 3));
  out.write_rows("particles/radius", 0, ArrayView(r));
  EXPECT_THROW(out.end_blocks(), std::logic_error);  // bonds/nodes has none of its 2 rows
  EXPECT_THROW(out.end_blocks(), std::logic_error);  // no frame is open
}

TEST(ParticleOutput, BadFramesAreRejectedBeforeAnythingIsWritten) {
  ScratchDir dir;
  ParticleOutput out(dir.path(), FileInfo{"dem_node", "", "", {}});
  DemFrame f = dem_frame(0);
  ParticleFrame pf;
  pf.position = ArrayView(f.x, 3);
  pf.point_arrays = {{"radius", ArrayView(f.r)}};
  std::vector<std::int32_t> bad_bonds = f.bonds;
  bad_bonds.back() = 6;  // row 6 of 6 particles: out of range
  pf.links = {LinkFrame{"bonds", ArrayView(bad_bonds, 2), {}}};
  try {
    out.write_frame(0, 0.0, pf);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("outside [0, 6)"), std::string::npos) << e.what();
  }
  pf.links = {LinkFrame{"bonds", ArrayView(f.bonds, 2), {}}};
  std::vector<double> short_r(5, 0.01);
  pf.point_arrays = {{"radius", ArrayView(short_r)}};
  EXPECT_THROW(out.write_frame(0, 0.0, pf), std::invalid_argument);
  pf.point_arrays = {{"radius", ArrayView(f.r)}};
  pf.links = {};
  EXPECT_THROW(out.write_frame(0, 0.0, pf), std::invalid_argument) << "declared link set missing";
  EXPECT_EQ(out.h5().frame_count(), 0u);
  EXPECT_FALSE(std::filesystem::exists(dir / "particles.xmf"));
  pf.links = {LinkFrame{"bonds", ArrayView(f.bonds, 2), {}}};
  out.write_frame(0, 0.0, pf);
  EXPECT_THROW(out.write_frame(1, 0.0, pf), std::invalid_argument) << "time must increase";
  EXPECT_EQ(out.h5().frame_count(), 1u);
}

TEST(ParticleOutput, RefusesToOverwriteAnEarlierRun) {
  ScratchDir dir;
  { std::ofstream(dir / "bonds.xmf") << "old"; }
  try {
    ParticleOutput out(dir.path(), FileInfo{"dem_node", "", "", {}});
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("bonds.xmf"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "dem.h5")) << "nothing is created when a target exists";
  EXPECT_EQ(test::slurp(dir / "bonds.xmf"), "old");
}

// A 2 x 1 x 1 brick of unit hexahedra: nodes on a 3 x 2 x 2 lattice, VTK order per zone.
struct Brick {
  std::vector<double> coords;
  std::vector<std::int64_t> zones;
};
Brick brick_vtk() {
  Brick b;
  auto node = [](int i, int j, int k) { return static_cast<std::int64_t>(i + 3 * (j + 2 * k)); };
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < 2; ++j)
      for (int i = 0; i < 3; ++i) b.coords.insert(b.coords.end(), {1.0 * i, 1.0 * j, 1.0 * k});
  for (int i = 0; i < 2; ++i)
    b.zones.insert(b.zones.end(), {node(i, 0, 0), node(i + 1, 0, 0), node(i + 1, 1, 0), node(i, 1, 0),
                                   node(i, 0, 1), node(i + 1, 0, 1), node(i + 1, 1, 1), node(i, 1, 1)});
  return b;
}

TEST(MeshOutput, HexMeshFramesReadBackAndSidecarResolves) {
  ScratchDir dir;
  const Brick b = brick_vtk();
  MeshOutput out(dir.path(), FileInfo{"fdm_node", "test-run", "0f0f", {}}, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
  EXPECT_EQ(out.node_count(), 12u);
  EXPECT_EQ(out.zone_count(), 2u);
  std::vector<std::vector<double>> stresses;
  for (int k = 0; k < 2; ++k) {
    std::vector<double> disp(12 * 3), vel(12 * 3), stress(2 * 6);
    for (std::size_t i = 0; i < disp.size(); ++i) disp[i] = -1e-4 * k * static_cast<double>(i % 3 == 2);
    for (std::size_t i = 0; i < vel.size(); ++i) vel[i] = 0.01 * k;
    for (std::size_t i = 0; i < stress.size(); ++i) stress[i] = -1e5 * (k + 1) * static_cast<double>(i + 1);
    std::vector<std::uint8_t> plastic{static_cast<std::uint8_t>(k), 0};
    MeshFrame mf;
    mf.node_arrays = {{"displacement", ArrayView(disp, 3)}, {"velocity", ArrayView(vel, 3)}};
    mf.zone_arrays = {{"stress", ArrayView(stress, 6)}, {"plastic_state", ArrayView(plastic)}};
    out.write_frame(10 * k, 0.01 * (k + 1), mf);
    stresses.push_back(stress);
  }
  H5Reader r(dir / "fdm.h5");
  EXPECT_EQ(r.attr_str("/", "stress_components"), "xx yy zz xy yz xz");
  EXPECT_EQ(r.attr_str("/", "stress_unit"), "Pa");
  EXPECT_EQ(r.attr_str("/mesh/zone_nodes", "zone_type"), "hexahedron8-vtk-order");
  EXPECT_EQ(r.read_f64("/mesh/node_coords"), b.coords);
  EXPECT_EQ(r.read_i64("/mesh/zone_nodes"), b.zones);
  EXPECT_EQ(r.read_f64("/frames/000001/zones/stress"), stresses[1]);
  EXPECT_EQ(r.dims("/frames/000001/zones/stress"), (std::vector<hsize_t>{2, 6}));
  const std::string mx = test::slurp(dir / "mesh.xmf");
  EXPECT_EQ(test::count_substr(mx, R"(<Attribute Name="stress" AttributeType="Matrix" Center="Cell">)"), 2u);
  EXPECT_EQ(test::count_substr(mx, R"(<Attribute Name="plastic_state" AttributeType="Scalar" Center="Cell">)"), 2u);
  EXPECT_EQ(test::count_substr(mx, R"(<Topology TopologyType="Hexahedron" NumberOfElements="2">)"), 2u);
  // Per frame: zone_nodes + node_coords + displacement + velocity + stress + plastic_state.
  EXPECT_EQ(check_data_items(dir / "mesh.xmf"), 12u);
}

TEST(MeshOutput, MirroredZonesAndBadIndicesAreRejected) {
  ScratchDir dir;
  Brick b = brick_vtk();
  std::swap(b.zones[1], b.zones[3]);  // zone 0 bottom face clockwise: mirrored
  try {
    MeshOutput out(dir.path(), FileInfo{"fdm_node", "", "", {}}, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("zone 0 is not in VTK hexahedron order"), std::string::npos) << e.what();
  }
  b = brick_vtk();
  b.zones[15] = 12;
  EXPECT_THROW(MeshOutput(dir.path(), FileInfo{"fdm_node", "", "", {}}, ArrayView(b.coords, 3), ArrayView(b.zones, 8)),
               std::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(dir / "fdm.h5"));
}

TEST(MeshOutput, CurrentPositionsBecomeTheGeometry) {
  ScratchDir dir;
  const Brick b = brick_vtk();
  MeshOutput out(dir.path(), FileInfo{"fdm_node", "", "", {}}, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
  MeshFrame mf;
  mf.node_arrays = {{"position", ArrayView(b.coords, 3)}};
  out.write_frame(0, 0.0, mf);
  const std::string mx = test::slurp(dir / "mesh.xmf");
  EXPECT_NE(mx.find(">fdm.h5:/frames/000000/nodes/position</DataItem>\n        </Geometry>"), std::string::npos) << mx;
  EXPECT_EQ(mx.find("<Attribute Name=\"position\""), std::string::npos);
  EXPECT_EQ(check_data_items(dir / "mesh.xmf"), 2u);
}

// ---------------------------------------------------------------------------------------
// Resume: an uninterrupted reference against a run that crashed after frame k-1's
// checkpoint (having written two more frames) and was resumed at frame k.

const std::vector<std::string> kResumeRoots{"/frames", "/mesh", "/xdmf"};

// Particle counts per frame go up and down, so the vertex index grows in some frames only.
constexpr int kParticles[5] = {3, 5, 4, 6, 2};

// Frame k with np particles; point arrays and bond arrays in a non-alphabetical order.
void write_particle_frame(ParticleOutput& out, int k, int np) {
  std::vector<double> x, r, v;
  std::vector<std::int64_t> id;
  std::vector<std::int32_t> bonds, contacts;
  std::vector<std::uint8_t> state;
  std::vector<double> force, normal;
  for (int i = 0; i < np; ++i) {
    x.insert(x.end(), {0.02 * i, 0.001 * k, 0.01 * k});
    r.push_back(0.01 + 1e-4 * i);
    v.insert(v.end(), {0.0, 0.1 * i, -0.1 * k});
    id.push_back(10 * k + i);
  }
  for (int b = 0; b + 1 < np; ++b) {
    bonds.insert(bonds.end(), {b, b + 1});
    state.push_back(static_cast<std::uint8_t>((b + k) % 3));
    force.insert(force.end(), {1.0 * b, -1.0 * k, 0.5});
  }
  for (int c = 0; c + 2 < np; c += 2) {
    contacts.insert(contacts.end(), {c, c + 2});
    normal.push_back(1e3 * (c + k));
  }
  ParticleFrame pf;
  pf.position = ArrayView(x, 3);
  pf.point_arrays = {{"radius", ArrayView(r)}, {"velocity", ArrayView(v, 3)}, {"id", ArrayView(id)}};
  pf.links = {LinkFrame{"bonds", ArrayView(bonds, 2), {{"state", ArrayView(state)}, {"force", ArrayView(force, 3)}}},
              LinkFrame{"contacts", ArrayView(contacts, 2), {{"normal_force", ArrayView(normal)}}}};
  out.write_frame(100 * k, 1e-3 * (k + 1), pf);
}

TEST(ParticleOutput, ResumedRunWritesTheFilesOfAnUninterruptedRun) {
  ScratchDir dir;
  const std::vector<std::string> links{"bonds", "contacts"};
  const std::vector<std::string> sidecars{"particles.xmf", "bonds.xmf", "contacts.xmf"};
  const FileInfo info{"dem_node", "run", "hash", {}};
  const auto ref_dir = dir / "ref";
  std::filesystem::create_directories(ref_dir);
  std::vector<std::vector<std::string>> ref_xmf;  // [frame][sidecar] after each frame
  {
    ParticleOutput ref(ref_dir, info, {}, links);
    for (int k = 0; k < 5; ++k) {
      write_particle_frame(ref, k, kParticles[k]);
      ref_xmf.emplace_back();
      for (const auto& x : sidecars) ref_xmf.back().push_back(test::slurp(ref_dir / x));
    }
  }
  const auto want = test::stored_contents(ref_dir / "dem.h5", kResumeRoots);
  ASSERT_GT(want.size(), 5u * 9u);

  for (const int k : {0, 2, 4}) {
    const auto run = dir / ("resumed-at-" + std::to_string(k));
    std::filesystem::create_directories(run);
    {
      ParticleOutput crashed(run, info, {}, links);
      for (int i = 0; i < k; ++i) write_particle_frame(crashed, i, kParticles[i]);
      // Written after the checkpoint and lost with the crash: more particles than any
      // kept frame, so the vertex index grew beyond what the resumed run may keep.
      write_particle_frame(crashed, k, 9);
      write_particle_frame(crashed, k + 1, 7);
    }
    ParticleOutput out = ParticleOutput::resume(run, {}, links, static_cast<std::size_t>(k));
    EXPECT_EQ(out.h5().frame_count(), static_cast<std::size_t>(k));
    for (std::size_t s = 0; s < sidecars.size(); ++s) {
      if (k == 0) {
        EXPECT_FALSE(std::filesystem::exists(run / sidecars[s])) << "no sidecar before a first frame";
      } else {
        EXPECT_TRUE(test::slurp(run / sidecars[s]) == ref_xmf[k - 1][s]) << sidecars[s] << " rebuilt at frame " << k;
      }
    }
    if (k > 0) {
      EXPECT_THROW(write_particle_frame(out, k - 1, 3), std::invalid_argument) << "time must still increase";
    }
    for (int i = k; i < 5; ++i) {
      write_particle_frame(out, i, kParticles[i]);
      for (std::size_t s = 0; s < sidecars.size(); ++s)
        EXPECT_TRUE(test::slurp(run / sidecars[s]) == ref_xmf[i][s]) << sidecars[s] << " after frame " << i
                                                                 << ", resumed at " << k;
    }
    out.h5().close();
    EXPECT_EQ(test::contents_diff(want, test::stored_contents(run / "dem.h5", kResumeRoots)), "") << "resumed at " << k;
  }
}

TEST(ParticleOutput, ResumeRefusesOtherLinkSetsAndMissingFrames) {
  ScratchDir dir;
  {
    ParticleOutput out(dir.path(), FileInfo{"dem_node", "", "", {}}, {}, {"bonds", "contacts"});
    for (int k = 0; k < 2; ++k) write_particle_frame(out, k, kParticles[k]);
  }
  EXPECT_THROW(ParticleOutput::resume(dir.path(), {}, {"bonds", "contacts"}, 3), IoError);
  try {
    ParticleOutput::resume(dir.path(), {}, {"bonds"}, 2);
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("contacts/nodes"), std::string::npos) << e.what();
  }
  EXPECT_THROW(ParticleOutput::resume(dir.path(), {}, {"bonds", "bonds"}, 2), std::invalid_argument);
  EXPECT_THROW(MeshOutput::resume(dir.path(), 1, {}, "dem.h5"), IoError) << "no mesh in a particle file";
}

// Frame k of the brick: moving node positions written between the other node arrays.
void write_mesh_frame(MeshOutput& out, const Brick& b, int k, double scale = 1.0) {
  std::vector<double> vel(12 * 3), pos = b.coords, disp(12 * 3), stress(2 * 6);
  for (std::size_t i = 0; i < vel.size(); ++i) vel[i] = scale * 0.01 * k * static_cast<double>(i);
  for (std::size_t i = 0; i < disp.size(); ++i) disp[i] = -scale * 1e-4 * k * static_cast<double>(i % 3 == 2);
  for (std::size_t i = 0; i < pos.size(); ++i) pos[i] += disp[i];
  for (std::size_t i = 0; i < stress.size(); ++i) stress[i] = -scale * 1e5 * (k + 1) * static_cast<double>(i + 1);
  std::vector<std::uint8_t> plastic{static_cast<std::uint8_t>(k % 2), 1};
  MeshFrame mf;
  mf.node_arrays = {
      {"velocity", ArrayView(vel, 3)}, {"position", ArrayView(pos, 3)}, {"displacement", ArrayView(disp, 3)}};
  mf.zone_arrays = {{"stress", ArrayView(stress, 6)}, {"plastic_state", ArrayView(plastic)}};
  out.write_frame(10 * k, 0.25 * (k + 1), mf);
}

TEST(MeshOutput, ResumedRunWritesTheFilesOfAnUninterruptedRun) {
  ScratchDir dir;
  const Brick b = brick_vtk();
  const FileInfo info{"fdm_node", "run", "hash", {}};
  const auto ref_dir = dir / "ref";
  std::filesystem::create_directories(ref_dir);
  std::vector<std::string> ref_xmf;
  {
    MeshOutput ref(ref_dir, info, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
    for (int k = 0; k < 4; ++k) {
      write_mesh_frame(ref, b, k);
      ref_xmf.push_back(test::slurp(ref_dir / "mesh.xmf"));
    }
  }
  const auto want = test::stored_contents(ref_dir / "fdm.h5", kResumeRoots);

  for (const int k : {0, 1, 3}) {
    const auto run = dir / ("resumed-at-" + std::to_string(k));
    std::filesystem::create_directories(run);
    {
      MeshOutput crashed(run, info, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
      for (int i = 0; i < k; ++i) write_mesh_frame(crashed, b, i);
      write_mesh_frame(crashed, b, k, 3.0);  // lost with the crash
      write_mesh_frame(crashed, b, k + 1, 3.0);
    }
    MeshOutput out = MeshOutput::resume(run, static_cast<std::size_t>(k));
    EXPECT_EQ(out.node_count(), 12u);
    EXPECT_EQ(out.zone_count(), 2u);
    if (k == 0) {
      EXPECT_FALSE(std::filesystem::exists(run / "mesh.xmf"));
    } else {
      EXPECT_TRUE(test::slurp(run / "mesh.xmf") == ref_xmf[k - 1]) << "rebuilt at frame " << k;
    }
    for (int i = k; i < 4; ++i) {
      write_mesh_frame(out, b, i);
      EXPECT_TRUE(test::slurp(run / "mesh.xmf") == ref_xmf[i]) << "after frame " << i << ", resumed at " << k;
    }
    out.h5().close();
    EXPECT_EQ(test::contents_diff(want, test::stored_contents(run / "fdm.h5", kResumeRoots)), "") << "resumed at " << k;
  }
}

// ---------------------------------------------------------------------------------------
// Surfaces (the footing) and frames whose times are set afterwards (docs/output.md "Time").

// Frame k of a run with the footing: 4 particles; frame 0 has no footing yet (empty surface),
// later frames a cylinder that moves down by 1e-4 per frame.
void write_footing_frame(ParticleOutput& out, int k, double time) {
  std::vector<double> x, r;
  std::vector<std::int32_t> bonds{0, 1, 2, 3};
  std::vector<std::uint8_t> state{0, static_cast<std::uint8_t>(k % 3)};
  for (int i = 0; i < 4; ++i) {
    x.insert(x.end(), {1e-3 * i, 0.0, -1e-3});
    r.push_back(5e-4);
  }
  const TriangleSurface footing =
      k == 0 ? TriangleSurface{} : cylinder_surface({1.5e-3, 0.0, -1e-4 * k}, 1e-3, 5e-4, 8);
  ParticleFrame pf;
  pf.position = ArrayView(x, 3);
  pf.point_arrays = {{"radius", ArrayView(r)}};
  pf.links = {LinkFrame{"bonds", ArrayView(bonds, 2), {{"state", ArrayView(state)}}}};
  pf.surfaces = {SurfaceFrame{"footing", ArrayView(footing.vertices, 3), ArrayView(footing.triangles, 3)}};
  out.write_frame(10 * k, time, pf);
}

TEST(ParticleOutput, FootingSurfaceFramesReadBackSidecarResolvesAndResumes) {
  ScratchDir dir;
  const FileInfo info{"dem_node", "run", "hash", {}};
  const std::vector<std::string> links{"bonds"}, surfaces{"footing"};
  std::vector<std::string> ref_xmf;
  {
    ParticleOutput out(dir.path(), info, {}, links, "dem.h5", surfaces);
    for (int k = 0; k < 3; ++k) {
      write_footing_frame(out, k, 1e-3 * k);
      ref_xmf.push_back(test::slurp(dir / "footing.xmf"));
    }
    EXPECT_EQ(out.surface_sidecar(0).frames(), 3u);
  }
  {
    H5Reader r(dir / "dem.h5");
    EXPECT_EQ(r.dims("/frames/000000/footing/vertices"), (std::vector<hsize_t>{0, 3}));
    EXPECT_EQ(r.dims("/frames/000000/footing/triangles"), (std::vector<hsize_t>{0, 3}));
    const TriangleSurface c2 = cylinder_surface({1.5e-3, 0.0, -2e-4}, 1e-3, 5e-4, 8);
    EXPECT_EQ(r.read_f64("/frames/000002/footing/vertices"), c2.vertices);
    EXPECT_EQ(r.read_i32("/frames/000002/footing/triangles"), c2.triangles);
  }

  const std::string fx = ref_xmf.back();
  EXPECT_EQ(test::count_substr(fx, R"(GridType="Uniform")"), 3u);
  EXPECT_EQ(test::count_substr(fx, R"(<Topology TopologyType="Triangle" NumberOfElements="0">)"), 1u);
  EXPECT_EQ(test::count_substr(fx, R"(<Topology TopologyType="Triangle" NumberOfElements="32">)"), 2u);
  // Connectivity + geometry per frame.
  EXPECT_EQ(check_data_items(dir / "footing.xmf"), 6u);

  // A resumed run rebuilds footing.xmf from the file alone, and refuses other surface sets.
  {
    ParticleOutput out = ParticleOutput::resume(dir.path(), {}, links, 2, "dem.h5", surfaces);
    EXPECT_TRUE(test::slurp(dir / "footing.xmf") == ref_xmf[1]);
    write_footing_frame(out, 2, 2e-3);
    EXPECT_TRUE(test::slurp(dir / "footing.xmf") == ref_xmf[2]);
  }
  EXPECT_THROW(ParticleOutput::resume(dir.path(), {}, links, 3), IoError) << "footing datasets of no declared set";
  EXPECT_THROW(ParticleOutput::resume(dir.path(), {}, links, 3, "dem.h5", {"lid"}), IoError);
  EXPECT_THROW(ParticleOutput::resume(dir.path(), {}, links, 3, "dem.h5", {"bonds"}), std::invalid_argument);
}

TEST(ParticleOutput, BadSurfacesAreRejectedBeforeAnythingIsWritten) {
  ScratchDir dir;
  ParticleOutput out(dir.path(), FileInfo{"dem_node", "", "", {}}, {}, {"bonds"}, "dem.h5", {"footing"});
  std::vector<double> x{0, 0, 0, 1, 0, 0}, v{0, 0, 0, 1, 0, 0, 0, 1, 0};
  std::vector<std::int32_t> b{0, 1}, tri{0, 1, 3};
  ParticleFrame pf;
  pf.position = ArrayView(x, 3);
  pf.links = {LinkFrame{"bonds", ArrayView(b, 2), {}}};
  EXPECT_THROW(out.write_frame(0, 0.0, pf), std::invalid_argument) << "the declared surface is missing";
  pf.surfaces = {SurfaceFrame{"lid", ArrayView(v, 3), ArrayView(tri, 3)}};
  EXPECT_THROW(out.write_frame(0, 0.0, pf), std::invalid_argument) << "another name";
  pf.surfaces = {SurfaceFrame{"footing", ArrayView(v, 3), ArrayView(tri, 3)}};
  EXPECT_THROW(out.write_frame(0, 0.0, pf), std::invalid_argument) << "vertex row 3 of 3";
  EXPECT_EQ(out.h5().frame_count(), 0u);
  EXPECT_FALSE(std::filesystem::exists(dir / "footing.xmf"));
  tri[2] = 2;
  EXPECT_EQ(out.write_frame(0, 0.0, pf), 0u);
  EXPECT_TRUE(std::filesystem::exists(dir / "footing.xmf"));
}

TEST(ParticleOutput, RetimedFramesEqualFramesWrittenWithThoseTimes) {
  ScratchDir dir;
  const FileInfo info{"dem_node", "run", "hash", {}};
  const std::vector<std::string> links{"bonds"}, surfaces{"footing"};
  const std::vector<std::string> sidecars{"particles.xmf", "bonds.xmf", "footing.xmf"};
  // Model times: the preparation frames before the origin are negative, the origin frame 0.
  const std::vector<double> node{0.75, 0.8125, 1.0}, model{-0.25, -0.1875, 0.0};
  const auto direct = dir / "direct", retimed = dir / "retimed";
  std::filesystem::create_directories(direct);
  std::filesystem::create_directories(retimed);
  {
    ParticleOutput out(direct, info, {}, links, "dem.h5", surfaces);
    for (int k = 0; k < 3; ++k) write_footing_frame(out, k, model[k]);
    write_footing_frame(out, 3, 0.5);
  }
  {
    ParticleOutput out(retimed, info, {}, links, "dem.h5", surfaces);
    for (int k = 0; k < 3; ++k) write_footing_frame(out, k, node[k]);
    EXPECT_THROW(out.retime_frames(std::vector<double>{-1.0, 0.0}), std::invalid_argument) << "one time per frame";
    EXPECT_THROW(out.retime_frames(std::vector<double>{-1.0, -1.0, 0.0}), std::invalid_argument) << "increasing";
    out.retime_frames(model);
    EXPECT_THROW(write_footing_frame(out, 3, 0.0), std::invalid_argument) << "after the last retimed time";
    write_footing_frame(out, 3, 0.5);
  }
  H5Reader r(retimed / "dem.h5");
  for (int k = 0; k < 3; ++k) EXPECT_EQ(r.attr_f64("/frames/00000" + std::to_string(k), "time"), model[k]);
  EXPECT_EQ(test::contents_diff(test::stored_contents(direct / "dem.h5", kResumeRoots),
                                test::stored_contents(retimed / "dem.h5", kResumeRoots)),
            "");
  for (const auto& x : sidecars) EXPECT_TRUE(test::slurp(direct / x) == test::slurp(retimed / x)) << x;
  EXPECT_NE(test::slurp(retimed / "particles.xmf").find(R"(<Time Value="-0.1875"/>)"), std::string::npos);
}

TEST(MeshOutput, RetimedFramesEqualFramesWrittenWithThoseTimes) {
  ScratchDir dir;
  const Brick b = brick_vtk();
  const FileInfo info{"fdm_node", "run", "hash", {}};
  const auto direct = dir / "direct", retimed = dir / "retimed";
  std::filesystem::create_directories(direct);
  std::filesystem::create_directories(retimed);
  // write_mesh_frame(k) writes time 0.25 (k + 1); the retimed run moves frames 0 and 1 there.
  {
    MeshOutput out(direct, info, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
    for (int k = 0; k < 3; ++k) write_mesh_frame(out, b, k);
  }
  {
    MeshOutput out(retimed, info, ArrayView(b.coords, 3), ArrayView(b.zones, 8));
    out.retime_frames({});  // nothing written yet: nothing to do
    EXPECT_FALSE(std::filesystem::exists(retimed / "mesh.xmf"));
    for (int k = 0; k < 2; ++k) write_mesh_frame(out, b, k);
    out.retime_frames(std::vector<double>{0.0625, 0.125});
    EXPECT_NE(test::slurp(retimed / "mesh.xmf").find(R"(<Time Value="0.0625"/>)"), std::string::npos);
    out.retime_frames(std::vector<double>{0.25, 0.5});
    write_mesh_frame(out, b, 2);
  }
  EXPECT_EQ(test::contents_diff(test::stored_contents(direct / "fdm.h5", kResumeRoots),
                                test::stored_contents(retimed / "fdm.h5", kResumeRoots)),
            "");
  EXPECT_TRUE(test::slurp(direct / "mesh.xmf") == test::slurp(retimed / "mesh.xmf"));
}

TEST(CylinderSurface, ClosedOutwardOrientedAndOfTheGivenSize) {
  const int n = 12;
  const double d = 0.4e-3, h = 0.2e-3;
  const std::array<double, 3> c{1e-3, 2e-3, 6.8e-3};
  const TriangleSurface s = cylinder_surface(c, d, h, n);
  ASSERT_EQ(s.vertices.size(), 3u * (2 * n + 2));
  ASSERT_EQ(s.triangles.size(), 3u * 4 * n);
  // Every directed edge once, and its reverse once: a closed, consistently oriented surface.
  std::map<std::pair<int, int>, int> edges;
  for (std::size_t t = 0; t < s.triangles.size(); t += 3)
    for (int e = 0; e < 3; ++e) ++edges[{s.triangles[t + e], s.triangles[t + (e + 1) % 3]}];
  for (const auto& [e, count] : edges) {
    EXPECT_EQ(count, 1) << e.first << "->" << e.second;
    EXPECT_EQ(edges.count({e.second, e.first}), 1u) << e.first << "->" << e.second;
  }
  // Enclosed volume (divergence theorem) = the n-gon prism's, positive for outward normals.
  auto v = [&](int i, int k) { return s.vertices[3 * i + k] - c[k]; };
  double vol = 0;
  for (std::size_t t = 0; t < s.triangles.size(); t += 3) {
    const int a = s.triangles[t], b = s.triangles[t + 1], q = s.triangles[t + 2];
    vol += (v(a, 0) * (v(b, 1) * v(q, 2) - v(b, 2) * v(q, 1)) - v(a, 1) * (v(b, 0) * v(q, 2) - v(b, 2) * v(q, 0)) +
            v(a, 2) * (v(b, 0) * v(q, 1) - v(b, 1) * v(q, 0))) /
           6;
  }
  const double pi = std::acos(-1.0);
  EXPECT_NEAR(vol, n / 2.0 * (d / 2) * (d / 2) * std::sin(2 * pi / n) * h, 1e-24);
  double zmin = 1e9, zmax = -1e9, rmax = 0;
  for (int i = 0; i < 2 * n + 2; ++i) {
    zmin = std::min(zmin, s.vertices[3 * i + 2]);
    zmax = std::max(zmax, s.vertices[3 * i + 2]);
    rmax = std::max(rmax, std::hypot(v(i, 0), v(i, 1)));
  }
  EXPECT_EQ(zmin, c[2]);
  EXPECT_DOUBLE_EQ(zmax, c[2] + h);
  EXPECT_DOUBLE_EQ(rmax, d / 2);
  EXPECT_THROW(cylinder_surface(c, 0.0, h), std::invalid_argument);
  EXPECT_THROW(cylinder_surface(c, d, h, 2), std::invalid_argument);
}

}  // namespace
}  // namespace demfdm::io
