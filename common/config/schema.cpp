// Schema declaration (Section, ParamBuilder, Schema) and everything generated from
// it without a scene: kind descriptions for messages, help_text() and markdown().
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "internal.hpp"

namespace demfdm::config {

using detail::format_number;
using detail::join_path;

// ---------------------------------------------------------------------------
// Text helpers
// ---------------------------------------------------------------------------
namespace detail {

std::string format_number(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  // Shortest representation that round-trips (std::to_chars without precision).
  auto res = std::to_chars(buf, buf + sizeof buf, v);
  std::string s(buf, res.ptr);
  // Compact the exponent: "1e+09" -> "1e9", "2.5e-05" -> "2.5e-5".
  auto e = s.find('e');
  if (e != std::string::npos) {
    std::string mant = s.substr(0, e);
    std::string ex = s.substr(e + 1);
    bool neg = false;
    std::size_t i = 0;
    if (i < ex.size() && (ex[i] == '+' || ex[i] == '-')) neg = ex[i++] == '-';
    while (i + 1 < ex.size() && ex[i] == '0') ++i;
    s = mant + "e" + (neg ? "-" : "") + ex.substr(i);
  }
  return s;
}

std::string join_path(std::string_view parent, std::string_view name) {
  if (parent.empty()) return std::string(name);
  std::string s(parent);
  s += '.';
  s += name;
  return s;
}

std::size_t edit_distance(std::string_view a, std::string_view b) {
  std::vector<std::size_t> prev(b.size() + 1), cur(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) prev[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    cur[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      std::size_t sub = prev[j - 1] + (a[i - 1] == b[j - 1] ? 0 : 1);
      cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, sub});
    }
    std::swap(prev, cur);
  }
  return prev[b.size()];
}

std::string suggest(std::string_view unknown, const std::vector<std::string>& names) {
  // Rank: a prefix match (either way round) beats a mere small edit distance
  // ("fie" -> "fields", not "dir"); then the smaller distance; ties keep declaration order.
  std::string best;
  bool best_prefix = false;
  std::size_t best_d = 0;
  for (const auto& n : names) {
    std::size_t d = edit_distance(unknown, n);
    bool prefix = !unknown.empty() && !n.empty() &&
                  (n.starts_with(unknown) || unknown.starts_with(std::string_view(n)));
    if (d > 3 && !prefix) continue;
    bool better = best.empty() || (prefix && !best_prefix) ||
                  (prefix == best_prefix && d < best_d);
    if (better) {
      best = n;
      best_prefix = prefix;
      best_d = d;
    }
  }
  return best;
}

std::string range_interval(const Param& p) {
  if (!p.lo && !p.hi) return "";
  std::string s;
  s += (p.lo && !p.lo_open) ? "[" : "(";
  s += p.lo ? format_number(*p.lo) : "-inf";
  s += ", ";
  s += p.hi ? format_number(*p.hi) : "inf";
  s += (p.hi && !p.hi_open) ? "]" : ")";
  return s;
}

std::string range_phrase(const Param& p) {
  if (p.lo && p.hi) return "in " + range_interval(p);
  if (p.lo) return (p.lo_open ? "> " : ">= ") + format_number(*p.lo);
  if (p.hi) return (p.hi_open ? "< " : "<= ") + format_number(*p.hi);
  return "";
}

bool in_range(const Param& p, double x) {
  if (!std::isfinite(x)) return false;  // no key accepts infinity or NaN
  if (p.lo && (p.lo_open ? !(x > *p.lo) : !(x >= *p.lo))) return false;
  if (p.hi && (p.hi_open ? !(x < *p.hi) : !(x <= *p.hi))) return false;
  return true;
}

}  // namespace detail

namespace {

// TOML basic string: escape quote, backslash and control characters.
std::string quote_toml(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\t') {
      out += "\\t";
    } else if (u < 0x20 || u == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof buf, "\\u%04X", u);
      out += buf;
    } else {
      out += c;
    }
  }
  return out + "\"";
}

// "" and "-" both mean dimensionless: no unit in messages or tables.
bool unitless(const std::string& unit) { return unit.empty() || unit == "-"; }

