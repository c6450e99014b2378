// Tests of demfdm::config: every kind of bad scene gives one exact message with
// file:line:col, good scenes read back declared defaults and explicit values.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include "config/config.hpp"
#include "common/schema/scene_schema.hpp"

#include <sched.h>

namespace cfg = demfdm::config;
namespace fs = std::filesystem;
using cfg::Presence;

namespace {

// A schema shaped like the real one (docs/theory.md §1.3 damping, §2 contact keys).
cfg::Schema make_schema() {
  cfg::Schema s;
  auto& r = s.root();
  r.string("title", "untitled", "Run title, copied into output metadata");

  auto& dem = r.section("dem", "DEM node", Presence::Required);
  dem.real("dt", "s", std::nullopt, "Time step").min(0, true);
  dem.real("damping", "", 0.7, "Local damping coefficient alpha (docs/theory.md 1.3)")
      .min(0)
      .max(1, true);
  dem.reals("gravity", "m/s^2", std::vector<double>{0, 0, -9.81}, "Gravity vector").length(3);
  dem.integer("seed", "", 42, "Random seed for packing").min(0);
  dem.path("particles", "", "Particle file (empty: generate)");

  auto& contact = dem.section("contact", "Contact law", Presence::Required);
  contact.real("emod", "Pa", 1e9, "Effective modulus E*").min(0, true);
  contact.real("kratio", "", 2.0, "Stiffness ratio kn/ks").min(0, true);
  contact.real("fric", "", 0.0, "Friction coefficient mu").min(0);
  contact.choice("model", {"linear", "softbond", "pbond"}, "softbond", "Contact model");

  auto& bonds = dem.section("bonds", "Bonds between particles", Presence::Optional);
  bonds.real("sb_ten", "Pa", std::nullopt, "Tensile strength").min(0, true);
  bonds.real("sb_coh", "Pa", 0.0, "Cohesion").min(0);

  auto& fdm = r.section("fdm", "FDM node", Presence::Required);
  fdm.real("damping", "", 0.8, "Local damping (FLAC3D default)").min(0).max(1, true);
  fdm.integers("cells", "", std::vector<std::int64_t>{10, 10, 10}, "Zones per axis")
      .length(3)
      .min(1);
  fdm.reals("origin", "m", std::vector<double>{0, 0, 0}, "Mesh origin").length(3);
  fdm.path("mesh", "", "Mesh file (empty: structured grid)");

  auto& coupling = r.section("coupling", "DEM-FDM coupling", Presence::Optional);
  coupling.choice("facet_spin", {"none", "kinematic"}, "none", "Facet spin model");
  coupling.real("overlap_tol", "m", 1e-6, "Overlap tolerance").min(0);
  coupling.boolean("enabled", true, "Exchange forces");

  auto& out = r.section("output", "Output files", Presence::Optional);
  out.string("dir", "out", "Output folder");
  out.real("interval", "s", 1e-3, "Output interval").min(0, true);
  out.strings("fields", std::vector<std::string>{"position", "velocity"}, "Fields written");

  auto& stage = r.array("stage", "Loading stages, run in order", Presence::Required);
  stage.string("name", std::nullopt, "Stage name");
  stage.real("duration", "s", std::nullopt, "Stage duration").min(0, true);
  stage.real("velocity", "m/s", 0.0, "Platen velocity");

  // Bonds need a bonded contact model: the error names both parties.
  s.check([](const cfg::Scene& sc, cfg::CheckContext& ctx) {
    if (sc.has("dem.bonds") && sc.string("dem.contact.model") == "linear")
      ctx.fail("dem.contact.model", "'softbond' or 'pbond' when [dem.bonds] is present",
               "'linear'");
  });
  // Output must be at least as frequent as the shortest stage.
  s.check([](const cfg::Scene& sc, cfg::CheckContext& ctx) {
    for (std::size_t i = 0; i < sc.count("stage"); ++i) {
      const std::string k = "stage[" + std::to_string(i) + "].duration";
      if (sc.has("output") && sc.real(k) < sc.real("output.interval"))
        ctx.fail(k, "a duration >= output.interval (" +
                        std::to_string(sc.real("output.interval")) + " s)",
                 std::to_string(sc.real(k)));
    }
  });
  return s;
}

// Smallest valid scene: only required keys and sections.
const char* const kMinimal =
    "[dem]\n"
    "dt = 1e-6\n"
    "[dem.contact]\n"
    "[fdm]\n"
    "[[stage]]\n"
    "name = \"settle\"\n"
    "duration = 0.5\n";

// Message of the Error thrown by parsing `text`, or "no error".
std::string error_of(std::string_view text, const std::string& base_dir = ".") {
  const cfg::Schema schema = make_schema();
  try {
    cfg::Scene::parse(text, "scene.toml", schema, base_dir);
  } catch (const cfg::Error& e) {
    return e.what();
  }
  return "no error";
}

// A fresh temporary folder per test, removed at the end.
struct TempDir {
  fs::path path;
  TempDir() {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    path = fs::temp_directory_path() /
           ("demfdm_config_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~TempDir() { fs::remove_all(path); }
  fs::path write(const std::string& name, const std::string& text) const {
    fs::path p = path / name;
    std::ofstream(p) << text;
    return p;
  }
};

}  // namespace

// ---------------------------------------------------------------------------
// Bad scenes: one exact message each, with line:col.
// ---------------------------------------------------------------------------

TEST(ConfigErrors, UnknownKeyWithSuggestion) {
  EXPECT_EQ(error_of("[dem]\n"
                     "dt = 1e-6\n"
                     "[dem.contact]\n"
                     "  emodd = 1e9\n"
                     "[fdm]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:3: dem.contact.emodd: unknown key; did you mean 'emod'?");
}

TEST(ConfigErrors, UnknownKeyPrefixSuggestion) {
  // Edit distance 5 but a prefix of a sibling: still suggested.
  EXPECT_EQ(error_of(std::string(kMinimal) + "[output]\nfie = [\"x\"]\n"),
            "scene.toml:9:1: output.fie: unknown key; did you mean 'fields'?");
}

TEST(ConfigErrors, UnknownKeyWithoutSuggestion) {
  EXPECT_EQ(error_of("[dem]\n"
                     "dt = 1e-6\n"
                     "[dem.contact]\n"
                     "[fdm]\n"
                     "banana_split = 3\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:5:1: fdm.banana_split: unknown key");
}

TEST(ConfigErrors, UnknownKeyInArrayElementAndInlineTable) {
  EXPECT_EQ(error_of(std::string(kMinimal) + "[[stage]]\nnme = \"b\"\n"),
            "scene.toml:9:1: stage[1].nme: unknown key; did you mean 'name'?");
  // Sections may be written as inline tables or dotted keys; unknown keys inside still
  // point at the key.
  EXPECT_EQ(error_of("dem = { dt = 1e-6, contact = { emod = 1e9, fricc = 0.1 } }\n[fdm]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:1:44: dem.contact.fricc: unknown key; did you mean 'fric'?");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\ncontact.emod = 1e9\ncontact.kratoi = 2\n[fdm]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:9: dem.contact.kratoi: unknown key; did you mean 'kratio'?");
}

TEST(ConfigErrors, UnknownSection) {
  EXPECT_EQ(error_of(std::string(kMinimal) + "[outptu]\ndir = \"x\"\n"),
            "scene.toml:8:2: outptu: unknown section; did you mean 'output'?");
  // A misspelled *required* section: the typo is reported, not "missing [dem.contact]".
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contct]\n[fdm]\n[[stage]]\nname = \"a\"\n"
                     "duration = 1\n"),
            "scene.toml:3:6: dem.contct: unknown section; did you mean 'contact'?");
}

TEST(ConfigErrors, WrongTypeStringForNumber) {
  EXPECT_EQ(error_of("[dem]\n"
                     "dt = \"fast\"\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:2:6: dem.dt: expected a number > 0 s, found string 'fast'");
}

TEST(ConfigErrors, WrongTypeRealForInt) {
  EXPECT_EQ(error_of("[dem]\n"
                     "dt = 1e-6\n"
                     "seed = 1.5\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:3:8: dem.seed: expected an integer >= 0, found float 1.5");
}

TEST(ConfigErrors, WrongTypeTableForScalar) {
  EXPECT_EQ(error_of("[dem]\n"
                     "dt = 1e-6\n"
                     "[dem.contact]\n"
                     "emod = { value = 1e9 }\n"
                     "[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:8: dem.contact.emod: expected a number > 0 Pa, found table");
}

TEST(ConfigErrors, WrongTypeForSections) {
  EXPECT_EQ(error_of("fdm = 3\n[dem]\ndt = 1e-6\n[dem.contact]\n[[stage]]\nname = \"a\"\n"
                     "duration = 1\n"),
            "scene.toml:1:7: fdm: expected a table [fdm], found integer 3");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n[stage]\nname = \"a\"\n"
                     "duration = 1\n"),
            "scene.toml:5:1: stage: expected an array of tables [[stage]], found table");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n[[stage]]\nname = true\n"
                     "duration = 1\n"),
            "scene.toml:6:8: stage[0].name: expected a string, found boolean true");
}

TEST(ConfigErrors, OutOfRangeLow) {
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n"
                     "fric = -0.1\n"
                     "[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:8: dem.contact.fric: expected a number >= 0, found -0.1");
}

