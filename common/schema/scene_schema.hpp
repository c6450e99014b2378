// The demfdm scene: one TOML file drives a whole run. This is the single declaration of every
// scene parameter (type, unit, default, range, doc); it drives parsing and validation in every
// process, `coordinator --help-scene`, and docs/scene-reference.md.
//
// A section that is absent switches its effect off and costs nothing: no [dem] -> no DEM node,
// no [continuum] -> no continuum node, no [coupling] -> no interface exchange, and so on.
#pragma once
#include <string>
#include <vector>

#include "common/config/config.hpp"

namespace demfdm::schema {

const config::Schema& scene_schema();

// Roles the scene needs, in start order ("dem", "continuum").
std::vector<std::string> roles(const config::Scene& s);
// Executable that plays a role (scene key <role>.executable).
std::string executable(const config::Scene& s, const std::string& role);

// Stage list, read once.
struct Stage {
  std::string name, action;
  std::vector<std::string> nodes;  // roles that take part
  std::int64_t steps = 0;          // step budget (coupling steps)
  bool until_done = false;         // stop when every node reports its criterion met
  bool fail_on_budget = true;      // with until_done: budget exhausted is an error
  bool coupled = false;
  std::int64_t steps_per_grant = 1;
  config::Scene view;              // the [[stage]] element, for action parameters
};
std::vector<Stage> stages(const config::Scene& s);

}  // namespace demfdm::schema
