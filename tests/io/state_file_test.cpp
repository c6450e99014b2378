// State-file container (common/io state_file.hpp, docs/checkpoint-format.md): exact round trip
// of every value type, the byte layout, atomic writing, and every refusal with its file named.
#include "demfdm/io/state_file.hpp"

#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace demfdm::io {
namespace {

constexpr std::uint64_t kHash = 0x0123456789abcdefULL;

// A fresh folder per test, removed afterwards.
class Scratch {
 public:
  Scratch() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path_ = std::filesystem::temp_directory_path() /
            (std::string("demfdm_state_") + info->name() + "_" + std::to_string(::getpid()));
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~Scratch() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  std::filesystem::path operator/(const std::string& f) const { return path_ / f; }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

std::string sample(std::string_view kind = "dem", std::uint64_t hash = kHash) {
  StateWriter w(kind, "demfdm test", hash);
  w.begin("numbers");
  w.u8(200);
  w.b(true);
  w.i8(-5);
  w.u32(0xdeadbeefu);
  w.i32(-123456);
  w.u64(0xfedcba9876543210ULL);
  w.i64(-9000000000LL);
  w.f64(-0.0);
  w.f64(std::numeric_limits<double>::denorm_min());
  w.f64(std::bit_cast<double>(0x7ff8000000000123ULL));  // a NaN with a payload
  w.f64(1.0 / 3.0);
  w.str("hello");
  w.end();
  w.begin("arrays");
  const std::vector<double> d{1.5, -2.25, 1e-300};
  const std::vector<std::uint8_t> u8{1, 2, 255};
  const std::vector<std::int32_t> i32{-1, 0, 7};
  const std::vector<std::uint32_t> u32{4000000000u};
  const std::vector<std::uint64_t> u64{};
  w.f64s(d);
  w.u8s(u8);
  w.i32s(i32);
  w.u32s(u32);
  w.u64s(u64);
  w.end();
  return w.bytes();
}

void write_file(const std::filesystem::path& p, const std::string& b) {
  std::ofstream o(p, std::ios::binary);
  o.write(b.data(), static_cast<std::streamsize>(b.size()));
}

// Reading `bytes` as file `name` must throw StateFileError starting with "<name>: " and
// containing `expect`; returns the message.
std::string refusal(const std::string& bytes, const std::string& name, const std::string& expect,
                    std::string_view kind = "dem", std::uint64_t hash = kHash) {
  std::string m;
  try {
    StateReader r(bytes, name, kind, hash);
    ADD_FAILURE() << "expected a refusal containing '" << expect << "'";
  } catch (const StateFileError& e) {
    m = e.what();
    EXPECT_EQ(m.rfind(name + ": ", 0), 0u) << m;
    EXPECT_NE(m.find(expect), std::string::npos) << m;
  }
  // The reader in pieces (StateFileReader) refuses the same file with the same message.
  const auto file = std::filesystem::temp_directory_path() / ("demfdm_refusal_" + std::to_string(::getpid()) + ".state");
  write_file(file, bytes);
  try {
    StateFileReader r(file, kind, hash);
    ADD_FAILURE() << "StateFileReader: expected a refusal containing '" << expect << "'";
  } catch (const StateFileError& e) {
    if (!m.empty()) {
      EXPECT_EQ(std::string(e.what()), file.string() + m.substr(name.size()));
    }
  }
  std::filesystem::remove(file);
  return m;
}

// Recompute the trailing checksum after editing bytes (to reach the checks behind it).
std::string reseal(std::string b) {
  const std::uint64_t h = fnv1a64(b.data(), b.size() - 8);
  for (int i = 0; i < 8; ++i) b[b.size() - 8 + i] = static_cast<char>((h >> (8 * i)) & 0xff);
  return b;
}

TEST(StateFile, EveryTypeRoundTripsBitExactly) {
  const std::string b = sample();
  StateReader r(b, "mem", "dem", kHash);
  EXPECT_EQ(r.header().format_version, io::kStateFormatVersion);
  EXPECT_EQ(r.header().kind, "dem");
  EXPECT_EQ(r.header().code_version, "demfdm test");
  EXPECT_EQ(r.header().scene_hash, kHash);
  EXPECT_TRUE(r.has("numbers"));
  EXPECT_FALSE(r.has("nothing"));
  {
    auto s = r.section("numbers");
    EXPECT_EQ(s.u8(), 200);
    EXPECT_TRUE(s.b());
    EXPECT_EQ(s.i8(), -5);
    EXPECT_EQ(s.u32(), 0xdeadbeefu);
    EXPECT_EQ(s.i32(), -123456);
    EXPECT_EQ(s.u64(), 0xfedcba9876543210ULL);
    EXPECT_EQ(s.i64(), -9000000000LL);
    const double z = s.f64();
    EXPECT_EQ(std::bit_cast<std::uint64_t>(z), std::bit_cast<std::uint64_t>(-0.0));
    EXPECT_EQ(s.f64(), std::numeric_limits<double>::denorm_min());
    EXPECT_EQ(std::bit_cast<std::uint64_t>(s.f64()), 0x7ff8000000000123ULL);
    EXPECT_EQ(s.f64(), 1.0 / 3.0);
    EXPECT_EQ(s.str(), "hello");
    s.done();
  }
  {
    auto s = r.section("arrays");
    EXPECT_EQ(s.f64s(), (std::vector<double>{1.5, -2.25, 1e-300}));
    EXPECT_EQ(s.u8s(), (std::vector<std::uint8_t>{1, 2, 255}));
    EXPECT_EQ(s.i32s(), (std::vector<std::int32_t>{-1, 0, 7}));
    EXPECT_EQ(s.u32s(), (std::vector<std::uint32_t>{4000000000u}));
    EXPECT_TRUE(s.u64s().empty());
    s.done();
  }
  r.finish();
}

// save_fields / load_fields: one list of fields, each written as its type's put would write it,
// read back into fields of the same types.
TEST(StateFile, FieldListsWriteEachFieldByItsType) {
  const bool b = true;
  const std::int32_t i = -7;
  const std::int64_t l = -9000000000LL;
  const std::uint64_t u = 0xfedcba9876543210ULL;
  const double d = -0.0;
  StateWriter listed("dem", "demfdm test", kHash), by_hand("dem", "demfdm test", kHash);
  listed.begin("s");
  save_fields(listed, b, i, l, u, d, i);
  listed.end();
  by_hand.begin("s");
  by_hand.b(b);
  by_hand.i32(i);
  by_hand.i64(l);
  by_hand.u64(u);
  by_hand.f64(d);
  by_hand.i32(i);
  by_hand.end();
  const std::string bytes = listed.bytes();
  EXPECT_EQ(bytes, by_hand.bytes());
  StateReader r(bytes, "mem", "dem", kHash);
  auto s = r.section("s");
  bool b2 = false;
  std::int32_t i2 = 0, i3 = 0;
  std::int64_t l2 = 0;
  std::uint64_t u2 = 0;
  double d2 = 1.0;
  load_fields(s, b2, i2, l2, u2, d2, i3);
  s.done();
  EXPECT_EQ(b2, b);
  EXPECT_EQ(i2, i);
  EXPECT_EQ(l2, l);
  EXPECT_EQ(u2, u);
  EXPECT_EQ(std::bit_cast<std::uint64_t>(d2), std::bit_cast<std::uint64_t>(d));
  EXPECT_EQ(i3, i);
}

// The layout of docs/checkpoint-format.md, byte by byte at the start and the end.
TEST(StateFile, LayoutIsTheDocumentedOne) {
  StateWriter w("fdm", "v", 0x1122334455667788ULL);
  w.begin("s");
  w.u32(0x0a0b0c0d);
  w.end();
  const std::string b = w.bytes();
  // magic 8 + version 4 + length 8 + kind (4+3) + code (4+1) + hash 8 + count 4
  // + section (name 4+1, length 8, data 4) + checksum 8
  ASSERT_EQ(b.size(), 8u + 4 + 8 + 7 + 5 + 8 + 4 + 5 + 8 + 4 + 8);
  EXPECT_EQ(b.substr(0, 8), "DEMFDMST");
  EXPECT_EQ(b.substr(8, 4), std::string("\x03\x00\x00\x00", 4));  // format version 3 (docs/checkpoint-format.md)
  EXPECT_EQ(static_cast<unsigned char>(b[12]), b.size());  // total length, little-endian
  EXPECT_EQ(b.substr(20, 7), std::string("\x03\x00\x00\x00" "fdm", 7));
  EXPECT_EQ(b.substr(32, 8), std::string("\x88\x77\x66\x55\x44\x33\x22\x11", 8));
  EXPECT_EQ(b.substr(40, 4), std::string("\x01\x00\x00\x00", 4));  // one section
  EXPECT_EQ(b.substr(44, 5), std::string("\x01\x00\x00\x00s", 5));
  EXPECT_EQ(b.substr(49, 8), std::string("\x04\0\0\0\0\0\0\0", 8));
  EXPECT_EQ(b.substr(57, 4), std::string("\x0d\x0c\x0b\x0a", 4));
  std::uint64_t sum = 0;
  for (int i = 0; i < 8; ++i) sum |= std::uint64_t(static_cast<unsigned char>(b[b.size() - 8 + i])) << (8 * i);
  EXPECT_EQ(sum, fnv1a64(b.data(), b.size() - 8));
  // FNV-1a 64 reference values.
  EXPECT_EQ(fnv1a64("", 0), 0xcbf29ce484222325ULL);
  EXPECT_EQ(fnv1a64("a", 1), 0xaf63dc4c8601ec8cULL);
}

TEST(StateFile, RefusalsNameTheFile) {
  const std::string good = sample();
  const std::string f = "runs/x/ckpt/dem-000042.state";
  std::string bad = good;
  bad[0] = 'X';
  refusal(bad, f, "bad magic");
  refusal("", f, "truncated: 0 bytes");
  refusal(good.substr(0, 12), f, "truncated");
  std::string v2 = good;
  v2[8] = static_cast<char>(kStateFormatVersion + 1);
  refusal(v2, f,
          "format version " + std::to_string(kStateFormatVersion + 1) + ", this code reads version " +
              std::to_string(kStateFormatVersion));
  refusal(good.substr(0, good.size() - 1), f, "truncated: ");
  refusal(good.substr(0, good.size() / 2), f, "truncated: ");
  refusal(good + "x", f, "trailing bytes");
  std::string flipped = good;
  flipped[good.size() / 2] ^= 0x01;
  refusal(flipped, f, "checksum mismatch");
  std::string last = good;
  last[good.size() - 1] ^= 0x40;  // the checksum itself
  refusal(last, f, "checksum mismatch");
  refusal(sample("fdm"), f, "kind 'fdm', expected 'dem'");
  const std::string m = refusal(sample("dem", kHash + 1), f, "scene hash");
  EXPECT_NE(m.find("0x0123456789abcdf0"), std::string::npos) << "the file's hash: " << m;
  EXPECT_NE(m.find("0x0123456789abcdef"), std::string::npos) << "the expected hash: " << m;
}

TEST(StateFile, MissingUnknownAndShortSections) {
  const std::string f = "a.state";
  {
    StateReader r(sample(), f, "dem", kHash);
    (void)r.section("numbers");
    try {
      r.finish();
      ADD_FAILURE();
    } catch (const StateFileError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(f + ": unknown section(s) 'arrays'", 0), 0u) << e.what();
    }
    try {
      (void)r.section("balls");
      ADD_FAILURE();
    } catch (const StateFileError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(f + ": missing section 'balls'", 0), 0u) << e.what();
    }
  }
  {
    StateReader r(sample(), f, "dem", kHash);
    auto s = r.section("numbers");
    (void)s.u64();
    EXPECT_THROW(s.done(), StateFileError);  // bytes left: longer than this code expects
    auto a = r.section("arrays");
    (void)a.f64s();
    (void)a.u8s();
    (void)a.i32s();
    (void)a.u32s();
    (void)a.u64s();
    try {
      (void)a.u8();
      ADD_FAILURE();
    } catch (const StateFileError& e) {
      EXPECT_NE(std::string(e.what()).find("section 'arrays': needs 1 more bytes"), std::string::npos) << e.what();
    }
  }
  {
    // A corrupt count (resealed, so it passes the checksum) cannot allocate beyond the section.
    StateWriter w("dem", "v", kHash);
    w.begin("s");
    w.u64(1ULL << 60);
    w.end();
    StateReader r(w.bytes(), f, "dem", kHash);
    auto s = r.section("s");
    EXPECT_THROW((void)s.f64s(), StateFileError);
  }
  {
    // A section length beyond the file (resealed).
    std::string b = sample();
    const std::size_t at = b.find("numbers") + 7;
    b[at + 6] = 0x7f;
    refusal(reseal(b), f, "announces");
  }
}

