#include "demfdm/io/csv_series.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
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

// `convention`: the characters of the project's names (letters, digits, _ . / % ^ -), else
// only what breaks a CSV line is refused; `unit`: a "_<unit>" suffix is required.
void check_column(const std::string& c, bool convention, bool unit) {
  const auto bad = [&](const std::string& why) {
    throw std::invalid_argument("CsvSeries column '" + c + "': " + why +
                                (unit ? " (expected name_unit, e.g. time_s, load_N, broken_ratio_1)" : ""));
  };
  if (c.empty()) bad("empty name");
  for (char ch : c) {
    const bool ok = convention ? (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') || (ch >= '0' && ch <= '9') ||
                                     ch == '_' || ch == '.' || ch == '/' || ch == '%' || ch == '^' || ch == '-'
                               : ch != ',' && ch != '"' && ch != '\n' && ch != '\r';
    if (!ok) bad(std::string("character '") + ch + "' is not allowed");
  }
  if (!unit) return;
  const auto us = c.rfind('_');
  if (us == std::string::npos || us == 0 || us + 1 == c.size()) bad("no unit suffix after the last '_'");
}

// Which columns hold text (CsvFormat::text_columns); checks every name and the format.
std::vector<bool> check_columns(const std::vector<std::string>& columns, const CsvFormat& format) {
  if (columns.empty()) throw std::invalid_argument("CsvSeries: at least one column is needed");
  if (format.digits < 0 || format.digits > 17)
    throw std::invalid_argument("CsvSeries: digits must be 0 (shortest round trip) to 17, found " +
                                std::to_string(format.digits));
  std::vector<bool> text(columns.size(), false);
  for (const auto& t : format.text_columns) {
    const auto at = std::find(columns.begin(), columns.end(), t);
    if (at == columns.end()) throw std::invalid_argument("CsvSeries: text column '" + t + "' is not a column");
    text[static_cast<std::size_t>(at - columns.begin())] = true;
  }
  for (std::size_t i = 0; i < columns.size(); ++i) {
    // A text has no unit; its name keeps the characters of the convention.
    check_column(columns[i], format.unit_suffix, format.unit_suffix && !text[i]);
    for (std::size_t j = 0; j < i; ++j)
      if (columns[j] == columns[i]) throw std::invalid_argument("CsvSeries: column '" + columns[i] + "' is given twice");
  }
  return text;
}

std::string header_line(const std::vector<std::string>& columns) {
  std::string header;
  for (std::size_t i = 0; i < columns.size(); ++i) {
    if (i) header += ',';
    header += columns[i];
  }
  header += '\n';
  return header;
}

// Shows a found header in a message: without its newline, shortened when long.
std::string shown(std::string s) {
  if (!s.empty() && s.back() == '\n') s.pop_back();
  if (s.size() > 200) s = s.substr(0, 200) + "...";
  return s;
}

}  // namespace

CsvSeries CsvSeries::create(const std::filesystem::path& file, std::vector<std::string> columns, bool fsync_each_row) {
  return create(file, std::move(columns), CsvFormat{}, fsync_each_row);
}

CsvSeries CsvSeries::create(const std::filesystem::path& file, std::vector<std::string> columns, const CsvFormat& format,
                            bool fsync_each_row) {
  CsvSeries s;
  s.text_ = check_columns(columns, format);
  s.format_ = format;
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
  const std::string header = header_line(s.columns_);
  if (std::fwrite(header.data(), 1, header.size(), s.f_) != header.size()) fail("fwrite", s.path_.string(), errno);
  if (std::fflush(s.f_) != 0) fail("fflush", s.path_.string(), errno);
  s.bytes_ = header.size();
  return s;
}

CsvSeries CsvSeries::resume(const std::filesystem::path& file, std::vector<std::string> columns, std::uint64_t bytes,
                            std::size_t rows, bool fsync_each_row) {
  return resume(file, std::move(columns), bytes, std::optional<std::size_t>(rows), CsvFormat{}, fsync_each_row);
}

