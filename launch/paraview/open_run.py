"""Open a demfdm run folder in ParaView (pvpython / pvbatch, ParaView 5.11).

    pvpython launch/paraview/open_run.py RUN_DIR                 # writes RUN_DIR/open_run.pvsm
    xvfb-run -a -s "-screen 0 1280x1024x24" \\
        pvpython launch/paraview/open_run.py RUN_DIR --png OUT.png   # renders the last time step

What it shows (docs/output.md "ParaView"), from the run folder's XDMF sidecars:
  * particles.xmf: the DEM particles as spheres scaled by their radius (Glyph "Sphere" with
    scale array radius and scale factor 2: the glyph sphere has diameter 1, so the drawn
    diameter is 2 x radius), coloured by radius;
  * bonds.xmf: the bonds as lines coloured by their state, categorical (0 intact,
    1 broken in tension, 2 broken in shear);
  * mesh.xmf: the continuum zones coloured by vertical stress, component zz (index 2 of the
    6-component stress: xx yy zz xy yz xz, Pa, tension positive), on a colour range fixed
    over all time steps;
  * footing.xmf: the footing's surface, moving with it.
Entities whose sidecar is absent (a run without [dem.output] or [continuum.output]) are
skipped. By default the view is a half section through the model's centre (plane normal +y,
the front half removed) so the DEM block inside the continuum's pocket is visible;
--no-section shows everything.

Without --png the pipeline is saved as a ParaView state (RUN_DIR/open_run.pvsm, or --state
PATH): `paraview --state=RUN_DIR/open_run.pvsm` opens it in the GUI. --png renders the last
time step and writes the PNG. Either way Debian's pvpython needs an X display (its render
view crashes without one): on a machine without a desktop use xvfb-run, as above. Run it with
pvpython or pvbatch, not python3 (it needs paraview.simple).
"""

import argparse
import os
import sys

# The bond "state" codes dem_node writes into dem.h5 (its BondState enum,
# dem_node/core/include/demfdm/dem/params.hpp; launch/py/demfdm/run.py BOND_STATES), drawn as
# categories in the colours of launch/py/paper_figures.py (fig. 7). Code 0 (a contact that was
# never bonded) is left out unless --contacts.
STATES = [(0, "contact, never bonded", [0.80, 0.80, 0.55]),
          (1, "intact", [0.55, 0.55, 0.55]),
          (2, "softening", [1.00, 0.50, 0.05]),
          (3, "broken: tension", [0.12, 0.47, 0.71]),
          (4, "broken: shear", [0.84, 0.15, 0.16])]
TEXT = [0.0, 0.0, 0.0]


def parse_args(argv):
    p = argparse.ArgumentParser(description="Open a demfdm run folder in ParaView.")
    p.add_argument("run_dir", help="run folder (holds particles.xmf, bonds.xmf, footing.xmf, mesh.xmf)")
    p.add_argument("--png", help="render the last time step to this PNG file")
    p.add_argument("--state", help="save the ParaView state here (default RUN_DIR/open_run.pvsm without --png)")
    p.add_argument("--size", type=int, nargs=2, default=[1280, 960], metavar=("W", "H"),
                   help="image size in pixels (default 1280 960)")
    p.add_argument("--no-section", action="store_true", help="show the whole model, not a half section")
    p.add_argument("--contacts", action="store_true", help="also draw the contacts that were never bonded (state 0)")
    p.add_argument("--particle-opacity", type=float, default=0.35,
                   help="opacity of the particle spheres (default 0.35, so that the bonds inside show)")
    p.add_argument("--time", type=float, help="render this time [s] instead of the last time step")
    p.add_argument("--no-display-check", action="store_true",
                   help="do not stop when no X display is set (for ParaView builds that render without X)")
    return p.parse_args(argv)


def style_bar(bar):
    """Black text on the white background."""
    bar.TitleColor = TEXT
    bar.LabelColor = TEXT
    bar.TitleFontSize = 14
    bar.LabelFontSize = 12


