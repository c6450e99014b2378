// The demfdm coupling protocol on top of the typed bus (messages/README.md is the contract).
//
// NodeEndpoint is what every node executable uses (dem_node, fdm_node, any other continuum
// solver, test participants): receive the scene, say hello, follow commands, report, and
// exchange interface data with resends. CoordinatorEndpoint is the coordinator's side:
// broadcast the scene, check hellos, watch heartbeats, grant steps, collect reports.
//
// Reliability rules: every wait has a deadline; a waiting
// receiver sends a NACK after resend_after_s (doubling up to 0.4 s) and the holder of the
// message re-publishes its stored copy; commands and reports are idempotent; heartbeats come
// from a helper thread every heartbeat_s; silence longer than peer_timeout_s is an error that
// names the silent process. Silence counts only while this process itself was running: the
// heartbeat thread measures its own wake-ups with the monotonic clock, and a wake-up later than
// heartbeat_s + stall_s (the process, or the whole host, was stopped: SIGSTOP, a debugger, a VM
// pause, a suspended laptop) re-arms every peer's timer, so a stalled host is not a dead node.
// A peer process on this host that is gone (kill(pid, 0) fails with ESRCH) is dead at once.
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <map>
#include <optional>
#include <set>
#include <tuple>
#include <thread>

#include "messages/bus.hpp"

namespace demfdm::proto {

inline constexpr int kProtocolVersion = demfdm::msg_types_t::PROTOCOL_VERSION;
inline constexpr std::size_t kSceneChunkBytes = 48 * 1024;
// Interface arrays are chunked so that each message stays under about 60 KB:
// kin = 48 B/point, force = 32 B/point.
inline constexpr std::size_t kPointsPerChunk = 1000;

struct Timeouts {
  double heartbeat_s = 0.25;      // heartbeat period
  double peer_timeout_s = 3.0;    // silence after which a peer is declared dead
  double resend_after_s = 0.02;   // first NACK / command resend after this wait
  double startup_s = 20.0;        // scene / hello deadline
  double stall_s = 0.5;           // a heartbeat wake-up this much later than planned = own stall
};

// Thrown when the run must stop: a SHUTDOWN command, a silent peer, a protocol violation.
struct ProtocolError : std::runtime_error {
  using std::runtime_error::runtime_error;
};
struct ShutdownRequested : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Set from a signal handler (SIGINT/SIGTERM): every bus wait then throws ShutdownRequested.
void request_interrupt(int signal_number);
bool interrupted();
void throw_if_interrupted();

struct InterfaceMesh {
  std::vector<std::int64_t> point_ids;
  std::vector<double> positions;       // [n*3]
  std::vector<std::int32_t> triangles;  // [nt*3], rows into positions
  std::vector<std::int32_t> wall_of_triangle;  // [nt]
  std::int32_t n_walls = 0;
  std::size_t n_points() const { return point_ids.size(); }
};
struct Kinematics {
  std::int64_t step = -1;
  std::vector<double> positions, velocities;  // [n*3]
};
struct Forces {
  std::int64_t step = -1;
  std::vector<double> forces;     // [n*3]
  std::vector<double> stiffness;  // [n]
  std::array<double, 3> total{0, 0, 0};
};

// A named scalar a node reports each step (e.g. "ratio", "footing_fz_N").
using Values = std::vector<std::pair<std::string, double>>;

// Where a peer's silence starts counting for the thread that watches it: its last message, or
// the end of this process's own last stall, whichever is later. Two views of a stall: the
// heartbeat thread's late wake-up, and a gap between two checks of the watching loop longer
// than stall_s (that loop may run first after a SIGCONT).
class StallWatch {
 public:
  explicit StallWatch(double stall_s) : stall_s_(stall_s) {}
  std::chrono::steady_clock::time_point origin(std::chrono::steady_clock::time_point last_seen,
                                               std::chrono::steady_clock::time_point heartbeat_stall_end);

