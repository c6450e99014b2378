"""One run folder (README "Running scenes"; files listed there) read into Python objects."""
import collections
import functools
import json
import os
import re
import tomllib

import numpy as np

from .table import read_csv

HISTORY = re.compile(r"^history_(\d+)_(.+)\.csv$")
RESULTS = {"dem": ("dem.h5",), "fdm": ("fdm.h5", "fem.h5")}
DEFAULT_BALL_BALL_MODEL = "softbond"  # common/schema/scene_schema.cpp, declare_family(d, "ball_ball", ...)
KINDS = {"dem": "dem", "fdm": "fdm", "fem": "fdm", "continuum": "fdm"}

# The bond "state" codes dem_node writes into dem.h5 (dem_node/core/include/demfdm/dem/params.hpp,
# BondState; the same names as launch/py/paper_figures.STATE_NAMES).
BOND_STATES = {0: "never_bonded", 1: "intact", 2: "softening", 3: "broken_tension", 4: "broken_shear"}

FrameInfo = collections.namedtuple("FrameInfo", "index step time")


class Frame(dict):
    """The arrays of one HDF5 output frame; attributes kind, index, step, time [s], path.

    Every dataset of the frame under its path in the frame group ("particles/position",
    "bonds/state", "nodes/displacement", "zones/stress"), and shorter names for the same arrays:
      dem: the particle arrays by their names ("position" [Np,3] m, "radius" [Np] m,
           "velocity" [Np,3] m/s, "id" [Np]); each link set by its name for its particle pairs
           ("bonds" = "bonds/nodes" [Nb,2], rows into the particle arrays; "bonds/state" codes in
           BOND_STATES, "bonds/force" [Nb,3] N);
      fdm: the node and zone arrays by their names ("displacement" [Nn,3] m, "velocity",
           "stress" [Nz,6] Pa xx yy zz xy yz xz tension positive, "plastic") when the name is not
           both a node and a zone array; the static mesh "node_coords" [Nn,3] m and "zone_nodes"
           [Nz,8] (VTK hexahedron order); "position" = the current node coordinates (the frame's
           "nodes/position", else node_coords + displacement).
    """

    def __init__(self, kind, index, step, time, path):
        super().__init__()
        self.kind, self.index, self.step, self.time, self.path = kind, index, step, time, path

    def __repr__(self):
        return "Frame(%s #%d, step %d, t = %.6g s: %s)" % (self.kind, self.index, self.step, self.time,
                                                          ", ".join(self.keys()))


def _text(v):
    return v.decode() if isinstance(v, bytes) else str(v)


