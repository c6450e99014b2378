// H5Frames: layout, read-back through the HDF5 C API, exclusivity, determinism, histories,
// reopening for a resumed run.
// All comparisons of written values are exact (tolerance 0): the file stores the bits given.
#include "demfdm/io/h5_frames.hpp"

#include <array>
#include <cstring>
#include <fstream>
#include <span>
#include <vector>

#include <gtest/gtest.h>

#include "demfdm/io/error.hpp"
#include "io_test_util.hpp"

namespace demfdm::io {
namespace {

using test::H5Reader;
using test::ScratchDir;

FileInfo dem_info() {
  FileInfo info;
  info.producer = "dem_node";
  info.run_id = "run-42";
  info.scene_hash = "abc123";
  return info;
}

// Frame k of a small DEM scene: 5 - k particles, 4 - k bonds; values depend on k so a
// frame mix-up shows.
struct SceneFrame {
  std::vector<double> position, radius;
  std::vector<float> velocity;
  std::vector<std::int64_t> id;
  std::vector<std::int32_t> bond_nodes;
  std::vector<std::uint8_t> bond_state;
};

SceneFrame scene_frame(int k) {
  SceneFrame f;
  const int np = 5 - k, nb = 4 - k;
  for (int i = 0; i < np; ++i) {
    f.position.insert(f.position.end(), {0.1 * i + k, 0.2 * i - k, 1.0 / (i + 3) + 1e-3 * k});
    f.radius.push_back(0.01 + 0.001 * i);
    f.velocity.insert(f.velocity.end(), {0.5f * i, -0.25f * k, 1.0f / 3.0f});
    f.id.push_back(100 + 2 * i + k);
  }
  for (int b = 0; b < nb; ++b) {
    f.bond_nodes.insert(f.bond_nodes.end(), {b, b + 1});
    f.bond_state.push_back(static_cast<std::uint8_t>((b + k) % 3));
  }
  return f;
}

void write_scene(const std::filesystem::path& file, const H5StorageParams& storage = {}) {
  H5Frames h5 = H5Frames::create(file, dem_info(), storage);
  h5.declare_history({{"time", "s"}, {"load", "N"}});
  for (int k = 0; k < 3; ++k) {
    const SceneFrame f = scene_frame(k);
    h5.begin_frame(1000 * k, 0.001 * k);
    h5.ensure_index("/xdmf/vertex_index", f.radius.size());
    h5.write("particles/position", f.position, 3);
    h5.write("particles/radius", f.radius);
    h5.write("particles/velocity", f.velocity, 3);
    h5.write("particles/id", f.id);
    h5.write("bonds/nodes", f.bond_nodes, 2);
    h5.write("bonds/state", f.bond_state);
    h5.end_frame();
    const double row[2] = {0.001 * k, 10.0 * k};
    h5.append_history(row);
  }
  h5.close();
}

TEST(H5Frames, ThreeFramesReadBackExactly) {
  ScratchDir dir;
  write_scene(dir / "dem.h5");
  H5Reader r(dir / "dem.h5");

  bool ascii = false;
  EXPECT_EQ(r.attr_str("/", "format", &ascii), "demfdm-results");
  EXPECT_TRUE(ascii) << "string attributes must be fixed-length null-padded ASCII";
  EXPECT_EQ(r.attr_i64("/", "format_version"), 1);
  EXPECT_EQ(r.attr_str("/", "producer"), "dem_node");
  EXPECT_EQ(r.attr_str("/", "run_id"), "run-42");
  EXPECT_EQ(r.attr_str("/", "scene_hash"), "abc123");
  EXPECT_EQ(r.attr_str("/", "length_unit"), "m");
  EXPECT_EQ(r.attr_str("/", "time_unit"), "s");

  for (int k = 0; k < 3; ++k) {
    const SceneFrame f = scene_frame(k);
    const std::string g = H5Frames::frame_group(static_cast<std::size_t>(k));
    ASSERT_EQ(g, "/frames/00000" + std::to_string(k));
    EXPECT_EQ(r.attr_f64(g, "time"), 0.001 * k);
    EXPECT_EQ(r.attr_i64(g, "step"), 1000 * k);
    const hsize_t np = static_cast<hsize_t>(5 - k), nb = static_cast<hsize_t>(4 - k);
    EXPECT_EQ(r.dims(g + "/particles/position"), (std::vector<hsize_t>{np, 3}));
    EXPECT_EQ(r.dims(g + "/particles/radius"), (std::vector<hsize_t>{np}));
    EXPECT_EQ(r.dims(g + "/bonds/nodes"), (std::vector<hsize_t>{nb, 2}));
    EXPECT_EQ(r.read_f64(g + "/particles/position"), f.position);
    EXPECT_EQ(r.read_f64(g + "/particles/radius"), f.radius);
    EXPECT_EQ(r.read_f32(g + "/particles/velocity"), f.velocity);
    EXPECT_EQ(r.read_i64(g + "/particles/id"), f.id);
    EXPECT_EQ(r.read_i32(g + "/bonds/nodes"), f.bond_nodes);
    EXPECT_EQ(r.read_u8(g + "/bonds/state"), f.bond_state);
  }
  // On-disk types: little-endian, the width asked for.
  struct Want { const char* path; H5T_class_t cls; std::size_t size; };
  for (const Want& w : {Want{"/frames/000000/particles/position", H5T_FLOAT, 8},
                        Want{"/frames/000000/particles/velocity", H5T_FLOAT, 4},
                        Want{"/frames/000000/particles/id", H5T_INTEGER, 8},
                        Want{"/frames/000000/bonds/nodes", H5T_INTEGER, 4},
                        Want{"/frames/000000/bonds/state", H5T_INTEGER, 1}}) {
    H5T_class_t cls;
    std::size_t size;
    bool little;
    r.file_type(w.path, cls, size, little);
    EXPECT_EQ(cls, w.cls) << w.path;
    EXPECT_EQ(size, w.size) << w.path;
    EXPECT_TRUE(little) << w.path;
  }
  // The vertex index holds 0..Nmax-1 with Nmax = 5 (frame 0).
  EXPECT_EQ(r.read_i32("/xdmf/vertex_index"), (std::vector<std::int32_t>{0, 1, 2, 3, 4}));
  // History: one row per frame.
  EXPECT_EQ(r.read_f64("/history/time"), (std::vector<double>{0.0, 0.001, 0.002}));
  EXPECT_EQ(r.read_f64("/history/load"), (std::vector<double>{0.0, 10.0, 20.0}));
  EXPECT_EQ(r.attr_str("/history/load", "unit"), "N");
  EXPECT_EQ(r.attr_str("/history", "load_unit"), "N");
}

TEST(H5Frames, ObjectTimesNotTrackedAndOldFormat) {
  ScratchDir dir;
  write_scene(dir / "dem.h5");
  H5Reader r(dir / "dem.h5");
  for (const char* p : {"/", "/frames", "/frames/000001", "/frames/000001/particles", "/frames/000001/particles/position",
                        "/xdmf/vertex_index", "/history/load"}) {
    H5O_info_t info;
    ASSERT_GE(H5Oget_info_by_name2(r.id(), p, &info, H5O_INFO_TIME, H5P_DEFAULT), 0) << p;
    EXPECT_EQ(info.ctime, 0) << p << ": object times must not be tracked (bit-identical files)";
    EXPECT_EQ(info.mtime, 0) << p;
  }
  // libver bounds EARLIEST..V18: superblock version 0 (readable by HDF5 >= 1.8; v3 would
  // need 1.10).
  H5F_info2_t finfo;
  ASSERT_GE(H5Fget_info2(r.id(), &finfo), 0);
  EXPECT_LE(finfo.super.version, 2u);
}

TEST(H5Frames, TwoIdenticalWritesAreByteIdentical) {
  ScratchDir dir;
  write_scene(dir / "a.h5");
  write_scene(dir / "b.h5");
  const std::string a = test::slurp(dir / "a.h5"), b = test::slurp(dir / "b.h5");
  ASSERT_GT(a.size(), 1000u);
  EXPECT_EQ(a.size(), b.size());
  EXPECT_TRUE(a == b) << "two identical writes must give byte-identical files";

  // Compressed storage too.
  H5StorageParams z;
  z.compress = true;
  write_scene(dir / "c.h5", z);
  write_scene(dir / "d.h5", z);
  EXPECT_TRUE(test::slurp(dir / "c.h5") == test::slurp(dir / "d.h5"));
}

TEST(H5Frames, CreateRefusesExistingFileAndLeavesItUnchanged) {
  ScratchDir dir;
  const auto file = dir / "dem.h5";
  write_scene(file);
  const std::string before = test::slurp(file);
  try {
    H5Frames::create(file, dem_info());
    FAIL() << "creating over an existing results file must throw";
  } catch (const IoError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("H5Fcreate"), std::string::npos) << msg;
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("already exists"), std::string::npos) << msg;
  }
  EXPECT_TRUE(test::slurp(file) == before) << "the existing file must be left byte-for-byte unchanged";
}

