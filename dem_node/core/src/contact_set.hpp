// The contact sets of World (not installed): the one interface through which the cycle drives
// the ball-ball contacts and every wall kind (docs/theory.md 1.2: neighbour search, force
// passes, gather, critical step, energy). World keeps the cycle and its order; a set keeps its
// contacts, their history and, for a wall kind, its walls. A call on a set is one virtual call
// per pass, never one per contact: inside, each set runs a template instantiation per law.
#pragma once

#include <omp.h>

#include <cstdint>
#include <vector>

#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/pair_block.hpp"
#include "demfdm/dem/world.hpp"

namespace demfdm::dem {

/// What a contact set sees of the world in a rebuild, a pass or a measurement.
struct SetContext {
  Particles& pt;
  const WorldParams& p;
  double skin;            // [m] Verlet skin of the neighbour lists
  Vec3 edot;              // [1/s] strain rate of the periodic cell
  int threads;            // OpenMP threads of the passes
  PairKernel kernel;      // implementation of the contact passes (ball-ball and walls)
  double& e_slip_dead;    // [J] slip energy of retired contacts (HistoryCarry::rest)
  double& e_soft_dead;    // [J] bond dissipation of retired contacts
  std::int64_t& bond_failures;  // ball-ball bonds that left the intact state
  const std::uint8_t* ghost;    // per row: a ghost (a copy of another rank's ball), or null
  bool newton = false;          // a pair is listed only where its lower-id ball is not a ghost
};

/// A set's per-contact work handed to another set's pass (World::force_pass): `units`
/// independent units (a few contacts each), which the ball-ball pass's threads take in any order
/// once their own chunk is done, filling the time a thread would wait at the barrier. A unit
/// writes only its own contacts' records, so the order in which units run changes no bit.
struct SideWork {
  std::int64_t units = 0;
  void (*run)(void* ctx, std::int64_t unit) = nullptr;
  void* ctx = nullptr;
  bool parallel = false;  // worth a parallel loop of its own (run_side_work)
  double thread_s = 0.0;  // [s] summed over the threads: the time spent in the units (for the phases)
};

/// Runs every unit of `w` here: a parallel loop on `threads` where w.parallel, else in order;
/// adds the time to w.thread_s.
inline void run_side_work(SideWork& w, int threads) {
  const bool par = threads > 1 && w.parallel;
  const double t0 = omp_get_wtime();
  if (par) {
#pragma omp parallel for schedule(static) num_threads(threads)
    for (std::int64_t u = 0; u < w.units; ++u) w.run(w.ctx, u);
  } else {  // (no parallel region at all: the planes and the footing run here every pass)
    for (std::int64_t u = 0; u < w.units; ++u) w.run(w.ctx, u);
  }
  w.thread_s += (omp_get_wtime() - t0) * (par ? threads : 1);
}

/// One set of contacts, in the cycle's order: the ball-ball pairs first, then the wall kinds.
class ContactSet {
 public:
  explicit ContactSet(double PhaseTimes::*phase) : phase_(phase) {}
  virtual ~ContactSet() = default;
  /// The PhaseTimes entry its force pass is timed in.
  double PhaseTimes::*phase() const { return phase_; }

