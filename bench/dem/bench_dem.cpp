// bench_dem: time the DEM cycle on the 25,835-sphere periodic reference packing (bench/dem/data)
// (LAMMPS dump: 9 header lines, box bounds on lines 6–8, then "x y z radius", SI).
// Same physics as the LAMMPS reference: k_n = 2.55e5 N/m for every pair, k_s = k_n/2.4,
// (soft bond and parallel bond: every touching pair bonded, bond keys at their defaults),
// μ = tan 32°, ρ = 2650 kg/m³, periodic, 2,000 held steps with no neighbour rebuild.
// (Local damping α = 0.7, the WorldParams default; bench/dem/vs_lammps.py runs LAMMPS
// gran/hooke/history on the same packing and prints the ratios, docs/speed.md.)
//
// Usage: bench_dem [packing] [linear|softbond|pbond|moving] [threads] [steps] [period]
//        bench_dem [packing]            → runs the configurations in child processes: per model,
//                                          1 thread, and 2 threads with the default OpenMP wait
//                                          policy and with OMP_WAIT_POLICY=PASSIVE (labelled)
//        bench_dem --info [packing] [linear|softbond|pbond]
//                                        → set-up only (load, sort, bond, 20 warm-up steps): one
//                                          "info key=value ..." line (dt, skin, list size, active
//                                          contacts, record sizes, bytes per contact of the pass)
//        bench_dem --hw [ws_bytes]       → hardware figures of this core: clock (dependent-add
//                                          chain), STREAM-like triad bandwidth at ws_bytes (default
//                                          16 MiB: the pass's working set) and at 384 MiB (DRAM),
//                                          vector throughput of ×/+, ÷ and √ at the kernel's ISA
// moving: a penetration-like run of the linear model: the periodic cell is strained in plane
// strain (ε̇_x = +ε̇, ε̇_y = −ε̇, volume kept to first order; the balls follow affinely and rearrange)
// at the rate that moves the cell edge by skin/3 in `period` steps (default 30), so the neighbour
// list is rebuilt every few tens of steps. It prints (stderr) "moving key=value ..." with the
// rebuild count and the share of the step spent in the neighbour check and rebuilds (target
// ≤ 15 %, issue 16 item 3).
// BENCH_DEM_KERNEL=auto|scalar|baseline|avx2|avx512 selects the ball–ball pass implementation
// (World::set_pair_kernel; default auto = vectorised with the best instruction set).
// BENCH_DEM_AB=A,B (kernel names as above) alternates the pass between kernels A and B in blocks
// of BENCH_DEM_AB_BLOCK steps (default 10; the first BENCH_DEM_AB_SKIP of each, default 1, left
// out) and prints (stderr) "ab ... ratio_a_over_b=... se=..." (A's pair-phase time over B's,
// paired by neighbouring blocks; see run_ab). Every kernel gives the same bits, so the run's hash
// is a plain run's. A name ending in "+nosteal" (e.g. avx512+nosteal) runs that side's threaded
// pass without work stealing; BENCH_DEM_STEAL=0 does so for the whole run.
// BENCH_DEM_HASH=1 also prints (stderr) an FNV-1a hash of x, v, ω after the run and the
// number of ball–ball pairs in the list: two builds compare bit for bit on the same input.
// BENCH_DEM_DUMP=file writes x, v, ω after the run as raw doubles [n,9] (row order of the
// world): two builds that differ by rounding are compared with bench/dem/compare_dumps.py.
// BENCH_DEM_PHASES=1 prints (stderr) World::phase_times() of the timed window, as a sentence
// and as one "phases_kv key=value ..." line (seconds; list size, active contacts, dt), and the
// threaded pass's blocks taken by another thread ("steal on=... blocks_stolen=... blocks=...").
// Output: one CSV line per configuration:
//   model,threads,steps,wall_s,cpu_s,particle_steps_per_s_wall,particle_steps_per_s_per_core_cpu,rebuilds_in_window,contacts,peak_rss_mib,pair_kernel,omp_wait_policy,kernel_isa
// (kernel_isa: the instruction set the ball–ball pass ran with: scalar, baseline, avx2 or avx512.)
#include <sys/resource.h>
#include <time.h>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iostream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "demfdm/dem/measure.hpp"
#include "demfdm/dem/pair_block.hpp"
#include "demfdm/dem/world.hpp"
#include "ab_blocks.hpp"
#include "packing.hpp"

