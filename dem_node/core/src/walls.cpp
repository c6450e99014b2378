// The wall-contact set of World (wall_set.hpp; docs/theory.md 1.4, 6.2-6.5): the wall kinds as
// geometries, their candidate search and history merge at a rebuild, the per-contact law and
// the pass over a kind's contacts, the bonding of balls to interface facets (2.6), and World's
// wall API.
#include <omp.h>

#include <algorithm>
#include <array>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>

#include "demfdm/dem/geometry.hpp"
#include "demfdm/dem/world.hpp"
#include "wall_set.hpp"
#include "world_detail.hpp"

namespace demfdm::dem {

using detail::facet_distance;
using detail::plane_distance;
using detail::WallCand;

// ------------------------------------------------------------------------------------------
// planes

void PlaneKind::begin(const SetContext&, const WallContacts&) {
  for (auto& pw : walls) { pw.reaction = Vec3{}; pw.k_sum = 0.0; }
}

WallSurface PlaneKind::surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const {
  const PlaneWall& pw = walls[wc.wall[c]];
  WallSurface s;
  s.dist = plane_distance(x, pw, s.n);
  s.v = pw.p.velocity;
  s.facet = wc.facet[c];
  s.bary = wc.bary[c];
  return s;
}

WallSumRec PlaneKind::rec(const WallContacts& wc, std::int64_t c) {
  WallSumRec r;
  r.wall = wc.wall[c];
  r.F = wc.F[c];
  r.active = (wc.h[c].flags & ContactHist::kActive) != 0;
  r.k = wc.h[c].kn;
  return r;
}

void PlaneKind::add(const WallSumRec& r) {
  PlaneWall& pw = walls[r.wall];
  pw.reaction += r.F;
  if (r.active) pw.k_sum += r.k;
}

void PlaneKind::candidates(const SetContext& cx, std::vector<WallCand>& cands) {
  const auto& pt = cx.pt;
  for (std::size_t w = 0; w < walls.size(); ++w) {
    for (std::size_t i = 0; i < pt.size(); ++i) {
      if (cx.ghost && cx.ghost[i]) continue;  // a ghost's wall contacts are its owner's
      Vec3 nn;
      const double d = plane_distance(pt.x[i], walls[w], nn);
      if (d - pt.r[i] < cx.skin + cx.p.ball_wall.linear.rgap)
        cands.push_back({static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(w), 0});
    }
    walls[w].disp = Vec3{};
  }
}

void PlaneKind::move(double dt) {
  for (auto& pw : walls) {
    pw.p.point += dt * pw.p.velocity;
    pw.disp += dt * pw.p.velocity;
  }
}

double PlaneKind::travel() const {
  double dw = 0.0;
  for (const auto& pw : walls) dw = std::max(dw, norm(pw.disp));
  return dw;
}

// ------------------------------------------------------------------------------------------
// interface facets

void FacetKind::begin(const SetContext& cx, const WallContacts& wc) {
  restore_linear = cx.p.ball_facet.model == ContactModel::kLinearPBond && cx.p.ball_facet.pbond.zero_linear &&
                   !wc.bond.empty();
  terms.resize(wc.size());
}

WallSurface FacetKind::surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const {
  const FacetWall& fw = walls[wc.wall[c]];
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
namespace {
WallSumRec facet_rec(const SetContext& cx, const WallContacts& wc, std::int64_t c);
FacetTerm facet_term(const std::vector<FacetWall>& walls, const WallSumRec& r);
}  // namespace

// (Then the contact's share of the vertex sums, from its final state of this pass.)
void FacetKind::after_law(const SetContext& cx, WallContacts& wc, std::int64_t c) {
  if (restore_linear && wc.h[c].kn == 0.0 &&
      (wc.bond[c].state == BondState::kBrokenTension || wc.bond[c].state == BondState::kBrokenShear))
    detail::init_contact(cx.pt, wc.ball[c], 0, wc.h[c], &wc.bond[c], cx.p.ball_facet, true);
  terms[static_cast<std::size_t>(c)] = facet_term(walls, facet_rec(cx, wc, c));
}

namespace {

// §6.4 equivalent vertex forces and §6.5 stiffness of one contact, from its WallSumRec (its
// wall, facet, F, M, x_c, weights and K, whether it acts), as the force pass forms them
// (FacetKind::after_law; World::facet_sum_shares passes them on).
FacetTerm facet_term(const std::vector<FacetWall>& walls, const WallSumRec& r) {
  FacetTerm t;
  if (!r.active) return t;
  t.active = true;
  t.wall = r.wall;
  t.facet = r.facet;
  const FacetWall& fw = walls[r.wall];
  const auto& tr = fw.tri[static_cast<std::size_t>(r.facet)];
  t.loaded = norm2(r.F) > 0.0 || norm2(r.M) > 0.0;
  if (t.loaded) {
    facet_equivalent_forces({fw.pos[tr[0]], fw.pos[tr[1]], fw.pos[tr[2]]}, r.xc, r.F, r.M, t.f);
    t.F = r.F;
  }
  for (int v = 0; v < 3; ++v) t.k[v] = r.bary[v] * r.k;
  return t;
}

void facet_zero(std::vector<FacetWall>& walls) {
  for (auto& fw : walls) {
    std::fill(fw.vforce.begin(), fw.vforce.end(), Vec3{});
    std::fill(fw.vstiff.begin(), fw.vstiff.end(), 0.0);
    fw.total_force = Vec3{};
  }
}

// A contact's share added to its wall's sums; in contact order, each sum's additions are those
// of one serial loop over the contacts.
void facet_add(std::vector<FacetWall>& walls, const FacetTerm& t) {
  if (!t.active) return;
  FacetWall& fw = walls[t.wall];
  const auto& tr = fw.tri[static_cast<std::size_t>(t.facet)];
  if (t.loaded) {
    for (int v = 0; v < 3; ++v) fw.vforce[tr[v]] += t.f[v];
    fw.total_force += t.F;
  }
  for (int v = 0; v < 3; ++v) fw.vstiff[tr[v]] += t.k[v];
}

// A facet contact's share: it acts while it carries a force or is bonded; K = K_n + K_s, plus
// the parallel bond's stiffness.
WallSumRec facet_rec(const SetContext& cx, const WallContacts& wc, std::int64_t c) {
  WallSumRec r;
  const bool bd = !wc.bond.empty() && bonded(wc.bond[c].state);
  r.active = (wc.h[c].flags & ContactHist::kActive) || bd;
  if (!r.active) return r;
  r.wall = wc.wall[c];
  r.facet = wc.facet[c];
  r.kind = 1;
  r.F = wc.F[c];
  r.M = wc.M[c];
  r.xc = wc.xc[c];
  r.bary = wc.bary[c];
  double K = wc.h[c].kn + wc.h[c].ks;
  if (bd && cx.p.ball_facet.model == ContactModel::kLinearPBond)
    K += wc.bond[c].kn * (1.0 + 1.0 / cx.p.ball_facet.pbond.kratio) * wc.bond[c].area();
  r.k = K;
  return r;
}

}  // namespace

// The shares formed by after_law, added in contact order.
void FacetKind::end(const SetContext&, WallContacts& wc) {
  facet_zero(walls);
  for (std::size_t c = 0; c < wc.size(); ++c) facet_add(walls, terms[c]);
}

// every facet against every ball near its bounding box (sorted by x for a cheap sweep);
// candidates within R + skin
void FacetKind::candidates(const SetContext& cx, std::vector<WallCand>& cands) {
  if (walls.empty()) return;
  const auto& pt = cx.pt;
  const std::size_t n = pt.size();
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  std::sort(order.begin(), order.end(), [&](std::uint32_t a, std::uint32_t b) { return pt.x[a].x < pt.x[b].x; });
  std::vector<double> xs(n);
  for (std::size_t k = 0; k < n; ++k) xs[k] = pt.x[order[k]].x;
  double rmax = 0.0;
  for (double r : pt.r) rmax = std::max(rmax, r);
  const double reach = rmax + cx.skin + cx.p.ball_facet.linear.rgap;
  for (std::size_t w = 0; w < walls.size(); ++w) {
    const auto& fw = walls[w];
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
        if (cx.ghost && cx.ghost[i]) continue;
        const Vec3& x = pt.x[i];
        if (x.y < lo.y - reach || x.y > hi.y + reach || x.z < lo.z - reach || x.z > hi.z + reach) continue;
        Vec3 nn, ww;
        const double d = facet_distance(x, fw, t, nn, ww);
        if (d - pt.r[i] < cx.skin + cx.p.ball_facet.linear.rgap)
          cands.push_back({i, static_cast<std::uint32_t>(w), static_cast<std::int32_t>(t)});
      }
    }
  }
  for (auto& fw : walls) fw.pos_ref = fw.pos;
}

