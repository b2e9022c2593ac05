"""Per-run figures, statistics and the run's ``report.html``.

:func:`run_outputs` is what ``strain2d analyze`` calls after tracking: it
finds the contraction endpoint (or takes the one given), draws the figures
(contour maps at chosen frames and at the endpoint with one colour scale for
all frames, principal directions as crosses, mean +/- spatial SD curves,
violins with the node-level tests, an animation of the field on the video),
and computes the run's statistics.  :func:`write_run_report` turns the run
folder and its ``summary.json`` into a self-contained ``report.html``.
"""

from __future__ import annotations

import base64
import math
import os
import tempfile
import uuid
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from strain2d.errors import InputError
from strain2d.stats import contraction_endpoint, paired_node_tests
from strain2d.tracks import Tracks
from surface_strain import CYCLE_COMPONENTS, StrainField, nodal_scalars, write_cycles_csv
from tissue_core.html import HtmlReport, format_value, input_records
from tissue_core.jsonio import write_json

__all__ = [
    "FIGURE_FORMATS",
    "endpoint_of",
    "parse_formats",
    "run_outputs",
    "study_outputs",
    "write_run_report",
    "write_study",
    "write_study_report",
]

FIGURE_FORMATS = ("png", "svg", "pdf")
#: largest change of the mean strains (from the reference) that counts as no deformation
NO_DEFORMATION = 1e-4
ANIMATIONS = ("mp4", "gif", "none")


