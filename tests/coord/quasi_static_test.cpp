// Footing rate, speed ramp and quasi-static measures of the penetrate stage
// (coordinator/core/quasi_static.hpp), the stage clock the ramp reads (Runner::grant_clock), and
// the summary's warning. No LCM, no nodes.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "coordinator/core/quasi_static.hpp"
#include "coordinator/core/runner.hpp"
#include "coordinator/core/summary.hpp"

using namespace demfdm;

namespace {
// Hand-computed numbers of the paper's rock: E = E50 of the UCS study, nu = 1/3, rho_b = 1272.
constexpr double kE = 1.083e9, kNu = 1.0 / 3.0, kRho = 1272.0, kSigmaC = 0.45e6;
// M = E (1 - 1/3) / ((4/3) (1/3)) = 1.5 E = 1.6245e9 Pa; c = sqrt(1.6245e9 / 1272) = sqrt(1277122.64)
// = 1130.0985 m/s (1130.1^2 = 1277126.01, 3.37 too much: 1130.1 - 3.37 / 2260.2).
constexpr double kM = 1.6245e9, kC = 1130.0985;
}  // namespace

TEST(QuasiStatic, PWaveModulusAndSpeedAgainstHandNumbers) {
  EXPECT_NEAR(coord::p_wave_modulus(kE, kNu), kM, 1e-12 * kM);
  EXPECT_NEAR(coord::p_wave_speed(kE, kNu, kRho), kC, 1e-4);
  // nu = 0: M = E; nu = 0.25: M = E 0.75 / (1.25 x 0.5) = 1.2 E.
  EXPECT_DOUBLE_EQ(coord::p_wave_modulus(2e9, 0.0), 2e9);
  EXPECT_NEAR(coord::p_wave_modulus(2e9, 0.25), 2.4e9, 1e-3);
  // Not the bar speed sqrt(E / rho_b) = 922.7 m/s.
  EXPECT_GT(coord::p_wave_speed(kE, kNu, kRho), 1100.0);
}

TEST(QuasiStatic, ImpedanceAndStrainRateRatiosAgainstHandNumbers) {
  // v = 4 m/s: rho_b c v = 1272 x 1130.0985 x 4 = 5.750005e6 Pa -> / 0.45e6 = 12.7778;
  // eps_f = 0.45e6 / 1.083e9 = 4.15512e-4, c eps_f = 0.469566 m/s -> v / (c eps_f) = 8.5184.
  auto m = coord::rate_measures(4.0, 1e-2, 6e-6, kE, kNu, kRho, kSigmaC, 0.1);
  ASSERT_TRUE(m.applicable());
  EXPECT_NEAR(m.wave_speed, kC, 1e-4);
  EXPECT_NEAR(*m.bond_strength, kSigmaC, 0.0);
  EXPECT_NEAR(*m.failure_strain, 4.15512e-4, 1e-9);
  EXPECT_NEAR(*m.impedance_ratio, 12.7776, 1e-3);
  EXPECT_NEAR(*m.strain_rate_ratio, 8.5184, 1e-3);
  // The two ratios differ by M / E (= 1.5 at nu = 1/3).
  EXPECT_NEAR(*m.impedance_ratio / *m.strain_rate_ratio, 1.5, 1e-12);
  EXPECT_FALSE(m.quasi_static());
  // 100 times slower: 0.128 > 0.1 still; 1000 times slower: 0.0128, quasi-static.
  EXPECT_FALSE(coord::rate_measures(0.04, 1e-4, 0, kE, kNu, kRho, kSigmaC, 0.1).quasi_static());
  EXPECT_TRUE(coord::rate_measures(0.004, 1e-5, 0, kE, kNu, kRho, kSigmaC, 0.1).quasi_static());
}

