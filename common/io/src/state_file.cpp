// State-file container: see state_file.hpp and docs/checkpoint-format.md.
#include "demfdm/io/state_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <fstream>
#include <functional>
#include <istream>
#include <iterator>
#include <ostream>
#include <iomanip>
#include <sstream>

#ifndef DEMFDM_VERSION_STRING
#define DEMFDM_VERSION_STRING "unknown"
#endif

namespace demfdm::io {

namespace {

std::string hex(std::uint64_t v) {
  std::ostringstream s;
  s << "0x" << std::hex << std::setw(16) << std::setfill('0') << v;
  return s.str();
}

// Little-endian integers at a byte offset of the file (the header fields).
template <class U>
U le_at(const std::string& b, std::size_t off) {
  U v = 0;
  for (std::size_t i = 0; i < sizeof(U); ++i)
    v |= static_cast<U>(static_cast<U>(static_cast<unsigned char>(b[off + i])) << (8 * i));
  return v;
}

template <class U>
void le_append(std::string& s, U v) {
  for (std::size_t i = 0; i < sizeof(U); ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xffu));
}

void str_append(std::string& s, std::string_view v) {
  le_append<std::uint32_t>(s, static_cast<std::uint32_t>(v.size()));
  s.append(v);
}

// magic + version + total length: what must be there before anything else can be judged.
constexpr std::size_t kFixedHead = 8 + 4 + 8;

[[noreturn]] void file_error(const char* call, const std::filesystem::path& f) {
  const int e = errno;
  throw StateFileError(f.string() + ": " + call + " failed: " + std::strerror(e));
}

}  // namespace

std::string default_code_version() { return std::string("demfdm ") + DEMFDM_VERSION_STRING + " gcc " + __VERSION__; }

std::uint64_t fnv1a64(const void* data, std::size_t n, std::uint64_t h) {
  const auto* p = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < n; ++i) {
    h ^= p[i];
    h *= 1099511628211ULL;
  }
  return h;
}

// ---- writer ------------------------------------------------------------------------------

StateWriter::StateWriter(std::string_view kind, std::string_view code_version, std::uint64_t scene_hash) {
  str_append(head_, kind);
  str_append(head_, code_version);
  le_append<std::uint64_t>(head_, scene_hash);
}

void StateWriter::begin(std::string_view section) {
  if (open_ != std::string::npos) throw std::logic_error("StateWriter::begin: a section is already open");
  str_append(buf_, section);
  open_ = buf_.size();
  le_append<std::uint64_t>(buf_, 0);  // patched by end()
}

void StateWriter::end() {
  if (open_ == std::string::npos) throw std::logic_error("StateWriter::end: no section is open");
  const std::uint64_t len = buf_.size() - open_ - 8;
  for (std::size_t i = 0; i < 8; ++i) buf_[open_ + i] = static_cast<char>((len >> (8 * i)) & 0xffu);
  open_ = std::string::npos;
  ++count_;
}

void ByteWriter::str(std::string_view s) {
  u32(static_cast<std::uint32_t>(s.size()));
  buf_.append(s);
}

void ByteWriter::f64s(std::span<const double> v) {
  u64(v.size());
  for (double x : v) f64(x);
}
void ByteWriter::u8s(std::span<const std::uint8_t> v) {
  u64(v.size());
  buf_.append(reinterpret_cast<const char*>(v.data()), v.size());
}
void ByteWriter::i32s(std::span<const std::int32_t> v) {
  u64(v.size());
  for (auto x : v) i32(x);
}
void ByteWriter::u32s(std::span<const std::uint32_t> v) {
  u64(v.size());
  for (auto x : v) u32(x);
}
void ByteWriter::u64s(std::span<const std::uint64_t> v) {
  u64(v.size());
  for (auto x : v) u64(x);
}

std::string StateWriter::bytes() const {
  if (open_ != std::string::npos) throw std::logic_error("StateWriter::bytes: a section is still open");
  std::string out;
  const std::uint64_t total = kFixedHead + head_.size() + 4 + buf_.size() + 8;
  out.reserve(total);
  out.append(kStateMagic, 8);
  le_append<std::uint32_t>(out, kStateFormatVersion);
  le_append<std::uint64_t>(out, total);
  out.append(head_);
  le_append<std::uint32_t>(out, count_);
  out.append(buf_);
  le_append<std::uint64_t>(out, fnv1a64(out.data(), out.size()));
  return out;
}

// ---- section reader ------------------------------------------------------------------------

