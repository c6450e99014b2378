// The one wall-contact set of World (docs/theory.md 1.4, 6.2-6.5): wall kinds as geometries,
// their candidate search and history merge at a rebuild, the per-contact law and the pass over
// a kind's contacts, and the bonding of balls to interface facets (§2.6).
#include <omp.h>

#include <algorithm>
#include <array>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "demfdm/dem/geometry.hpp"
#include "demfdm/dem/world.hpp"
#include "world_detail.hpp"

namespace demfdm::dem {

using detail::facet_distance;
using detail::plane_distance;
using detail::WallCand;

// The one wall-contact set (docs/theory.md 1.4): every wall kind's contacts go through the same
// law (wall_contact), history merge (rebuild_walls) and bookkeeping. A kind is a geometry:
//   begin()             reset what the kind sums over its contacts;
//   surface(x, wc, c)   the contact's surface point: distance from the ball centre, normal
//                       towards the wall, wall velocity and spin there, the facet and its
//                       barycentric weights (facet walls);
//   after_law(wc, c)    a per-contact rule after the law (may run in parallel);
//   add(wc, c)          sum the contact's results, serially in contact order;
//   end(wc)             what the kind derives from all its contacts;
//   candidates(cands)   the (ball, wall, facet) pairs within reach at a rebuild; wall_id(w).
struct WallSurface {
  double dist = 0.0;
  Vec3 n{}, v{}, w{}, bary{};
  std::int32_t facet = 0;
};

// Planar walls (platens, boxes): one-sided inside their rectangle; reaction and the sum of the
// active contacts' K_n (servo gain) per wall.
struct World::PlaneGeometry {
  World& wd;
  static constexpr bool kParallel = false;
  void begin() {
    for (auto& pw : wd.planes_) { pw.reaction = Vec3{}; pw.k_sum = 0.0; }
  }
  WallSurface surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const {
    const PlaneWall& pw = wd.planes_[wc.wall[c]];
    WallSurface s;
    s.dist = plane_distance(x, pw, s.n);
    s.v = pw.p.velocity;
    s.facet = wc.facet[c];
    s.bary = wc.bary[c];
    return s;
  }
  void after_law(WallContacts&, std::int64_t) const {}
  void add(const WallContacts& wc, std::int64_t c) {
    PlaneWall& pw = wd.planes_[wc.wall[c]];
    pw.reaction += wc.F[c];
    if (wc.h[c].flags & ContactHist::kActive) pw.k_sum += wc.h[c].kn;
  }
  void end(WallContacts&) {}
  void candidates(std::vector<WallCand>& cands) {
    const auto& pt = wd.pt_;
    for (std::size_t w = 0; w < wd.planes_.size(); ++w) {
      for (std::size_t i = 0; i < pt.size(); ++i) {
        Vec3 nn;
        const double d = plane_distance(pt.x[i], wd.planes_[w], nn);
        if (d - pt.r[i] < wd.skin_ + wd.p_.ball_wall.linear.rgap)
          cands.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(w), 0});
      }
      wd.planes_[w].disp = Vec3{};
    }
  }
  std::uint64_t wall_id(std::uint32_t w) const { return wd.planes_[w].id; }
};

