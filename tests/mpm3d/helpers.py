"""Small helpers shared by the mpm3d tests."""

from pathlib import Path

from mpm3d.cli import main

#: what ``mpm3d analyze`` writes without the surface and the figures
TABLES = frozenset(
    {
        "metrics.json",
        "folds.csv",
        "crests.csv",
        "heightmap.tif",
        "surface_intensity.tif",
        "report.html",
    }
)


def cli(*argv) -> int:
    """``main`` as the shell sees it: argparse's own errors leave by SystemExit."""
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def listing(folder: Path) -> set[str]:
    """Every path below ``folder``, relative, with forward slashes."""
    return {p.relative_to(folder).as_posix() for p in Path(folder).rglob("*")}


def rel_err(value, truth) -> float:
    return abs(value - truth) / abs(truth)


def axis_diff(a, b) -> float:
    """Difference of two axis directions in degrees, in [0, 90]."""
    d = (a - b) % 180.0
    return min(d, 180.0 - d)
