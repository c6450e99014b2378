// Scene loading and validation against a Schema, and read access to the result.
//
// Validation walks the declared schema and the parsed TOML tree together and
// records every problem with its source position; the problem that comes first in
// the file is reported (one line), so the message does not depend on toml++'s
// key order. Cross-field checks run only on a scene that passed every per-key check.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <sstream>
#include <toml++/toml.h>

#include "internal.hpp"

namespace demfdm::config {

namespace fs = std::filesystem;
using detail::Array;
using detail::Data;
using detail::Entry;
using detail::format_number;
using detail::join_path;
using detail::Node;
using detail::Pos;
using detail::SetInfo;

namespace {

// The source name given to toml++ when it parses the value of override i (1-based): a node
// moved from there into the scene's table keeps it, so every position derived from it (an
// entry, a list element, a table an override created) is known to be that override's.
const std::string kSetSource = "\x1f" "demfdm --set #";

Pos pos_of(const toml::source_region& r) {
  if (r.path && r.path->size() > kSetSource.size() && r.path->compare(0, kSetSource.size(), kSetSource) == 0)
    return Pos{0, 0, std::stoi(r.path->substr(kSetSource.size()))};
  return Pos{static_cast<int>(r.begin.line), static_cast<int>(r.begin.column)};
}

std::string quote(std::string_view s) {
  std::string q;  // (built by appending: "'" + s + "'" trips a false -Wrestrict in GCC 12)
  q.reserve(s.size() + 2);
  q += '\'';
  q.append(s);
  q += '\'';
  return q;
}

// "file:line:col" for a position in the file, "--set table.key=value" for an override's.
std::string source_of(const std::string& origin, const std::vector<SetInfo>& sets, Pos p) {
  if (p.set > 0 && static_cast<std::size_t>(p.set) <= sets.size())
    return "--set " + sets[static_cast<std::size_t>(p.set - 1)].text;
  std::string m = origin;
  if (p.line > 0) m += ":" + std::to_string(p.line) + ":" + std::to_string(p.col);
  return m;
}

// Error::file: the file, or "--set table.key=value" for an override's position.
std::string file_of(const std::string& origin, const std::vector<SetInfo>& sets, Pos p) {
  return p.set > 0 ? source_of(origin, sets, p) : origin;
}

// "file:line:col: key: tail"; for an override "--set table.key=value: tail", naming the key
// only when it is not the override's own (an element of a list, a key of a created table).
std::string message(const std::string& origin, const std::vector<SetInfo>& sets, Pos p,
                    const std::string& key, const std::string& tail) {
  std::string m = source_of(origin, sets, p) + ": ";
  const bool own = p.set > 0 && static_cast<std::size_t>(p.set) <= sets.size() &&
                   sets[static_cast<std::size_t>(p.set - 1)].path == key;
  if (!key.empty() && !own) m += key + ": ";
  return m + tail;
}

// "found ..." text for a value of the wrong type: TOML type and value.
std::string found_node(const toml::node& n) {
  switch (n.type()) {
    case toml::node_type::string: return "string " + quote(n.as_string()->get());
    case toml::node_type::integer: return "integer " + std::to_string(n.as_integer()->get());
    case toml::node_type::floating_point: return "float " + format_number(n.as_floating_point()->get());
    case toml::node_type::boolean: return std::string("boolean ") + (n.as_boolean()->get() ? "true" : "false");
    case toml::node_type::table: return "table";
    case toml::node_type::array: {
      std::size_t k = n.as_array()->size();
      return "array of " + std::to_string(k) + (k == 1 ? " element" : " elements");
    }
    default: {
      std::ostringstream os;
      os << n.type() << " ";
      n.visit([&](auto&& x) { os << x; });
      return os.str();
    }
  }
}

Param element_param(const Param& p) {
  Param e = p;
  e.kind = p.kind == Kind::RealList ? Kind::Real
           : p.kind == Kind::IntList ? Kind::Int
                                     : Kind::String;
  e.length.reset();
  e.def.reset();
  return e;
}

struct Issue {
  Pos pos;
  bool missing = false;  // "missing required ..." (reported only if nothing else is wrong)
  std::string key;
  std::string text;  // the full one-line message
};

class Loader {
 public:
  Loader(std::string origin, std::string base_dir, const std::vector<SetInfo>& sets)
      : origin_(std::move(origin)), base_dir_(std::move(base_dir)), sets_(sets) {}