TEST(ConfigErrors, OutOfRangeHigh) {
  // The example of the specification, column of the value.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"
                     "damping = 1.5\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:5:11: fdm.damping: expected a number in [0, 1), found 1.5");
}

TEST(ConfigErrors, OutOfRangeOpenBound) {
  // The open upper bound excludes 1 itself; the open lower bound of dt excludes 0.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n"
                     "damping = 1.0\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:3:11: dem.damping: expected a number in [0, 1), found 1");
  EXPECT_EQ(error_of("[dem]\n"
                     "dt = 0\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:2:6: dem.dt: expected a number > 0 s, found 0");
  // A closed bound accepts the bound itself.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\ndamping = 0\n[dem.contact]\nfric = 0.0\n[fdm]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "no error");
}

TEST(ConfigErrors, NanRejected) {
  EXPECT_EQ(error_of("[dem]\ndt = nan\n[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\n"
                     "duration = 1\n"),
            "scene.toml:2:6: dem.dt: expected a number > 0 s, found nan");
}

TEST(ConfigErrors, BadChoice) {
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n"
                     "model = \"hertz\"\n"
                     "[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:9: dem.contact.model: expected one of 'linear', 'softbond', "
            "'pbond', found 'hertz'");
}

TEST(ConfigErrors, MissingRequiredKey) {
  // Reported at the header of the table that lacks it.
  EXPECT_EQ(error_of("title = \"t\"\n"
                     "[dem]\n"
                     "seed = 1\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:2:1: dem.dt: missing required key; expected a number > 0 s");
  // Inside one element of an array of tables.
  EXPECT_EQ(error_of(std::string(kMinimal) + "[[stage]]\nname = \"b\"\n"),
            "scene.toml:8:1: stage[1].duration: missing required key; expected a number > 0 s");
  // A required key of an optional section, once the section is present.
  EXPECT_EQ(error_of(std::string(kMinimal) + "[dem.bonds]\nsb_coh = 1e6\n"),
            "scene.toml:8:1: dem.bonds.sb_ten: missing required key; expected a number > 0 Pa");
}

TEST(ConfigErrors, MissingRequiredSection) {
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:1:1: fdm: missing required section; expected a table [fdm]");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"),
            "scene.toml:1:1: stage: missing required section; expected at least one "
            "[[stage]] table");
  // A required sub-section is reported at its parent's header.
  EXPECT_EQ(error_of("[fdm]\n[dem]\ndt = 1e-6\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:2:1: dem.contact: missing required section; expected a table "
            "[dem.contact]");
}