using namespace demfdm::dem;

namespace {
PairKernel kernel_named(const std::string& name, const char* var) {
  if (name == "auto") return PairKernel::kAuto;
  if (name == "scalar") return PairKernel::kScalar;
  if (name == "baseline") return PairKernel::kBlockBaseline;
  if (name == "avx2") return PairKernel::kBlockAvx2;
  if (name == "avx512") return PairKernel::kBlockAvx512;
  throw std::runtime_error(std::string(var) + ": a kernel must be auto, scalar, baseline, avx2 or avx512, found '" +
                           name + "'");
}

PairKernel kernel_from_env(std::string& name) {
  const char* k = std::getenv("BENCH_DEM_KERNEL");
  name = k ? k : "auto";
  return kernel_named(name, "BENCH_DEM_KERNEL");
}

// BENCH_DEM_AB="A,B" (kernel names): the timed steps alternate the ball-ball pass between kernels
// A and B in blocks of BENCH_DEM_AB_BLOCK steps (default 10), in the order A B B A A B B A ..., so
// that a drift of the host's speed favours neither. Each pair of neighbouring blocks (A B or B A)
// gives one ratio of A's pair-phase time to B's; the first BENCH_DEM_AB_SKIP
// steps of every block (default 1) are left out (the switch). Neighbouring blocks share the host's
// load, so on a busy host the ratio holds to 1-3 % where separate runs scatter by 10-20 %
// (docs/speed.md, session 35). A candidate pass is compared with the current one by building it
// as one of the kernels.
// A name may end in "+nosteal": that side runs the threaded pass without work stealing
// (World::set_pair_stealing; the same bits).
struct AbSpec {
  std::string a, b;
  PairKernel ka = PairKernel::kAuto, kb = PairKernel::kAuto;
  bool steal_a = true, steal_b = true;
  int block = 10, skip = 1;
};

int env_int(const char* var, int dflt, int lo, int hi) {
  const char* v = std::getenv(var);
  if (!v) return dflt;
  char* end = nullptr;
  const long x = std::strtol(v, &end, 10);
  if (end == v || *end != '\0' || x < lo || x > hi)
    throw std::runtime_error(std::string(var) + ": expected an integer in [" + std::to_string(lo) + ", " +
                             std::to_string(hi) + "], found '" + v + "'");
  return static_cast<int>(x);
}

std::optional<AbSpec> ab_from_env(int steps) {
  const char* v = std::getenv("BENCH_DEM_AB");
  if (!v) return std::nullopt;
  AbSpec ab;
  const std::string s = v;
  const auto comma = s.find(',');
  if (comma == std::string::npos)
    throw std::runtime_error("BENCH_DEM_AB: expected two kernel names as 'A,B', found '" + s + "'");
  ab.a = s.substr(0, comma);
  ab.b = s.substr(comma + 1);
  auto strip = [](const std::string& n, bool& steal) {
    const std::string tag = "+nosteal";
    steal = !(n.size() > tag.size() && n.compare(n.size() - tag.size(), tag.size(), tag) == 0);
    return steal ? n : n.substr(0, n.size() - tag.size());
  };
  ab.ka = kernel_named(strip(ab.a, ab.steal_a), "BENCH_DEM_AB");
  ab.kb = kernel_named(strip(ab.b, ab.steal_b), "BENCH_DEM_AB");
  ab.block = env_int("BENCH_DEM_AB_BLOCK", 10, 2, 100000);
  ab.skip = env_int("BENCH_DEM_AB_SKIP", 1, 0, ab.block - 1);
  if (steps < 4 * ab.block)
    throw std::runtime_error("BENCH_DEM_AB: " + std::to_string(steps) + " steps hold fewer than two pairs of " +
                             std::to_string(ab.block) + "-step blocks; give at least " +
                             std::to_string(4 * ab.block) + " steps");
  return ab;
}

// The timed steps of an A/B run; prints the "ab ..." line (stderr).
void run_ab(World& w, const AbSpec& ab, int steps, PairKernel restore, bool steal) {
  std::vector<double> t(static_cast<std::size_t>(steps));
  for (int k = 0; k < steps; ++k) {
    if (k % ab.block == 0) {
      const bool is_a = demfdm::bench::ab_block_is_a(k / ab.block);
      w.set_pair_kernel(is_a ? ab.ka : ab.kb);
      w.set_pair_stealing(is_a ? ab.steal_a : ab.steal_b);
    }
    const double p0 = w.phase_times().pair;
    w.step(1);
    t[static_cast<std::size_t>(k)] = w.phase_times().pair - p0;
  }
  w.set_pair_kernel(restore);
  w.set_pair_stealing(steal);
  std::vector<double> block;  // each complete block's time, its first `skip` steps left out
  for (int blk = 0; (blk + 1) * ab.block <= steps; ++blk) {
    double s = 0.0;
    for (int j = ab.skip; j < ab.block; ++j) s += t[static_cast<std::size_t>(blk * ab.block + j)];
    block.push_back(s);
  }
  const demfdm::bench::AbRatios r = demfdm::bench::ab_ratios(block);
  const double per = double(ab.block - ab.skip) * double(r.pairs);
  std::fprintf(stderr, "ab kernel_a=%s kernel_b=%s block=%d skip=%d pairs=%zu ratio_a_over_b=%.4f se=%.4f a_ms=%.4f "
               "b_ms=%.4f\n",
               ab.a.c_str(), ab.b.c_str(), ab.block, ab.skip, r.pairs, r.mean, r.se, 1e3 * r.a / per, 1e3 * r.b / per);
}

using demfdm::simd::isa_name;

// The instruction set the ball–ball pass runs with for a kernel choice (PairSet::pass_law: the
// block kernels for the linear and soft-bond models with the default rescale and unloading).
const char* kernel_isa(PairKernel k) {
  switch (k) {
    case PairKernel::kScalar: return "scalar";
    case PairKernel::kBlockBaseline: return "baseline";
    case PairKernel::kBlockAvx2: return "avx2";
    case PairKernel::kBlockAvx512: return "avx512";
    case PairKernel::kAuto: return isa_name(pairblock::best_isa());
  }
  return "?";
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

double thread_cpu_s() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}

// The world of the benchmark: the packing, the model ("moving" runs the linear model), rows
// sorted along the Morton curve, soft bond and parallel bond: every touching pair bonded;
// 20 warm-up steps.
std::unique_ptr<World> make_world(const Packing& pk, const std::string& model, int threads, std::string& kname,
                                  PairKernel& kernel) {
  if (model != "linear" && model != "softbond" && model != "pbond" && model != "moving")
    throw std::runtime_error("model must be linear, softbond, pbond or moving, found '" + model + "'");
  WorldParams p;
  p.density = 2650.0;
  p.threads = threads;
  p.periodic.enabled = true;
  p.periodic.origin = pk.lo;
  p.periodic.length = pk.hi - pk.lo;
  p.ball_ball.linear.kn_fixed = 2.55e5;
  p.ball_ball.linear.kratio = 2.4;
  p.ball_ball.linear.fric = 0.6248693519093275;
  if (model == "moving" || !law_from_name(model, p.ball_ball.model)) p.ball_ball.model = ContactModel::kLinear;
  p.skin = 0.1 * 2.0 * 0.058e-3;  // 0.1 d50 (the second LAMMPS anchor uses the same)
  auto w = std::make_unique<World>(p);
  kernel = kernel_from_env(kname);
  w->set_pair_kernel(kernel);
  for (std::size_t i = 0; i < pk.x.size(); ++i) w->add_ball(pk.x[i], pk.r[i]);
  w->reorder_spatially();  // cache locality: the dump order is random in space
  w->prepare();
  if (law_has_bond(p.ball_ball.model)) w->bond_ball_ball(-1.0, 0.0);  // bond every touching pair
  w->step(20);  // warm-up (first-touch of all arrays)
  return w;
}

// Bytes per step that the linear ball–ball pass moves between the core and the level of the
// memory hierarchy that holds its working set, under the assumptions printed with it:
// per list entry the indices a, b and the image shift (read) and the ContactHist record (read,
// and written back since the flags and the force are stored); per ball once per step (the B rows
// of a spatially sorted list hit the cache): x, v, ω, R (read) and f, t (zeroed, then accumulated:
// read for ownership and written back).
struct Traffic {
  double per_entry, per_ball, per_step;
};
Traffic linear_traffic(std::size_t entries, std::size_t balls) {
  const double idx = sizeof(std::uint32_t) * 2 + sizeof(std::array<std::int8_t, 4>);
  const double entry = idx + 2.0 * sizeof(ContactHist);
  const double ball = 3 * sizeof(Vec3) + sizeof(double) + 2 * 2 * sizeof(Vec3);
  return {entry, ball, entry * double(entries) + ball * double(balls)};
}

// Working set of a step: every per-ball array of Particles and every per-contact array.
double working_set_bytes(const World& w) {
  const auto& pc = w.pair_contacts();
  const double ball = 8 * sizeof(Vec3) + 3 * sizeof(double) + sizeof(std::uint64_t) + sizeof(std::uint8_t);
  const double entry = 2 * sizeof(std::uint32_t) + sizeof(std::array<std::int8_t, 4>) + sizeof(ContactHist) +
                       (pc.bond.empty() ? 0.0 : double(sizeof(BondHist)));
  return ball * double(w.num_balls()) + entry * double(pc.size());
}

// Operations of the linear pass per live contact, counted from PairSet::pass_law (stage 1:
// branch vector, ‖d‖², idle test; stage 3: the four ball sums) and the linear lane loop of
// dem_node/core/src/pair_block_body.inc (lane_kin 42, rotate_lane 72, linear law 39, lane_out 15);
// + − × only (no compares or selects), and per idle list entry stage 1 alone. Recount when
// those files change.
constexpr int kFlopsLive = 191, kSqrtLive = 2, kDivLive = 4, kFlopsIdle = 11;

int info(const std::string& file, const std::string& model) {
  const Packing pk = load(file);
  std::string kname;
  PairKernel kernel;
  auto w = make_world(pk, model, 1, kname, kernel);
  const auto z = coordination(*w);
  const auto& pc = w->pair_contacts();
  const Traffic t = linear_traffic(pc.size(), w->num_balls());
  std::printf("info model=%s balls=%zu dt=%.6e skin=%.6e list=%zu active=%zu contact_hist_bytes=%zu "
              "bond_hist_bytes=%zu working_set_bytes=%.0f bytes_per_entry=%.0f bytes_per_ball=%.0f "
              "bytes_per_step=%.0f flops_live=%d sqrt_live=%d div_live=%d flops_idle=%d pair_kernel=%s kernel_isa=%s "
              "cell=%.6e,%.6e,%.6e\n",
              model.c_str(), w->num_balls(), w->dt(), w->skin(), pc.size(), z.active, sizeof(ContactHist),
              sizeof(BondHist), working_set_bytes(*w), t.per_entry, t.per_ball, t.per_step, kFlopsLive, kSqrtLive,
              kDivLive, kFlopsIdle, kname.c_str(), kernel_isa(kernel), w->cell_length().x, w->cell_length().y,
              w->cell_length().z);
  return 0;
}

// ---- hardware figures (--hw) -------------------------------------------------------------

// Clock: a chain of dependent integer adds retires one add per cycle on every x86-64 core, so
// adds per CPU second of this thread is the clock the core ran at while busy. Best of 5.
double measure_clock_ghz() {
#if defined(__x86_64__)
  double best = 0.0;
  for (int rep = 0; rep < 5; ++rep) {
    const long iters = 20000000;  // × 20 adds
    std::uint64_t x = 0;
    const double t0 = thread_cpu_s();
    for (long i = 0; i < iters; ++i) {
      asm volatile(
          "add %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\t"
          "add %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\t"
          "add %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\t"
          "add %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\tadd %1, %0\n\t"
          : "+r"(x)
          : "r"(static_cast<std::uint64_t>(i)));
    }
    const double t = thread_cpu_s() - t0;
    if (t > 0) best = std::max(best, 20.0 * double(iters) / t * 1e-9);
    if (x == 42) std::printf(" ");  // keep x alive
  }
  return best;
#else
  return 0.0;
#endif
}

// STREAM-like triad a = b + s c over three arrays of `bytes` in total; bandwidth counted as
// STREAM does (24 B per element: two reads and one write). Best of `reps`.
double measure_triad_gbs(double bytes, int reps) {
  const std::size_t n = std::max<std::size_t>(1024, static_cast<std::size_t>(bytes / 24.0));
  std::vector<double> a(n, 1.0), b(n, 2.0), c(n, 0.5);
  const double s = 3.0;
  double best = 0.0;
  for (int rep = 0; rep < reps; ++rep) {
    const auto t0 = std::chrono::steady_clock::now();
    double* __restrict__ pa = a.data();
    const double* __restrict__ pb = b.data();
    const double* __restrict__ pc = c.data();
    for (std::size_t i = 0; i < n; ++i) pa[i] = pb[i] + s * pc[i];
    const double t = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    asm volatile("" : : "r"(pa) : "memory");
    if (t > 0) best = std::max(best, 24.0 * double(n) / t * 1e-9);
  }
  if (a[n / 2] != 2.0 + s * 0.5) std::printf(" ");
  return best;
}

// Vector throughput of this core at an instruction set, in double-lane operations per ns:
// independent chains (more than latency × throughput) of × and + (separate, as the build
// forbids FMA contraction), of ÷, and of √. Best of 3.
struct Throughput {
  double addmul = 0, div = 0, sqrt = 0;  // lane operations per ns
  int lanes = 0;
};

#if defined(__x86_64__)
// The loops: k independent chains each (k × latency covers the throughput of every core of
// the last ten years); each returns a value that depends on every chain. Functions, not
// lambdas, so that the target attribute applies to the loop.
#define DEMFDM_TP_LOOPS(SUF, T, SET1, MUL, ADD, DIV, SQRT, FIRST)                          \
  double addmul_##SUF(long it) {                                                                 \
    const T m = SET1(1.0000000001), c = SET1(1e-9);                                              \
    T a[6], b[6];                                                                                \
    for (int k = 0; k < 6; ++k) { a[k] = SET1(1.0 + 0.01 * k); b[k] = SET1(0.01 * k); }           \
    for (long i = 0; i < it; ++i) {                                                              \
      for (int k = 0; k < 6; ++k) a[k] = MUL(a[k], m);                                           \
      for (int k = 0; k < 6; ++k) b[k] = ADD(b[k], c);                                           \
    }                                                                                            \
    T s = SET1(0.0);                                                                             \
    for (int k = 0; k < 6; ++k) s = ADD(s, ADD(a[k], b[k]));                                     \
    return FIRST(s);                                                                             \
  }                                                                                              \
  double div_##SUF(long it) {                                                                    \
    const T c = SET1(1.3);                                                                       \
    T x[8];                                                                                      \
    for (int k = 0; k < 8; ++k) x[k] = SET1(0.71 + 0.01 * k);                                    \
    for (long i = 0; i < it; ++i)                                                                \
      for (int k = 0; k < 8; ++k) x[k] = DIV(c, x[k]);                                           \
    T s = SET1(0.0);                                                                             \
    for (int k = 0; k < 8; ++k) s = ADD(s, x[k]);                                                \
    return FIRST(s);                                                                             \
  }                                                                                              \
  double sqrt_##SUF(long it) {                                                                   \
    const T c = SET1(1.7);                                                                       \
    T x[8];                                                                                      \
    for (int k = 0; k < 8; ++k) x[k] = SET1(0.71 + 0.01 * k);                                    \
    for (long i = 0; i < it; ++i)                                                                \
      for (int k = 0; k < 8; ++k) x[k] = SQRT(ADD(x[k], c));                                     \
    T s = SET1(0.0);                                                                             \
    for (int k = 0; k < 8; ++k) s = ADD(s, x[k]);                                                \
    return FIRST(s);                                                                             \
  }