TEST(H5Frames, FileIsClosedBetweenFramesSoReadersCanOpenIt) {
  ScratchDir dir;
  const auto file = dir / "dem.h5";
  H5Frames h5 = H5Frames::create(file, dem_info());
  const std::vector<double> x{1, 2, 3};
  h5.begin_frame(7, 0.5);
  h5.write("particles/position", x, 3);
  h5.end_frame();
  {
    // Opening read-only with HDF5's default file locking fails while a writer holds the
    // file (docs/output.md O12); it must succeed here.
    H5Reader r(file);
    EXPECT_EQ(r.read_f64("/frames/000000/particles/position"), x);
  }
  h5.begin_frame(8, 0.6);
  h5.write("particles/position", x, 3);
  h5.end_frame();
  H5Reader r(file);
  EXPECT_EQ(r.attr_i64("/frames/000001", "step"), 8);
}

TEST(H5Frames, ZeroRowArraysAndCompressedRoundTrip) {
  ScratchDir dir;
  H5StorageParams z;
  z.compress = true;
  z.chunk_rows = 4;  // several chunks, the last one partial
  H5Frames h5 = H5Frames::create(dir / "z.h5", dem_info(), z);
  std::vector<double> big(3 * 10);
  for (std::size_t i = 0; i < big.size(); ++i) big[i] = 0.37 * static_cast<double>(i) - 2.0;
  h5.begin_frame(0, 0.0);
  h5.write("particles/position", std::vector<double>{}, 3);
  h5.write("bonds/nodes", std::vector<std::int32_t>{}, 2);
  h5.write("zones/stress", big, 3);
  h5.end_frame();
  h5.close();
  H5Reader r(dir / "z.h5");
  EXPECT_EQ(r.dims("/frames/000000/particles/position"), (std::vector<hsize_t>{0, 3}));
  EXPECT_EQ(r.dims("/frames/000000/bonds/nodes"), (std::vector<hsize_t>{0, 2}));
  EXPECT_EQ(r.read_f64("/frames/000000/zones/stress"), big);
  hid_t d = H5Dopen2(r.id(), "/frames/000000/zones/stress", H5P_DEFAULT);
  hid_t p = H5Dget_create_plist(d);
  EXPECT_EQ(H5Pget_layout(p), H5D_CHUNKED);
  EXPECT_EQ(H5Pget_nfilters(p), 2) << "shuffle + deflate";
  hsize_t chunk[2] = {0, 0};
  H5Pget_chunk(p, 2, chunk);
  EXPECT_EQ(chunk[0], 4u);
  EXPECT_EQ(chunk[1], 3u);
  H5Pclose(p);
  H5Dclose(d);
}

