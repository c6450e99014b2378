#!/usr/bin/python3
"""The run-folder reader (launch/py/demfdm) against the values a synthetic run folder was written
with (make_run.py): scene, summary, stages, histories by raw and friendly names, the footing curve,
node histories, profiles, HDF5 frames, checkpoints, compare() and the optional pandas frames.

  /usr/bin/python3 tests/pyreader/check_reader.py LAUNCH_PY_DIR
"""
import math
import os
import subprocess
import sys
import tempfile
import types
import unittest

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
sys.path.insert(0, sys.argv.pop(1) if len(sys.argv) > 1 else os.path.join(HERE, "..", "..", "launch", "py"))

import demfdm  # noqa: E402
import make_run as mk  # noqa: E402


class Synthetic(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory(prefix="pyreader-")
        root = cls.tmp.name
        cls.a = demfdm.Run(mk.make_run(root, "run-a"))
        cls.b = demfdm.Run(mk.make_run(root, "run-b", scale=1.1, rows=33, with_result=False, h5=False, wall_s=20.0))
        cls.c = demfdm.Run(mk.make_run(root, "run-c", offset=0.05, first=4, h5=False))
        cls.d = demfdm.Run(mk.make_run(root, "run-d", ball_ball="", h5=False, summary_file=False))

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    # --- scene, summary, stages -------------------------------------------------------------------
    def test_scene_and_summary(self):
        a = self.a
        self.assertEqual(a.name, "run-a")
        self.assertEqual(a.scene["gravity"]["level"], mk.G)
        self.assertEqual(a.scene["dem"]["footing"]["diameter"], mk.D_F)
        self.assertEqual([s["name"] for s in a.scene["stage"]], ["generate", "servo", "bond", "gravity", "penetrate"])
        self.assertEqual(a.summary["totals"]["wall_s"], 12.5)
        self.assertEqual(a.wall_s, 12.5)
        self.assertEqual(a.result["peak_N"], 1.0)
        self.assertEqual(a.result["settlement_at_peak_m"], 20 * mk.DS)
        self.assertAlmostEqual(a.result["final_N"], 0.6, places=12)
        self.assertEqual(a.result["bonds_broken_shear"], 27)
        self.assertEqual(a.centrifuge["peak"]["load_prototype_N"], 1.0 * mk.G ** 2)
        self.assertEqual(a.footing_diameter, mk.D_F)
        self.assertEqual(a.g_level, mk.G)
        self.assertEqual(a.bond_strength, mk.SIGMA_C)
        self.assertIsNone(self.b.result)
        self.assertIsNone(self.b.centrifuge)
        self.assertEqual(self.b.bond_strength, mk.SIGMA_C)  # from the penetration's footing_rate

    def test_run_without_summary(self):
        d = self.d
        self.assertEqual(d.summary, {})
        self.assertIsNone(d.result)
        self.assertTrue(math.isnan(d.wall_s))
        self.assertEqual(d.stages, ["gravity", "penetrate"])  # from the history files
        self.assertEqual(d.penetration_stage(), "penetrate")   # from the scene's actions
        self.assertEqual(d.bond_strength, 0.45e6)              # scene: default softbond, default softbond.ten

    def test_stages(self):
        self.assertEqual(self.a.stages, ["generate", "servo", "bond", "gravity", "penetrate"])
        self.assertEqual([(n, s) for n, s, _ in self.a.history_files()], [(3, "gravity"), (4, "penetrate")])
        self.assertEqual(self.a.penetration_stage(), "penetrate")

    # --- histories ------------------------------------------------------------------------------------
    def test_history_raw_and_friendly(self):
        h = self.a.history("penetrate")
        cols = mk.penetrate_columns()
        self.assertEqual(h.columns, list(cols))
        self.assertEqual(h.rows, 41)
        for name, values in cols.items():
            np.testing.assert_array_equal(h[name], np.asarray(values, float), err_msg=name)
        # friendly names: the same arrays
        self.assertIs(h["load"], h["dem.footing_fz_N"])
        self.assertIs(h["settlement"], h["dem.footing_disp_m"])
        self.assertIs(h["footing_fz"], h["dem.footing_fz_N"])
        self.assertIs(h["dem.footing_fz"], h["dem.footing_fz_N"])
        self.assertIs(h["time"], h["dem.time_s"])              # the DEM's, before the continuum's
        self.assertIs(h["continuum.time"], h["continuum.time_s"])
        self.assertIs(h["ratio"], h["dem.ratio"])
        self.assertIs(h["iface_fz"], h["continuum.iface_fz_N"])
        self.assertIs(h["bond_failures"], h["dem.bond_failures"])
        self.assertEqual(h.units["load"], "N")
        self.assertEqual(h.units["settlement"], "m")
        self.assertEqual(h.units["time"], "s")
        self.assertEqual(h.units["bond_failures"], "")
        self.assertEqual(h.raw["time"], "dem.time_s")
        self.assertEqual(h["load"][20], 1.0)
        self.assertEqual(h["settlement"][40], 40 * mk.DS)
        # by history number too, and the same file
        self.assertEqual(self.a.history(4).path, h.path)
        with self.assertRaises(KeyError):
            self.a.history("ucs")

    def test_curve(self):
        s, f = self.a.curve()
        np.testing.assert_array_equal(s, np.arange(41) * mk.DS)
        np.testing.assert_allclose(f, mk.load_a(s), rtol=0, atol=1e-15)
        self.assertEqual(float(f.max()), 1.0)
        self.assertEqual(int(np.argmax(f)), 20)
        s, f = self.b.curve()
        self.assertEqual(len(s), 33)
        np.testing.assert_allclose(f, 1.1 * mk.load_a(s), rtol=1e-15, atol=1e-15)

    def test_node_histories(self):
        h = self.a.dem_history()
        self.assertEqual(h.columns, ["step_unit", "time_s", "ratio_unit", "kinetic_J", "footing_fz_N",
                                     "footing_disp_m", "facet_fz_N"])
        np.testing.assert_array_equal(h["step"], [0, 1, 2])
        np.testing.assert_array_equal(h["time"], [1e-5, 2e-5, 3e-5])
        np.testing.assert_array_equal(h["load"], [0, 0.1, 0.2])
        np.testing.assert_array_equal(h["settlement"], [0, 1e-6, 2e-6])
        self.assertEqual(h.units["step"], "1")
        self.assertEqual(h.units["kinetic"], "J")
        f = self.a.fdm_history()
        np.testing.assert_array_equal(f["base_fz"], [5.0, 5.1])
        np.testing.assert_array_equal(f["ratio_avg"], [0.01, 0.005])
        self.assertIs(f["load"], f["punch_fz_N"])  # no DEM footing: the punch's

    def test_profiles(self):
        p = self.a.profile("gravity", "dem")
        np.testing.assert_array_equal(p["depth"], [1e-4, 3e-4, 5e-4])
        np.testing.assert_array_equal(p["szz_Pa"], [-60.0, -180.0, -300.0])
        np.testing.assert_array_equal(p["balls"], [10, 12, 11])
        np.testing.assert_array_equal(p["rho_b"], [1272.0] * 3)
        self.assertEqual(p.units["rho_b"], "kg_m3")
        self.assertEqual(p.units["balls"], "1")
        q = self.a.profile("gravity", "fdm")
        np.testing.assert_array_equal(q["szz"], [-156.0, -468.0])
        np.testing.assert_array_equal(q["rho"], [1272.0, 1272.0])
        self.assertEqual(self.a.profiles("dem"), ["gravity"])
        with self.assertRaises(FileNotFoundError):
            self.a.profile("penetrate", "dem")
        with self.assertRaises(ValueError):
            self.a.profile("gravity", "xyz")

    def test_csv_with_quoted_text(self):
        t = self.a.csv("specimen_stages.csv")
        self.assertEqual(list(t["what"]), ["generated 238 balls, bonded (Z = 6.82)", "servo to sigma_v 2495.664 Pa"])
        np.testing.assert_array_equal(t["szz"], [0.0, -2495.664])
        np.testing.assert_array_equal(t["balls"], [238, 238])

    def test_split_name(self):
        self.assertEqual(demfdm.split_name("dem.footing_fz_N"), ("dem", "footing_fz", "N"))
        self.assertEqual(demfdm.split_name("rho_b_kg_m3"), ("", "rho_b", "kg_m3"))
        self.assertEqual(demfdm.split_name("step_unit"), ("", "step", "1"))
        self.assertEqual(demfdm.split_name("balls_1"), ("", "balls", "1"))
        self.assertEqual(demfdm.split_name("speed_m_s"), ("", "speed", "m_s"))
        self.assertEqual(demfdm.split_name("k_e_N_m"), ("", "k_e", "N_m"))
        self.assertEqual(demfdm.split_name("continuum.ratio"), ("continuum", "ratio", ""))
        self.assertEqual(demfdm.split_name("step"), ("", "step", ""))
        self.assertEqual(demfdm.friendly_name("dem.footing_disp_m"), "footing_disp")

    # --- HDF5 frames ------------------------------------------------------------------------------------
    def test_dem_frames(self):
        fr = self.a.frames("dem")
        self.assertEqual([tuple(x) for x in fr], [(0, 0, 1.0e-5), (1, 250, 2.5e-5)])
        self.assertEqual(fr[1].step, 250)
        last = self.a.frame("dem", -1)
        self.assertEqual((last.index, last.step, last.time), (1, 250, 2.5e-5))
        ref = mk.DEM_FRAMES[1]
        for k, v in ref["particles"].items():
            np.testing.assert_array_equal(last[k], v, err_msg=k)
            np.testing.assert_array_equal(last["particles/" + k], v, err_msg=k)
        np.testing.assert_array_equal(last["bonds"], ref["bonds"]["nodes"])
        np.testing.assert_array_equal(last["bonds/state"], [1, 3, 4])
        np.testing.assert_array_equal(last["bonds/force"], ref["bonds"]["force"])
        self.assertEqual(last["position"].shape, (4, 3))
        self.assertEqual(last["id"].dtype, np.int64)
        self.assertEqual([demfdm.BOND_STATES[s] for s in last["bonds/state"]], ["intact", "broken_tension", "broken_shear"])
        first = self.a.frame("dem", 0)
        self.assertEqual(first["radius"].tolist(), [1e-4, 2e-4, 1.5e-4])
        with self.assertRaises(IndexError):
            self.a.frame("dem", 2)
        self.assertEqual(self.a.attrs("dem")["producer"], "dem_node")
        self.assertEqual(self.a.attrs("dem")["format_version"], 1)

    def test_fdm_frames(self):
        fr = self.a.frames("fdm")
        self.assertEqual([tuple(x) for x in fr], [(0, 120, 1.2e-6), (1, 300, 3.0e-6)])
        self.assertEqual(self.a.frames("continuum"), fr)
        for i in (0, 1):  # frame 1 has no "datasets" attribute: read by walking the group
            f = self.a.frame("fdm", i)
            ref = mk.FDM_FRAMES[i]
            np.testing.assert_array_equal(f["stress"], ref["zones"]["stress"])
            np.testing.assert_array_equal(f["zones/stress"], ref["zones"]["stress"])
            np.testing.assert_array_equal(f["displacement"], ref["nodes"]["displacement"])
            np.testing.assert_array_equal(f["plastic"], ref["zones"]["plastic"])
            np.testing.assert_array_equal(f["node_coords"], mk.NODE_COORDS)
            np.testing.assert_array_equal(f["zone_nodes"], np.arange(8).reshape(1, 8))
            np.testing.assert_allclose(f["position"], mk.NODE_COORDS + ref["nodes"]["displacement"], rtol=0, atol=0)
            self.assertEqual(f["velocity"].shape, (8, 3))
        self.assertEqual(self.a.frame("fdm", 1).step, 300)
        with self.assertRaises(FileNotFoundError):
            self.b.frames("dem")
        with self.assertRaises(ValueError):
            self.a.frames("particles")

    # --- checkpoints ------------------------------------------------------------------------------------
    def test_fnv_vectors(self):
        # Published FNV-1a 64 test vectors.
        self.assertEqual(demfdm.run.fnv1a64(b""), 0xcbf29ce484222325)
        self.assertEqual(demfdm.run.fnv1a64(b"a"), 0xaf63dc4c8601ec8c)
        self.assertEqual(demfdm.run.fnv1a64(b"foobar"), 0x85944171f73967e8)

    def test_checkpoints(self):
        cps = self.a.checkpoints()
        self.assertEqual([c["tag"] for c in cps], ["bond-2-end", "gravity-120", "gravity-120-end", "penetrate-300-end"])
        self.assertEqual([c["step"] for c in cps], [2, 120, 120, 300])
        self.assertEqual([c["stage"] for c in cps], ["bond", "gravity", "gravity", "penetrate"])
        self.assertEqual([c["stage_index"] for c in cps], [2, 3, 3, 4])
        self.assertEqual([c["in_stage"] for c in cps], [False, True, False, False])
        self.assertEqual([c["end"] for c in cps], [True, False, True, True])
        # bond-2-end: wrong manifest checksum; penetrate-300-end: a file with another size
        self.assertEqual([c["ok"] for c in cps], [False, True, True, False])
        g = cps[2]
        self.assertEqual(g["files"], {"coordinator.state": 37, "dem.state": 220})
        self.assertEqual(g["scene_hash"], "0123456789abcdef")
        self.assertEqual(g["run_id"], "42")
        self.assertEqual(g["code_version"], "demfdm 0.1.0 test")
        self.assertEqual(g["path"], os.path.join(self.a.path, "checkpoints", "gravity-120-end"))

    # --- compare -----------------------------------------------------------------------------------------
    def test_compare_values(self):
        rows = demfdm.compare([self.a, self.b.path, self.c], points=161)
        self.assertEqual([r["run"] for r in rows], ["run-a", "run-b", "run-c"])
        a, b, c = rows
        self.assertEqual((a["peak_N"], a["settlement_at_peak_m"], a["k_e_N_m"], a["wall_s"]), (1.0, 20 * mk.DS, 2e4, 12.5))
        self.assertAlmostEqual(a["final_N"], 0.6, places=12)
        self.assertEqual((a["curve_max_diff"], a["curve_rms_diff"]), (0.0, 0.0))
        # run B has no result in its summary: recomputed from its curve
        self.assertAlmostEqual(b["peak_N"], 1.1, places=12)
        self.assertAlmostEqual(b["settlement_at_peak_m"], 20 * mk.DS, places=18)
        self.assertAlmostEqual(b["final_N"], 1.1 * (1.0 - 0.4 * 12 / 20), places=12)
        self.assertAlmostEqual(b["k_e_N_m"] / 2.2e4, 1.0, places=10)
        self.assertEqual(b["wall_s"], 20.0)
        # B = 1.1 A on [0, 8e-5]: |B - A| = 0.1 A; the 161-point grid holds the peak at 5e-5.
        self.assertEqual((b["grid_from_m"], b["grid_to_m"]), (0.0, 32 * mk.DS))
        self.assertAlmostEqual(b["curve_max_diff"], 0.1, places=12)
        grid = np.linspace(0, 32 * mk.DS, 161)
        self.assertAlmostEqual(b["curve_rms_diff"], float(np.sqrt(np.mean((0.1 * mk.load_a(grid)) ** 2))), places=12)
        self.assertLess(b["curve_rms_diff"], b["curve_max_diff"])
        # C = A + 0.05 N on [1e-5, 1e-4]
        self.assertAlmostEqual(c["grid_from_m"], 4 * mk.DS, places=18)
        self.assertEqual(c["grid_to_m"], 40 * mk.DS)
        self.assertAlmostEqual(c["curve_max_diff"], 0.05, places=12)
        self.assertAlmostEqual(c["curve_rms_diff"], 0.05, places=12)
        self.assertAlmostEqual(c["peak_N"], 1.05, places=12)  # from its summary's result

    def test_compare_normalises_by_first_peak(self):
        b, a = demfdm.compare([self.b, self.a], points=161)
        self.assertAlmostEqual(a["curve_max_diff"], 0.1 / 1.1, places=12)

    def test_compare_measures_and_labels(self):
        rows = demfdm.compare([self.a, self.b], measure=("peak_N", "bonds_broken_shear",
                                                        ("rows", lambda r: r.history("penetrate").rows)),
                              labels=["A", "B"])
        self.assertEqual(list(rows[0]), ["run", "path", "peak_N", "bonds_broken_shear", "rows", "curve_max_diff",
                                         "curve_rms_diff", "grid_from_m", "grid_to_m"])
        self.assertEqual([r["run"] for r in rows], ["A", "B"])
        self.assertEqual(rows[0]["bonds_broken_shear"], 27)
        self.assertTrue(math.isnan(rows[1]["bonds_broken_shear"]))  # no result, not computable
        self.assertEqual([r["rows"] for r in rows], [41, 33])
        text = demfdm.format_table(rows)
        self.assertIn("bonds_broken_shear", text.splitlines()[0])
        self.assertEqual(len(text.splitlines()), 3)
        md = demfdm.format_table(rows, markdown=True).splitlines()
        self.assertEqual(md[1].count("---"), len(rows[0]) - 1)  # every column but path
        self.assertTrue(md[2].startswith("| A | 1 | 27 | 41 | 0 | 0 |"))

    def test_command_line(self):
        env = dict(os.environ, PYTHONPATH=os.path.dirname(os.path.dirname(demfdm.__file__)))
        p = subprocess.run([sys.executable, "-m", "demfdm", self.a.path, self.c.path, "--markdown"], env=env,
                           capture_output=True, text=True, timeout=60)
        self.assertEqual(p.returncode, 0, p.stderr)
        lines = p.stdout.splitlines()
        self.assertTrue(lines[0].startswith("| run | peak_N | settlement_at_peak_m | k_e_N_m | final_N | wall_s |"))
        self.assertTrue(lines[3].startswith("| run-c | 1.05 | 5e-05 | 2e+04 | 0.65 | 12.5 | 0.05 | 0.05 |"), lines[3])
        self.assertEqual(lines[-1], "run-c: %s" % self.c.path)
        p = subprocess.run([sys.executable, "-m", "demfdm", os.path.join(self.tmp.name, "missing")], env=env,
                           capture_output=True, text=True, timeout=60)
        self.assertEqual((p.returncode, p.stdout), (1, ""))
        self.assertIn("not a run folder", p.stderr)

    def test_elastic_stiffness_rule(self):
        s = np.arange(10) * 1e-6
        f = 3e4 * s
        f[0] = 0
        failures = np.array([0, 0, 0, 0, 0, 0, 1, 1, 2, 3])
        self.assertAlmostEqual(demfdm.elastic_stiffness(s, f, failures), 3e4, delta=1e-6)  # rows 1..5
        self.assertTrue(math.isnan(demfdm.elastic_stiffness(s, f, np.array([0, 0, 0, 1, 1, 1, 2, 2, 2, 2]))))

    # --- pandas (optional) --------------------------------------------------------------------------------
    def test_pandas_frames(self):
        h = self.a.history("penetrate")
        friendly = ["step", "continuum.time", "time", "iface_fz", "continuum.ratio", "bond_failures", "footing_disp",
                    "footing_fz", "ratio"]
        if demfdm.HAVE_PANDAS:
            df = h.to_pandas()
            self.assertEqual(list(df.columns), h.columns)
            self.assertEqual(float(df["dem.footing_fz_N"].max()), 1.0)
            self.assertEqual(list(h.to_pandas(friendly=True).columns), friendly)
            return
        with self.assertRaises(ImportError) as cm:
            h.to_pandas()
        self.assertIn("python3-pandas", str(cm.exception))
        # The frame built with a stand-in pandas module: columns and data handed over.
        calls = []
        stub = types.ModuleType("pandas")
        stub.DataFrame = lambda data, columns: calls.append((data, columns)) or "frame"
        sys.modules["pandas"] = stub
        try:
            self.assertEqual(h.to_pandas(), "frame")
            self.assertEqual(h.to_pandas(friendly=True), "frame")
        finally:
            del sys.modules["pandas"]
        (raw_data, raw_cols), (fr_data, fr_cols) = calls
        self.assertEqual(raw_cols, h.columns)
        self.assertIs(raw_data["dem.footing_fz_N"], h["dem.footing_fz_N"])
        self.assertEqual(fr_cols, friendly)
        self.assertIs(fr_data["footing_fz"], h["dem.footing_fz_N"])
        self.assertIs(fr_data["continuum.time"], h["continuum.time_s"])

    def test_to_numpy(self):
        arr, names = self.a.history("penetrate").to_numpy()
        self.assertEqual(arr.shape, (41, 9))
        self.assertEqual(names[7], "dem.footing_fz_N")
        self.assertEqual(arr[20, 7], 1.0)


if __name__ == "__main__":
    unittest.main(verbosity=2)
