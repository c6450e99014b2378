// World::contact_scan (the critical step of docs/theory.md §1.8 and the mean contact force of
// §5.11 in one pass over the contacts, issue 16 item 2). The per-contact terms are computed in
// parallel and summed in contact order, so the result must be the bits of the serial loops it
// replaced (written out below as the reference), at 1 and 2 threads, for every law, periodic and
// free, after the scalar and the vector pass; and the fused call must equal the separate ones.
// The same for the per-step sums over the balls (kinetic energy, unbalanced force).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>

#include "demfdm/dem/world.hpp"

using namespace demfdm::dem;

namespace {

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// The serial loops of the mean contact force and of the critical step as they were before the
// scan (one contact after another, sums in contact order).
double reference_fc(const World& w) {
  double s = 0.0;
  std::size_t cnt = 0;
  for (std::size_t c = 0; c < w.pair_contacts().size(); ++c) {
    const double f = norm(w.pair_force(c));
    if (f > 0.0) { s += f; ++cnt; }
  }
  for (const WallContacts* wc : {&w.plane_contacts(), &w.facet_contacts(), &w.footing_contacts()})
    for (std::size_t c = 0; c < wc->size(); ++c) {
      const double f = norm(wc->F[c]);
      if (f > 0.0) { s += f; ++cnt; }
    }
  return cnt ? s / double(cnt) : 0.0;
}

// The O(balls) sums as serial loops in row order (World::ordered_ball_sum must give their bits).
double reference_kinetic(const World& w) {
  const Particles& pt = w.balls();
  double e = 0.0;
  for (std::size_t i = 0; i < pt.size(); ++i)
    e += 0.5 * pt.m[i] * norm2(pt.v[i]) + 0.5 * pt.inertia[i] * norm2(pt.w[i]);
  return e;
}

double reference_unbalanced_sum(const World& w) {
  const Particles& pt = w.balls();
  double s = 0.0;
  for (std::size_t i = 0; i < pt.size(); ++i) {
    const Vec3 F = pt.f[i] + pt.fa[i];
    double q = 0.0;
    for (int k = 0; k < 3; ++k)
      if (!(pt.fix[i] & (1u << k))) q += F[k] * F[k];
    s += std::sqrt(q);
  }
  return s;
}

// kt_out, kr_out: every ball's stiffness sums (the scan must give their bits too, not only
// those of the smallest step).
double reference_dt(const World& w, std::vector<double>* kt_out = nullptr, std::vector<double>* kr_out = nullptr) {
  const Particles& pt = w.balls();
  const PairContacts& pc = w.pair_contacts();
  const WorldParams& p = w.params();
  std::vector<double> kt(pt.size(), 0.0), kr(pt.size(), 0.0);
  visit_law(p.ball_ball.model, [&](auto law) {
    using L = decltype(law);
    for (std::size_t c = 0; c < pc.size(); ++c) {
      const ContactHist& h = pc.h[c];
      const BondHist* b = pc.bond.empty() ? nullptr : &pc.bond[c];
      if (!(h.flags & ContactHist::kActive) && !(b && bonded(b->state))) continue;
      const std::uint32_t a = pc.a[c], bb = pc.b[c];
      const ContactStiffness s = L::stiffness(h, b, p.ball_ball, pt.r[a], pt.r[bb]);
      kt[a] += s.k;
      kt[bb] += s.k;
      kr[a] += s.krot + s.ks * pt.r[a] * pt.r[a];
      kr[bb] += s.krot + s.ks * pt.r[bb] * pt.r[bb];
    }
  });
  double dt = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < pt.size(); ++i) {
    if (kt[i] > 0.0) dt = std::min(dt, std::sqrt(pt.m[i] / kt[i]));
    if (kr[i] > 0.0) dt = std::min(dt, std::sqrt(pt.inertia[i] / kr[i]));
  }
  if (kt_out) *kt_out = kt;
  if (kr_out) *kr_out = kr;
  return p.dt_safety * dt;
}

struct Case {
  ContactModel model;
  bool periodic;
  PairKernel kernel;
  int threads;
};

std::string name(const Case& c) {
  return std::string(law_name(c.model)) + (c.periodic ? " periodic" : " free") +
         (c.kernel == PairKernel::kScalar ? " scalar" : " auto") + " threads " + std::to_string(c.threads);
}