  /// Neighbour rebuild: the candidates within reach, their histories carried across by key
  /// (detail::HistoryCarry), bonded leftovers kept; a wall kind's travel restarts.
  virtual void rebuild(SetContext& cx) = 0;
  /// False: nothing to compute this step (a wall kind without walls); the cycle calls idle().
  virtual bool present() const { return true; }
  virtual void idle() {}
  /// Force-displacement of every contact (docs/theory.md 1.4-1.7, 2-3).
  virtual void pass(SetContext& cx, double dt) = 0;
  /// Add the contact forces and torques onto the balls, serially in contact order (the pairs
  /// add theirs in the pass).
  virtual void gather(Particles&) const {}
  /// Rigid walls move with their prescribed velocity (after the balls, before the rebuild check).
  virtual void move(double) {}
  /// [m] largest travel of a wall of the set since the last rebuild (0 for pairs).
  virtual double travel() const { return 0.0; }
  /// Per-contact terms of the O(contacts) measurements (the pairs compute them in parallel).
  virtual void scan(const SetContext&, bool /*critical_step*/, bool /*mean_force*/) {}
  /// Σ ‖F‖ and the count of the contacts that carry a force, in contact order.
  virtual void add_force_norms(double& sum, std::size_t& count) const = 0;
  /// The stiffness of every live contact added to its balls' translational (kt) and rotational
  /// (kr) sums, in contact order (docs/theory.md 1.8).
  virtual void add_stiffness(const SetContext& cx, double* kt, double* kr) const = 0;
  /// Strain energy, slip and bond dissipation of the live contacts; with ghost rows (a rank's
  /// part), those of the contacts whose ball (a pair's ball A) is not a ghost.
  virtual void add_energy(Energy& e, const WorldParams& p, const std::vector<std::uint8_t>& ghost) const = 0;
  /// Ball rows renumbered (World::reorder_spatially): new_row[old_row].
  virtual void remap(const std::vector<std::uint32_t>& new_row) = 0;
  /// Recompute the precomputed constants of every contact (World::refresh_contact_constants).
  virtual void refresh(const SetContext& cx) = 0;
  /// Forget every contact and history.
  virtual void clear() = 0;

 private:
  double PhaseTimes::*phase_;
};

namespace detail {

/// The law's per-pass constants of a family (docs/theory.md 1.7).
inline LawConst law_const(const ContactFamilyParams& f, bool rescale_shear, bool wall) {
  return visit_law(f.model, [&](auto law) { return decltype(law)::constants(f, rescale_shear, wall); });
}

/// Precomputed per-contact constants from the deformability method (docs/theory.md 1.7, 2.2,
/// 3.3). `wall` marks a ball-wall contact of ball a (b unused); otherwise a ball-ball contact.
inline void init_contact(const Particles& pt, std::uint32_t a, std::uint32_t b, ContactHist& h, BondHist* bond,
                         const ContactFamilyParams& fam, bool wall) {
  const double ra = pt.r[a];
  double rbar, L;
  if (!wall) {
    const double rb = pt.r[b];
    rbar = std::min(ra, rb);
    L = ra + rb;
  } else {
    rbar = ra;
    L = fam.linear.wall_length == WallLength::kRadius ? ra : 2.0 * ra;
  }
  visit_law(fam.model, [&](auto law) { decltype(law)::init(rbar, L, h, bond, fam); });
}

/// Flip the orientation of a contact's stored vectors (A and B swapped).
inline void flip(ContactHist& h, BondHist* b) {
  h.fs = -h.fs;
  h.n_old = -h.n_old;
  if (b) {
    b->fsb = -b->fsb;
    b->mb = -b->mb;
    b->mt = -b->mt;
  }
}

/// Strain energy, slip and bond dissipation of a family's live contacts (World::energy).
inline void add_contact_energy(Energy& e, const std::vector<ContactHist>& hs, const std::vector<BondHist>& bs,
                               const ContactFamilyParams& fam, const std::vector<std::uint32_t>& row,
                               const std::vector<std::uint8_t>& ghost) {
  visit_law(fam.model, [&](auto law) {
    for (std::size_t c = 0; c < hs.size(); ++c) {
      if (!ghost.empty() && ghost[row[c]]) continue;
      const ContactHist& h = hs[c];
      const BondHist* b = bs.empty() ? nullptr : &bs[c];
      decltype(law)::add_strain(e.strain, h, b, fam);
      e.friction += h.e_slip;
      if (b) e.softening += b->e_soft;
    }
  });
}

/// Instruction set of the lane kernels for a PairKernel choice; false: scalar loops.
inline bool block_isa(PairKernel k, pairblock::Isa& isa) {
  switch (k) {
    case PairKernel::kScalar: return false;
    case PairKernel::kBlockBaseline: isa = pairblock::Isa::kBaseline; return true;
    case PairKernel::kBlockAvx2: isa = pairblock::Isa::kAvx2; return true;
    case PairKernel::kBlockAvx512: isa = pairblock::Isa::kAvx512; return true;
    case PairKernel::kAuto: isa = pairblock::best_isa(); return true;
  }
  return false;
}

}  // namespace detail
}  // namespace demfdm::dem
