// Walks a parameter table (demfdm/param_table.hpp: a describe() beside the engine's struct) for
// the tests of "every parameter declared once": every key, set in a scene to another admissible
// value, lands in its own field and in no other; and for every bounded key the scene (schema)
// and the engine's validate() refuse the same out-of-range value under the same key. The walks
// take the table itself, so a key added to a table is covered without a new test line.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <initializer_list>
#include <stdexcept>
#include <string>
#include <vector>

#include "common/config/config.hpp"
#include "demfdm/param_table.hpp"

namespace table_walk {

using demfdm::ParamOption;
using demfdm::ParamRange;

inline std::string exact(double v) {
  if (std::isnan(v)) return "nan";
  char b[40];
  std::snprintf(b, sizeof b, "%.17g", v);
  return b;
}

// Every bound field's value, in table order (as text, so that NaN equals NaN).
struct Collect {
  std::vector<std::string> v;
  void real(const char*, const char*, double& f, const ParamRange&, const char*) { v.push_back(exact(f)); }
  void real_or_word(const char*, const char*, double& f, const ParamRange&, const char*, double, const char*) {
    v.push_back(exact(f));
  }
  void flag(const char*, bool& f, const char*) { v.push_back(f ? "true" : "false"); }
  template <class I>
  void integer(const char*, const char*, I& f, std::int64_t, std::int64_t, const char*) {
    v.push_back(std::to_string(f));
  }
  template <class E>
  void choice(const char*, E& f, std::initializer_list<ParamOption<E>>, const char*) {
    v.push_back(std::to_string(static_cast<int>(f)));
  }
};
template <class P>
std::vector<std::string> fields(P p) {
  Collect c;
  describe(c, p);
  return c.v;
}

// Number of keys of a table.
struct Count {
  int n = 0;
  void real(const char*, const char*, double&, const ParamRange&, const char*) { ++n; }
  void real_or_word(const char*, const char*, double&, const ParamRange&, const char*, double, const char*) { ++n; }
  void flag(const char*, bool&, const char*) { ++n; }
  template <class I>
  void integer(const char*, const char*, I&, std::int64_t, std::int64_t, const char*) { ++n; }
  template <class E>
  void choice(const char*, E&, std::initializer_list<ParamOption<E>>, const char*) { ++n; }
};

// Changes the key with index `target` (in table order) to another admissible value and writes
// the key and its TOML value text.
struct Mutate {
  int target = 0, at = 0;
  std::string key = {}, text = {};
  bool hit() { return at++ == target; }
  static double other(double f, const ParamRange& r) {
    const double lo = r.has_lo() ? r.lo : 0.0;
    for (double n : {f == 0 ? 0.25 : 0.75 * f, 1.25 * f, 0.5 * (f + lo), r.has_hi() ? 0.5 * (lo + r.hi) : lo + 1.0})
      if (r.contains(n) && n != f) return n;
    ADD_FAILURE() << "no other admissible value than " << f;
    return f;
  }
  void real(const char* k, const char*, double& f, const ParamRange& r, const char*) {
    if (!hit()) return;
    f = other(f, r);
    key = k;
    text = exact(f);
  }
  void real_or_word(const char* k, const char*, double& f, const ParamRange& r, const char* word, double wv,
                    const char*) {
    if (!hit()) return;
    key = k;
    if (f == wv || (std::isnan(f) && std::isnan(wv))) {  // the word is the default: a number
      f = other(f, r);
      text = exact(f);
    } else {  // a number is the default: the word
      f = wv;
      text = std::string("\"") + word + "\"";
    }
  }
  void flag(const char* k, bool& f, const char*) {
    if (!hit()) return;
    f = !f;
    key = k;
    text = f ? "true" : "false";
  }
  template <class I>
  void integer(const char* k, const char*, I& f, std::int64_t lo, std::int64_t hi, const char*) {
    if (!hit()) return;
    const auto x = static_cast<std::int64_t>(f);
    f = static_cast<I>(x < hi ? x + 1 : lo);
    key = k;
    text = std::to_string(f);
  }
  template <class E>
  void choice(const char* k, E& f, std::initializer_list<ParamOption<E>> options, const char*) {
    if (!hit()) return;
    for (const auto& o : options)
      if (o.value != f) {
        f = o.value;
        key = k;
        text = std::string("\"") + o.name + "\"";
        return;
      }
  }
};

// The bounded keys of a table and the values just outside (refused) and on a closed lower bound
// (admitted). Integers: one below the lowest and one above the highest.
struct Probe {
  std::string key;
  double value;
  bool ok;
};
struct Probes {
  std::vector<Probe> probes;
  void real(const char* k, const char*, double&, const ParamRange& r, const char*) {
    if (r.has_lo()) probes.push_back({k, r.lo_open ? r.lo : r.lo - 1.0, false});
    if (r.has_hi()) probes.push_back({k, r.hi_open ? r.hi : r.hi + 1.0, false});
    if (r.has_lo() && !r.lo_open) probes.push_back({k, r.lo, true});
  }
  void real_or_word(const char* k, const char* u, double& f, const ParamRange& r, const char*, double, const char* d) {
    real(k, u, f, r, d);
  }
  void flag(const char*, bool&, const char*) {}
  template <class I>
  void integer(const char* k, const char*, I&, std::int64_t lo, std::int64_t hi, const char*) {
    probes.push_back({k, static_cast<double>(lo) - 1.0, false});
    probes.push_back({k, static_cast<double>(hi) + 1.0, false});
    probes.push_back({k, static_cast<double>(lo), true});
  }
  template <class E>
  void choice(const char*, E&, std::initializer_list<ParamOption<E>>, const char*) {}
};

// Sets the key `key` of a table to a value.
struct Assign {
  std::string key;
  double value;
  void real(const char* k, const char*, double& f, const ParamRange&, const char*) {
    if (key == k) f = value;
  }
  void real_or_word(const char* k, const char*, double& f, const ParamRange&, const char*, double, const char*) {
    if (key == k) f = value;
  }
  void flag(const char*, bool&, const char*) {}
  template <class I>
  void integer(const char* k, const char*, I& f, std::int64_t, std::int64_t, const char*) {
    if (key == k) f = static_cast<I>(static_cast<std::int64_t>(value));
  }
  template <class E>
  void choice(const char*, E&, std::initializer_list<ParamOption<E>>, const char*) {}
};

// The read: each key of the table of `defaults`, set (through set(key, value text), which builds
// a scene) to another value, reads (read(scene)) into its own field only; the table's absent keys
// read as `defaults`. Returns the number of keys walked.
template <class P>
int every_key_reads_into_its_own_field(const P& defaults,
                                       const std::function<demfdm::config::Scene(const std::string&, const std::string&)>& set,
                                       const std::function<P(const demfdm::config::Scene&)>& read) {
  EXPECT_EQ(fields(read(set("", ""))), fields(defaults)) << "the defaults";
  Count c;
  P d = defaults;
  describe(c, d);
  for (int i = 0; i < c.n; ++i) {
    P expected = defaults;
    Mutate m{i};
    describe(m, expected);
    SCOPED_TRACE(m.key + " = " + m.text);
    EXPECT_EQ(fields(read(set(m.key, m.text))), fields(expected));
  }
  return c.n;
}

// The range: a value just outside a declared bound is refused by the scene (its message names
// scene_name(key)) and by validate() (its message names 'engine_name(key)'); a closed lower
// bound passes both. Returns the number of probes.
template <class P>
int schema_and_engine_refuse_the_same_values(
    const P& defaults, const std::function<demfdm::config::Scene(const std::string&, const std::string&)>& set,
    const std::function<void(const P&)>& validate, const std::function<std::string(const std::string&)>& scene_name,
    const std::function<std::string(const std::string&)>& engine_name) {
  Probes b;
  P d = defaults;
  describe(b, d);
  for (const auto& [key, value, ok] : b.probes) {
    SCOPED_TRACE(key + " = " + exact(value));
    P f = defaults;
    Assign a{key, value};
    describe(a, f);
    std::string engine, scene;
    try {
      validate(f);
    } catch (const std::invalid_argument& e) {
      engine = e.what();
    }
    try {
      (void)set(key, exact(value));
    } catch (const demfdm::config::Error& e) {
      scene = e.what();
    }
    if (ok) {
      EXPECT_EQ(engine, "");
      EXPECT_EQ(scene, "");
    } else {
      EXPECT_NE(engine.find("'" + engine_name(key) + "'"), std::string::npos) << engine;
      EXPECT_NE(scene.find(scene_name(key)), std::string::npos) << scene;
    }
  }
  return static_cast<int>(b.probes.size());
}

}  // namespace table_walk
