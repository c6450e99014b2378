// State files (checkpoints) of the cores: a small binary container shared by dem_core and
// fdm_core. Layout, sections and versioning: docs/checkpoint-format.md.
//
//   magic "DEMFDMST" | u32 format version | u64 total length | str kind | str code version |
//   u64 scene hash | u32 section count | sections (str name, u64 length, bytes) |
//   u64 FNV-1a 64 checksum of every byte before it
//
// All numbers are little-endian; doubles are their IEEE-754 bit patterns (bit-exact round
// trip); strings are u32 length + bytes. Structs are written field by field, never as raw
// memory (no padding bytes in the file).
//
// The reader checks, in this order, and throws StateFileError with the file named: too short
// for a header, bad magic, other format version, truncated or overlong file, checksum
// mismatch, other kind, other scene hash (both shown), malformed sections. The caller then asks
// for sections by name (a missing one throws) and calls finish() (a section never asked for,
// i.e. unknown to this code version, throws).
#pragma once

#include <bit>
#include <concepts>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <iosfwd>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace demfdm::io {

/// A state file was refused or could not be written; the message starts with the file name.
class StateFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

inline constexpr char kStateMagic[8] = {'D', 'E', 'M', 'F', 'D', 'M', 'S', 'T'};
inline constexpr std::uint32_t kStateFormatVersion = 3;

/// "demfdm <project version> gcc <compiler version>": the code version written by default
/// (the same text as the build id the nodes announce on the bus).
std::string default_code_version();

/// FNV-1a 64 of a byte range (the file checksum).
std::uint64_t fnv1a64(const void* data, std::size_t n, std::uint64_t h = 14695981039346656037ULL);

/// What the header of a state file says.
struct StateHeader {
  std::uint32_t format_version = kStateFormatVersion;
  std::string kind;          // "dem" or "fdm"
  std::string code_version;  // text; recorded, not checked
  std::uint64_t scene_hash = 0;
};

/// Values encoded as a state file holds them (little-endian, doubles as their bit patterns,
/// arrays as a u64 count and the elements), appended to a buffer: StateWriter's sections, and a
/// section's rows written on their own (dem::StateStream's blocks).
class ByteWriter {
 public:
  void u8(std::uint8_t v) { buf_.push_back(static_cast<char>(v)); }
  void b(bool v) { u8(v ? 1 : 0); }
  void i8(std::int8_t v) { u8(static_cast<std::uint8_t>(v)); }
  void u32(std::uint32_t v) { put_le(v); }
  void i32(std::int32_t v) { put_le(static_cast<std::uint32_t>(v)); }
  void u64(std::uint64_t v) { put_le(v); }
  void i64(std::int64_t v) { put_le(static_cast<std::uint64_t>(v)); }
  void f64(double v) { put_le(std::bit_cast<std::uint64_t>(v)); }
  void str(std::string_view s);
  /// Bytes as they are (a section's content copied from another file).
  void raw(std::string_view b) { buf_.append(b); }
  /// Array helpers: u64 count, then the elements.
  void f64s(std::span<const double> v);
  void u8s(std::span<const std::uint8_t> v);
  void i32s(std::span<const std::int32_t> v);
  void u32s(std::span<const std::uint32_t> v);
  void u64s(std::span<const std::uint64_t> v);
  /// What was appended so far (a caller may take it and clear it).
  std::string& buffer() { return buf_; }

 protected:
  std::string buf_;

 private:
  template <class U>
  void put_le(U v) {
    if constexpr (std::endian::native == std::endian::big) v = byteswap(v);
    char tmp[sizeof(U)];
    std::memcpy(tmp, &v, sizeof(U));
    buf_.append(tmp, sizeof(U));
  }
  template <class U>
  static U byteswap(U v) {
    U r = 0;
    for (std::size_t i = 0; i < sizeof(U); ++i) r = static_cast<U>((r << 8) | ((v >> (8 * i)) & 0xffu));
    return r;
  }
};

/// Builds a state file in memory. Sections are written one at a time: begin(name), put...,
/// end(). bytes() closes the file (checksum) and returns it.
class StateWriter : public ByteWriter {
 public:
  StateWriter(std::string_view kind, std::string_view code_version, std::uint64_t scene_hash);

  void begin(std::string_view section);
  void end();

  /// The complete file (header, sections, checksum). Throws std::logic_error inside a section.
  std::string bytes() const;

 private:
  std::string head_;  // header up to (not including) the section count
  // (buf_: the sections written so far, and the open one)
  std::uint32_t count_ = 0;
  std::size_t open_ = std::string::npos;  // offset of the open section's length field
};

