// The demfdm scene: one TOML file drives a whole run. This is the single declaration of every
// scene parameter (type, unit, default, range, doc); it drives parsing and validation in every
// process, `coordinator --help-scene`, and docs/scene-reference.md.
//
// A section that is absent switches its effect off and costs nothing: no [dem] -> no DEM node,
// no [continuum] -> no continuum node, no [coupling] -> no interface exchange, and so on.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "common/config/config.hpp"

namespace demfdm::schema {

const config::Schema& scene_schema();

// Roles the scene needs, in start order ("dem", "continuum").
std::vector<std::string> roles(const config::Scene& s);
// Executable that plays a role (scene key <role>.executable).
std::string executable(const config::Scene& s, const std::string& role);

// OpenMP threads of a node process (run.threads): the number given, or for "auto" the CPUs this
// process may run on (its affinity mask: taskset and cgroup cpusets count), at least 1.
int run_threads(const config::Scene& s);

// The stage actions (docs/stages.md): the one table of what a [[stage]] may do. The schema's
// `action` choice, its doc, the keys each action reads and which roles act in it come from
// here; the nodes switch on Action, so a new action is one row here plus its case in each node
// that acts in it (the compiler names a node's switch that misses it).
enum class Action : std::uint8_t {
  kCycle,
  kEquilibrium,
  kGeostatic,
  kGenerate,
  kServo,
  kBond,
  kReplicate,
  kCouple,
  kPenetrate,
  kUcs,
};
struct ActionInfo {
  Action id;
  const char* name;
  const char* doc;
  bool preparation;  // DEM specimen preparation: periodic REV, own step rule, no gravity, before model time 0
  bool dem;          // the DEM node acts in it
  bool continuum;    // a continuum node acts in it
  std::vector<std::string> keys;  // [[stage]] keys read by this action only (and others that list them)
};
const std::vector<ActionInfo>& actions();
const ActionInfo& action_info(Action a);

// Stage list, read once.
struct Stage {
  std::string name, action;
  Action kind = Action::kCycle;    // the action, as the nodes switch on it
  std::vector<std::string> nodes;  // roles that take part
  std::int64_t steps = 0;          // step budget (coupling steps)
  bool until_done = false;         // stop when every node reports its criterion met
  bool fail_on_budget = true;      // with until_done: budget exhausted is an error
  bool coupled = false;
  std::int64_t steps_per_grant = 1;
  config::Scene view;              // the [[stage]] element, for action parameters
};
std::vector<Stage> stages(const config::Scene& s);

// Geometry of the DEM block of a scene with [dem]: the REV cell dem.specimen.cell replicated
// dem.specimen.replicate times, its minimum corner at dem.specimen.origin, or (empty origin)
// in the continuum's pocket (centred in x and y, top flush with the box top), or at [0, 0, 0].
// One definition for the checks and the DEM node. Throws config::Error naming
// dem.specimen.origin if it holds neither 0 nor 3 numbers.
struct DemBlock {
  double origin[3] = {0, 0, 0};  // [m] minimum corner
  double cell[3] = {0, 0, 0};    // [m] REV cell
  int n[3] = {1, 1, 1};          // replication
  double size(int a) const { return cell[a] * n[a]; }  // [m] block edge along axis a
  double z_top() const { return origin[2] + size(2); }
};
DemBlock dem_block(const config::Scene& s);


}  // namespace demfdm::schema
