#include "traffic_log.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <memory>
#include <tuple>

namespace demfdm::traffic {

namespace {

constexpr std::uint32_t kSync = 0xEDA1DA01u;
constexpr std::int64_t kFrame = 28;  // sync, eventnum, timestamp, channel length, data length
constexpr std::uint8_t kCheckBegin = 0, kCheckBlockKind = 1, kCheckEnd = 2;
constexpr std::int64_t kCheckHead = 28;  // "DFLC", version, kind, 2 spare, first i64, count u32, total i64

std::uint32_t get32(const std::uint8_t* p) {
  return (std::uint32_t(p[0]) << 24) | (std::uint32_t(p[1]) << 16) | (std::uint32_t(p[2]) << 8) | std::uint32_t(p[3]);
}
std::uint64_t get64(const std::uint8_t* p) { return (std::uint64_t(get32(p)) << 32) | get32(p + 4); }
void put32(std::uint8_t* p, std::uint32_t v) {
  p[0] = std::uint8_t(v >> 24);
  p[1] = std::uint8_t(v >> 16);
  p[2] = std::uint8_t(v >> 8);
  p[3] = std::uint8_t(v);
}
void put64(std::uint8_t* p, std::uint64_t v) {
  put32(p, std::uint32_t(v >> 32));
  put32(p + 4, std::uint32_t(v));
}
std::string hex32(std::uint32_t v) {
  char b[16];
  std::snprintf(b, sizeof b, "0x%08X", v);
  return b;
}
std::string at_byte(std::int64_t index, std::int64_t offset) {
  return "event " + std::to_string(index) + " at byte " + std::to_string(offset);
}

template <class T>
bool decodes(const std::vector<std::uint8_t>& d) {
  T m{};
  try {
    return m.decode(d.data(), 0, static_cast<int>(d.size())) == static_cast<int>(d.size()) &&
           m.header.msg_type == bus::MsgType<T>::id;
  } catch (const std::exception&) {
    return false;
  }
}

}  // namespace

const char* LogError::kind_name(Kind k) {
  switch (k) {
    case Kind::Empty: return "empty log";
    case Kind::NotALog: return "not an LCM event log";
    case Kind::Truncated: return "truncated log";
    case Kind::Corrupt: return "corrupt log";
  }
  return "bad log";
}

LogError::LogError(Kind k, std::string file, std::int64_t at, std::int64_t event, const std::string& detail)
    : std::runtime_error(file + ": " + kind_name(k) + ": " + detail), kind(k), path(std::move(file)), offset(at),
      eventnum(event) {}

std::uint32_t crc32(std::uint32_t crc, const void* data, std::size_t n) {
  static const auto table = [] {
    std::array<std::uint32_t, 256> t{};
    for (std::uint32_t i = 0; i < 256; ++i) {
      std::uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[i] = c;
    }
    return t;
  }();
  const auto* p = static_cast<const std::uint8_t*>(data);
  crc = ~crc;
  for (std::size_t i = 0; i < n; ++i) crc = table[(crc ^ p[i]) & 0xFFu] ^ (crc >> 8);
  return ~crc;
}

std::string payload_problem(const std::string& ch, const std::vector<std::uint8_t>& d) {
  namespace c = bus::channel;
  if (ch == c::kScene || ch == kSceneRepeat) return decodes<demfdm::scene_t>(d) ? "" : "scene_t";
  if (ch == c::kHello) return decodes<demfdm::hello_t>(d) ? "" : "hello_t";
  if (ch == c::kCommand) return decodes<demfdm::command_t>(d) ? "" : "command_t";
  if (ch == c::kReport) return decodes<demfdm::report_t>(d) ? "" : "report_t";
  if (ch == c::kHeartbeat) return decodes<demfdm::heartbeat_t>(d) ? "" : "heartbeat_t";
  if (ch == c::kNack) return decodes<demfdm::nack_t>(d) ? "" : "nack_t";
  if (ch == c::kIfaceMesh) return decodes<demfdm::iface_mesh_t>(d) ? "" : "iface_mesh_t";
  if (ch == c::kIfaceKin) return decodes<demfdm::iface_kin_t>(d) ? "" : "iface_kin_t";
  if (ch == c::kIfaceForce) return decodes<demfdm::iface_force_t>(d) ? "" : "iface_force_t";
  return "";
}

EventReader::EventReader(const std::string& path) : path_(path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw std::runtime_error(path + ": is a folder, not a log file");
  f_ = std::fopen(path.c_str(), "rb");
  if (!f_) throw std::runtime_error(path + ": cannot open (" + std::strerror(errno) + ")");
  std::setvbuf(f_, nullptr, _IOFBF, 1 << 20);
  auto n = std::filesystem::file_size(path, ec);
  size_ = ec ? 0 : static_cast<std::int64_t>(n);
}

EventReader::~EventReader() {
  if (f_) std::fclose(f_);
}

void EventReader::fail(LogError::Kind k, std::int64_t at, std::int64_t event, const std::string& detail) const {
  throw LogError(k, path_, at, event, detail);
}

void EventReader::read_exact(void* buf, std::size_t n) {
  if (n && std::fread(buf, 1, n, f_) != n)
    fail(LogError::Kind::Truncated, pos_, index_, "read error at byte " + std::to_string(pos_) + " (" +
                                                      std::strerror(errno) + ")");
  pos_ += static_cast<std::int64_t>(n);
}

bool EventReader::next(RawEvent& e) {
  using K = LogError::Kind;
  for (;;) {
    const std::int64_t at = pos_, i = index_, left = size_ - pos_;
    if (left <= 0) {
      if (checksummed_ && !ended_)
        fail(K::Truncated, at, i,
             "the file ends at byte " + std::to_string(at) + " after event " + std::to_string(i - 1) +
                 " without the closing checksum block that demfdm_log merge writes: the rest of the log is missing");
      return false;
    }
    if (ended_) fail(K::Corrupt, at, i, at_byte(i, at) + ": data after the closing checksum block");
    std::uint8_t h[kFrame];
    if (left < 4)
      fail(K::Truncated, at, i, at_byte(i, at) + ": the file ends inside its sync word (" + std::to_string(left) +
                                    " of 28 frame bytes)");
    read_exact(h, 4);
    if (get32(h) != kSync) {
      if (at == 0)
        fail(K::NotALog, 0, 0, "the file starts with " + hex32(get32(h)) + ", not the LCM sync word 0xEDA1DA01");
      fail(K::Corrupt, at, i, at_byte(i, at) + ": found " + hex32(get32(h)) + " where the sync word 0xEDA1DA01 belongs");
    }
    if (left < kFrame)
      fail(K::Truncated, at, i, at_byte(i, at) + ": the file ends inside its 28-byte frame header (" +
                                    std::to_string(left) + " bytes left)");
    read_exact(h + 4, kFrame - 4);
    const auto num = static_cast<std::int64_t>(get64(h + 4));
    const auto ts = static_cast<std::int64_t>(get64(h + 12));
    const auto chlen = static_cast<std::int32_t>(get32(h + 20));
    const auto dlen = static_cast<std::int32_t>(get32(h + 24));
    if (i > 0 && num != last_eventnum_ + 1)
      fail(K::Corrupt, at, i, at_byte(i, at) + ": event number " + std::to_string(num) + " where " +
                                  std::to_string(last_eventnum_ + 1) + " was expected");
    if (i == 0 && num < 0) fail(K::Corrupt, at, i, at_byte(i, at) + ": negative event number " + std::to_string(num));
    if (chlen <= 0 || chlen >= 1000)
      fail(K::Corrupt, at, i, at_byte(i, at) + ": channel length " + std::to_string(chlen) + " (expected 1..999)");
    if (dlen < 0) fail(K::Corrupt, at, i, at_byte(i, at) + ": negative data length " + std::to_string(dlen));
    if (left - kFrame < chlen)
      fail(K::Truncated, at, i, at_byte(i, at) + ": the file ends inside its channel name (" +
                                    std::to_string(chlen) + " bytes announced, " + std::to_string(left - kFrame) +
                                    " left)");
    e.channel.resize(static_cast<std::size_t>(chlen));
    read_exact(e.channel.data(), e.channel.size());
    for (unsigned char c : e.channel)
      if (c < 0x21 || c > 0x7E)
        fail(K::Corrupt, at, i, at_byte(i, at) + ": the channel name holds the byte 0x" + hex32(c).substr(8) +
                                    ", not a printable character");
    if (left - kFrame - chlen < dlen)
      fail(K::Truncated, at, i, at_byte(i, at) + " (channel " + e.channel + ") announces " + std::to_string(dlen) +
                                    " bytes of data but the file ends " + std::to_string(left - kFrame - chlen) +
                                    " bytes later");
    e.data.resize(static_cast<std::size_t>(dlen));
    read_exact(e.data.data(), e.data.size());
    std::uint32_t crc = crc32(0, h, kFrame);
    crc = crc32(crc, e.channel.data(), e.channel.size());
    crc = crc32(crc, e.data.data(), e.data.size());
    last_eventnum_ = num;
    ++index_;
    if (e.channel == kCheckChannel) {
      check_block(at, e.data);
      continue;
    }
    if (checksummed_) {
      if (static_cast<std::int64_t>(pending_.size()) >= kCheckBlock)
        fail(K::Corrupt, at, i, at_byte(i, at) + ": more than " + std::to_string(kCheckBlock) +
                                    " events since the last checksum block (a block is missing or damaged)");
      pending_.push_back({i, at, crc, e.channel, e.data.size()});
    }
    auto bad = payload_problem(e.channel, e.data);
    if (!bad.empty())
      fail(K::Corrupt, at, i, at_byte(i, at) + " (channel " + e.channel + ", " + std::to_string(dlen) +
                                  " bytes) does not decode as " + bad);
    e.eventnum = num;
    e.timestamp = ts;
    e.offset = at;
    ++data_events_;
    return true;
  }
}

void EventReader::check_block(std::int64_t at, const std::vector<std::uint8_t>& p) {
  using K = LogError::Kind;
  const std::int64_t i = index_ - 1;
  const std::string where = "the checksum block (" + at_byte(i, at) + ")";
  const auto n = static_cast<std::int64_t>(p.size());
  bool ok = n >= kCheckHead + 4 && std::memcmp(p.data(), "DFLC", 4) == 0 && p[4] == 1 && p[5] <= kCheckEnd;
  std::int64_t count = ok ? get32(p.data() + 16) : 0;
  ok = ok && n == kCheckHead + 4 * count + 4 &&
       crc32(0, p.data(), static_cast<std::size_t>(n - 4)) == get32(p.data() + n - 4);
  if (!ok) fail(K::Corrupt, at, i, where + " is damaged");
  const std::uint8_t kind = p[5];
  const auto first = static_cast<std::int64_t>(get64(p.data() + 8));
  const auto total = static_cast<std::int64_t>(get64(p.data() + 20));
  if (kind == kCheckBegin) {
    if (i != 0) fail(K::Corrupt, at, i, where + " is a 'begin' block, which only the first event may be");
    checksummed_ = true;
    return;
  }
  if (!checksummed_) fail(K::Corrupt, at, i, where + " belongs to a checksummed log, but the file does not start as one");
  if (count != static_cast<std::int64_t>(pending_.size()))
    fail(K::Corrupt, at, i, where + " covers " + std::to_string(count) + " events, but " +
                                std::to_string(pending_.size()) +
                                " precede it since the previous block (events lost, inserted or damaged)");
  if (count > 0 && first != pending_.front().eventnum)
    fail(K::Corrupt, at, i, where + " starts at event " + std::to_string(first) + ", the events it follows at " +
                                std::to_string(pending_.front().eventnum));
  for (std::int64_t j = 0; j < count; ++j) {
    const auto& q = pending_[static_cast<std::size_t>(j)];
    const std::uint32_t want = get32(p.data() + kCheckHead + 4 * j);
    if (want != q.crc)
      fail(K::Corrupt, q.offset, q.eventnum,
           at_byte(q.eventnum, q.offset) + " (channel " + q.channel + ", " + std::to_string(q.bytes) +
               " bytes) does not match its checksum (CRC-32 " + hex32(want) + " written, " + hex32(q.crc) + " read)");
  }
  if (total != data_events_)
    fail(K::Corrupt, at, i, where + " counts " + std::to_string(total) + " events in all, the log holds " +
                                std::to_string(data_events_));
  pending_.clear();
  if (kind == kCheckEnd) ended_ = true;
}

Log read_log(const std::string& path) {
  EventReader reader(path);
  if (reader.file_bytes() == 0)
    throw LogError(LogError::Kind::Empty, path, 0, -1, "the file is empty (0 bytes): no traffic was recorded in it");
  Log log;
  std::map<std::int32_t, std::string> scene_chunks;
  std::int32_t scene_n = -1;
  RawEvent raw;
  while (reader.next(raw)) {
    Event e;
    e.channel = raw.channel;
    e.log_us = raw.timestamp;
    e.bytes = static_cast<std::int64_t>(raw.data.size());
    e.data = std::move(raw.data);
    raw.data = {};
    const int datalen = static_cast<int>(e.data.size());
    // Every demfdm message starts with its 8-byte fingerprint, then header_t (no fingerprint).
    if (datalen > 8) {
      try {
        e.has_header = e.header._decodeNoHash(e.data.data(), 8, datalen - 8) >= 0;
      } catch (const std::exception&) {
        e.has_header = false;
      }
    }
    if (e.channel == bus::channel::kScene) {
      demfdm::scene_t s;
      if (decode(e, s) && (log.run_id == 0 || s.header.run_id == log.run_id)) {
        log.run_id = s.header.run_id;
        log.scene_hash = s.scene_hash;
        log.scene_origin = s.origin;
        scene_n = s.n_chunks;
        scene_chunks[s.chunk_index] = s.text;
      }
    } else if (e.channel == bus::channel::kIfaceMesh) {
      demfdm::iface_mesh_t m;
      auto& g = log.mesh;
      if (decode(e, m) && m.header.sender == "continuum" && !g.chunks.count(m.chunk_index)) {
        g.n_chunks = m.n_chunks;
        g.n_walls = m.n_walls;
        g.point_ids.resize(static_cast<std::size_t>(m.n_points_total));
        g.positions.resize(3 * static_cast<std::size_t>(m.n_points_total));
        g.triangles.resize(3 * static_cast<std::size_t>(m.n_triangles_total));
        g.wall_of_triangle.resize(static_cast<std::size_t>(m.n_triangles_total));
        std::copy(m.point_ids.begin(), m.point_ids.end(), g.point_ids.begin() + m.point_offset);
        std::copy(m.positions.begin(), m.positions.end(), g.positions.begin() + 3 * m.point_offset);
        std::copy(m.triangles.begin(), m.triangles.end(), g.triangles.begin() + 3 * m.triangle_offset);
        std::copy(m.wall_of_triangle.begin(), m.wall_of_triangle.end(),
                  g.wall_of_triangle.begin() + m.triangle_offset);
        g.chunks.insert(m.chunk_index);
      }
    } else if (e.channel == bus::channel::kIfaceKin) {
      demfdm::iface_kin_t m;
      if (decode(e, m) && m.header.sender == "continuum") {
        auto& k = log.kin[m.header.step];
        if (!k.chunks.count(m.chunk_index)) {
          k.n_chunks = m.n_chunks;
          k.positions.resize(3 * static_cast<std::size_t>(m.n_points_total));
          k.velocities.resize(3 * static_cast<std::size_t>(m.n_points_total));
          std::copy(m.positions.begin(), m.positions.end(), k.positions.begin() + 3 * m.point_offset);
          std::copy(m.velocities.begin(), m.velocities.end(), k.velocities.begin() + 3 * m.point_offset);
          k.chunks.insert(m.chunk_index);
          if (k.complete()) k.last_log_us = e.log_us;
        }
      }
    } else if (e.channel == bus::channel::kIfaceForce) {
      demfdm::iface_force_t m;
      if (decode(e, m) && m.header.sender == "dem") {
        auto& f = log.force[m.header.step];
        if (!f.chunks.count(m.chunk_index)) {
          f.n_chunks = m.n_chunks;
          f.forces.resize(3 * static_cast<std::size_t>(m.n_points_total));
          f.stiffness.resize(static_cast<std::size_t>(m.n_points_total));
          std::copy(m.forces.begin(), m.forces.end(), f.forces.begin() + 3 * m.point_offset);
          std::copy(m.stiffness.begin(), m.stiffness.end(), f.stiffness.begin() + m.point_offset);
          f.total = {m.total[0], m.total[1], m.total[2]};
          f.chunks.insert(m.chunk_index);
          if (f.complete()) f.last_log_us = e.log_us;
        }
      }
    }
    log.events.push_back(std::move(e));
  }
  if (log.events.empty())
    throw LogError(LogError::Kind::Empty, path, reader.file_bytes(), -1,
                   "no messages in its " + std::to_string(reader.file_bytes()) + " bytes");
  if (scene_n > 0 && static_cast<std::int32_t>(scene_chunks.size()) == scene_n)
    for (auto& [i, t] : scene_chunks) log.scene_text += t;
  log.checksummed = reader.checksummed();
  log.file_bytes = reader.file_bytes();
  return log;
}

namespace {

// Writes a checksummed event log (the layout EventReader verifies).
class CheckedWriter {
 public:
  CheckedWriter(const std::string& path) : path_(path) {
    f_ = std::fopen(path.c_str(), "wb");
    if (!f_) throw std::runtime_error(path + ": cannot create the merged log (" + std::strerror(errno) + ")");
    std::setvbuf(f_, nullptr, _IOFBF, 1 << 20);
  }
  ~CheckedWriter() {
    if (f_) std::fclose(f_);
  }
  void begin(std::int64_t t) { block(kCheckBegin, t); }
  void event(std::int64_t t, const std::string& ch, const std::vector<std::uint8_t>& data) {
    if (crcs_.empty()) first_ = n_;
    crcs_.push_back(record(t, ch, data.data(), data.size()));
    ++total_;
    last_t_ = t;
    if (static_cast<std::int64_t>(crcs_.size()) == kCheckBlock) block(kCheckBlockKind, t);
  }
  void end() {
    block(kCheckEnd, last_t_);
    if (std::fflush(f_) != 0 || std::ferror(f_)) fail();
    if (std::fclose(f_) != 0) {
      f_ = nullptr;
      fail();
    }
    f_ = nullptr;
  }
  std::int64_t events() const { return total_; }