// A jittered lattice of 17³ = 4,913 overlapping balls (above the parallel threshold of 4,096 balls and contacts
// contacts), random velocities and spins, pulled apart so that contacts open and
// close and (bond laws) bonds soften and break during the run.
std::unique_ptr<World> make_world(const Case& c) {
  const double R = 1e-4, s = 1.97 * R;
  const int ns = 17;
  WorldParams p;
  p.threads = c.threads;
  p.periodic.enabled = c.periodic;
  p.periodic.origin = {0, 0, 0};
  p.periodic.length = {ns * s, ns * s, ns * s};
  p.ball_ball.model = c.model;
  p.ball_ball.softbond.soft = 20.0;
  p.ball_ball.pbond.ten = p.ball_ball.pbond.coh = 2e5;  // parallel bonds break within the run
  auto w = std::make_unique<World>(p);
  w->set_pair_kernel(c.kernel);
  std::mt19937_64 rng(77);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int k = 0; k < ns; ++k)
    for (int j = 0; j < ns; ++j)
      for (int i = 0; i < ns; ++i)
        w->add_ball({(i + 0.5) * s + 0.03 * R * u(rng), (j + 0.5) * s + 0.03 * R * u(rng), (k + 0.5) * s + 0.03 * R * u(rng)},
                    R * (1.0 + 0.03 * u(rng)));
  w->prepare();
  if (law_has_bond(c.model)) w->bond_ball_ball(-1.0, 0.02 * R);
  const Vec3 mid{0.5 * ns * s, 0.5 * ns * s, 0.5 * ns * s};
  for (std::size_t i = 0; i < w->num_balls(); ++i) {
    w->balls().v[i] = 0.02 * Vec3{u(rng), u(rng), u(rng)};
    if (!c.periodic) w->balls().v[i] += 60.0 * (w->balls().x[i] - mid);
    w->balls().w[i] = 50.0 * Vec3{u(rng), u(rng), u(rng)};
  }
  if (c.periodic) w->set_strain_rate({60.0, 60.0, -30.0});
  return w;
}

std::vector<Case> cases() {
  std::vector<Case> out;
  for (ContactModel m : {ContactModel::kLinear, ContactModel::kLinearPBond, ContactModel::kSoftBond, ContactModel::kHertz})
    for (bool per : {true, false})
      for (PairKernel k : {PairKernel::kScalar, PairKernel::kAuto})
        for (int t : {1, 2}) out.push_back({m, per, k, t});
  return out;
}

}  // namespace

TEST(ContactScan, SameBitsAsTheSerialLoopsAtOneAndTwoThreads) {
  for (const Case& c : cases()) {
    auto w = make_world(c);
    std::size_t bonded_before = 0, bonded_after = 0;
    for (const BondHist& b : w->pair_contacts().bond) bonded_before += bonded(b.state);
    ASSERT_GT(w->pair_contacts().size(), 4096u) << name(c);
    for (int k = 0; k < 20; ++k) {
      w->step();
      if (k % 5 != 4) continue;
      const World& cw = *w;
      const World::ContactScan both = cw.contact_scan(true, true);
      const std::string at = name(c) + " step " + std::to_string(k + 1);
      std::vector<double> kt, kr;
      ASSERT_TRUE(same_bits(both.dt, reference_dt(cw, &kt, &kr))) << at << ": critical step " << both.dt << " vs " << reference_dt(cw);
      // every ball's sums, at this thread count and (below) the other
      auto same_sums = [&](const std::string& what) {
        ASSERT_EQ(cw.stiffness_sums_translational().size(), kt.size()) << what;
        for (std::size_t i = 0; i < kt.size(); ++i) {
          ASSERT_TRUE(same_bits(cw.stiffness_sums_translational()[i], kt[i])) << what << ": k_t of row " << i;
          ASSERT_TRUE(same_bits(cw.stiffness_sums_rotational()[i], kr[i])) << what << ": k_r of row " << i;
        }
      };
      same_sums(at);
      ASSERT_TRUE(same_bits(both.fc, reference_fc(cw))) << at << ": mean contact force " << both.fc << " vs " << reference_fc(cw);
      ASSERT_GT(both.fc, 0.0) << at;
      // the separate calls, and the other thread count on the same state
      EXPECT_TRUE(same_bits(w->critical_timestep(), both.dt)) << at;
      EXPECT_TRUE(same_bits(w->mean_contact_force(), both.fc)) << at;
      w->mutable_params().threads = 3 - c.threads;
      const World::ContactScan other = cw.contact_scan(true, true);
      same_sums(at + ": threads " + std::to_string(3 - c.threads));
      w->mutable_params().threads = c.threads;
      EXPECT_TRUE(same_bits(other.dt, both.dt) && same_bits(other.fc, both.fc)) << at << ": threads " << 3 - c.threads;
      // the O(balls) measurements of every step
      EXPECT_TRUE(same_bits(w->kinetic_energy(), reference_kinetic(cw))) << at;
      EXPECT_TRUE(same_bits(w->unbalanced_ratio(both.fc),
                            (reference_unbalanced_sum(cw) / double(w->num_balls())) / both.fc))
          << at;
      // only what is asked for is computed
      EXPECT_EQ(cw.contact_scan(true, false).fc, 0.0);
      EXPECT_EQ(cw.contact_scan(false, true).dt, 0.0);
    }
    for (const BondHist& b : w->pair_contacts().bond) bonded_after += bonded(b.state);
    // The run exercises what the stiffness depends on: bonds leave the intact state (bond laws).
    if (law_has_bond(c.model)) {
      EXPECT_LT(bonded_after, bonded_before) << name(c) << ": no bond failed";
    }
  }
}

