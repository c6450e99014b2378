// demfdm::config: one TOML scene file drives a whole run.
//
// Every parameter is declared once in code (Schema -> Section -> Param) with its
// type, unit, default, range and doc string. That single declaration drives parsing,
// validation, default filling, `--help` text and the Markdown reference table
// (as preCICE documents each attribute where it is declared, makeXMLAttribute().setDocumentation(), and YADE
// YADE_CLASS_BASE_DOC_ATTRS). Bad input gives one error line in the form
//
//   file:line:col: key.path: expected <what>, found <what>
//
// (the style of Drake's YamlReadArchive::ReportError and preCICE's "Did you mean").
// Unknown keys are errors, never warnings (Kratos ValidateAndAssignDefaults).
//
// Usage:
//   1. Build a Schema: `auto& dem = schema.root().section("dem", "DEM node");
//      dem.real("dt", "s", 1e-6, "time step").min(0, true);`
//   2. Optionally add cross-field checks with Schema::check().
//   3. `Scene s = Scene::load("scene.toml", schema);` throws config::Error with the
//      one-line message; afterwards every declared key can be read
//      (`s.real("dem.dt")`), defaults filled.
//   4. Send `s.text()` over the bus; the receiver calls Scene::parse() with the
//      same schema and checks `hash()`.
//
// No global state: a Schema is a plain value built by the caller; a Scene is an
// immutable, cheaply copyable view (shared data) that does not refer to the Schema.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace demfdm::config {

enum class Kind { Bool, Int, Real, String, Choice, Path, RealList, IntList, StringList };

// Optional section absent => the effect it configures is off (Scene::has() is false);
// present => its params get their defaults. Required section absent => error.
// Defaults: a table of settings whose absence means every key at its default (a contact
// family, a law's table); it loads as Optional, only the documentation differs.
// For an array of tables ([[name]]) Required means "at least one element".
enum class Presence { Required, Optional, Defaults };

// Value of one parameter. Alternatives by Kind: Bool->bool, Int->int64_t,
// Real->double, String/Choice/Path->string, RealList->vector<double>,
// IntList->vector<int64_t>, StringList->vector<string>.
using Value = std::variant<bool, std::int64_t, double, std::string, std::vector<double>,
                           std::vector<std::int64_t>, std::vector<std::string>>;

// One declared parameter.
struct Param {
  std::string name, unit, doc;
  Kind kind = Kind::Real;
  std::optional<Value> def;  // absent => required
  std::optional<double> lo, hi;  // numeric range (also applied to each list element)
  bool lo_open = false, hi_open = false;
  std::vector<std::string> choices;  // Kind::Choice
  std::string word;  // Kind::Real: a word the key may hold instead of a number ("auto", "none")
  std::optional<std::size_t> length;  // fixed list length, e.g. 3 for a vector
};

// "a number in [0, 1) Pa", "one of 'a', 'b'", "a list of 3 numbers in m", ... The
// text used after "expected" in messages and in help_text()/markdown().
std::string describe(const Param& p);
// Human-readable rendering of a value ("1e+09", "'hertz'", "[0, 0, -9.81]").
std::string format_value(const Value& v);

// Handle to a Param inside its Section, used to chain range/length declarations:
//   sec.real("damping", "", 0.0, "local damping").min(0).max(1, /*open=*/true);
// Each call re-validates the declared default against the new constraint and throws
// std::logic_error (a schema bug, not an input error) if the default violates it.
struct ParamBuilder {
  Param* param = nullptr;
  std::string path;  // dotted path, for schema-bug messages
  ParamBuilder& min(double lo, bool open = false);
  ParamBuilder& max(double hi, bool open = false);
  ParamBuilder& length(std::size_t n);
  // A number key (real or integer) that may instead hold `word` (e.g. "auto": a value derived
  // from others, or "none"), never a negative sentinel; `is_default`: the word is the default.
  // Read it with Scene::real_or_word() / integer_or_word(); real() / integer() on the word is a
  // programming error.
  ParamBuilder& or_word(std::string word, bool is_default);
};

class Scene;

// A TOML table in the schema (or the element schema of an array of tables).
// Parameters, sub-sections and arrays share one name space per section and keep
// their declaration order (used by help_text() and markdown()).
// Declaring a name twice, or a name containing '.', '[' or ']', throws std::logic_error.
class Section {
 public:
  Section(std::string name, std::string path, std::string doc, Presence presence,
          bool is_array);
  Section(const Section&) = delete;
  Section& operator=(const Section&) = delete;