double FacetKind::travel() const {
  double dw = 0.0;
  for (const auto& fw : walls)
    for (std::size_t i = 0; i < fw.pos.size(); ++i) dw = std::max(dw, norm(fw.pos[i] - fw.pos_ref[i]));
  return dw;
}

// §6.2 facet normal and kinematic spin ω_f = ω_⊥ + ω_n n̂ from the vertex velocities.
void FacetKind::update_spin(FacetWall& fw, bool spin) {
  for (std::size_t t = 0; t < fw.tri.size(); ++t) {
    const auto& tr = fw.tri[t];
    const Vec3 e1 = fw.pos[tr[1]] - fw.pos[tr[0]], e2 = fw.pos[tr[2]] - fw.pos[tr[0]];
    Vec3 n = cross(e1, e2);
    const double nn = norm(n);
    if (!(nn > 0.0)) throw std::invalid_argument("facet wall: degenerate triangle (zero area).");
    n *= 1.0 / nn;
    fw.tri_normal[t] = n;
    if (!spin) { fw.tri_spin[t] = Vec3{}; continue; }
    const Vec3 d1 = fw.vel[tr[1]] - fw.vel[tr[0]], d2 = fw.vel[tr[2]] - fw.vel[tr[0]];
    // L_s = Ė (EᵀE)⁻¹ Eᵀ
    const double g11 = dot(e1, e1), g12 = dot(e1, e2), g22 = dot(e2, e2);
    const double det = g11 * g22 - g12 * g12;
    const double i11 = g22 / det, i12 = -g12 / det, i22 = g11 / det;
    auto Ls = [&](const Vec3& x) {  // L_s x
      const double a1 = dot(e1, x), a2 = dot(e2, x);
      const double c1 = i11 * a1 + i12 * a2, c2 = i12 * a1 + i22 * a2;
      return c1 * d1 + c2 * d2;
    };
    auto LsT = [&](const Vec3& y) {  // L_sᵀ y = E (EᵀE)⁻¹ Ėᵀ y
      const double b1 = dot(d1, y), b2 = dot(d2, y);
      const double c1 = i11 * b1 + i12 * b2, c2 = i12 * b1 + i22 * b2;
      return c1 * e1 + c2 * e2;
    };
    Vec3 nd = -LsT(n);
    nd -= dot(nd, n) * n;
    const Vec3 t1 = e1 * (1.0 / norm(e1));
    const Vec3 t2 = cross(n, t1);
    const double wn = 0.5 * (dot(t2, Ls(t1)) - dot(t1, Ls(t2)));
    fw.tri_spin[t] = cross(n, nd) + wn * n;
  }
}

