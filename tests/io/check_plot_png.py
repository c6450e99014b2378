#!/usr/bin/python3
"""ctest io_plot_png: runs launch/py/demfdm_plot.py (the CLI, as a user would) on the CSV
series and the history.h5 written by io_sample_writer, and checks the images: file exists,
non-empty, PNG signature, IHDR size = figure size x dpi. Also checks the axis-label helper,
that a missing column fails with a message naming it, and the stress-depth profile read from
fdm.h5 against the values the writer was given (relative tolerance 1e-12).
Usage: check_plot_png.py RUN_FOLDER LAUNCH_PY_FOLDER
"""
import os
import struct
import subprocess
import sys

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    if head[:8] != PNG_SIGNATURE or head[12:16] != b"IHDR":
        return None
    return struct.unpack(">II", head[16:24])


def run_plot(tools, args):
    return subprocess.run([sys.executable, os.path.join(tools, "demfdm_plot.py")] + args,
                          capture_output=True, text=True)


def main():
    run, tools = sys.argv[1], sys.argv[2]
    failures = []
    out = os.path.join(run, "plots", "load_displacement.png")
    if os.path.exists(out):
        os.remove(out)
    r = run_plot(tools, ["-o", out, "--x", "displacement_m", "--x-factor=-1e3", "--x-unit", "mm",
                         "--y", "load_N", "--y-factor", "1e-3", "--y-unit", "kN", "--size", "4", "3", "--dpi", "100",
                         os.path.join(run, "load_displacement_a.csv"), os.path.join(run, "load_displacement_b.csv"),
                         "--label", "run A", "--label", "run B"])
    if r.returncode != 0:
        failures.append("demfdm_plot.py failed: %s %s" % (r.stdout, r.stderr))
    elif not os.path.isfile(out) or os.path.getsize(out) == 0:
        failures.append("no PNG written at %s" % out)
    elif png_size(out) != (400, 300):
        failures.append("%s: not a 400x300 PNG (signature/IHDR: %s)" % (out, png_size(out)))

    out2 = os.path.join(run, "plots", "history.png")
    if os.path.exists(out2):
        os.remove(out2)
    r = run_plot(tools, ["-o", out2, "--x", "time_s", "--y", "load_N", os.path.join(run, "history.h5")])
    if r.returncode != 0 or png_size(out2) is None:
        failures.append("plot from history.h5 failed: %s %s" % (r.stdout, r.stderr))

    r = run_plot(tools, ["-o", os.path.join(run, "plots", "bad.png"), "--x", "nope_m", "--y", "load_N",
                         os.path.join(run, "load_displacement_a.csv")])
    if r.returncode == 0 or "nope_m" not in r.stderr or "load_N" not in r.stderr:
        failures.append("missing column should fail naming it and the available ones: rc %d, %s"
                        % (r.returncode, r.stderr))
    if os.path.exists(os.path.join(run, "plots", "bad.png")):
        failures.append("a failed plot must not leave an image")

    sys.dont_write_bytecode = True  # no __pycache__ in the source tree
    sys.path.insert(0, tools)
    import demfdm_plot  # noqa: E402
    for col, want in [("load_N", "load [N]"), ("stress_zz_Pa", "stress zz [Pa]"), ("broken_ratio_1", "broken ratio [-]"),
                      ("time", "time")]:
        got = demfdm_plot.axis_label(col)
        if got != want:
            failures.append("axis_label(%r) = %r, expected %r" % (col, got, want))
    if demfdm_plot.axis_label("displacement_m", "mm") != "displacement [mm]":
        failures.append("unit override ignored")

    # Stress-depth profile straight from fdm.h5. io_sample_writer puts sigma_zz = -2e4 (f + 1)
    # (z + 1) Pa in zone z of frame f, zones 0-5 in the lower level (centroid z = -0.75 m) and
    # 6-11 in the upper one (-0.25 m), mesh top at z = 0. Last frame (f = 1), level means:
    # upper -4e4 * 9.5 = -3.8e5 Pa at depth 0.25 m, lower -4e4 * 3.5 = -1.4e5 Pa at 0.75 m.
    prof = demfdm_plot.read_series(os.path.join(run, "fdm.h5"))
    import numpy as np  # noqa: E402
    checks = [("depth_m", [0.25, 0.75]), ("stress_zz_Pa", [-3.8e5, -1.4e5]), ("stress_xx_Pa", [0.0, 0.0]),
              ("zones_1", [6.0, 6.0])]
    for col, want in checks:
        if not np.allclose(prof.column(col), want, rtol=1e-12, atol=0.0):
            failures.append("fdm profile %s = %s, expected %s" % (col, prof.column(col), want))
    first = demfdm_plot.read_series(os.path.join(run, "fdm.h5"), frame=0)
    if not np.allclose(first.column("stress_zz_Pa"), [-1.9e5, -0.7e5], rtol=1e-12, atol=0.0):
        failures.append("fdm profile of frame 0: %s" % first.column("stress_zz_Pa"))
    out3 = os.path.join(run, "plots", "stress_depth.png")
    if os.path.exists(out3):
        os.remove(out3)
    r = run_plot(tools, ["-o", out3, "--x", "stress_zz_Pa", "--x-factor=-1e-3", "--x-unit", "kPa", "--y", "depth_m",
                         "--invert-y", "--markers", os.path.join(run, "fdm.h5")])
    if r.returncode != 0 or png_size(out3) is None:
        failures.append("stress-depth plot from fdm.h5 failed: %s %s" % (r.stdout, r.stderr))

    if failures:
        print("FAILED:\n  " + "\n  ".join(failures))
        return 1
    print("PNG checks passed: %s (%d bytes)" % (out, os.path.getsize(out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