  ParamBuilder real(std::string name, std::string unit, std::optional<double> def,
                    std::string doc);
  ParamBuilder integer(std::string name, std::string unit, std::optional<std::int64_t> def,
                       std::string doc);
  ParamBuilder boolean(std::string name, bool def, std::string doc);
  ParamBuilder string(std::string name, std::optional<std::string> def, std::string doc);
  ParamBuilder choice(std::string name, std::vector<std::string> choices,
                      std::optional<std::string> def, std::string doc);
  // Must name an existing regular file; relative paths are resolved against the
  // scene file's folder and returned absolute by Scene::string(). If the default is
  // the empty string, "" (defaulted or written) means "no file" and is not checked.
  ParamBuilder path(std::string name, std::optional<std::string> def, std::string doc);
  ParamBuilder reals(std::string name, std::string unit,
                     std::optional<std::vector<double>> def, std::string doc);
  ParamBuilder integers(std::string name, std::string unit,
                        std::optional<std::vector<std::int64_t>> def, std::string doc);
  ParamBuilder strings(std::string name, std::optional<std::vector<std::string>> def,
                       std::string doc);
  Section& section(std::string name, std::string doc, Presence p = Presence::Optional);
  // [[name]] array of tables; the returned Section is the element schema.
  Section& array(std::string name, std::string doc, Presence p = Presence::Optional);

  // A key that no longer exists under this name: a scene that writes it is refused with
  // "unknown key; it moved: <hint>" (for example "write [dem.ball_ball.softbond] ten").
  void moved(std::string old_name, std::string hint);
  const std::string* moved_hint(std::string_view old_name) const;

  // Introspection (used by the loader, help_text() and markdown()).
  struct Member {  // exactly one of param / section is set
    Param* param = nullptr;
    Section* section = nullptr;
  };
  const std::string& name() const { return name_; }
  const std::string& path() const { return path_; }  // "" for root, "dem.contact", "stage"
  const std::string& doc() const { return doc_; }
  Presence presence() const { return presence_; }
  bool is_array() const { return is_array_; }
  const std::vector<Member>& members() const { return members_; }
  const Member* find(std::string_view name) const;

 private:
  ParamBuilder add(Param p);
  Section& add_section(std::string name, std::string doc, Presence p, bool is_array);
  void check_new_name(const std::string& name) const;

  std::string name_, path_, doc_;
  Presence presence_;
  bool is_array_;
  std::vector<Member> members_;
  std::vector<std::unique_ptr<Param>> params_;      // stable addresses for ParamBuilder
  std::vector<std::unique_ptr<Section>> sections_;  // stable addresses for Section&
  std::vector<std::pair<std::string, std::string>> moved_;  // old name, hint
};

// Passed to cross-field checks; fail() throws config::Error at the key's position.
class CheckContext {
 public:
  explicit CheckContext(const Scene& scene) : scene_(scene) {}
  // key_path is relative to the scene root and may index arrays: "stage[1].t_end".
  [[noreturn]] void fail(std::string_view key_path, std::string_view expected,
                         std::string_view found) const;
  const Scene& scene() const { return scene_; }

 private:
  const Scene& scene_;
};

class Schema {
 public:
  Schema();
  Schema(Schema&&) noexcept;
  Schema& operator=(Schema&&) noexcept;
  ~Schema();

  Section& root();
  const Section& root() const;
  // Cross-field checks run, in registration order, after the per-key checks;
  // call ctx.fail(key_path, expected, found) to reject the scene.
  void check(std::function<void(const Scene&, CheckContext&)> fn);
  const std::vector<std::function<void(const Scene&, CheckContext&)>>& checks() const {
    return checks_;
  }
  // Plain-text reference: every key with type, unit, default, range, doc.
  std::string help_text() const;
  // The same, as one Markdown table per section.
  std::string markdown() const;

 private:
  std::unique_ptr<Section> root_;
  std::vector<std::function<void(const Scene&, CheckContext&)>> checks_;
};

// Input error. what() is the one-line message "file:line:col: key: ...".
// line/col are 1-based, 0 when there is no position (unreadable file).
struct Error : std::runtime_error {
  Error(const std::string& message, std::string file_, int line_, int col_, std::string key_)
      : std::runtime_error(message), file(std::move(file_)), line(line_), col(col_),
        key(std::move(key_)) {}
  std::string file;
  int line = 0, col = 0;
  std::string key;
};