  // Fill `node` (already carrying path, section_path, parent-inherited pos) from the
  // schema section `sec` and the TOML table `tbl` (nullptr: section absent).
  void fill(const Section& sec, const toml::table* tbl, Node& node) {
    node.present = tbl != nullptr;
    if (tbl && !node.path.empty()) node.pos = pos_of(tbl->source());

    if (tbl) report_unknown(sec, *tbl, node);

    for (const auto& m : sec.members()) {
      if (m.param) {
        fill_param(*m.param, tbl ? tbl->get(m.param->name) : nullptr, node);
      } else if (!m.section->is_array()) {
        fill_section(*m.section, tbl ? tbl->get(m.section->name()) : nullptr, node);
      } else {
        fill_array(*m.section, tbl ? tbl->get(m.section->name()) : nullptr, node);
      }
    }
  }

  const std::vector<Issue>& issues() const { return issues_; }

 private:
  void issue(Pos p, const std::string& key, const std::string& tail, bool missing = false) {
    issues_.push_back(Issue{p, missing, key, message(origin_, sets_, p, key, tail)});
  }

  void report_unknown(const Section& sec, const toml::table& tbl, const Node& node) {
    std::vector<std::string> names;
    for (const auto& m : sec.members())
      names.push_back(m.param ? m.param->name : m.section->name());
    for (auto&& [k, v] : tbl) {
      if (sec.find(k.str())) continue;
      bool is_section = v.is_table() || v.is_array_of_tables();
      std::string tail = is_section ? "unknown section" : "unknown key";
      if (const std::string* hint = sec.moved_hint(k.str())) {
        tail += "; it moved: " + *hint;
      } else {
        std::string best = detail::suggest(k.str(), names);
        if (!best.empty()) tail += "; did you mean " + quote(best) + "?";
      }
      issue(pos_of(k.source()), join_path(node.path, k.str()), tail);
    }
  }

  void fill_section(const Section& sec, const toml::node* v, Node& parent) {
    auto child = std::make_unique<Node>();
    child->path = join_path(parent.path, sec.name());
    child->section_path = sec.path();
    child->pos = parent.pos;
    const toml::table* t = nullptr;
    if (v) {
      t = v->as_table();
      if (!t)
        issue(pos_of(v->source()), child->path,
              "expected a table [" + sec.path() + "], found " + found_node(*v));
    } else if (parent.present && sec.presence() == Presence::Required) {
      issue(parent.pos, child->path,
            "missing required section; expected a table [" + sec.path() + "]", true);
    }
    fill(sec, t, *child);
    parent.sections.emplace(sec.name(), std::move(child));
  }

  void fill_array(const Section& sec, const toml::node* v, Node& parent) {
    Array arr;
    arr.pos = parent.pos;
    const std::string path = join_path(parent.path, sec.name());
    const std::string want = "an array of tables [[" + sec.path() + "]]";
    const toml::array* a = v ? v->as_array() : nullptr;
    if (v && (!a || !a->is_array_of_tables())) {
      // An empty array `stage = []` is accepted as "no elements".
      if (!(a && a->empty())) {
        issue(pos_of(v->source()), path, "expected " + want + ", found " + found_node(*v));
        a = nullptr;
      }
    }
    if (a && !a->empty()) arr.pos = pos_of((*a)[0].source());
    if (parent.present && sec.presence() == Presence::Required && (!a || a->empty()) &&
        !(v && !a))
      issue(parent.pos, path,
            "missing required section; expected at least one [[" + sec.path() + "]] table",
            true);
    if (a) {
      for (std::size_t i = 0; i < a->size(); ++i) {
        auto elem = std::make_unique<Node>();
        elem->path = path + "[" + std::to_string(i) + "]";
        elem->section_path = sec.path();
        elem->pos = parent.pos;
        fill(sec, (*a)[i].as_table(), *elem);
        arr.elems.push_back(std::move(elem));
      }
    }
    parent.arrays.emplace(sec.name(), std::move(arr));
  }

  void fill_param(const Param& p, const toml::node* v, Node& node) {
    Entry e;
    e.kind = p.kind;
    e.pos = node.pos;
    const std::string key = join_path(node.path, p.name);
    if (v) {
      e.explicit_set = true;
      e.pos = pos_of(v->source());
      e.value = convert(p, *v, key);  // empty on error (issue recorded)
      if (const toml::array* a = v->as_array())
        for (const auto& el : *a) e.elem_pos.push_back(pos_of(el.source()));
    } else if (p.def) {
      e.value = *p.def;
      // A defaulted path is resolved (and checked, if the section is in use);
      // an empty default means "no file".
      if (p.kind == Kind::Path && !std::get<std::string>(*p.def).empty()) {
        std::string raw = std::get<std::string>(*p.def);
        std::string resolved = resolve_path(raw);
        if (node.present && !fs::is_regular_file(resolved))
          issue(node.pos, key,
                "expected an existing file (default), found " + quote(raw) + " (resolved to " +
                    resolved + ")");
        e.value = resolved;
      }
    } else if (node.present) {
      issue(node.pos, key, "missing required key; expected " + describe(p), true);
    }
    node.params.emplace(p.name, std::move(e));
  }

