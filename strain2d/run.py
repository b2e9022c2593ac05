"""Run folders: :func:`write_run` writes one, :func:`load_run` reads one back.

A run folder holds ``summary.json`` and ``strain_nodes.csv`` (see
:mod:`strain2d.export`) besides the tables, figures and report that
:func:`write_run` (and ``strain2d analyze``) write; :func:`load_run` checks
both and returns a :class:`Run` with the nodal strain of every frame.  It
reads the 3D runs of ``surface_strain compute`` and ``stereo reconstruct
--strain`` too (their ``strain_nodes.csv`` is the same table with ``X, Y, Z``
and ``U, V, W``), so that a study can combine 2D and 3D specimens.  Anything missing,
unreadable or inconsistent raises :class:`~strain2d.errors.InputError` naming
the file and the problem, so a study over many runs fails with one clear line
instead of a traceback.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from strain2d.errors import InputError

__all__ = ["Run", "check_run_options", "load_run", "write_run"]

#: The nodal strain components a run provides.
COMPONENTS = ("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J")


@dataclass(frozen=True, repr=False)
class Run:
    """The nodal results of one ``analyze`` run.

    Attributes
    ----------
    path : Path
        The run folder.
    summary : dict
        ``summary.json`` as written by ``analyze``.
    times : (T,) float
        Frame times, in ``time_unit``.
    time_unit : {"s", "frame"}
    positions : (T, N, 2) or (T, N, 3) float
        Node positions in ``unit``: pixels for 2D runs (``strain2d analyze``),
        the calibration's unit for 3D ones (``surface_strain compute``,
        ``stereo reconstruct --strain``).
    visible : (T, N) bool
    nodal : dict of (T, N) float
        Nodal strain components (:data:`COMPONENTS`), NaN where undefined.
    endpoint : int
        The contraction endpoint frame recorded by ``analyze`` (detected or
        given), or the last frame for runs that did not record one.
    endpoint_source : str
        ``"detected"``, ``"given"`` or ``"last frame"``.
    unit : str
        Unit of ``positions``.
    """

    path: Path
    summary: dict
    times: np.ndarray
    time_unit: str
    positions: np.ndarray
    visible: np.ndarray
    nodal: dict
    endpoint: int
    endpoint_source: str
    meta: dict = field(default_factory=dict)
    unit: str = "px"

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_points(self) -> int:
        return self.positions.shape[1]

    def at(self, frame: int) -> dict[str, np.ndarray]:
        """Nodal values of every component on ``frame``."""
        if not -self.n_frames <= frame < self.n_frames:
            raise InputError(f"{self.path}: frame {frame} is outside 0..{self.n_frames - 1}")
        return {k: v[frame] for k, v in self.nodal.items()}

    def __repr__(self) -> str:
        return (
            f"Run({str(self.path)!r}, {self.n_frames} frames, {self.n_points} nodes, "
            f"endpoint {self.endpoint})"
        )


def _read_summary(path: Path) -> dict:
    file = path / "summary.json"
    if not file.is_file():
        raise InputError(f"{path} is not an analyze output folder: summary.json is missing")
    try:
        with open(file, encoding="utf-8-sig") as f:
            summary = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{file} cannot be read: {exc}") from None
    if not isinstance(summary, dict) or not isinstance(summary.get("software"), dict):
        raise InputError(f"{file} is not a strain2d summary (no 'software' entry)")
    for key in ("source", "time_axis", "contraction_endpoint"):
        if summary.get(key) is not None and not isinstance(summary[key], dict):
            raise InputError(f"{file}: '{key}' must be an object, got {summary[key]!r}")
    return summary


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _run_folder(path: Path) -> Path:
    """The folder with the run's strain: ``path``, or a stereo reconstruction's ``strain/``."""
    if not (path / "strain_nodes.csv").exists() and (path / "strain" / "strain_nodes.csv").exists():
        return path / "strain"
    return path


def _read_nodes(file: Path):
    """The nodal table of a 2D (``x,y,...``) or 3D (``X,Y,Z,...``) run: (LongTable, axes)."""
    from tissue_core.tables import read_long_table

    if not file.is_file():
        raise InputError(f"{file.parent}: strain_nodes.csv is missing")
    # 2D is the planar case of one schema: x, y (and u, v) without z
    table = read_long_table(
        file, required=("x", "y", "visible", *COMPONENTS), optional=("z",), flags=("visible",)
    )
    return table, ("x", "y", "z") if "z" in table else ("x", "y")


def load_run(path: str | os.PathLike) -> Run:
    """Load a run folder, 2D or 3D.

    Parameters
    ----------
    path : path
        The folder given to ``strain2d analyze --out`` or ``surface_strain
        compute --out``, or to ``stereo reconstruct --strain --out`` (whose
        ``strain/`` holds the run).

    Returns
    -------
    Run

    Raises
    ------
    InputError
        The folder, ``summary.json`` or ``strain_nodes.csv`` is missing,
        unreadable, truncated or inconsistent.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"run folder {path} does not exist")
    if not path.is_dir():
        raise InputError(f"{path} is not a folder: give an analyze output folder")
    folder = _run_folder(path)
    summary = _read_summary(folder)
    file = folder / "strain_nodes.csv"
    table, dims = _read_nodes(file)
    T = table.n_frames
    positions = np.stack([table[d] for d in dims], axis=-1)
    visible = table["visible"] != 0
    # a lost point may have no position (imported tracks, a point stereo lost on the
    # reference frame); a visible one must
    if not np.isfinite(positions[visible]).all():
        raise InputError(f"{file}: positions of visible nodes must be finite")
    nodal = {k: table[k].copy() for k in COMPONENTS}

    frames_used = (summary.get("source") or {}).get("frames_used", summary.get("frames"))
    if frames_used is not None and not _whole(frames_used):
        raise InputError(f"{path / 'summary.json'}: source.frames_used must be a whole number")
    if frames_used is not None and frames_used != T:
        raise InputError(
            f"{folder}: summary.json says {frames_used} frames but strain_nodes.csv has {T}"
        )
    fps = (summary.get("time_axis") or {}).get("fps")
    if fps is not None and (
        isinstance(fps, bool)
        or not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0)
    ):
        raise InputError(f"{path / 'summary.json'}: time_axis.fps must be a positive number")
    step = (summary.get("time_axis") or {}).get("step", 1)
    if not _whole(step) or step < 1:
        raise InputError(f"{path / 'summary.json'}: time_axis.step must be a whole number >= 1")
    times = np.arange(T) * step / fps if fps else np.arange(T, dtype=float)
    ep = summary.get("contraction_endpoint") or {}
    endpoint, source = T - 1, "last frame"
    if "frame" in ep:
        endpoint = ep["frame"]
        if not _whole(endpoint) or not 0 <= endpoint < T:
            raise InputError(
                f"{path / 'summary.json'}: contraction_endpoint.frame must be a frame "
                f"index 0..{T - 1}, got {endpoint!r}"
            )
        source = ep.get("source", "detected")
    unit = "px" if len(dims) == 2 else str(summary.get("unit") or "mm")
    return Run(
        path=path,
        summary=summary,
        times=times,
        time_unit="s" if fps else "frame",
        positions=positions,
        visible=visible,
        nodal=nodal,
        endpoint=int(endpoint),
        endpoint_source=str(source),
        unit=unit,
    )