namespace detail {
struct Node;
struct Data;
}  // namespace detail

// A validated scene: every declared key present (defaults filled), unknown keys
// rejected. Paths are dotted ("dem.contact.emod") and may index arrays of tables
// ("stage[1].t_end"). where(), fail() and has() also take one element of a list
// parameter ("dem.gravity[2]"), so cross-field checks can point at that element. Reading an undeclared path, or a key with the wrong accessor
// (real() on an Int), is a programming error: std::logic_error. Reading a required
// key of an absent optional section also throws std::logic_error (check has() first).
class Scene {
 public:
  Scene();  // empty scene (no keys); useful as a placeholder member
  // Throws Error (also: file missing/unreadable, TOML syntax error with its position).
  // overrides: "table.key=value" texts (launch/run --set), see parse().
  static Scene load(const std::string& path, const Schema&,
                    const std::vector<std::string>& overrides = {});
  // origin is used as the file name in messages; base_dir resolves relative Paths.
  // overrides: each "path=value" sets one declared key after the text is read and before it is
  // validated, so it passes exactly the checks a key in the file passes; a later one wins. The
  // path is dotted ("dem.damping", "dem.specimen.replicate"); an element of an array of tables
  // is named by its `name` key ("stage.penetrate.inertial_number") or indexed ("stage[4].steps");
  // a missing optional section is created. The value is TOML ("0.1", "[2, 2, 4]", ""x""); a
  // value that is not TOML and does not start with [ { " ' is taken as a string ("x").
  // Errors name the override: "--set dem.damping=abc: expected a number in [0, 1), found
  // string 'abc'" (a problem of an override is reported before those of the file).
  static Scene parse(std::string_view text, std::string origin, const Schema&,
                     std::string base_dir = ".", const std::vector<std::string>& overrides = {});

  // The exact source text, or with overrides effective_toml() (the values in effect, which a
  // node that gets the text over the bus parses to the same scene).
  const std::string& text() const;
  std::uint64_t hash() const;       // FNV-1a 64 of text()
  const std::string& origin() const;
  std::vector<std::string> overrides() const;  // as given to parse()
  // Section present in the file? Array non-empty? Key given in the file (not defaulted)?
  bool has(std::string_view path) const;
  bool explicitly_set(std::string_view path) const;  // key (or section) given in the file
  double real(std::string_view path) const;
  // A Real key declared with or_word(): the number, or nothing when it holds its word.
  std::optional<double> real_or_word(std::string_view path) const;
  std::int64_t integer(std::string_view path) const;
  // An Int key declared with or_word(): the number, or nothing when it holds its word.
  std::optional<std::int64_t> integer_or_word(std::string_view path) const;
  bool boolean(std::string_view path) const;
  // Also Choice and Path (Path returned resolved to an absolute path).
  const std::string& string(std::string_view path) const;
  std::vector<double> reals(std::string_view path) const;
  std::vector<std::int64_t> integers(std::string_view path) const;
  std::vector<std::string> strings(std::string_view path) const;
  std::size_t count(std::string_view array_path) const;  // number of [[stage]] elements
  Scene at(std::string_view array_path, std::size_t i) const;  // one element (paths relative)
  // "file:line:col" of a key (or of its section if defaulted); "--set path=value" for a key
  // an override set.
  std::string where(std::string_view path) const;
  // Throws Error "file:line:col: full.key.path: expected <expected>, found <found>".
  [[noreturn]] void fail(std::string_view path, std::string_view expected,
                         std::string_view found) const;
  // The whole scene (not just this view) as TOML with every value in effect: defaults
  // filled, paths absolute, absent optional sections omitted, overrides applied (the comment
  // header names the source file, the FNV-1a 64 of its text and each override). Written to
  // the run folder so a run records exactly what it used; parsing it again gives the same
  // values.
  std::string effective_toml() const;
  // Full dotted path of this view's table ("" for the root, "stage[1]" for an element).
  const std::string& prefix() const { return prefix_; }

 private:
  struct Target;
  Target resolve(std::string_view path) const;
  const Value& value_of(std::string_view path, Kind kind, const char* accessor) const;

  std::shared_ptr<const detail::Data> data_;
  const detail::Node* node_ = nullptr;
  std::string prefix_;
};

}  // namespace demfdm::config
