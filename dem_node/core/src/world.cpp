// DEM world: the cycle over the particle store and the contact sets (pair_set.hpp,
// wall_set.hpp), the critical step, the law of motion, effects and measurements.
// See world.hpp for the design notes (determinism, history keyed by ids).
#include "demfdm/dem/world.hpp"

#include "demfdm/dem/neighbour_grid.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <tuple>

#include "demfdm/dem/geometry.hpp"
#include "demfdm/dem/pair_block.hpp"
#include "pair_set.hpp"
#include "wall_set.hpp"
#include "world_detail.hpp"

namespace demfdm::dem {

namespace {
using detail::Lap;
constexpr std::size_t kChunk = 2048;  // fixed chunking: reductions independent of threads

}  // namespace

World::World(const WorldParams& p)
    : p_(p),
      pairs_(std::make_unique<PairSet>()),
      planes_(std::make_unique<WallSet<PlaneKind>>(&PhaseTimes::plane)),
      facets_(std::make_unique<WallSet<FacetKind>>(&PhaseTimes::facet)),
      footing_(std::make_unique<WallSet<FootingKind>>(&PhaseTimes::footing)),
      sets_{pairs_.get(), planes_.get(), facets_.get(), footing_.get()} {
  validate(p_);
  if (p_.periodic.enabled) cell_len_ref_ = p_.periodic.length;
  if (p_.gravity) set_gravity(true, p_.g_level);
}

World::~World() = default;

SetContext World::context() {
  return SetContext{pt_,           p_,           skin_,          edot_,
                    thread_count(), kernel_,      e_slip_dead_,   e_soft_dead_,
                    bond_failures_, ghost_.empty() ? nullptr : ghost_.data(), bool(newton_reverse_)};
}

PairContacts& World::pair_contacts() {
  pairs_->touch();  // the caller may change the pairs: the threaded pass re-plans
  return pairs_->contacts;
}
const PairContacts& World::pair_contacts() const { return pairs_->contacts; }
WallContacts& World::plane_contacts() { return planes_->contacts; }
WallContacts& World::facet_contacts() { return facets_->contacts; }
WallContacts& World::footing_contacts() { return footing_->contacts; }
const WallContacts& World::plane_contacts() const { return planes_->contacts; }
const WallContacts& World::facet_contacts() const { return facets_->contacts; }
const WallContacts& World::footing_contacts() const { return footing_->contacts; }

// ------------------------------------------------------------------------------------------
// particles and constants

std::size_t World::add_ball(const Vec3& x, double radius, double density) {
  if (!(radius > 0.0)) {
    std::ostringstream s;
    s << "add_ball: 'radius' must be > 0 m, found " << radius << ".";
    throw std::invalid_argument(s.str());
  }
  const std::size_t row = pt_.add(x, radius, density > 0.0 ? density : p_.density, next_id_++);
  dirty_ = true;
  return row;
}

void World::set_radius(std::size_t i, double r) {
  pt_.set_radius(i, r);
  dirty_ = true;  // the Verlet list depends on the radii
  last_dt_step_ = -1;
}

std::vector<std::uint32_t> World::reorder_spatially() {
  const std::vector<std::uint32_t> newrow = morton_rows(pt_);
  if (newrow.empty()) return newrow;
  pt_.permute(newrow);
  for (ContactSet* set : sets_) set->remap(newrow);
  dirty_ = true;
  return newrow;
}

void World::refresh_contact_constants() {
  const SetContext cx = context();
  for (ContactSet* set : sets_) set->refresh(cx);
  last_dt_step_ = -1;
}

// ------------------------------------------------------------------------------------------
// effects

Effect* World::add_effect(std::unique_ptr<Effect> e) {
  Effect* raw = e.get();
  effects_.push_back(std::move(e));
  const unsigned ph = raw->phases();
  std::size_t slot = 0;  // the timer entry of this effect's name (shared by equal names)
  while (slot < times_.effect.size() && times_.effect[slot].first != raw->name()) ++slot;
  if (slot == times_.effect.size()) times_.effect.emplace_back(raw->name(), 0.0);
  for (int k = 0; k < 4; ++k)
    if (ph & (1u << k)) by_phase_[k].push_back({raw, slot});
  return raw;
}

// Effects of one phase (0 pre-step, 1 force, 2 end-of-step, 3 kinematics), in order of addition,
// each timed.
void World::run_effects(int phase) {
  if (by_phase_[phase].empty()) return;
  Lap lap;
  double total = 0.0;
  for (const EffectSlot& s : by_phase_[phase]) {
    s.e->apply(*this, static_cast<Effect::Phase>(1u << phase));
    double t = 0.0;
    lap(t);
    times_.effect[s.slot].second += t;
    total += t;
  }
  times_.effects_total += total;
}

bool World::pair_kernel_available(PairKernel k) {
  switch (k) {
    case PairKernel::kBlockAvx2: return pairblock::isa_available(pairblock::Isa::kAvx2);
    case PairKernel::kBlockAvx512: return pairblock::isa_available(pairblock::Isa::kAvx512);
    default: return true;
  }
}

void World::keep_force_norms(bool on) { pairs_->keep_force_norms(on); }

bool World::force_norms_kept() const { return pairs_->pass_norms(p_.ball_ball.model); }

void World::set_pair_stealing(bool on, double hold_s) { pairs_->set_stealing(on, hold_s); }

std::pair<std::uint64_t, std::uint64_t> World::pair_blocks_stolen() const {
  return {pairs_->blocks_stolen(), pairs_->blocks_stealable()};
}

void World::set_pair_kernel(PairKernel k) {
  if (!pair_kernel_available(k))
    throw std::invalid_argument("set_pair_kernel: this CPU lacks the instruction set of the requested kernel.");
  kernel_ = k;
}

const PhaseTimes& World::phase_times() const { return times_; }

void World::reset_phase_times() {
  auto effect = std::move(times_.effect);
  for (auto& e : effect) e.second = 0.0;
  times_ = PhaseTimes{};
  times_.effect = std::move(effect);
}

void World::remove_effect(const Effect* e) {
  for (auto& l : by_phase_)
    l.erase(std::remove_if(l.begin(), l.end(), [&](const EffectSlot& s) { return s.e == e; }), l.end());
  effects_.erase(std::remove_if(effects_.begin(), effects_.end(),
                                [&](const auto& p) { return p.get() == e; }),
                 effects_.end());
  if (e == gravity_) gravity_ = nullptr;
}

void World::set_gravity(bool on, double g_level) {
  if (gravity_) remove_effect(gravity_);
  p_.gravity = on;
  p_.g_level = g_level;
  if (on) gravity_ = add_effect(std::make_unique<GravityEffect>(Vec3{0, 0, -g_level * p_.g0}));
}

Vec3 World::gravity() const {
  return gravity_ ? static_cast<const GravityEffect*>(gravity_)->g() : Vec3{};
}

void GravityEffect::apply(World& w, Phase) {
  auto& pt = w.pt_;
  const std::size_t n = pt.size();
  for (std::size_t i = 0; i < n; ++i) pt.f[i] += pt.m[i] * g_;
}

// ------------------------------------------------------------------------------------------
// periodic cell

double World::cell_volume() const {
  const Vec3 L = p_.periodic.length;
  return L.x * L.y * L.z;
}

void World::set_cell(const Vec3& origin, const Vec3& length) {
  p_.periodic.origin = origin;
  p_.periodic.length = length;
  cell_len_ref_ = length;
  dirty_ = true;
}

Vec3 World::pair_force(std::size_t c) const { return pairs_->force(c, p_.ball_ball); }

Vec3 World::pair_moment(std::size_t c) const { return pairs_->moment(c, p_.ball_ball); }

Vec3 World::branch(std::size_t c) const { return pairs_->branch(pt_, p_.periodic, c); }

// ------------------------------------------------------------------------------------------
// neighbour search and history

void World::clear_contacts() {
  for (ContactSet* set : sets_) set->clear();
  dirty_ = true;
}

void World::append_pair(std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& s,
                        const ContactHist& h, const BondHist* bond) {
  pairs_->append(a, b, s, h, bond, law_has_bond(p_.ball_ball.model));
  dirty_ = true;
}

bool World::need_rebuild() const { return need_rebuild(max_disp2_); }

bool World::need_rebuild(double max_disp2) const {
  if (dirty_) return true;
  const double dmax = std::sqrt(max_disp2);
  double dcell = 0.0;
  if (p_.periodic.enabled)
    for (int k = 0; k < 3; ++k)
      dcell = std::max(dcell, std::abs(p_.periodic.length[k] - cell_len_ref_[k]));
  if (2.0 * dmax + dcell > skin_) return true;
  double dw = 0.0;  // the largest wall travel (a maximum: exact in any order)
  for (const ContactSet* set : sets_) dw = std::max(dw, set->travel());
  return dmax + dw > skin_;
}

void World::rebuild() {
  ++rebuilds_;
  const std::size_t n = pt_.size();
  const bool per = p_.periodic.enabled;
  const Vec3 o = p_.periodic.origin, L = p_.periodic.length;
  if (per) {  // wrap into [o, o+L) (§4.2)
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        const double s = std::floor((pt_.x[i][k] - o[k]) / L[k]);
        if (s != 0.0) pt_.x[i][k] -= s * L[k];
      }
  }
  // every set in the cycle's order: candidates within reach, history carried across by key
  SetContext cx = context();
  for (ContactSet* set : sets_) set->rebuild(cx);
  pt_.x_ref = pt_.x;
  max_disp2_ = 0.0;
  if (per) cell_len_ref_ = p_.periodic.length;
  dirty_ = false;
}



