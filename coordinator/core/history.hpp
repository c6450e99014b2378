// The coordinator's stage histories (history_<i>_<stage>.csv): every value the nodes report,
// one file per stage, one row per reported step, written through io::CsvSeries.
//
// Columns: "step", one "<role>.time_s" per node of the stage, then "<role>.<value name>" for
// every value of the stage's first report (nan where a later report lacks one). The value names
// are the nodes' own (proto::Values), taken as they are: a unit suffix where the node gives one
// ("dem.footing_fz_N", "dem.dt_s"), none on ratios and counts ("dem.ratio", "dem.balls"). Numbers
// carry 17 significant digits (every double reads back exactly); the step is an integer
// (docs/output.md "CSV files").
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "coordinator/core/checkpoint.hpp"
#include "coordinator/core/runner.hpp"
#include "demfdm/io/csv_series.hpp"

namespace demfdm::coord {

class StageHistory {
 public:
  /// Files go to `dir`; an empty `dir` records nothing.
  explicit StageHistory(std::string dir) : dir_(std::move(dir)) {}

  /// The format of every stage history (io::CsvSeries).
  static io::CsvFormat format();

  /// One row: the reports of `step` (the first report of a stage begins its file).
  void record(const schema::Stage& st, std::int64_t step, const std::map<std::string, NodeReport>& reps);

  /// Position for a checkpoint (every row written so far is flushed).
  HistoryState state() const;
  /// Resume: the open file is cut back to its size at the checkpoint and continued. Its header
  /// must be "step", time columns, then the checkpoint's value columns; throws io::IoError or
  /// CheckpointError naming the file otherwise (or when it is missing or shorter).
  void restore(const HistoryState& h);
  /// Branch: a new run folder; the history files are numbered on from the saved run's.
  void continue_numbering(const HistoryState& h) { index_ = h.index; }

 private:
  std::string dir_, current_, file_;
  int index_ = 0;
  std::optional<io::CsvSeries> out_;
  std::vector<std::pair<std::string, std::string>> cols_;  // (role, value name) of the value columns
  std::vector<io::CsvCell> row_;                          // reused row
};

}  // namespace demfdm::coord
