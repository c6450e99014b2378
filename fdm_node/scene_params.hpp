// Scene keys -> the parameters every continuum solver on the shared mesh (fdm_mesh) reads the
// same way (fdm_node, fem_node), so that both read [continuum.mesh] and [[continuum.material]]
// regions alike and their interfaces match. A key with a field is read through its declaration
// beside the struct (describe() in demfdm/fdm/mesh.hpp and params.hpp, demfdm/param_table.hpp);
// the lists (sizes, origins, regions) are declared in the schema and read with its defaults.
// Errors are config::Error at the offending key.
#pragma once
#include <cstddef>
#include <optional>
#include <vector>

#include "common/config/config.hpp"
#include "demfdm/fdm/mesh.hpp"
#include "demfdm/fdm/params.hpp"  // header only: the material and model tables

namespace demfdm::continuum {

// [continuum.mesh], validated (a bad combination fails at "continuum.mesh").
fdm::MeshParams mesh_from_scene(const config::Scene& s);
// region_lo / region_hi of one [[continuum.material]] element: nullopt = every zone.
std::optional<fdm::Box> region_from_scene(const config::Scene& element);

// One [[continuum.material]] element: its material (the table of fdm::Material) and region.
fdm::MaterialGroup material_from_scene(const config::Scene& element);

// The continuum's own keys with a field in fdm::ModelParams ([continuum] mode, damping,
// large_strain, averaging, timestep_safety, static_mass_factor), read into p.
void model_keys_from_scene(const config::Scene& s, fdm::ModelParams& p);

// The keys of one [[continuum.material]] element that every solver reads: the elastic
// constants and the region (read as material_from_scene reads them).
struct ElasticMaterial {
  double density = 0;  // [kg/m^3]
  double young = 0;    // [Pa]
  double poisson = 0;  // [-]
  std::optional<fdm::Box> region;
};
ElasticMaterial elastic_from_scene(const config::Scene& element);

// One group per [[continuum.material]] element, in scene order, each made by read(element);
// a scene without the array gets one default-constructed group (the solver's default material).
template <class Group, class Read>
std::vector<Group> material_groups(const config::Scene& s, Read read) {
  std::vector<Group> groups;
  const std::size_t n = s.count("continuum.material");
  if (n == 0) groups.push_back(Group{});
  for (std::size_t i = 0; i < n; ++i) groups.push_back(read(s.at("continuum.material", i)));
  return groups;
}

}  // namespace demfdm::continuum