std::size_t FacetKind::bond(const SetContext& cx, WallContacts& wc, double hi) const {
  std::size_t cnt = 0;
  for (std::size_t c = 0; c < wc.size(); ++c) {
    BondHist& b = wc.bond[c];
    if (b.state != BondState::kNeverBonded) continue;
    const FacetWall& fw = walls[wc.wall[c]];
    double best = std::numeric_limits<double>::infinity();
    Vec3 n{};
    for (std::uint32_t k = wc.cand_off[c]; k < wc.cand_off[c + 1]; ++k) {
      Vec3 nn, ww;
      const double d = facet_distance(cx.pt.x[wc.ball[c]], fw, wc.cand[k], nn, ww);
      if (d < best) { best = d; n = nn; }
    }
    if (best - cx.pt.r[wc.ball[c]] > hi) continue;
    b.state = BondState::kIntact;
    ContactHist& h = wc.h[c];
    h.flags |= ContactHist::kIncremental | ContactHist::kHasNormal;
    h.n_old = n;
    visit_law(cx.p.ball_facet.model, [&](auto law) { decltype(law)::install_bond(h, b, cx.p.ball_facet); });
    ++cnt;
  }
  return cnt;
}

// ------------------------------------------------------------------------------------------
// footing

WallSurface FootingKind::surface(const Vec3& x, const WallContacts& wc, std::int64_t c) const {
  WallSurface s;
  Vec3 q;
  s.dist = closest_point_cylinder(x, ft.p.bottom_centre, 0.5 * ft.p.diameter, ft.p.height, q, s.n);
  s.v = ft.p.velocity;
  s.facet = wc.facet[c];
  s.bary = wc.bary[c];
  return s;
}

void FootingKind::candidates(const SetContext& cx, std::vector<WallCand>& cands) {
  if (!ft.enabled) return;
  const auto& pt = cx.pt;
  const double R = 0.5 * ft.p.diameter;
  for (std::size_t i = 0; i < pt.size(); ++i) {
    if (cx.ghost && cx.ghost[i]) continue;
    Vec3 q, nn;
    const double d = closest_point_cylinder(pt.x[i], ft.p.bottom_centre, R, ft.p.height, q, nn);
    if (d - pt.r[i] < cx.skin + cx.p.ball_footing.linear.rgap) cands.push_back({static_cast<std::uint32_t>(i), 0, 0});
  }
  ft.disp = Vec3{};
}

void FootingKind::move(double dt) {
  if (!ft.enabled) return;
  ft.p.bottom_centre += dt * ft.p.velocity;
  ft.disp += dt * ft.p.velocity;
}

double FootingKind::travel() const { return ft.enabled ? norm(ft.disp) : 0.0; }

// ------------------------------------------------------------------------------------------
// the set: one template for every kind

namespace {

// Reorder a rebuilt list (ball, wall, candidates, facet, history, bond) by (ball, wall).
void sort_by_ball(WallContacts& q) {
  const std::size_t m = q.ball.size();
  std::vector<std::uint32_t> o(m);
  std::iota(o.begin(), o.end(), 0u);
  std::stable_sort(o.begin(), o.end(), [&](std::uint32_t x, std::uint32_t y) {
    return std::tie(q.ball[x], q.wall[x]) < std::tie(q.ball[y], q.wall[y]);
  });
  WallContacts s;
  s.cand_off.push_back(0);
  const bool has_bond = !q.bond.empty();
  for (std::uint32_t c : o) {
    s.ball.push_back(q.ball[c]);
    s.wall.push_back(q.wall[c]);
    s.cand.insert(s.cand.end(), q.cand.begin() + q.cand_off[c], q.cand.begin() + q.cand_off[c + 1]);
    s.cand_off.push_back(static_cast<std::uint32_t>(s.cand.size()));
    s.facet.push_back(q.facet[c]);
    s.h.push_back(q.h[c]);
    if (has_bond) s.bond.push_back(q.bond[c]);
  }
  q = std::move(s);
}

}  // namespace

