// bench_fdm: zone-steps per second of the FDM engine on 1 and 2 OpenMP threads, and peak
// memory (getrusage ru_maxrss). Cases (plain box, 50 g, geostatic stress with K0 = 0.2,
// dynamic mode):
//   elastic          linear elastic zones
//   mc-elastic       Mohr-Coulomb, c = 1 MPa: every tetrahedron stays inside the surface
//                    (cost of the yield check)
//   mc-yielding      Mohr-Coulomb, c = 10 kPa: most tetrahedra are on the surface (eigen-
//                    decomposition and return every step)
// The elastic case runs with the zone pass on vector lanes (ZoneKernel::kAuto, the instruction
// set named in the output) and zone by zone (elastic-scalar), one after the other for `rounds`
// rounds, and prints the ratio of the two per round.
// Usage: bench_fdm [zones_per_side=37] [steps=20] [rounds=1]   (37^3 = 50653 zones)
#include <omp.h>
#include <sys/resource.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>

#include "demfdm/fdm/model.hpp"
#include "demfdm/simd/isa.hpp"

using namespace demfdm::fdm;

namespace {

struct Case {
  const char* name;
  Constitutive law;
  double cohesion;
  ZoneKernel kernel = ZoneKernel::kAuto;
};

double cpu_seconds() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

double run(const Case& c, int n, int steps, int threads, std::size_t& zones, double& plastic_fraction,
           double& per_cpu_second) {
  omp_set_num_threads(threads);
  ModelParams p;
  p.mesh = MeshParams::plain_box(1.0, 1.0, 1.0, 1.0 / n);
  Material m;
  m.model = c.law;
  m.young = 1e8;
  m.poisson = 0.3;
  m.density = 2000.0;
  m.cohesion = c.cohesion;
  m.friction_deg = 30.0;
  p.materials = {MaterialGroup{m, std::nullopt}};
  p.mode = Mode::kDynamic;
  p.gravity_level = 50.0;
  Model model(p);
  model.set_zone_kernel(c.kernel);
  model.set_geostatic_stress({kNaN, 0.2});
  zones = model.num_zones();
  model.step(2);  // warm-up
  const double c0 = cpu_seconds();
  const auto t0 = std::chrono::steady_clock::now();
  model.step(steps);
  const auto t1 = std::chrono::steady_clock::now();
  per_cpu_second = static_cast<double>(model.num_zones()) * steps / (cpu_seconds() - c0);
  std::size_t plastic = 0;
  for (auto s : model.plastic_state()) plastic += (s & (kShearNow | kTensionNow)) ? 1 : 0;
  plastic_fraction = static_cast<double>(plastic) / static_cast<double>(zones);
  const double sec = std::chrono::duration<double>(t1 - t0).count();
  return static_cast<double>(zones) * steps / sec;
}

}  // namespace

int main(int argc, char** argv) {
  const int n = argc > 1 ? std::atoi(argv[1]) : 37;
  const int steps = argc > 2 ? std::atoi(argv[2]) : 20;
  const int rounds = argc > 3 ? std::atoi(argv[3]) : 1;
  const Case cases[] = {{"elastic", Constitutive::kElastic, 0.0},
                        {"mc-elastic", Constitutive::kMohrCoulomb, 1e6},
                        {"mc-yielding", Constitutive::kMohrCoulomb, 1e4}};
  const Case scalar{"elastic-scalar", Constitutive::kElastic, 0.0, ZoneKernel::kScalar};
  std::printf("zone kernel of the elastic case: %s lanes (elastic-scalar: zone by zone)\n",
              demfdm::simd::isa_name(demfdm::simd::best_isa()));
  for (int r = 0; r < rounds; ++r) {
    std::size_t zones = 0;
    double plastic = 0.0, per_cpu = 0.0;
    const double lanes = run(cases[0], n, steps, 1, zones, plastic, per_cpu);
    const double one = run(scalar, n, steps, 1, zones, plastic, per_cpu);
    std::printf("round %d, 1 thread: elastic %.3e, elastic-scalar %.3e zone-steps/s, lanes/scalar %.3f\n", r + 1, lanes,
                one, lanes / one);
  }
  // zone-steps/s: wall clock; per thread: divided by the thread count; per cpu-s: divided by
  // the CPU time the process used (user + system), which is what a thread costs when the
  // machine is shared and a thread does not get a whole core.
  std::printf("%-12s %7s %8s %6s %9s %14s %14s %14s\n", "model", "threads", "zones", "steps", "yielding",
              "zone-steps/s", "per thread", "per cpu-s");
  for (const Case& c : cases)
    for (int threads : {1, 2}) {
      std::size_t zones = 0;
      double plastic = 0.0, per_cpu = 0.0;
      const double rate = run(c, n, steps, threads, zones, plastic, per_cpu);
      std::printf("%-12s %7d %8zu %6d %8.0f%% %14.3e %14.3e %14.3e\n", c.name, threads, zones, steps, 100.0 * plastic,
                  rate, rate / threads, per_cpu);
    }
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  std::printf("peak memory (ru_maxrss): %.1f MiB\n", static_cast<double>(ru.ru_maxrss) / 1024.0);
  return 0;
}