  std::string resolve_path(const std::string& raw) const {
    fs::path p(raw);
    if (p.is_relative()) p = fs::path(base_dir_) / p;
    std::error_code ec;
    fs::path abs = fs::absolute(p, ec);
    return (ec ? p : abs).lexically_normal().string();
  }

  // Scalar check for Bool/Int/Real/String/Choice/Path (also list elements).
  std::optional<Value> convert_scalar(const Param& p, const toml::node& v,
                                      const std::string& key) {
    const Pos at = pos_of(v.source());
    auto wrong = [&] {
      issue(at, key, "expected " + describe(p) + ", found " + found_node(v));
      return std::optional<Value>{};
    };
    switch (p.kind) {
      case Kind::Bool:
        if (!v.is_boolean()) return wrong();
        return Value(v.as_boolean()->get());
      case Kind::Int: {
        if (v.is_string() && !p.word.empty() && v.as_string()->get() == p.word) return Value(p.word);
        if (!v.is_integer()) return wrong();
        std::int64_t x = v.as_integer()->get();
        if (!detail::in_range(p, static_cast<double>(x))) {
          issue(at, key, "expected " + describe(p) + ", found " + std::to_string(x));
          return std::nullopt;
        }
        return Value(x);
      }
      case Kind::Real: {
        double x;
        if (v.is_string() && !p.word.empty() && v.as_string()->get() == p.word) return Value(p.word);
        if (v.is_integer())
          x = static_cast<double>(v.as_integer()->get());  // int -> real promotion
        else if (v.is_floating_point())
          x = v.as_floating_point()->get();
        else
          return wrong();
        if (std::isnan(x) || !detail::in_range(p, x)) {
          issue(at, key, "expected " + describe(p) + ", found " + format_number(x));
          return std::nullopt;
        }
        return Value(x);
      }
      case Kind::String:
        if (!v.is_string()) return wrong();
        return Value(v.as_string()->get());
      case Kind::Choice: {
        if (!v.is_string()) return wrong();
        const std::string& s = v.as_string()->get();
        if (std::find(p.choices.begin(), p.choices.end(), s) == p.choices.end()) {
          issue(at, key, "expected " + describe(p) + ", found " + quote(s));
          return std::nullopt;
        }
        return Value(s);
      }
      case Kind::Path: {
        if (!v.is_string()) return wrong();
        const std::string& raw = v.as_string()->get();
        // An empty path is allowed only where the schema's default is empty ("no file").
        if (raw.empty() && p.def && std::get<std::string>(*p.def).empty()) return Value(raw);
        std::string resolved = resolve_path(raw);
        if (raw.empty() || !fs::is_regular_file(resolved)) {
          issue(at, key,
                "expected an existing file, found " + quote(raw) + " (resolved to " + resolved +
                    ")");
          return std::nullopt;
        }
        return Value(resolved);
      }
      default: return wrong();
    }
  }

  std::optional<Value> convert(const Param& p, const toml::node& v, const std::string& key) {
    if (p.kind != Kind::RealList && p.kind != Kind::IntList && p.kind != Kind::StringList)
      return convert_scalar(p, v, key);
    const toml::array* a = v.as_array();
    if (!a) {
      issue(pos_of(v.source()), key, "expected " + describe(p) + ", found " + found_node(v));
      return std::nullopt;
    }
    const std::size_t n = a->size();
    if (p.length && n != *p.length) {
      const std::string found =
          "found " + std::to_string(n) + (n == 1 ? " element" : " elements");
      if (n < *p.length)  // name the first missing index, at the array
        issue(pos_of(v.source()), key + "[" + std::to_string(n) + "]",
              "missing element; expected " + describe(p) + ", " + found);
      else  // name the first extra element, at that element
        issue(pos_of((*a)[*p.length].source()), key + "[" + std::to_string(*p.length) + "]",
              "unexpected element; expected " + describe(p) + ", " + found);
      return std::nullopt;
    }
    const Param ep = element_param(p);
    std::vector<double> reals;
    std::vector<std::int64_t> ints;
    std::vector<std::string> strs;
    bool ok = true;
    for (std::size_t i = 0; i < n; ++i) {
      auto x = convert_scalar(ep, (*a)[i], key + "[" + std::to_string(i) + "]");
      if (!x) {
        ok = false;
        continue;
      }
      if (p.kind == Kind::RealList) reals.push_back(std::get<double>(*x));
      else if (p.kind == Kind::IntList) ints.push_back(std::get<std::int64_t>(*x));
      else strs.push_back(std::get<std::string>(*x));
    }
    if (!ok) return std::nullopt;
    if (p.kind == Kind::RealList) return Value(std::move(reals));
    if (p.kind == Kind::IntList) return Value(std::move(ints));
    return Value(std::move(strs));
  }