TEST(ConfigErrors, PathMissingFile) {
  TempDir dir;
  const std::string resolved = (dir.path / "nope.vtk").string();
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"
                     "mesh = \"nope.vtk\"\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n",
                     dir.path.string()),
            "scene.toml:5:8: fdm.mesh: expected an existing file, found 'nope.vtk' (resolved to " +
                resolved + ")");
  // "" means "no file" where the default is "" (fdm.mesh), but is not a file otherwise.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\nmesh = \"\"\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "no error");
  // A folder is not a file.
  fs::create_directory(dir.path / "meshdir");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"
                     "mesh = \"meshdir\"\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n",
                     dir.path.string()),
            "scene.toml:5:8: fdm.mesh: expected an existing file, found 'meshdir' (resolved to " +
                (dir.path / "meshdir").string() + ")");
}

TEST(ConfigErrors, ListLengthWrong) {
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n"
                     "gravity = [0, -9.81]\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:3:11: dem.gravity[2]: missing element; expected a list of 3 numbers in "
            "m/s^2, found 2 elements");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n"
                     "gravity = [0, 0, -9.81, 1]\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:3:25: dem.gravity[3]: unexpected element; expected a list of 3 numbers "
            "in m/s^2, found 4 elements");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n"
                     "gravity = 9.81\n"
                     "[dem.contact]\n[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:3:11: dem.gravity: expected a list of 3 numbers in m/s^2, found float "
            "9.81");
}

TEST(ConfigErrors, ListElementOutOfRangeOrWrongType) {
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"
                     "cells = [10, 0, 10]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:5:14: fdm.cells[1]: expected an integer >= 1, found 0");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"
                     "cells = [10, 10, 2.5]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:5:18: fdm.cells[2]: expected an integer >= 1, found float 2.5");
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\n"
                     "origin = [0, \"a\", 0]\n"
                     "[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:5:14: fdm.origin[1]: expected a number in m, found string 'a'");
}

TEST(ConfigErrors, TomlSyntaxError) {
  EXPECT_EQ(error_of("[dem]\ndt = = 3\n"),
            "scene.toml:2:6: TOML syntax error: Error while parsing value: could not determine "
            "value type");
  // Duplicate keys are syntax errors too.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\ndt = 2e-6\n"),
            "scene.toml:3:6: TOML syntax error: Error while parsing key-value pair: cannot "
            "redefine existing floating-point 'dt'");
}

TEST(ConfigErrors, UnreadableFile) {
  const cfg::Schema schema = make_schema();
  TempDir dir;
  const std::string missing = (dir.path / "missing.toml").string();
  try {
    cfg::Scene::load(missing, schema);
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(std::string(e.what()), missing + ": cannot read scene file: No such file or directory");
    EXPECT_EQ(e.file, missing);
    EXPECT_EQ(e.line, 0);
    EXPECT_EQ(e.col, 0);
    EXPECT_EQ(e.key, "");
  }
  // A folder opens but cannot be read (EISDIR).
  try {
    cfg::Scene::load(dir.path.string(), schema);
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(std::string(e.what()), dir.path.string() + ": cannot read scene file: Is a directory");
  }
  // Permission denied (meaningless as root, who may read anything).
  if (::geteuid() != 0) {
    fs::path p = dir.write("locked.toml", kMinimal);
    fs::permissions(p, fs::perms::none);
    try {
      cfg::Scene::load(p.string(), schema);
      FAIL() << "no error";
    } catch (const cfg::Error& e) {
      EXPECT_EQ(std::string(e.what()), p.string() + ": cannot read scene file: Permission denied");
    }
  }
}

TEST(ConfigErrors, CrossFieldCheck) {
  // Explicit key: reported at its value.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n"
                     "model = \"linear\"\n"
                     "[dem.bonds]\nsb_ten = 1e6\n"
                     "[fdm]\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:9: dem.contact.model: expected 'softbond' or 'pbond' when [dem.bonds] "
            "is present, found 'linear'");
  // Key inside an array element, addressed by index.
  EXPECT_EQ(error_of(std::string(kMinimal) + "[[stage]]\nname = \"b\"\nduration = 1e-4\n" +
                     "[output]\ninterval = 0.01\n"),
            "scene.toml:10:12: stage[1].duration: expected a duration >= output.interval "
            "(0.010000 s), found 0.000100");
}

TEST(ConfigErrors, FirstErrorInFileIsReported) {
  // Three problems; the earliest position wins, whatever toml++'s key order.
  EXPECT_EQ(error_of("[dem]\ndt = 1e-6\n[dem.contact]\n"
                     "zzz = 1\n"
                     "aaa = 2\n"
                     "[fdm]\ndamping = 7\n[[stage]]\nname = \"a\"\nduration = 1\n"),
            "scene.toml:4:1: dem.contact.zzz: unknown key");
}

TEST(ConfigErrors, ErrorFields) {
  const cfg::Schema schema = make_schema();
  try {
    cfg::Scene::parse("[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\ndamping = 1.5\n[[stage]]\n"
                      "name = \"a\"\nduration = 1\n",
                      "scenes/x.toml", schema);
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(e.file, "scenes/x.toml");
    EXPECT_EQ(e.line, 5);
    EXPECT_EQ(e.col, 11);
    EXPECT_EQ(e.key, "fdm.damping");
  }
}