TEST(QuasiStatic, WithoutAFiniteBondTheMeasuresDoNotApply) {
  const double inf = std::numeric_limits<double>::infinity();
  for (auto sc : {std::optional<double>{}, std::optional<double>{0.0}, std::optional<double>{inf}}) {
    auto m = coord::rate_measures(4.0, 1e-2, 0, kE, kNu, kRho, sc, 0.1);
    EXPECT_FALSE(m.applicable());
    EXPECT_FALSE(m.impedance_ratio || m.strain_rate_ratio || m.failure_strain || m.bond_strength);
    EXPECT_TRUE(m.quasi_static());
    EXPECT_NE(coord::describe(m).find("rho_b c v / sigma_c n/a"), std::string::npos) << coord::describe(m);
    EXPECT_EQ(coord::quasi_static_warning("penetrate", m), "");
  }
}

TEST(QuasiStatic, FootingSpeedIsTheRateRuleBitForBit) {
  // The paper's default scene: I = 1e-2, L_p = 3 D_f, D_f = 1.2 mm, d50 = 0.116 mm x 1.5,
  // rho_s = 2650, P = 1 MPa: v = 3.6e-5 / (1.74e-4 x 0.0514782) = 4.0191 m/s.
  double v = coord::footing_speed(1e-2, 3.0, 1.2e-3, 0.116e-3, 1.5, 2650.0, 1e6, 1.0);
  EXPECT_NEAR(v, 4.01911, 1e-5);
  // The coordinator's expression before the ramp, operation for operation.
  volatile double I = 1e-2, ratio = 3.0, df = 1.2e-3, d50 = 0.116e-3, scale = 1.5, rho = 2650.0, p = 1e6, f = 2.5;
  double d = d50 * scale, lp = ratio * df;
  double old = I * lp / (d * std::sqrt(rho / p));
  EXPECT_EQ(coord::footing_speed(I, ratio, df, d50, scale, rho, p, f), old * f);
}

TEST(QuasiStatic, RampProfileIsLinearFromZeroToFullSpeed) {
  const double v = 4.0191, df = 1.2e-3, ratio = 0.01;
  const double tr = coord::ramp_time(ratio, df, v);
  EXPECT_NEAR(tr, 2 * 0.01 * 1.2e-3 / 4.0191, 1e-20);  // 5.9715e-6 s
  EXPECT_EQ(coord::ramped_speed(v, 0.0, tr), 0.0);
  EXPECT_NEAR(coord::ramped_speed(v, 0.25 * tr, tr), 0.25 * v, 1e-12);
  EXPECT_NEAR(coord::ramped_speed(v, 0.5 * tr, tr), 0.5 * v, 1e-12);
  EXPECT_NEAR(coord::ramped_speed(v, 0.9 * tr, tr), 0.9 * v, 1e-12);
  EXPECT_EQ(coord::ramped_speed(v, tr, tr), v);
  EXPECT_EQ(coord::ramped_speed(v, 7 * tr, tr), v);
  // No ramp: the speed itself at any time, bit for bit.
  EXPECT_EQ(coord::ramp_time(0.0, df, v), 0.0);
  for (double t : {0.0, 1e-9, 1.0}) EXPECT_EQ(coord::ramped_speed(v, t, 0.0), v);
}

TEST(QuasiStatic, RampMovesTheFootingRampDepthRatioTimesDf) {
  // Midpoint speeds of steps of dt = t_r / n: the displacement during the ramp is v t_r / 2 =
  // ramp_depth_ratio D_f to rounding.
  const double v = 4.0191, df = 1.2e-3, ratio = 0.01;
  const double tr = coord::ramp_time(ratio, df, v);
  for (int n : {1, 7, 1000}) {
    const double dt = tr / n;
    double x = 0;
    for (int k = 0; k < n; ++k) x += coord::ramped_speed(v, (k + 0.5) * dt, tr) * dt;
    EXPECT_NEAR(x, ratio * df, 1e-12 * ratio * df) << n << " steps";
    EXPECT_NEAR(x, 0.5 * v * tr, 1e-12 * ratio * df);
  }
}