template <class Kind>
void WallSet<Kind>::rebuild(SetContext& cx) {
  std::vector<WallCand> cands;
  kind.candidates(cx, cands);
  const ContactFamilyParams& fam = cx.p.*Kind::kFamily;
  WallContacts& old = contacts;
  const bool has_bond = law_has_bond(fam.model);
  detail::HistoryCarry carry(old.size(), false, [&](std::size_t c) {
    return std::make_pair(std::uint64_t(cx.pt.id[old.ball[c]]), std::uint64_t(kind.wall_id(old.wall[c])));
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
    const std::int64_t found = carry.take(cx.pt.id[e.ball], kind.wall_id(e.wall));
    if (found >= 0) {
      const auto oc = static_cast<std::size_t>(found);
      q.h.push_back(old.h[oc]);
      if (has_bond) q.bond.push_back(old.bond[oc]);
      if (!old.facet.empty()) keep_facet = old.facet[oc];
    } else {
      q.h.push_back({});
      if (has_bond) q.bond.push_back({});
      detail::init_contact(cx.pt, e.ball, 0, q.h.back(), has_bond ? &q.bond.back() : nullptr, fam, true);
    }
    q.facet.push_back(keep_facet);
    k = k2;
  }
  // bonded wall contacts never disappear: keep them with their last facet as candidate, then
  // sort them in by (ball, wall), so that the list's order is fixed by its contacts alone (the
  // order that a rank of the DEM on MPI ranks merges in, World::set_wall_sums)
  const std::size_t kept = q.ball.size();
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
      cx.e_slip_dead, cx.e_soft_dead, [](std::size_t) { return true; });  // a ghost row has no wall contact
  if (q.ball.size() > kept) sort_by_ball(q);
  const std::size_t m = q.ball.size();
  q.F.assign(m, {});
  q.M.assign(m, {});
  q.TA.assign(m, {});
  q.xc.assign(m, {});
  q.bary.assign(m, {});
  old = std::move(q);
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

template <class Kind>
void WallSet<Kind>::pass(SetContext& cx, double dt) {
  const ContactFamilyParams& fam = cx.p.*Kind::kFamily;
  visit_law(fam.model, [&](auto law) { pass_law<decltype(law)>(cx, fam, dt, nullptr); });
}

template <class Kind>
void WallSet<Kind>::pass_hosted(SetContext& cx, double dt, const std::function<void(SideWork&)>& host)
  requires Kind::kParallel
{
  const ContactFamilyParams& fam = cx.p.*Kind::kFamily;
  visit_law(fam.model, [&](auto law) { pass_law<decltype(law)>(cx, fam, dt, &host); });
}

template <class Kind>
template <class Law>
void WallSet<Kind>::pass_law(SetContext& cx, const ContactFamilyParams& fam, double dt,
                             const std::function<void(SideWork&)>* host) {
  const LawConst lc = detail::law_const(fam, cx.p.rescale_shear, true);
  WallContacts& wc = contacts;
  const std::int64_t m = static_cast<std::int64_t>(wc.size());
  kind.begin(cx, wc);
  // Vectorised blocks (pair_block.hpp WallIn) where the law has a wall lane kernel: stage 1 finds
  // each contact's surface (scalar), stage 2 runs the kinematics of wall_contact and the law per
  // lane, stage 3 stores the lanes (a lane the kernel marks is redone by the scalar law from its
  // untouched history) and runs after_law. Each contact writes only its own records, as below,
  // so the results are the scalar loop's bits (tests/dem/simd_kernel_test.cpp).
  pairblock::WallFn kern = nullptr;
  {
    pairblock::Isa isa;
    if (detail::block_isa(cx.kernel, isa)) kern = Law::wall_lane_kernel(isa, lc);
    if (Law::kBond && wc.bond.size() != wc.size()) kern = nullptr;
  }
  auto one = [&](std::int64_t c) {
    const WallSurface s = kind.surface(cx.pt.x[wc.ball[c]], wc, c);
    wc.facet[c] = s.facet;
    wc.bary[c] = s.bary;
    wall_contact<Law>(cx.pt, wc, c, s.n, s.dist, s.v, s.w, lc, dt);
    kind.after_law(cx, wc, c);
  };
  constexpr int K = pairblock::kLanes;
  const pairblock::WallCtx ctx{{cx.pt.v.data(), cx.pt.w.data(), cx.pt.r.data(), wc.h.data(),
                                wc.bond.empty() ? nullptr : wc.bond.data(), lc, dt, Vec3{}, false},
                               cx.pt.x.data()};
  auto block = [&](std::int64_t c0) {
    const int n = static_cast<int>(std::min<std::int64_t>(K, m - c0));
    pairblock::WallIn in;
    pairblock::Out out;
    pairblock::WallOut wo;
    in.n = n;
    for (int l = 0; l < K; ++l) {
      const std::int64_t c = c0 + (l < n ? l : 0);  // padding lanes repeat lane 0
      const std::uint32_t i = wc.ball[c];
      const std::uint8_t fl = wc.h[c].flags;
      in.c[l] = c;
      in.a[l] = i;
      in.hasn[l] = (fl & ContactHist::kHasNormal) != 0;
      in.incr[l] = (fl & ContactHist::kIncremental) != 0;
      const BondHist* bd = wc.bond.empty() ? nullptr : &wc.bond[c];
      if constexpr (Law::kBond) in.intact[l] = bd->state == BondState::kIntact;
      else in.intact[l] = 0;
      in.scalar[l] = Law::lane_needs_scalar(bd);
      if (l >= n) {
        in.nx[l] = in.nx[0], in.ny[l] = in.ny[0], in.nz[l] = in.nz[0], in.dist[l] = in.dist[0];
        in.vx[l] = in.vx[0], in.vy[l] = in.vy[0], in.vz[l] = in.vz[0];
        in.wx[l] = in.wx[0], in.wy[l] = in.wy[0], in.wz[l] = in.wz[0];
        continue;
      }
      const WallSurface s = kind.surface(cx.pt.x[i], wc, c);
      wc.facet[c] = s.facet;
      wc.bary[c] = s.bary;
      in.nx[l] = s.n.x, in.ny[l] = s.n.y, in.nz[l] = s.n.z, in.dist[l] = s.dist;
      in.vx[l] = s.v.x, in.vy[l] = s.v.y, in.vz[l] = s.v.z;
      in.wx[l] = s.w.x, in.wy[l] = s.w.y, in.wz[l] = s.w.z;
    }
    kern(ctx, in, out, wo);
    for (int l = 0; l < n; ++l) {
      const std::int64_t c = in.c[l];
      if (in.scalar[l] || out.scalar[l]) {
        wall_contact<Law>(cx.pt, wc, c, Vec3{in.nx[l], in.ny[l], in.nz[l]}, in.dist[l],
                          Vec3{in.vx[l], in.vy[l], in.vz[l]}, Vec3{in.wx[l], in.wy[l], in.wz[l]}, lc, dt);
      } else {
        Law::store_lane(wc.h[c], wc.bond.empty() ? nullptr : &wc.bond[c], out, l);
        wc.F[c] = {out.F[0][l], out.F[1][l], out.F[2][l]};
        wc.M[c] = {wo.M[0][l], wo.M[1][l], wo.M[2][l]};
        wc.TA[c] = {out.TA[0][l], out.TA[1][l], out.TA[2][l]};
        wc.xc[c] = {wo.xc[0][l], wo.xc[1][l], wo.xc[2][l]};
      }
      kind.after_law(cx, wc, c);
    }
  };
  // Units of K contacts: a lane block, or K contacts one by one. Each contact writes only its own
  // records, so the units may run in any order, on any threads, without changing a bit: in a
  // parallel loop (kinds with kParallel, from a few hundred contacts, the interface facets of a
  // coupled block, which already pay for the fork), else in order, or by `host` (pass_hosted).
  auto unit = [&](std::int64_t u) {
    if (kern) {
      block(u * K);
    } else {
      for (std::int64_t c = u * K, e = std::min(m, c + K); c < e; ++c) one(c);
    }
  };
  SideWork w;
  w.units = (m + K - 1) / K;
  w.run = [](void* p, std::int64_t u) { (*static_cast<decltype(unit)*>(p))(u); };
  w.ctx = &unit;
  w.parallel = Kind::kParallel && m > 256;
  if (host) {
    (*host)(w);
  } else {
    run_side_work(w, cx.threads);
  }
  for (std::int64_t c = 0; c < m; ++c) kind.add(Kind::rec(wc, c));
  kind.end(cx, wc);
}

// Wall contacts act on balls after the ball–ball pass, serially in contact order.
template <class Kind>
void WallSet<Kind>::gather(Particles& pt) const {
  Vec3* f = pt.f.data();
  Vec3* t = pt.t.data();
  const WallContacts& wc = contacts;
  for (std::size_t c = 0; c < wc.size(); ++c) {
    f[wc.ball[c]] -= wc.F[c];
    t[wc.ball[c]] += wc.TA[c];
  }
}

template <class Kind>
void WallSet<Kind>::add_force_norms(double& sum, std::size_t& count) const {
  for (std::size_t c = 0; c < contacts.size(); ++c) {
    const double f = norm(contacts.F[c]);
    if (f > 0.0) { sum += f; ++count; }
  }
}

template <class Kind>
void WallSet<Kind>::add_stiffness(const SetContext& cx, double* kt, double* kr) const {
  const ContactFamilyParams& fam = cx.p.*Kind::kFamily;
  const WallContacts& wc = contacts;
  visit_law(fam.model, [&](auto law) {
    using L = decltype(law);
    for (std::size_t c = 0; c < wc.size(); ++c) {
      const ContactHist& h = wc.h[c];
      const BondHist* b = wc.bond.empty() ? nullptr : &wc.bond[c];
      if (!(h.flags & ContactHist::kActive) && !(b && bonded(b->state))) continue;
      const std::uint32_t i = wc.ball[c];
      const ContactStiffness s = L::stiffness(h, b, fam, cx.pt.r[i], 0.0);
      kt[i] += s.k;
      kr[i] += s.krot + s.ks * cx.pt.r[i] * cx.pt.r[i];
    }
  });
}

template <class Kind>
void WallSet<Kind>::add_energy(Energy& e, const WorldParams& p, const std::vector<std::uint8_t>& ghost) const {
  detail::add_contact_energy(e, contacts.h, contacts.bond, p.*Kind::kFamily, contacts.ball, ghost);
}

template <class Kind>
void WallSet<Kind>::remap(const std::vector<std::uint32_t>& new_row) {
  for (auto& b : contacts.ball) b = new_row[b];
}

template <class Kind>
void WallSet<Kind>::refresh(const SetContext& cx) {
  const ContactFamilyParams& fam = cx.p.*Kind::kFamily;
  const bool bd = law_has_bond(fam.model);
  WallContacts& wc = contacts;
  for (std::size_t c = 0; c < wc.size(); ++c)
    detail::init_contact(cx.pt, wc.ball[c], 0, wc.h[c], bd ? &wc.bond[c] : nullptr, fam, true);
}

template class WallSet<PlaneKind>;
template class WallSet<FacetKind>;
template class WallSet<FootingKind>;

// ------------------------------------------------------------------------------------------
// World's wall API

int World::add_plane(const PlaneWallParams& p) {
  PlaneWall w;
  w.p = p;
  const double nn = norm(p.normal);
  if (!(nn > 0.0)) throw std::invalid_argument("add_plane: 'normal' must be a non-zero vector.");
  w.p.normal = p.normal * (1.0 / nn);
  Vec3 a1 = p.axis1 - dot(p.axis1, w.p.normal) * w.p.normal;
  if (norm(a1) < 1e-12) a1 = std::abs(w.p.normal.x) < 0.9 ? Vec3{1, 0, 0} : Vec3{0, 1, 0};
  a1 = a1 - dot(a1, w.p.normal) * w.p.normal;
  w.p.axis1 = a1 * (1.0 / norm(a1));
  w.axis2 = cross(w.p.normal, w.p.axis1);
  if (p.half1 < 0.0 || p.half2 < 0.0)
    throw std::invalid_argument("add_plane: 'half1' and 'half2' must be >= 0 m (0 = infinite).");
  w.id = next_wall_id_++;
  planes_->kind.walls.push_back(w);
  dirty_ = true;
  return num_planes() - 1;
}

PlaneWall& World::plane(int i) { return planes_->kind.walls[static_cast<std::size_t>(i)]; }
const PlaneWall& World::plane(int i) const { return planes_->kind.walls[static_cast<std::size_t>(i)]; }
int World::num_planes() const { return static_cast<int>(planes_->kind.walls.size()); }

int World::add_facet_wall(std::span<const double> vertices, std::span<const std::int32_t> triangles) {
  if (vertices.size() % 3 != 0 || triangles.size() % 3 != 0 || triangles.empty()) {
    std::ostringstream s;
    s << "add_facet_wall: 'vertices' and 'triangles' must be non-empty flat [n,3] arrays, found "
      << vertices.size() << " and " << triangles.size() << " values.";
    throw std::invalid_argument(s.str());
  }
  FacetWall fw;
  const std::size_t nv = vertices.size() / 3;
  for (std::size_t i = 0; i < nv; ++i)
    fw.pos.push_back({vertices[3 * i], vertices[3 * i + 1], vertices[3 * i + 2]});
  fw.vel.assign(nv, Vec3{});
  for (std::size_t t = 0; t < triangles.size() / 3; ++t) {
    std::array<std::int32_t, 3> tr{triangles[3 * t], triangles[3 * t + 1], triangles[3 * t + 2]};
    for (auto v : tr)
      if (v < 0 || static_cast<std::size_t>(v) >= nv) {
        std::ostringstream s;
        s << "add_facet_wall: triangle " << t << " has vertex index " << v << ", expected [0, "
          << nv << ").";
        throw std::invalid_argument(s.str());
      }
    fw.tri.push_back(tr);
  }
  fw.pos_ref = fw.pos;
  fw.vforce.assign(nv, Vec3{});
  fw.vstiff.assign(nv, 0.0);
  fw.tri_normal.resize(fw.tri.size());
  fw.tri_spin.assign(fw.tri.size(), Vec3{});
  fw.id = next_wall_id_++;
  auto& walls = facets_->kind.walls;
  walls.push_back(std::move(fw));
  FacetKind::update_spin(walls.back(), p_.facet_spin);
  dirty_ = true;
  return static_cast<int>(walls.size()) - 1;
}

void World::set_vertex_kinematics(int wall, std::span<const double> pos, std::span<const double> vel) {
  if (wall < 0 || wall >= num_facet_walls())
    throw std::invalid_argument("set_vertex_kinematics: 'wall' index out of range.");
  FacetWall& fw = facet_wall(wall);
  if (pos.size() != 3 * fw.pos.size() || vel.size() != 3 * fw.pos.size()) {
    std::ostringstream s;
    s << "set_vertex_kinematics: 'pos' and 'vel' must hold " << 3 * fw.pos.size()
      << " values (nv*3), found " << pos.size() << " and " << vel.size() << ".";
    throw std::invalid_argument(s.str());
  }
  for (std::size_t i = 0; i < fw.pos.size(); ++i) {
    fw.pos[i] = {pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]};
    fw.vel[i] = {vel[3 * i], vel[3 * i + 1], vel[3 * i + 2]};
  }
  FacetKind::update_spin(fw, p_.facet_spin);
}

