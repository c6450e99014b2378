// Reads the keys of a parameter table (demfdm/param_table.hpp: a describe() beside the engine's
// struct) from a scene into the bound fields. The schema declared the same table (unit, range,
// default), so every key read here exists and is in range.
#pragma once

#include <cstdint>
#include <initializer_list>
#include <string>
#include <utility>

#include "common/config/config.hpp"
#include "demfdm/param_table.hpp"

namespace demfdm::schema {

struct SceneRead {
  const config::Scene& s;
  std::string prefix;  // "dem.ball_ball.", "continuum.mesh.", "" for a stage or an array element
  void real(const char* key, const char*, double& field, const ParamRange&, const char*) {
    field = s.real(prefix + key);
  }
  void real_or_word(const char* key, const char*, double& field, const ParamRange&, const char*, double word_value,
                    const char*) {
    field = s.real_or_word(prefix + key).value_or(word_value);
  }
  void flag(const char* key, bool& field, const char*) { field = s.boolean(prefix + key); }
  template <class I>
  void integer(const char* key, const char*, I& field, std::int64_t, std::int64_t, const char*) {
    field = static_cast<I>(s.integer(prefix + key));  // the schema's range fits I
  }
  template <class E>
  void choice(const char* key, E& field, std::initializer_list<ParamOption<E>> options, const char*) {
    const std::string name = s.string(prefix + key);  // the schema admits only the options' names
    for (const auto& o : options)
      if (name == o.name) field = o.value;
  }
};

/// Reads the table of `p` (its describe(), found by argument-dependent lookup) under `prefix`.
template <class P>
void read_table(const config::Scene& s, std::string prefix, P& p) {
  SceneRead r{s, std::move(prefix)};
  describe(r, p);
}

}  // namespace demfdm::schema
