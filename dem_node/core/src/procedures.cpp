#include "demfdm/dem/procedures.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include "demfdm/dem/measure.hpp"

namespace demfdm::dem {

SkeletonRatio skeleton_ratio(const World& w) { return skeleton_ratio(w, w.mean_contact_force()); }

using detail::rattler_of;
using detail::term_of;

bool is_rattler(const World& w, std::size_t i, const Vec3& g) {
  Vec3 f;
  return rattler_of(w.balls(), i, g, f);
}

double skeleton_term(const World& w, std::size_t i, const Vec3& g) {
  Vec3 f;
  if (rattler_of(w.balls(), i, g, f)) return 0.0;
  return term_of(w.balls(), i, f);
}

bool is_rattler(const World& w, std::size_t i) { return is_rattler(w, i, w.gravity()); }

double skeleton_term(const World& w, std::size_t i) { return skeleton_term(w, i, w.gravity()); }

SkeletonRatio skeleton_ratio_of(double sum, std::size_t rattlers, std::size_t balls, double fc) {
  SkeletonRatio r;
  r.rattlers = rattlers;
  const std::size_t n = balls - rattlers;
  r.ratio = n == 0 || fc <= 0 ? std::numeric_limits<double>::infinity() : sum / static_cast<double>(n) / fc;
  return r;
}

SkeletonRatio skeleton_ratio(const World& w, double fc) {
  // is_rattler and skeleton_term for every ball in one parallel pass (gravity read once), then
  // the two sums in row order: the additions of the serial loops, at any thread count.
  // A rattler adds +0 to the sum of non-negative terms, which leaves it unchanged: the sum over
  // every ball is the sum over the skeleton, bit for bit. The count is a sum of ones: exact.
  const std::int64_t n = static_cast<std::int64_t>(w.num_balls());
  const Vec3 g = w.gravity();
  const int nt = w.thread_count();
  const bool par = nt > 1 && n > 4096, order_free = w.params().order_free_sums;
  if (!par && !order_free) {
    // One thread (the DEM node measures a coupled step on one, dem_node/main.cpp): the same
    // terms and the same sums in row order in one loop, without the two work arrays.
    const Particles& b = w.balls();
    double sum = 0.0;
    std::size_t rattlers = 0;
    for (std::size_t u = 0; u < static_cast<std::size_t>(n); ++u) {
      Vec3 f;
      const bool r = rattler_of(b, u, g, f);
      rattlers += r;
      sum += r ? 0.0 : term_of(b, u, f);  // skeleton_term: +0 for a rattler
    }
    return skeleton_ratio_of(sum, rattlers, w.num_balls(), fc);
  }
  thread_local std::vector<double> term;  // (kept: a fresh array per call costs page faults)
  thread_local std::vector<std::uint8_t> rattler;
  term.resize(static_cast<std::size_t>(n));
  rattler.resize(static_cast<std::size_t>(n));
  double* const tm = term.data();
  std::uint8_t* const rt = rattler.data();
#pragma omp parallel for schedule(static) num_threads(nt) if (par)
  for (std::int64_t i = 0; i < n; ++i) {
    const std::size_t u = static_cast<std::size_t>(i);
    Vec3 f;
    const bool r = rattler_of(w.balls(), u, g, f);
    rt[u] = r;
    tm[u] = r ? 0.0 : term_of(w.balls(), u, f);  // skeleton_term: +0 for a rattler
  }
  double sum = 0.0;
  std::size_t rattlers = 0;
  for (std::int64_t i = 0; i < n; ++i) {
    if (!order_free) sum += tm[i];
    rattlers += rt[i];
  }
  if (order_free) sum = order_free_total(tm, term.size());  // (the order-free sum instead)
  return skeleton_ratio_of(sum, rattlers, w.num_balls(), fc);
}

BallRatios ball_ratios(const World& w, double fc) {
  const std::size_t n = w.num_balls();
  const bool par = w.thread_count() > 1 && n > 4096;
  if (n == 0 || par || w.params().order_free_sums) return {w.unbalanced_ratio(fc), skeleton_ratio(w, fc)};
  const Particles& b = w.balls();
  const Vec3 g = w.gravity();
  double unb = 0.0, skel = 0.0;
  std::size_t rattlers = 0;
  for (std::size_t u = 0; u < n; ++u) {
    Vec3 f;
    const bool r = rattler_of(b, u, g, f);  // f = F + F_a, as World::unbalanced_force_of forms it
    const double t = term_of(b, u, f);      // World::unbalanced_force_of(u), bit for bit
    unb += t;
    rattlers += r;
    skel += r ? 0.0 : t;
  }
  return {World::unbalanced_ratio_of(unb, n, fc), skeleton_ratio_of(skel, rattlers, n, fc)};
}

std::vector<std::pair<Region, ProfileSlab>> profile_slabs(const ProfileBox& box, int slabs) {
  if (slabs < 1) throw std::invalid_argument("stress_profile: slabs must be >= 1");
  std::vector<std::pair<Region, ProfileSlab>> out;
  const double h = box.height, top = box.z_top;
  for (int i = 0; i < slabs; ++i) {
    Region r;
    r.kind = Region::Kind::kBox;
    const double z_hi = top - h * i / slabs, z_lo = top - h * (i + 1) / slabs;
    r.lo = {box.x_lo, box.y_lo, z_lo};
    r.hi = {box.x_hi, box.y_hi, z_hi};
    ProfileSlab s;
    s.depth = top - 0.5 * (z_lo + z_hi);
    s.depth_top = top - z_hi;
    s.depth_bottom = top - z_lo;
    out.push_back({r, s});
  }
  return out;
}

std::vector<ProfileSlab> stress_profile(const World& w, const ProfileBox& box, int slabs) {
  std::vector<ProfileSlab> out;
  const auto& b = w.balls();
  for (auto [r, s] : profile_slabs(box, slabs)) {
    for (std::size_t k = 0; k < b.size(); ++k) s.balls += r.contains(b.x[k]) ? 1 : 0;
    const auto sig = region_stress(w, r);
    s.szz = sig[8];
    s.sxx = sig[0];
    s.syy = sig[4];
    out.push_back(s);
  }
  return out;
}

std::pair<Vec3, Vec3> add_box_walls(World& w) {
  const auto [lo, hi] = ball_bounds(w);
  add_box_planes(w, lo, hi);
  return {lo, hi};
}

std::pair<Vec3, Vec3> ball_bounds(const World& w) {
  const auto& b = w.balls();
  const auto& ghost = w.ghost_rows();
  Vec3 lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (!ghost.empty() && ghost[i]) continue;
    for (int k = 0; k < 3; ++k) {
      lo[k] = std::min(lo[k], b.x[i][k] - b.r[i]);
      hi[k] = std::max(hi[k], b.x[i][k] + b.r[i]);
    }
  }
  return {lo, hi};
}