def parse_formats(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"png,svg"`` -> ``("png", "svg")``; PNG is always included (the report embeds it)."""
    items = text.split(",") if isinstance(text, str) else list(text)
    formats = [f.strip().lower().lstrip(".") for f in items if f.strip()]
    bad = [f for f in formats if f not in FIGURE_FORMATS]
    if bad:
        raise InputError(
            f"unknown figure format {bad[0]!r}; choose from {', '.join(FIGURE_FORMATS)}"
        )
    return tuple(dict.fromkeys(["png", *formats]))


def _mean_curves(field: StrainField, components: Sequence[str]) -> np.ndarray:
    """(T, C) mean nodal value of each component per frame (NaN on frames without one)."""
    from strain2d.figures import mean_strain_curves

    means = mean_strain_curves(field, components)["mean"]
    return np.column_stack([means[c] for c in components])


def endpoint_of(
    field: StrainField,
    *,
    times: np.ndarray | None = None,
    frame: int | None = None,
    rate_tolerance: float | None = None,
    relative_tolerance: float = 0.05,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    min_change: float = NO_DEFORMATION,
    curves: np.ndarray | None = None,
) -> dict:
    """The contraction endpoint of a run: detected from the mean strains, or ``frame``.

    ``curves``: the mean strains ``(T, len(components))`` when they are at hand (a
    streamed field computes its strain again for each pass over it).

    When the mean strains never move more than ``min_change`` away from
    their reference values, there is no contraction to find an endpoint of:
    the source is ``"none: no deformation ..."`` and the last frame is used.

    Returns a dict for ``summary.json``: ``frame``, ``time``, ``source``
    (``"detected"`` or ``"given"``, else why there is none), the method and
    tolerance, and the detected frame even when one was given, so the two can
    be compared.
    """
    T = field.n_frames
    if frame is not None and not 0 <= frame < T:
        raise InputError(f"--endpoint {frame} is outside the frames 0..{T - 1}")
    t = np.arange(T, dtype=float) if times is None else np.asarray(times, float)
    if curves is None:
        curves = _mean_curves(field, components)
    valid = np.flatnonzero(np.isfinite(curves).all(axis=1))
    last_valid = int(valid[-1]) if valid.size else -1
    change = float(np.abs(curves[valid] - curves[valid[:1]]).max()) if valid.size else 0.0
    detected, status = None, "detected"
    if last_valid < 2:
        status = "too few frames with strain to detect it; the last frame is used"
    elif change < min_change:
        status = (
            f"none: no deformation (the mean {', '.join(components)} change by at most "
            f"{change:.1e} over the video, below {min_change:g}); the last frame is used"
        )
    else:
        # frames after the last one with data tell nothing: detect on the rest
        detected = contraction_endpoint(
            curves[: last_valid + 1],
            times=t[: last_valid + 1],
            rate_tolerance=rate_tolerance,
            relative_tolerance=relative_tolerance,
        )
        if detected == last_valid < T - 1:
            status = (
                f"not reached: the strain is unknown after frame {last_valid} (points lost), "
                "and still changing there"
            )
        elif detected == T - 1:
            status = "not reached: still deforming at the last frame"
    if frame is not None:
        chosen, source = frame, "given"
    else:
        chosen = T - 1 if detected is None else detected
        source = status
    kind = _deformation_kind(curves[chosen], components)
    if source == "given":
        label = f"{kind} endpoint (given)"
    elif source == "detected":
        label = f"{kind} endpoint"
    elif source.startswith("not reached"):
        label = f"last frame ({kind} endpoint not reached)"
    elif source.startswith("none"):
        label = "last frame (no deformation)"
    else:
        label = "last frame"
    return {
        "frame": int(chosen),
        "time": float(t[chosen]),
        "label": label,
        "deformation": kind,
        "source": source,
        "detected_frame": detected,
        "detection": status,
        "method": (
            f"last frame into which the rate of the mean {', '.join(components)} exceeds "
            + (
                f"{rate_tolerance:g} per time unit"
                if rate_tolerance is not None
                else f"{relative_tolerance:g} x its largest value"
            )
        ),
    }


def run_cycles(
    field: StrainField,
    times: np.ndarray,
    *,
    stimulus: np.ndarray | None = None,
    sigma_px: float | None = None,
    curves: np.ndarray | None = None,
) -> dict | None:
    """The contraction cycles of a run (:func:`surface_strain.find_run_cycles` on its
    mean strains, ``curves`` when they are at hand), or None without any.  ``sigma_px``,
    the tracker's median uncertainty, sets the noise the peaks must stand out of
    (:func:`surface_strain.mean_strain_noise`)."""
    from surface_strain import find_run_cycles, mean_strain_noise

    if curves is None:
        curves = _mean_curves(field, CYCLE_COMPONENTS)
    noise = None
    if sigma_px is not None and np.isfinite(sigma_px) and sigma_px > 0:
        noise = mean_strain_noise(field.reference, field.triangles, float(sigma_px))
    return find_run_cycles(curves, times, stimulus=stimulus, noise=noise)


def _cycle_endpoint(ep: dict, cycles: dict, cycle: int | None, times) -> dict:
    """The endpoint at the peak of cycle ``cycle`` (1, 2, ...; default the largest)."""
    rows = cycles["cycles"]
    if cycle is None:
        index = cycles["largest"]
        if index is None:
            return ep
        why = f"the largest of {len(rows)}"
    else:
        if not 1 <= cycle <= len(rows):
            raise InputError(f"--cycle {cycle}: the run has cycles 1..{len(rows)}")
        index = cycle - 1
        if rows[index]["peak"] is None:
            raise InputError(f"--cycle {cycle}: that stimulus pulse has no contraction")
        why = f"cycle {cycle} of {len(rows)}, given"
    cycles["chosen"] = index
    k = int(rows[index]["peak"])
    kind = _deformation_kind(cycles["curves"][k], CYCLE_COMPONENTS)
    return {
        **ep,
        "frame": k,
        "time": float(np.asarray(times, float)[k]),
        "label": f"peak of cycle {index + 1} of {len(rows)}",
        "deformation": kind,
        "source": "cycle",
        "cycle": index + 1,
        "detection": f"peak of cycle {index + 1} ({why}) of the repeated contractions",
    }


def _write_signals(folder: Path, signals, curves: np.ndarray, times, unit: str) -> Path:
    """``signals.csv``: per frame its time, each signal aligned to it and the mean strains."""
    from tissue_core.csvtext import csv_writer, number_cell
    from tissue_core.outputs import replaced_on_success

    path = folder / "signals.csv"
    time_column = "time_s" if unit == "s" else "time_frame"
    with replaced_on_success(path) as tmp, open(tmp, "w", newline="") as f:
        writer = csv_writer(f, lineterminator="\n")
        writer.writerow(["frame", time_column, *signals.names,
                         *(f"{c}_mean" for c in CYCLE_COMPONENTS)])  # fmt: skip
        for k in range(signals.values.shape[0]):
            writer.writerow([k, number_cell(times[k]), *(number_cell(v) for v in signals.values[k]),
                             *(number_cell(v) for v in curves[k])])  # fmt: skip
    return path


#: a mean normal strain below this share of the larger one is taken as none in naming the
#: deformation: the tissue's shortening, not the trackers' noise on the other axis, names it
_MINOR_SHARE = 0.2


def _deformation_kind(mean: np.ndarray, components: Sequence[str]) -> str:
    """ "contraction" when the mean normal strains at a frame are both <= 0 (not both 0),
    "stretch" when both >= 0, else "deformation" (one shortens, the other stretches).

    A normal strain under :data:`_MINOR_SHARE` of the larger does not count, so that a
    contraction along one axis with tracking noise on the other (-0.008 and +0.0003) is
    a contraction with any tracker, not a contraction with one and a deformation with
    another."""
    normal = [float(mean[j]) for j, c in enumerate(components) if c in ("Exx", "Eyy")]
    normal = [v for v in normal if math.isfinite(v)]
    if not normal or all(abs(v) < NO_DEFORMATION for v in normal):
        return "deformation"
    largest = max(abs(v) for v in normal)
    normal = [v for v in normal if abs(v) >= _MINOR_SHARE * largest]
    if all(v <= 0 for v in normal):
        return "contraction"
    if all(v >= 0 for v in normal):
        return "stretch"
    return "deformation"


class _FigureLog:
    """The ``figures/`` folder of a run or study and the list of what went into it."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.dir = folder / "figures"
        self.dir.mkdir(exist_ok=True)
        self.items: list[dict] = []

    def add(self, paths, caption: str) -> None:
        files = [str(Path(p).relative_to(self.folder)) for p in paths]
        self.items.append({"files": files, "caption": caption})


def _capture(
    frames: Iterable[np.ndarray],
    wanted: set[int],
    seen: Callable[[int, np.ndarray], None],
) -> Iterable[np.ndarray]:
    """The frames, passing those in ``wanted`` to ``seen(k, image)`` on the way."""
    for k, image in enumerate(frames):
        if k in wanted:
            seen(k, np.array(image))
        yield image


def _saved(make: Callable, path: Path, formats: Sequence[str], *args, **kwargs) -> list[Path]:
    """``make(*args, **kwargs)``'s figure, saved (a task for a worker process)."""
    from strain2d.figures import save_figure

    return save_figure(make(*args, **kwargs), path, formats)


def _tests_and_violins(
    path: Path, formats: Sequence[str], a: str, b: str, nodal: dict, positions, n_boot: int,
    frame: int, title: str,
) -> tuple[dict, list[Path]]:  # fmt: skip
    """The node-level paired tests of ``a`` against ``b`` and the violins that show them."""
    from strain2d.figures import plot_strain_violins, save_figure

    try:
        tests = paired_node_tests(nodal[a], nodal[b], positions=positions, n_boot=n_boot)
        tests["label"] = "node-level paired t-test"
    except InputError as exc:  # too few nodes with values on that frame
        tests = {"error": f"frame {frame}: {exc}"}
    values = {c: v[np.isfinite(v)] for c, v in nodal.items()}
    fig = plot_strain_violins(values, title=title, tests=None if "error" in tests else tests)
    return tests, save_figure(fig, path, formats)


def run_outputs(
    folder: str | os.PathLike,
    field: StrainField,
    tracks: Tracks,
    *,
    frames: Callable[[], Iterable[np.ndarray]],
    times: np.ndarray,
    time_unit: str,
    endpoint: int | None = None,
    rate_tolerance: float | None = None,
    relative_tolerance: float = 0.05,
    map_frames: Sequence[int] = (),
    animation: str = "mp4",
    animation_fps: float = 10.0,
    formats: Sequence[str] = ("png",),
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    n_boot: int = 2000,
    progress: Callable[[int, int | None], None] | None = None,
    length=None,
    images: Mapping[int, np.ndarray] | None = None,
    pool=None,
    meanwhile: Callable[[], None] | None = None,
    runtime_s: dict | None = None,
    cycle: int | None = None,
    maps_at_peaks: bool = False,
    signals=None,
    trigger: str | None = None,
) -> dict:
    """Write a run's figures and ``statistics.json`` into ``folder``; return summary entries.

    Parameters
    ----------
    folder : path
        The run folder (``figures/`` is created in it).
    frames : callable
        Returns a fresh iterable over the video's frames (``(H, W)`` gray),
        one per field frame; called once at most.
    times : (T,) float
        Frame times in ``time_unit`` (``"s"`` or ``"frame"``).
    endpoint : int, optional
        The contraction endpoint frame; detected when None (see :func:`endpoint_of`
        for ``rate_tolerance`` and ``relative_tolerance``).
    map_frames : sequence of int
        Frames that get contour maps besides the endpoint and the last frame.
    animation : {"mp4", "gif", "none"}
    formats : sequence of {"png", "svg", "pdf"}
        Every figure is written in each format (animations excepted).
    length : PixelScale, optional
        The pixel size (``--scale``): image axes in its unit.
    images : dict, optional
        ``{frame: (H, W) image}`` already read (the first and the last, say):
        their figures need not wait for the video to be read to them.
    pool : strain2d.figures._pool.FigurePool, optional
        Where the figures are drawn (worker processes) while this function
        writes the animation; default here, one after the other.
    meanwhile : callable, optional
        Called once the figures that need no frame of the video are on their
        way, before the animation (:func:`strain2d.write_run` writes the
        tables then).
    runtime_s : dict, optional
        Filled with the seconds the animation took (``animation``).
    cycle : int, optional
        With repeated contractions (:func:`run_cycles`), the cycle (1, 2, ...)
        whose peak is the endpoint; default the largest.
    maps_at_peaks : bool
        Draw maps at every cycle's peak too.
    signals : strain2d.signals.Signals, optional
        The lab's signals aligned to the frames: ``signals.csv`` (each with
        the mean strains) and ``figures/strain_and_signals.png``.
    trigger : str, optional
        The signal whose pulses start the cycles (a stimulus).

    Returns
    -------
    dict
        ``contraction_endpoint``, ``statistics``, ``cycles`` (None with one
        contraction) and ``figures`` (a list of {``files``, ``caption``}) for
        ``summary.json``.
    """
    import time

    from strain2d import figures as fg
    from strain2d.figures._pool import FigurePool

    folder = Path(folder)
    T = field.n_frames
    if animation not in ANIMATIONS:
        raise InputError(f"unknown animation {animation!r}; choose from {', '.join(ANIMATIONS)}")
    bad = [k for k in map_frames if not 0 <= k < T]
    if bad:
        raise InputError(f"--maps-at frame {bad[0]} is outside the frames 0..{T - 1}")
    pool = FigurePool(0) if pool is None else pool
    # the mean strains, once (a streamed field computes its strain again for each pass)
    wanted = tuple(dict.fromkeys([*components, *CYCLE_COMPONENTS]))
    mean_curves = fg.mean_strain_curves(field, wanted)
    means = np.column_stack([mean_curves["mean"][c] for c in CYCLE_COMPONENTS])
    ep = endpoint_of(
        field,
        times=times,
        frame=endpoint,
        rate_tolerance=rate_tolerance,
        relative_tolerance=relative_tolerance,
        curves=means,
    )
    quality = fg.run_quality(tracks, field)
    unc = quality["uncertainty_median_px"]
    with warnings.catch_warnings():  # frames without an uncertainty
        warnings.simplefilter("ignore", RuntimeWarning)
        sigma_all = None if unc is None else float(np.nanmedian(np.asarray(unc, dtype=float)))
    stimulus = None if trigger is None else signals.column(trigger)
    cycles = run_cycles(field, times, stimulus=stimulus, sigma_px=sigma_all, curves=means)
    repeated = cycles is not None and cycles["repeated"]
    if repeated and endpoint is None:
        # repeated contractions: the endpoint is a cycle's peak (the largest by default)
        ep = _cycle_endpoint(ep, cycles, cycle, times)
    elif cycle is not None:
        raise InputError(
            f"--cycle {cycle}: the run has "
            + ("one contraction or none" if not repeated else "an endpoint given by --endpoint")
        )
    k_end = ep["frame"]
    end_name = ep["label"]
    peaks = [] if cycles is None else [c["peak"] for c in cycles["cycles"] if c["peak"] is not None]
    maps = sorted({*map_frames, k_end, T - 1, *(peaks if maps_at_peaks else [])})
    peak_names = (
        {}
        if not repeated
        else {int(c["peak"]): f"peak of cycle {c['cycle']}" for c in cycles["cycles"]
              if c["peak"] is not None}
    )  # fmt: skip
    unit = "s" if time_unit == "s" else "frame"

    def when(k: int) -> str:
        return f"frame {k}" + (f" (t = {times[k]:.3g} s)" if unit == "s" else "")

    log = _FigureLog(folder)
    figdir, record = log.dir, log.add
    limits = fg.strain_limits(field, components, cover=maps)  # no node of a map saturates
    sigma = None if unc is None else unc[k_end]  # the median over the endpoint's points
    noise = fg.principal_noise_floor(field, sigma, frame=k_end) if sigma is not None else 0.0
    noise = noise if np.isfinite(noise) else 0.0

    # the figures on a frame of the video, as soon as the frame is at hand
    drawn: dict[int, object] = {}
    crosses = None

    def draw_on(k: int, image: np.ndarray) -> None:
        nonlocal crosses
        if k in drawn:
            return
        what = end_name if k == k_end else peak_names.get(k, "last frame" if k == T - 1 else "")
        drawn[k] = pool.submit(
            _saved,
            fg.strain_maps_figure,
            figdir / f"strain_frame{k:04d}",
            formats,
            image,
            field,
            k,
            components=components,
            limits=limits,
            title=f"{when(k)}: {what}" if what else when(k),
            length=length,
        )
        if k == k_end:
            crosses = pool.submit(
                _saved,
                fg.plot_principal_crosses,
                figdir / f"principal_directions_frame{k_end:04d}",
                formats,
                image,
                field,
                k_end,
                noise=noise,
                length=length,
                title=f"principal strains at {when(k_end)}\n{end_name}",
            )

    # the maps on frames at hand first: they take longest
    for k, image in (images or {}).items():
        if k in maps:
            draw_on(k, np.asarray(image))
    # then the figures that need no frame of the video
    node = nodal_scalars(field)
    a, b = "Exx", "Eyy"
    at_end = {c: np.asarray(node[c][k_end]) for c in (a, b, "Exy")}
    tests = pool.submit(
        _tests_and_violins,
        figdir / f"violins_frame{k_end:04d}",
        formats,
        a,
        b,
        at_end,
        np.asarray(field.points[k_end]),
        n_boot,
        k_end,
        f"nodal strain at {when(k_end)}: {end_name}",
    )
    curves = pool.submit(
        _saved,
        fg.plot_strain_curves,
        figdir / "strain_curves",
        formats,
        field,
        times=times,
        time_unit=unit,
        components=components,
        endpoint=k_end,
        curves={k: {c: v[c] for c in components} for k, v in mean_curves.items()},
    )
    tracking = pool.submit(
        _saved,
        fg.plot_run_quality,
        figdir / "tracking_quality",
        formats,
        quality,
        times,
        time_unit=unit,
        tracker=str(tracks.meta.get("tracker", "")),
        length=length,
    )

    drawn_signals = None
    if signals is not None:
        from surface_strain import activity

        _, main, _ = activity(means, CYCLE_COMPONENTS)
        strain = means[:, CYCLE_COMPONENTS.index(main)]
        _write_signals(folder, signals, means, times, unit)
        drawn_signals = pool.submit(
            _saved,
            fg.plot_strain_and_signals,
            figdir / "strain_and_signals",
            formats,
            times,
            strain,
            main,
            signals.names,
            signals.values,
            time_unit=unit,
        )
    drawn_cycles = None
    if repeated:  # one contraction: the strain curves show it
        drawn_cycles = pool.submit(
            _saved,
            fg.plot_cycles,
            figdir / "cycles",
            formats,
            times,
            cycles["curves"],
            CYCLE_COMPONENTS,
            {k: v for k, v in cycles.items() if k != "curves"},
            time_unit=unit,
        )
    if meanwhile is not None:
        meanwhile()
    # one pass over the video: the animation, and the frames under the maps not yet at hand
    wanted = set(maps) - set(drawn)
    if animation != "none":
        started = time.perf_counter()
        path = figdir / f"strain_animation.{animation}"
        fg.write_strain_animation(
            path,
            _capture(frames(), wanted, draw_on),
            field,
            components=tuple(c for c in components if c != "Exy")[:2] or tuple(components[:1]),
            limits=limits,
            fps=animation_fps,
            time_labels=[when(k) for k in range(T)],
            progress=progress,
            length=length,
        )
        record([path], f"Strain field over time on the video ({animation.upper()}).")
        if runtime_s is not None:
            runtime_s["animation"] = time.perf_counter() - started
    elif wanted:
        for k, _ in enumerate(_capture(frames(), wanted, draw_on)):
            if k >= max(wanted):
                break
    missing = set(maps) - set(drawn)
    if missing:
        raise InputError(f"the video ended before frame {min(missing)}")

    for k in maps:
        what = end_name if k == k_end else peak_names.get(k, "last frame" if k == T - 1 else "")
        record(
            drawn[k].result(),
            f"Nodal strain on the deformed grid at {when(k)}"
            + (f", the {what}" if what else "")
            + "; the colour scale is the same at every frame.",
        )
    if sigma is None:
        noise_text = (
            "The tracker does not measure its uncertainty, so crosses are drawn wherever "
            "E1 differs from E2."
        )
    else:
        noise_text = (
            f"Crosses only where E1 - E2 exceeds {noise:.2g}, the 95th percentile that the "
            f"tracking noise alone ({sigma:.2g} px, median uncertainty) gives on this mesh; "
            "elsewhere the directions are not measured and an open circle shows the mean "
            "principal strain."
        )
    record(
        crosses.result(),
        f"Principal strain directions at {when(k_end)}, the {end_name}: arm lengths "
        f"proportional to |E1| and |E2|, red = stretch, blue = shortening. {noise_text}",
    )
    record(
        curves.result(),
        "Mean nodal strain over time with a band of +/- one spatial SD over the nodes.",
    )
    tests, paths = tests.result()
    record(
        paths,
        f"Distribution of the nodal strains at the {end_name}, with the node-level "
        f"paired tests of {a} against {b} (descriptive: nodes of one specimen are not "
        "independent).",
    )
    record(
        tracking.result(),
        "Quality of the measurement over time: the points still tracked and the mesh area "
        "with a valid strain (top); the tracker's own quality over the tracked points, median "
        "and 5th percentile, and its measured uncertainty where it has one (bottom).",
    )
    values = {c: v[np.isfinite(v)] for c, v in at_end.items()}
    quality_summary = _quality_summary(quality, sigma, noise, unit)
    flags = _run_flags(
        quality_summary, ep, field, values, noise, tracks.meta.get("reference_updates")
    )

    table = {}
    for key in ("Exx", "Eyy", "Exy", "E1", "E2", "J"):
        v = node[key][k_end]
        v = v[np.isfinite(v)]
        table[key] = (
            {
                "mean": float(v.mean()),
                "sd": float(v.std(ddof=1)) if v.size > 1 else float("nan"),
                "min": float(v.min()),
                "max": float(v.max()),
                "n": int(v.size),
            }
            if v.size
            else {"n": 0}
        )
    statistics = {
        "principal_direction_noise_floor": noise,
        "frame": k_end,
        "frame_meaning": end_name,
        "nodal_strain": table,
        "paired": {"components": [a, b], **tests},
    }
    write_json(folder / "statistics.json", statistics)
    if drawn_signals is not None:
        record(
            drawn_signals.result(),
            f"The signals of {Path(signals.source).name}, aligned to the frames by "
            f"{signals.aligned_by}, beside the mean strain that moves most: over time (left) "
            "and the strain against each signal (right). Per frame: signals.csv.",
        )
    summary_cycles = None
    if cycles is not None:
        write_cycles_csv(folder, cycles, field, node=node)
        summary_cycles = {k: v for k, v in cycles.items() if k != "curves"}
    if drawn_cycles is not None:
        record(
            drawn_cycles.result(),
            f"Repeated contractions: the {len(cycles['cycles'])} cycles found in the mean "
            f"{cycles['component']} ({cycles['trigger']}), with onset, peak and end (top), "
            "and each complete cycle from its onset with the ensemble mean +/- one SD over "
            "the cycles (bottom). Per cycle: cycles.csv; each peak per node: cycles_nodes.csv.",
        )
    return {
        "contraction_endpoint": ep,
        "statistics": statistics,
        "figures": log.items,
        "quality": quality_summary,
        "flags": flags,
        "cycles": summary_cycles,
        "signals": None if signals is None else signals.summary(),
    }


def _worst(values, lowest: bool = True) -> tuple[float | None, int | None]:
    a = np.array([np.nan if v is None else v for v in values], dtype=float)
    if not np.isfinite(a).any():
        return None, None
    k = int(np.nanargmin(a) if lowest else np.nanargmax(a))
    return float(a[k]), k


def _quality_summary(quality: dict, sigma, noise, unit) -> dict:
    """The quality of a run for ``summary.json``: worst frames, mesh, noise; per-frame lists."""
    mesh = quality["mesh"]
    vis, k_vis = _worst(quality["visible_pct"])
    cov, k_cov = _worst(quality["coverage_pct"])
    q, k_q = _worst(quality["quality_median"])
    return {
        "lowest_visible_pct": vis,
        "lowest_visible_frame": k_vis,
        "lowest_coverage_pct": cov,
        "lowest_coverage_frame": k_cov,
        "lowest_median_quality": q,
        "lowest_median_quality_frame": k_q,
        "median_uncertainty_px": sigma,
        "principal_direction_noise_floor": noise,
        "mesh": {
            "n_triangles": mesh["n_triangles"],
            "radius_ratio_min": mesh["quality_min"],
            "radius_ratio_median": mesh["quality_median"],
            "slivers": mesh["slivers"],
        },
        "per_frame": {k: v for k, v in quality.items() if k != "mesh"},
        "time_unit": unit,
    }


def _run_flags(
    q: dict, ep: dict, field: StrainField, values: dict, noise: float, updates=None
) -> list[str]:
    """What a reader of the run should know before trusting it, one sentence each.

    ``updates``: per point, how often the tracker renewed its reference subset (dic's
    ``reference_updates``)."""
    flags = []
    if q["lowest_visible_pct"] is not None and q["lowest_visible_pct"] < 100:
        flags.append(
            f"Points were lost: {q['lowest_visible_pct']:.0f} % still tracked on frame "
            f"{q['lowest_visible_frame']}; their triangles have no strain there."
        )
    if q["lowest_coverage_pct"] is not None and q["lowest_coverage_pct"] < 90:
        flags.append(
            f"Only {q['lowest_coverage_pct']:.0f} % of the mesh area has a valid strain on "
            f"frame {q['lowest_coverage_frame']}."
        )
    if q["lowest_median_quality"] is not None and q["lowest_median_quality"] < 0.8:
        flags.append(
            f"The tracker's median quality falls to {q['lowest_median_quality']:.2f} on frame "
            f"{q['lowest_median_quality_frame']}: check the tracked grid on the video."
        )
    if q["mesh"]["slivers"]:
        flags.append(
            f"{q['mesh']['slivers']} of {q['mesh']['n_triangles']} triangles are slivers "
            "(radius ratio below 0.1): their strain magnifies tracking noise."
        )
    renewed = np.asarray(updates if updates is not None else [], dtype=float)
    if renewed.size and np.nanmax(renewed) > 0:
        worst = int(np.nanargmax(renewed))
        flags.append(
            f"The reference subsets of {int((renewed > 0).sum())} of {renewed.size} points were "
            f"renewed as the tissue deformed (most often point {worst}, "
            f"{int(renewed[worst])} times): each renewal adds its match's error, so those "
            "points may drift more than the others (summary.json: tracker.reference_updates)."
        )
    source = str(ep.get("source", ""))
    if source.startswith(("not reached", "none", "too few")):
        flags.append(f"Endpoint: {source}.")
    e1 = values.get("Exx")
    if noise > 0 and e1 is not None and e1.size:
        typical = float(np.median(np.abs(np.concatenate(list(values.values())))))
        if typical < 2 * noise:
            flags.append(
                f"The strain at the endpoint (median |E| {typical:.2g}) is within twice the "
                f"noise floor ({noise:.2g}) that the tracking uncertainty gives."
            )
    return flags


def _embeddable(folder: Path, files: list[str]) -> Path | None:
    by_suffix = {Path(f).suffix.lower(): folder / f for f in files}
    for suffix in (".png", ".gif", ".mp4", ".svg"):
        if suffix in by_suffix and by_suffix[suffix].is_file():
            return by_suffix[suffix]
    return None


def _embed_figures(
    doc: HtmlReport, folder: Path, figures: list[dict], streamed: dict[str, Path], tmp: Path
) -> None:
    """Embed the figures; videos as stand-ins whose data :func:`_write_report` streams in.

    A video is as long as the run (an MP4 of 3,000 frames is some 80 MB, over
    100 MB as base64), so it is never held in memory: a stand-in file of the
    same name, whose base64 is a unique token, is embedded in its place, and
    ``streamed`` maps the token to the video.
    """
    if figures:
        doc.heading("Figures")
    for item in figures:
        path = _embeddable(folder, item["files"])
        if path is not None:
            also = [f for f in item["files"] if folder / f != path]
            caption = item["caption"] + (f" Also: {', '.join(also)}." if also else "")
            if path.suffix.lower() == ".mp4":
                token = f"streamedvideo{uuid.uuid4().hex}{len(streamed):03d}"  # 48 base64 chars
                stand_in = tmp / str(len(streamed)) / path.name
                stand_in.parent.mkdir()
                stand_in.write_bytes(base64.b64decode(token))
                streamed[token] = path
                path = stand_in
            doc.media(path, caption)


def _write_report(doc: HtmlReport, out: Path, streamed: dict[str, Path]) -> None:
    """``doc.write(out)``, with the base64 of each streamed video written in blocks."""
    text = doc.html()
    with open(out, "w", encoding="utf-8") as f:
        for token, path in streamed.items():  # in the document's order
            before, text = text.split(token, 1)
            f.write(before)
            with open(path, "rb") as video:
                for block in iter(lambda: video.read(3 << 18), b""):  # 768 KiB -> 1 MiB
                    f.write(base64.b64encode(block).decode("ascii"))
        f.write(text)


def _p(p) -> str:
    if not isinstance(p, int | float) or not math.isfinite(p):
        return "n/a"
    return "< 0.001" if p < 0.001 else f"{p:.3f}"


def _uncertainty_text(u) -> str:
    if not isinstance(u, dict) or u.get("median") is None:
        return "not measured by this tracker"
    text = f"median {u['median']:.3g}, 95th percentile {u['p95']:.3g} over all frames"
    if u.get("last_frame_median") is not None:
        text += f"; median {u['last_frame_median']:.3g} on the last frame"
    return text


def _quality_section(doc: HtmlReport, summary: dict) -> None:
    q = summary.get("quality")
    if not q:
        return
    doc.heading("Quality of the measurement")
    mesh = q.get("mesh", {})
    unc = q.get("median_uncertainty_px")
    scale = (summary.get("units") or {}).get("scale")
    unc_text = "not measured by this tracker"
    if unc is not None:
        unc_text = f"{unc:.3g} px"
        if isinstance(scale, dict) and scale.get("length_per_px"):
            unc_text += f" = {unc * scale['length_per_px']:.3g} {scale['unit']}"
    rows = [
        ("points tracked, lowest", q.get("lowest_visible_pct"), q.get("lowest_visible_frame"), "%"),
        (
            "mesh area with strain, lowest",
            q.get("lowest_coverage_pct"),
            q.get("lowest_coverage_frame"),
            "%",
        ),
        (
            "tracker's median quality, lowest",
            q.get("lowest_median_quality"),
            q.get("lowest_median_quality_frame"),
            "(-)",
        ),
    ]
    table = [
        {"measure": name, "value": "n/a" if v is None else f"{v:.4g} {u}", "frame": k}
        for name, v, k, u in rows
    ]
    table += [
        {"measure": "tracking uncertainty at the endpoint, median (1 sigma)", "value": unc_text},
        {
            "measure": "mesh: triangles, radius ratio min / median, slivers",
            "value": f"{mesh.get('n_triangles')}, {format_value(mesh.get('radius_ratio_min'))}"
            f" / {format_value(mesh.get('radius_ratio_median'))}, {mesh.get('slivers')}",
        },
        {
            "measure": "principal-direction noise floor (E1 - E2)",
            "value": format_value(q.get("principal_direction_noise_floor")),
        },
    ]
    doc.table(table, columns=["measure", "value", "frame"])
    doc.paragraph(
        "Every frame's values are in summary.json (quality.per_frame) and in the tracking "
        "quality figure below."
    )


def _scale_text(scale) -> str:
    if not isinstance(scale, dict) or scale.get("length_per_px") is None:
        return "not given (positions in pixels; strain is dimensionless)"
    return (
        f"{scale['length_per_px']:.6g} {scale['unit']}/px ({scale['px_per_unit']:.6g} "
        f"px/{scale['unit']}), {scale.get('source', '')}"
    )


def _mask_text(mask: dict | None) -> str | None:
    """The tissue mask in a line: its file, its share of the frame, what it left out."""
    if not mask:
        return None
    text = f"{mask['file']} ({mask['fraction_of_frame']:.0%} of the frame)"
    left = [
        f"{mask[key]} {what} off the tissue left out"
        for key, what in (("points_off_tissue", "grid points"), ("triangles_off_tissue",
                          "triangles"))
        if mask.get(key)
    ]  # fmt: skip
    return text + (": " + ", ".join(left) if left else "")


def _cycles_section(doc: HtmlReport, summary: dict) -> None:
    """The repeated contractions (a table of the cycles) and the signals beside the video."""
    cycles = summary.get("cycles")
    unit = "s" if summary.get("time_axis", {}).get("unit") == "s" else "frames"
    if cycles:
        doc.heading("Repeated contractions" if cycles.get("repeated", True) else "Contraction")
        doc.paragraph(
            f"{len(cycles['cycles'])} cycle{'s' if len(cycles['cycles']) != 1 else ''}, found "
            + ("at the pulses of the stimulus" if cycles["trigger"] == "stimulus" else
               f"in the mean {cycles['component']}")
            + f" (peaks rising at least {cycles['min_prominence']:.2g} above their valleys; "
            f"noise {cycles['noise']:.2g} from the {cycles.get('noise_from', 'curve')}). "
            f"Times in {unit}; strains are the mean nodal values at each peak; cycles.csv "
            "and cycles_nodes.csv hold them."
        )  # fmt: skip
        rows = []
        for c in cycles["cycles"]:
            means = c.get("peak_mean") or {}
            rows.append({
                "cycle": c["cycle"], "onset": c["onset"], "peak": c["peak"], "end": c["end"],
                "time to peak": c.get("time_to_peak"), "50 % relaxation": c.get("rt50"),
                "relaxation": c.get("relaxation_time"), "rise": c.get("amplitude"),
                **{f"{k} at peak": means.get(k) for k in ("Exx", "Eyy", "Exy")},
            })  # fmt: skip
        doc.table(rows)
    signals = summary.get("signals")
    if signals:
        doc.heading("Signals beside the video")
        doc.paragraph(
            f"{Path(signals['file']).name}: {signals['samples']} rows aligned to the frames by "
            f"{signals['aligned_by']} (signals.csv holds them per frame, with the mean strains)."
        )
        doc.table([{"signal": name, **values} for name, values in signals["signals"].items()])


def write_run_report(folder: str | os.PathLike, summary: dict) -> Path:
    """Write ``report.html`` for a run folder from its ``summary.json`` content.

    Figures listed in ``summary["figures"]`` are embedded (PNG, GIF, MP4 or
    SVG); the report needs no other file to be read.
    """
    folder = Path(folder)
    software = summary.get("software", {})
    inputs = summary.get("inputs") or []
    doc = HtmlReport(
        f"Strain analysis: {', '.join(Path(i).name for i in inputs[:3]) or folder.name}",
        subtitle=f"{software.get('name', 'strain2d')} {software.get('version', '?')}, "
        f"created {summary.get('created', '?')}",
    )
    doc.heading("Run")
    units = summary.get("units") or {}
    source = summary.get("source", {})
    tracker = summary.get("tracker", {})
    points = summary.get("points", {})
    doc.key_values(
        {
            "inputs": ", ".join(inputs),
            "frames used": source.get("frames_used"),
            "frame size (px)": source.get("frame_size_px"),
            "pixel size": _scale_text(units.get("scale")),
            "tracker": tracker.get("name"),
            "tracker options": tracker.get("options", {}),
            "points": points.get("grid") or points.get("points_file") or points.get("points"),
            "tissue mask": _mask_text(points.get("mask")),
            "triangles": summary.get("mesh", {}).get("n_triangles"),
            "points lost by the last frame": summary.get("lost_points_last_frame"),
            "tracking uncertainty (px, 1 sigma per coordinate)": _uncertainty_text(
                summary.get("tracking_uncertainty_px")
            ),
            "time axis": summary.get("time_axis", {}).get("unit"),
            "command": " ".join(summary.get("command") or []),
        }
    )
    if summary.get("input_files"):
        doc.heading("Inputs")
        doc.inputs(summary["input_files"])
    doc.heading("What was flagged")
    doc.flags(summary.get("flags") or [])
    _quality_section(doc, summary)
    ep = summary.get("contraction_endpoint")
    if ep:
        doc.heading(ep.get("label", "contraction endpoint").capitalize())
        text = f"Frame {ep['frame']}"
        if summary.get("time_axis", {}).get("unit") == "s":
            text += f" (t = {ep['time']:.4g} s)"
        if ep["source"] == "given":
            text += (
                f", given by the user (detection: frame {ep.get('detected_frame')}, "
                f"{ep.get('detection', 'detected')})."
            )
        elif ep["source"] == "detected":
            text += f", detected: {ep['method']}."
        elif ep["source"] == "cycle":
            text += f": the {ep.get('detection', 'peak of a cycle')}."
        else:
            text += f": the endpoint was {ep['source']}."
        doc.paragraph(text)
    _cycles_section(doc, summary)
    stats = summary.get("statistics")
    if stats:
        doc.heading(f"Nodal strain at frame {stats.get('frame')}: {stats.get('frame_meaning')}")
        rows = [{"component": k, **v} for k, v in stats["nodal_strain"].items() if v.get("n", 0)]
        doc.table(rows, columns=["component", "mean", "sd", "min", "max", "n"])
        paired = stats["paired"]
        a, b = paired.get("components", ("Exx", "Eyy"))
        doc.heading(f"{a} against {b}: node-level paired tests")
        if "error" in paired:
            doc.paragraph(f"Not computed: {paired['error']}.", css="note")
            paired = {}
        lo, hi = paired.get("mean_difference_ci", [float("nan")] * 2)
        dlo, dhi = paired.get("cohens_dz_ci", [float("nan")] * 2)
        doc.table(
            [
                {"quantity": "nodes", "value": paired.get("n")},
                {"quantity": f"mean {a} - {b}", "value": paired.get("mean_difference")},
                {"quantity": "bootstrap 95% CI", "value": [lo, hi]},
                {"quantity": "paired t-test p", "value": _p(paired.get("t_p"))},
                {"quantity": "Wilcoxon signed-rank p", "value": _p(paired.get("wilcoxon_p"))},
                {"quantity": "Cohen's d_z", "value": paired.get("cohens_dz")},
                {"quantity": "d_z bootstrap 95% CI", "value": [dlo, dhi]},
                {"quantity": "Moran's I of the differences", "value": paired.get("morans_i")},
                {"quantity": "Moran's I permutation p", "value": _p(paired.get("morans_p"))},
            ]
        )
        if paired:
            doc.paragraph(paired.get("note", ""), css="note")
    out = folder / "report.html"
    with tempfile.TemporaryDirectory() as tmp:
        streamed: dict[str, Path] = {}
        _embed_figures(doc, folder, summary.get("figures") or [], streamed, Path(tmp))
        doc.provenance({k: v for k, v in summary.items() if k not in ("figures", "statistics")})
        _write_report(doc, out, streamed)
    return out


def _curves(run, components: Sequence[str]) -> tuple[dict, dict]:
    mean, sd = {}, {}
    for c in components:
        v = run.nodal[c]
        ok = np.isfinite(v)
        n = ok.sum(axis=1)
        m = np.where(n > 0, np.where(ok, v, 0).sum(axis=1) / np.maximum(n, 1), np.nan)
        dev = np.where(ok, v - m[:, None], 0.0)
        s = np.where(n > 1, np.sqrt((dev**2).sum(axis=1) / np.maximum(n - 1, 1)), np.nan)
        mean[c], sd[c] = m, s
    return mean, sd


def _write_study_cycles(folder: Path, cycles: dict) -> None:
    """A study's ``cycles.csv`` (a row per specimen and cycle) and ``specimen_cycles.csv``
    (each specimen's cycles averaged)."""
    from tissue_core.csvtext import csv_writer, number_cell

    for name, rows in (("cycles.csv", cycles["rows"]), ("specimen_cycles.csv",
                                                        cycles["specimens"])):  # fmt: skip
        columns = list(rows[0])
        with open(folder / name, "w", newline="") as f:
            writer = csv_writer(f, lineterminator="\n")
            writer.writerow(columns)
            for row in rows:
                writer.writerow([v if isinstance(v, str) else number_cell(v) for v in
                                 (row.get(c) for c in columns)])  # fmt: skip


def study_outputs(
    folder: str | os.PathLike,
    specimens: Sequence,
    stats: dict,
    *,
    formats: Sequence[str] = ("png",),
) -> dict:
    """Write a study's table, figures and ``statistics.json`` into ``folder``.

    ``specimens`` are :class:`strain2d.study.Specimen` and ``stats`` the
    result of :func:`strain2d.study.study_statistics` for them.  Returns the
    ``figures`` list for ``summary.json``.
    """
    from strain2d import figures as fg
    from tissue_core.csvtext import csv_writer

    folder = Path(folder)
    a, b = stats["components"]
    log = _FigureLog(folder)
    figdir, record, written = log.dir, log.add, log.items

    units = {s.run.time_unit for s in specimens}
    time_unit = units.pop() if len(units) == 1 else "frame"
    curves = []
    for s in specimens:
        mean, sd = _curves(s.run, (a, b))
        times = s.run.times if time_unit == s.run.time_unit else np.arange(s.run.n_frames)
        curves.append(
            {
                "name": s.name,
                "group": s.group,
                "times": times,
                "mean": mean,
                "sd": sd,
                "endpoint": s.endpoint,
            }
        )
    fig = fg.plot_study_curves(curves, time_unit=time_unit, components=(a, b))
    record(
        fg.save_figure(fig, figdir / "study_curves", formats),
        f"Mean {a} and {b} over time for every specimen, with a band of +/- one spatial SD "
        "over the nodes; the dashed line marks each specimen's contraction endpoint.",
    )
    rows = {r["specimen"]: r for r in stats["specimens"]}
    violins = [
        {
            "name": s.name,
            "group": s.group,
            "values": {c: s.values(c)[np.isfinite(s.values(c))] for c in (a, b)},
            "tests": rows[s.name]["node_level"] if "t_p" in rows[s.name]["node_level"] else None,
        }
        for s in specimens
    ]
    levels = stats["specimen_level"]
    tests = {g: levels[g] for g in stats["groups"]} if stats["groups"] else levels["all"]
    fig = fg.plot_study_violins(violins, components=(a, b), tests=tests)
    record(
        fg.save_figure(fig, figdir / "study_violins", formats),
        f"Nodal {a} and {b} at each specimen's contraction endpoint. Title: the specimen-level "
        "paired tests (one mean per specimen). Above each specimen: the p-value of its "
        "node-level paired t-test, descriptive only: nodes within a specimen are not "
        "independent.",
    )
    table = [
        {"name": r["specimen"], "group": r["group"], a: r[f"mean_{a}"], b: r[f"mean_{b}"]}
        for r in stats["specimens"]
    ]
    fig = fg.plot_specimen_means(table, a=a, b=b, tests=tests)
    record(
        fg.save_figure(fig, figdir / "specimen_means", formats),
        f"Specimen means of {a} and {b} at the contraction endpoint, joined per specimen, "
        "with the specimen-level paired tests (the specimen is the experimental unit).",
    )

    columns = [
        "specimen", "group", "run", "endpoint", "endpoint_source", "endpoint_time", "time_unit",
        "n_nodes", f"mean_{a}", f"sd_{a}", f"mean_{b}", f"sd_{b}", "mean_difference",
    ]  # fmt: skip
    node_cols = ["t_p", "wilcoxon_p", "cohens_dz", "morans_i", "morans_p"]
    with open(folder / "specimens.csv", "w", newline="", encoding="utf-8") as f:
        writer = csv_writer(f)  # names and groups are the user's text
        writer.writerow(columns + [f"node_{c}" for c in node_cols])
        for r in stats["specimens"]:
            writer.writerow(
                [r[c] for c in columns] + [r["node_level"].get(c, "") for c in node_cols]
            )
    write_json(folder / "statistics.json", stats)
    return {"figures": written}


_NODE_CAVEAT = (
    "Node-level, descriptive: these tests treat the nodes of one specimen as independent "
    "samples, which they are not (neighbouring nodes share the tissue and the mesh). They "
    "describe each specimen's field; conclusions about the tissue rest on the specimen-level "
    "results above."
)


def _study_figure(doc: HtmlReport, folder: Path, figures: list[dict], stem: str) -> bool:
    """Embed the study figure whose files are named ``stem``.*; whether there was one."""
    for item in figures:
        if any(Path(f).stem == stem for f in item["files"]):
            path = _embeddable(folder, item["files"])
            if path is not None:
                also = [f for f in item["files"] if folder / f != path]
                doc.media(path, item["caption"] + (f" Also: {', '.join(also)}." if also else ""))
                return True
    return False


def _study_flags(stats: dict) -> list[str]:
    """What a reader of the study should know before trusting its numbers."""
    a, b = stats["components"]
    alpha = float(stats.get("alpha", 0.05))
    out = []
    if stats.get("excluded"):
        out.append(
            f"Left out, no node with both {a} and {b} at the endpoint: "
            f"{', '.join(stats['excluded'])}."
        )
    for key, t in stats["specimen_level"].items():
        who = "The study" if key == "all" else f"Group {key}"
        if t["n"] < 2:
            out.append(f"{who} has {t['n']} specimen(s): nothing can be tested.")
        elif 2.0 / 2.0 ** t["n"] >= alpha:  # the exact test's smallest two-sided p
            out.append(
                f"{who} has {t['n']} specimens: its Wilcoxon signed-rank test "
                f"cannot reach p < {alpha:g} (two-sided; its smallest p is "
                f"{2.0 / 2.0 ** t['n']:.3g})."
            )
    model = stats.get("mixed_model")
    if model and not model["usable"]:
        out.append(
            "The mixed-effects model did not fit cleanly ("
            + ("; ".join(model["warnings"]) or "no convergence")
            + "): its p-values are reported, not used."
        )
    elif stats.get("mixed_model_note"):
        out.append(f"No mixed-effects model: {stats['mixed_model_note']}.")
    for r in stats["specimens"]:
        if str(r.get("endpoint_source", "")).startswith("not reached"):
            out.append(f"{r['specimen']}: endpoint {r['endpoint_source']}.")
    return out


def _endpoint_text(row: dict) -> str:
    text = f"frame {row['endpoint']}"
    if row.get("time_unit") not in (None, "frame"):
        text += f" (t = {row['endpoint_time']:.4g} {row['time_unit']})"
    return text


def _study_cycles_section(doc: HtmlReport, cycles: dict | None, pct: int) -> None:
    """Runs with repeated contractions: per specimen its cycles averaged, and the
    specimen-level tests per cycle number and on the averages."""
    if not cycles:
        return
    a, b = cycles["components"]
    doc.heading("Repeated contractions")
    doc.paragraph(
        f"{len(cycles['specimens'])} specimens contracted more than once "
        f"({len(cycles['rows'])} cycles). {a} and {b} at each cycle's peak (mean over the "
        "nodes), averaged over each specimen's cycles with their SD over the cycles; "
        "cycles.csv has every cycle, specimen_cycles.csv the averages."
    )
    doc.table(
        [
            {
                "specimen": e["specimen"], "group": e["group"], "cycles": e["n_cycles"],
                f"{a} mean": e[f"{a}_mean"], f"{a} SD": e[f"{a}_sd"],
                f"{b} mean": e[f"{b}_mean"], f"{b} SD": e[f"{b}_sd"],
                "time to peak": e["time_to_peak_mean"], "50 % relaxation": e["rt50_mean"],
            }
            for e in cycles["specimens"]
        ]
    )  # fmt: skip
    doc.paragraph(
        f"Specimen-level paired tests of {a} against {b} (the specimen is the unit): at each "
        "cycle number two specimens or more reach, and on the specimens' averages over "
        "their cycles."
    )
    rows = [{"cycles": f"cycle {t['cycle']}", **t} for t in cycles["per_cycle"]]
    rows.append({"cycles": "averaged over cycles", **cycles["averaged_over_cycles"]})
    doc.table(
        [
            {
                "cycles": r["cycles"], "specimens": r["n"],
                f"mean {a} - {b}": r["mean_difference"], f"{pct}% CI": r["mean_difference_ci"],
                "p (paired t)": _p(r["t_p"]), "p (Wilcoxon)": _p(r["wilcoxon_p"]),
            }
            for r in rows
        ]
    )  # fmt: skip


def write_study_report(folder: str | os.PathLike, summary: dict, stats: dict) -> Path:
    """Write a study folder's self-contained ``report.html``.

    The specimen is the experimental unit: the report leads with the
    specimen-level tests on specimen means (and the mixed-effects model),
    then the per-specimen tables; the node-level tests come last, marked as
    descriptive.
    """
    from strain2d.study import plain_summary

    folder = Path(folder)
    software = summary.get("software", {})
    a, b = stats["components"]
    n = len(stats["specimens"])
    figures = summary.get("figures") or []
    pct = round(100 * stats["confidence"])
    doc = HtmlReport(
        f"Strain study: {n} specimen{'s' if n != 1 else ''}, {a} against {b}",
        subtitle=f"{software.get('name', 'strain2d')} {software.get('version', '?')}, "
        f"created {summary.get('created', '?')}; {a} and {b} compared at each specimen's "
        "contraction endpoint",
    )
    doc.heading("Summary")
    doc.bullets(plain_summary(stats), css="summary")
    doc.heading("Flagged")
    doc.flags(_study_flags(stats))

    doc.heading("Specimen-level results (the specimen is the experimental unit)")
    doc.paragraph(
        f"Each specimen gives one mean of {a} and of {b} over its nodes at its contraction "
        f"endpoint; the paired t-test and the Wilcoxon signed-rank test compare these means "
        f"across specimens, the mean difference {a} - {b} with its {pct}% t interval and "
        "Cohen's d_z (mean difference / SD of the differences)."
    )
    rows = []
    for key, t in stats["specimen_level"].items():
        rows.append(
            {
                "specimens": "all" if key == "all" else f"group {key}",
                "n": t["n"],
                f"mean {a} - {b}": t["mean_difference"],
                f"{pct}% CI (t)": t["mean_difference_ci"],
                "paired t p": _p(t["t_p"]),
                "Wilcoxon p": _p(t["wilcoxon_p"]),
                "Cohen's d_z": t["cohens_dz"],
            }
        )
    doc.table(rows)
    comp = stats.get("groups_compared")
    if comp:
        doc.heading("Between the groups", level=3)
        doc.paragraph(
            f"{comp['label']}: difference {comp['difference']:+.4f}, "
            f"t = {comp['welch_t']:.3g}, p {_p(comp['welch_p'])}."
        )
    _study_figure(doc, folder, figures, "specimen_means")
    model = stats.get("mixed_model")
    if model:
        doc.heading("Mixed-effects model", level=3)
        doc.paragraph(
            f"{model['formula']}, fitted by {model['method']} on {model['n_nodes']} nodes of "
            f"{model['n_specimens']} specimens, where d = {a} - {b} at each node: the nodes "
            "enter with the specimen as a random effect, so they are not counted as "
            "independent. p (t) uses a t reference with specimen-level degrees of freedom; "
            "p (z) is the Wald z statsmodels reports, anticonservative with few specimens."
        )
        doc.table(
            [
                {
                    "term": e["term"],
                    "estimate": e["estimate"],
                    "SE": e["se"],
                    "CI": e["ci"],
                    "df": e["df"],
                    "p (t)": _p(e["t_p"]),
                    "p (z)": _p(e["z_p"]),
                }
                for e in model["effects"] + model["contrasts"]
            ]
        )
        doc.key_values(
            {
                "between-specimen variance": model["specimen_variance"],
                "within-specimen (node) variance": model["residual_variance"],
                "intraclass correlation": model["icc"],
                "converged": model["converged"],
                "fit warnings": "; ".join(model["warnings"]) or "none",
            }
        )

    doc.heading("Specimens")
    doc.table(
        [
            {
                "specimen": r["specimen"],
                "group": r["group"],
                "run folder": Path(r["run"]).name,
                "endpoint": _endpoint_text(r),
                "endpoint source": r["endpoint_source"],
                "nodes": r["n_nodes"],
            }
            for r in stats["specimens"]
        ]
    )
    doc.paragraph(
        f"Means and SDs over each specimen's nodes at its endpoint (the SD describes the "
        f"spread within the specimen); mean {a} - {b} is what the specimen-level tests compare."
    )
    doc.table(
        [
            {
                "specimen": r["specimen"],
                "group": r["group"],
                f"mean {a}": r[f"mean_{a}"],
                f"SD {a}": r[f"sd_{a}"],
                f"mean {b}": r[f"mean_{b}"],
                f"SD {b}": r[f"sd_{b}"],
                f"mean {a} - {b}": r["mean_difference"],
            }
            for r in stats["specimens"]
        ]
    )
    _study_cycles_section(doc, stats.get("cycles"), pct)

    doc.heading("Node-level tests (descriptive)")
    doc.paragraph(_NODE_CAVEAT, css="note")
    doc.table(
        [
            {
                "specimen": r["specimen"],
                "nodes": r["node_level"].get("n", r["n_nodes"]),
                "node t-test p": _p(r["node_level"].get("t_p")),
                "node Wilcoxon p": _p(r["node_level"].get("wilcoxon_p")),
                "Cohen's d_z (nodes)": r["node_level"].get("cohens_dz"),
                "Moran's I": r["node_level"].get("morans_i"),
                "Moran's I p": _p(r["node_level"].get("morans_p")),
                "note": r["node_level"].get("error", ""),
            }
            for r in stats["specimens"]
        ],
        columns=[
            "specimen", "nodes", "node t-test p", "node Wilcoxon p", "Cohen's d_z (nodes)",
            "Moran's I", "Moran's I p",
            *(["note"] if any("error" in r["node_level"] for r in stats["specimens"]) else []),
        ],
    )  # fmt: skip

    doc.heading("Figures")
    for stem in ("study_violins", "study_curves"):
        _study_figure(doc, folder, figures, stem)
    doc.provenance({k: v for k, v in summary.items() if k != "figures"})
    out = folder / "report.html"
    doc.write(out)
    return out


def write_study(
    out: str | os.PathLike,
    runs: Sequence,
    *,
    compare: tuple[str, str] = ("Exx", "Eyy"),
    alpha: float = 0.05,
    formats: Sequence[str] = ("png",),
    overwrite: bool = False,
    manifest: str | os.PathLike | None = None,
    command: Sequence[str] | None = None,
) -> dict:
    """Combine ``analyze`` run folders into a study folder (what ``strain2d study`` does).

    Parameters
    ----------
    out : path
        The study folder to create (written atomically; an existing one is
        replaced only with ``overwrite``).
    runs : sequence
        Run folders, or manifest entries (dicts with ``run`` and optional
        ``specimen``, ``group``, ``endpoint``; see
        :func:`strain2d.study.read_manifest`).
    compare : (a, b)
        The nodal components compared at each contraction endpoint.
    manifest : path, optional
        The manifest the entries came from (recorded, and never overwritten).

    Returns
    -------
    dict
        The study's ``summary.json`` content (``plain_summary`` holds the
        plain-language sentences); the statistics are in
        ``OUT/statistics.json``.

    Examples
    --------
    After ``strain2d analyze`` wrote ``runs/S01`` and ``runs/S02``::

        summary = write_study("study", ["runs/S01", "runs/S02"])
        print("\n".join(summary["plain_summary"]))
    """
    from datetime import UTC, datetime

    from strain2d import __version__
    from strain2d.study import load_specimens, plain_summary, study_cycles, study_statistics
    from tissue_core.outputs import atomic_dir, check_writable

    entries = [e if isinstance(e, dict) else {"run": Path(e)} for e in runs]
    inputs = ([str(manifest)] if manifest else []) + [str(e["run"]) for e in entries]
    check_writable(out, overwrite=overwrite, inputs=inputs)
    # the manifest's checksum: a batch makes its study again once the manifest is edited
    manifest_files = input_records([manifest]) if manifest else []
    specimens = load_specimens(entries)
    a, b = compare
    stats = study_statistics(specimens, a=a, b=b, alpha=alpha)
    cycles = study_cycles(specimens, a, b)
    if cycles is not None:
        stats["cycles"] = cycles
    formats = parse_formats(formats)
    with atomic_dir(out, overwrite=overwrite, inputs=inputs) as tmp:
        extra = study_outputs(tmp, specimens, stats, formats=formats)
        if cycles is not None:
            _write_study_cycles(tmp, cycles)
        summary = {
            "software": {"name": "strain2d", "version": __version__},
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "command": list(command) if command is not None else None,
            "inputs": {
                "manifest": str(manifest) if manifest else None,
                "runs": [str(e["run"]) for e in entries],
            },
            "input_files": manifest_files,
            "parameters": {"compare": [a, b], "alpha": alpha, "formats": list(formats)},
            "specimens": [
                {
                    "specimen": s.name,
                    "group": s.group,
                    "run": str(s.run.path),
                    "run_software": s.run.summary.get("software"),
                    "endpoint": s.endpoint,
                    "endpoint_source": s.endpoint_source,
                }
                for s in specimens
            ],
            "plain_summary": plain_summary(stats),
            "outputs": [
                *sorted(str(p.relative_to(tmp)) for p in tmp.rglob("*") if p.is_file()),
                "report.html",
                "summary.json",
            ],
            "figures": extra["figures"],
        }
        write_json(tmp / "summary.json", summary)
        write_study_report(tmp, summary, stats)
    return summary
