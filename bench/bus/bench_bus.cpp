// Per-step overhead of lockstep coupling over the bus, beside a raw LCM round trip measured in
// the same run on the same URL kind (udpm on loopback, private network namespace when root).
//
//   bench_bus [steps=4000] [round_trips=2000] [repeats=3]
//
// The coupled run is the split chain (tests/chain) with 10 masses per side: its physics costs
// well under a microsecond per step, so the time per coupling step is the protocol's overhead
// (commands, interface data, reports) through three processes.
//
// Wall times on a shared 2-core machine are noisy, so the bench also counts, per coupling step
// and per process, the wake-ups (voluntary context switches: a thread blocked and was woken),
// the involuntary context switches (preemptions) and the CPU time, from the rusage of each
// process (wait4, all its threads). Start-up, the warm-up stage and the shut-down are taken
// out by a second, shorter run of the same scene: per step = (long - short) / (steps - steps/4).
// The raw round trip is counted the same way (the echo process and the pinging process).
// Each measure is repeated, interleaved (round trip, then every coupled case, per repeat); the
// table shows every repeat and the median, the ratios are taken within a repeat.
// DEMFDM_BUS_FILTER=0 in the environment turns the nodes' kernel channel filter off
// (messages/bus.hpp), for comparisons.
#include <lcm/lcm-cpp.hpp>
#include <sys/resource.h>

#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <numeric>
#include <regex>
#include <sstream>
#include <thread>

#include "tests/integration/process.hpp"

namespace fs = std::filesystem;
using namespace demfdm::testing;