// Interface facet walls (§6.2-6.5): the nearest candidate facet of each contact (the history
// stays with the (ball, wall) contact, §1.4); equivalent vertex forces and vertex stiffness.
struct World::FacetGeometry {
  World& wd;
  bool restore_linear = false;
  static constexpr bool kParallel = true;
  void begin() {
    const WallContacts& wc = wd.fcc_;
    restore_linear = wd.p_.ball_facet.model == ContactModel::kLinearPBond && wd.p_.ball_facet.pbond.zero_linear &&
                     !wc.bond.empty();
  }
  WallSurface surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const {
    const FacetWall& fw = wd.fwalls_[wc.wall[c]];
    WallSurface s;
    double best = std::numeric_limits<double>::infinity();
    std::int32_t ft = wc.facet[c];
    for (std::uint32_t k = wc.cand_off[c]; k < wc.cand_off[c + 1]; ++k) {
      Vec3 nn, ww;
      const double d = facet_distance(x, fw, wc.cand[k], nn, ww);
      if (d < best) { best = d; s.n = nn; s.bary = ww; ft = static_cast<std::int32_t>(wc.cand[k]); }
    }
    s.dist = best;
    s.facet = ft;
    const auto& tr = fw.tri[static_cast<std::size_t>(ft)];
    const Vec3& w = s.bary;
    s.v = w.x * fw.vel[tr[0]] + w.y * fw.vel[tr[1]] + w.z * fw.vel[tr[2]];
    s.w = fw.tri_spin[static_cast<std::size_t>(ft)];
    return s;
  }
  // §2.6, §6.3: a bonded interface contact has no linear part (zero_linear); once its bond
  // breaks it is an ordinary linear contact again, from the configuration at the break (its
  // force starts at 0 and grows with further overlap), so the ball cannot cross the wall.
  void after_law(WallContacts& wc, std::int64_t c) const {
    if (restore_linear && wc.h[c].kn == 0.0 &&
        (wc.bond[c].state == BondState::kBrokenTension || wc.bond[c].state == BondState::kBrokenShear))
      wd.init_contact(wc.ball[c], 0, wc.h[c], &wc.bond[c], wd.p_.ball_facet, true);
  }
  void add(const WallContacts&, std::int64_t) {}
  // §6.4 equivalent vertex forces and §6.5 stiffness, serial in contact order
  void end(WallContacts& wc) {
    for (auto& fw : wd.fwalls_) {
      std::fill(fw.vforce.begin(), fw.vforce.end(), Vec3{});
      std::fill(fw.vstiff.begin(), fw.vstiff.end(), 0.0);
      fw.total_force = Vec3{};
    }
    const std::int64_t m = static_cast<std::int64_t>(wc.size());
    for (std::int64_t c = 0; c < m; ++c) {
      FacetWall& fw = wd.fwalls_[wc.wall[c]];
      const auto& tr = fw.tri[static_cast<std::size_t>(wc.facet[c])];
      const bool bd = !wc.bond.empty() && bonded(wc.bond[c].state);
      const bool act = (wc.h[c].flags & ContactHist::kActive) || bd;
      if (!act) continue;
      if (norm2(wc.F[c]) > 0.0 || norm2(wc.M[c]) > 0.0) {
        std::array<Vec3, 3> f;
        facet_equivalent_forces({fw.pos[tr[0]], fw.pos[tr[1]], fw.pos[tr[2]]}, wc.xc[c], wc.F[c], wc.M[c], f);
        for (int v = 0; v < 3; ++v) fw.vforce[tr[v]] += f[v];
        fw.total_force += wc.F[c];
      }
      double K = wc.h[c].kn + wc.h[c].ks;
      if (bd && wd.p_.ball_facet.model == ContactModel::kLinearPBond)
        K += wc.bond[c].kn * (1.0 + 1.0 / wd.p_.ball_facet.pbond.kratio) * wc.bond[c].area();
      const Vec3& w = wc.bary[c];
      for (int v = 0; v < 3; ++v) fw.vstiff[tr[v]] += w[v] * K;
    }
  }
  // every facet against every ball near its bounding box (sorted by x for a cheap sweep);
  // candidates within R + skin
  void candidates(std::vector<WallCand>& cands) {
    if (wd.fwalls_.empty()) return;
    const auto& pt = wd.pt_;
    const std::size_t n = pt.size();
    std::vector<std::uint32_t> order(n);
    std::iota(order.begin(), order.end(), 0u);
    std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return pt.x[a].x < pt.x[b].x; });
    std::vector<double> xs(n);
    for (std::size_t k = 0; k < n; ++k) xs[k] = pt.x[order[k]].x;
    double rmax = 0.0;
    for (double r : pt.r) rmax = std::max(rmax, r);
    const double reach = rmax + wd.skin_ + wd.p_.ball_facet.linear.rgap;
    for (std::size_t w = 0; w < wd.fwalls_.size(); ++w) {
      const auto& fw = wd.fwalls_[w];
      for (std::size_t t = 0; t < fw.tri.size(); ++t) {
        Vec3 lo = fw.pos[fw.tri[t][0]], hi = lo;
        for (int v = 1; v < 3; ++v)
          for (int k = 0; k < 3; ++k) {
            lo[k] = std::min(lo[k], fw.pos[fw.tri[t][v]][k]);
            hi[k] = std::max(hi[k], fw.pos[fw.tri[t][v]][k]);
          }
        auto it0 = std::lower_bound(xs.begin(), xs.end(), lo.x - reach);
        auto it1 = std::upper_bound(xs.begin(), xs.end(), hi.x + reach);
        for (auto it = it0; it != it1; ++it) {
          const std::uint32_t i = order[static_cast<std::size_t>(it - xs.begin())];
          const Vec3& x = pt.x[i];
          if (x.y < lo.y - reach || x.y > hi.y + reach || x.z < lo.z - reach || x.z > hi.z + reach) continue;
          Vec3 nn, ww;
          const double d = facet_distance(x, fw, t, nn, ww);
          if (d - pt.r[i] < wd.skin_ + wd.p_.ball_facet.linear.rgap)
            cands.push_back({i, static_cast<std::uint32_t>(w), static_cast<std::int32_t>(t)});
        }
      }
    }
    for (auto& fw : wd.fwalls_) fw.pos_ref = fw.pos;
  }
  std::uint64_t wall_id(std::uint32_t w) const { return wd.fwalls_[w].id; }
};

