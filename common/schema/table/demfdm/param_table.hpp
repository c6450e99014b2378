// Parameter tables (issue 15: every parameter declared once, next to the code that uses it).
// Header-only and free of the scene library (common/config): the engines' cores (dem_core,
// fdm_mesh, fdm_core) include it to declare their keys; the scene schema (common/schema), the
// scene readers and the cores' validate() walk the same declarations with their own visitors.
//
// A table is a template function describe(V& v, Params& p) beside the struct it binds. It names
// each scene key, its unit, its range and its doc, and binds the field. A visitor V supplies:
//   v.real(key, unit, double& field, ParamRange, doc)
//   v.real_or_word(key, unit, double& field, ParamRange, word, double word_value, doc)
//       (the key may hold `word` instead of a number; the field then holds word_value; a field
//       whose initial value is word_value makes the word the key's default)
//   v.flag(key, bool& field, doc)
//   v.integer(key, unit, I& field, lo, hi, doc)          (any integer type I; closed [lo, hi])
//   v.choice(key, E& field, {{"name", E::kValue}, ...}, doc)
// The default of a key is the field's initial value in the object the schema walks.
#pragma once

#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <sstream>
#include <stdexcept>
#include <string>

namespace demfdm {

/// Range of a declared real: lower and upper bounds, each closed or open; none = unbounded.
/// Every value must also be finite: a key that accepts infinity says so with a word
/// (real_or_word, e.g. "unbreakable").
struct ParamRange {
  double lo = -INFINITY, hi = INFINITY;
  bool lo_open = true, hi_open = true;
  static constexpr ParamRange ge(double a) { return {a, INFINITY, false, true}; }
  static constexpr ParamRange gt(double a) { return {a, INFINITY, true, true}; }
  constexpr ParamRange le(double b) const { return {lo, b, lo_open, false}; }
  constexpr ParamRange lt(double b) const { return {lo, b, lo_open, true}; }
  bool has_lo() const { return std::isfinite(lo); }
  bool has_hi() const { return std::isfinite(hi); }
  bool contains(double v) const {
    return (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi) && std::isfinite(v);
  }
};

/// One named value of an enum key.
template <class E>
struct ParamOption {
  const char* name;
  E value;
};

/// The range checks of a table, for the engines' validate(): each key against its declared
/// range, named as the scene names it (prefix + key). Throws std::invalid_argument
/// "<engine> parameter '<prefix><key>' must be <range>, found <value>.".
struct RangeCheck {
  std::string engine;  // "DEM", "FDM"
  std::string prefix;  // "dem.ball_ball.", "continuum.mesh.", ...
  static std::string text(const ParamRange& r) {
    std::ostringstream s;
    if (r.has_lo() && r.has_hi())
      s << "in " << (r.lo_open ? "(" : "[") << r.lo << ", " << r.hi << (r.hi_open ? ")" : "]");
    else if (r.has_lo())
      s << (r.lo_open ? "> " : ">= ") << r.lo << " and finite";
    else if (r.has_hi())
      s << (r.hi_open ? "< " : "<= ") << r.hi;
    else
      s << "finite";
    return s.str();
  }
  template <class T>
  void fail(const char* key, const std::string& range, T value) const {
    std::ostringstream s;
    s << engine << " parameter '" << prefix << key << "' must be " << range << ", found " << value << ".";
    throw std::invalid_argument(s.str());
  }
  void real(const char* key, const char* unit, const double& v, const ParamRange& r, const char*) const {
    if (r.contains(v)) return;
    fail(key, text(r) + (std::string(unit) == "-" ? "" : std::string(" ") + unit), v);
  }
  void real_or_word(const char* key, const char* unit, const double& v, const ParamRange& r, const char*,
                    double word_value, const char* doc) const {
    if (v == word_value || (std::isnan(v) && std::isnan(word_value))) return;
    real(key, unit, v, r, doc);
  }
  void flag(const char*, const bool&, const char*) const {}
  template <class I>
  void integer(const char* key, const char*, const I& v, std::int64_t lo, std::int64_t hi, const char*) const {
    const auto x = static_cast<std::int64_t>(v);
    if (x >= lo && x <= hi && static_cast<I>(x) == v) return;
    fail(key, "in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]", v);
  }
  template <class E>
  void choice(const char*, const E&, std::initializer_list<ParamOption<E>>, const char*) const {}
};

}  // namespace demfdm
