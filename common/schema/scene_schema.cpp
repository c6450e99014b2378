#include "common/schema/scene_schema.hpp"

#include <algorithm>

namespace demfdm::schema {
namespace {

void declare_run(config::Section& root) {
  auto& run = root.section("run", "Run identity and process settings.", config::Presence::Optional);
  run.string("name", std::string("run"), "Short name used in the run folder name.");
  run.string("description", std::string(""), "Free text copied into the run summary.");
  run.integer("seed", "-", 1, "Seed of every random generator (same seed + same threads = same results).").min(0);
  run.integer("threads", "-", 1, "OpenMP threads per node.").min(1).max(256);
}

void declare_bus(config::Section& root) {
  auto& bus = root.section("bus", "Message bus timing (messages/README.md).", config::Presence::Optional);
  bus.real("heartbeat_s", "s", 0.25, "Heartbeat period of every process.").min(0.01).max(2.0);
  bus.real("peer_timeout_s", "s", 3.0,
           "Silence after which a process is declared dead or hung (detection within this + one heartbeat).")
      .min(0.5).max(600.0);
  bus.real("startup_s", "s", 30.0, "Deadline for every node to receive the scene and say hello.").min(1.0).max(3600.0);
  bus.real("resend_after_s", "s", 0.02, "First NACK/resend after waiting this long for a message (doubles up to 0.4 s).")
      .min(0.001).max(1.0);
}

void declare_nodes(config::Section& root) {
  auto& dem = root.section("dem", "The DEM node. Absent: no DEM process is started.", config::Presence::Optional);
  dem.string("executable", std::string("dem_node"),
             "Program that plays the DEM role (name in the build's bin/ folder, or a path).");
  auto& cont = root.section("continuum", "The continuum node (FDM by default). Absent: none is started.",
                            config::Presence::Optional);
  cont.string("executable", std::string("fdm_node"),
              "Program that plays the continuum role: fdm_node, or any solver that speaks the protocol.");
  auto& cpl = root.section("coupling",
                           "DEM-continuum interface exchange. Absent: the nodes never exchange interface data.",
                           config::Presence::Optional);
  cpl.choice("scheme", {"serial", "parallel"}, std::string("serial"),
             "serial: the continuum integrates step k with the DEM forces of step k (no lag); parallel: both "
             "nodes compute step k at once from each other's step k-1 data (one-step lag, both cores busy).");
  cpl.integer("interval", "-", 1, "DEM steps per coupling step (exchange every n DEM steps).").min(1).max(100000);
  cpl.integer("window", "-", 4,
              "Grants the coordinator keeps outstanding in coupled stages: the nodes are then paced by their "
              "interface data alone. 1 = strict grant-report lockstep. Results do not depend on it; an "
              "until = \"done\" stage ends window-1 steps after its criterion is met.")
      .min(1).max(64);
}

void declare_gravity(config::Section& root) {
  auto& g = root.section("gravity",
                         "Self-weight at N g (the centrifuge's g-level) for every node. Absent: no gravity, "
                         "and no cost for it.",
                         config::Presence::Optional);
  g.real("level", "-", 1.0, "g-level N: gravity is (0, 0, -N g0).").min(0.0).max(10000.0);
  g.real("g0", "m/s^2", 9.81, "Standard gravity g0.").min(0.0, true);
}

void declare_continuum(config::Section& root) {
  auto& c = *root.find("continuum")->section;
  c.choice("mode", {"dynamic", "static"}, std::string("dynamic"),
           "FDM law of motion: dynamic = real masses and the critical time step (physics.md 6.6 option A); "
           "static = mass-scaled, dt = 1 (option B, pseudo-static only).");
  c.real("damping", "-", 0.8, "FDM local damping alpha_F (physics.md 5.6).").min(0.0).max(1.0, true);
  c.boolean("large_strain", false, "Recompute zone geometry every step with the Jaumann rate (physics.md 5.8).");
  c.choice("averaging", {"overlay", "zone"}, std::string("overlay"),
           "Mixed-discretisation volumetric averaging over each 5-tetrahedron overlay (default) or all 10 "
           "tetrahedra of a zone (physics.md 5.3, U15).");
  c.real("timestep_safety", "-", 0.5, "FDM time step = safety * min tetrahedron height / P-wave speed (5.7).")
      .min(0.0, true).max(1.0);
  c.real("static_mass_factor", "-", 1.0, "Multiplier on the static-mode inertial masses (5.6).").min(1.0);
  c.choice("boundary", {"strongbox", "none"}, std::string("strongbox"),
           "strongbox: fixed base, rollers on the four sides, free top (physics.md 5.10); none: all free.");
  auto& m = c.section("mesh", "FDM mesh: a box of hexahedra around the DEM pocket (physics.md 5.1).",
                      config::Presence::Optional);
  m.reals("size", "m", std::vector<double>{16e-3, 16e-3, 16e-3}, "Box L x W x H.").length(3).min(0.0, true);
  m.boolean("pocket", true, "Leave the inner box open for the DEM block (its faces are the coupling interface).");
  m.reals("inner_size", "m", std::vector<double>{4e-3, 4e-3, 10e-3},
          "Inner box L_D x W_D x H_D (the pocket, or a refined block when pocket = false); [0,0,0]: none.")
      .length(3).min(0.0);
  m.reals("inner_origin", "m", std::vector<double>{},
          "Minimum corner of the inner box; empty: centred in x and y, top flush with the surface.");
  m.real("size_near", "m", 0.5e-3, "Zone size in and next to the inner box.").min(0.0, true);
  m.real("size_far", "m", 2e-3, "Largest zone size towards the outer boundary.").min(0.0, true);
  m.real("growth", "-", 1.2, "Zone-to-zone size ratio away from the inner box.").min(1.0).max(2.0);
  auto& mat = c.array("material",
                      "Zone groups, applied in order (a later group overrides an earlier one where regions "
                      "overlap). Absent: one elastic group with the defaults below.",
                      config::Presence::Optional);
  mat.choice("model", {"elastic", "mohr_coulomb"}, std::string("elastic"),
             "Constitutive model (physics.md 5.4).");
  mat.real("density", "kg/m^3", 1272.0, "Bulk density rho_b = (1-n) rho_s (physics.md 7.4).").min(0.0, true);
  mat.real("young", "Pa", 2.0e9, "Young's modulus E (calibrate from the DEM UCS test).").min(0.0, true);
  mat.real("poisson", "-", 0.25, "Poisson's ratio.").min(-1.0, true).max(0.5, true);
  mat.real("cohesion", "Pa", 0.0, "Mohr-Coulomb cohesion c.").min(0.0);
  mat.real("friction_deg", "deg", 30.0, "Mohr-Coulomb friction angle.").min(0.0).max(90.0, true);
  mat.real("dilation_deg", "deg", 0.0, "Mohr-Coulomb dilation angle (<= friction).").min(0.0).max(90.0, true);
  mat.real("tension", "Pa", -1.0, "Tension cut-off (tension positive); negative: the apex value c/tan(phi).");
  mat.reals("region_lo", "m", std::vector<double>{}, "Minimum corner of the group's box; empty: every zone.");
  mat.reals("region_hi", "m", std::vector<double>{}, "Maximum corner of the group's box; empty: every zone.");
  auto& punch = c.section("punch",
                          "A rigid circular punch on the FDM top surface (verification without DEM): the top "
                          "gridpoints within the radius move down at a prescribed speed; the reaction is "
                          "reported. Absent: none.",
                          config::Presence::Optional);
  punch.real("radius", "m", std::nullopt, "Punch radius a.").min(0.0, true);
  punch.real("velocity", "m/s", std::nullopt, "Downward speed (dynamic mode) or displacement per step (static).")
      .min(0.0);
  punch.reals("centre", "m", std::vector<double>{}, "Centre [x, y]; empty: the centre of the top face.");
  auto& out = c.section("output", "Continuum results (fdm.h5 + mesh.xmf, fdm_history.csv).",
                        config::Presence::Optional);
  out.integer("frame_every", "steps", 0, "HDF5 frame every n coupling steps; 0: only at the end of each stage.")
      .min(0);
  out.integer("history_every", "steps", 1, "fdm_history.csv row every n coupling steps; 0: none.").min(0);
}

void declare_output(config::Section& root) {
  auto& out = root.section("output", "What a run writes to its run folder.", config::Presence::Optional);
  out.boolean("traffic_log", true, "Record the bus traffic with lcm-logger (traffic.lcmlog).");
  out.strings("traffic_channels", std::vector<std::string>{},
              "Channels to record (regular expressions); empty: all channels.");
}

void declare_chain(config::Section& root) {
  auto& ch = root.section("chain",
                          "Protocol test problem: a 1-D chain of masses and springs whose first 'split' masses "
                          "live in the DEM-role process and the rest in the continuum-role process.",
                          config::Presence::Optional);
  ch.integer("n_masses", "-", 20, "Number of masses.").min(2).max(100000);
  ch.integer("split", "-", 10, "Masses 0..split-1 belong to the DEM side; mass 'split' is the interface point.")
      .min(1);
  ch.real("mass", "kg", 1.0, "Mass of each point.").min(0.0, true);
  ch.real("stiffness", "N/m", 100.0, "Stiffness of each spring.").min(0.0, true);
  ch.real("dt", "s", 0.01, "Time step (stable below 2*sqrt(m/k)/2 for a chain).").min(0.0, true);
  ch.real("v0", "m/s", 1.0, "Initial velocity of mass 0 (the others start at rest).");
  ch.integer("record_every", "-", 1, "Write the displacement history every this many steps.").min(1);
}

void declare_stages(config::Section& root) {
  auto& st = root.array("stage", "The run's stages, in order (staged initialisation, loading).",
                        config::Presence::Required);
  st.string("name", std::nullopt, "Stage name (logs, summary).");
  st.choice("action", {"cycle", "equilibrium", "geostatic"}, std::string("cycle"),
            "What the nodes do in this stage. cycle: step the models as they are; equilibrium: step until the "
            "unbalanced-force ratio is below 'ratio' (use until = \"done\"); geostatic: assign the initial "
            "stresses sigma_v = rho N g depth, sigma_h = K0 sigma_v (continuum), then as equilibrium.");
  st.real("ratio", "-", 1e-5, "Equilibrium criterion: unbalanced-force ratio (FLAC3D ratio-average, physics.md 5.11).")
      .min(0.0, true);
  st.real("k0", "-", -1.0, "K0 for 'geostatic'; negative: nu/(1-nu) of each zone's material.");
  st.boolean("reset_displacements", false, "Set continuum displacements to zero at the stage's start.");
  st.strings("nodes", std::vector<std::string>{}, "Roles taking part ('dem', 'continuum'); empty: all of the scene's.");
  st.integer("steps", "-", std::nullopt, "Step budget in coupling steps.").min(1);
  st.choice("until", {"steps", "done"}, std::string("steps"),
            "steps: run exactly 'steps'; done: stop when every node reports its exit criterion met.");
  st.choice("on_budget", {"fail", "continue"}, std::string("fail"),
            "With until = done: what to do when the budget runs out first.");
  st.boolean("coupled", false, "Exchange interface data every coupling step (needs [coupling]).");
  st.integer("steps_per_grant", "-", 1,
             "Coupling steps granted per command (uncoupled stages may take large blocks).").min(1);
}

config::Schema build() {
  config::Schema s;
  auto& root = s.root();
  declare_run(root);
  declare_bus(root);
  declare_nodes(root);
  declare_gravity(root);
  declare_continuum(root);
  declare_output(root);
  declare_chain(root);
  declare_stages(root);

  s.check([](const config::Scene& sc, config::CheckContext& ctx) {
    if (!sc.has("dem") && !sc.has("continuum"))
      ctx.fail("dem", "a [dem] or a [continuum] section (a scene needs at least one node)", "neither");
    if (sc.has("coupling") && !(sc.has("dem") && sc.has("continuum")))
      ctx.fail("coupling", "both [dem] and [continuum] sections (coupling joins the two)",
               sc.has("dem") ? "no [continuum]" : "no [dem]");
    if (sc.has("chain")) {
      auto n = sc.integer("chain.n_masses"), sp = sc.integer("chain.split");
      if (sp >= n)
        ctx.fail("chain.split", "an integer in [1, n_masses-1] = [1, " + std::to_string(n - 1) + "]",
                 std::to_string(sp));
    }
    auto present = roles(sc);
    for (std::size_t i = 0; i < sc.count("stage"); ++i) {
      auto e = sc.at("stage", i);
      std::string p = "stage[" + std::to_string(i) + "]";
      auto nodes = e.strings("nodes");
      for (std::size_t j = 0; j < nodes.size(); ++j)
        if (std::find(present.begin(), present.end(), nodes[j]) == present.end()) {
          std::string have;
          for (auto& r : present) have += (have.empty() ? "'" : ", '") + r + "'";
          ctx.fail(p + ".nodes", "roles present in the scene (" + have + ")", "'" + nodes[j] + "'");
        }
      if (e.boolean("coupled")) {
        if (!sc.has("coupling")) ctx.fail(p + ".coupled", "a [coupling] section for a coupled stage", "none");
        if (!nodes.empty() && nodes.size() != 2)
          ctx.fail(p + ".nodes", "both 'dem' and 'continuum' in a coupled stage", std::to_string(nodes.size()) + " role(s)");
      }
    }
  });
  return s;
}
}  // namespace

const config::Schema& scene_schema() {
  static const config::Schema s = build();
  return s;
}

std::vector<std::string> roles(const config::Scene& s) {
  std::vector<std::string> r;
  if (s.has("dem")) r.push_back("dem");
  if (s.has("continuum")) r.push_back("continuum");
  return r;
}

std::string executable(const config::Scene& s, const std::string& role) {
  return s.string(role + ".executable");
}

std::vector<Stage> stages(const config::Scene& s) {
  std::vector<Stage> out;
  auto all = roles(s);
  for (std::size_t i = 0; i < s.count("stage"); ++i) {
    auto e = s.at("stage", i);
    Stage st;
    st.name = e.string("name");
    st.action = e.string("action");
    st.nodes = e.strings("nodes");
    if (st.nodes.empty()) st.nodes = all;
    st.steps = e.integer("steps");
    st.until_done = e.string("until") == "done";
    st.fail_on_budget = e.string("on_budget") == "fail";
    st.coupled = e.boolean("coupled");
    st.steps_per_grant = st.coupled ? 1 : e.integer("steps_per_grant");
    st.view = e;
    out.push_back(std::move(st));
  }
  return out;
}

}  // namespace demfdm::schema
