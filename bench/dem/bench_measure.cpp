// A coupled DEM step's own work on a real state (issue 16 item 2): the engine's step, the guard
// and the measurements the DEM node reports after every step (docs/speed.md, "The step's
// measurements"). The guard (finite values, escape, kinetic energy) is timed as the node runs it,
// in one pass (dem::screen_balls), and as the three separate tests it replaced; the measurements
// are the contact scan (critical step and mean contact force) and the unbalanced and skeleton
// ratios, timed one after the other and in one pass (dem::ball_ratios, as the node forms them;
// `measurements` counts the one pass).
//
//   bench_measure CHECKPOINT_DIR [steps=300] [rounds=1] [measure_threads] [step_threads]
//
// CHECKPOINT_DIR is a run's checkpoint folder (its dem.world.state and manifest.txt), e.g. the
// default scene's gravity-end checkpoint (runs/<run>/checkpoints/gravity-<step>-end). The World
// keeps the thread count it was saved with (OMP_NUM_THREADS does not change it). Each round
// starts from the loaded state; one line per round, times in ms per step. `measure_threads`
// runs the measurements (not the step) on that many threads, as the DEM node does in a coupled
// stage (one thread, dem_node/main.cpp step_values); `step_threads` runs the step on that many.
// The line ends with the step's phases (World::phase_times) and the wall-contact counts; a second
// line gives a hash of the state after the steps (x, v, ω, the facet walls' vertex sums).
// BENCH_MEASURE_HOSTED=0 runs the facets in their own pass after the ball-ball pass
// (World::set_hosted_facets(false)); =ab switches between the two every 10 steps inside the run
// (ab_blocks.hpp: A = hosted; the same bits either way) and prints the ratio of the step's time,
// hosted over own, per pair of neighbouring blocks (mean and standard error).
// BENCH_MEASURE_STEAL=0 runs the threaded ball-ball pass without work stealing
// (World::set_pair_stealing(false)); =ab switches it on (A) and off (B) the same way (not together
// with BENCH_MEASURE_HOSTED=ab). A last line gives the blocks of that pass other threads took.
// BENCH_MEASURE_NORMS=0 runs the pass without keeping the contacts' force norms (the scan forms
// them); =ab with (A) and without (B), the same way. Each switch takes 0, 1 (the default) or ab,
// one ab at a time.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "coordinator/core/checkpoint.hpp"
#include "demfdm/dem/checkpoint.hpp"
#include "demfdm/dem/guard.hpp"
#include "demfdm/dem/procedures.hpp"
#include "demfdm/dem/world.hpp"
#include "demfdm/io/state_file.hpp"
#include "ab_blocks.hpp"

using namespace demfdm::dem;
using Clock = std::chrono::steady_clock;

namespace {

double ms(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double, std::milli>(b - a).count(); }

// A BENCH_MEASURE_* switch: 0 (off), 1 (on, the default) or ab (on in the A blocks, off in the B
// blocks, ab_blocks.hpp).
struct Switch {
  bool on = true, ab = false;
};
Switch switch_of(const char* var) {
  const char* v = std::getenv(var);
  const std::string m = v ? v : "1";
  if (m != "0" && m != "1" && m != "ab")
    throw std::runtime_error(std::string(var) + " must be 0, 1 or ab, found '" + m + "'");
  return {m != "0", m == "ab"};
}

}  // namespace

