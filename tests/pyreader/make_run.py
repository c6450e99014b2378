"""Synthetic run folders for the reader tests, in the layout the simulator writes (README "Running
scenes", common/io/include/demfdm/io/results_output.hpp, h5_frames.hpp, docs/checkpoint-format.md),
with values known in closed form.

Footing curve of run A (history_4_penetrate.csv): 41 rows, settlement s_i = i * 2.5e-6 m; load
k s with k = 2e4 N/m up to the peak 1.0 N at i = 20 (s = 5e-5 m), then linearly down to 0.6 N at
i = 40 (s = 1e-4 m); dem.bond_failures 0 up to i = 10, then i - 10, so k_e = 2e4 N/m exactly.
"""
import json
import os

import numpy as np

K = 2.0e4
DS = 2.5e-6
D_F = 0.002
SIGMA_C = 5.0e5
G = 50


def load_a(s):
    """Run A's load [N] at settlement s [m] (the closed form behind the rows)."""
    s = np.asarray(s, float)
    return np.where(s <= 20 * DS, K * s, 1.0 - 0.4 * (s - 20 * DS) / (20 * DS))


def write_csv(path, names, cols):
    with open(path, "w") as f:
        f.write(",".join(names) + "\n")
        for row in zip(*cols):
            f.write(",".join(repr(float(v)) for v in row) + "\n")


SCENE = """# synthetic run for tests/pyreader
[run]
seed = %(seed)d

[gravity]
level = %(g)d

[dem]
[dem.footing]
diameter = %(d_f)r
%(ball_ball)s
[continuum]
[continuum.mesh]
nx = 1

[[stage]]
name = "generate"
action = "generate"

[[stage]]
name = "servo"
action = "servo"

[[stage]]
name = "bond"
action = "bond"

[[stage]]
name = "gravity"
action = "couple"

[[stage]]
name = "penetrate"
action = "penetrate"
"""


def penetrate_columns(scale=1.0, offset=0.0, rows=41, first=0):
    i = np.arange(first, rows)
    s = i * DS
    f = scale * load_a(s) + offset
    f[i == 0] = 0.0
    step = 400 + i
    cols = {
        "step": step,
        "continuum.time_s": 1e-8 * i,
        "dem.time_s": 2e-5 + 1e-8 * i,
        "continuum.iface_fz_N": -f,
        "continuum.ratio": 1e-3 + 0 * i,
        "dem.bond_failures": np.maximum(i - 10, 0),
        "dem.footing_disp_m": s,
        "dem.footing_fz_N": f,
        "dem.ratio": 2e-3 + 0 * i,
    }
    return cols


