// Centrifuge planning report (coordinator/core/centrifuge.hpp, docs/theory.md §7.7): scaling of
// a footing run at N g to prototype scale and the rig's demand, against hand-computed numbers.
#include <gtest/gtest.h>

#include <cctype>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "coordinator/core/centrifuge.hpp"

using namespace demfdm::coord;

namespace {
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kPi = 3.14159265358979323846;

// A minimal JSON validator (RFC 8259 grammar, no semantic checks): true when s is exactly one value.
struct JsonCheck {
  const std::string& s;
  std::size_t i = 0;
  void ws() {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\n' || s[i] == '\t' || s[i] == '\r')) ++i;
  }
  bool lit(const char* w) {
    std::string t(w);
    if (s.compare(i, t.size(), t) != 0) return false;
    i += t.size();
    return true;
  }
  bool str() {
    if (s[i] != '"') return false;
    for (++i; i < s.size(); ++i) {
      if (s[i] == '\\') {
        ++i;
        continue;
      }
      if (static_cast<unsigned char>(s[i]) < 0x20) return false;
      if (s[i] == '"') {
        ++i;
        return true;
      }
    }
    return false;
  }
  bool num() {
    std::size_t b = i;
    if (s[i] == '-') ++i;
    if (i >= s.size() || !std::isdigit(static_cast<unsigned char>(s[i]))) return false;
    while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i;
    if (i < s.size() && s[i] == '.') {
      ++i;
      if (i >= s.size() || !std::isdigit(static_cast<unsigned char>(s[i]))) return false;
      while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i;
    }
    if (i < s.size() && (s[i] == 'e' || s[i] == 'E')) {
      ++i;
      if (i < s.size() && (s[i] == '+' || s[i] == '-')) ++i;
      if (i >= s.size() || !std::isdigit(static_cast<unsigned char>(s[i]))) return false;
      while (i < s.size() && std::isdigit(static_cast<unsigned char>(s[i]))) ++i;
    }
    return i > b;
  }
  bool value() {
    ws();
    if (i >= s.size()) return false;
    char c = s[i];
    if (c == '{') {
      ++i;
      ws();
      if (s[i] == '}') return ++i, true;
      for (;;) {
        ws();
        if (!str()) return false;
        ws();
        if (s[i++] != ':') return false;
        if (!value()) return false;
        ws();
        if (s[i] == ',') {
          ++i;
          continue;
        }
        return s[i++] == '}';
      }
    }
    if (c == '[') {
      ++i;
      ws();
      if (s[i] == ']') return ++i, true;
      for (;;) {
        if (!value()) return false;
        ws();
        if (s[i] == ',') {
          ++i;
          continue;
        }
        return s[i++] == ']';
      }
    }
    if (c == '"') return str();
    if (c == 't') return lit("true");
    if (c == 'f') return lit("false");
    if (c == 'n') return lit("null");
    return num();
  }
  bool document() {
    if (!value()) return false;
    ws();
    return i == s.size();
  }
};
bool valid_json(const std::string& s) { return JsonCheck{s}.document(); }

// The reference case: N = 100, D_f = 0.4 mm, target 0.2 D_f = 0.08 mm, a linear curve F = k s
// with k = 2000 N/m over 0..0.08 mm (81 rows), v = 0.5 m/s, ramp travel 0.01 D_f = 0.004 mm.
constexpr double kN = 100, kD = 0.4e-3, kTarget = 0.08e-3, kK = 2000, kV = 0.5;
CentrifugeInput linear_input(double n = kN) {
  CentrifugeInput in;
  in.g_level = n;
  in.footing_diameter_m = kD;
  in.footing_speed_m_s = kV;
  for (int i = 0; i <= 80; ++i) {
    double s = kTarget * i / 80.0;
    in.settlement_m.push_back(s);
    in.load_N.push_back(kK * s);
  }
  in.target_settlement_m = kTarget;
  in.block_size_m[0] = in.block_size_m[1] = in.block_size_m[2] = 16e-3;
  in.rock_density_kg_m3 = 1272;
  in.sigma_c_Pa = 0.45e6;
  in.young_Pa = 1.083e9;
  in.load_cell_margin = 1.5;
  in.ramp_travel_m = 0.01 * kD;
  in.overtravel_ratio = 0.5;
  in.scene = "unit \"test\"";
  in.stage = "penetrate";
  return in;
}
}  // namespace

