// A coupled DEM step's own work on a real state (issue 16 item 2): the engine's step and the
// measurements the DEM node reports after every step (docs/speed.md, "The step's
// measurements"): the contact scan (critical step and mean contact force), the unbalanced and
// skeleton ratios, the kinetic energy and the guard's finite-value test.
//
//   bench_measure CHECKPOINT_DIR [steps=300] [rounds=1]
//
// CHECKPOINT_DIR is a run's checkpoint folder (its dem.world.state and manifest.txt), e.g. the
// default scene's gravity-end checkpoint (runs/<run>/checkpoints/gravity-<step>-end). The World
// keeps the thread count it was saved with (OMP_NUM_THREADS does not change it). Each round
// starts from the loaded state; one line per round, times in ms per step.
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/guard.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;
using Clock = std::chrono::steady_clock;

namespace {

std::uint64_t manifest_scene_hash(const std::filesystem::path& dir) {
  std::ifstream in(dir / "manifest.txt");
  std::string key, value;
  while (in >> key) {
    if (key == "scene_hash" && in >> value) return std::stoull(value, nullptr, 16);
    std::getline(in, value);
  }
  throw std::runtime_error((dir / "manifest.txt").string() + ": no scene_hash line");
}

double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 2) {
    std::fprintf(stderr, "usage: bench_measure CHECKPOINT_DIR [steps=300] [rounds=1]\n");
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  const int steps = argc > 2 ? std::stoi(argv[2]) : 300;
  const int rounds = argc > 3 ? std::stoi(argv[3]) : 1;
  const std::uint64_t hash = manifest_scene_hash(dir);
  for (int r = 0; r < rounds; ++r) {
    World w{WorldParams{}};
    load_state_file(w, dir / "dem.world.state", hash);
    double t_step = 0, t_scan = 0, t_ratio = 0, t_skel = 0, t_ke = 0, t_guard = 0, sink = 0;
    for (int s = 0; s < steps; ++s) {
      const auto t0 = Clock::now();
      w.step();
      const auto t1 = Clock::now();
      const World::ContactScan sc = static_cast<const World&>(w).contact_scan(true, true);
      const auto t2 = Clock::now();
      sink += w.unbalanced_ratio(sc.fc);
      const auto t3 = Clock::now();
      if (w.gravity_on()) sink += skeleton_ratio(w, sc.fc).ratio;
      const auto t4 = Clock::now();
      sink += w.kinetic_energy();
      const auto t5 = Clock::now();
      sink += check_finite(w).has_value() ? 1.0 : 0.0;
      const auto t6 = Clock::now();
      sink += sc.dt;
      t_step += ms(t0, t1), t_scan += ms(t1, t2), t_ratio += ms(t2, t3), t_skel += ms(t3, t4), t_ke += ms(t4, t5),
          t_guard += ms(t5, t6);
    }
    const double n = steps;
    std::printf(
        "bench_measure balls %zu pairs %zu threads %d steps %d | ms/step: step %.3f scan %.3f ratio %.3f skeleton %.3f "
        "kinetic %.3f guard %.3f measurements %.3f total %.3f (checksum %.17g)\n",
        w.num_balls(), w.pair_contacts().size(), w.params().threads, steps, t_step / n, t_scan / n, t_ratio / n,
        t_skel / n, t_ke / n, t_guard / n, (t_scan + t_ratio + t_skel + t_ke + t_guard) / n,
        (t_step + t_scan + t_ratio + t_skel + t_ke + t_guard) / n, sink);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_measure: %s\n", e.what());
  return 1;
}
