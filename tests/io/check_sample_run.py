#!/usr/bin/python3
"""ctest io_sample_run_h5py_xml: checks the run folder written by io_sample_writer.

1. launch/py/h5_summary.py --json (h5py) reports exactly the datasets, shapes and dtypes the
   writer was given (expected_shapes.json), the frame times increase and string attributes
   are fixed-length (bytes in h5py).
2. Every .xmf sidecar parses with xml.etree; each HDF DataItem names an existing dataset whose
   shape and dtype match Dimensions / NumberType / Precision; topology counts, HyperSlab
   counts, attribute row counts and connectivity ranges agree; each grid's Time equals the
   `time` attribute of the frame group it points into, and there is one grid per frame.
Usage: check_sample_run.py RUN_FOLDER LAUNCH_PY_FOLDER
"""
import json
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import h5py
import numpy as np

FAILURES = []


def check(cond, msg):
    if not cond:
        FAILURES.append(msg)


def xdmf_dtype(number_type, precision):
    return {("Float", "8"): "float64", ("Float", "4"): "float32", ("Int", "8"): "int64",
            ("Int", "4"): "int32", ("UChar", "1"): "uint8"}.get((number_type, precision), "?")


def check_shapes(run, tools):
    expected = json.load(open(os.path.join(run, "expected_shapes.json")))
    for fname, datasets in expected.items():
        path = os.path.join(run, fname)
        out = subprocess.run([sys.executable, os.path.join(tools, "h5_summary.py"), "--json", path],
                             capture_output=True, text=True)
        check(out.returncode == 0, "h5_summary.py failed on %s: %s" % (fname, out.stderr))
        if out.returncode != 0:
            continue
        s = json.loads(out.stdout)
        got = s["datasets"]
        for ds, (shape, dtype) in datasets.items():
            check(ds in got, "%s: dataset %s missing" % (fname, ds))
            if ds in got:
                check(got[ds] == [shape, dtype], "%s:%s is %s, expected %s" % (fname, ds, got[ds], [shape, dtype]))
        extra = sorted(set(got) - set(datasets))
        check(not extra, "%s: unexpected datasets %s" % (fname, extra))
        times = [fr["time"] for fr in s["frames"]]
        check(times == sorted(times) and len(set(times)) == len(times), "%s: frame times not increasing: %s"
              % (fname, times))
        check(s["attrs"].get("format") == "demfdm-results", "%s: format attribute %r" % (fname, s["attrs"]))
        with h5py.File(path, "r") as f:
            check(isinstance(f.attrs["producer"], (bytes, np.bytes_)),
                  "%s: producer should be a fixed-length string (bytes in h5py)" % fname)
    hist = json.loads(subprocess.run([sys.executable, os.path.join(tools, "h5_summary.py"), "--json",
                                      os.path.join(run, "history.h5")], capture_output=True, text=True).stdout)
    check(hist["history"].get("load") == {"length": 50, "unit": "N"}, "history load: %s" % hist["history"])
    print("shapes: %d files checked against expected_shapes.json" % len(expected))


