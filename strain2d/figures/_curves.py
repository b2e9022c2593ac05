"""Mean +/- spatial SD of strain components over time for one run."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from strain2d.errors import InputError
from strain2d.figures._checks import _frame_index, _scalars
from strain2d.figures._style import _STRAIN_AXIS, _colour, _label
from surface_strain import StrainField, iter_blocks, nodal_scalars

__all__ = ["mean_strain_curves", "plot_strain_curves"]


def mean_strain_curves(
    field: StrainField, components: Sequence[str] = ("Exx", "Eyy", "Exy")
) -> dict[str, dict[str, np.ndarray]]:
    """Mean and spatial SD of nodal strain components over the nodes, per frame.

    Returns
    -------
    dict
        ``{"mean": {comp: (T,)}, "sd": {comp: (T,)}, "n": {comp: (T,) int}}``:
        the mean over the nodes with a finite value, their standard deviation
        (``ddof=0``, the spread of this field, not an estimate for a
        population) and how many nodes entered; NaN on frames without any.
        The ``mean`` and ``sd`` entries are what :func:`plot_study_curves`
        takes per specimen.
    """
    _scalars(field, components)  # the names, checked
    T = field.n_frames
    out: dict[str, dict[str, np.ndarray]] = {
        "mean": {c: np.full(T, np.nan) for c in components},
        "sd": {c: np.full(T, np.nan) for c in components},
        "n": {c: np.zeros(T, int) for c in components},
    }
    for start, block in iter_blocks(field):  # a streamed field a block of frames at a time
        scalars = nodal_scalars(block)
        rows = slice(start, start + block.n_frames)
        for comp in components:
            v = scalars[comp]
            ok = np.isfinite(v)
            n = ok.sum(axis=1)
            filled = np.where(ok, v, 0.0)
            with np.errstate(invalid="ignore", divide="ignore"):
                mean = filled.sum(axis=1) / n
                sd = np.sqrt(np.where(ok, (filled - mean[:, None]) ** 2, 0.0).sum(axis=1) / n)
            out["mean"][comp][rows] = np.where(n > 0, mean, np.nan)
            out["sd"][comp][rows] = np.where(n > 0, sd, np.nan)
            out["n"][comp][rows] = n
    return out


def _time_label(time_unit: str) -> str:
    if not isinstance(time_unit, str) or not time_unit:
        raise InputError(f"time_unit must be 'frame' or a unit such as 's', got {time_unit!r}")
    return "frame" if time_unit == "frame" else f"time ({time_unit})"


def _endpoint_text(x: float, time_unit: str) -> str:
    if time_unit == "frame":
        return f"endpoint (frame {x:g})"
    return f"endpoint ({x:.3g} {time_unit})"


def _draw_curves(ax, times, mean, sd, components, endpoint_x, time_unit, *, legend=True):
    for i, comp in enumerate(components):
        if comp not in mean:
            raise InputError(f"no mean curve for component {comp!r}; have {sorted(mean)}")
        m = np.asarray(mean[comp], dtype=float)
        if m.shape != times.shape:
            raise InputError(
                f"the mean curve of {comp} has shape {m.shape}, the times {times.shape}"
            )
        colour = _colour(comp, i)
        ax.plot(times, m, color=colour, lw=1.6, label=f"{_label(comp)} mean")
        if sd is not None and comp in sd:
            s = np.asarray(sd[comp], dtype=float)
            if s.shape != times.shape:
                raise InputError(
                    f"the SD curve of {comp} has shape {s.shape}, the times {times.shape}"
                )
            ax.fill_between(
                times, m - s, m + s, color=colour, alpha=0.2, lw=0, label=f"{_label(comp)} ± SD"
            )
    ax.axhline(0, color="k", lw=0.6)
    if endpoint_x is not None:
        ax.axvline(endpoint_x, color="0.3", ls="--", lw=1)
        ax.annotate(
            _endpoint_text(endpoint_x, time_unit),
            xy=(endpoint_x, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(-3, -3),
            textcoords="offset points",
            ha="right",
            va="top",
            fontsize=8,
            color="0.2",
        )
    ax.set_xlabel(_time_label(time_unit))
    ax.set_ylabel(_STRAIN_AXIS)
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(fontsize=8, loc="best", ncols=2)


def plot_strain_curves(
    field: StrainField,
    *,
    times: Sequence[float] | np.ndarray | None = None,
    time_unit: str = "frame",
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    endpoint: int | None = None,
    title: str = "",
    curves: dict | None = None,
) -> Figure:
    """Mean nodal strain over time with a band of +/- one spatial SD (the paper's Fig. 14).

    Parameters
    ----------
    field : StrainField
    times : (T,) float, keyword-only
        Time of each frame in ``time_unit`` (default: the frame indices).
    time_unit : str, keyword-only
        ``"frame"`` or a unit of ``times`` such as ``"s"``; labels the x axis.
    components : sequence of str, keyword-only
    endpoint : int, keyword-only
        Frame index of the contraction endpoint
        (:func:`strain2d.stats.contraction_endpoint`), marked by a dashed line.
    title : str, keyword-only
    curves : dict, keyword-only
        ``mean_strain_curves(field, components)`` when it is at hand already
        (a streamed field need not be computed again).

    Returns
    -------
    matplotlib.figure.Figure
    """
    stats = mean_strain_curves(field, components) if curves is None else curves
    T = field.n_frames
    t = np.arange(T, dtype=float) if times is None else np.asarray(times, dtype=float)
    if t.shape != (T,):
        raise InputError(f"times must have one value per frame, shape ({T},), got {t.shape}")
    x_end = None if endpoint is None else float(t[_frame_index(field, endpoint, "endpoint")])
    fig = Figure(figsize=(7.0, 4.2), layout="constrained")
    ax = fig.add_subplot()
    _draw_curves(ax, t, stats["mean"], stats["sd"], components, x_end, time_unit)
    if title:
        ax.set_title(title)
    return fig