 private:
  double stall_s_;
  std::chrono::steady_clock::time_point last_check_{}, loop_stall_end_{};
};

class Heartbeat {
 public:
  // stall_s: a wake-up later than period_s + stall_s records a stall of this process.
  Heartbeat(bus::Bus& bus, double period_s, double stall_s = 0.5);
  ~Heartbeat();
  void set_state(const std::string& s);
  void set_step(std::int64_t step) { step_ = step; }
  void tick() { ++progress_; }
  void stop();
  // End of the last stall of this process (steady clock), or the epoch if none was seen. A
  // peer's silence is counted from max(its last message, this).
  std::chrono::steady_clock::time_point stall_end() const {
    return std::chrono::steady_clock::time_point(std::chrono::steady_clock::duration(stall_end_.load()));
  }
  // Longest stall seen [s] and the number of stalls (for the logs and the summary).
  double longest_stall_s() const { return longest_stall_ns_.load() * 1e-9; }
  std::int64_t stalls() const { return stalls_.load(); }

 private:
  std::atomic<std::int64_t> stall_end_{0}, longest_stall_ns_{0}, stalls_{0};
  bus::Bus& bus_;
  std::atomic<bool> stop_{false};
  std::atomic<std::int64_t> step_{-1}, progress_{0};
  std::mutex mu_;
  std::condition_variable cv_;
  std::string state_ = "starting";
  std::thread th_;
};

class NodeEndpoint {
 public:
  NodeEndpoint(bus::Bus& bus, std::string role, std::string solver, Timeouts t = {});
  ~NodeEndpoint();

  const std::string& role() const { return role_; }
  bus::Bus& bus() { return bus_; }
  Heartbeat& heartbeat() { return hb_; }

  // Waits for every chunk of the scene; returns its text. Also records its hash and origin.
  std::string wait_scene();
  std::int64_t scene_hash() const { return scene_hash_; }
  const std::string& scene_origin() const { return scene_origin_; }

  // Deadlines from the scene (known only after the scene has arrived).
  void set_timeouts(double peer_timeout_s, double resend_after_s) {
    t_.peer_timeout_s = peer_timeout_s;
    t_.resend_after_s = resend_after_s;
  }

  // Says hello (repeated until the first command for this node arrives) and sets the
  // node's stable time step for the coordinator's dt choice.
  void hello(double dt_stable);

  // Next command for this node (STAGE_BEGIN, GRANT, STAGE_END, SHUTDOWN), in order.
  // Pumps the bus, answers NACKs, checks the coordinator's liveness. A repeated command is
  // answered by re-sending the stored report and is not returned again.
  demfdm::command_t next_command();

  // Report for a step (or a stage begin/end); stored so that a repeated command or a NACK
  // gets the same report again.
  void report(std::int64_t step, std::int32_t status, std::int32_t stage, double time,
              double dt_stable, double compute_s, double wait_s, const Values& values,
              const std::string& text = {},
              const std::vector<std::pair<std::int64_t, std::vector<double>>>& rows = {});
  // Time spent in bus waits since the last report [s] (goes into report.wait_s).
  double take_wait_s();

  // Interface data. Continuum side: send_mesh once, send_kin every step, wait_forces.
  // DEM side: wait_mesh once, wait_kin every step, send_forces.
  void send_mesh(const InterfaceMesh& m);
  InterfaceMesh wait_mesh();
  void send_kin(const Kinematics& k);
  Kinematics wait_kin(std::int64_t step);
  void send_forces(const Forces& f);
  Forces wait_forces(std::int64_t step);

  // Resend/NACK counters for the run summary.
  std::int64_t nacks_sent() const { return nacks_sent_; }
  std::int64_t resends() const { return resends_; }

 private:
  template <class Done>
  void wait_for(Done done, const char* what, std::int64_t step, std::int32_t type,
                const std::string& from);
  void on_command(const demfdm::command_t& c);
  void on_nack(const demfdm::nack_t& n);
  void on_any_from_coordinator();
  void check_coordinator_alive();
  void store(std::int32_t type, std::int64_t step, std::vector<std::function<void()>> resend);
  // Chunks n interface points (kPointsPerChunk per message), fills each chunk's arrays with
  // fill(msg, offset, count), publishes, and keeps the chunks for resends after a NACK.
  template <class Msg, class Fill>
  void publish_chunked(const std::string& channel, std::int32_t type, std::int64_t step, std::size_t n, Fill fill);