TEST(StateFile, AtomicWriteAndFileRefusals) {
  Scratch dir;
  const auto file = dir / "dem-000001.state";
  write_atomically(file, sample());
  EXPECT_EQ(read_whole_file(file), sample());
  EXPECT_FALSE(std::filesystem::exists(file.string() + ".tmp-" + std::to_string(::getpid())));
  write_atomically(file, sample("dem", 7));  // replaces the earlier file
  EXPECT_EQ(read_whole_file(file), sample("dem", 7));
  std::size_t entries = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) entries += e.is_regular_file();
  EXPECT_EQ(entries, 1u) << "no temporary file left behind";
  try {
    write_atomically(dir / "no/such/folder/x.state", "abc");
    ADD_FAILURE();
  } catch (const StateFileError& e) {
    EXPECT_NE(std::string(e.what()).find("no/such/folder/x.state.tmp-"), std::string::npos) << e.what();
  }
  try {
    (void)read_whole_file(dir / "missing.state");
    ADD_FAILURE();
  } catch (const StateFileError& e) {
    EXPECT_NE(std::string(e.what()).find("missing.state"), std::string::npos) << e.what();
  }
  // A truncated file on disk is refused with its path.
  const std::string b = sample();
  write_file(file, b.substr(0, b.size() - 3));
  refusal(read_whole_file(file), file.string(), "truncated");
}

