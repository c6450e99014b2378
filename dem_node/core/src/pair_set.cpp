// The ball-ball contact set (pair_set.hpp).
#include "pair_set.hpp"

#include <omp.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numeric>
#include <thread>
#include <tuple>

#include "demfdm/dem/neighbour_grid.hpp"
#include "demfdm/dem/pair_block.hpp"
#include "world_detail.hpp"

namespace demfdm::dem {

namespace {



// Force and torque sums of a run of ball–ball contacts onto the balls, in contact order. The
// list is sorted by A: the sums on A are kept in registers for the run of contacts that share
// it and flushed when A changes (fixed order, hence deterministic). The scalar pass calls at()
// for every contact, the block pass for live ones only: the sums are the same, since idle
// contacts add nothing and flushing a zero sum cannot change a ball's sum (the sums start at
// +0 and never become −0). The threaded pass (Save) also keeps the run sum of every split ball
// (PairSet::plan_split) in its record of `run`, stamped with the pass.
template <bool Save>
struct BallSums {
  Vec3* __restrict__ f;
  Vec3* __restrict__ t;
  std::uint32_t cur;
  // Save: the chunk's split balls with a run, ascending rows (ending in a sentinel above every
  // row), their records, and the pass's stamp. A runs in ascending order within a chunk, so one
  // cursor finds them.
  const std::uint32_t* __restrict__ rrow = nullptr;
  const std::uint32_t* __restrict__ rrec = nullptr;
  PairSet::RunSave* __restrict__ run = nullptr;
  std::uint64_t stamp = 0;
  Vec3 fa{}, ta{};
  [[gnu::always_inline]] void put() {
    f[cur] += fa;
    t[cur] += ta;
    if constexpr (Save) {
      while (*rrow < cur) ++rrow, ++rrec;
      if (*rrow == cur) run[*rrec] = {fa, ta, stamp};
    }
  }
  // Contact with A = a next: flush the sums of the previous A.
  [[gnu::always_inline]] void at(std::uint32_t a) {
    if (a != cur) {
      put();
      fa = Vec3{};
      ta = Vec3{};
      cur = a;
    }
  }
  [[gnu::always_inline]] void add(std::uint32_t b, const Vec3& F, const Vec3& TA, const Vec3& TB) {
    fa -= F;
    f[b] += F;
    ta += TA;
    t[b] += TB;
  }
  void flush() { put(); }
};}  // namespace

// ------------------------------------------------------------------------------------------
// neighbour rebuild: the candidates of the grid search, history merged by key

void PairSet::rebuild(SetContext& cx) {
  const Particles& pt = cx.pt;
  const std::size_t n = pt.size();
  const bool per = cx.p.periodic.enabled;
  const Vec3 L = cx.p.periodic.length;
  PairContacts& pc = contacts;
  std::vector<PairCandidate>& np = cand_;
  find_pair_candidates(pt.x, pt.r, cx.skin, cx.p.periodic, pc.size() + n * 4, SearchIsa::kBest, np);
  // merge the history keyed by (id_A, id_B): a contact's history follows the pair
  const bool has_bond = law_has_bond(cx.p.ball_ball.model);
  // The old list's rows are current (remap keeps them so). A rebuild leaves it sorted by
  // (a, b) with a < b, like the new one: then one linear merge finds each old contact. A
  // reorder or appended pairs break the order: then the history is found by its id key.
  const std::size_t mo = pc.size();
  auto row_key = [](std::uint32_t a, std::uint32_t b) { return std::uint64_t(a) << 32 | b; };
  bool sorted = true;
  for (std::size_t k = 0; k < mo && sorted; ++k)
    sorted = pc.a[k] < pc.b[k] && (k == 0 || row_key(pc.a[k - 1], pc.b[k - 1]) < row_key(pc.a[k], pc.b[k]));
  // Keys: rows (a, b) for the linear merge, ids (lower, higher) otherwise.
  auto id_key = [&](std::uint32_t a, std::uint32_t b) {
    const std::uint64_t ia = pt.id[a], ib = pt.id[b];
    return std::make_pair(std::min(ia, ib), std::max(ia, ib));
  };
  auto old_key = [&](std::size_t k) {
    return sorted ? std::make_pair(std::uint64_t(pc.a[k]), std::uint64_t(pc.b[k])) : id_key(pc.a[k], pc.b[k]);
  };
  detail::HistoryCarry carry(mo, sorted, old_key);
  auto find_old = [&](std::uint32_t a, std::uint32_t b) -> std::int64_t {
    const auto k = sorted ? std::make_pair(std::uint64_t(a), std::uint64_t(b)) : id_key(a, b);
    return carry.take(k.first, k.second);
  };
  // The new list in the arrays of the list before last (spare_): their memory is kept from
  // rebuild to rebuild.
  PairContacts& q = spare_;
  q.a.clear(), q.b.clear(), q.shift.clear(), q.h.clear(), q.bond.clear();
  // with a quarter more room when it must grow: a list a few pairs longer than the last would
  // otherwise take fresh memory at every rebuild
  auto room = [&](auto& v) {
    if (v.capacity() < np.size()) v.reserve(np.size() + np.size() / 4);
  };
  room(q.a), room(q.b), room(q.shift), room(q.h);
  if (has_bond) room(q.bond);
  auto push = [&](std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& s) {
    q.a.push_back(a);
    q.b.push_back(b);
    q.shift.push_back(s);
    const std::uint64_t ia = pt.id[a];
    const std::int64_t found = find_old(a, b);
    if (found >= 0) {
      const std::uint32_t oc = static_cast<std::uint32_t>(found);
      q.h.push_back(pc.h[oc]);
      if (has_bond) q.bond.push_back(pc.bond[oc]);
      if (pt.id[pc.a[oc]] != ia) detail::flip(q.h.back(), has_bond ? &q.bond.back() : nullptr);
    } else {
      q.h.push_back({});
      if (has_bond) q.bond.push_back({});
      detail::init_contact(pt, a, b, q.h.back(), has_bond ? &q.bond.back() : nullptr, cx.p.ball_ball, false);
    }
  };
  // A rank's world (cx.ghost): a pair of two ghosts acts on ghosts only and is not kept; with
  // `newton`, neither is a pair whose lower-id ball is a ghost: its owner computes it. (With
  // rows in id order that is ball a, the lower row; with the ghosts in rows of their own after
  // the owned ones, a ghost b may have the lower id.)
  const std::uint8_t* G = cx.ghost;
  const bool newton = cx.newton;
  auto elsewhere = [&](std::uint32_t a, std::uint32_t b) {
    return G && (newton ? (G[a] != 0 || (G[b] != 0 && pt.id[b] < pt.id[a])) : (G[a] & G[b]) != 0);
  };
  for (const auto& e : np)
    if (!elsewhere(e.a, e.b)) push(e.a, e.b, e.s);
  // bonded contacts beyond the cut-off are kept (a bond never disappears in a rebuild)
  bool appended = false;
  carry.rest(
      pc.h, pc.bond, has_bond,
      [&](std::size_t k) {
        std::uint32_t a = pc.a[k], b = pc.b[k];
        if (elsewhere(a, b)) return;
        Vec3 d = pt.x[b] - pt.x[a];
        std::array<std::int8_t, 4> s{0, 0, 0, 0};
        if (per)
          for (int ax = 0; ax < 3; ++ax) {
            const double sh = -std::round(d[ax] / L[ax]);
            s[ax] = static_cast<std::int8_t>(sh);
          }
        q.a.push_back(a);
        q.b.push_back(b);
        q.shift.push_back(s);
        q.h.push_back(pc.h[k]);
        q.bond.push_back(pc.bond[k]);
        appended = true;
      },
      cx.e_slip_dead, cx.e_soft_dead, [&](std::size_t k) { return !G || !G[pc.a[k]]; });
  if (appended) {  // restore the (a, b) order
    std::vector<std::uint32_t> perm(q.a.size());
    std::iota(perm.begin(), perm.end(), 0u);
    std::sort(perm.begin(), perm.end(), [&](std::uint32_t x, std::uint32_t y) {
      return std::tie(q.a[x], q.b[x]) < std::tie(q.a[y], q.b[y]);
    });
    PairContacts r;
    for (auto k : perm) {
      r.a.push_back(q.a[k]);
      r.b.push_back(q.b[k]);
      r.shift.push_back(q.shift[k]);
      r.h.push_back(q.h[k]);
      if (has_bond) r.bond.push_back(q.bond[k]);
    }
    q = std::move(r);
  }
  std::swap(pc, q);  // the old list's arrays are the next rebuild's
  ++gen_;
}

// ------------------------------------------------------------------------------------------
// force pass (one template instantiation per law and cell kind; no model branch in the loops)

namespace {
// Software prefetch distances of the ball–ball pass (bench/dem): the B rows are scattered and
// the history stream is not kept in flight by the hardware prefetcher alone (+20 % measured).
constexpr std::int64_t kPrefetchB = 12;  // contacts ahead for the B rows
constexpr std::int64_t kPrefetchH = 24;  // contacts ahead for the history records
// Contacts in a block of the threaded pass's work stealing (pass_law): the owner's atomic take
// per block costs about 0.1 % of the block's time, a late thread waits at most about a block.
constexpr std::int64_t kStealBlock = 2048;

// A contact's ||F|| from its history: the term of the mean contact force, formed by the scan or,
// with keep_force_norms, by the pass (one formula, so the same bits).
template <class L>
[[gnu::always_inline]] inline double force_norm(const ContactHist& h, const BondHist* b) {
  return norm(L::force(h, b));
}
}  // namespace

void PairSet::pass(SetContext& cx, double dt, SideWork* side) {
  const bool per = cx.p.periodic.enabled;
  visit_law(cx.p.ball_ball.model, [&](auto law) {
    using L = decltype(law);
    per ? pass_law<L, true>(cx, dt, side) : pass_law<L, false>(cx, dt, side);
  });
}

// Ball–ball pass. Each contact stores its force (and moment) in its own slot for the
// measurements, and adds −F/+F and the torques onto its balls through BallSums, in contact order.
//
// One thread: straight into the particle arrays. A ball's sum is then a fixed sequence of
// additions: +F of each contact where it is B, and the flushed run sum of the contacts where it
// is A, in contact order, starting from +0.
//
// Several threads: the list is cut into `threads` chunks of contiguous contacts, each boundary
// moved forward to where A changes, so that no ball's run of A contacts is cut. Chunk 0 adds into
// the particle arrays, every other chunk into its own buffer, and the buffers are added in after
// a barrier. A ball whose contacts all lie in one chunk gets the sequence of the one-thread pass
// (+0 plus a sum that is never −0 leaves it unchanged). A ball whose contacts span chunks
// ("split": plan_split) would get a different association. In a sorted list its contacts as B
// all come before its run, so its first chunk holds only B contacts and sums a true prefix of
// the one-thread sequence. The later chunks save what the ball receives from each of its B
// contacts there (F and the torque on B, stamped with the pass) and its run sum (BallSums), and
// the reduction continues the prefix with them in contact order. The result is the one-thread
// pass bit for bit at any thread count (tests/dem/thread_count_test.cpp); a list that is not
// sorted (never seen by a pass in practice: a rebuild sorts it) runs on one thread.
template <class Law, bool Periodic>
void PairSet::pass_law(SetContext& cx, double dt, SideWork* side) {
  const std::int64_t m = static_cast<std::int64_t>(contacts.size());
  const std::size_t n = cx.pt.size();
  const LawConst lc = detail::law_const(cx.p.ball_ball, cx.p.rescale_shear, false);
  // No array aliases another (restrict lets loads be kept across the force stores).
  const Vec3* __restrict__ X = cx.pt.x.data();
  const Vec3* __restrict__ V = cx.pt.v.data();
  const Vec3* __restrict__ W = cx.pt.w.data();
  const double* __restrict__ R = cx.pt.r.data();
  const std::uint32_t* __restrict__ A = contacts.a.data();
  const std::uint32_t* __restrict__ B = contacts.b.data();
  const auto* __restrict__ S = contacts.shift.data();
  ContactHist* __restrict__ H = contacts.h.data();
  BondHist* __restrict__ BD = contacts.bond.empty() ? nullptr : contacts.bond.data();
  const Vec3 L = cx.p.periodic.length;
  const Vec3 ed = cx.edot;
  // Marks the contacts whose active flag or bond state this pass changes, for scan()'s kept
  // terms (a byte per contact, or-ed until a scan takes them; no branch in the loops).
  if (chg_.size() != contacts.size()) {
    chg_.assign(contacts.size(), 0);
    terms_ok_ = false;  // the marks of earlier passes are gone
  }
  std::uint8_t* __restrict__ CH = chg_.data();
  // The state a contact's stiffness terms depend on that a pass can change.
  // (key_of: the same from flags already in hand, fl = H[c].flags.)
  auto key_of = [=](std::uint8_t fl, std::int64_t c) __attribute__((always_inline)) -> unsigned {
    return (fl & ContactHist::kActive) | (BD ? static_cast<unsigned>(BD[c].state) << 8 : 0u);
  };
  auto key = [=](std::int64_t c) __attribute__((always_inline)) -> unsigned { return key_of(H[c].flags, c); };
  // Every contact's ||F|| for the measurements (keep_force_norms): ||Law::force|| of its history
  // after the update, the scan's formula; +0 for an idle one (F_n = 0 and so F_s = 0, and no
  // bond force: the scan's value too).
  if (keep_norms_ && norm_.size() != contacts.size()) norm_.resize(contacts.size());
  double* __restrict__ SN = keep_norms_ ? norm_.data() : nullptr;
  pn_ok_ = keep_norms_;  // (the pass writes every entry below)
  pn_gen_ = gen_;
  pn_model_ = cx.p.ball_ball.model;
  std::int64_t* const fails = &cx.bond_failures;  // bonds that leave the intact state
  const std::uint8_t* const G = cx.ghost;          // ghost rows (a rank's world), or null
  const double rgap = lc.rgap;
  const int nt = cx.threads;
  // Thread-independent bits (WorldParams::thread_independent): the chunk scheme below from 1,024
  // contacts. Otherwise the chunks cut at m k / threads from 4,096 contacts, and a ball's sums are
  // associated per chunk (same bits for the same thread count only).
  const bool ti = cx.p.thread_independent;
  const bool par = nt > 1 && m > (ti ? 1024 : 4096);
  const bool strained = ed.x != 0.0 || ed.y != 0.0 || ed.z != 0.0;
  // Vectorised blocks (pair_block.hpp) where the law has a lane kernel; bit-identical to the
  // scalar loop below (tests/dem/simd_kernel_test.cpp).
  pairblock::Fn kern = nullptr;
  {
    pairblock::Isa isa;
    if (detail::block_isa(cx.kernel, isa)) kern = Law::lane_kernel(isa, lc);
  }
  const pairblock::Ctx ctx{V, W, R, H, BD, lc, dt, ed, Periodic && strained};
  // Threaded: the B contacts of split balls after their first chunk save into their records; a
  // chunk walks its list of them (ascending contact, sentinel-terminated) with a cursor. `stamp`
  // tells this pass's records from stale ones (a contact idle this pass saved nothing and adds
  // nothing).
  if (par && ti && (plan_gen_ != gen_ || plan_chunks_ != nt || plan_m_ != contacts.size() || plan_n_ != n))
    plan_split(n, nt);
  const bool threaded = par && ti && plan_ok_;
  const std::uint64_t stamp = ++stamp_;
  BSave* __restrict__ SV = threaded ? save_.data() : nullptr;
  RunSave* __restrict__ RS = threaded ? run_.data() : nullptr;
  auto cursor = [this](int k) {
    const std::size_t uk = static_cast<std::size_t>(k);
    return ChunkCursor{sc_.data(), sc_.data() + sc_off_[uk], rrow_.data() + rr_off_[uk], rrec_.data() + rr_off_[uk]};
  };
  // The helpers below are forced inline: left to GCC, the soft-bond block pass measured 1.27 x
  // slower (bench/dem/results_2core_kvm.csv).
  // The helpers and the loop bodies capture by value: the arrays' base pointers then live in the
  // closures as copies the loop can keep in registers, where a by-reference capture made GCC
  // reload them through the captured locals after every store (3.2 % + 2.5 % fewer instructions
  // in the soft-bond pass, callgrind, the same state hash).
  // Software prefetch (see kPrefetchB/H): the scattered B rows, and the history records
  // (96 B, plus 104 B of bond state) that the loop streams through.
  // (`sums` false: not the ball sums' rows f, t; a stolen block adds nothing to them.)
  auto prefetch = [=](auto sums, std::int64_t c, std::int64_t c1, const Vec3* f, const Vec3* t)
                      __attribute__((always_inline)) {
    if (c + kPrefetchH < c1) {
      __builtin_prefetch(reinterpret_cast<const char*>(H + c + kPrefetchH), 1);
      __builtin_prefetch(reinterpret_cast<const char*>(H + c + kPrefetchH) + 64, 1);
      if (BD) {
        __builtin_prefetch(reinterpret_cast<const char*>(BD + c + kPrefetchH), 1);
        __builtin_prefetch(reinterpret_cast<const char*>(BD + c + kPrefetchH) + 64, 1);
      }
    }
    if (c + kPrefetchB < c1) {
      const std::uint32_t bp = B[c + kPrefetchB];
      __builtin_prefetch(X + bp);
      __builtin_prefetch(V + bp);
      __builtin_prefetch(W + bp);
      __builtin_prefetch(R + bp);
      if constexpr (decltype(sums)::value) {
        __builtin_prefetch(f + bp, 1);
        __builtin_prefetch(t + bp, 1);
      }
    }
  };
  // Branch vector d (periodic image) and its square.
  auto branch_d = [=](std::int64_t c, std::uint32_t a, std::uint32_t b, Vec3& d, double& d2)
                      __attribute__((always_inline)) {
    d = X[b] - X[a];
    if constexpr (Periodic) {
      std::uint32_t any;  // most contacts lie inside the cell: skip the conversion
      std::memcpy(&any, S[c].data(), 4);
      if (any) d += cmul(Vec3{double(S[c][0]), double(S[c][1]), double(S[c][2])}, L);
    }
    d2 = norm2(d);
  };
  // Separated and force-free: nothing to do. F_n = 0 implies F_s = 0 (Coulomb limit
  // μF_n = 0), so the stale n_old is never used to rotate a non-zero vector. Soft bond:
  // the same for an unbonded contact (never bonded or broken), whose §3.5 moment limits
  // are proportional to F_n, so M_b = M_t = 0 as well; the result of the full law
  // would be F = M = 0 with kActive and kSlip cleared. (Bitwise & on purpose: one
  // unpredictable branch at most.)
  // The bond record of contact c: only laws with bond state have one (no null test per contact).
  auto bond_at = [=](std::int64_t c) __attribute__((always_inline)) -> BondHist* {
    if constexpr (Law::kBond) return BD + c;
    else return nullptr;
  };
  auto idle = [=](std::int64_t c, std::uint32_t a, std::uint32_t b, double d2) __attribute__((always_inline)) {
    return Law::idle(d2, R[a] + R[b] + rgap, H[c], bond_at(c));
  };
  constexpr std::uint8_t kActSlip = ContactHist::kActive | ContactHist::kSlip;
  // Scalar kinematics and law of one live contact: force F on B and the torques added to A
  // (TA) and B (TB).
  auto law = [=](std::int64_t c, std::uint32_t a, std::uint32_t b, const Vec3& d, double d2, Vec3& F, Vec3& TA,
                 Vec3& TB) __attribute__((always_inline)) {
    const double dist = std::sqrt(d2);
    const double gap = dist - R[a] - R[b];
    const Vec3 nn = d * (1.0 / dist);
    Kin k;
    k.n = nn;
    k.gap = gap;
    // Lever arms ℓ_A = s_A n̂ and ℓ_B = −s_B n̂ (contact point mid-overlap, §1.4), so
    // ω_B × ℓ_B − ω_A × ℓ_A = −(s_A ω_A + s_B ω_B) × n̂ and ℓ_A × (−F) = s_A F × n̂,
    // ℓ_B × F = s_B F × n̂: one cross product each for the velocity and the torques
    // (agrees with the two-cross form to rounding, 1e-13 of the per-ball torque sums).
    const double sa = R[a] + 0.5 * gap, sb = R[b] + 0.5 * gap;
    Vec3 vr = (V[b] - V[a]) - cross(sa * W[a] + sb * W[b], nn);
    if constexpr (Periodic) {
      if (strained) vr += cmul(ed, d);  // affine cell motion (§4.5)
    }
    k.du = vr * dt;
    k.dtheta = (W[b] - W[a]) * dt;
    k.wmean = 0.5 * (W[a] + W[b]);
    k.dt = dt;
    if constexpr (Law::kNeedsReff) k.reff = R[a] * R[b] / (R[a] + R[b]);
    Vec3 Mo;
    if constexpr (Law::kBond) {
      // A bond leaving the intact state is rare: one compare per contact, an atomic add per event.
      const bool was_intact = BD[c].state == BondState::kIntact;
      F = Law::update(k, H[c], BD + c, lc, Mo);
      // counted where ball A is owned (a rank of the DEM on ranks computes a pair across its
      // brick's face too): the counts of the ranks add up to one World's
      if (was_intact && BD[c].state != BondState::kIntact && !(G && G[a])) {
#pragma omp atomic
        ++*fails;
      }
    } else {
      F = Law::update(k, H[c], nullptr, lc, Mo);
    }
    // (F_s × n̂ would drop the rounding noise of the normal part, but reloading h.fs right
    // after the law's store measured 3 % slower than using F from registers.)
    const Vec3 fxn = cross(F, nn);
    if constexpr (Law::kBond) {
      TA = sa * fxn - Mo;  // ℓ_A × (−F) − M
      TB = sb * fxn + Mo;
    } else {
      TA = sa * fxn;
      TB = sb * fxn;
    }
  };
  // The same law out of line, for the rare lanes of the block pass that need it.
  auto law_rare = [&](std::int64_t c, std::uint32_t a, std::uint32_t b, const Vec3& d, double d2, Vec3& F, Vec3& TA,
                      Vec3& TB) __attribute__((noinline)) { law(c, a, b, d, d2, F, TA, TB); };
  // One contact at a time (the reference).
  // `save` (std::bool_constant): store every contact's force and torques in its save slot.
  // (Save: `cur` is the chunk's cursors, see ChunkCursor.)
  // Contacts [c0, c1) of a chunk that ends at ce, added to the ball sums `sums_io` (kept in a
  // local copy meanwhile, so that the run sums stay in registers). `steal` (std::bool_constant):
  // a stolen block; its live contacts go to se[nse++] instead of the sums (StealEntry).
  auto body = [=](auto save, auto steal, std::int64_t c0, std::int64_t c1, std::int64_t ce, auto& sums_io,
                  ChunkCursor cur, StealEntry* __restrict__ se, std::uint32_t& nse) {
    constexpr bool Save = decltype(save)::value;
    constexpr bool Steal = decltype(steal)::value;
    static_assert(!(Save && Steal), "a stolen block saves nothing");
    auto sums = sums_io;
    Vec3* __restrict__ const f = sums.f;
    Vec3* __restrict__ const t = sums.t;
    std::uint32_t ns = nse;
    for (std::int64_t c = c0; c < c1; ++c) {
      const std::uint32_t a = A[c], b = B[c];
      prefetch(std::bool_constant<!Steal>{}, c, ce, f, t);
      if constexpr (!Steal) sums.at(a);
      Vec3 d;
      double d2;
      branch_d(c, a, b, d, d2);
      if (idle(c, a, b, d2)) {
        if (H[c].flags & ContactHist::kActive) {
          H[c].flags &= static_cast<std::uint8_t>(~kActSlip);
          CH[c] = 1;
        }
        if (SN) SN[c] = 0.0;
        continue;
      }
      const unsigned k0 = key(c);
      Vec3 F, TA, TB;
      law(c, a, b, d, d2, F, TA, TB);
      CH[c] |= key(c) != k0;
      if (SN) SN[c] = force_norm<Law>(H[c], bond_at(c));
      if constexpr (Save) {
        while (*cur.c < static_cast<std::uint64_t>(c)) ++cur.c;
        if (*cur.c == static_cast<std::uint64_t>(c)) SV[cur.c - cur.c0] = {F, TB, stamp};
      }
      if constexpr (Steal) se[ns++] = {a, b, F, TA, TB};
      else sums.add(b, F, TA, TB);
    }
    sums_io = sums;
    nse = ns;
  };
  // Blocks of kLanes live contacts: stage 1 (lane list), stage 2 (kern), stage 3 (histories
  // and sums in contact order; lanes flagged `scalar` are redone by the scalar law from their
  // untouched history).
  // (The arguments as body's.)
  auto body_block = [=](auto save, auto steal, std::int64_t c0, std::int64_t c1, std::int64_t ce, auto& sums_io,
                        ChunkCursor cur, StealEntry* __restrict__ se, std::uint32_t& nse) {
    // Local copies of the closure's pointers and helpers: the byte stores below (a contact's
    // flags, its change mark) may alias any object as far as GCC knows, the closure's members
    // included, so that it reloaded every captured pointer after each of them; locals whose
    // address is not taken stay in registers (the same operations, so the same bits).
    // (No restrict on them: the helpers read the same records through their own copies.)
    const std::uint32_t* const A_ = A;
    const std::uint32_t* const B_ = B;
    ContactHist* const H_ = H;
    BondHist* const BD_ = BD;
    std::uint8_t* const CH_ = CH;
    double* const SN_ = SN;
    const auto prefetch_ = prefetch;
    const auto branch_d_ = branch_d;
    const auto idle_ = idle;
    const auto key_ = key;
    const auto key_of_ = key_of;
    const auto bond_at_ = bond_at;
    constexpr bool Save = decltype(save)::value;
    constexpr bool Steal = decltype(steal)::value;
    static_assert(!(Save && Steal), "a stolen block saves nothing");
    constexpr int K = pairblock::kLanes;
    auto sums = sums_io;
    Vec3* __restrict__ const f = sums.f;
    Vec3* __restrict__ const t = sums.t;
    StealEntry* __restrict__ const se_ = se;
    std::uint32_t ns = nse;
    pairblock::In in;
    pairblock::Out out;
    unsigned k0[K];  // each lane's key() before the law
    std::int64_t c = c0;
    while (c < c1) {
      int n = 0;
      for (; c < c1 && n < K; ++c) {
        const std::uint32_t a = A_[c], b = B_[c];
        prefetch_(std::bool_constant<!Steal>{}, c, ce, f, t);
        Vec3 d;
        double d2;
        branch_d_(c, a, b, d, d2);
        // Branch-free: the lane is written for every contact and kept (n advances) only for a
        // live one; an idle contact gets kActive and kSlip cleared (the same flags as `body`).
        const bool skip = idle_(c, a, b, d2);
        const std::uint8_t fl = H_[c].flags;
        H_[c].flags = skip ? static_cast<std::uint8_t>(fl & ~kActSlip) : fl;
        CH_[c] |= skip & ((fl & ContactHist::kActive) != 0);
        if (SN_) SN_[c] = 0.0;  // a live lane's is written in stage 3
        // key_(c) from the flags in hand (a live lane's are still fl): reloading the byte just
        // stored cost 2 % of the linear pass, measured inside one run (docs/speed.md, session 36).
        k0[n] = key_of_(fl, c);
        in.c[n] = c;
        in.a[n] = a;
        in.b[n] = b;
        in.dx[n] = d.x;
        in.dy[n] = d.y;
        in.dz[n] = d.z;
        in.d2[n] = d2;
        in.hasn[n] = (fl & ContactHist::kHasNormal) != 0;
        in.incr[n] = (fl & ContactHist::kIncremental) != 0;
        in.scalar[n] = Law::lane_needs_scalar(bond_at_(c));
        if constexpr (Law::kBond) in.intact[n] = BD_[c].state == BondState::kIntact;
        n += !skip;
      }
      if (n == 0) break;
      for (int l = n; l < K; ++l) {  // padding lanes repeat lane 0
        in.c[l] = in.c[0]; in.a[l] = in.a[0]; in.b[l] = in.b[0];
        in.dx[l] = in.dx[0]; in.dy[l] = in.dy[0]; in.dz[l] = in.dz[0]; in.d2[l] = in.d2[0];
        in.hasn[l] = in.hasn[0]; in.incr[l] = in.incr[0]; in.scalar[l] = in.scalar[0];
        if constexpr (Law::kBond) in.intact[l] = in.intact[0];
      }
      kern(ctx, in, out);
      for (int l = 0; l < n; ++l) {
        const std::int64_t cl = in.c[l];
        const std::uint32_t a = static_cast<std::uint32_t>(in.a[l]), b = static_cast<std::uint32_t>(in.b[l]);
        Vec3 F, TA, TB;
        if (out.scalar[l]) {
          law_rare(cl, a, b, Vec3{in.dx[l], in.dy[l], in.dz[l]}, in.d2[l], F, TA, TB);
        } else {
          Law::store_lane(H_[cl], bond_at_(cl), out, l);
          F = {out.F[0][l], out.F[1][l], out.F[2][l]};
          TA = {out.TA[0][l], out.TA[1][l], out.TA[2][l]};
          TB = {out.TB[0][l], out.TB[1][l], out.TB[2][l]};
        }
        // The key after the law: a lane's from its result (Law::lane_key), without reloading the
        // records just stored; a lane redone by the scalar law may change anything.
        CH_[cl] |= (out.scalar[l] ? key_(cl) : Law::lane_key(out, l, k0[l])) != k0[l];
        if (SN_) SN_[cl] = force_norm<Law>(H_[cl], bond_at_(cl));
        if constexpr (Save) {
          while (*cur.c < static_cast<std::uint64_t>(cl)) ++cur.c;
          if (*cur.c == static_cast<std::uint64_t>(cl)) SV[cur.c - cur.c0] = {F, TB, stamp};
        }
        if constexpr (Steal) {
          se_[ns++] = {a, b, F, TA, TB};
        } else {
          sums.at(a);
          sums.add(b, F, TA, TB);
        }
      }
    }
    sums_io = sums;
    nse = ns;
  };
  // Contacts [c0, c1) of a chunk (or of a block of it that ends the chunk at ce) onto the sums.
  auto part = [&](auto save, auto steal, std::int64_t c0, std::int64_t c1, std::int64_t ce, auto& sums,
                  ChunkCursor cur, StealEntry* se, std::uint32_t& nse) {
    if (kern) body_block(save, steal, c0, c1, ce, sums, cur, se, nse);
    else body(save, steal, c0, c1, ce, sums, cur, se, nse);
  };
  auto run = [&](auto save, std::int64_t c0, std::int64_t c1, Vec3* f, Vec3* t, ChunkCursor cur) {
    BallSums<decltype(save)::value> sums{f, t, c0 < c1 ? A[c0] : 0u, cur.run_row, cur.run_rec, RS, stamp};
    std::uint32_t nse = 0;
    part(save, std::false_type{}, c0, c1, c1, sums, cur, nullptr, nse);
    if (c0 < c1) sums.flush();
  };
  if (!par || (ti && !threaded)) {
    std::fill(cx.pt.f.begin(), cx.pt.f.end(), Vec3{});
    std::fill(cx.pt.t.begin(), cx.pt.t.end(), Vec3{});
    run(std::false_type{}, 0, m, cx.pt.f.data(), cx.pt.t.data(), ChunkCursor{});
    if (side) run_side_work(*side, nt);  // the side units after it, in a loop of their own
    return;
  }
  if (tbuf_.size() < static_cast<std::size_t>(nt)) tbuf_.resize(static_cast<std::size_t>(nt));
  // Chunk buffers are all zero between passes (zeroed by the reduction that reads them), so a
  // chunk only costs the rows it touches: [lo, hi) of its contacts' rows, found by a scan of its
  // (A, B) indices. Adding zeros elsewhere is skipped; the order of the sums is unchanged.
  for (int k = 1; k < nt; ++k) {
    auto& tb = tbuf_[static_cast<std::size_t>(k)];
    if (tb.size() != 2 * n) tb.assign(2 * n, Vec3{});
  }
  row_lo_.assign(static_cast<std::size_t>(nt), n);
  row_hi_.assign(static_cast<std::size_t>(nt), 0);
  // chunk boundaries: the plan's (thread-independent) or m k / threads
  if (!threaded) {
    cut_.assign(static_cast<std::size_t>(nt) + 1, 0);
    for (int k = 0; k <= nt; ++k) cut_[static_cast<std::size_t>(k)] = m * k / nt;
    plan_gen_ = ~std::uint64_t{0};  // the plan's cuts are gone
  }
  const std::int64_t* CB = cut_.data();
  // Work stealing (the chunks at m k / threads only): chunk k's blocks of kStealBlock contacts,
  // [lo, hi) in steal_range_[k]; block j of chunk k is block steal_base(k) + j of the buffers.
  const bool steal = steal_on_ && !threaded;
  auto blocks_of = [CB](int k) { return (CB[k + 1] - CB[k] + kStealBlock - 1) / kStealBlock; };
  auto steal_base = [&blocks_of](int k) {
    std::int64_t b = 0;
    for (int i = 0; i < k; ++i) b += blocks_of(i);
    return b;
  };
  if (steal) {
    const std::size_t nb = static_cast<std::size_t>(steal_base(nt));
    if (steal_blocks_ < nb) {
      steal_done_.reset(new std::atomic<std::uint64_t>[nb]());  // stamps 0: no pass's
      steal_cnt_.reset(new std::uint32_t[nb]);
      steal_blocks_ = nb;
    }
    const std::size_t cap = nb * static_cast<std::size_t>(kStealBlock);
    if (steal_cap_ < cap) {
      steal_buf_.reset(new StealEntry[cap]);
      steal_cap_ = cap;
    }
    if (steal_chunks_ < nt) {
      steal_range_.reset(new StealRange[static_cast<std::size_t>(nt)]);
      steal_chunks_ = nt;
    }
    for (int k = 0; k < nt; ++k)
      steal_range_[static_cast<std::size_t>(k)].v.store(static_cast<std::uint64_t>(blocks_of(k)) << 32,
                                                        std::memory_order_relaxed);
  }
  StealRange* const SR = steal ? steal_range_.get() : nullptr;
  std::atomic<std::uint64_t>* const SD = steal ? steal_done_.get() : nullptr;
  std::uint32_t* const SC = steal ? steal_cnt_.get() : nullptr;
  StealEntry* const SB = steal ? steal_buf_.get() : nullptr;
  // The owner of chunk k takes its next block from the bottom, another thread one from the top
  // (while at least two are left, so that the owner has work meanwhile); -1: none.
  auto take_low = [SR](int k) -> std::int64_t {
    std::atomic<std::uint64_t>& r = SR[k].v;
    std::uint64_t v = r.load(std::memory_order_relaxed);
    while (static_cast<std::uint32_t>(v) < static_cast<std::uint32_t>(v >> 32))
      if (r.compare_exchange_weak(v, v + 1, std::memory_order_relaxed)) return static_cast<std::uint32_t>(v);
    return -1;
  };
  auto take_high = [SR](int k) -> std::int64_t {
    std::atomic<std::uint64_t>& r = SR[k].v;
    std::uint64_t v = r.load(std::memory_order_relaxed);
    while (static_cast<std::uint32_t>(v) + 1 < static_cast<std::uint32_t>(v >> 32))
      if (r.compare_exchange_weak(v, v - (std::uint64_t{1} << 32), std::memory_order_relaxed))
        return static_cast<std::uint32_t>(v >> 32) - 1;
    return -1;
  };
  // Chunk k by its owner onto (f, t): its blocks from the bottom until the rest is taken, then
  // the taken blocks' contacts in contact order (waiting for a block still being computed), so
  // that every ball's sums run as in one walk of the chunk.
  auto own_chunk = [&](int k, Vec3* f, Vec3* t) {
    const std::int64_t c0 = CB[k], c1 = CB[k + 1];
    BallSums<false> sums{f, t, c0 < c1 ? A[c0] : 0u, nullptr, nullptr, nullptr, stamp};
    std::uint32_t nse = 0;
    for (std::int64_t j; (j = take_low(k)) >= 0;) {
      const std::int64_t b0 = c0 + j * kStealBlock;
      part(std::false_type{}, std::false_type{}, b0, std::min(c1, b0 + kStealBlock), c1, sums, ChunkCursor{}, nullptr,
           nse);
    }
    const std::int64_t base = steal_base(k), nbk = blocks_of(k);
    for (std::int64_t j = static_cast<std::uint32_t>(SR[k].v.load(std::memory_order_relaxed) >> 32); j < nbk; ++j) {
      const std::size_t g = static_cast<std::size_t>(base + j);
      for (unsigned spin = 0; SD[g].load(std::memory_order_acquire) != stamp; ++spin) {
        if (spin % 1024 == 1023) std::this_thread::yield();
#if defined(__x86_64__) || defined(__i386__)
        else __builtin_ia32_pause();
#endif
      }
      const StealEntry* e = SB + g * kStealBlock;
      for (std::uint32_t q = 0, nq = SC[g]; q < nq; ++q) {
        sums.at(e[q].a);
        sums.add(e[q].b, e[q].F, e[q].TA, e[q].TB);
      }
    }
    if (c0 < c1) sums.flush();
  };
  // Blocks taken from the top of the chunks with most left, until none has two.
  std::atomic<std::uint64_t> stolen{0};
  auto thieve = [&]() {
    BallSums<false> none{nullptr, nullptr, 0u, nullptr, nullptr, nullptr, stamp};  // (not used)
    std::uint64_t mine = 0;
    for (;;) {
      int best = -1;
      std::uint32_t most = 1;
      for (int k = 0; k < nt; ++k) {
        const std::uint64_t v = SR[k].v.load(std::memory_order_relaxed);
        const std::uint32_t left = static_cast<std::uint32_t>(v >> 32) - static_cast<std::uint32_t>(v);
        if (left > most) most = left, best = k;
      }
      if (best < 0) break;
      const std::int64_t j = take_high(best);
      if (j < 0) continue;
      const std::size_t g = static_cast<std::size_t>(steal_base(best) + j);
      const std::int64_t b0 = CB[best] + j * kStealBlock, b1 = std::min(CB[best + 1], b0 + kStealBlock);
      std::uint32_t nse = 0;
      part(std::false_type{}, std::true_type{}, b0, b1, b1, none, ChunkCursor{}, SB + g * kStealBlock, nse);
      SC[g] = nse;
      SD[g].store(stamp, std::memory_order_release);
      ++mine;
    }
    stolen.fetch_add(mine, std::memory_order_relaxed);
  };
  const std::uint32_t* __restrict__ EO = ev_off_.data();
  const std::uint32_t* __restrict__ EV = ev_.data();
  const std::int32_t* __restrict__ K0 = first_.data();
  // The side units: taken kSideGrab at a time from a shared counter by each thread once its own
  // chunks are done. On a 2-vCPU virtual machine the threads' chunks finished 0.7-1.0 ms apart on
  // average, the late thread changing from pass to pass (docs/speed.md, session 37): the first
  // thread done fills that wait, and the last one takes what is left.
  constexpr std::int64_t kSideGrab = 4;
  std::atomic<std::int64_t> side_next{0};
  double side_s = 0.0;
  // One parallel region per pass: the chunks (chunk k on thread k mod T, so the chunks, and the
  // bits, do not depend on how many threads the runtime grants), the side units, blocks of the
  // chunks still being walked (steal), a barrier, then the fixed-order reduction of the chunk
  // buffers split by particle rows, which also finishes the split balls.
#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num(), T = omp_get_num_threads();
    for (int k = tid; k < nt; k += T) {
      const std::size_t uk = static_cast<std::size_t>(k);
      const std::int64_t c0 = CB[k], c1 = CB[k + 1];
      Vec3* f = cx.pt.f.data();
      Vec3* t = cx.pt.t.data();
      if (k == 0) {
        std::fill(f, f + n, Vec3{});
        std::fill(t, t + n, Vec3{});
      } else {
        f = tbuf_[uk].data();
        t = f + n;
        std::uint32_t lo = static_cast<std::uint32_t>(n), hi = 0;
        for (std::int64_t c = c0; c < c1; ++c) {
          lo = std::min(lo, std::min(A[c], B[c]));
          hi = std::max(hi, std::max(A[c], B[c]));
        }
        row_lo_[uk] = lo;
        row_hi_[uk] = c0 < c1 ? std::size_t{hi} + 1 : 0;
      }
      if (threaded) run(std::true_type{}, c0, c1, f, t, cursor(k));
      else if (steal) {
        if (k == 0 && steal_hold_s_ > 0.0) std::this_thread::sleep_for(std::chrono::duration<double>(steal_hold_s_));
        own_chunk(k, f, t);
      }
      else run(std::false_type{}, c0, c1, f, t, ChunkCursor{});
    }
    if (side) {
      const double t0 = omp_get_wtime();
      const SideWork& w = *side;
      for (;;) {
        const std::int64_t u0 = side_next.fetch_add(kSideGrab, std::memory_order_relaxed);
        if (u0 >= w.units) break;
        for (std::int64_t u = u0, e = std::min(w.units, u0 + kSideGrab); u < e; ++u) w.run(w.ctx, u);
      }
      const double ts = omp_get_wtime() - t0;
#pragma omp atomic
      side_s += ts;
    }
    if (steal) thieve();
#pragma omp barrier
    std::size_t rlo = n, rhi = 0;
    for (int k = 1; k < nt; ++k) {
      rlo = std::min(rlo, row_lo_[static_cast<std::size_t>(k)]);
      rhi = std::max(rhi, row_hi_[static_cast<std::size_t>(k)]);
    }
    // (Every split ball has a contact outside chunk 0, so its row is in [rlo, rhi).)
#pragma omp for schedule(static)
    for (std::int64_t ii = static_cast<std::int64_t>(rlo); ii < static_cast<std::int64_t>(rhi); ++ii) {
      const std::size_t i = static_cast<std::size_t>(ii);
      const std::int32_t sp = threaded ? split_of_[i] : -1;
      if (sp < 0) {
        for (int k = 1; k < nt; ++k) {
          const std::size_t uk = static_cast<std::size_t>(k);
          if (i < row_lo_[uk] || i >= row_hi_[uk]) continue;
          Vec3& bf = tbuf_[uk][i];
          Vec3& bt = tbuf_[uk][n + i];
          cx.pt.f[i] += bf;
          cx.pt.t[i] += bt;
          bf = Vec3{};
          bt = Vec3{};
        }
        continue;
      }
      // A split ball: the prefix of its first chunk, then its saved B contacts of the later
      // chunks in contact order, then its run sum.
      const std::size_t us = static_cast<std::size_t>(sp);
      const int k0 = K0[us];
      Vec3 fs = k0 == 0 ? cx.pt.f[i] : tbuf_[static_cast<std::size_t>(k0)][i];
      Vec3 ts = k0 == 0 ? cx.pt.t[i] : tbuf_[static_cast<std::size_t>(k0)][n + i];
      for (std::uint32_t e = EO[us]; e < EO[us + 1]; ++e) {
        const BSave& q = SV[EV[e]];
        if (q.stamp != stamp) continue;  // idle this pass
        fs += q.f;
        ts += q.tb;
      }
      if (RS[us].stamp == stamp) {
        fs += RS[us].f;
        ts += RS[us].t;
      }
      cx.pt.f[i] = fs;
      cx.pt.t[i] = ts;
      for (int k = 1; k < nt; ++k) {
        const std::size_t uk = static_cast<std::size_t>(k);
        if (i < row_lo_[uk] || i >= row_hi_[uk]) continue;
        tbuf_[uk][i] = Vec3{};
        tbuf_[uk][n + i] = Vec3{};
      }
    }
  }
  if (side) side->thread_s += side_s;
  if (steal) {
    stolen_ += stolen.load(std::memory_order_relaxed);
    stealable_ += static_cast<std::uint64_t>(steal_base(nt));
  }
}