DEMFDM_TP_LOOPS(sse2, __m128d, _mm_set1_pd, _mm_mul_pd, _mm_add_pd, _mm_div_pd, _mm_sqrt_pd, _mm_cvtsd_f64)
#pragma GCC push_options
#pragma GCC target("avx2")
DEMFDM_TP_LOOPS(avx2, __m256d, _mm256_set1_pd, _mm256_mul_pd, _mm256_add_pd, _mm256_div_pd, _mm256_sqrt_pd,
                _mm256_cvtsd_f64)
#pragma GCC pop_options
#pragma GCC push_options
#pragma GCC target("avx512f")
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // GCC 12's _mm512_undefined_pd inside _mm512_sqrt_pd
DEMFDM_TP_LOOPS(avx512, __m512d, _mm512_set1_pd, _mm512_mul_pd, _mm512_add_pd, _mm512_div_pd, _mm512_sqrt_pd,
                _mm512_cvtsd_f64)
#pragma GCC diagnostic pop
#pragma GCC pop_options
#undef DEMFDM_TP_LOOPS

volatile double g_sink;

double best_rate(double (*f)(long), long it, double lane_ops) {
  double best = 0.0;
  for (int rep = 0; rep < 3; ++rep) {
    const double t0 = thread_cpu_s();
    g_sink = f(it);
    const double t = thread_cpu_s() - t0;
    if (t > 0) best = std::max(best, lane_ops / t * 1e-9);
  }
  return best;
}