 private:
  [[noreturn]] void fail() { throw std::runtime_error(path_ + ": write error (disk full?)"); }
  std::uint32_t record(std::int64_t t, const std::string& ch, const std::uint8_t* data, std::size_t n) {
    std::uint8_t h[kFrame];
    put32(h, kSync);
    put64(h + 4, static_cast<std::uint64_t>(n_));
    put64(h + 12, static_cast<std::uint64_t>(t));
    put32(h + 20, static_cast<std::uint32_t>(ch.size()));
    put32(h + 24, static_cast<std::uint32_t>(n));
    if (std::fwrite(h, 1, kFrame, f_) != kFrame || std::fwrite(ch.data(), 1, ch.size(), f_) != ch.size() ||
        (n && std::fwrite(data, 1, n, f_) != n))
      fail();
    ++n_;
    std::uint32_t crc = crc32(0, h, kFrame);
    crc = crc32(crc, ch.data(), ch.size());
    return crc32(crc, data, n);
  }
  void block(std::uint8_t kind, std::int64_t t) {
    std::vector<std::uint8_t> p(static_cast<std::size_t>(kCheckHead) + 4 * crcs_.size() + 4, 0);
    std::memcpy(p.data(), "DFLC", 4);
    p[4] = 1;
    p[5] = kind;
    put64(p.data() + 8, static_cast<std::uint64_t>(crcs_.empty() ? n_ : first_));
    put32(p.data() + 16, static_cast<std::uint32_t>(crcs_.size()));
    put64(p.data() + 20, static_cast<std::uint64_t>(total_));
    for (std::size_t j = 0; j < crcs_.size(); ++j) put32(p.data() + kCheckHead + 4 * j, crcs_[j]);
    put32(p.data() + p.size() - 4, crc32(0, p.data(), p.size() - 4));
    record(t, kCheckChannel, p.data(), p.size());
    crcs_.clear();
  }
  std::string path_;
  std::FILE* f_ = nullptr;
  std::int64_t n_ = 0, first_ = 0, total_ = 0, last_t_ = 0;
  std::vector<std::uint32_t> crcs_;
};

}  // namespace

MergeResult merge_logs(const std::vector<std::string>& inputs, const std::string& out) {
  namespace fs = std::filesystem;
  std::vector<std::string> files;
  for (const auto& in : inputs) {
    if (fs::is_directory(in)) {
      std::vector<std::string> part;
      for (const auto& de : fs::directory_iterator(in))
        if (de.is_regular_file() && de.path().extension() == ".lcmlog") part.push_back(de.path().string());
      files.insert(files.end(), part.begin(), part.end());
    } else if (fs::is_regular_file(in)) {
      files.push_back(in);
    } else {
      throw std::runtime_error(in + ": no such log file or folder");
    }
  }
  std::sort(files.begin(), files.end());
  if (files.empty()) throw std::runtime_error("merge: no *.lcmlog files in the given inputs");
  MergeResult result;
  result.inputs = files.size();
  // k-way merge: each process writes its events in send order (timestamps taken under its
  // publish lock), so every input is already sorted; memory holds one event per input.
  std::vector<std::unique_ptr<EventReader>> in;
  struct Head {
    RawEvent ev;
    bool valid = false;
  };
  std::vector<Head> head(files.size());
  auto advance = [&](std::size_t f) {
    try {
      head[f].valid = in[f]->next(head[f].ev);
    } catch (const LogError& e) {
      // A process killed while writing leaves its last event cut short: merge the rest.
      if (e.kind != LogError::Kind::Truncated) throw;
      head[f].valid = false;
      result.warnings.push_back(std::string(e.what()) + "; merged without it");
    }
  };
  for (std::size_t f = 0; f < files.size(); ++f) {
    in.push_back(std::make_unique<EventReader>(files[f]));
    advance(f);
  }
  // Written next to OUT and renamed at the end: a failed merge leaves no partial log behind.
  const std::string tmp = out + ".partial";
  try {
    CheckedWriter w(tmp);
    std::int64_t t0 = 0;
    bool any = false;
    for (const auto& h : head)
      if (h.valid && (!any || h.ev.timestamp < t0)) t0 = h.ev.timestamp, any = true;
    w.begin(t0);
    for (;;) {
      std::size_t best = files.size();  // smallest timestamp; ties: the first input
      for (std::size_t f = 0; f < files.size(); ++f)
        if (head[f].valid && (best == files.size() || head[f].ev.timestamp < head[best].ev.timestamp)) best = f;
      if (best == files.size()) break;
      w.event(head[best].ev.timestamp, head[best].ev.channel, head[best].ev.data);
      advance(best);
    }
    w.end();
    result.events = static_cast<std::size_t>(w.events());
    std::error_code ec;
    fs::rename(tmp, out, ec);
    if (ec) throw std::runtime_error(out + ": cannot write the merged log (" + ec.message() + ")");
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
  return result;
}

namespace {
// LCM publishes on this channel itself when an instance starts (not demfdm traffic).
const std::string kLcmSelfTest = "LCM_SELF_TEST";
}  // namespace

std::map<std::string, ChannelDiff> compare_logs(const Log& log, const Log& wire) {
  // (channel, size, FNV-1a-64 of the bytes) -> count in the log minus count on the wire.
  // A scene broadcast is identified by its header and chunk instead: the tee records the text of
  // each chunk once and a repeat as a stub on kSceneRepeat (lcm-logger records every copy whole).
  auto key = [](const Event& e) {
    std::uint64_t h = 1469598103934665603ull;
    auto mix = [&h](const void* p, std::size_t n) {
      for (std::size_t i = 0; i < n; ++i) h = (h ^ static_cast<const std::uint8_t*>(p)[i]) * 1099511628211ull;
    };
    if (e.channel == bus::channel::kScene || e.channel == kSceneRepeat) {
      demfdm::scene_t s;
      if (decode(e, s)) {
        mix(&s.header.run_id, 8);
        mix(s.header.sender.data(), s.header.sender.size() + 1);
        mix(&s.header.seq, 8);
        mix(&s.scene_hash, 8);
        mix(&s.chunk_index, 4);
        return std::make_tuple(bus::channel::kScene, std::size_t{0}, h);
      }
    }
    mix(e.data.data(), e.data.size());
    return std::make_tuple(e.channel, e.data.size(), h);
  };
  auto name = [](const Event& e) { return e.channel == kSceneRepeat ? bus::channel::kScene : e.channel; };
  std::map<std::tuple<std::string, std::size_t, std::uint64_t>, std::int64_t> balance;
  std::map<std::string, ChannelDiff> out;
  for (const auto& e : log.events) {
    ++balance[key(e)];
    ++out[name(e)].in_log;
  }
  for (const auto& e : wire.events) {
    if (e.channel == kLcmSelfTest) continue;
    --balance[key(e)];
    ++out[name(e)].on_wire;
  }
  for (const auto& [k, b] : balance) {
    if (b > 0) out[std::get<0>(k)].lost_on_wire += b;
    if (b < 0) out[std::get<0>(k)].only_on_wire -= b;
  }
  return out;
}

}  // namespace demfdm::traffic
