// CSV time series: one header line, then one row per sample, flushed row by row.
//
// Column names carry their unit after the last underscore: "time_s", "load_N",
// "displacement_m", "stress_zz_Pa", "broken_ratio_1" ("1" = dimensionless). The plot tool
// launch/py/demfdm_plot.py turns "load_N" into the axis label "load [N]".
// Values are written as the shortest decimal text that reads back to the same double
// (std::to_chars), independent of the C locale, so two identical runs give identical files.
//
// CsvFormat relaxes this convention for files whose bytes their readers and the golden data
// already fix (docs/output.md "CSV files"): a fixed number of significant digits, names taken
// as given, text columns.
#pragma once

#include <concepts>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace demfdm::io {

/// How a series names its columns and writes its values. The defaults are the convention above.
struct CsvFormat {
  /// Significant digits of a number: 0 = the shortest text that reads back to the same double;
  /// 1..17 = printf "%.<digits>g" in the C locale (17 reads back every double, as the shortest
  /// text does, only longer).
  int digits = 0;
  /// true: every name ends in "_<unit>" and uses letters, digits and _ . / % ^ - only. false:
  /// names are chosen by others and taken as they are (the coordinator's stage histories, whose
  /// columns are the value names the nodes report); only what would break the CSV (an empty
  /// name, a comma, a double quote, a line break) is refused.
  bool unit_suffix = true;
  /// Columns holding text, not numbers (one of `columns`; a text has no unit, so the name needs
  /// no unit suffix). A text is written in double quotes, a quote in it doubled (RFC 4180).
  std::vector<std::string> text_columns;
};

/// One value of a row: a number (written as the series' CsvFormat says), an integer (its exact
/// decimal text: counts, steps, flags) or a text (text columns only).
class CsvCell {
 public:
  enum class Kind { kNumber, kInteger, kText };
  CsvCell(double v) : kind_(Kind::kNumber), number_(v) {}
  template <std::integral T>
  CsvCell(T v) : kind_(Kind::kInteger), integer_(static_cast<std::int64_t>(v)) {}
  CsvCell(std::string_view t) : kind_(Kind::kText), text_(t) {}
  CsvCell(const std::string& t) : kind_(Kind::kText), text_(t) {}
  CsvCell(const char* t) : kind_(Kind::kText), text_(t) {}
  Kind kind() const noexcept { return kind_; }
  double number() const noexcept { return number_; }
  std::int64_t integer() const noexcept { return integer_; }
  std::string_view text() const noexcept { return text_; }

 private:
  Kind kind_;
  double number_ = 0.0;
  std::int64_t integer_ = 0;
  std::string_view text_;
};

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
  /// The same in `format` (std::invalid_argument also when a text column is not a column or
  /// digits is outside 0..17).
  static CsvSeries create(const std::filesystem::path& file, std::vector<std::string> columns, const CsvFormat& format,
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
  /// The same in `format`. `rows` may be unknown (a checkpoint that recorded the bytes only):
  /// the data lines of the kept part are then counted, which must still end a line.
  static CsvSeries resume(const std::filesystem::path& file, std::vector<std::string> columns, std::uint64_t bytes,
                          std::optional<std::size_t> rows, const CsvFormat& format, bool fsync_each_row = false);

  CsvSeries(CsvSeries&& o) noexcept;
  CsvSeries& operator=(CsvSeries&& o) noexcept;
  CsvSeries(const CsvSeries&) = delete;
  CsvSeries& operator=(const CsvSeries&) = delete;
  ~CsvSeries();

  /// Appends one row (row.size() == columns().size()) and flushes it to the OS, so a crash
  /// of this process keeps every appended row. Throws std::invalid_argument (nothing written)
  /// when the series has a text column.
  void append(std::span<const double> row);
  void append(std::initializer_list<double> row) { append(std::span<const double>(row.begin(), row.size())); }
  /// Appends a row of cells: a text in each text column, a number or an integer in the others.
  /// Throws std::invalid_argument (nothing written) on another count or kind, or on a text
  /// holding a line break (each row is one line: resume() counts rows by lines).
  void append_cells(std::span<const CsvCell> row);
  void append_cells(std::initializer_list<CsvCell> row) {
    append_cells(std::span<const CsvCell>(row.begin(), row.size()));
  }
  /// Closes the file; throws IoError when fclose fails. Further appends throw std::logic_error.
  void close();

  const std::filesystem::path& path() const noexcept { return path_; }
  const std::vector<std::string>& columns() const noexcept { return columns_; }
  const CsvFormat& format() const noexcept { return format_; }
  std::size_t rows() const noexcept { return rows_; }
  /// Bytes in the file so far (header and every appended row): the file size after the
  /// last append. Recorded with rows() in a checkpoint for resume().
  std::uint64_t bytes() const noexcept { return bytes_; }

 private:
  CsvSeries() = default;
  void put_number(double v);
  void write_line();
  std::filesystem::path path_;
  std::vector<std::string> columns_;
  CsvFormat format_;
  std::vector<bool> text_;  // text_[i]: column i holds text
  std::FILE* f_ = nullptr;
  bool fsync_ = false;
  std::size_t rows_ = 0;
  std::uint64_t bytes_ = 0;
  std::string line_;  // reused row buffer
};

}  // namespace demfdm::io