def make_run(root, name="run-a", scale=1.0, offset=0.0, rows=41, first=0, with_result=True, h5=True,
             ball_ball='[dem.ball_ball.softbond]\nten = %r\n' % SIGMA_C, wall_s=12.5, summary_file=True):
    """Writes a run folder and returns its path. Run A: the defaults."""
    run = os.path.join(root, name)
    os.makedirs(run)
    with open(os.path.join(run, "scene.toml"), "w") as f:
        f.write(SCENE % {"seed": 7, "g": G, "d_f": D_F, "ball_ball": ball_ball})
    # Stage histories: a short gravity one and the penetration.
    write_csv(os.path.join(run, "history_3_gravity.csv"), ["step", "continuum.time_s", "dem.time_s", "dem.ratio"],
              [np.arange(3, 6), [1e-8, 2e-8, 3e-8], [1e-5, 1.1e-5, 1.2e-5], [0.5, 0.1, 0.01]])
    cols = penetrate_columns(scale, offset, rows, first)
    write_csv(os.path.join(run, "history_4_penetrate.csv"), list(cols), list(cols.values()))
    s, f = cols["dem.footing_disp_m"], cols["dem.footing_fz_N"]
    ip = int(np.argmax(f))
    stages = [{"name": n, "action": a, "first_step": i, "last_step": i, "steps": 1, "wall_s": 0.1, "ended_by": "steps"}
              for i, (n, a) in enumerate([("generate", "generate"), ("servo", "servo"), ("bond", "bond")])]
    stages.append({"name": "gravity", "action": "couple", "first_step": 3, "last_step": 120, "steps": 118,
                   "wall_s": 1.0, "ended_by": "done"})
    stages.append({"name": "penetrate", "action": "penetrate", "first_step": 121, "last_step": 300, "steps": 180,
                   "wall_s": 11.1, "ended_by": "done",
                   "footing_rate": {"speed_m_s": 0.1, "bond_strength_Pa": SIGMA_C}})
    summary = {"scene": "scenes/synthetic.toml", "stages": stages, "totals": {"steps": 301, "wall_s": wall_s},
               "run": {"seed": 7, "g_level": G, "footing_diameter_m": D_F}}
    if with_result:
        summary["result"] = {"stage": "penetrate", "footing_diameter_m": D_F, "peak_N": float(f[ip]),
                             "settlement_at_peak_m": float(s[ip]), "final_N": float(f[-1]),
                             "final_settlement_m": float(s[-1]), "k_e_N_m": K * scale, "elastic_rows": 10,
                             "bonds_broken_tension": 3, "bonds_broken_shear": 27, "target_reached": True}
        summary["centrifuge"] = {"g_level": G, "scale_factors": {"length": G, "force": G * G},
                                 "ground": {"sigma_c_Pa": SIGMA_C},
                                 "peak": {"load_model_N": float(f[ip]), "load_prototype_N": float(f[ip]) * G * G}}
    with open(os.path.join(run, "summary.json"), "w") as fh:
        json.dump(summary, fh, indent=1)
    # Node outputs.
    write_csv(os.path.join(run, "dem_history.csv"),
              ["step_unit", "time_s", "ratio_unit", "kinetic_J", "footing_fz_N", "footing_disp_m", "facet_fz_N"],
              [[0, 1, 2], [1e-5, 2e-5, 3e-5], [0.5, 0.25, 0.125], [1e-9, 2e-9, 3e-9], [0, 0.1, 0.2], [0, 1e-6, 2e-6],
               [0.3, 0.3, 0.3]])
    write_csv(os.path.join(run, "fdm_history.csv"),
              ["step_unit", "time_s", "ratio_avg_unit", "kinetic_J", "base_fz_N", "punch_fz_N", "punch_disp_m"],
              [[3, 4], [1e-8, 2e-8], [0.01, 0.005], [1e-12, 2e-12], [5.0, 5.1], [0, 0], [0, 0]])
    write_csv(os.path.join(run, "dem_profile_gravity.csv"),
              ["depth_m", "depth_top_m", "depth_bottom_m", "szz_Pa", "sxx_Pa", "syy_Pa", "balls_1",
               "selfweight_szz_Pa", "rho_b_kg_m3", "d_max_m"],
              [[1e-4, 3e-4, 5e-4], [0, 2e-4, 4e-4], [2e-4, 4e-4, 6e-4], [-60.0, -180.0, -300.0], [-30.0, -90.0, -150.0],
               [-31.0, -91.0, -151.0], [10, 12, 11], [-62.4, -187.2, -312.0], [1272.0] * 3, [2.7e-4] * 3])
    write_csv(os.path.join(run, "fdm_profile_gravity.csv"),
              ["depth_m", "szz_Pa", "sxx_Pa", "zones_1", "selfweight_szz_Pa", "rho_kg_m3"],
              [[2.5e-4, 7.5e-4], [-156.0, -468.0], [-78.0, -234.0], [4, 4], [-156.0, -468.0], [1272.0, 1272.0]])
    with open(os.path.join(run, "specimen_stages.csv"), "w") as fh:
        fh.write('balls_unit,porosity_unit,szz_Pa,what\n')
        fh.write('238,0.52,0,"generated 238 balls, bonded (Z = 6.82)"\n')
        fh.write('238,0.5204,-2495.664,"servo to sigma_v 2495.664 Pa"\n')
    if h5:
        write_dem_h5(os.path.join(run, "dem.h5"))
        write_fdm_h5(os.path.join(run, "fdm.h5"))
    write_checkpoints(run)
    if not summary_file:  # a crashed or running run: no summary.json yet
        os.remove(os.path.join(run, "summary.json"))
    return run


# --- HDF5 results in the documented layout -------------------------------------------------------
DEM_FRAMES = [
    {"step": 0, "time": 1.0e-5,
     "particles": {"position": np.array([[0, 0, 0], [1e-3, 0, 0], [0, 1e-3, 0]], float),
                   "radius": np.array([1e-4, 2e-4, 1.5e-4]),
                   "velocity": np.zeros((3, 3)),
                   "id": np.array([10, 11, 12], np.int64)},
     "bonds": {"nodes": np.array([[0, 1], [1, 2]], np.int32), "state": np.array([1, 1], np.uint8),
               "force": np.array([[0, 0, 1.0], [0, 0, 2.0]])}},
    {"step": 250, "time": 2.5e-5,
     "particles": {"position": np.array([[0, 0, -1e-6], [1e-3, 0, 0], [0, 1e-3, 0], [1e-3, 1e-3, 0]], float),
                   "radius": np.array([1e-4, 2e-4, 1.5e-4, 1.2e-4]),
                   "velocity": np.array([[0, 0, -0.1], [0, 0, 0], [0, 0, 0], [0.2, 0, 0]]),
                   "id": np.array([10, 11, 12, 13], np.int64)},
     "bonds": {"nodes": np.array([[0, 1], [1, 2], [2, 3]], np.int32), "state": np.array([1, 3, 4], np.uint8),
               "force": np.array([[0, 0, 1.5], [0, 0, 0], [0, 0, 0]])}},
]
NODE_COORDS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]],
                       float) * 1e-3