void World::force_pass(double dt) {
  // Every set's pass in the cycle's order, each timed in its phase; a wall kind without walls
  // costs nothing. Inside a set one switch per pass selects the law's template instantiation
  // (no virtual call per contact).
  times_.pair_model = to_string(p_.ball_ball.model);
  SetContext cx = context();
  // The interface facets' contacts run as side units of the ball-ball pass (SideWork): its
  // threads take them once their own chunk is done, instead of waiting at its barrier and then
  // forking again for the facets. Each unit writes only its own contacts' records and the facets'
  // sums follow in contact order, so this changes no bit. Not on ranks, whose Newton reverse
  // communication follows the ball-ball pass.
  const bool hosted = hosted_facets_ && !newton_reverse_ && facets_->present();
  Lap lap;
  for (ContactSet* set : sets_) {
    if (!set->present()) {
      set->idle();
      continue;
    }
    if (hosted && set == facets_.get()) continue;  // (ran inside the ball-ball pass)
    if (hosted && set == pairs_.get()) {
      double host_s = 0.0, units_s = 0.0;
      facets_->pass_hosted(cx, dt, [&](SideWork& w) {
        Lap in;
        pairs_->pass(cx, dt, &w);
        in(host_s);
        units_s = w.thread_s;
      });
      double both = 0.0;
      lap(both);
      // The phases: the units' thread time over the threads goes to the facets, with the facet
      // pass's own work before and after them; the rest of the ball-ball pass to the pairs.
      const double units = std::min(host_s, units_s / std::max(1, cx.threads));
      times_.pair += host_s - units;
      times_.facet += both - host_s + units;
      ++times_.facets_hosted;
      continue;
    }
    set->pass(cx, dt);
    lap(times_.*(set->phase()));
    if (set == pairs_.get() && newton_reverse_) {  // (communication: timed by its caller, in no phase)
      newton_reverse_(pt_.f.data(), pt_.t.data());
      double comm = 0.0;
      lap(comm);
    }
  }
  if (p_.order_free_sums && !wall_sums_by_caller_) order_free_wall_sums();
  Lap lap_gather;
  gather();
  lap_gather(times_.gather);
  run_effects(1);
}