std::span<const double> World::vertex_forces(int wall) const {
  const auto& fw = facets_->kind.walls.at(static_cast<std::size_t>(wall));
  return {reinterpret_cast<const double*>(fw.vforce.data()), 3 * fw.vforce.size()};
}
std::span<const double> World::vertex_stiffness(int wall) const {
  const auto& fw = facets_->kind.walls.at(static_cast<std::size_t>(wall));
  return {fw.vstiff.data(), fw.vstiff.size()};
}
Vec3 World::facet_wall_force(int wall) const {
  return facets_->kind.walls.at(static_cast<std::size_t>(wall)).total_force;
}
Vec3 World::facet_walls_total_force() const {
  Vec3 s{};
  for (const auto& fw : facets_->kind.walls) s += fw.total_force;
  return s;
}
FacetWall& World::facet_wall(int i) { return facets_->kind.walls[static_cast<std::size_t>(i)]; }
const FacetWall& World::facet_wall(int i) const { return facets_->kind.walls[static_cast<std::size_t>(i)]; }
int World::num_facet_walls() const { return static_cast<int>(facets_->kind.walls.size()); }

void World::set_footing(const FootingParams& p) {
  if (!(p.diameter > 0.0) || !(p.height > 0.0)) {
    std::ostringstream s;
    s << "set_footing: 'diameter' and 'height' must be > 0 m, found " << p.diameter << " and "
      << p.height << ".";
    throw std::invalid_argument(s.str());
  }
  Footing& ft = footing_->kind.ft;
  ft.p = p;
  if (!ft.enabled) ft.id = next_wall_id_++;
  ft.enabled = true;
  dirty_ = true;
}
void World::remove_footing() {
  footing_->kind.ft.enabled = false;
  dirty_ = true;
}
void World::set_footing_position(const Vec3& c) {
  Footing& ft = footing_->kind.ft;
  ft.disp += c - ft.p.bottom_centre;
  ft.p.bottom_centre = c;
}
bool World::has_footing() const { return footing_->kind.ft.enabled; }
void World::set_footing_velocity(const Vec3& v) { footing_->kind.ft.p.velocity = v; }
const Footing& World::footing() const { return footing_->kind.ft; }
Vec3 World::footing_reaction() const { return footing_->kind.ft.reaction; }