TEST(H5Frames, HistoryAppendsRowsBufferedAndExtendible) {
  ScratchDir dir;
  H5StorageParams s;
  s.history_flush_rows = 7;  // 100 rows = 14 full batches + 2 rows flushed by close()
  H5Frames h5 = H5Frames::create(dir / "history.h5", FileInfo{"coordinator", "r", "h", {}}, s);
  h5.declare_history({{"time", "s"}, {"displacement", "m"}, {"load", "N"}});
  std::vector<double> t, u, f;
  for (int i = 0; i < 100; ++i) {
    t.push_back(1e-4 * i);
    u.push_back(-2.5e-6 * i);
    f.push_back(1.0e3 * i * i);
    h5.append_history(std::vector<double>{t.back(), u.back(), f.back()});
  }
  {
    H5Reader r(dir / "history.h5");
    EXPECT_EQ(r.dims("/history/load")[0], 98u) << "98 rows flushed in batches of 7 before close()";
  }
  h5.close();
  H5Reader r(dir / "history.h5");
  EXPECT_EQ(r.read_f64("/history/time"), t);
  EXPECT_EQ(r.read_f64("/history/displacement"), u);
  EXPECT_EQ(r.read_f64("/history/load"), f);
  EXPECT_EQ(r.attr_str("/history", "displacement_unit"), "m");
  hid_t d = H5Dopen2(r.id(), "/history/time", H5P_DEFAULT);
  hid_t sp = H5Dget_space(d);
  hsize_t cur = 0, mx = 0;
  H5Sget_simple_extent_dims(sp, &cur, &mx);
  EXPECT_EQ(mx, H5S_UNLIMITED);
  hid_t p = H5Dget_create_plist(d);
  hsize_t chunk = 0;
  H5Pget_chunk(p, 1, &chunk);
  EXPECT_EQ(chunk, 1024u);
  H5Pclose(p);
  H5Sclose(sp);
  H5Dclose(d);
}

