"""Result values of one or more run folders, and for several the curve differences against the
first (demfdm.compare).

  PYTHONPATH=launch/py /usr/bin/python3 -m demfdm RUN [RUN ...] [--markdown]
"""
import argparse
import sys

from .comparison import compare, format_table


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python3 -m demfdm", description=__doc__.split("\n\n")[0].replace("\n", " "))
    ap.add_argument("runs", nargs="+", metavar="RUN")
    ap.add_argument("--markdown", action="store_true", help="a markdown table")
    a = ap.parse_args(argv)
    try:
        rows = compare(a.runs)
    except (OSError, ValueError) as e:
        print("demfdm: %s" % e, file=sys.stderr)
        return 1
    print(format_table(rows, a.markdown))
    if len(rows) > 1:
        print("\ncurve_max_diff, curve_rms_diff: largest and RMS |load - load of %s| on a common settlement grid, "
              "over its peak load" % rows[0]["run"])
    for r in rows:
        print("%s: %s" % (r["run"], r["path"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