// The plan of a threaded pass in `chunks` chunks (see pass_law): the chunk boundaries, the split
// balls with their first chunk, the save record of every B contact of a split ball after that
// chunk (in contact order per ball), and a run record per split ball. O(contacts + balls), redone
// only when the list, its size, the ball count or the chunk count changes.
void PairSet::plan_split(std::size_t n, int chunks) {
  const std::size_t m = contacts.size();
  const std::uint32_t* A = contacts.a.data();
  const std::uint32_t* B = contacts.b.data();
  plan_gen_ = gen_;
  plan_chunks_ = chunks;
  plan_m_ = m;
  plan_n_ = n;
  // The scheme needs a list sorted by (a, b) with a < b (a rebuild leaves it so).
  plan_ok_ = true;
  for (std::size_t c = 0; c < m && plan_ok_; ++c)
    plan_ok_ = A[c] < B[c] && (c == 0 || A[c - 1] < A[c] || (A[c - 1] == A[c] && B[c - 1] < B[c]));
  if (!plan_ok_) return;
  cut_.assign(static_cast<std::size_t>(chunks) + 1, 0);
  for (int k = 1; k < chunks; ++k) {
    std::size_t c = std::max<std::size_t>(m * static_cast<std::size_t>(k) / static_cast<std::size_t>(chunks),
                                          static_cast<std::size_t>(cut_[static_cast<std::size_t>(k) - 1]));
    while (c > 0 && c < m && A[c] == A[c - 1]) ++c;  // do not cut a run
    cut_[static_cast<std::size_t>(k)] = static_cast<std::int64_t>(c);
  }
  cut_[static_cast<std::size_t>(chunks)] = static_cast<std::int64_t>(m);
  std::vector<std::int32_t> first(n, -1);
  std::vector<std::uint8_t> split(n, 0);
  for (int k = 0; k < chunks; ++k)
    for (std::int64_t c = cut_[static_cast<std::size_t>(k)]; c < cut_[static_cast<std::size_t>(k) + 1]; ++c)
      for (const std::uint32_t e : {A[c], B[c]}) {
        if (first[e] < 0) first[e] = k;
        else if (first[e] != k) split[e] = 1;
      }
  split_of_.assign(n, -1);
  first_.clear();
  std::int32_t ns = 0;
  for (std::size_t i = 0; i < n; ++i)
    if (split[i]) {
      split_of_[i] = ns++;
      first_.push_back(first[i]);
    }
  run_.assign(static_cast<std::size_t>(ns), RunSave{});
  // Save records: one per contact whose B is a split ball outside its first chunk, numbered in
  // contact order (the chunks write theirs in sequence; sentinels take a number too). Per chunk,
  // the list of those contacts and of its split balls with a run (ascending rows) with their run
  // records, each ending in a sentinel; per split ball, its records in contact order (CSR).
  constexpr std::uint64_t kEnd = ~std::uint64_t{0};
  constexpr std::uint32_t kEndRow = ~std::uint32_t{0};
  sc_.clear();
  rrow_.clear();
  rrec_.clear();
  sc_off_.assign(static_cast<std::size_t>(chunks), 0);
  rr_off_.assign(static_cast<std::size_t>(chunks), 0);
  ev_off_.assign(static_cast<std::size_t>(ns) + 1, 0);
  for (int k = 0; k < chunks; ++k) {
    sc_off_[static_cast<std::size_t>(k)] = sc_.size();
    rr_off_[static_cast<std::size_t>(k)] = rrow_.size();
    for (std::int64_t c = cut_[static_cast<std::size_t>(k)]; c < cut_[static_cast<std::size_t>(k) + 1]; ++c) {
      const std::int32_t sb = split_of_[B[c]];
      if (sb >= 0 && first[B[c]] != k) {
        sc_.push_back(static_cast<std::uint64_t>(c));
        ++ev_off_[static_cast<std::size_t>(sb) + 1];
      }
      const std::int32_t sa = split_of_[A[c]];
      if (sa >= 0 && (rrow_.size() == rr_off_[static_cast<std::size_t>(k)] || rrow_.back() != A[c])) {
        rrow_.push_back(A[c]);
        rrec_.push_back(static_cast<std::uint32_t>(sa));
      }
    }
    sc_.push_back(kEnd);
    rrow_.push_back(kEndRow);
    rrec_.push_back(0);
  }
  for (std::size_t s = 0; s < static_cast<std::size_t>(ns); ++s) ev_off_[s + 1] += ev_off_[s];
  ev_.resize(ev_off_.back());
  std::vector<std::uint32_t> fill(ev_off_.begin(), ev_off_.end() - 1);
  for (std::size_t r = 0; r < sc_.size(); ++r)  // records in contact order, so per ball too
    if (sc_[r] != kEnd) ev_[fill[static_cast<std::size_t>(split_of_[B[sc_[r]]])]++] = static_cast<std::uint32_t>(r);
  save_.assign(sc_.size(), BSave{});
}

