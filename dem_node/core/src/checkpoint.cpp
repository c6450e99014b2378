// Bit-exact DEM state save/load: see checkpoint.hpp and docs/checkpoint-format.md.
#include "demfdm/dem/checkpoint.hpp"

#include "demfdm/dem/specimen.hpp"
#include "pair_set.hpp"
#include "wall_set.hpp"

#include <istream>
#include <iterator>
#include <memory>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <limits>
#include <bit>
#include <span>
#include <array>
#include "demfdm/dem/laws/registry.hpp"

namespace demfdm::dem {

// Tripwires: a new field in a saved struct (or a new World member) changes its size. Then
// decide whether it influences later steps, save it below and in docs/checkpoint-format.md
// (raising the section layout: format version or a new section), and update the size here.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(_GLIBCXX_DEBUG)
static_assert(sizeof(ContactHist) == 96, "ContactHist changed: update the checkpoint (docs/checkpoint-format.md)");
static_assert(sizeof(BondHist) == 104, "BondHist changed: update the checkpoint (docs/checkpoint-format.md)");
static_assert(sizeof(LinearParams) == 56, "LinearParams changed: update the checkpoint");
static_assert(sizeof(ParallelBondParams) == 64, "ParallelBondParams changed: update the checkpoint");
static_assert(sizeof(SoftBondParams) == 80, "SoftBondParams changed: update the checkpoint");
static_assert(sizeof(HertzParams) == 16, "HertzParams changed: update the checkpoint");
static_assert(sizeof(ContactFamilyParams) == 224, "ContactFamilyParams changed: update the checkpoint");
static_assert(sizeof(WorldParams) == 1048, "WorldParams changed: update the checkpoint");  // + thread_independent, order_free_sums (not saved: the scene's)
static_assert(sizeof(PlaneWallParams) == 112, "PlaneWallParams changed: update the checkpoint");
static_assert(sizeof(PlaneWall) == 200, "PlaneWall changed: update the checkpoint");
static_assert(sizeof(FacetWall) == 224, "FacetWall changed: update the checkpoint");
static_assert(sizeof(Footing) == 128, "Footing changed: update the checkpoint");
static_assert(sizeof(Particles) == 13 * 24, "Particles changed: update the checkpoint");
static_assert(sizeof(PairContacts) == 5 * 24, "PairContacts changed: update the checkpoint");
static_assert(sizeof(WallContacts) == 12 * 24, "WallContacts changed: update the checkpoint");
static_assert(sizeof(World) == 2208, "World changed: is the new member state? update the checkpoint");  // + measurement scratch (not state; the order-free force norms and walls' sums too), ghost rows and the rows integrated (a rank's: refused), step reduction and newton hooks (a rank driver's), the facets hosted by the ball-ball pass (a choice of how, not state)
// The contact sets: vtable, phase, contacts, the kind's walls (PairSet: + pass and measurement scratch, not state).
static_assert(sizeof(PairSet) == 1184, "PairSet changed: is the new member state? update the checkpoint");  // + the threaded pass plan and its work stealing, the kept stiffness terms, the serial scan's norm sum (derived), the pass's force norms (derived), the rebuild's kept arrays (scratch)
static_assert(sizeof(WallSet<PlaneKind>) == 328, "WallSet<PlaneKind> changed: update the checkpoint");
static_assert(sizeof(WallSet<FacetKind>) == 360, "WallSet<FacetKind> changed: update the checkpoint");  // + restore_linear, the vertex-sum terms (per pass)
static_assert(sizeof(WallSet<FootingKind>) == 432, "WallSet<FootingKind> changed: update the checkpoint");
#endif

namespace {

constexpr const char* kKind = "dem";

// ---- writing -------------------------------------------------------------------------------


void put(io::ByteWriter& o, const Vec3& v) {
  o.f64(v.x);
  o.f64(v.y);
  o.f64(v.z);
}
void put_vecs(io::ByteWriter& o, const std::vector<Vec3>& v) {
  o.u64(v.size());
  for (const Vec3& x : v) put(o, x);
}

void put(io::StateWriter& o, const ContactFamilyParams& f) {
  o.u8(static_cast<std::uint8_t>(f.model));
  const LinearParams& l = f.linear;
  o.f64(l.emod);
  o.f64(l.kratio);
  o.f64(l.fric);
  o.u8(static_cast<std::uint8_t>(l.mode));
  o.f64(l.rgap);
  o.u8(static_cast<std::uint8_t>(l.wall_length));
  o.f64(l.kn_fixed);
  const ParallelBondParams& pb = f.pbond;
  o.f64(pb.emod);
  o.f64(pb.kratio);
  o.f64(pb.rmul);
  o.f64(pb.mcf);
  o.f64(pb.ten);
  o.f64(pb.coh);
  o.f64(pb.fa_deg);
  o.b(pb.zero_linear);
  const SoftBondParams& sb = f.softbond;
  o.f64(sb.rmul);
  o.f64(sb.mcf);
  o.f64(sb.bmul);
  o.f64(sb.ten);
  o.f64(sb.coh);
  o.f64(sb.fa_deg);
  o.f64(sb.soft);
  o.f64(sb.cut);
  o.f64(sb.twist_factor);
  o.u8(static_cast<std::uint8_t>(sb.ret));
  o.u8(static_cast<std::uint8_t>(sb.unload));
  o.u8(static_cast<std::uint8_t>(sb.cohesion));
  o.b(sb.bending_in_softening);
  o.u8(static_cast<std::uint8_t>(sb.moments));
  o.f64(f.hertz.shear);
  o.f64(f.hertz.poisson);
}

void put(io::StateWriter& o, const WorldParams& p) {
  o.f64(p.density);
  o.f64(p.local_damping);
  o.f64(p.g0);
  o.f64(p.g_level);
  o.b(p.gravity);
  o.f64(p.dt_safety);
  o.i32(p.dt_interval);
  o.f64(p.dt_fixed);
  o.f64(p.skin);
  o.f64(p.skin_factor);
  o.b(p.rescale_shear);
  o.b(p.facet_spin);
  o.b(p.track_energy);
  o.i32(p.threads);
  o.b(p.periodic.enabled);
  put(o, p.periodic.origin);
  put(o, p.periodic.length);
  put(o, p.ball_ball);
  put(o, p.ball_wall);
  put(o, p.ball_facet);
  put(o, p.ball_footing);
}

void put(io::ByteWriter& o, const ContactHist& h) {
  put(o, h.fs);
  o.f64(h.fn);
  put(o, h.n_old);
  o.f64(h.kn);
  o.f64(h.ks);
  o.f64(h.mu);
  o.f64(h.e_slip);
  o.u8(h.flags);
}
constexpr std::size_t kHistBytes = 11 * 8 + 1;

void put(io::ByteWriter& o, const BondHist& b) {
  put(o, b.fsb);
  o.f64(b.nb);
  put(o, b.mb);
  o.f64(b.mt);
  o.f64(b.rb);
  o.f64(b.kn);
  o.f64(b.sigma_t);
  o.f64(b.e_soft);
  o.u8(static_cast<std::uint8_t>(b.state));
  o.u8(b.slip_b);
  o.u8(b.slip_t);
}
constexpr std::size_t kBondBytes = 12 * 8 + 3;

void put_hists(io::ByteWriter& o, const std::vector<ContactHist>& h, const std::vector<BondHist>& b) {
  o.u64(h.size());
  for (const ContactHist& x : h) put(o, x);
  o.u64(b.size());
  for (const BondHist& x : b) put(o, x);
}

void put(io::ByteWriter& o, const WallContacts& wc) {
  o.u32s(wc.ball);
  o.u32s(wc.wall);
  put_hists(o, wc.h, wc.bond);
  o.i32s(wc.facet);
  o.u32s(wc.cand_off);
  o.u32s(wc.cand);
  put_vecs(o, wc.F);
  put_vecs(o, wc.M);
  put_vecs(o, wc.TA);
  put_vecs(o, wc.xc);
  put_vecs(o, wc.bary);
}

void put(io::StateWriter& o, const PlaneWall& w) {
  const PlaneWallParams& p = w.p;
  put(o, p.point);
  put(o, p.normal);
  put(o, p.axis1);
  o.f64(p.half1);
  o.f64(p.half2);
  put(o, p.velocity);
  put(o, w.axis2);
  put(o, w.disp);
  put(o, w.reaction);
  o.f64(w.k_sum);
  o.u64(w.id);
}

void put(io::StateWriter& o, const FacetWall& fw) {
  put_vecs(o, fw.pos);
  put_vecs(o, fw.vel);
  o.u64(fw.tri.size());
  for (const auto& t : fw.tri)
    for (std::int32_t v : t) o.i32(v);
  put_vecs(o, fw.tri_normal);
  put_vecs(o, fw.tri_spin);
  put_vecs(o, fw.pos_ref);
  put_vecs(o, fw.vforce);
  o.f64s(fw.vstiff);
  put(o, fw.total_force);
  o.u64(fw.id);
}

void put(io::StateWriter& o, const Footing& f) {
  o.f64(f.p.diameter);
  o.f64(f.p.height);
  put(o, f.p.bottom_centre);
  put(o, f.p.velocity);
  o.b(f.enabled);
  put(o, f.disp);
  put(o, f.reaction);
  o.u64(f.id);
}

// ---- reading -------------------------------------------------------------------------------

Vec3 get_vec(io::SectionReader& in) {
  Vec3 v;
  v.x = in.f64();
  v.y = in.f64();
  v.z = in.f64();
  return v;
}
std::vector<Vec3> get_vecs(io::SectionReader& in) {
  std::vector<Vec3> v(in.count(24));
  for (Vec3& x : v) x = get_vec(in);
  return v;
}

// An enum stored as u8 with values 0..last.
template <class E>
E get_enum(io::SectionReader& in, std::uint8_t last, const char* what) {
  const std::uint8_t v = in.u8();
  if (v > last) in.fail(std::string(what) + " = " + std::to_string(v) + ", expected 0.." + std::to_string(last));
  return static_cast<E>(v);
}

ContactFamilyParams get_family(io::SectionReader& in) {
  ContactFamilyParams f;
  f.model = get_enum<ContactModel>(in, 3, "contact model");
  LinearParams& l = f.linear;
  l.emod = in.f64();
  l.kratio = in.f64();
  l.fric = in.f64();
  l.mode = get_enum<NormalMode>(in, 1, "linear.mode");
  l.rgap = in.f64();
  l.wall_length = get_enum<WallLength>(in, 1, "linear.wall_length");
  l.kn_fixed = in.f64();
  ParallelBondParams& pb = f.pbond;
  pb.emod = in.f64();
  pb.kratio = in.f64();
  pb.rmul = in.f64();
  pb.mcf = in.f64();
  pb.ten = in.f64();
  pb.coh = in.f64();
  pb.fa_deg = in.f64();
  pb.zero_linear = in.b();
  SoftBondParams& sb = f.softbond;
  sb.rmul = in.f64();
  sb.mcf = in.f64();
  sb.bmul = in.f64();
  sb.ten = in.f64();
  sb.coh = in.f64();
  sb.fa_deg = in.f64();
  sb.soft = in.f64();
  sb.cut = in.f64();
  sb.twist_factor = in.f64();
  sb.ret = get_enum<SoftReturn>(in, 1, "softbond.ret");
  sb.unload = get_enum<SoftUnload>(in, 1, "softbond.unload");
  sb.cohesion = get_enum<CohesionSoftening>(in, 1, "softbond.cohesion");
  sb.bending_in_softening = in.b();
  sb.moments = get_enum<UnbondedMoments>(in, 1, "softbond.moments");
  f.hertz.shear = in.f64();
  f.hertz.poisson = in.f64();
  return f;
}

WorldParams get_params(io::SectionReader& in) {
  WorldParams p;
  p.density = in.f64();
  p.local_damping = in.f64();
  p.g0 = in.f64();
  p.g_level = in.f64();
  p.gravity = in.b();
  p.dt_safety = in.f64();
  p.dt_interval = in.i32();
  p.dt_fixed = in.f64();
  p.skin = in.f64();
  p.skin_factor = in.f64();
  p.rescale_shear = in.b();
  p.facet_spin = in.b();
  p.track_energy = in.b();
  p.threads = in.i32();
  p.periodic.enabled = in.b();
  p.periodic.origin = get_vec(in);
  p.periodic.length = get_vec(in);
  p.ball_ball = get_family(in);
  p.ball_wall = get_family(in);
  p.ball_facet = get_family(in);
  p.ball_footing = get_family(in);
  return p;
}

ContactHist get_hist(io::SectionReader& in) {
  ContactHist h;
  h.fs = get_vec(in);
  h.fn = in.f64();
  h.n_old = get_vec(in);
  h.kn = in.f64();
  h.ks = in.f64();
  h.mu = in.f64();
  h.e_slip = in.f64();
  h.flags = in.u8();
  return h;
}

BondHist get_bond(io::SectionReader& in) {
  BondHist b;
  b.fsb = get_vec(in);
  b.nb = in.f64();
  b.mb = get_vec(in);
  b.mt = in.f64();
  b.rb = in.f64();
  b.kn = in.f64();
  b.sigma_t = in.f64();
  b.e_soft = in.f64();
  b.state = get_enum<BondState>(in, 4, "bond state");
  b.slip_b = in.u8();
  b.slip_t = in.u8();
  return b;
}

void get_hists(io::SectionReader& in, std::vector<ContactHist>& h, std::vector<BondHist>& b) {
  h.resize(in.count(kHistBytes));
  for (ContactHist& x : h) x = get_hist(in);
  b.resize(in.count(kBondBytes));
  for (BondHist& x : b) x = get_bond(in);
}

WallContacts get_wall_contacts(io::SectionReader& in) {
  WallContacts wc;
  wc.ball = in.u32s();
  wc.wall = in.u32s();
  get_hists(in, wc.h, wc.bond);
  wc.facet = in.i32s();
  wc.cand_off = in.u32s();
  wc.cand = in.u32s();
  wc.F = get_vecs(in);
  wc.M = get_vecs(in);
  wc.TA = get_vecs(in);
  wc.xc = get_vecs(in);
  wc.bary = get_vecs(in);
  return wc;
}

PlaneWall get_plane(io::SectionReader& in) {
  PlaneWall w;
  PlaneWallParams& p = w.p;
  p.point = get_vec(in);
  p.normal = get_vec(in);
  p.axis1 = get_vec(in);
  p.half1 = in.f64();
  p.half2 = in.f64();
  p.velocity = get_vec(in);
  w.axis2 = get_vec(in);
  w.disp = get_vec(in);
  w.reaction = get_vec(in);
  w.k_sum = in.f64();
  w.id = in.u64();
  return w;
}

FacetWall get_facet_wall(io::SectionReader& in) {
  FacetWall fw;
  fw.pos = get_vecs(in);
  fw.vel = get_vecs(in);
  fw.tri.resize(in.count(12));
  for (auto& t : fw.tri)
    for (std::int32_t& v : t) v = in.i32();
  fw.tri_normal = get_vecs(in);
  fw.tri_spin = get_vecs(in);
  fw.pos_ref = get_vecs(in);
  fw.vforce = get_vecs(in);
  fw.vstiff = in.f64s();
  fw.total_force = get_vec(in);
  fw.id = in.u64();
  const std::size_t nv = fw.pos.size(), nt = fw.tri.size();
  if (fw.vel.size() != nv || fw.pos_ref.size() != nv || fw.vforce.size() != nv || fw.vstiff.size() != nv ||
      fw.tri_normal.size() != nt || fw.tri_spin.size() != nt)
    in.fail("facet wall arrays of different lengths");
  for (const auto& t : fw.tri)
    for (std::int32_t v : t)
      if (v < 0 || static_cast<std::size_t>(v) >= nv) in.fail("facet wall triangle vertex " + std::to_string(v) + " out of range");
  return fw;
}

Footing get_footing(io::SectionReader& in) {
  Footing f;
  f.p.diameter = in.f64();
  f.p.height = in.f64();
  f.p.bottom_centre = get_vec(in);
  f.p.velocity = get_vec(in);
  f.enabled = in.b();
  f.disp = get_vec(in);
  f.reaction = get_vec(in);
  f.id = in.u64();
  return f;
}

// Consistency of a wall-contact list with the balls and walls it names (the file passed its
// checksum, so this only guards against a writer of another build).
void check_wall_contacts(io::SectionReader& in, const WallContacts& wc, std::size_t nballs, std::size_t nwalls,
                         bool can_bond, const std::vector<FacetWall>* fwalls) {
  const std::size_t m = wc.ball.size();
  if (wc.wall.size() != m || wc.h.size() != m || wc.facet.size() != m || wc.cand_off.size() != m + 1 ||
      wc.F.size() != m || wc.M.size() != m || wc.TA.size() != m || wc.xc.size() != m || wc.bary.size() != m)
    in.fail("contact arrays of different lengths");
  if (wc.bond.size() != (can_bond ? m : 0))
    in.fail("bond histories (" + std::to_string(wc.bond.size()) + ") do not match the family's contact model");
  if (wc.cand_off[0] != 0 || wc.cand_off[m] != wc.cand.size()) in.fail("candidate offsets inconsistent");
  for (std::size_t c = 0; c < m; ++c) {
    if (wc.ball[c] >= nballs) in.fail("contact " + std::to_string(c) + " names ball row " + std::to_string(wc.ball[c]));
    if (wc.wall[c] >= nwalls) in.fail("contact " + std::to_string(c) + " names wall " + std::to_string(wc.wall[c]));
    if (wc.cand_off[c] > wc.cand_off[c + 1]) in.fail("candidate offsets not ascending");
    if (fwalls) {
      const std::size_t nt = (*fwalls)[wc.wall[c]].tri.size();
      if (wc.facet[c] < 0 || static_cast<std::size_t>(wc.facet[c]) >= nt) in.fail("contact facet out of range");
      for (std::uint32_t k = wc.cand_off[c]; k < wc.cand_off[c + 1]; ++k)
        if (wc.cand[k] >= nt) in.fail("candidate facet out of range");
    }
  }
}

}  // namespace

// Private-state access of World for the checkpoint (friend of World).
struct CheckpointAccess {
  static void save(const World& w, io::StateWriter& o) {
    std::vector<PlatenServoParams> platens;  // in the order they were added
    for (const auto& e : w.effects_) {
      if (e.get() == w.gravity_) continue;
      if (const auto* ps = dynamic_cast<const PlatenServo*>(e.get())) {
        platens.push_back(ps->params());
        continue;
      }
      throw std::invalid_argument(std::string("save_state: the world has the effect '") + e->name() +
                                  "', which a checkpoint cannot hold (only gravity and platen servos are saved; "
                                  "docs/checkpoint-format.md). Remove it before saving and add it again after loading.");
    }
    o.begin("params");
    put(o, w.p_);
    o.end();

    o.begin("counters");
    const World::Counters k = w.counters();
    o.f64(k.time);
    o.f64(k.dt);
    o.f64(k.skin);
    o.i64(k.step);
    o.i64(k.rebuilds);
    o.i64(k.last_dt_step);
    o.i64(k.bond_failures);
    o.b(k.prepared);
    o.b(k.dirty);
    put(o, k.edot);
    put(o, k.cell_strain);
    put(o, k.cell_len_ref);
    o.u64(k.next_id);
    o.u64(k.next_wall_id);
    o.f64(k.e_damp);
    o.f64(k.max_disp2);
    o.f64(k.e_slip_dead);
    o.f64(k.e_soft_dead);
    o.end();

    o.begin("effects");
    o.b(w.gravity_ != nullptr);
    put(o, w.gravity());
    o.u64(platens.size());
    for (const PlatenServoParams& p : platens) {
      o.i32(p.wall);
      o.f64(p.stress);
      o.f64(p.area);
      o.f64(p.gain);
      o.f64(p.vmax);
    }
    o.end();

    o.begin("balls");
    const Particles& pt = w.pt_;
    put_vecs(o, pt.x);
    put_vecs(o, pt.v);
    put_vecs(o, pt.w);
    put_vecs(o, pt.f);
    put_vecs(o, pt.t);
    put_vecs(o, pt.fa);
    put_vecs(o, pt.ta);
    put_vecs(o, pt.x_ref);
    o.f64s(pt.r);
    o.f64s(pt.m);
    o.f64s(pt.inertia);
    o.u64s(pt.id);
    o.u8s(pt.fix);
    o.end();

    o.begin("pairs");
    const PairContacts& pc = w.pairs_->contacts;
    o.u32s(pc.a);
    o.u32s(pc.b);
    o.u64(pc.shift.size());
    for (const auto& s : pc.shift)
      for (std::int8_t v : s) o.i8(v);
    put_hists(o, pc.h, pc.bond);
    o.end();

    o.begin("plane_contacts");
    put(o, w.planes_->contacts);
    o.end();
    o.begin("facet_contacts");
    put(o, w.facets_->contacts);
    o.end();
    o.begin("footing_contacts");
    put(o, w.footing_->contacts);
    o.end();

    o.begin("planes");
    o.u64(w.planes_->kind.walls.size());
    for (const PlaneWall& p : w.planes_->kind.walls) put(o, p);
    o.end();

    o.begin("facet_walls");
    o.u64(w.facets_->kind.walls.size());
    for (const FacetWall& fw : w.facets_->kind.walls) put(o, fw);
    o.end();

    o.begin("footing");
    put(o, w.footing_->kind.ft);
    o.end();
  }

