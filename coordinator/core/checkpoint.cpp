#include "coordinator/core/checkpoint.hpp"

#include <algorithm>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>

#include <toml++/toml.h>

#include "demfdm/io/state_file.hpp"

namespace demfdm::coord {
namespace fs = std::filesystem;

namespace {

constexpr const char* kKind = "coordinator";

void put_values(io::StateWriter& w, const std::map<std::string, double>& m) {
  w.u64(m.size());
  for (auto& [k, v] : m) {
    w.str(k);
    w.f64(v);
  }
}
std::map<std::string, double> get_values(io::SectionReader& r) {
  std::map<std::string, double> m;
  auto n = r.count(12);
  for (std::uint64_t i = 0; i < n; ++i) {
    auto k = r.str();
    m[k] = r.f64();
  }
  return m;
}
void put_report(io::StateWriter& w, const NodeReport& n) {
  w.i32(static_cast<std::int32_t>(n.status));
  for (double v : {n.time, n.dt_stable, n.compute_s, n.wait_s}) w.f64(v);
  put_values(w, n.values);
  w.str(n.text);
}
NodeReport get_report(io::SectionReader& r) {
  NodeReport n;
  n.status = static_cast<Status>(r.i32());
  for (double* v : {&n.time, &n.dt_stable, &n.compute_s, &n.wait_s}) *v = r.f64();
  n.values = get_values(r);
  n.text = r.str();
  return n;
}
void put_reports(io::StateWriter& w, const std::map<std::string, NodeReport>& m) {
  w.u64(m.size());
  for (auto& [k, v] : m) {
    w.str(k);
    put_report(w, v);
  }
}
std::map<std::string, NodeReport> get_reports(io::SectionReader& r) {
  std::map<std::string, NodeReport> m;
  auto n = r.count(40);
  for (std::uint64_t i = 0; i < n; ++i) {
    auto k = r.str();
    m[k] = get_report(r);
  }
  return m;
}
void put_stage(io::StateWriter& w, const StageSummary& s) {
  w.str(s.name);
  w.str(s.action);
  w.i64(s.first_step);
  w.i64(s.last_step);
  w.f64(s.wall_s);
  w.b(s.criterion_met);
  w.str(s.ended_by);
  put_reports(w, s.begin);
  put_reports(w, s.end);
  put_values(w, s.compute_s);
  put_values(w, s.wait_s);
}
StageSummary get_stage(io::SectionReader& r) {
  StageSummary s;
  s.name = r.str();
  s.action = r.str();
  s.first_step = r.i64();
  s.last_step = r.i64();
  s.wall_s = r.f64();
  s.criterion_met = r.b();
  s.ended_by = r.str();
  s.begin = get_reports(r);
  s.end = get_reports(r);
  s.compute_s = get_values(r);
  s.wait_s = get_values(r);
  return s;
}
void put_strings(io::StateWriter& w, const std::vector<std::pair<std::string, std::string>>& v) {
  w.u64(v.size());
  for (auto& [a, b] : v) {
    w.str(a);
    w.str(b);
  }
}
std::vector<std::pair<std::string, std::string>> get_strings(io::SectionReader& r) {
  std::vector<std::pair<std::string, std::string>> v(r.count(8));
  for (auto& [a, b] : v) {
    a = r.str();
    b = r.str();
  }
  return v;
}

std::string hex64(std::uint64_t v) {
  std::ostringstream os;
  os << std::hex << std::setw(16) << std::setfill('0') << v;
  return os.str();
}

// Top-level files a checkpoint never accounts for: logs (appended by every process, also
// across a resume), traffic records, the summary (written at the end), the scene copy, and
// process output captured by test harnesses. (Folders, such as checkpoints/ and
// traffic.parts/, are never in the ledger.)
bool outside_ledger(const fs::path& file) {
  const auto name = file.filename().string(), ext = file.extension().string();
  return ext == ".log" || ext == ".out" || ext == ".lcmlog" || name == "summary.txt" || name == "summary.json" ||
         name == "scene.toml" || name == "traffic_compare.txt" || name.rfind("blowup_", 0) == 0 ||
         name.find(".tmp") != std::string::npos;
}

}  // namespace

std::string record_bytes(const CheckpointRecord& rec, std::uint64_t scene_hash) {
  io::StateWriter w(kKind, io::default_code_version(), scene_hash);
  const auto& s = rec.runner;
  w.begin("runner");
  w.u64(s.stage);
  w.b(s.in_stage);
  w.i64(s.step);
  w.i32(s.clock.stage_index);
  w.i64(s.clock.stage_first_step);
  w.i64(s.clock.first_step);
  w.i64(s.clock.last_step);
  w.f64(s.clock.dt);
  w.f64(s.clock.t_begin);
  put_stage(w, s.current);
  w.u64(s.done.size());
  for (auto& d : s.done) put_stage(w, d);
  put_values(w, s.dt_stable);
  w.i64(s.grants_posted);
  w.u64(s.pending_dt.size());
  for (auto& [i, m] : s.pending_dt) {
    w.i64(i);
    put_values(w, m);
  }
  w.f64(s.wall_s);
  w.end();
  w.begin("history");
  w.i32(rec.history.index);
  w.str(rec.history.current);
  w.str(rec.history.file);
  put_strings(w, rec.history.cols);
  w.u64(rec.history.bytes);
  w.end();
  w.begin("run");
  w.str(rec.scene_text);
  put_strings(w, rec.nodes);
  w.u64(rec.participated.size());
  for (auto& p : rec.participated) w.str(p);
  w.u64(rec.outputs.size());
  for (auto& f : rec.outputs) {
    w.str(f.name);
    w.u64(f.size);
  }
  w.i64(rec.run_id);
  w.end();
  return w.bytes();
}

CheckpointRecord load_record(const fs::path& file, std::uint64_t scene_hash) {
  io::StateReader r(io::read_whole_file(file), file.string(), kKind, scene_hash);
  CheckpointRecord rec;
  auto& s = rec.runner;
  {
    auto sec = r.section("runner");
    s.stage = sec.u64();
    s.in_stage = sec.b();
    s.step = sec.i64();
    s.clock.stage_index = sec.i32();
    s.clock.stage_first_step = sec.i64();
    s.clock.first_step = sec.i64();
    s.clock.last_step = sec.i64();
    s.clock.dt = sec.f64();
    s.clock.t_begin = sec.f64();
    s.current = get_stage(sec);
    s.done.resize(sec.count(40));
    for (auto& d : s.done) d = get_stage(sec);
    s.dt_stable = get_values(sec);
    s.grants_posted = sec.i64();
    s.pending_dt.resize(sec.count(16));
    for (auto& [i, m] : s.pending_dt) {
      i = sec.i64();
      m = get_values(sec);
    }
    s.wall_s = sec.f64();
    sec.done();
  }
  {
    auto sec = r.section("history");
    rec.history.index = sec.i32();
    rec.history.current = sec.str();
    rec.history.file = sec.str();
    rec.history.cols = get_strings(sec);
    rec.history.bytes = sec.u64();
    sec.done();
  }
  {
    auto sec = r.section("run");
    rec.scene_text = sec.str();
    rec.nodes = get_strings(sec);
    rec.participated.resize(sec.count(4));
    for (auto& p : rec.participated) p = sec.str();
    rec.outputs.resize(sec.count(12));
    for (auto& f : rec.outputs) {
      f.name = sec.str();
      f.size = sec.u64();
    }
    rec.run_id = sec.i64();
    sec.done();
  }
  r.finish();
  return rec;
}

namespace {
std::string manifest_body(const Manifest& m) {
  std::ostringstream os;
  os << "demfdm checkpoint " << m.format_version << "\n"
     << "code_version " << m.code_version << "\n"
     << "scene_hash " << hex64(m.scene_hash) << "\n"
     << "run_id " << m.run_id << "\n"
     << "tag " << m.tag << "\n"
     << "stage " << m.stage << " " << m.stage_name << "\n"
     << "step " << m.step << "\n"
     << "in_stage " << (m.in_stage ? 1 : 0) << "\n";
  for (auto& [f, h] : m.files) os << "file " << f.size << " " << hex64(h) << " " << f.name << "\n";
  return os.str();
}
std::uint64_t file_checksum(const fs::path& p) {
  auto bytes = io::read_whole_file(p);
  return io::fnv1a64(bytes.data(), bytes.size());
}
}  // namespace

Manifest write_manifest(const fs::path& dir, Manifest m) {
  m.files.clear();
  std::vector<fs::path> names;
  for (auto& e : fs::directory_iterator(dir))
    if (e.is_regular_file() && e.path().filename() != "manifest.txt" && e.path().extension() != ".tmp")
      names.push_back(e.path().filename());
  std::sort(names.begin(), names.end());
  for (auto& n : names) m.files.push_back({{n.string(), fs::file_size(dir / n)}, file_checksum(dir / n)});
  auto body = manifest_body(m);
  body += "checksum " + hex64(io::fnv1a64(body.data(), body.size())) + "\n";
  io::write_atomically(dir / "manifest.txt", body);
  return m;
}

Manifest verify_checkpoint(const fs::path& dir) {
  const auto path = dir / "manifest.txt";
  auto fail = [&](const std::string& what) -> CheckpointError {
    return CheckpointError("checkpoint " + dir.string() + ": " + what);
  };
  if (!fs::exists(path)) throw fail("no manifest.txt (incomplete: the run stopped while writing it)");
  std::string text;
  try {
    text = io::read_whole_file(path);
  } catch (const std::exception& e) {
    throw fail(e.what());
  }
  auto pos = text.rfind("checksum ");
  if (pos == std::string::npos || (pos > 0 && text[pos - 1] != '\n')) throw fail("manifest.txt has no checksum line");
  const std::string body = text.substr(0, pos);
  std::string stored = text.substr(pos + 9);
  while (!stored.empty() && (stored.back() == '\n' || stored.back() == '\r')) stored.pop_back();
  if (stored != hex64(io::fnv1a64(body.data(), body.size()))) throw fail("manifest.txt fails its checksum");
  Manifest m;
  std::istringstream is(body);
  std::string line;
  bool header = false;
  while (std::getline(is, line)) {
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "demfdm") {
      std::string word;
      ls >> word >> m.format_version;
      header = word == "checkpoint";
      if (m.format_version != kCheckpointFormatVersion)
        throw fail("format version " + std::to_string(m.format_version) + ", this build reads version " +
                   std::to_string(kCheckpointFormatVersion));
    } else if (key == "code_version") {
      std::getline(ls >> std::ws, m.code_version);
    } else if (key == "scene_hash") {
      std::string h;
      ls >> h;
      m.scene_hash = std::stoull(h, nullptr, 16);
    } else if (key == "run_id") {
      ls >> m.run_id;
    } else if (key == "tag") {
      ls >> m.tag;
    } else if (key == "stage") {
      ls >> m.stage >> m.stage_name;
    } else if (key == "step") {
      ls >> m.step;
    } else if (key == "in_stage") {
      int v = 0;
      ls >> v;
      m.in_stage = v != 0;
    } else if (key == "file") {
      FileEntry f;
      std::string h;
      ls >> f.size >> h;
      std::getline(ls >> std::ws, f.name);
      m.files.push_back({f, std::stoull(h, nullptr, 16)});
    }
  }
  if (!header) throw fail("manifest.txt is not a demfdm checkpoint manifest");
  for (auto& [f, h] : m.files) {
    const auto p = dir / f.name;
    if (!fs::exists(p)) throw fail("file " + f.name + " is missing");
    if (fs::file_size(p) != f.size)
      throw fail("file " + f.name + " has " + std::to_string(fs::file_size(p)) + " bytes, the manifest says " +
                 std::to_string(f.size));
    if (file_checksum(p) != h) throw fail("file " + f.name + " fails its checksum");
  }
  return m;
}

