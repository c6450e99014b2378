#include "coordinator/core/summary.hpp"

#include <cmath>
#include <cstdio>
#include <iomanip>
#include <sstream>

namespace demfdm::coord {
namespace {

double share(double part, double whole) { return whole > 0 ? 100.0 * part / whole : 0.0; }

double value_or_zero(const std::map<std::string, double>& m, const std::string& k) {
  auto it = m.find(k);
  return it == m.end() ? 0.0 : it->second;
}

// role -> effect -> seconds of one stage (from its STAGE_END reports).
std::map<std::string, std::map<std::string, double>> stage_effects(const StageSummary& s) {
  std::map<std::string, std::map<std::string, double>> out;
  for (auto& [role, rep] : s.end) {
    auto e = effects_of(rep);
    if (!e.empty()) out[role] = std::move(e);
  }
  return out;
}

}  // namespace

std::string json_number(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

namespace {

// {"gravity": {"s": 1.2, "share": 0.05}, ...}: share of the node's compute time (fraction).
std::string json_effects(const std::map<std::string, double>& eff, double compute) {
  std::string o = "{";
  bool first = true;
  for (auto& [name, sec] : eff) {
    o += (first ? "" : ", ") + json_string(name) + ": {\"s\": " + json_number(sec) +
         ", \"share\": " + json_number(compute > 0 ? sec / compute : 0.0) + "}";
    first = false;
  }
  return o + "}";
}

// {"speed_m_s": ..., ..., "quasi_static": false}: the bond measures only when they apply.
std::string json_rate(const RateMeasures& m) {
  std::string o = "{\"speed_m_s\": " + json_number(m.speed) + ", \"inertial_number\": " + json_number(m.inertial_number) +
                  ", \"ramp_time_s\": " + json_number(m.ramp_time) + ", \"wave_speed_m_s\": " + json_number(m.wave_speed) +
                  ", \"young_Pa\": " + json_number(m.young) + ", \"poisson\": " + json_number(m.poisson) +
                  ", \"bulk_density_kg_m3\": " + json_number(m.bulk_density) +
                  ", \"quasi_static_limit\": " + json_number(m.limit);
  if (m.applicable())
    o += ", \"bond_strength_Pa\": " + json_number(*m.bond_strength) + ", \"failure_strain\": " +
         json_number(*m.failure_strain) + ", \"impedance_ratio\": " + json_number(*m.impedance_ratio) +
         ", \"strain_rate_ratio\": " + json_number(*m.strain_rate_ratio) +
         ", \"quasi_static\": " + (m.quasi_static() ? "true" : "false");
  return o + "}";
}

}  // namespace

std::map<std::string, double> effects_of(const NodeReport& end) {
  std::map<std::string, double> out;
  const std::string prefix = kEffectPrefix;
  for (auto& [k, v] : end.values)
    if (k.size() > prefix.size() && k.compare(0, prefix.size(), prefix) == 0) out[k.substr(prefix.size())] = v;
  return out;
}

double cpu_of(const NodeReport& end) {
  auto it = end.values.find(kCpuKey);
  return it == end.values.end() ? -1.0 : it->second;
}

RunTotals run_totals(const RunSummary& sum) {
  RunTotals t;
  for (auto& s : sum.stages) {
    for (auto& [r, c] : s.compute_s) t.compute_s[r] += c;
    for (auto& [r, w] : s.wait_s) t.wait_s[r] += w;
    for (auto& [r, rep] : s.end) {
      if (const double cpu = cpu_of(rep); cpu >= 0) {
        t.cpu_s[r] += cpu;
        t.cpu_wall_s[r] += s.wall_s;
      }
      if (auto it = rep.values.find(kPeakKey); it != rep.values.end()) t.peak_mb[r] = std::max(t.peak_mb[r], it->second);
      if (auto it = rep.values.find(kPeakRanksKey); it != rep.values.end())
        t.peak_ranks_mb[r] = std::max(t.peak_ranks_mb[r], it->second);
    }
    for (auto& [r, eff] : stage_effects(s))
      for (auto& [name, sec] : eff) t.effects[r][name] += sec;
  }
  return t;
}

std::string json_string(const std::string& s) {
  std::string o = "\"";
  for (char ch : s) {
    auto c = static_cast<unsigned char>(ch);
    if (c == '"' || c == '\\') {
      o += '\\';
      o += ch;
    } else if (c == '\n') {
      o += "\\n";
    } else if (c == '\t') {
      o += "\\t";
    } else if (c < 0x20) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04x", c);
      o += buf;
    } else {
      o += ch;
    }
  }
  return o + "\"";
}

std::string summary_text(const RunInfo& info, const RunSummary& sum) {
  std::ostringstream os;
  os << std::fixed << std::setprecision(3);
  os << "scene: " << info.scene << " (hash " << std::hex << info.hash << std::dec << ")\n";
  os << "nodes:\n";
  for (auto& n : info.nodes)
    os << "  " << n.role << ": " << n.solver << " pid " << n.pid << " on " << n.host << " (" << n.build_id << ")\n";
  os << "stages:\n";
  for (std::size_t i = 0; i < sum.stages.size(); ++i) {
    auto& s = sum.stages[i];
    os << "  " << s.name << " [" << s.action << "]: steps " << s.first_step << ".." << s.last_step << " ("
       << (s.last_step - s.first_step + 1) << "), wall " << s.wall_s << " s, ended by " << s.ended_by << "\n";
    if (auto r = info.rates.find(i); r != info.rates.end())
      os << "    footing rate: " << describe(r->second) << "\n";
    auto eff = stage_effects(s);
    for (auto& [r, c] : s.compute_s) {
      double w = value_or_zero(s.wait_s, r);
      os << "    " << r << ": compute " << c << " s, bus wait " << w << " s (" << std::setprecision(1)
         << share(w, c + w) << " %)" << std::setprecision(3);
      if (auto e = s.end.find(r); e != s.end.end() && cpu_of(e->second) >= 0 && s.wall_s > 0)
        os << ", CPU " << cpu_of(e->second) << " s (" << std::setprecision(2) << cpu_of(e->second) / s.wall_s
           << " cores)" << std::setprecision(3);
      os << "\n";
      auto it = eff.find(r);
      if (it == eff.end()) continue;
      os << "      effects:";
      bool first = true;
      for (auto& [name, sec] : it->second) {
        os << (first ? " " : ", ") << name << " " << sec << " s (" << std::setprecision(1) << share(sec, c) << " %)"
           << std::setprecision(3);
        first = false;
      }
      os << "\n";
    }
  }
  os << "total: " << sum.steps << " coupling steps in " << sum.wall_s << " s\n";
  auto tot = run_totals(sum);
  os << "run totals per node (compute, bus wait; effects with their share of the node's compute time):\n";
  for (auto& [r, c] : tot.compute_s) {
    double w = value_or_zero(tot.wait_s, r);
    os << "  " << r << ": compute " << c << " s, bus wait " << w << " s\n";
    auto it = tot.effects.find(r);
    if (it == tot.effects.end()) {
      os << "    (no effects reported)\n";
      continue;
    }
    for (auto& [name, sec] : it->second) {
      os << "    " << std::left << std::setw(20) << name << std::right << std::setw(12) << sec << " s "
         << std::setw(6) << std::setprecision(1) << share(sec, c) << " %" << std::setprecision(3) << "\n";
    }
  }
  if (!tot.cpu_s.empty()) {
    // Cores kept busy: each node's CPU time over the wall time of the stages it reported on.
    os << "CPU utilisation (cores busy over the stages' wall time):";
    double together = 0;
    bool first = true;
    for (auto& [r, cpu] : tot.cpu_s) {
      const double wall = value_or_zero(tot.cpu_wall_s, r), cores = wall > 0 ? cpu / wall : 0.0;
      together += cores;
      os << (first ? " " : ", ") << r << " " << std::setprecision(2) << cores << std::setprecision(3);
      first = false;
    }
    os << "; together " << std::setprecision(2) << together << std::setprecision(3);
    if (info.host_cores > 0)
      os << " of the coordinator host's " << info.host_cores << " (" << std::setprecision(0)
         << share(together, info.host_cores) << " %)" << std::setprecision(3);
    os << "\n";
  }
  if (!tot.peak_mb.empty()) {
    // The largest resident set of each node's process (and of the DEM's other ranks).
    os << "Peak memory (resident set):";
    bool first = true;
    for (auto& [r, mb] : tot.peak_mb) {
      os << (first ? " " : ", ") << r << " " << std::setprecision(0) << mb << " MB" << std::setprecision(3);
      if (auto o = tot.peak_ranks_mb.find(r); o != tot.peak_ranks_mb.end())
        os << " (rank 0; its other ranks at most " << std::setprecision(0) << o->second << " MB each)"
           << std::setprecision(3);
      first = false;
    }
    os << "\n";
  }
  if (!info.bus.empty()) os << "coordinator bus: " << info.bus << "\n";
  if (!info.checkpoints.empty()) os << "checkpoints: " << info.checkpoints << "\n";
  if (!info.resumed.empty()) os << info.resumed << "\n";
  for (auto& [i, m] : info.rates) {
    if (i >= sum.stages.size()) continue;
    auto w = quasi_static_warning(sum.stages[i].name, m);
    if (!w.empty()) os << w << "\n";
  }
  return os.str();
}

std::string summary_json(const RunInfo& info, const RunSummary& sum) {
  std::ostringstream os;
  char hash[32];
  std::snprintf(hash, sizeof hash, "%llx", static_cast<unsigned long long>(info.hash));
  os << "{\n  \"scene\": " << json_string(info.scene) << ",\n  \"hash\": " << json_string(hash) << ",\n";
  os << "  \"nodes\": [";
  for (std::size_t i = 0; i < info.nodes.size(); ++i) {
    auto& n = info.nodes[i];
    os << (i ? ",\n    " : "\n    ") << "{\"role\": " << json_string(n.role) << ", \"solver\": " << json_string(n.solver)
       << ", \"pid\": " << n.pid << ", \"host\": " << json_string(n.host) << ", \"build_id\": " << json_string(n.build_id)
       << "}";
  }
  os << (info.nodes.empty() ? "],\n" : "\n  ],\n");
  os << "  \"stages\": [";
  for (std::size_t i = 0; i < sum.stages.size(); ++i) {
    auto& s = sum.stages[i];
    auto eff = stage_effects(s);
    os << (i ? ",\n    " : "\n    ") << "{\"name\": " << json_string(s.name) << ", \"action\": " << json_string(s.action)
       << ", \"first_step\": " << s.first_step << ", \"last_step\": " << s.last_step
       << ", \"steps\": " << (s.last_step - s.first_step + 1) << ", \"wall_s\": " << json_number(s.wall_s)
       << ", \"ended_by\": " << json_string(s.ended_by);
    if (auto r = info.rates.find(i); r != info.rates.end()) os << ",\n      \"footing_rate\": " << json_rate(r->second);
    os << ",\n      \"nodes\": {";
    bool first = true;
    for (auto& [r, c] : s.compute_s) {
      auto it = eff.find(r);
      os << (first ? "" : ", ") << json_string(r) << ": {\"compute_s\": " << json_number(c)
         << ", \"wait_s\": " << json_number(value_or_zero(s.wait_s, r));
      if (auto e = s.end.find(r); e != s.end.end() && cpu_of(e->second) >= 0)
        os << ", \"cpu_s\": " << json_number(cpu_of(e->second))
           << ", \"cpu_cores\": " << json_number(s.wall_s > 0 ? cpu_of(e->second) / s.wall_s : 0.0);
      os << ", \"effects\": " << json_effects(it == eff.end() ? std::map<std::string, double>{} : it->second, c) << "}";
      first = false;
    }
    os << "}}";
  }
  os << (sum.stages.empty() ? "],\n" : "\n  ],\n");
  auto tot = run_totals(sum);
  os << "  \"totals\": {\"steps\": " << sum.steps << ", \"wall_s\": " << json_number(sum.wall_s) << ", \"nodes\": {";
  bool first = true;
  for (auto& [r, c] : tot.compute_s) {
    auto it = tot.effects.find(r);
    os << (first ? "" : ",") << "\n    " << json_string(r) << ": {\"compute_s\": " << json_number(c)
       << ", \"wait_s\": " << json_number(value_or_zero(tot.wait_s, r));
    if (auto cp = tot.cpu_s.find(r); cp != tot.cpu_s.end()) {
      const double wall = value_or_zero(tot.cpu_wall_s, r);
      os << ", \"cpu_s\": " << json_number(cp->second) << ", \"cpu_cores\": " << json_number(wall > 0 ? cp->second / wall : 0.0);
    }
    os << ", \"effects\": " << json_effects(it == tot.effects.end() ? std::map<std::string, double>{} : it->second, c);
    // (after the effects: readers that match the members before them keep working)
    if (auto pk = tot.peak_mb.find(r); pk != tot.peak_mb.end()) os << ", \"peak_rss_mb\": " << json_number(pk->second);
    if (auto pk = tot.peak_ranks_mb.find(r); pk != tot.peak_ranks_mb.end())
      os << ", \"peak_rss_mb_other_ranks\": " << json_number(pk->second);
    os << "}";
    first = false;
  }
  os << (tot.compute_s.empty() ? "}" : "\n  }");
  os << ", \"host_cores\": " << info.host_cores << "}";
  for (auto& [key, value] : info.extra_json) os << ",\n  " << json_string(key) << ": " << value;
  os << "\n}\n";
  return os.str();
}

}  // namespace demfdm::coord
