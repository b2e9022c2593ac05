"""Figures of a study: every specimen's curves and violins side by side, specimen means.

Specimens of a group are drawn next to each other, groups in order of appearance.
The specimen is the experimental unit: the specimen-level tests (on one mean
per specimen) head the figures; node-level p-values are drawn as descriptive
(the nodes of one specimen are not independent samples).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from strain2d.errors import InputError
from strain2d.figures._checks import _finite
from strain2d.figures._curves import _draw_curves
from strain2d.figures._style import _STRAIN_AXIS, _colour, _label
from strain2d.figures._violins import _bracket, _draw_violins, _marker_handles, format_p

__all__ = ["plot_specimen_means", "plot_study_curves", "plot_study_violins"]


def _group_order(items: Sequence[Mapping]) -> list[int]:
    """Indices of ``items`` with equal ``group`` adjacent, groups in order of appearance."""
    groups = list(dict.fromkeys(str(it.get("group") or "") for it in items))
    return sorted(range(len(items)), key=lambda i: groups.index(str(items[i].get("group") or "")))


_NODE_NOTE = "node-level, descriptive: nodes within a specimen are not independent"


def _one_test(t: Mapping) -> str:
    """``paired t-test p = 0.003, Wilcoxon p = 0.12`` of one specimen-level result."""
    parts = []
    if "t_p" in t:
        parts.append(f"paired t-test {format_p(t['t_p'])}")
    if "wilcoxon_p" in t:
        parts.append(f"Wilcoxon {format_p(t['wilcoxon_p'])}")
    return ", ".join(parts) or "no test"


def _specimen_lines(tests: Mapping | None) -> list[str]:
    """One line per specimen-level result: ``tests`` is one result or ``{group: result}``."""
    if not tests:
        return []
    single = any(k in tests for k in ("t_p", "wilcoxon_p", "n"))
    items = {"": tests} if single else dict(tests)
    lines = []
    for group, t in items.items():
        if not isinstance(t, Mapping):
            raise InputError(f"tests[{group!r}] must be a dict of test results")
        n = t.get("n")
        size = f" (n = {n} specimen{'s' if n != 1 else ''})" if n is not None else ""
        lines.append(f"{group or 'all'}{size}: {_one_test(t)}")
    return lines


def _wrap(lines: Sequence[str], width_in: float, fontsize: float) -> str:
    """``lines`` as one text, each wrapped at spaces to fit ``width_in`` inches at ``fontsize``.

    Widths are estimated from the visible characters (mathtext's ``$``,
    braces and ``_`` take no room) at 0.6 em each, DejaVu Sans' widest average.
    """
    room = max(20.0, width_in * 72 / (0.6 * fontsize))

    def seen(word: str) -> int:
        return sum(ch not in "${}_\\" for ch in word)

    out = []
    for line in lines:
        current = ""
        for word in line.split(" "):
            if current and seen(current) + 1 + seen(word) > room:
                out.append(current)
                current = word
            else:
                current = f"{current} {word}" if current else word
        out.append(current)
    return "\n".join(out)


def _spread(y: np.ndarray, gap: float, lo: float = -np.inf, hi: float = np.inf) -> np.ndarray:
    """Label heights at least ``gap`` apart, in the order of ``y``, as near ``y`` as can be.

    Minimises ``sum((p - y)**2)`` subject to ``p[j+1] - p[j] >= gap`` along
    the sorted ``y``: with ``q_j = p_j - j * gap`` this is isotonic regression
    of ``y_j - j * gap``, solved by pool-adjacent-violators; clipping ``q``
    to ``[lo, hi - (n - 1) * gap]`` keeps the labels inside ``[lo, hi]``
    (the clipped isotonic fit is the bounded optimum).  When they cannot all
    fit, they are centred on the span.

    Parameters
    ----------
    y : (n,) float
        Wanted heights (finite).
    gap : float
        Least distance between neighbours, in the units of ``y``.

    Returns
    -------
    (n,) float
        The heights, in the order of ``y`` as given.

    Examples
    --------
    >>> _spread(np.array([0.0, 0.0, 5.0]), 1.0).tolist()
    [-0.5, 0.5, 5.0]
    """
    y = np.asarray(y, dtype=float)
    n = y.size
    if n == 0:
        return y.copy()
    order = np.argsort(y, kind="stable")
    steps = gap * np.arange(n)
    target = y[order] - steps
    sums: list[float] = []
    counts: list[int] = []
    for v in target:
        sums.append(float(v))
        counts.append(1)
        while len(sums) > 1 and sums[-2] / counts[-2] > sums[-1] / counts[-1]:
            merged, size = sums.pop(), counts.pop()
            sums[-1] += merged
            counts[-1] += size
    q = np.repeat([s / c for s, c in zip(sums, counts, strict=True)], counts)
    top = hi - steps[-1]
    if top >= lo:
        q = np.clip(q, lo, top)
    elif np.isfinite(lo) and np.isfinite(hi):
        q = np.full(n, 0.5 * (lo + top))
    out = np.empty(n)
    out[order] = q + steps
    return out


def _name(item: Mapping, i: int) -> str:
    name = str(item.get("name", f"specimen {i + 1}"))
    group = item.get("group")
    return f"{name} ({group})" if group else name


def plot_study_curves(
    curves: Sequence[Mapping],
    *,
    time_unit: str = "frame",
    components: Sequence[str] = ("Exx", "Eyy"),
    ncols: int | None = None,
) -> Figure:
    """Mean +/- spatial SD over time for every specimen, one panel each (the paper's Fig. 14).

    Parameters
    ----------
    curves : sequence of dict
        One per specimen: ``"name"``, optional ``"group"``, ``"times"`` (T,),
        ``"mean"`` ``{comp: (T,)}``, optional ``"sd"`` ``{comp: (T,)}`` (e.g.
        from :func:`mean_strain_curves`), optional ``"endpoint"``: an int is a
        frame index into ``times``, a float a time.
    time_unit : str, keyword-only
        ``"frame"`` or the unit of ``times``.
    components : sequence of str, keyword-only
    ncols : int, keyword-only
        Panels per row (default: up to 4).

    Returns
    -------
    matplotlib.figure.Figure
        Panels share the strain axis; specimens of a group are adjacent.
    """
    if len(curves) == 0:
        raise InputError("curves is empty; give at least one specimen")
    n = len(curves)
    ncols = min(n, 4) if ncols is None else int(ncols)
    if ncols < 1:
        raise InputError(f"ncols must be at least 1, got {ncols}")
    nrows = math.ceil(n / ncols)
    fig = Figure(figsize=(3.4 * ncols + 0.6, 2.8 * nrows + 0.7), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, sharey=True, squeeze=False)).ravel()
    for ax, i in zip(axes, _group_order(curves), strict=False):
        c = curves[i]
        if "times" not in c or "mean" not in c:
            raise InputError(f"curves[{i}] needs 'times' and 'mean'")
        t = np.asarray(c["times"], dtype=float)
        if t.ndim != 1:
            raise InputError(f"curves[{i}]['times'] must be (T,), got shape {t.shape}")
        end = c.get("endpoint")
        if end is None:
            x_end = None
        elif isinstance(end, (int, np.integer)) and not isinstance(end, bool):
            if not -len(t) <= end < len(t):
                raise InputError(f"curves[{i}]['endpoint'] {end} is out of range of its times")
            x_end = float(t[end])
        else:
            x_end = float(end)
        _draw_curves(ax, t, c["mean"], c.get("sd"), components, x_end, time_unit, legend=False)
        ax.set_title(_name(c, i), fontsize=10)
        ax.tick_params(labelleft=True)
    for ax in axes[n:]:
        ax.set_visible(False)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncols=2 * len(components), fontsize=8)
    return fig


def _group_label(ax, group: str, x: float, offset_pt: float) -> None:
    """A group's name in bold under the x axis, centred at data ``x``."""
    ax.annotate(
        group,
        xy=(x, 0),
        xycoords=("data", "axes fraction"),
        xytext=(0, offset_pt),
        textcoords="offset points",
        ha="center",
        va="top",
        fontsize=10,
        fontweight="bold",
    )


def plot_study_violins(
    specimens: Sequence[Mapping],
    *,
    components: Sequence[str] = ("Exx", "Eyy"),
    tests: Mapping | None = None,
) -> Figure:
    """Violins of every specimen side by side (the paper's Fig. 15).

    Parameters
    ----------
    specimens : sequence of dict
        One per specimen: ``"name"``, optional ``"group"``, ``"values"``
        ``{component: (N,)}``, optional ``"tests"`` (as for
        :func:`plot_strain_violins`): the p-value of the node-level paired
        test between the first two components is written above each
        specimen, marked as descriptive.
    components : sequence of str, keyword-only
    tests : dict, keyword-only
        The specimen-level paired test of the first two components on
        specimen means (the headline of the figure): one result (keys
        ``"t_p"``, ``"wilcoxon_p"``, ``"n"``) or one per group
        ``{group: result}``, as for :func:`plot_specimen_means`.

    Returns
    -------
    matplotlib.figure.Figure
        The components of a specimen are adjacent and coloured alike across
        specimens; specimens of a group are adjacent, the group named under
        its specimens.  A legend under the axes names the components and
        what the violins draw.
    """
    if len(specimens) == 0:
        raise InputError("specimens is empty; give at least one")
    comps = list(components)
    order = _group_order(specimens)
    k = len(comps)
    step = 0.8
    positions, centres, group_spans = [], [], {}
    x = 0.0
    previous = None
    for i in order:
        group = str(specimens[i].get("group") or "")
        if previous is not None and group != previous:
            x += 0.8 * step  # a wider gap between groups
        previous = group
        xs = x + step * np.arange(k)
        positions.append(xs)
        centres.append(float(xs.mean()))
        lo_hi = group_spans.setdefault(group, [xs[0], xs[-1]])
        lo_hi[1] = xs[-1]
        x = xs[-1] + 1.6 * step
    fig = Figure(figsize=(max(5.5, 0.75 * k * len(order) + 2.0), 4.8), layout="constrained")
    ax = fig.add_subplot()
    rng = np.random.default_rng(0)
    tops, bottoms = [], []
    per_specimen = []
    for xs, i in zip(positions, order, strict=True):
        spec = specimens[i]
        vals = spec.get("values")
        if not isinstance(vals, Mapping):
            raise InputError(f"specimens[{i}] needs 'values', a dict of component -> (N,)")
        missing = [c for c in comps if c not in vals]
        if missing:
            raise InputError(f"specimens[{i}] ({spec.get('name')}) has no values for {missing}")
        arrays = [_finite(vals[c]) for c in comps]
        _draw_violins(
            ax,
            xs,
            arrays,
            [_colour(c, j) for j, c in enumerate(comps)],
            width=0.7 * step,
            rng=rng,
            point_size=4.0,
        )
        present = [a for a in arrays if a.size]
        top = max((float(a.max()) for a in present), default=np.nan)
        tops.append(top)
        bottoms.append(min((float(a.min()) for a in present), default=np.nan))
        per_specimen.append((xs, top, spec.get("tests")))
    lo, hi = float(np.nanmin([*bottoms, np.inf])), float(np.nanmax([*tops, -np.inf]))
    if not (np.isfinite(lo) and np.isfinite(hi)):
        lo, hi = -0.01, 0.01
    span = max(hi - lo, 1e-3)
    bracketed = False
    for xs, top, node_tests in per_specimen:
        if node_tests and k >= 2 and "t_p" in node_tests and np.isfinite(top):
            _bracket(
                ax,
                xs[0],
                xs[1],
                top + 0.05 * span,
                0.025 * span,
                format_p(node_tests["t_p"]),
                fontsize=7,
            )
            bracketed = True
    ax.set_ylim(lo - 0.06 * span, hi + 0.3 * span)
    ax.set_xticks(centres, [str(specimens[i].get("name", f"specimen {i + 1}")) for i in order])
    ax.tick_params(axis="x", length=0)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_ylabel(_STRAIN_AXIS)
    ax.grid(alpha=0.3, axis="y")
    ax.set_xlim(positions[0][0] - step, positions[-1][-1] + step)
    if any(g for g in group_spans):
        for group, (g0, g1) in group_spans.items():
            _group_label(ax, group, 0.5 * (g0 + g1), -26)
        ax.set_xlabel("specimen (group)", labelpad=20)
    else:
        ax.set_xlabel("specimen")
    handles = [
        Patch(facecolor=_colour(c, j), edgecolor=_colour(c, j), alpha=0.35, label=_label(c))
        for j, c in enumerate(comps)
    ]
    handles += _marker_handles(point_size=4.0)
    width = fig.get_figwidth()
    fig.legend(
        handles=handles,
        loc="outside lower center",
        ncols=max(1, min(len(handles), int(width / 2.1))),
        fontsize=8,
        frameon=False,
    )
    vs = f"{_label(comps[0])} vs {_label(comps[1])}" if k >= 2 else _label(comps[0])
    headline = _specimen_lines(tests)
    if headline:
        head = [f"specimen-level paired tests of {vs} on specimen means", *headline]
        fig.suptitle(_wrap(head, width, 10), fontsize=10)
    if bracketed:
        note = ["p above each specimen: paired t-test over its nodes", f"({_NODE_NOTE})"]
        ax.set_title(_wrap(note, width - 0.4, 8.5), fontsize=8.5, color="0.3")
    return fig


def plot_specimen_means(
    table: Sequence[Mapping],
    *,
    a: str = "Exx",
    b: str = "Eyy",
    tests: Mapping | None = None,
) -> Figure:
    """Each specimen's mean of two components joined by a line (specimen-level paired plot).

    The specimen, not the node, is the unit of this plot: it goes with the
    paired test on specimen means across specimens.

    Parameters
    ----------
    table : sequence of dict
        One row per specimen: ``"name"``, optional ``"group"``, and the two
        means either as ``row[a]``, ``row[b]`` or as ``row["mean"][a]``, ...
    a, b : str, keyword-only
        The two components (left and right in each group).
    tests : dict, keyword-only
        The specimen-level paired test, written under the title: one result
        (keys ``"t_p"``, ``"wilcoxon_p"``, ``"n"``, ``"label"``) or one per
        group ``{group: result}``.

    Returns
    -------
    matplotlib.figure.Figure
        Groups side by side; a thin line per specimen, the group mean as a
        thick line.  The specimen-level tests head the title.  Each
        specimen is named right of its ``b`` point; names of nearly equal
        means are moved apart (at least 1.5 line heights, as little as
        possible, in order, with a leader line), so no two overlap.
    """
    if len(table) == 0:
        raise InputError("table is empty; give at least one specimen")

    def mean_of(row, comp, i):
        source = row["mean"] if isinstance(row.get("mean"), Mapping) else row
        if comp not in source:
            raise InputError(f"table[{i}] ({row.get('name')}) has no mean for {comp!r}")
        return float(source[comp])

    groups: dict[str, list[int]] = {}
    for i, row in enumerate(table):
        groups.setdefault(str(row.get("group") or ""), []).append(i)
    largest = max(len(rows) for rows in groups.values())
    # room for one label per specimen of the largest group, _LABEL_GAP apart
    height = max(4.4, largest * _LABEL_GAP * _LABEL_SIZE / 72 + 1.9)
    fig = Figure(figsize=(max(4.8, 2.6 * len(groups) + 1.2), height), layout="constrained")
    ax = fig.add_subplot()
    ca, cb = _colour(a, 0), _colour(b, 1)
    ticks, ticklabels = [], []
    labelled = []  # (name, x of the b point, b mean) per specimen
    for gi, (group, rows) in enumerate(groups.items()):
        x0, x1 = 3.0 * gi, 3.0 * gi + 1.0
        va = np.array([mean_of(table[i], a, i) for i in rows])
        vb = np.array([mean_of(table[i], b, i) for i in rows])
        for i, ya, yb in zip(rows, va, vb, strict=True):
            ax.plot([x0, x1], [ya, yb], color="0.55", lw=1, zorder=1)
            if np.isfinite(yb):
                labelled.append((str(table[i].get("name", i + 1)), x1, float(yb)))
        ax.scatter(
            np.full(va.size, x0), va, color=ca, s=28, edgecolors="k", linewidths=0.4, zorder=3
        )
        ax.scatter(
            np.full(vb.size, x1), vb, color=cb, s=28, edgecolors="k", linewidths=0.4, zorder=3
        )
        ok = np.isfinite(va) & np.isfinite(vb)
        ma, mb = (va[ok].mean(), vb[ok].mean()) if ok.any() else (np.nan, np.nan)
        ax.plot(
            [x0, x1],
            [ma, mb],
            color="k",
            lw=2.4,
            zorder=2,
            label="group mean" if gi == 0 else None,
        )
        ticks += [x0, x1]
        ticklabels += [_label(a), _label(b)]
        if group:
            _group_label(ax, group, 0.5 * (x0 + x1), -22)
    ax.set_xticks(ticks, ticklabels)
    ax.set_xlim(-0.6, 3.0 * (len(groups) - 1) + 1.9)
    ax.axhline(0, color="k", lw=0.6)
    ax.set_ylabel(f"specimen mean, {_STRAIN_AXIS}")
    ax.set_xlabel(
        "component (group)" if any(groups) else "component", labelpad=18 if any(groups) else 4
    )
    ax.grid(alpha=0.3, axis="y")
    fig.legend(
        handles=[
            Line2D([], [], color="0.55", lw=1, label="one specimen"),
            Line2D([], [], color="k", lw=2.4, label="group mean" if any(groups) else "mean"),
        ],
        loc="outside lower center",
        ncols=2,
        fontsize=8,
        frameon=False,
    )
    lines = _specimen_lines(tests)
    title = f"specimen-level: specimen means of {_label(a)} and {_label(b)}"
    used = sum(np.isfinite(mean_of(r, a, i)) and np.isfinite(mean_of(r, b, i))
               for i, r in enumerate(table))  # fmt: skip
    left_out = f"; {len(table) - used} without a mean left out" if used < len(table) else ""
    title += f" (n = {used} specimen{'s' if used != 1 else ''}{left_out})"
    ax.set_title(_wrap([title, *lines], fig.get_figwidth() - 0.4, 9), fontsize=9)
    _place_labels(fig, ax, labelled)
    return fig


#: specimen labels of :func:`plot_specimen_means`: font size (pt) and least spacing (x size)
_LABEL_SIZE = 7.0
_LABEL_GAP = 1.5


def _place_labels(fig: Figure, ax, labelled: list[tuple[str, float, float]]) -> None:
    """Name each specimen right of its point, spread so that no two names overlap.

    The spacing is set in points; turning it into data units needs the laid-out
    axes, so the figure is laid out first and again once the names are in (a
    name that widens a margin changes the scale), up to three times.
    """
    if not labelled:
        return
    ylim = ax.get_ylim()
    ax.set_ylim(ylim)  # fixed: the names must not rescale the axis they are spread on
    by_x: dict[float, list[int]] = {}
    for j, (_, x, _) in enumerate(labelled):
        by_x.setdefault(x, []).append(j)
    notes = [
        ax.annotate(
            name,
            xy=(x, y),
            xytext=(x, y),
            va="center",
            ha="left",
            fontsize=_LABEL_SIZE,
            color="0.25",
            arrowprops={"arrowstyle": "-", "color": "0.6", "lw": 0.5, "shrinkA": 0, "shrinkB": 3},
            annotation_clip=False,
        )
        for name, x, y in labelled
    ]
    for _ in range(3):
        fig.draw_without_rendering()
        box = ax.get_window_extent()
        per_pt_y = (ylim[1] - ylim[0]) / (box.height * 72 / fig.dpi)
        per_pt_x = np.diff(ax.get_xlim())[0] / (box.width * 72 / fig.dpi)
        gap = _LABEL_GAP * _LABEL_SIZE * per_pt_y
        moved = 0.0
        for x, idx in by_x.items():
            want = np.array([labelled[j][2] for j in idx])
            at = _spread(want, gap, ylim[0] + 0.5 * gap, ylim[1] - 0.5 * gap)
            for j, y in zip(idx, at, strict=True):
                new = (x + 7 * per_pt_x, float(y))
                old = notes[j].xyann
                moved = max(moved, abs(new[1] - old[1]) / gap, abs(new[0] - old[0]) / per_pt_x)
                notes[j].xyann = new
        if moved < 0.02:
            break
