// bench_dem: time the DEM cycle on the 25,835-sphere periodic reference packing (bench/dem/data)
// (LAMMPS dump: 9 header lines, box bounds on lines 6–8, then "x y z radius", SI).
// Same physics as the LAMMPS reference: k_n = 2.55e5 N/m for every pair, k_s = k_n/2.4,
// μ = tan 32°, ρ = 2650 kg/m³, periodic, 2,000 held steps with no neighbour rebuild.
//
// Usage: bench_dem [packing] [linear|softbond] [threads] [steps]
//        bench_dem [packing]            → runs the configurations in child processes: per model,
//                                          1 thread, and 2 threads with the default OpenMP wait
//                                          policy and with OMP_WAIT_POLICY=PASSIVE (labelled)
// BENCH_DEM_KERNEL=auto|scalar|baseline|avx2|avx512 selects the ball–ball pass implementation
// (World::set_pair_kernel; default auto = vectorised with the best instruction set).
// BENCH_DEM_HASH=1 also prints (stderr) an FNV-1a hash of x, v, ω after the run and the
// number of ball–ball pairs in the list: two builds compare bit for bit on the same input.
// BENCH_DEM_DUMP=file writes x, v, ω after the run as raw doubles [n,9] (row order of the
// world): two builds that differ by rounding are compared with bench/dem/compare_dumps.py.
// BENCH_DEM_PHASES=1 prints (stderr) World::phase_times() of the timed window.
// Output: one CSV line per configuration:
//   model,threads,steps,wall_s,cpu_s,particle_steps_per_s_wall,particle_steps_per_s_per_core_cpu,rebuilds_in_window,contacts,peak_rss_mib,pair_kernel,omp_wait_policy
#include <sys/resource.h>
#include <time.h>

#include <cctype>
#include <chrono>
#include <cstdio>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>

#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {
struct Packing {
  Vec3 lo, hi;
  std::vector<Vec3> x;
  std::vector<double> r;
};

Packing load(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open packing file '" + path + "'");
  Packing p;
  std::string line;
  for (int l = 1; l <= 9; ++l) {
    std::getline(in, line);
    if (l >= 6 && l <= 8) {
      std::istringstream s(line);
      s >> p.lo[l - 6] >> p.hi[l - 6];
    }
  }
  double x, y, z, r;
  while (in >> x >> y >> z >> r) {
    p.x.push_back({x, y, z});
    p.r.push_back(r);
  }
  return p;
}

PairKernel kernel_from_env(std::string& name) {
  const char* k = std::getenv("BENCH_DEM_KERNEL");
  name = k ? k : "auto";
  if (name == "auto") return PairKernel::kAuto;
  if (name == "scalar") return PairKernel::kScalar;
  if (name == "baseline") return PairKernel::kBlockBaseline;
  if (name == "avx2") return PairKernel::kBlockAvx2;
  if (name == "avx512") return PairKernel::kBlockAvx512;
  throw std::runtime_error("BENCH_DEM_KERNEL must be auto, scalar, baseline, avx2 or avx512, found '" + name + "'");
}

std::string wait_policy() {
  const char* w = std::getenv("OMP_WAIT_POLICY");
  if (!w) return "default";
  std::string s(w);
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

double peak_rss_mib() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;  // ru_maxrss is in KiB on Linux
}