  static void load(World& w, io::StateReader& r) {
    // Parse and check everything first; the world changes only once all of it is read.
    WorldParams p;
    {
      auto in = r.section("params");
      p = get_params(in);
      in.done();
      try {
        validate(p);
      } catch (const std::invalid_argument& e) {
        in.fail(std::string("invalid parameters: ") + e.what());
      }
    }
    World::Counters k;
    {
      auto in = r.section("counters");
      k.time = in.f64();
      k.dt = in.f64();
      k.skin = in.f64();
      k.step = in.i64();
      k.rebuilds = in.i64();
      k.last_dt_step = in.i64();
      k.bond_failures = in.i64();
      k.prepared = in.b();
      k.dirty = in.b();
      k.edot = get_vec(in);
      k.cell_strain = get_vec(in);
      k.cell_len_ref = get_vec(in);
      k.next_id = in.u64();
      k.next_wall_id = in.u64();
      k.e_damp = in.f64();
      k.max_disp2 = in.f64();
      k.e_slip_dead = in.f64();
      k.e_soft_dead = in.f64();
      in.done();
    }
    bool gravity_on;
    Vec3 g;
    std::vector<PlatenServoParams> platens;
    {
      auto in = r.section("effects");
      gravity_on = in.b();
      g = get_vec(in);
      platens.resize(in.count(36));  // wall i32 + 4 f64
      for (PlatenServoParams& p : platens) {
        p.wall = in.i32();
        p.stress = in.f64();
        p.area = in.f64();
        p.gain = in.f64();
        p.vmax = in.f64();
      }
      in.done();
    }
    Particles pt;
    {
      auto in = r.section("balls");
      pt.x = get_vecs(in);
      pt.v = get_vecs(in);
      pt.w = get_vecs(in);
      pt.f = get_vecs(in);
      pt.t = get_vecs(in);
      pt.fa = get_vecs(in);
      pt.ta = get_vecs(in);
      pt.x_ref = get_vecs(in);
      pt.r = in.f64s();
      pt.m = in.f64s();
      pt.inertia = in.f64s();
      pt.id = in.u64s();
      pt.fix = in.u8s();
      in.done();
      const std::size_t n = pt.x.size();
      if (pt.v.size() != n || pt.w.size() != n || pt.f.size() != n || pt.t.size() != n || pt.fa.size() != n ||
          pt.ta.size() != n || pt.x_ref.size() != n || pt.r.size() != n || pt.m.size() != n ||
          pt.inertia.size() != n || pt.id.size() != n || pt.fix.size() != n)
        in.fail("ball arrays of different lengths");
    }
    const std::size_t n = pt.size();
    PairContacts pc;
    {
      auto in = r.section("pairs");
      pc.a = in.u32s();
      pc.b = in.u32s();
      pc.shift.resize(in.count(4));
      for (auto& s : pc.shift)
        for (std::int8_t& v : s) v = in.i8();
      get_hists(in, pc.h, pc.bond);
      in.done();
      const std::size_t m = pc.a.size();
      if (pc.b.size() != m || pc.shift.size() != m || pc.h.size() != m) in.fail("contact arrays of different lengths");
      if (pc.bond.size() != (law_has_bond(p.ball_ball.model) ? m : 0))
        in.fail("bond histories (" + std::to_string(pc.bond.size()) + ") do not match the ball_ball contact model");
      for (std::size_t c = 0; c < m; ++c)
        if (pc.a[c] >= n || pc.b[c] >= n) in.fail("contact " + std::to_string(c) + " names a ball row out of range");
    }
    std::vector<PlaneWall> planes;
    {
      auto in = r.section("planes");
      planes.resize(in.count(1));
      for (PlaneWall& pw : planes) pw = get_plane(in);
      in.done();
    }
    std::vector<FacetWall> fwalls;
    {
      auto in = r.section("facet_walls");
      fwalls.resize(in.count(1));
      for (FacetWall& fw : fwalls) fw = get_facet_wall(in);
      in.done();
    }
    Footing footing;
    {
      auto in = r.section("footing");
      footing = get_footing(in);
      in.done();
    }
    WallContacts plc, fcc, ftc;
    {
      auto in = r.section("plane_contacts");
      plc = get_wall_contacts(in);
      in.done();
      check_wall_contacts(in, plc, n, planes.size(), law_has_bond(p.ball_wall.model), nullptr);
    }
    {
      auto in = r.section("facet_contacts");
      fcc = get_wall_contacts(in);
      in.done();
      check_wall_contacts(in, fcc, n, fwalls.size(), law_has_bond(p.ball_facet.model), &fwalls);
    }
    {
      auto in = r.section("footing_contacts");
      ftc = get_wall_contacts(in);
      in.done();
      check_wall_contacts(in, ftc, n, 1, law_has_bond(p.ball_footing.model), nullptr);
    }
    r.finish();

    // Commit (nothing below throws except on allocation failure). thread_independent and
    // order_free_sums are not saved: the target keeps its own (the scene's, like the thread count).
    p.thread_independent = w.p_.thread_independent;
    p.order_free_sums = w.p_.order_free_sums;
    w.p_ = p;
    w.set_counters(k);
    w.pt_ = std::move(pt);
    // Scratch: the pair set's per-thread force buffers are re-created (all zero) by the next pass.
    w.pairs_->reset(std::move(pc));
    w.planes_->contacts = std::move(plc);
    w.facets_->contacts = std::move(fcc);
    w.footing_->contacts = std::move(ftc);
    w.planes_->kind.walls = std::move(planes);
    w.facets_->kind.walls = std::move(fwalls);
    w.footing_->kind.ft = footing;
    w.chunk_e_.clear();
    if (w.gravity_) w.remove_effect(w.gravity_);
    if (gravity_on) w.gravity_ = w.add_effect(std::make_unique<GravityEffect>(g));
    // The saved platen servos replace the target's.
    for (const PlatenServoParams& p : platens)
      if (p.wall < 0 || p.wall >= w.num_planes())
        throw std::runtime_error("load_state: a platen servo of wall " + std::to_string(p.wall) + " in a world of " +
                                 std::to_string(w.num_planes()) + " planes");
    std::vector<const Effect*> old;
    for (const auto& e : w.effects_)
      if (dynamic_cast<const PlatenServo*>(e.get())) old.push_back(e.get());
    for (const Effect* e : old) w.remove_effect(e);
    for (const PlatenServoParams& p : platens) w.add_effect(std::make_unique<PlatenServo>(p));
  }
};

using Front = io::StateFront<CheckpointAccess, World>;

std::string state_bytes(const World& w, const CheckpointMeta& meta) {
  // A rank's world (ghost rows, dem_node/dist) holds only its sub-domain: the format has no
  // place for the decomposition yet.
  if (!w.ghost_rows().empty())
    throw std::invalid_argument("save_state: this world is one rank's sub-domain (it has ghost rows); the ranks' "
                                "state is saved by DistDem::save_state_file, as one World's.");
  return Front::bytes(w, kKind, meta);
}

void save_state(const World& w, std::ostream& out, const CheckpointMeta& meta) {
  io::write_stream(out, state_bytes(w, meta));
}

void save_state_file(const World& w, const std::filesystem::path& path, const CheckpointMeta& meta) {
  io::write_atomically(path, state_bytes(w, meta));
}

io::StateHeader load_state_bytes(World& w, std::string bytes, std::uint64_t scene_hash, std::string_view source) {
  return Front::load(w, std::move(bytes), kKind, scene_hash, source);
}

io::StateHeader load_state(World& w, std::istream& in, std::uint64_t scene_hash, std::string_view source) {
  return load_state_bytes(w, io::read_stream(in, source), scene_hash, source);
}

io::StateHeader load_state_file(World& w, const std::filesystem::path& path, std::uint64_t scene_hash) {
  return load_state_bytes(w, io::read_whole_file(path), scene_hash, path.string());
}

// ---- a World's state file written in pieces --------------------------------------------------

// The bulk sections' columns, in file order: each is a u64 count and `count` elements of `bytes`.
struct StateStream::Impl {
  struct Column {
    std::uint64_t at = 0;    // the count's offset in the file
    std::size_t bytes = 0;   // per element
  };
  io::StateReader frame;                // the frame World's file (its other sections)
  io::StateFileWriter file;             // (the frame's sections, the bulk ones streamed)
  std::vector<std::string> after;       // the sections after "pairs", in order
  std::vector<Column> ball_cols, pair_cols;
  std::uint64_t nballs, npairs, balls_done = 0, pairs_done = 0;
  bool bonds;

