// Typed bus wrapper over lcm::LCM (LCM 1.3.1 as shipped by Debian 12).
//
// Design (after Drake's DrakeLcm layering, and the LCM pitfalls measured on this machine kind:
// corrupt datagrams, lost messages, foreign runs on one port):
//  * raw subscription + guarded decoding: a corrupt length field makes lcm-gen's decode()
//    throw inside LCM's C callback, so we decode inside try and count the failure instead;
//  * handler exceptions are stored and re-thrown from pump(), never through LCM's C code;
//  * every message starts with demfdm::header_t; messages of another run id are rejected,
//    a process's own publications (self-delivery) are ignored, duplicates (same sender and
//    seq, e.g. a resend that crossed the original) are dropped;
//  * subscription queues are unbounded (LCM's default of 30 silently drops bursts) and udpm
//    URLs get recv_buf_size=4 MiB unless the URL sets it;
//  * fault injection for tests: DEMFDM_FAULT="drop:CHANNEL:N,dup:CHANNEL:N" drops or
//    duplicates this process's N-th publication on CHANNEL (1-based);
//  * lossless traffic log (tee): DEMFDM_TRAFFIC_DIR=DIR makes every Bus write each message it
//    hands to LCM (resends and injected duplicates included, injected drops not) into its own
//    standard LCM event log DIR/<sender>-<pid>-<n>.lcmlog, before sending, with the exact
//    encoded bytes and the send time; DEMFDM_TRAFFIC_CHANNELS=REGEX (ECMAScript, whole channel
//    name) limits it to the matching channels. `demfdm_log merge` joins the parts.
//  * direct receive (udpm, a Bus that owns its LCM instance): LCM 1.3.1 receives on a thread of
//    its own, which hands every message to the pumping thread through a pipe: two wake-ups per
//    message. The Bus instead opens its own socket on the run's group and port (bound and
//    joined exactly as LCM's, with the URL's recv_buf_size), reads the LCM datagrams (short
//    "LC02" and fragmented "LC03", reassembled as LCM does) in pump() on the owning thread and
//    uses LCM only to publish (LCM then never starts its receive thread). The wire is
//    unchanged. While the owner computes, the heartbeat thread moves what the socket holds into
//    the Bus's queue (drain()), so a long step cannot overflow the kernel buffer. Back to
//    LCM's receive thread with DEMFDM_BUS_RECV=lcm;
//  * kernel channel filter (udpm, Linux): every process's socket receives every datagram of
//    the run's port, its own included (multicast loopback), and would wake for each one only to
//    drop those on channels nobody here subscribed to. A Bus that owns its LCM instance attaches
//    a classic BPF socket filter to its receive socket that keeps the short LCM datagrams of the
//    subscribed channels and every other datagram (fragments of large messages, anything not
//    LCM), so the kernel drops the rest before anything wakes: what the handlers see is
//    unchanged (LCM drops the same messages later). The kernel counts the filtered datagrams
//    as socket drops (/proc/net/udp "drops", UDP InErrors). Off with DEMFDM_BUS_FILTER=0, or
//    when LCM's receive socket cannot be identified.
// Only the owning thread pumps; publish() may be called from any thread (heartbeats).
#pragma once

#include <lcm/lcm-cpp.hpp>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "demfdm/command_t.hpp"
#include "demfdm/header_t.hpp"
#include "demfdm/heartbeat_t.hpp"
#include "demfdm/hello_t.hpp"
#include "demfdm/iface_force_t.hpp"
#include "demfdm/iface_kin_t.hpp"
#include "demfdm/iface_mesh_t.hpp"
#include "demfdm/msg_types_t.hpp"
#include "demfdm/nack_t.hpp"
#include "demfdm/report_t.hpp"
#include "demfdm/scene_t.hpp"