std::vector<fs::path> checkpoints_latest_first(const fs::path& run_dir) {
  struct Item {
    std::int64_t step;
    int end;
    fs::path dir;
  };
  std::vector<Item> items;
  const auto root = run_dir / "checkpoints";
  if (!fs::exists(root)) return {};
  for (auto& e : fs::directory_iterator(root)) {
    if (!e.is_directory() || !fs::exists(e.path() / "manifest.txt")) continue;
    // The step and the kind from the tag "<stage>-<step>" / "<stage>-<step>-end".
    std::string tag = e.path().filename().string();
    int end = 0;
    if (tag.size() > 4 && tag.compare(tag.size() - 4, 4, "-end") == 0) {
      end = 1;
      tag.resize(tag.size() - 4);
    }
    auto dash = tag.rfind('-');
    if (dash == std::string::npos) continue;
    try {
      items.push_back({std::stoll(tag.substr(dash + 1)), end, e.path()});
    } catch (...) {
    }
  }
  std::sort(items.begin(), items.end(), [](const Item& a, const Item& b) {
    return a.step != b.step ? a.step > b.step : a.end > b.end;
  });
  std::vector<fs::path> out;
  for (auto& i : items) out.push_back(i.dir);
  return out;
}

Loaded latest_valid_checkpoint(const fs::path& run_dir, std::uint64_t scene_hash,
                               const std::function<void(const std::string&)>& refused) {
  for (auto& dir : checkpoints_latest_first(run_dir)) {
    try {
      Loaded s;
      s.dir = fs::absolute(dir);
      s.manifest = verify_checkpoint(dir);
      if (s.manifest.scene_hash != scene_hash)
        throw CheckpointError("checkpoint " + dir.string() + " was written under another scene (hash " +
                              hex64(s.manifest.scene_hash) + ", the scene has " + hex64(scene_hash) + ")");
      s.record = load_record(dir / "coordinator.state", scene_hash);
      return s;
    } catch (const CheckpointError& e) {
      refused(e.what());
    } catch (const io::StateFileError& e) {
      refused("checkpoint " + dir.string() + ": " + e.what());
    }
  }
  throw CheckpointError("no complete checkpoint in " + (run_dir / "checkpoints").string() + " to resume from");
}