// ------------------------------------------------------------------------------------------
// measurements: one parallel pass computes each contact's terms (its force norm, its
// stiffnesses); the sums over them then run in contact order, the additions and their order of
// one serial loop: the same bits at any thread count.

namespace {
// One contact's terms of the critical step (Law::stiffness): translational to both balls,
// rotational plus k_s R² to each; `live`: the contact counts.
template <class L>
[[gnu::always_inline]] inline void stiffness_terms(const ContactHist& h, const BondHist* b, const ContactFamilyParams& fam,
                                                   double ra, double rb, double& k, double& ka, double& kb,
                                                   std::uint8_t& live) {
  live = (h.flags & ContactHist::kActive) || (b && bonded(b->state));
  if (!live) return;
  const ContactStiffness s = L::stiffness(h, b, fam, ra, rb);
  k = s.k;
  ka = s.krot + s.ks * ra * ra;
  kb = s.krot + s.ks * rb * rb;
}
// f where f > 0, else +0 (f = 0 or NaN), as a mask of f's bits: the values of `pos ? f : 0.0`,
// so the sum's additions and bits are those of the loop that skips the term, without the branch
// GCC made of the select (a norm is +0 for every idle list entry, so that branch mispredicted:
// 1.44-1.46 ms of a 148,172-pair scan on one AVX-512 core, docs/speed.md session 17).
[[gnu::always_inline]] inline double positive_or_zero(double f, bool pos) {
  std::uint64_t u;
  std::memcpy(&u, &f, sizeof u);
  u &= 0 - static_cast<std::uint64_t>(pos);
  std::memcpy(&f, &u, sizeof u);
  return f;
}
}  // namespace

