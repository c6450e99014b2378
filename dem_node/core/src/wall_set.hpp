// The wall-contact set of World (not installed; docs/theory.md 1.4, 6.2-6.5): one template for
// every wall kind, so plane walls, interface facets and the footing share the law, the history
// merge and the bookkeeping. A kind is its walls plus their geometry:
//   kFamily                    the contact family of its contacts (a WorldParams member);
//   kParallel                  its per-contact work may run in parallel;
//   present() / idle()         whether it has walls; what it resets when it has none;
//   begin(cx, wc)              reset what the kind sums over its contacts;
//   surface(x, wc, c)          the contact's surface point: distance from the ball centre, normal
//                              towards the wall, wall velocity and spin there, the facet and its
//                              barycentric weights (facet walls);
//   after_law(cx, wc, c)       a per-contact rule after the law (may run in parallel);
//   rec(wc, c) / add(rec)      the contact's share of the kind's sums (a WallSumRec) and adding
//                              it, serially in contact order (also World::set_wall_sums);
//   end(cx, wc)                what the kind derives from all its contacts;
//   candidates(cx, cands)      the (ball, wall, facet) triples within reach at a rebuild (the
//                              walls' travel restarts); wall_id(w);
//   move(dt) / travel()        rigid motion with the prescribed velocity; travel since the rebuild.
// Adding a wall kind is a kind struct here, its geometry in walls.cpp and one set in World.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "contact_set.hpp"
#include "world_detail.hpp"

namespace demfdm::dem {

struct WallSurface {
  double dist = 0.0;
  Vec3 n{}, v{}, w{}, bary{};
  std::int32_t facet = 0;
};

template <class Kind>
class WallSet final : public ContactSet {
 public:
  explicit WallSet(double PhaseTimes::*phase) : ContactSet(phase) {}

  WallContacts contacts;
  Kind kind;  // the walls of this kind and their geometry

  void rebuild(SetContext& cx) override;
  bool present() const override { return kind.present(); }
  void idle() override { kind.idle(); }
  void pass(SetContext& cx, double dt) override;
  /// The pass with its per-contact units handed to `host`, which runs them all (in any order, on
  /// any threads) before it returns; the kind's work before and after them runs here
  /// (World::force_pass: the facets inside the ball-ball pass).
  void pass_hosted(SetContext& cx, double dt, const std::function<void(SideWork&)>& host)
    requires Kind::kParallel;
  void gather(Particles& pt) const override;
  void move(double dt) override { kind.move(dt); }
  double travel() const override { return kind.travel(); }
  void add_force_norms(double& sum, std::size_t& count) const override;
  void add_stiffness(const SetContext& cx, double* kt, double* kr) const override;
  void add_energy(Energy& e, const WorldParams& p, const std::vector<std::uint8_t>& ghost) const override;
  void remap(const std::vector<std::uint32_t>& new_row) override;
  void refresh(const SetContext& cx) override;
  void clear() override { contacts = WallContacts{}; }

 private:
  template <class Law>
  void pass_law(SetContext& cx, const ContactFamilyParams& fam, double dt,
                const std::function<void(SideWork&)>* host);
};

/// Planar walls (platens, boxes): one-sided inside their rectangle; reaction and the sum of the
/// active contacts' K_n (servo gain) per wall.
struct PlaneKind {
  static constexpr ContactFamilyParams WorldParams::*kFamily = &WorldParams::ball_wall;
  static constexpr bool kParallel = false;
  std::vector<PlaneWall> walls;

  bool present() const { return !walls.empty(); }
  void idle() {}
  void begin(const SetContext&, const WallContacts&);
  WallSurface surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const;
  void after_law(const SetContext&, WallContacts&, std::int64_t) const {}
  static WallSumRec rec(const WallContacts& wc, std::int64_t c);
  void add(const WallSumRec& r);
  void end(const SetContext&, WallContacts&) {}
  void candidates(const SetContext& cx, std::vector<detail::WallCand>& cands);
  std::uint64_t wall_id(std::uint32_t w) const { return walls[w].id; }
  void move(double dt);
  double travel() const;
};

/// One facet contact's share of its wall's vertex sums (docs/theory.md 6.4, 6.5): its three
/// equivalent vertex forces and stiffness shares, formed per contact (in parallel in the pass)
/// and added in contact order (FacetKind::end).
struct FacetTerm {
  std::uint32_t wall = 0;
  std::int32_t facet = 0;
  bool active = false;  // it acts (carries a force or is bonded)
  bool loaded = false;  // it carries a force or moment: vertex forces and the wall's total
  std::array<Vec3, 3> f{};
  Vec3 F{};
  double k[3] = {0.0, 0.0, 0.0};
};

/// Interface facet walls (docs/theory.md 6.2-6.5): the nearest candidate facet of each contact
/// (the history stays with the (ball, wall) contact, 1.4); equivalent vertex forces and vertex
/// stiffness.
struct FacetKind {
  static constexpr ContactFamilyParams WorldParams::*kFamily = &WorldParams::ball_facet;
  static constexpr bool kParallel = true;
  std::vector<FacetWall> walls;
  bool restore_linear = false;  // this pass: a broken interface bond becomes a linear contact
  std::vector<FacetTerm> terms;  // this pass: each contact's share of the vertex sums

  bool present() const { return !walls.empty(); }
  void idle() {}
  void begin(const SetContext& cx, const WallContacts& wc);
  WallSurface surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const;
  void after_law(const SetContext& cx, WallContacts& wc, std::int64_t c);
  static WallSumRec rec(const WallContacts&, std::int64_t) { return {}; }  // summed in end()
  void add(const WallSumRec&) {}
  void end(const SetContext& cx, WallContacts& wc);
  void candidates(const SetContext& cx, std::vector<detail::WallCand>& cands);
  std::uint64_t wall_id(std::uint32_t w) const { return walls[w].id; }
  void move(double) {}  // the continuum sets the vertices (World::set_vertex_kinematics)
  double travel() const;
  /// Facet normals and kinematic spin from the vertex velocities (6.2); spin = false: no spin.
  static void update_spin(FacetWall& fw, bool spin);
  /// Bond the ball-facet contacts with gap <= hi (2.6, 4.8); returns the count.
  std::size_t bond(const SetContext& cx, WallContacts& wc, double hi) const;
};

/// The rigid cylindrical footing (docs/theory.md 0.3): its reaction.
struct FootingKind {
  static constexpr ContactFamilyParams WorldParams::*kFamily = &WorldParams::ball_footing;
  static constexpr bool kParallel = false;
  Footing ft;

  bool present() const { return ft.enabled; }
  void idle() { ft.reaction = Vec3{}; }
  void begin(const SetContext&, const WallContacts&) { ft.reaction = Vec3{}; }
  WallSurface surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const;
  void after_law(const SetContext&, WallContacts&, std::int64_t) const {}
  static WallSumRec rec(const WallContacts& wc, std::int64_t c) {
    WallSumRec r;
    r.F = wc.F[c];
    return r;
  }
  void add(const WallSumRec& r) { ft.reaction += r.F; }
  void end(const SetContext&, WallContacts&) {}
  void candidates(const SetContext& cx, std::vector<detail::WallCand>& cands);
  std::uint64_t wall_id(std::uint32_t) const { return ft.id; }
  void move(double dt);
  double travel() const;
};

extern template class WallSet<PlaneKind>;
extern template class WallSet<FacetKind>;
extern template class WallSet<FootingKind>;

}  // namespace demfdm::dem