std::vector<FileEntry> run_folder_files(const fs::path& run_dir) {
  std::vector<FileEntry> out;
  for (auto& e : fs::directory_iterator(run_dir)) {
    if (!e.is_regular_file()) continue;
    if (outside_ledger(e.path())) continue;
    out.push_back({e.path().filename().string(), fs::file_size(e.path())});
  }
  std::sort(out.begin(), out.end(), [](const FileEntry& a, const FileEntry& b) { return a.name < b.name; });
  return out;
}

std::vector<std::string> drop_files_after(const fs::path& run_dir, const std::vector<FileEntry>& ledger) {
  std::map<std::string, std::uint64_t> known;
  for (auto& f : ledger) known[f.name] = f.size;
  for (auto& [name, size] : known) {
    const auto p = run_dir / name;
    if (!fs::exists(p))
      throw CheckpointError(p.string() + ": written before the checkpoint, now missing: the run folder was changed");
    if (fs::file_size(p) < size)
      throw CheckpointError(p.string() + ": " + std::to_string(fs::file_size(p)) + " bytes, the checkpoint recorded " +
                            std::to_string(size) + ": the run folder was changed");
  }
  std::vector<std::string> dropped;
  for (auto& f : run_folder_files(run_dir))
    if (!known.count(f.name)) {
      fs::remove(run_dir / f.name);
      dropped.push_back(f.name);
    }
  return dropped;
}