class Run:
    """A run folder. Cheap to create: every file is read when first asked for.

    path, name          the folder and its base name
    scene               scene.toml as a dict (tomllib)
    summary             summary.json as a dict ({} when the run wrote none: crashed or running)
    result              summary["result"] (the footing result), or None
    centrifuge          summary["centrifuge"] (the centrifuge planning values), or None
    stages              stage names in run order
    history(stage)      a stage history history_<n>_<stage>.csv as a Table
    curve()             (settlement [m], load [N]) of the last penetration stage
    dem_history(), fdm_history()         the node histories (dem_history.csv, fdm/fem_history.csv)
    profile(stage, kind)                 dem_profile_<stage>.csv / fdm_profile_<stage>.csv
    frames(kind), frame(kind, i)         HDF5 output frames of dem.h5 / fdm.h5 (fem.h5)
    checkpoints()       the checkpoint folders with a manifest, by step
    csv(name)           any CSV file of the folder as a Table (e.g. "specimen_stages.csv")
    """

    def __init__(self, path):
        self.path = os.path.abspath(os.fspath(path))
        if not os.path.isdir(self.path):
            raise FileNotFoundError("%s: not a run folder" % path)
        self.name = os.path.basename(self.path.rstrip(os.sep))

    def __repr__(self):
        return "Run(%r)" % self.path

    def file(self, name):
        return os.path.join(self.path, name)

    # --- scene and summary -------------------------------------------------------------------
    @functools.cached_property
    def scene(self):
        with open(self.file("scene.toml"), "rb") as f:
            return tomllib.load(f)

    @functools.cached_property
    def summary(self):
        p = self.file("summary.json")
        if not os.path.exists(p):
            return {}
        with open(p) as f:
            return json.load(f)

    @property
    def result(self):
        return self.summary.get("result")

    @property
    def centrifuge(self):
        return self.summary.get("centrifuge")

    @property
    def wall_s(self):
        """The run's wall time [s] (summary.json totals), NaN without a summary."""
        return float(self.summary.get("totals", {}).get("wall_s", float("nan")))

    @property
    def footing_diameter(self):
        """D_f [m] (dem.footing.diameter), NaN without a footing."""
        d = self.scene.get("dem", {}).get("footing", {}).get("diameter")
        if d is None:
            d = self.summary.get("run", {}).get("footing_diameter_m", float("nan"))
        return float(d)

    @property
    def bond_strength(self):
        """sigma_c [Pa], the ball-ball bond's tensile strength: summary.json's centrifuge ground
        sigma_c_Pa, else a penetration stage's footing_rate bond_strength_Pa, else the scene
        (dem.ball_ball: model softbond by default, softbond.ten 0.45 MPa by default; pbond:
        pbond.ten unless "unbreakable"); None for a run without bonds or DEM."""
        v = (self.centrifuge or {}).get("ground", {}).get("sigma_c_Pa")
        if v is None:
            for st in reversed(self.summary.get("stages", [])):
                v = st.get("footing_rate", {}).get("bond_strength_Pa")
                if v is not None:
                    break
        if v is not None:
            return float(v)
        if "dem" not in self.scene:
            return None
        bb = self.scene["dem"].get("ball_ball", {})
        model = bb.get("model", DEFAULT_BALL_BALL_MODEL)
        if model == "softbond":
            return float(bb.get("softbond", {}).get("ten", 0.45e6))
        pb_ten = bb.get("pbond", {}).get("ten", 0.45e6)
        if model == "pbond" and pb_ten != "unbreakable":
            return float(pb_ten)
        return None

    @property
    def g_level(self):
        return float(self.scene.get("gravity", {}).get("level", self.summary.get("run", {}).get("g_level", 1)))

    # --- stage histories -----------------------------------------------------------------------
    def history_files(self):
        """[(n, stage, path)] of the stage histories history_<n>_<stage>.csv, by n."""
        out = []
        for f in os.listdir(self.path):
            m = HISTORY.match(f)
            if m:
                out.append((int(m.group(1)), m.group(2), self.file(f)))
        return sorted(out)

    @property
    def stages(self):
        """Stage names in run order: summary.json's stages, else the stage histories', else the
        scene's [[stage]] names."""
        s = [st["name"] for st in self.summary.get("stages", [])]
        if s:
            return s
        s = [name for _, name, _ in self.history_files()]
        if s:
            return s
        return [st.get("name", "") for st in self.scene.get("stage", [])]

    def _history_path(self, stage):
        files = self.history_files()
        if isinstance(stage, int):
            hit = [p for n, _, p in files if n == stage]
        else:
            hit = [p for _, name, p in files if name == stage]
        if not hit:
            raise KeyError("%s: no stage history for %r; histories: %s" % (
                self.path, stage, ", ".join("%d %s" % (n, s) for n, s, _ in files) or "none"))
        return hit[-1]

    def history(self, stage):
        """The history of a stage (name, or the number n of history_<n>_<stage>.csv) as a Table:
        h["dem.footing_fz_N"], h["footing_fz"], h["load"], h["settlement"], h["time"], h["step"].
        A stage name that ran more than once gives its last history."""
        return read_csv(self._history_path(stage))

    def penetration_stage(self):
        """The name of the last penetration stage that has a footing history, or None: the last
        stage with action "penetrate" (summary.json, else scene), else the last stage history
        with the DEM footing's columns and more than one row."""
        actions = [(st["name"], st.get("action")) for st in self.summary.get("stages", [])]
        if not actions:
            actions = [(st.get("name", ""), st.get("action")) for st in self.scene.get("stage", [])] \
                if os.path.exists(self.file("scene.toml")) else []
        have = {name for _, name, _ in self.history_files()}
        for name, action in reversed(actions):
            if action == "penetrate" and name in have:
                return name
        for n, name, path in reversed(self.history_files()):
            with open(path) as f:
                header = f.readline().strip().split(",")
                second, third = f.readline(), f.readline()
            if "dem.footing_disp_m" in header and "dem.footing_fz_N" in header and second.strip() and third.strip():
                return name
        return None

    def curve(self, stage=None):
        """(settlement [m], load [N]) of the last penetration stage (or of `stage`), in time order."""
        stage = stage if stage is not None else self.penetration_stage()
        if stage is None:
            raise KeyError("%s: no penetration stage history" % self.path)
        h = self.history(stage)
        if "settlement" not in h or "load" not in h:
            raise KeyError("%s: stage %r has no footing columns (dem.footing_disp_m, dem.footing_fz_N)" % (
                self.path, stage))
        return h["settlement"], h["load"]

    # --- node results ------------------------------------------------------------------------------
    def csv(self, name):
        return read_csv(self.file(name))

    def dem_history(self):
        """dem_history.csv (written when the scene asks for [dem.output])."""
        return self.csv("dem_history.csv")

    def fdm_history(self):
        """fdm_history.csv, or fem_history.csv of an fem_node run."""
        for n in ("fdm_history.csv", "fem_history.csv"):
            if os.path.exists(self.file(n)):
                return self.csv(n)
        raise FileNotFoundError("%s: no fdm_history.csv or fem_history.csv" % self.path)

    def profile(self, stage, kind="dem"):
        """The stress-depth profile a node wrote after `stage`: kind "dem" (block slabs) or "fdm"
        (zone layers). Columns include depth_m, szz_Pa, sxx_Pa, selfweight_szz_Pa."""
        kind = KINDS.get(kind)
        if kind is None:
            raise ValueError("profile kind must be 'dem' or 'fdm'")
        names = ["dem_profile_%s.csv" % stage] if kind == "dem" else \
            ["fdm_profile_%s.csv" % stage, "fem_profile_%s.csv" % stage]
        for n in names:
            if os.path.exists(self.file(n)):
                return self.csv(n)
        raise FileNotFoundError("%s: no %s" % (self.path, " or ".join(names)))

    def profiles(self, kind="dem"):
        """Stage names that have a `kind` profile, in run order where known."""
        kind = KINDS.get(kind)
        pre = ("dem_profile_",) if kind == "dem" else ("fdm_profile_", "fem_profile_")
        found = {f[len(p):-4] for f in os.listdir(self.path) for p in pre if f.startswith(p) and f.endswith(".csv")}
        order = [s for s in self.stages if s in found]
        return order + sorted(found - set(order))

    # --- HDF5 frames ------------------------------------------------------------------------------
    def results_file(self, kind):
        """The HDF5 results file of kind "dem" (dem.h5) or "fdm" (fdm.h5, else fem.h5)."""
        k = KINDS.get(kind)
        if k is None:
            raise ValueError("kind must be 'dem' or 'fdm' (or 'continuum'), not %r" % (kind,))
        for n in RESULTS[k]:
            if os.path.exists(self.file(n)):
                return self.file(n)
        raise FileNotFoundError("%s: no %s (the scene's [%s.output] writes it)" % (
            self.path, " or ".join(RESULTS[k]), "dem" if k == "dem" else "continuum"))

    def frames(self, kind):
        """[(index, step, time)] of the frames of dem.h5 / fdm.h5, in output order."""
        import h5py

        with h5py.File(self.results_file(kind), "r") as f:
            if "frames" not in f:
                return []
            return [FrameInfo(int(name), int(g.attrs["step"]), float(g.attrs["time"]))
                    for name, g in sorted(f["frames"].items())]

    def frame(self, kind, i=-1):
        """The arrays of frame i (an output index; negative counts from the end) as a Frame."""
        import h5py

        k = KINDS.get(kind)
        path = self.results_file(kind)
        with h5py.File(path, "r") as f:
            names = sorted(f["frames"]) if "frames" in f else []
            if not names:
                raise IndexError("%s: no frames" % path)
            if i < 0:
                i += len(names)
            key = "%06d" % i
            if key not in f["frames"]:
                raise IndexError("%s: no frame %d (frames 0..%d)" % (path, i, len(names) - 1))
            g = f["frames"][key]
            fr = Frame(k, i, int(g.attrs["step"]), float(g.attrs["time"]), path)
            if "datasets" in g.attrs:
                dsets = [_text(n) for n in np.atleast_1d(g.attrs["datasets"])]
            else:
                dsets = []
                g.visititems(lambda n, o: dsets.append(n) if isinstance(o, h5py.Dataset) else None)
            for n in dsets:
                fr[n] = g[n][()]
            short = collections.defaultdict(list)
            for n in dsets:
                group, _, leaf = n.rpartition("/")
                short[leaf].append((group, n))
            if k == "dem":
                for leaf, where in short.items():
                    for group, n in where:
                        if group == "particles":
                            fr.setdefault(leaf, fr[n])
                        elif leaf == "nodes":
                            fr.setdefault(group, fr[n])
            else:
                for leaf, where in short.items():
                    if len(where) == 1:
                        fr.setdefault(leaf, fr[where[0][1]])
                if "mesh" in f:
                    for n in ("node_coords", "zone_nodes"):
                        if n in f["mesh"]:
                            fr.setdefault(n, f["mesh"][n][()])
                if "nodes/position" not in fr and "node_coords" in fr and "nodes/displacement" in fr:
                    fr["position"] = fr["node_coords"] + fr["nodes/displacement"]
            return fr

    def attrs(self, kind):
        """The root attributes of dem.h5 / fdm.h5 (producer, run_id, units, ...) as text."""
        import h5py

        with h5py.File(self.results_file(kind), "r") as f:
            return {k: (_text(v) if isinstance(v, (bytes, str)) else v.item() if hasattr(v, "item") else v)
                    for k, v in f.attrs.items()}

    # --- checkpoints --------------------------------------------------------------------------------
    def checkpoints(self):
        """The checkpoint folders with a manifest.txt (docs/checkpoint-format.md), by step (a
        stage-end one after a mid-stage one of the same step). Each a dict: path, tag, stage (name),
        stage_index, step, in_stage (bool), end (bool), code_version, scene_hash, run_id, files
        ({name: bytes}), ok (the manifest's checksum matches and every file has its size; file
        contents are checked by the coordinator when it resumes, not here). Folders without a
        manifest (a checkpoint being written) are left out."""
        root = self.file("checkpoints")
        out = []
        if not os.path.isdir(root):
            return out
        for tag in os.listdir(root):
            man = os.path.join(root, tag, "manifest.txt")
            if os.path.isfile(man):
                out.append(read_manifest(man))
        return sorted(out, key=lambda c: (c["step"], c["end"], c["tag"]))


