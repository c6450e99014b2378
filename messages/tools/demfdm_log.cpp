// demfdm_log: inspect a recorded bus traffic log (traffic.lcmlog of a run folder).
//
//   demfdm_log summary LOG
//     channels with message counts, bytes and rates; per sender: messages, seq gaps (numbers
//     never seen between the first and the last), resends (a seq seen more than once);
//     coupled steps with complete kin/force data; per-step latency from the logger's clock:
//     DEM step = kin(k-1) -> force(k), continuum step = force(k) -> kin(k) (serial scheme;
//     the parallel scheme pairs force(k-1) -> kin(k)), as min / median / max.
//   demfdm_log export LOG --steps A:B --out FILE [--format csv|h5]
//     interface data of steps A..B (inclusive). csv: one row per step, kind and point:
//     step,kind,point,x,y,z,vx,vy,vz,fx,fy,fz,stiffness (kin rows leave the force columns
//     empty and the other way round). h5: the interface mesh and per-step arrays (layout in
//     h5_export.hpp). The format defaults to h5 for an .h5/.hdf5 file name, else csv.
//   demfdm_log merge OUT INPUT...
//     joins per-process tee logs (files, or folders of *.lcmlog) into one standard event log
//     ordered by send time (ties: inputs in path order, then file order).
//   demfdm_log compare LOG WIRE_LOG
//     per channel: messages in the (lossless, merged) log, on the wire capture (lcm-logger),
//     lost on the wire (in LOG, not in WIRE_LOG), only on the wire; messages are matched by
//     channel and exact bytes. Prints "lost on the wire: N of M messages".
//   demfdm_log verify LOG
//     reads the whole log strictly (event framing, every payload decoded, the checksums that
//     merge writes) and prints "LOG: ok: N messages, B bytes, ..." .
// Every command reads its logs strictly first (traffic_log.hpp): an empty file, a file that is
// not an event log, a truncated or a corrupt log is one line naming the file, the byte offset
// and the event number ("demfdm_log: FILE: corrupt log: event 7 at byte 2345 ...").
// Exit codes: 0 ok, 2 bad command line, unreadable, empty, truncated or corrupt log.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <set>

#include "h5_export.hpp"
#include "traffic_log.hpp"

using namespace demfdm;