CheckpointPolicy::CheckpointPolicy(fs::path run_dir, Settings s, std::vector<schema::Stage> stages,
                                   std::uint64_t scene_hash, std::int64_t run_id, SaveNodes save, Record record,
                                   std::function<void(const std::string&)> log)
    : run_dir_(std::move(run_dir)), s_(s), stages_(std::move(stages)), hash_(scene_hash), run_id_(run_id),
      save_(std::move(save)), record_(std::move(record)), log_(std::move(log)),
      on_(!run_dir_.empty() && (s.at_stage_end || s.every_s > 0)), last_(std::chrono::steady_clock::now()) {}

bool CheckpointPolicy::due() const {
  return on_ && s_.every_s > 0 &&
         std::chrono::duration<double>(std::chrono::steady_clock::now() - last_).count() >= s_.every_s;
}

void CheckpointPolicy::take(const RunnerState& rs) {
  if (!on_ || (!rs.in_stage && !s_.at_stage_end)) return;
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t si = rs.in_stage ? rs.stage : rs.stage - 1;
  const auto& st = stages_.at(si);
  const std::int64_t last = rs.step - 1;
  const std::string tag = st.name + "-" + std::to_string(last) + (rs.in_stage ? "" : "-end");
  const std::string rel = "checkpoints/" + tag;
  const fs::path dir = run_dir_ / rel;
  if (fs::exists(dir / "manifest.txt")) return;  // a resumed run at its own checkpoint
  fs::create_directories(dir);
  for (auto& [role, saved] : save_(rel, last, static_cast<std::int32_t>(si), st.name))
    if (!saved) {
      log_("checkpoints are off for this run: node '" + role + "' cannot save its state");
      on_ = false;
      fs::remove_all(dir);
      return;
    }
  auto rec = record_(rs);
  rec.runner = rs;
  rec.outputs = run_folder_files(run_dir_);
  rec.run_id = run_id_;
  io::write_atomically(dir / "coordinator.state", record_bytes(rec, hash_));
  Manifest m;
  m.code_version = io::default_code_version();
  m.scene_hash = hash_;
  m.run_id = run_id_;
  m.tag = tag;
  m.stage = static_cast<std::int32_t>(si);
  m.stage_name = st.name;
  m.step = last;
  m.in_stage = rs.in_stage;
  m = write_manifest(dir, m);
  std::uint64_t bytes = 0;
  for (auto& [f, h] : m.files) bytes += f.size;
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  ++n_;
  seconds_ += sec;
  last_mb_ = static_cast<double>(bytes) / 1e6;
  mb_ += last_mb_;
  std::ostringstream os;
  os << "checkpoint " << rel << ": " << m.files.size() << " files, " << std::fixed << std::setprecision(2) << last_mb_
     << " MB, written in " << std::setprecision(3) << sec << " s";
  log_(os.str());
  // Keep the newest `keep` checkpoints inside stages (every stage-end one).
  if (rs.in_stage) {
    std::vector<fs::path> inside;
    for (auto& d : checkpoints_latest_first(run_dir_)) {
      const auto name = d.filename().string();
      if (name.size() < 4 || name.compare(name.size() - 4, 4, "-end") != 0) inside.push_back(d);
    }
    for (std::size_t i = s_.keep; i < inside.size(); ++i) fs::remove_all(inside[i]);
  }
  last_ = std::chrono::steady_clock::now();
}