// Wall contacts act on balls after the ball–ball pass, serially in set and contact order.
void World::gather() {
  for (const ContactSet* set : sets_) set->gather(pt_);
}

namespace {
// One component of the law of motion with local damping (§1.2–1.3): v ← v + Δt (F + F_d)/m,
// F_d = −α|F| sign(v), written as a select (−0 for v = ±0, as (−α|F|)·0 gives for α ≥ 0).
// Subtracts the damping work from `ed` if Energy.
template <bool Energy>
[[gnu::always_inline]] inline void advance(double& v, double F, double im, double alpha, double dt, double& ed) {
  const double fd = v != 0.0 ? std::copysign(alpha * std::abs(F), -v) : -0.0;
  const double v0 = v;
  v = v0 + dt * (F + fd) * im;
  if constexpr (Energy) ed -= fd * 0.5 * (v0 + v) * dt;
}
}  // namespace

// §1.2–1.3: centred differences with local damping; fixed components keep their velocity.
// Rows without fixity (nearly all) take a straight-line path; the arithmetic and the order
// of the energy sum are the same on both paths.
template <bool Energy, bool Periodic>
void World::integrate_rows(std::size_t i0, std::size_t i1, double dt, const Vec3& sc, double& ed_own, double& dmax) {
  const double alpha = p_.local_damping;
  const Vec3 o = p_.periodic.origin;
  Vec3* __restrict__ X = pt_.x.data();
  Vec3* __restrict__ V = pt_.v.data();
  Vec3* __restrict__ W = pt_.w.data();
  const Vec3* __restrict__ Fc = pt_.f.data();
  const Vec3* __restrict__ Tc = pt_.t.data();
  const Vec3* __restrict__ Fa = pt_.fa.data();
  const Vec3* __restrict__ Ta = pt_.ta.data();
  const Vec3* __restrict__ X0 = pt_.x_ref.data();
  const double* __restrict__ Ms = pt_.m.data();
  const double* __restrict__ Is = pt_.inertia.data();
  const std::uint8_t* __restrict__ Fx = pt_.fix.data();
  // A rank's world: a ghost row among the moving rows moves too (its owner's state replaces
  // it), but its damping work is its owner's to count.
  const std::uint8_t* __restrict__ G = ghost_.empty() ? nullptr : ghost_.data();
  double e_ghost = 0.0;
  auto row = [&](std::size_t i) __attribute__((always_inline)) {
    double& ed = (Energy && G && G[i]) ? e_ghost : ed_own;
    const Vec3 F = Fc[i] + Fa[i];
    const Vec3 T = Tc[i] + Ta[i];
    const std::uint8_t fx = Fx[i];
    const double im = 1.0 / Ms[i], ii = 1.0 / Is[i];
    Vec3& v = V[i];
    Vec3& w = W[i];
    if (fx == 0) {
      advance<Energy>(v.x, F.x, im, alpha, dt, ed);
      advance<Energy>(w.x, T.x, ii, alpha, dt, ed);
      advance<Energy>(v.y, F.y, im, alpha, dt, ed);
      advance<Energy>(w.y, T.y, ii, alpha, dt, ed);
      advance<Energy>(v.z, F.z, im, alpha, dt, ed);
      advance<Energy>(w.z, T.z, ii, alpha, dt, ed);
    } else {
      for (int k = 0; k < 3; ++k) {
        if (!(fx & (1u << k))) advance<Energy>(v[k], F[k], im, alpha, dt, ed);
        if (!(fx & (8u << k))) advance<Energy>(w[k], T[k], ii, alpha, dt, ed);
      }
    }
    Vec3& x = X[i];
    x += dt * v;
    if constexpr (Periodic) x = o + cmul(x - o, sc);
    dmax = std::max(dmax, norm2(x - X0[i]));
  };
  std::size_t i = i0;
  pairblock::Isa isa;
  if (detail::block_isa(kernel_, isa)) {
    // Blocks of kLanes rows without fixity through the lane kernel (same operations); the
    // damping work and the maximum are then reduced here in row and component order.
    constexpr std::size_t K = pairblock::kLanes;
    const pairblock::MotionFn mk = pairblock::motion_kernel(isa);
    const pairblock::MotionCtx ctx{X, V, W, Fc, Tc, Fa, Ta, X0, Ms, Is, alpha, dt, o, sc, Periodic};
    pairblock::MotionOut out;
    for (; i + K <= i1; i += K) {
      std::uint8_t any = 0;
      for (std::size_t l = 0; l < K; ++l) any |= Fx[i + l];
      if (any) {
        for (std::size_t j = i; j < i + K; ++j) row(j);
        continue;
      }
      mk(ctx, i, out);
      for (std::size_t l = 0; l < K; ++l) {
        if constexpr (Energy) {
          if (!G || !G[i + l])
            for (int q = 0; q < 6; ++q) ed_own -= out.e[q][l];
        }
        dmax = std::max(dmax, out.d2[l]);
      }
    }
  }
  for (; i < i1; ++i) row(i);
}