TEST(Centrifuge, RoundUp125) {
  EXPECT_DOUBLE_EQ(round_up_125(0.24), 0.5);
  EXPECT_DOUBLE_EQ(round_up_125(1.0), 1.0);
  EXPECT_DOUBLE_EQ(round_up_125(1.0001), 2.0);
  EXPECT_DOUBLE_EQ(round_up_125(2.0), 2.0);
  EXPECT_DOUBLE_EQ(round_up_125(2.01), 5.0);
  EXPECT_DOUBLE_EQ(round_up_125(5.0), 5.0);
  EXPECT_DOUBLE_EQ(round_up_125(5.1), 10.0);
  EXPECT_DOUBLE_EQ(round_up_125(11.4), 20.0);  // 1.5 x 7.6 N
  EXPECT_DOUBLE_EQ(round_up_125(0.78), 1.0);   // 1.5 x 0.52 N
  EXPECT_DOUBLE_EQ(round_up_125(1e-3), 1e-3);
  EXPECT_DOUBLE_EQ(round_up_125(1.1e-3), 2e-3);
  EXPECT_DOUBLE_EQ(round_up_125(999.0), 1000.0);
  EXPECT_DOUBLE_EQ(round_up_125(2400.0), 5000.0);
  EXPECT_DOUBLE_EQ(round_up_125(1e5), 1e5);
  EXPECT_TRUE(std::isnan(round_up_125(0.0)));
  EXPECT_TRUE(std::isnan(round_up_125(-3.0)));
  EXPECT_TRUE(std::isnan(round_up_125(kNaN)));
  EXPECT_TRUE(std::isnan(round_up_125(std::numeric_limits<double>::infinity())));
}