void World::copy_walls(const World& o) {
  if (o.num_planes() != num_planes() || o.num_facet_walls() != num_facet_walls())
    throw std::invalid_argument("World::copy_walls: the worlds have different walls");
  planes_->kind.walls = o.planes_->kind.walls;
  facets_->kind.walls = o.facets_->kind.walls;
  footing_->kind.ft = o.footing_->kind.ft;
}

void World::wall_sum_records(std::vector<WallSumRec>& out) const {
  auto ids = [&](const WallContacts& wc, std::size_t c, WallSumRec r, std::uint8_t kind) {
    r.ball = pt_.id[wc.ball[c]];
    r.wall = wc.wall[c];
    r.kind = kind;
    out.push_back(r);
  };
  const WallContacts& pc = planes_->contacts;
  for (std::size_t c = 0; c < pc.size(); ++c) ids(pc, c, PlaneKind::rec(pc, static_cast<std::int64_t>(c)), 0);
  const WallContacts& gc = footing_->contacts;
  for (std::size_t c = 0; c < gc.size(); ++c) ids(gc, c, FootingKind::rec(gc, static_cast<std::int64_t>(c)), 2);
}

void World::set_wall_sums(std::span<const WallSumRec> recs) {
  std::size_t k1 = 0;
  while (k1 < recs.size() && recs[k1].kind == 0) ++k1;
  for (std::size_t k = k1; k < recs.size(); ++k)
    if (recs[k].kind != 2)
      throw std::invalid_argument("set_wall_sums: the records must be the planes' (kind 0), then the footing's (kind 2).");
  const SetContext cx = context();
  if (planes_->present()) {
    planes_->kind.begin(cx, planes_->contacts);
    for (std::size_t k = 0; k < k1; ++k) planes_->kind.add(recs[k]);
  }
  if (footing_->present()) {
    footing_->kind.begin(cx, footing_->contacts);
    for (std::size_t k = k1; k < recs.size(); ++k) footing_->kind.add(recs[k]);
  }
}