void World::integrate(double dt) {
  const std::size_t n = std::min(pt_.size(), moving_rows_);
  const bool per = p_.periodic.enabled;
  Vec3 sc{1.0 + edot_.x * dt, 1.0 + edot_.y * dt, 1.0 + edot_.z * dt};
  const bool energy = p_.track_energy;
  const std::size_t nch = (n + kChunk - 1) / kChunk;
  chunk_e_.assign(2 * nch, 0.0);
  const int nt = thread_count();
  // One instantiation per (energy, periodic): no flag tests inside the row loop.
  auto rows = energy ? (per ? &World::integrate_rows<true, true> : &World::integrate_rows<true, false>)
                     : (per ? &World::integrate_rows<false, true> : &World::integrate_rows<false, false>);
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1 && nch > 1)
  for (std::int64_t ch = 0; ch < static_cast<std::int64_t>(nch); ++ch) {
    double ed = 0.0, dmax = 0.0;
    const std::size_t i0 = static_cast<std::size_t>(ch) * kChunk, i1 = std::min(n, i0 + kChunk);
    (this->*rows)(i0, i1, dt, sc, ed, dmax);
    chunk_e_[2 * static_cast<std::size_t>(ch)] = ed;
    chunk_e_[2 * static_cast<std::size_t>(ch) + 1] = dmax;
  }
  for (std::size_t ch = 0; ch < nch; ++ch) {  // fixed-order reduction
    e_damp_ += chunk_e_[2 * ch];
    max_disp2_ = std::max(max_disp2_, chunk_e_[2 * ch + 1]);
  }
  if (per) {
    for (int k = 0; k < 3; ++k) {
      p_.periodic.length[k] *= sc[k];
      cell_strain_[k] += edot_[k] * dt;
    }
  }
}