TEST(ConfigErrors, SchemaBugsAreLogicErrors) {
  cfg::Schema s;
  auto& r = s.root();
  // A default outside its own range is caught when the range is declared.
  EXPECT_THROW(r.real("a", "", -1.0, "").min(0), std::logic_error);
  EXPECT_THROW(r.choice("b", {"x", "y"}, "z", ""), std::logic_error);
  EXPECT_THROW(r.reals("c", "m", std::vector<double>{1, 2}, "").length(3), std::logic_error);
  r.real("d", "", 1.0, "");
  EXPECT_THROW(r.integer("d", "", 1, ""), std::logic_error);  // declared twice
  EXPECT_THROW(r.section("e.f", ""), std::logic_error);       // dotted name
  EXPECT_THROW(r.string("g", "x", "").min(0), std::logic_error);  // range on a string
}

// ---------------------------------------------------------------------------
// Good scenes.
// ---------------------------------------------------------------------------

TEST(ConfigScene, DefaultsFilled) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene s = cfg::Scene::parse(kMinimal, "scene.toml", schema);
  EXPECT_EQ(s.string("title"), "untitled");
  EXPECT_EQ(s.real("dem.damping"), 0.7);
  EXPECT_EQ(s.reals("dem.gravity"), (std::vector<double>{0, 0, -9.81}));
  EXPECT_EQ(s.integer("dem.seed"), 42);
  EXPECT_EQ(s.string("dem.particles"), "");  // empty default path: "no file"
  EXPECT_EQ(s.real("dem.contact.emod"), 1e9);
  EXPECT_EQ(s.string("dem.contact.model"), "softbond");
  EXPECT_EQ(s.integers("fdm.cells"), (std::vector<std::int64_t>{10, 10, 10}));
  EXPECT_EQ(s.real("fdm.damping"), 0.8);
  // Optional sections absent: effect off, but defaults still readable.
  EXPECT_FALSE(s.has("coupling"));
  EXPECT_FALSE(s.has("output"));
  EXPECT_EQ(s.string("coupling.facet_spin"), "none");
  EXPECT_TRUE(s.boolean("coupling.enabled"));
  EXPECT_EQ(s.strings("output.fields"), (std::vector<std::string>{"position", "velocity"}));
  EXPECT_EQ(s.real("stage[0].velocity"), 0.0);
  EXPECT_FALSE(s.explicitly_set("dem.damping"));
  EXPECT_TRUE(s.explicitly_set("dem.dt"));
}

TEST(ConfigScene, ExplicitValuesRead) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene s = cfg::Scene::parse(
      "title = \"uniaxial\"\n"
      "[dem]\ndt = 2.5e-7\ndamping = 0.3\ngravity = [0, -9.81, 0]\nseed = 7\n"
      "[dem.contact]\nemod = 3.5e9\nmodel = \"pbond\"\n"
      "[dem.bonds]\nsb_ten = 2e6\n"
      "[fdm]\ncells = [4, 5, 6]\norigin = [1.5, -2, 0]\n"
      "[coupling]\nfacet_spin = \"kinematic\"\nenabled = false\n"
      "[output]\nfields = [\"stress\"]\ninterval = 0.5\n"
      "[[stage]]\nname = \"a\"\nduration = 1\n",
      "scene.toml", schema);
  EXPECT_EQ(s.string("title"), "uniaxial");
  EXPECT_EQ(s.real("dem.dt"), 2.5e-7);
  EXPECT_EQ(s.real("dem.damping"), 0.3);
  EXPECT_EQ(s.reals("dem.gravity"), (std::vector<double>{0, -9.81, 0}));
  EXPECT_EQ(s.integer("dem.seed"), 7);
  EXPECT_EQ(s.real("dem.contact.emod"), 3.5e9);
  EXPECT_EQ(s.string("dem.contact.model"), "pbond");
  EXPECT_EQ(s.real("dem.bonds.sb_ten"), 2e6);
  EXPECT_EQ(s.real("dem.bonds.sb_coh"), 0.0);
  EXPECT_EQ(s.integers("fdm.cells"), (std::vector<std::int64_t>{4, 5, 6}));
  EXPECT_EQ(s.reals("fdm.origin"), (std::vector<double>{1.5, -2, 0}));
  EXPECT_EQ(s.string("coupling.facet_spin"), "kinematic");
  EXPECT_FALSE(s.boolean("coupling.enabled"));
  EXPECT_EQ(s.strings("output.fields"), (std::vector<std::string>{"stress"}));
  EXPECT_EQ(s.real("output.interval"), 0.5);
  EXPECT_TRUE(s.has("dem.bonds"));
  EXPECT_TRUE(s.has("coupling"));
  EXPECT_TRUE(s.has("dem.contact.model"));
  EXPECT_FALSE(s.has("dem.contact.fric"));
}

TEST(ConfigScene, IntegerPromotedToReal) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene s = cfg::Scene::parse(
      "[dem]\ndt = 1\ngravity = [0, 0, -10]\n[dem.contact]\nemod = 2000000000\n[fdm]\n"
      "[[stage]]\nname = \"a\"\nduration = 3\n",
      "scene.toml", schema);
  EXPECT_EQ(s.real("dem.dt"), 1.0);
  EXPECT_EQ(s.real("dem.contact.emod"), 2e9);
  EXPECT_EQ(s.reals("dem.gravity"), (std::vector<double>{0, 0, -10}));
  EXPECT_EQ(s.real("stage[0].duration"), 3.0);
}