  std::string origin_, base_dir_;
  const std::vector<SetInfo>& sets_;
  std::vector<Issue> issues_;
};

std::uint64_t fnv1a64(std::string_view s) {
  std::uint64_t h = 14695981039346656037ull;  // FNV offset basis
  for (unsigned char c : s) {
    h ^= c;
    h *= 1099511628211ull;  // FNV prime
  }
  return h;
}

// Read a whole file with POSIX calls so errno (ENOENT, EACCES, EISDIR) is exact.
std::string read_file(const std::string& path) {
  auto fail = [&](int err) -> std::string {
    throw Error(path + ": cannot read scene file: " + std::strerror(err), path, 0, 0, "");
  };
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail(errno);
  std::string out;
  char buf[1 << 16];
  for (;;) {
    ssize_t k = ::read(fd, buf, sizeof buf);
    if (k < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      ::close(fd);
      fail(err);
    }
    if (k == 0) break;
    out.append(buf, static_cast<std::size_t>(k));
  }
  ::close(fd);
  return out;
}

std::shared_ptr<const Data> empty_data() {
  auto d = std::make_shared<Data>();
  d->hash = fnv1a64("");
  d->root.pos = Pos{1, 1};
  return d;
}

[[noreturn]] void usage_error(const std::string& what) {
  throw std::logic_error("config: " + what);
}

// ---------------------------------------------------------------------------
// Overrides ("table.key=value", launch/run --set): applied to the parsed file's table before
// validation, so an override goes through exactly the checks a key in the file does.
// ---------------------------------------------------------------------------
[[noreturn]] void set_error(const std::string& text, const std::string& tail) {
  throw Error("--set " + text + ": " + tail, "--set " + text, 0, 0, "");
}

// A TOML node parsed from `value_text` under the source name of override `index` (1-based):
// the value, or (with `as_table`) an empty table for a section the override creates. A value
// that is not TOML and does not look like an attempt at an array, table or quoted string is
// taken as a string, so that `run.name=x` works after the shell removed the quotes.
toml::table parse_set_node(const std::string& text, std::size_t index, const std::string& value_text,
                           bool as_table) {
  const std::string source = kSetSource + std::to_string(index);
  auto attempt = [&](const std::string& v) { return toml::parse("v = " + v + "\n", source); };
  if (as_table) return attempt("{}");
  try {
    toml::table doc = attempt(value_text);
    if (doc.size() != 1) set_error(text, "expected one TOML value after '=', found more");
    return doc;
  } catch (const toml::parse_error& e) {
    const char c = value_text.front();
    if (c == '[' || c == '{' || c == '"' || c == '\'' || value_text.find('\n') != std::string::npos) {
      std::string desc(e.description());
      std::replace(desc.begin(), desc.end(), '\n', ' ');
      set_error(text, "the value is not TOML: " + desc);
    }
    return attempt(format_value(Value(value_text)));  // a TOML basic string
  }
}

// Applies one override to `root` (the file's table) and returns the key path it resolved to.
std::string apply_override(toml::table& root, const Schema& schema, const std::string& text,
                           std::size_t index) {
  const auto eq = text.find('=');
  if (eq == std::string::npos)
    set_error(text, "expected table.key=value (stage keys: stage.NAME.key=value or stage[i].key=value), found no '='");
  auto trim = [](std::string s) {
    const auto a = s.find_first_not_of(" \t"), b = s.find_last_not_of(" \t");
    return a == std::string::npos ? std::string() : s.substr(a, b - a + 1);
  };
  const std::string key = trim(text.substr(0, eq)), value = trim(text.substr(eq + 1));
  if (key.empty()) set_error(text, "expected table.key=value, found no key before '='");
  if (value.empty()) set_error(text, "expected a TOML value after '=' (an empty string is \"\")");

  std::vector<std::string> segs;
  for (std::size_t a = 0;;) {
    const auto dot = key.find('.', a);
    segs.push_back(key.substr(a, dot == std::string::npos ? std::string::npos : dot - a));
    if (dot == std::string::npos) break;
    a = dot + 1;
  }
  const Section* sec = &schema.root();
  toml::table* tbl = &root;
  std::string path;  // resolved, with indices
  for (std::size_t i = 0; i < segs.size(); ++i) {
    std::string seg = segs[i];
    std::optional<std::size_t> idx;
    if (const auto lb = seg.find('['); lb != std::string::npos) {
      const std::string num = seg.size() > lb + 2 && seg.back() == ']' ? seg.substr(lb + 1, seg.size() - lb - 2) : "";
      if (num.empty() || num.find_first_not_of("0123456789") != std::string::npos || num.size() > 9)
        set_error(text, "bad index in '" + seg + "'; expected name[i] with i = 0, 1, ...");
      idx = static_cast<std::size_t>(std::stoul(num));
      seg = seg.substr(0, lb);
    }
    if (seg.empty()) set_error(text, "empty name in key '" + key + "'");
    const std::string here = join_path(path, seg);
    const bool last = i + 1 == segs.size();
    const Section::Member* m = sec->find(seg);
    if (!m) {
      std::vector<std::string> names;
      for (const auto& mm : sec->members()) names.push_back(mm.param ? mm.param->name : mm.section->name());
      std::string tail = std::string(path.empty() ? "unknown section " : "unknown key ") + quote(here);
      if (const std::string* hint = sec->moved_hint(seg)) {
        tail += "; it moved: " + *hint;
      } else {
        std::string best = detail::suggest(seg, names);
        if (!best.empty()) tail += "; did you mean " + quote(join_path(path, best)) + "?";
      }
      set_error(text, tail);
    }
    if (idx && !(m->section && m->section->is_array()))
      set_error(text, quote(here) + " is not an array of tables; only [[...]] elements are indexed");
    if (m->param) {
      if (!last) set_error(text, quote(here) + " is a key, not a table");
      toml::table doc = parse_set_node(text, index, value, false);
      tbl->insert_or_assign(seg, std::move(*doc.get("v")));
      return here;
    }
    if (last)
      set_error(text, quote(here) + (m->section->is_array()
                                         ? " is an array of tables; set a key of one element: " + here +
                                               ".NAME.key=value or " + here + "[i].key=value"
                                         : " is a section; set one of its keys: " + here + ".key=value"));
    toml::node* child = tbl->get(seg);
    if (!m->section->is_array()) {
      if (!child) {  // a section the file does not have: the override creates it
        toml::table doc = parse_set_node(text, index, "", true);
        tbl->insert_or_assign(seg, std::move(*doc.get("v")));
        child = tbl->get(seg);
      }
      if (!child->is_table()) set_error(text, quote(here) + " is not a table in the scene");
      tbl = child->as_table();
      sec = m->section;
      path = here;
      continue;
    }
    // An element of an array of tables, by index or by its `name` key.
    toml::array* arr = child ? child->as_array() : nullptr;
    const std::size_t n = arr ? arr->size() : 0;
    const std::string header = "[[" + m->section->path() + "]]";
    std::size_t k = 0;
    if (idx) {
      if (*idx >= n)
        set_error(text, "no element " + here + "[" + std::to_string(*idx) + "]: the scene has " + std::to_string(n) +
                            " " + header + " table" + (n == 1 ? "" : "s"));
      k = *idx;
    } else {
      const std::string name = segs[++i];
      if (i + 1 == segs.size())
        set_error(text, "expected a key after the element name: " + here + "." + name + ".key=value");
      const Section::Member* nm = m->section->find("name");
      if (!nm || !nm->param)
        set_error(text, header + " elements have no name; index them: " + here + "[i].key=value");
      std::vector<std::size_t> hits;
      std::string names;
      for (std::size_t j = 0; j < n; ++j) {
        const toml::table* e = (*arr)[j].as_table();
        const toml::node* nv = e ? e->get("name") : nullptr;
        if (!nv || !nv->is_string()) continue;
        const std::string& s = nv->as_string()->get();
        names += (names.empty() ? "" : ", ") + s;
        if (s == name) hits.push_back(j);
      }
      if (hits.empty())
        set_error(text, "no " + header + " named " + quote(name) + (names.empty() ? "" : " (the scene's: " + names + ")"));
      if (hits.size() > 1)
        set_error(text, std::to_string(hits.size()) + " " + header + " tables are named " + quote(name) +
                            "; index one: " + here + "[" + std::to_string(hits[0]) + "].key=value");
      k = hits[0];
    }
    if (!(*arr)[k].is_table()) set_error(text, here + "[" + std::to_string(k) + "] is not a table in the scene");
    tbl = (*arr)[k].as_table();
    sec = m->section;
    path = here + "[" + std::to_string(k) + "]";
  }
  set_error(text, "expected table.key=value");  // not reached: the loop returns at the key
}


}  // namespace

// ---------------------------------------------------------------------------
// Loading
// ---------------------------------------------------------------------------
Scene::Scene() : data_(empty_data()), node_(&data_->root) {}

Scene Scene::load(const std::string& path, const Schema& schema,
                  const std::vector<std::string>& overrides) {
  std::string text = read_file(path);
  fs::path dir = fs::path(path).parent_path();
  return parse(text, path, schema, dir.empty() ? "." : dir.string(), overrides);
}

namespace {
std::string effective_text(const Data& d);
}

Scene Scene::parse(std::string_view text, std::string origin, const Schema& schema,
                   std::string base_dir, const std::vector<std::string>& overrides) {
  toml::table tbl;
  try {
    tbl = toml::parse(text, std::string_view(origin));
  } catch (const toml::parse_error& e) {
    Pos p = pos_of(e.source());
    std::string desc(e.description());
    std::replace(desc.begin(), desc.end(), '\n', ' ');  // keep the message on one line
    throw Error(message(origin, {}, p, "", "TOML syntax error: " + desc),
                origin, p.line, p.col, "");
  }

  auto data = std::make_shared<Data>();
  data->text = std::string(text);
  data->origin = origin;
  data->hash = data->source_hash = fnv1a64(text);
  data->root.pos = Pos{1, 1};  // missing top-level keys/sections are reported at 1:1
  for (std::size_t i = 0; i < overrides.size(); ++i) {
    data->sets.push_back(SetInfo{overrides[i], ""});
    data->sets.back().path = apply_override(tbl, schema, overrides[i], i + 1);
  }

  Loader loader(origin, std::move(base_dir), data->sets);
  loader.fill(schema.root(), &tbl, data->root);
  data->root.pos = Pos{1, 1};

  const auto& issues = loader.issues();
  if (!issues.empty()) {
    // The first problem in file order (ties keep discovery order), after those of the
    // overrides (in the order given). Missing keys and sections come last: they are reported
    // at their table's header, and a misspelled name ("unknown section; did you mean
    // 'contact'?") is the more useful message.
    auto first = std::min_element(issues.begin(), issues.end(), [](const Issue& a, const Issue& b) {
      if (a.missing != b.missing) return !a.missing;
      if ((a.pos.set > 0) != (b.pos.set > 0)) return a.pos.set > 0;
      if (a.pos.set != b.pos.set) return a.pos.set < b.pos.set;
      return a.pos.line != b.pos.line ? a.pos.line < b.pos.line : a.pos.col < b.pos.col;
    });
    throw Error(first->text, file_of(origin, data->sets, first->pos), first->pos.line, first->pos.col,
                first->key);
  }
  // With overrides, the text is the effective scene (what the bus carries to the nodes): a
  // receiver parsing it gets the overridden values.
  if (!data->sets.empty()) {
    data->text = effective_text(*data);
    data->hash = fnv1a64(data->text);
  }

  Scene scene;
  scene.data_ = std::move(data);
  scene.node_ = &scene.data_->root;
  scene.prefix_.clear();
  CheckContext ctx(scene);
  for (const auto& check : schema.checks()) {
    try {
      check(scene, ctx);
    } catch (const Error& e) {
      // A cross-field check that blames a key of the file may fail because of an override
      // (a larger replicate against the file's mesh size): the message names the overrides.
      if (scene.data_->sets.empty() || e.line == 0) throw;
      std::string with;
      for (const auto& s : scene.data_->sets) with += (with.empty() ? "--set " : ", --set ") + s.text;
      throw Error(std::string(e.what()) + " (with " + with + ")", e.file, e.line, e.col, e.key);
    }
  }
  return scene;
}

// ---------------------------------------------------------------------------
// Path resolution and access
// ---------------------------------------------------------------------------
struct Scene::Target {
  const Node* parent = nullptr;   // table holding the last segment
  const Entry* entry = nullptr;   // a parameter
  const Node* section = nullptr;  // a section or an indexed array element
  const Array* array = nullptr;   // an array of tables, not indexed
  std::optional<std::size_t> elem;  // "key[i]": element i of a list parameter
  bool out_of_range = false;      // an index past the end (has() -> false)
  std::string full;               // full dotted path for messages
  Pos pos() const;
};

Scene::Target Scene::resolve(std::string_view path) const {
  Target t;
  const Node* cur = node_;
  std::string_view rest = path;
  if (rest.empty()) usage_error("empty key path");
  for (;;) {
    auto dot = rest.find('.');
    std::string_view seg = rest.substr(0, dot);
    bool last = dot == std::string_view::npos;
    std::optional<std::size_t> index;
    if (auto lb = seg.find('['); lb != std::string_view::npos) {
      if (seg.back() != ']') usage_error("bad key path '" + std::string(path) + "'");
      std::string_view num = seg.substr(lb + 1, seg.size() - lb - 2);
      std::size_t i = 0;
      if (num.empty() || num.find_first_not_of("0123456789") != std::string_view::npos)
        usage_error("bad index in key path '" + std::string(path) + "'");
      for (char c : num) i = i * 10 + static_cast<std::size_t>(c - '0');
      index = i;
      seg = seg.substr(0, lb);
    }
    const std::string full = join_path(cur->path, seg);
    t.parent = cur;
    t.full = index ? full + "[" + std::to_string(*index) + "]" : full;
    const Node* next = nullptr;
    if (index) {
      auto it = cur->arrays.find(seg);
      if (it == cur->arrays.end()) {
        // "key[i]" on a list parameter: element i, for where(), fail() and has().
        auto ip = cur->params.find(seg);
        if (!last || ip == cur->params.end() ||
            (ip->second.kind != Kind::RealList && ip->second.kind != Kind::IntList &&
             ip->second.kind != Kind::StringList))
          usage_error("'" + full + "' is neither an array of tables nor a list parameter");
        t.entry = &ip->second;
        t.elem = index;
        std::size_t n = 0;
        if (const Value* v = t.entry->value ? &*t.entry->value : nullptr) {
          if (auto* r = std::get_if<std::vector<double>>(v)) n = r->size();
          if (auto* i = std::get_if<std::vector<std::int64_t>>(v)) n = i->size();
          if (auto* k = std::get_if<std::vector<std::string>>(v)) n = k->size();
        }
        t.out_of_range = *index >= n;
        return t;
      }
      if (*index >= it->second.elems.size()) {
        if (!last)
          throw std::out_of_range("config: '" + t.full + "': index out of range (" +
                                  std::to_string(it->second.elems.size()) + " elements)");
        t.out_of_range = true;
        return t;
      }
      next = it->second.elems[*index].get();
    } else if (last) {
      if (auto it = cur->params.find(seg); it != cur->params.end()) {
        t.entry = &it->second;
      } else if (auto is = cur->sections.find(seg); is != cur->sections.end()) {
        t.section = is->second.get();
      } else if (auto ia = cur->arrays.find(seg); ia != cur->arrays.end()) {
        t.array = &ia->second;
      } else {
        usage_error("'" + full + "' is not a declared key");
      }
      return t;
    } else {
      auto is = cur->sections.find(seg);
      if (is == cur->sections.end()) {
        if (cur->arrays.count(seg))
          usage_error("'" + full + "' is an array of tables; index it as '" +
                      std::string(seg) + "[i]'");
        usage_error("'" + full + "' is not a declared section");
      }
      next = is->second.get();
    }
    if (last) {
      t.section = next;
      return t;
    }
    cur = next;
    rest = rest.substr(dot + 1);
  }
}

const Value& Scene::value_of(std::string_view path, Kind kind, const char* accessor) const {
  Target t = resolve(path);
  if (!t.entry) usage_error("'" + t.full + "' is not a parameter (" + accessor + ")");
  if (t.elem) usage_error("'" + t.full + "': read the whole list, not one element");
  const Kind k = t.entry->kind;
  bool ok = k == kind || (kind == Kind::String && (k == Kind::Choice || k == Kind::Path));
  if (!ok) usage_error("'" + t.full + "' is read with " + accessor + "() but declared as another kind");
  if (!t.entry->value)
    usage_error("'" + t.full + "' has no value: its section '" + t.parent->path +
                "' is absent from the scene (check has() first)");
  return *t.entry->value;
}

const std::string& Scene::text() const { return data_->text; }
std::vector<std::string> Scene::overrides() const {
  std::vector<std::string> out;
  for (const auto& s : data_->sets) out.push_back(s.text);
  return out;
}
std::uint64_t Scene::hash() const { return data_->hash; }
const std::string& Scene::origin() const { return data_->origin; }

bool Scene::has(std::string_view path) const {
  Target t = resolve(path);
  if (t.out_of_range) return false;
  if (t.entry) return t.entry->explicit_set;  // (for "key[i]": and i < its length)
  if (t.section) return t.section->present;
  return !t.array->elems.empty();
}

bool Scene::explicitly_set(std::string_view path) const { return has(path); }

double Scene::real(std::string_view path) const {
  const Value& v = value_of(path, Kind::Real, "real");
  if (const auto* w = std::get_if<std::string>(&v))
    throw std::logic_error("config: " + std::string(path) + " holds '" + *w + "'; read it with real_or_word()");
  return std::get<double>(v);
}
std::optional<double> Scene::real_or_word(std::string_view path) const {
  const Value& v = value_of(path, Kind::Real, "real_or_word");
  if (std::holds_alternative<std::string>(v)) return std::nullopt;
  return std::get<double>(v);
}
std::int64_t Scene::integer(std::string_view path) const {
  const Value& v = value_of(path, Kind::Int, "integer");
  if (const auto* w = std::get_if<std::string>(&v))
    throw std::logic_error("config: " + std::string(path) + " holds '" + *w + "'; read it with integer_or_word()");
  return std::get<std::int64_t>(v);
}
std::optional<std::int64_t> Scene::integer_or_word(std::string_view path) const {
  const Value& v = value_of(path, Kind::Int, "integer_or_word");
  if (std::holds_alternative<std::string>(v)) return std::nullopt;
  return std::get<std::int64_t>(v);
}
bool Scene::boolean(std::string_view path) const {
  return std::get<bool>(value_of(path, Kind::Bool, "boolean"));
}
const std::string& Scene::string(std::string_view path) const {
  return std::get<std::string>(value_of(path, Kind::String, "string"));
}
std::vector<double> Scene::reals(std::string_view path) const {
  return std::get<std::vector<double>>(value_of(path, Kind::RealList, "reals"));
}
std::vector<std::int64_t> Scene::integers(std::string_view path) const {
  return std::get<std::vector<std::int64_t>>(value_of(path, Kind::IntList, "integers"));
}
std::vector<std::string> Scene::strings(std::string_view path) const {
  return std::get<std::vector<std::string>>(value_of(path, Kind::StringList, "strings"));
}

std::size_t Scene::count(std::string_view array_path) const {
  Target t = resolve(array_path);
  if (!t.array) usage_error("'" + t.full + "' is not a declared array of tables");
  return t.array->elems.size();
}

Scene Scene::at(std::string_view array_path, std::size_t i) const {
  Target t = resolve(array_path);
  if (!t.array) usage_error("'" + t.full + "' is not a declared array of tables");
  if (i >= t.array->elems.size())
    throw std::out_of_range("config: '" + t.full + "[" + std::to_string(i) +
                            "]': index out of range (" + std::to_string(t.array->elems.size()) +
                            " elements)");
  Scene s;
  s.data_ = data_;
  s.node_ = t.array->elems[i].get();
  s.prefix_ = s.node_->path;
  return s;
}

// Position of a key, or of its table when the key was defaulted (Entry::pos already
// holds that), or of the nearest present ancestor for an absent section.
Pos Scene::Target::pos() const {
  if (entry && elem && *elem < entry->elem_pos.size()) return entry->elem_pos[*elem];
  return entry ? entry->pos : section ? section->pos : array ? array->pos : parent->pos;
}

std::string Scene::where(std::string_view path) const {
  Pos p = resolve(path).pos();
  if (p.set > 0) return source_of(data_->origin, data_->sets, p);
  return data_->origin + ":" + std::to_string(p.line) + ":" + std::to_string(p.col);
}

void Scene::fail(std::string_view path, std::string_view expected,
                 std::string_view found) const {
  Target t = resolve(path);
  Pos p = t.pos();
  std::string tail = "expected " + std::string(expected) + ", found " + std::string(found);
  throw Error(message(data_->origin, data_->sets, p, t.full, tail), file_of(data_->origin, data_->sets, p),
              p.line, p.col, t.full);
}

namespace {

// A TOML key: bare if it only uses A-Za-z0-9_- (TOML 1.0 bare keys), else quoted.
std::string toml_key(const std::string& k) {
  bool bare = !k.empty() && std::all_of(k.begin(), k.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
  });
  return bare ? k : format_value(Value(k));
}

std::string toml_header_path(const std::string& dotted) {
  std::string out, seg;
  std::istringstream in(dotted);
  while (std::getline(in, seg, '.')) {
    if (!out.empty()) out += '.';
    out += toml_key(seg);
  }
  return out;
}

// Parameters first, then present sub-sections and array elements under absolute headers
// (the declared section path, without indices: TOML attaches [a.b] after [[a]] to the
// last element). Keys in name order, so the text depends only on the values.
void emit(const Node& n, std::ostringstream& os) {
  for (const auto& [name, e] : n.params)
    if (e.value) os << toml_key(name) << " = " << format_value(*e.value) << "\n";
  for (const auto& [name, child] : n.sections) {
    if (!child->present) continue;
    os << "\n[" << toml_header_path(child->section_path) << "]\n";
    emit(*child, os);
  }
  for (const auto& [name, arr] : n.arrays) {
    for (const auto& el : arr.elems) {
      os << "\n[[" << toml_header_path(el->section_path) << "]]\n";
      emit(*el, os);
    }
  }
}

// The header names the source file, the hash of its text and the overrides (one line each).
std::string effective_text(const Data& d) {
  std::ostringstream os;
  os << "# Effective scene: " << d.origin << " (FNV-1a 64 of the source text: " << std::hex
     << d.source_hash << std::dec << "), defaults filled\n";
  for (const auto& s : d.sets) {
    std::string t = s.text;
    std::replace(t.begin(), t.end(), '\n', ' ');
    os << "#   --set " << t << "\n";
  }
  emit(d.root, os);
  return os.str();
}

}  // namespace

std::string Scene::effective_toml() const { return effective_text(*data_); }

void CheckContext::fail(std::string_view key_path, std::string_view expected,
                        std::string_view found) const {
  scene_.fail(key_path, expected, found);
}

}  // namespace demfdm::config