const char* SectionReader::take(std::size_t n) {
  if (n > end_ - pos_) {
    std::ostringstream s;
    s << "needs " << n << " more bytes at offset " << pos_ << " of " << end_ << " (section too short)";
    fail(s.str());
  }
  const char* q = p_ + pos_;
  pos_ += n;
  return q;
}

bool SectionReader::b() {
  const std::uint8_t v = u8();
  if (v > 1) fail("boolean byte " + std::to_string(v) + " (expected 0 or 1)");
  return v != 0;
}

std::string SectionReader::str() {
  const std::uint32_t n = u32();
  const char* q = take(n);
  return std::string(q, n);
}

std::uint64_t SectionReader::count(std::size_t min_bytes_each) {
  const std::uint64_t n = u64();
  if (min_bytes_each > 0 && n > remaining() / min_bytes_each) {
    std::ostringstream s;
    s << "count " << n << " at offset " << pos_ - 8 << " exceeds what the " << remaining()
      << " remaining bytes can hold";
    fail(s.str());
  }
  return n;
}

std::vector<double> SectionReader::f64s() {
  std::vector<double> v(count(8));
  for (auto& x : v) x = f64();
  return v;
}
std::vector<std::uint8_t> SectionReader::u8s() {
  const std::uint64_t n = count(1);
  const char* q = take(n);
  return std::vector<std::uint8_t>(reinterpret_cast<const std::uint8_t*>(q), reinterpret_cast<const std::uint8_t*>(q) + n);
}
std::vector<std::int32_t> SectionReader::i32s() {
  std::vector<std::int32_t> v(count(4));
  for (auto& x : v) x = i32();
  return v;
}
std::vector<std::uint32_t> SectionReader::u32s() {
  std::vector<std::uint32_t> v(count(4));
  for (auto& x : v) x = u32();
  return v;
}
std::vector<std::uint64_t> SectionReader::u64s() {
  std::vector<std::uint64_t> v(count(8));
  for (auto& x : v) x = u64();
  return v;
}

void SectionReader::done() {
  if (pos_ != end_) {
    std::ostringstream s;
    s << (end_ - pos_) << " bytes left unread of " << end_ << " (section longer than this code expects)";
    fail(s.str());
  }
}

void SectionReader::fail(const std::string& what) const {
  throw StateFileError(source_ + ": section '" + name_ + "': " + what);
}

// ---- file reader ---------------------------------------------------------------------------

void StateReader::fail(const std::string& what) const { throw StateFileError(source_ + ": " + what); }

namespace {

// A state file's container as its readers check it (docs/checkpoint-format.md "Refusals"), from
// `size` bytes read through `at(offset, n)` and the FNV-1a 64 of the bytes before the checksum
// (`checksum()`, asked for once the length is known to be right). `fail` throws.
struct Container {
  StateHeader header;
  struct Section {
    std::string name;
    std::uint64_t off, len;
  };
  std::vector<Section> sections;
};

Container parse_container(std::uint64_t size, const std::function<std::string(std::uint64_t, std::size_t)>& at,
                          const std::function<std::uint64_t()>& checksum, std::string_view expected_kind,
                          std::uint64_t expected_scene_hash, const std::function<void(const std::string&)>& fail) {
  Container c;
  if (size >= 8 && at(0, 8) != std::string_view(kStateMagic, 8))
    fail("bad magic: not a demfdm state file (expected the first 8 bytes to be \"DEMFDMST\")");
  if (size < kFixedHead + 8) {
    std::ostringstream s;
    s << "truncated: " << size << " bytes, shorter than the fixed header and checksum (" << kFixedHead + 8 << " bytes)";
    fail(s.str());
  }
  const std::string head = at(0, kFixedHead);
  c.header.format_version = le_at<std::uint32_t>(head, 8);
  if (c.header.format_version != kStateFormatVersion) {
    std::ostringstream s;
    s << "format version " << c.header.format_version << ", this code reads version " << kStateFormatVersion;
    fail(s.str());
  }
  const std::uint64_t total = le_at<std::uint64_t>(head, 12);
  if (size < total) {
    std::ostringstream s;
    s << "truncated: " << size << " bytes, the header announces " << total;
    fail(s.str());
  }
  if (size > total) {
    std::ostringstream s;
    s << size << " bytes, the header announces " << total << " (trailing bytes)";
    fail(s.str());
  }
  const std::uint64_t stored = le_at<std::uint64_t>(at(size - 8, 8), 0);
  const std::uint64_t computed = checksum();
  if (stored != computed)
    fail("checksum mismatch: stored " + hex(stored) + ", computed " + hex(computed) + " (file damaged)");
  // From here the bytes are what the writer produced; the structure is still checked (as a
  // section named "header" that ends before the checksum).
  std::uint64_t pos = kFixedHead;
  const std::uint64_t end = size - 8;
  auto take = [&](std::uint64_t n) {
    if (n > end - pos) {
      std::ostringstream s;
      s << "section 'header': needs " << n << " more bytes at offset " << pos - kFixedHead << " of " << end - kFixedHead
        << " (section too short)";
      fail(s.str());
    }
    const std::uint64_t p = pos;
    pos += n;
    return p;
  };
  auto u32 = [&] { return le_at<std::uint32_t>(at(take(4), 4), 0); };
  auto u64 = [&] { return le_at<std::uint64_t>(at(take(8), 8), 0); };
  auto str = [&] {
    const std::uint32_t n = u32();
    return at(take(n), n);
  };
  c.header.kind = str();
  c.header.code_version = str();
  c.header.scene_hash = u64();
  if (c.header.kind != expected_kind)
    fail("kind '" + c.header.kind + "', expected '" + std::string(expected_kind) + "'");
  if (c.header.scene_hash != expected_scene_hash)
    fail("scene hash " + hex(c.header.scene_hash) + " in the file, expected " + hex(expected_scene_hash) +
         " (a checkpoint of another scene)");
  const std::uint32_t n = u32();
  for (std::uint32_t k = 0; k < n; ++k) {
    Container::Section e;
    e.name = str();
    const std::uint64_t len = u64();
    if (len > end - pos) {
      std::ostringstream s;
      s << "section '" << e.name << "' announces " << len << " bytes, " << end - pos << " are left";
      fail(s.str());
    }
    e.off = take(len);
    e.len = len;
    for (const Container::Section& o : c.sections)
      if (o.name == e.name) fail("section '" + e.name + "' appears twice");
    c.sections.push_back(std::move(e));
  }
  if (end - pos != 0) fail(std::to_string(end - pos) + " bytes after the last section");
  return c;
}

}  // namespace

