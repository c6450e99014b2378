// Golden data of the DEM contact laws (issue 15 item 1), in the spirit of LAMMPS's force-style
// YAML tests: small fixed configurations are stepped N times and every ball's state, every
// contact's history (linear part and bond part), force and moment, the wall reactions and the
// energy terms are written as exact hexadecimal floats and compared, line by line, with the files
// in tests/golden/data/. A deterministic change of any law, of the cycle's order of operations or
// of the sums makes the test fail and prints the first lines that differ (golden, then now, with
// decimal values). A restructure of the engine must keep these files byte for byte.
//
// Each configuration is a jittered block of 64 polydisperse balls with random velocities and
// spins, under 100 g, between a planar floor, a facet wall on one side and the footing pushed
// down into its top (or, for the periodic ones, a straining periodic cell without walls), so that
// contacts slip, bonds soften and break in tension and in shear, and every contact set carries
// load within the run. Every configuration runs with the scalar reference pass and with the
// vectorised pass of this CPU; both must give the golden bits.
//
// Regenerate (only for a deliberate change of physics, and say so in the commit):
//   DEMFDM_GOLDEN_UPDATE=1 build/bin/golden_tests
// writes the files into the source tree and reports the tests as skipped.
#include <gtest/gtest.h>

#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "demfdm/dem/world.hpp"
#include "tests/golden/golden.hpp"

using namespace demfdm::dem;
namespace gold = demfdm::golden;

namespace {

using gold::hx;
std::string hx(const Vec3& v) { return hx(v.x) + " " + hx(v.y) + " " + hx(v.z); }

struct Config {
  std::string name;
  ContactModel model = ContactModel::kLinear;
  NormalMode mode = NormalMode::kAbsolute;
  bool periodic = false;
  SoftBondParams soft{};  // soft-bond options (ζ set below)
  int steps = 800;
};

void hist_text(std::ostringstream& o, const ContactHist& h) {
  o << " fn " << hx(h.fn) << " fs " << hx(h.fs) << " n_old " << hx(h.n_old) << " kn " << hx(h.kn) << " ks "
    << hx(h.ks) << " mu " << hx(h.mu) << " e_slip " << hx(h.e_slip) << " flags " << int(h.flags);
}

void bond_text(std::ostringstream& o, const BondHist& b) {
  o << " | state " << to_string(b.state) << " rb " << hx(b.rb) << " kn " << hx(b.kn) << " sigma_t " << hx(b.sigma_t)
    << " nb " << hx(b.nb) << " fsb " << hx(b.fsb) << " mb " << hx(b.mb) << " mt " << hx(b.mt) << " e_soft "
    << hx(b.e_soft) << " slip " << int(b.slip_b) << int(b.slip_t);
}

void wall_text(std::ostringstream& o, const char* kind, const World& w, const WallContacts& c) {
  o << kind << "_contacts " << c.size() << "\n";
  for (std::size_t k = 0; k < c.size(); ++k) {
    o << kind << " ball " << w.balls().id[c.ball[k]] << " wall " << c.wall[k];
    hist_text(o, c.h[k]);
    if (!c.bond.empty()) bond_text(o, c.bond[k]);
    o << " | F " << hx(c.F[k]) << " M " << hx(c.M[k]) << "\n";
  }
}

struct Outcome {
  std::string text;
  std::size_t pairs = 0, plane = 0, facet = 0, footing = 0;
  int broken = 0, softening = 0, intact = 0;
};

Outcome run(const Config& cf, PairKernel kernel) {
  const double R = 1e-4, s = 2.004 * R;
  const int ns = 4;
  WorldParams p;
  p.threads = 1;
  p.local_damping = 0.1;
  p.gravity = false;
  p.g_level = 100.0;
  p.ball_ball.model = cf.model;
  p.ball_ball.linear.mode = cf.mode;
  p.ball_ball.softbond = cf.soft;
  p.ball_ball.softbond.soft = 20.0;  // ζ: a short softening branch, so bonds break within the run
  p.ball_wall.linear.fric = 0.3;
  p.ball_footing.linear.fric = 0.5;
  if (cf.model != ContactModel::kLinear) {  // the paper's interface: parallel bonds on the facets
    p.ball_facet.model = ContactModel::kLinearPBond;
    p.ball_facet.pbond.zero_linear = true;
  }
  if (cf.periodic) {
    p.periodic.enabled = true;
    p.periodic.origin = {0, 0, 0};
    p.periodic.length = {ns * s, ns * s, ns * s};
  }
  World w(p);
  w.set_pair_kernel(kernel);
  std::mt19937_64 rng(15);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < ns; ++k)
    for (int j = 0; j < ns; ++j)
      for (int i = 0; i < ns; ++i)
        w.add_ball({(i + 0.5) * s + 0.002 * R * u(rng), (j + 0.5) * s + 0.002 * R * u(rng), (k + 0.5) * s + 0.002 * R * u(rng)},
                   R * (1.0 + 0.002 * u(rng)));
  const double top = ns * s, side = ns * s;
  if (!cf.periodic) {
    PlaneWallParams floor;
    floor.point = {0.5 * side, 0.5 * side, 0.5 * s - 1.003 * R};
    floor.normal = {0, 0, 1};
    w.add_plane(floor);
    // A vertical facet wall on the x = 0 side (two triangles, winding towards +x).
    const double xf = 0.5 * s - 1.003 * R;
    const std::vector<double> v{xf, -s, -s, xf, side + s, -s, xf, side + s, top + s, xf, -s, top + s};
    const std::vector<std::int32_t> t{0, 1, 2, 0, 2, 3};
    w.add_facet_wall(v, t);
    FootingParams fp;
    fp.diameter = 2.2 * s;
    fp.height = s;
    fp.bottom_centre = {0.5 * side, 0.5 * side, top - 0.5 * s + 1.003 * R};
    fp.velocity = {0, 0, -0.5};
    w.set_footing(fp);
  }
  w.prepare();
  if (cf.model != ContactModel::kLinear) {
    w.bond_ball_ball(-1.0, 0.012 * R);
    if (!cf.periodic) w.bond_ball_facet(0.01 * R);
  }
  for (std::size_t i = 0; i < w.num_balls(); ++i) {
    w.balls().v[i] = 0.01 * Vec3{u(rng), u(rng), u(rng)};
    w.balls().w[i] = 30.0 * Vec3{u(rng), u(rng), u(rng)};
    if (i % 29 == 5) w.balls().fix[i] = kFixVx | kFixWz;  // fixity takes the scalar path of a block
  }
  if (cf.periodic) w.set_strain_rate({150.0, 150.0, -75.0});
  else w.set_gravity(true, 100.0);
  w.step(cf.steps);

