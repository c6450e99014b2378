#include "coordinator/core/progress.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

namespace demfdm::coord {
namespace {

std::string grouped(std::int64_t n) {
  std::string s = std::to_string(n), out;
  int k = 0;
  for (auto it = s.rbegin(); it != s.rend(); ++it) {
    if (k > 0 && k % 3 == 0 && *it != '-') out.insert(out.begin(), ',');
    out.insert(out.begin(), *it);
    ++k;
  }
  return out;
}

std::string num(const char* fmt, double v) {
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

// The value `key` of any node's report (the first role that has it), or NaN.
double value(const std::map<std::string, NodeReport>& reps, const std::string& role, const std::string& key) {
  auto it = reps.find(role);
  if (it == reps.end()) return std::numeric_limits<double>::quiet_NaN();
  auto jt = it->second.values.find(key);
  return jt == it->second.values.end() ? std::numeric_limits<double>::quiet_NaN() : jt->second;
}

}  // namespace

std::string clock_text(double s) {
  if (!std::isfinite(s) || s < 0) return "-";
  auto t = static_cast<std::int64_t>(std::llround(s));
  char b[48];
  std::snprintf(b, sizeof b, "%lld:%02lld:%02lld", static_cast<long long>(t / 3600),
                static_cast<long long>(t / 60 % 60), static_cast<long long>(t % 60));
  return b;
}

std::optional<std::string> Progress::observe(const schema::Stage& st, std::int64_t stage_first_step, std::int64_t step,
                                             const std::map<std::string, NodeReport>& reps,
                                             std::chrono::steady_clock::time_point now, bool force) {
  const std::int64_t done = step - stage_first_step + 1;
  if (st.name != stage_) {  // a new stage: start its clock, say nothing yet
    stage_ = st.name;
    t_last_ = now;
    step_last_ = done;
    have_last_ = false;
    crit_last_ = 0;
    return std::nullopt;
  }
  const double dt = std::chrono::duration<double>(now - t_last_).count();
  if (!force && dt < every_s_) return std::nullopt;
  const double rate = dt > 0 ? static_cast<double>(done - step_last_) / dt : 0.0;
  std::string line = st.name + "  step " + grouped(done) + " of " + grouped(st.steps);
  double eta = std::numeric_limits<double>::quiet_NaN();
  bool bound = false;
  const double disp = value(reps, "dem", "footing_disp_m");
  if (st.kind == schema::Action::kPenetrate && std::isfinite(disp) && d_f_ > 0) {
    const double target = st.view.real("depth_ratio") * d_f_;
    line += " | settlement " + num("%.3g", disp / d_f_) + " D_f of " + num("%.3g", target / d_f_) + " (" +
            num("%.0f", 100.0 * disp / target) + " %)";
    const double load = value(reps, "dem", "footing_fz_N");
    if (std::isfinite(load)) line += " | load " + num("%.4g", load) + " N";
    const double speed = have_last_ && dt > 0 ? (disp - crit_last_) / dt : 0.0;
    if (speed > 0) eta = (target - disp) / speed;
    crit_last_ = disp;
  } else if (st.until_done) {
    // The largest unbalanced-force ratio of the stage's nodes (the DEM's skeleton ratio under
    // gravity) against the stage's target.
    double r = std::numeric_limits<double>::quiet_NaN();
    for (auto& role : st.nodes) {
      double v = value(reps, role, "ratio_skeleton");
      if (!std::isfinite(v)) v = value(reps, role, "ratio");
      if (std::isfinite(v)) r = std::isfinite(r) ? std::max(r, v) : v;
    }
    if (std::isfinite(r)) line += " | ratio " + num("%.2e", r) + " -> " + num("%.1e", st.view.real("ratio"));
    if (rate > 0) eta = static_cast<double>(st.steps - done) / rate, bound = true;
  } else if (rate > 0) {
    eta = static_cast<double>(st.steps - done) / rate;
  }
  if (rate > 0) line += " | " + grouped(static_cast<std::int64_t>(std::llround(rate))) + " steps/s";
  line += " | ETA " + std::string(bound ? "<= " : "") + clock_text(eta);
  t_last_ = now;
  step_last_ = done;
  have_last_ = true;
  return line;
}

}  // namespace demfdm::coord