CsvSeries CsvSeries::resume(const std::filesystem::path& file, std::vector<std::string> columns, std::uint64_t bytes,
                            std::optional<std::size_t> rows, const CsvFormat& format, bool fsync_each_row) {
  CsvSeries s;
  s.text_ = check_columns(columns, format);
  s.format_ = format;
  s.path_ = std::filesystem::absolute(file).lexically_normal();
  s.columns_ = std::move(columns);
  s.fsync_ = fsync_each_row;
  const std::string name = s.path_.string();
  const std::string header = header_line(s.columns_);

  // Everything is checked before the file is touched: a refused resume leaves it as found.
  {
    std::FILE* in = std::fopen(s.path_.c_str(), "rb");
    if (in == nullptr) fail("fopen(\"rb\")", name, errno, "the series to resume must exist");
    struct Closer {
      std::FILE* f;
      ~Closer() { std::fclose(f); }
    } closer{in};
    struct stat st {};
    if (::fstat(::fileno(in), &st) != 0) fail("fstat", name, errno);
    const auto size = static_cast<std::uint64_t>(st.st_size);

    // The header: the file's first line, read up to the expected header's length + 1 so
    // a longer first line shows as different.
    std::string found(header.size() + 1, '\0');
    found.resize(std::fread(found.data(), 1, found.size(), in));
    if (std::ferror(in)) fail("fread", name, errno);
    const auto nl = found.find('\n');
    if (nl != std::string::npos) found.resize(nl + 1);
    if (found != header)
      throw IoError("CsvSeries::resume: '" + name + "' does not start with the expected header '" + shown(header) +
                    "', found '" + shown(found) + "'");
    if (bytes < header.size() || bytes > size)
      throw IoError("CsvSeries::resume: '" + name + "' cannot be resumed at " + std::to_string(bytes) +
                    " bytes: the file has " + std::to_string(size) + " bytes and a " + std::to_string(header.size()) +
                    "-byte header" +
                    (bytes > size ? " (shorter than the checkpoint says: rows it counts are missing)" : ""));

    // Count the data lines in the kept part [header, bytes): the checkpoint's row count
    // must match, and the part must end a line (a cut mid-row would glue two rows).
    if (std::fseek(in, static_cast<long>(header.size()), SEEK_SET) != 0) fail("fseek", name, errno);
    std::uint64_t left = bytes - header.size(), lines = 0;
    char last = '\n';
    char buf[65536];
    while (left > 0) {
      const std::size_t want = static_cast<std::size_t>(std::min<std::uint64_t>(left, sizeof buf));
      const std::size_t got = std::fread(buf, 1, want, in);
      if (got != want) fail("fread", name, std::ferror(in) ? errno : EIO, "the file changed while it was checked");
      for (std::size_t i = 0; i < got; ++i) lines += buf[i] == '\n';
      last = buf[got - 1];
      left -= got;
    }
    if (last != '\n' || (rows && lines != *rows))
      throw IoError("CsvSeries::resume: '" + name + "' holds " + std::to_string(lines) + " data line(s)" +
                    (last != '\n' ? " and a partial one" : "") + " in its first " + std::to_string(bytes) + " bytes" +
                    (rows ? ", the checkpoint says " + std::to_string(*rows) + " rows" : ""));
    rows = lines;
  }

  // Drop what the crashed run appended after the checkpoint, then append after the kept part.
  std::error_code ec;
  std::filesystem::resize_file(s.path_, bytes, ec);
  if (ec) fail("truncate", name, ec.value());
  // "a": every write goes to the end, which is now `bytes`.
  s.f_ = std::fopen(s.path_.c_str(), "ab");
  if (s.f_ == nullptr) fail("fopen(\"ab\")", name, errno);
  // The cut must be durable too, or a machine crash could bring the dropped rows back
  // below the rows appended from now on.
  if (s.fsync_ && ::fsync(::fileno(s.f_)) != 0) fail("fsync", name, errno);
  s.rows_ = *rows;
  s.bytes_ = bytes;
  return s;
}

CsvSeries::CsvSeries(CsvSeries&& o) noexcept
    : path_(std::move(o.path_)),
      columns_(std::move(o.columns_)),
      format_(std::move(o.format_)),
      text_(std::move(o.text_)),
      f_(std::exchange(o.f_, nullptr)),
      fsync_(o.fsync_),
      rows_(o.rows_),
      bytes_(o.bytes_),
      line_(std::move(o.line_)) {}