TEST(ConfigScene, ArrayOfTables) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene s = cfg::Scene::parse(std::string(kMinimal) +
                                             "[[stage]]\n"        // line 8
                                             "name = \"load\"\n"  // line 9
                                             "duration = 2\n"     // line 10
                                             "velocity = -0.01\n",
                                         "scene.toml", schema);
  ASSERT_EQ(s.count("stage"), 2u);
  EXPECT_TRUE(s.has("stage"));
  EXPECT_TRUE(s.has("stage[1]"));
  EXPECT_FALSE(s.has("stage[2]"));
  const cfg::Scene st0 = s.at("stage", 0);
  const cfg::Scene st1 = s.at("stage", 1);
  EXPECT_EQ(st0.string("name"), "settle");
  EXPECT_EQ(st0.real("duration"), 0.5);
  EXPECT_EQ(st0.real("velocity"), 0.0);
  EXPECT_EQ(st1.string("name"), "load");
  EXPECT_EQ(st1.real("velocity"), -0.01);
  EXPECT_EQ(s.real("stage[1].duration"), 2.0);
  EXPECT_EQ(st1.prefix(), "stage[1]");
  EXPECT_EQ(st1.where("duration"), "scene.toml:10:12");
  EXPECT_EQ(st0.where("velocity"), "scene.toml:5:1");  // defaulted: the [[stage]] header
  EXPECT_EQ(st1.text(), s.text());
  // fail() on a view names the full path.
  try {
    st1.fail("duration", "a shorter stage", "2");
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(std::string(e.what()),
              "scene.toml:10:12: stage[1].duration: expected a shorter stage, found 2");
  }
  EXPECT_THROW(s.at("stage", 2), std::out_of_range);
  // An absent optional array has zero elements.
  cfg::Schema opt;
  opt.root().array("probe", "", Presence::Optional).real("x", "m", 0.0, "");
  const cfg::Scene e = cfg::Scene::parse("", "e.toml", opt);
  EXPECT_EQ(e.count("probe"), 0u);
  EXPECT_FALSE(e.has("probe"));
}

TEST(ConfigScene, HasForOptionalSections) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene off = cfg::Scene::parse(kMinimal, "scene.toml", schema);
  EXPECT_FALSE(off.has("dem.bonds"));
  EXPECT_EQ(off.real("dem.bonds.sb_coh"), 0.0);
  // A required key of an absent section has no value; reading it is a program error.
  EXPECT_THROW(off.real("dem.bonds.sb_ten"), std::logic_error);
  // An empty table switches the effect on with defaults (only sb_ten is required).
  cfg::Schema s2;
  s2.root().section("gravity", "", Presence::Optional).reals("g", "m/s^2",
                                                             std::vector<double>{0, 0, -9.81}, "");
  const cfg::Scene on = cfg::Scene::parse("[gravity]\n", "g.toml", s2);
  EXPECT_TRUE(on.has("gravity"));
  EXPECT_FALSE(on.has("gravity.g"));
  EXPECT_EQ(on.reals("gravity.g"), (std::vector<double>{0, 0, -9.81}));
  // Program errors: undeclared path, wrong accessor.
  EXPECT_THROW(off.has("dem.nonsense"), std::logic_error);
  EXPECT_THROW(off.integer("dem.dt"), std::logic_error);
  EXPECT_THROW(off.real("stage.duration"), std::logic_error);
}

TEST(ConfigScene, WhereAndFail) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene s = cfg::Scene::parse(kMinimal, "scene.toml", schema);
  EXPECT_EQ(s.where("dem.dt"), "scene.toml:2:6");
  EXPECT_EQ(s.where("dem.damping"), "scene.toml:1:1");        // defaulted: the [dem] header
  EXPECT_EQ(s.where("dem.contact.emod"), "scene.toml:3:1");   // defaulted: [dem.contact]
  EXPECT_EQ(s.where("coupling.enabled"), "scene.toml:1:1");   // absent section: top of file
  EXPECT_EQ(s.where("fdm"), "scene.toml:4:1");
  // List elements: positions of explicit elements; a defaulted list points at its table.
  const cfg::Scene g = cfg::Scene::parse(
      "[dem]\ndt = 1e-6\ngravity = [0, -9.81, 0]\n[dem.contact]\n[fdm]\n[[stage]]\n"
      "name = \"a\"\nduration = 1\n",
      "scene.toml", schema);
  EXPECT_EQ(g.where("dem.gravity[1]"), "scene.toml:3:15");
  EXPECT_TRUE(g.has("dem.gravity[2]"));
  EXPECT_FALSE(g.has("dem.gravity[3]"));
  EXPECT_EQ(g.where("fdm.cells[1]"), "scene.toml:5:1");
  EXPECT_THROW(g.real("dem.gravity[1]"), std::logic_error);
  try {
    g.fail("dem.gravity[1]", "a horizontal component of 0", "-9.81");
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(std::string(e.what()),
              "scene.toml:3:15: dem.gravity[1]: expected a horizontal component of 0, found -9.81");
  }
  try {
    s.fail("fdm.damping", "a damping below 0.5", "0.8");
    FAIL() << "no error";
  } catch (const cfg::Error& e) {
    EXPECT_EQ(std::string(e.what()), "scene.toml:4:1: fdm.damping: expected a damping below 0.5, found 0.8");
    EXPECT_EQ(e.key, "fdm.damping");
  }
}

TEST(ConfigScene, LoadFromFileResolvesPaths) {
  TempDir dir;
  fs::create_directories(dir.path / "meshes");
  dir.write("meshes/block.vtk", "# vtk\n");
  const fs::path scene = dir.write(
      "scene.toml", "[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\nmesh = \"meshes/block.vtk\"\n"
                    "[[stage]]\nname = \"a\"\nduration = 1\n");
  const cfg::Schema schema = make_schema();
  const cfg::Scene s = cfg::Scene::load(scene.string(), schema);
  EXPECT_EQ(s.origin(), scene.string());
  const std::string mesh = s.string("fdm.mesh");
  EXPECT_TRUE(fs::path(mesh).is_absolute());
  EXPECT_EQ(mesh, (dir.path / "meshes" / "block.vtk").lexically_normal().string());
  EXPECT_TRUE(fs::is_regular_file(mesh));
  std::ifstream in(scene);
  std::stringstream buf;
  buf << in.rdbuf();
  EXPECT_EQ(s.text(), buf.str());  // the exact source text, for the bus
  EXPECT_EQ(s.where("fdm.mesh"), scene.string() + ":5:8");
  // An absolute path is kept as is, whatever base_dir says.
  const std::string abs_mesh = (dir.path / "meshes" / "block.vtk").string();
  const cfg::Scene t = cfg::Scene::parse(
      "[dem]\ndt = 1e-6\n[dem.contact]\n[fdm]\nmesh = \"" + abs_mesh +
          "\"\n[[stage]]\nname = \"a\"\nduration = 1\n",
      "bus", schema, "/nonexistent");
  EXPECT_EQ(t.string("fdm.mesh"), abs_mesh);
}