StateReader::StateReader(std::string bytes, std::string source, std::string_view expected_kind,
                         std::uint64_t expected_scene_hash)
    : bytes_(std::move(bytes)), source_(std::move(source)) {
  const std::string& b = bytes_;
  const Container c = parse_container(
      b.size(), [&](std::uint64_t off, std::size_t n) { return b.substr(static_cast<std::size_t>(off), n); },
      [&] { return fnv1a64(b.data(), b.size() - 8); }, expected_kind, expected_scene_hash,
      [&](const std::string& what) { fail(what); });
  header_ = c.header;
  for (const Container::Section& e : c.sections)
    sections_.push_back(Entry{e.name, static_cast<std::size_t>(e.off), static_cast<std::size_t>(e.len)});
}

// ---- a state file read in pieces ------------------------------------------------------------

StateFileReader::StateFileReader(const std::filesystem::path& path, std::string_view expected_kind,
                                 std::uint64_t expected_scene_hash)
    : source_(path.string()) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) file_error("open", path);
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    const int e = errno;
    ::close(fd_);
    errno = e;
    file_error("fstat", path);
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  try {
    const Container c = parse_container(
        size_, [&](std::uint64_t off, std::size_t n) { return pread_all(off, n); },
        [&] {
          std::uint64_t h = fnv1a64(nullptr, 0);
          const std::uint64_t end = size_ - 8;
          for (std::uint64_t at = 0; at < end;) {
            const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(std::uint64_t{4} << 20, end - at));
            const std::string b = pread_all(at, n);
            h = fnv1a64(b.data(), b.size(), h);
            at += n;
          }
          return h;
        },
        expected_kind, expected_scene_hash, [&](const std::string& what) { throw StateFileError(source_ + ": " + what); });
    header_ = c.header;
    for (const auto& e : c.sections) sections_.push_back(Section{e.name, e.off, e.len});
  } catch (...) {
    ::close(fd_);
    fd_ = -1;
    throw;
  }
}

StateFileReader::~StateFileReader() {
  if (fd_ >= 0) ::close(fd_);
}

std::string StateFileReader::pread_all(std::uint64_t off, std::size_t n) const {
  std::string b(n, '\0');
  std::size_t done = 0;
  while (done < n) {
    const ssize_t r = ::pread(fd_, b.data() + done, n - done, static_cast<off_t>(off + done));
    if (r < 0) {
      if (errno == EINTR) continue;
      file_error("pread", source_);
    }
    if (r == 0)
      throw StateFileError(source_ + ": truncated while reading: " + std::to_string(off + done) + " of " +
                           std::to_string(size_) + " bytes (changed since it was opened?)");
    done += static_cast<std::size_t>(r);
  }
  return b;
}