Throughput throughput(pairblock::Isa isa) {
  Throughput r;
  const long it = 20000000, itd = 2000000;
  double (*am)(long) = addmul_sse2, (*dv)(long) = div_sse2, (*sq)(long) = sqrt_sse2;
  r.lanes = 2;
  if (isa == pairblock::Isa::kAvx2) { am = addmul_avx2; dv = div_avx2; sq = sqrt_avx2; r.lanes = 4; }
  if (isa == pairblock::Isa::kAvx512) { am = addmul_avx512; dv = div_avx512; sq = sqrt_avx512; r.lanes = 8; }
  r.addmul = best_rate(am, it, 12.0 * r.lanes * double(it));
  r.div = best_rate(dv, itd, 8.0 * r.lanes * double(itd));
  r.sqrt = best_rate(sq, itd, 8.0 * r.lanes * double(itd));
  return r;
}
#endif

int hw(double ws_bytes) {
  const double ghz = measure_clock_ghz();
  // The pass's working set (L3-resident on the machines of docs/speed.md) and 384 MiB (DRAM).
  const double bw_ws = measure_triad_gbs(ws_bytes, 20);
  const double dram_bytes = 384.0 * 1024 * 1024;
  const double bw_dram = measure_triad_gbs(dram_bytes, 5);
  const char* isa = isa_name(pairblock::best_isa());
  Throughput tp;
#if defined(__x86_64__)
  tp = throughput(pairblock::best_isa());
#endif
  std::printf("hw clock_ghz=%.3f clock_source=dependent-add-chain triad_ws_bytes=%.0f triad_ws_gbs=%.2f "
              "triad_dram_bytes=%.0f triad_dram_gbs=%.2f isa=%s lanes=%d addmul_per_ns=%.2f div_per_ns=%.3f "
              "sqrt_per_ns=%.3f\n",
              ghz, ws_bytes, bw_ws, dram_bytes, bw_dram, isa, tp.lanes, tp.addmul, tp.div, tp.sqrt);
  return 0;
}

