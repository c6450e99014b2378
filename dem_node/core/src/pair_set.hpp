// The ball-ball contact set of World (not installed): the half list of pairs found by the
// neighbour search (neighbour_grid.hpp), its history carried across rebuilds, the force pass
// (scalar law or the lane kernels of pair_block.hpp, one template instantiation per law), the
// per-contact terms of the critical step and the mean contact force, and bonding (docs/theory.md
// 1.2-1.8, 2-4.6).
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

#include "contact_set.hpp"
#include "demfdm/dem/neighbour_grid.hpp"

namespace demfdm::dem {

class PairSet final : public ContactSet {
 public:
  PairSet() : ContactSet(&PhaseTimes::pair) {}

  PairContacts contacts;  // the contacts, sorted by (a, b) after a rebuild

  void rebuild(SetContext& cx) override;
  void pass(SetContext& cx, double dt) override { pass(cx, dt, nullptr); }
  /// The pass, with another set's units (`side`, may be null) run by its threads once their own
  /// chunk is done (World::force_pass): all of them before it returns.
  void pass(SetContext& cx, double dt, SideWork* side);
  void scan(const SetContext& cx, bool critical_step, bool mean_force) override;
  void add_force_norms(double& sum, std::size_t& count) const override;
  void add_stiffness(const SetContext& cx, double* kt, double* kr) const override;
  void add_energy(Energy& e, const WorldParams& p, const std::vector<std::uint8_t>& ghost) const override;
  void remap(const std::vector<std::uint32_t>& new_row) override;
  void refresh(const SetContext& cx) override;
  void clear() override {
    contacts = PairContacts{};
    spare_ = PairContacts{};
    ++gen_;
  }
  /// Take a loaded contact list (a checkpoint); the scratch is dropped.
  void reset(PairContacts loaded);
  /// Exchange the list with `other` (World::swap_balls: the caller reuses the old arrays).
  void swap_in(PairContacts& other) {
    std::swap(contacts, other);
    ++gen_;
  }

  /// ||F|| of every contact from the last scan(.., want_fc = true).
  const std::vector<double>& force_norms() const { return norm_; }
  /// The pass writes every contact's ||F|| (World::keep_force_norms); a scan that follows it on
  /// the same state takes them instead of reading the histories again.
  void keep_force_norms(bool on) {
    keep_norms_ = on;
    pn_ok_ = false;
  }
  /// The pass's norms hold for the present list and histories under model m.
  bool pass_norms(ContactModel m) const {
    return pn_ok_ && pn_gen_ == gen_ && pn_model_ == m && norm_.size() == contacts.size();
  }
  /// Force and moment on B of contact k, rebuilt from its history (World::pair_force).
  Vec3 force(std::size_t k, const ContactFamilyParams& fam) const;
  Vec3 moment(std::size_t k, const ContactFamilyParams& fam) const;
  /// Branch vector x_B - x_A of contact k (minimum image).
  Vec3 branch(const Particles& pt, const PeriodicParams& cell, std::size_t k) const;
  /// Append a contact with a given state (replication).
  void append(std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& shift, const ContactHist& h,
              const BondHist* bond, bool has_bond);
  /// Bond every contact with gap in [lo, hi] (docs/theory.md 4.6); returns the count.
  std::size_t bond(const SetContext& cx, double lo, double hi);
  /// The list's pairs (a, b) may have been changed from outside (World::pair_contacts): the
  /// threaded pass re-plans its split balls before the next pass.
  void touch() {
    ++gen_;
    pn_ok_ = false;  // the caller may change histories too
  }
  /// A split ball's run sum (its contacts as A) in the threaded pass, and the pass that wrote it.
  struct RunSave {
    Vec3 f, t;
    std::uint64_t stamp = 0;
  };
  /// The threaded pass takes blocks of another thread's chunk once its own work is done (work
  /// stealing, pass_law; default on). The same bits either way (tests/dem/simd_kernel_test.cpp).
  /// `hold_s` > 0 (tests): the owner of the first chunk starts that late in every threaded pass,
  /// so that another thread takes most of its blocks.
  void set_stealing(bool on, double hold_s = 0.0) {
    steal_on_ = on;
    steal_hold_s_ = hold_s;
  }
  /// Blocks taken from another thread's chunk so far, and the blocks of the passes that could
  /// (the threaded passes without a plan).
  std::uint64_t blocks_stolen() const { return stolen_; }
  std::uint64_t blocks_stealable() const { return stealable_; }
  /// A live contact of a stolen block: its balls and what the ball sums add (pass_law).
  struct StealEntry {
    std::uint32_t a, b;
    Vec3 F, TA, TB;
  };
  /// A chunk's cursors into its save lists (pass_law); empty for the one-thread pass.
  struct ChunkCursor {
    const std::uint64_t* c0 = nullptr;  // the save list's start: record of *c = c - c0
    const std::uint64_t* c = nullptr;
    const std::uint32_t* run_row = nullptr;
    const std::uint32_t* run_rec = nullptr;
  };

 private:
  template <class Law, bool Periodic>
  void pass_law(SetContext& cx, double dt, SideWork* side);

  // Plan of the threaded pass for its chunk count (pass_law, plan_split).
  void plan_split(std::size_t n, int chunks);
  struct BSave {
    Vec3 f, tb;               // force and torque a split ball received as B
    std::uint64_t stamp = 0;  // the pass that wrote them
  };

