"""The source paper's Table 1 on synthetic videos with exact ground truth.

For every case of :mod:`sample_data_synth.cases` and every tracker that works
on frames, a grid (7 x 7 as in the paper) is placed on frame 0 over the
case's region, tracked to the last frame, meshed and turned into nodal
strain.  Reported, as in the
paper (eqs. 14-15): tracking RMSE and SD of the point error magnitude (px),
RMSE and SD of the signed nodal strain error per component against the
analytic strain at the nodes, and run time.

Each case also gets a row ``exact positions``: the strain computed from the
true positions on the same grid.  It is the discretization floor of that grid
(zero for the paper's homogeneous cases; on the heterogeneous fields it shows
what the grid spacing alone costs), so a tracker's strain error above that
row is what tracking adds.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from strain2d.pipeline import strain_from_tracks, track
from strain2d.trackers import available_trackers
from strain2d.tracks import Tracks

__all__ = [
    "PAPER_TABLE1",
    "benchmark_markdown",
    "check_benchmark_grid",
    "error_stats",
    "run_benchmark",
]

#: CoTracker3 results from the paper's Table 1: track (RMSE, SD) px; E (RMSE, SD) per component.
PAPER_TABLE1 = {
    "equibiaxial": {
        "track": (1.31, 0.62),
        "Exx": (0.0073, 0.0053),
        "Eyy": (0.0123, 0.0109),
        "Exy": (0.0047, 0.004),
    },
    "rotation": {
        "track": (1.29, 0.64),
        "Exx": (0.0033, 0.0031),
        "Eyy": (0.0045, 0.0043),
        "Exy": (0.0037, 0.0035),
    },
    "shear": {
        "track": (1.21, 0.59),
        "Exx": (0.0058, 0.0051),
        "Eyy": (0.0063, 0.0061),
        "Exy": (0.0045, 0.0041),
    },
    "tissue": {
        "track": (1.48, 0.81),
        "Exx": (0.0052, 0.0049),
        "Eyy": (0.0067, 0.0056),
        "Exy": (0.0042, 0.0039),
    },
}


def _tracker_runs(trackers: Sequence[str]) -> list[tuple[str, str, dict]]:
    """(label, tracker, options) for each tracker; dic also with its quadratic warp."""
    runs = []
    for name in trackers:
        runs.append((name, name, {}))
        if name == "dic":
            runs.append(("dic (quadratic)", "dic", {"shape_function": "quadratic"}))
    return runs


def error_stats(errors: np.ndarray) -> dict[str, float]:
    """RMSE and spatial SD (eqs. 14-15 of the paper, ddof = 0) of finite errors."""
    e = np.asarray(errors, dtype=float)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"rmse": float("nan"), "sd": float("nan"), "n": 0}
    return {"rmse": float(np.sqrt(np.mean(e**2))), "sd": float(np.std(e)), "n": int(e.size)}


def _size(quick: bool) -> tuple[int, int]:
    """The benchmark's frame size and frame count."""
    return (400, 11) if quick else (800, 31)


def check_benchmark_grid(
    grid: tuple[int, int], *, quick: bool = False, cases: Sequence[str] | None = None
) -> None:
    """Refuse a grid too dense for a case's region (:func:`strain2d.grid.check_grid_spacing`)."""
    from sample_data_synth import CASES
    from strain2d.grid import check_grid_spacing

    size, _ = _size(quick)
    for case in list(CASES) if cases is None else cases:
        x0, y0, x1, y1 = (f * (size - 1) for f in CASES[case].roi)
        check_grid_spacing(grid, (x1 - x0, y1 - y0))