// ---- timed run --------------------------------------------------------------------------

int run(const std::string& file, const std::string& model, int threads, int steps, int period) {
  if (steps <= 0) throw std::runtime_error("steps must be > 0");
  const std::optional<AbSpec> ab = ab_from_env(steps);  // (refused before the packing is loaded)
  const Packing pk = load(file);
  std::string kname;
  PairKernel kernel;
  auto wp = make_world(pk, model, threads, kname, kernel);
  World& w = *wp;
  // BENCH_DEM_STEAL=0: the threaded pass without work stealing (World::set_pair_stealing).
  const bool steal = env_int("BENCH_DEM_STEAL", 1, 0, 1) == 1;
  w.set_pair_stealing(steal);
  double edot = 0.0;
  if (model == "moving") {
    // Plane strain at the rate that moves the cell edge by skin/3 in `period` steps: the
    // rebuild test (2 max displacement + cell length change > skin) then trips every ~period
    // steps from the affine motion alone; the balls' own motion can only make it sooner.
    if (period <= 0) throw std::runtime_error("period must be > 0");
    const Vec3 L = w.cell_length();
    const double lmax = std::max({L.x, L.y, L.z});
    edot = w.skin() / (3.0 * lmax * double(period) * w.dt());
    w.set_strain_rate({edot, -edot, 0.0});
  }
  w.reset_phase_times();
  const auto reb0 = w.rebuild_count();
  const double dt0 = w.dt();
  timespec c0{}, c1{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c0);
  const auto t0 = std::chrono::steady_clock::now();
  if (ab) {
    run_ab(w, *ab, steps, kernel, steal);
  } else {
    w.step(steps);
  }
  const auto t1 = std::chrono::steady_clock::now();
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &c1);
  const double cpu = double(c1.tv_sec - c0.tv_sec) + 1e-9 * double(c1.tv_nsec - c0.tv_nsec);
  const double sec = std::chrono::duration<double>(t1 - t0).count();
  const auto z = coordination(w);
  const long long rebuilds = static_cast<long long>(w.rebuild_count() - reb0);
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
  const PhaseTimes& t = w.phase_times();
  if (std::getenv("BENCH_DEM_PHASES")) {
    std::fprintf(stderr, "phases %s threads %d (%lld steps, wall %.4f s): rebuild %.4f pair %.4f gather %.4f "
                 "motion %.4f effects %.4f, sum %.4f s\n",
                 t.pair_model, threads, static_cast<long long>(t.steps), sec, t.rebuild, t.pair, t.gather, t.motion,
                 t.effects_total, t.total());
    std::fprintf(stderr, "phases_kv model=%s threads=%d steps=%lld wall=%.6f cpu=%.6f rebuild=%.6f pair=%.6f "
                 "plane=%.6f facet=%.6f footing=%.6f gather=%.6f motion=%.6f effects=%.6f sum=%.6f rebuilds=%lld "
                 "list=%zu active=%zu balls=%zu dt=%.6e kernel_isa=%s\n",
                 model.c_str(), threads, static_cast<long long>(t.steps), sec, cpu, t.rebuild, t.pair, t.plane,
                 t.facet, t.footing, t.gather, t.motion, t.effects_total, t.total(), rebuilds,
                 w.pair_contacts().size(), z.active, w.num_balls(), dt0, kernel_isa(kernel));
    const auto st = w.pair_blocks_stolen();
    std::fprintf(stderr, "steal on=%d blocks_stolen=%llu blocks=%llu\n", steal ? 1 : 0,
                 static_cast<unsigned long long>(st.first), static_cast<unsigned long long>(st.second));
  }
  if (model == "moving") {
    const double share = t.total() > 0 ? t.rebuild / t.total() : 0.0;
    const Vec3 cs = w.cell_strain_since_reset();
    std::fprintf(stderr, "moving steps=%d period=%d strain_rate=%.6e strain_x=%.5f strain_y=%.5f rebuilds=%lld "
                 "steps_per_rebuild=%.1f rebuild_s=%.6f step_sum_s=%.6f rebuild_share=%.4f ms_per_rebuild=%.3f "
                 "target_share=0.15 verdict=%s\n",
                 steps, period, edot, cs.x, cs.y, rebuilds, rebuilds > 0 ? double(steps) / double(rebuilds) : 0.0,
                 t.rebuild, t.total(), share, rebuilds > 0 ? 1e3 * t.rebuild / double(rebuilds) : 0.0,
                 share <= 0.15 ? "met" : "NOT_met");
  }
  std::printf("%s,%d,%d,%.4f,%.4f,%.4e,%.4e,%lld,%zu,%.1f,%s,%s,%s\n", model.c_str(), threads, steps, sec, cpu,
              double(w.num_balls()) * steps / sec, double(w.num_balls()) * steps / cpu, rebuilds, z.active,
              peak_rss_mib(), kname.c_str(), wait_policy().c_str(), kernel_isa(kernel));
  return 0;
}
}  // namespace