def main(argv):
    args = parse_args(argv)
    run = os.path.abspath(args.run_dir)
    if not os.path.isdir(run):
        sys.exit("open_run.py: '%s' is not a folder" % args.run_dir)
    if sys.platform.startswith("linux") and not args.no_display_check and not os.environ.get("DISPLAY") \
            and not os.environ.get("WAYLAND_DISPLAY"):
        # Debian's ParaView is built for X only: a render view without a display crashes.
        sys.exit("open_run.py: no X display (DISPLAY is not set); run it under xvfb-run:\n"
                 "  xvfb-run -a -s \"-screen 0 1280x1024x24\" pvpython %s %s"
                 % (sys.argv[0], " ".join(argv)))
    try:
        import paraview.simple as pv
    except ImportError:
        sys.exit("open_run.py: paraview.simple not found: run this script with pvpython or pvbatch")

    def sidecar(name):
        # Absolute paths: the XDMF3 readers abort on a bare file name (common/io/README.md).
        path = os.path.join(run, name)
        return path if os.path.isfile(path) else None

    files = {name: sidecar(name + ".xmf") for name in ("particles", "bonds", "footing", "mesh")}
    if not any(files.values()):
        sys.exit("open_run.py: no particles.xmf, bonds.xmf, footing.xmf or mesh.xmf in '%s' "
                 "(the scene writes frames only with [dem.output] / [continuum.output])" % run)

    readers = {}
    for name, path in files.items():
        if path:
            r = pv.Xdmf3ReaderT(registrationName=name, FileName=[path])
            r.UpdatePipelineInformation()
            readers[name] = r

    times = sorted({t for r in readers.values() for t in r.TimestepValues})
    t_show = times[-1] if times else 0.0
    if args.time is not None:
        t_show = min(times, key=lambda t: abs(t - args.time)) if times else args.time

    view = pv.CreateView("RenderView")
    view.ViewSize = list(args.size)
    view.OrientationAxesVisibility = 1
    view.UseColorPaletteForBackground = 0  # needed in 5.11 for Background to apply
    view.Background = [1.0, 1.0, 1.0]
    pv.SetActiveView(view)

    # Model bounds and the section plane through their centre.
    bounds = None
    for name in ("mesh", "particles"):
        if name in readers:
            readers[name].UpdatePipeline(t_show)
            b = readers[name].GetDataInformation().GetBounds()
            if b[0] <= b[1]:
                bounds = b
                break
    centre = [0.5 * (bounds[0] + bounds[1]), 0.5 * (bounds[2] + bounds[3]), 0.5 * (bounds[4] + bounds[5])] \
        if bounds else [0.0, 0.0, 0.0]

    def section(src, name):
        """The half y >= centre (whole cells kept), or src itself with --no-section."""
        if args.no_section:
            return src
        c = pv.Clip(registrationName=name + "_section", Input=src)
        c.ClipType = "Plane"
        c.ClipType.Origin = centre
        c.ClipType.Normal = [0.0, 1.0, 0.0]
        c.Invert = 0        # keep the side the normal points to (y >= centre)
        c.Crinkleclip = 1   # whole cells: zones, bonds and particles are not cut
        return c

    if "mesh" in readers:
        mesh = section(readers["mesh"], "mesh")
        d = pv.Show(mesh, view)
        d.SetRepresentationType("Surface With Edges")
        d.EdgeColor = [0.3, 0.3, 0.3]
        pv.ColorBy(d, ("CELLS", "stress", "ZZ"))
        lut = pv.GetColorTransferFunction("stress")
        lut.VectorMode = "Component"
        lut.VectorComponent = 2
        lut.ApplyPreset("Cool to Warm", True)
        # One colour range over every time step (a frame of zero stress would otherwise give a
        # useless range), from the unclipped zones.
        lo, hi = None, None
        for t in times:
            readers["mesh"].UpdatePipeline(t)
            a = readers["mesh"].CellData["stress"] if "stress" in readers["mesh"].CellData.keys() else None
            if a is None:
                continue
            r = a.GetRange(2)
            lo = r[0] if lo is None else min(lo, r[0])
            hi = r[1] if hi is None else max(hi, r[1])
        if lo is not None:
            if hi <= lo:
                hi = lo + 1.0
            lut.AutomaticRescaleRangeMode = "Never"
            lut.RescaleTransferFunction(lo, hi)
            pv.GetOpacityTransferFunction("stress").RescaleTransferFunction(lo, hi)
        d.SetScalarBarVisibility(view, True)
        bar = pv.GetScalarBar(lut, view)
        bar.Title = "continuum: vertical stress zz [Pa] (tension +)"
        bar.ComponentTitle = ""
        style_bar(bar)

    if "particles" in readers:
        parts = section(readers["particles"], "particles")
        g = pv.Glyph(registrationName="spheres", Input=parts, GlyphType="Sphere")
        g.OrientationArray = ["POINTS", "No orientation array"]
        g.ScaleArray = ["POINTS", "radius"]
        g.ScaleFactor = 2.0  # unit-diameter glyph x 2 radius = the particle's diameter
        g.GlyphMode = "All Points"
        g.GlyphType.ThetaResolution = 12
        g.GlyphType.PhiResolution = 12
        d = pv.Show(g, view)
        d.ColorArrayName = ["POINTS", ""]
        d.AmbientColor = d.DiffuseColor = [0.87, 0.78, 0.60]
        d.Opacity = args.particle_opacity

    if "bonds" in readers:
        bonds = section(readers["bonds"], "bonds")
        states = STATES if args.contacts else STATES[1:]
        if not args.contacts:
            bonds = pv.Threshold(registrationName="bonds_only", Input=bonds)
            bonds.Scalars = ["CELLS", "state"]
            bonds.LowerThreshold = 1
            bonds.UpperThreshold = 255
        d = pv.Show(bonds, view)
        d.SetRepresentationType("Wireframe")
        d.LineWidth = 2.0
        pv.ColorBy(d, ("CELLS", "state"))
        lut = pv.GetColorTransferFunction("state")
        lut.InterpretValuesAsCategories = 1
        lut.AnnotationsInitialized = 1
        lut.Annotations = [x for code, name, _ in states for x in (str(code), name)]
        lut.IndexedColors = [c for _, _, rgb in states for c in rgb]
        d.SetScalarBarVisibility(view, True)
        bar = pv.GetScalarBar(lut, view)
        bar.Title = "bond state"
        style_bar(bar)

    if "footing" in readers:
        foot = section(readers["footing"], "footing")
        d = pv.Show(foot, view)
        d.SetRepresentationType("Surface")
        d.ColorArrayName = ['POINTS', '']
        d.AmbientColor = d.DiffuseColor = [0.35, 0.35, 0.40]
        d.Specular = 0.3

    # The model time of the shown step (docs/output.md "Time": 0 at the beginning of the first
    # stage after the specimen preparation; the DEM's preparation frames are negative).
    clock = pv.AnnotateTime(registrationName="model_time")
    clock.Format = "model time t = {time:.6g} s"
    d = pv.Show(clock, view)
    d.Color = TEXT
    d.FontSize = 14
    d.WindowLocation = "Upper Left Corner"

    # Look at the section face (from -y), slightly from above.
    if bounds:
        size = max(bounds[1] - bounds[0], bounds[3] - bounds[2], bounds[5] - bounds[4])
        view.CameraFocalPoint = centre
        view.CameraPosition = [centre[0] + 0.3 * size, centre[1] - 2.2 * size, centre[2] + 0.8 * size]
        view.CameraViewUp = [0.0, 0.0, 1.0]
        view.CameraParallelProjection = 0
    scene = pv.GetAnimationScene()
    scene.UpdateAnimationUsingDataTimeSteps()
    scene.AnimationTime = t_show
    view.ViewTime = t_show
    if not bounds:
        view.ResetCamera()

    if args.png:
        pv.Render(view)
        pv.SaveScreenshot(os.path.abspath(args.png), view, ImageResolution=list(args.size), CompressionLevel="9")
        print("open_run.py: %s at t = %.9g s (%d time steps) -> %s" % (run, t_show, len(times), args.png))
    state = args.state or (None if args.png else os.path.join(run, "open_run.pvsm"))
    if state:
        pv.SaveState(os.path.abspath(state))
        print("open_run.py: state %s (open it with: paraview --state=%s)" % (state, state))


if __name__ == "__main__":
    main(sys.argv[1:])
