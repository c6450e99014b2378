#include "messages/bus.hpp"

#include <lcm/eventlog.h>
#include <dirent.h>
#include <arpa/inet.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>
#ifdef __linux__
#include <linux/filter.h>
#include <linux/sock_diag.h>
#endif

#include <atomic>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <optional>
#include <regex>
#include <sstream>

#include <spdlog/spdlog.h>

namespace demfdm::bus {

std::vector<TypeFingerprint> compiled_fingerprints() {
  return {
      {"header_t", demfdm::header_t::getHash()},
      {"scene_t", demfdm::scene_t::getHash()},
      {"hello_t", demfdm::hello_t::getHash()},
      {"command_t", demfdm::command_t::getHash()},
      {"report_t", demfdm::report_t::getHash()},
      {"heartbeat_t", demfdm::heartbeat_t::getHash()},
      {"nack_t", demfdm::nack_t::getHash()},
      {"iface_mesh_t", demfdm::iface_mesh_t::getHash()},
      {"iface_kin_t", demfdm::iface_kin_t::getHash()},
      {"iface_force_t", demfdm::iface_force_t::getHash()},
  };
}

std::string resolve_url(const std::string& cli_url) {
  std::string url = cli_url;
  if (url.empty()) {
    const char* env = std::getenv("LCM_DEFAULT_URL");
    if (env && *env) url = env;
  }
  if (url.empty()) url = "udpm://239.255.76.67:7667?ttl=0";
  if (url.rfind("udpm://", 0) == 0 && url.find("recv_buf_size") == std::string::npos) {
    url += (url.find('?') == std::string::npos) ? "?" : "&";
    url += "recv_buf_size=4194304";
  }
  return url;
}

namespace {
// DEMFDM_FAULT="drop:CHANNEL:N,dup:CHANNEL:N"
std::map<std::string, std::map<std::int64_t, char>> parse_faults() {
  std::map<std::string, std::map<std::int64_t, char>> out;
  const char* env = std::getenv("DEMFDM_FAULT");
  if (!env || !*env) return out;
  std::stringstream ss(env);
  std::string item;
  while (std::getline(ss, item, ',')) {
    auto a = item.find(':'), b = item.rfind(':');
    if (a == std::string::npos || a == b)
      throw BusError("DEMFDM_FAULT: expected 'drop:CHANNEL:N' or 'dup:CHANNEL:N', found '" + item + "'");
    std::string kind = item.substr(0, a), ch = item.substr(a + 1, b - a - 1);
    long long n = std::atoll(item.c_str() + b + 1);
    if ((kind != "drop" && kind != "dup") || n <= 0)
      throw BusError("DEMFDM_FAULT: expected 'drop:CHANNEL:N' or 'dup:CHANNEL:N' with N >= 1, found '" + item + "'");
    out[ch][n] = kind == "drop" ? 'd' : 'u';
  }
  return out;
}
}  // namespace

Bus::Bus(const std::string& url, std::int64_t run_id, std::string sender)
    : Bus(open_owned(url), run_id, std::move(sender)) {
  url_ = url;
}

Bus::Bus(Owned owned, std::int64_t run_id, std::string sender)
    : Bus(std::move(owned.lcm), run_id, std::move(sender)) {
  filter_fd_ = owned.recv_fd;
  direct_ = std::move(owned.direct);
  // Until the first subscription, keep nothing but fragments (LCM would drop the rest too).
  if (direct_) update_filter();
}

// Direct receive (bus.hpp): the Bus's own socket on the run's group and port, read by pump().
struct Bus::Direct {
  int fd = -1;
  std::mutex mu;  // held by pump() (the owner) and by drain() (the heartbeat thread)
  // Datagrams drain() read while the owner was busy: (sender, bytes), handled first by pump().
  std::deque<std::pair<std::uint64_t, std::vector<std::uint8_t>>> queue;
  std::size_t queued_bytes = 0;  // bounded: beyond kMaxQueued the kernel buffer fills and drops
  // Fragmented messages being reassembled, by sender address (as LCM does: one per sender).
  struct Frag {
    std::uint32_t seqno = 0, size = 0, remaining = 0;
    std::string channel;
    std::vector<std::uint8_t> data;
  };
  std::map<std::uint64_t, Frag> frags;
  std::vector<std::uint8_t> buf = std::vector<std::uint8_t>(65536);
  ~Direct() {
    if (fd >= 0) ::close(fd);
  }
  // One datagram without blocking: its size (buf), or -1 when none is waiting.
  long read(std::uint64_t& from) {
    sockaddr_in a{};
    socklen_t len = sizeof(a);
    for (;;) {
      ssize_t n = ::recvfrom(fd, buf.data(), buf.size(), MSG_DONTWAIT, reinterpret_cast<sockaddr*>(&a), &len);
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) return -1;
      from = (static_cast<std::uint64_t>(a.sin_addr.s_addr) << 16) | a.sin_port;
      return static_cast<long>(n);
    }
  }
};

