// CsvSeries: header, exact round trip of values, per-row flush, exclusive creation,
// resume after a crash.
#include "demfdm/io/csv_series.hpp"

#include <cmath>
#include <cstdlib>
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

}  // namespace
}  // namespace demfdm::io
