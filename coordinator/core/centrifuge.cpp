#include "coordinator/core/centrifuge.hpp"

#include "coordinator/core/summary.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>
#include <stdexcept>

// Scaling laws and their sources: docs/theory.md §7.7.
namespace demfdm::coord {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string fmt(const char* f, double v) {
  if (!std::isfinite(v)) return "n/a";
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}
std::string g4(double v) { return fmt("%.4g", v); }

std::string jnum(double v) { return json_number(v); }
std::string jstr(const std::string& s) { return json_string(s); }
template <class F>
std::string jarr(const std::vector<CurvePoint>& pts, F get) {
  std::string o = "[";
  for (std::size_t i = 0; i < pts.size(); ++i) o += (i ? ", " : "") + jnum(get(pts[i]));
  return o + "]";
}
std::string jbool_or_null(int tri) { return tri < 0 ? "null" : (tri ? "true" : "false"); }

[[noreturn]] void refuse(const std::string& what) { throw std::invalid_argument("centrifuge report: " + what); }

void need_positive(const char* name, double v) {
  if (!std::isfinite(v) || !(v > 0)) refuse(std::string(name) + " must be finite and > 0, got " + g4(v));
}
void need_nonnegative(const char* name, double v) {
  if (!std::isfinite(v) || v < 0) refuse(std::string(name) + " must be finite and >= 0, got " + g4(v));
}

void validate(const CentrifugeInput& in) {
  need_positive("g_level", in.g_level);
  need_positive("footing_diameter_m", in.footing_diameter_m);
  need_positive("footing_speed_m_s", in.footing_speed_m_s);
  need_positive("target_settlement_m", in.target_settlement_m);
  need_positive("g0_m_s2", in.g0_m_s2);
  if (!std::isfinite(in.load_cell_margin) || in.load_cell_margin < 1)
    refuse("load_cell_margin must be finite and >= 1, got " + g4(in.load_cell_margin));
  need_nonnegative("ramp_travel_m", in.ramp_travel_m);
  need_nonnegative("overtravel_ratio", in.overtravel_ratio);
  if (in.settlement_m.empty() || in.load_N.empty()) refuse("the load-settlement curve is empty");
  if (in.settlement_m.size() != in.load_N.size())
    refuse("settlement_m has " + std::to_string(in.settlement_m.size()) + " values but load_N has " +
           std::to_string(in.load_N.size()));
  for (std::size_t i = 0; i < in.settlement_m.size(); ++i) {
    if (!std::isfinite(in.settlement_m[i]))
      refuse("non-finite settlement_m[" + std::to_string(i) + "] = " + g4(in.settlement_m[i]));
    if (!std::isfinite(in.load_N[i])) refuse("non-finite load_N[" + std::to_string(i) + "] = " + g4(in.load_N[i]));
  }
  for (int k = 0; k < 3; ++k)
    if (in.block_size_m[k] <= 0) refuse("block_size_m[" + std::to_string(k) + "] must be > 0 (or NaN: not reported)");
  if (in.rock_density_kg_m3 <= 0) refuse("rock_density_kg_m3 must be > 0 (or NaN: not reported)");
}

// ~10 points of the curve at 0.1, 0.2, ..., 1.0 of its largest settlement, by linear
// interpolation at the first crossing; when the footing never moved, up to 10 evenly spaced rows.
std::vector<std::pair<double, double>> resample(const std::vector<double>& s, const std::vector<double>& f) {
  std::vector<std::pair<double, double>> out;
  const double smax = *std::max_element(s.begin(), s.end());
  const std::size_t n = s.size();
  if (!(smax > 0)) {
    const std::size_t m = std::min<std::size_t>(10, n);
    for (std::size_t k = 0; k < m; ++k) {
      std::size_t i = m == 1 ? n - 1 : (k * (n - 1) + (m - 1) / 2) / (m - 1);
      out.emplace_back(s[i], f[i]);
    }
    return out;
  }
  for (int k = 1; k <= 10; ++k) {
    const double target = k == 10 ? smax : smax * k / 10.0;
    std::size_t i = 0;
    while (i < n && s[i] < target) ++i;
    if (i >= n) i = n - 1;  // cannot happen (smax is in s); defensive
    if (i == 0 || s[i] == s[i - 1]) {
      out.emplace_back(s[i], f[i]);
    } else {
      const double w = (target - s[i - 1]) / (s[i] - s[i - 1]);
      out.emplace_back(target, f[i - 1] + w * (f[i] - f[i - 1]));
    }
  }
  return out;
}

}  // namespace