namespace {
// The port of a udpm URL ("udpm://ADDR:PORT?..."), or -1 for another provider.
int udpm_port(const std::string& url) {
  if (url.rfind("udpm://", 0) != 0) return -1;
  std::string rest = url.substr(7);
  rest = rest.substr(0, rest.find('?'));
  auto colon = rest.rfind(':');
  if (colon == std::string::npos) return 7667;  // LCM's default port
  return std::atoi(rest.c_str() + colon + 1);
}

// This process's UDP sockets bound to INADDR_ANY:port (fd -> inode): LCM's udpm receive
// socket is one (its send socket is not bound to the port).
std::map<int, ino_t> bound_udp_sockets(int port) {
  std::map<int, ino_t> out;
  DIR* d = ::opendir("/proc/self/fd");
  if (!d) return out;
  while (dirent* e = ::readdir(d)) {
    if (!std::isdigit(static_cast<unsigned char>(e->d_name[0]))) continue;
    const int fd = std::atoi(e->d_name);
    struct stat st {};
    if (::fstat(fd, &st) != 0 || !S_ISSOCK(st.st_mode)) continue;
    int type = 0;
    socklen_t len = sizeof(type);
    if (::getsockopt(fd, SOL_SOCKET, SO_TYPE, &type, &len) != 0 || type != SOCK_DGRAM) continue;
    sockaddr_in a{};
    len = sizeof(a);
    if (::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) != 0 || a.sin_family != AF_INET) continue;
    if (ntohs(a.sin_port) != port || a.sin_addr.s_addr != htonl(INADDR_ANY)) continue;
    out[fd] = st.st_ino;
  }
  ::closedir(d);
  return out;
}

// Bus construction is serialised so that the receive socket a new LCM instance opens is
// told apart from those of other instances of this process.
std::mutex g_open_mu;
}  // namespace

namespace {
// The own receive socket of a udpm URL ("udpm://ADDR:PORT?...&recv_buf_size=N"), set up as
// LCM 1.3.1 sets up its own (lcm_udpm.c): SO_REUSEADDR, the receive buffer, bound to
// INADDR_ANY:PORT, member of the group. -1 if any step fails (the Bus then uses LCM's).
int open_udpm_socket(const std::string& url) {
  std::string rest = url.substr(7);
  std::string query;
  if (auto q = rest.find('?'); q != std::string::npos) {
    query = rest.substr(q + 1);
    rest = rest.substr(0, q);
  }
  std::string addr = rest;
  int port = 7667;
  if (auto colon = rest.rfind(':'); colon != std::string::npos) {
    addr = rest.substr(0, colon);
    port = std::atoi(rest.c_str() + colon + 1);
  }
  if (addr.empty()) addr = "239.255.76.67";
  int rcvbuf = 0;
  std::stringstream qs(query);
  std::string kv;
  while (std::getline(qs, kv, '&'))
    if (kv.rfind("recv_buf_size=", 0) == 0) rcvbuf = std::atoi(kv.c_str() + 14);
  in_addr group{};
  if (port <= 0 || port > 65535 || ::inet_aton(addr.c_str(), &group) == 0) return -1;
  int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  int one = 1;
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_ANY);
  a.sin_port = htons(static_cast<std::uint16_t>(port));
  ip_mreq mreq{};
  mreq.imr_multiaddr = group;
  mreq.imr_interface.s_addr = htonl(INADDR_ANY);
  if (::setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one)) != 0 ||
      (rcvbuf > 0 && ::setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &rcvbuf, sizeof(rcvbuf)) != 0) ||
      ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 ||
      ::setsockopt(fd, IPPROTO_IP, IP_ADD_MEMBERSHIP, &mreq, sizeof(mreq)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}
}  // namespace