namespace {
// Records every grant's dt and values; the dem node's stable step changes from grant to grant.
class ClockDriver : public coord::Driver {
 public:
  struct Grant {
    std::int64_t last;
    double dt;
    std::vector<double> values;
  };
  std::vector<Grant> grants;
  int reports = 0;
  void post(coord::Cmd cmd, const std::vector<std::string>&, std::int64_t step, std::int32_t, const std::string&,
            double dt, const std::vector<double>& values) override {
    if (cmd == coord::Cmd::Grant) grants.push_back({step, dt, values});
  }
  std::map<std::string, coord::NodeReport> collect(coord::Cmd, const std::vector<std::string>& targets, std::int64_t,
                                                   std::int32_t) override {
    std::map<std::string, coord::NodeReport> out;
    ++reports;
    for (auto& t : targets) {
      coord::NodeReport r;
      r.dt_stable = reports % 2 ? 1e-8 : 1.5e-8;
      out[t] = r;
    }
    return out;
  }
};
}  // namespace

TEST(QuasiStatic, GrantClockCountsTheStagesOwnTimeFromItsFirstGlobalStep) {
  auto sc = config::Scene::parse(
      "[dem]\n[dem.footing]\n"
      "[[stage]]\nname = \"settle\"\nsteps = 7\n"
      "[[stage]]\nname = \"penetrate\"\naction = \"penetrate\"\nsteps = 400\nsteps_per_grant = 3\n",
      "test.toml", schema::scene_schema());
  ClockDriver d;
  coord::Runner r(schema::stages(sc), d, {{"dem", 1e-8}});
  const double v = 2.0, tr = 2e-6;  // the footing reaches v after t_r = 2e-6 s (about 160 steps)
  std::vector<coord::GrantClock> clocks;
  r.set_kinematics([&](const schema::Stage& st, std::int64_t last, double dt) -> std::vector<double> {
    const auto& c = r.grant_clock();
    EXPECT_EQ(c.last_step, last);
    EXPECT_EQ(c.dt, dt);
    if (st.action != "penetrate") return {};
    clocks.push_back(c);
    return {coord::ramped_speed(v, c.t_mid(), tr)};
  });
  r.run();
  ASSERT_EQ(clocks.size(), 134u);  // 133 grants of 3 steps + 1 of 1
  // The stage starts at global step 7, not 0: its first grant is at the start of the ramp.
  EXPECT_EQ(clocks.front().stage_index, 1);
  EXPECT_EQ(clocks.front().stage_first_step, 7);
  EXPECT_EQ(clocks.front().first_step, 7);
  EXPECT_EQ(clocks.front().last_step, 9);
  EXPECT_EQ(clocks.front().t_begin, 0.0);
  EXPECT_EQ(clocks.back().first_step, 406);
  EXPECT_EQ(clocks.back().last_step, 406);
  // Each grant starts where the previous one ended, whatever its dt; the speed is the ramp's at
  // the middle of the grant, so the displacement is the integral of the ramp to rounding.
  double t = 0, x = 0, t_in = 0;  // displacement and end time of the grants wholly inside the ramp
  std::size_t g0 = d.grants.size() - clocks.size();
  for (std::size_t i = 0; i < clocks.size(); ++i) {
    const auto& c = clocks[i];
    const auto& g = d.grants[g0 + i];
    EXPECT_NEAR(c.t_begin, t, 1e-20);
    EXPECT_EQ(g.dt, c.dt);
    const double n = static_cast<double>(c.last_step - c.first_step + 1);
    ASSERT_EQ(g.values.size(), 1u);
    EXPECT_NEAR(g.values[0], v * std::min(1.0, (t + 0.5 * n * c.dt) / tr), 1e-12);
    if (t + n * c.dt <= tr) {
      x += g.values[0] * n * c.dt;
      t_in = t + n * c.dt;
    }
    t += n * c.dt;
  }
  // The midpoint of a grant integrates the linear ramp exactly: x = v t^2 / (2 t_r).
  EXPECT_GT(t_in, 0.9 * tr);
  EXPECT_NEAR(x, v * t_in * t_in / (2 * tr), 1e-12 * v * tr);
  EXPECT_GT(d.grants[g0].dt, 0.0);
  EXPECT_NE(d.grants[g0].dt, d.grants[g0 + 1].dt);  // dt really changes between grants
  EXPECT_GT(t, tr);
  EXPECT_LT(d.grants[g0].values[0], 0.02 * v);  // the first grant is slow
  EXPECT_EQ(d.grants.back().values[0], v);
}