// The pass writes every contact's force norm for the scan (it need not stream the histories
// again). A history changed after the pass (through pair_contacts(), or by bonding) must be
// seen by the next scan: the norms are then recomputed.
TEST(ContactScan, HistoriesChangedAfterThePassAreSeen) {
  for (ContactModel m : {ContactModel::kLinear, ContactModel::kSoftBond}) {
    auto w = make_world({m, false, PairKernel::kAuto, 2});
    w->step();
    w->step();
    const double before = w->mean_contact_force();
    ASSERT_TRUE(same_bits(before, reference_fc(*w))) << law_name(m);
    std::size_t c = 0;
    while (c < w->pair_contacts().size() && !(w->pair_contacts().h[c].flags & ContactHist::kActive)) ++c;
    ASSERT_LT(c, w->pair_contacts().size()) << law_name(m);
    w->pair_contacts().h[c].fn *= 3.0;
    const double after = w->mean_contact_force();
    EXPECT_FALSE(same_bits(after, before)) << law_name(m);
    EXPECT_TRUE(same_bits(after, reference_fc(*w))) << law_name(m) << ": " << after << " vs " << reference_fc(*w);
    if (law_has_bond(m)) {  // bonding changes the histories too
      w->bond_ball_ball(-1.0, 0.05 * 1e-4);
      EXPECT_TRUE(same_bits(w->mean_contact_force(), reference_fc(*w))) << law_name(m) << " after bonding";
    }
  }
}

// The critical step's terms are kept across steps and redone only for the contacts whose active
// flag or bond state a pass changed. What else they depend on, changed between two scans, must
// make the next scan start again: a radius, the family's parameters, the list's histories.
TEST(ContactScan, KeptStiffnessTermsFollowRadiiParametersAndHistories) {
  for (ContactModel m : {ContactModel::kLinear, ContactModel::kSoftBond, ContactModel::kLinearPBond}) {
    auto w = make_world({m, false, PairKernel::kAuto, 2});
    auto check = [&](const std::string& what) {
      std::vector<double> kt, kr;
      const double ref = reference_dt(*w, &kt, &kr);
      const double dt = static_cast<const World&>(*w).contact_scan(true, false).dt;
      ASSERT_TRUE(same_bits(dt, ref)) << law_name(m) << " " << what;
      for (std::size_t i = 0; i < kt.size(); ++i) {
        ASSERT_TRUE(same_bits(w->stiffness_sums_translational()[i], kt[i])) << law_name(m) << " " << what << ": row " << i;
        ASSERT_TRUE(same_bits(w->stiffness_sums_rotational()[i], kr[i])) << law_name(m) << " " << what << ": row " << i;
      }
    };
    w->step();
    check("after a step");
    w->step();
    check("after the next step (kept terms)");
    w->set_radius(7, w->balls().r[7] * 1.01);
    check("after a radius changed");
    w->mutable_params().ball_ball.linear.emod *= 2.0;  // new contacts' stiffness; kept ones keep theirs
    w->mutable_params().ball_ball.pbond.kratio *= 2.0;
    check("after the family changed");
    std::size_t c = 0;
    while (c < w->pair_contacts().size() && !(w->pair_contacts().h[c].flags & ContactHist::kActive)) ++c;
    ASSERT_LT(c, w->pair_contacts().size());
    w->pair_contacts().h[c].kn *= 3.0;
    check("after a history changed");
    w->step();
    check("after one more step");
  }
}