TEST(ConfigScene, EffectiveTomlRoundTrip) {
  // Invariant: the effective TOML re-parses to the same values, and is a fixed point.
  TempDir dir;
  dir.write("mesh.vtk", "# vtk\n");
  const cfg::Schema schema = make_schema();
  const cfg::Scene a = cfg::Scene::parse(
      "title = \"say \\\"hi\\\"\\n\\ttab\"\n"
      "[dem]\ndt = 1e-6\ndamping = 0.1\n[dem.contact]\nemod = 12345678901\nmodel = \"pbond\"\n"
      "[dem.bonds]\nsb_ten = 0.1\n[fdm]\nmesh = \"mesh.vtk\"\norigin = [0.1, 0.2, 0.30000000000000004]\n"
      "[output]\n"
      "[[stage]]\nname = \"a\"\nduration = 1\n[[stage]]\nname = \"b\"\nduration = 2.5\n",
      "scene.toml", schema, dir.path.string());
  const std::string eff = a.effective_toml();
  const cfg::Scene b = cfg::Scene::parse(eff, "effective.toml", schema, "/nonexistent");
  const std::string eff2 = b.effective_toml();  // the first (comment) line names the origin
  EXPECT_EQ(eff2.substr(eff2.find('\n')), eff.substr(eff.find('\n'))) << eff;
  EXPECT_EQ(b.string("title"), "say \"hi\"\n\ttab");
  EXPECT_EQ(b.real("dem.contact.emod"), 12345678901.0);
  EXPECT_EQ(b.reals("fdm.origin"), a.reals("fdm.origin"));  // bit-exact shortest digits
  EXPECT_EQ(b.string("fdm.mesh"), (dir.path / "mesh.vtk").string());
  EXPECT_EQ(b.real("dem.contact.fric"), 0.0);
  EXPECT_TRUE(b.explicitly_set("dem.contact.fric"));  // defaults are written out
  EXPECT_TRUE(b.has("dem.bonds"));
  EXPECT_TRUE(b.has("output"));
  EXPECT_FALSE(b.has("coupling"));  // absent optional sections stay absent
  ASSERT_EQ(b.count("stage"), 2u);
  EXPECT_EQ(b.at("stage", 1).string("name"), "b");
  EXPECT_EQ(b.real("stage[1].duration"), 2.5);
}

TEST(ConfigScene, SchemaMovable) {
  cfg::Schema moved = make_schema();
  cfg::Schema target;
  target = std::move(moved);
  const cfg::Scene s = cfg::Scene::parse(kMinimal, "scene.toml", target);
  EXPECT_EQ(s.real("dem.dt"), 1e-6);
  // The cross-field checks moved along.
  EXPECT_EQ(target.checks().size(), 2u);
}

TEST(ConfigScene, HashStableAndTextSensitive) {
  const cfg::Schema schema = make_schema();
  const cfg::Scene a = cfg::Scene::parse(kMinimal, "a.toml", schema);
  const cfg::Scene b = cfg::Scene::parse(kMinimal, "b.toml", schema);
  EXPECT_EQ(a.hash(), b.hash());  // independent of origin, stable across parses
  // Reference value computed independently (Python FNV-1a 64 over the same bytes).
  EXPECT_EQ(a.hash(), 0x07e5783878bfc53bull);
  // FNV-1a 64 of the empty string is the offset basis.
  EXPECT_EQ(cfg::Scene().hash(), 0xcbf29ce484222325ull);
  // One character changed (same meaning) changes the hash.
  std::string other(kMinimal);
  other.replace(other.find("1e-6"), 4, "1E-6");
  const cfg::Scene c = cfg::Scene::parse(other, "a.toml", schema);
  EXPECT_EQ(c.real("dem.dt"), a.real("dem.dt"));
  EXPECT_NE(c.hash(), a.hash());
  // Round trip over the "bus": text() re-parsed gives the same scene and hash.
  const cfg::Scene d = cfg::Scene::parse(a.text(), "bus", schema);
  EXPECT_EQ(d.hash(), a.hash());
  EXPECT_EQ(d.text(), kMinimal);
}

TEST(ConfigScene, SceneOutlivesSchema) {
  cfg::Scene s;
  {
    const cfg::Schema schema = make_schema();
    s = cfg::Scene::parse(kMinimal, "scene.toml", schema);
  }
  EXPECT_EQ(s.real("dem.dt"), 1e-6);
  EXPECT_EQ(s.at("stage", 0).string("name"), "settle");
}

// ---------------------------------------------------------------------------
// Generated documentation.
// ---------------------------------------------------------------------------

namespace {
// Every declared parameter with its full dotted section path.
void collect(const cfg::Section& sec, std::vector<std::pair<std::string, const cfg::Param*>>& out) {
  for (const auto& m : sec.members()) {
    if (m.param) out.emplace_back(sec.path(), m.param);
    else collect(*m.section, out);
  }
}

// The line of `text` under the header `header` that documents `key`
// (a line starting with key, after the given prefix).
std::string line_of(const std::string& text, const std::string& header, const std::string& key,
                    const std::string& key_prefix) {
  std::istringstream in(text);
  std::string line;
  bool in_section = false;
  while (std::getline(in, line)) {
    if (line.find(header) != std::string::npos) {
      in_section = true;
      continue;
    }
    if (in_section && line.rfind(key_prefix + key + (key_prefix == "  " ? " " : "`"), 0) == 0)
      return line;
    if (in_section && (line.rfind("[", 0) == 0 || line.rfind("(top level)", 0) == 0 ||
                       line.rfind("### ", 0) == 0))
      in_section = false;
  }
  return "";
}
}  // namespace

