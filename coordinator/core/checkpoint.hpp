// Coordinated checkpoints of a run (issue 13; layout and versioning: docs/checkpoint-format.md).
//
// A checkpoint is a folder <run>/checkpoints/<tag>/ written at one step boundary:
//   <role>.state             each node's own file (its runtime and adapter state, kind "node")
//   dem.world.state, continuum.model.state   the engines' state files
//   coordinator.state        the stage machine (RunnerState), the stage histories' positions,
//                            the scene text, the nodes, the run folder's files and sizes
//   manifest.txt             written last: format version, code version, scene hash, stage,
//                            step, every file of the folder with its size and FNV-1a 64
//                            checksum, and a checksum of the manifest itself
// A folder without a manifest is incomplete (a run killed while writing it) and is ignored; one
// whose manifest or files fail their checks is refused by name and the previous one is used.
//
// Tags: "<stage>-<step>" inside a stage, "<stage>-<step>-end" after it (step = the last step
// run). Resume continues from the latest complete checkpoint of a run folder; a branch starts a
// new run folder from a stage-end checkpoint with a scene whose later stages may differ.
#pragma once

#include <cstdint>
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "coordinator/core/runner.hpp"

namespace demfdm::coord {

inline constexpr std::uint32_t kCheckpointFormatVersion = 1;

// A checkpoint was refused; the message names it and says why.
struct CheckpointError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Position of the coordinator's per-stage history CSV (history_<i>_<stage>.csv).
struct HistoryState {
  std::int32_t index = 0;   // number of history files begun
  std::string current;      // stage name of the open file ("" none)
  std::string file;         // its name in the run folder
  std::vector<std::pair<std::string, std::string>> cols;  // (role, value name)
  std::uint64_t bytes = 0;  // its size at the checkpoint
};

// A file of the run folder and its size at the checkpoint.
struct FileEntry {
  std::string name;
  std::uint64_t size = 0;
};

// coordinator.state
struct CheckpointRecord {
  RunnerState runner;
  HistoryState history;
  std::string scene_text;                                   // the scene the run used
  std::vector<std::pair<std::string, std::string>> nodes;   // role, solver
  std::vector<std::string> participated;                    // roles that took part in a stage
  std::vector<FileEntry> outputs;                           // run folder ledger
  std::int64_t run_id = 0;
};

std::string record_bytes(const CheckpointRecord& r, std::uint64_t scene_hash);
CheckpointRecord load_record(const std::filesystem::path& file, std::uint64_t scene_hash);

// What manifest.txt says.
struct Manifest {
  std::uint32_t format_version = kCheckpointFormatVersion;
  std::string code_version, tag, stage_name;
  std::uint64_t scene_hash = 0;
  std::int64_t run_id = 0, step = -1;  // step: the last step run
  std::int32_t stage = 0;
  bool in_stage = false;
  std::vector<std::pair<FileEntry, std::uint64_t>> files;  // entry, FNV-1a 64
};

// Writes manifest.txt of `dir` (atomically) over every other file of the folder.
Manifest write_manifest(const std::filesystem::path& dir, Manifest m);
// Reads and checks a checkpoint folder: manifest format and checksum, every file's size and
// checksum. Throws CheckpointError naming the folder and what failed.
Manifest verify_checkpoint(const std::filesystem::path& dir);

// Checkpoint folders of a run folder that have a manifest, latest first (by step; a stage-end
// checkpoint after a mid-stage one of the same step).
std::vector<std::filesystem::path> checkpoints_latest_first(const std::filesystem::path& run_dir);

// A checkpoint read back: where it is, its manifest and the coordinator's record.
struct Loaded {
  std::filesystem::path dir;
  Manifest manifest;
  CheckpointRecord record;
};
// Resume: the latest checkpoint of the run folder that passes every check (manifest, file
// checksums, the same scene hash, a readable record). Each one refused on the way is passed to
// `refused` with its reason, and the previous one is tried. Throws CheckpointError when none is
// left.
Loaded latest_valid_checkpoint(const std::filesystem::path& run_dir, std::uint64_t scene_hash,
                               const std::function<void(const std::string&)>& refused);

// Files of the run folder a checkpoint accounts for (everything the run wrote except logs,
// checkpoints, traffic records and the summary), with their sizes.
std::vector<FileEntry> run_folder_files(const std::filesystem::path& run_dir);
// Resume: deletes the run-folder files written after the checkpoint (not in `ledger`) and
// refuses a ledger file that is now shorter than recorded. Returns the names deleted.
std::vector<std::string> drop_files_after(const std::filesystem::path& run_dir, const std::vector<FileEntry>& ledger);

// The checkpoint policy of a run (scene keys run.checkpoint_stage_end, run.checkpoint_every_s,
// run.checkpoint_keep): when to checkpoint, the folder and tag, the coordinator's record and the
// manifest, the retention of checkpoints inside stages, and the cost figures for the summary.
// The nodes' part is a callback: ask every node to save into a folder (relative to the run
// folder) after a step, and say which could.
class CheckpointPolicy {
 public:
  struct Settings {
    bool at_stage_end = true;
    double every_s = 600;
    std::size_t keep = 2;
  };
  // (folder relative to the run folder, last step, stage index, stage name) -> role -> saved
  using SaveNodes = std::function<std::map<std::string, bool>(const std::string&, std::int64_t, std::int32_t,
                                                              const std::string&)>;
  // What the coordinator records besides the runner state (the history position, the nodes...).
  using Record = std::function<CheckpointRecord(const RunnerState&)>;

  CheckpointPolicy(std::filesystem::path run_dir, Settings s, std::vector<schema::Stage> stages,
                   std::uint64_t scene_hash, std::int64_t run_id, SaveNodes save, Record record,
                   std::function<void(const std::string&)> log);
  // Is a checkpoint inside a stage due (wall time since the last one)?
  bool due() const;
  // Takes the checkpoint of `rs` (a stage end or a step inside a stage) when the policy asks
  // for one. A node that cannot save turns checkpoints off for the run (logged once).
  void take(const RunnerState& rs);
  bool on() const { return on_; }
  // "N written in X s (P % of the run), M MB in all, the last L MB", or "" when none was.
  std::string summary(double run_wall_s) const;

 private:
  std::filesystem::path run_dir_;
  Settings s_;
  std::vector<schema::Stage> stages_;
  std::uint64_t hash_;
  std::int64_t run_id_;
  SaveNodes save_;
  Record record_;
  std::function<void(const std::string&)> log_;
  bool on_;
  std::chrono::steady_clock::time_point last_;
  int n_ = 0;
  double seconds_ = 0, mb_ = 0, last_mb_ = 0;
};

// Branch (launch/run SCENE --from CHECKPOINT): the keys of `scene` that would make the saved
// state inconsistent, one line each naming the key and both values. Empty: the branch may
// start. Rules (docs/checkpoint-format.md): the stages that have run must be the same; the
// specimen, contact laws, seed, particle scale and gravity must not change once a stage has
// run; the continuum's keys must not change once it took part in a stage; a checkpoint must
// be a stage-end one. Free: the later stages, the footing, the DEM step factor and damping,
// coupling, outputs, bus timing, threads, checkpoint policy.
std::vector<std::string> branch_conflicts(const config::Scene& saved, const config::Scene& scene,
                                          const CheckpointRecord& rec, const Manifest& m);

}  // namespace demfdm::coord
