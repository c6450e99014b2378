// DEM world: cycle, neighbour search, contact passes, gather, law of motion.
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
#include "world_detail.hpp"

namespace demfdm::dem {

namespace {
using detail::Lap;
constexpr double kPi = 3.14159265358979323846;
constexpr std::size_t kChunk = 2048;  // fixed chunking: reductions independent of threads
// Software prefetch distances of the ball–ball pass (bench/dem): the B rows are scattered and
// the history stream is not kept in flight by the hardware prefetcher alone (+20 % measured).
constexpr std::int64_t kPrefetchB = 12;  // contacts ahead for the B rows
constexpr std::int64_t kPrefetchH = 24;  // contacts ahead for the history records



// Force and torque sums of a run of ball–ball contacts onto the balls, in contact order. The
// list is sorted by A: the sums on A are kept in registers for the run of contacts that share
// it and flushed when A changes (fixed order, hence deterministic). The scalar pass calls at()
// for every contact, the block pass for live ones only: the sums are the same, since idle
// contacts add nothing and flushing a zero sum cannot change a ball's sum (the sums start at
// +0 and never become −0).
struct BallSums {
  Vec3* __restrict__ f;
  Vec3* __restrict__ t;
  std::uint32_t cur;
  Vec3 fa{}, ta{};
  // Contact with A = a next: flush the sums of the previous A.
  [[gnu::always_inline]] void at(std::uint32_t a) {
    if (a != cur) {
      f[cur] += fa;
      t[cur] += ta;
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
  void flush() {
    f[cur] += fa;
    t[cur] += ta;
  }
};

// Instruction set of the lane kernels for a PairKernel choice; false: scalar loops.
bool block_isa(PairKernel k, pairblock::Isa& isa) {
  switch (k) {
    case PairKernel::kScalar: return false;
    case PairKernel::kBlockBaseline: isa = pairblock::Isa::kBaseline; return true;
    case PairKernel::kBlockAvx2: isa = pairblock::Isa::kAvx2; return true;
    case PairKernel::kBlockAvx512: isa = pairblock::Isa::kAvx512; return true;
    case PairKernel::kAuto: isa = pairblock::best_isa(); return true;
  }
  return false;
}


// Flip the orientation of a contact's stored vectors (A and B swapped).
void flip(ContactHist& h, BondHist* b) {
  h.fs = -h.fs;
  h.n_old = -h.n_old;
  if (b) {
    b->fsb = -b->fsb;
    b->mb = -b->mb;
    b->mt = -b->mt;
  }
}
}  // namespace

World::World(const WorldParams& p) : p_(p) {
  validate(p_);
  if (p_.periodic.enabled) cell_len_ref_ = p_.periodic.length;
  if (p_.gravity) set_gravity(true, p_.g_level);
}

World::~World() = default;

// ------------------------------------------------------------------------------------------
// particles and constants

std::size_t World::add_ball(const Vec3& x, double radius, double density) {
  if (!(radius > 0.0)) {
    std::ostringstream s;
    s << "add_ball: 'radius' must be > 0 m, found " << radius << ".";
    throw std::invalid_argument(s.str());
  }
  const double rho = density > 0.0 ? density : p_.density;
  const double m = rho * 4.0 / 3.0 * kPi * radius * radius * radius;
  pt_.x.push_back(x);
  pt_.v.push_back({});
  pt_.w.push_back({});
  pt_.f.push_back({});
  pt_.t.push_back({});
  pt_.fa.push_back({});
  pt_.ta.push_back({});
  pt_.x_ref.push_back(x);
  pt_.r.push_back(radius);
  pt_.m.push_back(m);
  pt_.inertia.push_back(0.4 * m * radius * radius);
  pt_.id.push_back(next_id_++);
  pt_.fix.push_back(0);
  dirty_ = true;
  return pt_.size() - 1;
}

void World::set_radius(std::size_t i, double r) {
  const double rho = pt_.m[i] / (4.0 / 3.0 * kPi * pt_.r[i] * pt_.r[i] * pt_.r[i]);
  pt_.r[i] = r;
  pt_.m[i] = rho * 4.0 / 3.0 * kPi * r * r * r;
  pt_.inertia[i] = 0.4 * pt_.m[i] * r * r;
  dirty_ = true;  // the Verlet list depends on the radii
  last_dt_step_ = -1;
}

std::vector<std::uint32_t> World::reorder_spatially() {
  const std::size_t n = pt_.size();
  std::vector<std::uint32_t> newrow(n);
  if (n == 0) return newrow;
  Vec3 lo = pt_.x[0], hi = lo;
  double rmax = 0.0;
  for (std::size_t i = 0; i < n; ++i) {
    rmax = std::max(rmax, pt_.r[i]);
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], pt_.x[i][k]);
      hi[k] = std::max(hi[k], pt_.x[i][k]);
    }
  }
  // Morton (z-order) key of cells of size 2 R_max: neighbours end up close in memory.
  const double cs = 2.0 * rmax;
  auto spread = [](std::uint64_t v) {
    v &= 0x1fffff;
    v = (v | v << 32) & 0x1f00000000ffffULL;
    v = (v | v << 16) & 0x1f0000ff0000ffULL;
    v = (v | v << 8) & 0x100f00f00f00f00fULL;
    v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
    v = (v | v << 2) & 0x1249249249249249ULL;
    return v;
  };
  std::vector<std::pair<std::uint64_t, std::uint32_t>> key(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t c[3];
    for (int k = 0; k < 3; ++k) c[k] = static_cast<std::uint64_t>((pt_.x[i][k] - lo[k]) / cs);
    key[i] = {spread(c[0]) | spread(c[1]) << 1 | spread(c[2]) << 2, static_cast<std::uint32_t>(i)};
  }
  std::sort(key.begin(), key.end());
  for (std::size_t k = 0; k < n; ++k) newrow[key[k].second] = static_cast<std::uint32_t>(k);
  auto perm = [&](auto& v) {
    auto old = v;
    for (std::size_t i = 0; i < n; ++i) v[newrow[i]] = old[i];
  };
  perm(pt_.x); perm(pt_.v); perm(pt_.w); perm(pt_.f); perm(pt_.t); perm(pt_.fa); perm(pt_.ta);
  perm(pt_.x_ref); perm(pt_.r); perm(pt_.m); perm(pt_.inertia); perm(pt_.id); perm(pt_.fix);
  for (std::size_t c = 0; c < pc_.size(); ++c) {
    pc_.a[c] = newrow[pc_.a[c]];
    pc_.b[c] = newrow[pc_.b[c]];
    if (pc_.a[c] > pc_.b[c]) {  // keep A = lower row: swap sides
      std::swap(pc_.a[c], pc_.b[c]);
      for (int k = 0; k < 3; ++k) pc_.shift[c][k] = static_cast<std::int8_t>(-pc_.shift[c][k]);
      flip(pc_.h[c], pc_.bond.empty() ? nullptr : &pc_.bond[c]);
    }
  }
  for (WallContacts* wc : {&plc_, &fcc_, &ftc_})
    for (auto& b : wc->ball) b = newrow[b];
  dirty_ = true;
  return newrow;
}