void PairSet::scan(const SetContext& cx, bool want_dt, bool want_fc) {
  fc_ = want_fc;
  dt_ = want_dt;
  terms_fresh_ = false;
  const std::int64_t m = static_cast<std::int64_t>(contacts.size());
  const int nt = cx.threads;
  const std::size_t um = contacts.size();
  const std::size_t n = cx.pt.size();
  const ContactFamilyParams& fam = cx.p.ball_ball;
  // The kept terms of the critical step, if the list, the radii and the family are those they
  // were computed for: only the contacts the passes since then changed are redone.
  bool terms_loop = want_dt;
  if (want_dt && terms_ok_ && terms_gen_ == gen_ && kt_pair_.size() == n && terms_r_.size() == n &&
      std::memcmp(terms_r_.data(), cx.pt.r.data(), n * sizeof(double)) == 0 &&
      std::memcmp(terms_fam_.data(), &fam, sizeof fam) == 0) {
    visit_law(fam.model, [&](auto law) {
      using L = decltype(law);
      if constexpr (!L::kStiffnessVaries) {
        terms_events<L>(cx);
        terms_loop = false;
        terms_fresh_ = true;
      }
    });
  }
  summed_ = false;
  // The pass's norms hold for this state: add_force_norms sums them.
  if (want_fc && pass_norms(fam.model)) want_fc = false;
  if (!want_fc && !terms_loop) return;
  if (want_fc) norm_.resize(um);
  if (terms_loop) {
    k_.resize(um);
    ka_.resize(um);
    kb_.resize(um);
    live_.resize(um);
  }
  // Raw pointers, so that the loop keeps them in registers (the stores cannot alias them), and
  // a prefetch of the scattered radius of B a few contacts ahead.
  const ContactHist* __restrict__ H = contacts.h.data();
  const BondHist* __restrict__ BD = contacts.bond.empty() ? nullptr : contacts.bond.data();
  const std::uint32_t* __restrict__ A = contacts.a.data();
  const std::uint32_t* __restrict__ B = contacts.b.data();
  const double* __restrict__ R = cx.pt.r.data();
  double* __restrict__ SN = want_fc ? norm_.data() : nullptr;
  double* __restrict__ SK = terms_loop ? k_.data() : nullptr;
  double* __restrict__ SKA = terms_loop ? ka_.data() : nullptr;
  double* __restrict__ SKB = terms_loop ? kb_.data() : nullptr;
  std::uint8_t* __restrict__ SL = terms_loop ? live_.data() : nullptr;
  // On one thread the loop also sums the norms, in contact order from +0 as add_force_norms
  // does (the same bits), so that add_force_norms need not read them again.
  const bool serial = !(nt > 1 && m > 4096);
  double fsum = 0.0;
  std::size_t fcnt = 0;
  visit_law(fam.model, [=, &fam, &fsum, &fcnt](auto law) {
    using L = decltype(law);
    constexpr std::int64_t ahead = 16;
    auto one = [=, &fam](std::int64_t c) __attribute__((always_inline)) {
      if (SK && c + ahead < m) __builtin_prefetch(R + B[c + ahead]);
      const ContactHist& h = H[c];
      const BondHist* b = BD ? BD + c : nullptr;
      double f = 0.0;
      if (SN) SN[c] = f = force_norm<L>(h, b);
      if (SK) stiffness_terms<L>(h, b, fam, R[A[c]], R[B[c]], SK[c], SKA[c], SKB[c], SL[c]);
      return f;
    };
    if (serial && SN) {
      double s = 0.0;
      std::size_t k = 0;
      for (std::int64_t c = 0; c < m; ++c) {
        const double f = one(c);
        const bool pos = f > 0.0;
        s += positive_or_zero(f, pos);
        k += pos;
      }
      fsum = s;
      fcnt = k;
    } else {
#pragma omp parallel for schedule(static) num_threads(nt) if (!serial)
      for (std::int64_t c = 0; c < m; ++c) one(c);
    }
  });
  fsum_ = fsum;
  fcnt_ = fcnt;
  summed_ = serial && want_fc;
  if (terms_loop)
    visit_law(fam.model, [&](auto law) {
      using L = decltype(law);
      if constexpr (!L::kStiffnessVaries) {
        terms_full<L>(cx);
        terms_fresh_ = true;
      }
    });
}