namespace demfdm::bus {

// Explicit type ids (LCM fingerprints ignore struct names).
template <class T> struct MsgType;
#define DEMFDM_MSG_TYPE(T, ID)                                            \
  template <> struct MsgType<demfdm::T> {                               \
    static constexpr std::int32_t id = demfdm::msg_types_t::ID;         \
    static constexpr const char* name = #T;                             \
  }
DEMFDM_MSG_TYPE(scene_t, MSG_SCENE);
DEMFDM_MSG_TYPE(hello_t, MSG_HELLO);
DEMFDM_MSG_TYPE(command_t, MSG_COMMAND);
DEMFDM_MSG_TYPE(report_t, MSG_REPORT);
DEMFDM_MSG_TYPE(heartbeat_t, MSG_HEARTBEAT);
DEMFDM_MSG_TYPE(nack_t, MSG_NACK);
DEMFDM_MSG_TYPE(iface_mesh_t, MSG_IFACE_MESH);
DEMFDM_MSG_TYPE(iface_kin_t, MSG_IFACE_KIN);
DEMFDM_MSG_TYPE(iface_force_t, MSG_IFACE_FORCE);
#undef DEMFDM_MSG_TYPE

// Channel names (messages/README.md).
namespace channel {
inline const std::string kScene = "DEMFDM_SCENE";
inline const std::string kHello = "DEMFDM_HELLO";
inline const std::string kCommand = "DEMFDM_COMMAND";
inline const std::string kReport = "DEMFDM_REPORT";
inline const std::string kHeartbeat = "DEMFDM_HEARTBEAT";
inline const std::string kNack = "DEMFDM_NACK";
inline const std::string kIfaceMesh = "DEMFDM_IFACE_MESH";
inline const std::string kIfaceKin = "DEMFDM_IFACE_KIN";
inline const std::string kIfaceForce = "DEMFDM_IFACE_FORCE";
}  // namespace channel

// Type names and fingerprints of every message type this build knows, for the handshake.
struct TypeFingerprint {
  std::string name;
  std::int64_t hash;
};
std::vector<TypeFingerprint> compiled_fingerprints();

struct BusError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct BusStats {
  std::int64_t published = 0, received = 0, accepted = 0;
  std::int64_t foreign_run = 0, own_echo = 0, duplicates = 0, decode_errors = 0, wrong_type = 0;
  std::int64_t injected_drops = 0, injected_dups = 0;
  std::int64_t bytes_published = 0;
};

// The LCM URL to use: --lcm-url value if given, else $LCM_DEFAULT_URL, else LCM's default;
// udpm URLs get recv_buf_size=4194304 unless they already set it.
std::string resolve_url(const std::string& cli_url);

class Bus {
 public:
  // run_id: this run's nonce (0 accepts any run: only for tools that listen, such as a
  // "who is there" probe). sender: this process's name, written into every header.
  Bus(const std::string& url, std::int64_t run_id, std::string sender);
  // Several participants in one process share one LCM instance (memq:// delivers only within
  // an instance); whichever pumps dispatches to all of them.
  Bus(std::shared_ptr<lcm::LCM> shared, std::int64_t run_id, std::string sender);
  ~Bus();
  Bus(const Bus&) = delete;  // lcm::LCM copies segfault at exit (messages/README.md "Transport")
  Bus& operator=(const Bus&) = delete;

  std::int64_t run_id() const { return run_id_; }
  // True while the kernel channel filter is attached to the receive socket (see above).
  bool kernel_filter() const { return filter_on_; }
  // True when this Bus reads its own socket instead of LCM's receive thread (see above).
  bool direct_receive() const { return direct_ != nullptr; }
  // Moves the datagrams the receive socket holds into the Bus's queue without handling them
  // (pump() handles them, in order, before the socket). Any thread; returns at once when the
  // owner is pumping. No-op without direct receive.
  void drain();
  // Datagrams the kernel dropped at the receive socket (the filter's, and any for lack of
  // buffer space), or -1 when the socket is unknown (for tests and benchmarks).
  std::int64_t kernel_drops() const;
  const std::string& sender() const { return sender_; }
  const std::string& url() const { return url_; }

  // Fills header.run_id, msg_type, sender, seq and utime (header.step is the caller's), then
  // publishes. Returns the seq used. Thread-safe.
  template <class T>
  std::int64_t publish(const std::string& ch, T& msg) {
    std::lock_guard<std::mutex> lk(pub_mu_);
    msg.header.run_id = run_id_;
    msg.header.msg_type = MsgType<T>::id;
    msg.header.sender = sender_;
    msg.header.seq = ++seq_;
    msg.header.utime = now_us();
    publish_locked(ch, msg);
    return msg.header.seq;
  }
  // Re-publishes a message exactly as stored (same seq): for resends after a NACK.
  template <class T>
  void republish(const std::string& ch, const T& msg) {
    std::lock_guard<std::mutex> lk(pub_mu_);
    publish_locked(ch, msg);
  }