Bus::Owned Bus::open_owned(const std::string& url) {
  Owned o;
  const int port = udpm_port(url);
  const char* env = std::getenv("DEMFDM_BUS_FILTER");
  const char* recv = std::getenv("DEMFDM_BUS_RECV");
  if (port > 0 && !(recv && std::string(recv) == "lcm")) {
    // Only publishes through LCM: its receive side (socket, thread, self-test) never starts.
    o.lcm = open_lcm(url);
    const int fd = open_udpm_socket(url);
    if (fd >= 0) {
      o.direct = std::make_unique<Direct>();
      o.direct->fd = fd;
      if (!(env && std::string(env) == "0")) o.recv_fd = fd;
      return o;
    }
    spdlog::debug("bus: could not open an own receive socket for {}; LCM receives", url);
  }
  bool want = port > 0 && !(env && std::string(env) == "0");
#ifndef __linux__
  want = false;
#endif
  std::lock_guard<std::mutex> lk(g_open_mu);
  std::map<int, ino_t> before;
  if (want) before = bound_udp_sockets(port);
  if (!o.lcm) o.lcm = open_lcm(url);
  // getFileno() sets up LCM's receive side (socket, thread, self-test), as the first
  // subscription or pump would.
  if (want && o.lcm->getFileno() >= 0) {
    int found = -1, n = 0;
    for (auto& [fd, ino] : bound_udp_sockets(port)) {
      auto it = before.find(fd);
      if (it == before.end() || it->second != ino) {
        found = fd;
        ++n;
      }
    }
    if (n == 1) o.recv_fd = found;
  }
  return o;
}

void Bus::update_filter() {
#ifdef __linux__
  if (filter_fd_ < 0) return;
  std::set<std::string> channels;
  for (auto& s : subs_) channels.insert(s->channel);
  // A UDP socket filter sees the UDP header (8 bytes) first. A short LCM datagram follows it
  // with its magic "LC02" (4 bytes), a sequence number (4) and the NUL-terminated channel name.
  constexpr std::uint32_t kMagicAt = 8, kChannelAt = 16, kShortMagic = 0x4c433032, kKeep = 0xffffffffu;
  std::vector<sock_filter> prog;
  prog.push_back(BPF_STMT(BPF_LD | BPF_W | BPF_ABS, kMagicAt));
  prog.push_back(BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, kShortMagic, 1, 0));
  prog.push_back(BPF_STMT(BPF_RET | BPF_K, kKeep));  // a fragment, or not LCM: LCM decides
  for (const auto& ch : channels) {
    std::string name = ch;
    name.push_back('\0');
    struct Piece {
      std::uint16_t size;
      std::uint32_t offset, value;
    };
    std::vector<Piece> pieces;
    for (std::size_t i = 0; i < name.size();) {
      const std::size_t left = name.size() - i;
      const std::uint16_t sz = left >= 4 ? BPF_W : left >= 2 ? BPF_H : BPF_B;
      const std::size_t n = sz == BPF_W ? 4 : sz == BPF_H ? 2 : 1;
      std::uint32_t v = 0;
      for (std::size_t k = 0; k < n; ++k) v = (v << 8) | static_cast<unsigned char>(name[i + k]);
      pieces.push_back({sz, static_cast<std::uint32_t>(kChannelAt + i), v});
      i += n;
    }
    if (2 * pieces.size() + 1 > 255) return;  // a jump cannot skip the block: no filter
    const auto skip = static_cast<std::uint8_t>(2 * pieces.size() + 1);
    // Long enough to hold the name? (A load beyond the end would end the program: drop.)
    prog.push_back(BPF_STMT(BPF_LD | BPF_W | BPF_LEN, 0));
    prog.push_back(BPF_JUMP(BPF_JMP | BPF_JGE | BPF_K, static_cast<std::uint32_t>(kChannelAt + name.size()), 0, skip));
    for (std::size_t i = 0; i < pieces.size(); ++i) {
      prog.push_back(BPF_STMT(BPF_LD | pieces[i].size | BPF_ABS, pieces[i].offset));
      prog.push_back(BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, pieces[i].value, 0,
                              static_cast<std::uint8_t>(2 * (pieces.size() - i - 1) + 1)));
    }
    prog.push_back(BPF_STMT(BPF_RET | BPF_K, kKeep));
  }
  prog.push_back(BPF_STMT(BPF_RET | BPF_K, 0));  // a short datagram on a channel nobody here reads
  if (prog.size() > BPF_MAXINSNS) return;
  sock_fprog fp{static_cast<unsigned short>(prog.size()), prog.data()};
  if (::setsockopt(filter_fd_, SOL_SOCKET, SO_ATTACH_FILTER, &fp, sizeof(fp)) == 0) {
    filter_on_ = true;
  } else {
    spdlog::debug("bus: could not attach the kernel channel filter ({}); LCM filters in user space", std::strerror(errno));
    if (filter_on_) ::setsockopt(filter_fd_, SOL_SOCKET, SO_DETACH_FILTER, nullptr, 0);
    filter_on_ = false;
    filter_fd_ = -1;
  }