// ------------------------------------------------------------------------------------------
// timestep (§1.8)

double World::critical_timestep() { return contact_scan(true, false).dt; }

World::ContactScan World::contact_scan(bool want_dt, bool want_fc) const {
  ContactScan out;
  const std::size_t n = pt_.size();
  const int nt = thread_count();
  // The sets only read the particles here (the context is non-const for the passes).
  const SetContext cx = const_cast<World*>(this)->context();
  // Each set computes its per-contact terms (the pairs in one parallel pass); the sums over
  // them run in set and contact order, the additions of one serial loop: the same bits at any
  // thread count.
  for (ContactSet* set : sets_) set->scan(cx, want_dt, want_fc);
  std::vector<double>& kt = scratch_kt_;
  std::vector<double>& kr = scratch_kr_;
  // Two serial loops, each in set and contact order: the sum of the force norms, and every
  // ball's stiffness sums. They share nothing, so on two threads they run side by side.
  auto force_sum = [&] {
    if (p_.order_free_sums) {  // the norms > 0 (as add_force_norms counts them), order-free:
      // the pairs' from the scan's array, the walls' gathered, folded against one bound
      const std::vector<double>& pn = pairs_->force_norms();
      const std::size_t m = ghost_.empty() ? pairs_->contacts.size() : 0;  // (a rank's: DistDem's)
      std::vector<double>& v = scratch_fc_;
      v.clear();
      force_norm_values(v, m == 0);
      const double bound = std::max(max_positive_of(pn.data(), m), max_positive_of(v.data(), v.size()));
      const std::size_t cnt = count_positive(pn.data(), m) + count_positive(v.data(), v.size());
      OrderFreeSum sum = fold_terms(pn.data(), m, bound, true);
      sum.merge(fold_terms(v.data(), v.size(), bound, true));
      out.fc = cnt ? sum.result() / double(cnt) : 0.0;
      return;
    }
    double sum = 0.0;
    std::size_t cnt = 0;
    for (const ContactSet* set : sets_) set->add_force_norms(sum, cnt);
    out.fc = cnt ? sum / double(cnt) : 0.0;
  };
  auto stiffness_sums = [&] {
    kt.assign(n, 0.0);
    kr.assign(n, 0.0);
    for (const ContactSet* set : sets_) set->add_stiffness(cx, kt.data(), kr.data());
  };
  if (want_fc && want_dt && nt > 1 && n > 4096) {
#pragma omp parallel sections num_threads(2)
    {
#pragma omp section
      force_sum();
#pragma omp section
      stiffness_sums();
    }
  } else {
    if (want_fc) force_sum();
    if (want_dt) stiffness_sums();
  }
  if (!want_dt) return out;
  if (newton_stiffness_) newton_stiffness_(kt.data(), kr.data());  // (outside the sections: MPI)
  // The smallest step over the balls (a minimum: exact in any order). The square root is
  // monotonic and correctly rounded, so the root of the smallest ratio is the smallest root: one
  // root instead of two per ball, and a branch-free loop that vectorises.
  double q = std::numeric_limits<double>::infinity();
  const std::int64_t ni = static_cast<std::int64_t>(n);
  const double* __restrict__ M = pt_.m.data();
  const double* __restrict__ I = pt_.inertia.data();
  const double* __restrict__ KT = kt.data();
  const double* __restrict__ KR = kr.data();
  constexpr double kInf = std::numeric_limits<double>::infinity();
#pragma omp parallel for simd schedule(static) num_threads(nt) if (nt > 1 && ni > 4096) reduction(min : q)
  for (std::int64_t i = 0; i < ni; ++i) {
    const double a = KT[i] > 0.0 ? M[i] / KT[i] : kInf;
    const double b = KR[i] > 0.0 ? I[i] / KR[i] : kInf;
    q = std::min(std::min(q, a), b);
  }
  // On ranks (set_step_reduction) the smallest over every rank, before the fallback below: a
  // rank whose rows touch nothing must not take it while another rank's contacts set the step.
  if (step_reduction_) q = step_reduction_(q);
  double dt = std::sqrt(q);
  if (!std::isfinite(dt)) {
    // No active contact: use one contact with an equal ball (the law's reference stiffness;
    // linear springs: k_n = π R E*/2, §7.2). The smallest ratio, then its root: the root of
    // every ball's smallest, bit for bit (the root is monotonic and correctly rounded).
    double qf = kInf;
    visit_law(p_.ball_ball.model, [&](auto law) {
      for (std::size_t i = 0; i < n; ++i) {
        const double k = decltype(law)::reference_stiffness(pt_.r[i], p_.ball_ball);
        if (k > 0.0) qf = std::min(qf, pt_.m[i] / k);
      }
    });
    if (step_reduction_) qf = step_reduction_(qf);
    dt = std::sqrt(qf);
    if (!std::isfinite(dt)) dt = 1e-6;
  }
  out.dt = p_.dt_safety * dt;
  return out;
}