LawConst World::law_const(const ContactFamilyParams& f, bool wall) const {
  return visit_law(f.model, [&](auto law) { return decltype(law)::constants(f, p_.rescale_shear, wall); });
}

// Precomputed per-contact constants from the deformability method (§1.7, §2.2, §3.3).
// `wall` marks a ball–wall contact of ball a (b unused); otherwise a ball–ball contact.
void World::init_contact(std::uint32_t a, std::uint32_t b, ContactHist& h, BondHist* bond,
                         const ContactFamilyParams& fam, bool wall) const {
  const double ra = pt_.r[a];
  double rbar, L;
  if (!wall) {
    const double rb = pt_.r[b];
    rbar = std::min(ra, rb);
    L = ra + rb;
  } else {
    rbar = ra;
    L = fam.linear.wall_length == WallLength::kRadius ? ra : 2.0 * ra;
  }
  visit_law(fam.model, [&](auto law) { decltype(law)::init(rbar, L, h, bond, fam); });
}

void World::refresh_contact_constants() {
  const bool bb = law_has_bond(p_.ball_ball.model);
  for (std::size_t c = 0; c < pc_.size(); ++c)
    init_contact(pc_.a[c], pc_.b[c], pc_.h[c], bb ? &pc_.bond[c] : nullptr, p_.ball_ball, false);
  auto wall = [&](WallContacts& wc, const ContactFamilyParams& fam) {
    const bool bd = law_has_bond(fam.model);
    for (std::size_t c = 0; c < wc.size(); ++c)
      init_contact(wc.ball[c], 0, wc.h[c], bd ? &wc.bond[c] : nullptr, fam, true);
  };
  wall(plc_, p_.ball_wall);
  wall(fcc_, p_.ball_facet);
  wall(ftc_, p_.ball_footing);
  last_dt_step_ = -1;
}

// ------------------------------------------------------------------------------------------
// walls

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
  planes_.push_back(w);
  dirty_ = true;
  return static_cast<int>(planes_.size()) - 1;
}

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
  fwalls_.push_back(std::move(fw));
  update_facet_spin(fwalls_.back());
  dirty_ = true;
  return static_cast<int>(fwalls_.size()) - 1;
}

