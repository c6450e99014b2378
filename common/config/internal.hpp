// Private to demfdm_config: the resolved-scene tree and small text helpers shared by
// schema.cpp and scene.cpp. Not installed, not included by users.
#pragma once

#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "config.hpp"

namespace demfdm::config::detail {

struct Pos {
  int line = 0, col = 0;  // 1-based; 0 = unknown
  int set = 0;            // 1-based index of the override (--set) the value came from; 0: the file
};

// One override "table.key=value" (Scene::parse overrides): the text as given and the key path it
// resolved to ("stage.penetrate.steps=9" -> "stage[5].steps").
struct SetInfo {
  std::string text, path;
};

// One parameter after validation. Holds no pointer into the Schema, so a Scene
// outlives the Schema it was validated against.
struct Entry {
  Kind kind = Kind::Real;
  std::optional<Value> value;  // empty only for a required key of an absent section
  Pos pos;                     // of the value if explicit, else of the enclosing table
  std::vector<Pos> elem_pos;   // of each element of an explicit list (for "key[i]" paths)
  bool explicit_set = false;
};

struct Node;
struct Array {
  Pos pos;  // first element (or enclosing table if empty)
  std::vector<std::unique_ptr<Node>> elems;
};

// One table instance (a section, or one element of an array of tables).
struct Node {
  std::string path;  // full path: "", "dem.contact", "stage[1]", "stage[1].load"
  std::string section_path;  // declared section path ("stage" for "stage[1]")
  Pos pos;           // of the table if present, else inherited from the parent
  bool present = false;
  std::map<std::string, Entry, std::less<>> params;
  std::map<std::string, std::unique_ptr<Node>, std::less<>> sections;
  std::map<std::string, Array, std::less<>> arrays;
};

struct Data {
  std::string text, origin;
  std::uint64_t hash = 0;         // of text
  std::uint64_t source_hash = 0;  // of the file's text (== hash without overrides)
  std::vector<SetInfo> sets;      // overrides, in the order given
  Node root;
};

// Shortest decimal that round-trips the double, with a compact exponent
// ("1e9", "2.5e-5", "0.3", "inf").
std::string format_number(double v);
// "a.b" + "c" -> "a.b.c"; "" + "c" -> "c".
std::string join_path(std::string_view parent, std::string_view name);
// Levenshtein edit distance (insert, delete, substitute; each cost 1).
std::size_t edit_distance(std::string_view a, std::string_view b);
// Closest sibling name for an unknown key among those with edit distance <= 3 or a
// prefix match (either way round): prefix matches first, then smallest distance, ties
// in declaration order. Empty when nothing is close.
std::string suggest(std::string_view unknown, const std::vector<std::string>& names);
// Interval notation for tables: "[0, 1)", "(0, inf)"; "" when unbounded.
std::string range_interval(const Param& p);
// Inequality/interval phrase for messages: "in [0, 1)", "> 0", "<= 5"; "" when unbounded.
std::string range_phrase(const Param& p);
// Does x satisfy the declared range?
bool in_range(const Param& p, double x);

}  // namespace demfdm::config::detail