// The rigid cylindrical footing (§0.3): its reaction.
struct World::FootingGeometry {
  World& wd;
  static constexpr bool kParallel = false;
  void begin() { wd.footing_.reaction = Vec3{}; }
  WallSurface surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const {
    const Footing& ft = wd.footing_;
    WallSurface s;
    Vec3 q;
    s.dist = closest_point_cylinder(x, ft.p.bottom_centre, 0.5 * ft.p.diameter, ft.p.height, q, s.n);
    s.v = ft.p.velocity;
    s.facet = wc.facet[c];
    s.bary = wc.bary[c];
    return s;
  }
  void after_law(WallContacts&, std::int64_t) const {}
  void add(const WallContacts& wc, std::int64_t c) { wd.footing_.reaction += wc.F[c]; }
  void end(WallContacts&) {}
  void candidates(std::vector<WallCand>& cands) {
    Footing& ft = wd.footing_;
    if (!ft.enabled) return;
    const auto& pt = wd.pt_;
    const double R = 0.5 * ft.p.diameter;
    for (std::size_t i = 0; i < pt.size(); ++i) {
      Vec3 q, nn;
      const double d = closest_point_cylinder(pt.x[i], ft.p.bottom_centre, R, ft.p.height, q, nn);
      if (d - pt.r[i] < wd.skin_ + wd.p_.ball_footing.linear.rgap) cands.push_back({static_cast<std::uint32_t>(i), 0, 0});
    }
    ft.disp = Vec3{};
  }
  std::uint64_t wall_id(std::uint32_t) const { return wd.footing_.id; }
};