def fnv1a64(data):
    """FNV-1a 64 of bytes (the checkpoint manifest's checksum)."""
    h = 0xcbf29ce484222325
    for b in data:
        h = ((h ^ b) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
    return h


def read_manifest(path):
    """One checkpoint manifest.txt as the dict Run.checkpoints() lists."""
    with open(path, "rb") as f:
        raw = f.read()
    folder = os.path.dirname(os.path.abspath(path))
    c = {"path": folder, "tag": os.path.basename(folder), "stage": None, "stage_index": None, "step": None,
         "in_stage": None, "code_version": None, "scene_hash": None, "run_id": None, "files": {}, "ok": False}
    checksum = None
    for line in raw.decode("utf-8", "replace").splitlines():
        key, _, rest = line.partition(" ")
        if key == "stage":
            idx, _, name = rest.partition(" ")
            c["stage_index"], c["stage"] = int(idx), name
        elif key == "step":
            c["step"] = int(rest)
        elif key == "in_stage":
            c["in_stage"] = rest.strip() == "1"
        elif key in ("code_version", "scene_hash", "run_id", "tag"):
            c[key] = rest
        elif key == "file":
            size, _, rest2 = rest.partition(" ")
            _, _, name = rest2.partition(" ")
            c["files"][name] = int(size)
        elif key == "checksum":
            checksum = rest.strip()
    cut = raw.rfind(b"\nchecksum ")
    ok = checksum is not None and cut >= 0 and "%016x" % fnv1a64(raw[:cut + 1]) == checksum
    for name, size in c["files"].items():
        p = os.path.join(folder, name)
        ok = ok and os.path.isfile(p) and os.path.getsize(p) == size
    c["ok"] = ok
    c["end"] = c["in_stage"] is False if c["in_stage"] is not None else c["tag"].endswith("-end")
    if c["step"] is None:
        c["step"] = -1
    return c