TEST(Centrifuge, LinearCurveAt100gAgainstHandNumbers) {
  const auto r = centrifuge_report(linear_input());
  const double tol = 1e-12;
  EXPECT_DOUBLE_EQ(r.n, 100);
  // Footing: 0.4 mm -> 40 mm; area pi 0.4^2 / 4 = 0.12566 mm^2 -> x 1e4.
  EXPECT_NEAR(r.diameter_proto_m, 40e-3, tol);
  EXPECT_NEAR(r.area_model_m2, kPi * 0.16e-6 / 4, 1e-20);
  EXPECT_NEAR(r.area_proto_m2, kPi * 1.6e-3 / 4, 1e-15);
  EXPECT_NEAR(r.target_proto_m, 8e-3, tol);
  // Peak at the end: F = 2000 x 8e-5 = 0.16 N -> 0.16 x 1e4 = 1600 N, at 0.08 mm -> 8 mm.
  EXPECT_NEAR(r.peak_model_N, 0.16, tol);
  EXPECT_NEAR(r.peak_proto_N, 1600, 1e-9);
  EXPECT_NEAR(r.settlement_at_peak_proto_m, 8e-3, tol);
  // Stiffness: k -> k N = 2e5 N/m. q = 0.16 / 1.2566e-7 = 1.2732e6 Pa at both scales.
  EXPECT_NEAR(r.secant_stiffness_model_N_m, 2000, 1e-9);
  EXPECT_NEAR(r.secant_stiffness_proto_N_m, 2e5, 1e-7);
  EXPECT_NEAR(r.peak_q_Pa, 0.16 / (kPi * 0.16e-6 / 4), 1e-6);
  EXPECT_NEAR(r.peak_q_Pa, 1.27324e6, 1.0);
  EXPECT_TRUE(r.target_reached);
  // Curve: 10 points at 0.008 mm steps, F = k s, prototype F / s = k N, q and s / D equal at both scales.
  ASSERT_EQ(r.curve.size(), 10u);
  for (std::size_t i = 0; i < r.curve.size(); ++i) {
    const auto& p = r.curve[i];
    EXPECT_NEAR(p.settlement_model_m, 8e-6 * (i + 1), 1e-15);
    EXPECT_NEAR(p.load_model_N, kK * p.settlement_model_m, 1e-12);
    EXPECT_NEAR(p.settlement_proto_m, 100 * p.settlement_model_m, 1e-15);
    EXPECT_NEAR(p.load_proto_N / p.settlement_proto_m, kK * 100, 1e-6);
    EXPECT_NEAR(p.s_over_d, 0.02 * (i + 1), 1e-12);
    EXPECT_NEAR(p.q_Pa, p.load_proto_N / r.area_proto_m2, 1e-6);
  }
  // Rig: max 0.16 N; 1.5 x 0.16 = 0.24 -> 0.5 N; prototype 1.5 x 1600 = 2400 -> 5000 N.
  EXPECT_NEAR(r.max_force_model_N, 0.16, tol);
  EXPECT_DOUBLE_EQ(r.load_cell_range_model_N, 0.5);
  EXPECT_DOUBLE_EQ(r.load_cell_range_proto_N, 5000);
  // Stroke: 0.08 + 0.004 (ramp) + 0.04 (50 % overtravel) = 0.124 mm -> 12.4 mm.
  EXPECT_NEAR(r.stroke_model_m, 0.124e-3, 1e-15);
  EXPECT_NEAR(r.stroke_proto_m, 12.4e-3, 1e-13);
  // Speed and power: 0.16 N x 0.5 m/s = 0.08 W; prototype 1600 x 0.5 = 800 W; at 1 mm/s 1.6e-4 W.
  EXPECT_DOUBLE_EQ(r.speed_model_m_s, 0.5);
  EXPECT_DOUBLE_EQ(r.speed_proto_m_s, 0.5);
  EXPECT_NEAR(r.power_model_W, 0.08, 1e-14);
  EXPECT_NEAR(r.power_proto_W, 800, 1e-9);
  EXPECT_NEAR(r.power_model_rig_max_W, 1.6e-4, 1e-16);
  EXPECT_NEAR(r.loading_time_model_s, 1.6e-4, 1e-16);
  // Speed: 500 mm/s = 500 x the fastest rig: warned, with the ratio.
  EXPECT_NEAR(r.speed_over_rig_max, 500, 1e-9);
  EXPECT_FALSE(r.speed_realistic);
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("500 times the fastest"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.warnings[0].find("not evaluated"), std::string::npos) << r.warnings[0];
  // Markdown: prototype numbers, units in the headers.
  const auto& md = r.markdown;
  EXPECT_NE(md.find("| Footing diameter D_f [mm] | 0.4 | 40 | N |"), std::string::npos) << md;
  EXPECT_NE(md.find("| Peak load F_peak [N] | 0.16 | 1600 | N^2 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| Load-cell range [N] | 0.5 | 5000 |"), std::string::npos) << md;
  EXPECT_NE(md.find("| s model [mm] | F model [N] | s prototype [mm] | F prototype [kN] | s / D_f [-] | q = F / A "
                    "[kPa] | q / sigma_c [-] |"),
            std::string::npos)
      << md;
  // Self-weight stress at the base of 16 mm at 100 g: 1272 x 100 x 9.81 x 0.016 = 1272 x 15.696 = 19965.3 Pa
  // (§7.4: 20.0 kPa).
  EXPECT_NE(md.find("| Self-weight vertical stress at the ground's base [kPa] | 19.97 | 19.97 | 1 |"),
            std::string::npos)
      << md;
  // Ground mass 1272 x 4.096e-6 = 5.21e-3 kg -> x 1e6 = 5210 kg.
  EXPECT_NE(md.find("| 0.00521 | 5210 | N^3 |"), std::string::npos) << md;
  EXPECT_NE(md.find("not a physical time"), std::string::npos);
  // JSON: valid, no NaN literal, the numbers.
  EXPECT_TRUE(valid_json(r.json)) << r.json;
  EXPECT_EQ(r.json.find("nan"), std::string::npos);
  EXPECT_EQ(r.json.find("inf"), std::string::npos);
  EXPECT_NE(r.json.find("\"load_cell_range_prototype_N\": 5000"), std::string::npos) << r.json;
  EXPECT_NE(r.json.find("\"diameter_prototype_m\": 0.04"), std::string::npos) << r.json;
  EXPECT_NE(r.json.find("\"quasi_static\": null"), std::string::npos) << r.json;
  EXPECT_NE(r.json.find("\"scene\": \"unit \\\"test\\\"\""), std::string::npos) << r.json;
}