void World::rebuild_walls() {
  auto merge = [&](WallContacts& old, std::vector<WallCand>& cands, const ContactFamilyParams& fam,
                   auto wall_id) {
    const bool has_bond = law_has_bond(fam.model);
    detail::HistoryCarry carry(old.size(), false, [&](std::size_t c) {
      return std::make_pair(std::uint64_t(pt_.id[old.ball[c]]), std::uint64_t(wall_id(old.wall[c])));
    });
    std::sort(cands.begin(), cands.end(), [](const WallCand& x, const WallCand& y) {
      return std::tie(x.ball, x.wall, x.facet) < std::tie(y.ball, y.wall, y.facet);
    });
    WallContacts q;
    q.cand_off.push_back(0);
    for (std::size_t k = 0; k < cands.size();) {
      const auto& e = cands[k];
      q.ball.push_back(e.ball);
      q.wall.push_back(e.wall);
      std::int32_t keep_facet = e.facet;
      std::size_t k2 = k;
      for (; k2 < cands.size() && cands[k2].ball == e.ball && cands[k2].wall == e.wall; ++k2)
        q.cand.push_back(static_cast<std::uint32_t>(cands[k2].facet));
      q.cand_off.push_back(static_cast<std::uint32_t>(q.cand.size()));
      const std::int64_t found = carry.take(pt_.id[e.ball], wall_id(e.wall));
      if (found >= 0) {
        const auto oc = static_cast<std::size_t>(found);
        q.h.push_back(old.h[oc]);
        if (has_bond) q.bond.push_back(old.bond[oc]);
        if (!old.facet.empty()) keep_facet = old.facet[oc];
      } else {
        q.h.push_back({});
        if (has_bond) q.bond.push_back({});
        init_contact(e.ball, 0, q.h.back(), has_bond ? &q.bond.back() : nullptr, fam, true);
      }
      q.facet.push_back(keep_facet);
      k = k2;
    }
    // bonded wall contacts never disappear: keep them with their last facet as candidate
    carry.rest(
        old.h, old.bond, has_bond,
        [&](std::size_t c) {
          q.ball.push_back(old.ball[c]);
          q.wall.push_back(old.wall[c]);
          q.cand.push_back(static_cast<std::uint32_t>(old.facet.empty() ? 0 : old.facet[c]));
          q.cand_off.push_back(static_cast<std::uint32_t>(q.cand.size()));
          q.facet.push_back(old.facet.empty() ? 0 : old.facet[c]);
          q.h.push_back(old.h[c]);
          q.bond.push_back(old.bond[c]);
        },
        e_slip_dead_, e_soft_dead_);
    const std::size_t m = q.ball.size();
    q.F.assign(m, {});
    q.M.assign(m, {});
    q.TA.assign(m, {});
    q.xc.assign(m, {});
    q.bary.assign(m, {});
    old = std::move(q);
  };
  // every wall kind: its candidates, merged into its contact set
  auto kind = [&](WallContacts& wc, const ContactFamilyParams& fam, auto geometry) {
    std::vector<WallCand> cands;
    geometry.candidates(cands);
    merge(wc, cands, fam, [&](std::uint32_t w) { return geometry.wall_id(w); });
  };
  kind(plc_, p_.ball_wall, PlaneGeometry{*this});
  kind(fcc_, p_.ball_facet, FacetGeometry{*this});
  kind(ftc_, p_.ball_footing, FootingGeometry{*this});
}

// One ball against a wall (platen, footing or facet) whose surface point moves at v_wall and
// spins at w_wall (0 for the rigid walls): contact kinematics at the middle of the overlap
// (docs/theory.md 1.4-1.5), the family's law, and the per-contact results stored in wc. Returns the
// force on the wall.
template <class Law>
Vec3 wall_contact(const Particles& pt, WallContacts& wc, std::int64_t c, const Vec3& n, double dist,
                  const Vec3& v_wall, const Vec3& w_wall, const LawConst& lc, double dt) {
  const std::uint32_t i = wc.ball[c];
  Kin k;
  k.n = n;
  k.gap = dist - pt.r[i];
  const Vec3 la = (pt.r[i] + 0.5 * k.gap) * n;
  const Vec3 vr = v_wall - (pt.v[i] + cross(pt.w[i], la));
  k.du = vr * dt;
  k.dtheta = (w_wall - pt.w[i]) * dt;
  k.wmean = 0.5 * (pt.w[i] + w_wall);
  k.dt = dt;
  if constexpr (Law::kNeedsReff) k.reff = pt.r[i];
  Vec3 Mo;
  const Vec3 F = Law::update(k, wc.h[c], wc.bond.empty() ? nullptr : &wc.bond[c], lc, Mo);
  wc.F[c] = F;
  wc.M[c] = Mo;
  wc.TA[c] = cross(F, la) - Mo;
  wc.xc[c] = pt.x[i] + la;
  return F;
}