TEST(H5Frames, MisuseIsReportedClearly) {
  ScratchDir dir;
  const auto file = dir / "dem.h5";
  H5Frames h5 = H5Frames::create(file, dem_info());
  const std::vector<double> x{1, 2, 3};
  EXPECT_THROW(h5.write("particles/position", x, 3), std::logic_error);
  EXPECT_THROW(h5.end_frame(), std::logic_error);
  EXPECT_THROW(h5.write_static("/frames/x", x), std::invalid_argument);
  EXPECT_THROW(h5.write_static("relative", x), std::invalid_argument);
  EXPECT_THROW(h5.append_history(x), std::logic_error);
  h5.begin_frame(0, 0.0);
  EXPECT_THROW(h5.begin_frame(1, 0.1), std::logic_error);
  h5.write("particles/position", x, 3);
  EXPECT_THROW(h5.write("particles/position", x, 3), std::logic_error);
  EXPECT_THROW(h5.write("/abs", x), std::invalid_argument);
  EXPECT_THROW(h5.write("p/bad", x, 2), std::invalid_argument) << "3 values are not rows of 2";
  h5.end_frame();
  EXPECT_EQ(h5.ref("particles/position").path, "/frames/000000/particles/position");
  EXPECT_THROW(h5.ref("particles/nothing"), std::out_of_range);

  H5StorageParams bad;
  bad.deflate_level = 0;
  try {
    H5Frames::create(dir / "other.h5", dem_info(), bad);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("deflate_level"), std::string::npos) << e.what();
    EXPECT_FALSE(std::filesystem::exists(dir / "other.h5"));
  }

  // The file vanished between frames: the next frame names the file and H5Fopen.
  std::filesystem::remove(file);
  try {
    h5.begin_frame(1, 0.1);
    FAIL();
  } catch (const IoError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("H5Fopen"), std::string::npos) << msg;
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
  }
}

TEST(H5Frames, VertexIndexGrowsOnlyWhenNeeded) {
  ScratchDir dir;
  H5Frames h5 = H5Frames::create(dir / "dem.h5", dem_info());
  EXPECT_EQ(h5.ensure_index("/xdmf/vertex_index", 3).rows, 3u);
  EXPECT_EQ(h5.ensure_index("/xdmf/vertex_index", 2).rows, 3u);
  EXPECT_EQ(h5.ensure_index("/xdmf/vertex_index", 70000).rows, 70000u);  // crosses a 65536 chunk
  h5.close();
  H5Reader r(dir / "dem.h5");
  const auto v = r.read_i32("/xdmf/vertex_index");
  ASSERT_EQ(v.size(), 70000u);
  for (std::size_t i = 0; i < v.size(); ++i) ASSERT_EQ(v[i], static_cast<std::int32_t>(i));
}