/// Writes a state file to disk in pieces: the bytes StateWriter::bytes() gives for the same
/// sections, for a state too large to hold in memory at once (the DEM ranks' checkpoint: every
/// rank's part merged on rank 0 block by block, dem::DistDem::save_state_file). Sections come
/// in file order, `sections` of them; a section's content is either given whole (section()) or
/// its length is reserved (reserve()) and its bytes are written into it later, in any order
/// (write_at(), each byte once). commit() writes the header's length and the checksum (reading
/// the file back once for it), then fsyncs and renames the temporary file `<path>.tmp-<pid>`
/// over `path` as write_atomically() does. A writer destroyed before commit() removes its
/// temporary file. Throws StateFileError naming the file when a call to the system fails, and
/// std::logic_error on misuse (a write outside the reserved bytes, a commit before every
/// section and reserved byte is there).
class StateFileWriter {
 public:
  StateFileWriter(const std::filesystem::path& path, std::string_view kind, std::string_view code_version,
                  std::uint64_t scene_hash, std::uint32_t sections);
  ~StateFileWriter();
  StateFileWriter(const StateFileWriter&) = delete;
  StateFileWriter& operator=(const StateFileWriter&) = delete;

  void section(std::string_view name, std::string_view content);
  /// A section of `length` bytes, written later by write_at(); returns its content's offset in the file.
  std::uint64_t reserve(std::string_view name, std::uint64_t length);
  void write_at(std::uint64_t offset, std::string_view bytes);
  void commit();

 private:
  void put(std::uint64_t offset, std::string_view bytes);  // pwrite, whole
  void head(std::string_view name, std::uint64_t length);  // a section's name and length, appended
  [[noreturn]] void fail(const char* call) const;
  std::filesystem::path path_, tmp_;
  int fd_ = -1;
  std::uint64_t end_ = 0;  // bytes appended so far
  std::uint32_t declared_ = 0, count_ = 0;
  struct Region {
    std::uint64_t off, len, filled = 0;
  };
  std::vector<Region> reserved_;
};

class StateReader;

/// Reads one section; every get checks the remaining length (a short section throws, naming
/// the file and the section).
class SectionReader {
 public:
  /// A section's content (or a range of it) read on its own, from a file read in pieces
  /// (StateFileReader); the reader owns the bytes. `source` and `section` name them in errors.
  SectionReader(std::string bytes, std::string source, std::string section)
      : source_(std::move(source)), name_(std::move(section)), own_(std::move(bytes)), owns_(true), p_(own_.data()),
        end_(own_.size()) {}
  SectionReader(SectionReader&& o) noexcept
      : source_(std::move(o.source_)), name_(std::move(o.name_)), own_(std::move(o.own_)), owns_(o.owns_),
        p_(owns_ ? own_.data() : o.p_), pos_(o.pos_), end_(o.end_) {}
  SectionReader(const SectionReader&) = delete;
  SectionReader& operator=(const SectionReader&) = delete;

  std::uint8_t u8() { return static_cast<std::uint8_t>(*take(1)); }
  bool b();
  std::int8_t i8() { return static_cast<std::int8_t>(u8()); }
  std::uint32_t u32() { return get_le<std::uint32_t>(); }
  std::int32_t i32() { return static_cast<std::int32_t>(get_le<std::uint32_t>()); }
  std::uint64_t u64() { return get_le<std::uint64_t>(); }
  std::int64_t i64() { return static_cast<std::int64_t>(get_le<std::uint64_t>()); }
  double f64() { return std::bit_cast<double>(get_le<std::uint64_t>()); }
  std::string str();
  std::vector<double> f64s();
  std::vector<std::uint8_t> u8s();
  std::vector<std::int32_t> i32s();
  std::vector<std::uint32_t> u32s();
  std::vector<std::uint64_t> u64s();
  /// An element count followed by at least `min_bytes_each` bytes per element: refuses counts
  /// that cannot fit in what is left (a corrupt count must not allocate gigabytes).
  std::uint64_t count(std::size_t min_bytes_each);

  /// Throws unless every byte of the section was read.
  void done();
  /// A malformed section: throws StateFileError "<file>: section '<name>': <what>".
  [[noreturn]] void fail(const std::string& what) const;
  std::size_t remaining() const { return end_ - pos_; }

 private:
  friend class StateReader;
  SectionReader(std::string source, std::string name, const char* p, std::size_t n)
      : source_(std::move(source)), name_(std::move(name)), p_(p), end_(n) {}
  const char* take(std::size_t n);
  template <class U>
  U get_le() {
    U v;
    std::memcpy(&v, take(sizeof(U)), sizeof(U));
    if constexpr (std::endian::native == std::endian::big) {
      U r = 0;
      for (std::size_t i = 0; i < sizeof(U); ++i) r = static_cast<U>((r << 8) | ((v >> (8 * i)) & 0xffu));
      v = r;
    }
    return v;
  }
  std::string source_, name_;
  std::string own_;     // the bytes, when the reader owns them
  bool owns_ = false;
  const char* p_;
  std::size_t pos_ = 0, end_;
};

/// Parses and verifies a whole state file held in memory. `source` names the file in every
/// message.
class StateReader {
 public:
  StateReader(std::string bytes, std::string source, std::string_view expected_kind,
              std::uint64_t expected_scene_hash);

  const StateHeader& header() const { return header_; }
  const std::string& source() const { return source_; }
  bool has(std::string_view section) const;
  /// The named section (each may be read once). Throws if the file has none of that name.
  SectionReader section(std::string_view name);
  /// The sections' names in file order.
  std::vector<std::string> names() const;
  /// The named section's content as it is in the file (read once, as section()).
  std::string_view section_bytes(std::string_view name);
  /// Throws if a section of the file was never asked for (unknown to this code).
  void finish() const;
  [[noreturn]] void fail(const std::string& what) const;

