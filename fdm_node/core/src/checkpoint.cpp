// Bit-exact FDM state save/load: see checkpoint.hpp and docs/checkpoint-format.md.
#include "demfdm/fdm/checkpoint.hpp"

#include <bit>
#include <istream>
#include <iterator>
#include <ostream>
#include <stdexcept>
#include <utility>

namespace demfdm::fdm {

// Tripwire: a new Model member (or a new HistoryRecord field) changes the size. Decide whether
// it is state, save it below and in docs/checkpoint-format.md, then update the size.
#if defined(__x86_64__) && defined(__GNUC__) && !defined(_GLIBCXX_DEBUG)
static_assert(sizeof(Model) == 1288, "Model changed: is the new member state? update the checkpoint");
// (zone_kernel_ is not state: every choice gives the same bits.)
static_assert(sizeof(HistoryRecord) == 72, "HistoryRecord changed: update the checkpoint");
#endif

namespace {

constexpr const char* kKind = "fdm";

struct Fingerprint {
  std::uint64_t h = 14695981039346656037ULL;
  void add(const void* p, std::size_t n) { h = io::fnv1a64(p, n, h); }
  void f64(double v) {
    const std::uint64_t b = std::bit_cast<std::uint64_t>(v);
    add(&b, 8);
  }
  void u64(std::uint64_t v) { add(&v, 8); }
  void f64s(const std::vector<double>& v) {
    u64(v.size());
    for (double x : v) f64(x);
  }
  void i32s(const std::vector<std::int32_t>& v) {
    u64(v.size());
    for (std::int32_t x : v) u64(static_cast<std::uint64_t>(static_cast<std::uint32_t>(x)));
  }
};

void put(io::StateWriter& o, const HistoryRecord& r) {
  o.i64(r.step);
  o.f64(r.time);
  o.f64(r.ratios.average);
  o.f64(r.ratios.max);
  o.f64(r.ratios.local);
  o.f64(r.kinetic_energy);
  for (double v : r.base_reaction) o.f64(v);
}

HistoryRecord get_record(io::SectionReader& in) {
  HistoryRecord r;
  r.step = in.i64();
  r.time = in.f64();
  r.ratios.average = in.f64();
  r.ratios.max = in.f64();
  r.ratios.local = in.f64();
  r.kinetic_energy = in.f64();
  for (double& v : r.base_reaction) v = in.f64();
  return r;
}

}  // namespace

// Private-state access of Model for the checkpoint (friend of Model).
struct CheckpointAccess {
  // What the constructor derives from the mesh and the parameters; equal fingerprints mean
  // the loading model was built like the saved one.
  static std::uint64_t fingerprint(const Model& m) {
    Fingerprint f;
    const Mesh& me = m.mesh_;
    f.f64s(me.grid_x);
    f.f64s(me.grid_y);
    f.f64s(me.grid_z);
    f.f64s(me.points);
    f.i32s(me.point_ijk);
    f.i32s(me.zones);
    f.i32s(me.interface_points);
    f.i32s(me.interface_triangles);
    f.f64s(m.x0_);
    f.f64s(m.geom_);
    f.f64s(m.gmass_);
    f.f64s(m.mass_base_);
    f.f64s(m.zone_stiffness_);
    f.i32s(m.zone_material_);
    f.i32s(m.elastic_zones_);  // the constitutive law of each zone
    f.i32s(m.mc_zones_);
    f.u64(m.materials_.size());
    for (const MaterialConstants& c : m.materials_) {
      for (double v : {c.bulk, c.shear, c.alpha1, c.alpha2, c.density, c.cohesion, c.n_phi, c.n_psi, c.sqrt_n_phi,
                       c.tension, c.alpha_p, c.sigma_p})
        f.f64(v);
    }
    const ModelParams& p = m.params_;
    f.u64(static_cast<std::uint64_t>(p.mode));
    f.f64(p.damping);
    f.f64(p.gravity_level);
    f.u64(p.large_strain);
    f.u64(static_cast<std::uint64_t>(p.averaging));
    f.f64(p.timestep_safety);
    f.f64(p.static_mass_factor);
    f.u64(static_cast<std::uint64_t>(p.history_every));
    for (double g : m.gravity_) f.f64(g);
    return f.h;
  }

  static void save(const Model& m, io::StateWriter& o) {
    o.begin("model");
    o.u64(fingerprint(m));
    o.u64(m.n_);
    o.u64(m.nz_);
    o.u64(m.mesh_.interface_points.size());
    o.end();

    o.begin("counters");
    o.i64(m.step_);
    o.f64(m.time_);
    o.f64(m.dt_);
    o.b(m.dt_imposed_);
    o.f64(m.zone_critical_dt_);
    o.f64(m.interface_critical_dt_);
    o.b(m.has_coupling_);
    o.b(m.forces_valid_);
    o.end();

    o.begin("gridpoints");
    o.f64s(m.x_);
    o.f64s(m.u_);
    o.f64s(m.v_);
    o.f64s(m.mass_);
    o.f64s(m.fzone_);
    o.f64s(m.fext_);
    o.f64s(m.fapplied_);
    o.f64s(m.vfix_);
    o.u8s(m.fix_);
    o.end();

    o.begin("zones");
    o.f64s(m.stress_);
    o.u8s(m.plastic_);
    o.f64s(m.zone_slot_);
    o.end();

    o.begin("interface");
    o.f64s(m.fcouple_);
    o.f64s(m.kcouple_);
    o.end();

    o.begin("history");
    o.u64(m.history_.size());
    for (const HistoryRecord& r : m.history_) put(o, r);
    o.end();
  }