int main(int argc, char** argv) {
  try {
    if (argc > 1 && std::string(argv[1]) == "--info")
      return info(argc > 2 ? argv[2] : DEMFDM_BENCH_PACKING, argc > 3 ? argv[3] : "linear");
    if (argc > 1 && std::string(argv[1]) == "--hw")
      return hw(argc > 2 ? std::atof(argv[2]) : 16.0 * 1024 * 1024);
    const std::string file = argc > 1 ? argv[1] : DEMFDM_BENCH_PACKING;
    if (argc > 2)
      return run(file, argv[2], argc > 3 ? std::atoi(argv[3]) : 1, argc > 4 ? std::atoi(argv[4]) : 2000,
                 argc > 5 ? std::atoi(argv[5]) : 30);
    // The 2-thread rows run twice: with the default OpenMP wait policy (threads spin briefly
    // at the barrier: fastest on a quiet machine) and with OMP_WAIT_POLICY=PASSIVE (on a
    // shared machine spinning threads steal the core that the other thread needs). The
    // children read the policy at start-up.
    std::printf("model,threads,steps,wall_s,cpu_s,particle_steps_per_s_wall,particle_steps_per_s_per_core_cpu,"
                "rebuilds_in_window,contacts,peak_rss_mib,pair_kernel,omp_wait_policy,kernel_isa\n");
    std::fflush(stdout);
    struct Config {
      int threads;
      const char* policy;  // nullptr: default (unset)
    };
    for (const char* m : {"linear", "softbond", "pbond"})
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