  Impl(const std::filesystem::path& path, std::string frame_bytes, std::uint64_t nb, std::uint64_t np,
       const CheckpointMeta& meta)
      : frame(std::move(frame_bytes), "the frame of " + path.string(), kKind, meta.scene_hash),
        file(path, kKind, meta.code_version, meta.scene_hash, static_cast<std::uint32_t>(frame.names().size())),
        nballs(nb),
        npairs(np),
        bonds(false) {}

  // Reserves a section of columns of `n` elements each (`bytes` per element) and writes their counts.
  std::vector<Column> reserve(std::string_view name, const std::vector<std::pair<std::uint64_t, std::size_t>>& cols) {
    std::uint64_t len = 0;
    for (const auto& [n, b] : cols) len += 8 + n * b;
    std::uint64_t at = file.reserve(name, len);
    std::vector<Column> out;
    for (const auto& [n, b] : cols) {
      io::ByteWriter c;
      c.u64(n);
      file.write_at(at, c.buffer());
      out.push_back(Column{at, b});
      at += 8 + n * b;
    }
    return out;
  }
  // One column's elements from row `row0` on.
  void put(const Column& c, std::uint64_t row0, io::ByteWriter& o) {
    file.write_at(c.at + 8 + row0 * c.bytes, o.buffer());
    o.buffer().clear();
  }
};

StateStream::StateStream(const std::filesystem::path& path, const World& frame, std::uint64_t balls,
                         std::uint64_t pairs, const CheckpointMeta& meta) {
  if (balls > std::numeric_limits<std::uint32_t>::max())
    throw std::invalid_argument("StateStream: " + std::to_string(balls) + " balls: contact rows are 32-bit");
  // the frame World's file: its sections in order, the bulk ones replaced by the streamed rows
  p_ = std::make_unique<Impl>(path, state_bytes(frame, meta), balls, pairs, meta);
  Impl& q = *p_;
  q.bonds = law_has_bond(frame.params().ball_ball.model);
  const auto names = q.frame.names();
  std::size_t k = 0;
  for (; k < names.size() && names[k] != "balls"; ++k) q.file.section(names[k], q.frame.section_bytes(names[k]));
  if (k + 1 >= names.size() || names[k + 1] != "pairs")
    throw std::logic_error("StateStream: the state file's sections are not params..., balls, pairs, ...");
  (void)q.frame.section_bytes("balls");  // (replaced)
  (void)q.frame.section_bytes("pairs");
  const std::uint64_t n = balls, m = pairs;
  q.ball_cols = q.reserve("balls", {{n, 24}, {n, 24}, {n, 24}, {n, 24}, {n, 24}, {n, 24}, {n, 24}, {n, 24},
                                    {n, 8}, {n, 8}, {n, 8}, {n, 8}, {n, 1}});
  q.pair_cols = q.reserve("pairs", {{m, 4}, {m, 4}, {m, 4}, {m, kHistBytes}, {q.bonds ? m : 0, kBondBytes}});
  q.after.assign(names.begin() + static_cast<std::ptrdiff_t>(k + 2), names.end());
}

StateStream::~StateStream() = default;

void StateStream::balls(const Particles& rows) {
  Impl& q = *p_;
  const std::size_t n = rows.size();
  if (q.balls_done + n > q.nballs)
    throw std::logic_error("StateStream::balls: more than the " + std::to_string(q.nballs) + " balls announced");
  io::ByteWriter o;
  const std::vector<Vec3>* vecs[8] = {&rows.x, &rows.v, &rows.w, &rows.f, &rows.t, &rows.fa, &rows.ta, &rows.x_ref};
  for (int c = 0; c < 8; ++c) {
    for (std::size_t i = 0; i < n; ++i) put(o, (*vecs[c])[i]);
    q.put(q.ball_cols[static_cast<std::size_t>(c)], q.balls_done, o);
  }
  const std::vector<double>* dbl[3] = {&rows.r, &rows.m, &rows.inertia};
  for (int c = 0; c < 3; ++c) {
    for (std::size_t i = 0; i < n; ++i) o.f64((*dbl[c])[i]);
    q.put(q.ball_cols[8 + static_cast<std::size_t>(c)], q.balls_done, o);
  }
  for (std::size_t i = 0; i < n; ++i) o.u64(rows.id[i]);
  q.put(q.ball_cols[11], q.balls_done, o);
  for (std::size_t i = 0; i < n; ++i) o.u8(rows.fix[i]);
  q.put(q.ball_cols[12], q.balls_done, o);
  q.balls_done += n;
}

void StateStream::pairs(const PairContacts& rows) {
  Impl& q = *p_;
  const std::size_t n = rows.size();
  if (q.pairs_done + n > q.npairs)
    throw std::logic_error("StateStream::pairs: more than the " + std::to_string(q.npairs) + " contacts announced");
  if (rows.bond.size() != (q.bonds ? n : 0))
    throw std::logic_error("StateStream::pairs: bond histories do not match the ball-ball law");
  io::ByteWriter o;
  for (std::size_t c = 0; c < n; ++c) o.u32(rows.a[c]);
  q.put(q.pair_cols[0], q.pairs_done, o);
  for (std::size_t c = 0; c < n; ++c) o.u32(rows.b[c]);
  q.put(q.pair_cols[1], q.pairs_done, o);
  for (std::size_t c = 0; c < n; ++c)
    for (std::int8_t v : rows.shift[c]) o.i8(v);
  q.put(q.pair_cols[2], q.pairs_done, o);
  for (std::size_t c = 0; c < n; ++c) put(o, rows.h[c]);
  q.put(q.pair_cols[3], q.pairs_done, o);
  if (q.bonds) {
    for (std::size_t c = 0; c < n; ++c) put(o, rows.bond[c]);
    q.put(q.pair_cols[4], q.pairs_done, o);
  }
  q.pairs_done += n;
}

void StateStream::commit(const WallContacts& planes, const WallContacts& facets, const WallContacts& footing) {
  Impl& q = *p_;
  if (q.balls_done != q.nballs || q.pairs_done != q.npairs)
    throw std::logic_error("StateStream::commit: " + std::to_string(q.balls_done) + " of " + std::to_string(q.nballs) +
                           " balls and " + std::to_string(q.pairs_done) + " of " + std::to_string(q.npairs) +
                           " contacts given");
  for (const std::string& name : q.after) {
    const WallContacts* wc = name == "plane_contacts" ? &planes : name == "facet_contacts" ? &facets
                             : name == "footing_contacts" ? &footing : nullptr;
    if (!wc) {
      q.file.section(name, q.frame.section_bytes(name));
      continue;
    }
    (void)q.frame.section_bytes(name);  // (replaced)
    io::ByteWriter o;
    put(o, *wc);
    q.file.section(name, o.buffer());
  }
  q.file.commit();
}

}  // namespace demfdm::dem