double round_up_125(double x) {
  if (!std::isfinite(x) || !(x > 0)) return std::numeric_limits<double>::quiet_NaN();
  const int k = static_cast<int>(std::floor(std::log10(x)));
  // Try one decade below and above too: log10 may round across a decade boundary.
  for (int e = k - 1; e <= k + 1; ++e) {
    const double p = std::pow(10.0, e);
    for (double m : {1.0, 2.0, 5.0}) {
      const double r = m * p;
      if (r >= x * (1 - 1e-12)) return r;
    }
  }
  return std::pow(10.0, k + 2);  // not reached
}

CentrifugeReport centrifuge_report(const CentrifugeInput& in) {
  validate(in);
  CentrifugeReport r;
  const double N = in.g_level, N2 = N * N, N3 = N2 * N;
  const double D = in.footing_diameter_m;
  r.n = N;
  r.diameter_model_m = D;
  r.diameter_proto_m = D * N;
  r.area_model_m2 = kPi * D * D / 4.0;
  r.area_proto_m2 = r.area_model_m2 * N2;
  r.target_model_m = in.target_settlement_m;
  r.target_proto_m = in.target_settlement_m * N;

  const auto& s = in.settlement_m;
  const auto& f = in.load_N;
  const std::size_t ip = static_cast<std::size_t>(std::max_element(f.begin(), f.end()) - f.begin());
  r.peak_model_N = f[ip];
  r.peak_proto_N = f[ip] * N2;
  r.settlement_at_peak_model_m = s[ip];
  r.settlement_at_peak_proto_m = s[ip] * N;
  r.peak_q_Pa = r.peak_model_N / r.area_model_m2;
  r.secant_stiffness_model_N_m = s[ip] != 0 ? f[ip] / s[ip] : std::numeric_limits<double>::quiet_NaN();
  r.secant_stiffness_proto_N_m = r.secant_stiffness_model_N_m * N;
  r.max_settlement_model_m = *std::max_element(s.begin(), s.end());
  r.target_reached = r.max_settlement_model_m >= in.target_settlement_m * (1 - 1e-12);
  for (auto [sm, fm] : resample(s, f))
    r.curve.push_back({sm, fm, sm * N, fm * N2, sm / D, fm / r.area_model_m2});

  // Rig demand.
  double fabs_max = 0;
  for (double v : f) fabs_max = std::max(fabs_max, std::fabs(v));
  r.max_force_model_N = fabs_max;
  r.max_force_proto_N = fabs_max * N2;
  r.load_cell_range_model_N = round_up_125(in.load_cell_margin * r.max_force_model_N);
  r.load_cell_range_proto_N = round_up_125(in.load_cell_margin * r.max_force_proto_N);
  const double overtravel = in.overtravel_ratio * in.target_settlement_m;
  r.stroke_model_m = in.target_settlement_m + in.ramp_travel_m + overtravel;
  r.stroke_proto_m = r.stroke_model_m * N;
  const double v = in.footing_speed_m_s;
  r.speed_model_m_s = v;
  r.speed_proto_m_s = v;  // length x N over dynamic time x N
  r.power_model_W = r.max_force_model_N * v;
  r.power_proto_W = r.max_force_proto_N * r.speed_proto_m_s;
  r.power_model_rig_max_W = r.max_force_model_N * kRigSpeedMax_m_s;
  r.loading_time_model_s = in.target_settlement_m / v;
  r.speed_over_rig_max = v / kRigSpeedMax_m_s;
  r.speed_realistic = v >= kRigSpeedMin_m_s * (1 - 1e-12) && v <= kRigSpeedMax_m_s * (1 + 1e-12);

  // Quasi-static status: 1 met, 0 not met, -1 unknown.
  const int qs = (std::isfinite(in.impedance_ratio) && std::isfinite(in.quasi_static_limit))
                     ? (in.impedance_ratio <= in.quasi_static_limit ? 1 : 0)
                     : -1;
  std::string qs_text;
  if (qs == 1)
    qs_text = "it was: rho_b c v / sigma_c = " + g4(in.impedance_ratio) + " <= quasi_static_limit " +
              g4(in.quasi_static_limit) + ".";
  else if (qs == 0)
    qs_text = "it was NOT: rho_b c v / sigma_c = " + g4(in.impedance_ratio) + " > quasi_static_limit " +
              g4(in.quasi_static_limit) +
              ", so the curve includes rate (inertia) effects and overstates the load a rig would measure.";
  else
    qs_text = "the criterion was not evaluated for this run (no bond strength or no rate measures): treat the "
              "curve as an upper bound until a slower run confirms it.";

  const double vmm = v * 1e3;
  if (v > kRigSpeedMax_m_s * (1 + 1e-12))
    r.warnings.push_back("The run's footing speed " + g4(vmm) + " mm/s is " + g4(v / kRigSpeedMax_m_s) +
                         " times the fastest actuator speed assumed here (1 mm/s) and " +
                         g4(v / kRigSpeedMin_m_s) +
                         " times the slowest (0.01 mm/s); it was chosen for computing cost. The models are "
                         "rate-independent, so the curve holds at a rig's speed only if the run was quasi-static "
                         "(docs/theory.md §7.6): " +
                         qs_text);
  else if (v < kRigSpeedMin_m_s * (1 - 1e-12))
    r.warnings.push_back("The run's footing speed " + g4(vmm) +
                         " mm/s is below the slowest actuator speed assumed here (0.01 mm/s).");
  else if (qs == 0)
    r.warnings.push_back("The run was not quasi-static (docs/theory.md §7.6): rho_b c v / sigma_c = " +
                         g4(in.impedance_ratio) + " > quasi_static_limit " + g4(in.quasi_static_limit) +
                         "; the curve includes rate (inertia) effects.");
  if (!r.target_reached)
    r.warnings.push_back("The curve ends at " + g4(r.max_settlement_model_m * 1e3) + " mm, before the target " +
                         g4(in.target_settlement_m * 1e3) +
                         " mm: the peak, load-cell range and power are those of the part that ran; a test to the "
                         "target may need more.");
  else if (ip + 1 == f.size() && f.size() > 1)
    r.warnings.push_back("The load is largest at the end of the curve: a test pushed beyond the target needs more "
                         "force than the load-cell range below.");
  if (!(fabs_max > 0))
    r.warnings.push_back("No footing load was recorded: the load-cell range and the power cannot be sized.");

  // Ground block.
  const bool has_block =
      std::isfinite(in.block_size_m[0]) && std::isfinite(in.block_size_m[1]) && std::isfinite(in.block_size_m[2]);
  const double vol = has_block ? in.block_size_m[0] * in.block_size_m[1] * in.block_size_m[2]
                               : std::numeric_limits<double>::quiet_NaN();
  const double mass = vol * in.rock_density_kg_m3;                           // NaN when either is unknown
  const double sigv = in.rock_density_kg_m3 * N * in.g0_m_s2 * (has_block ? in.block_size_m[2] : std::numeric_limits<double>::quiet_NaN());
  const double eps_f = in.sigma_c_Pa / in.young_Pa;

  // ---------------------------------------------------------------- Markdown
  std::ostringstream md;
  md << "# Centrifuge planning report\n\n"
     << "Scene `" << in.scene << "`, stage `" << in.stage << "`, g-level N = " << g4(N)
     << ". The run is the model of a centrifuge test at N g; the prototype is the full-scale footing it "
        "stands for, at 1 g. Scaling laws and sources: docs/theory.md §7.7.\n\n";

  if (!r.warnings.empty()) {
    md << "## Warnings\n\n";
    for (auto& w : r.warnings) md << "* **" << w << "**\n";
    md << "\n";
  }

  md << "## 1. Scaling laws (prototype / model)\n\n"
     << "| Quantity | Factor | Factor at N = " << g4(N) << " [-] |\n| --- | --- | --- |\n"
     << "| Gravity | 1/N | " << g4(1 / N) << " |\n"
     << "| Length, displacement | N | " << g4(N) << " |\n"
     << "| Area | N^2 | " << g4(N2) << " |\n"
     << "| Volume, mass | N^3 | " << g4(N3) << " |\n"
     << "| Force | N^2 | " << g4(N2) << " |\n"
     << "| Stress, pressure, strength, stiffness modulus | 1 | 1 |\n"
     << "| Strain, s / D | 1 | 1 |\n"
     << "| Density | 1 | 1 |\n"
     << "| Footing stiffness F / s | N | " << g4(N) << " |\n"
     << "| Time of inertial (dynamic) processes | N | " << g4(N) << " |\n"
     << "| Time of diffusion (consolidation, seepage) | N^2 | " << g4(N2) << " |\n"
     << "| Time of creep, viscous (rate-dependent) behaviour | 1 | 1 |\n"
     << "| Velocity (inertial time scaling) | 1 | 1 |\n\n";

  md << "## 2. Model and prototype side by side\n\n"
     << "| Quantity [unit] | Model (at N g) | Prototype (at 1 g) | Factor [-] |\n| --- | --- | --- | --- |\n"
     << "| Gravity [g] | " << g4(N) << " | 1 | 1/N |\n"
     << "| Footing diameter D_f [mm] | " << g4(D * 1e3) << " | " << g4(r.diameter_proto_m * 1e3) << " | N |\n"
     << "| Footing area A = pi D_f^2 / 4 [mm^2] | " << g4(r.area_model_m2 * 1e6) << " | "
     << g4(r.area_proto_m2 * 1e6) << " | N^2 |\n"
     << "| Target settlement [mm] | " << g4(r.target_model_m * 1e3) << " | " << g4(r.target_proto_m * 1e3)
     << " | N |\n";
  if (has_block) {
    auto box = [&](double k) {
      return g4(in.block_size_m[0] * k) + " x " + g4(in.block_size_m[1] * k) + " x " + g4(in.block_size_m[2] * k);
    };
    md << "| Modelled ground, x by y by z [mm] | " << box(1e3) << " | " << box(1e3 * N) << " | N |\n"
       << "| Ground volume [m^3] | " << g4(vol) << " | " << g4(vol * N3) << " | N^3 |\n";
    if (std::isfinite(mass))
      md << "| Ground mass (bulk density " << g4(in.rock_density_kg_m3) << " kg/m^3) [kg] | " << g4(mass) << " | "
         << g4(mass * N3) << " | N^3 |\n"
         << "| Self-weight vertical stress at the ground's base [kPa] | " << g4(sigv / 1e3) << " | "
         << g4(sigv / 1e3) << " | 1 |\n";
  }
  md << "| Peak load F_peak [N] | " << g4(r.peak_model_N) << " | " << g4(r.peak_proto_N) << " | N^2 |\n"
     << "| Settlement at the peak [mm] | " << g4(r.settlement_at_peak_model_m * 1e3) << " | "
     << g4(r.settlement_at_peak_proto_m * 1e3) << " | N |\n"
     << "| Peak bearing stress q = F_peak / A [kPa] | " << g4(r.peak_q_Pa / 1e3) << " | " << g4(r.peak_q_Pa / 1e3)
     << " | 1 |\n"
     << "| s / D_f at the peak [-] | " << g4(r.settlement_at_peak_model_m / D) << " | "
     << g4(r.settlement_at_peak_model_m / D) << " | 1 |\n"
     << "| Secant stiffness to the peak F_peak / s [N/m] | " << g4(r.secant_stiffness_model_N_m) << " | "
     << g4(r.secant_stiffness_proto_N_m) << " | N |\n";
  if (std::isfinite(in.sigma_c_Pa))
    md << "| Rock bond strength sigma_c [kPa] | " << g4(in.sigma_c_Pa / 1e3) << " | " << g4(in.sigma_c_Pa / 1e3)
       << " | 1 |\n";
  if (std::isfinite(in.young_Pa))
    md << "| Rock Young's modulus E [MPa] | " << g4(in.young_Pa / 1e6) << " | " << g4(in.young_Pa / 1e6)
       << " | 1 |\n";
  if (std::isfinite(eps_f))
    md << "| Failure strain sigma_c / E [-] | " << g4(eps_f) << " | " << g4(eps_f) << " | 1 |\n";
  md << "\nThe prototype is made of the same rock (same density, strength and stiffness) and carries the same "
        "stresses at homologous points, because its depth is N times larger and its gravity N times smaller.\n\n";

  md << "## 3. Time\n\n"
     << "| Process | Time factor (prototype / model) [-] | Applies to this run |\n| --- | --- | --- |\n"
     << "| Inertia, stress waves (dynamic) | N = " << g4(N)
     << " | only to the transient of the loading (speed ramp, wave transit), which the quasi-static criterion "
        "(docs/theory.md §7.6) keeps out of the curve |\n"
     << "| Diffusion: consolidation, seepage | N^2 = " << g4(N2) << " | no: dry ground, no pore fluid in the model |\n"
     << "| Creep, viscous (rate-dependent) behaviour | 1 | no: the contact, bond and continuum laws are "
        "rate-independent |\n\n"
     << "The footing is pushed quasi-statically into weakly cemented rock described by rate-independent laws. "
        "No material time enters the model, so the run's loading time (target / v = "
     << g4(r.loading_time_model_s) << " s at model scale) is a numerical choice made for computing cost, not a "
        "physical time: it maps to no prototype time. The load-settlement curve depends on settlement alone and "
        "scales with the length and force laws. A real weakly cemented rock that creeps or holds pore water would "
        "bring in a viscous (x 1) or a consolidation (x N^2) time scale, and the two cannot both be satisfied "
        "with the length scale N: that is outside this model.\n\n";

  const bool has_sc = std::isfinite(in.sigma_c_Pa) && in.sigma_c_Pa > 0;
  md << "## 4. Prototype footing and its load-settlement curve\n\n"
     << "Prototype footing: rigid circular footing, diameter " << g4(r.diameter_proto_m * 1e3) << " mm (model "
     << g4(D * 1e3) << " mm x N), area " << g4(r.area_proto_m2) << " m^2, pushed to "
     << g4(r.target_proto_m * 1e3) << " mm (" << g4(in.target_settlement_m / D)
     << " D_f). Peak load " << g4(r.peak_proto_N / 1e3) << " kN at " << g4(r.settlement_at_peak_proto_m * 1e3)
     << " mm; target settlement " << (r.target_reached ? "reached" : "NOT reached") << ".\n\n"
     << "Curve at 0.1, 0.2, ..., 1.0 of the largest settlement (" << g4(r.max_settlement_model_m * 1e3)
     << " mm model), interpolated linearly; s / D_f and q = F / A are the same at both scales.\n\n"
     << "| s model [mm] | F model [N] | s prototype [mm] | F prototype [kN] | s / D_f [-] | q = F / A [kPa] |"
     << (has_sc ? " q / sigma_c [-] |" : "") << "\n| --- | --- | --- | --- | --- | --- |" << (has_sc ? " --- |" : "")
     << "\n";
  for (auto& p : r.curve) {
    md << "| " << g4(p.settlement_model_m * 1e3) << " | " << g4(p.load_model_N) << " | "
       << g4(p.settlement_proto_m * 1e3) << " | " << g4(p.load_proto_N / 1e3) << " | " << g4(p.s_over_d) << " | "
       << g4(p.q_Pa / 1e3) << " |";
    if (has_sc) md << " " << g4(p.q_Pa / in.sigma_c_Pa) << " |";
    md << "\n";
  }
  md << "\n";

  md << "## 5. Demand on the rig\n\n"
     << "| Item [unit] | Model scale (the centrifuge rig) | Prototype equivalent (full-scale test) | Rule |\n"
     << "| --- | --- | --- | --- |\n"
     << "| Largest force max abs(F) [N] | " << g4(r.max_force_model_N) << " | " << g4(r.max_force_proto_N)
     << " | x N^2 |\n"
     << "| Load-cell range [N] | " << g4(r.load_cell_range_model_N) << " | " << g4(r.load_cell_range_proto_N)
     << " | margin " << g4(in.load_cell_margin) << " x largest force, rounded up to 1, 2 or 5 x 10^k N |\n"
     << "| Stroke [mm] | " << g4(r.stroke_model_m * 1e3) << " | " << g4(r.stroke_proto_m * 1e3)
     << " | target " << g4(in.target_settlement_m * 1e3) << " mm + run-up " << g4(in.ramp_travel_m * 1e3)
     << " mm + overtravel " << g4(in.overtravel_ratio * 100) << " % of the target (" << g4(overtravel * 1e3)
     << " mm); x N |\n"
     << "| Actuator speed (the run's) [mm/s] | " << g4(vmm) << " | " << g4(r.speed_proto_m_s * 1e3)
     << " | x 1 (inertial time scaling) |\n"
     << "| Power at the run's speed, max abs(F) x v [W] | " << g4(r.power_model_W) << " | " << g4(r.power_proto_W)
     << " | x N^2 |\n"
     << "| Power at 1 mm/s [W] | " << g4(r.power_model_rig_max_W) << " | "
     << g4(r.max_force_proto_N * kRigSpeedMax_m_s) << " | x N^2 |\n"
     << "| Time to the target at the run's speed [s] | " << g4(r.loading_time_model_s) << " | n/a | not a physical "
        "time (section 3) |\n"
     << "| Time to the target at 1 mm/s / at 0.01 mm/s [s] | " << g4(in.target_settlement_m / kRigSpeedMax_m_s)
     << " / " << g4(in.target_settlement_m / kRigSpeedMin_m_s) << " | " << g4(r.target_proto_m / kRigSpeedMax_m_s)
     << " / " << g4(r.target_proto_m / kRigSpeedMin_m_s) << " | target / speed |\n\n"
     << "A real centrifuge actuator pushes at about 0.01 to 1 mm/s (assumed here); the run's speed is "
     << g4(r.speed_over_rig_max)
     << " times 1 mm/s. The curve holds at a rig's speed only if the run was quasi-static (docs/theory.md §7.6): "
     << qs_text << "\n";
  r.markdown = md.str();

  // ---------------------------------------------------------------- JSON
  std::ostringstream js;
  js << "{\"scene\": " << jstr(in.scene) << ", \"stage\": " << jstr(in.stage) << ", \"g_level\": " << jnum(N)
     << ", \"g0_m_s2\": " << jnum(in.g0_m_s2) << ",\n"
     << " \"scale_factors\": {\"length\": " << jnum(N) << ", \"area\": " << jnum(N2) << ", \"volume\": " << jnum(N3)
     << ", \"mass\": " << jnum(N3) << ", \"force\": " << jnum(N2) << ", \"stress\": 1, \"strain\": 1"
     << ", \"stiffness_F_per_s\": " << jnum(N) << ", \"time_dynamic\": " << jnum(N)
     << ", \"time_diffusion\": " << jnum(N2) << ", \"time_viscous\": 1, \"velocity_dynamic\": 1},\n"
     << " \"time_scale_applies\": \"none: quasi-static, rate-independent; the loading time is not physical\",\n"
     << " \"footing\": {\"diameter_model_m\": " << jnum(D) << ", \"diameter_prototype_m\": " << jnum(r.diameter_proto_m)
     << ", \"area_model_m2\": " << jnum(r.area_model_m2) << ", \"area_prototype_m2\": " << jnum(r.area_proto_m2)
     << ", \"target_settlement_model_m\": " << jnum(r.target_model_m)
     << ", \"target_settlement_prototype_m\": " << jnum(r.target_proto_m)
     << ", \"target_reached\": " << (r.target_reached ? "true" : "false") << "},\n"
     << " \"ground\": {\"block_model_m\": [" << jnum(in.block_size_m[0]) << ", " << jnum(in.block_size_m[1]) << ", "
     << jnum(in.block_size_m[2]) << "], \"block_prototype_m\": [" << jnum(in.block_size_m[0] * N) << ", "
     << jnum(in.block_size_m[1] * N) << ", " << jnum(in.block_size_m[2] * N)
     << "], \"density_kg_m3\": " << jnum(in.rock_density_kg_m3) << ", \"mass_model_kg\": " << jnum(mass)
     << ", \"mass_prototype_kg\": " << jnum(mass * N3) << ", \"sigma_v_base_Pa\": " << jnum(sigv)
     << ", \"sigma_c_Pa\": " << jnum(in.sigma_c_Pa) << ", \"young_Pa\": " << jnum(in.young_Pa) << "},\n"
     << " \"peak\": {\"load_model_N\": " << jnum(r.peak_model_N) << ", \"load_prototype_N\": " << jnum(r.peak_proto_N)
     << ", \"settlement_model_m\": " << jnum(r.settlement_at_peak_model_m)
     << ", \"settlement_prototype_m\": " << jnum(r.settlement_at_peak_proto_m) << ", \"q_Pa\": " << jnum(r.peak_q_Pa)
     << ", \"s_over_D\": " << jnum(r.settlement_at_peak_model_m / D)
     << ", \"secant_stiffness_model_N_m\": " << jnum(r.secant_stiffness_model_N_m)
     << ", \"secant_stiffness_prototype_N_m\": " << jnum(r.secant_stiffness_proto_N_m) << "},\n"
     << " \"curve\": {\"settlement_model_m\": " << jarr(r.curve, [](auto& p) { return p.settlement_model_m; })
     << ", \"load_model_N\": " << jarr(r.curve, [](auto& p) { return p.load_model_N; })
     << ", \"settlement_prototype_m\": " << jarr(r.curve, [](auto& p) { return p.settlement_proto_m; })
     << ", \"load_prototype_N\": " << jarr(r.curve, [](auto& p) { return p.load_proto_N; })
     << ", \"s_over_D\": " << jarr(r.curve, [](auto& p) { return p.s_over_d; })
     << ", \"q_Pa\": " << jarr(r.curve, [](auto& p) { return p.q_Pa; }) << "},\n"
     << " \"rig\": {\"load_cell_margin\": " << jnum(in.load_cell_margin)
     << ", \"max_force_model_N\": " << jnum(r.max_force_model_N)
     << ", \"max_force_prototype_N\": " << jnum(r.max_force_proto_N)
     << ", \"load_cell_range_model_N\": " << jnum(r.load_cell_range_model_N)
     << ", \"load_cell_range_prototype_N\": " << jnum(r.load_cell_range_proto_N)
     << ", \"stroke_model_m\": " << jnum(r.stroke_model_m) << ", \"stroke_prototype_m\": " << jnum(r.stroke_proto_m)
     << ", \"ramp_travel_model_m\": " << jnum(in.ramp_travel_m) << ", \"overtravel_ratio\": " << jnum(in.overtravel_ratio)
     << ", \"speed_model_m_s\": " << jnum(r.speed_model_m_s) << ", \"speed_prototype_m_s\": " << jnum(r.speed_proto_m_s)
     << ", \"power_model_W\": " << jnum(r.power_model_W) << ", \"power_prototype_W\": " << jnum(r.power_proto_W)
     << ", \"power_model_at_1mm_s_W\": " << jnum(r.power_model_rig_max_W)
     << ", \"loading_time_model_s\": " << jnum(r.loading_time_model_s)
     << ", \"speed_over_rig_max\": " << jnum(r.speed_over_rig_max)
     << ", \"speed_realistic\": " << (r.speed_realistic ? "true" : "false")
     << ", \"quasi_static\": " << jbool_or_null(qs) << ", \"impedance_ratio\": " << jnum(in.impedance_ratio)
     << ", \"quasi_static_limit\": " << jnum(in.quasi_static_limit) << "},\n"
     << " \"warnings\": [";
  for (std::size_t i = 0; i < r.warnings.size(); ++i) js << (i ? ", " : "") << jstr(r.warnings[i]);
  js << "]}";
  r.json = js.str();
  return r;
}

}  // namespace demfdm::coord