int run(const std::string& file, const std::string& model, int threads, int steps) {
  const Packing pk = load(file);
  WorldParams p;
  p.density = 2650.0;
  p.threads = threads;
  p.periodic.enabled = true;
  p.periodic.origin = pk.lo;
  p.periodic.length = pk.hi - pk.lo;
  p.ball_ball.linear.kn_fixed = 2.55e5;
  p.ball_ball.linear.kratio = 2.4;
  p.ball_ball.linear.fric = 0.6248693519093275;
  p.ball_ball.model = model == "softbond" ? ContactModel::kSoftBond : ContactModel::kLinear;
  double rsum = 0;
  for (double r : pk.r) rsum += r;
  p.skin = 0.1 * 2.0 * 0.058e-3;  // 0.1 d50 (the second LAMMPS anchor uses the same)
  (void)rsum;
  World w(p);
  std::string kname;
  w.set_pair_kernel(kernel_from_env(kname));
  for (std::size_t i = 0; i < pk.x.size(); ++i) w.add_ball(pk.x[i], pk.r[i]);
  w.reorder_spatially();  // cache locality: the dump order is random in space
  w.prepare();
  if (model == "softbond") w.bond_ball_ball(-1.0, 0.0);  // bond every touching pair
  w.step(20);  // warm-up (first-touch of all arrays)
  w.reset_phase_times();
  const auto reb0 = w.rebuild_count();
  timespec c0{}, c1{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
  const auto t0 = std::chrono::steady_clock::now();
  w.step(steps);
  const auto t1 = std::chrono::steady_clock::now();
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
  const double cpu = double(c1.tv_sec - c0.tv_sec) + 1e-9 * double(c1.tv_nsec - c0.tv_nsec);
  const double sec = std::chrono::duration<double>(t1 - t0).count();
  const auto z = coordination(w);
  if (std::getenv("BENCH_DEM_HASH")) {  // FNV-1a over x, v, ω: compare builds bit for bit
    std::uint64_t h = 1469598103934665603ULL;
    auto mix = [&](double d) {
      std::uint64_t u;
      std::memcpy(&u, &d, 8);
      for (int k = 0; k < 8; ++k) { h ^= (u >> (8 * k)) & 0xff; h *= 1099511628211ULL; }
    };
    const auto& pt = w.balls();
    for (std::size_t i = 0; i < w.num_balls(); ++i)
      for (int k = 0; k < 3; ++k) { mix(pt.x[i][k]); mix(pt.v[i][k]); mix(pt.w[i][k]); }
    std::fprintf(stderr, "hash %s threads %d steps %d: %016llx (pairs %zu)\n", model.c_str(), threads, steps,
                 static_cast<unsigned long long>(h), w.pair_contacts().size());
  }
  if (const char* dump = std::getenv("BENCH_DEM_DUMP")) {
    std::ofstream out(dump, std::ios::binary);
    const auto& pt = w.balls();
    for (std::size_t i = 0; i < w.num_balls(); ++i)
      for (const Vec3* a : {&pt.x[i], &pt.v[i], &pt.w[i]}) out.write(reinterpret_cast<const char*>(a), sizeof(Vec3));
    if (!out) throw std::runtime_error(std::string("cannot write '") + dump + "'");
  }
  if (std::getenv("BENCH_DEM_PHASES")) {
    const PhaseTimes& t = w.phase_times();
    std::fprintf(stderr, "phases %s threads %d (%lld steps, wall %.4f s): rebuild %.4f pair %.4f gather %.4f "
                 "motion %.4f effects %.4f, sum %.4f s\n",
                 t.pair_model, threads, static_cast<long long>(t.steps), sec, t.rebuild, t.pair, t.gather, t.motion,
                 t.effects_total, t.total());
  }
  std::printf("%s,%d,%d,%.4f,%.4f,%.4e,%.4e,%lld,%zu,%.1f,%s,%s\n", model.c_str(), threads, steps, sec, cpu,
              double(w.num_balls()) * steps / sec, double(w.num_balls()) * steps / cpu,
              static_cast<long long>(w.rebuild_count() - reb0), z.active, peak_rss_mib(), kname.c_str(),
              wait_policy().c_str());
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  const std::string file = argc > 1 ? argv[1] : DEMFDM_BENCH_PACKING;
  try {
    if (argc > 2) return run(file, argv[2], argc > 3 ? std::atoi(argv[3]) : 1, argc > 4 ? std::atoi(argv[4]) : 2000);
    // The 2-thread rows run twice: with the default OpenMP wait policy (threads spin briefly
    // at the barrier: fastest on a quiet machine) and with OMP_WAIT_POLICY=PASSIVE (on a
    // shared machine spinning threads steal the core that the other thread needs). The
    // children read the policy at start-up.
    std::printf("model,threads,steps,wall_s,cpu_s,particle_steps_per_s_wall,particle_steps_per_s_per_core_cpu,"
                "rebuilds_in_window,contacts,peak_rss_mib,pair_kernel,omp_wait_policy\n");
    std::fflush(stdout);
    struct Config {
      int threads;
      const char* policy;  // nullptr: default (unset)
    };
    for (const char* m : {"linear", "softbond"})
      for (const Config& c : {Config{1, nullptr}, Config{2, nullptr}, Config{2, "PASSIVE"}}) {
        if (c.policy) setenv("OMP_WAIT_POLICY", c.policy, 1);
        else unsetenv("OMP_WAIT_POLICY");
        const std::string cmd =
            std::string("\"") + argv[0] + "\" \"" + file + "\" " + m + " " + std::to_string(c.threads);
        if (std::system(cmd.c_str()) != 0) return 1;
      }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_dem: %s\n", e.what());
    return 1;
  }
  return 0;
}
