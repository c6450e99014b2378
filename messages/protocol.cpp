#include "messages/protocol.hpp"

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

#include <spdlog/spdlog.h>

namespace demfdm::proto {
namespace {
using clock = std::chrono::steady_clock;
double since(clock::time_point t) { return std::chrono::duration<double>(clock::now() - t).count(); }

std::uint64_t fnv1a64(const std::string& s) {
  std::uint64_t h = 14695981039346656037ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;
  }
  return h;
}

// The process is gone: no such pid, or a zombie (it exited and its parent has not reaped it yet).
bool process_gone(std::int32_t pid) {
  if (pid <= 0) return false;
  if (::kill(pid, 0) != 0) return errno == ESRCH;
  std::ifstream f("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(f, stat)) return false;
  const auto close = stat.rfind(')');  // "pid (comm) S ...": the state follows the command name
  return close != std::string::npos && close + 2 < stat.size() && stat[close + 2] == 'Z';
}

std::string hostname() {
  char buf[256] = {0};
  ::gethostname(buf, sizeof(buf) - 1);
  return buf;
}

const char* command_name(std::int32_t c) {
  switch (c) {
    case demfdm::command_t::STAGE_BEGIN: return "STAGE_BEGIN";
    case demfdm::command_t::GRANT: return "GRANT";
    case demfdm::command_t::STAGE_END: return "STAGE_END";
    case demfdm::command_t::SHUTDOWN: return "SHUTDOWN";
  }
  return "?";
}
}  // namespace

namespace {
std::atomic<int> g_signal{0};
}
void request_interrupt(int signal_number) { g_signal = signal_number; }
bool interrupted() { return g_signal.load() != 0; }
void throw_if_interrupted() {
  int s = g_signal.load();
  if (s != 0) throw ShutdownRequested("interrupted by signal " + std::to_string(s));
}

std::vector<std::pair<std::size_t, std::size_t>> chunks(std::size_t n, std::size_t per) {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  for (std::size_t off = 0; off < n; off += per) out.emplace_back(off, std::min(per, n - off));
  if (out.empty()) out.emplace_back(0, 0);
  return out;
}

// ---------------------------------------------------------------------------------------
clock::time_point StallWatch::origin(clock::time_point last_seen, clock::time_point heartbeat_stall_end) {
  const auto now = clock::now();
  if (last_check_ != clock::time_point{} && std::chrono::duration<double>(now - last_check_).count() > stall_s_)
    loop_stall_end_ = now;
  last_check_ = now;
  return std::max({last_seen, heartbeat_stall_end, loop_stall_end_});
}

Heartbeat::Heartbeat(bus::Bus& bus, double period_s, double stall_s) : bus_(bus) {
  th_ = std::thread([this, period_s, stall_s] {
    std::unique_lock<std::mutex> lk(mu_);
    auto planned = clock::now();
    while (!stop_) {
      // Own stall: this wake-up came later than planned by more than stall_s.
      const auto now = clock::now();
      const double late = std::chrono::duration<double>(now - planned).count();
      if (late > stall_s) {
        stall_end_ = now.time_since_epoch().count();
        ++stalls_;
        longest_stall_ns_ = std::max<std::int64_t>(longest_stall_ns_.load(), static_cast<std::int64_t>(late * 1e9));
      }
      demfdm::heartbeat_t hb;
      hb.header.step = step_;
      hb.state = state_;
      hb.progress = progress_;
      lk.unlock();
      try {
        bus_.publish(bus::channel::kHeartbeat, hb);
        // A long computation of the owner must not overflow the kernel's receive buffer
        // (direct receive, messages/bus.hpp): what is waiting moves to the bus's queue.
        bus_.drain();
      } catch (...) {
      }
      lk.lock();
      planned = clock::now() + std::chrono::duration_cast<clock::duration>(std::chrono::duration<double>(period_s));
      cv_.wait_for(lk, std::chrono::duration<double>(period_s), [this] { return stop_.load(); });
    }
  });
}
Heartbeat::~Heartbeat() { stop(); }
void Heartbeat::stop() {
  {
    std::lock_guard<std::mutex> lk(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  if (th_.joinable()) th_.join();
}
void Heartbeat::set_state(const std::string& s) {
  std::lock_guard<std::mutex> lk(mu_);
  state_ = s;
}

// ---------------------------------------------------------------------------------------
NodeEndpoint::NodeEndpoint(bus::Bus& bus, std::string role, std::string solver, Timeouts t)
    : bus_(bus), role_(std::move(role)), solver_(std::move(solver)), t_(t), hb_(bus, t.heartbeat_s, t.stall_s) {
  coord_seen_ = clock::now();
  hb_.set_state("waiting-scene");
  bus_.subscribe<demfdm::scene_t>(bus::channel::kScene, [this](const demfdm::scene_t& m) {
    on_any_from_coordinator();
    if (m.protocol_version != kProtocolVersion)
      throw ProtocolError("coordinator speaks protocol version " + std::to_string(m.protocol_version) +
                          ", this " + solver_ + " speaks " + std::to_string(kProtocolVersion));
    if (scene_n_ >= 0 && m.scene_hash != scene_hash_) return;  // a stale scene; keep the first
    scene_n_ = m.n_chunks;
    scene_hash_ = m.scene_hash;
    scene_origin_ = m.origin;
    scene_chunks_[m.chunk_index] = m.text;
  });
  bus_.subscribe<demfdm::command_t>(bus::channel::kCommand, [this](const demfdm::command_t& c) {
    on_any_from_coordinator();
    on_command(c);
  });
  bus_.subscribe<demfdm::heartbeat_t>(bus::channel::kHeartbeat, [this](const demfdm::heartbeat_t& h) {
    if (h.header.sender == "coordinator") on_any_from_coordinator();
  });
  bus_.subscribe<demfdm::nack_t>(bus::channel::kNack, [this](const demfdm::nack_t& n) { on_nack(n); });
  // Each side reads only the interface data it waits for (the DEM: mesh and kinematics; the
  // continuum: forces): its own publications come back over multicast loopback, and a
  // subscription to them would wake this process for every one only to drop it.
  const bool any_role = role_ != "dem" && role_ != "continuum";
  if (any_role || role_ == "dem") {
    bus_.subscribe<demfdm::iface_kin_t>(bus::channel::kIfaceKin, [this](const demfdm::iface_kin_t& m) {
      kin_in_[m.header.step][m.chunk_index] = m;
    });
    bus_.subscribe<demfdm::iface_mesh_t>(bus::channel::kIfaceMesh, [this](const demfdm::iface_mesh_t& m) {
      mesh_in_[m.chunk_index] = m;
    });
  }
  if (any_role || role_ == "continuum") {
    bus_.subscribe<demfdm::iface_force_t>(bus::channel::kIfaceForce, [this](const demfdm::iface_force_t& m) {
      force_in_[m.header.step][m.chunk_index] = m;
    });
  }
}

NodeEndpoint::~NodeEndpoint() { hb_.stop(); }

void NodeEndpoint::on_any_from_coordinator() { coord_seen_ = clock::now(); }

void NodeEndpoint::check_coordinator_alive() {
  double s = since(watch_.origin(coord_seen_, hb_.stall_end()));
  if (s > t_.peer_timeout_s) {
    std::ostringstream os;
    os << "the coordinator has been silent for " << std::round(s * 10) / 10
       << " s (no heartbeat or command); " << role_ << " stops";
    throw ProtocolError(os.str());
  }
}

std::string NodeEndpoint::wait_scene() {
  auto done = [this] { return scene_n_ >= 0 && static_cast<std::int32_t>(scene_chunks_.size()) == scene_n_; };
  auto start = clock::now();
  while (!done()) {
    bus_.pump(0.05);
    throw_if_interrupted();
    if (since(start) > t_.startup_s)
      throw ProtocolError(role_ + ": no scene received from the coordinator within " +
                          std::to_string(static_cast<int>(t_.startup_s)) + " s on " + bus_.url());
  }
  std::string text;
  for (auto& [i, s] : scene_chunks_) text += s;
  if (fnv1a64(text) != static_cast<std::uint64_t>(scene_hash_))
    throw ProtocolError(role_ + ": the scene text received does not match its hash");
  coord_seen_ = clock::now();
  return text;
}

void NodeEndpoint::hello(double dt_stable) {
  demfdm::hello_t h;
  h.role = role_;
  h.solver = solver_;
  h.protocol_version = kProtocolVersion;
  h.scene_hash = scene_hash_;
  for (auto& f : bus::compiled_fingerprints()) {
    h.type_names.push_back(f.name);
    h.fingerprints.push_back(f.hash);
  }
  h.n_types = static_cast<std::int32_t>(h.type_names.size());
  h.build_id = std::string("demfdm ") + DEMFDM_VERSION_STRING + " gcc " + __VERSION__;
  h.pid = static_cast<std::int32_t>(::getpid());
  h.host = hostname();
  h.dt_stable = dt_stable;
  hello_ = h;
  bus_.publish(bus::channel::kHello, *hello_);
  hb_.set_state("ready");
}

void NodeEndpoint::on_command(const demfdm::command_t& c) {
  if (c.target != "*" && c.target != role_) return;
  got_command_ = true;
  // A repeated command (the coordinator did not get our report): re-send the report.
  auto it = reports_.find({c.command, c.header.step});
  if (it != reports_.end() && it->second.stage_index == c.stage_index) {
    bus_.republish(bus::channel::kReport, it->second);
    ++resends_;
    return;
  }
  // Queued, or taken and still being worked on: nothing to do yet.
  if (!handled_.insert({c.command, c.header.step, c.stage_index}).second) return;
  commands_.push_back(c);
}

demfdm::command_t NodeEndpoint::next_command() {
  hb_.set_state("waiting-command");
  auto last_hello = clock::now();
  auto start = clock::now();
  while (commands_.empty()) {
    bus_.pump(0.05);
    throw_if_interrupted();
    check_coordinator_alive();
    if (!got_command_ && hello_ && since(last_hello) > 0.25) {
      bus_.publish(bus::channel::kHello, *hello_);
      last_hello = clock::now();
    }
  }
  wait_accum_s_ += since(start);
  auto c = commands_.front();
  commands_.pop_front();
  current_command_ = c.command;
  hb_.set_state(command_name(c.command));
  return c;
}

double NodeEndpoint::take_wait_s() {
  double w = wait_accum_s_;
  wait_accum_s_ = 0;
  return w;
}

void NodeEndpoint::report(std::int64_t step, std::int32_t status, std::int32_t stage, double time,
                          double dt_stable, double compute_s, double wait_s, const Values& values,
                          const std::string& text,
                          const std::vector<std::pair<std::int64_t, std::vector<double>>>& rows) {
  // The report answers the most recently taken command.
  demfdm::report_t r;
  r.header.step = step;
  r.status = status;
  r.stage_index = stage;
  r.time = time;
  r.dt_stable = dt_stable;
  r.wait_s = wait_s;
  r.compute_s = compute_s;
  for (auto& [k, v] : values) {
    r.names.push_back(k);
    r.values.push_back(v);
  }
  r.n_values = static_cast<std::int32_t>(r.values.size());
  r.text = text;
  r.n_rows = 0;
  for (auto& [k, row] : rows) {
    if (row.size() != r.values.size()) continue;  // a row must carry the same names
    r.row_steps.push_back(k);
    r.rows.push_back(row);
  }
  r.n_rows = static_cast<std::int32_t>(r.rows.size());
  r.command = current_command_;
  bus_.publish(bus::channel::kReport, r);
  reports_[{r.command, step}] = r;
  // Keep a bounded history for resends.
  while (reports_.size() > 64) reports_.erase(reports_.begin());
  hb_.set_step(step);
}

template <class Done>
void NodeEndpoint::wait_for(Done done, const char* what, std::int64_t step, std::int32_t type,
                            const std::string& from) {
  if (done()) return;
  hb_.set_state(std::string("waiting-") + what);
  auto start = clock::now();
  auto last = start;
  double interval = t_.resend_after_s;
  while (!done()) {
    bus_.pump(std::min(0.01, interval));
    if (done()) break;
    throw_if_interrupted();
    for (auto& q : commands_)
      if (q.command == demfdm::command_t::SHUTDOWN)
        throw ShutdownRequested("shutdown while waiting for " + std::string(what) + " of step " +
                                std::to_string(step) + ": " + q.text);
    check_coordinator_alive();
    if (since(last) >= interval) {
      demfdm::nack_t n;
      n.header.step = step;
      n.addressee = from;
      n.wanted_type = type;
      n.wanted_step = step;
      n.n_chunks = 0;
      bus_.publish(bus::channel::kNack, n);
      ++nacks_sent_;
      last = clock::now();
      interval = std::min(interval * 2, 0.4);
    }
  }
  wait_accum_s_ += since(start);
  hb_.set_state("computing");
}

void NodeEndpoint::on_nack(const demfdm::nack_t& n) {
  if (n.addressee != role_) return;
  auto it = out_.find({n.wanted_type, n.wanted_step});
  if (it == out_.end()) return;  // not produced yet: the peer will ask again
  for (auto& f : it->second) f();
  ++resends_;
}

void NodeEndpoint::store(std::int32_t type, std::int64_t step, std::vector<std::function<void()>> resend) {
  out_[{type, step}] = std::move(resend);
  // Keep the mesh (step -1) and the last few steps of each type.
  for (auto it = out_.begin(); it != out_.end();) {
    if (it->first.second >= 0 && it->first.second < step - 4 && it->first.first == type)
      it = out_.erase(it);
    else
      ++it;
  }
}

template <class Msg, class Fill>
void NodeEndpoint::publish_chunked(const std::string& channel, std::int32_t type, std::int64_t step, std::size_t n,
                                   Fill fill) {
  auto pc = chunks(n);
  std::vector<std::function<void()>> resend;
  for (std::size_t i = 0; i < pc.size(); ++i) {
    auto [off, cnt] = pc[i];
    auto msg = std::make_shared<Msg>();
    msg->header.step = step;
    msg->chunk_index = static_cast<std::int32_t>(i);
    msg->n_chunks = static_cast<std::int32_t>(pc.size());
    msg->n_points_total = static_cast<std::int32_t>(n);
    msg->point_offset = static_cast<std::int32_t>(off);
    msg->n_points = static_cast<std::int32_t>(cnt);
    msg->n_coords = static_cast<std::int32_t>(3 * cnt);
    fill(*msg, off, cnt);
    bus_.publish(channel, *msg);
    resend.push_back([this, msg, channel] { bus_.republish(channel, *msg); });
  }
  store(type, step, std::move(resend));
}

void NodeEndpoint::send_mesh(const InterfaceMesh& m) {
  auto pc = chunks(m.n_points());
  auto tc = chunks(m.triangles.size() / 3);
  std::size_t n = std::max(pc.size(), tc.size());
  std::vector<std::function<void()>> resend;
  for (std::size_t i = 0; i < n; ++i) {
    auto msg = std::make_shared<demfdm::iface_mesh_t>();
    msg->header.step = -1;
    msg->point_offset = msg->n_points = msg->n_coords = 0;
    msg->triangle_offset = msg->n_triangles = msg->n_corners = 0;
    msg->chunk_index = static_cast<std::int32_t>(i);
    msg->n_chunks = static_cast<std::int32_t>(n);
    msg->n_points_total = static_cast<std::int32_t>(m.n_points());
    msg->n_triangles_total = static_cast<std::int32_t>(m.triangles.size() / 3);
    msg->n_walls = m.n_walls;
    if (i < pc.size()) {
      auto [off, cnt] = pc[i];
      msg->point_offset = static_cast<std::int32_t>(off);
      msg->n_points = static_cast<std::int32_t>(cnt);
      msg->point_ids.assign(m.point_ids.begin() + off, m.point_ids.begin() + off + cnt);
      msg->positions.assign(m.positions.begin() + 3 * off, m.positions.begin() + 3 * (off + cnt));
      msg->n_coords = static_cast<std::int32_t>(3 * cnt);
    }
    if (i < tc.size()) {
      auto [off, cnt] = tc[i];
      msg->triangle_offset = static_cast<std::int32_t>(off);
      msg->n_triangles = static_cast<std::int32_t>(cnt);
      msg->triangles.assign(m.triangles.begin() + 3 * off, m.triangles.begin() + 3 * (off + cnt));
      msg->n_corners = static_cast<std::int32_t>(3 * cnt);
      for (std::size_t t = off; t < off + cnt; ++t)
        msg->wall_of_triangle.push_back(m.wall_of_triangle.empty() ? 0 : m.wall_of_triangle[t]);
    }
    bus_.publish(bus::channel::kIfaceMesh, *msg);
    resend.push_back([this, msg] { bus_.republish(bus::channel::kIfaceMesh, *msg); });
  }
  store(demfdm::msg_types_t::MSG_IFACE_MESH, -1, std::move(resend));
}

InterfaceMesh NodeEndpoint::wait_mesh() {
  if (role_ == "continuum") throw std::logic_error("the continuum does not read the interface mesh");
  wait_for([this] {
    return !mesh_in_.empty() && static_cast<std::int32_t>(mesh_in_.size()) == mesh_in_.begin()->second.n_chunks;
  }, "interface-mesh", -1, demfdm::msg_types_t::MSG_IFACE_MESH, "continuum");
  InterfaceMesh m;
  auto& first = mesh_in_.begin()->second;
  m.n_walls = first.n_walls;
  m.point_ids.resize(first.n_points_total);
  m.positions.resize(3 * static_cast<std::size_t>(first.n_points_total));
  m.triangles.resize(3 * static_cast<std::size_t>(first.n_triangles_total));
  m.wall_of_triangle.resize(first.n_triangles_total);
  for (auto& [i, c] : mesh_in_) {
    for (int p = 0; p < c.n_points; ++p) {
      std::size_t r = static_cast<std::size_t>(c.point_offset + p);
      if (r >= m.point_ids.size()) throw ProtocolError("interface mesh chunk has point rows out of range");
      m.point_ids[r] = c.point_ids[p];
      for (int d = 0; d < 3; ++d) m.positions[3 * r + d] = c.positions[3 * p + d];
    }
    for (int t = 0; t < c.n_triangles; ++t) {
      std::size_t r = static_cast<std::size_t>(c.triangle_offset + t);
      if (r >= m.wall_of_triangle.size()) throw ProtocolError("interface mesh chunk has triangle rows out of range");
      for (int d = 0; d < 3; ++d) {
        auto v = c.triangles[3 * t + d];
        if (v < 0 || v >= first.n_points_total)
          throw ProtocolError("interface triangle " + std::to_string(r) + " names point row " +
                              std::to_string(v) + ", outside [0, " + std::to_string(first.n_points_total) + ")");
        m.triangles[3 * r + d] = v;
      }
      m.wall_of_triangle[r] = c.wall_of_triangle[t];
    }
  }
  return m;
}

void NodeEndpoint::send_kin(const Kinematics& k) {
  std::size_t n = k.positions.size() / 3;
  publish_chunked<demfdm::iface_kin_t>(bus::channel::kIfaceKin, demfdm::msg_types_t::MSG_IFACE_KIN, k.step, n,
                                       [&](demfdm::iface_kin_t& msg, std::size_t off, std::size_t cnt) {
                                         msg.positions.assign(k.positions.begin() + 3 * off,
                                                              k.positions.begin() + 3 * (off + cnt));
                                         msg.velocities.assign(k.velocities.begin() + 3 * off,
                                                               k.velocities.begin() + 3 * (off + cnt));
                                       });
}

Kinematics NodeEndpoint::wait_kin(std::int64_t step) {
  if (role_ == "continuum") throw std::logic_error("the continuum does not read interface kinematics");
  wait_for([&] {
    auto it = kin_in_.find(step);
    return it != kin_in_.end() && static_cast<std::int32_t>(it->second.size()) == it->second.begin()->second.n_chunks;
  }, "interface-kinematics", step, demfdm::msg_types_t::MSG_IFACE_KIN, "continuum");
  auto& parts = kin_in_[step];
  Kinematics k;
  k.step = step;
  std::size_t n = static_cast<std::size_t>(parts.begin()->second.n_points_total);
  k.positions.resize(3 * n);
  k.velocities.resize(3 * n);
  for (auto& [i, c] : parts)
    for (int p = 0; p < c.n_points; ++p) {
      std::size_t r = static_cast<std::size_t>(c.point_offset + p);
      if (r >= n) throw ProtocolError("interface kinematics chunk has rows out of range");
      for (int d = 0; d < 3; ++d) {
        double x = c.positions[3 * p + d], v = c.velocities[3 * p + d];
        if (!std::isfinite(x) || !std::isfinite(v))
          throw ProtocolError("non-finite interface kinematics from " + c.header.sender + " at step " +
                              std::to_string(step) + ", point row " + std::to_string(r));
        k.positions[3 * r + d] = x;
        k.velocities[3 * r + d] = v;
      }
    }
  kin_in_.erase(kin_in_.begin(), kin_in_.upper_bound(step));
  return k;
}

void NodeEndpoint::send_forces(const Forces& f) {
  std::size_t n = f.forces.size() / 3;
  publish_chunked<demfdm::iface_force_t>(
      bus::channel::kIfaceForce, demfdm::msg_types_t::MSG_IFACE_FORCE, f.step, n,
      [&](demfdm::iface_force_t& msg, std::size_t off, std::size_t cnt) {
        msg.forces.assign(f.forces.begin() + 3 * off, f.forces.begin() + 3 * (off + cnt));
        msg.stiffness.resize(cnt);
        for (std::size_t p = 0; p < cnt; ++p) msg.stiffness[p] = f.stiffness.empty() ? 0.0 : f.stiffness[off + p];
        for (int d = 0; d < 3; ++d) msg.total[d] = f.total[d];
      });
}

Forces NodeEndpoint::wait_forces(std::int64_t step) {
  if (role_ == "dem") throw std::logic_error("the DEM does not read interface forces");
  wait_for([&] {
    auto it = force_in_.find(step);
    return it != force_in_.end() && static_cast<std::int32_t>(it->second.size()) == it->second.begin()->second.n_chunks;
  }, "interface-forces", step, demfdm::msg_types_t::MSG_IFACE_FORCE, "dem");
  auto& parts = force_in_[step];
  Forces f;
  f.step = step;
  std::size_t n = static_cast<std::size_t>(parts.begin()->second.n_points_total);
  f.forces.resize(3 * n);
  f.stiffness.resize(n);
  for (auto& [i, c] : parts) {
    for (int d = 0; d < 3; ++d) f.total[d] = c.total[d];
    for (int p = 0; p < c.n_points; ++p) {
      std::size_t r = static_cast<std::size_t>(c.point_offset + p);
      if (r >= n) throw ProtocolError("interface force chunk has rows out of range");
      for (int d = 0; d < 3; ++d) {
        double v = c.forces[3 * p + d];
        if (!std::isfinite(v))
          throw ProtocolError("non-finite interface force from " + c.header.sender + " at step " +
                              std::to_string(step) + ", point row " + std::to_string(r));
        f.forces[3 * r + d] = v;
      }
      f.stiffness[r] = c.stiffness[p];
    }
  }
  force_in_.erase(force_in_.begin(), force_in_.upper_bound(step));
  return f;
}

// ---------------------------------------------------------------------------------------
CoordinatorEndpoint::CoordinatorEndpoint(bus::Bus& bus, Timeouts t)
    : bus_(bus), t_(t), hb_(bus, t.heartbeat_s, t.stall_s) {
  hb_.set_state("starting");
  bus_.subscribe<demfdm::hello_t>(bus::channel::kHello, [this](const demfdm::hello_t& h) {
    hellos_[h.role] = h;
    auto& n = nodes_[h.role];
    n.role = h.role;
    n.solver = h.solver;
    n.host = h.host;
    n.pid = h.pid;
    n.build_id = h.build_id;
    n.dt_stable = h.dt_stable;
    n.last_seen = clock::now();
    n.local = h.host == hostname();
  });
  bus_.subscribe<demfdm::heartbeat_t>(bus::channel::kHeartbeat, [this](const demfdm::heartbeat_t& h) {
    auto it = nodes_.find(h.header.sender);
    if (it == nodes_.end()) return;
    it->second.last_seen = clock::now();
    it->second.last_step = h.header.step;
    it->second.state = h.state;
  });
  bus_.subscribe<demfdm::report_t>(bus::channel::kReport, [this](const demfdm::report_t& r) {
    auto it = nodes_.find(r.header.sender);
    if (it != nodes_.end()) it->second.last_seen = clock::now();
    reports_[{r.header.sender + "#" + std::to_string(r.command), r.header.step}] = r;
  });
}

CoordinatorEndpoint::~CoordinatorEndpoint() { hb_.stop(); }

void CoordinatorEndpoint::start(const std::string& text, const std::string& origin, std::uint64_t hash,
                                const std::vector<std::string>& roles) {
  if (fnv1a64(text) != hash) throw ProtocolError("scene hash does not match its text");
  auto pieces = chunks(text.size(), kSceneChunkBytes);
  std::vector<demfdm::scene_t> msgs;
  for (std::size_t i = 0; i < pieces.size(); ++i) {
    demfdm::scene_t s;
    s.header.step = -1;
    s.protocol_version = kProtocolVersion;
    s.scene_hash = static_cast<std::int64_t>(hash);
    s.origin = origin;
    s.chunk_index = static_cast<std::int32_t>(i);
    s.n_chunks = static_cast<std::int32_t>(pieces.size());
    s.total_bytes = static_cast<std::int64_t>(text.size());
    s.text = text.substr(pieces[i].first, pieces[i].second);
    msgs.push_back(s);
  }
  hb_.set_state("waiting-hello");
  auto all_in = [&] {
    for (auto& r : roles)
      if (!hellos_.count(r)) return false;
    return true;
  };
  auto start = clock::now();
  auto last = start - std::chrono::seconds(1);
  while (!all_in()) {
    for (auto& [k, r] : reports_)
      if (r.status == demfdm::report_t::FAILED) throw ProtocolError("node '" + r.header.sender + "' failed at start-up: " + r.text);
    if (since(last) > 0.25) {
      for (auto& m : msgs) bus_.publish(bus::channel::kScene, m);
      last = clock::now();
    }
    bus_.pump(0.05);
    throw_if_interrupted();
    if (since(start) > t_.startup_s) {
      std::string missing;
      for (auto& r : roles)
        if (!hellos_.count(r)) missing += (missing.empty() ? "" : ", ") + r;
      throw ProtocolError("no hello from node(s) " + missing + " within " +
                          std::to_string(static_cast<int>(t_.startup_s)) +
                          " s: not started, crashed at start-up, or on another LCM URL/port (" + bus_.url() + ")");
    }
  }
  // Check each hello against ours.
  auto ours = bus::compiled_fingerprints();
  for (auto& r : roles) {
    auto& h = hellos_.at(r);
    std::string who = "node '" + r + "' (" + h.solver + ", pid " + std::to_string(h.pid) + " on " + h.host + ")";
    if (h.protocol_version != kProtocolVersion)
      throw ProtocolError(who + " speaks protocol version " + std::to_string(h.protocol_version) +
                          ", the coordinator " + std::to_string(kProtocolVersion));
    if (static_cast<std::uint64_t>(h.scene_hash) != hash)
      throw ProtocolError(who + " received a different scene (hash mismatch)");
    std::map<std::string, std::int64_t> theirs;
    for (int i = 0; i < h.n_types; ++i) theirs[h.type_names[i]] = h.fingerprints[i];
    for (auto& f : ours) {
      auto it = theirs.find(f.name);
      if (it == theirs.end())
        throw ProtocolError(who + " does not know message type " + f.name);
      if (it->second != f.hash)
        throw ProtocolError(who + " was built with a different definition of message type " + f.name +
                            " (fingerprint mismatch): rebuild it from the same messages/");
    }
    nodes_[r].last_seen = clock::now();
  }
  hb_.set_state("running");
}

void CoordinatorEndpoint::check_alive(const std::vector<std::string>& roles) {
  for (auto& r : roles) {
    auto it = nodes_.find(r);
    if (it == nodes_.end()) continue;
    // A node process on this host that no longer exists is dead now (kill -9, a crash). Looked
    // up once per heartbeat period, not at every pass of the waiting loop (a /proc read).
    bool gone = false;
    if (it->second.local && since(it->second.pid_checked) >= t_.heartbeat_s) {
      it->second.pid_checked = clock::now();
      gone = process_gone(it->second.pid);
    }
    if (gone) {
      std::ostringstream os;
      os << "node '" << r << "' (" << it->second.solver << ", pid " << it->second.pid << " on " << it->second.host
         << ") is gone: its process has exited (last step " << it->second.last_step << ", state "
         << it->second.state << ")";
      throw ProtocolError(os.str());
    }
    // Silence counts from the node's last message or the end of this process's own last stall.
    double s = since(watch_.origin(it->second.last_seen, hb_.stall_end()));
    if (s > t_.peer_timeout_s) {
      std::ostringstream os;
      os << "node '" << r << "' (" << it->second.solver << ", pid " << it->second.pid << " on "
         << it->second.host << ") has been silent for " << std::round(s * 10) / 10
         << " s (last step " << it->second.last_step << ", state " << it->second.state
         << "): it died or hangs";
      throw ProtocolError(os.str());
    }
  }
}

std::map<std::string, demfdm::report_t> CoordinatorEndpoint::command(
    std::int32_t cmd, const std::vector<std::string>& targets, std::int64_t step, std::int32_t stage_index,
    const std::string& stage_name, double dt, const std::vector<double>& values, const std::string& text) {
  post(cmd, targets, step, stage_index, stage_name, dt, values, text);
  return collect(cmd, targets, step, stage_index);
}

void CoordinatorEndpoint::post(std::int32_t cmd, const std::vector<std::string>& targets, std::int64_t step,
                               std::int32_t stage_index, const std::string& stage_name, double dt,
                               const std::vector<double>& values, const std::string& text) {
  demfdm::command_t c;
  c.header.step = step;
  c.command = cmd;
  c.target = targets.size() == 1 ? targets[0] : "*";
  c.stage_index = stage_index;
  c.stage_name = stage_name;
  c.dt = dt;
  c.values = values;
  c.n_values = static_cast<std::int32_t>(values.size());
  c.text = text;
  bus_.publish(bus::channel::kCommand, c);
  hb_.set_step(step);
  outstanding_[{cmd, step}] = {c, targets};
}

std::map<std::string, demfdm::report_t> CoordinatorEndpoint::collect(std::int32_t cmd,
                                                                     const std::vector<std::string>& targets,
                                                                     std::int64_t step, std::int32_t stage_index) {
  std::vector<std::string> all;
  for (auto& [r, n] : nodes_) all.push_back(r);
  auto key = [](const std::string& r, std::int32_t c, std::int64_t s) {
    return std::make_pair(r + "#" + std::to_string(c), s);
  };
  auto have = [&](const std::string& r) {
    auto it = reports_.find(key(r, cmd, step));
    return it != reports_.end() && it->second.stage_index == stage_index;
  };
  auto done = [&] {
    for (auto& r : targets)
      if (!have(r)) return false;
    return true;
  };
  auto start = clock::now();
  auto last = start;
  double interval = t_.resend_after_s;
  while (!done()) {
    bus_.pump(std::min(0.01, interval));
    // A failure report from any node ends the run, whatever command it answers.
    for (auto& [k, rep] : reports_)
      if (rep.status == demfdm::report_t::FAILED)
        throw ProtocolError("node '" + rep.header.sender + "' failed: " + rep.text);
    if (done()) break;
    throw_if_interrupted();
    check_alive(all);
    if (since(last) >= interval) {
      // Resend, as new publications, every outstanding command some target has not answered:
      // a node answers a repeated command with its stored report and never runs it twice.
      for (auto& [k, v] : outstanding_) {
        bool missing = false;
        for (auto& r : v.second)
          if (!reports_.count(key(r, k.first, k.second))) missing = true;
        if (missing) bus_.publish(bus::channel::kCommand, v.first);
      }
      last = clock::now();
      interval = std::min(interval * 2, 0.4);
    }
  }
  wait_s_ += since(start);
  std::map<std::string, demfdm::report_t> out;
  for (auto& r : targets) {
    auto& rep = reports_.at(key(r, cmd, step));
    if (rep.status == demfdm::report_t::FAILED)
      throw ProtocolError("node '" + r + "' failed at step " + std::to_string(step) + ": " + rep.text);
    out[r] = rep;
    reports_.erase(key(r, cmd, step));
  }
  outstanding_.erase({cmd, step});
  return out;
}

void CoordinatorEndpoint::shutdown(const std::string& reason) {
  demfdm::command_t c;
  c.header.step = -1;
  c.command = demfdm::command_t::SHUTDOWN;
  c.target = "*";
  c.stage_index = -1;
  c.n_values = 0;
  c.dt = 0;
  c.text = reason;
  for (int i = 0; i < 3; ++i) {
    bus_.publish(bus::channel::kCommand, c);
    bus_.pump(0.02);
  }
}

}  // namespace demfdm::proto
