#!/usr/bin/python3
"""`python3 -m demfdm.plot` and demfdm.plot's functions on synthetic run folders (make_run.py):
which files are written, and what the figures draw (the data and labels of their lines, caught
before the figure is closed), including q / sigma_c for a scene that leaves the ball-ball model
to its default (softbond).

  /usr/bin/python3 tests/pyreader/check_plot.py LAUNCH_PY_DIR
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
sys.path.insert(0, HERE)
sys.path.insert(0, LAUNCH_PY)

import demfdm  # noqa: E402
import demfdm.plot as dplot  # noqa: E402
import make_run as mk  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.image as mpimg  # noqa: E402

PNG = b"\x89PNG\r\n\x1a\n"


def cli(*args):
    env = dict(os.environ, PYTHONPATH=LAUNCH_PY)
    return subprocess.run([sys.executable, "-m", "demfdm.plot", *args], env=env, capture_output=True, text=True,
                          timeout=120)


class Caught:
    """Catches the figures that are closed (plt.close(fig)) while in the with block."""

    def __enter__(self):
        self.figs, self._close = [], plt.close
        # (matplotlib's own close("all") on its first figure is not one of them)
        plt.close = lambda fig=None: (self.figs.append(fig) if hasattr(fig, "axes") else None) or self._close(fig)
        return self

    def __exit__(self, *exc):
        plt.close = self._close


class Plot(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory(prefix="pyreader-plot-")
        root = cls.tmp.name
        cls.a = mk.make_run(root, "run-a")
        cls.b = mk.make_run(root, "run-b", scale=1.1, rows=33, with_result=False, h5=False)
        cls.d = mk.make_run(root, "run-d", ball_ball="", h5=False, summary_file=False)
        cls.root = root

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_figures_draw_the_runs_values(self):
        out = os.path.join(self.root, "out-a")
        with Caught() as c:
            made = dplot.figures(self.a, out)
        self.assertEqual(made, [os.path.join(out, "load_settlement.png"), os.path.join(out, "stress_profiles.png")])
        ls, prof = c.figs
        raw, norm = ls.axes
        s = np.arange(41) * mk.DS
        f = mk.load_a(s)
        line = raw.lines[0]
        np.testing.assert_allclose(line.get_xdata(), s * 1e3, rtol=1e-15)
        np.testing.assert_allclose(line.get_ydata(), f, rtol=0, atol=1e-15)
        self.assertEqual(raw.get_xlabel(), "settlement at model scale [mm]")
        self.assertEqual(raw.get_ylabel(), "footing load at model scale [N]")
        # The scene gives softbond.ten but no model: the default softbond, so q / sigma_c is drawn.
        self.assertIn("q / sigma_c", norm.get_ylabel())
        q = f / (math.pi * mk.D_F ** 2 / 4)
        np.testing.assert_allclose(norm.lines[0].get_xdata(), s / mk.D_F, rtol=1e-15)
        np.testing.assert_allclose(norm.lines[0].get_ydata(), q / mk.SIGMA_C, rtol=1e-14, atol=1e-15)
        ax = prof.axes[0]
        by_label = {ln.get_label(): ln for ln in ax.lines}
        dem = by_label["DEM block slabs, after 'gravity'"]
        np.testing.assert_allclose(dem.get_xdata(), [0.06, 0.18, 0.30], rtol=1e-14)
        np.testing.assert_allclose(dem.get_ydata(), [0.1, 0.3, 0.5], rtol=1e-14)
        fdm = by_label["continuum zones, after 'gravity'"]
        np.testing.assert_allclose(fdm.get_xdata(), [0.156, 0.468], rtol=1e-14)
        for p in made:
            with open(p, "rb") as fh:
                self.assertEqual(fh.read(8), PNG)
        self.assertEqual(mpimg.imread(made[0]).shape[:2], (572, 1430))  # 11 x 4.4 in at 130 dpi

    def test_scene_default_model_not_changed_on_disk(self):
        run = demfdm.Run(self.d)
        scene = dplot.scene_with_defaults(run.scene)
        self.assertEqual(scene["dem"]["ball_ball"]["model"], "softbond")
        self.assertNotIn("ball_ball", run.scene["dem"])  # a copy; the Run's scene is as read
        explicit = {"dem": {"ball_ball": {"model": "linear"}}}
        self.assertIs(dplot.scene_with_defaults(explicit), explicit)
        no_dem = {"continuum": {}}
        self.assertIs(dplot.scene_with_defaults(no_dem), no_dem)

    def test_curves_figure(self):
        path = os.path.join(self.root, "curves.png")
        with Caught() as c:
            self.assertEqual(dplot.curves_figure([self.a, self.b, self.d], path, labels=["A", "B", "D"]), path)
        fig, = c.figs
        raw, norm = fig.axes
        self.assertEqual([ln.get_label() for ln in raw.lines], ["A", "B", "D"])
        np.testing.assert_allclose(raw.lines[1].get_ydata(), 1.1 * mk.load_a(np.arange(33) * mk.DS), rtol=1e-14,
                                   atol=1e-15)
        # D's sigma_c is the scene default 0.45 MPa (no summary), A's and B's 0.5 MPa.
        qa = norm.lines[0].get_ydata()
        qd = norm.lines[2].get_ydata()
        np.testing.assert_allclose(qd[1:] / qa[1:], mk.SIGMA_C / 0.45e6, rtol=1e-12)
        self.assertIn("q / sigma_c", norm.get_ylabel())
        with open(path, "rb") as fh:
            self.assertEqual(fh.read(8), PNG)

    def test_cli_one_run(self):
        out = os.path.join(self.root, "cli-one")
        r = cli(self.a, "--out", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(r.stdout.split(), [os.path.join(out, "load_settlement.png"),
                                            os.path.join(out, "stress_profiles.png")])
        for n in ("load_settlement.png", "stress_profiles.png"):
            with open(os.path.join(out, n), "rb") as fh:
                self.assertEqual(fh.read(8), PNG)

    def test_cli_default_out_is_the_run(self):
        r = cli(self.b)
        self.assertEqual(r.returncode, 0, r.stderr)
        self.assertEqual(r.stdout.split(), [os.path.join(self.b, "load_settlement.png"),
                                            os.path.join(self.b, "stress_profiles.png")])

    def test_cli_several_runs(self):
        out = os.path.join(self.root, "cli-many")
        r = cli(self.a, self.b, "--out", out)
        self.assertEqual(r.returncode, 0, r.stderr)
        lines = r.stdout.split()
        self.assertEqual(lines[-2:], [os.path.join(out, "compare_load_settlement.png"), os.path.join(out, "compare.md")])
        for sub in ("run-a", "run-b"):
            self.assertTrue(os.path.isfile(os.path.join(out, sub, "load_settlement.png")), sub)
        with open(os.path.join(out, "compare.md")) as fh:
            md = fh.read()
        rows = [ln for ln in md.splitlines() if ln.startswith("| run-")]
        self.assertEqual(len(rows), 2)
        self.assertTrue(rows[0].startswith("| run-a | 1 | 5e-05 | 2e+04 | 0.6 | 12.5 | 0 | 0 |"), rows[0])
        self.assertTrue(rows[1].startswith("| run-b | 1.1 | 5e-05 | 2.2e+04 | 0.836 | 12.5 | "), rows[1])
        # |B - A| = 0.1 A: at most 0.1 of A's peak (the 200-point grid misses the peak by a little)
        max_diff = float(rows[1].split("|")[7])
        self.assertTrue(0.099 < max_diff <= 0.1, max_diff)

    def test_cli_errors(self):
        r = cli(os.path.join(self.root, "no-such-run"))
        self.assertEqual(r.returncode, 1)
        self.assertIn("not a run folder", r.stderr)
        r = cli(self.a, self.b)
        self.assertEqual(r.returncode, 2)
        self.assertIn("--out", r.stderr)


if __name__ == "__main__":
    unittest.main(verbosity=2)