  bus::Bus& bus_;
  std::string role_, solver_;
  Timeouts t_;
  Heartbeat hb_;
  StallWatch watch_{0.5};
  // scene assembly
  std::map<std::int32_t, std::string> scene_chunks_;
  std::int32_t scene_n_ = -1;
  std::int64_t scene_hash_ = 0;
  std::string scene_origin_;
  // commands
  std::deque<demfdm::command_t> commands_;
  std::set<std::tuple<std::int32_t, std::int64_t, std::int32_t>> handled_;  // (command, step, stage)
  std::int32_t current_command_ = 0;
  bool got_command_ = false;
  std::optional<demfdm::hello_t> hello_;
  std::chrono::steady_clock::time_point coord_seen_;
  // data in
  std::map<std::int64_t, std::map<std::int32_t, demfdm::iface_kin_t>> kin_in_;
  std::map<std::int64_t, std::map<std::int32_t, demfdm::iface_force_t>> force_in_;
  std::map<std::int32_t, demfdm::iface_mesh_t> mesh_in_;
  // stored outputs for resends: (type, step) -> republish actions
  std::map<std::pair<std::int32_t, std::int64_t>, std::vector<std::function<void()>>> out_;
  std::map<std::pair<std::int32_t, std::int64_t>, demfdm::report_t> reports_;
  std::int64_t nacks_sent_ = 0, resends_ = 0;
  double wait_accum_s_ = 0;
};

// Coordinator side.
struct NodeInfo {
  std::string role, solver, host, build_id;
  std::int32_t pid = 0;
  double dt_stable = 0;
  std::chrono::steady_clock::time_point last_seen;
  std::int64_t last_step = -1;
  bool local = false;  // the node runs on this host (its pid can be checked)
  std::chrono::steady_clock::time_point pid_checked{};  // last look at its process
  std::string state;
};

class CoordinatorEndpoint {
 public:
  CoordinatorEndpoint(bus::Bus& bus, Timeouts t = {});
  ~CoordinatorEndpoint();
  bus::Bus& bus() { return bus_; }

  // Broadcasts the scene until every role in 'roles' has said hello with matching protocol
  // version, scene hash and fingerprints. Throws ProtocolError naming what differs, or which
  // roles never answered.
  void start(const std::string& scene_text, const std::string& origin, std::uint64_t hash,
             const std::vector<std::string>& roles);
  const std::map<std::string, NodeInfo>& nodes() const { return nodes_; }
  const Heartbeat& heartbeat() const { return hb_; }

  // Publishes a command to 'targets' and waits for a report of 'step' from each (resending
  // the command if a report is late). Throws ProtocolError when a node is silent for
  // peer_timeout_s, or a report says FAILED (naming the node and its text).
  std::map<std::string, demfdm::report_t> command(std::int32_t cmd, const std::vector<std::string>& targets,
                                                  std::int64_t step, std::int32_t stage_index,
                                                  const std::string& stage_name, double dt,
                                                  const std::vector<double>& values,
                                                  const std::string& text = {});
  // The two halves of command(): several commands may be posted before their reports are
  // collected; collect() resends every outstanding command whose reports are late.
  void post(std::int32_t cmd, const std::vector<std::string>& targets, std::int64_t step, std::int32_t stage_index,
            const std::string& stage_name, double dt, const std::vector<double>& values, const std::string& text = {});
  std::map<std::string, demfdm::report_t> collect(std::int32_t cmd, const std::vector<std::string>& targets,
                                                  std::int64_t step, std::int32_t stage_index);
  // Tells every node to stop (best effort, repeated a few times).
  void shutdown(const std::string& reason);
  // Seconds spent waiting for reports (for the run summary).
  double wait_s() const { return wait_s_; }

 private:
  void check_alive(const std::vector<std::string>& roles);
  bus::Bus& bus_;
  Timeouts t_;
  Heartbeat hb_;
  StallWatch watch_{0.5};
  std::map<std::string, NodeInfo> nodes_;
  std::map<std::string, demfdm::hello_t> hellos_;
  std::map<std::pair<std::string, std::int64_t>, demfdm::report_t> reports_;
  // Posted commands without all their reports: (command, step) -> (message, targets).
  std::map<std::pair<std::int32_t, std::int64_t>, std::pair<demfdm::command_t, std::vector<std::string>>> outstanding_;
  double wait_s_ = 0;
};

// Splits [0, n) into chunks of at most kPointsPerChunk (at least one chunk, even for n = 0).
std::vector<std::pair<std::size_t, std::size_t>> chunks(std::size_t n, std::size_t per = kPointsPerChunk);

}  // namespace demfdm::proto