TEST(Centrifuge, OneGIsIdentity) {
  const auto r = centrifuge_report(linear_input(1.0));
  EXPECT_DOUBLE_EQ(r.diameter_proto_m, r.diameter_model_m);
  EXPECT_DOUBLE_EQ(r.area_proto_m2, r.area_model_m2);
  EXPECT_DOUBLE_EQ(r.peak_proto_N, r.peak_model_N);
  EXPECT_DOUBLE_EQ(r.settlement_at_peak_proto_m, r.settlement_at_peak_model_m);
  EXPECT_DOUBLE_EQ(r.secant_stiffness_proto_N_m, r.secant_stiffness_model_N_m);
  EXPECT_DOUBLE_EQ(r.load_cell_range_proto_N, r.load_cell_range_model_N);
  EXPECT_DOUBLE_EQ(r.stroke_proto_m, r.stroke_model_m);
  EXPECT_DOUBLE_EQ(r.power_proto_W, r.power_model_W);
  for (auto& p : r.curve) {
    EXPECT_DOUBLE_EQ(p.settlement_proto_m, p.settlement_model_m);
    EXPECT_DOUBLE_EQ(p.load_proto_N, p.load_model_N);
  }
  EXPECT_NE(r.markdown.find("| Footing diameter D_f [mm] | 0.4 | 0.4 | N |"), std::string::npos) << r.markdown;
  EXPECT_TRUE(valid_json(r.json)) << r.json;
}