  static void load(Model& m, io::StateReader& r) {
    const std::size_t n = m.n_, nz = m.nz_, nif = m.mesh_.interface_points.size();
    {
      auto in = r.section("model");
      const std::uint64_t fp = in.u64(), sn = in.u64(), snz = in.u64(), snif = in.u64();
      in.done();
      if (sn != n || snz != nz || snif != nif)
        r.fail("the model was saved with " + std::to_string(sn) + " gridpoints, " + std::to_string(snz) + " zones and " +
               std::to_string(snif) + " interface gridpoints; this one has " + std::to_string(n) + ", " +
               std::to_string(nz) + " and " + std::to_string(nif) + " (built from other parameters)");
      if (fp != fingerprint(m))
        r.fail("the model to load into was built from other parameters (mesh, materials, mode or gravity differ "
               "from the saved model's; construct it from the same scene)");
    }
    struct Counters {
      std::int64_t step;
      double time, dt;
      bool dt_imposed;
      double zone_dt, interface_dt;
      bool has_coupling, forces_valid;
    } k;
    {
      auto in = r.section("counters");
      k.step = in.i64();
      k.time = in.f64();
      k.dt = in.f64();
      k.dt_imposed = in.b();
      k.zone_dt = in.f64();
      k.interface_dt = in.f64();
      k.has_coupling = in.b();
      k.forces_valid = in.b();
      in.done();
    }
    auto sized = [](io::SectionReader& in, std::vector<double> v, std::size_t want, const char* what) {
      if (v.size() != want)
        in.fail(std::string(what) + ": " + std::to_string(v.size()) + " values, expected " + std::to_string(want));
      return v;
    };
    std::vector<double> x, u, v, mass, fzone, fext, fapplied, vfix, stress, slot, fcouple, kcouple;
    std::vector<std::uint8_t> fix, plastic;
    {
      auto in = r.section("gridpoints");
      x = sized(in, in.f64s(), 3 * n, "x");
      u = sized(in, in.f64s(), 3 * n, "u");
      v = sized(in, in.f64s(), 3 * n, "v");
      mass = sized(in, in.f64s(), n, "mass");
      fzone = sized(in, in.f64s(), 3 * n, "zone forces");
      fext = sized(in, in.f64s(), 3 * n, "external forces");
      fapplied = sized(in, in.f64s(), 3 * n, "applied loads");
      vfix = sized(in, in.f64s(), 3 * n, "prescribed velocities");
      fix = in.u8s();
      if (fix.size() != n) in.fail("fixity: " + std::to_string(fix.size()) + " values, expected " + std::to_string(n));
      in.done();
    }
    {
      auto in = r.section("zones");
      stress = sized(in, in.f64s(), nz * kTetsPerZone * 6, "stresses");
      plastic = in.u8s();
      if (plastic.size() != nz)
        in.fail("plastic state: " + std::to_string(plastic.size()) + " values, expected " + std::to_string(nz));
      slot = sized(in, in.f64s(), nz * 24, "zone force slots");
      in.done();
    }
    {
      auto in = r.section("interface");
      fcouple = sized(in, in.f64s(), 3 * nif, "coupling forces");
      kcouple = sized(in, in.f64s(), nif, "coupling stiffness");
      in.done();
    }
    std::vector<HistoryRecord> history;
    {
      auto in = r.section("history");
      history.resize(in.count(72));
      for (HistoryRecord& h : history) h = get_record(in);
      in.done();
    }
    r.finish();

    m.step_ = k.step;
    m.time_ = k.time;
    m.dt_ = k.dt;
    m.dt_imposed_ = k.dt_imposed;
    m.zone_critical_dt_ = k.zone_dt;
    m.interface_critical_dt_ = k.interface_dt;
    m.has_coupling_ = k.has_coupling;
    m.forces_valid_ = k.forces_valid;
    m.x_ = std::move(x);
    m.u_ = std::move(u);
    m.v_ = std::move(v);
    m.mass_ = std::move(mass);
    m.fzone_ = std::move(fzone);
    m.fext_ = std::move(fext);
    m.fapplied_ = std::move(fapplied);
    m.vfix_ = std::move(vfix);
    m.fix_ = std::move(fix);
    m.stress_ = std::move(stress);
    m.plastic_ = std::move(plastic);
    m.zone_slot_ = std::move(slot);
    m.fcouple_ = std::move(fcouple);
    m.kcouple_ = std::move(kcouple);
    m.history_ = std::move(history);
  }
};

using Front = io::StateFront<CheckpointAccess, Model>;

std::string state_bytes(const Model& m, const CheckpointMeta& meta) { return Front::bytes(m, kKind, meta); }

void save_state(const Model& m, std::ostream& out, const CheckpointMeta& meta) {
  io::write_stream(out, state_bytes(m, meta));
}

void save_state_file(const Model& m, const std::filesystem::path& path, const CheckpointMeta& meta) {
  io::write_atomically(path, state_bytes(m, meta));
}

io::StateHeader load_state_bytes(Model& m, std::string bytes, std::uint64_t scene_hash, std::string_view source) {
  return Front::load(m, std::move(bytes), kKind, scene_hash, source);
}

io::StateHeader load_state(Model& m, std::istream& in, std::uint64_t scene_hash, std::string_view source) {
  return load_state_bytes(m, io::read_stream(in, source), scene_hash, source);
}

io::StateHeader load_state_file(Model& m, const std::filesystem::path& path, std::uint64_t scene_hash) {
  return load_state_bytes(m, io::read_whole_file(path), scene_hash, path.string());
}

}  // namespace demfdm::fdm