// World::keep_force_norms: the pass writes every contact's ||F|| (the node measures after every
// step), and the scan sums those instead of reading the histories. Every norm, idle entries
// included, must be the bits of ||Law::force|| of the history, for every law, periodic and free,
// after the scalar and the vector pass, at 1 and 2 threads, and after a new list; a change of
// the histories outside the pass (bonding, mutable access) makes the scan read them again.
TEST(ContactScan, PassForceNormsSameBitsAsTheHistories) {
  for (const Case& c : cases()) {
    auto w = make_world(c);
    w->keep_force_norms(true);
    EXPECT_FALSE(w->force_norms_kept()) << name(c) << ": before any pass";
    std::size_t idle_seen = 0;
    const std::int64_t rebuilds0 = w->rebuild_count();
    for (int k = 0; k < 20; ++k) {
      if (k == 10) {  // new rows and a new list: every entry's norm is written again
        w->reorder_spatially();
        w->prepare();
      }
      w->step();
      const World& cw = *w;
      const std::string at = name(c) + " step " + std::to_string(k + 1);
      ASSERT_TRUE(cw.force_norms_kept()) << at;
      std::vector<double> terms;
      cw.contact_force_norms(terms);
      std::vector<World::ContactTerm> keys;  // (the keys of the terms, in their order)
      cw.contact_force_keys(keys);
      const PairContacts& pc = cw.pair_contacts();
      ASSERT_GE(terms.size(), pc.size()) << at;
      ASSERT_EQ(keys.size(), terms.size()) << at;
      for (std::size_t j = 0; j < pc.size(); ++j) {
        const double ref = norm(cw.pair_force(j));
        ASSERT_TRUE(same_bits(terms[j], ref)) << at << ": contact " << j << " norm " << terms[j] << " vs " << ref;
        ASSERT_EQ(keys[j].a, cw.balls().id[pc.a[j]]) << at << ": contact " << j;
        ASSERT_EQ(keys[j].b, cw.balls().id[pc.b[j]]) << at << ": contact " << j;
        idle_seen += ref == 0.0;
      }
      const World::ContactScan s = cw.contact_scan(true, true);
      ASSERT_TRUE(same_bits(s.fc, reference_fc(cw))) << at << ": mean contact force";
      ASSERT_TRUE(same_bits(s.dt, reference_dt(cw))) << at << ": critical step";
    }
    EXPECT_GT(idle_seen, 0u) << name(c) << ": no contact with a zero force";
    EXPECT_GT(w->rebuild_count(), rebuilds0) << name(c) << ": no new list";
    // Histories changed outside the pass: the scan reads them again.
    if (law_has_bond(c.model)) {
      w->bond_ball_ball(-1.0, 0.02 * 1e-4);
      EXPECT_FALSE(w->force_norms_kept()) << name(c) << ": after bonding";
      const World& cw = *w;
      EXPECT_TRUE(same_bits(cw.contact_scan(false, true).fc, reference_fc(cw))) << name(c) << ": after bonding";
      w->step();
    }
    EXPECT_TRUE(w->force_norms_kept()) << name(c);
    w->pair_contacts();  // mutable access: the caller may change histories
    EXPECT_FALSE(w->force_norms_kept()) << name(c) << ": after mutable access";
    const World& cw = *w;
    EXPECT_TRUE(same_bits(cw.contact_scan(false, true).fc, reference_fc(cw))) << name(c) << ": after mutable access";
  }
}