TEST(Centrifuge, RealisticSpeedAndQuasiStaticStatus) {
  auto in = linear_input();
  in.footing_speed_m_s = 1e-4;  // 0.1 mm/s
  auto r = centrifuge_report(in);
  EXPECT_TRUE(r.speed_realistic);
  for (auto& w : r.warnings) EXPECT_EQ(w.find("fastest actuator"), std::string::npos) << w;
  EXPECT_NEAR(r.power_model_W, 0.16 * 1e-4, 1e-18);

  in.footing_speed_m_s = 4.0;
  in.impedance_ratio = 0.5;
  in.quasi_static_limit = 1.0;
  r = centrifuge_report(in);
  ASSERT_FALSE(r.warnings.empty());
  EXPECT_NE(r.warnings[0].find("4000 times the fastest"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.warnings[0].find("it was: rho_b c v / sigma_c = 0.5 <= quasi_static_limit 1"), std::string::npos)
      << r.warnings[0];
  EXPECT_NE(r.json.find("\"quasi_static\": true"), std::string::npos);

  in.impedance_ratio = 12.8;
  r = centrifuge_report(in);
  EXPECT_NE(r.warnings[0].find("it was NOT"), std::string::npos) << r.warnings[0];
  EXPECT_NE(r.json.find("\"quasi_static\": false"), std::string::npos);
  EXPECT_TRUE(valid_json(r.json)) << r.json;
}

TEST(Centrifuge, TargetNotReachedAndOptionalFieldsAsNull) {
  auto in = linear_input();
  in.settlement_m.resize(41);  // ends at 0.04 mm, half the target
  in.load_N.resize(41);
  in.sigma_c_Pa = kNaN;
  in.young_Pa = kNaN;
  in.rock_density_kg_m3 = kNaN;
  in.block_size_m[0] = in.block_size_m[1] = in.block_size_m[2] = kNaN;
  const auto r = centrifuge_report(in);
  EXPECT_FALSE(r.target_reached);
  bool warned = false;
  for (auto& w : r.warnings) warned |= w.find("before the target 0.08 mm") != std::string::npos;
  EXPECT_TRUE(warned);
  EXPECT_NEAR(r.curve.back().settlement_model_m, 0.04e-3, 1e-15);
  EXPECT_EQ(r.markdown.find("q / sigma_c"), std::string::npos);
  EXPECT_EQ(r.markdown.find("Ground mass"), std::string::npos);
  EXPECT_TRUE(valid_json(r.json)) << r.json;
  EXPECT_NE(r.json.find("\"sigma_c_Pa\": null"), std::string::npos);
  EXPECT_NE(r.json.find("\"block_model_m\": [null, null, null]"), std::string::npos) << r.json;
  EXPECT_EQ(r.json.find("nan"), std::string::npos);
}

TEST(Centrifuge, FootingThatNeverMovedGivesTheRowsAndNoStiffness) {
  auto in = linear_input();
  in.settlement_m.assign(25, 0.0);
  in.load_N.assign(25, 0.0);
  const auto r = centrifuge_report(in);
  EXPECT_EQ(r.curve.size(), 10u);
  EXPECT_TRUE(std::isnan(r.secant_stiffness_model_N_m));
  EXPECT_TRUE(std::isnan(r.load_cell_range_model_N));
  EXPECT_TRUE(valid_json(r.json)) << r.json;
  EXPECT_NE(r.json.find("\"load_cell_range_model_N\": null"), std::string::npos);
}

TEST(Centrifuge, RefusesBadInputWithAClearMessage) {
  auto expect_refused = [](CentrifugeInput in, const std::string& words) {
    try {
      centrifuge_report(in);
      ADD_FAILURE() << "accepted; expected a refusal naming: " << words;
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find(words), std::string::npos) << e.what();
    }
  };
  auto in = linear_input();
  in.settlement_m.clear();
  in.load_N.clear();
  expect_refused(in, "curve is empty");
  in = linear_input();
  in.load_N.pop_back();
  expect_refused(in, "settlement_m has 81 values but load_N has 80");
  in = linear_input();
  in.load_N[7] = kNaN;
  expect_refused(in, "non-finite load_N[7]");
  in = linear_input();
  in.settlement_m[3] = std::numeric_limits<double>::infinity();
  expect_refused(in, "non-finite settlement_m[3]");
  in = linear_input();
  in.g_level = kNaN;
  expect_refused(in, "g_level must be finite and > 0");
  in = linear_input();
  in.g_level = 0;
  expect_refused(in, "g_level");
  in = linear_input();
  in.footing_diameter_m = 0;
  expect_refused(in, "footing_diameter_m");
  in = linear_input();
  in.footing_speed_m_s = -1;
  expect_refused(in, "footing_speed_m_s");
  in = linear_input();
  in.target_settlement_m = kNaN;
  expect_refused(in, "target_settlement_m");
  in = linear_input();
  in.load_cell_margin = 0.5;
  expect_refused(in, "load_cell_margin");
  in = linear_input();
  in.block_size_m[1] = -1;
  expect_refused(in, "block_size_m[1]");
}

TEST(Centrifuge, JsonCheckerRejectsWhatItShould) {
  EXPECT_TRUE(valid_json("{\"a\": [1, -2.5e-3, null, true], \"b\": {}}"));
  EXPECT_FALSE(valid_json("{\"a\": nan}"));
  EXPECT_FALSE(valid_json("{\"a\": 1"));
  EXPECT_FALSE(valid_json("{\"a\": [1, 2}"));
  EXPECT_FALSE(valid_json("{\"a\": inf}"));
}