#endif
}

std::int64_t Bus::kernel_drops() const {
#if defined(__linux__) && defined(SO_MEMINFO)
  if (filter_fd_ < 0) return -1;
  std::uint32_t mem[SK_MEMINFO_VARS] = {};
  socklen_t len = sizeof(mem);
  if (::getsockopt(filter_fd_, SOL_SOCKET, SO_MEMINFO, mem, &len) != 0) return -1;
  return mem[SK_MEMINFO_DROPS];
#else
  return -1;
#endif
}

struct Bus::TeeLog {
  lcm_eventlog_t* log = nullptr;
  std::optional<std::regex> channels;
  std::map<std::string, bool> match;  // channel -> recorded (cache of the regex)
  std::int64_t eventnum = 0;
  std::string path;
  ~TeeLog() {
    if (log) lcm_eventlog_destroy(log);
  }
};

Bus::Bus(std::shared_ptr<lcm::LCM> shared, std::int64_t run_id, std::string sender)
    : lcm_(std::move(shared)), run_id_(run_id), sender_(std::move(sender)) {
  if (!lcm_ || !lcm_->good()) throw BusError("the shared LCM instance is not usable");
  faults_ = parse_faults();
  open_tee();
}

void Bus::open_tee() {
  const char* dir = std::getenv("DEMFDM_TRAFFIC_DIR");
  if (!dir || !*dir) return;
  auto t = std::make_unique<TeeLog>();
  const char* ch = std::getenv("DEMFDM_TRAFFIC_CHANNELS");
  if (ch && *ch) {
    try {
      t->channels.emplace(ch, std::regex::ECMAScript);
    } catch (const std::regex_error& e) {
      throw BusError(std::string("DEMFDM_TRAFFIC_CHANNELS: '") + ch + "' is not a regular expression: " + e.what());
    }
  }
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  // One file per Bus: several Bus objects of one process (tests) never share a file.
  static std::atomic<int> instance{0};
  std::string safe = sender_;
  for (char& c : safe)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') c = '_';
  t->path = std::string(dir) + "/" + safe + "-" + std::to_string(::getpid()) + "-" + std::to_string(instance++) +
            ".lcmlog";
  t->log = lcm_eventlog_create(t->path.c_str(), "w");
  if (!t->log) throw BusError("DEMFDM_TRAFFIC_DIR: cannot create the traffic log '" + t->path + "'");
  tee_ = std::move(t);
}

