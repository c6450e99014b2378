"""Read demfdm run folders from Python (Debian's python3 with numpy and h5py; pandas optional).

  import demfdm                                   # PYTHONPATH=launch/py
  run = demfdm.Run("runs/2026-12-02-1200-footing_small-1a2b")
  s, f = run.curve()                              # settlement [m], load [N] of the penetration
  h = run.history("penetrate")                    # h["load"], h["dem.footing_fz_N"], h["time"]
  run.result["peak_N"], run.frame("dem", -1)["position"], run.checkpoints()[-1]["tag"]
  demfdm.compare([run, "runs/other"])             # result values and curve differences

Modules: run (Run, Frame, read_manifest), table (Table, read_csv: columns by raw and friendly
names), comparison (compare, format_table; `python3 -m demfdm RUN...` prints the table), plot (figures,
curves_figure; `python3 -m demfdm.plot RUN [--out DIR]`, imported on demand: it loads matplotlib).
"""
from .comparison import compare, curve_difference, elastic_stiffness, format_table
from .run import BOND_STATES, Frame, FrameInfo, Run, read_manifest
from .table import HAVE_PANDAS, Table, friendly_name, read_csv, split_name

__all__ = ["Run", "BOND_STATES", "Frame", "FrameInfo", "Table", "read_csv", "read_manifest", "compare", "format_table",
           "curve_difference", "elastic_stiffness", "friendly_name", "split_name", "HAVE_PANDAS"]
