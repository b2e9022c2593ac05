"""Principal strain directions drawn as crosses over a video frame."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from strain2d.errors import InputError
from strain2d.figures._checks import _check_2d, _check_image, _frame_index
from strain2d.figures._maps import _figsize_for_image, _show_image
from strain2d.figures._style import _SHORTENING, _STRETCH
from surface_strain import (
    StrainField,
    element_principal_directions,
    element_scalars,
    nodal_principal_directions,
    nodal_scalars,
)

__all__ = ["plot_principal_crosses", "principal_noise_floor"]


def _one_frame(field: StrainField, k: int) -> StrainField:
    """Frame ``k`` of ``field`` as a field of one frame (per-frame quantities are per frame)."""
    return field.frames(k, k + 1)


def _nice_value(x: float) -> float:
    """The largest of 1, 2, 5 times a power of ten not above ``x`` (``x > 0``)."""
    e = math.floor(math.log10(x))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0**e <= x * (1 + 1e-9):
            return float(f"{m * 10.0**e:.12g}")
    return float(f"{10.0**e:.12g}")


def _node_spacing(field: StrainField, frame: int) -> float:
    """Median over nodes of the shortest valid mesh edge at each node, on ``frame``."""
    tri = field.triangles[field.element_valid[frame]]
    if len(tri) == 0:
        return float("nan")
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    pos = field.points[frame]
    length = np.linalg.norm(pos[edges[:, 0]] - pos[edges[:, 1]], axis=1)
    shortest = np.full(field.n_points, np.inf)
    np.minimum.at(shortest, edges[:, 0], length)
    np.minimum.at(shortest, edges[:, 1], length)
    shortest = shortest[np.isfinite(shortest) & (shortest > 0)]
    return float(np.median(shortest)) if shortest.size else float("nan")


def principal_noise_floor(
    field: StrainField,
    sigma_px: float,
    *,
    frame: int = -1,
    quantile: float = 0.95,
    draws: int = 32,
    seed: int = 0,
) -> float:
    """The ``E1 - E2`` that tracking noise alone gives on this mesh at ``frame`` (a quantile).

    Gaussian noise of ``sigma_px`` per coordinate is added to the node
    positions of ``frame`` (``draws`` times; the reference positions are the
    field's own, as a tracker's are), the nodal strain computed as the run
    computes it, and the change of the strain tensor that the noise made is
    turned into the ``E1 - E2`` it would give on an isotropic strain:
    ``2 sqrt(((dExx - dEyy) / 2)^2 + dExy^2)``.  Its ``quantile`` over nodes
    and draws is returned: below it a difference of the principal strains is
    not distinguishable from noise, so their directions are not measured.
    The noise is taken at ``frame``'s deformation because Green-Lagrange
    strain amplifies it with the stretch (a contraction damps it).  Small
    noise is linear, so the floor scales with ``sigma_px``.
    """
    from surface_strain import compute_strain

    if not (np.isfinite(sigma_px) and sigma_px >= 0):
        raise InputError(f"sigma_px must be a number >= 0, got {sigma_px}")
    if sigma_px == 0:
        return 0.0
    k = _frame_index(field, frame)
    cur = field.points[k]
    ok = np.all(np.isfinite(cur), axis=1) & np.all(np.isfinite(field.reference), axis=1)
    tri = field.triangles[np.all(ok[field.triangles], axis=1)]
    if len(tri) == 0:
        return float("nan")
    ref = np.where(ok[:, None], field.reference, 0.0)
    base = np.where(ok[:, None], cur, 0.0)
    rng = np.random.default_rng(seed)
    noisy = base[None] + rng.normal(0.0, sigma_px, (draws, *base.shape))
    clean = nodal_scalars(compute_strain(ref, base[None], tri))
    node = nodal_scalars(compute_strain(ref, noisy, tri))
    dxx = node["Exx"] - clean["Exx"]
    dyy = node["Eyy"] - clean["Eyy"]
    dxy = node["Exy"] - clean["Exy"]
    diff = (2.0 * np.sqrt(((dxx - dyy) / 2.0) ** 2 + dxy**2))[:, ok]
    diff = diff[np.isfinite(diff)]
    return float(np.quantile(diff, quantile)) if diff.size else float("nan")


def plot_principal_crosses(
    image: np.ndarray,
    field: StrainField,
    frame: int,
    *,
    scale: float | None = None,
    at: Literal["nodes", "triangles"] = "nodes",
    key_value: float | None = None,
    title: str | None = None,
    noise: float = 0.0,
    length=None,
) -> Figure:
    """Principal strain directions as crosses over the image, on the deformed configuration.

    At each node (or triangle centroid) a cross of two bars centred on it:
    one along the first principal direction and one along the second, as
    directions in the current configuration (the material fibres along the
    reference principal directions after deformation, which stay
    orthogonal).  Each bar's length is ``scale * |E|`` of its principal
    strain, red for stretch (E > 0) and blue for shortening (E < 0).

    Parameters
    ----------
    image : (H, W) float or uint8
        The frame shown underneath.
    field : StrainField
        A 2D field.
    frame : int
    scale : float, keyword-only
        Bar length in pixels per unit strain.  Default: the longest bar is
        0.8 times the typical node spacing (the median over nodes of the
        shortest mesh edge), i.e. each arm from the centre is 0.4 of it.
    at : {"nodes", "triangles"}, keyword-only
        Nodal principal strains (:func:`surface_strain.nodal_scalars`,
        directions from :func:`surface_strain.nodal_principal_directions`)
        at the nodes, or the constant strain of each triangle at its centroid.
    key_value : float, keyword-only
        Strain of the key's bar (default: a round value, 1, 2 or 5 times a
        power of ten, not above the largest |E| drawn).
    title : str, keyword-only
    noise : float, keyword-only
        The strain noise floor: where ``E1 - E2`` is not above it the
        principal directions are not measured (any direction fits the data
        within noise), and the point is drawn as an open circle of diameter
        ``scale * |E1 + E2| / 2`` instead of a cross (see
        :func:`principal_noise_floor`).  Default 0: crosses everywhere the
        strain is not exactly isotropic.
    length : PixelScale, keyword-only
        The pixel size: axes in its unit instead of pixels.

    Returns
    -------
    matplotlib.figure.Figure
        The bars are two :class:`~matplotlib.collections.LineCollection`
        artists with ``gid`` ``"E1"`` and ``"E2"`` (one segment per drawn
        point, in the same order); points without finite values are skipped,
        points isotropic within ``noise`` are in the collection with ``gid``
        ``"isotropic"`` (a circle each).
    """
    from matplotlib.patheffects import withStroke
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    image = _check_image(image)
    _check_2d(field)
    k = _frame_index(field, frame)
    if at not in ("nodes", "triangles"):
        raise InputError(f"at must be 'nodes' or 'triangles', got {at!r}")
    if scale is not None and not (np.isfinite(scale) and scale > 0):
        raise InputError(f"scale must be a positive number of pixels per unit strain, got {scale}")
    if key_value is not None and not (np.isfinite(key_value) and key_value > 0):
        raise InputError(f"key_value must be a positive strain, got {key_value}")
    if not (np.isfinite(noise) and noise >= 0):
        raise InputError(f"noise must be a strain >= 0, got {noise}")
    one = _one_frame(field, k)  # directions of this frame only, not of every frame
    if at == "nodes":
        s = nodal_scalars(one)
        d = nodal_principal_directions(one)
        centres = field.points[k]
        ok = field.visible[k].copy()
    else:
        s = element_scalars(one)
        d = element_principal_directions(one)
        centres = field.points[k][field.triangles].mean(axis=1)
        ok = field.element_valid[k].copy()
    e1, e2 = s["E1"][0], s["E2"][0]
    u1, u2 = d.dir1_cur[0], d.dir2_cur[0]
    ok &= np.isfinite(e1) & np.isfinite(e2) & np.all(np.isfinite(centres), axis=1)
    ok &= np.all(np.isfinite(u1), axis=1) & np.all(np.isfinite(u2), axis=1)
    iso = ok & np.isfinite(e1) & np.isfinite(e2) & (np.abs(e1 - e2) <= noise)
    iso &= np.all(np.isfinite(centres), axis=1)
    ok &= ~iso
    c_iso, e_iso = centres[iso], 0.5 * (e1[iso] + e2[iso])
    c, e1, e2, u1, u2 = centres[ok], e1[ok], e2[ok], u1[ok], u2[ok]
    largest = float(
        max(np.abs(e1).max(initial=0.0), np.abs(e2).max(initial=0.0), np.abs(e_iso).max(initial=0))
    )
    if scale is None:
        spacing = _node_spacing(field, k)
        if not np.isfinite(spacing):
            spacing = 0.1 * min(image.shape[:2])
        scale = 0.8 * spacing / largest if largest > 0 else 0.0

    fig = Figure(figsize=_figsize_for_image(image, 1, 6.4), layout="constrained")
    ax = fig.add_subplot()
    _show_image(ax, image, length=length)
    outline = [withStroke(linewidth=3.2, foreground="white")]
    for gid, e, u in (("E1", e1, u1), ("E2", e2, u2)):
        half = (0.5 * scale * np.abs(e))[:, None] * u
        segments = np.stack([c - half, c + half], axis=1)
        colours = np.where(e >= 0, _STRETCH, _SHORTENING)
        lc = LineCollection(segments, colors=colours, linewidths=1.8, capstyle="round")
        lc.set_gid(gid)
        lc.set_path_effects(outline)
        ax.add_collection(lc, autolim=False)
    handles = [
        Line2D([], [], color=_STRETCH, lw=2, label="stretch (E > 0)"),
        Line2D([], [], color=_SHORTENING, lw=2, label="shortening (E < 0)"),
    ]
    if c_iso.size:
        from matplotlib.collections import EllipseCollection

        diam = np.maximum(scale * np.abs(e_iso), 1e-9)
        circles = EllipseCollection(
            diam,
            diam,
            np.zeros_like(diam),
            units="xy",
            offsets=c_iso,
            offset_transform=ax.transData,
            facecolors="none",
            edgecolors=np.where(e_iso >= 0, _STRETCH, _SHORTENING),
            linewidths=1.4,
        )
        circles.set_gid("isotropic")
        circles.set_path_effects(outline)
        ax.add_collection(circles, autolim=False)
        handles.append(
            Line2D(
                [],
                [],
                ls="",
                marker="o",
                mfc="none",
                mec="0.3",
                mew=1.4,
                label=f"E1 - E2 within noise ({noise:.2g}): no direction",
            )
        )
    ax.legend(handles=handles, loc="upper right", fontsize=8, framealpha=0.85)
    if scale > 0 and largest > 0:
        value = _nice_value(largest) if key_value is None else float(key_value)
        bar = AnchoredSizeBar(
            ax.transData,
            scale * value,
            f"|E| = {value:g}",
            loc="lower right",
            color="k",
            frameon=True,
            size_vertical=0,
            pad=0.4,
            sep=4,
            fontproperties={"size": 8},
        )
        bar.patch.set_alpha(0.85)
        ax.add_artist(bar)
    where = "nodes" if at == "nodes" else "triangles"
    ax.set_title(title or f"principal strains at the {where}, frame {k}")
    return fig