// Called with pub_mu_ held, before the message goes to LCM. Flushed per message so that a
// process that is killed loses nothing it has sent.
// Size guard: the coordinator repeats the scene text (up to many MB) every 250 ms until every
// node has said hello. Each (scene hash, chunk) is recorded once per log; a repeat is recorded
// on DEMFDM_SCENE_REPEAT as the same scene_t without its text (header, hash and chunk kept, so
// the log still shows every publication and its seq).
void Bus::tee(const std::string& ch, const std::vector<std::uint8_t>& buf) {
  auto it = tee_->match.find(ch);
  if (it == tee_->match.end())
    it = tee_->match.emplace(ch, !tee_->channels || std::regex_match(ch, *tee_->channels)).first;
  if (!it->second) return;
  static const std::string kSceneRepeat = "DEMFDM_SCENE_REPEAT";
  const std::string* rec_ch = &ch;
  const std::vector<std::uint8_t>* rec = &buf;
  std::vector<std::uint8_t> stub;
  demfdm::scene_t s;
  if (ch == channel::kScene && s.decode(buf.data(), 0, static_cast<int>(buf.size())) >= 0) {
    // The chunks already recorded are kept in the channel cache under keys that no channel
    // name can take (they hold a newline).
    auto key = ch + "\n" + std::to_string(s.scene_hash) + "/" + std::to_string(s.chunk_index);
    if (!tee_->match.emplace(std::move(key), true).second) {
      s.text.clear();
      stub.resize(static_cast<std::size_t>(s.getEncodedSize()));
      s.encode(stub.data(), 0, static_cast<int>(stub.size()));
      rec_ch = &kSceneRepeat;
      rec = &stub;
    }
  }
  lcm_eventlog_event_t ev{};
  ev.eventnum = tee_->eventnum++;
  ev.timestamp = now_us();
  ev.channellen = static_cast<std::int32_t>(rec_ch->size());
  ev.datalen = static_cast<std::int32_t>(rec->size());
  ev.channel = const_cast<char*>(rec_ch->c_str());
  ev.data = const_cast<std::uint8_t*>(rec->data());
  if (lcm_eventlog_write_event(tee_->log, &ev) != 0 || std::fflush(tee_->log->f) != 0)
    throw BusError("cannot write the traffic log '" + tee_->path + "' (disk full?)");
}

std::shared_ptr<lcm::LCM> Bus::open_lcm(const std::string& url) {
  auto lcm = std::make_shared<lcm::LCM>(url);
  if (!lcm->good()) {
    throw BusError("cannot open the LCM bus at '" + url +
                   "': for udpm a multicast route is needed (as root: ip link set lo up; "
                   "ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo), or use "
                   "--lcm-url=memq:// for a single process");
  }
  return lcm;
}

Bus::~Bus() = default;

std::int64_t Bus::now_us() {
  using namespace std::chrono;
  return duration_cast<microseconds>(system_clock::now().time_since_epoch()).count();
}

void Bus::send_bytes(const std::string& ch, const std::vector<std::uint8_t>& buf) {
  std::int64_t n = ++pub_count_[ch];
  char action = 0;
  if (!faults_.empty()) {
    auto it = faults_.find(ch);
    if (it != faults_.end()) {
      auto jt = it->second.find(n);
      if (jt != it->second.end()) action = jt->second;
    }
  }
  {
    std::lock_guard<std::mutex> lk(stats_mu_);
    if (action == 'd') {
      ++stats_.injected_drops;
      return;
    }
    stats_.published += action == 'u' ? 2 : 1;
    stats_.bytes_published += static_cast<std::int64_t>(buf.size());
    if (action == 'u') ++stats_.injected_dups;
  }
  const int copies = action == 'u' ? 2 : 1;
  for (int i = 0; i < copies; ++i) {
    if (tee_) tee(ch, buf);
    lcm_->publish(ch, buf.data(), static_cast<unsigned>(buf.size()));
  }
}

void Bus::trampoline(const lcm::ReceiveBuffer* rbuf, const std::string& channel, Sub* sub) {
  sub->bus->deliver(sub, rbuf->data, rbuf->data_size, channel);
}