void add_box_planes(World& w, const Vec3& lo, const Vec3& hi) {
  if (w.periodic())
    throw std::invalid_argument("dem.specimen.box = \"walls\": the block is still periodic (no replicate stage before)");
  if (!(lo.x <= hi.x)) throw std::invalid_argument("dem.specimen.box = \"walls\": no balls to enclose");
  const double lx = hi.x - lo.x, ly = hi.y - lo.y;
  const Vec3 o = lo, c{0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), 0.5 * (lo.z + hi.z)};
  auto plane = [&](Vec3 point, Vec3 normal, Vec3 axis1) {
    PlaneWallParams p;
    p.point = point;
    p.normal = normal;
    p.axis1 = axis1;
    w.add_plane(p);
  };
  plane({c.x, c.y, o.z}, {0, 0, 1}, {1, 0, 0});
  plane({o.x, c.y, c.z}, {1, 0, 0}, {0, 1, 0});
  plane({o.x + lx, c.y, c.z}, {-1, 0, 0}, {0, 1, 0});
  plane({c.x, o.y, c.z}, {0, 1, 0}, {1, 0, 0});
  plane({c.x, o.y + ly, c.z}, {0, -1, 0}, {1, 0, 0});
}

double footing_contact_height(const World& w, const FootingParams& f) {
  const Vec3 axis = f.bottom_centre;
  const auto& b = w.balls();
  const auto& ghost = w.ghost_rows();
  const double r_f = f.diameter / 2;
  double best = -std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < b.size(); ++i) {
    if (!ghost.empty() && ghost[i]) continue;
    const double dx = b.x[i].x - axis.x, dy = b.x[i].y - axis.y, rho = std::sqrt(dx * dx + dy * dy);
    const double out = rho - r_f, r = b.r[i];
    if (out >= r) continue;
    best = std::max(best, b.x[i].z + (out <= 0 ? r : std::sqrt(r * r - out * out)));
  }
  return best;
}

void set_footing_at(World& w, FootingParams f, double z) {
  if (!std::isfinite(z)) {
    std::ostringstream os;
    os << "penetrate: no ball lies under the footing's footprint (D " << f.diameter << " m centred at ("
       << f.bottom_centre.x << ", " << f.bottom_centre.y << ")): the footing would never touch the block; place it "
       << "over the block (dem.footing.centre, dem.footing.diameter)";
    throw std::runtime_error(os.str());
  }
  f.bottom_centre.z = z;
  f.velocity = {0, 0, 0};
  w.set_footing(f);
}

double place_footing_at_first_contact(World& w, FootingParams f) {
  const double best = footing_contact_height(w, f);
  set_footing_at(w, f, best);
  return best;
}

double boundary_power(const World& w) {
  double p = 0;
  if (w.has_footing()) p -= dot(w.footing_reaction(), w.footing().p.velocity);
  for (int k = 0; k < w.num_facet_walls(); ++k) {
    const auto& fw = w.facet_wall(k);
    for (std::size_t j = 0; j < fw.vel.size() && j < fw.vforce.size(); ++j) p -= dot(fw.vforce[j], fw.vel[j]);
  }
  return p;
}