// ------------------------------------------------------------------------------------------
// stepping

void World::prepare() {
  if (skin_ <= 0.0) {
    if (p_.skin > 0.0) {
      skin_ = p_.skin;
    } else {
      double rmin = std::numeric_limits<double>::infinity();
      for (double r : pt_.r) rmin = std::min(rmin, r);
      skin_ = std::isfinite(rmin) ? p_.skin_factor * 2.0 * rmin : 1e-3;
    }
  }
  Lap lap;
  rebuild();
  lap(times_.rebuild);
  force_pass(0.0);
  Lap lap_dt;
  dt_ = p_.dt_fixed > 0.0 ? p_.dt_fixed : critical_timestep();
  lap_dt(times_.motion);
  last_dt_step_ = step_;
  prepared_ = true;
}

// A law whose stiffness grows with the overlap (Hertz–Mindlin, §1.9) has the step recomputed
// every step; the others every dt_interval steps (§1.8).
std::int64_t World::dt_interval() const {
  bool varies = false;
  for (const ContactFamilyParams* f : {&p_.ball_ball, &p_.ball_wall, &p_.ball_facet, &p_.ball_footing})
    varies |= visit_law(f->model, [](auto law) { return decltype(law)::kStiffnessVaries; });
  return varies ? 1 : p_.dt_interval;
}