namespace {

int usage(const std::string& why) {
  std::cerr << "demfdm_log: " << why
            << "\nusage: demfdm_log summary LOG\n       demfdm_log export LOG --steps A:B --out FILE [--format csv|h5]\n"
               "       demfdm_log merge OUT INPUT...\n       demfdm_log compare LOG WIRE_LOG\n       demfdm_log verify LOG\n";
  return 2;
}

struct Stats {
  double min = 0, median = 0, max = 0, mean = 0;
  std::size_t n = 0;
};
Stats stats(std::vector<double> v) {
  Stats s;
  s.n = v.size();
  if (v.empty()) return s;
  std::sort(v.begin(), v.end());
  s.min = v.front();
  s.max = v.back();
  s.median = v[v.size() / 2];
  for (double x : v) s.mean += x / static_cast<double>(v.size());
  return s;
}

std::string integrity(const traffic::Log& log) {
  return log.checksummed ? "every event verified against the checksums written by demfdm_log merge"
                         : "event framing and payloads checked; no checksums (not written by demfdm_log merge)";
}

int summary(const traffic::Log& log) {
  double t0 = static_cast<double>(log.events.front().log_us), t1 = static_cast<double>(log.events.back().log_us);
  double dur = std::max((t1 - t0) * 1e-6, 1e-9);
  std::printf("log: %zu messages over %.3f s", log.events.size(), dur);
  if (log.run_id) std::printf(", run %lld", static_cast<long long>(log.run_id));
  if (!log.scene_origin.empty()) std::printf(", scene %s", log.scene_origin.c_str());
  std::printf("\nintegrity: %s\n", integrity(log).c_str());
  std::printf("\n%-20s %9s %12s %10s %12s\n", "channel", "messages", "bytes", "msg/s", "bytes/msg");
  std::map<std::string, std::pair<std::int64_t, std::int64_t>> ch;
  for (const auto& e : log.events) {
    ch[e.channel].first += 1;
    ch[e.channel].second += e.bytes;
  }
  for (const auto& [name, cb] : ch)
    std::printf("%-20s %9lld %12lld %10.1f %12.1f\n", name.c_str(), static_cast<long long>(cb.first),
                static_cast<long long>(cb.second), static_cast<double>(cb.first) / dur,
                static_cast<double>(cb.second) / static_cast<double>(cb.first));

  // Per sender (and run): seq gaps and resends.
  struct Sender {
    std::int64_t messages = 0, resends = 0, foreign = 0;
    std::set<std::int64_t> seqs;
  };
  std::map<std::string, Sender> senders;
  std::int64_t no_header = 0;
  for (const auto& e : log.events) {
    if (!e.has_header) {
      ++no_header;
      continue;
    }
    auto& s = senders[e.header.sender];
    if (log.run_id && e.header.run_id != log.run_id) {
      ++s.foreign;
      continue;
    }
    ++s.messages;
    if (!s.seqs.insert(e.header.seq).second) ++s.resends;
  }
  std::printf("\n%-14s %9s %8s %8s %8s %12s\n", "sender", "messages", "seq", "gaps", "resends", "foreign-run");
  for (const auto& [name, s] : senders) {
    std::int64_t lo = s.seqs.empty() ? 0 : *s.seqs.begin(), hi = s.seqs.empty() ? -1 : *s.seqs.rbegin();
    std::int64_t gaps = (hi - lo + 1) - static_cast<std::int64_t>(s.seqs.size());
    std::printf("%-14s %9lld %3lld-%-4lld %8lld %8lld %12lld\n", name.c_str(), static_cast<long long>(s.messages),
                static_cast<long long>(lo), static_cast<long long>(hi), static_cast<long long>(gaps),
                static_cast<long long>(s.resends), static_cast<long long>(s.foreign));
  }
  if (no_header) std::printf("messages without a demfdm header: %lld\n", static_cast<long long>(no_header));

  // Coupled steps and per-step latency (logger clock).
  std::size_t kin_steps = 0, force_steps = 0;
  for (const auto& [k, v] : log.kin) kin_steps += v.complete();
  for (const auto& [k, v] : log.force) force_steps += v.complete();
  std::printf("\ninterface: %zu steps with kinematics, %zu steps with forces", kin_steps, force_steps);
  if (!log.kin.empty()) std::printf(" (kin steps %lld..%lld)", static_cast<long long>(log.kin.begin()->first),
                                    static_cast<long long>(log.kin.rbegin()->first));
  std::printf("\n");
  if (!log.kin.empty()) {
    // Steps inside the recorded range whose data are missing or incomplete (lost by the logger).
    std::int64_t lo = log.kin.begin()->first, hi = log.kin.rbegin()->first, no_kin = 0, no_force = 0;
    for (std::int64_t k = lo; k <= hi; ++k) {
      auto a = log.kin.find(k);
      if (a == log.kin.end() || !a->second.complete()) ++no_kin;
      auto b = log.force.find(k);
      if (k > lo && (b == log.force.end() || !b->second.complete())) ++no_force;
    }
    std::printf("missing in that range: %lld steps without kinematics, %lld without forces\n",
                static_cast<long long>(no_kin), static_cast<long long>(no_force));
  }
  std::vector<double> dem_ms, cont_ms;
  for (const auto& [k, f] : log.force) {
    auto kin_prev = log.kin.find(k - 1), kin_k = log.kin.find(k);
    if (!f.complete()) continue;
    if (kin_prev != log.kin.end() && kin_prev->second.complete() && f.last_log_us >= kin_prev->second.last_log_us)
      dem_ms.push_back(static_cast<double>(f.last_log_us - kin_prev->second.last_log_us) * 1e-3);
    if (kin_k != log.kin.end() && kin_k->second.complete() && kin_k->second.last_log_us >= f.last_log_us)
      cont_ms.push_back(static_cast<double>(kin_k->second.last_log_us - f.last_log_us) * 1e-3);
  }
  auto line = [](const char* what, const Stats& s) {
    if (s.n == 0)
      std::printf("%-34s none\n", what);
    else
      std::printf("%-34s %6zu steps  min %.3f  median %.3f  mean %.3f  max %.3f ms\n", what, s.n, s.min, s.median,
                  s.mean, s.max);
  };
  line("latency dem kin(k-1) -> force(k):", stats(dem_ms));
  line("latency continuum force(k) -> kin(k):", stats(cont_ms));
  return 0;
}

int export_csv(const traffic::Log& log, std::int64_t a, std::int64_t b, const std::string& out) {
  std::ofstream f(out);
  if (!f) {
    std::cerr << "demfdm_log: cannot write " << out << "\n";
    return 2;
  }
  f.precision(17);
  f << "step,kind,point,x,y,z,vx,vy,vz,fx,fy,fz,stiffness\n";
  std::size_t rows = 0, steps = 0;
  for (std::int64_t k = a; k <= b; ++k) {
    auto ki = log.kin.find(k);
    if (ki != log.kin.end() && ki->second.complete()) {
      ++steps;
      const auto& v = ki->second;
      for (std::size_t i = 0; i < v.positions.size() / 3; ++i, ++rows)
        f << k << ",kin," << i << ',' << v.positions[3 * i] << ',' << v.positions[3 * i + 1] << ','
          << v.positions[3 * i + 2] << ',' << v.velocities[3 * i] << ',' << v.velocities[3 * i + 1] << ','
          << v.velocities[3 * i + 2] << ",,,,\n";
    }
    auto fi = log.force.find(k);
    if (fi != log.force.end() && fi->second.complete()) {
      const auto& v = fi->second;
      for (std::size_t i = 0; i < v.forces.size() / 3; ++i, ++rows)
        f << k << ",force," << i << ",,,,,,," << v.forces[3 * i] << ',' << v.forces[3 * i + 1] << ','
          << v.forces[3 * i + 2] << ',' << v.stiffness[i] << '\n';
    }
  }
  if (!f.good()) {
    std::cerr << "demfdm_log: error writing " << out << "\n";
    return 2;
  }
  std::cout << "wrote " << rows << " rows (steps " << a << ".." << b << ", " << steps << " with kinematics) to " << out
            << "\n";
  return 0;
}

int export_hdf5(const traffic::Log& log, std::int64_t a, std::int64_t b, const std::string& out) {
  try {
    auto c = traffic::export_h5(log, a, b, out);
    std::cout << "wrote steps " << a << ".." << b << " to " << out << ": " << c.kin_steps << " with kinematics, "
              << c.force_steps << " with forces" << (c.mesh ? ", interface mesh" : ", no interface mesh in the log")
              << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "demfdm_log: " << out << ": " << e.what() << "\n";
    return 2;
  }
}

int merge(int argc, char** argv) {
  if (argc < 4) return usage("merge needs OUT and at least one INPUT");
  std::vector<std::string> inputs(argv + 3, argv + argc);
  try {
    auto r = traffic::merge_logs(inputs, argv[2]);
    for (const auto& w : r.warnings) std::cerr << "demfdm_log: warning: " << w << "\n";
    std::cout << "merged " << r.events << " messages from " << r.inputs << " logs into " << argv[2] << "\n";
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "demfdm_log: " << e.what() << "\n";
    return 2;
  }
}

int compare(const traffic::Log& log, const traffic::Log& wire) {
  auto d = traffic::compare_logs(log, wire);
  std::printf("%-20s %9s %9s %13s %13s\n", "channel", "log", "wire", "lost-on-wire", "only-on-wire");
  std::int64_t lost = 0, total = 0, only = 0;
  for (const auto& [ch, c] : d) {
    std::printf("%-20s %9lld %9lld %13lld %13lld\n", ch.c_str(), static_cast<long long>(c.in_log),
                static_cast<long long>(c.on_wire), static_cast<long long>(c.lost_on_wire),
                static_cast<long long>(c.only_on_wire));
    lost += c.lost_on_wire;
    total += c.in_log;
    only += c.only_on_wire;
  }
  std::printf("lost on the wire: %lld of %lld messages; only on the wire: %lld\n", static_cast<long long>(lost),
              static_cast<long long>(total), static_cast<long long>(only));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) return usage("expected a command and a log file");
  std::string cmd = argv[1], path = argv[2];
  if (cmd != "summary" && cmd != "export" && cmd != "merge" && cmd != "compare" && cmd != "verify")
    return usage("unknown command '" + cmd + "'");
  if (cmd == "merge") return merge(argc, argv);
  if (cmd == "verify") {
    if (argc != 3) return usage("verify needs exactly one LOG");
    try {
      auto log = traffic::read_log(path);
      std::printf("%s: ok: %zu messages, %lld bytes; %s\n", path.c_str(), log.events.size(),
                  static_cast<long long>(log.file_bytes), integrity(log).c_str());
      return 0;
    } catch (const std::exception& e) {
      std::cerr << "demfdm_log: " << e.what() << "\n";
      return 2;
    }
  }
  if (cmd == "compare") {
    if (argc != 4) return usage("compare needs LOG and WIRE_LOG");
    try {
      return compare(traffic::read_log(path), traffic::read_log(argv[3]));
    } catch (const std::exception& e) {
      std::cerr << "demfdm_log: " << e.what() << "\n";
      return 2;
    }
  }
  std::int64_t a = 0, b = -1;
  std::string out, format;
  bool have_steps = false;
  for (int i = 3; i < argc; ++i) {
    std::string arg = argv[i];
    auto value = [&](const std::string& key) -> std::optional<std::string> {
      if (arg == key && i + 1 < argc) return std::string(argv[++i]);
      if (arg.rfind(key + "=", 0) == 0) return arg.substr(key.size() + 1);
      return std::nullopt;
    };
    if (auto v = value("--steps")) {
      auto c = v->find(':');
      try {
        if (c == std::string::npos) throw std::invalid_argument("no colon");
        std::size_t p1 = 0, p2 = 0;
        a = std::stoll(v->substr(0, c), &p1);
        b = std::stoll(v->substr(c + 1), &p2);
        if (p1 != c || p2 != v->size() - c - 1 || b < a) throw std::invalid_argument("order");
      } catch (const std::exception&) {
        return usage("--steps: expected A:B with integers A <= B, found '" + *v + "'");
      }
      have_steps = true;
    } else if (auto o = value("--out")) {
      out = *o;
    } else if (auto f = value("--format")) {
      format = *f;
      if (format != "csv" && format != "h5") return usage("--format: expected csv or h5, found '" + format + "'");
    } else {
      return usage("unknown argument '" + arg + "'");
    }
  }
  if (cmd == "export" && (!have_steps || out.empty())) return usage("export needs --steps A:B and --out FILE");
  traffic::Log log;
  try {
    log = traffic::read_log(path);
  } catch (const std::exception& e) {
    std::cerr << "demfdm_log: " << e.what() << "\n";
    return 2;
  }
  if (cmd == "summary") return summary(log);
  if (format.empty()) {
    auto ends = [&](const std::string& x) { return out.size() >= x.size() && out.compare(out.size() - x.size(), x.size(), x) == 0; };
    format = ends(".h5") || ends(".hdf5") ? "h5" : "csv";
  }
  return format == "h5" ? export_hdf5(log, a, b, out) : export_csv(log, a, b, out);
}