double gravity_work(const World& w, const std::vector<Vec3>& x_begin) {
  if (!w.gravity_on()) return 0.0;
  const auto& b = w.balls();
  const Vec3 g = w.gravity();
  double work = 0;
  for (std::size_t i = 0; i < b.size() && i < x_begin.size(); ++i) work += b.m[i] * dot(g, b.x[i] - x_begin[i]);
  return work;
}

double largest_critical_step(WorldParams p, double r_min, double r_max) {
  p.periodic.enabled = false;
  p.dt_safety = 1.0;
  p.threads = 1;
  double best = 0.0;
  for (double rp : {r_min, r_max}) {
    World w(p);
    w.add_ball({0, 0, 0}, r_min);
    w.add_ball({(r_min + rp) * (1 - 1e-9), 0, 0}, rp);  // a slight overlap: one active contact
    w.prepare();
    best = std::max(best, w.critical_timestep());
  }
  return best;
}

double total_energy(const Energy& e) { return e.kinetic + e.strain + e.damping + e.friction + e.softening; }
double total_energy(const World& w) { return total_energy(w.energy()); }

// One World::energy() (a pass over every contact) per call.
void StageEnergy::begin(const World& w) {
  begin_with(w.energy());
  x_begin = w.balls().x;
}

void StageEnergy::begin_with(const Energy& e0) {
  total_begin = total_energy(e0);
  mechanical_begin = e0.kinetic + e0.strain;
  x_begin.clear();
  work = 0;
}

StageEnergy::Balance StageEnergy::balance(const World& w) const { return balance_with(w.energy(), gravity_work(w, x_begin)); }

StageEnergy::Balance StageEnergy::balance_with(const Energy& e, double gravity_work) const {
  const double total = total_energy(e), wk = work + gravity_work;
  const double dissipated = total - e.kinetic - e.strain - (total_begin - mechanical_begin);
  // Relative to the largest energy flow of the stage.
  const double scale = std::max({std::abs(wk), mechanical_begin, e.kinetic + e.strain, std::abs(dissipated), 1e-300});
  return {e.kinetic, e.strain, dissipated, wk, (total - total_begin - wk) / scale};
}

void StageEnergy::save(io::StateWriter& w) const {
  io::save_fields(w, total_begin, mechanical_begin, work);
  w.u64(x_begin.size());
  for (const auto& x : x_begin) io::save_fields(w, x.x, x.y, x.z);
}

void StageEnergy::load(io::SectionReader& r) {
  io::load_fields(r, total_begin, mechanical_begin, work);
  x_begin.resize(r.count(24));
  for (auto& x : x_begin) io::load_fields(r, x.x, x.y, x.z);
}

StageReport generate_specimen(World& w, const RevParams& p, double bond_coordination, double gap_floor) {
  auto r = generate_rev(w, p);
  bond_specimen(w, r, bond_coordination, gap_floor);
  return r;
}

double ball_weight(const World& w) {
  const auto& m = w.balls().m;
  // (row order, or the order-free sum under run.order_free_sums: DistDem::ball_weight's bits)
  return w.ordered_ball_sum([&](std::size_t i) { return m[i]; }) * std::abs(w.gravity().z);
}

GuardFinding energy_jump_finding(const World& w, const std::string& jump) {
  const auto& b = w.balls();
  if (b.size() == 0) throw std::invalid_argument("energy_jump_finding: the world has no balls");
  std::size_t worst = 0;
  double e_worst = -1;
  for (std::size_t i = 0; i < b.size(); ++i) {
    const double e = 0.5 * (b.m[i] * dot(b.v[i], b.v[i]) + b.inertia[i] * dot(b.w[i], b.w[i]));
    if (e > e_worst) e_worst = e, worst = i;
  }
  GuardFinding f;
  f.cause = "DEM " + jump + "; fastest ball id " + std::to_string(b.id[worst]);
  f.detail = "ball with the largest kinetic energy (" + std::to_string(e_worst) + " J): " + describe_ball(w, worst) +
             "\n10 nearest balls:\n" + neighbourhood(w, worst, 10);
  f.row = worst;
  f.id = b.id[worst];
  return f;
}

std::size_t kick_highest_ball(World& w, const Vec3& v) {
  const auto& b = w.balls();
  if (b.size() == 0) throw std::invalid_argument("kick: the world has no balls");
  std::size_t top = 0;
  for (std::size_t i = 1; i < b.size(); ++i) {
    const double h = b.x[i].z + b.r[i], best = b.x[top].z + b.r[top];
    if (h > best || (h == best && b.id[i] < b.id[top])) top = i;
  }
  w.balls().v[top] = v;
  return top;
}

}  // namespace demfdm::dem
