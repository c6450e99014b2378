"""ctest io_paraview_readers (registered only when ParaView's pvbatch is installed).

Opens the sidecars written by io_sample_writer with all three XDMF readers of ParaView
(Xdmf3ReaderT, Xdmf3ReaderS, XDMFReader), by absolute path (docs/output.md O28), and
checks for every time step: the time values equal the frames' `time` attributes; the point and
cell counts; the cell type (VTK_POLY_VERTEX 2 for particles, VTK_POLY_LINE 4 for bonds, VTK_TRIANGLE 5 for
the footing surface, VTK_HEXAHEDRON 12 for the mesh); every array's name, component count and
values (exactly) against the HDF5 datasets read with h5py; the points against the positions /
vertices / node coordinates. A frame without the footing is an empty grid. No rendering, so no
display is needed.
Usage: pvbatch check_paraview_readers.py RUN_FOLDER
"""
import os
import sys

import h5py
import numpy as np
from paraview import servermanager as sm
from paraview import simple
from vtk.util.numpy_support import vtk_to_numpy

run = os.path.abspath(sys.argv[1])
failures = []

# xmf -> (h5 file, frame subgroup of point arrays, of cell arrays, cell type,
#         (group, dataset) giving the cell count, geometry: static path or frame dataset)
ENTITIES = {
    "particles.xmf": ("dem.h5", "particles", None, 2, ("particles", "position"), "particles/position"),
    "bonds.xmf": ("dem.h5", None, "bonds", 4, ("bonds", "nodes"), "particles/position"),
    "footing.xmf": ("dem.h5", None, None, 5, ("footing", "triangles"), "footing/vertices"),
    "mesh.xmf": ("fdm.h5", "nodes", "zones", 12, None, "/mesh/node_coords"),
}
SKIP = {"position", "nodes"}  # geometry / connectivity, not attributes


def check(cond, msg):
    if not cond:
        failures.append(msg)


def arrays(vtk_fd):
    return {vtk_fd.GetArrayName(i): vtk_to_numpy(vtk_fd.GetArray(i)) for i in range(vtk_fd.GetNumberOfArrays())}


def compare_group(tag, got, group):
    want = {k: group[k][()] for k in group if k not in SKIP}
    check(set(got) == set(want), "%s: arrays %s, expected %s" % (tag, sorted(got), sorted(want)))
    for name, w in want.items():
        if name in got:
            g = got[name].reshape(w.shape) if got[name].size == w.size else got[name]
            check(g.shape == w.shape and np.array_equal(g, w), "%s: array %s differs" % (tag, name))


for reader in ("Xdmf3ReaderT", "Xdmf3ReaderS", "XDMFReader"):
    for xmf, (h5name, pgroup, cgroup, ctype, count_ds, static_geom) in ENTITIES.items():
        path = os.path.join(run, xmf)
        prop = {"FileNames": [path]} if reader == "XDMFReader" else {"FileName": [path]}
        r = getattr(simple, reader)(**prop)
        r.UpdatePipelineInformation()
        times = list(r.TimestepValues)
        with h5py.File(os.path.join(run, h5name), "r") as f:
            frames = [f["frames"][k] for k in sorted(f["frames"])]
            check(times == [fr.attrs["time"] for fr in frames],
                  "%s %s: times %s differ from the frames' time attributes" % (reader, xmf, times))
            for t, fr in zip(times, frames):
                tag = "%s %s t=%r" % (reader, xmf, t)
                r.UpdatePipeline(t)
                d = sm.Fetch(r)
                if d.IsA("vtkMultiBlockDataSet"):
                    d = d.GetBlock(0)
                geom = f[static_geom][()] if static_geom.startswith("/") else fr[static_geom][()]
                ncells = fr[count_ds[0]][count_ds[1]].shape[0] if count_ds else f["/mesh/zone_nodes"].shape[0]
                check(d.GetNumberOfPoints() == geom.shape[0], "%s: %d points, expected %d"
                      % (tag, d.GetNumberOfPoints(), geom.shape[0]))
                check(d.GetNumberOfCells() == ncells, "%s: %d cells, expected %d" % (tag, d.GetNumberOfCells(), ncells))
                types = {d.GetCellType(i) for i in range(d.GetNumberOfCells())}
                check(types == ({ctype} if ncells else set()), "%s: cell types %s, expected {%d}" % (tag, types, ctype))
                if geom.shape[0] > 0:
                    pts = vtk_to_numpy(d.GetPoints().GetData())
                    check(np.array_equal(pts, geom), "%s: points differ from the HDF5 geometry" % tag)
                if pgroup:
                    compare_group(tag + " point data", arrays(d.GetPointData()), fr[pgroup])
                if cgroup:
                    compare_group(tag + " cell data", arrays(d.GetCellData()), fr[cgroup])
        simple.Delete(r)
        print("%-12s %-14s %d time steps checked" % (reader, xmf, len(times)))

if failures:
    print("FAILED:\n  " + "\n  ".join(failures))
    sys.exit(1)
print("all ParaView reader checks passed")