// The kept terms start again from the ones just computed for every contact: every ball's pair
// sums (add_stiffness's serial loop), the per-ball index, and the keys they hold for.
template <class L>
void PairSet::terms_full(const SetContext& cx) {
  const std::size_t n = cx.pt.size(), m = contacts.size();
  kt_pair_.assign(n, 0.0);
  kr_pair_.assign(n, 0.0);
  stiffness_loop(kt_pair_.data(), kr_pair_.data());
  const std::uint32_t* A = contacts.a.data();
  const std::uint32_t* B = contacts.b.data();
  bb_off_.assign(n + 1, 0u);
  for (std::size_t c = 0; c < m; ++c) {
    ++bb_off_[A[c] + 1];
    ++bb_off_[B[c] + 1];
  }
  for (std::size_t i = 0; i < n; ++i) bb_off_[i + 1] += bb_off_[i];
  bb_.resize(2 * m);
  std::vector<std::uint32_t> at(bb_off_.begin(), bb_off_.end() - 1);
  for (std::size_t c = 0; c < m; ++c) {  // ascending c: each ball's entries in contact order
    const auto e = static_cast<std::uint32_t>(2 * c);
    bb_[at[A[c]]++] = e;
    bb_[at[B[c]]++] = e + 1;
  }
  terms_r_ = cx.pt.r;
  const auto* fb = reinterpret_cast<const unsigned char*>(&cx.p.ball_ball);
  terms_fam_.assign(fb, fb + sizeof(ContactFamilyParams));
  terms_gen_ = gen_;
  terms_ok_ = true;
  chg_.assign(m, 0);
  dirty_.assign(n, 0);
}

