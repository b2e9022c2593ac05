"""The look shared by the figures: component labels, colours and diverging colour scales.

Strain colour maps are ``RdBu_r`` with zero white (``J``: one white) and a
range that does not reach zero uses one half of the map only; the colour of
a value depends on its sign and magnitude alone (see :mod:`strain2d.figures`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from matplotlib import colormaps
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from strain2d.errors import InputError
from strain2d.figures._checks import _finite, _frame_index, _scalars
from surface_strain import StrainField

__all__ = ["strain_limits"]

_LABELS = {
    "Exx": r"$E_{xx}$",
    "Eyy": r"$E_{yy}$",
    "Exy": r"$E_{xy}$",
    "E1": r"$E_1$",
    "E2": r"$E_2$",
    "max_shear": r"$(E_1 - E_2)/2$",
    "theta1_deg": r"$\theta_1$",
    "J": r"$J$",
}

#: Colours of the components in curves and violins (Paul Tol's "vibrant", colour-blind safe).
_COLOURS = {
    "Exx": "#0077BB",
    "Eyy": "#EE7733",
    "Exy": "#009988",
    "E1": "#CC3311",
    "E2": "#33BBEE",
    "max_shear": "#EE3377",
    "J": "#555555",
    "theta1_deg": "#BBBBBB",
}
_STRETCH = "#b2182b"  # the red and blue ends of RdBu_r
_SHORTENING = "#2166ac"
_STRAIN_AXIS = "Green-Lagrange strain (-)"


def _label(comp: str) -> str:
    return _LABELS.get(comp, comp)


def _colour(comp: str, i: int) -> str:
    return _COLOURS.get(comp, f"C{i % 10}")


def _unit_label(comp: str) -> str:
    """Colour bar and axis label of a component, with its unit."""
    if comp == "J":
        return f"{_label(comp)} (area ratio, -)"
    if comp == "theta1_deg":
        return f"{_label(comp)}, direction of $E_1$ (deg)"
    return f"{_label(comp)} ({_STRAIN_AXIS})"


def completed_limits(
    field: StrainField, components: Sequence[str], limits: dict | None
) -> dict[str, tuple[float, float]]:
    """``limits`` with :func:`strain_limits` for the components it lacks (all when None)."""
    if limits is None:
        return strain_limits(field, components)
    missing = [c for c in components if c not in limits]
    return {**strain_limits(field, missing), **limits} if missing else limits


#: the most frames whose values set the colour limits (:func:`strain_limits`)
LIMIT_FRAMES = 512


def strain_limits(
    field: StrainField,
    components: Sequence[str] = ("Exx", "Eyy", "Exy"),
    *,
    frames: Sequence[int] | None = None,
    min_span: float = 0.01,
    symmetric: bool = False,
    percentile: float = 0.5,
    cover: Sequence[int] = (),
) -> dict[str, tuple[float, float]]:
    """Colour limits per component, shared by all frames.

    Parameters
    ----------
    field : StrainField
    components : sequence of str
        Names from :func:`surface_strain.nodal_scalars`.
    frames : sequence of int, keyword-only
        Frames whose nodal values set the limits (default: every frame of a
        video of up to :data:`LIMIT_FRAMES` frames; of a longer one,
        that many frames evenly spread over it, so that memory does not grow
        with the video's length).
    min_span : float, keyword-only
        Smallest range, widened about its middle, so that a uniform field
        with tracking noise of a few 1e-4 does not fill the whole colour scale.
    symmetric : bool, keyword-only
        Limits ``(-m, m)`` with ``m`` the larger magnitude of the two ends.
    percentile : float, keyword-only
        Percentage of the values left out at each end: the limits are the
        ``percentile`` and ``100 - percentile`` percentiles of the finite
        nodal values over the frames.  The default 0.5 keeps a spike of one
        node on a few frames (a tracking glitch) from washing out every map;
        values beyond the limits are drawn in the end colours and the colour
        bar shows arrows.  0 gives the full range.  A node that is wrong on
        every frame is more than 0.5 % of the values of a 7x7 grid; raise
        ``percentile`` (e.g. 2.5) or mask the node instead.
    cover : sequence of int, keyword-only
        Frames whose every value lies within the limits (the frames drawn as
        maps): a video that ends at its peak strain would otherwise show many
        of the last frame's nodes in the end colours.

    Returns
    -------
    dict
        ``{component: (low, high)}`` as floats; ``(-min_span/2, min_span/2)``
        for a component without finite values.

    Examples
    --------
    >>> import numpy as np
    >>> from surface_strain import compute_strain, grid_triangles
    >>> X = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2)
    >>> f = compute_strain(X, np.stack([X, X * [1.0, 0.8]]), grid_triangles(3, 3))
    >>> strain_limits(f, ["Eyy"], percentile=0)
    {'Eyy': (-0.18, 0.0)}
    """
    if not (np.isfinite(min_span) and min_span >= 0):
        raise InputError(f"min_span must be a non-negative number, got {min_span}")
    if not 0 <= percentile < 50:
        raise InputError(f"percentile must be in [0, 50), got {percentile}")
    scalars = _scalars(field, components)
    if frames is None:
        T = field.n_frames
        idx = np.arange(T) if T <= LIMIT_FRAMES else np.linspace(0, T - 1, LIMIT_FRAMES).round()
        idx = idx.astype(int)
    else:
        idx = np.array([_frame_index(field, f, "frames entry") for f in frames], dtype=int)
        if idx.size == 0:
            raise InputError("frames is empty; leave it out to use every frame")
    covered = [_frame_index(field, f, "cover entry") for f in cover]
    # a streamed field's frames a block at a time, every component's before the next block:
    # each block is computed once
    size = getattr(field, "block_frames", None) or field.n_frames
    picked: dict[str, list[np.ndarray]] = {comp: [] for comp in components}
    for b in np.unique(idx // size):
        at = idx[idx // size == b]
        for comp in components:
            picked[comp].append(_finite(scalars[comp][at]))
    out = {}
    for comp in components:
        finite = np.concatenate(picked[comp])
        if finite.size == 0:
            lo = hi = 0.0
        elif percentile > 0:
            lo, hi = (float(v) for v in np.percentile(finite, [percentile, 100 - percentile]))
        else:
            lo, hi = float(finite.min()), float(finite.max())
        shown = _finite(scalars[comp][covered]) if covered else np.empty(0)
        if shown.size:
            lo, hi = min(lo, float(shown.min())), max(hi, float(shown.max()))
        if symmetric:
            m = max(abs(lo), abs(hi), 0.5 * min_span)
            lo, hi = -m, m
        elif hi - lo < min_span:
            mid = 0.5 * (lo + hi)
            lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
        rlo, rhi = round(lo, 12) + 0.0, round(hi, 12) + 0.0
        # rounded outwards: a covered value must not fall just outside
        out[comp] = (rlo - 1e-12 if rlo > lo else rlo, rhi + 1e-12 if rhi < hi else rhi)
    return out


def _frame_limits(values: np.ndarray, min_span: float) -> tuple[float, float]:
    """One frame's full range, widened about its middle to at least ``min_span``."""
    finite = _finite(values)
    if finite.size == 0:
        return -0.5 * min_span, 0.5 * min_span
    lo, hi = float(finite.min()), float(finite.max())
    if hi - lo < min_span:
        mid = 0.5 * (lo + hi)
        lo, hi = mid - 0.5 * min_span, mid + 0.5 * min_span
    return lo, hi