def check_xmf(run, xmf_name):
    xmf = os.path.join(run, xmf_name)
    root = ET.parse(xmf).getroot()  # raises on malformed XML
    check(root.tag == "Xdmf" and root.get("Version") == "3.0", "%s: root %s %s" % (xmf_name, root.tag, root.attrib))
    coll = root.find("Domain/Grid")
    check(coll is not None and coll.get("CollectionType") == "Temporal", "%s: no temporal collection" % xmf_name)
    grids = coll.findall("Grid")
    files = {}

    def open_h5(name):
        if name not in files:
            files[name] = h5py.File(os.path.join(os.path.dirname(xmf), name), "r")
        return files[name]

    def resolve(item):
        """Dataset of an HDF DataItem after checking shape and dtype against the XML."""
        fname, path = item.text.strip().split(":", 1)
        f = open_h5(fname)
        check(path in f, "%s: %s not in %s" % (xmf_name, path, fname))
        if path not in f:
            return None, fname, path
        d = f[path]
        dims = [int(v) for v in item.get("Dimensions").split()]
        check(list(d.shape) == dims, "%s: %s shape %s, Dimensions %s" % (xmf_name, path, d.shape, dims))
        want = xdmf_dtype(item.get("NumberType", "Float"), item.get("Precision", "4"))
        check(str(d.dtype) == want, "%s: %s dtype %s, XML says %s" % (xmf_name, path, d.dtype, want))
        return d, fname, path

    n_items = 0
    frame_names = set()
    for g in grids:
        t = float(g.find("Time").get("Value"))
        topo = g.find("Topology")
        nelem = int(topo.get("NumberOfElements"))
        geom_item = g.find("Geometry/DataItem")
        geom, gfile, gpath = resolve(geom_item)
        n_items += 1
        npts = geom.shape[0] if geom is not None else -1
        # The frame this grid shows: from any per-frame path; its time attribute must match.
        per_frame = [it.text.strip().split(":", 1) for it in g.iter("DataItem")
                     if it.get("Format") == "HDF" and "/frames/" in it.text]
        for fname, path in per_frame:
            frame = "/".join(path.split("/")[:3])
            frame_names.add((fname, frame))
            check(open_h5(fname)[frame].attrs["time"] == t,
                  "%s: Time %r differs from %s@time" % (xmf_name, t, frame))
        ttype = topo.get("TopologyType")
        if ttype == "Polyvertex":
            slab = topo.find("DataItem")
            check(slab.get("ItemType") == "HyperSlab", "%s: Polyvertex without HyperSlab" % xmf_name)
            start, stride, count = [int(v) for v in slab.find("DataItem[@Format='XML']").text.split()]
            check((start, stride, count) == (0, 1, nelem) and int(slab.get("Dimensions")) == nelem,
                  "%s: hyperslab %s for %d elements" % (xmf_name, (start, stride, count), nelem))
            idx, _, _ = resolve(slab.find("DataItem[@Format='HDF']"))
            n_items += 1
            check(idx is not None and idx.shape[0] >= nelem and np.array_equal(idx[:nelem], np.arange(nelem)),
                  "%s: vertex index is not 0..N-1" % xmf_name)
            check(nelem == npts, "%s: %d vertices for %d points" % (xmf_name, nelem, npts))
        else:
            conn, _, cpath = resolve(topo.find("DataItem"))
            n_items += 1
            per = {"Polyline": 2, "Triangle": 3, "Hexahedron": 8}[ttype]
            check(conn is not None and conn.shape == (nelem, per), "%s: %s shape" % (xmf_name, cpath))
            if conn is not None and conn.shape[0] > 0:
                c = conn[()]
                check(c.min() >= 0 and c.max() < npts, "%s: connectivity %s outside [0, %d)" % (xmf_name, cpath, npts))
        for a in g.findall("Attribute"):
            d, _, apath = resolve(a.find("DataItem"))
            n_items += 1
            want_rows = npts if a.get("Center") == "Node" else nelem
            check(d is not None and d.shape[0] == want_rows,
                  "%s: attribute %s rows %s, expected %d" % (xmf_name, a.get("Name"), d.shape if d else None, want_rows))
            cols = 1 if d is None or d.ndim == 1 else d.shape[1]
            want_type = {1: "Scalar", 3: "Vector"}.get(cols, "Matrix")
            check(a.get("AttributeType") == want_type, "%s: %s is %s, expected %s"
                  % (xmf_name, a.get("Name"), a.get("AttributeType"), want_type))
    # One grid per frame of the file the sidecar shows.
    for fname in {f for f, _ in frame_names}:
        check(len(grids) == len(open_h5(fname)["frames"]), "%s: %d grids, %d frames in %s"
              % (xmf_name, len(grids), len(open_h5(fname)["frames"]), fname))
    for f in files.values():
        f.close()
    print("%s: %d grids, %d HDF data items resolved" % (xmf_name, len(grids), n_items))
    return len(grids)


def main():
    run, tools = sys.argv[1], sys.argv[2]
    check_shapes(run, tools)
    counts = {x: check_xmf(run, x) for x in ("particles.xmf", "bonds.xmf", "footing.xmf", "mesh.xmf")}
    check(counts == {"particles.xmf": 3, "bonds.xmf": 3, "footing.xmf": 3, "mesh.xmf": 2}, "grid counts %s" % counts)
    check(not [f for f in os.listdir(run) if f.endswith(".tmp")], "temporary sidecar files left behind")
    if FAILURES:
        print("FAILED:\n  " + "\n  ".join(FAILURES))
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
