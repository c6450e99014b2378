#include "common/schema/scene_schema.hpp"

#include "demfdm/dem/balance_cost.hpp"
#include "demfdm/dem/laws/registry.hpp"
#include "demfdm/dem/params.hpp"
#include "demfdm/dem/specimen.hpp"
#include "demfdm/dem/world.hpp"
#include "demfdm/fdm/params.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <map>
#include <sstream>

#include <sched.h>
#include <unistd.h>

namespace demfdm::schema {

int run_threads(const config::Scene& s) {
  if (auto n = s.integer_or_word("run.threads")) return static_cast<int>(*n);
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0) return std::max(1, CPU_COUNT(&set));
  return std::max(1L, sysconf(_SC_NPROCESSORS_ONLN));
}

namespace {

// Declares the keys of a parameter table (demfdm/param_table.hpp: the describe() tables beside
// the engines' structs) in a schema section: unit, range, doc, and as default the field's
// initial value.
struct SchemaDecl {
  config::Section& sec;
  static void bounds(config::ParamBuilder b, const ParamRange& r) {
    if (r.has_lo()) b.min(r.lo, r.lo_open);
    if (r.has_hi()) b.max(r.hi, r.hi_open);
  }
  void real(const char* key, const char* unit, double& field, const ParamRange& r, const char* doc) {
    bounds(sec.real(key, unit, field, doc), r);
  }
  // A field holding word_value makes the word the default ("auto").
  void real_or_word(const char* key, const char* unit, double& field, const ParamRange& r, const char* word,
                    double word_value, const char* doc) {
    const bool word_default = field == word_value || (std::isnan(field) && std::isnan(word_value));
    auto b = sec.real(key, unit, word_default ? std::nullopt : std::optional<double>(field), doc);
    bounds(b, r);
    b.or_word(word, word_default);
  }
  void flag(const char* key, bool& field, const char* doc) { sec.boolean(key, field, doc); }
  template <class I>
  void integer(const char* key, const char* unit, I& field, std::int64_t lo, std::int64_t hi, const char* doc) {
    sec.integer(key, unit, static_cast<std::int64_t>(field), doc).min(static_cast<double>(lo)).max(static_cast<double>(hi));
  }
  template <class E>
  void choice(const char* key, E& field, std::initializer_list<ParamOption<E>> options, const char* doc) {
    std::vector<std::string> names;
    std::string def;
    for (const auto& o : options) {
      names.emplace_back(o.name);
      if (o.value == field) def = o.name;
    }
    sec.choice(key, names, def, doc);
  }
};

void declare_run(config::Section& root) {
  auto& run = root.section("run", "Run identity and process settings.", config::Presence::Optional);
  run.string("name", std::string("run"), "Short name used in the run folder name.");
  run.string("description", std::string(""), "Free text copied into the run summary.");
  run.integer("seed", "-", 1, "Seed of every random generator (same scene + same seed + same threads = same results).").min(0);
  run.integer("threads", "-", 1,
              "OpenMP threads per node. \"auto\": every CPU the node's process may run on (with the serial "
              "coupling scheme the nodes take turns, so each can use them all; the run summary reports the cores "
              "each node kept busy). The same bits need the same count, unless run.thread_independent is on.")
      .min(1).max(256).or_word("auto", false);
  run.boolean("order_free_sums", false,
              "The DEM's per-step measurements (kinetic energy, unbalanced and skeleton ratios, mean contact "
              "force), the walls' sums, the REV servo's sums and the cell stress as order-free sums: every term "
              "split against fixed power-of-two boundaries into parts that add "
              "exactly in any order (docs/scaling.md), so the ranks of dem.ranks fold their own terms and combine "
              "them in two allreduces instead of gathering every term on rank 0 each step. The same bits at any "
              "thread and rank count; they differ from the default sums in the last bits (about 1e-16 relative), "
              "so off by default (the golden data).");
  run.boolean("thread_independent", false,
              "Every thread count gives the same bits: the DEM's threaded ball-ball pass keeps the one-thread order "
              "of every ball's sums (docs/scaling.md; the continuum is independent of the count already). It costs "
              "2-8 % of the pair pass in bench_dem at 2 threads; on the default scene the cost was not resolved "
              "within this machine's scatter (up to 20 % in some windows), so it is off by default. The tests "
              "turn it on.");
  run.integer("guard_every", "steps", 1,
              "Blow-up guard (docs/stability.md): every node scans its state for non-finite values and energy "
              "jumps after every n-th coupling step and stops the run at the first finding, writing "
              "blowup_<role>.txt (0: off).")
      .min(0);
  run.real("guard_energy_jump", "-", 1000.0,
           "Guard: stop when a node's kinetic energy exceeds this factor times the larger of guard_energy_floor "
           "and the largest value of its previous guard_energy_window checks (0: no energy test).")
      .min(0.0);
  run.real("guard_energy_floor", "J", 1e-6,
           "Guard: smallest reference energy of the jump test, so that a start from rest does not trip it.")
      .min(0.0);
  run.integer("guard_energy_window", "checks", 100, "Guard: number of previous checks the jump test looks back on.")
      .min(1);
  run.boolean("checkpoint_stage_end", true,
              "Checkpoint (docs/checkpoint-format.md) after every stage: every node saves its whole state into "
              "checkpoints/<stage>-<step>-end/ of the run folder, the state a resume or a branch (launch/run --from) "
              "starts from.");
  run.real("checkpoint_every_s", "s", 600.0,
           "Inside a stage, a checkpoint checkpoints/<stage>-<step>/ at the first step boundary after this much wall "
           "time since the last one (0: none inside stages). Where checkpoints fall changes no result.")
      .min(0.0);
  run.integer("checkpoint_keep", "-", 2,
              "Checkpoints inside stages kept in the run folder (the older ones are deleted once a newer one is "
              "complete; stage-end checkpoints are all kept).")
      .min(1);
}

void declare_bus(config::Section& root) {
  auto& bus = root.section("bus", "Message bus timing (messages/README.md).", config::Presence::Optional);
  bus.real("heartbeat_s", "s", 0.25, "Heartbeat period of every process.").min(0.01).max(2.0);
  bus.real("peer_timeout_s", "s", 3.0,
           "Silence after which a process is declared dead or hung (detection within this + one heartbeat). Silence "
           "counts only while the watching process runs: a stall of its own (SIGSTOP, a debugger, a paused VM or "
           "host) re-arms the timers; a node process on the same host that is gone is named at once.")
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
  {  // the keys of fdm::ModelParams, declared beside it (fdm_node/core params.hpp)
    fdm::ModelParams defaults;
    SchemaDecl model_keys{c};
    fdm::describe(model_keys, defaults);
  }
  c.choice("linear_solver", {"auto", "cholmod", "ldlt"}, std::string("auto"),
           "fem_node only (fdm_node ignores it): sparse direct solver for the stiffness matrix, factorised once. "
           "cholmod = CHOLMOD supernodal Cholesky (fast on large meshes); ldlt = Eigen SimplicialLDLT (no "
           "extra library, slow beyond ~10^4 dofs); auto = cholmod when the build has it, else ldlt. Same "
           "answer to round-off (docs/continuum-solvers.md).");
  c.real("relaxation", "-", 0.0,
         "fem_node only (fdm_node ignores it): under-relaxation factor omega of the static continuum's coupling "
         "update, u_k = u_(k-1) + omega (u_static - u_(k-1)); 1 = unrelaxed (diverges against stiff DEM contacts: "
         "the node warns when omega exceeds the stability limit it estimates). 0 = automatic: the DEM's interface "
         "stiffness k is added as springs D to the stiffness, (K + D) u_k = f + D u_(k-1), contractive for k <= 2 D; "
         "the static answer in one step when the DEM reports no stiffness. Both converge to the same static answer "
         "(docs/continuum-solvers.md).")
      .min(0.0).max(1.0);
  c.choice("boundary", {"strongbox", "symmetry", "none"}, std::string("strongbox"),
           "strongbox: fixed base, rollers on the four sides, free top (docs/theory.md 5.10); symmetry: rollers on "
           "the x = 0, y = 0 and z = 0 planes only (element tests: a quarter of a triaxial specimen); none: all free.");
  c.real("confining", "Pa", 0.0,
         "Confining pressure on the x = L and y = W faces (with boundary = \"symmetry\"), also set as the initial "
         "hydrostatic stress; 0: none.").min(0.0);
  auto& m = c.section("mesh", "FDM mesh: a box of hexahedra around the DEM pocket (docs/theory.md 5.1).",
                      config::Presence::Optional);
  {  // lists here (defaults from fdm::MeshParams), the other keys beside it (fdm_node/core mesh.hpp)
    fdm::MeshParams defaults;
    m.reals("size", "m", std::vector<double>{defaults.length, defaults.width, defaults.height}, "Box L x W x H.")
        .length(3)
        .min(0.0, true);
    m.reals("inner_size", "m", std::vector<double>(defaults.inner_size.begin(), defaults.inner_size.end()),
            "Inner box L_D x W_D x H_D (the pocket, or a refined block when pocket = false); [0,0,0]: none.")
        .length(3)
        .min(0.0);
    m.reals("inner_origin", "m", std::vector<double>{},
            "Minimum corner of the inner box; empty: centred in x and y, top flush with the surface.");
    SchemaDecl mesh_keys{m};
    fdm::describe(mesh_keys, defaults);
  }
  auto& mat = c.array("material",
                      "Zone groups, applied in order (a later group overrides an earlier one where regions "
                      "overlap). Absent: one elastic group with the defaults below.",
                      config::Presence::Optional);
  {  // the keys of fdm::Material, declared beside it (fdm_node/core params.hpp)
    fdm::Material defaults;
    SchemaDecl material_keys{mat};
    fdm::describe(material_keys, defaults);
  }
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
  punch.boolean("rough", true, "Rough punch (all velocity components fixed) or smooth platen (vertical only).");
  punch.real("release_after", "s", 0.0,
             "Free the punch's vertical velocity after this time (a pulse, e.g. for wave-speed checks); 0: never.")
      .min(0.0);
  auto& out = c.section("output", "Continuum results (fdm.h5 or fem.h5 + mesh.xmf, fdm_history.csv or fem_history.csv, fdm_profile_<stage>.csv). "
                        "Without this table the continuum writes no result files.",
                        config::Presence::Optional);
  out.integer("frame_every", "steps", 0, "HDF5 frame every n coupling steps; 0: only at the end of each stage.")
      .min(0);
  out.integer("history_every", "steps", 1, "fdm_history.csv row every n coupling steps; 0: none.").min(0);
}

// Records a law key's earlier prefixed name (sb_ten, pb_ten, hz_shear) as moved to its table.
struct MovedKeys {
  config::Section& fam;
  std::string prefix, table;
  void add(const char* key) { fam.moved(prefix + key, std::string("write [") + fam.path() + "." + table + "] " + key); }
  void real(const char* key, const char*, double&, const ParamRange&, const char*) { add(key); }
  void real_or_word(const char* key, const char*, double&, const ParamRange&, const char*, double, const char*) {
    add(key);
  }
  void flag(const char* key, bool&, const char*) { add(key); }
  template <class E>
  void choice(const char* key, E&, std::initializer_list<ParamOption<E>>, const char*) { add(key); }
};

// A contact family [dem.<name>]: its law (the registry's names), its family-wide keys, and one
// table per law with keys of its own, [dem.<name>.<law>]. The keys of the prefixed form of
// earlier versions (sb_ten, pb_ten, hz_shear, ...) are refused with the new place.
void declare_family(config::Section& dem_sec, const dem::FamilyInfo& info) {
  auto& f = dem_sec.section(info.name, info.doc, config::Presence::Defaults);
  dem::ContactFamilyParams defaults = info.defaults();
  std::vector<std::string> names;
  std::string doc = "Contact law (one of the registered laws, dem_node/core laws/registry.hpp):";
  dem::for_each_law([&](auto law) {
    names.emplace_back(decltype(law)::kName);
    doc += std::string(names.size() > 1 ? ";" : "") + " " + decltype(law)::kName + " = " + decltype(law)::kTitle;
  });
  f.choice("model", names, std::string(dem::law_name(info.model)), doc + ".");
  SchemaDecl family_keys{f};
  dem::describe_family(family_keys, defaults);
  dem::for_each_law([&](auto law) {
    using Law = decltype(law);
    if constexpr (Law::kHasParams) {
      auto& t = f.section(Law::kName,
                          std::string("Keys of the ") + Law::kName + " law (" + Law::kTitle + "), read when model = \"" +
                              Law::kName + "\"; in a family of another law a value other than the default is refused.",
                          config::Presence::Defaults);
      SchemaDecl law_keys{t};
      Law::params(law_keys, defaults);
      // Earlier versions wrote the keys of these three laws in the family table with a prefix.
      const std::string name = Law::kName;
      const std::string prefix = name == "pbond" ? "pb_" : name == "softbond" ? "sb_" : name == "hertz" ? "hz_" : "";
      if (!prefix.empty()) {
        MovedKeys moved{f, prefix, Law::kName};
        Law::params(moved, defaults);
      }
    }
  });
}

void declare_dem(config::Section& root) {
  auto& d = *root.find("dem")->section;
  {  // the world's keys, declared beside WorldParams (dem_node/core params.hpp)
    dem::WorldParams defaults;
    SchemaDecl world_keys{d};
    dem::describe(world_keys, defaults);
  }
  d.choice("dt_above_critical", {"error", "reduce"}, std::string("error"),
           "A dt_fixed above the critical step (1.8, without dt_safety) at a stage begin: error stops the run "
           "naming both values; reduce uses dt_safety x critical instead, with a warning (docs/stability.md).");
  d.real("escape_margin", "-", 5.0,
         "A ball whose centre leaves the DEM block (or the continuum's pocket) by more than this many d_max "
         "(upscaled) stops the run with an error naming it (docs/stability.md); 0: no check.")
      .min(0.0);
  d.integer("ranks", "-", 1,
            "MPI ranks of the DEM (docs/scaling.md): launch/run starts dem_node under mpirun with this many, "
            "each stepping one brick of the DEM block (dem.decomposition). The ranks sum in the one-thread "
            "order: the results are one process's bits at any rank count when run.thread_independent is on "
            "or run.threads = 1. run.threads = \"auto\" shares a host's CPUs among its ranks. 1: one "
            "process, no MPI.")
      .min(1)
      .max(4096);
  d.choice("decomposition", {"rcb", "slabs"}, std::string("rcb"),
           "With dem.ranks > 1, how the DEM block is cut into the ranks' bricks (docs/scaling.md): rcb, "
           "recursive coordinate bisection (the block halved across its longest side, each half again, "
           "until one brick per rank: compact bricks at any rank count, LAMMPS's balance rcb); slabs, "
           "slabs across the block's longest side. The same bits either way.");
  d.integer("balance_every", "-", 1,
            "With dem.ranks > 1: move the cuts between the ranks' bricks every this many neighbour-list "
            "rebuilds so that the bricks carry equal weight (rcb: every cut of the tree, LAMMPS's balance "
            "rcb; slabs: LAMMPS's fix balance shift; docs/scaling.md); the first cut, at a stage's start, "
            "is balanced by contacts. Balancing moves balls between ranks, never a bit of the results. "
            "0: the geometric cuts (on the default scene's penetration at 2 ranks, a time imbalance of "
            "1.14 against 1.013 balanced by contacts; session 29).")
      .min(0);
  d.choice("balance_weight", {"auto", "contacts", "time"}, std::string("auto"),
           "What dem.balance_every weighs: a ball's modelled cost per step from its contacts (contacts: "
           "the ball itself, half of each listed pair by what the pass does with it, a bond, a contact "
           "that touches or a pair apart, and its wall contacts, a facet contact weighing about five "
           "bonded pairs; costs fitted to the default scene's penetration, docs/scaling.md), or its "
           "rank's measured compute time shared by the rank's balls (time, LAMMPS's weight time; the "
           "cuts then differ from run to run, the results do not, unless dem.newton is on: refused "
           "with it). auto: time, and contacts with dem.newton on. On the default scene's penetration "
           "at 2 ranks, cuts balanced by contacts leave a time imbalance of 1.013 (s.e. 0.002; the "
           "ranks' compute ratio 1.000, s.e. 0.005; session 29).");
  {
    const dem::ContactCost c;
    d.integers("balance_costs", "ns",
               std::vector<std::int64_t>{c.ball, c.bonded_end, c.touching_end, c.apart_end, c.facet, c.plane},
               "What dem.balance_weight = contacts charges a ball per step, in ns of one core: [the ball, each "
               "end of a bonded pair, of an unbonded pair that touches, of a pair listed apart, each facet "
               "contact, each plane or footing contact]; the ball's at least 1. The defaults were fitted to "
               "the default scene's penetration (soft bond law) on an AVX2 core; bench/dem/fit_costs.py fits "
               "them to a run's own checkpoint on the machine at hand (docs/scaling.md, session 29).")
        .length(6)
        .min(0);
  }
  d.boolean("newton", false,
            "With dem.ranks > 1 (LAMMPS's newton on; docs/scaling.md): a ball-ball pair across two ranks' "
            "bricks is computed once, on the rank of its lower-id ball, and its force on the other ball is "
            "sent back to that ball's rank after the pass. Saves the second computation of every such "
            "pair; the results then depend on the rank count (within round-off at first, which the "
            "dynamics amplify). false: each such pair computed on both ranks, one process's bits at any "
            "rank count.");
  d.boolean("spatial_order", false,
            "Renumber the balls' rows along a space-filling (Morton) curve of cells 2 R_max wide once the "
            "replicate stage has built the block (LAMMPS's atom_modify sort, done once), so that a contact's "
            "two balls lie near each other in memory: the default scene's ball-ball pass took 0.70-0.77 of "
            "its time at one thread on its gravity-end state (docs/speed.md, session 36). The forces are "
            "then summed in another order: the results differ from the run without it within round-off at "
            "first, which the dynamics amplify, as with another thread count. false: the rows stay in the "
            "order the copies were made (copy by copy). Not with dem.ranks > 1.");
  d.reals("kick", "m/s", std::vector<double>{},
          "Stability studies: velocity [vx, vy, vz] given to the highest ball at the first stage that is not "
          "a specimen-generation stage; empty: none.");
  for (const auto& fam : dem::kFamilies) declare_family(d, fam);
  auto& sp = d.section("specimen", "Specimen generation (docs/theory.md 0.4, 4).", config::Presence::Optional);
  {  // the REV generation's keys, declared beside RevParams (dem_node/core specimen.hpp)
    dem::RevParams defaults = dem::scene_rev_defaults();
    SchemaDecl rev_keys{sp};
    dem::describe(rev_keys, defaults);
  }
  sp.real("d50", "m", 0.116e-3, "d50 quoted by the paper (inertial-number rate rule).").min(0.0, true);
  sp.reals("cell", "m", std::vector<double>{4e-3, 4e-3, 2e-3}, "REV periodic cell L_c x W_c x H_c.").length(3).min(0.0, true);
  sp.reals("origin", "m", std::vector<double>{},
           "Minimum corner of the REV (and of the replicated block); empty: the continuum's pocket if there is "
           "a [continuum], else [0, 0, 0].");
  sp.real("bond_coordination", "-", std::nullopt,
          "generate: after the expansion, bond every pair up to the gap that gives this bonded coordination "
          "number (Table 1: 6.82; docs/ucs-study.md); \"none\": no bonding in 'generate'.")
      .min(0.0, true)
      .or_word("none", true);
  sp.real("dt_safety", "-", 0.8,
          "Time step of specimen preparation (the generate, servo, bond and replicate stages) = this * critical "
          "step (1.8); dem.dt_safety applies from the first later stage. Preparation counts its rules in critical "
          "steps t_c, so this factor sets how finely the same procedure is integrated (docs/theory.md 4.11).")
      .min(0.0, true)
      .max(1.0);
  sp.real("damping", "-", 0.7,
          "Local damping alpha of specimen preparation (a preparation stage's own 'damping' wins); dem.damping "
          "applies from the first later stage.")
      .min(0.0)
      .max(1.0, true);
  sp.real("k0", "-", 0.5, "sigma_h / sigma_v of the REV servo (U7).").min(0.0);
  sp.real("sigma_v", "Pa", std::nullopt,
          "REV vertical stress (compression positive); \"auto\": rho_b N g0 H_D, the self-weight stress at the DEM "
          "block's bottom (docs/theory.md 4.5), with rho_b = (1 - 0.52) rho_s unless bulk_density is set.")
      .min(0.0, true)
      .or_word("auto", true);
  sp.real("bulk_density", "kg/m^3", std::nullopt, "Bulk density for sigma_v; \"auto\": 0.48 rho_s.")
      .min(0.0, true)
      .or_word("auto", true);
  {  // the REV servo's keys, declared beside ServoSettings (dem_node/core specimen.hpp)
    dem::ServoSettings defaults;
    SchemaDecl servo_keys{sp};
    dem::describe(servo_keys, defaults);
  }
  sp.real("bond_gap", "m", std::nullopt, "bond stage: bond contacts with gap <= this; \"auto\": 1e-3 d_min (4.6).")
      .or_word("auto", true);
  sp.integers("replicate", "-", std::vector<std::int64_t>{1, 1, 5}, "Copies alpha x beta x gamma (4.7).")
      .length(3).min(1);
  sp.choice("box", {"none", "walls"}, std::string("none"),
            "DEM-only model of a block (no continuum): walls places frictional planes (family ball_wall) on the "
            "bottom and the four sides of the replicated block at the first stage that is not a generation stage, "
            "and scales the forces with depth there (depth_scaling), as the coupled interface set-up does; the "
            "reference of the accuracy study's coupled-versus-DEM-only knob (docs/accuracy-study.md).");
  sp.choice("depth_scaling", {"depth_ratio", "paper_literal", "none"}, std::string("depth_ratio"),
            "Scaling of contact and bond forces with depth (4.9, U7): depth_ratio (default) f = depth/H_D; "
            "paper_literal f = height above the block bottom / H_D; none.");
  {  // the couple stage's interface-bond forces, declared beside InterfaceBondParams (specimen.hpp)
    dem::InterfaceBondParams defaults;
    SchemaDecl bond_keys{sp};
    dem::describe(bond_keys, defaults);
  }
  auto& ft = d.section("footing", "Rigid cylindrical footing (paper: D_f 1.2 mm, H_f 0.6 mm). Absent: none.",
                       config::Presence::Optional);
  {  // the footing's shape, declared beside FootingParams (dem_node/core world.hpp)
    dem::FootingParams defaults;
    SchemaDecl footing_keys{ft};
    dem::describe(footing_keys, defaults);
  }
  ft.reals("centre", "m", std::vector<double>{}, "Axis position [x, y]; empty: the centre of the DEM block.");
  auto& o = d.section("output", "DEM results (dem.h5 + particles.xmf + bonds.xmf, dem_history.csv, dem_profile_<stage>.csv). "
                      "Without this table the DEM writes no result files.",
                      config::Presence::Optional);
  o.integer("frame_every", "steps", 0, "HDF5 frame every n coupling steps; 0: only at the end of each stage.").min(0);
  o.integer("history_every", "steps", 1, "dem_history.csv row every n coupling steps; 0: none.").min(0);
}

void declare_output(config::Section& root) {
  auto& out = root.section("output", "What a run writes to its run folder.", config::Presence::Optional);
  out.boolean("traffic_log", true,
              "Record the bus traffic (traffic.lcmlog: every process's own publications, merged; lossless).");
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
  std::vector<std::string> names;
  std::string doc = "What the nodes do in this stage (docs/stages.md; [d] the DEM acts, [c] a continuum acts).";
  for (const auto& a : actions()) {
    names.emplace_back(a.name);
    doc += std::string(" ") + a.name + " [" + (a.dem ? "d" : "") + (a.continuum ? "c" : "") + "]: " + a.doc;
  }
  st.choice("action", names, std::string("cycle"), doc);
  st.real("ratio", "-", 1e-5, "Equilibrium criterion: unbalanced-force ratio (FLAC3D ratio-average, docs/theory.md 5.11).")
      .min(0.0, true);
  st.real("k0", "-", std::nullopt, "K0 for 'geostatic' and 'couple'; \"auto\": nu/(1-nu) of each zone's material.")
      .min(0.0)
      .or_word("auto", true);
  st.boolean("reset_displacements", false, "Set continuum displacements to zero at the stage's start.");
  st.real("inertial_number", "-", 1e-3,
          "penetrate: inertial number I of the footing rate (docs/theory.md 7.1); I >= 1 is no longer a granular "
          "flow regime.")
      .min(0.0, true)
      .max(1.0, true);
  st.real("plastic_zone_ratio", "-", 3.0, "penetrate: L_p / D_f in v = I L_p / (d50 sqrt(rho_s / P)).")
      .min(0.0, true)
      .max(100.0);
  st.real("mean_stress", "Pa", 1e6, "penetrate: mean stress P at the footing tip in the rate rule (U12).").min(0.0, true);
  st.real("depth_ratio", "-", 0.2, "penetrate: stop when the footing has moved this many D_f (paper: 0.2).")
      .min(0.0, true)
      .max(1.0);
  st.real("speed_factor", "-", 1.0, "penetrate: multiply the rate-rule speed (stability studies).")
      .min(0.0, true)
      .max(1000.0);
  st.real("ramp_depth_ratio", "-", 0.01,
          "penetrate: the footing speed rises linearly in time from 0 to the rate-rule speed v while the footing "
          "moves this many D_f (ramp time t_r = 2 ramp_depth_ratio D_f / v), so that it does not hit the block "
          "at first contact (docs/stages.md); 0: full speed from the first step.")
      .min(0.0)
      .max(1.0);
  st.real("quasi_static_limit", "-", 1.0,
          "penetrate: the largest impedance ratio rho_b c v / sigma_c (c the P-wave speed of the rock, sigma_c "
          "the ball-ball bond tensile strength) treated as quasi-static; the run summary warns above it "
          "(docs/stages.md). Default from the convergence study (docs/convergence.md): at penetration damping "
          "0.1 the seed-mean curve no longer changes beyond its scatter below a ratio of about 0.75 (I = 1e-3 on "
          "the reduced footing); at damping 0.7 it still changes at 0.25.")
      .min(0.0, true);
  st.real("rock_young", "Pa", 1.083e9,
          "penetrate: E of the rock for the wave measures when the scene has no continuum (with nu = 1/3); "
          "default: E50 of the UCS study, docs/ucs-study.md. With a continuum: the first "
          "[[continuum.material]]'s young and poisson.")
      .min(0.0, true);
  st.real("damping", "-", std::nullopt,
          "DEM local damping alpha in this stage (docs/theory.md 1.3: the penetration stage may use less than the "
          "0.7 of equilibration); \"auto\": dem.damping (dem.specimen.damping in preparation stages).")
      .min(0.0)
      .max(0.99)
      .or_word("auto", true);
  {  // the ucs stage's keys, declared beside UcsParams (dem_node/core specimen.hpp)
    dem::UcsParams defaults;
    SchemaDecl ucs_keys{st};
    dem::describe(ucs_keys, defaults);
  }
  st.strings("nodes", std::vector<std::string>{}, "Roles taking part ('dem', 'continuum'); empty: all of the scene's.");
  st.integer("steps", "-", std::nullopt,
             "Step budget in coupling steps (at most 1e12: a year of steps at 30 kHz; larger budgets would "
             "overflow the step counters).")
      .min(1)
      .max(1e12);
  st.choice("until", {"steps", "done"}, std::string("steps"),
            "steps: run exactly 'steps'; done: stop when every node reports its exit criterion met.");
  st.choice("on_budget", {"fail", "continue"}, std::string("fail"),
            "With until = done: what to do when the budget runs out first.");
  st.boolean("coupled", false, "Exchange interface data every coupling step (needs [coupling]).");
  st.integer("steps_per_grant", "-", 1,
             "Coupling steps granted per command. The nodes still report every step's values (one row per step), "
             "so larger blocks only cut bus traffic; an until = \"done\" stage then ends at a block boundary.")
      .min(1)
      .max(1000000);
}

// The row of an action name (nullptr for a name the schema does not admit).
const ActionInfo* action_named(std::string_view name) {
  for (const auto& a : actions())
    if (name == a.name) return &a;
  return nullptr;
}

std::string num(double v) {
  std::ostringstream o;
  o << std::setprecision(6) << v;
  return o.str();
}

// Refuses a key of a law table set to a value other than its default in a family of another
// law (the table has no effect there).
struct OtherLawKeys {
  const config::Scene& sc;
  config::CheckContext& ctx;
  std::string table, model;
  void refuse_if(bool differs, const char* key) {
    const std::string path = table + "." + key;
    if (differs && sc.explicitly_set(path))
      ctx.fail(path, "a key of the family's own law only (model = '" + model + "'; this table has no effect)",
               "it set while model = '" + model + "'");
  }
  void real(const char* key, const char*, double& def, const ParamRange&, const char*) {
    refuse_if(sc.real(table + "." + key) != def, key);
  }
  void real_or_word(const char* key, const char*, double& def, const ParamRange&, const char*, double, const char*) {
    refuse_if(sc.real_or_word(table + "." + key) != std::optional<double>(def), key);
  }
  void flag(const char* key, bool& def, const char*) { refuse_if(sc.boolean(table + "." + key) != def, key); }
  template <class E>
  void choice(const char* key, E& def, std::initializer_list<ParamOption<E>> options, const char*) {
    for (const auto& o : options)
      if (o.value == def) refuse_if(sc.string(table + "." + key) != o.name, key);
  }
};

// Cross-field checks of the DEM part (the ranges of single keys are declared with the keys).
void check_dem(const config::Scene& sc, config::CheckContext& ctx) {
  const double dmin = sc.real("dem.specimen.d_min"), dmax = sc.real("dem.specimen.d_max"),
               d50 = sc.real("dem.specimen.d50");
  if (!(dmin < dmax)) ctx.fail("dem.specimen.d_min", "a diameter < d_max = " + num(dmax) + " m", num(dmin) + " m");
  if (d50 < dmin || d50 > dmax)
    ctx.fail("dem.specimen.d50", "a diameter in [d_min, d_max] = [" + num(dmin) + ", " + num(dmax) + "] m",
             num(d50) + " m");
  const auto st = stages(sc);
  auto has_action = [&](const char* a) {
    return std::any_of(st.begin(), st.end(), [&](const Stage& x) { return x.action == a; });
  };
  for (const char* fam : {"ball_ball", "ball_wall", "ball_facet", "ball_footing"}) {
    const std::string f = std::string("dem.") + fam;
    if (sc.string(f + ".model") == "softbond" && !(sc.real(f + ".emod") > 0))
      ctx.fail(f + ".emod", "a modulus > 0 Pa for the soft bond (its only stiffness set)", num(sc.real(f + ".emod")) + " Pa");
  }
  // A law table of a family whose model is another law has no effect: refused when it sets a
  // value other than the default (the effective scene of a run writes every key).
  for (const auto& info : dem::kFamilies) {
    const std::string fam = std::string("dem.") + info.name;
    dem::ContactFamilyParams defaults = info.defaults();
    const std::string model = sc.string(fam + ".model");
    dem::for_each_law([&](auto law) {
      using Law = decltype(law);
      if constexpr (Law::kHasParams) {
        if (model == Law::kName) return;
        OtherLawKeys check{sc, ctx, fam + "." + Law::kName, model};
        Law::params(check, defaults);
      }
    });
  }
  const bool bonds = has_action("bond") || (has_action("generate") && sc.real_or_word("dem.specimen.bond_coordination"));
  // Laws with a bond (laws/registry.hpp, kBond).
  auto can_bond = [&](const std::string& key) {
    dem::ContactModel m;
    return dem::law_from_name(sc.string(key), m) && dem::law_has_bond(m);
  };
  if (bonds && !can_bond("dem.ball_ball.model"))
    ctx.fail("dem.ball_ball.model", "'pbond' or 'softbond' (the scene bonds the specimen: a bond stage, or "
             "dem.specimen.bond_coordination >= 0)", "'" + sc.string("dem.ball_ball.model") + "'");
  // newton on sums a ball's remote pairs after its local ones, so its results follow the cuts;
  // cuts that follow measured times differ from run to run (docs/scaling.md).
  if (sc.boolean("dem.newton") && sc.integer("dem.balance_every") > 0 && sc.string("dem.balance_weight") == "time")
    ctx.fail("dem.balance_weight",
             "\"contacts\" or \"auto\" with dem.newton = true (newton's results follow the cuts, and cuts "
             "balanced by measured time differ from run to run: two runs of the scene would differ)",
             "\"time\"");
  // The ranks build their parts of the block themselves (DistDem's replicate): no renumbering.
  if (sc.boolean("dem.spatial_order") && sc.integer("dem.ranks") > 1)
    ctx.fail("dem.spatial_order", "false with dem.ranks > 1 (the ranks build their own parts of the block)", "true");
  // A ball that weighs nothing leaves a brick of them without weight (the geometric cut).
  if (const std::int64_t ball = sc.has("dem") ? sc.integers("dem.balance_costs")[0] : 1; ball < 1)
    ctx.fail("dem.balance_costs", "a ball's cost (the first number) of at least 1 ns", std::to_string(ball));
  // The couple stage bonds the balls to the interface facets (docs/theory.md 2.6).
  if (has_action("couple") && !can_bond("dem.ball_facet.model"))
    ctx.fail("dem.ball_facet.model", "'pbond' or 'softbond' (a couple stage bonds the balls to the interface facets)",
             "'" + sc.string("dem.ball_facet.model") + "'");
  // A derived REV stress (sigma_v < 0: rho_b N g0 H_D) needs gravity.
  const double g = sc.has("gravity") ? sc.real("gravity.level") * sc.real("gravity.g0") : 0.0;
  if (has_action("servo") && !sc.real_or_word("dem.specimen.sigma_v") && !(g > 0))
    ctx.fail("dem.specimen.sigma_v",
             "a stress > 0 Pa: \"auto\" derives it from the self-weight rho_b N g0 H_D, and this scene's gravity is "
             "zero",
             std::string("\"auto\"") + (sc.has("gravity") ? " with gravity.level " + num(sc.real("gravity.level"))
                                                           : " without a [gravity] section"));
  const DemBlock b = dem_block(sc);
  if (!sc.has("dem.footing")) return;
  const auto c = sc.reals("dem.footing.centre");
  if (!c.empty() && c.size() != 2)
    ctx.fail("dem.footing.centre", "an empty list or [x, y] in m", std::to_string(c.size()) + " numbers");
  if (!has_action("penetrate")) return;
  // The footing's disc must lie inside the block's top face (the footing is placed on the
  // highest ball under its footprint; outside the block it would never touch it).
  const double d = sc.real("dem.footing.diameter");
  const double cx = c.empty() ? b.origin[0] + b.size(0) / 2 : c[0], cy = c.empty() ? b.origin[1] + b.size(1) / 2 : c[1];
  if (d > std::min(b.size(0), b.size(1)))
    ctx.fail("dem.footing.diameter",
             "a diameter <= the DEM block's top face, " + num(b.size(0)) + " x " + num(b.size(1)) + " m", num(d) + " m");
  const double r = d / 2;
  if (cx - r < b.origin[0] || cx + r > b.origin[0] + b.size(0) || cy - r < b.origin[1] || cy + r > b.origin[1] + b.size(1))
    ctx.fail(c.empty() ? "dem.footing.diameter" : "dem.footing.centre",
             "a footing disc inside the DEM block's top face x in [" + num(b.origin[0]) + ", " +
                 num(b.origin[0] + b.size(0)) + "], y in [" + num(b.origin[1]) + ", " + num(b.origin[1] + b.size(1)) + "] m",
             "a disc of diameter " + num(d) + " m centred at (" + num(cx) + ", " + num(cy) + ")");
}

// The continuum mesh: the inner box inside the outer box, zone sizes that fit them.
void check_mesh(const config::Scene& sc, config::CheckContext& ctx) {
  const auto size = sc.reals("continuum.mesh.size"), inner = sc.reals("continuum.mesh.inner_size");
  const auto io = sc.reals("continuum.mesh.inner_origin");
  if (!io.empty() && io.size() != 3)
    ctx.fail("continuum.mesh.inner_origin", "an empty list or [x, y, z] in m", std::to_string(io.size()) + " numbers");
  const double near = sc.real("continuum.mesh.size_near"), far = sc.real("continuum.mesh.size_far");
  if (near > far)
    ctx.fail("continuum.mesh.size_near", "a zone size <= size_far = " + num(far) + " m", num(near) + " m");
  const char* axis = "xyz";
  for (int a = 0; a < 3; ++a) {
    const double lo = io.empty() ? (a < 2 ? (size[a] - inner[a]) / 2 : size[a] - inner[a]) : io[a];
    if (inner[a] > size[a] || lo < 0 || lo + inner[a] > size[a] * (1 + 1e-12))
      ctx.fail(io.empty() ? "continuum.mesh.inner_size" : "continuum.mesh.inner_origin",
               std::string("an inner box inside the mesh box along ") + axis[a] + " (size " + num(size[a]) + " m)",
               "[" + num(lo) + ", " + num(lo + inner[a]) + "] m");
    if (near > size[a])
      ctx.fail("continuum.mesh.size_near", std::string("a zone size <= the mesh box along ") + axis[a] + ", " + num(size[a]) + " m",
               num(near) + " m");
    if (inner[a] > 0 && near > inner[a])
      ctx.fail("continuum.mesh.size_near",
               std::string("a zone size <= the inner box along ") + axis[a] + ", " + num(inner[a]) + " m (at least one zone across it)",
               num(near) + " m");
  }
}

config::Schema build() {
  config::Schema s;
  auto& root = s.root();
  declare_run(root);
  declare_bus(root);
  declare_nodes(root);
  declare_gravity(root);
  declare_dem(root);
  declare_continuum(root);
  declare_output(root);
  declare_chain(root);
  declare_stages(root);

  // The keys only some actions read, with those actions and the key's default: the effective
  // scene of a run (config::Scene::effective_toml) writes every key of every stage, so only a
  // value other than the default is refused.
  struct ActionKey {
    std::vector<std::string> actions;
    std::optional<double> def;  // nothing: the key's word ("auto")
  };
  std::map<std::string, ActionKey> action_keys;
  for (const auto& a : actions())
    for (const auto& key : a.keys) {
      auto& k = action_keys[key];
      k.actions.emplace_back(a.name);
      const config::Value& def = *root.find("stage")->section->find(key)->param->def;
      k.def = std::holds_alternative<double>(def) ? std::optional<double>(std::get<double>(def)) : std::nullopt;
    }
  s.check([action_keys](const config::Scene& sc, config::CheckContext& ctx) {
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
    if (sc.has("dem") && sc.has("continuum") && sc.boolean("continuum.mesh.pocket")) {
      auto cell = sc.reals("dem.specimen.cell");
      auto rep = sc.integers("dem.specimen.replicate");
      auto inner = sc.reals("continuum.mesh.inner_size");
      for (int a = 0; a < 3; ++a) {
        double block = cell[a] * static_cast<double>(rep[a]);
        if (std::abs(block - inner[a]) > 1e-9 * std::max(block, inner[a]))
          ctx.fail("continuum.mesh.inner_size",
                   "the DEM block size dem.specimen.cell x dem.specimen.replicate = [" +
                       std::to_string(cell[0] * rep[0]) + ", " + std::to_string(cell[1] * rep[1]) + ", " +
                       std::to_string(cell[2] * rep[2]) + "] m (the pocket holds the block)",
                   "[" + std::to_string(inner[0]) + ", " + std::to_string(inner[1]) + ", " + std::to_string(inner[2]) + "]");
      }
    }
    if (sc.has("dem")) check_dem(sc, ctx);
    if (sc.has("continuum")) check_mesh(sc, ctx);
    auto present = roles(sc);
    for (std::size_t i = 0; i < sc.count("stage"); ++i) {
      auto e = sc.at("stage", i);
      std::string p = "stage[" + std::to_string(i) + "]";
      const std::string act = e.string("action");
      for (const auto& [key, k] : action_keys) {
        if (e.explicitly_set(key) && e.real_or_word(key) != k.def &&
            std::find(k.actions.begin(), k.actions.end(), act) == k.actions.end()) {
          std::string list;
          for (auto& a : k.actions) list += (list.empty() ? "'" : "' or '") + a;
          ctx.fail(p + "." + key, "a key of a " + list + "' stage only (it has no effect in a '" + act + "' stage)",
                   "it in a '" + act + "' stage");
        }
      }
      auto nodes = e.strings("nodes");
      // Every role that takes part must act in the action (a continuum cannot generate a specimen).
      {
        const ActionInfo* info = action_named(act);
        const std::vector<std::string>& taking = nodes.empty() ? present : nodes;
        for (const auto& r : taking) {
          const bool acts = r == "dem" ? info->dem : info->continuum;
          if (acts || std::find(present.begin(), present.end(), r) == present.end()) continue;
          std::string can;
          if (info->dem) can += "'dem'";
          if (info->continuum) can += std::string(can.empty() ? "" : ", ") + "'continuum'";
          ctx.fail(p + ".nodes", "roles that act in a '" + act + "' stage (" + can + ")",
                   "'" + r + "'" + (nodes.empty() ? " (an empty list: all of the scene's roles)" : ""));
        }
      }
      for (std::size_t j = 0; j < nodes.size(); ++j)
        if (std::find(present.begin(), present.end(), nodes[j]) == present.end()) {
          std::string have;
          for (auto& r : present) have += (have.empty() ? "'" : ", '") + r + "'";
          ctx.fail(p + ".nodes", "roles present in the scene (" + have + ")", "'" + nodes[j] + "'");
        }
      auto action = e.string("action");
      if (action == "penetrate" && !sc.has("dem.footing"))
        ctx.fail(p + ".action", "a [dem.footing] section for a penetrate stage", "none");
      if (action == "couple" && !e.boolean("coupled"))
        ctx.fail(p + ".coupled", "true for a couple stage (it sets up the interface)", "false");
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

DemBlock dem_block(const config::Scene& s) {
  DemBlock b;
  const auto c = s.reals("dem.specimen.cell");
  const auto r = s.integers("dem.specimen.replicate");
  for (int a = 0; a < 3; ++a) {
    b.cell[a] = c[static_cast<std::size_t>(a)];
    b.n[a] = static_cast<int>(r[static_cast<std::size_t>(a)]);
  }
  const auto o = s.reals("dem.specimen.origin");
  if (o.size() == 3) {
    for (int a = 0; a < 3; ++a) b.origin[a] = o[static_cast<std::size_t>(a)];
  } else if (!o.empty()) {
    s.fail("dem.specimen.origin", "an empty list or [x, y, z] in m", std::to_string(o.size()) + " numbers");
  } else if (s.has("continuum")) {
    const auto box = s.reals("continuum.mesh.size");
    b.origin[0] = (box[0] - b.size(0)) / 2;
    b.origin[1] = (box[1] - b.size(1)) / 2;
    b.origin[2] = box[2] - b.size(2);
  }
  return b;
}

const std::vector<ActionInfo>& actions() {
  static const std::vector<ActionInfo> table{
      {Action::kCycle, "cycle", "step the models as they are.", false, true, true, {}},
      {Action::kEquilibrium, "equilibrium",
       "step until the unbalanced-force ratio is below 'ratio' (use until = \"done\").", false, true, true, {}},
      {Action::kGeostatic, "geostatic",
       "(continuum) assign sigma_v = rho N g depth, sigma_h = K0 sigma_v, then as equilibrium.", false, false, true,
       {"k0"}},
      {Action::kGenerate, "generate", "DEM generation: the REV in a periodic cell by radius expansion.", true, true,
       false, {}},
      {Action::kServo, "servo", "DEM generation: compress the REV to sigma_v, sigma_h.", true, true, false, {}},
      {Action::kBond, "bond", "DEM generation: install bonds.", true, true, false, {}},
      {Action::kReplicate, "replicate", "DEM generation: stack copies of the REV, open the boundaries.", true, true,
       false, {}},
      {Action::kCouple, "couple",
       "interface set-up (facets from the continuum's mesh, ball-facet bonds, depth scaling, facet bond forces; "
       "continuum: geostatic stresses), gravity on, then as equilibrium.",
       false, true, true, {"k0"}},
      {Action::kPenetrate, "penetrate",
       "the footing moves down at the rate of the inertial number; the stage ends at 'depth_ratio'.", false, true,
       true,
       {"inertial_number", "plastic_zone_ratio", "mean_stress", "depth_ratio", "speed_factor", "ramp_depth_ratio",
        "quasi_static_limit", "rock_young"}},
      {Action::kUcs, "ucs", "unconfined compression between platens (DEM).", false, true, false,
       {"strain_rate", "max_strain"}},
  };
  return table;
}

const ActionInfo& action_info(Action a) {
  for (const auto& info : actions())
    if (info.id == a) return info;
  throw std::logic_error("stage action without a row in schema::actions()");
}

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
    st.kind = action_named(st.action)->id;  // the schema admits only the table's names
    st.nodes = e.strings("nodes");
    if (st.nodes.empty()) st.nodes = all;
    st.steps = e.integer("steps");
    st.until_done = e.string("until") == "done";
    st.fail_on_budget = e.string("on_budget") == "fail";
    st.coupled = e.boolean("coupled");
    st.steps_per_grant = e.integer("steps_per_grant");
    st.view = e;
    out.push_back(std::move(st));
  }
  return out;
}

}  // namespace demfdm::schema
