#!/usr/bin/python3
"""Plot demfdm time series (CSV, or /history of a results .h5) into PNG/PDF/SVG.

Column names carry their unit after the last underscore (CsvSeries convention):
"time_s", "load_N", "displacement_m", "stress_zz_Pa", "broken_ratio_1" ("1" = dimensionless).
Axis labels are made from them: "load_N" -> "load [N]". A history file (history.h5) offers
its /history/<name> datasets as columns "<name>_<unit>" using each dataset's `unit` attribute.

Typical figures of the paper:
  load-displacement:   --x displacement_m --x-factor=-1e3 --x-unit mm --y load_N --y-factor 1e-3 --y-unit kN
  stress-depth:        --x stress_zz_Pa --x-factor=-1e-3 --x-unit kPa --y depth_m --invert-y
                       (from a CSV, or straight from fdm.h5: horizontally averaged zone stresses
                       of frame --frame, see read_fdm_profile)
  stress-strain:       --x strain_1 --y stress_zz_Pa --y-factor=-1e-6 --y-unit MPa

Usage:
  /usr/bin/python3 launch/py/demfdm_plot.py -o fig.png --x displacement_m --y load_N \
      runA/load.csv runB/load.csv --label "A" --label "B"

Negative factors must be written with "=" (--x-factor=-1e3), or argparse takes them for options.

Library use (from other scripts): read_series(path) -> Series; plot_series(runs, x, ys, out, ...).
Only numpy and matplotlib (Agg backend, no display needed).
"""
import argparse
import os
import sys

import numpy as np
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


class Series:
    """Columns of one run: `names` in file order, `data[name]` a float64 numpy array."""

    def __init__(self, path, names, data):
        self.path = path
        self.names = list(names)
        self.data = dict(data)

    def column(self, name):
        if name not in self.data:
            raise KeyError("column '%s' not in %s; available: %s" % (name, self.path, ", ".join(self.names)))
        return self.data[name]


def read_csv(path):
    """Read a CsvSeries file: one header line of names, then comma-separated numbers."""
    with open(path, "r", encoding="ascii") as f:
        header = f.readline().strip()
        if not header:
            raise ValueError("%s: empty file, expected a header line" % path)
        names = [n.strip() for n in header.split(",")]
        rows = []
        for lineno, line in enumerate(f, start=2):
            line = line.strip()
            if not line:
                continue
            parts = line.split(",")
            if len(parts) != len(names):
                raise ValueError("%s:%d: %d values, the header has %d columns" % (path, lineno, len(parts), len(names)))
            rows.append([float(p) for p in parts])
    arr = np.array(rows, dtype=np.float64).reshape(len(rows), len(names))
    return Series(path, names, {n: arr[:, i] for i, n in enumerate(names)})


def read_h5_history(path):
    """Read /history/<name> of a results file as columns "<name>_<unit>"."""
    import h5py  # only needed for .h5 input

    names, data = [], {}
    with h5py.File(path, "r") as f:
        if "history" not in f:
            raise ValueError("%s has no /history group" % path)
        for name in sorted(f["history"]):
            d = f["history"][name]
            unit = d.attrs.get("unit", b"1")
            unit = unit.decode() if isinstance(unit, (bytes, np.bytes_)) else str(unit)
            col = "%s_%s" % (name, unit or "1")
            names.append(col)
            data[col] = np.asarray(d[()], dtype=np.float64)
    return Series(path, names, data)


STRESS_COMPONENTS = ("xx", "yy", "zz", "xy", "yz", "xz")  # fdm.h5 column order (VTK order)


def read_fdm_profile(path, frame=-1):
    """Horizontally averaged zone stresses against depth, from an fdm.h5 results file.

    Zone centroids are the means of their 8 nodes' reference coordinates (/mesh/node_coords,
    /mesh/zone_nodes). Zones whose centroid z agree to 1e-9 of the mesh height form one level;
    each level gives one row with columns z_m, depth_m (top of the mesh minus z),
    stress_<c>_Pa for c in xx yy zz xy yz xz (mean over the level, tension positive as
    written by the FDM) and zones_1 (zones in the level). Rows are sorted by depth.
    `frame` indexes the frames in time order (-1 = last).
    """
    import h5py

    with h5py.File(path, "r") as f:
        if "mesh" not in f or "frames" not in f:
            raise ValueError("%s has no /mesh and /frames (not an fdm.h5 results file)" % path)
        coords = f["mesh/node_coords"][()]
        zones = f["mesh/zone_nodes"][()]
        names = sorted(f["frames"])
        if not names:
            raise ValueError("%s has no frames" % path)
        try:
            name = names[frame]
        except IndexError:
            raise ValueError("%s: frame %d out of range (%d frames)" % (path, frame, len(names)))
        stress = f["frames"][name]["zones/stress"][()]
    zc = coords[zones][:, :, 2].mean(axis=1)
    height = max(coords[:, 2].max() - coords[:, 2].min(), 1e-300)
    levels = np.round((zc - zc.min()) / (1e-9 * height)).astype(np.int64)
    uniq = np.unique(levels)
    rows = []
    for lv in uniq:
        sel = levels == lv
        rows.append([zc[sel].mean(), coords[:, 2].max() - zc[sel].mean()] + list(stress[sel].mean(axis=0))
                    + [float(sel.sum())])
    rows.sort(key=lambda r: r[1])
    cols = ["z_m", "depth_m"] + ["stress_%s_Pa" % c for c in STRESS_COMPONENTS] + ["zones_1"]
    arr = np.array(rows, dtype=np.float64)
    return Series("%s[frame %s]" % (path, name), cols, {c: arr[:, i] for i, c in enumerate(cols)})