def check_run_options(
    *,
    fps: float | None = None,
    endpoint: int | None = None,
    endpoint_tolerance: float = 0.05,
    maps_at: Sequence[int] = (),
    min_triangle_quality: float = 0.1,
    figure_format: str | Sequence[str] = "png",
    animation: str = "mp4",
) -> tuple[str, ...]:
    """Check :func:`write_run`'s options before any work; returns the figure formats.

    ``strain2d analyze`` calls it before tracking, so that a bad option costs
    nothing; :func:`write_run` calls it again.
    """
    from strain2d.report import ANIMATIONS, parse_formats

    if fps is not None and not (math.isfinite(fps) and fps > 0):
        raise InputError(f"--fps must be a positive number, got {fps}")
    if not 0 <= min_triangle_quality < 1:
        raise InputError(f"--min-triangle-quality must lie in [0, 1), got {min_triangle_quality}")
    if not 0 < endpoint_tolerance < 1:
        raise InputError(f"--endpoint-tolerance must lie between 0 and 1, got {endpoint_tolerance}")
    for flag, frames in (("--endpoint", [endpoint]), ("--maps-at", list(maps_at))):
        for k in frames:
            if k is not None and (not _whole(k) or k < 0):
                raise InputError(
                    f"{flag} takes frame numbers from 0 (the reference frame), got {k}"
                )
    if animation not in ANIMATIONS:
        raise InputError(f"unknown animation {animation!r}; choose from {', '.join(ANIMATIONS)}")
    return parse_formats(figure_format)


