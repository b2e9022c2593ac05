"""Open a strain series in ParaView and save a picture of it.

    pvpython scripts/open_in_paraview.py RESULT/strain.pvd [--array E1] [--out picture.png]

Runs with ParaView's own Python (``pvpython``, shipped with ParaView); it
loads the ``.pvd`` time series that ``python -m surface_strain compute``,
``python -m stereo reconstruct --strain`` and ``python -m strain2d analyze``
write, colours the last frame by a strain array and saves a screenshot.
"""

import argparse
import sys

try:
    from paraview import simple
except ImportError:
    sys.exit("this script needs ParaView's pvpython (https://www.paraview.org/download/)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pvd", help="the strain.pvd file")
    parser.add_argument("--array", default="E1", help="point array to colour by (default E1)")
    parser.add_argument("--out", default="strain_paraview.png", help="screenshot to write")
    args = parser.parse_args()
    reader = simple.OpenDataFile(args.pvd)
    if reader is None:
        sys.exit(f"ParaView cannot open {args.pvd}")
    times = reader.TimestepValues or [0.0]
    view = simple.GetActiveViewOrCreate("RenderView")
    view.ViewTime = times[-1] if hasattr(times, "__len__") else times
    display = simple.Show(reader, view)
    simple.ColorBy(display, ("POINTS", args.array))
    display.SetScalarBarVisibility(view, True)
    view.ResetCamera()
    simple.SaveScreenshot(args.out, view, ImageResolution=[1000, 800])
    print(
        f"{args.pvd}: {len(times) if hasattr(times, '__len__') else 1} time steps; "
        f"picture in {args.out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
