// XdmfSidecar: the emitted XML against the skeletons verified in ParaView 5.11 (docs/output.md O18-O26).
#include "demfdm/io/xdmf_sidecar.hpp"

#include <gtest/gtest.h>

#include "demfdm/io/error.hpp"
#include "io_test_util.hpp"

namespace demfdm::io {
namespace {

using test::ScratchDir;

DatasetRef ref(const std::filesystem::path& file, std::string path, DType t, std::size_t rows, std::size_t cols = 1) {
  return DatasetRef{file, std::move(path), t, rows, cols};
}

// The verified particles.xmf (docs/output.md O19), frame 1 (t = 0.001 s, 285 of 288 particles).
const char* const kVerifiedParticles = R"(<?xml version="1.0" ?>
<Xdmf Version="3.0">
  <Domain>
    <Grid Name="particles" GridType="Collection" CollectionType="Temporal">
      <Grid Name="particles" GridType="Uniform">
        <Time Value="0.001"/>
        <Topology TopologyType="Polyvertex" NumberOfElements="285" NodesPerElement="1">
          <DataItem ItemType="HyperSlab" Dimensions="285" NumberType="Int" Precision="4">
            <DataItem Dimensions="3 1" Format="XML">0 1 285</DataItem>
            <DataItem Dimensions="288" NumberType="Int" Precision="4" Format="HDF">dem.h5:/xdmf/vertex_index</DataItem>
          </DataItem>
        </Topology>
        <Geometry GeometryType="XYZ">
          <DataItem Dimensions="285 3" NumberType="Float" Precision="8" Format="HDF">dem.h5:/frames/000001/particles/position</DataItem>
        </Geometry>
        <Attribute Name="radius" AttributeType="Scalar" Center="Node">
          <DataItem Dimensions="285" NumberType="Float" Precision="8" Format="HDF">dem.h5:/frames/000001/particles/radius</DataItem>
        </Attribute>
        <Attribute Name="velocity" AttributeType="Vector" Center="Node">
          <DataItem Dimensions="285 3" NumberType="Float" Precision="4" Format="HDF">dem.h5:/frames/000001/particles/velocity</DataItem>
        </Attribute>
        <Attribute Name="id" AttributeType="Scalar" Center="Node">
          <DataItem Dimensions="285" NumberType="Int" Precision="8" Format="HDF">dem.h5:/frames/000001/particles/id</DataItem>
        </Attribute>
      </Grid>
    </Grid>
  </Domain>
</Xdmf>
)";

TEST(XdmfSidecar, ParticlesMatchVerifiedSkeletonExactly) {
  ScratchDir dir;
  const auto h5 = dir / "dem.h5";
  XdmfSidecar s(dir / "particles.xmf", "particles");
  XdmfGrid g;
  g.time = 0.001;
  g.topology = XdmfTopology::kPolyvertex;
  g.elements = 285;
  g.connectivity = ref(h5, "/xdmf/vertex_index", DType::kInt32, 288);
  g.geometry = ref(h5, "/frames/000001/particles/position", DType::kFloat64, 285, 3);
  g.attributes.push_back(XdmfAttribute::node("radius", ref(h5, "/frames/000001/particles/radius", DType::kFloat64, 285)));
  g.attributes.push_back(
      XdmfAttribute::node("velocity", ref(h5, "/frames/000001/particles/velocity", DType::kFloat32, 285, 3)));
  g.attributes.push_back(XdmfAttribute::node("id", ref(h5, "/frames/000001/particles/id", DType::kInt64, 285)));
  s.append(g);
  EXPECT_EQ(s.xml(), kVerifiedParticles);
  s.write();
  EXPECT_EQ(test::slurp(dir / "particles.xmf"), kVerifiedParticles);
  EXPECT_FALSE(std::filesystem::exists(dir / "particles.xmf.tmp")) << "the temporary must be renamed away";
}

TEST(XdmfSidecar, BondsAndMeshMatchVerifiedSkeletons) {
  ScratchDir dir;
  const auto dem = dir / "dem.h5", fdm = dir / "fdm.h5";
  XdmfSidecar bonds(dir / "bonds.xmf", "bonds");
  XdmfGrid b;
  b.time = 0.001;
  b.topology = XdmfTopology::kPolyline;
  b.elements = 711;
  b.connectivity = ref(dem, "/frames/000001/bonds/nodes", DType::kInt32, 711, 2);
  b.geometry = ref(dem, "/frames/000001/particles/position", DType::kFloat64, 285, 3);
  b.attributes.push_back(XdmfAttribute::cell("state", ref(dem, "/frames/000001/bonds/state", DType::kUInt8, 711)));
  bonds.append(b);
  const std::string bx = bonds.xml();
  for (const char* line : {
           R"(<Topology TopologyType="Polyline" NumberOfElements="711" NodesPerElement="2">)",
           R"(<DataItem Dimensions="711 2" NumberType="Int" Precision="4" Format="HDF">dem.h5:/frames/000001/bonds/nodes</DataItem>)",
           R"(<DataItem Dimensions="285 3" NumberType="Float" Precision="8" Format="HDF">dem.h5:/frames/000001/particles/position</DataItem>)",
           R"(<Attribute Name="state" AttributeType="Scalar" Center="Cell">)",
           R"(<DataItem Dimensions="711" NumberType="UChar" Precision="1" Format="HDF">dem.h5:/frames/000001/bonds/state</DataItem>)"})
    EXPECT_NE(bx.find(line), std::string::npos) << "missing: " << line << "\nin:\n" << bx;

  XdmfSidecar mesh(dir / "mesh.xmf", "mesh");
  XdmfGrid m;
  m.time = 0.001;
  m.topology = XdmfTopology::kHexahedron;
  m.elements = 288;
  m.connectivity = ref(fdm, "/mesh/zone_nodes", DType::kInt64, 288, 8);
  m.geometry = ref(fdm, "/mesh/node_coords", DType::kFloat64, 455, 3);
  m.attributes.push_back(XdmfAttribute::node("displacement", ref(fdm, "/frames/000001/nodes/displacement", DType::kFloat64, 455, 3)));
  m.attributes.push_back(XdmfAttribute::cell("stress", ref(fdm, "/frames/000001/zones/stress", DType::kFloat64, 288, 6)));
  mesh.append(m);
  const std::string mx = mesh.xml();
  for (const char* line : {
           R"(<Topology TopologyType="Hexahedron" NumberOfElements="288">)",
           R"(<DataItem Dimensions="288 8" NumberType="Int" Precision="8" Format="HDF">fdm.h5:/mesh/zone_nodes</DataItem>)",
           R"(<DataItem Dimensions="455 3" NumberType="Float" Precision="8" Format="HDF">fdm.h5:/mesh/node_coords</DataItem>)",
           R"(<Attribute Name="displacement" AttributeType="Vector" Center="Node">)",
           R"(<Attribute Name="stress" AttributeType="Matrix" Center="Cell">)",
           R"(<DataItem Dimensions="288 6" NumberType="Float" Precision="8" Format="HDF">fdm.h5:/frames/000001/zones/stress</DataItem>)"})
    EXPECT_NE(mx.find(line), std::string::npos) << "missing: " << line << "\nin:\n" << mx;
  EXPECT_EQ(mx.find("Tensor6"), std::string::npos) << "docs/output.md O21: never Tensor6";
  EXPECT_EQ(test::xml_problem(bx), "");
  EXPECT_EQ(test::xml_problem(mx), "");
}

TEST(XdmfSidecar, GrowingIndexRestatesItsLengthInEveryFrame) {
  ScratchDir dir;
  const auto h5 = dir / "dem.h5";
  XdmfSidecar s(dir / "particles.xmf", "particles");
  for (std::size_t k = 0; k < 3; ++k) {
    const std::size_t n = 10 + 5 * k;  // 10, 15, 20 particles: the index grows each frame
    XdmfGrid g;
    g.time = 0.5 * static_cast<double>(k);
    g.elements = n;
    g.connectivity = ref(h5, "/xdmf/vertex_index", DType::kInt32, n);
    g.geometry = ref(h5, "/frames/00000" + std::to_string(k) + "/particles/position", DType::kFloat64, n, 3);
    s.append(g);
  }
  const std::string x = s.xml();
  EXPECT_EQ(test::count_substr(x, R"(<DataItem Dimensions="20" NumberType="Int" Precision="4" Format="HDF">dem.h5:/xdmf/vertex_index)"), 3u)
      << x;
  EXPECT_EQ(test::count_substr(x, "<Time Value="), 3u);
  EXPECT_NE(x.find(R"(<DataItem Dimensions="3 1" Format="XML">0 1 10</DataItem>)"), std::string::npos);
  EXPECT_NE(x.find(R"(<DataItem Dimensions="3 1" Format="XML">0 1 20</DataItem>)"), std::string::npos);
  EXPECT_EQ(test::xml_problem(x), "");
}

TEST(XdmfSidecar, PathsRelativeToTheXmfFolderAndTimesAtFullPrecision) {
  ScratchDir dir;
  XdmfSidecar s(dir / "view" / "particles.xmf", "particles");
  XdmfGrid g;
  g.time = 0.1 + 0.2;  // 0.30000000000000004: needs 17 significant digits
  g.elements = 1;
  g.connectivity = ref(dir / "dem.h5", "/xdmf/vertex_index", DType::kInt32, 1);
  g.geometry = ref(dir / "data" / "dem.h5", "/frames/000000/particles/position", DType::kFloat64, 1, 3);
  s.append(g);
  const std::string x = s.xml();
  EXPECT_NE(x.find(">../dem.h5:/xdmf/vertex_index<"), std::string::npos) << x;
  EXPECT_NE(x.find(">../data/dem.h5:/frames/000000/particles/position<"), std::string::npos) << x;
  EXPECT_NE(x.find(R"(<Time Value="0.30000000000000004"/>)"), std::string::npos) << x;
}

TEST(XdmfSidecar, EscapesNamesAndRejectsInconsistentFrames) {
  ScratchDir dir;
  const auto h5 = dir / "dem.h5";
  XdmfSidecar s(dir / "p.xmf", "a&b");
  XdmfGrid g;
  g.time = 1.0;
  g.elements = 4;
  g.connectivity = ref(h5, "/xdmf/vertex_index", DType::kInt32, 4);
  g.geometry = ref(h5, "/frames/000000/particles/position", DType::kFloat64, 4, 3);
  g.attributes.push_back(XdmfAttribute::node("x<y", ref(h5, "/frames/000000/particles/r", DType::kFloat64, 4)));
  s.append(g);
  const std::string x = s.xml();
  EXPECT_NE(x.find(R"(Name="a&amp;b")"), std::string::npos);
  EXPECT_NE(x.find(R"(Name="x&lt;y")"), std::string::npos);
  EXPECT_EQ(test::xml_problem(x), "");

  XdmfGrid same_time = g;
  EXPECT_THROW(s.append(same_time), std::invalid_argument) << "times must increase strictly";
  XdmfGrid bad_rows = g;
  bad_rows.time = 2.0;
  bad_rows.attributes[0].data.rows = 3;
  EXPECT_THROW(s.append(bad_rows), std::invalid_argument);
  XdmfGrid bad_geom = g;
  bad_geom.time = 2.0;
  bad_geom.geometry.cols = 2;
  EXPECT_THROW(s.append(bad_geom), std::invalid_argument);
  XdmfGrid short_index = g;
  short_index.time = 2.0;
  short_index.connectivity.rows = 3;
  EXPECT_THROW(s.append(short_index), std::invalid_argument);
  XdmfGrid bad_line;
  bad_line.time = 2.0;
  bad_line.topology = XdmfTopology::kPolyline;
  bad_line.elements = 2;
  bad_line.connectivity = ref(h5, "/b", DType::kInt32, 2, 3);
  bad_line.geometry = g.geometry;
  EXPECT_THROW(s.append(bad_line), std::invalid_argument);
  EXPECT_EQ(s.frames(), 1u);
}

TEST(XdmfSidecar, WriteFailureNamesTheFile) {
  ScratchDir dir;
  XdmfSidecar s(dir / "missing_folder" / "p.xmf", "p");
  try {
    s.write();
    FAIL();
  } catch (const IoError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("fopen"), std::string::npos) << msg;
    EXPECT_NE(msg.find("missing_folder/p.xmf.tmp"), std::string::npos) << msg;
  }
}

}  // namespace
}  // namespace demfdm::io
