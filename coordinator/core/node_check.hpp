// `--check` runs every check a node would run (issue 15 item 6): the coordinator validates the
// scene against the declared schema and its cross-field checks, then runs each role's executable
// as `EXE --check SCENE [--set table.key=value]...`, which maps the scene onto its engine and runs
// the engine's validation without a bus (messages/README.md, "Checking a scene").
#pragma once

#include <optional>
#include <string>
#include <vector>

namespace demfdm::coord {

/// Path of a node executable: `name` itself if it contains a '/', else `bin_dir`/name if that is
/// an executable file, else the first match on PATH; "" when none is found.
std::string resolve_executable(const std::string& name, const std::string& bin_dir);

/// Folder of the running executable (for resolve_executable), "" if unknown.
std::string own_bin_dir();

/// Runs `exe --check scene [--set s]...` and returns nothing when it exits 0, else its output
/// (stderr and stdout, trimmed) or a line saying how it ended (signal, exit code).
std::optional<std::string> check_node(const std::string& exe, const std::string& scene,
                                      const std::vector<std::string>& sets);

}  // namespace demfdm::coord