// "a number in [0, 1) Pa" / "an integer >= 1" / "numbers each > 0 m" ...
std::string numeric_phrase(const Param& p, const char* noun) {
  std::string s = noun;
  std::string r = detail::range_phrase(p);
  if (!r.empty()) s += " " + r;
  if (!unitless(p.unit)) s += (r.empty() ? " in " : " ") + p.unit;
  return s;
}

std::string list_phrase(const Param& p, const char* plural) {
  std::string s = "a list of ";
  if (p.length) s += std::to_string(*p.length) + " ";
  s += plural;
  std::string r = detail::range_phrase(p);
  if (!r.empty()) s += " each " + r;
  if (!unitless(p.unit)) s += (r.empty() ? " in " : " ") + p.unit;
  return s;
}

const char* kind_name(const Param& p) {
  switch (p.kind) {
    case Kind::Bool: return "bool";
    case Kind::Int: return "integer";
    case Kind::Real: return "real";
    case Kind::String: return "string";
    case Kind::Choice: return "choice";
    case Kind::Path: return "path";
    case Kind::RealList: return "real list";
    case Kind::IntList: return "integer list";
    case Kind::StringList: return "string list";
  }
  return "?";
}

std::string type_name(const Param& p) {
  std::string s = kind_name(p);
  if (p.length) {  // appended piecewise: GCC 12 warns falsely (-Wrestrict) on "[" + string
    s += '[';
    s += std::to_string(*p.length);
    s += ']';
  }
  return s;
}

std::string range_text(const Param& p) {
  if (p.kind == Kind::Choice) {
    std::string s;
    for (std::size_t i = 0; i < p.choices.size(); ++i)
      s += (i ? ", " : "") + quote_toml(p.choices[i]);
    return s;
  }
  if (p.kind == Kind::Path) return "existing file";
  return detail::range_interval(p);
}

std::string default_text(const Param& p) {
  return p.def ? format_value(*p.def) : std::string("(required)");
}

bool is_numeric(Kind k) {
  return k == Kind::Int || k == Kind::Real || k == Kind::RealList || k == Kind::IntList;
}
bool is_list(Kind k) {
  return k == Kind::RealList || k == Kind::IntList || k == Kind::StringList;
}

// Schema bugs (a default outside its own range, ...) are programming errors.
[[noreturn]] void schema_bug(const std::string& path, const std::string& what) {
  throw std::logic_error("config schema: " + path + ": " + what);
}

void check_default(const Param& p, const std::string& path) {
  if (!p.def) return;
  const Value& v = *p.def;
  auto check_num = [&](double x, const std::string& where) {
    if (!detail::in_range(p, x))
      schema_bug(where, "default " + format_number(x) + " is not " + describe(p));
  };
  auto check_len = [&](std::size_t n) {
    if (p.length && n != *p.length)
      schema_bug(path, "default has " + std::to_string(n) + " elements, declared length " +
                           std::to_string(*p.length));
  };
  switch (p.kind) {
    case Kind::Int:
      if (const auto* w = std::get_if<std::string>(&v)) {
        if (*w != p.word) schema_bug(path, "default '" + *w + "' is not " + describe(p));
      } else {
        check_num(static_cast<double>(std::get<std::int64_t>(v)), path);
      }
      break;
    case Kind::Real:
      if (const auto* w = std::get_if<std::string>(&v)) {
        if (*w != p.word) schema_bug(path, "default '" + *w + "' is not " + describe(p));
      } else {
        check_num(std::get<double>(v), path);
      }
      break;
    case Kind::RealList: {
      const auto& l = std::get<std::vector<double>>(v);
      check_len(l.size());
      for (std::size_t i = 0; i < l.size(); ++i)
        check_num(l[i], path + "[" + std::to_string(i) + "]");
      break;
    }
    case Kind::IntList: {
      const auto& l = std::get<std::vector<std::int64_t>>(v);
      check_len(l.size());
      for (std::size_t i = 0; i < l.size(); ++i)
        check_num(static_cast<double>(l[i]), path + "[" + std::to_string(i) + "]");
      break;
    }
    case Kind::StringList: check_len(std::get<std::vector<std::string>>(v).size()); break;
    case Kind::Choice: {
      const auto& s = std::get<std::string>(v);
      if (std::find(p.choices.begin(), p.choices.end(), s) == p.choices.end())
        schema_bug(path, "default '" + s + "' is not " + describe(p));
      break;
    }
    default: break;
  }
}

}  // namespace

