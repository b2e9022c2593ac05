"""Repeated contractions: each cycle on the run's mean strain, and the ensemble cycle."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from strain2d.figures._curves import _time_label
from strain2d.figures._style import _STRAIN_AXIS, _colour, _label

__all__ = ["plot_cycles"]


def plot_cycles(
    times: np.ndarray,
    curves: np.ndarray,
    components: Sequence[str],
    cycles: dict,
    *,
    time_unit: str = "frame",
    title: str = "",
) -> Figure:
    """The cycles found (:func:`strain2d.cycles.detect_cycles`) and their ensemble.

    Top: the mean strain of each component over time; each cycle's onset
    (triangle), peak (circle, numbered) and end (square) on the component
    the cycles were found in, the chosen endpoint's cycle filled.  Bottom:
    each complete cycle's mean strain of that component from its onset
    (thin) and the ensemble mean with a band of +/- one SD over the cycles.

    Parameters
    ----------
    times : (T,) float
    curves : (T, K) float
        Mean strain of each of ``components`` per frame.
    cycles : dict
        What :func:`strain2d.report.run_cycles` returns (``cycles``,
        ``ensemble``, ``component``, ``chosen``).
    time_unit : str, keyword-only
        ``"frame"`` or ``"s"``.
    """
    t = np.asarray(times, dtype=float)
    curves = np.asarray(curves, dtype=float)
    names = list(components)
    main = cycles["component"]
    j = names.index(main)
    fig = Figure(figsize=(7.5, 6.2), layout="constrained")
    top, bottom = fig.subplots(2, 1)
    for k, name in enumerate(names):
        top.plot(t, curves[:, k], color=_colour(name, k), lw=1.4 if name == main else 0.9,
                 label=_label(name))  # fmt: skip
    for n, c in enumerate(cycles["cycles"], start=1):
        if c["peak"] is None:
            top.axvline(t[c["onset"]], color="0.6", ls=":", lw=0.8)
            continue
        filled = n - 1 == cycles.get("chosen")
        colour = _colour(main, j)
        top.plot(t[c["onset"]], curves[c["onset"], j], "^", color=colour, ms=6)
        top.plot(t[c["peak"]], curves[c["peak"], j], "o", ms=7, mec=colour,
                 mfc=colour if filled else "white")  # fmt: skip
        top.annotate(str(n), (t[c["peak"]], curves[c["peak"], j]), textcoords="offset points",
                     xytext=(0, 7 if curves[c["peak"], j] >= 0 else -13), ha="center",
                     fontsize=8)  # fmt: skip
        if c["end"] is not None:
            top.plot(t[c["end"]], curves[c["end"], j], "s", color=colour, ms=5)
    top.set_xlabel(_time_label(time_unit))
    top.set_ylabel(_STRAIN_AXIS)
    top.grid(alpha=0.3)
    top.legend(fontsize=8, loc="best", ncols=len(names))
    top.set_title(
        f"{len(cycles['cycles'])} cycles found in the mean {_label(main)} "
        "(onset ^, peak o, end s; filled: the endpoint's)",
        fontsize=9,
    )
    ens = cycles.get("ensemble")
    unit = "frames" if time_unit == "frame" else time_unit
    if ens:
        since = np.asarray(ens["time_since_onset"])
        for c in cycles["cycles"]:
            if c["peak"] is None or c["end"] is None:
                continue
            stop = min(c["onset"] + since.size, t.size)
            bottom.plot(since[: stop - c["onset"]], curves[c["onset"] : stop, j],
                        color="0.6", lw=0.8)  # fmt: skip
        mean = np.asarray(ens["mean"][main], dtype=float)
        sd = np.asarray(ens["sd"][main], dtype=float)
        bottom.fill_between(since, mean - sd, mean + sd, color=_colour(main, j), alpha=0.25,
                            lw=0, label="+/- 1 SD over the cycles")  # fmt: skip
        bottom.plot(since, mean, color=_colour(main, j), lw=2,
                    label=f"ensemble of {ens['n_cycles']} cycles")  # fmt: skip
        bottom.legend(fontsize=8, loc="best")
    else:
        bottom.text(0.5, 0.5, "no cycle ends before the video does", ha="center",
                    va="center", transform=bottom.transAxes)  # fmt: skip
    bottom.set_xlabel(f"time since the cycle's onset ({unit})")
    bottom.set_ylabel(f"mean {_label(main)} (-)")
    bottom.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    return fig