def _frames_of(frames) -> tuple[Callable[[], Iterable[np.ndarray]], Callable[[], tuple]]:
    """(a function that iterates the frames afresh, one that gives the first and last)."""
    if callable(frames) and not hasattr(frames, "__iter__"):
        reopen = frames
    elif not hasattr(frames, "__iter__") or iter(frames) is frames:
        raise InputError(
            "write_run needs the frames twice (first and last, then every frame for the "
            "animation): give an array, a FrameSource, or a function that returns the frames, "
            f"not {type(frames).__name__}"
        )
    else:

        def reopen():
            return iter(frames)

    def ends():
        if hasattr(frames, "ends"):  # strain2d.frames.EndFrames: kept while tracking
            return frames.ends()
        if hasattr(frames, "first") and hasattr(frames, "frame"):  # a FrameSource
            return frames.first(), frames.frame(-1)
        if isinstance(frames, np.ndarray):
            return frames[0], frames[-1]
        first = last = None
        for k, frame in enumerate(reopen()):
            first = frame if k == 0 else first
            last = frame
        return first, last

    return reopen, ends


def _source_info(frames, n_frames: int, shape) -> tuple[list[str], dict]:
    """The input names and the ``source`` entry of ``summary.json``."""
    source = getattr(frames, "source", frames)  # through EndFrames
    names = list(getattr(source, "names", []))
    whole = {"start": 0, "stop": None, "step": 1}
    return names, {
        "kind": getattr(source, "kind", "array"),
        "frames_used": n_frames,
        "frame_range": dict(getattr(source, "frame_range", whole)),
        "frame_size_px": [int(shape[1]), int(shape[0])],
    }


def _points_info(analysis) -> dict:
    shape = analysis.grid_shape
    if shape is None:
        return {}
    points = analysis.tracks.reference if analysis.points is None else analysis.points
    x0, y0 = points.min(axis=0)
    x1, y1 = points.max(axis=0)
    return {
        "grid": f"{shape[0]}x{shape[1]}",
        "grid_shape": list(shape),
        "roi": [float(x0), float(y0), float(x1), float(y1)],
    }


def _uncertainty_summary(tracks) -> dict | None:
    """Median and 95th percentile of the tracker's uncertainty (px), or None."""
    if tracks.uncertainty is None:
        return None
    seen = tracks.uncertainty[1:][tracks.visible[1:]]
    seen = seen[np.isfinite(seen)]
    last = tracks.uncertainty[-1][tracks.visible[-1]]
    last = last[np.isfinite(last)]
    if seen.size == 0:
        return None
    return {
        "meaning": "standard deviation of each coordinate of a tracked position",
        "median": float(np.median(seen)),
        "p95": float(np.percentile(seen, 95)),
        "last_frame_median": float(np.median(last)) if last.size else None,
    }