  template <class T>
  void subscribe(const std::string& ch, std::function<void(const T&)> handler) {
    auto sub = std::make_unique<Sub>();
    sub->bus = this;
    sub->decode = [handler = std::move(handler), this](const void* data, int size) -> int {
      T msg;
      int r = -1;
      try {
        r = msg.decode(data, 0, size);
      } catch (const std::exception&) {
        r = -1;
      }
      if (r < 0) return -1;
      if (msg.header.msg_type != MsgType<T>::id) return -2;
      if (!accept_header(msg.header)) return 0;
      handler(msg);
      return 1;
    };
    sub->channel = ch;
    Sub* raw = sub.get();
    subs_.push_back(std::move(sub));
    if (direct_) {
      by_channel_[ch].push_back(raw);
    } else {
      auto* s = lcm_->subscribeFunction(ch, &Bus::trampoline, raw);
      if (s) s->setQueueCapacity(0);  // unbounded: never drop silently
    }
    update_filter();
  }

  // Handles incoming messages for at most timeout_s (returns early after the first batch).
  // Re-throws the first exception a handler raised. Returns true if anything was handled.
  bool pump(double timeout_s);
  // Pumps until done() is true or timeout_s passes; on_idle() is called about every
  // idle_s while waiting (e.g. to send a NACK). Returns done().
  bool wait_until(const std::function<bool()>& done, double timeout_s,
                  const std::function<void()>& on_idle = {}, double idle_s = 0.05);

  BusStats stats() const;
  static std::int64_t now_us();

 private:
  struct Sub {
    Bus* bus = nullptr;
    std::string channel;
    std::function<int(const void*, int)> decode;
  };
  // An LCM instance this Bus owns, and its udpm receive socket (-1: unknown or not udpm).
  struct Direct;
  struct Owned {
    std::shared_ptr<lcm::LCM> lcm;
    int recv_fd = -1;
    std::unique_ptr<Direct> direct;
  };
  Bus(Owned owned, std::int64_t run_id, std::string sender);
  static Owned open_owned(const std::string& url);
  static std::shared_ptr<lcm::LCM> open_lcm(const std::string& url);
  // (Re)attaches the kernel channel filter for the channels subscribed so far.
  void update_filter();
  static void trampoline(const lcm::ReceiveBuffer* rbuf, const std::string& channel, Sub* sub);
  // Decodes one message for one subscription (both receive paths).
  void deliver(Sub* sub, const void* data, std::uint32_t size, const std::string& channel);
  // Direct receive: one datagram (whole message, or a fragment), and pump() on the own socket.
  void on_datagram(std::uint64_t from, const std::uint8_t* p, std::size_t n);
  bool pump_direct(int timeout_ms);
  bool accept_header(const demfdm::header_t& h);
  template <class T>
  void publish_locked(const std::string& ch, const T& msg) {
    int n = msg.getEncodedSize();
    std::vector<std::uint8_t> buf(static_cast<std::size_t>(n));
    msg.encode(buf.data(), 0, n);
    send_bytes(ch, buf);
  }
  void send_bytes(const std::string& ch, const std::vector<std::uint8_t>& buf);
  void open_tee();
  void tee(const std::string& ch, const std::vector<std::uint8_t>& buf);

  std::shared_ptr<lcm::LCM> lcm_;
  std::string url_;
  std::int64_t run_id_;
  std::string sender_;
  std::mutex pub_mu_;
  std::int64_t seq_ = 0;
  std::vector<std::unique_ptr<Sub>> subs_;
  std::exception_ptr pending_;
  mutable std::mutex stats_mu_;
  BusStats stats_;
  // Duplicate filter: recent (sender, seq) pairs, bounded per sender.
  std::map<std::string, std::pair<std::set<std::int64_t>, std::deque<std::int64_t>>> seen_;
  // Fault injection: channel -> (publication number -> action)
  std::map<std::string, std::map<std::int64_t, char>> faults_;
  std::map<std::string, std::int64_t> pub_count_;
  // Tee (DEMFDM_TRAFFIC_DIR): the open event log (lcm_eventlog_t*, owned), its channel filter.
  struct TeeLog;
  std::unique_ptr<TeeLog> tee_;
  // Kernel channel filter: LCM's receive socket (owned by the LCM instance), on or off.
  int filter_fd_ = -1;
  bool filter_on_ = false;
  // Direct receive: the own socket, its queue and fragment buffers; subscriptions by channel.
  std::unique_ptr<Direct> direct_;
  std::map<std::string, std::vector<Sub*>> by_channel_;
};

}  // namespace demfdm::bus
