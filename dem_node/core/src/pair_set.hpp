// The ball-ball contact set of World (not installed): the half list of pairs found by the
// neighbour search (neighbour_grid.hpp), its history carried across rebuilds, the force pass
// (scalar law or the lane kernels of pair_block.hpp, one template instantiation per law), the
// per-contact terms of the critical step and the mean contact force, and bonding (docs/theory.md
// 1.2-1.8, 2-4.6).
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "contact_set.hpp"

namespace demfdm::dem {

class PairSet final : public ContactSet {
 public:
  PairSet() : ContactSet(&PhaseTimes::pair) {}

  PairContacts contacts;  // the contacts, sorted by (a, b) after a rebuild

  void rebuild(SetContext& cx) override;
  void pass(SetContext& cx, double dt) override;
  void scan(const SetContext& cx, bool critical_step, bool mean_force) override;
  void add_force_norms(double& sum, std::size_t& count) const override;
  void add_stiffness(const SetContext& cx, double* kt, double* kr) const override;
  void add_energy(Energy& e, const WorldParams& p) const override;
  void remap(const std::vector<std::uint32_t>& new_row) override;
  void refresh(const SetContext& cx) override;
  void clear() override { contacts = PairContacts{}; }
  /// Take a loaded contact list (a checkpoint); the scratch is dropped.
  void reset(PairContacts loaded);

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

 private:
  template <class Law, bool Periodic>
  void pass_law(SetContext& cx, double dt);

  std::vector<std::vector<Vec3>> tbuf_;       // per-thread force/torque buffers [2n] (thread >= 1),
                                              // all zero between passes
  std::vector<std::size_t> row_lo_, row_hi_;  // rows touched by each thread's block
  // Scratch of the O(contacts) measurements (kept to avoid an allocation per call).
  std::vector<double> norm_;             // per-contact ||F||
  std::vector<double> k_, ka_, kb_;      // per-contact k and rotational terms of A, B
  std::vector<std::uint8_t> live_;       // contact counted in the critical step
  bool fc_ = false, dt_ = false;         // what the last scan computed
};

}  // namespace demfdm::dem
