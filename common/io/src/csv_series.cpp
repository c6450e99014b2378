#include "demfdm/io/csv_series.hpp"

#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cstring>
#include <stdexcept>
#include <utility>

#include "demfdm/io/error.hpp"

namespace demfdm::io {

namespace {

[[noreturn]] void fail(const char* call, const std::string& file, int err, const std::string& hint = {}) {
  std::string msg = std::string(call) + " failed for '" + file + "': " + std::strerror(err);
  if (!hint.empty()) msg += "; " + hint;
  throw IoError(msg);
}

void check_column(const std::string& c) {
  const auto bad = [&](const std::string& why) {
    throw std::invalid_argument("CsvSeries column '" + c + "': " + why +
                                " (expected name_unit, e.g. time_s, load_N, broken_ratio_1)");
  };
  if (c.empty()) bad("empty name");
  for (char ch : c) {
    const bool ok = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') || ch == '_' ||
                    ch == '.' || ch == '/' || ch == '%' || ch == '^' || ch == '-';
    if (!ok) bad(std::string("character '") + ch + "' is not allowed");
  }
  const auto us = c.rfind('_');
  if (us == std::string::npos || us == 0 || us + 1 == c.size()) bad("no unit suffix after the last '_'");
}

}  // namespace

CsvSeries CsvSeries::create(const std::filesystem::path& file, std::vector<std::string> columns, bool fsync_each_row) {
  if (columns.empty()) throw std::invalid_argument("CsvSeries: at least one column is needed");
  for (std::size_t i = 0; i < columns.size(); ++i) {
    check_column(columns[i]);
    for (std::size_t j = 0; j < i; ++j)
      if (columns[j] == columns[i]) throw std::invalid_argument("CsvSeries: column '" + columns[i] + "' is given twice");
  }
  CsvSeries s;
  s.path_ = std::filesystem::absolute(file).lexically_normal();
  s.columns_ = std::move(columns);
  s.fsync_ = fsync_each_row;
  // "x" (C11): O_CREAT|O_EXCL, never truncates an earlier run's series.
  s.f_ = std::fopen(s.path_.c_str(), "wx");
  if (s.f_ == nullptr) {
    const int err = errno;
    fail("fopen(\"wx\")", s.path_.string(), err,
         err == EEXIST ? "series are never overwritten, choose a new run folder or remove the old file" : "");
  }
  std::string header;
  for (std::size_t i = 0; i < s.columns_.size(); ++i) {
    if (i) header += ',';
    header += s.columns_[i];
  }
  header += '\n';
  if (std::fwrite(header.data(), 1, header.size(), s.f_) != header.size()) fail("fwrite", s.path_.string(), errno);
  if (std::fflush(s.f_) != 0) fail("fflush", s.path_.string(), errno);
  return s;
}

CsvSeries::CsvSeries(CsvSeries&& o) noexcept
    : path_(std::move(o.path_)),
      columns_(std::move(o.columns_)),
      f_(std::exchange(o.f_, nullptr)),
      fsync_(o.fsync_),
      rows_(o.rows_),
      line_(std::move(o.line_)) {}

CsvSeries& CsvSeries::operator=(CsvSeries&& o) noexcept {
  if (this != &o) {
    if (f_ != nullptr) std::fclose(f_);
    path_ = std::move(o.path_);
    columns_ = std::move(o.columns_);
    f_ = std::exchange(o.f_, nullptr);
    fsync_ = o.fsync_;
    rows_ = o.rows_;
    line_ = std::move(o.line_);
  }
  return *this;
}

CsvSeries::~CsvSeries() {
  if (f_ != nullptr) std::fclose(f_);  // every row is already flushed
}

void CsvSeries::append(std::span<const double> row) {
  if (f_ == nullptr) throw std::logic_error("CsvSeries::append on closed series '" + path_.string() + "'");
  if (row.size() != columns_.size())
    throw std::invalid_argument("CsvSeries::append: row has " + std::to_string(row.size()) + " values, '" +
                                path_.string() + "' has " + std::to_string(columns_.size()) + " columns");
  line_.clear();
  char buf[32];
  for (std::size_t i = 0; i < row.size(); ++i) {
    if (i) line_ += ',';
    // Shortest round-trip text; nan and inf come out as "nan", "inf", "-inf", which
    // numpy.genfromtxt and pandas read back.
    auto res = std::to_chars(buf, buf + sizeof buf, row[i]);
    line_.append(buf, res.ptr);
  }
  line_ += '\n';
  if (std::fwrite(line_.data(), 1, line_.size(), f_) != line_.size()) fail("fwrite", path_.string(), errno);
  if (std::fflush(f_) != 0) fail("fflush", path_.string(), errno);
  if (fsync_ && ::fsync(::fileno(f_)) != 0) fail("fsync", path_.string(), errno);
  ++rows_;
}

void CsvSeries::close() {
  if (f_ == nullptr) return;
  std::FILE* f = std::exchange(f_, nullptr);
  if (std::fclose(f) != 0) fail("fclose", path_.string(), errno);
}

}  // namespace demfdm::io