std::string CheckpointPolicy::summary(double run_wall_s) const {
  if (n_ == 0) return "";
  std::ostringstream cs;
  cs << std::setprecision(3) << n_ << " written in " << seconds_ << " s ("
     << 100.0 * seconds_ / std::max(run_wall_s, 1e-9) << " % of the run), " << mb_ << " MB in all, the last " << last_mb_
     << " MB";
  return cs.str();
}

namespace {

// Every key of a scene with the value in effect, as text: "dem.specimen.d50" -> "1e-05",
// "stage[2].name" -> "\"gravity\"".
std::map<std::string, std::string> flatten(const config::Scene& s) {
  std::map<std::string, std::string> out;
  auto tbl = toml::parse(s.effective_toml());
  std::function<void(const toml::node&, const std::string&)> walk = [&](const toml::node& n, const std::string& path) {
    if (auto t = n.as_table()) {
      for (auto& [k, v] : *t) walk(v, path.empty() ? std::string(k.str()) : path + "." + std::string(k.str()));
    } else if (auto a = n.as_array(); a && !a->empty() && a->front().is_table()) {
      for (std::size_t i = 0; i < a->size(); ++i) walk(*a->get(i), path + "[" + std::to_string(i) + "]");
    } else {
      std::ostringstream os;
      if (auto a2 = n.as_array())
        os << *a2;
      else
        n.visit([&](auto&& v) { os << v; });
      out[path] = os.str();
    }
  };
  walk(tbl, "");
  return out;
}

bool starts(const std::string& s, const std::string& p) { return s.rfind(p, 0) == 0; }

}  // namespace

