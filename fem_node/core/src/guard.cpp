#include "demfdm/fem/guard.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace demfdm::fem {
namespace {

std::string triple(const std::vector<double>& a, std::int32_t g) {
  std::ostringstream os;
  os.precision(9);
  const auto i = 3 * static_cast<std::size_t>(g);
  os << "(" << a[i] << ", " << a[i + 1] << ", " << a[i + 2] << ")";
  return os.str();
}

}  // namespace

std::string zones_around(const Model& m, std::int32_t g) {
  const auto& z = m.mesh().zones;
  std::ostringstream os;
  for (std::size_t k = 0; k < z.size() / 8; ++k) {
    if (std::find(z.begin() + 8 * k, z.begin() + 8 * k + 8, g) == z.begin() + 8 * k + 8) continue;
    os << "  zone " << k << ":";
    for (int c = 0; c < 8; ++c) os << " gp " << z[8 * k + c] << " u " << triple(m.displacements(), z[8 * k + c]);
    os << "\n";
  }
  return os.str();
}

std::optional<GuardFinding> check_finite(const Model& m) {
  const auto& u = m.displacements();
  for (std::size_t i = 0; i < u.size(); ++i) {
    if (std::isfinite(u[i])) continue;
    const auto g = static_cast<std::int32_t>(i / 3);
    const std::string id = std::to_string(g), at = triple(m.mesh().points, g);
    return GuardFinding{"non-finite displacement of gridpoint " + id + " at " + at + " m",
                        "gridpoint " + id + " at " + at + " m, displacement " + triple(u, g) +
                            " m\nzones around it:\n" + zones_around(m, g),
                        g};
  }
  return std::nullopt;
}

}  // namespace demfdm::fem