def run_benchmark(
    *,
    quick: bool = False,
    cases: Sequence[str] | None = None,
    trackers: Sequence[str] | None = None,
    grid: tuple[int, int] = (7, 7),
    seed: int = 0,
    figures: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Run the benchmark and return its results as a JSON-ready dict.

    Parameters
    ----------
    quick : bool, keyword-only
        400 x 400 px and 11 frames instead of the paper's 800 x 800 px (31 frames).
    cases : keyword-only
        Subset of the case names (default all four).
    trackers : keyword-only
        Tracker names (default every registered tracker that reads frames and needs no
        outside model, i.e. not cotracker3).
    grid : (n_cols, n_rows), keyword-only
    seed : int, keyword-only
    figures : path, keyword-only
        Folder for error-contour figures, one per case and tracker (none if None).
    progress : callable(message), keyword-only
        Called with a short line before each case and tracker.
    """
    from sample_data_synth import CASES, make_case

    cases = list(CASES) if cases is None else list(cases)
    check_benchmark_grid(grid, quick=quick, cases=cases)
    registry = available_trackers()
    if trackers is None:
        trackers = [n for n, spec in registry.items() if spec.needs_frames and not spec.needs_model]
    size, n_frames = _size(quick)
    rows = []
    for case in cases:
        if progress:
            progress(f"rendering {case} ({size}x{size} px, {n_frames} frames)")
        video = make_case(case, size=size, n_frames=n_frames, rng=seed)
        truth = video.truth
        points = truth.grid(grid)
        last = n_frames - 1
        true_pos = truth.positions(points, last)
        true_E = truth.strain(points, last)
        ones = np.ones((n_frames, len(points)))
        exact = Tracks(truth.positions(points), ones.astype(bool), ones)
        exact_E = strain_from_tracks(exact, grid_shape=grid).nodal_E[last]
        rows.append(
            _row(
                case,
                "exact positions",
                np.zeros(len(points)),
                exact_E - true_E,
                true_pos - points,
                np.ones(len(points), bool),
                0.0,
                0.0,
                true_E,
            )
        )
        for name, tracker, options in _tracker_runs(trackers):
            if progress:
                progress(f"  {case}: tracking with {name}")
            t0 = time.perf_counter()
            tracks = track(video.frames, points, tracker=tracker, options=options)
            t_track = time.perf_counter() - t0
            field = strain_from_tracks(tracks, grid_shape=grid)
            t_total = time.perf_counter() - t0
            vis = tracks.visible[last]
            dist = np.linalg.norm(tracks.positions[last] - true_pos, axis=1)
            err = field.nodal_E[last] - true_E
            rows.append(
                _row(
                    case,
                    name,
                    np.where(vis, dist, np.nan),
                    err,
                    true_pos - points,
                    vis,
                    t_track,
                    t_total,
                    true_E,
                )
            )
            if figures:
                from strain2d.figures import plot_strain_errors

                plot_strain_errors(
                    Path(figures) / f"{case}_{re.sub(r'[^0-9a-z]+', '_', name).strip('_')}.png",
                    video.frames[last],
                    field,
                    last,
                    err,
                    title=f"{case}, {name}: nodal strain error on frame {last}",
                )
    return {
        "setup": {
            "image_size": [size, size],
            "n_frames": n_frames,
            "grid": list(grid),
            "seed": seed,
            "quick": quick,
            "measured_on": "final frame, nodal strain, grid initialized on frame 0",
        },
        "results": rows,
        "paper_cotracker3": PAPER_TABLE1,
    }


def _row(case, tracker, dist, err, disp, vis, t_track, t_total, true_E) -> dict:
    return {
        "case": case,
        "tracker": tracker,
        "track_px": error_stats(dist),
        "Exx": error_stats(err[:, 0, 0]),
        "Eyy": error_stats(err[:, 1, 1]),
        "Exy": error_stats(err[:, 0, 1]),
        "max_displacement_px": float(np.max(np.linalg.norm(disp, axis=1))),
        "lost_points": int((~vis).sum()),
        "n_points": len(vis),
        "time_s": {"tracking": t_track, "total": t_total},
        "true_E_range": {
            k: [float(true_E[:, i, j].min()), float(true_E[:, i, j].max())]
            for k, (i, j) in (("Exx", (0, 0)), ("Eyy", (1, 1)), ("Exy", (0, 1)))
        },
    }


def _fmt(stat: dict, digits: int) -> str:
    return f"{stat['rmse']:.{digits}f} / {stat['sd']:.{digits}f}"


def benchmark_markdown(results: dict) -> str:
    """A Markdown table laid out like the paper's Table 1 (RMSE / SD in each cell)."""
    setup = results["setup"]
    lines = [
        f"Synthetic benchmark, {setup['image_size'][0]}x{setup['image_size'][1]} px, "
        f"{setup['n_frames']} frames, {setup['grid'][0]}x{setup['grid'][1]} grid, "
        "errors on the final frame as RMSE / SD.",
        "",
        "| case | tracker | tracking error (px) | Exx | Eyy | Exy | lost | time (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    by_case: dict[str, list] = {}
    for row in results["results"]:
        by_case.setdefault(row["case"], []).append(row)
    for case, rows in by_case.items():
        for row in rows:
            if row["tracker"] == "exact positions":
                cells = " | ".join(_fmt(row[k], 4) for k in ("Exx", "Eyy", "Exy"))
                lines.append(f"| {case} | exact positions (grid floor) | 0 | {cells} | - | - |")
                continue
            lines.append(
                f"| {case} | {row['tracker']} | {_fmt(row['track_px'], 3)} | "
                f"{_fmt(row['Exx'], 4)} | {_fmt(row['Eyy'], 4)} | {_fmt(row['Exy'], 4)} | "
                f"{row['lost_points']}/{row['n_points']} | {row['time_s']['total']:.2f} |"
            )
        paper = results["paper_cotracker3"].get(case)
        if paper:
            cells = [f"{paper[k][0]:.4f} / {paper[k][1]:.4f}" for k in ("Exx", "Eyy", "Exy")]
            lines.append(
                f"| {case} | paper (CoTracker3) | {paper['track'][0]:.2f} / {paper['track'][1]:.2f}"
                f" | {' | '.join(cells)} | - | - |"
            )
    return "\n".join(lines) + "\n"


#: What each sweep varies, its values, and the cases it runs on.
SWEEPS = {
    "grid": ("grid points per side", (7, 11, 15, 21, 31), ("gaussian", "fold")),
    "noise": ("read noise (gray levels)", (0.0, 1.0, 2.0, 4.0, 8.0), ("equibiaxial",)),
    "contrast": ("speckle contrast", (0.1, 0.2, 0.4, 0.8), ("equibiaxial",)),
    "density": ("speckle density", (0.25, 0.5, 1.0, 1.5), ("equibiaxial",)),
    "subset": ("subset / window size (px)", (15, 21, 31, 41), ("gaussian", "equibiaxial")),
}


def run_sweep(
    kind: str,
    *,
    quick: bool = False,
    trackers: Sequence[str] | None = None,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Errors as one parameter varies (see :data:`SWEEPS`), beyond the paper.

    ``grid`` re-tracks one video per case with denser and denser grids and
    shows the spatial-resolution trade-off together with the grid floor
    (strain from exact positions); ``subset`` re-tracks a 15 x 15 grid with
    smaller and larger subsets (``dic``) and windows (``klt``), the other
    half of that trade-off; ``noise``, ``contrast`` and ``density`` re-render
    the equibiaxial case with the changed image and track a 7 x 7 grid.  Errors are
    on the final frame, as in :func:`run_benchmark`.
    """
    from sample_data_synth import make_case

    if kind not in SWEEPS:
        raise ValueError(f"unknown sweep {kind!r}; choose from {', '.join(SWEEPS)}")
    label, values, cases = SWEEPS[kind]
    registry = available_trackers()
    if trackers is None:
        trackers = [n for n, spec in registry.items() if spec.needs_frames and not spec.needs_model]
    size, n_frames = _size(quick)
    last = n_frames - 1
    rows = []
    for case in cases:
        video = None
        for value in values:
            if progress:
                progress(f"sweep {kind}: {case}, {label} = {value}")
            render = {"read_noise": value} if kind == "noise" else {}
            if kind == "contrast":
                render = {"speckle_contrast": value}
            elif kind == "density":
                render = {"speckle_density": value}
            if video is None or kind not in ("grid", "subset"):
                video = make_case(case, size=size, n_frames=n_frames, rng=seed, **render)
            grid = {"grid": (int(value), int(value)), "subset": (15, 15)}.get(kind, (7, 7))
            points = video.truth.grid(grid)
            true_E = video.truth.strain(points, last)
            true_pos = video.truth.positions(points, last)
            ones = np.ones((n_frames, len(points)))
            exact = Tracks(video.truth.positions(points), ones.astype(bool), ones)
            runs = [("exact positions", exact, 0.0)]
            for name, tracker, options in _tracker_runs(trackers):
                if kind == "subset":
                    size_option = {"dic": "subset", "gdic": "subset", "klt": "window"}.get(tracker)
                    options = {**options, size_option: int(value)} if size_option else options
                t0 = time.perf_counter()
                tracks = track(video.frames, points, tracker=tracker, options=options)
                runs.append((name, tracks, time.perf_counter() - t0))
            for name, tracks, seconds in runs:
                field = strain_from_tracks(tracks, grid_shape=grid)
                vis = tracks.visible[last]
                dist = np.linalg.norm(tracks.positions[last] - true_pos, axis=1)
                row = _row(
                    case,
                    name,
                    np.where(vis, dist, np.nan),
                    field.nodal_E[last] - true_E,
                    true_pos - points,
                    vis,
                    seconds,
                    seconds,
                    true_E,
                )
                row["value"] = value
                rows.append(row)
    return {
        "sweep": kind,
        "parameter": label,
        "setup": {"image_size": [size, size], "n_frames": n_frames, "seed": seed, "quick": quick},
        "results": rows,
    }


def sweep_markdown(results: dict) -> str:
    """A Markdown table of a sweep: one row per case, value and tracker."""
    setup = results["setup"]
    lines = [
        f"Sweep of {results['parameter']}, {setup['image_size'][0]} px, {setup['n_frames']} "
        "frames, final frame, RMSE of the tracking error (px) and of each strain component.",
        "",
        f"| case | {results['parameter']} | tracker | tracking (px) | Exx | Eyy | Exy | lost |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in results["results"]:
        track_cell = (
            "0" if row["tracker"] == "exact positions" else f"{row['track_px']['rmse']:.3f}"
        )
        cells = " | ".join(f"{row[k]['rmse']:.4f}" for k in ("Exx", "Eyy", "Exy"))
        lines.append(
            f"| {row['case']} | {row['value']:g} | {row['tracker']} | {track_cell} | {cells} | "
            f"{row['lost_points']}/{row['n_points']} |"
        )
    return "\n".join(lines) + "\n"
