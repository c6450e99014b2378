#include "coordinator/core/history.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>

namespace demfdm::coord {

namespace fs = std::filesystem;

io::CsvFormat StageHistory::format() {
  io::CsvFormat f;
  f.digits = 17;
  f.unit_suffix = false;  // the nodes' value names (history.hpp)
  return f;
}

void StageHistory::record(const schema::Stage& st, std::int64_t step, const std::map<std::string, NodeReport>& reps) {
  if (dir_.empty()) return;
  if (st.name != current_ || !out_) {
    current_ = st.name;
    if (out_) out_->close();
    cols_.clear();
    for (auto& [role, r] : reps)
      for (auto& [k, v] : r.values) cols_.push_back({role, k});
    std::vector<std::string> columns{"step"};
    for (auto& [role, r] : reps) columns.push_back(role + ".time_s");
    for (auto& [role, k] : cols_) columns.push_back(role + "." + k);
    file_ = "history_" + std::to_string(index_++) + "_" + st.name + ".csv";
    out_.emplace(io::CsvSeries::create(fs::path(dir_) / file_, std::move(columns), format()));
  }
  row_.clear();
  row_.emplace_back(step);
  for (auto& [role, r] : reps) row_.emplace_back(r.time);
  for (auto& [role, k] : cols_) {
    double v = std::nan("");
    if (auto it = reps.find(role); it != reps.end())
      if (auto jt = it->second.values.find(k); jt != it->second.values.end()) v = jt->second;
    row_.emplace_back(v);
  }
  out_->append_cells(row_);
}

HistoryState StageHistory::state() const {
  HistoryState h;
  h.index = index_;
  h.current = current_;
  h.file = file_;
  h.cols = cols_;
  h.bytes = out_ ? out_->bytes() : 0;
  return h;
}

void StageHistory::restore(const HistoryState& h) {
  index_ = h.index;
  current_ = h.current;
  file_ = h.file;
  cols_ = h.cols;
  if (dir_.empty() || file_.empty()) return;
  const auto path = fs::path(dir_) / file_;
  // The time columns are one per node of the stage; the checkpoint has the value columns only,
  // so the header is read back and its value columns compared with the checkpoint's.
  std::string header;
  if (std::ifstream in(path); !in || !std::getline(in, header))
    throw CheckpointError(path.string() + " is missing or has no header line (the checkpoint says " +
                          std::to_string(h.bytes) + " bytes)");
  std::vector<std::string> columns;
  for (std::size_t a = 0;;) {
    const auto b = header.find(',', a);
    columns.push_back(header.substr(a, b == std::string::npos ? std::string::npos : b - a));
    if (b == std::string::npos) break;
    a = b + 1;
  }
  const std::size_t times = columns.size() >= cols_.size() + 1 ? columns.size() - cols_.size() - 1 : 0;
  bool same = columns.size() == cols_.size() + 1 + times && columns[0] == "step";
  for (std::size_t i = 0; same && i < times; ++i) same = columns[1 + i].ends_with(".time_s");
  for (std::size_t i = 0; same && i < cols_.size(); ++i)
    same = columns[1 + times + i] == cols_[i].first + "." + cols_[i].second;
  if (!same)
    throw CheckpointError(path.string() + ": the header '" + header +
                          "' is not 'step', the nodes' times and the checkpoint's value columns");
  out_.emplace(io::CsvSeries::resume(path, std::move(columns), h.bytes, std::nullopt, format()));
}

}  // namespace demfdm::coord