void World::step() {
  step_motion();
  step_forces_now();
}

void World::step_forces_now() { step_forces(need_rebuild()); }

void World::step_motion() {
  if (!prepared_) prepare();
  run_effects(0);
  Lap lap;
  if (p_.dt_fixed > 0.0) {
    dt_ = p_.dt_fixed;
  } else if (last_dt_step_ < 0 || step_ - last_dt_step_ >= dt_interval()) {
    dt_ = critical_timestep();
    last_dt_step_ = step_;
  }
  integrate(dt_);
  lap(times_.motion);
  run_effects(3);  // kinematics: wall servos (PlatenServo)
  Lap lap_walls;
  for (ContactSet* set : sets_) set->move(dt_);
  time_ += dt_;
  ++step_;
  lap_walls(times_.motion);
}

void World::step_forces(bool rebuild_now) {
  Lap lap;
  if (rebuild_now) rebuild();
  lap(times_.rebuild);
  force_pass(dt_);
  run_effects(2);
  ++times_.steps;
}

void World::drop_balls() {
  const Counters k = counters();
  Particles none;
  PairContacts no_pairs;
  std::array<WallContacts, 3> no_walls;
  for (auto& wc : no_walls) wc.cand_off.push_back(0);
  std::vector<std::uint8_t> no_ghosts;
  swap_balls(none, no_pairs, no_walls, no_ghosts);
  set_counters(k);
}

void World::swap_balls(Particles& pt, PairContacts& pc, std::array<WallContacts, 3>& wall,
                       std::vector<std::uint8_t>& ghost) {
  std::swap(pt_, pt);
  pairs_->swap_in(pc);
  std::swap(planes_->contacts, wall[0]);
  std::swap(facets_->contacts, wall[1]);
  std::swap(footing_->contacts, wall[2]);
  std::swap(ghost_, ghost);
  dirty_ = true;
}

std::vector<std::string> World::effect_names() const {
  std::vector<std::string> out;
  for (const auto& e : effects_) out.emplace_back(e->name());
  return out;
}

std::vector<const Effect*> World::effects() const {
  std::vector<const Effect*> out;
  for (const auto& e : effects_) out.push_back(e.get());
  return out;
}

World::Counters World::counters() const {
  return Counters{time_,  dt_,          skin_,          step_,    rebuilds_,    last_dt_step_,
                  bond_failures_, prepared_, dirty_, edot_, cell_strain_, cell_len_ref_,
                  next_id_, next_wall_id_, e_damp_, max_disp2_, e_slip_dead_, e_soft_dead_};
}

void World::set_counters(const Counters& k) {
  time_ = k.time, dt_ = k.dt, skin_ = k.skin;
  step_ = k.step, rebuilds_ = k.rebuilds, last_dt_step_ = k.last_dt_step, bond_failures_ = k.bond_failures;
  prepared_ = k.prepared, dirty_ = k.dirty;
  edot_ = k.edot, cell_strain_ = k.cell_strain, cell_len_ref_ = k.cell_len_ref;
  next_id_ = k.next_id, next_wall_id_ = k.next_wall_id;
  e_damp_ = k.e_damp, max_disp2_ = k.max_disp2, e_slip_dead_ = k.e_slip_dead, e_soft_dead_ = k.e_soft_dead;
}

void World::set_step_reduction(std::function<double(double)> reduce) { step_reduction_ = std::move(reduce); }

void World::set_newton(std::function<void(Vec3*, Vec3*)> reverse, std::function<void(double*, double*)> stiffness) {
  newton_reverse_ = std::move(reverse);
  newton_stiffness_ = std::move(stiffness);
}

