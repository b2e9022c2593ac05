"""Before / after: two stacks of one specimen, aligned, their metrics compared.

:func:`compare_stacks` is what ``python -m mpm3d compare`` runs.  Both
stacks are analysed in full (:func:`mpm3d.analyze.analyze_stack`); their
height maps are aligned laterally by phase correlation, refined with
point-to-plane ICP on the surfaces when open3d is installed (the ``3d``
extra); every metric's change is reported.  It writes::

    OUT/compare.json       alignment, both metric sets, every change
    OUT/changes.csv        metric, before, after, change, ratio
    OUT/figures/compare_heightmaps.png
    OUT/before/, OUT/after/  each stack's full analysis (as ``analyze`` writes it)
    OUT/report.html        one self-contained page: inputs, parameters, changes with
                           units, alignment and measurement quality, figures, flags
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from mpm3d.analyze import Analysis, analyze_stack, write_analysis
from mpm3d.errors import InputError, SourceError
from tissue_core.csvtext import csv_writer
from tissue_core.jsonio import write_json

__all__ = [
    "align_heightmaps",
    "compare_stacks",
    "icp_refine",
    "metric_changes",
    "write_comparison",
]

log = logging.getLogger(__name__)

#: least overlap correlation of two aligned height maps for them to count as the same surface
MATCH_CORRELATION = 0.5

#: metrics whose change is reported (numbers in metrics.json)
COMPARED = (
    "fold_wavelength_um",
    "fold_height_um",
    "max_fold_height_um",
    "n_folds",
    "fold_orientation_deg",
    "fold_coherency",
    "Sa_um",
    "Sq_um",
    "Ssk",
    "Sku",
    "Sp_um",
    "Sv_um",
    "Sz_um",
    "Sdr_percent",
)


def align_heightmaps(
    before: np.ndarray, after: np.ndarray, *, spacing: tuple[float, float]
) -> dict:
    """Lateral shift of ``after`` relative to ``before`` by phase correlation.

    Both maps (same shape and pixel size) have their least-squares plane
    removed and a Hann window applied; the shift is refined to 1/20 pixel
    (Guizar-Sicairos et al., Opt. Lett. 33 (2008) 156,
    doi:10.1364/OL.33.000156), then measured once more after moving
    ``after`` by it, which removes the pull of the shared window towards
    zero shift.

    Returns
    -------
    dict
        ``shift_x_um``, ``shift_y_um`` (move ``after`` by minus these to
        overlay ``before``) and ``overlap_correlation``, the correlation
        of the two form-removed maps where they overlap once aligned (near 1
        for the same surface; near 0 when the surfaces have nothing in
        common, as a contracted specimen's new folds may not),
        ``overlap_fraction`` (share of the map both cover once aligned) and
        ``residual_rms_um``, the root mean square of their difference there
        (form removed): what the alignment leaves unexplained.

    Examples
    --------
    The same rough surface seen again 5 rows lower and 3 columns to the left:

    >>> from scipy import ndimage
    >>> big = ndimage.gaussian_filter(np.random.default_rng(0).normal(size=(200, 200)), 3)
    >>> a = align_heightmaps(big[50:146, 50:146], big[45:141, 53:149], spacing=(2.0, 2.0))
    >>> round(a["shift_y_um"]), round(a["shift_x_um"]), a["overlap_correlation"] > 0.99
    (10, -6, True)
    """
    from scipy import ndimage
    from skimage.registration import phase_cross_correlation

    from mpm3d.metrics import detrend

    if before.shape != after.shape:
        raise InputError(f"height maps differ in shape: {before.shape} and {after.shape}")
    window = np.hanning(before.shape[0])[:, None] * np.hanning(before.shape[1])[None, :]
    ref = detrend(before, spacing=spacing)
    b = detrend(after, spacing=spacing)
    shift, _, _ = phase_cross_correlation(ref * window, b * window, upsample_factor=20)
    # the window both maps share pulls the peak towards zero shift (by up to ~0.2 px):
    # measure once more what is left after moving `after` by the first estimate
    moved = ndimage.shift(b, shift, order=3, mode="nearest")
    rest, _, _ = phase_cross_correlation(ref * window, moved * window, upsample_factor=20)
    shift = shift + rest
    dy, dx = spacing
    # skimage gives the shift that moves `b` onto `a`; report how `after` moved
    moved = ndimage.shift(b, shift, order=1, cval=np.nan)
    both = np.isfinite(moved)
    r = float(np.corrcoef(ref[both], moved[both])[0, 1]) if both.sum() > 2 else float("nan")
    residual = (
        float(np.sqrt(np.mean((ref[both] - moved[both]) ** 2))) if both.any() else float("nan")
    )
    return {
        "shift_x_um": float(-shift[1] * dx),
        "shift_y_um": float(-shift[0] * dy),
        "overlap_correlation": r,
        "overlap_fraction": float(both.mean()),
        "residual_rms_um": residual,
    }


def _open3d():
    try:
        import open3d
    except ImportError as exc:
        raise InputError(
            "ICP refinement needs open3d: pip install 'tissue-strain[3d]' "
            "(and the system library libusb-1.0-0)"
        ) from exc
    return open3d


def icp_refine(
    before_mesh, after_mesh, *, shift_xy_um: tuple[float, float], max_points: int = 60_000
) -> dict:
    """Rigid point-to-plane ICP of ``after`` onto ``before`` (open3d).

    Starts from the phase-correlation shift; returns how the centre of
    ``after`` moved (um, the sign of :func:`align_heightmaps`' shift), the
    rotation angle (degrees), the ICP fitness (share of points paired) and
    inlier RMSE (um), and ``matched`` (fitness at least 0.5: below it the
    surfaces do not correspond and the transform means nothing).
    """
    o3d = _open3d()

    def cloud(mesh):
        pts = np.asarray(mesh.points, np.float64)
        nrm = np.asarray(mesh.point_normals, np.float64)
        step = max(1, len(pts) // max_points)
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts[::step]))
        pc.normals = o3d.utility.Vector3dVector(nrm[::step])
        return pc

    source, target = cloud(after_mesh), cloud(before_mesh)
    init = np.eye(4)
    init[0, 3], init[1, 3] = -shift_xy_um[0], -shift_xy_um[1]
    extent = np.ptp(np.asarray(before_mesh.points), axis=0)
    radius = 0.05 * float(np.hypot(extent[0], extent[1]))
    result = o3d.pipelines.registration.registration_icp(
        source,
        target,
        radius,
        init,
        o3d.pipelines.registration.TransformationEstimationPointToPlane(),
    )
    t = np.asarray(result.transformation)  # maps `after` onto `before`
    angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(t[:3, :3]) - 1) / 2))))
    centre = np.asarray(after_mesh.points, np.float64).mean(axis=0)
    moved = centre - (t[:3, :3] @ centre + t[:3, 3])  # how `after`'s centre moved
    fitness = float(result.fitness)
    return {
        "translation_um": [float(v) for v in moved],
        "rotation_deg": angle,
        "fitness": fitness,
        "inlier_rmse_um": float(result.inlier_rmse),
        "matched": fitness >= 0.5,
    }


def metric_changes(before: dict, after: dict) -> list[dict]:
    """One row per compared metric: before, after, change and ratio."""
    rows = []
    for key in COMPARED:
        a, b = before.get(key), after.get(key)
        row = {"metric": key, "before": a, "after": b, "change": None, "ratio": None}
        if isinstance(a, int | float) and isinstance(b, int | float):
            row["change"] = b - a
            if key == "fold_orientation_deg":  # an axis: the change lies in (-90, 90]
                row["change"] = 90.0 - (90.0 - (b - a)) % 180.0
            elif a != 0:
                row["ratio"] = b / a
        rows.append(row)
    return rows


def _resample(height: np.ndarray, spacing, target_shape, target_spacing) -> np.ndarray:
    from scipy import ndimage

    dy, dx = spacing
    ty, tx = target_spacing
    rows = np.arange(target_shape[0]) * ty / dy
    cols = np.arange(target_shape[1]) * tx / dx
    rr, cc = np.meshgrid(rows, cols, indexing="ij")
    return ndimage.map_coordinates(height, [rr, cc], order=1, mode="nearest")


def _namer(label: str, path: str | os.PathLike) -> Callable[[object], str]:
    """A message about one side, naming the side and the stack."""
    name = os.fspath(path)

    def named(message: object) -> str:
        text = str(message)
        return f"{label} stack: {text}" if name in text else f"{label} stack {name}: {text}"

    return named


def _check_side(label: str, path: str | os.PathLike, options: dict) -> None:
    """The checks of one side's file that need no pixel: its pages and bytes (truncation), its
    type and axes, the spacing and the channel asked for; errors name the side."""
    from mpm3d.io import _channel_index
    from mpm3d.lazyio import open_stack_lazily

    named = _namer(label, path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the analysis says them, once
            stack = open_stack_lazily(path, spacing=options.get("spacing"))
        try:
            if options.get("channel") is not None:
                _channel_index(options["channel"], stack.channel_names)
        finally:
            stack.data.close()
    except InputError as exc:
        raise InputError(named(exc)) from exc
    except OSError as exc:  # SourceError, and the system's own (permissions)
        raise SourceError(named(exc)) from exc


def _analyze_side(
    label: str, path: str | os.PathLike, say: Callable[[str], None], options: dict
) -> Analysis:
    """:func:`analyze_stack` on one side; its errors and warnings name the side and the stack.

    Two stacks go through the same steps with the same options, so an error
    such as "no surface found" must say which stack it is about.
    """
    named = _namer(label, path)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            analysis = analyze_stack(path, progress=lambda m: say(f"{label}: {m}"), **options)
    except InputError as exc:
        raise InputError(named(exc)) from exc
    except OSError as exc:  # SourceError, and the system's own (permissions, a full disk)
        raise SourceError(named(exc)) from exc
    finally:
        for record in caught:  # shown even when the analysis failed
            if issubclass(record.category, UserWarning):
                warnings.warn(record.category(named(record.message)), stacklevel=3)
            else:
                warnings.warn_explicit(
                    record.message, record.category, record.filename, record.lineno
                )
    return analysis


def compare_stacks(
    before: str | os.PathLike,
    after: str | os.PathLike,
    *,
    icp: bool | None = None,
    progress: Callable[[str], None] | None = None,
    **options,
) -> tuple[dict, Analysis, Analysis]:
    """Analyse two stacks, align them and compare every metric.

    Parameters
    ----------
    before, after : path
    icp : bool, optional
        Refine the alignment by ICP (open3d); by default when open3d is
        installed.
    **options
        Passed to :func:`mpm3d.analyze.analyze_stack` for both stacks.

    Returns
    -------
    report, before_analysis, after_analysis
    """
    say = progress or (lambda message: None)
    if icp:  # fail before the analyses, not after them
        if not options.get("surface", True):
            raise InputError("ICP refinement needs the isosurfaces: drop --no-surface")
        _open3d()
    for label, path in (("before", before), ("after", after)):
        _check_side(label, path, options)  # a broken after stack: before the first analysis
    first = _analyze_side("before", before, say, options)
    second = _analyze_side("after", after, say, options)
    sp_b = first.heightmap.spacing[1:]
    sp_a = second.heightmap.spacing[1:]
    h_b = first.height_um
    h_a = _resample(second.height_um, sp_a, h_b.shape, sp_b)
    say("aligning")
    try:
        alignment = align_heightmaps(h_b, h_a, spacing=sp_b)
    except InputError as exc:
        raise InputError(
            f"aligning the before stack {before} with the after stack {after}: {exc}"
        ) from exc
    if icp is None:
        try:
            import open3d  # noqa: F401

            icp = True
        except ImportError:
            icp = False
            alignment["icp"] = "skipped: open3d is not installed (the '3d' extra)"
    if icp and first.surface is not None and second.surface is not None:
        alignment["icp"] = icp_refine(
            _held(first.surface),
            _held(second.surface),
            shift_xy_um=(alignment["shift_x_um"], alignment["shift_y_um"]),
        )
    elif icp:
        alignment["icp"] = "skipped: no isosurfaces (--no-surface)"
    r = alignment["overlap_correlation"]
    alignment["matched"] = bool(r >= MATCH_CORRELATION)
    alignment["note"] = (
        f"the surfaces match where they overlap (correlation {r:.2f}): the shift locates "
        "the second stack on the first"
        if alignment["matched"]
        else f"the surfaces do not match (correlation {r:.2f} < {MATCH_CORRELATION}), as "
        "when folds form or move: the shift is not meaningful and the metrics are compared "
        "over each whole field of view"
    )
    report = {
        "inputs": first.metrics["inputs"] + second.metrics["inputs"],
        "before": first.metrics,
        "after": second.metrics,
        "alignment": alignment,
        "changes": metric_changes(first.metrics, second.metrics),
        "software": first.metrics["software"],
        "command": first.metrics.get("command"),
    }
    return report, first, second


def write_comparison(
    report: dict, first: Analysis, second: Analysis, folder: str | os.PathLike, *, figures=True
) -> None:
    """Write a comparison into an existing, empty ``folder``, ``report.html`` last."""
    from mpm3d.report import write_comparison_report

    folder = Path(folder)
    for name, analysis in (("before", first), ("after", second)):
        (folder / name).mkdir()
        write_analysis(analysis, folder / name, figures=figures)
    with open(folder / "changes.csv", "w", newline="", encoding="utf-8") as f:
        columns = ["metric", "before", "after", "change", "ratio"]
        w = csv_writer(f)
        w.writerow(columns)
        for row in report["changes"]:
            w.writerow(["" if row.get(k) is None else row[k] for k in columns])
    if figures:
        from mpm3d.figures import plot_comparison
        from mpm3d.metrics import detrend

        (folder / "figures").mkdir()
        fb = first.metrics
        sb = report["after"]
        titles = (
            f"before ({fb['input']}): folds {fb['fold_height_um'] or 0:.0f} µm high",
            f"after ({sb['input']}): folds {sb['fold_height_um'] or 0:.0f} µm high",
        )
        plot_comparison(
            detrend(first.height_um, spacing=first.heightmap.spacing),
            detrend(second.height_um, spacing=second.heightmap.spacing),
            spacing_before=first.heightmap.spacing,
            spacing_after=second.heightmap.spacing,
            titles=titles,
        ).savefig(folder / "figures" / "compare_heightmaps.png")
        report["figures"] = [
            {
                "file": "figures/compare_heightmaps.png",
                "caption": "Both height maps with their least-squares planes removed, on one "
                "colour scale (µm), each in its own stack's frame (not shifted).",
            }
        ]
    write_json(folder / "compare.json", report)
    write_comparison_report(folder, report)


def _held(mesh, max_points: int = 60_000):
    """A mesh ICP can take: an in-memory one as it is; of a
    :class:`mpm3d.meshstream.DiskMesh`, every k-th point with its normal (as
    :func:`icp_refine` thins a mesh's points itself; its extent and centre then come
    from these points)."""
    import pyvista as pv

    from mpm3d.meshstream import CHUNK, DiskMesh

    if not isinstance(mesh, DiskMesh):
        return mesh
    step = max(1, mesh.n_points // max_points)
    points, normals = [], []
    for start in range(0, mesh.n_points, CHUNK):
        first = (-start) % step
        points.append(mesh.points(start, start + CHUNK)[first::step])
        normals.append(mesh.normals(start, start + CHUNK)[first::step])
    cloud = pv.PolyData(np.concatenate(points))
    cloud.point_data["Normals"] = np.concatenate(normals)
    cloud.point_data.active_normals_name = "Normals"
    return cloud