FDM_FRAMES = [
    {"step": 120, "time": 1.2e-6, "datasets_attr": True,
     "nodes": {"displacement": np.tile([0, 0, -1e-7], (8, 1)), "velocity": np.zeros((8, 3))},
     "zones": {"stress": np.array([[-100.0, -100.0, -300.0, 1.0, 2.0, 3.0]]), "plastic": np.array([0], np.uint8)}},
    {"step": 300, "time": 3.0e-6, "datasets_attr": False,
     "nodes": {"displacement": np.tile([0, 0, -2e-7], (8, 1)), "velocity": np.zeros((8, 3))},
     "zones": {"stress": np.array([[-110.0, -110.0, -350.0, 0.0, 0.0, 0.0]]), "plastic": np.array([1], np.uint8)}},
]


def _root_attrs(f, producer):
    f.attrs["format"] = np.bytes_("demfdm-results")
    f.attrs["format_version"] = np.int64(1)
    f.attrs["producer"] = np.bytes_(producer)
    f.attrs["run_id"] = np.bytes_("42")
    f.attrs["length_unit"] = np.bytes_("m")
    f.attrs["time_unit"] = np.bytes_("s")


def _frame(f, i, fr, groups):
    g = f.create_group("frames/%06d" % i)
    g.attrs["time"] = np.float64(fr["time"])
    g.attrs["step"] = np.int64(fr["step"])
    names = []
    for grp in groups:
        for k, v in fr[grp].items():
            g.create_dataset("%s/%s" % (grp, k), data=v)
            names.append("%s/%s" % (grp, k))
    if fr.get("datasets_attr", True):
        g.attrs["datasets"] = np.array([n.encode() for n in names], dtype="S%d" % max(len(n) for n in names))


def write_dem_h5(path):
    import h5py

    with h5py.File(path, "w") as f:
        _root_attrs(f, "dem_node")
        f.create_dataset("xdmf/vertex_index", data=np.arange(4, dtype=np.int32))
        for i, fr in enumerate(DEM_FRAMES):
            _frame(f, i, fr, ("particles", "bonds"))


def write_fdm_h5(path):
    import h5py

    with h5py.File(path, "w") as f:
        _root_attrs(f, "fdm_node")
        f.attrs["stress_sign"] = np.bytes_("tension positive")
        f.create_dataset("mesh/node_coords", data=NODE_COORDS)
        f.create_dataset("mesh/zone_nodes", data=np.arange(8, dtype=np.int64).reshape(1, 8))
        for i, fr in enumerate(FDM_FRAMES):
            _frame(f, i, fr, ("nodes", "zones"))


# --- checkpoints ---------------------------------------------------------------------------------
def fnv1a64(data):
    h = 0xcbf29ce484222325
    for b in data:
        h = ((h ^ b) * 0x100000001b3) & 0xFFFFFFFFFFFFFFFF
    return h


# (tag, stage index, stage, step, in_stage, corrupt): written in this (unsorted) order.
CHECKPOINTS = [
    ("penetrate-300-end", 4, "penetrate", 300, False, "size"),
    ("gravity-120-end", 3, "gravity", 120, False, None),
    ("gravity-120", 3, "gravity", 120, True, None),
    ("bond-2-end", 2, "bond", 2, False, "checksum"),
]


def write_checkpoints(run):
    root = os.path.join(run, "checkpoints")
    for tag, idx, stage, step, in_stage, corrupt in CHECKPOINTS:
        d = os.path.join(root, tag)
        os.makedirs(d)
        files = {"dem.state": b"D" * (100 + step), "coordinator.state": b"C" * 37}
        for n, data in files.items():
            with open(os.path.join(d, n), "wb") as fh:
                fh.write(data)
        text = "demfdm checkpoint 1\ncode_version demfdm 0.1.0 test\nscene_hash 0123456789abcdef\nrun_id 42\n"
        text += "tag %s\nstage %d %s\nstep %d\nin_stage %d\n" % (tag, idx, stage, step, 1 if in_stage else 0)
        for n in sorted(files):
            text += "file %d %016x %s\n" % (len(files[n]), fnv1a64(files[n]), n)
        body = text.encode()
        checksum = fnv1a64(body) ^ (1 if corrupt == "checksum" else 0)
        with open(os.path.join(d, "manifest.txt"), "wb") as fh:
            fh.write(body + b"checksum %016x\n" % checksum)
        if corrupt == "size":
            with open(os.path.join(d, "dem.state"), "ab") as fh:
                fh.write(b"extra")
    # A checkpoint being written: no manifest yet, so not listed.
    os.makedirs(os.path.join(root, "penetrate-350"))
    with open(os.path.join(root, "penetrate-350", "dem.state"), "wb") as fh:
        fh.write(b"partial")
