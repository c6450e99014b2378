// CsvSeries: header, exact round trip of values, per-row flush, exclusive creation,
// resume after a crash.
#include "demfdm/io/csv_series.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <limits>
#include <sstream>

#include <gtest/gtest.h>

#include "demfdm/io/error.hpp"
#include "io_test_util.hpp"

namespace demfdm::io {
namespace {

using test::ScratchDir;

std::vector<std::string> lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) out.push_back(l);
  return out;
}

TEST(CsvSeries, HeaderAndValuesRoundTripExactly) {
  ScratchDir dir;
  const auto file = dir / "load.csv";
  const std::vector<double> values{0.0, 0.1, 1.0 / 3.0, -2.5e-7, 1e300, 5e-324, 123456789012345678.0,
                                   std::nextafter(1.0, 2.0)};
  {
    CsvSeries csv = CsvSeries::create(file, {"time_s", "load_N"});
    for (std::size_t i = 0; i < values.size(); ++i) csv.append({static_cast<double>(i), values[i]});
    EXPECT_EQ(csv.rows(), values.size());
    csv.close();
  }
  const auto ls = lines(test::slurp(file));
  ASSERT_EQ(ls.size(), values.size() + 1);
  EXPECT_EQ(ls[0], "time_s,load_N");
  EXPECT_EQ(ls[2], "1,0.1") << "shortest round-trip text";
  for (std::size_t i = 0; i < values.size(); ++i) {
    const std::string& l = ls[i + 1];
    const auto comma = l.find(',');
    ASSERT_NE(comma, std::string::npos);
    EXPECT_EQ(std::strtod(l.substr(0, comma).c_str(), nullptr), static_cast<double>(i));
    EXPECT_EQ(std::strtod(l.substr(comma + 1).c_str(), nullptr), values[i]) << l << " must read back bit-exactly";
  }
}

TEST(CsvSeries, EveryRowIsOnDiskBeforeClose) {
  ScratchDir dir;
  const auto file = dir / "s.csv";
  CsvSeries csv = CsvSeries::create(file, {"time_s", "ratio_1"}, /*fsync_each_row=*/true);
  EXPECT_EQ(test::slurp(file), "time_s,ratio_1\n");
  csv.append({0.5, 0.25});
  EXPECT_EQ(test::slurp(file), "time_s,ratio_1\n0.5,0.25\n") << "a crash after append() must keep the row";
  csv.append({1.0, std::numeric_limits<double>::quiet_NaN()});
  EXPECT_EQ(test::slurp(file), "time_s,ratio_1\n0.5,0.25\n1,nan\n");
}

TEST(CsvSeries, CreateRefusesExistingFile) {
  ScratchDir dir;
  const auto file = dir / "s.csv";
  { CsvSeries::create(file, {"time_s"}).append({1.0}); }
  const std::string before = test::slurp(file);
  try {
    CsvSeries::create(file, {"time_s"});
    FAIL() << "an existing series must not be overwritten";
  } catch (const IoError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("fopen"), std::string::npos) << msg;
    EXPECT_NE(msg.find(file.string()), std::string::npos) << msg;
    EXPECT_NE(msg.find("exists"), std::string::npos) << msg;
  }
  EXPECT_EQ(test::slurp(file), before);
}

TEST(CsvSeries, RejectsBadColumnsAndRows) {
  ScratchDir dir;
  for (const std::vector<std::string>& cols : std::vector<std::vector<std::string>>{
           {}, {"time"}, {"time_"}, {"_s"}, {"a,b_s"}, {"load N_N"}, {"time_s", "time_s"}})
    EXPECT_THROW(CsvSeries::create(dir / "bad.csv", cols), std::invalid_argument);
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.csv")) << "no file for rejected columns";
  CsvSeries csv = CsvSeries::create(dir / "ok.csv", {"time_s", "stress_zz_Pa", "speed_m/s"});
  EXPECT_THROW(csv.append({1.0, 2.0}), std::invalid_argument);
  csv.close();
  EXPECT_THROW(csv.append({1.0, 2.0, 3.0}), std::logic_error);
}

std::vector<double> row_of(int i) { return {0.25 * i, 1.0 / (i + 3), -1e-7 * i * i}; }