std::vector<std::string> branch_conflicts(const config::Scene& saved, const config::Scene& scene,
                                          const CheckpointRecord& rec, const Manifest& m) {
  std::vector<std::string> out;
  if (m.in_stage) {
    out.push_back("checkpoint " + m.tag + " lies inside stage '" + m.stage_name +
                  "': a branch starts from a stage-end checkpoint (<stage>-<step>-end); use launch/run --resume to "
                  "continue this run");
    return out;
  }
  const std::size_t ran = rec.runner.stage;  // stages 0..ran-1 have run
  const bool any_ran = ran > 0;
  std::set<std::string> took_part(rec.participated.begin(), rec.participated.end());
  auto a = flatten(saved), b = flatten(scene);
  // Keys a branch may change.
  auto free_key = [&](const std::string& k) {
    if (starts(k, "stage[")) {
      auto idx = std::stoul(k.substr(6));
      return idx >= ran;
    }
    for (const char* p : {"dem.dt_safety", "dem.damping", "dem.dt_fixed", "dem.dt_above_critical", "dem.footing.",
                          "dem.output.", "dem.escape_margin", "dem.ranks", "dem.decomposition", "dem.balance_", "dem.newton", "coupling.",
                          "output.", "bus.", "run.threads", "run.thread_independent", "run.order_free_sums", "run.name",
                          "run.description", "run.guard_", "run.checkpoint_", "continuum.output."})
      if (starts(k, p)) return true;
    if (starts(k, "continuum.")) return !took_part.count("continuum");
    if (starts(k, "dem.") || starts(k, "gravity.") || starts(k, "run.seed")) return !any_ran;
    return false;
  };
  std::set<std::string> keys;
  for (auto& [k, v] : a) keys.insert(k);
  for (auto& [k, v] : b) keys.insert(k);
  for (auto& k : keys) {
    auto ia = a.find(k), ib = b.find(k);
    const std::string va = ia == a.end() ? "(absent)" : ia->second, vb = ib == b.end() ? "(absent)" : ib->second;
    if (va == vb || free_key(k)) continue;
    out.push_back(scene.origin() + ": " + k + ": the saved state has " + va + ", the scene " + vb);
  }
  // A node that took part in a stage must be played by the same solver (its state is its own).
  for (auto& [role, solver] : rec.nodes) {
    if (!took_part.count(role)) continue;
    if (!scene.has(role))
      out.push_back(scene.origin() + ": [" + role + "]: the saved state has a " + role + " node (" + solver +
                    ") that took part in a stage, the scene has none");
  }
  if (schema::stages(scene).size() < ran)
    out.push_back(scene.origin() + ": [[stage]]: the saved state ran " + std::to_string(ran) + " stages, the scene has " +
                  std::to_string(schema::stages(scene).size()));
  return out;
}

}  // namespace demfdm::coord
