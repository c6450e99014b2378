// Golden files (issue 15 item 1): text files in tests/golden/data/ that a run must reproduce byte
// for byte. DEMFDM_GOLDEN_UPDATE=1 in the environment writes them instead (only for a deliberate
// change of physics; say so in the commit). Used by tests/golden (contact laws) and
// tests/stability/determinism_test.cpp (the reduced coupled footing's histories).
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace demfdm::golden {

inline std::string data_dir() { return std::string(DEMFDM_SOURCE_DIR) + "/tests/golden/data"; }

inline bool update_mode() {
  const char* up = std::getenv("DEMFDM_GOLDEN_UPDATE");
  return up && std::string(up) == "1";
}

/// Exact text of a double (C99 hexadecimal: "0x1.8p+1").
inline std::string hx(double v) {
  char b[64];
  std::snprintf(b, sizeof b, "%a", v);
  return b;
}

/// A golden line for people: every hexadecimal float followed by its decimal value.
inline std::string readable(const std::string& line) {
  std::istringstream in(line);
  std::string out, tok;
  while (in >> tok) {
    out += out.empty() ? "" : " ";
    out += tok;
    if (tok.rfind("0x", 0) == 0 || tok.rfind("-0x", 0) == 0) {
      char b[32];
      std::snprintf(b, sizeof b, "(%.9g)", std::strtod(tok.c_str(), nullptr));
      out += b;
    }
  }
  return out;
}

inline std::vector<std::string> lines(const std::string& s) {
  std::vector<std::string> v;
  std::istringstream in(s);
  for (std::string l; std::getline(in, l);) v.push_back(l);
  return v;
}

inline std::string slurp(const std::string& path, bool& ok) {
  std::ifstream f(path);
  ok = static_cast<bool>(f);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

/// Writes `text` as golden file `name` (update mode).
inline void write(const std::string& name, const std::string& text) {
  std::filesystem::create_directories(data_dir());
  std::ofstream(data_dir() + "/" + name) << text;
}

/// Differences of `now` from golden file `name`: empty when equal byte for byte, else one
/// message per differing line (at most `max_shown`, then the line counts), for people.
inline std::vector<std::string> compare(const std::string& name, const std::string& now, int max_shown = 4) {
  const std::string path = data_dir() + "/" + name;
  bool ok = false;
  const std::string gold = slurp(path, ok);
  if (!ok) return {"no golden file " + path + " (write it with DEMFDM_GOLDEN_UPDATE=1)"};
  if (gold == now) return {};
  std::vector<std::string> out;
  const auto g = lines(gold), n = lines(now);
  for (std::size_t i = 0; i < std::max(g.size(), n.size()) && static_cast<int>(out.size()) < max_shown; ++i) {
    const std::string a = i < g.size() ? g[i] : "<end of file>", b = i < n.size() ? n[i] : "<end of output>";
    if (a != b)
      out.push_back(path + " line " + std::to_string(i + 1) + ":\n  golden: " + readable(a) + "\n  now:    " + readable(b));
  }
  if (g.size() != n.size())
    out.push_back(path + ": " + std::to_string(g.size()) + " lines, now " + std::to_string(n.size()));
  if (out.empty()) out.push_back(path + ": differs (line endings)");
  return out;
}

}  // namespace demfdm::golden
