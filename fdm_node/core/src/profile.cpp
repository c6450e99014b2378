#include "demfdm/fdm/profile.hpp"

namespace demfdm::fdm {

std::vector<ProfileLayer> stress_profile(const Model& model) {
  const auto& m = model.mesh();
  const std::size_t nk = m.grid_z.size() - 1;
  std::vector<double> vol(nk, 0.0), szz(nk, 0.0), sxx(nk, 0.0);
  std::vector<std::size_t> count(nk, 0);
  const auto stress = model.zone_stress();
  for (std::size_t z = 0; z < model.num_zones(); ++z) {
    auto i = m.zone_ijk[3 * z], j = m.zone_ijk[3 * z + 1], k = m.zone_ijk[3 * z + 2];
    double v = (m.grid_x[i + 1] - m.grid_x[i]) * (m.grid_y[j + 1] - m.grid_y[j]) * (m.grid_z[k + 1] - m.grid_z[k]);
    vol[k] += v;
    szz[k] += v * stress[6 * z + 2];
    sxx[k] += v * stress[6 * z];
    ++count[k];
  }
  const double top = m.grid_z.back();
  std::vector<ProfileLayer> layers;
  for (std::size_t k = nk; k-- > 0;) {
    if (count[k] == 0) continue;
    const double d = top - 0.5 * (m.grid_z[k] + m.grid_z[k + 1]);
    layers.push_back({d, szz[k] / vol[k], sxx[k] / vol[k], count[k]});
  }
  return layers;
}

}  // namespace demfdm::fdm
