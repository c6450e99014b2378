// Centrifuge planning report of a footing run (issue 14 item 3; docs/theory.md §7.7).
//
// The run is the model of a centrifuge test at N g. From its load-settlement curve this module
// states, at model and at prototype scale side by side, what the test means (length x N,
// area and force x N^2, stress and strain x 1, mass x N^3, the time scales and which one
// applies), the prototype footing and its load-settlement curve, and the demand on the rig at
// model scale: load-cell range (largest force x a stated margin, rounded up to a 1-2-5 range),
// stroke, actuator speed and power, with their prototype-equivalent figures. It warns when the
// run's speed is far above a real actuator's.
//
// Transport-free: plain numbers in, Markdown (centrifuge.md) and a JSON object out.
#pragma once

#include <limits>
#include <string>
#include <vector>

namespace demfdm::coord {

struct CentrifugeInput {
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double g_level = 1;              // N (gravity.level) [-]; 1 for a 1 g run; finite, > 0
  double footing_diameter_m = 0;   // D_f at model scale [m]; finite, > 0
  double footing_speed_m_s = 0;    // model-scale penetration speed after the ramp [m/s]; finite, > 0
  std::vector<double> settlement_m, load_N;  // model-scale curve (dem.footing_disp_m, dem.footing_fz_N)
  double target_settlement_m = 0;  // depth_ratio D_f [m]; finite, > 0
  double block_size_m[3] = {kNaN, kNaN, kNaN};  // modelled ground x, y, z [m]; non-finite: not reported
  double g0_m_s2 = 9.81;             // standard gravity (gravity.g0) [m/s^2]
  double rock_density_kg_m3 = kNaN;  // bulk density of the ground [kg/m^3]; NaN: not reported
  double sigma_c_Pa = kNaN;          // bond (tensile) strength of the rock [Pa]; NaN if none
  double young_Pa = kNaN;            // Young's modulus of the rock [Pa]; NaN if none
  double load_cell_margin = 1.5;     // load-cell range = margin x largest force [-]; finite, >= 1
  // Stroke = target settlement + ramp_travel_m + overtravel_ratio x target settlement.
  double ramp_travel_m = 0;          // run-up travel to reach speed (the run's speed ramp) [m]; >= 0
  double overtravel_ratio = 0.5;     // overtravel beyond the target, fraction of it [-]; >= 0
  // Quasi-static criterion of the run (docs/theory.md §7.6): rho_b c v / sigma_c and the stage's
  // quasi_static_limit; NaN when not applicable or unknown.
  double impedance_ratio = kNaN;
  double quasi_static_limit = kNaN;
  std::string scene, stage;
};

// One point of the resampled curve (at both scales; s/D and q are the same at both).
struct CurvePoint {
  double settlement_model_m = 0, load_model_N = 0;
  double settlement_proto_m = 0, load_proto_N = 0;
  double s_over_d = 0;  // [-]
  double q_Pa = 0;      // F / (pi D^2 / 4) [Pa]
};

struct CentrifugeReport {
  double n = 1;                                  // g-level N
  double diameter_model_m = 0, diameter_proto_m = 0;
  double area_model_m2 = 0, area_proto_m2 = 0;
  double target_model_m = 0, target_proto_m = 0;
  double peak_model_N = 0, peak_proto_N = 0;     // largest load (signed max of the curve)
  double settlement_at_peak_model_m = 0, settlement_at_peak_proto_m = 0;
  double peak_q_Pa = 0;                          // peak / area (same at both scales)
  double secant_stiffness_model_N_m = 0;         // peak / settlement at peak; NaN at zero settlement
  double secant_stiffness_proto_N_m = 0;         // x N
  double max_settlement_model_m = 0;             // largest settlement of the curve
  bool target_reached = false;
  std::vector<CurvePoint> curve;                 // ~10 points at 0.1, 0.2, ... 1.0 of the largest settlement
  // Rig demand at model scale and its prototype equivalent.
  double max_force_model_N = 0, max_force_proto_N = 0;       // max |F|
  double load_cell_range_model_N = 0, load_cell_range_proto_N = 0;  // 1-2-5 x 10^k >= margin x max |F|
  double stroke_model_m = 0, stroke_proto_m = 0;
  double speed_model_m_s = 0, speed_proto_m_s = 0;           // prototype: x 1 (inertial time scaling)
  double power_model_W = 0, power_proto_W = 0;               // max |F| x speed
  double power_model_rig_max_W = 0;                          // max |F| x 1 mm/s (fastest rig speed)
  double loading_time_model_s = 0;                           // target / speed [s] (not a physical time)
  double speed_over_rig_max = 0;                             // speed / 1 mm/s
  bool speed_realistic = false;                              // 0.01 <= speed <= 1 mm/s
  std::vector<std::string> warnings;
  std::string markdown;  // centrifuge.md
  std::string json;      // one JSON object, non-finite values as null
};

// Fastest and slowest displacement rate of a real centrifuge actuator assumed here [m/s].
inline constexpr double kRigSpeedMin_m_s = 1e-5;  // 0.01 mm/s
inline constexpr double kRigSpeedMax_m_s = 1e-3;  // 1 mm/s

// The smallest value of the 1-2-5 series (1, 2, 5 x 10^k) that is >= x; NaN for x <= 0 or non-finite.
double round_up_125(double x);

// Throws std::invalid_argument (naming the field) on an empty curve, curves of different
// lengths, a non-finite curve value, or a non-finite / out-of-range scalar listed above.
CentrifugeReport centrifuge_report(const CentrifugeInput& in);

}  // namespace demfdm::coord
