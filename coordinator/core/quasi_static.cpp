#include "coordinator/core/quasi_static.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace demfdm::coord {
namespace {
std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}
}  // namespace

double footing_speed(double inertial_number, double plastic_zone_ratio, double footing_diameter, double d50,
                     double scale, double grain_density, double mean_stress, double speed_factor) {
  // docs/theory.md §7.1. Keep the order of the operations: runs must not change by a bit.
  double d = d50 * scale;
  double lp = plastic_zone_ratio * footing_diameter;
  double speed = inertial_number * lp / (d * std::sqrt(grain_density / mean_stress));
  return speed * speed_factor;
}

double ramp_time(double ramp_depth_ratio, double footing_diameter, double speed) {
  if (!(ramp_depth_ratio > 0) || !(speed > 0)) return 0.0;
  return 2.0 * ramp_depth_ratio * footing_diameter / speed;
}

double ramped_speed(double speed, double t, double t_ramp) {
  if (!(t_ramp > 0)) return speed;
  return speed * std::min(1.0, std::max(0.0, t) / t_ramp);
}

double p_wave_modulus(double young, double poisson) {
  return young * (1.0 - poisson) / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
}

double p_wave_speed(double young, double poisson, double density) {
  return std::sqrt(p_wave_modulus(young, poisson) / density);
}

RateMeasures rate_measures(double speed, double inertial_number, double ramp_time, double young, double poisson,
                           double bulk_density, std::optional<double> bond_strength, double limit) {
  RateMeasures m;
  m.speed = speed;
  m.inertial_number = inertial_number;
  m.ramp_time = ramp_time;
  m.young = young;
  m.poisson = poisson;
  m.bulk_density = bulk_density;
  m.wave_speed = p_wave_speed(young, poisson, bulk_density);
  m.limit = limit;
  if (bond_strength && *bond_strength > 0 && std::isfinite(*bond_strength)) {
    const double sc = *bond_strength;
    m.bond_strength = sc;
    m.failure_strain = sc / young;
    m.impedance_ratio = bulk_density * m.wave_speed * speed / sc;
    m.strain_rate_ratio = speed / (m.wave_speed * *m.failure_strain);
  }
  return m;
}

std::string describe(const RateMeasures& m) {
  auto opt = [](const std::optional<double>& v, const char* unit) {
    return v ? num(*v) + unit : std::string("n/a");
  };
  return "v " + num(m.speed) + " m/s, I " + num(m.inertial_number) + ", ramp " +
         (m.ramp_time > 0 ? num(m.ramp_time) + " s" : std::string("none")) + ", c " + num(m.wave_speed) +
         " m/s (E " + num(m.young) + " Pa, nu " + num(m.poisson) + ", rho_b " + num(m.bulk_density) +
         " kg/m3), sigma_c " + opt(m.bond_strength, " Pa") + ", eps_f " + opt(m.failure_strain, "") +
         ", rho_b c v / sigma_c " + opt(m.impedance_ratio, "") + ", v / (c eps_f) " + opt(m.strain_rate_ratio, "") +
         " (quasi-static limit " + num(m.limit) + ")";
}

std::string quasi_static_warning(const std::string& stage, const RateMeasures& m) {
  if (m.quasi_static()) return "";
  return "WARNING: not quasi-static: stage '" + stage + "': rho_b c v / sigma_c = " + num(*m.impedance_ratio) +
         " > quasi_static_limit " + num(m.limit) + " (v " + num(m.speed) + " m/s; lower inertial_number or "
         "speed_factor)";
}

}  // namespace demfdm::coord