// The contacts the passes changed: their terms again, then each of their balls' sums from +0
// over its contacts in ascending order (the serial loop's additions for that ball).
template <class L>
void PairSet::terms_events(const SetContext& cx) {
  const ContactFamilyParams& fam = cx.p.ball_ball;
  const double* R = cx.pt.r.data();
  const std::uint32_t* A = contacts.a.data();
  const std::uint32_t* B = contacts.b.data();
  std::vector<std::uint32_t>& balls = dirty_list_;
  balls.clear();
  const std::size_t m = contacts.size();
  for (std::size_t c = 0; c < m; ++c) {
    if (!chg_[c]) continue;
    chg_[c] = 0;
    const BondHist* b = contacts.bond.empty() ? nullptr : &contacts.bond[c];
    stiffness_terms<L>(contacts.h[c], b, fam, R[A[c]], R[B[c]], k_[c], ka_[c], kb_[c], live_[c]);
    for (std::uint32_t i : {A[c], B[c]})
      if (!dirty_[i]) {
        dirty_[i] = 1;
        balls.push_back(i);
      }
  }
  for (std::uint32_t i : balls) {
    double kt = 0.0, kr = 0.0;
    for (std::uint32_t e = bb_off_[i]; e < bb_off_[i + 1]; ++e) {
      const std::uint32_t c = bb_[e] >> 1;
      if (!live_[c]) continue;
      kt += k_[c];
      kr += (bb_[e] & 1u) ? kb_[c] : ka_[c];
    }
    kt_pair_[i] = kt;
    kr_pair_[i] = kr;
    dirty_[i] = 0;
  }
}