// The additions of set_wall_sums for this World's own wall contacts as (slot, value) terms, slots
// in pack_wall_sums' order: the planes' and the footing's shares from their contacts, the facets'
// from the terms the force pass formed (FacetKind::after_law), as FacetKind::end adds them.
void World::wall_sum_terms(std::vector<WallTerm>& out) const {
  const std::uint32_t planes = static_cast<std::uint32_t>(planes_->kind.walls.size());
  auto put3 = [&](std::uint32_t slot, const Vec3& v) {
    out.push_back({slot, v.x});
    out.push_back({slot + 1, v.y});
    out.push_back({slot + 2, v.z});
  };
  const WallContacts& pc = planes_->contacts;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    const WallSumRec r = PlaneKind::rec(pc, static_cast<std::int64_t>(c));
    put3(4 * r.wall, r.F);
    if (r.active) out.push_back({4 * r.wall + 3, r.k});
  }
  std::uint32_t at = 4 * planes;
  const auto& fws = facets_->kind.walls;
  std::vector<std::uint32_t>& base = scratch_slots_;  // each facet wall's first slot
  base.clear();
  for (const FacetWall& fw : fws) {
    base.push_back(at);
    at += static_cast<std::uint32_t>(4 * fw.vforce.size() + 3);
  }
  if (facets_->present()) {
    for_each_facet_term([&](std::size_t, const FacetTerm& t) {
      if (!t.active) return;
      const FacetWall& fw = fws[t.wall];
      const auto& tr = fw.tri[static_cast<std::size_t>(t.facet)];
      const std::uint32_t b = base[t.wall], nv = static_cast<std::uint32_t>(fw.vforce.size());
      if (t.loaded) {
        for (int v = 0; v < 3; ++v) put3(b + 3 * static_cast<std::uint32_t>(tr[v]), t.f[v]);
        put3(b + 4 * nv, t.F);
      }
      for (int v = 0; v < 3; ++v) out.push_back({b + 3 * nv + static_cast<std::uint32_t>(tr[v]), t.k[v]});
    });
  }
  const WallContacts& gc = footing_->contacts;
  for (std::size_t c = 0; c < gc.size(); ++c) put3(at, FootingKind::rec(gc, static_cast<std::int64_t>(c)).F);
}