namespace {
coord::RunSummary penetrating_run() {
  coord::RunSummary sum;
  coord::StageSummary a, b;
  a.name = "gravity";
  a.action = "couple";
  b.name = "push";
  b.action = "penetrate";
  b.first_step = 10;
  b.last_step = 19;
  sum.stages = {a, b};
  return sum;
}
}  // namespace

TEST(QuasiStatic, SummaryWarnsAboveTheLimitOnly) {
  auto sum = penetrating_run();
  coord::RunInfo info;
  info.scene = "s.toml";
  // Above: the default scene's rate (12.8 > 0.1).
  info.rates[1] = coord::rate_measures(4.0191, 1e-2, 5.97e-6, kE, kNu, kRho, kSigmaC, 0.1);
  auto text = coord::summary_text(info, sum);
  EXPECT_NE(text.find("\nWARNING: not quasi-static: stage 'push': rho_b c v / sigma_c = 12.84 > quasi_static_limit 0.1"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("footing rate: v 4.019 m/s, I 0.01, ramp 5.97e-06 s, c 1130 m/s"), std::string::npos) << text;
  EXPECT_NE(text.find("v / (c eps_f) 8.559"), std::string::npos) << text;
  auto json = coord::summary_json(info, sum);
  EXPECT_NE(json.find("\"footing_rate\": {\"speed_m_s\": 4.0191,"), std::string::npos) << json;
  EXPECT_NE(json.find("\"impedance_ratio\": 12.8"), std::string::npos) << json;
  EXPECT_NE(json.find("\"quasi_static\": false"), std::string::npos) << json;
  EXPECT_EQ(json.find("nan"), std::string::npos);

  // Below: 1000 times slower.
  info.rates[1] = coord::rate_measures(4.0191e-3, 1e-5, 0, kE, kNu, kRho, kSigmaC, 0.1);
  text = coord::summary_text(info, sum);
  EXPECT_EQ(text.find("WARNING"), std::string::npos) << text;
  EXPECT_NE(text.find("ramp none"), std::string::npos) << text;
  json = coord::summary_json(info, sum);
  EXPECT_NE(json.find("\"quasi_static\": true"), std::string::npos) << json;

  // Just above a raised limit: still a warning; the limit is the stage's.
  info.rates[1] = coord::rate_measures(4.0191, 1e-2, 0, kE, kNu, kRho, kSigmaC, 12.0);
  EXPECT_NE(coord::summary_text(info, sum).find("> quasi_static_limit 12 ("), std::string::npos);
  info.rates[1].limit = 13.0;
  EXPECT_EQ(coord::summary_text(info, sum).find("WARNING"), std::string::npos);

  // No bond: "n/a" in the text; neither the ratios nor a quasi_static field in JSON.
  info.rates[1] = coord::rate_measures(4.0191, 1e-2, 0, kE, kNu, kRho, std::nullopt, 0.1);
  text = coord::summary_text(info, sum);
  EXPECT_NE(text.find("rho_b c v / sigma_c n/a"), std::string::npos) << text;
  EXPECT_EQ(text.find("WARNING"), std::string::npos) << text;
  json = coord::summary_json(info, sum);
  EXPECT_EQ(json.find("impedance_ratio"), std::string::npos) << json;
  EXPECT_EQ(json.find("quasi_static\":"), std::string::npos) << json;
  EXPECT_EQ(json.find("null"), std::string::npos) << json;
}