int main(int argc, char** argv) try {
  if (argc < 2) {
    std::fprintf(stderr, "usage: bench_measure CHECKPOINT_DIR [steps=300] [rounds=1] [measure_threads] [step_threads]\n");
    return 2;
  }
  const std::filesystem::path dir = argv[1];
  const int steps = argc > 2 ? std::stoi(argv[2]) : 300;
  const int rounds = argc > 3 ? std::stoi(argv[3]) : 1;
  const int measure_threads = argc > 4 ? std::stoi(argv[4]) : 0;  // 0: the World's own
  const int step_threads_arg = argc > 5 ? std::stoi(argv[5]) : 0;  // 0: the World's own
  const std::uint64_t hash = demfdm::coord::verify_checkpoint(dir).scene_hash;
  const Switch hosted = switch_of("BENCH_MEASURE_HOSTED"), steal = switch_of("BENCH_MEASURE_STEAL"),
               norms = switch_of("BENCH_MEASURE_NORMS");
  const bool ab = hosted.ab, ab_steal = steal.ab, ab_norms = norms.ab;
  if (int(ab) + int(ab_steal) + int(ab_norms) > 1)
    throw std::runtime_error("BENCH_MEASURE_HOSTED, BENCH_MEASURE_STEAL and BENCH_MEASURE_NORMS: one =ab at a time");
  for (int r = 0; r < rounds; ++r) {
    World w{WorldParams{}};
    load_state_file(w, dir / "dem.world.state", hash);
    if (step_threads_arg > 0) w.mutable_params().threads = step_threads_arg;
    // As the DEM node: hosted facets, work stealing, the pass keeps the force norms for the scan.
    w.set_hosted_facets(hosted.on);
    w.set_pair_stealing(steal.on);
    w.keep_force_norms(norms.on);
    constexpr int kBlock = 10;
    std::vector<double> block_ms;  // (ab) the step's time per block of kBlock steps
    const int step_threads = w.params().threads;
    const int mt = measure_threads > 0 ? measure_threads : step_threads;
    // The escape test's box: the balls' extent at the start, one diameter wider.
    Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    for (std::size_t i = 0; i < w.num_balls(); ++i)
      for (int k = 0; k < 3; ++k) {
        lo[k] = std::min(lo[k], w.balls().x[i][k] - 2 * w.balls().r[i]);
        hi[k] = std::max(hi[k], w.balls().x[i][k] + 2 * w.balls().r[i]);
      }
    std::vector<double> scratch;
    w.reset_phase_times();
    double t_step = 0, t_sep = 0, t_screen = 0, t_scan = 0, t_ratio = 0, t_skel = 0, t_both = 0, sink = 0;
    for (int s = 0; s < steps; ++s) {
      // The step and the guard on the World's threads (the node's guard runs before the forces
      // go out), the measurements on `mt`.
      w.mutable_params().threads = step_threads;
      const int blk = s / kBlock;
      if (ab) w.set_hosted_facets(demfdm::bench::ab_block_is_a(blk));
      if (ab_steal) w.set_pair_stealing(demfdm::bench::ab_block_is_a(blk));
      if (ab_norms) w.keep_force_norms(demfdm::bench::ab_block_is_a(blk));
      const auto t0 = Clock::now();
      w.step();
      const auto t1 = Clock::now();
      if (ab || ab_steal || ab_norms) {
        if (static_cast<int>(block_ms.size()) <= blk) block_ms.resize(static_cast<std::size_t>(blk) + 1, 0.0);
        block_ms[static_cast<std::size_t>(blk)] += ms(t0, t1);
      }
      // The guard's tests one by one (the node before session 16) and in one pass (screen_balls),
      // first the one, then the other on alternate steps (the second finds the rows in cache).
      double ke = 0.0;
      BallScreen bs;
      double dt_sep = 0.0, dt_screen = 0.0;
      for (int k = 0; k < 2; ++k) {
        const auto a = Clock::now();
        if ((k + s) % 2 == 0) {
          sink += check_finite(w).has_value() ? 1.0 : 0.0;
          sink += check_escape(w, lo, hi, 0.0).has_value() ? 1.0 : 0.0;
          ke = w.kinetic_energy();
          dt_sep = ms(a, Clock::now());
        } else {
          bs = screen_balls(w, lo, hi, true, scratch);
          dt_screen = ms(a, Clock::now());
        }
      }
      if (bs.kinetic != ke || !bs.finite) throw std::runtime_error("screen_balls disagrees with the separate tests");
      sink += bs.kinetic + bs.outside;
      w.mutable_params().threads = mt;
      const auto t3 = Clock::now();
      const World::ContactScan sc = static_cast<const World&>(w).contact_scan(true, true);
      const auto t4 = Clock::now();
      // The two ratios one after the other and in one pass (dem::ball_ratios, as the node forms
      // them with gravity on), first the one, then the other on alternate steps.
      double unb = 0.0, skel = 0.0;
      BallRatios both;
      for (int k = 0; k < 2; ++k) {
        if ((k + s) % 2 == 0) {
          const auto a = Clock::now();
          unb = w.unbalanced_ratio(sc.fc);
          const auto b = Clock::now();
          if (w.gravity_on()) skel = skeleton_ratio(w, sc.fc).ratio;
          t_ratio += ms(a, b), t_skel += ms(b, Clock::now());
        } else if (w.gravity_on()) {
          const auto a = Clock::now();
          both = ball_ratios(w, sc.fc);
          t_both += ms(a, Clock::now());
        }
      }
      if (w.gravity_on() && (both.unbalanced != unb || both.skeleton.ratio != skel))
        throw std::runtime_error("ball_ratios disagrees with the two ratios");
      sink += unb + skel + sc.dt;
      t_step += ms(t0, t1), t_sep += dt_sep, t_screen += dt_screen, t_scan += ms(t3, t4);
    }
    const double n = steps;
    const PhaseTimes& ph = w.phase_times();
    std::printf(
        "bench_measure balls %zu pairs %zu threads %d (measurements %d) steps %d | ms/step: step %.3f guard %.3f "
        "(separate tests %.3f) scan %.3f ratio %.3f skeleton %.3f (both in one pass %.3f) measurements %.3f total %.3f "
        "(checksum %.17g) | "
        "step phases ms/step: rebuild %.3f pair %.3f facet %.3f footing %.3f plane %.3f gather %.3f motion %.3f "
        "effects %.3f | facet contacts %zu footing contacts %zu\n",
        w.num_balls(), w.pair_contacts().size(), step_threads, mt, steps, t_step / n, t_screen / n, t_sep / n,
        t_scan / n, t_ratio / n, t_skel / n, t_both / n, (t_scan + t_both) / n, (t_step + t_screen + t_scan + t_both) / n,
        sink, 1e3 * ph.rebuild / n, 1e3 * ph.pair / n, 1e3 * ph.facet / n, 1e3 * ph.footing / n, 1e3 * ph.plane / n,
        1e3 * ph.gather / n, 1e3 * ph.motion / n, 1e3 * ph.effects_total / n, w.facet_contacts().size(),
        w.footing_contacts().size());
    if (ab || ab_steal || ab_norms) {
      block_ms.resize(static_cast<std::size_t>(steps / kBlock));  // complete blocks only
      const demfdm::bench::AbRatios r = demfdm::bench::ab_ratios(block_ms);
      if (ab)
        std::printf("bench_measure hosted facets: step time hosted/own %.4f (s.e. %.4f) over %zu block pairs of %d steps\n",
                    r.mean, r.se, r.pairs, kBlock);
      else if (ab_steal)
        std::printf("bench_measure stealing: step time with/without %.4f (s.e. %.4f) over %zu block pairs of %d steps\n",
                    r.mean, r.se, r.pairs, kBlock);
      else
        std::printf("bench_measure force norms: step time kept/not %.4f (s.e. %.4f) over %zu block pairs of %d steps\n",
                    r.mean, r.se, r.pairs, kBlock);
    }
    const auto st = w.pair_blocks_stolen();
    std::printf("bench_measure blocks stolen %llu of %llu (%.2f %%)\n", static_cast<unsigned long long>(st.first),
                static_cast<unsigned long long>(st.second), st.second ? 100.0 * double(st.first) / double(st.second) : 0.0);
    // The state after the steps, for comparing builds bit for bit: x, v, ω of every ball and the
    // facet walls' vertex forces and stiffnesses.
    std::uint64_t h = demfdm::io::fnv1a64(w.balls().x.data(), w.num_balls() * sizeof(Vec3));
    h = demfdm::io::fnv1a64(w.balls().v.data(), w.num_balls() * sizeof(Vec3), h);
    h = demfdm::io::fnv1a64(w.balls().w.data(), w.num_balls() * sizeof(Vec3), h);
    for (int k = 0; k < w.num_facet_walls(); ++k) {
      const FacetWall& fw = w.facet_wall(k);
      h = demfdm::io::fnv1a64(fw.vforce.data(), fw.vforce.size() * sizeof(Vec3), h);
      h = demfdm::io::fnv1a64(fw.vstiff.data(), fw.vstiff.size() * sizeof(double), h);
    }
    std::printf("bench_measure state hash %016llx\n", static_cast<unsigned long long>(h));
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "bench_measure: %s\n", e.what());
  return 1;
}