  Outcome out;
  std::ostringstream o;
  o << "# demfdm golden data (tests/golden/golden_laws_test.cpp): " << cf.name << "\n";
  o << "steps " << w.step_count() << " time " << hx(w.time()) << " dt " << hx(w.dt()) << " rebuilds "
    << w.rebuild_count() << " bond_failures " << w.bond_failures() << "\n";
  const Particles& b = w.balls();
  o << "balls " << b.size() << "\n";
  for (std::size_t i = 0; i < b.size(); ++i)
    o << "ball " << b.id[i] << " r " << hx(b.r[i]) << " x " << hx(b.x[i]) << " v " << hx(b.v[i]) << " w " << hx(b.w[i])
      << " f " << hx(b.f[i]) << " t " << hx(b.t[i]) << "\n";
  const PairContacts& pc = w.pair_contacts();
  out.pairs = pc.size();
  o << "pairs " << pc.size() << "\n";
  for (std::size_t k = 0; k < pc.size(); ++k) {
    o << "pair " << b.id[pc.a[k]] << " " << b.id[pc.b[k]] << " shift " << int(pc.shift[k][0]) << int(pc.shift[k][1])
      << int(pc.shift[k][2]);
    hist_text(o, pc.h[k]);
    if (!pc.bond.empty()) {
      bond_text(o, pc.bond[k]);
      const BondState st = pc.bond[k].state;
      out.broken += st == BondState::kBrokenTension || st == BondState::kBrokenShear;
      out.softening += st == BondState::kSoftening;
      out.intact += st == BondState::kIntact;
    }
    o << " | F " << hx(w.pair_force(k)) << " M " << hx(w.pair_moment(k)) << "\n";
  }
  wall_text(o, "plane", w, w.plane_contacts());
  wall_text(o, "facet", w, w.facet_contacts());
  wall_text(o, "footing", w, w.footing_contacts());
  out.plane = w.plane_contacts().size();
  out.facet = w.facet_contacts().size();
  out.footing = w.footing_contacts().size();
  for (int i = 0; i < w.num_planes(); ++i) o << "plane_reaction " << i << " " << hx(w.plane(i).reaction) << "\n";
  for (int i = 0; i < w.num_facet_walls(); ++i) {
    o << "facet_force " << i << " " << hx(w.facet_wall_force(i)) << "\n";
    const auto vf = w.vertex_forces(i);
    const auto vs = w.vertex_stiffness(i);
    for (std::size_t k = 0; k < vs.size(); ++k)
      o << "vertex " << k << " force " << hx(vf[3 * k]) << " " << hx(vf[3 * k + 1]) << " " << hx(vf[3 * k + 2])
        << " stiffness " << hx(vs[k]) << "\n";
  }
  if (w.has_footing()) o << "footing_reaction " << hx(w.footing_reaction()) << "\n";
  const Energy e = w.energy();
  o << "energy kinetic " << hx(e.kinetic) << " strain " << hx(e.strain) << " damping " << hx(e.damping) << " friction "
    << hx(e.friction) << " softening " << hx(e.softening) << "\n";
  out.text = o.str();
  return out;
}