namespace demfdm::dem {

// ---- a World's state file read in pieces ------------------------------------------------------

struct StateSource::Impl {
  io::StateFileReader file;
  std::uint64_t scene_hash;
  std::string frame;
  std::uint64_t n = 0, m = 0;
  WorldParams params;
  std::size_t nplanes = 0;
  std::vector<FacetWall> fwalls;  // (for the facet contacts' checks)
  std::array<std::uint64_t, 13> ball_at{};  // each column's first element, within the section
  std::array<std::size_t, 13> ball_bytes{24, 24, 24, 24, 24, 24, 24, 24, 8, 8, 8, 8, 1};
  std::array<std::uint64_t, 5> pair_at{};
  std::array<std::size_t, 5> pair_bytes{4, 4, 4, kHistBytes, kBondBytes};
  bool pair_bonds = false;

  Impl(const std::filesystem::path& path, std::uint64_t hash) : file(path, kKind, hash), scene_hash(hash) {}
  [[noreturn]] void fail(const std::string& section, const std::string& what) const {
    throw io::StateFileError(file.source() + ": section '" + section + "': " + what);
  }
  std::uint64_t u64_at(const std::string& section, std::uint64_t off) const {
    io::SectionReader in(file.read(section, off, 8), file.source(), section);
    return in.u64();
  }
  // A section of columns, each a u64 count and count elements of bytes[k]: the columns' first
  // elements, every count checked against `want` (each its own: the bond column's may be 0).
  template <std::size_t K>
  void columns(const std::string& section, const std::array<std::uint64_t, K>& want, const std::array<std::size_t, K>& bytes,
               std::array<std::uint64_t, K>& at, const char* what) const {
    const std::uint64_t len = file.length(section);
    std::uint64_t off = 0;
    for (std::size_t k = 0; k < K; ++k) {
      if (off + 8 > len) fail(section, std::string(what) + ": the section ends at " + std::to_string(len) + " bytes");
      if (u64_at(section, off) != want[k]) fail(section, std::string(what) + " of different lengths");
      at[k] = off + 8;
      if (want[k] > (len - off - 8) / std::max<std::size_t>(bytes[k], 1))
        fail(section, std::string(what) + ": " + std::to_string(want[k]) + " elements cannot fit");
      off += 8 + want[k] * bytes[k];
    }
    if (off != len) fail(section, std::to_string(len - off) + " bytes left unread");
  }
  // Rows [r0, r0 + n) of a section of `rows` rows, or a refusal naming them.
  void check_rows(const std::string& section, const char* what, std::uint64_t r0, std::size_t n, std::uint64_t rows) const {
    if (r0 > rows || n > rows - r0)
      fail(section, std::string(what) + " " + std::to_string(r0) + " + " + std::to_string(n) + " of " + std::to_string(rows));
  }
  io::SectionReader column(const std::string& section, std::uint64_t at, std::size_t bytes, std::uint64_t first, std::size_t count) const {
    return io::SectionReader(file.read(section, at + first * bytes, count * bytes), file.source(), section);
  }
};

StateSource::StateSource(const std::filesystem::path& path, std::uint64_t scene_hash)
    : p_(std::make_unique<Impl>(path, scene_hash)) {
  Impl& q = *p_;
  // the frame: every section as the file has it, the balls, contacts and wall contacts empty
  io::StateWriter w(kKind, q.file.header().code_version, scene_hash);
  for (const std::string& name : q.file.names()) {
    w.begin(name);
    if (name == "balls") {
      for (int k = 0; k < 13; ++k) w.u64(0);
    } else if (name == "pairs") {
      for (int k = 0; k < 5; ++k) w.u64(0);
    } else if (name == "plane_contacts" || name == "facet_contacts" || name == "footing_contacts") {
      WallContacts none;
      none.cand_off.push_back(0);
      put(w, none);
    } else {
      w.raw(q.file.section_bytes(name));
    }
    w.end();
  }
  q.frame = w.bytes();
  World f{WorldParams{}};
  load_frame(f);  // (load_state's checks of every other section, and of the section list)
  q.params = f.params();
  q.nplanes = static_cast<std::size_t>(f.num_planes());
  for (int i = 0; i < f.num_facet_walls(); ++i) q.fwalls.push_back(f.facet_wall(i));
  q.pair_bonds = law_has_bond(q.params.ball_ball.model);
  q.n = q.file.length("balls") >= 8 ? q.u64_at("balls", 0) : 0;
  std::array<std::uint64_t, 13> nb;
  nb.fill(q.n);
  q.columns("balls", nb, q.ball_bytes, q.ball_at, "ball arrays");
  q.m = q.file.length("pairs") >= 8 ? q.u64_at("pairs", 0) : 0;
  if (q.file.length("pairs") >= q.pair_bytes.size() * 8 &&
      q.u64_at("pairs", 4 * 8 + q.m * (4 + 4 + 4 + kHistBytes)) != (q.pair_bonds ? q.m : 0))
    q.fail("pairs", "bond histories do not match the ball_ball contact model");
  q.columns("pairs", std::array<std::uint64_t, 5>{q.m, q.m, q.m, q.m, q.pair_bonds ? q.m : 0}, q.pair_bytes, q.pair_at,
            "contact arrays");
}

StateSource::~StateSource() = default;

const std::string& StateSource::frame_bytes() const { return p_->frame; }

void StateSource::load_frame(World& frame) const {
  load_state_bytes(frame, p_->frame, p_->scene_hash, p_->file.source());
}

std::uint64_t StateSource::balls() const { return p_->n; }
std::uint64_t StateSource::pairs() const { return p_->m; }

void StateSource::read_balls(std::uint64_t r0, std::size_t n, Particles& out) const {
  const Impl& q = *p_;
  q.check_rows("balls", "rows", r0, n, q.n);
  out = Particles{};
  std::vector<Vec3>* vecs[8] = {&out.x, &out.v, &out.w, &out.f, &out.t, &out.fa, &out.ta, &out.x_ref};
  for (std::size_t c = 0; c < 8; ++c) {
    io::SectionReader in = q.column("balls", q.ball_at[c], 24, r0, n);
    vecs[c]->resize(n);
    for (Vec3& x : *vecs[c]) x = get_vec(in);
  }
  std::vector<double>* dbl[3] = {&out.r, &out.m, &out.inertia};
  for (std::size_t c = 0; c < 3; ++c) {
    io::SectionReader in = q.column("balls", q.ball_at[8 + c], 8, r0, n);
    dbl[c]->resize(n);
    for (double& x : *dbl[c]) x = in.f64();
  }
  {
    io::SectionReader in = q.column("balls", q.ball_at[11], 8, r0, n);
    out.id.resize(n);
    for (auto& x : out.id) x = in.u64();
  }
  io::SectionReader in = q.column("balls", q.ball_at[12], 1, r0, n);
  out.fix.resize(n);
  for (auto& x : out.fix) x = in.u8();
}

void StateSource::read_positions(std::uint64_t r0, std::size_t n, std::vector<Vec3>& x, std::vector<double>& r,
                                 std::vector<std::uint64_t>& id) const {
  const Impl& q = *p_;
  q.check_rows("balls", "rows", r0, n, q.n);
  io::SectionReader ix = q.column("balls", q.ball_at[0], 24, r0, n), ir = q.column("balls", q.ball_at[8], 8, r0, n);
  io::SectionReader iid = q.column("balls", q.ball_at[11], 8, r0, n);
  x.resize(n), r.resize(n), id.resize(n);
  for (std::size_t i = 0; i < n; ++i) x[i] = get_vec(ix), r[i] = ir.f64(), id[i] = iid.u64();
}

void StateSource::read_pair_rows(std::uint64_t c0, std::size_t n, std::vector<std::uint32_t>& a,
                                 std::vector<std::uint32_t>& b) const {
  const Impl& q = *p_;
  q.check_rows("pairs", "contacts", c0, n, q.m);
  io::SectionReader ia = q.column("pairs", q.pair_at[0], 4, c0, n), ib = q.column("pairs", q.pair_at[1], 4, c0, n);
  a.resize(n), b.resize(n);
  for (std::size_t c = 0; c < n; ++c) {
    a[c] = ia.u32(), b[c] = ib.u32();
    if (a[c] >= q.n || b[c] >= q.n) q.fail("pairs", "contact " + std::to_string(c0 + c) + " names a ball row out of range");
  }
}

void StateSource::read_pairs(std::uint64_t c0, std::size_t n, PairContacts& out) const {
  const Impl& q = *p_;
  out = PairContacts{};
  read_pair_rows(c0, n, out.a, out.b);
  io::SectionReader is = q.column("pairs", q.pair_at[2], 4, c0, n), ih = q.column("pairs", q.pair_at[3], kHistBytes, c0, n);
  out.shift.resize(n), out.h.resize(n);
  for (std::size_t c = 0; c < n; ++c) {
    for (std::int8_t& v : out.shift[c]) v = is.i8();
    out.h[c] = get_hist(ih);
  }
  if (q.pair_bonds) {
    io::SectionReader ibd = q.column("pairs", q.pair_at[4], kBondBytes, c0, n);
    out.bond.resize(n);
    for (BondHist& b : out.bond) b = get_bond(ibd);
  }
}

std::array<WallContacts, 3> StateSource::read_wall_contacts() const {
  const Impl& q = *p_;
  std::array<WallContacts, 3> out;
  const char* names[3] = {"plane_contacts", "facet_contacts", "footing_contacts"};
  const ContactFamilyParams* fam[3] = {&q.params.ball_wall, &q.params.ball_facet, &q.params.ball_footing};
  const std::size_t walls[3] = {q.nplanes, q.fwalls.size(), 1};
  for (std::size_t k = 0; k < 3; ++k) {
    io::SectionReader in(q.file.section_bytes(names[k]), q.file.source(), names[k]);
    out[k] = get_wall_contacts(in);
    in.done();
    check_wall_contacts(in, out[k], q.n, walls[k], law_has_bond(fam[k]->model), k == 1 ? &q.fwalls : nullptr);
  }
  return out;
}

}  // namespace demfdm::dem