void World::step(std::int64_t n) {
  for (std::int64_t k = 0; k < n; ++k) step();
}

// ------------------------------------------------------------------------------------------
// bonds

std::size_t World::bond_ball_ball(double lo, double hi) {
  if (!law_has_bond(p_.ball_ball.model))
    throw std::invalid_argument(std::string("bond_ball_ball: family 'ball_ball' uses model '") +
                                law_name(p_.ball_ball.model) +
                                "', which cannot bond; set ball_ball.model to 'pbond' or 'softbond'.");
  if (!prepared_) prepare();
  const std::size_t cnt = pairs_->bond(context(), lo, hi);
  last_dt_step_ = -1;
  return cnt;
}


// ------------------------------------------------------------------------------------------
// measurements

double World::kinetic_energy() const {
  return ordered_ball_sum([this](std::size_t i) { return kinetic_energy_of(i); });
}

void World::contact_force_norms(std::vector<double>& out) const {
  const SetContext cx = const_cast<World*>(this)->context();
  pairs_->scan(cx, false, true);
  force_norm_values(out, true);
}

void World::contact_force_keys(std::vector<ContactTerm>& out) const {
  const PairContacts& pc = pairs_->contacts;
  for (std::size_t c = 0; c < pc.size(); ++c)
    if (ghost_.empty() || !ghost_[pc.a[c]]) out.push_back({0, pt_.id[pc.a[c]], pt_.id[pc.b[c]], 0.0});
  const WallContacts* wl[3] = {&planes_->contacts, &facets_->contacts, &footing_->contacts};
  for (std::uint64_t k = 0; k < 3; ++k)
    for (std::size_t c = 0; c < wl[k]->size(); ++c) out.push_back({k + 1, pt_.id[wl[k]->ball[c]], wl[k]->wall[c], 0.0});
}

void World::force_norm_values(std::vector<double>& out, bool pairs) const {
  const PairContacts& pc = pairs_->contacts;
  const std::vector<double>& f = pairs_->force_norms();
  for (std::size_t c = 0; pairs && c < pc.size(); ++c)
    if (ghost_.empty() || !ghost_[pc.a[c]]) out.push_back(f[c]);
  const WallContacts* wl[3] = {&planes_->contacts, &facets_->contacts, &footing_->contacts};
  for (const WallContacts* w : wl)
    for (std::size_t c = 0; c < w->size(); ++c) out.push_back(norm(w->F[c]));
}

Energy World::energy() const {
  Energy e;
  e.kinetic = kinetic_energy();
  e.damping = e_damp_;
  e.friction = e_slip_dead_;
  e.softening = e_soft_dead_;
  for (const ContactSet* set : sets_) set->add_energy(e, p_, ghost_);
  return e;
}

double World::unbalanced_force_of(std::size_t i) const {
  const Vec3 F = pt_.f[i] + pt_.fa[i];
  double s = 0.0;
  for (int k = 0; k < 3; ++k)
    if (!(pt_.fix[i] & (1u << k))) s += F[k] * F[k];
  return std::sqrt(s);
}

double World::mean_contact_force() const { return contact_scan(false, true).fc; }

double World::unbalanced_ratio() const {
  if (pt_.size() == 0) return 0.0;
  return unbalanced_ratio(mean_contact_force());
}

double World::unbalanced_ratio(double fc) const {
  if (pt_.size() == 0) return 0.0;
  return unbalanced_ratio_of(ordered_ball_sum([this](std::size_t i) { return unbalanced_force_of(i); }), pt_.size(), fc);
}

double World::unbalanced_ratio_of(double sum, std::size_t balls, double fc) {
  if (fc <= 0.0) return sum > 0.0 ? std::numeric_limits<double>::infinity() : 0.0;
  return (sum / double(balls)) / fc;
}

double World::max_unbalanced_force() const {
  double s = 0.0;
  for (std::size_t i = 0; i < pt_.size(); ++i) s = std::max(s, unbalanced_force_of(i));
  return s;
}

}  // namespace demfdm::dem