 private:
  struct Entry {
    std::string name;
    std::size_t off, len;
    bool used = false;
  };
  std::string bytes_;
  std::string source_;
  StateHeader header_;
  std::vector<Entry> sections_;
};

/// Reads a state file from disk in pieces, for a state too large to hold in memory at once (the
/// DEM ranks' resume: rank 0 reads the World's sections a block of rows at a time and sends
/// each rank its share, dem::DistDem::load_state_file). On construction the file's container is
/// checked as StateReader checks it, with the same refusals and messages (the checksum in one
/// pass of 4 MiB reads); sections are then read whole or in ranges of their content.
class StateFileReader {
 public:
  StateFileReader(const std::filesystem::path& path, std::string_view expected_kind, std::uint64_t expected_scene_hash);
  ~StateFileReader();
  StateFileReader(const StateFileReader&) = delete;
  StateFileReader& operator=(const StateFileReader&) = delete;

  const StateHeader& header() const { return header_; }
  const std::string& source() const { return source_; }
  std::vector<std::string> names() const;
  /// A section's content length; its content whole; `n` bytes of it from `offset`. Throw
  /// StateFileError for a missing section or a range beyond it.
  std::uint64_t length(std::string_view name) const;
  std::string section_bytes(std::string_view name) const;
  std::string read(std::string_view name, std::uint64_t offset, std::size_t n) const;

 private:
  struct Section {
    std::string name;
    std::uint64_t off, len;
  };
  const Section& find(std::string_view name) const;
  std::string pread_all(std::uint64_t off, std::size_t n) const;
  std::string source_;
  int fd_ = -1;
  std::uint64_t size_ = 0;
  StateHeader header_;
  std::vector<Section> sections_;
};

/// Write `bytes` to `path` atomically: `<path>.tmp-<pid>` is written and fsync'ed, then renamed
/// over `path` (and the folder fsync'ed). Throws StateFileError naming the file and the call.
void write_atomically(const std::filesystem::path& path, std::string_view bytes);

/// The whole file; throws StateFileError naming the file if it cannot be read.
std::string read_whole_file(const std::filesystem::path& path);

/// `bytes` to `out`; the rest of `in` (`source` names it in errors). Throw StateFileError.
void write_stream(std::ostream& out, std::string_view bytes);
std::string read_stream(std::istream& in, std::string_view source);

/// What a core writes into the header next to its state.
struct StateMeta {
  std::uint64_t scene_hash = 0;                       // the caller's hash of the scene
  std::string code_version = default_code_version();  // recorded, not checked on load
};

/// A section's fields declared once for both directions: save_fields(w, a, b, ...) writes them
/// in the order given, each by its type (bool: b, int32: i32, int64: i64, uint64: u64, double:
/// f64), and load_fields(r, a, b, ...) reads the same list back, so that what a checkpoint
/// writes and what it reads cannot drift apart.
template <class T>
void save_field(StateWriter& w, const T& v) {
  if constexpr (std::same_as<T, bool>) w.b(v);
  else if constexpr (std::same_as<T, std::int32_t>) w.i32(v);
  else if constexpr (std::same_as<T, std::int64_t>) w.i64(v);
  else if constexpr (std::same_as<T, std::uint64_t>) w.u64(v);
  else if constexpr (std::same_as<T, double>) w.f64(v);
  else static_assert(sizeof(T) == 0, "save_fields: bool, int32, int64, uint64 or double");
}
template <class T>
void load_field(SectionReader& r, T& v) {
  if constexpr (std::same_as<T, bool>) v = r.b();
  else if constexpr (std::same_as<T, std::int32_t>) v = r.i32();
  else if constexpr (std::same_as<T, std::int64_t>) v = r.i64();
  else if constexpr (std::same_as<T, std::uint64_t>) v = r.u64();
  else if constexpr (std::same_as<T, double>) v = r.f64();
  else static_assert(sizeof(T) == 0, "load_fields: bool, int32, int64, uint64 or double");
}
template <class... T>
void save_fields(StateWriter& w, const T&... v) {
  (save_field(w, v), ...);
}
template <class... T>
void load_fields(SectionReader& r, T&... v) {
  (load_field(r, v), ...);
}

/// The memory, stream and file front ends every core's checkpoint shares: `Access` has
/// static save(const Obj&, StateWriter&) and load(Obj&, StateReader&); `kind` names the core.
template <class Access, class Obj>
struct StateFront {
  static std::string bytes(const Obj& o, std::string_view kind, const StateMeta& meta) {
    StateWriter w(kind, meta.code_version, meta.scene_hash);
    Access::save(o, w);
    return w.bytes();
  }
  static StateHeader load(Obj& o, std::string b, std::string_view kind, std::uint64_t scene_hash,
                          std::string_view source) {
    StateReader r(std::move(b), std::string(source), kind, scene_hash);
    Access::load(o, r);
    return r.header();
  }
};

}  // namespace demfdm::io