namespace {
struct Echo {
  lcm::LCM* l;
  void on(const lcm::ReceiveBuffer* rb, const std::string&) { l->publish("PONG", rb->data, rb->data_size); }
};
struct Ping {
  bool got = false;
  void on(const lcm::ReceiveBuffer*, const std::string&) { got = true; }
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// Counters of one process (all its threads).
struct Usage {
  double wakeups = 0, preempted = 0, cpu_us = 0;
  Usage operator-(const Usage& o) const { return {wakeups - o.wakeups, preempted - o.preempted, cpu_us - o.cpu_us}; }
  Usage operator/(double n) const { return {wakeups / n, preempted / n, cpu_us / n}; }
};
Usage usage_of(const rusage& ru) {
  auto us = [](const timeval& t) { return 1e6 * static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_usec); };
  return {static_cast<double>(ru.ru_nvcsw), static_cast<double>(ru.ru_nivcsw), us(ru.ru_utime) + us(ru.ru_stime)};
}

// Waits up to timeout_s for the child (< 0: blocks, no polling that would compete for the
// cores); its wait status and rusage, or nullopt on timeout.
std::optional<std::pair<int, Usage>> wait_usage(pid_t pid, double timeout_s) {
  if (timeout_s < 0) {
    int st = 0;
    rusage ru{};
    if (wait4(pid, &st, 0, &ru) == pid) return std::make_pair(st, usage_of(ru));
    return std::nullopt;
  }
  auto t0 = std::chrono::steady_clock::now();
  for (;;) {
    int st = 0;
    rusage ru{};
    if (wait4(pid, &st, WNOHANG, &ru) == pid) return std::make_pair(st, usage_of(ru));
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() > timeout_s) return std::nullopt;
    std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
}

struct RoundTrip {
  double us = 0;          // median round trip
  Usage pinger, echo;     // per round trip
};

// Raw round trips: one small message to an echo process (its own LCM instance, like the
// nodes) and back; n timed after 100 warm-up ones.
std::pair<std::vector<double>, std::pair<Usage, Usage>> round_trips(const std::string& url, int n) {
  pid_t child = fork();
  if (child == 0) {
    lcm::LCM b(url);
    Echo e{&b};
    b.subscribe("PING", &Echo::on, &e);
    for (;;) b.handleTimeout(1000);
  }
  lcm::LCM a(url);
  Ping p;
  a.subscribe("PONG", &Ping::on, &p);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  std::vector<std::uint8_t> msg(64, 1);
  std::vector<double> rtt;
  rusage r0{}, r1{};
  for (int i = 0; i < n + 100; ++i) {
    if (i == 100) getrusage(RUSAGE_SELF, &r0);
    p.got = false;
    auto t0 = std::chrono::steady_clock::now();
    a.publish("PING", msg.data(), static_cast<unsigned>(msg.size()));
    while (!p.got) a.handleTimeout(100);  // the first PINGs may precede the echo's subscription
    double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
    if (i >= 100) rtt.push_back(us);  // warm-up excluded
  }
  getrusage(RUSAGE_SELF, &r1);
  ::kill(child, SIGKILL);
  auto w = wait_usage(child, 10);
  return {rtt, {usage_of(r1) - usage_of(r0), w ? w->second : Usage{}}};
}

RoundTrip raw_round_trip(const std::string& url, int n) {
  // The echo's counters cover its whole life: take out a short run's (start-up, warm-up).
  auto big = round_trips(url, n);
  auto small = round_trips(url, n / 4);
  RoundTrip r;
  r.us = median(big.first);
  r.pinger = big.second.first / n;
  r.echo = (big.second.second - small.second.second) / (n - n / 4);
  return r;
}

struct Coupled {
  double us = 0;                        // wall per coupling step of the timed stage
  std::map<std::string, Usage> per;     // per process, per coupling step
  std::map<std::string, double> count;  // coordinator's message counters per step
};

struct RunOut {
  double us = 0;
  std::map<std::string, Usage> usage;
  std::int64_t published = 0, accepted = 0;
};

RunOut run_chain(const std::string& bin, const std::string& scheme, int steps, int port, int per_grant) {
  auto dir = fs::temp_directory_path() / ("demfdm-bench-bus-" + scheme + std::to_string(per_grant) + "-" +
                                          std::to_string(steps) + "-" + std::to_string(getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  std::ofstream(dir / "scene.toml")
      << "[dem]\nexecutable = \"chain_dem\"\n[continuum]\nexecutable = \"chain_continuum\"\n[coupling]\nscheme = \""
      << scheme << "\"\n[chain]\nn_masses = 20\nsplit = 10\nrecord_every = 1000000\n"
      << "[[stage]]\nname = \"warmup\"\nsteps = 200\ncoupled = true\n"
      << "[[stage]]\nname = \"timed\"\nsteps = " << steps << "\ncoupled = true\nsteps_per_grant = " << per_grant << "\n";
  std::string url = "udpm://239.255.76.67:" + std::to_string(port) + "?ttl=0";
  auto args = [&](const std::string& exe) {
    return std::vector<std::string>{bin + "/" + exe, "--lcm-url=" + url, "--run-id=99", "--run-dir=" + dir.string()};
  };
  auto d = spawn(args("chain_dem"));
  auto c = spawn(args("chain_continuum"));
  auto ca = args("coordinator");
  ca.insert(ca.begin() + 1, (dir / "scene.toml").string());
  auto co = spawn(ca, {}, (dir / "out.txt").string());
  RunOut out;
  auto st = wait_usage(co.pid, -1);  // the coordinator ends by itself (a silent node: 3 s)
  auto sd = wait_usage(d.pid, 5);
  auto sc = wait_usage(c.pid, 5);
  if (!sd) kill_and_reap(d);
  if (!sc) kill_and_reap(c);
  if (!st || exit_code(st->first) != 0 || !sd || !sc)
    throw std::runtime_error("coupled run failed: " + read_file((dir / "out.txt").string()));
  out.usage = {{"coordinator", st->second}, {"dem", sd->second}, {"continuum", sc->second}};
  auto text = read_file((dir / "summary.txt").string());
  std::smatch m;
  std::regex re("timed \\[cycle\\]: steps \\d+\\.\\.\\d+ \\((\\d+)\\), wall ([0-9.]+) s");
  if (!std::regex_search(text, m, re)) throw std::runtime_error("no timed stage in summary:\n" + text);
  out.us = std::stod(m[2]) / std::stod(m[1]) * 1e6;
  std::regex bus("coordinator bus: published (\\d+), accepted (\\d+)");
  if (std::regex_search(text, m, bus)) {
    out.published = std::stoll(m[1]);
    out.accepted = std::stoll(m[2]);
  }
  fs::remove_all(dir);
  return out;
}

Coupled coupled_step(const std::string& bin, const std::string& scheme, int steps, int port, int per_grant) {
  auto big = run_chain(bin, scheme, steps, port, per_grant);
  const int few = std::max(per_grant, steps / 4 / per_grant * per_grant);
  auto small = run_chain(bin, scheme, few, port, per_grant);
  Coupled c;
  c.us = big.us;
  const double n = steps - few;
  for (auto& [role, u] : big.usage) c.per[role] = (u - small.usage[role]) / n;
  c.count["coordinator published"] = (big.published - small.published) / n;
  c.count["coordinator accepted"] = (big.accepted - small.accepted) / n;
  return c;
}

std::string loadavg() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a + " " + b + " " + c;
}
}  // namespace

int main(int argc, char** argv) {
  int steps = argc > 1 ? std::atoi(argv[1]) : 4000;
  int rts = argc > 2 ? std::atoi(argv[2]) : 2000;
  int repeats = argc > 3 ? std::max(1, std::atoi(argv[3])) : 3;
  auto why = enter_private_network();
  if (!why.empty()) std::cerr << "note: " << why << "; using the host network as it is\n";
  std::string bin = DEMFDM_BIN_DIR;
  const std::string load_before = loadavg();
  struct Case {
    std::string label, scheme;
    int per_grant;
  };
  const std::vector<Case> cases = {{"serial", "serial", 1},
                                   {"parallel", "parallel", 1},
                                   {"serial, 16 steps per grant", "serial", 16},
                                   {"parallel, 16 steps per grant", "parallel", 16}};
  std::vector<RoundTrip> rt;
  std::vector<std::vector<Coupled>> co(cases.size());
  const int base = static_cast<int>(getpid() % 500);
  for (int r = 0; r < repeats; ++r) {
    std::string url = "udpm://239.255.76.67:" + std::to_string(41000 + base) + "?ttl=0&recv_buf_size=4194304";
    rt.push_back(raw_round_trip(url, rts));
    for (std::size_t i = 0; i < cases.size(); ++i)
      co[i].push_back(coupled_step(bin, cases[i].scheme, steps, 42000 + 1000 * static_cast<int>(i) + base,
                                   cases[i].per_grant));
  }
  const std::string load_after = loadavg();
  const char* filt = std::getenv("DEMFDM_BUS_FILTER");
  std::cout << std::fixed;
  std::cout << "bench_bus: lockstep coupling overhead (3 processes, udpm loopback), " << repeats << " repeats of "
            << steps << " coupled steps and " << rts << " round trips; " << std::thread::hardware_concurrency()
            << " cores, load average " << load_before << " before, " << load_after << " after; kernel channel filter "
            << (filt && std::string(filt) == "0" ? "off" : "on") << "\n\n";
  auto cells = [&](auto get) {
    std::ostringstream os;
    os << std::fixed;
    std::vector<double> v;
    for (int r = 0; r < repeats; ++r) {
      double x = get(r);
      v.push_back(x);
      os << " " << std::setprecision(1) << x << " |";
    }
    os << " **" << std::setprecision(1) << median(v) << "** |";
    return std::make_pair(os.str(), v);
  };
  std::cout << "| measure [us per step] |";
  for (int r = 0; r < repeats; ++r) std::cout << " run " << r + 1 << " |";
  std::cout << " median | raw round trips (per run; median) |\n|---|";
  for (int r = 0; r <= repeats; ++r) std::cout << "---|";
  std::cout << "---|\n";
  std::cout << "| raw LCM round trip, 2 processes, 64 B (median of " << rts << ") |"
            << cells([&](int r) { return rt[r].us; }).first << " 1.00 |\n";
  for (std::size_t i = 0; i < cases.size(); ++i) {
    std::cout << "| coupled step, " << cases[i].label << " (mean of " << steps << ") |"
              << cells([&](int r) { return co[i][r].us; }).first;
    std::vector<double> ratio;
    for (int r = 0; r < repeats; ++r) ratio.push_back(co[i][r].us / rt[r].us);
    std::cout << std::setprecision(2);
    for (double x : ratio) std::cout << " " << x;
    std::cout << "; **" << median(ratio) << "** |\n";
  }
  std::cout << "target: at most 2 raw round trips per coupled step, 1 step per grant\n\n";

  std::cout << "Per coupling step (per round trip for the raw one), per process, median of the runs: wake-ups "
               "(voluntary context switches) / preemptions (involuntary) / CPU us\n\n";
  std::cout << "| process | raw round trip |";
  for (auto& c : cases) std::cout << " " << c.label << " |";
  std::cout << "\n|---|---|";
  for (std::size_t i = 0; i < cases.size(); ++i) std::cout << "---|";
  std::cout << "\n";
  auto fmt = [&](const std::vector<Usage>& v) {
    std::vector<double> w, p, c;
    for (auto& u : v) {
      w.push_back(u.wakeups);
      p.push_back(u.preempted);
      c.push_back(u.cpu_us);
    }
    std::ostringstream os;
    os << std::fixed << std::setprecision(2) << median(w) << " / " << median(p) << " / " << std::setprecision(0) << median(c);
    return os.str();
  };
  const std::vector<std::pair<std::string, std::string>> rows = {
      {"dem", "pinger"}, {"continuum", "echo"}, {"coordinator", ""}};
  for (auto& [role, raw] : rows) {
    std::cout << "| " << role << (raw.empty() ? "" : " (raw: " + raw + ")") << " | ";
    if (raw.empty()) {
      std::cout << "- |";
    } else {
      std::vector<Usage> v;
      for (auto& x : rt) v.push_back(raw == "pinger" ? x.pinger : x.echo);
      std::cout << fmt(v) << " |";
    }
    for (std::size_t i = 0; i < cases.size(); ++i) {
      std::vector<Usage> v;
      for (auto& x : co[i]) v.push_back(x.per.at(role));
      std::cout << " " << fmt(v) << " |";
    }
    std::cout << "\n";
  }
  std::cout << "| all | ";
  {
    std::vector<Usage> v;
    for (auto& x : rt) v.push_back({x.pinger.wakeups + x.echo.wakeups, x.pinger.preempted + x.echo.preempted,
                                    x.pinger.cpu_us + x.echo.cpu_us});
    std::cout << fmt(v) << " |";
  }
  for (std::size_t i = 0; i < cases.size(); ++i) {
    std::vector<Usage> v;
    for (auto& x : co[i]) {
      Usage s;
      for (auto& [role, u] : x.per) s = {s.wakeups + u.wakeups, s.preempted + u.preempted, s.cpu_us + u.cpu_us};
      v.push_back(s);
    }
    std::cout << " " << fmt(v) << " |";
  }
  std::cout << "\n| coordinator messages published / accepted | - |";
  for (std::size_t i = 0; i < cases.size(); ++i) {
    std::vector<double> p, a;
    for (auto& x : co[i]) {
      p.push_back(x.count.at("coordinator published"));
      a.push_back(x.count.at("coordinator accepted"));
    }
    std::cout << " " << std::setprecision(2) << median(p) << " / " << median(a) << " |";
  }
  std::cout << "\n";
  return 0;
}
