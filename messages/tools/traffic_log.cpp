#include "traffic_log.hpp"

#include <lcm/eventlog.h>

#include <algorithm>
#include <filesystem>
#include <memory>
#include <tuple>

namespace demfdm::traffic {

Log read_log(const std::string& path) {
  lcm::LogFile file(path, "r");
  if (!file.good()) throw std::runtime_error(path + ": cannot open as an LCM event log");
  Log log;
  std::map<std::int32_t, std::string> scene_chunks;
  std::int32_t scene_n = -1;
  while (const lcm::LogEvent* ev = file.readNextEvent()) {
    Event e;
    e.channel = ev->channel;
    e.log_us = ev->timestamp;
    e.bytes = ev->datalen;
    const auto* p = static_cast<const std::uint8_t*>(ev->data);
    e.data.assign(p, p + ev->datalen);
    // Every demfdm message starts with its 8-byte fingerprint, then header_t (no fingerprint).
    if (ev->datalen > 8) {
      try {
        e.has_header = e.header._decodeNoHash(ev->data, 8, ev->datalen - 8) >= 0;
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
  if (scene_n > 0 && static_cast<std::int32_t>(scene_chunks.size()) == scene_n)
    for (auto& [i, t] : scene_chunks) log.scene_text += t;
  return log;
}

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
  // k-way merge: each process writes its events in send order (timestamps taken under its
  // publish lock), so every input is already sorted; memory holds one event per input.
  std::vector<std::unique_ptr<lcm::LogFile>> in;
  struct Head {
    std::int64_t t = 0;
    std::string channel;
    std::vector<std::uint8_t> data;
    bool valid = false;
  };
  std::vector<Head> head(files.size());
  auto advance = [&](std::size_t f) {
    const lcm::LogEvent* ev = in[f]->readNextEvent();
    head[f].valid = ev != nullptr;
    if (!ev) return;
    const auto* p = static_cast<const std::uint8_t*>(ev->data);
    head[f].t = ev->timestamp;
    head[f].channel = ev->channel;
    head[f].data.assign(p, p + ev->datalen);
  };
  for (std::size_t f = 0; f < files.size(); ++f) {
    in.push_back(std::make_unique<lcm::LogFile>(files[f], "r"));
    if (!in.back()->good()) throw std::runtime_error(files[f] + ": cannot open as an LCM event log");
    advance(f);
  }
  std::unique_ptr<lcm_eventlog_t, void (*)(lcm_eventlog_t*)> w(lcm_eventlog_create(out.c_str(), "w"),
                                                              lcm_eventlog_destroy);
  if (!w) throw std::runtime_error(out + ": cannot create the merged log");
  std::int64_t n = 0;
  for (;;) {
    std::size_t best = files.size();  // smallest timestamp; ties: the first input
    for (std::size_t f = 0; f < files.size(); ++f)
      if (head[f].valid && (best == files.size() || head[f].t < head[best].t)) best = f;
    if (best == files.size()) break;
    Head& e = head[best];
    lcm_eventlog_event_t ev{};
    ev.eventnum = n++;
    ev.timestamp = e.t;
    ev.channellen = static_cast<std::int32_t>(e.channel.size());
    ev.datalen = static_cast<std::int32_t>(e.data.size());
    ev.channel = e.channel.data();
    ev.data = e.data.data();
    if (lcm_eventlog_write_event(w.get(), &ev) != 0) throw std::runtime_error(out + ": write error (disk full?)");
    advance(best);
  }
  if (std::fflush(w->f) != 0) throw std::runtime_error(out + ": write error (disk full?)");
  return MergeResult{files.size(), static_cast<std::size_t>(n)};
}

namespace {
// LCM publishes on this channel itself when an instance starts (not demfdm traffic).
const std::string kLcmSelfTest = "LCM_SELF_TEST";
}  // namespace

std::map<std::string, ChannelDiff> compare_logs(const Log& log, const Log& wire) {
  // (channel, size, FNV-1a-64 of the bytes) -> count in the log minus count on the wire.
  auto key = [](const Event& e) {
    std::uint64_t h = 1469598103934665603ull;
    for (std::uint8_t c : e.data) h = (h ^ c) * 1099511628211ull;
    return std::make_tuple(e.channel, e.data.size(), h);
  };
  std::map<std::tuple<std::string, std::size_t, std::uint64_t>, std::int64_t> balance;
  std::map<std::string, ChannelDiff> out;
  for (const auto& e : log.events) {
    ++balance[key(e)];
    ++out[e.channel].in_log;
  }
  for (const auto& e : wire.events) {
    if (e.channel == kLcmSelfTest) continue;
    --balance[key(e)];
    ++out[e.channel].on_wire;
  }
  for (const auto& [k, b] : balance) {
    if (b > 0) out[std::get<0>(k)].lost_on_wire += b;
    if (b < 0) out[std::get<0>(k)].only_on_wire -= b;
  }
  return out;
}

}  // namespace demfdm::traffic