class _Scale(NamedTuple):
    """A discrete colour scale: ``cmap`` has one colour per band between ``levels``."""

    cmap: Colormap
    norm: Normalize
    levels: np.ndarray


def _colour_scale(comp: str, lo: float, hi: float, n: int = 20) -> _Scale:
    """Colour scale of a component over ``[lo, hi]`` in ``n`` bands.

    Strain components use ``RdBu_r`` with zero white (``J``: one white); the
    part of the map used is the part ``[lo, hi]`` covers when the map spans
    ``[-m, m]`` about the centre, ``m`` the larger distance of an end from
    it.  ``theta1_deg`` uses the cyclic ``twilight_shifted``.
    """
    if not (np.isfinite(lo) and np.isfinite(hi) and hi > lo):
        raise InputError(f"colour limits of {comp} must be finite with low < high, got {(lo, hi)}")
    levels = np.linspace(lo, hi, n + 1)
    mids = 0.5 * (levels[:-1] + levels[1:])
    step = (hi - lo) / n
    if comp == "theta1_deg":
        base = colormaps["twilight_shifted"]
        pos = (np.concatenate([[lo - step / 2], mids, [hi + step / 2]]) - lo) / (hi - lo)
    else:
        base = colormaps["RdBu_r"]
        centre = 1.0 if comp == "J" else 0.0
        m = max(abs(lo - centre), abs(hi - centre))
        pos = 0.5 + (np.concatenate([[lo - step / 2], mids, [hi + step / 2]]) - centre) / (2 * m)
    colours = base(np.clip(pos, 0.0, 1.0))
    cmap = ListedColormap(colours[1:-1], name=f"{comp}_scale")
    cmap = cmap.with_extremes(under=colours[0], over=colours[-1])
    return _Scale(cmap, Normalize(lo, hi), levels)


def _colorbar(fig: Figure, ax, scale: _Scale, label: str, *, alpha: float = 1.0, **kwargs):
    lo, hi = scale.levels[0], scale.levels[-1]
    ticks = MaxNLocator(6).tick_values(lo, hi)
    ticks = ticks[(ticks >= lo - 1e-12 * (hi - lo)) & (ticks <= hi + 1e-12 * (hi - lo))]
    sm = ScalarMappable(norm=scale.norm, cmap=scale.cmap)
    cbar = fig.colorbar(sm, ax=ax, ticks=ticks, extend="both", alpha=alpha, **kwargs)
    cbar.set_label(label)
    return cbar