  std::vector<std::vector<Vec3>> tbuf_;       // per-chunk force/torque buffers [2n] (chunk >= 1),
                                              // all zero between passes
  std::vector<std::size_t> row_lo_, row_hi_;  // rows touched by each chunk
  std::uint64_t gen_ = 0;                     // bumped whenever the pairs (a, b) may change
  PairContacts spare_;                        // rebuild: the list before last, its memory kept for the next
  std::vector<PairCandidate> cand_;           // rebuild: the candidates, memory kept
  std::uint64_t plan_gen_ = ~std::uint64_t{0};
  int plan_chunks_ = 0;
  bool plan_ok_ = false;                      // the list is sorted: the scheme applies
  std::size_t plan_m_ = 0, plan_n_ = 0;
  std::uint64_t stamp_ = 0;                   // passes so far
  std::vector<std::int64_t> cut_;             // chunk boundaries [chunks + 1]
  std::vector<std::int32_t> split_of_;        // per row: split record, or -1
  std::vector<std::int32_t> first_;           // per split ball: its first chunk
  std::vector<std::uint32_t> ev_off_, ev_;    // per split ball: its save records (CSR)
  // Per chunk (offsets sc_off_, rr_off_), each list ending in a sentinel: the contacts whose
  // B is a split ball outside its first chunk (ascending; record = place in sc_), and the split
  // balls with a run in the chunk (ascending rows) with their run records.
  std::vector<std::uint64_t> sc_;
  std::vector<std::uint32_t> rrow_, rrec_;
  std::vector<std::size_t> sc_off_, rr_off_;
  std::vector<BSave> save_;
  std::vector<RunSave> run_;
  // Work stealing in the threaded pass without a plan (pass_law): chunk k's blocks of kStealBlock
  // contacts are [lo, hi) of steal_range_[k] (lo | hi << 32), its owner takes them from the
  // bottom, another thread from the top. A stolen block's live contacts go to its slice of
  // steal_buf_ (count in steal_cnt_), and steal_done_ holds the pass's stamp once it is
  // complete; the owner then adds them to the ball sums in contact order.
  struct alignas(64) StealRange {
    std::atomic<std::uint64_t> v{0};
  };
  bool steal_on_ = true;
  double steal_hold_s_ = 0.0;                // set_stealing's hold (tests)
  std::unique_ptr<StealEntry[]> steal_buf_;  // (not value-initialised: pages only where used)
  std::size_t steal_cap_ = 0;                // entries in steal_buf_
  std::unique_ptr<std::atomic<std::uint64_t>[]> steal_done_;
  std::unique_ptr<std::uint32_t[]> steal_cnt_;
  std::size_t steal_blocks_ = 0;             // blocks in steal_done_ / steal_cnt_
  std::unique_ptr<StealRange[]> steal_range_;
  int steal_chunks_ = 0;                     // chunks in steal_range_
  std::uint64_t stolen_ = 0, stealable_ = 0;  // blocks_stolen, blocks_stealable
  // Scratch of the O(contacts) measurements (kept to avoid an allocation per call).
  std::vector<double> norm_;             // per-contact ||F||
  // The pass's norms (keep_norms_): norm_ holds ||Law::force|| of every contact for the list of
  // gen pn_gen_ and the model pn_model_, unless a history changed since (pn_ok_ cleared).
  bool keep_norms_ = false;
  bool pn_ok_ = false;
  std::uint64_t pn_gen_ = 0;
  ContactModel pn_model_ = ContactModel::kLinear;
  bool summed_ = false;                  // the last scan summed norm_ (one thread): fsum_, fcnt_
  double fsum_ = 0.0;                    // its sum of the positive norms, in contact order from +0
  std::size_t fcnt_ = 0;                 // and their count
  // The critical step's terms kept across steps (laws whose stiffness varies only with the
  // contact's active flag and bond state, !kStiffnessVaries): k_, ka_, kb_, live_ and every
  // ball's pair sums kt_pair_, kr_pair_ hold for the list of gen terms_gen_, the radii terms_r_
  // and the family terms_fam_. The pass records the contacts whose flag or bond state changed
  // (chg_); scan() recomputes only their terms and their balls' sums, each ball's in
  // ascending contact order (the CSR bb_off_, bb_: entry 2 c + 1 where the ball is B), which are
  // the additions of add_stiffness's serial loop.
  bool terms_ok_ = false;
  std::uint64_t terms_gen_ = 0;
  std::vector<double> terms_r_;
  std::vector<unsigned char> terms_fam_;
  std::vector<double> kt_pair_, kr_pair_;
  std::vector<std::uint32_t> bb_off_, bb_;
  std::vector<std::uint8_t> chg_;        // per contact: a pass changed its key since the last scan
  std::vector<std::uint8_t> dirty_;      // terms_events: balls whose sums are redone (flag, list)
  std::vector<std::uint32_t> dirty_list_;
  bool terms_fresh_ = false;             // the last scan left kt_pair_/kr_pair_ for add_stiffness
  void stiffness_loop(double* kt, double* kr) const;  // add_stiffness's serial loop
  template <class L>
  void terms_full(const SetContext& cx);
  template <class L>
  void terms_events(const SetContext& cx);
  std::vector<double> k_, ka_, kb_;      // per-contact k and rotational terms of A, B
  std::vector<std::uint8_t> live_;       // contact counted in the critical step
  bool fc_ = false, dt_ = false;         // what the last scan computed
};

}  // namespace demfdm::dem
