#include "coordinator/core/results.hpp"

#include "coordinator/core/summary.hpp"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

namespace demfdm::coord {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string num(const char* fmt, double v) {
  if (!std::isfinite(v)) return "n/a";
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}
// Every digit: a reader compares the result with the history it was read from.
std::string jnum(double v) {
  if (!std::isfinite(v)) return "null";
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

}  // namespace

FootingResult footing_result(const std::string& path, const std::string& stage, double diameter_m, double target_m) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot read the stage history");
  std::string line;
  std::getline(f, line);
  std::map<std::string, std::size_t> col;
  {
    std::stringstream hs(line);
    std::string c;
    for (std::size_t i = 0; std::getline(hs, c, ','); ++i) col[c] = i;
  }
  for (const char* need : {"dem.footing_disp_m", "dem.footing_fz_N"})
    if (!col.count(need)) throw std::runtime_error(path + ": no column " + need + " (not a footing stage history)");
  const std::size_t id = col["dem.footing_disp_m"], il = col["dem.footing_fz_N"];
  const bool has_fail = col.count("dem.bond_failures") > 0;
  const std::size_t ib = has_fail ? col["dem.bond_failures"] : 0;
  FootingResult r;
  r.stage = stage;
  r.diameter_m = diameter_m;
  r.target_m = target_m;
  std::vector<double> failures;
  while (std::getline(f, line)) {
    std::vector<double> v;
    std::stringstream ss(line);
    std::string c;
    while (std::getline(ss, c, ',')) v.push_back(std::strtod(c.c_str(), nullptr));
    if (v.size() <= std::max(id, std::max(il, ib))) continue;
    r.settlement_m.push_back(v[id]);
    r.load_N.push_back(v[il]);
    failures.push_back(has_fail ? v[ib] : kNaN);
  }
  const std::size_t n = r.load_N.size();
  if (n == 0) throw std::invalid_argument(path + ": the footing curve has no rows");
  for (std::size_t i = 0; i < n; ++i)
    if (!std::isfinite(r.load_N[i]) || !std::isfinite(r.settlement_m[i]))
      throw std::invalid_argument(path + ": non-finite footing load or settlement in data row " + std::to_string(i + 1));
  std::size_t ip = 0;
  for (std::size_t i = 1; i < n; ++i)
    if (r.load_N[i] > r.load_N[ip]) ip = i;
  r.peak_N = r.load_N[ip];
  r.settlement_at_peak_m = r.settlement_m[ip];
  r.final_N = r.load_N.back();
  r.final_settlement_m = r.settlement_m.back();
  r.target_reached = r.final_settlement_m >= target_m * (1 - 1e-12);
  // Elastic branch: first loaded row to the last row before the first bond failure.
  r.k_e_N_m = kNaN;
  if (has_fail) {
    std::size_t i0 = 0;
    while (i0 < n && !(r.load_N[i0] > 0)) ++i0;
    if (i0 < n) {
      std::size_t ie = i0;
      while (ie + 1 < n && failures[ie + 1] <= failures[i0]) ++ie;
      r.elastic_rows = static_cast<std::int64_t>(ie - i0 + 1);
      if (r.elastic_rows >= 5) {
        double sx = 0, sy = 0, sxx = 0, sxy = 0;
        const double m = static_cast<double>(r.elastic_rows);
        for (std::size_t i = i0; i <= ie; ++i) {
          sx += r.settlement_m[i];
          sy += r.load_N[i];
        }
        const double mx = sx / m, my = sy / m;
        for (std::size_t i = i0; i <= ie; ++i) {
          sxx += (r.settlement_m[i] - mx) * (r.settlement_m[i] - mx);
          sxy += (r.settlement_m[i] - mx) * (r.load_N[i] - my);
        }
        r.k_e_N_m = sxx > 0 ? sxy / sxx : kNaN;
      }
    }
  }
  r.bonds_broken_tension = r.bonds_broken_shear = kNaN;
  return r;
}

std::string result_text(const FootingResult& r) {
  std::ostringstream os;
  const double d = r.diameter_m;
  os << "result (stage '" << r.stage << "', footing D_f " << num("%.4g", d * 1e3) << " mm, model scale):\n"
     << "  peak load           " << num("%.4g", r.peak_N) << " N at settlement " << num("%.4g", r.settlement_at_peak_m * 1e3)
     << " mm (" << num("%.3g", r.settlement_at_peak_m / d) << " D_f)\n"
     << "  final load          " << num("%.4g", r.final_N) << " N at settlement " << num("%.4g", r.final_settlement_m * 1e3)
     << " mm (" << num("%.3g", r.final_settlement_m / d) << " D_f)\n"
     << "  initial stiffness   k_e " << num("%.4g", r.k_e_N_m) << " N/m (elastic branch, " << r.elastic_rows
     << " steps before the first bond failure)\n"
     << "  bonds broken        " << num("%.0f", r.bonds_broken_tension) << " in tension, "
     << num("%.0f", r.bonds_broken_shear) << " in shear\n"
     << "  target settlement   " << num("%.4g", r.target_m * 1e3) << " mm (" << num("%.3g", r.target_m / d) << " D_f): "
     << (r.target_reached ? "reached" : "NOT reached") << "\n";
  return os.str();
}

std::string result_json(const FootingResult& r) {
  std::ostringstream os;
  os << "{\"stage\": \"" << r.stage << "\", \"footing_diameter_m\": " << jnum(r.diameter_m)
     << ", \"peak_N\": " << jnum(r.peak_N) << ", \"settlement_at_peak_m\": " << jnum(r.settlement_at_peak_m)
     << ", \"final_N\": " << jnum(r.final_N) << ", \"final_settlement_m\": " << jnum(r.final_settlement_m)
     << ", \"k_e_N_m\": " << jnum(r.k_e_N_m) << ", \"elastic_rows\": " << r.elastic_rows
     << ", \"bonds_broken_tension\": " << jnum(r.bonds_broken_tension)
     << ", \"bonds_broken_shear\": " << jnum(r.bonds_broken_shear) << ", \"target_settlement_m\": " << jnum(r.target_m)
     << ", \"target_reached\": " << (r.target_reached ? "true" : "false") << "}";
  return os.str();
}

}  // namespace demfdm::coord