TEST(ConfigDocs, HelpTextHasEveryKeyWithUnitAndDefault) {
  const cfg::Schema schema = make_schema();
  const std::string help = schema.help_text();
  std::vector<std::pair<std::string, const cfg::Param*>> params;
  collect(schema.root(), params);
  ASSERT_EQ(params.size(), 25u);
  for (const auto& [sec, p] : params) {
    const std::string header = sec.empty()    ? "(top level)"
                               : sec == "stage" ? "[[stage]]"
                                                : "[" + sec + "]";
    const std::string line =
        line_of(help, sec.empty() ? header : header + "  (", p->name, "  ");
    ASSERT_FALSE(line.empty()) << sec << "." << p->name << "\n" << help;
    if (!p->unit.empty()) {
      EXPECT_NE(line.find("[" + p->unit + "]"), std::string::npos) << line;
    }
    const std::string def = p->def ? cfg::format_value(*p->def) : "(required)";
    EXPECT_NE(line.find(def), std::string::npos) << line;
    EXPECT_NE(line.find(p->doc), std::string::npos) << line;
  }
  // Ranges appear in interval form.
  EXPECT_NE(line_of(help, "[fdm]  (", "damping", "  ").find("[0, 1)"), std::string::npos);
  EXPECT_NE(line_of(help, "[dem]  (", "dt", "  ").find("(0, inf)"), std::string::npos);
}

TEST(ConfigDocs, MarkdownHasEveryKeyWithUnitAndDefault) {
  const cfg::Schema schema = make_schema();
  const std::string md = schema.markdown();
  std::vector<std::pair<std::string, const cfg::Param*>> params;
  collect(schema.root(), params);
  for (const auto& [sec, p] : params) {
    const std::string header = sec.empty()    ? "### `(top level)`"
                               : sec == "stage" ? "### `[[stage]]`"
                                                : "### `[" + sec + "]`";
    const std::string line = line_of(md, header, p->name, "| `");
    ASSERT_FALSE(line.empty()) << sec << "." << p->name << "\n" << md;
    EXPECT_NE(line.find("| " + (p->unit.empty() ? std::string("-") : p->unit) + " |"),
              std::string::npos)
        << line;
    std::string def = "required";
    if (p->def) {  // built piecewise: GCC 12 warns falsely (-Wrestrict) on "`" + string
      def = "`";
      def += cfg::format_value(*p->def);
      def += '`';
    }
    EXPECT_NE(line.find(def), std::string::npos) << line;
  }
  EXPECT_NE(md.find("| Key | Type | Unit | Default | Range | Description |"), std::string::npos);
}

TEST(ConfigDocs, Describe) {
  cfg::Param p;
  p.kind = cfg::Kind::Real;
  p.unit = "Pa";
  EXPECT_EQ(cfg::describe(p), "a number in Pa");
  p.lo = 0;
  p.hi = 1;
  p.hi_open = true;
  EXPECT_EQ(cfg::describe(p), "a number in [0, 1) Pa");
  p.kind = cfg::Kind::RealList;
  p.length = 3;
  EXPECT_EQ(cfg::describe(p), "a list of 3 numbers each in [0, 1) Pa");
  // "-" marks a dimensionless quantity, like an empty unit.
  cfg::Param n;
  n.kind = cfg::Kind::Int;
  n.unit = "-";
  n.lo = 1;
  EXPECT_EQ(cfg::describe(n), "an integer >= 1");
  n.kind = cfg::Kind::Choice;
  n.choices = {"a", "b"};
  EXPECT_EQ(cfg::describe(n), "one of 'a', 'b'");
  EXPECT_EQ(cfg::format_value(cfg::Value(1e9)), "1e9");
  EXPECT_EQ(cfg::format_value(cfg::Value(2.5e-5)), "2.5e-5");
  EXPECT_EQ(cfg::format_value(cfg::Value(std::vector<double>{0, 0, -9.81})), "[0, 0, -9.81]");
}

// The message of the config::Error that f throws, or "no error".
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const cfg::Error& e) {
    return std::string(e.what());
  }
  return std::string("no error");
}

