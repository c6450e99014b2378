// The result of a footing run (issue 14 item 2), read back from the run folder's penetration
// history (history_<i>_<stage>.csv) so that a resumed run reports the same result as an
// uninterrupted one. Independent of the transport.
//
// Measures (model scale), docs/paper-study.md:
//  * peak load: the largest footing load of the stage, and the settlement at it;
//  * final load and settlement: the last row;
//  * k_e: the elastic stiffness, the least-squares slope of load against settlement from the
//    first row with a load to the last row before the first ball-ball bond failure (at least 5
//    rows; the same rule as launch/py/paper_figures.elastic_stiffness);
//  * bonds broken in tension and in shear (the DEM's STAGE_END values);
//  * target reached: the settlement reached depth_ratio D_f (the stage's criterion).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace demfdm::coord {

struct FootingResult {
  std::string stage;
  double diameter_m = 0, target_m = 0;
  double peak_N = 0, settlement_at_peak_m = 0;
  double final_N = 0, final_settlement_m = 0;
  double k_e_N_m = 0;               // NaN when the elastic branch has fewer than 5 rows
  std::int64_t elastic_rows = 0;
  double bonds_broken_tension = 0, bonds_broken_shear = 0;  // NaN when not reported
  bool target_reached = false;
  std::vector<double> settlement_m, load_N;  // the curve (every row)
};

// Reads the columns dem.footing_disp_m, dem.footing_fz_N (and dem.bond_failures if present)
// of a stage history CSV. Throws std::runtime_error naming the file when it cannot be read or
// lacks the footing columns, std::invalid_argument on an empty or non-finite curve.
FootingResult footing_result(const std::string& history_csv, const std::string& stage, double diameter_m,
                             double target_m);

// The result block printed at the end of a run and written to summary.txt (a few lines).
std::string result_text(const FootingResult& r);
// The same values as a JSON object (non-finite values as null).
std::string result_json(const FootingResult& r);

}  // namespace demfdm::coord
