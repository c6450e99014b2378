#!/usr/bin/python3
"""The reader on a real run folder of scenes/footing_small.toml (default /tmp/ck/e, or the
folder in DEMFDM_PYREADER_RUN): what it reads must agree with what the simulator wrote elsewhere
(summary.json's result against the curve, the bond states of the last frame against the broken
bond counts, the checkpoint manifests' checksums, frames against the HDF5 file). Exit 77 (CTest:
skipped) when the folder does not exist.

  /usr/bin/python3 tests/pyreader/check_real_run.py LAUNCH_PY_DIR
"""
import math
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
LAUNCH_PY = os.path.abspath(sys.argv.pop(1) if len(sys.argv) > 1 else os.path.join(HERE, "..", "..", "launch", "py"))
sys.path.insert(0, LAUNCH_PY)
RUN = os.environ.get("DEMFDM_PYREADER_RUN", "/tmp/ck/e")

import demfdm  # noqa: E402


class RealRun(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.rr = demfdm.Run(RUN)

    def test_result_agrees_with_the_curve(self):
        r = self.rr
        res = r.result
        self.assertIsNotNone(res, "summary.json has no result")
        stage = r.penetration_stage()
        self.assertEqual(stage, res["stage"])
        self.assertIn(stage, r.stages)
        s, f = r.curve()
        h = r.history(stage)
        self.assertEqual(len(s), h.rows)
        self.assertIs(h["load"], h["dem.footing_fz_N"])
        self.assertIs(h["settlement"], h["dem.footing_disp_m"])
        ip = int(np.argmax(f))
        self.assertEqual(float(f[ip]), res["peak_N"])
        self.assertEqual(float(s[ip]), res["settlement_at_peak_m"])
        self.assertEqual(float(f[-1]), res["final_N"])
        self.assertEqual(float(s[-1]), res["final_settlement_m"])
        k_e = demfdm.comparison.curve_values(r)["k_e_N_m"]
        self.assertAlmostEqual(k_e / res["k_e_N_m"], 1.0, places=9)
        self.assertEqual(r.footing_diameter, res["footing_diameter_m"])
        if r.centrifuge:
            self.assertAlmostEqual(r.centrifuge["peak"]["load_model_N"] / res["peak_N"], 1.0, places=9)

    def test_frames(self):
        import h5py

        r = self.rr
        for kind, name in (("dem", "dem.h5"), ("fdm", "fdm.h5")):
            if not os.path.exists(r.file(name)):
                continue
            fr = r.frames(kind)
            with h5py.File(r.file(name), "r") as f:
                self.assertEqual(len(fr), len(f["frames"]))
            self.assertEqual([x.index for x in fr], list(range(len(fr))))
            times = np.array([x.time for x in fr])
            self.assertTrue(np.all(np.diff(times) > 0), "%s frame times must increase" % kind)
            last = r.frame(kind, -1)
            self.assertEqual((last.step, last.time), (fr[-1].step, fr[-1].time))
            if kind == "dem":
                n = len(last["radius"])
                self.assertEqual(last["position"].shape, (n, 3))
                self.assertTrue(np.all(last["radius"] > 0))
                self.assertTrue(np.all((last["bonds"] >= 0) & (last["bonds"] < n)))
                counts = np.bincount(last["bonds/state"], minlength=5)
                if r.result and r.result.get("stage") == r.stages[-1]:
                    self.assertEqual(counts[3], r.result["bonds_broken_tension"])
                    self.assertEqual(counts[4], r.result["bonds_broken_shear"])
            else:
                nz = len(last["zone_nodes"])
                self.assertEqual(last["stress"].shape, (nz, 6))
                np.testing.assert_array_equal(last["position"], last["node_coords"] + last["displacement"])

    def test_checkpoints(self):
        cps = self.rr.checkpoints()
        if not cps:
            self.skipTest("no checkpoints")
        self.assertTrue(all(c["ok"] for c in cps), [c["tag"] for c in cps if not c["ok"]])
        for c in cps:
            self.assertEqual(c["tag"], "%s-%d%s" % (c["stage"], c["step"], "-end" if c["end"] else ""))
        ends = {c["stage"]: c["step"] for c in cps if c["end"]}
        for st in self.rr.summary.get("stages", []):
            if st["name"] in ends:
                self.assertEqual(ends[st["name"]], st["last_step"], st["name"])

    def test_profiles_and_histories(self):
        r = self.rr
        for kind in ("dem", "fdm"):
            for st in r.profiles(kind):
                p = r.profile(st, kind)
                self.assertTrue(np.all(np.diff(p["depth"]) > 0))
                self.assertTrue(np.all(p["szz"] < 0), "compression is negative")
        if os.path.exists(r.file("dem_history.csv")):
            h = r.dem_history()
            self.assertTrue(np.all(np.diff(h["step"]) >= 0))

    def test_compare_with_itself_and_plot(self):
        rows = demfdm.compare([self.rr, self.rr])
        self.assertEqual((rows[1]["curve_max_diff"], rows[1]["curve_rms_diff"]), (0.0, 0.0))
        self.assertEqual(rows[1]["peak_N"], self.rr.result["peak_N"])
        self.assertTrue(math.isfinite(rows[0]["wall_s"]))
        with tempfile.TemporaryDirectory() as out:
            p = subprocess.run([sys.executable, "-m", "demfdm.plot", RUN, "--out", out], capture_output=True, text=True,
                               env=dict(os.environ, PYTHONPATH=LAUNCH_PY), timeout=120)
            self.assertEqual(p.returncode, 0, p.stderr)
            self.assertIn(os.path.join(out, "load_settlement.png"), p.stdout.split())
            self.assertTrue(os.path.getsize(os.path.join(out, "load_settlement.png")) > 10000)


if __name__ == "__main__":
    if not os.path.isdir(RUN):
        print("skipped: no run folder %s (a run of scenes/footing_small.toml; DEMFDM_PYREADER_RUN)" % RUN)
        sys.exit(77)
    unittest.main(verbosity=2)