// A "derived" value is an explicit word, never a negative number (issue 15 item 5): a number key
// declared with or_word() holds a number in its range or the word; a negative number is refused
// with the word named; infinity and NaN are never accepted.
TEST(ConfigScene, NumberOrWord) {
  cfg::Schema s;
  auto& sp = s.root().section("specimen", "REV", Presence::Required);
  sp.real("sigma_v", "Pa", std::nullopt, "Vertical stress; auto: from the self-weight").min(0, true).or_word("auto", true);
  sp.real("pb_ten", "Pa", 4.5e5, "Tensile strength; unbreakable: none").min(0).or_word("unbreakable", false);
  auto parse = [&](const std::string& text, std::vector<std::string> sets = {}) {
    return cfg::Scene::parse(text, "w.toml", s, ".", sets);
  };
  const auto a = parse("[specimen]\n");
  EXPECT_FALSE(a.real_or_word("specimen.sigma_v").has_value());  // the default is the word
  EXPECT_EQ(*a.real_or_word("specimen.pb_ten"), 4.5e5);
  EXPECT_THROW(a.real("specimen.sigma_v"), std::logic_error);  // a word read as a number: a bug
  const auto b = parse("[specimen]\nsigma_v = 5e3\npb_ten = \"unbreakable\"\n");
  EXPECT_EQ(*b.real_or_word("specimen.sigma_v"), 5e3);
  EXPECT_EQ(b.real("specimen.sigma_v"), 5e3);
  EXPECT_FALSE(b.real_or_word("specimen.pb_ten").has_value());
  // The effective TOML writes the word and reads back the same.
  const auto c = parse(b.effective_toml());
  EXPECT_FALSE(c.real_or_word("specimen.pb_ten").has_value());
  EXPECT_EQ(c.real("specimen.sigma_v"), 5e3);
  // Overrides take the word as the file does.
  EXPECT_FALSE(parse("[specimen]\nsigma_v = 5e3\n", {"specimen.sigma_v=auto"}).real_or_word("specimen.sigma_v"));
  auto err = [&](const std::string& text) { return error_of([&] { parse(text); }); };
  EXPECT_EQ(err("[specimen]\nsigma_v = -5e3\n"), "w.toml:2:11: specimen.sigma_v: expected a number > 0 Pa or 'auto', found -5000");
  EXPECT_EQ(err("[specimen]\nsigma_v = \"derived\"\n"),
            "w.toml:2:11: specimen.sigma_v: expected a number > 0 Pa or 'auto', found string 'derived'");
  EXPECT_EQ(err("[specimen]\npb_ten = inf\n"),
            "w.toml:2:10: specimen.pb_ten: expected a number >= 0 Pa or 'unbreakable', found inf");
  // A word on a key that is not a number, or an empty word, is a schema bug.
  cfg::Schema bad;
  EXPECT_THROW(bad.root().string("name", std::string("x"), "doc").or_word("auto", true), std::logic_error);
  EXPECT_THROW(bad.root().real("v", "", 1.0, "doc").or_word("", false), std::logic_error);
}

// The same for an integer key (run.threads = "auto", issue 16 item 2): the number or the word,
// read with integer_or_word(); the effective TOML and overrides keep the word.
TEST(ConfigScene, IntegerOrWord) {
  cfg::Schema s;
  auto& run = s.root().section("run", "run", Presence::Optional);
  run.integer("threads", "-", 1, "threads; auto: every CPU").min(1).max(256).or_word("auto", false);
  auto parse = [&](const std::string& text, std::vector<std::string> sets = {}) {
    return cfg::Scene::parse(text, "t.toml", s, ".", sets);
  };
  EXPECT_EQ(*parse("").integer_or_word("run.threads"), 1);
  EXPECT_EQ(parse("[run]\nthreads = 3\n").integer("run.threads"), 3);
  const auto a = parse("[run]\nthreads = \"auto\"\n");
  EXPECT_FALSE(a.integer_or_word("run.threads").has_value());
  EXPECT_THROW(a.integer("run.threads"), std::logic_error);
  EXPECT_FALSE(parse(a.effective_toml()).integer_or_word("run.threads").has_value());
  EXPECT_FALSE(parse("[run]\nthreads = 2\n", {"run.threads=auto"}).integer_or_word("run.threads").has_value());
  auto err = [&](const std::string& text) { return error_of([&] { parse(text); }); };
  EXPECT_EQ(err("[run]\nthreads = 0\n"), "t.toml:2:11: run.threads: expected an integer in [1, 256] or 'auto', found 0");
  EXPECT_EQ(err("[run]\nthreads = \"all\"\n"),
            "t.toml:2:11: run.threads: expected an integer in [1, 256] or 'auto', found string 'all'");
  // The project's key: "auto" resolves to the CPUs of this process, a number to itself.
  const auto& sc = demfdm::schema::scene_schema();
  const std::string stage = "[[stage]]\nname = \"s\"\naction = \"cycle\"\nnodes = [\"dem\"]\nsteps = 1\n[dem]\n";
  EXPECT_EQ(demfdm::schema::run_threads(cfg::Scene::parse("[run]\nthreads = 3\n" + stage, "r.toml", sc)), 3);
  cpu_set_t set;
  CPU_ZERO(&set);
  ASSERT_EQ(sched_getaffinity(0, sizeof set, &set), 0);
  EXPECT_EQ(demfdm::schema::run_threads(cfg::Scene::parse("[run]\nthreads = \"auto\"\n" + stage, "r.toml", sc)), CPU_COUNT(&set));
}

// The stage-action table (schema::actions()) is the one list of actions: the schema's choice
// holds its names in order, each row's own keys are declared stage keys, preparation is the
// DEM's specimen generation, and a read stage carries the row's Action.
TEST(SceneSchema, StageActionsAreOneTable) {
  namespace sch = demfdm::schema;
  const auto& sc = sch::scene_schema();
  const auto* stage = sc.root().find("stage")->section;
  const auto* action = stage->find("action")->param;
  ASSERT_EQ(action->choices.size(), sch::actions().size());
  std::vector<std::string> preparation;
  for (std::size_t i = 0; i < sch::actions().size(); ++i) {
    const auto& a = sch::actions()[i];
    EXPECT_EQ(action->choices[i], a.name);
    EXPECT_EQ(&sch::action_info(a.id), &a);
    EXPECT_TRUE(a.dem || a.continuum) << a.name;
    for (const auto& key : a.keys) EXPECT_NE(stage->find(key), nullptr) << a.name << "." << key;
    if (a.preparation) {
      preparation.emplace_back(a.name);
      EXPECT_FALSE(a.continuum) << a.name << ": preparation is the DEM's alone";
    }
  }
  EXPECT_EQ(preparation, (std::vector<std::string>{"generate", "servo", "bond", "replicate"}));
  std::string text = "[dem]\n";
  for (const char* a : {"generate", "cycle", "ucs", "bond"})
    text += std::string("[[stage]]\nname = \"") + a + "\"\naction = \"" + a + "\"\nsteps = 1\n";
  const auto stages = sch::stages(cfg::Scene::parse(text, "a.toml", sc));
  ASSERT_EQ(stages.size(), 4u);
  for (const auto& st : stages) EXPECT_EQ(st.name, sch::action_info(st.kind).name);
}