template <class Law, class Geom>
void World::wall_set_pass(WallContacts& wc, const ContactFamilyParams& fam, Geom& g, double dt) {
  const LawConst lc = law_const(fam, true);
  const std::int64_t m = static_cast<std::int64_t>(wc.size());
  g.begin();
  auto one = [&](std::int64_t c) {
    const WallSurface s = g.surface(pt_.x[wc.ball[c]], wc, c);
    wc.facet[c] = s.facet;
    wc.bary[c] = s.bary;
    wall_contact<Law>(pt_, wc, c, s.n, s.dist, s.v, s.w, lc, dt);
    g.after_law(wc, c);
  };
  if constexpr (Geom::kParallel) {
    const int nt = thread_count();
    // Each contact writes only its own records, so the split changes no bit; a few hundred
    // contacts (the interface facets of a coupled block) already pay for the fork.
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1 && m > 256)
    for (std::int64_t c = 0; c < m; ++c) one(c);
  } else {
    for (std::int64_t c = 0; c < m; ++c) one(c);
  }
  for (std::int64_t c = 0; c < m; ++c) g.add(wc, c);
  g.end(wc);
}

// The wall kinds of the force pass, each timed in its phase (World::phase_times).
void World::wall_passes(double dt) {
  detail::Lap lap;
  if (!planes_.empty()) {
    PlaneGeometry g{*this};
    visit_law(p_.ball_wall.model, [&](auto law) { wall_set_pass<decltype(law)>(plc_, p_.ball_wall, g, dt); });
    lap(times_.plane);
  }
  if (!fwalls_.empty()) {
    FacetGeometry g{*this};
    visit_law(p_.ball_facet.model, [&](auto law) { wall_set_pass<decltype(law)>(fcc_, p_.ball_facet, g, dt); });
    lap(times_.facet);
  }
  if (footing_.enabled) {
    FootingGeometry g{*this};
    visit_law(p_.ball_footing.model, [&](auto law) { wall_set_pass<decltype(law)>(ftc_, p_.ball_footing, g, dt); });
    lap(times_.footing);
  } else {
    footing_.reaction = Vec3{};
  }
}

std::size_t World::bond_ball_facet(double hi) {
  if (!law_has_bond(p_.ball_facet.model))
    throw std::invalid_argument(std::string("bond_ball_facet: family 'ball_facet' uses model '") +
                                law_name(p_.ball_facet.model) +
                                "', which cannot bond; set ball_facet.model to 'pbond' (the paper's interface, §2.6).");
  if (!prepared_) prepare();
  std::size_t cnt = 0;
  for (std::size_t c = 0; c < fcc_.size(); ++c) {
    BondHist& b = fcc_.bond[c];
    if (b.state != BondState::kNeverBonded) continue;
    const FacetWall& fw = fwalls_[fcc_.wall[c]];
    double best = std::numeric_limits<double>::infinity();
    Vec3 n{};
    for (std::uint32_t k = fcc_.cand_off[c]; k < fcc_.cand_off[c + 1]; ++k) {
      Vec3 nn, ww;
      const double d = facet_distance(pt_.x[fcc_.ball[c]], fw, fcc_.cand[k], nn, ww);
      if (d < best) { best = d; n = nn; }
    }
    if (best - pt_.r[fcc_.ball[c]] > hi) continue;
    b.state = BondState::kIntact;
    ContactHist& h = fcc_.h[c];
    h.flags |= ContactHist::kIncremental | ContactHist::kHasNormal;
    h.n_old = n;
    visit_law(p_.ball_facet.model, [&](auto law) { decltype(law)::install_bond(h, b, p_.ball_facet); });
    ++cnt;
  }
  last_dt_step_ = -1;
  return cnt;
}

}  // namespace demfdm::dem
