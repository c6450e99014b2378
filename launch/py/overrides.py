#!/usr/bin/python3
"""Scene variants as overrides: what the studies, ensembles and sweeps share.

No study edits a scene's text. A variant is a scene file and a list of overrides
"table.key=value" (a stage key: "stage.NAME.key=value" or "stage[i].key=value"; values are TOML),
the arguments of `launch/run SCENE --set ...`. The coordinator applies them to the file's values
and validates the result as it validates the file (`coordinator SCENE --check --set ...`), and a
run with overrides records its effective scene (every value in effect; its header names the scene
file and the overrides) as RUN_DIR/scene.toml. Here: the overrides as command-line arguments, the
studies' quiet traffic default, the coordinator's check and effective scene, and whether a
finished run ran a given variant (by the values in effect, so that a run folder written before
the studies used overrides, whose scene.toml is an edited copy of the scene, counts as well).
"""
import hashlib
import os
import subprocess
import tomllib

import branching  # (coordinator_command)


def set_args(sets):
    """The overrides as launch/run and coordinator arguments: ["--set=KEY=VALUE", ...]."""
    return ["--set=" + s for s in sets]


def key_of(s):
    """The key of an override "KEY=VALUE"."""
    return s.split("=", 1)[0].strip()


def merge(sets):
    """The overrides with one per key: a later one replaces an earlier one of the same key in its
    place (launch/run applies them in order, a later one wins: the values are the same)."""
    out = {}
    for s in sets:
        out[key_of(s)] = s
    return list(out.values())


def stage_set(stage, key, value):
    """The override of key `key` of the [[stage]] named `stage`."""
    return "stage.%s.%s=%s" % (stage, key, value)


def scene_values(scene):
    """The scene file's own tables (tomllib), {} when it cannot be read (the coordinator names the
    problem when the scene is checked)."""
    try:
        with open(scene, "rb") as f:
            return tomllib.load(f)
    except (OSError, tomllib.TOMLDecodeError):
        return {}


def quiet_traffic(scene, sets):
    """The overrides with "output.traffic_log=false" added unless the scene file or an override
    says output.traffic_log itself. Study, ensemble and sweep runs record no traffic log by
    default: a coupled run's log holds every interface message (about 1 GB for the default
    scene), which a study of load curves does not need."""
    sets = list(sets)
    if any(key_of(s) == "output.traffic_log" for s in sets):
        return sets
    out = scene_values(scene).get("output")
    if isinstance(out, dict) and "traffic_log" in out:
        return sets
    return sets + ["output.traffic_log=false"]


def _coordinator(coordinator):
    return list(coordinator) if coordinator else branching.coordinator_command()


def check(scene, sets=(), coordinator=None, checkpoint=None):
    """(True, "") when the coordinator accepts the scene with the overrides (and, with
    `checkpoint`, a start from that saved state), else (False, its one error line)."""
    cmd = _coordinator(coordinator) + [scene, "--check"] + set_args(sets)
    if checkpoint:
        cmd.append("--from=" + checkpoint)
    r = subprocess.run(cmd, capture_output=True, text=True)
    return r.returncode == 0, (r.stderr or r.stdout).strip()


def effective(scene, sets=(), coordinator=None):
    """The effective scene of the scene file with the overrides (coordinator --print-effective),
    the text a run records as its scene.toml; ValueError with the coordinator's error line when
    they are invalid."""
    r = subprocess.run(_coordinator(coordinator) + [scene] + set_args(sets) + ["--print-effective"],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise ValueError((r.stderr or r.stdout).strip() or "%s: coordinator exit %d" % (scene, r.returncode))
    return r.stdout


def values_text(effective_text):
    """An effective scene without its comment header (the scene file, its hash, the overrides):
    the values in effect, equal for every way of writing the same scene."""
    lines = effective_text.split("\n")
    i = 0
    while i < len(lines) and (lines[i].startswith("#") or not lines[i].strip()):
        i += 1
    return "\n".join(lines[i:])


def values(scene, sets=(), coordinator=None):
    """The values in effect of the scene file with the overrides (values_text of effective)."""
    return values_text(effective(scene, sets, coordinator))


def digest(values_text):
    """A short hash of values in effect (values_text)."""
    return hashlib.sha1(values_text.encode()).hexdigest()[:12]


def fingerprint(scene, sets=(), coordinator=None):
    """A short hash of the values in effect: two variants with the same fingerprint are one run."""
    return digest(values(scene, sets, coordinator))


EFFECTIVE_HEADER = "# Effective scene:"


def run_values(run_dir, coordinator=None):
    """The values in effect of the scene a run folder ran (its scene.toml), or None. Read through
    the coordinator, so that an edited copy of a scene (a run of a study written before the
    studies used overrides) and an effective scene of an older build (keys added since get their
    defaults) compare alike; an effective scene the coordinator cannot read again is taken as it
    is (its values are explicit)."""
    path = os.path.join(run_dir, "scene.toml")
    try:
        with open(path) as f:
            text = f.read()
    except OSError:
        return None
    try:
        return values(path, (), coordinator)
    except ValueError:
        return values_text(text) if text.startswith(EFFECTIVE_HEADER) else None


def ran(run_dir, scene, sets=(), coordinator=None):
    """Whether the run folder ran the scene file with these overrides: its scene.toml is their
    effective scene, or has the same values in effect (run_values)."""
    try:
        with open(os.path.join(run_dir, "scene.toml")) as f:
            have = f.read()
    except OSError:
        return False
    want = effective(scene, sets, coordinator)
    if have == want or (have.startswith(EFFECTIVE_HEADER) and values_text(have) == values_text(want)):
        return True
    return run_values(run_dir, coordinator) == values_text(want)