TEST(CsvSeries, ResumeAfterACrashGivesTheUninterruptedFile) {
  ScratchDir dir;
  const std::vector<std::string> cols{"time_s", "load_N", "displacement_m"};
  {
    CsvSeries ref = CsvSeries::create(dir / "ref.csv", cols);
    EXPECT_EQ(ref.bytes(), std::filesystem::file_size(dir / "ref.csv")) << "the header";
    for (int i = 0; i < 6; ++i) {
      ref.append(row_of(i));
      EXPECT_EQ(ref.bytes(), std::filesystem::file_size(dir / "ref.csv")) << i;
    }
  }
  for (const std::size_t k : {std::size_t{0}, std::size_t{3}}) {
    const auto file = dir / ("run" + std::to_string(k) + ".csv");
    std::uint64_t bytes = 0;
    {
      CsvSeries crashed = CsvSeries::create(file, cols);
      for (std::size_t i = 0; i < k; ++i) crashed.append(row_of(static_cast<int>(i)));
      bytes = crashed.bytes();  // the checkpoint
      EXPECT_EQ(crashed.rows(), k);
      crashed.append({9.0, 9.0, 9.0});  // output after the checkpoint, lost with the crash
      crashed.append({1e300, -0.0, 12345.678});
    }
    CsvSeries resumed = CsvSeries::resume(file, cols, bytes, k);
    EXPECT_EQ(resumed.rows(), k);
    EXPECT_EQ(resumed.bytes(), bytes);
    EXPECT_EQ(std::filesystem::file_size(file), bytes) << "the rows after the checkpoint are cut off at once";
    for (std::size_t i = k; i < 6; ++i) resumed.append(row_of(static_cast<int>(i)));
    resumed.close();
    EXPECT_EQ(resumed.rows(), 6u);
    EXPECT_EQ(test::slurp(file), test::slurp(dir / "ref.csv")) << "resumed at row " << k;
  }
}

TEST(CsvSeries, ResumeRefusesFilesThatDoNotMatchTheCheckpoint) {
  ScratchDir dir;
  const auto file = dir / "s.csv";
  const std::vector<std::string> cols{"time_s", "load_N"};
  std::uint64_t bytes = 0, header = 0;
  {
    CsvSeries csv = CsvSeries::create(file, cols);
    header = csv.bytes();
    csv.append({1.0, 2.0});
    csv.append({3.0, 4.0});
    bytes = csv.bytes();
  }
  const std::string before = test::slurp(file);
  const auto refused = [&](const std::vector<std::string>& c, std::uint64_t b, std::size_t rows,
                           std::vector<std::string> words) {
    try {
      CsvSeries::resume(file, c, b, rows);
      ADD_FAILURE() << "resume at " << b << " bytes, " << rows << " rows must be refused";
    } catch (const IoError& e) {
      const std::string msg = e.what();
      words.push_back(file.string());
      for (const auto& w : words) EXPECT_NE(msg.find(w), std::string::npos) << "'" << w << "' not in: " << msg;
    }
    EXPECT_EQ(test::slurp(file), before) << "a refused resume leaves the file as found";
  };
  refused(cols, bytes + 1, 2, {std::to_string(bytes + 1), std::to_string(bytes), "shorter than the checkpoint"});
  refused({"time_s", "force_N"}, bytes, 2, {"time_s,force_N", "time_s,load_N"});
  refused({"time_s"}, bytes, 2, {"header"});
  refused(cols, bytes, 3, {"holds 2 data line(s)", "says 3 rows"});
  refused(cols, bytes - 1, 2, {"partial"});
  refused(cols, header - 1, 0, {std::to_string(header - 1)});
  EXPECT_THROW(CsvSeries::resume(dir / "missing.csv", cols, header, 0), IoError);
  EXPECT_THROW(CsvSeries::resume(file, {"time"}, bytes, 2), std::invalid_argument);
  // The checkpoint may sit at the header alone.
  CsvSeries csv = CsvSeries::resume(file, cols, header, 0);
  csv.append({5.0, 6.0});
  EXPECT_EQ(test::slurp(file), "time_s,load_N\n5,6\n");
}

// CsvFormat::digits: the text of printf "%.<d>g" (what a std::ostream with setprecision(d)
// writes), for the files whose readers and golden data fix it (docs/output.md "CSV files").
TEST(CsvSeries, FixedDigitsWriteWhatPrintfWrites) {
  ScratchDir dir;
  std::vector<double> values{0.0, -0.0, 0.1, 1.0 / 3.0, -2.5e-7, 1e300, 5e-324, 123456789012345678.0, 38075.0,
                             1e17, 1e16, 2.9800340176287996e-05, std::numeric_limits<double>::infinity(),
                             -std::numeric_limits<double>::infinity(), std::nan(""), -std::nan("")};
  std::mt19937_64 gen(7);
  std::uniform_real_distribution<double> mant(-10.0, 10.0);
  std::uniform_int_distribution<int> exp10(-320, 300);
  for (int i = 0; i < 2000; ++i) values.push_back(mant(gen) * std::pow(10.0, exp10(gen)));
  for (int digits : {17, 10, 1}) {
    const auto file = dir / ("d" + std::to_string(digits) + ".csv");
    {
      CsvSeries csv = CsvSeries::create(file, {"value_1"}, CsvFormat{digits});
      for (double v : values) csv.append({v});
    }
    const auto ls = lines(test::slurp(file));
    ASSERT_EQ(ls.size(), values.size() + 1);
    for (std::size_t i = 0; i < values.size(); ++i) {
      char want[64];
      std::snprintf(want, sizeof want, "%.*g", digits, values[i]);
      ASSERT_EQ(ls[i + 1], want) << "digits " << digits << ", value " << i;
    }
  }
  EXPECT_THROW(CsvSeries::create(dir / "bad.csv", {"value_1"}, CsvFormat{18}), std::invalid_argument);
  EXPECT_THROW(CsvSeries::create(dir / "bad.csv", {"value_1"}, CsvFormat{-1}), std::invalid_argument);
}

