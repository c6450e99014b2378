#include "messages/bus.hpp"

#include <lcm/eventlog.h>
#include <poll.h>
#include <unistd.h>

#include <atomic>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
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
    : Bus(open_lcm(url), run_id, std::move(sender)) {
  url_ = url;
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
  Bus* self = sub->bus;
  {
    std::lock_guard<std::mutex> lk(self->stats_mu_);
    ++self->stats_.received;
  }
  if (self->pending_) return;  // an earlier handler failed: stop handling until rethrown
  try {
    int r = sub->decode(rbuf->data, static_cast<int>(rbuf->data_size));
    std::lock_guard<std::mutex> lk(self->stats_mu_);
    if (r == -1) {
      ++self->stats_.decode_errors;
      spdlog::warn("bus: could not decode a {}-byte message on channel {} (corrupt or other "
                   "message version); ignored",
                   rbuf->data_size, channel);
    } else if (r == -2) {
      ++self->stats_.wrong_type;
      spdlog::warn("bus: message on channel {} has an unexpected msg_type; ignored", channel);
    } else if (r == 1) {
      ++self->stats_.accepted;
    }
  } catch (...) {
    self->pending_ = std::current_exception();
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