void Bus::deliver(Sub* sub, const void* data, std::uint32_t size, const std::string& channel) {
  {
    std::lock_guard<std::mutex> lk(stats_mu_);
    ++stats_.received;
  }
  if (pending_) return;  // an earlier handler failed: stop handling until rethrown
  try {
    int r = sub->decode(data, static_cast<int>(size));
    std::lock_guard<std::mutex> lk(stats_mu_);
    if (r == -1) {
      ++stats_.decode_errors;
      spdlog::warn("bus: could not decode a {}-byte message on channel {} (corrupt or other "
                   "message version); ignored",
                   size, channel);
    } else if (r == -2) {
      ++stats_.wrong_type;
      spdlog::warn("bus: message on channel {} has an unexpected msg_type; ignored", channel);
    } else if (r == 1) {
      ++stats_.accepted;
    }
  } catch (...) {
    pending_ = std::current_exception();
  }
}

namespace {
std::uint32_t be32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) | p[3];
}
std::uint16_t be16(const std::uint8_t* p) { return static_cast<std::uint16_t>((p[0] << 8) | p[1]); }
constexpr std::uint32_t kLcmShort = 0x4c433032, kLcmLong = 0x4c433033;  // "LC02", "LC03"
constexpr std::size_t kMaxChannel = 63;                                  // LCM_MAX_CHANNEL_NAME_LENGTH
constexpr std::uint32_t kMaxMessage = 1u << 28;                          // LCM_MAX_MESSAGE_SIZE
}  // namespace

// The LCM 1.3.1 wire format (lcm_udpm.c): a short message is one datagram, "LC02", a sequence
// number, the NUL-terminated channel and the payload; a long one is sent in fragments, "LC03",
// sequence number, message size, fragment offset, fragment number and count (16 bits each),
// fragment 0 starting with the channel. Reassembly follows LCM: one message in progress per
// sender, dropped when a fragment of another message (or size) arrives from that sender, or
// when fragment 0 was missed; a message on a channel nobody here reads is dropped at once.
void Bus::on_datagram(std::uint64_t from, const std::uint8_t* p, std::size_t n) {
  if (n < 8) return;
  const std::uint32_t magic = be32(p);
  if (magic == kLcmShort) {
    const char* ch = reinterpret_cast<const char*>(p + 8);
    const std::size_t len = strnlen(ch, n - 8);
    if (len == n - 8 || len > kMaxChannel) return;
    auto it = by_channel_.find(std::string(ch, len));
    if (it == by_channel_.end()) return;
    const std::string channel = it->first;
    for (Sub* sub : std::vector<Sub*>(it->second))
      deliver(sub, p + 8 + len + 1, static_cast<std::uint32_t>(n - 8 - len - 1), channel);
    return;
  }
  if (magic != kLcmLong || n < 20) return;
  const std::uint32_t seqno = be32(p + 4), size = be32(p + 8), offset = be32(p + 12);
  const std::uint16_t fragment = be16(p + 16), fragments = be16(p + 18);
  const std::uint8_t* data = p + 20;
  std::size_t len = n - 20;
  auto& frags = direct_->frags;
  auto it = frags.find(from);
  if (it != frags.end() && (it->second.seqno != seqno || it->second.size != size)) {
    frags.erase(it);
    it = frags.end();
  }
  if (size > kMaxMessage) return;
  if (fragment == 0) {
    const char* ch = reinterpret_cast<const char*>(data);
    const std::size_t clen = strnlen(ch, len);
    if (clen == len || clen > kMaxChannel) return;
    if (it == frags.end()) {
      std::string channel(ch, clen);
      if (!by_channel_.count(channel)) return;
      Direct::Frag f;
      f.seqno = seqno;
      f.size = size;
      f.remaining = fragments;
      f.channel = std::move(channel);
      f.data.resize(size);
      it = frags.emplace(from, std::move(f)).first;
    }
    data += clen + 1;
    len -= clen + 1;
  }
  if (it == frags.end()) return;
  auto& f = it->second;
  if (static_cast<std::uint64_t>(offset) + len > f.size) {
    frags.erase(it);
    return;
  }
  std::memcpy(f.data.data() + offset, data, len);
  if (--f.remaining > 0) return;
  Direct::Frag done = std::move(f);
  frags.erase(it);
  auto subs = by_channel_.find(done.channel);
  if (subs == by_channel_.end()) return;
  for (Sub* sub : std::vector<Sub*>(subs->second))
    deliver(sub, done.data.data(), static_cast<std::uint32_t>(done.data.size()), done.channel);
}