std::string describe(const Param& p) {
  switch (p.kind) {
    case Kind::Bool: return "a boolean (true or false)";
    case Kind::Int: return numeric_phrase(p, "an integer") + (p.word.empty() ? "" : " or '" + p.word + "'");
    case Kind::Real: return numeric_phrase(p, "a number") + (p.word.empty() ? "" : " or '" + p.word + "'");
    case Kind::String: return "a string";
    case Kind::Choice: {
      std::string s = "one of ";
      for (std::size_t i = 0; i < p.choices.size(); ++i)
        s += (i ? ", '" : "'") + p.choices[i] + "'";
      return s;
    }
    case Kind::Path: return "a path to an existing file";
    case Kind::RealList: return list_phrase(p, "numbers");
    case Kind::IntList: return list_phrase(p, "integers");
    case Kind::StringList: return list_phrase(p, "strings");
  }
  return "?";
}

namespace {
struct ValueFormatter {
  std::string operator()(bool b) const { return b ? "true" : "false"; }
  std::string operator()(std::int64_t i) const { return std::to_string(i); }
  std::string operator()(double d) const { return format_number(d); }
  std::string operator()(const std::string& s) const { return quote_toml(s); }
  template <class T>
  std::string operator()(const std::vector<T>& l) const {
    std::string s = "[";
    for (std::size_t i = 0; i < l.size(); ++i) s += (i ? ", " : "") + (*this)(l[i]);
    return s + "]";
  }
};
}  // namespace

std::string format_value(const Value& v) { return std::visit(ValueFormatter{}, v); }

// ---------------------------------------------------------------------------
// ParamBuilder
// ---------------------------------------------------------------------------
ParamBuilder& ParamBuilder::min(double lo, bool open) {
  if (!is_numeric(param->kind)) schema_bug(path, "min() on a non-numeric parameter");
  param->lo = lo;
  param->lo_open = open;
  check_default(*param, path);
  return *this;
}

ParamBuilder& ParamBuilder::max(double hi, bool open) {
  if (!is_numeric(param->kind)) schema_bug(path, "max() on a non-numeric parameter");
  param->hi = hi;
  param->hi_open = open;
  check_default(*param, path);
  return *this;
}

ParamBuilder& ParamBuilder::or_word(std::string word, bool is_default) {
  if (param->kind != Kind::Real && param->kind != Kind::Int)
    schema_bug(path, "or_word() on a parameter that is not a number");
  if (word.empty()) schema_bug(path, "or_word() with an empty word");
  param->word = std::move(word);
  if (is_default) param->def = Value(param->word);
  check_default(*param, path);
  return *this;
}

ParamBuilder& ParamBuilder::length(std::size_t n) {
  if (!is_list(param->kind)) schema_bug(path, "length() on a non-list parameter");
  param->length = n;
  check_default(*param, path);
  return *this;
}

// ---------------------------------------------------------------------------
// Section
// ---------------------------------------------------------------------------
Section::Section(std::string name, std::string path, std::string doc, Presence presence,
                 bool is_array)
    : name_(std::move(name)), path_(std::move(path)), doc_(std::move(doc)),
      presence_(presence), is_array_(is_array) {}

void Section::moved(std::string old_name, std::string hint) { moved_.emplace_back(std::move(old_name), std::move(hint)); }

const std::string* Section::moved_hint(std::string_view old_name) const {
  for (const auto& [name, hint] : moved_)
    if (name == old_name) return &hint;
  return nullptr;
}

const Section::Member* Section::find(std::string_view name) const {
  for (const auto& m : members_) {
    const std::string& n = m.param ? m.param->name : m.section->name();
    if (n == name) return &m;
  }
  return nullptr;
}

void Section::check_new_name(const std::string& name) const {
  const std::string full = join_path(path_, name);
  if (name.empty()) schema_bug(path_.empty() ? "(root)" : path_, "empty key name");
  if (name.find_first_of(".[] \t\"'") != std::string::npos)
    schema_bug(full, "key names may not contain '.', '[', ']', quotes or blanks");
  if (find(name)) schema_bug(full, "declared twice");
}