// Without a branch: a norm that is not > 0 (0, or NaN) adds +0, which leaves the sum's bits
// unchanged (the sum starts at +0 and only grows), so the additions are those of the loop that
// skips it.
void PairSet::add_force_norms(double& sum, std::size_t& count) const {
  if (summed_) {  // the serial scan's sum, from +0: valid as the first set's (World::contact_scan)
    if (sum != 0.0 || count != 0) throw std::logic_error("PairSet::add_force_norms: the pairs must be the first set");
    sum = fsum_;
    count = fcnt_;
    return;
  }
  const std::size_t m = contacts.size();
  const double* __restrict__ f = norm_.data();
  double s = sum;
  std::size_t k = count;
  for (std::size_t c = 0; c < m; ++c) {
    const bool pos = f[c] > 0.0;
    s += positive_or_zero(f[c], pos);
    k += pos;
  }
  sum = s;
  count = k;
}

// The pairs come first in the cycle, so KT and KR are +0 here: adding a ball's kept pair sum
// gives that sum, the bits of the serial loop.
void PairSet::add_stiffness(const SetContext& cx, double* __restrict__ KT, double* __restrict__ KR) const {
  if (terms_fresh_ && kt_pair_.size() == cx.pt.size()) {
    const std::size_t n = kt_pair_.size();
    for (std::size_t i = 0; i < n; ++i) {
      KT[i] += kt_pair_[i];
      KR[i] += kr_pair_[i];
    }
    return;
  }
  stiffness_loop(KT, KR);
}