const StateFileReader::Section& StateFileReader::find(std::string_view name) const {
  for (const Section& e : sections_)
    if (e.name == name) return e;
  throw StateFileError(source_ + ": missing section '" + std::string(name) + "' (kind '" + header_.kind +
                       "', code version '" + header_.code_version + "')");
}

std::vector<std::string> StateFileReader::names() const {
  std::vector<std::string> out;
  for (const Section& e : sections_) out.push_back(e.name);
  return out;
}

std::uint64_t StateFileReader::length(std::string_view name) const { return find(name).len; }

std::string StateFileReader::section_bytes(std::string_view name) const {
  const Section& e = find(name);
  return pread_all(e.off, static_cast<std::size_t>(e.len));
}

std::string StateFileReader::read(std::string_view name, std::uint64_t offset, std::size_t n) const {
  const Section& e = find(name);
  if (offset > e.len || n > e.len - offset) {
    std::ostringstream s;
    s << source_ << ": section '" << e.name << "': needs " << n << " bytes at offset " << offset << " of " << e.len
      << " (section too short)";
    throw StateFileError(s.str());
  }
  return pread_all(e.off + offset, n);
}

bool StateReader::has(std::string_view name) const {
  for (const Entry& e : sections_)
    if (e.name == name) return true;
  return false;
}

SectionReader StateReader::section(std::string_view name) {
  for (Entry& e : sections_)
    if (e.name == name) {
      if (e.used) fail("section '" + e.name + "' read twice");
      e.used = true;
      return SectionReader(source_, e.name, bytes_.data() + e.off, e.len);
    }
  fail("missing section '" + std::string(name) + "' (kind '" + header_.kind + "', code version '" +
       header_.code_version + "')");
}

std::vector<std::string> StateReader::names() const {
  std::vector<std::string> out;
  for (const Entry& e : sections_) out.push_back(e.name);
  return out;
}

std::string_view StateReader::section_bytes(std::string_view name) {
  SectionReader r = section(name);
  return {r.p_, r.end_};
}

void StateReader::finish() const {
  std::string unknown;
  for (const Entry& e : sections_)
    if (!e.used) unknown += (unknown.empty() ? "'" : ", '") + e.name + "'";
  if (!unknown.empty()) fail("unknown section(s) " + unknown + " (written by code version '" + header_.code_version + "')");
}

// ---- files -----------------------------------------------------------------------------------

namespace {

// fsync and close `fd` (the file `tmp`), rename it over `path` and make the rename durable; on a
// failure the temporary file is removed and the error names the call.
void publish(int fd, const std::filesystem::path& tmp, const std::filesystem::path& path) {
  auto undo = [&](const char* call, const std::filesystem::path& f, bool close_fd) {
    const int e = errno;
    if (close_fd) ::close(fd);
    ::unlink(tmp.c_str());
    errno = e;
    file_error(call, f);
  };
  if (::fsync(fd) != 0) undo("fsync", tmp, true);
  if (::close(fd) != 0) undo("close", tmp, false);
  if (::rename(tmp.c_str(), path.c_str()) != 0) undo("rename", path, false);
  // Make the rename itself durable.
  std::filesystem::path dir = path.parent_path();
  if (dir.empty()) dir = ".";
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

std::filesystem::path temporary_of(const std::filesystem::path& path) {
  return path.string() + ".tmp-" + std::to_string(::getpid());
}

}  // namespace

void write_atomically(const std::filesystem::path& path, std::string_view bytes) {
  const std::filesystem::path tmp = temporary_of(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) file_error("open", tmp);
  std::size_t off = 0;
  while (off < bytes.size()) {
    const ssize_t w = ::write(fd, bytes.data() + off, bytes.size() - off);
    if (w < 0) {
      if (errno == EINTR) continue;
      const int e = errno;
      ::close(fd);
      ::unlink(tmp.c_str());
      errno = e;
      file_error("write", tmp);
    }
    off += static_cast<std::size_t>(w);
  }
  publish(fd, tmp, path);
}

// ---- a state file written in pieces ----------------------------------------------------------

StateFileWriter::StateFileWriter(const std::filesystem::path& path, std::string_view kind, std::string_view code_version,
                                 std::uint64_t scene_hash, std::uint32_t sections)
    : path_(path), tmp_(temporary_of(path)), declared_(sections) {
  fd_ = ::open(tmp_.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) file_error("open", tmp_);
  std::string h(kStateMagic, 8);
  le_append<std::uint32_t>(h, kStateFormatVersion);
  le_append<std::uint64_t>(h, 0);  // the total length, written by commit()
  str_append(h, kind);
  str_append(h, code_version);
  le_append<std::uint64_t>(h, scene_hash);
  le_append<std::uint32_t>(h, sections);
  try {
    put(0, h);
  } catch (...) {
    ::close(fd_);
    ::unlink(tmp_.c_str());
    throw;
  }
  end_ = h.size();
}

StateFileWriter::~StateFileWriter() {
  if (fd_ < 0) return;
  ::close(fd_);
  ::unlink(tmp_.c_str());
}

void StateFileWriter::fail(const char* call) const { file_error(call, tmp_); }

void StateFileWriter::put(std::uint64_t offset, std::string_view bytes) {
  if (fd_ < 0) throw std::logic_error("StateFileWriter: the file is committed");
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t w = ::pwrite(fd_, bytes.data() + done, bytes.size() - done, static_cast<off_t>(offset + done));
    if (w < 0) {
      if (errno == EINTR) continue;
      fail("pwrite");
    }
    done += static_cast<std::size_t>(w);
  }
}

