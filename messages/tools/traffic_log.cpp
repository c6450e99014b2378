#include "traffic_log.hpp"

#include <algorithm>

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

}  // namespace demfdm::traffic
