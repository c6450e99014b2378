// CSV time series: one header line, then one row per sample, flushed row by row.
//
// Column names carry their unit after the last underscore: "time_s", "load_N",
// "displacement_m", "stress_zz_Pa", "broken_ratio_1" ("1" = dimensionless). The plot tool
// launch/py/demfdm_plot.py turns "load_N" into the axis label "load [N]".
// Values are written as the shortest decimal text that reads back to the same double
// (std::to_chars), independent of the C locale, so two identical runs give identical files.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <initializer_list>
#include <span>
#include <string>
#include <vector>

namespace demfdm::io {

class CsvSeries {
 public:
  /// Creates `file` exclusively (fopen mode "wx": an existing file is never overwritten)
  /// and writes the header. `fsync_each_row`: also fsync() after every row, so rows survive
  /// a machine crash, not only a process crash (costs a disk round trip per row).
  /// Throws IoError naming the file and the failing call, std::invalid_argument on a column
  /// name that is empty, lacks a "_unit" suffix, or contains characters other than
  /// letters, digits and _ . / % ^ -.
  static CsvSeries create(const std::filesystem::path& file, std::vector<std::string> columns,
                          bool fsync_each_row = false);

  /// Continues the series of a run resumed from a checkpoint that recorded bytes() and
  /// rows() of this file: rows the crashed run appended after the checkpoint are cut off
  /// (the file is truncated to `bytes`) and appends continue after them, so the finished
  /// file is the one an uninterrupted run writes. Refuses (IoError naming the file) when
  /// the first line is not the header create() writes for `columns`, when `bytes` is
  /// shorter than that header or longer than the file (rows the checkpoint counts are
  /// missing), or when the kept part does not end a line or holds other than `rows` data
  /// lines. Column names are checked as in create().
  static CsvSeries resume(const std::filesystem::path& file, std::vector<std::string> columns, std::uint64_t bytes,
                          std::size_t rows, bool fsync_each_row = false);

  CsvSeries(CsvSeries&& o) noexcept;
  CsvSeries& operator=(CsvSeries&& o) noexcept;
  CsvSeries(const CsvSeries&) = delete;
  CsvSeries& operator=(const CsvSeries&) = delete;
  ~CsvSeries();

  /// Appends one row (row.size() == columns().size()) and flushes it to the OS, so a crash
  /// of this process keeps every appended row.
  void append(std::span<const double> row);
  void append(std::initializer_list<double> row) { append(std::span<const double>(row.begin(), row.size())); }
  /// Closes the file; throws IoError when fclose fails. Further appends throw std::logic_error.
  void close();

  const std::filesystem::path& path() const noexcept { return path_; }
  const std::vector<std::string>& columns() const noexcept { return columns_; }
  std::size_t rows() const noexcept { return rows_; }
  /// Bytes in the file so far (header and every appended row): the file size after the
  /// last append. Recorded with rows() in a checkpoint for resume().
  std::uint64_t bytes() const noexcept { return bytes_; }

 private:
  CsvSeries() = default;
  std::filesystem::path path_;
  std::vector<std::string> columns_;
  std::FILE* f_ = nullptr;
  bool fsync_ = false;
  std::size_t rows_ = 0;
  std::uint64_t bytes_ = 0;
  std::string line_;  // reused row buffer
};

}  // namespace demfdm::io