def _final_stats(field) -> dict:
    from surface_strain import nodal_scalars

    scalars = nodal_scalars(field)
    last = field.n_frames - 1
    out = {}
    for key in ("Exx", "Eyy", "Exy", "E1", "E2", "J"):
        v = scalars[key][last]
        v = v[np.isfinite(v)]
        out[key] = (
            {"mean": v.mean(), "sd": v.std(), "min": v.min(), "max": v.max(), "n": v.size}
            if v.size
            else {"n": 0}
        )
    return out


def _units(scale, fps, uncertainty: bool) -> dict:
    """``summary.json``'s ``units``: the pixel size and every table column's unit."""
    length = None if scale is None else scale.unit
    position = {"x": "px", "y": "px"}
    displacement = {"u": "px", "v": "px"}
    if length:
        position |= {f"x_{length}": length, f"y_{length}": length}
        displacement |= {f"u_{length}": length, f"v_{length}": length}
    strain = dict.fromkeys(("Exx", "Eyy", "Exy", "E1", "E2", "max_shear", "J"), "1")
    tracks = {**position, "visible": "1 (flag)", "quality": "tracker's own (see tracker)"}
    nodes = {**position, **displacement, "visible": "1 (flag)", **strain, "theta1_deg": "degree"}
    if uncertainty:
        extra = {"uncertainty_px": "px"} | ({f"uncertainty_{length}": length} if length else {})
        tracks |= extra
        nodes |= extra
    return {
        "positions": "px",
        "length": length or "px",
        "scale": None if scale is None else scale.to_json(),
        "time": "s" if fps else "frame",
        "strain": "Green-Lagrange, dimensionless",
        "vtp": (
            f"points and displacement in {length or 'px'}; field data length_unit, "
            "time_unit and array_units"
        ),
        "columns": {
            "tracks.csv": tracks,
            "strain_nodes.csv": nodes,
            "strain_elements.csv": {"valid": "1 (flag)", **strain, "theta1_deg": "degree"},
        },
    }


@contextlib.contextmanager
def _figure_pool(pool, workers: int | None):
    """``pool``, ended on an error (its workers may be writing into the run's temporary
    folder, which the error removes next), or a pool of ``workers`` for this run."""
    from strain2d.figures._pool import FigurePool

    if pool is None:
        with FigurePool(workers) as made:
            yield made
        return
    try:
        yield pool
    except BaseException:
        pool.cancel()
        raise


def _write_tables(folder: Path, tracks, field, times, time_unit: str, length: dict) -> float:
    """The run's tables and ParaView series in ``folder`` (a task for a worker process);
    returns the seconds they took."""
    import time

    from strain2d.export import write_pvd, write_strain_elements_csv, write_strain_nodes_csv
    from strain2d.tracks import write_tracks_csv

    started = time.perf_counter()
    write_tracks_csv(folder / "tracks.csv", tracks, **length)
    write_strain_nodes_csv(folder / "strain_nodes.csv", field, tracks.uncertainty, **length)
    write_strain_elements_csv(folder / "strain_elements.csv", field)
    write_pvd(folder, field, name="strain", times=times, time_unit=time_unit, **length)
    return time.perf_counter() - started