// §6.2 facet normal and kinematic spin ω_f = ω_⊥ + ω_n n̂ from the vertex velocities.
void World::update_facet_spin(FacetWall& fw) {
  for (std::size_t t = 0; t < fw.tri.size(); ++t) {
    const auto& tr = fw.tri[t];
    const Vec3 e1 = fw.pos[tr[1]] - fw.pos[tr[0]], e2 = fw.pos[tr[2]] - fw.pos[tr[0]];
    Vec3 n = cross(e1, e2);
    const double nn = norm(n);
    if (!(nn > 0.0)) throw std::invalid_argument("facet wall: degenerate triangle (zero area).");
    n *= 1.0 / nn;
    fw.tri_normal[t] = n;
    if (!p_.facet_spin) { fw.tri_spin[t] = Vec3{}; continue; }
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

void World::set_vertex_kinematics(int wall, std::span<const double> pos, std::span<const double> vel) {
  if (wall < 0 || wall >= num_facet_walls())
    throw std::invalid_argument("set_vertex_kinematics: 'wall' index out of range.");
  FacetWall& fw = fwalls_[static_cast<std::size_t>(wall)];
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
  update_facet_spin(fw);
}

std::span<const double> World::vertex_forces(int wall) const {
  const auto& fw = fwalls_.at(static_cast<std::size_t>(wall));
  return {reinterpret_cast<const double*>(fw.vforce.data()), 3 * fw.vforce.size()};
}
std::span<const double> World::vertex_stiffness(int wall) const {
  const auto& fw = fwalls_.at(static_cast<std::size_t>(wall));
  return {fw.vstiff.data(), fw.vstiff.size()};
}
Vec3 World::facet_wall_force(int wall) const { return fwalls_.at(static_cast<std::size_t>(wall)).total_force; }
Vec3 World::facet_walls_total_force() const {
  Vec3 s{};
  for (const auto& fw : fwalls_) s += fw.total_force;
  return s;
}

void World::set_footing(const FootingParams& p) {
  if (!(p.diameter > 0.0) || !(p.height > 0.0)) {
    std::ostringstream s;
    s << "set_footing: 'diameter' and 'height' must be > 0 m, found " << p.diameter << " and "
      << p.height << ".";
    throw std::invalid_argument(s.str());
  }
  footing_.p = p;
  if (!footing_.enabled) footing_.id = next_wall_id_++;
  footing_.enabled = true;
  dirty_ = true;
}
void World::remove_footing() {
  footing_.enabled = false;
  dirty_ = true;
}
void World::set_footing_position(const Vec3& c) {
  footing_.disp += c - footing_.p.bottom_centre;
  footing_.p.bottom_centre = c;
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

Vec3 World::pair_force(std::size_t c) const {
  const BondHist* b = pc_.bond.empty() ? nullptr : &pc_.bond[c];
  return visit_law(p_.ball_ball.model, [&](auto law) { return decltype(law)::force(pc_.h[c], b); });
}

Vec3 World::pair_moment(std::size_t c) const {
  const BondHist* b = pc_.bond.empty() ? nullptr : &pc_.bond[c];
  return visit_law(p_.ball_ball.model, [&](auto law) { return decltype(law)::moment(pc_.h[c], b); });
}

Vec3 World::branch(std::size_t c) const {
  Vec3 d = pt_.x[pc_.b[c]] - pt_.x[pc_.a[c]];
  if (p_.periodic.enabled) {
    const auto& s = pc_.shift[c];
    d += cmul(Vec3{double(s[0]), double(s[1]), double(s[2])}, p_.periodic.length);
  }
  return d;
}

// ------------------------------------------------------------------------------------------
// neighbour search and history

void World::clear_contacts() {
  pc_ = PairContacts{};
  plc_ = WallContacts{};
  fcc_ = WallContacts{};
  ftc_ = WallContacts{};
  dirty_ = true;
}

void World::append_pair(std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& s,
                        const ContactHist& h, const BondHist* bond) {
  pc_.a.push_back(a);
  pc_.b.push_back(b);
  pc_.shift.push_back(s);
  pc_.h.push_back(h);
  if (law_has_bond(p_.ball_ball.model)) pc_.bond.push_back(bond ? *bond : BondHist{});
  dirty_ = true;
}

bool World::need_rebuild() const {
  if (dirty_) return true;
  const double dmax = std::sqrt(max_disp2_);
  double dcell = 0.0;
  if (p_.periodic.enabled)
    for (int k = 0; k < 3; ++k)
      dcell = std::max(dcell, std::abs(p_.periodic.length[k] - cell_len_ref_[k]));
  if (2.0 * dmax + dcell > skin_) return true;
  double dw = 0.0;
  for (const auto& pw : planes_) dw = std::max(dw, norm(pw.disp));
  if (footing_.enabled) dw = std::max(dw, norm(footing_.disp));
  for (const auto& fw : fwalls_)
    for (std::size_t i = 0; i < fw.pos.size(); ++i) dw = std::max(dw, norm(fw.pos[i] - fw.pos_ref[i]));
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
  const std::vector<PairCandidate> np = find_pair_candidates(pt_.x, pt_.r, skin_, p_.periodic, pc_.size() + n * 4);
  // merge the history keyed by (id_A, id_B): a contact's history follows the pair
  const bool has_bond = law_has_bond(p_.ball_ball.model);
  // The old list's rows are current (reorder_spatially remaps them). A rebuild leaves it sorted
  // by (a, b) with a < b, like the new one: then one linear merge finds each old contact. A
  // reorder or appended pairs break the order: then the history is found by its id key.
  const std::size_t mo = pc_.size();
  auto row_key = [](std::uint32_t a, std::uint32_t b) { return std::uint64_t(a) << 32 | b; };
  bool sorted = true;
  for (std::size_t c = 0; c < mo && sorted; ++c)
    sorted = pc_.a[c] < pc_.b[c] && (c == 0 || row_key(pc_.a[c - 1], pc_.b[c - 1]) < row_key(pc_.a[c], pc_.b[c]));
  // Keys: rows (a, b) for the linear merge, ids (lower, higher) otherwise.
  auto id_key = [&](std::uint32_t a, std::uint32_t b) {
    const std::uint64_t ia = pt_.id[a], ib = pt_.id[b];
    return std::make_pair(std::min(ia, ib), std::max(ia, ib));
  };
  auto old_key = [&](std::size_t c) {
    return sorted ? std::make_pair(std::uint64_t(pc_.a[c]), std::uint64_t(pc_.b[c])) : id_key(pc_.a[c], pc_.b[c]);
  };
  detail::HistoryCarry carry(mo, sorted, old_key);
  auto find_old = [&](std::uint32_t a, std::uint32_t b) -> std::int64_t {
    const auto k = sorted ? std::make_pair(std::uint64_t(a), std::uint64_t(b)) : id_key(a, b);
    return carry.take(k.first, k.second);
  };
  PairContacts q;
  q.a.reserve(np.size());
  q.b.reserve(np.size());
  q.shift.reserve(np.size());
  q.h.reserve(np.size());
  if (has_bond) q.bond.reserve(np.size());
  auto push = [&](std::uint32_t a, std::uint32_t b, const std::array<std::int8_t, 4>& s) {
    q.a.push_back(a);
    q.b.push_back(b);
    q.shift.push_back(s);
    const std::uint64_t ia = pt_.id[a];
    const std::int64_t found = find_old(a, b);
    if (found >= 0) {
      const std::uint32_t oc = static_cast<std::uint32_t>(found);
      q.h.push_back(pc_.h[oc]);
      if (has_bond) q.bond.push_back(pc_.bond[oc]);
      if (pt_.id[pc_.a[oc]] != ia) flip(q.h.back(), has_bond ? &q.bond.back() : nullptr);
    } else {
      q.h.push_back({});
      if (has_bond) q.bond.push_back({});
      init_contact(a, b, q.h.back(), has_bond ? &q.bond.back() : nullptr, p_.ball_ball, false);
    }
  };
  for (const auto& e : np) push(e.a, e.b, e.s);
  // bonded contacts beyond the cut-off are kept (a bond never disappears in a rebuild)
  bool appended = false;
  carry.rest(
      pc_.h, pc_.bond, has_bond,
      [&](std::size_t c) {
        std::uint32_t a = pc_.a[c], b = pc_.b[c];
        Vec3 d = pt_.x[b] - pt_.x[a];
        std::array<std::int8_t, 4> s{0, 0, 0, 0};
        if (per)
          for (int k = 0; k < 3; ++k) {
            const double sh = -std::round(d[k] / L[k]);
            s[k] = static_cast<std::int8_t>(sh);
          }
        q.a.push_back(a);
        q.b.push_back(b);
        q.shift.push_back(s);
        q.h.push_back(pc_.h[c]);
        q.bond.push_back(pc_.bond[c]);
        appended = true;
      },
      e_slip_dead_, e_soft_dead_);
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
  pc_ = std::move(q);
  rebuild_walls();
  pt_.x_ref = pt_.x;
  max_disp2_ = 0.0;
  if (per) cell_len_ref_ = p_.periodic.length;
  dirty_ = false;
}



// ------------------------------------------------------------------------------------------
// contact passes (one template instantiation per pass; no model branch in the loops)

// Ball–ball pass. Each contact stores its force (and moment) in its own slot for the
// measurements, and adds −F/+F and the torques into a force buffer: the particle arrays for
// thread 0 and a private buffer for every other thread; the buffers are then summed in
// thread order. The static partition makes the result bit-identical from run to run for a
// given thread count (determinism: same scene, seed and thread count, same bits).
template <class Law, bool Periodic>
void World::pair_pass(double dt) {
  const std::int64_t m = static_cast<std::int64_t>(pc_.size());
  const std::size_t n = pt_.size();
  const LawConst lc = law_const(p_.ball_ball, false);
  // No array aliases another (restrict lets loads be kept across the force stores).
  const Vec3* __restrict__ X = pt_.x.data();
  const Vec3* __restrict__ V = pt_.v.data();
  const Vec3* __restrict__ W = pt_.w.data();
  const double* __restrict__ R = pt_.r.data();
  const std::uint32_t* __restrict__ A = pc_.a.data();
  const std::uint32_t* __restrict__ B = pc_.b.data();
  const auto* __restrict__ S = pc_.shift.data();
  ContactHist* __restrict__ H = pc_.h.data();
  BondHist* __restrict__ BD = pc_.bond.empty() ? nullptr : pc_.bond.data();
  const Vec3 L = p_.periodic.length;
  const Vec3 ed = edot_;
  const double rgap = lc.rgap;
  const int nt = thread_count();
  const bool par = nt > 1 && m > 4096;
  const bool strained = ed.x != 0.0 || ed.y != 0.0 || ed.z != 0.0;
  // Vectorised blocks (pair_block.hpp) where the law has a lane kernel; bit-identical to the
  // scalar loop below (tests/dem/simd_kernel_test.cpp).
  pairblock::Fn kern = nullptr;
  {
    pairblock::Isa isa;
    if (block_isa(kernel_, isa)) kern = Law::lane_kernel(isa, lc);
  }
  const pairblock::Ctx ctx{V, W, R, H, BD, lc, dt, ed, Periodic && strained};
  // The helpers below are forced inline: left to GCC, the soft-bond block pass measured 1.27 x
  // slower (bench/dem/results_2core_kvm.csv).
  // The helpers and the loop bodies capture by value: the arrays' base pointers then live in the
  // closures as copies the loop can keep in registers, where a by-reference capture made GCC
  // reload them through the captured locals after every store (3.2 % + 2.5 % fewer instructions
  // in the soft-bond pass, callgrind, the same state hash).
  // Software prefetch (see kPrefetchB/H): the scattered B rows, and the history records
  // (96 B, plus 104 B of bond state) that the loop streams through.
  auto prefetch = [=](std::int64_t c, std::int64_t c1, const Vec3* f, const Vec3* t) __attribute__((always_inline)) {
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
      __builtin_prefetch(f + bp, 1);
      __builtin_prefetch(t + bp, 1);
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
  auto law = [=, this](std::int64_t c, std::uint32_t a, std::uint32_t b, const Vec3& d, double d2, Vec3& F, Vec3& TA,
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
      if (was_intact && BD[c].state != BondState::kIntact) {
#pragma omp atomic
        ++bond_failures_;
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
  auto body = [=](std::int64_t c0, std::int64_t c1, Vec3* __restrict__ f, Vec3* __restrict__ t) {
    BallSums sums{f, t, c0 < c1 ? A[c0] : 0u};
    for (std::int64_t c = c0; c < c1; ++c) {
      const std::uint32_t a = A[c], b = B[c];
      prefetch(c, c1, f, t);
      sums.at(a);
      Vec3 d;
      double d2;
      branch_d(c, a, b, d, d2);
      if (idle(c, a, b, d2)) {
        if (H[c].flags & ContactHist::kActive) H[c].flags &= static_cast<std::uint8_t>(~kActSlip);
        continue;
      }
      Vec3 F, TA, TB;
      law(c, a, b, d, d2, F, TA, TB);
      sums.add(b, F, TA, TB);
    }
    if (c0 < c1) sums.flush();
  };
  // Blocks of kLanes live contacts: stage 1 (lane list), stage 2 (kern), stage 3 (histories
  // and sums in contact order; lanes flagged `scalar` are redone by the scalar law from their
  // untouched history).
  auto body_block = [=](std::int64_t c0, std::int64_t c1, Vec3* __restrict__ f, Vec3* __restrict__ t) {
    constexpr int K = pairblock::kLanes;
    BallSums sums{f, t, c0 < c1 ? A[c0] : 0u};
    pairblock::In in;
    pairblock::Out out;
    std::int64_t c = c0;
    while (c < c1) {
      int n = 0;
      for (; c < c1 && n < K; ++c) {
        const std::uint32_t a = A[c], b = B[c];
        prefetch(c, c1, f, t);
        Vec3 d;
        double d2;
        branch_d(c, a, b, d, d2);
        // Branch-free: the lane is written for every contact and kept (n advances) only for a
        // live one; an idle contact gets kActive and kSlip cleared (the same flags as `body`).
        const bool skip = idle(c, a, b, d2);
        const std::uint8_t fl = H[c].flags;
        H[c].flags = skip ? static_cast<std::uint8_t>(fl & ~kActSlip) : fl;
        in.c[n] = c;
        in.a[n] = a;
        in.b[n] = b;
        in.dx[n] = d.x;
        in.dy[n] = d.y;
        in.dz[n] = d.z;
        in.d2[n] = d2;
        in.hasn[n] = (fl & ContactHist::kHasNormal) != 0;
        in.incr[n] = (fl & ContactHist::kIncremental) != 0;
        in.scalar[n] = Law::lane_needs_scalar(bond_at(c));
        n += !skip;
      }
      if (n == 0) break;
      for (int l = n; l < K; ++l) {  // padding lanes repeat lane 0
        in.c[l] = in.c[0]; in.a[l] = in.a[0]; in.b[l] = in.b[0];
        in.dx[l] = in.dx[0]; in.dy[l] = in.dy[0]; in.dz[l] = in.dz[0]; in.d2[l] = in.d2[0];
        in.hasn[l] = in.hasn[0]; in.incr[l] = in.incr[0]; in.scalar[l] = in.scalar[0];
      }
      kern(ctx, in, out);
      for (int l = 0; l < n; ++l) {
        const std::int64_t cl = in.c[l];
        const std::uint32_t a = static_cast<std::uint32_t>(in.a[l]), b = static_cast<std::uint32_t>(in.b[l]);
        Vec3 F, TA, TB;
        if (out.scalar[l]) {
          law_rare(cl, a, b, Vec3{in.dx[l], in.dy[l], in.dz[l]}, in.d2[l], F, TA, TB);
        } else {
          Law::store_lane(H[cl], bond_at(cl), out, l);
          F = {out.F[0][l], out.F[1][l], out.F[2][l]};
          TA = {out.TA[0][l], out.TA[1][l], out.TA[2][l]};
          TB = {out.TB[0][l], out.TB[1][l], out.TB[2][l]};
        }
        sums.at(a);
        sums.add(b, F, TA, TB);
      }
    }
    if (c0 < c1) sums.flush();
  };
  auto run = [&](std::int64_t c0, std::int64_t c1, Vec3* f, Vec3* t) {
    if (kern) body_block(c0, c1, f, t);
    else body(c0, c1, f, t);
  };
  if (!par) {
    std::fill(pt_.f.begin(), pt_.f.end(), Vec3{});
    std::fill(pt_.t.begin(), pt_.t.end(), Vec3{});
    run(0, m, pt_.f.data(), pt_.t.data());
    return;
  }
  if (tbuf_.size() < static_cast<std::size_t>(nt)) tbuf_.resize(static_cast<std::size_t>(nt));
  // Thread buffers are all zero between passes (zeroed by the reduction that reads them), so a
  // block only costs the rows it touches: [lo, hi) of its contacts' rows, found by a scan of
  // its (A, B) indices. Adding zeros elsewhere is skipped; the order of the sums is unchanged.
  for (int k = 1; k < nt; ++k) {
    auto& tb = tbuf_[static_cast<std::size_t>(k)];
    if (tb.size() != 2 * n) tb.assign(2 * n, Vec3{});
  }
  row_lo_.assign(static_cast<std::size_t>(nt), n);
  row_hi_.assign(static_cast<std::size_t>(nt), 0);
  // One parallel region per pass: contact blocks, a barrier, then the fixed-order
  // reduction of the thread buffers split by particle rows (one fork/join per step).
#pragma omp parallel num_threads(nt)
  {
    const int tid = omp_get_thread_num(), T = omp_get_num_threads();
    const std::size_t ut = static_cast<std::size_t>(tid);
    const std::int64_t c0 = m * tid / T, c1 = m * (tid + 1) / T;
    Vec3* f = pt_.f.data();
    Vec3* t = pt_.t.data();
    if (tid == 0) {
      std::fill(f, f + n, Vec3{});
      std::fill(t, t + n, Vec3{});
    } else {
      f = tbuf_[ut].data();
      t = f + n;
      std::uint32_t lo = static_cast<std::uint32_t>(n), hi = 0;
      for (std::int64_t c = c0; c < c1; ++c) {
        lo = std::min(lo, std::min(A[c], B[c]));
        hi = std::max(hi, std::max(A[c], B[c]));
      }
      row_lo_[ut] = lo;
      row_hi_[ut] = c0 < c1 ? std::size_t{hi} + 1 : 0;
    }
    run(c0, c1, f, t);
#pragma omp barrier
    std::size_t rlo = n, rhi = 0;
    for (int k = 1; k < T; ++k) {
      rlo = std::min(rlo, row_lo_[static_cast<std::size_t>(k)]);
      rhi = std::max(rhi, row_hi_[static_cast<std::size_t>(k)]);
    }
#pragma omp for schedule(static)
    for (std::int64_t ii = static_cast<std::int64_t>(rlo); ii < static_cast<std::int64_t>(rhi); ++ii) {
      const std::size_t i = static_cast<std::size_t>(ii);
      for (int k = 1; k < T; ++k) {
        const std::size_t uk = static_cast<std::size_t>(k);
        if (i < row_lo_[uk] || i >= row_hi_[uk]) continue;
        Vec3& bf = tbuf_[uk][i];
        Vec3& bt = tbuf_[uk][n + i];
        pt_.f[i] += bf;
        pt_.t[i] += bt;
        bf = Vec3{};
        bt = Vec3{};
      }
    }
  }
}


void World::force_pass(double dt) {
  // One switch per pass selects the template instantiation (no virtual call per contact).
  const bool per = p_.periodic.enabled;
  Lap lap;
  times_.pair_model = to_string(p_.ball_ball.model);
  visit_law(p_.ball_ball.model, [&](auto law) {
    using L = decltype(law);
    per ? pair_pass<L, true>(dt) : pair_pass<L, false>(dt);
  });
  lap(times_.pair);
  wall_passes(dt);  // walls.cpp
  Lap lap_gather;
  gather();
  lap_gather(times_.gather);
  run_effects(1);
}

// Wall contacts act on balls after the ball–ball pass, serially in contact order.
void World::gather() {
  Vec3* f = pt_.f.data();
  Vec3* t = pt_.t.data();
  for (const WallContacts* wc : {&plc_, &fcc_, &ftc_})
    for (std::size_t c = 0; c < wc->size(); ++c) {
      f[wc->ball[c]] -= wc->F[c];
      t[wc->ball[c]] += wc->TA[c];
    }
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
void World::integrate_rows(std::size_t i0, std::size_t i1, double dt, const Vec3& sc, double& ed, double& dmax) {
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
  auto row = [&](std::size_t i) __attribute__((always_inline)) {
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
  if (block_isa(kernel_, isa)) {
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
          for (int q = 0; q < 6; ++q) ed -= out.e[q][l];
        }
        dmax = std::max(dmax, out.d2[l]);
      }
    }
  }
  for (; i < i1; ++i) row(i);
}

void World::integrate(double dt) {
  const std::size_t n = pt_.size();
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
  const std::int64_t m = static_cast<std::int64_t>(pc_.size());
  const int nt = thread_count();
  // One parallel pass over the ball-ball contacts computes each contact's terms (its force norm,
  // its stiffnesses); the sums over them then run in contact order, the additions and their order
  // of one serial loop: the same bits at any thread count.
  const std::size_t um = pc_.size();
  if (want_fc) scratch_norm_.resize(um);
  if (want_dt) {
    scratch_k_.resize(um);
    scratch_ka_.resize(um);
    scratch_kb_.resize(um);
    scratch_live_.resize(um);
  }
  // Raw pointers, so that the loop keeps them in registers (the stores cannot alias them), and
  // a prefetch of the scattered radius of B a few contacts ahead.
  const ContactHist* __restrict__ H = pc_.h.data();
  const BondHist* __restrict__ BD = pc_.bond.empty() ? nullptr : pc_.bond.data();
  const std::uint32_t* __restrict__ A = pc_.a.data();
  const std::uint32_t* __restrict__ B = pc_.b.data();
  const double* __restrict__ R = pt_.r.data();
  double* __restrict__ SN = want_fc ? scratch_norm_.data() : nullptr;
  double* __restrict__ SK = want_dt ? scratch_k_.data() : nullptr;
  double* __restrict__ SKA = want_dt ? scratch_ka_.data() : nullptr;
  double* __restrict__ SKB = want_dt ? scratch_kb_.data() : nullptr;
  std::uint8_t* __restrict__ SL = want_dt ? scratch_live_.data() : nullptr;
  const ContactFamilyParams& fam = p_.ball_ball;
  visit_law(fam.model, [=, &fam](auto law) {
    using L = decltype(law);
    constexpr std::int64_t ahead = 16;
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1 && m > 4096)
    for (std::int64_t c = 0; c < m; ++c) {
      if (want_dt && c + ahead < m) __builtin_prefetch(R + B[c + ahead]);
      const ContactHist& h = H[c];
      const BondHist* b = BD ? BD + c : nullptr;
      if (want_fc) SN[c] = norm(L::force(h, b));
      if (!want_dt) continue;
      // Each counted contact adds the stiffnesses of its law (Law::stiffness): translational to
      // both balls, rotational plus k_s R² to each.
      const bool live = (h.flags & ContactHist::kActive) || (b && bonded(b->state));
      SL[c] = live;
      if (!live) continue;
      const std::uint32_t a = A[c], bb = B[c];
      const ContactStiffness s = L::stiffness(h, b, fam, R[a], R[bb]);
      SK[c] = s.k;
      SKA[c] = s.krot + s.ks * R[a] * R[a];
      SKB[c] = s.krot + s.ks * R[bb] * R[bb];
    }
  });
  if (want_fc) {
    double sum = 0.0;
    std::size_t cnt = 0;
    for (std::int64_t c = 0; c < m; ++c) {
      const double f = SN[c];
      if (f > 0.0) { sum += f; ++cnt; }
    }
    for (const WallContacts* wc : {&plc_, &fcc_, &ftc_})
      for (std::size_t c = 0; c < wc->size(); ++c) {
        const double f = norm(wc->F[c]);
        if (f > 0.0) { sum += f; ++cnt; }
      }
    out.fc = cnt ? sum / double(cnt) : 0.0;
  }
  if (!want_dt) return out;
  std::vector<double>& kt = scratch_kt_;
  std::vector<double>& kr = scratch_kr_;
  kt.assign(n, 0.0);
  kr.assign(n, 0.0);
  double* __restrict__ KT = kt.data();
  double* __restrict__ KR = kr.data();
  for (std::int64_t c = 0; c < m; ++c) {
    if (c + 16 < m) {
      __builtin_prefetch(KT + B[c + 16], 1);
      __builtin_prefetch(KR + B[c + 16], 1);
    }
    if (!SL[c]) continue;
    const std::uint32_t a = A[c], bb = B[c];
    KT[a] += SK[c];
    KT[bb] += SK[c];
    KR[a] += SKA[c];
    KR[bb] += SKB[c];
  }
  auto wall = [&](const WallContacts& wc, const ContactFamilyParams& fam) {
    visit_law(fam.model, [&](auto law) {
      using L = decltype(law);
      for (std::size_t c = 0; c < wc.size(); ++c) {
        const ContactHist& h = wc.h[c];
        const BondHist* b = wc.bond.empty() ? nullptr : &wc.bond[c];
        if (!(h.flags & ContactHist::kActive) && !(b && bonded(b->state))) continue;
        const std::uint32_t i = wc.ball[c];
        const ContactStiffness s = L::stiffness(h, b, fam, pt_.r[i], 0.0);
        kt[i] += s.k;
        kr[i] += s.krot + s.ks * pt_.r[i] * pt_.r[i];
      }
    });
  };
  wall(plc_, p_.ball_wall);
  wall(fcc_, p_.ball_facet);
  wall(ftc_, p_.ball_footing);
  // The smallest step over the balls (a minimum: exact in any order).
  double dt = std::numeric_limits<double>::infinity();
  const std::int64_t ni = static_cast<std::int64_t>(n);
#pragma omp parallel for schedule(static) num_threads(nt) if (nt > 1 && ni > 4096) reduction(min : dt)
  for (std::int64_t i = 0; i < ni; ++i) {
    if (kt[i] > 0.0) dt = std::min(dt, std::sqrt(pt_.m[i] / kt[i]));
    if (kr[i] > 0.0) dt = std::min(dt, std::sqrt(pt_.inertia[i] / kr[i]));
  }
  if (!std::isfinite(dt)) {
    // No active contact: use one contact with an equal ball (the law's reference stiffness;
    // linear springs: k_n = π R E*/2, §7.2).
    visit_law(p_.ball_ball.model, [&](auto law) {
      for (std::size_t i = 0; i < n; ++i) {
        const double k = decltype(law)::reference_stiffness(pt_.r[i], p_.ball_ball);
        if (k > 0.0) dt = std::min(dt, std::sqrt(pt_.m[i] / k));
      }
    });
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
  for (auto& pw : planes_) {
    pw.p.point += dt_ * pw.p.velocity;
    pw.disp += dt_ * pw.p.velocity;
  }
  if (footing_.enabled) {
    footing_.p.bottom_centre += dt_ * footing_.p.velocity;
    footing_.disp += dt_ * footing_.p.velocity;
  }
  time_ += dt_;
  ++step_;
  lap_walls(times_.motion);
  if (need_rebuild()) rebuild();
  lap_walls(times_.rebuild);
  force_pass(dt_);
  run_effects(2);
  ++times_.steps;
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
  std::size_t cnt = 0;
  for (std::size_t c = 0; c < pc_.size(); ++c) {
    BondHist& b = pc_.bond[c];
    if (b.state != BondState::kNeverBonded) continue;
    const Vec3 d = branch(c);
    const double gap = norm(d) - pt_.r[pc_.a[c]] - pt_.r[pc_.b[c]];
    if (gap < lo || gap > hi) continue;
    b.state = BondState::kIntact;
    ContactHist& h = pc_.h[c];
    h.flags |= ContactHist::kIncremental;  // §3.1: bonding switches to incremental mode
    if (!(h.flags & ContactHist::kHasNormal)) { h.n_old = d * (1.0 / norm(d)); h.flags |= ContactHist::kHasNormal; }
    visit_law(p_.ball_ball.model, [&](auto law) { decltype(law)::install_bond(h, b, p_.ball_ball); });
    ++cnt;
  }
  last_dt_step_ = -1;
  return cnt;
}


// ------------------------------------------------------------------------------------------
// measurements

double World::kinetic_energy() const {
  return ordered_ball_sum(
      [this](std::size_t i) { return 0.5 * pt_.m[i] * norm2(pt_.v[i]) + 0.5 * pt_.inertia[i] * norm2(pt_.w[i]); });
}

Energy World::energy() const {
  Energy e;
  e.kinetic = kinetic_energy();
  e.damping = e_damp_;
  e.friction = e_slip_dead_;
  e.softening = e_soft_dead_;
  auto add = [&](const std::vector<ContactHist>& hs, const std::vector<BondHist>& bs,
                 const ContactFamilyParams& fam) {
    visit_law(fam.model, [&](auto law) {
      for (std::size_t c = 0; c < hs.size(); ++c) {
        const ContactHist& h = hs[c];
        const BondHist* b = bs.empty() ? nullptr : &bs[c];
        decltype(law)::add_strain(e.strain, h, b, fam);
        e.friction += h.e_slip;
        if (b) e.softening += b->e_soft;
      }
    });
  };
  add(pc_.h, pc_.bond, p_.ball_ball);
  add(plc_.h, plc_.bond, p_.ball_wall);
  add(fcc_.h, fcc_.bond, p_.ball_facet);
  add(ftc_.h, ftc_.bond, p_.ball_footing);
  return e;
}

namespace {
double unbalanced(const Particles& pt, std::size_t i) {
  const Vec3 F = pt.f[i] + pt.fa[i];
  double s = 0.0;
  for (int k = 0; k < 3; ++k)
    if (!(pt.fix[i] & (1u << k))) s += F[k] * F[k];
  return std::sqrt(s);
}
}  // namespace

double World::mean_contact_force() const { return contact_scan(false, true).fc; }

double World::unbalanced_ratio() const {
  if (pt_.size() == 0) return 0.0;
  return unbalanced_ratio(mean_contact_force());
}

double World::unbalanced_ratio(double fc) const {
  if (pt_.size() == 0) return 0.0;
  const double s = ordered_ball_sum([this](std::size_t i) { return unbalanced(pt_, i); });
  if (fc <= 0.0) return s > 0.0 ? std::numeric_limits<double>::infinity() : 0.0;
  return (s / double(pt_.size())) / fc;
}

double World::max_unbalanced_force() const {
  double s = 0.0;
  for (std::size_t i = 0; i < pt_.size(); ++i) s = std::max(s, unbalanced(pt_, i));
  return s;
}

}  // namespace demfdm::dem