void PairSet::stiffness_loop(double* __restrict__ KT, double* __restrict__ KR) const {
  const std::int64_t m = static_cast<std::int64_t>(contacts.size());
  const std::uint32_t* __restrict__ A = contacts.a.data();
  const std::uint32_t* __restrict__ B = contacts.b.data();
  for (std::int64_t c = 0; c < m; ++c) {
    if (c + 16 < m) {
      __builtin_prefetch(KT + B[c + 16], 1);
      __builtin_prefetch(KR + B[c + 16], 1);
    }
    if (!live_[c]) continue;
    const std::uint32_t a = A[c], bb = B[c];
    KT[a] += k_[c];
    KT[bb] += k_[c];
    KR[a] += ka_[c];
    KR[bb] += kb_[c];
  }
}

void PairSet::add_energy(Energy& e, const WorldParams& p, const std::vector<std::uint8_t>& ghost) const {
  detail::add_contact_energy(e, contacts.h, contacts.bond, p.ball_ball, contacts.a, ghost);
}

// ------------------------------------------------------------------------------------------
// bookkeeping

void PairSet::remap(const std::vector<std::uint32_t>& newrow) {
  ++gen_;
  PairContacts& pc = contacts;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    pc.a[c] = newrow[pc.a[c]];
    pc.b[c] = newrow[pc.b[c]];
    if (pc.a[c] > pc.b[c]) {  // keep A = lower row: swap sides
      std::swap(pc.a[c], pc.b[c]);
      for (int k = 0; k < 3; ++k) pc.shift[c][k] = static_cast<std::int8_t>(-pc.shift[c][k]);
      detail::flip(pc.h[c], pc.bond.empty() ? nullptr : &pc.bond[c]);
    }
  }
}

void PairSet::refresh(const SetContext& cx) {
  terms_ok_ = false;  // the histories change
  pn_ok_ = false;
  const bool bb = law_has_bond(cx.p.ball_ball.model);
  PairContacts& pc = contacts;
  for (std::size_t c = 0; c < pc.size(); ++c)
    detail::init_contact(cx.pt, pc.a[c], pc.b[c], pc.h[c], bb ? &pc.bond[c] : nullptr, cx.p.ball_ball, false);
}

void PairSet::reset(PairContacts loaded) {
  contacts = std::move(loaded);
  ++gen_;
  tbuf_.clear();
  row_lo_.clear();
  row_hi_.clear();
}

Vec3 PairSet::force(std::size_t c, const ContactFamilyParams& fam) const {
  const BondHist* b = contacts.bond.empty() ? nullptr : &contacts.bond[c];
  return visit_law(fam.model, [&](auto law) { return decltype(law)::force(contacts.h[c], b); });
}

Vec3 PairSet::moment(std::size_t c, const ContactFamilyParams& fam) const {
  const BondHist* b = contacts.bond.empty() ? nullptr : &contacts.bond[c];
  return visit_law(fam.model, [&](auto law) { return decltype(law)::moment(contacts.h[c], b); });
}

Vec3 PairSet::branch(const Particles& pt, const PeriodicParams& cell, std::size_t c) const {
  Vec3 d = pt.x[contacts.b[c]] - pt.x[contacts.a[c]];
  if (cell.enabled) {
    const auto& s = contacts.shift[c];
    d += cmul(Vec3{double(s[0]), double(s[1]), double(s[2])}, cell.length);
  }
  return d;
}

void PairSet::append(std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& s, const ContactHist& h,
                     const BondHist* bond, bool has_bond) {
  ++gen_;
  contacts.a.push_back(a);
  contacts.b.push_back(b);
  contacts.shift.push_back(s);
  contacts.h.push_back(h);
  if (has_bond) contacts.bond.push_back(bond ? *bond : BondHist{});
}

std::size_t PairSet::bond(const SetContext& cx, double lo, double hi) {
  terms_ok_ = false;  // the histories change
  pn_ok_ = false;
  std::size_t cnt = 0;
  PairContacts& pc = contacts;
  for (std::size_t c = 0; c < pc.size(); ++c) {
    BondHist& b = pc.bond[c];
    if (b.state != BondState::kNeverBonded) continue;
    const Vec3 d = branch(cx.pt, cx.p.periodic, c);
    const double gap = norm(d) - cx.pt.r[pc.a[c]] - cx.pt.r[pc.b[c]];
    if (gap < lo || gap > hi) continue;
    b.state = BondState::kIntact;
    ContactHist& h = pc.h[c];
    h.flags |= ContactHist::kIncremental;  // §3.1: bonding switches to incremental mode
    if (!(h.flags & ContactHist::kHasNormal)) { h.n_old = d * (1.0 / norm(d)); h.flags |= ContactHist::kHasNormal; }
    visit_law(cx.p.ball_ball.model, [&](auto law) { decltype(law)::install_bond(h, b, cx.p.ball_ball); });
    ++cnt;
  }
  return cnt;
}

}  // namespace demfdm::dem