// Compares with the golden file; prints the first (up to 4) differing lines.
void check_golden(const Config& cf, const Outcome& now, const char* kernel) {
  for (const std::string& d : gold::compare(cf.name + ".golden", now.text))
    ADD_FAILURE() << cf.name << " (" << kernel << " pass) differs from its golden data: " << d;
}

void golden(const Config& cf) {
  const Outcome ref = run(cf, PairKernel::kScalar);
  // The configuration exercises what it is meant to (a failure here means the golden data
  // would no longer cover the contact sets or the bond states it claims to).
  EXPECT_GT(ref.pairs, 40u);
  if (!cf.periodic) {
    EXPECT_GT(ref.plane, 0u);
    EXPECT_GT(ref.facet, 0u);
    EXPECT_GT(ref.footing, 0u);
  }
  if (cf.model != ContactModel::kLinear) {
    EXPECT_GT(ref.broken, 0) << "no bond broke";
    EXPECT_GT(ref.intact, 0) << "no bond left intact";
  }
  std::printf("%s: %zu pairs, plane %zu, facet %zu, footing %zu contacts; bonds intact %d softening %d broken %d\n",
              cf.name.c_str(), ref.pairs, ref.plane, ref.facet, ref.footing, ref.intact, ref.softening, ref.broken);
  if (gold::update_mode()) {
    gold::write(cf.name + ".golden", ref.text);
    GTEST_SKIP() << "wrote " << gold::data_dir() << "/" << cf.name << ".golden";
  }
  check_golden(cf, ref, "scalar");
  check_golden(cf, run(cf, PairKernel::kAuto), "vectorised");
}

}  // namespace

TEST(GoldenLaws, Linear) {
  Config c;
  c.name = "linear";
  golden(c);
}

TEST(GoldenLaws, LinearIncremental) {
  Config c;
  c.name = "linear_incremental";
  c.mode = NormalMode::kIncremental;
  golden(c);
}

TEST(GoldenLaws, LinearPeriodicStrained) {
  Config c;
  c.name = "linear_periodic";
  c.periodic = true;
  golden(c);
}

TEST(GoldenLaws, ParallelBond) {
  Config c;
  c.name = "pbond";
  c.model = ContactModel::kLinearPBond;
  golden(c);
}

TEST(GoldenLaws, SoftBond) {
  Config c;
  c.name = "softbond";
  c.model = ContactModel::kSoftBond;
  golden(c);
}

TEST(GoldenLaws, SoftBondOptions) {  // radial return, secant unloading, proportional cohesion, no bending in softening
  Config c;
  c.name = "softbond_options";
  c.model = ContactModel::kSoftBond;
  c.soft.ret = SoftReturn::kRadial;
  c.soft.unload = SoftUnload::kSecant;
  c.soft.cohesion = CohesionSoftening::kProportional;
  c.soft.bending_in_softening = false;
  c.soft.moments = UnbondedMoments::kNone;
  golden(c);
}

TEST(GoldenLaws, SoftBondPeriodicStrained) {
  Config c;
  c.name = "softbond_periodic";
  c.model = ContactModel::kSoftBond;
  c.periodic = true;
  golden(c);
}
