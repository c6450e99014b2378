#include "fdm_node/scene_params.hpp"

#include <stdexcept>
#include <string>

#include "common/schema/scene_read.hpp"

namespace demfdm::continuum {
namespace {
std::array<double, 3> vec3(const std::vector<double>& v) { return {v[0], v[1], v[2]}; }
}  // namespace

fdm::MeshParams mesh_from_scene(const config::Scene& s) {
  fdm::MeshParams m;
  auto size = s.reals("continuum.mesh.size");
  m.length = size[0];
  m.width = size[1];
  m.height = size[2];
  m.inner_size = vec3(s.reals("continuum.mesh.inner_size"));
  auto origin = s.reals("continuum.mesh.inner_origin");
  if (origin.size() == 3)
    m.inner_origin = vec3(origin);
  else if (!origin.empty())
    s.fail("continuum.mesh.inner_origin", "an empty list or 3 numbers [x, y, z] in m",
           std::to_string(origin.size()) + " numbers");
  schema::read_table(s, "continuum.mesh.", m);
  try {
    fdm::validate(m);
  } catch (const std::invalid_argument& e) {
    s.fail("continuum.mesh", "a valid mesh", e.what());
  }
  return m;
}

std::optional<fdm::Box> region_from_scene(const config::Scene& e) {
  auto lo = e.reals("region_lo"), hi = e.reals("region_hi");
  if (lo.size() != hi.size() || (lo.size() != 0 && lo.size() != 3))
    e.fail("region_lo", "region_lo and region_hi both empty or both [x, y, z]",
           std::to_string(lo.size()) + " and " + std::to_string(hi.size()) + " numbers");
  if (lo.size() == 3) return fdm::Box{vec3(lo), vec3(hi)};
  return std::nullopt;
}

fdm::MaterialGroup material_from_scene(const config::Scene& e) {
  fdm::MaterialGroup g;
  schema::read_table(e, "", g.material);
  g.region = region_from_scene(e);
  return g;
}

void model_keys_from_scene(const config::Scene& s, fdm::ModelParams& p) { schema::read_table(s, "continuum.", p); }

ElasticMaterial elastic_from_scene(const config::Scene& e) {
  const fdm::MaterialGroup g = material_from_scene(e);
  return {g.material.density, g.material.young, g.material.poisson, g.region};
}

}  // namespace demfdm::continuum