ParamBuilder Section::add(Param p) {
  check_new_name(p.name);
  std::string full = join_path(path_, p.name);
  if (p.kind == Kind::Choice && p.choices.empty()) schema_bug(full, "choice with no options");
  check_default(p, full);
  params_.push_back(std::make_unique<Param>(std::move(p)));
  members_.push_back(Member{params_.back().get(), nullptr});
  return ParamBuilder{params_.back().get(), std::move(full)};
}

Section& Section::add_section(std::string name, std::string doc, Presence p, bool is_array) {
  check_new_name(name);
  std::string full = join_path(path_, name);
  sections_.push_back(
      std::make_unique<Section>(std::move(name), std::move(full), std::move(doc), p, is_array));
  members_.push_back(Member{nullptr, sections_.back().get()});
  return *sections_.back();
}

namespace {
Param make(std::string name, std::string unit, Kind kind, std::optional<Value> def,
           std::string doc) {
  Param p;
  p.name = std::move(name);
  p.unit = std::move(unit);
  p.kind = kind;
  p.def = std::move(def);
  p.doc = std::move(doc);
  return p;
}
template <class T>
std::optional<Value> opt(std::optional<T> v) {
  if (!v) return std::nullopt;
  return Value(std::move(*v));
}
}  // namespace

ParamBuilder Section::real(std::string name, std::string unit, std::optional<double> def,
                           std::string doc) {
  return add(make(std::move(name), std::move(unit), Kind::Real, opt(def), std::move(doc)));
}
ParamBuilder Section::integer(std::string name, std::string unit,
                              std::optional<std::int64_t> def, std::string doc) {
  return add(make(std::move(name), std::move(unit), Kind::Int, opt(def), std::move(doc)));
}
ParamBuilder Section::boolean(std::string name, bool def, std::string doc) {
  return add(make(std::move(name), "", Kind::Bool, Value(def), std::move(doc)));
}
ParamBuilder Section::string(std::string name, std::optional<std::string> def,
                             std::string doc) {
  return add(make(std::move(name), "", Kind::String, opt(std::move(def)), std::move(doc)));
}
ParamBuilder Section::choice(std::string name, std::vector<std::string> choices,
                             std::optional<std::string> def, std::string doc) {
  Param p = make(std::move(name), "", Kind::Choice, opt(std::move(def)), std::move(doc));
  p.choices = std::move(choices);
  return add(std::move(p));
}
ParamBuilder Section::path(std::string name, std::optional<std::string> def, std::string doc) {
  return add(make(std::move(name), "", Kind::Path, opt(std::move(def)), std::move(doc)));
}
ParamBuilder Section::reals(std::string name, std::string unit,
                            std::optional<std::vector<double>> def, std::string doc) {
  return add(
      make(std::move(name), std::move(unit), Kind::RealList, opt(std::move(def)), std::move(doc)));
}
ParamBuilder Section::integers(std::string name, std::string unit,
                               std::optional<std::vector<std::int64_t>> def, std::string doc) {
  return add(
      make(std::move(name), std::move(unit), Kind::IntList, opt(std::move(def)), std::move(doc)));
}
ParamBuilder Section::strings(std::string name, std::optional<std::vector<std::string>> def,
                              std::string doc) {
  return add(make(std::move(name), "", Kind::StringList, opt(std::move(def)), std::move(doc)));
}
Section& Section::section(std::string name, std::string doc, Presence p) {
  return add_section(std::move(name), std::move(doc), p, false);
}
Section& Section::array(std::string name, std::string doc, Presence p) {
  return add_section(std::move(name), std::move(doc), p, true);
}

// ---------------------------------------------------------------------------
// Schema
// ---------------------------------------------------------------------------
Schema::Schema() : root_(std::make_unique<Section>("", "", "", Presence::Required, false)) {}
Schema::Schema(Schema&&) noexcept = default;
Schema& Schema::operator=(Schema&&) noexcept = default;
Schema::~Schema() = default;

Section& Schema::root() { return *root_; }
const Section& Schema::root() const { return *root_; }

void Schema::check(std::function<void(const Scene&, CheckContext&)> fn) {
  checks_.push_back(std::move(fn));
}