CsvSeries& CsvSeries::operator=(CsvSeries&& o) noexcept {
  if (this != &o) {
    if (f_ != nullptr) std::fclose(f_);
    path_ = std::move(o.path_);
    columns_ = std::move(o.columns_);
    format_ = std::move(o.format_);
    text_ = std::move(o.text_);
    f_ = std::exchange(o.f_, nullptr);
    fsync_ = o.fsync_;
    rows_ = o.rows_;
    bytes_ = o.bytes_;
    line_ = std::move(o.line_);
  }
  return *this;
}

CsvSeries::~CsvSeries() {
  if (f_ != nullptr) std::fclose(f_);  // every row is already flushed
}

void CsvSeries::put_number(double v) {
  // Shortest round-trip text, or printf's "%.<digits>g" (C locale); nan and inf come out as
  // "nan", "inf", "-inf", which numpy.genfromtxt and pandas read back.
  char buf[32];
  const auto res = format_.digits == 0
                       ? std::to_chars(buf, buf + sizeof buf, v)
                       : std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, format_.digits);
  line_.append(buf, res.ptr);
}

void CsvSeries::write_line() {
  line_ += '\n';
  if (std::fwrite(line_.data(), 1, line_.size(), f_) != line_.size()) fail("fwrite", path_.string(), errno);
  if (std::fflush(f_) != 0) fail("fflush", path_.string(), errno);
  if (fsync_ && ::fsync(::fileno(f_)) != 0) fail("fsync", path_.string(), errno);
  ++rows_;
  bytes_ += line_.size();
}

void CsvSeries::append(std::span<const double> row) {
  if (f_ == nullptr) throw std::logic_error("CsvSeries::append on closed series '" + path_.string() + "'");
  if (row.size() != columns_.size())
    throw std::invalid_argument("CsvSeries::append: row has " + std::to_string(row.size()) + " values, '" +
                                path_.string() + "' has " + std::to_string(columns_.size()) + " columns");
  if (!format_.text_columns.empty())
    throw std::invalid_argument("CsvSeries::append: '" + path_.string() + "' has text columns (append_cells)");
  line_.clear();
  for (std::size_t i = 0; i < row.size(); ++i) {
    if (i) line_ += ',';
    put_number(row[i]);
  }
  write_line();
}

void CsvSeries::append_cells(std::span<const CsvCell> row) {
  if (f_ == nullptr) throw std::logic_error("CsvSeries::append_cells on closed series '" + path_.string() + "'");
  if (row.size() != columns_.size())
    throw std::invalid_argument("CsvSeries::append_cells: row has " + std::to_string(row.size()) + " values, '" +
                                path_.string() + "' has " + std::to_string(columns_.size()) + " columns");
  for (std::size_t i = 0; i < row.size(); ++i) {
    const bool text = row[i].kind() == CsvCell::Kind::kText;
    if (text != text_[i])
      throw std::invalid_argument("CsvSeries::append_cells: column '" + columns_[i] + "' of '" + path_.string() +
                                  "' holds " + (text_[i] ? "text" : "numbers") + ", the row gives " +
                                  (text ? "a text" : "a number"));
    if (text && row[i].text().find_first_of("\r\n") != std::string_view::npos)
      throw std::invalid_argument("CsvSeries::append_cells: the text of column '" + columns_[i] + "' of '" +
                                  path_.string() + "' holds a line break (one row is one line)");
  }
  line_.clear();
  char buf[32];
  for (std::size_t i = 0; i < row.size(); ++i) {
    if (i) line_ += ',';
    const CsvCell& c = row[i];
    switch (c.kind()) {
      case CsvCell::Kind::kNumber: put_number(c.number()); break;
      case CsvCell::Kind::kInteger: line_.append(buf, std::to_chars(buf, buf + sizeof buf, c.integer()).ptr); break;
      case CsvCell::Kind::kText:
        line_ += '"';
        for (char ch : c.text()) {
          if (ch == '"') line_ += '"';  // RFC 4180: a quote inside a quoted field is doubled
          line_ += ch;
        }
        line_ += '"';
        break;
    }
  }
  write_line();
}

void CsvSeries::close() {
  if (f_ == nullptr) return;
  std::FILE* f = std::exchange(f_, nullptr);
  if (std::fclose(f) != 0) fail("fclose", path_.string(), errno);
}

}  // namespace demfdm::io