TEST(H5Frames, AcceptsVectorsAndSpansOfAnyConstnessAndExtent) {
  ScratchDir dir;
  H5Frames h5 = H5Frames::create(dir / "dem.h5", dem_info());
  std::vector<double> x{1, 2, 3, 4, 5, 6};
  std::array<std::int64_t, 4> ids{7, 8, 9, 10};
  h5.write_static("/static/x", x, 3);
  h5.begin_frame(0, 0.0);
  h5.write("a/mutable", std::span<double>(x), 2);
  h5.write("a/fixed", std::span<std::int64_t, 4>(ids));
  h5.write("a/const", std::span<const double>(x));
  h5.end_frame();
  h5.close();
  H5Reader r(dir / "dem.h5");
  EXPECT_EQ(r.dims("/static/x"), (std::vector<hsize_t>{2, 3}));
  EXPECT_EQ(r.dims("/frames/000000/a/mutable"), (std::vector<hsize_t>{3, 2}));
  EXPECT_EQ(r.read_i64("/frames/000000/a/fixed"), (std::vector<std::int64_t>{7, 8, 9, 10}));
  EXPECT_EQ(r.read_f64("/frames/000000/a/const"), x);
}

// Frame k of a resumable scene, with `np` particles; arrays written in a non-alphabetical
// order so a reader falling back to HDF5's name order shows.
void write_resume_frame(H5Frames& h5, int k, int np) {
  std::vector<double> pos, radius;
  std::vector<std::int32_t> bonds;
  for (int i = 0; i < np; ++i) {
    pos.insert(pos.end(), {0.1 * i + k, 0.2 * i, 1e-3 * k});
    radius.push_back(0.01 + 1e-4 * (i + k));
  }
  for (int b = 0; b + 1 < np; ++b) bonds.insert(bonds.end(), {b, b + 1});
  h5.begin_frame(100 * k, 0.5 * k);
  h5.ensure_index("/xdmf/vertex_index", static_cast<std::size_t>(np));
  h5.write("particles/position", pos, 3);
  h5.write("particles/radius", radius);
  h5.write("bonds/nodes", bonds, 2);
  h5.end_frame();
  h5.append_history(std::vector<double>{0.5 * k, -1.0 * k * k, 7.0 + k});
}

constexpr int kResumeParticles[5] = {3, 5, 4, 6, 2};