def write_run(
    out: str | os.PathLike,
    analysis,
    frames,
    *,
    fps: float | None = None,
    endpoint: int | None = None,
    endpoint_tolerance: float = 0.05,
    maps_at: Sequence[int] = (),
    animation: str = "mp4",
    figure_format: str | Sequence[str] = "png",
    points_info: dict | None = None,
    overwrite: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
    progress=None,
    runtime_s: dict | None = None,
    scale=None,
    workers: int | None = None,
    pool=None,
    mask=None,
    log: Callable[[], str] | None = None,
    cycle: int | None = None,
    maps_at_peaks: bool = False,
    signals=None,
    trigger: str | None = None,
) -> dict:
    """Write the run folder of an analysis: what ``strain2d analyze --out`` writes.

    ``tracks.csv``, ``strain_nodes.csv``, ``strain_elements.csv``, the ParaView
    series ``strain.pvd``, ``figures/``, ``statistics.json``, ``summary.json``
    (schema :data:`surface_strain.RUN_SCHEMA`) and ``report.html``, written
    into a temporary folder and renamed into place (see
    :func:`tissue_core.outputs.atomic_dir`); :func:`load_run` reads it back.

    Parameters
    ----------
    out : path
        The run folder; it must not exist unless ``overwrite``.
    analysis : Analysis
        From :func:`strain2d.analyze`.
    frames : (T, H, W) array, FrameSource, sequence, or callable
        The video the points were tracked on (for the figures and the
        animation), read twice: an array or a :class:`~strain2d.FrameSource`
        (whose file names, kind and frame range go into ``summary.json``), a
        list of frames, or a function that returns a fresh iterable of
        ``(H, W)`` frames (not a generator, which can be read only once).
    fps : float, keyword-only
        Frame rate: time axes in seconds instead of frames.
    endpoint : int, keyword-only
        The contraction endpoint frame; detected when None.
    endpoint_tolerance : float, keyword-only
        Endpoint detection: the mean strains' rate, as a fraction of its
        largest value, below which the tissue counts as still.
    maps_at : sequence of int, keyword-only
        Frames that also get contour maps.
    animation : {"mp4", "gif", "none"}, keyword-only
    figure_format : str or sequence of {"png", "svg", "pdf"}, keyword-only
    points_info : dict, keyword-only
        Extra entries for ``summary.json``'s ``points`` (e.g. ``points_file``).
    overwrite : bool, keyword-only
        Replace an existing run folder written by the toolkit.
    inputs : sequence of path, keyword-only
        Further files the output may not replace (the video's are known).
    progress : callable(done, total), keyword-only
        Called as the figures and the animation are made.
    runtime_s : dict, keyword-only
        Timings to record (the command line passes tracking and strain).  The
        time a streamed field (:func:`surface_strain.streamed_strain`) spends
        computing its frames while the outputs are written is added to
        ``strain`` (but where a worker process writes the tables).  Then, in
        seconds of the clock: ``tables`` (the tables and the ParaView series,
        written by a worker process when there is one) and ``animation``
        (written here); ``figures``, from the start of the writing until the
        last figure was drawn (by worker processes, meanwhile); ``report``
        (``summary.json`` and ``report.html``); ``outputs``, the whole writing
        less the strain.
    scale : PixelScale or str, keyword-only
        The pixel size (``"0.012mm/px"``, see :mod:`strain2d.scale`): the
        tables gain positions and displacements in its unit (``x_mm``...),
        the figures' axes and the ParaView files are in it, and
        ``summary.json`` records it.  Strain does not depend on it.
    workers : int, keyword-only
        Processes that draw the figures meanwhile: default one per core this
        process may use (none with one core, or in a daemonic process such as
        a Dask worker's); 0 draws them here.  The files are the same.
    pool : strain2d.figures._pool.FigurePool, keyword-only
        Workers already started (``FigurePool(warm=True)`` entered before the
        tracking, as ``strain2d analyze`` does, so that they load Matplotlib
        while it tracks); ``workers`` is then ignored.  Ended on an error.
    mask : tissue_core.masks.Mask, keyword-only
        The tissue mask the points were placed in: outlined on the reference
        frame of the tracked-grid figure.
    cycle : int, keyword-only
        With repeated contractions (two cycles or more, :mod:`strain2d.cycles`),
        the cycle (1, 2, ...) whose peak is the endpoint; default the largest.
        The cycles go into ``summary.json`` (``cycles``), ``cycles.csv``,
        ``cycles_nodes.csv`` and ``figures/cycles.png``.
    maps_at_peaks : bool, keyword-only
        Draw strain maps at every cycle's peak too (``--maps-at peaks``).
    signals : strain2d.signals.Signals, keyword-only
        The lab's signals aligned to the frames (``--signals``): into
        ``signals.csv``, ``figures/strain_and_signals.png`` and ``summary.json``.
    trigger : str, keyword-only
        The signal whose pulses start the cycles (``--trigger``).
    log : callable, keyword-only
        Returns the command's log so far (its timestamped steps and warnings,
        :meth:`tissue_core.progress.Progress.recorded`), written last as
        ``run.log``; ``strain2d analyze`` gives it.

    Returns
    -------
    dict
        The run's summary, as written to ``summary.json``.

    Examples
    --------
    >>> from sample_data_synth.cases import make_case
    >>> from strain2d import analyze, make_grid, write_run
    >>> video = make_case("equibiaxial", size=160, n_frames=4)
    >>> grid = make_grid((160, 160), shape=(3, 3), roi=video.truth.roi)
    >>> result = analyze(video.frames, grid, tracker="klt", grid_shape=(3, 3))
    >>> import tempfile, pathlib
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "run"
    >>> summary = write_run(out, result, video.frames, animation="none")
    >>> load_run(out).n_points
    9
    """
    import time
    import warnings
    from datetime import UTC, datetime

    from strain2d.figures import plot_tracked_grid
    from strain2d.report import run_outputs, write_run_report
    from surface_strain import RUN_SCHEMA, Mesh
    from tissue_core.html import sequence_record
    from tissue_core.jsonio import write_json
    from tissue_core.outputs import atomic_dir, recorded_command
    from tissue_core.version import __version__

    formats = check_run_options(
        fps=fps,
        endpoint=endpoint,
        endpoint_tolerance=endpoint_tolerance,
        maps_at=maps_at,
        figure_format=figure_format,
        animation=animation,
    )
    if isinstance(scale, str):
        from strain2d.scale import parse_scale

        scale = parse_scale(scale)
    length = {} if scale is None else {"length_scale": scale.per_px, "length_unit": scale.unit}
    tracks, field = analysis.tracks, analysis.field
    T = tracks.n_frames
    for flag, ks in (("--endpoint", [endpoint]), ("--maps-at", list(maps_at))):
        bad = [k for k in ks if k is not None and k >= T]
        if bad:
            raise InputError(f"{flag} {bad[0]} is outside the frames 0..{T - 1}")
    reopen, ends = _frames_of(frames)
    first_img, last_img = ends()
    names, source = _source_info(frames, T, first_img.shape)
    # --step N uses every N-th frame of the video: N / fps seconds between the frames used
    step = int((getattr(frames, "frame_range", None) or {}).get("step", 1) or 1)
    times = np.arange(T) * step / fps if fps else np.arange(T)
    t_start = time.perf_counter()
    # a streamed field's strain is computed while the outputs below read it: its time counts
    # as the strain's, not the figures'
    strain_before = getattr(field, "seconds_computing", 0.0)
    if not np.isfinite(field.nodal_E[-1]).any():
        warnings.warn(
            "no node has a valid strain on the last frame: every triangle lost a point",
            UserWarning,
            stacklevel=2,
        )
    mesh = analysis.mesh or Mesh(field.triangles, "given", "given")
    tracker = analysis.tracker or tracks.meta.get("tracker") or "unknown"
    spent: dict[str, float] = {}
    # the video's files are inputs too: no output may replace them; the figures and the
    # tables are written by worker processes (when there are cores for them) while the
    # animation is written here
    with (
        atomic_dir(out, overwrite=overwrite, inputs=[*inputs, *names]) as tmp,
        _figure_pool(pool, workers) as pool,
    ):
        figs = tmp / "figures"
        figs.mkdir()
        grid = pool.submit(
            plot_tracked_grid,
            figs / "tracked_grid",
            first_img,
            last_img,
            tracks,
            field.triangles,
            formats=formats,
            length=scale,
            outline=[] if mask is None else mask.outline(),
        )

        tables: list = []  # the tables, written by a worker once the figures are on their way

        def meanwhile() -> None:
            tables.append(
                pool.submit(_write_tables, tmp, tracks, field, times, "s" if fps else "frame",
                            length)
            )  # fmt: skip

        extra = run_outputs(
            tmp,
            field,
            tracks,
            frames=reopen,
            times=times,
            time_unit="s" if fps else "frame",
            endpoint=endpoint,
            relative_tolerance=endpoint_tolerance,
            map_frames=list(maps_at),
            animation=animation,
            animation_fps=fps or 10.0,
            formats=formats,
            progress=progress,
            length=scale,
            images={0: first_img, T - 1: last_img},
            pool=pool,
            meanwhile=meanwhile,
            runtime_s=spent,
            cycle=cycle,
            maps_at_peaks=maps_at_peaks,
            signals=signals,
            trigger=trigger,
        )
        spent["tables"] = tables[0].result()
        extra["figures"].insert(
            0,
            {
                "files": [f"figures/{p.name}" for p in grid.result()],
                "caption": "The tracked grid and mesh on the reference and the last frame; "
                "lost points are red crosses.",
            },
        )
        spent["figures"] = time.perf_counter() - t_start
        reporting = time.perf_counter()
        command = recorded_command.get()
        summary = {
            "schema": RUN_SCHEMA,
            "software": {"name": "strain2d", "version": __version__},
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "command": list(command) if command else None,
            "inputs": names,
            "input_files": [sequence_record(names)] if names else [],
            "source": source,
            # name, options, and whatever else the tracker reports (dic: reference updates)
            "tracker": {
                "name": tracker,
                **{k: v for k, v in tracks.meta.items() if k != "tracker"},
            },
            "points": {"n": tracks.n_points, **_points_info(analysis), **(points_info or {})},
            "mesh": {
                "method": "grid, alternating diagonals" if mesh.method == "grid" else mesh.method,
                "n_triangles": field.n_triangles,
                "min_triangle_quality": (
                    analysis.min_triangle_quality if mesh.method == "delaunay" else None
                ),
            },
            "time_axis": {
                "fps": fps,
                "unit": "s" if fps else "frame",
                **({"step": step} if step != 1 else {}),
            },
            "lost_points_last_frame": int((~tracks.visible[-1]).sum()),
            "tracking_uncertainty_px": _uncertainty_summary(tracks),
            "final_frame": {"index": T - 1, "nodal_strain": _final_stats(field)},
            "contraction_endpoint": extra["contraction_endpoint"],
            "quality": extra["quality"],
            "flags": extra["flags"],
            "statistics": extra["statistics"],
            **({"cycles": extra["cycles"]} if extra["cycles"] is not None else {}),
            **({"signals": extra["signals"]} if extra["signals"] is not None else {}),
            "units": _units(scale, fps, tracks.uncertainty is not None),
            "pixel_convention": "x = column, y = row, centre of the top-left pixel at (0, 0)",
            "outputs": sorted(
                [
                    *(str(p.relative_to(tmp)) for p in tmp.rglob("*") if p.is_file()),
                    "report.html",
                    "summary.json",
                    *(["run.log"] if log is not None else []),
                ]
            ),
            "figures": extra["figures"],
        }
        strain_s = getattr(field, "seconds_computing", 0.0) - strain_before
        times = dict(runtime_s or {})
        if strain_s:
            times["strain"] = times.get("strain", 0.0) + strain_s
        summary["runtime_s"] = {**times, **spent}
        write_json(tmp / "summary.json", summary)
        write_run_report(tmp, summary)
        ended = time.perf_counter()
        summary["runtime_s"] |= {
            "report": ended - reporting,
            "outputs": ended - t_start - strain_s,
        }
        write_json(tmp / "summary.json", summary)
        if log is not None:
            (tmp / "run.log").write_text(log(), encoding="utf-8")
    return summary
