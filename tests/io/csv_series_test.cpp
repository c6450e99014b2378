// CsvSeries: header, exact round trip of values, per-row flush, exclusive creation.
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

}  // namespace
}  // namespace demfdm::io