// Each facet contact's share of the vertex sums as the last force pass formed it
// (FacetKind::after_law), in contact order. (No pass yet, e.g. a World just loaded onto a rank:
// the terms from the contacts' records, facet_term of facet_rec, as after_law forms them.)
template <class Fn>
void World::for_each_facet_term(Fn fn) const {
  const std::vector<FacetTerm>& ft = facets_->kind.terms;
  const WallContacts& wc = facets_->contacts;
  const bool passed = ft.size() == wc.size();
  const SetContext cx = const_cast<World*>(this)->context();
  for (std::size_t c = 0; c < wc.size(); ++c)
    fn(c, passed ? ft[c] : facet_term(facets_->kind.walls, facet_rec(cx, wc, static_cast<std::int64_t>(c))));
}

void World::facet_sum_shares(std::vector<FacetSumShare>& out) const {
  if (!facets_->present()) return;
  const WallContacts& wc = facets_->contacts;
  for_each_facet_term([&](std::size_t c, const FacetTerm& t) {
    if (!t.active) return;  // (adds nothing)
    FacetSumShare s;
    s.ball = pt_.id[wc.ball[c]];
    s.wall = t.wall;
    s.facet = t.facet;
    s.loaded = t.loaded ? 1 : 0;
    s.f = t.f;
    s.F = t.F;
    for (int v = 0; v < 3; ++v) s.k[v] = t.k[v];
    out.push_back(s);
  });
}

void World::set_facet_sums(std::span<const FacetSumShare> shares) {
  auto& walls = facets_->kind.walls;
  facet_zero(walls);
  for (const FacetSumShare& s : shares) {
    if (s.wall >= walls.size() || s.facet < 0 || static_cast<std::size_t>(s.facet) >= walls[s.wall].tri.size())
      throw std::invalid_argument("set_facet_sums: a share names facet " + std::to_string(s.facet) + " of wall " +
                                  std::to_string(s.wall) + ", which this World does not have.");
    FacetTerm t;
    t.active = true;
    t.wall = s.wall;
    t.facet = s.facet;
    t.loaded = s.loaded != 0;
    t.f = s.f;
    t.F = s.F;
    for (int v = 0; v < 3; ++v) t.k[v] = s.k[v];
    facet_add(walls, t);
  }
}

std::size_t World::wall_sum_slots() const {
  std::size_t n = 4 * planes_->kind.walls.size() + (footing_->present() ? 3 : 0);
  for (const FacetWall& fw : facets_->kind.walls) n += 4 * fw.vforce.size() + 3;
  return n;
}

void World::order_free_wall_sums() {
  if (!planes_->present() && !facets_->present() && !footing_->present()) return;
  of_terms_.clear();
  wall_sum_terms(of_terms_);
  const std::size_t S = wall_sum_slots();
  std::vector<double>& v = of_values_;
  slot_bounds(of_terms_, S, v);  // first the bounds, then the sums
  slot_folds(of_terms_, v, of_sums_);
  for (std::size_t k = 0; k < S; ++k) v[k] = of_sums_[k].result();
  unpack_wall_sums(v);
}

void World::pack_wall_sums(std::vector<double>& out) const {
  out.clear();
  auto put = [&](const Vec3& v) { out.insert(out.end(), {v.x, v.y, v.z}); };
  for (const PlaneWall& pw : planes_->kind.walls) {
    put(pw.reaction);
    out.push_back(pw.k_sum);
  }
  for (const FacetWall& fw : facets_->kind.walls) {
    for (const Vec3& f : fw.vforce) put(f);
    out.insert(out.end(), fw.vstiff.begin(), fw.vstiff.end());
    put(fw.total_force);
  }
  if (footing_->present()) put(footing_->kind.ft.reaction);
}

void World::unpack_wall_sums(std::span<const double> in) {
  std::size_t k = 0;
  auto get = [&](Vec3& v) {
    v = {in[k], in[k + 1], in[k + 2]};
    k += 3;
  };
  const std::size_t need = wall_sum_slots();
  if (in.size() != need)
    throw std::invalid_argument("unpack_wall_sums: " + std::to_string(in.size()) + " values for walls that take " +
                                std::to_string(need) + ".");
  for (PlaneWall& pw : planes_->kind.walls) {
    get(pw.reaction);
    pw.k_sum = in[k++];
  }
  for (FacetWall& fw : facets_->kind.walls) {
    for (Vec3& f : fw.vforce) get(f);
    for (double& v : fw.vstiff) v = in[k++];
    get(fw.total_force);
  }
  if (footing_->present()) get(footing_->kind.ft.reaction);
}

std::size_t World::bond_ball_facet(double hi) {
  if (!law_has_bond(p_.ball_facet.model))
    throw std::invalid_argument(std::string("bond_ball_facet: family 'ball_facet' uses model '") +
                                law_name(p_.ball_facet.model) +
                                "', which cannot bond; set ball_facet.model to 'pbond' (the paper's interface, §2.6).");
  if (!prepared_) prepare();
  SetContext cx = context();
  const std::size_t cnt = facets_->kind.bond(cx, facets_->contacts, hi);
  last_dt_step_ = -1;
  return cnt;
}

}  // namespace demfdm::dem