// Text columns (no unit, quoted, a quote doubled) and integer cells (exact, whatever the digits).
TEST(CsvSeries, TextColumnsAndIntegerCells) {
  ScratchDir dir;
  const auto file = dir / "stages.csv";
  CsvFormat f;
  f.digits = 10;
  f.text_columns = {"what"};
  {
    CsvSeries csv = CsvSeries::create(file, {"balls_unit", "ratio_unit", "what"}, f);
    csv.append_cells({std::size_t{38075}, 0.23572080394, "replicated 7615 balls; 8004 dropped"});
    csv.append_cells({std::int64_t{123456789012345678}, 1.0 / 3.0, std::string("say \"done\", twice")});
    EXPECT_THROW(csv.append_cells({1, 2.0, 3.0}), std::invalid_argument) << "a number in the text column";
    EXPECT_THROW(csv.append_cells({"one", 2.0, "x"}), std::invalid_argument) << "a text in a number column";
    EXPECT_THROW(csv.append_cells({1, 2.0}), std::invalid_argument);
    EXPECT_THROW(csv.append_cells({1, 2.0, "two\nlines"}), std::invalid_argument);
    EXPECT_THROW(csv.append({1.0, 2.0, 3.0}), std::invalid_argument) << "the all-number row of a series with text";
    EXPECT_EQ(csv.rows(), 2u);
  }
  EXPECT_EQ(test::slurp(file),
            "balls_unit,ratio_unit,what\n"
            "38075,0.2357208039,\"replicated 7615 balls; 8004 dropped\"\n"
            "123456789012345678,0.3333333333,\"say \"\"done\"\", twice\"\n")
      << "nothing of a refused row is written";
  CsvFormat g;
  g.text_columns = {"note"};
  EXPECT_THROW(CsvSeries::create(dir / "bad.csv", {"time_s"}, g), std::invalid_argument) << "not a column";
  g.text_columns = {"no te"};
  EXPECT_THROW(CsvSeries::create(dir / "bad.csv", {"time_s", "no te"}, g), std::invalid_argument);
}

// unit_suffix = false: names given by others (the coordinator's "step", "dem.ratio") are taken
// as they are; only what breaks a CSV line is refused.
TEST(CsvSeries, NamesTakenAsGiven) {
  ScratchDir dir;
  CsvFormat f;
  f.digits = 17;
  f.unit_suffix = false;
  {
    CsvSeries csv = CsvSeries::create(dir / "h.csv", {"step", "dem.time_s", "dem.ratio", "fdm.ratio (max)"}, f);
    csv.append_cells({std::int64_t{12}, 0.1, std::nan(""), 2.0});
  }
  EXPECT_EQ(test::slurp(dir / "h.csv"), "step,dem.time_s,dem.ratio,fdm.ratio (max)\n12,0.10000000000000001,nan,2\n");
  for (const std::vector<std::string>& cols : std::vector<std::vector<std::string>>{
           {""}, {"a,b"}, {"say \"x\""}, {"two\nlines"}, {"step", "step"}})
    EXPECT_THROW(CsvSeries::create(dir / "bad.csv", cols, f), std::invalid_argument);
  EXPECT_THROW(CsvSeries::create(dir / "bad.csv", {"step"}), std::invalid_argument) << "the convention needs a unit";
  EXPECT_FALSE(std::filesystem::exists(dir / "bad.csv"));
}

// A checkpoint that recorded the bytes only: the kept part's rows are counted.
TEST(CsvSeries, ResumeCountsTheRowsWhenTheCheckpointHasNone) {
  ScratchDir dir;
  const auto file = dir / "s.csv";
  CsvFormat f;
  f.digits = 10;
  f.text_columns = {"what"};
  const std::vector<std::string> cols{"steps_unit", "what"};
  std::uint64_t bytes = 0;
  {
    CsvSeries csv = CsvSeries::create(file, cols, f);
    csv.append_cells({1, "a, b"});
    csv.append_cells({2, "c"});
    bytes = csv.bytes();
    csv.append_cells({3, "after the checkpoint"});
  }
  EXPECT_THROW(CsvSeries::resume(file, cols, bytes - 1, std::nullopt, f), IoError) << "a partial line";
  EXPECT_THROW(CsvSeries::resume(file, {"count_unit", "what"}, bytes, std::nullopt, f), IoError) << "header";
  CsvSeries csv = CsvSeries::resume(file, cols, bytes, std::nullopt, f);
  EXPECT_EQ(csv.rows(), 2u);
  csv.append_cells({4, "d"});
  csv.close();
  EXPECT_EQ(test::slurp(file), "steps_unit,what\n1,\"a, b\"\n2,\"c\"\n4,\"d\"\n");
  EXPECT_EQ(csv.rows(), 3u);
}

}  // namespace
}  // namespace demfdm::io