def read_series(path, frame=-1):
    """CSV by default; an .h5 gives its /history, or, for an fdm.h5 without history, the
    stress-depth profile of frame `frame` (read_fdm_profile)."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in (".h5", ".hdf5"):
        return read_csv(path)
    import h5py

    with h5py.File(path, "r") as f:
        has_history = "history" in f
    return read_h5_history(path) if has_history else read_fdm_profile(path, frame)


def split_unit(column):
    """"stress_zz_Pa" -> ("stress zz", "Pa"); "ratio_1" -> ("ratio", "-"); "time" -> ("time", "")."""
    if "_" not in column:
        return column, ""
    name, unit = column.rsplit("_", 1)
    return name.replace("_", " "), ("-" if unit == "1" else unit)


def axis_label(column, unit=None):
    """Axis label with unit in brackets; `unit` overrides the unit taken from the name."""
    name, u = split_unit(column)
    u = unit if unit else u
    return "%s [%s]" % (name, u) if u else name


def plot_series(runs, x, ys, out, labels=None, x_factor=1.0, y_factor=1.0, x_unit=None, y_unit=None,
                xlabel=None, ylabel=None, logx=False, logy=False, invert_y=False, title=None,
                figsize=(5.0, 3.5), dpi=150, markers=False):
    """Overlay columns `ys` against column `x` for every Series in `runs` and save to `out`.

    `labels[i]` names run i in the legend (default: the file name). The factors scale the
    plotted values (e.g. 1e3 for m -> mm, with x_unit="mm"); a negative factor flips a sign
    convention (settlement as positive displacement, compression as positive stress).
    Returns the path written.
    """
    if not runs:
        raise ValueError("no runs to plot")
    labels = list(labels) if labels else [os.path.splitext(os.path.basename(r.path))[0] for r in runs]
    if len(labels) != len(runs):
        raise ValueError("%d labels for %d runs" % (len(labels), len(runs)))
    fig, ax = plt.subplots(figsize=figsize)
    style = "o-" if markers else "-"
    for run, label in zip(runs, labels):
        xv = run.column(x) * x_factor
        for y in ys:
            yv = run.column(y) * y_factor
            # Several y columns: the legend names each with its unit (they may differ).
            yname = axis_label(y, y_unit)
            name = label if len(ys) == 1 else ("%s: %s" % (label, yname) if len(runs) > 1 else yname)
            ax.plot(xv, yv, style, label=name, markersize=3)
    ax.set_xlabel(xlabel or axis_label(x, x_unit))
    if ylabel:
        ax.set_ylabel(ylabel)
    elif len(ys) == 1:
        ax.set_ylabel(axis_label(ys[0], y_unit))
    else:
        units = {y_unit or split_unit(y)[1] for y in ys}
        ax.set_ylabel("[%s]" % units.pop() if len(units) == 1 else "value")
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    if invert_y:
        ax.invert_yaxis()
    if title:
        ax.set_title(title)
    if len(runs) > 1 or len(ys) > 1:
        ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    out_dir = os.path.dirname(os.path.abspath(out))
    os.makedirs(out_dir, exist_ok=True)
    fig.savefig(out, dpi=dpi)
    plt.close(fig)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description="Plot demfdm CSV / history time series (several runs overlaid).")
    ap.add_argument("inputs", nargs="+", help="CSV files or results .h5 files with /history")
    ap.add_argument("-o", "--output", required=True, help="image to write (.png, .pdf, .svg)")
    ap.add_argument("--x", required=True, help="x column, e.g. displacement_m")
    ap.add_argument("--y", action="append", required=True, help="y column (repeat for several)")
    ap.add_argument("--label", action="append", help="legend label per input, in order")
    ap.add_argument("--x-factor", type=float, default=1.0, help="multiply x by this (e.g. 1e3 for mm)")
    ap.add_argument("--y-factor", type=float, default=1.0, help="multiply y by this")
    ap.add_argument("--x-unit", help="unit shown on the x axis after scaling (e.g. mm)")
    ap.add_argument("--y-unit", help="unit shown on the y axis after scaling (e.g. kN)")
    ap.add_argument("--xlabel", help="full x axis label (overrides name and unit)")
    ap.add_argument("--ylabel", help="full y axis label")
    ap.add_argument("--logx", action="store_true")
    ap.add_argument("--logy", action="store_true")
    ap.add_argument("--invert-y", action="store_true", help="e.g. depth downwards")
    ap.add_argument("--markers", action="store_true", help="mark the samples")
    ap.add_argument("--frame", type=int, default=-1,
                    help="frame of an fdm.h5 stress-depth profile (time order, -1 = last)")
    ap.add_argument("--title")
    ap.add_argument("--size", type=float, nargs=2, default=(5.0, 3.5), metavar=("W", "H"), help="inches")
    ap.add_argument("--dpi", type=int, default=150)
    args = ap.parse_args(argv)
    try:
        runs = [read_series(p, args.frame) for p in args.inputs]
        plot_series(runs, args.x, args.y, args.output, labels=args.label, x_factor=args.x_factor,
                    y_factor=args.y_factor, x_unit=args.x_unit, y_unit=args.y_unit, xlabel=args.xlabel,
                    ylabel=args.ylabel, logx=args.logx, logy=args.logy, invert_y=args.invert_y,
                    title=args.title, figsize=tuple(args.size), dpi=args.dpi, markers=args.markers)
    except (OSError, ValueError, KeyError) as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        print("demfdm_plot: %s" % msg, file=sys.stderr)
        return 1
    print("demfdm_plot: wrote %s" % args.output)
    return 0


if __name__ == "__main__":
    sys.exit(main())
