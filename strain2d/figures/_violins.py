"""Violins of nodal strain components at one frame, with paired-test brackets."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from matplotlib.figure import Figure

from strain2d.errors import InputError
from strain2d.figures._checks import _finite
from strain2d.figures._style import _STRAIN_AXIS, _colour, _label

__all__ = ["format_p", "plot_strain_violins"]


def format_p(p: float | None) -> str:
    """A p-value as a figure or report shows it.

    Examples
    --------
    >>> format_p(2e-5), format_p(0.0042), format_p(0.0496), format_p(0.31)
    ('p < 0.001', 'p = 0.004', 'p = 0.050', 'p = 0.31')
    """
    if p is None or not np.isfinite(p):
        return "p = n/a"
    if p < 0.001:
        return "p < 0.001"
    if p < 0.1:
        return f"p = {p:.3f}"
    return f"p = {p:.2f}"


def _draw_violins(ax, positions, arrays, colours, *, width=0.7, rng=None, point_size=6.0):
    """Violins with the nodes as jittered points, a median bar and the quartiles.

    The violin is matplotlib's Gaussian kernel density estimate (Scott's
    bandwidth), drawn only where the values spread; :func:`_marker_handles`
    gives the legend entries.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    for x, data, colour in zip(positions, arrays, colours, strict=True):
        if data.size == 0:
            continue
        if data.size >= 2 and np.ptp(data) > 1e-12 * max(1.0, float(np.abs(data).max())):
            parts = ax.violinplot(
                [data], positions=[x], widths=width, showextrema=False, showmedians=False
            )
            for body in parts["bodies"]:
                body.set_facecolor(colour)
                body.set_edgecolor(colour)
                body.set_alpha(0.35)
        jitter = rng.uniform(-0.18, 0.18, data.size) * width
        ax.scatter(
            x + jitter,
            data,
            s=point_size,
            color=colour,
            edgecolors="k",
            linewidths=0.3,
            alpha=0.8,
            zorder=3,
        )
        q1, med, q3 = np.percentile(data, [25, 50, 75])
        ax.vlines(x, q1, q3, color="k", lw=2.5, zorder=4)
        ax.hlines(med, x - 0.25 * width, x + 0.25 * width, color="k", lw=2, zorder=4)


def _marker_handles(*, point_size: float = 6.0) -> list:
    """Legend entries saying what :func:`_draw_violins` draws.

    The entries are grey or black, so they read as the same for every
    component; the component colours are the caller's entries.
    """
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    ms = max(3.0, float(np.sqrt(point_size)) * 1.4)
    node = Line2D([], [], ls="", marker="o", ms=ms, color="0.55", mec="k", mew=0.3)
    median = Line2D([], [], color="k", lw=2)
    iqr = Line2D([], [], ls="", marker="|", ms=11, mew=2.5, color="k")
    body = Patch(facecolor="0.55", edgecolor="0.55", alpha=0.35)
    node.set_label("one node (jittered)")
    median.set_label("median")
    iqr.set_label("interquartile range")
    body.set_label("violin: kernel density of the nodes")
    return [node, median, iqr, body]


def _bracket(ax, x0: float, x1: float, y: float, height: float, text: str, *, fontsize=8):
    ax.plot([x0, x0, x1, x1], [y, y + height, y + height, y], color="k", lw=0.9)
    ax.text(0.5 * (x0 + x1), y + 1.4 * height, text, ha="center", va="bottom", fontsize=fontsize)


def _test_lines(tests: Mapping, *, short: bool = False) -> str:
    label = tests.get("label", "paired t-test")
    n = tests.get("n")
    lines = []
    if "t_p" in tests:
        lines.append(f"{'t' if short else label}: {format_p(tests['t_p'])}")
    if "wilcoxon_p" in tests:
        lines.append(f"{'W' if short else 'Wilcoxon signed-rank'}: {format_p(tests['wilcoxon_p'])}")
    if n is not None and not short:
        lines.append(f"n = {n} nodes")
    return "\n".join(lines)


def _values(values: Mapping[str, np.ndarray], where: str) -> dict[str, np.ndarray]:
    if len(values) == 0:
        raise InputError(f"{where} is empty; give at least one component")
    return {str(k): _finite(v) for k, v in values.items()}


def plot_strain_violins(
    values: Mapping[str, np.ndarray],
    *,
    title: str = "",
    tests: Mapping | None = None,
) -> Figure:
    """Violins of nodal strain components at one frame (the paper's Fig. 15 for one specimen).

    Parameters
    ----------
    values : dict
        ``{component: (N,) nodal values}``, e.g. ``{"Exx": ..., "Eyy": ...}``
        at the contraction endpoint; NaN are left out.
    title : str, keyword-only
    tests : dict, keyword-only
        A paired comparison of the first two components, e.g. from
        :func:`strain2d.stats.paired_node_tests` with a ``"label"`` added:
        ``"t_p"``, ``"wilcoxon_p"``, ``"n"``, ``"label"`` (e.g.
        "node-level paired t-test"), each optional.  Drawn as a bracket
        annotated with the p-values.

    Returns
    -------
    matplotlib.figure.Figure
        Each component as a violin (kernel density) with every node as a
        (jittered) point, the median as a bar and the interquartile range as
        a thick line; a legend under the axes says so.
    """
    data = _values(values, "values")
    comps = list(data)
    fig = Figure(figsize=(1.6 * len(comps) + 2.2, 4.4), layout="constrained")
    ax = fig.add_subplot()
    positions = np.arange(len(comps), dtype=float)
    _draw_violins(ax, positions, list(data.values()), [_colour(c, i) for i, c in enumerate(comps)])
    ax.set_xticks(positions, [_label(c) for c in comps])
    ax.set_xlim(-0.6, len(comps) - 0.4)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("component")
    ax.set_ylabel(_STRAIN_AXIS)
    ax.grid(alpha=0.3, axis="y")
    every = np.concatenate([*data.values(), [np.nan]])
    if tests and len(comps) >= 2 and np.isfinite(every).any():
        lo, hi = float(np.nanmin(every)), float(np.nanmax(every))
        span = max(hi - lo, 1e-3)
        _bracket(ax, 0, 1, hi + 0.06 * span, 0.03 * span, _test_lines(tests))
        ax.set_ylim(lo - 0.06 * span, hi + 0.4 * span)
    if title:
        ax.set_title(title)
    fig.legend(
        handles=_marker_handles(point_size=6.0),
        loc="outside lower center",
        ncols=2,
        fontsize=8,
        frameon=False,
    )
    return fig