TEST(H5Frames, ReopenDropsLaterFramesAndContinuesLikeAnUninterruptedWriter) {
  ScratchDir dir;
  const std::vector<HistoryColumn> cols{{"time", "s"}, {"load", "N"}, {"displacement", "m"}};
  {
    H5Frames ref = H5Frames::create(dir / "ref.h5", dem_info());
    ref.write_static("/mesh/extra", std::vector<std::int64_t>{1, 2, 3, 4}, 2);
    ref.declare_history(cols);
    for (int k = 0; k < 5; ++k) write_resume_frame(ref, k, kResumeParticles[k]);
    ref.close();
  }
  const auto want = test::stored_contents(dir / "ref.h5", {"/frames", "/xdmf", "/mesh", "/history"});
  {
    H5Frames crashed = H5Frames::create(dir / "run.h5", dem_info());
    crashed.write_static("/mesh/extra", std::vector<std::int64_t>{1, 2, 3, 4}, 2);
    crashed.declare_history(cols);
    for (int k = 0; k < 2; ++k) write_resume_frame(crashed, k, kResumeParticles[k]);
    EXPECT_EQ(crashed.history_rows(), 2u);
    // After the checkpoint (2 frames, 2 history rows): other output, then the crash.
    write_resume_frame(crashed, 7, 8);
    write_resume_frame(crashed, 8, 1);
  }
  H5Frames h5 = H5Frames::reopen(dir / "run.h5", 2, {}, 2);
  EXPECT_EQ(h5.frame_count(), 2u);
  EXPECT_EQ(h5.history_rows(), 2u);
  ASSERT_EQ(h5.history_columns().size(), 3u);
  EXPECT_EQ(h5.history_columns()[2].name, "displacement");
  EXPECT_EQ(h5.history_columns()[2].unit, "m");
  EXPECT_EQ(h5.ref("particles/radius").path, "/frames/000001/particles/radius") << "the last kept frame";
  EXPECT_EQ(h5.ref("particles/position").rows, 5u);
  EXPECT_EQ(h5.ref("/mesh/extra").cols, 2u);
  EXPECT_EQ(h5.ref("/mesh/extra").dtype, DType::kInt64);
  EXPECT_EQ(h5.ref("/xdmf/vertex_index").rows, 8u) << "as the crashed run left it";
  h5.truncate_index("/xdmf/vertex_index", 5);  // the kept frames' largest particle count
  EXPECT_EQ(h5.ref("/xdmf/vertex_index").rows, 5u);
  {
    H5Reader r(dir / "run.h5");
    EXPECT_FALSE(r.exists("/frames/000002"));
    EXPECT_EQ(r.dims("/history/load"), (std::vector<hsize_t>{2}));
    EXPECT_EQ(r.dims("/xdmf/vertex_index"), (std::vector<hsize_t>{5}));
  }
  const auto frames = h5.read_frames();
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[1].step, 100);
  EXPECT_EQ(frames[1].time, 0.5);
  EXPECT_EQ(frames[1].names, (std::vector<std::string>{"particles/position", "particles/radius", "bonds/nodes"}))
      << "write order, not name order";
  EXPECT_EQ(frames[1].datasets[2].path, "/frames/000001/bonds/nodes");
  EXPECT_EQ(frames[1].datasets[2].cols, 2u);
  EXPECT_EQ(frames[1].datasets[2].dtype, DType::kInt32);
  for (int k = 2; k < 5; ++k) write_resume_frame(h5, k, kResumeParticles[k]);
  h5.close();
  EXPECT_EQ(test::contents_diff(want, test::stored_contents(dir / "run.h5", {"/frames", "/xdmf", "/mesh", "/history"})),
            "");
}

TEST(H5Frames, ReopenRefusesFilesItCannotResume) {
  ScratchDir dir;
  const auto file = dir / "dem.h5";
  {
    H5Frames h5 = H5Frames::create(file, dem_info());
    h5.declare_history({{"time", "s"}, {"load", "N"}, {"displacement", "m"}});
    for (int k = 0; k < 2; ++k) write_resume_frame(h5, k, 3);
  }
  const std::string before = test::slurp(file);
  const auto refused = [&](const std::filesystem::path& f, std::size_t frames, std::size_t rows,
                           const std::string& word) {
    try {
      H5Frames::reopen(f, frames, {}, rows);
      ADD_FAILURE() << "reopen of " << f << " at " << frames << " frames must be refused";
    } catch (const IoError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(f.string()), std::string::npos) << msg;
      EXPECT_NE(msg.find(word), std::string::npos) << "'" << word << "' not in: " << msg;
    }
  };
  refused(file, 3, 0, "holds 2 of the frames 0..3-1");
  refused(file, 1, 5, "holds 2 rows, the checkpoint counts 5");
  EXPECT_EQ(test::slurp(file), before) << "a refused reopen leaves the file as found";

  // An HDF5 file of someone else, and a file that is no HDF5 file at all.
  const auto foreign = dir / "foreign.h5";
  H5Fclose(H5Fcreate(foreign.c_str(), H5F_ACC_EXCL, H5P_DEFAULT, H5P_DEFAULT));
  refused(foreign, 0, 0, "not a demfdm results file");
  { std::ofstream(dir / "text.h5") << "time_s\n"; }
  refused(dir / "text.h5", 0, 0, "H5Fopen");
  refused(dir / "missing.h5", 0, 0, "H5Fopen");
}

}  // namespace
}  // namespace demfdm::io