TEST(StateFile, WriterMisuseIsALogicError) {
  StateWriter w("dem", "v", 0);
  EXPECT_THROW(w.end(), std::logic_error);
  w.begin("a");
  EXPECT_THROW(w.begin("b"), std::logic_error);
  EXPECT_THROW((void)w.bytes(), std::logic_error);
  w.end();
  EXPECT_NO_THROW((void)w.bytes());
}

// A file written in pieces (StateFileWriter: sections whole or reserved and filled in any
// order) has the bytes of the same sections written in memory, and reads back.
TEST(StateFile, FileWrittenInPiecesHasTheBytesOfOneWriter) {
  Scratch dir;
  StateWriter w("dem", "v1", kHash);
  w.begin("head");
  w.f64(-0.0);
  w.str("text");
  w.end();
  w.begin("rows");
  for (std::uint64_t k = 0; k < 1000; ++k) w.u64(k * k);
  w.end();
  w.begin("empty");
  w.end();
  w.begin("tail");
  w.u32(7);
  w.end();
  const std::string want = w.bytes();

  const auto file = dir / "pieces.state";
  {
    StateFileWriter f(file, "dem", "v1", kHash, 4);
    std::string head;
    head.append(8, '\0');  // -0.0 is the sign bit alone
    head[7] = static_cast<char>(0x80);
    head += std::string("\x04\0\0\0text", 8);
    f.section("head", head);
    const std::uint64_t at = f.reserve("rows", 8000);
    f.section("empty", "");
    // the rows in blocks, last block first
    for (std::uint64_t b = 1000; b > 0; b -= 100) {
      std::string block;
      for (std::uint64_t k = b - 100; k < b; ++k)
        for (int i = 0; i < 8; ++i) block.push_back(static_cast<char>(((k * k) >> (8 * i)) & 0xffu));
      f.write_at(at + 8 * (b - 100), block);
    }
    EXPECT_FALSE(std::filesystem::exists(file)) << "nothing under the final name before commit()";
    EXPECT_THROW(f.commit(), std::logic_error) << "a declared section is missing";
    f.section("tail", std::string("\x07\0\0\0", 4));
    EXPECT_THROW(f.section("more", ""), std::logic_error);
    EXPECT_THROW(f.write_at(at + 7996, "12345678"), std::logic_error) << "past the reserved bytes";
    f.commit();
  }
  EXPECT_EQ(read_whole_file(file), want);
  {  // read back in pieces
    StateFileReader q(file, "dem", kHash);
    EXPECT_EQ(q.names(), (std::vector<std::string>{"head", "rows", "empty", "tail"}));
    EXPECT_EQ(q.header().code_version, "v1");
    EXPECT_EQ(q.length("rows"), 8000u);
    EXPECT_EQ(q.section_bytes("empty"), "");
    const std::string r = q.read("rows", 8 * 999, 8);
    std::uint64_t v = 0;
    for (int i = 0; i < 8; ++i) v |= static_cast<std::uint64_t>(static_cast<unsigned char>(r[static_cast<std::size_t>(i)])) << (8 * i);
    EXPECT_EQ(v, 999u * 999u);
    EXPECT_THROW((void)q.read("rows", 7996, 8), StateFileError);
    EXPECT_THROW((void)q.section_bytes("nope"), StateFileError);
  }
  StateReader r(read_whole_file(file), file.string(), "dem", kHash);
  EXPECT_EQ(r.names(), (std::vector<std::string>{"head", "rows", "empty", "tail"}));
  EXPECT_EQ(r.section_bytes("tail"), std::string_view("\x07\0\0\0", 4));
  EXPECT_THROW((void)r.section_bytes("tail"), StateFileError) << "read twice";

  // a reserved section not filled: no commit; an abandoned writer leaves no file
  {
    StateFileWriter f(dir / "unfilled.state", "dem", "v1", kHash, 1);
    const std::uint64_t at = f.reserve("rows", 16);
    f.write_at(at, "12345678");
    EXPECT_THROW(f.commit(), std::logic_error);
  }
  std::size_t entries = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) entries += e.is_regular_file();
  EXPECT_EQ(entries, 1u) << "only the committed file, no temporary one";
  EXPECT_THROW(StateFileWriter(dir / "no/such/folder/x.state", "dem", "v", 0, 1), StateFileError);
}

}  // namespace
}  // namespace demfdm::io
