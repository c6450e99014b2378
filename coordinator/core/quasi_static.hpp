// Footing rate of a penetrate stage and whether it is quasi-static for a bonded solid.
//
// The rate rule (docs/theory.md §7.1) sets the footing speed from the inertial number,
// v = I L_p / (d50 sqrt(rho_s / P)). The inertial number measures the grains' rearrangement
// against their confinement; it says nothing about the bonds. A cemented block loaded at speed
// v carries the impedance stress rho_b c v at once (c the P-wave speed of the rock), and it
// strains at the rate v / (c ...); both are judged against the bond's tensile strength:
//   impedance ratio    rho_b c v / sigma_c     (stress of the impact / bond strength)
//   strain-rate ratio  v / (c eps_f)           (eps_f = sigma_c / E: strain at failure)
// A run is treated as quasi-static when the impedance ratio is at most the stage's
// quasi_static_limit (docs/stages.md).
//
// The ramp: the speed rises linearly in time from 0 to v over t_r = 2 ramp_depth_ratio D_f / v,
// during which the footing moves v t_r / 2 = ramp_depth_ratio D_f.
//
// Pure functions of plain numbers (no scene, no LCM): coordinator/main.cpp looks the values up.
#pragma once
#include <optional>
#include <string>

namespace demfdm::coord {

// Rate-rule speed v = I L_p / (d50 sqrt(rho_s / P)) times speed_factor, L_p = plastic_zone_ratio
// D_f, with d50 of the upscaled PSD (d50 x scale) [m/s]. The arithmetic is the coordinator's
// original one, operation for operation.
double footing_speed(double inertial_number, double plastic_zone_ratio, double footing_diameter, double d50,
                     double scale, double grain_density, double mean_stress, double speed_factor);

// Ramp time t_r = 2 ramp_depth_ratio D_f / v [s]; 0 without a ramp (ratio 0) or at v = 0.
double ramp_time(double ramp_depth_ratio, double footing_diameter, double speed);

// Footing speed at time t since the start of the stage: v min(1, t / t_r). t_r <= 0 returns v
// itself (no arithmetic on it, so a run without a ramp is bit-identical to one before the ramp).
double ramped_speed(double speed, double t, double t_ramp);

// P-wave (constrained) modulus M = E (1 - nu) / ((1 + nu) (1 - 2 nu)) [Pa].
double p_wave_modulus(double young, double poisson);
// P-wave speed c = sqrt(M / rho) [m/s].
double p_wave_speed(double young, double poisson, double density);

// The measures of one penetrate stage.
struct RateMeasures {
  double speed = 0;            // v [m/s]: full speed after the ramp, speed_factor included
  double inertial_number = 0;  // I [-]
  double ramp_time = 0;        // t_r [s]; 0: no ramp
  double young = 0, poisson = 0;  // E [Pa], nu [-] of the rock
  double bulk_density = 0;     // rho_b [kg/m^3]
  double wave_speed = 0;       // c [m/s]
  double limit = 0;            // quasi_static_limit [-]
  // Only when the ball-ball contacts have a bond of finite, positive tensile strength:
  std::optional<double> bond_strength;      // sigma_c [Pa]
  std::optional<double> failure_strain;     // eps_f = sigma_c / E [-]
  std::optional<double> impedance_ratio;    // rho_b c v / sigma_c [-]
  std::optional<double> strain_rate_ratio;  // v / (c eps_f) [-]
  bool applicable() const { return impedance_ratio.has_value(); }
  // Quasi-static: impedance ratio <= limit (true when the measures do not apply).
  bool quasi_static() const { return !impedance_ratio || *impedance_ratio <= limit; }
};

// bond_strength: sigma_c of the ball-ball bond; nullopt (no bond), a value <= 0 or an
// infinite one (unbreakable) make the bond measures not applicable.
RateMeasures rate_measures(double speed, double inertial_number, double ramp_time, double young, double poisson,
                           double bulk_density, std::optional<double> bond_strength, double limit);

// One line: "v 4.02 m/s, I 0.01, ramp 5.97e-06 s, c 1130 m/s (E ..., nu ..., rho_b ...), sigma_c ...,
// eps_f ..., rho_b c v / sigma_c 12.8, v / (c eps_f) 8.56, limit 0.1" ("n/a" without a bond).
std::string describe(const RateMeasures& m);
// "WARNING: not quasi-static: stage 'NAME': rho_b c v / sigma_c = R > quasi_static_limit L ..."
// when the measures apply and exceed the limit; "" otherwise.
std::string quasi_static_warning(const std::string& stage, const RateMeasures& m);

}  // namespace demfdm::coord
