#!/usr/bin/python3
"""Print the frames, datasets and shapes of a demfdm results file (dem.h5, fdm.h5, history.h5).

Layout: common/io/README.md (root attributes, /frames/NNNNNN groups with
`time` and `step` attributes, static datasets such as /mesh/*, /history/<name> series).

Usage:
    /usr/bin/python3 launch/py/h5_summary.py RUN/dem.h5 [more files] [--all-frames] [--json]

Text output shows the root attributes, the static datasets, the frame count and time range,
the datasets of the first and last frame (of every frame with --all-frames) and the history
lengths. --json prints one machine-readable object per file (a list when several files):
{"file", "attrs", "datasets": {path: [shape, dtype]}, "frames": [{"name", "time", "step"}],
"history": {name: {"length", "unit"}}}; "datasets" lists every dataset, frames included.

Run it with Debian's /usr/bin/python3 (h5py); a pyenv python3 on PATH may lack h5py.
"""
import argparse
import json
import sys

import h5py
import numpy as np


def _attr_value(v):
    """Attribute value as a plain Python object (fixed-length strings come back as bytes)."""
    if isinstance(v, (bytes, np.bytes_)):
        return v.decode("ascii", errors="replace")
    if isinstance(v, np.ndarray):
        return [_attr_value(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        return v.item()
    return v


def summarize(path):
    """Return a dict describing the results file at `path` (see the module docstring)."""
    out = {"file": str(path), "attrs": {}, "datasets": {}, "frames": [], "history": {}}
    with h5py.File(path, "r") as f:
        out["attrs"] = {k: _attr_value(v) for k, v in sorted(f.attrs.items())}

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out["datasets"]["/" + name] = [list(obj.shape), str(obj.dtype)]

        f.visititems(visit)
        if "frames" in f:
            # 6-digit zero-padded names: sorted() is chronological.
            for name in sorted(f["frames"]):
                g = f["frames"][name]
                out["frames"].append({
                    "name": name,
                    "time": _attr_value(g.attrs.get("time", float("nan"))),
                    "step": _attr_value(g.attrs.get("step", -1)),
                })
        if "history" in f:
            for name in sorted(f["history"]):
                d = f["history"][name]
                out["history"][name] = {"length": int(d.shape[0]),
                                        "unit": _attr_value(d.attrs.get("unit", b""))}
    return out


def _frame_datasets(summary, frame_name):
    prefix = "/frames/%s/" % frame_name
    return {p[len(prefix):]: v for p, v in summary["datasets"].items() if p.startswith(prefix)}


def format_text(s, all_frames=False):
    lines = ["file: %s" % s["file"]]
    for k, v in s["attrs"].items():
        lines.append("  @%s = %r" % (k, v))
    static = {p: v for p, v in s["datasets"].items()
              if not p.startswith("/frames/") and not p.startswith("/history/")}
    if static:
        lines.append("static datasets:")
        for p, (shape, dtype) in sorted(static.items()):
            lines.append("  %-40s %-16s %s" % (p, "x".join(map(str, shape)) or "scalar", dtype))
    frames = s["frames"]
    if frames:
        lines.append("frames: %d, t = %.9g .. %.9g s, steps %d .. %d"
                     % (len(frames), frames[0]["time"], frames[-1]["time"], frames[0]["step"], frames[-1]["step"]))
        shown = frames if all_frames or len(frames) <= 2 else [frames[0], frames[-1]]
        for i, fr in enumerate(shown):
            if not all_frames and len(frames) > 2 and i == 1:
                lines.append("  ... %d more frame(s) ..." % (len(frames) - 2))
            lines.append("  /frames/%s  time %r s  step %d" % (fr["name"], fr["time"], fr["step"]))
            for p, (shape, dtype) in sorted(_frame_datasets(s, fr["name"]).items()):
                lines.append("    %-36s %-16s %s" % (p, "x".join(map(str, shape)) or "0", dtype))
    else:
        lines.append("frames: 0")
    if s["history"]:
        lines.append("history:")
        for name, h in s["history"].items():
            lines.append("  %-20s %8d rows  [%s]" % (name, h["length"], h["unit"]))
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("files", nargs="+", help="results files (.h5)")
    ap.add_argument("--json", action="store_true", help="machine-readable output")
    ap.add_argument("--all-frames", action="store_true", help="list the datasets of every frame")
    args = ap.parse_args(argv)
    summaries = []
    for path in args.files:
        try:
            summaries.append(summarize(path))
        except OSError as e:
            print("h5_summary: cannot read %s: %s" % (path, e), file=sys.stderr)
            return 1
    if args.json:
        json.dump(summaries[0] if len(summaries) == 1 else summaries, sys.stdout, indent=1)
        print()
    else:
        print("\n\n".join(format_text(s, args.all_frames) for s in summaries))
    return 0


if __name__ == "__main__":
    sys.exit(main())