bool Bus::pump_direct(int timeout_ms) {
  std::unique_lock<std::mutex> lk(direct_->mu);
  bool handled = false;
  // First what drain() read while this thread was busy, in order.
  while (!direct_->queue.empty() && !pending_) {
    auto d = std::move(direct_->queue.front());
    direct_->queue.pop_front();
    direct_->queued_bytes -= d.second.size();
    on_datagram(d.first, d.second.data(), d.second.size());
    handled = true;
  }
  if (!handled && !pending_) {
    pollfd pfd{direct_->fd, POLLIN, 0};
    ::poll(&pfd, 1, timeout_ms);
  }
  // Then everything the socket holds now, without blocking.
  std::uint64_t from = 0;
  for (long n; !pending_ && (n = direct_->read(from)) >= 0;) {
    on_datagram(from, direct_->buf.data(), static_cast<std::size_t>(n));
    handled = true;
  }
  return handled;
}

void Bus::drain() {
  if (!direct_) return;
  std::unique_lock<std::mutex> lk(direct_->mu, std::try_to_lock);
  if (!lk.owns_lock()) return;  // the owner is pumping
  constexpr std::size_t kMaxQueued = std::size_t{256} << 20;  // a bus nobody pumps
  std::uint64_t from = 0;
  for (long n; direct_->queued_bytes < kMaxQueued && (n = direct_->read(from)) >= 0;) {
    direct_->queue.emplace_back(from, std::vector<std::uint8_t>(direct_->buf.begin(), direct_->buf.begin() + n));
    direct_->queued_bytes += static_cast<std::size_t>(n);
  }
}

bool Bus::accept_header(const demfdm::header_t& h) {
  std::lock_guard<std::mutex> lk(stats_mu_);
  if (run_id_ != 0 && h.run_id != run_id_) {
    ++stats_.foreign_run;
    return false;
  }
  if (h.sender == sender_) {
    ++stats_.own_echo;
    return false;
  }
  auto& [set, order] = seen_[h.sender];
  if (!set.insert(h.seq).second) {
    ++stats_.duplicates;
    return false;
  }
  order.push_back(h.seq);
  if (order.size() > 8192) {
    set.erase(order.front());
    order.pop_front();
  }
  return true;
}

bool Bus::pump(double timeout_s) {
  int ms = static_cast<int>(timeout_s * 1000.0 + 0.5);
  if (ms < 0) ms = 0;
  if (direct_) {
    bool handled = pump_direct(ms);
    if (pending_) {
      auto e = pending_;
      pending_ = nullptr;
      std::rethrow_exception(e);
    }
    return handled;
  }
  pollfd pfd{lcm_->getFileno(), POLLIN, 0};
  int pr = ::poll(&pfd, 1, ms);
  bool handled = false;
  if (pr > 0 && (pfd.revents & POLLIN)) {
    lcm_->handle();
    handled = true;
    // Drain whatever else is already queued without blocking.
    for (;;) {
      pollfd p2{lcm_->getFileno(), POLLIN, 0};
      if (::poll(&p2, 1, 0) <= 0 || !(p2.revents & POLLIN)) break;
      lcm_->handle();
      if (pending_) break;
    }
  }
  if (pending_) {
    auto e = pending_;
    pending_ = nullptr;
    std::rethrow_exception(e);
  }
  return handled;
}

bool Bus::wait_until(const std::function<bool()>& done, double timeout_s,
                     const std::function<void()>& on_idle, double idle_s) {
  using clock = std::chrono::steady_clock;
  auto start = clock::now();
  auto last_idle = start;
  while (!done()) {
    double elapsed = std::chrono::duration<double>(clock::now() - start).count();
    if (elapsed >= timeout_s) return done();
    double slice = std::min(idle_s, timeout_s - elapsed);
    pump(slice);
    if (on_idle && std::chrono::duration<double>(clock::now() - last_idle).count() >= idle_s) {
      last_idle = clock::now();
      if (!done()) on_idle();
    }
  }
  return true;
}

BusStats Bus::stats() const {
  std::lock_guard<std::mutex> lk(stats_mu_);
  return stats_;
}

}  // namespace demfdm::bus