namespace {

std::string header_of(const Section& s) {
  if (s.path().empty()) return "(top level)";
  return s.is_array() ? "[[" + s.path() + "]]" : "[" + s.path() + "]";
}

std::string presence_of(const Section& s) {
  if (s.path().empty()) return "";
  if (s.is_array())
    return s.presence() == Presence::Required ? "array of tables, at least one required"
                                              : "array of tables, optional";
  if (s.presence() == Presence::Defaults) return "optional section: absent = every key at its default";
  return s.presence() == Presence::Required ? "required section"
                                            : "optional section: absent = off";
}

// Depth-first over sections in declaration order, parameters before sub-sections.
template <class F>
void walk(const Section& s, F&& f) {
  f(s);
  for (const auto& m : s.members())
    if (m.section) walk(*m.section, f);
}

std::string md_escape(std::string s) {
  std::string out;
  for (char c : s) {
    if (c == '|') out += '\\';
    out += c;
  }
  return out;
}

}  // namespace

std::string Schema::help_text() const {
  std::ostringstream os;
  os << "Scene file reference (TOML). Columns: key, type, unit, default, allowed range, "
        "meaning.\n";
  walk(*root_, [&](const Section& s) {
    std::vector<const Param*> ps;
    for (const auto& m : s.members())
      if (m.param) ps.push_back(m.param);
    if (ps.empty() && s.path().empty()) return;
    os << "\n" << header_of(s);
    std::string pres = presence_of(s);
    if (!pres.empty()) os << "  (" << pres << ")";
    if (!s.doc().empty()) os << "  " << s.doc();
    os << "\n";
    // Column widths per section so each key is one aligned, grep-able line.
    std::size_t w[5] = {0, 0, 0, 0, 0};
    for (const Param* p : ps) {
      w[0] = std::max(w[0], p->name.size());
      w[1] = std::max(w[1], type_name(*p).size());
      w[2] = std::max(w[2], unitless(p->unit) ? std::size_t{1} : p->unit.size() + 2);
      w[3] = std::max(w[3], default_text(*p).size());
      w[4] = std::max(w[4], range_text(*p).size());
    }
    auto pad = [](const std::string& t, std::size_t n) {
      return t + std::string(n > t.size() ? n - t.size() : 0, ' ');
    };
    for (const Param* p : ps) {
      std::string unit = unitless(p->unit) ? "-" : "[" + p->unit + "]";
      os << "  " << pad(p->name, w[0]) << "  " << pad(type_name(*p), w[1]) << "  "
         << pad(unit, w[2]) << "  " << pad(default_text(*p), w[3]) << "  "
         << pad(range_text(*p), w[4]) << "  " << p->doc << "\n";
    }
  });
  return os.str();
}

std::string Schema::markdown() const {
  std::ostringstream os;
  walk(*root_, [&](const Section& s) {
    std::vector<const Param*> ps;
    for (const auto& m : s.members())
      if (m.param) ps.push_back(m.param);
    if (ps.empty() && s.path().empty()) return;
    os << "### `" << header_of(s) << "`\n\n";
    std::string pres = presence_of(s);
    if (!s.doc().empty()) os << md_escape(s.doc()) << " ";
    if (!pres.empty()) os << "*(" << pres << ")*";
    if (!s.doc().empty() || !pres.empty()) os << "\n\n";
    if (ps.empty()) return;
    os << "| Key | Type | Unit | Default | Range | Description |\n"
       << "| --- | --- | --- | --- | --- | --- |\n";
    for (const Param* p : ps) {
      std::string range = range_text(*p);
      std::string def = "required";
      if (p->def) {  // built piecewise: GCC 12 warns falsely (-Wrestrict) on "`" + string
        def = "`";
        def += md_escape(default_text(*p));
        def += '`';
      }
      os << "| `" << p->name << "` | " << type_name(*p) << " | "
         << (unitless(p->unit) ? "-" : md_escape(p->unit)) << " | "
         << def << " | "
         << (range.empty() ? "-" : md_escape(range)) << " | " << md_escape(p->doc) << " |\n";
    }
    os << "\n";
  });
  return os.str();
}

}  // namespace demfdm::config