void StateFileWriter::head(std::string_view name, std::uint64_t length) {
  if (count_ == declared_) throw std::logic_error("StateFileWriter: more sections than the " + std::to_string(declared_) + " declared");
  std::string h;
  str_append(h, name);
  le_append<std::uint64_t>(h, length);
  put(end_, h);
  end_ += h.size();
  ++count_;
}

void StateFileWriter::section(std::string_view name, std::string_view content) {
  head(name, content.size());
  put(end_, content);
  end_ += content.size();
}

std::uint64_t StateFileWriter::reserve(std::string_view name, std::uint64_t length) {
  head(name, length);
  const std::uint64_t at = end_;
  reserved_.push_back(Region{at, length});
  end_ += length;
  return at;
}

void StateFileWriter::write_at(std::uint64_t offset, std::string_view bytes) {
  for (Region& r : reserved_)
    if (offset >= r.off && offset + bytes.size() <= r.off + r.len) {
      put(offset, bytes);
      r.filled += bytes.size();
      return;
    }
  throw std::logic_error("StateFileWriter::write_at: " + std::to_string(bytes.size()) + " bytes at offset " +
                         std::to_string(offset) + " are outside every reserved section");
}

void StateFileWriter::commit() {
  if (count_ != declared_)
    throw std::logic_error("StateFileWriter::commit: " + std::to_string(count_) + " of " + std::to_string(declared_) + " sections written");
  for (const Region& r : reserved_)
    if (r.filled != r.len)
      throw std::logic_error("StateFileWriter::commit: a reserved section at offset " + std::to_string(r.off) + " has " +
                             std::to_string(r.filled) + " of its " + std::to_string(r.len) + " bytes");
  const std::uint64_t total = end_ + 8;
  std::string len;
  le_append<std::uint64_t>(len, total);
  put(12, len);
  // the checksum of every byte before it, read back in order
  std::uint64_t h = fnv1a64(nullptr, 0);
  std::vector<char> buf(std::size_t{4} << 20);
  for (std::uint64_t at = 0; at < end_;) {
    const ssize_t n = ::pread(fd_, buf.data(), static_cast<std::size_t>(std::min<std::uint64_t>(buf.size(), end_ - at)),
                              static_cast<off_t>(at));
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("pread");
    }
    if (n == 0) throw StateFileError(tmp_.string() + ": read back " + std::to_string(at) + " of " + std::to_string(end_) + " bytes");
    h = fnv1a64(buf.data(), static_cast<std::size_t>(n), h);
    at += static_cast<std::uint64_t>(n);
  }
  std::string sum;
  le_append<std::uint64_t>(sum, h);
  put(end_, sum);
  const int fd = fd_;
  fd_ = -1;
  publish(fd, tmp_, path_);
}

void write_stream(std::ostream& out, std::string_view bytes) {
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  if (!out) throw StateFileError("save_state: writing " + std::to_string(bytes.size()) + " bytes to the stream failed");
}

std::string read_stream(std::istream& in, std::string_view source) {
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw StateFileError(std::string(source) + ": read failed");
  return bytes;
}

std::string read_whole_file(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw StateFileError(path.string() + ": cannot open for reading: " + std::strerror(errno));
  std::ostringstream s;
  s << in.rdbuf();
  if (in.bad()) throw StateFileError(path.string() + ": read failed");
  return std::move(s).str();
}

}  // namespace demfdm::io
