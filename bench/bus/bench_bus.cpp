// Per-step overhead of lockstep coupling over the bus, beside a raw LCM round trip measured in
// the same run on the same URL kind (udpm on loopback, private network namespace when root).
//
//   bench_bus [steps=4000] [round_trips=2000]
//
// The coupled run is the split chain (tests/chain) with 10 masses per side: its physics costs
// well under a microsecond per step, so the time per coupling step is the protocol's overhead
// (commands, interface data, reports) through three processes.
#include <lcm/lcm-cpp.hpp>

#include <algorithm>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <numeric>
#include <regex>
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
  return v[v.size() / 2];
}

// Raw round trip: one small message to an echo process (its own LCM instance, like the
// nodes) and back.
double raw_round_trip_us(const std::string& url, int n) {
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
  for (int i = 0; i < n + 100; ++i) {
    p.got = false;
    auto t0 = std::chrono::steady_clock::now();
    a.publish("PING", msg.data(), static_cast<unsigned>(msg.size()));
    while (!p.got) a.handleTimeout(100);  // the first PINGs may precede the echo's subscription
    double us = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count();
    if (i >= 100) rtt.push_back(us);  // warm-up excluded
  }
  ::kill(child, SIGKILL);
  waitpid(child, nullptr, 0);
  return median(rtt);
}

// Wall time per coupling step of the chain run, from the coordinator's summary.
double coupled_step_us(const std::string& bin, const std::string& scheme, int steps, int port, int per_grant = 1) {
  auto dir = fs::temp_directory_path() /
             ("demfdm-bench-bus-" + scheme + std::to_string(per_grant) + "-" + std::to_string(getpid()));
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
  auto st = wait_for(co, 600);
  wait_for(d, 5);
  wait_for(c, 5);
  if (!st || exit_code(*st) != 0) throw std::runtime_error("coupled run failed: " + read_file((dir / "out.txt").string()));
  auto text = read_file((dir / "summary.txt").string());
  std::smatch m;
  std::regex re("timed \\[cycle\\]: steps \\d+\\.\\.\\d+ \\((\\d+)\\), wall ([0-9.]+) s");
  if (!std::regex_search(text, m, re)) throw std::runtime_error("no timed stage in summary:\n" + text);
  return std::stod(m[2]) / std::stod(m[1]) * 1e6;
}
}  // namespace

int main(int argc, char** argv) {
  int steps = argc > 1 ? std::atoi(argv[1]) : 4000;
  int rts = argc > 2 ? std::atoi(argv[2]) : 2000;
  auto why = enter_private_network();
  if (!why.empty()) std::cerr << "note: " << why << "; using the host network as it is\n";
  std::string bin = DEMFDM_BIN_DIR;
  std::string url = "udpm://239.255.76.67:" + std::to_string(41000 + getpid() % 1000) + "?ttl=0&recv_buf_size=4194304";
  double rtt = raw_round_trip_us(url, rts);
  double serial = coupled_step_us(bin, "serial", steps, 42000 + getpid() % 1000);
  double parallel = coupled_step_us(bin, "parallel", steps, 43000 + getpid() % 1000);
  double serial16 = coupled_step_us(bin, "serial", steps, 44000 + getpid() % 1000, 16);
  double parallel16 = coupled_step_us(bin, "parallel", steps, 45000 + getpid() % 1000, 16);
  std::cout << std::fixed << std::setprecision(1);
  std::cout << "bench_bus: lockstep coupling overhead (3 processes, udpm loopback)\n";
  std::cout << "| measure | us per step | raw round trips |\n|---|---|---|\n";
  std::cout << "| raw LCM round trip between two processes (64 B, median of " << rts << ") | " << rtt << " | 1.00 |\n";
  std::cout << "| coupled step, serial scheme (mean of " << steps << ") | " << serial << " | " << std::setprecision(2)
            << serial / rtt << " |\n";
  std::cout << std::setprecision(1) << "| coupled step, parallel scheme (mean of " << steps << ") | " << parallel << " | "
            << std::setprecision(2) << parallel / rtt << " |\n";
  std::cout << std::setprecision(1) << "| coupled step, serial, 16 steps per grant | " << serial16 << " | "
            << std::setprecision(2) << serial16 / rtt << " |\n";
  std::cout << std::setprecision(1) << "| coupled step, parallel, 16 steps per grant | " << parallel16 << " | "
            << std::setprecision(2) << parallel16 / rtt << " |\n";
  std::cout << "target: at most 2 raw round trips per coupled step\n";
  return 0;
}
