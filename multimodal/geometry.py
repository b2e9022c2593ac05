"""The camera's grid on the microscope's surface: lengths along a folding surface.

The camera sees the lumen from above: the projection of a wall that folds.
The multiphoton microscope measures the wall's height ``z(x, y)`` over the
same region (a height map, before and after).  A material edge of the
camera's mesh runs, on the tissue, along the surface: over the straight path
between its projected ends, its length is the arc length of the height map,

    L = integral over the path of sqrt(1 + (dz/ds)^2) ds,

with ``s`` the projected distance along the path.  A fold hides length from
the camera: a sheet that folds without stretching shortens in projection and
keeps its length along the surface.

From the three edges of a triangle, in the reference state and the deformed
one, the triangle's surface metric follows (each edge ``D`` with surface
length ``L`` gives one equation ``D^T G D = L^2``): ``G0`` before, ``G1``
after, both in the reference's projected coordinates.  The membrane strain on
the folded surface is then

    E = (R^-T G1 R^-1 - I) / 2,   G0 = R^T R  (R upper triangular),

in the orthonormal frame of the reference surface whose first axis is the
surface's tangent over the projected x axis (the same frame
:mod:`surface_strain` uses for curved surfaces).  On a flat height map every
surface length is the projected one, ``G0 = I``, ``G1 = F^T F``, and ``E``
is the 2D Green-Lagrange strain.

Without a registration to pixel level, :func:`directional_tortuosity`
measures, over the whole height map, how much longer the surface is than its
projection along each direction, and :func:`tortuosity_correction` scales
each triangle's principal stretches by it (before and after).

Coordinates: camera positions in pixels (x = column, y = row); the
microscope's in micrometres, ``(x, y) = origin + (column * dx, row * dy)``;
:class:`Similarity` maps the first to the second.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from tissue_core.errors import InputError

__all__ = [
    "EDGES",
    "Similarity",
    "SurfaceMap",
    "SurfaceMosaic",
    "Tortuosity",
    "directional_tortuosity",
    "fold_aware_strain",
    "surface_lengths",
    "surface_metric",
    "tortuosity_correction",
]

#: the edges of a triangle (p0, p1, p2), as pairs of its corners
EDGES = ((0, 1), (0, 2), (1, 2))

#: samples per height-map pixel along a path (bilinear heights: the path is resolved
#: far below a pixel)
SAMPLES_PER_PIXEL = 4

#: micrometres: the pixel sizes and camera scales taken as real (a picometre to a metre);
#: beyond them, a unit was mistaken
_PLAUSIBLE = (1e-6, 1e6)

#: map pixels between the knots of a shortest path's offsets across its chord
KNOT_PIXELS = 2.0

#: about the most segments laid along one direction by :func:`directional_tortuosity`
_MAX_SEGMENTS = 20_000

#: the most samples held at once when lengths are measured (memory: 8 bytes each, a few
#: arrays of this size)
_CHUNK_SAMPLES = 4_000_000


@dataclass(frozen=True, eq=False)
class SurfaceMap:
    """A height map: the surface's height over the microscope's x-y plane.

    Attributes
    ----------
    height_um : (Y, X) float
        Height in micrometres (any datum: only differences matter); NaN where
        the surface was not measured.
    pixel_um : (dy, dx)
        Pixel size in micrometres.
    origin_um : (x, y)
        Microscope coordinates of the centre of pixel (0, 0).
    source : str
        Where the map came from (for the run's records).
    measured : (Y, X) bool, optional
        Where the surface was measured rather than filled in (as ``mpm3d``
        fills its gaps); everywhere when None.
    """

    height_um: np.ndarray
    pixel_um: tuple[float, float]
    origin_um: tuple[float, float] = (0.0, 0.0)
    source: str = ""
    measured: np.ndarray | None = None

    def __post_init__(self) -> None:
        z = np.asarray(self.height_um, dtype=float)
        if z.ndim != 2 or min(z.shape) < 2:
            raise InputError(f"a height map must be 2D and at least 2 x 2, got shape {z.shape}")
        if not np.isfinite(z).any():
            raise InputError("the height map has no measured (finite) height")
        dy, dx = (float(v) for v in self.pixel_um)
        if not (_PLAUSIBLE[0] <= dx <= _PLAUSIBLE[1] and _PLAUSIBLE[0] <= dy <= _PLAUSIBLE[1]):
            raise InputError(
                f"the height map's pixel size {self.pixel_um} um is not a microscope's "
                f"({_PLAUSIBLE[0]:g} to {_PLAUSIBLE[1]:g} um)"
            )
        x0, y0 = (float(v) for v in self.origin_um)
        if not (math.isfinite(x0) and math.isfinite(y0)):
            raise InputError(f"the height map's origin must be finite, got {self.origin_um}")
        object.__setattr__(self, "height_um", z)
        object.__setattr__(self, "pixel_um", (dy, dx))
        object.__setattr__(self, "origin_um", (x0, y0))
        if self.measured is not None:
            measured = np.asarray(self.measured, dtype=bool)
            if measured.shape != z.shape:
                raise InputError(
                    f"the measured mask's shape {measured.shape} differs from the map's {z.shape}"
                )
            object.__setattr__(self, "measured", measured)

    @classmethod
    def flat(
        cls, shape: tuple[int, int], pixel_um: float | tuple[float, float], **kwargs
    ) -> SurfaceMap:
        """A flat map of ``shape`` pixels (height 0)."""
        size = (pixel_um, pixel_um) if np.isscalar(pixel_um) else tuple(pixel_um)
        return cls(np.zeros(shape), size, **kwargs)

    @property
    def shape(self) -> tuple[int, int]:
        return self.height_um.shape

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)`` in micrometres: the centres of the corner pixels."""
        (dy, dx), (x0, y0) = self.pixel_um, self.origin_um
        Y, X = self.shape
        return x0, y0, x0 + (X - 1) * dx, y0 + (Y - 1) * dy

    def heights(self, xy_um: np.ndarray) -> np.ndarray:
        """Bilinear heights at ``xy_um`` (..., 2); NaN outside the map or next to a gap."""
        xy = np.asarray(xy_um, dtype=float)
        (dy, dx), (x0, y0) = self.pixel_um, self.origin_um
        Y, X = self.shape
        c = (xy[..., 0] - x0) / dx
        r = (xy[..., 1] - y0) / dy
        tol = 1e-9
        inside = (c >= -tol) & (c <= X - 1 + tol) & (r >= -tol) & (r <= Y - 1 + tol)
        c = np.clip(np.nan_to_num(c, nan=0.0), 0.0, X - 1)
        r = np.clip(np.nan_to_num(r, nan=0.0), 0.0, Y - 1)
        i = np.minimum(np.floor(r).astype(np.intp), Y - 2)
        j = np.minimum(np.floor(c).astype(np.intp), X - 2)
        fr, fc = r - i, c - j
        z = self.height_um
        out = (z[i, j] * (1 - fc) + z[i, j + 1] * fc) * (1 - fr) + (
            z[i + 1, j] * (1 - fc) + z[i + 1, j + 1] * fc
        ) * fr
        return np.where(inside, out, np.nan)

    def filled(self, xy_um: np.ndarray) -> np.ndarray:
        """Whether the nearest pixel's height was filled in, not measured (False off the
        map and where every height was measured)."""
        xy = np.asarray(xy_um, dtype=float)
        if self.measured is None:
            return np.zeros(xy.shape[:-1], bool)
        (dy, dx), (x0, y0) = self.pixel_um, self.origin_um
        Y, X = self.shape
        c = np.rint(np.nan_to_num((xy[..., 0] - x0) / dx, nan=-1.0)).astype(np.intp)
        r = np.rint(np.nan_to_num((xy[..., 1] - y0) / dy, nan=-1.0)).astype(np.intp)
        inside = (c >= 0) & (c < X) & (r >= 0) & (r < Y)
        return inside & ~self.measured[r.clip(0, Y - 1), c.clip(0, X - 1)]


class SurfaceMosaic:
    """Height-map tiles at their stage positions, read as one surface.

    A point takes its height from the tile that holds it with a measured
    height and whose centre is nearest (where tiles overlap, the middle of
    a tile is trusted before its edge).  Tiles of one pixel grid give, where
    they hold a point, exactly the stitched map's bilinear height.  Tiles
    must overlap by a pixel at least (microscope mosaics overlap by 5-20 %):
    between two tiles that only abut, no height is interpolated and a path
    across the seam has no length.

    Parameters
    ----------
    tiles : sequence of SurfaceMap
        Each with its ``origin_um`` (the stage position of its pixel (0, 0)).
    """

    def __init__(self, tiles: Sequence[SurfaceMap], *, source: str = "") -> None:
        tiles = list(tiles)
        if not tiles:
            raise InputError("a mosaic needs at least one tile")
        self.tiles = tiles
        self.source = source
        self.pixel_um = (min(t.pixel_um[0] for t in tiles), min(t.pixel_um[1] for t in tiles))
        bounds = np.array([t.bounds() for t in tiles])
        self._bounds = (
            float(bounds[:, 0].min()), float(bounds[:, 1].min()),
            float(bounds[:, 2].max()), float(bounds[:, 3].max()),
        )  # fmt: skip
        self._centres = np.column_stack(
            [(bounds[:, 0] + bounds[:, 2]) / 2, (bounds[:, 1] + bounds[:, 3]) / 2]
        )

    @property
    def shape(self) -> tuple[int, int]:
        """The mosaic's extent in its finest pixels (rows, columns)."""
        x0, y0, x1, y1 = self._bounds
        dy, dx = self.pixel_um
        return round((y1 - y0) / dy) + 1, round((x1 - x0) / dx) + 1

    def bounds(self) -> tuple[float, float, float, float]:
        """``(x0, y0, x1, y1)``: the box around every tile (parts of it may be no tile's)."""
        return self._bounds

    def _choice(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per point, the height and the index of the tile it comes from (-1: none)."""
        best = np.full(xy.shape[:-1], np.inf)
        height = np.full(xy.shape[:-1], np.nan)
        which = np.full(xy.shape[:-1], -1)
        for k, (tile, centre) in enumerate(zip(self.tiles, self._centres, strict=True)):
            z = tile.heights(xy)
            d = np.sum((xy - centre) ** 2, axis=-1)
            take = np.isfinite(z) & (d < best)
            height = np.where(take, z, height)
            which = np.where(take, k, which)
            best = np.where(take, d, best)
        return height, which

    def heights(self, xy_um: np.ndarray) -> np.ndarray:
        return self._choice(np.asarray(xy_um, dtype=float))[0]

    def filled(self, xy_um: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy_um, dtype=float)
        _, which = self._choice(xy)
        out = np.zeros(xy.shape[:-1], bool)
        for k, tile in enumerate(self.tiles):
            mine = which == k
            if mine.any():
                out[mine] = tile.filled(xy[mine])
        return out


@dataclass(frozen=True)
class Similarity:
    """Camera pixels to microscope micrometres: ``m = scale * R(angle) * M c + shift``.

    ``M`` mirrors the camera's y axis where ``mirrored`` (a microscope that
    sees the tissue from the other side); ``scale`` is micrometres per camera
    pixel, ``angle_deg`` the rotation ``x' = x cos a - y sin a``, ``y' = x
    sin a + y cos a`` (clockwise on screen, where y points down).
    """

    scale: float
    angle_deg: float = 0.0
    shift_um: tuple[float, float] = (0.0, 0.0)
    mirrored: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise InputError(f"the transform's scale must be positive, got {self.scale}")
        if not _PLAUSIBLE[0] <= self.scale <= _PLAUSIBLE[1]:
            raise InputError(
                f"the transform's scale of {self.scale:g} um per camera pixel is not plausible "
                "(are the microscope's coordinates in um?)"
            )
        if not math.isfinite(self.angle_deg) or not all(map(math.isfinite, self.shift_um)):
            raise InputError("the transform's angle and shift must be finite")

    @property
    def matrix(self) -> np.ndarray:
        """(2, 2): ``scale * R * M``."""
        a = math.radians(self.angle_deg)
        R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        M = np.diag([1.0, -1.0 if self.mirrored else 1.0])
        return self.scale * R @ M

    def apply(self, xy_px: np.ndarray) -> np.ndarray:
        """Camera pixels (..., 2) to microscope micrometres."""
        return np.asarray(xy_px, float) @ self.matrix.T + np.asarray(self.shift_um)

    def inverse(self, xy_um: np.ndarray) -> np.ndarray:
        """Microscope micrometres (..., 2) to camera pixels."""
        return (np.asarray(xy_um, float) - np.asarray(self.shift_um)) @ np.linalg.inv(self.matrix).T

    @classmethod
    def from_landmarks(
        cls, camera_px: np.ndarray, microscope_um: np.ndarray, *, mirrored: bool = False
    ) -> tuple[Similarity, np.ndarray]:
        """The least-squares similarity through landmark pairs, and each pair's residual (um).

        Closed form (Umeyama 1991): the rotation from the SVD of the
        landmarks' cross-covariance, the scale from its singular values.  Two
        landmarks fix the transform exactly (residuals 0); give three or more
        to measure how well it holds.
        """
        c = np.asarray(camera_px, float)
        m = np.asarray(microscope_um, float)
        if c.ndim != 2 or c.shape[1] != 2 or c.shape != m.shape:
            raise InputError(
                f"landmarks: need (K, 2) camera and microscope points of the same shape, got "
                f"{c.shape} and {m.shape}"
            )
        if len(c) < 2:
            raise InputError(f"landmarks: need at least 2 pairs, got {len(c)}")
        if not (np.isfinite(c).all() and np.isfinite(m).all()):
            raise InputError("landmarks: every coordinate must be a finite number")
        if mirrored:
            c = c * np.array([1.0, -1.0])
        mc, mm = c.mean(axis=0), m.mean(axis=0)
        a, b = c - mc, m - mm
        spread = float(np.mean(np.sum(a**2, axis=1)))
        if spread <= 1e-12 or float(np.mean(np.sum(b**2, axis=1))) <= 1e-12:
            raise InputError("landmarks: the points all lie at one place")
        U, S, Vt = np.linalg.svd(b.T @ a / len(c))
        d = np.array([1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
        R = U @ np.diag(d) @ Vt
        scale = float(np.sum(S * d) / spread)
        if not scale > 0:
            raise InputError("landmarks: no similarity fits them (are the pairs in order?)")
        angle = math.degrees(math.atan2(R[1, 0], R[0, 0]))
        shift = mm - scale * R @ mc
        transform = cls(scale, angle, (float(shift[0]), float(shift[1])), mirrored)
        residual = np.hypot(*(transform.apply(np.asarray(camera_px, float)) - m).T)
        return transform, residual

    def as_dict(self) -> dict:
        return {
            "scale_um_per_px": self.scale,
            "angle_deg": self.angle_deg,
            "shift_um": list(self.shift_um),
            "mirrored": self.mirrored,
        }


def surface_lengths(
    surface: SurfaceMap,
    starts_um: np.ndarray,
    ends_um: np.ndarray,
    *,
    path: str = "geodesic",
    samples_per_pixel: int = SAMPLES_PER_PIXEL,
) -> np.ndarray:
    """Length along the surface between ``starts_um`` and ``ends_um``.

    Parameters
    ----------
    surface : SurfaceMap
    starts_um, ends_um : (E, 2) float
        The paths' ends in microscope coordinates.
    path : {"geodesic", "chord"}
        ``"chord"``: the arc length over the straight projected path.
        ``"geodesic"`` (default): the shortest path on the surface near it
        (the chord's points moved across it until the length is least).  A
        material line of a wall that folds and stretches evenly is such a
        shortest path; the chord is longer wherever it crosses folds
        obliquely (0.2-0.9 % at 30-60 degrees to folds of slope 1.2-2).
    samples_per_pixel : int
        Samples per pixel of the map along each path.

    Returns
    -------
    (E,) float
        Micrometres; NaN where a path leaves the map, crosses a gap or has a
        NaN end.  A flat map gives the straight distance (to rounding).
    """
    if path not in ("geodesic", "chord"):
        raise InputError(f"path must be 'geodesic' or 'chord', got {path!r}")
    a = np.asarray(starts_um, float).reshape(-1, 2)
    b = np.asarray(ends_um, float).reshape(-1, 2)
    if a.shape != b.shape:
        raise ValueError(f"starts and ends differ in shape: {a.shape} and {b.shape}")
    out = np.full(len(a), np.nan)
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    if not ok.any():
        return out
    step = min(surface.pixel_um) / max(int(samples_per_pixel), 1)
    chord = np.hypot(*(b - a).T)
    n = np.where(ok, np.ceil(np.nan_to_num(chord) / step).astype(np.int64) + 1, 2)
    n = np.maximum(n, 2)
    # paths of similar length together: one sample count per group, no more than needed
    order = np.argsort(n)
    start = 0
    while start < len(order):
        count = int(n[order[start]])
        stop = start + 1
        while stop < len(order) and n[order[stop]] <= 2 * count:
            stop += 1
        samples = int(n[order[stop - 1]])
        rows = max(1, _CHUNK_SAMPLES // samples)
        stop = min(stop, start + rows)
        idx = order[start:stop]
        idx = idx[ok[idx]]
        if idx.size:
            chord_lengths = _lengths(surface, a[idx], b[idx], samples)
            if path == "geodesic":
                chord_lengths = _geodesic(surface, a[idx], b[idx], samples, chord_lengths)
            out[idx] = chord_lengths
        start = stop
    return out


def _lengths(surface: SurfaceMap, a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    """Arc lengths over straight paths sampled at ``n`` equally spaced points each."""
    t = np.linspace(0.0, 1.0, n)
    delta = (b - a) / (n - 1)  # the same projected step all along a path
    points = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    z = surface.heights(points)
    dz = np.diff(z, axis=1)
    flat2 = np.sum(delta**2, axis=1)[:, None]
    return np.sum(np.sqrt(flat2 + dz**2), axis=1)


def _geodesic(
    surface: SurfaceMap, a: np.ndarray, b: np.ndarray, n: int, chord: np.ndarray
) -> np.ndarray:
    """The least length of paths from ``a`` to ``b`` that leave the chord only sideways.

    The offsets across the chord are linear between knots :data:`KNOT_PIXELS`
    map pixels apart (a fold is many pixels wide: the shortest path bends
    over tens of them) and bounded so that the path stays on the map.
    L-BFGS-B minimises the length sampled once per map pixel, with its
    gradient from the surface's slope across the chord (central differences
    a quarter pixel apart; 0.5 % from the exact one on a bilinear map, which
    leaves the lengths within 3e-4 of the shortest); the path found is then
    measured at all ``n`` samples.  The edges are solved as one problem; an
    edge whose path would step into a gap of the map is solved again on its
    own, and the others without it.  Where the chord's length is NaN, or no
    shorter path is found, the chord's length is kept.
    """
    from scipy.optimize import minimize

    use = np.isfinite(chord)
    out = chord.copy()
    if not use.any() or n < 3:
        return out
    a, b = a[use], b[use]
    E = len(a)
    length = np.hypot(*(b - a).T)
    pixel = min(surface.pixel_um)
    knots = np.linspace(0.0, 1.0, max(3, int(np.ceil(length.max() / (KNOT_PIXELS * pixel))) + 1))
    K = len(knots)
    across = np.stack([-(b - a)[:, 1], (b - a)[:, 0]], axis=1) / np.maximum(length, 1e-300)[:, None]
    # how far each knot may move either way and stay on the map (a rectangle: the path,
    # linear between knots, stays on it too)
    x0, y0, x1, y1 = surface.bounds()
    q = a[:, None, :] + knots[None, :, None] * (b - a)[:, None, :]  # (E, K, 2)
    lo, hi = np.full((E, K), -np.inf), np.full((E, K), np.inf)
    for axis, (low, high) in enumerate(((x0, x1), (y0, y1))):
        d = across[:, axis][:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            to_low, to_high = (low - q[..., axis]) / d, (high - q[..., axis]) / d
        moving = np.abs(d) > 1e-12
        lo = np.where(moving, np.maximum(lo, np.minimum(to_low, to_high)), lo)
        hi = np.where(moving, np.minimum(hi, np.maximum(to_low, to_high)), hi)
    reach = 0.25 * length[:, None]
    lo, hi = np.maximum(lo, -reach), np.minimum(hi, reach)
    lo, hi = np.minimum(lo, 0.0), np.maximum(hi, 0.0)
    bounds = list(zip(lo[:, 1:-1].ravel(), hi[:, 1:-1].ravel(), strict=True))

    def basis(count: int) -> tuple[np.ndarray, np.ndarray]:
        t = np.linspace(0.0, 1.0, count)
        B = np.zeros((count, K))
        cell = np.minimum(np.searchsorted(knots, t, side="right") - 1, K - 2)
        f = (t - knots[cell]) / (knots[cell + 1] - knots[cell])
        B[np.arange(count), cell] = 1 - f
        B[np.arange(count), cell + 1] += f
        return t, B[:, 1:-1]

    def path(w_knots: np.ndarray, t: np.ndarray, B: np.ndarray, rows) -> np.ndarray:
        w = w_knots.reshape(len(rows), K - 2) @ B.T
        ab = (b - a)[rows]
        along = ab[:, None, :] * t[None, :, None] + a[rows][:, None, :]
        return along + w[..., None] * across[rows][:, None, :]

    t_fit, B_fit = basis(max(3, int(np.ceil(length.max() / pixel)) + 1))
    h = 0.25 * pixel
    # a path that steps into a gap costs each such segment this much (the chord, where every
    # path starts, has none), and its edge is noted: the edges solved together are then
    # solved again apart, so that one edge beside a gap does not hold the others back
    gap_cost = 10.0 * float(np.max(chord[use]))

    def solve(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        touched = np.zeros(len(rows), bool)

        def cost(w_knots: np.ndarray) -> tuple[float, np.ndarray]:
            p = path(w_knots, t_fit, B_fit, rows)
            z = surface.heights(p)
            step = h * across[rows][:, None, :]
            slope = (surface.heights(p + step) - surface.heights(p - step)) / (2 * h)
            dp = np.diff(p, axis=1)
            dz = np.diff(z, axis=1)
            seg = np.sqrt(np.sum(dp**2, axis=2) + dz**2)
            gap = ~np.isfinite(seg)
            touched[gap.any(axis=1)] = True
            seg = np.where(gap, 1.0, np.maximum(seg, 1e-300))
            dz = np.where(gap, 0.0, dz)
            sideways = np.where(gap, 0.0, np.einsum("ejk,ek->ej", dp, across[rows]))
            grad = np.zeros(p.shape[:2])
            grad[:, 1:] += (sideways + dz * np.nan_to_num(slope[:, 1:])) / seg
            grad[:, :-1] -= (sideways + dz * np.nan_to_num(slope[:, :-1])) / seg
            total = float(np.where(gap, gap_cost, seg).sum())
            return total, (grad @ B_fit).ravel()

        result = minimize(
            cost,
            np.zeros(len(rows) * (K - 2)),
            jac=True,
            method="L-BFGS-B",
            bounds=[bound for r in rows for bound in bounds[r * (K - 2) : (r + 1) * (K - 2)]],
            options={"maxiter": 1000, "ftol": 1e-12, "gtol": 1e-9},
        )
        return result.x.reshape(len(rows), K - 2), touched

    w_all = np.zeros((E, K - 2))
    pending = [np.arange(E)]
    while pending:
        rows = pending.pop()
        w, touched = solve(rows)
        if touched.any() and len(rows) > 1:
            if (~touched).any():
                pending.append(rows[~touched])
            pending.extend(np.array([r]) for r in rows[touched])
        else:
            w_all[rows] = w
    t, B = basis(n)
    p = path(w_all.ravel(), t, B, np.arange(E))
    z = surface.heights(p)
    found = np.sum(np.sqrt(np.sum(np.diff(p, axis=1) ** 2, axis=2) + np.diff(z, axis=1) ** 2), 1)
    better = np.isfinite(found) & (found <= chord[use])
    out[np.flatnonzero(use)[better]] = found[better]
    return out


def surface_metric(edges: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Per triangle, the symmetric ``G`` with ``D_i^T G D_i = L_i^2`` for its three edges.

    Parameters
    ----------
    edges : (M, 3, 2) float
        Each triangle's edges (:data:`EDGES`) in projected reference coordinates.
    lengths : (M, 3) float
        Their lengths along the surface, in the same unit.

    Returns
    -------
    (M, 2, 2) float
        NaN where a length is NaN or the triangle is degenerate.
    """
    D = np.asarray(edges, float)
    L = np.asarray(lengths, float)
    A = np.stack([D[..., 0] ** 2, 2 * D[..., 0] * D[..., 1], D[..., 1] ** 2], axis=-1)
    rhs = L**2
    bad = ~np.isfinite(rhs).all(axis=1) | ~np.isfinite(A).all(axis=(1, 2))
    det = np.linalg.det(np.where(bad[:, None, None], np.eye(3), A))
    scale = np.max(np.abs(A), axis=(1, 2)) ** 3
    bad |= ~(np.abs(det) > 1e-12 * np.where(scale > 0, scale, 1.0))
    g = np.linalg.solve(
        np.where(bad[:, None, None], np.eye(3), A), np.where(bad[:, None], 1.0, rhs)[..., None]
    )[..., 0]
    G = np.stack([g[:, [0, 1]], g[:, [1, 2]]], axis=1)
    G[bad] = np.nan
    return G


def _edge_vectors(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(..., M, 3, 2): each triangle's edges (:data:`EDGES`)."""
    p = points[..., triangles, :]
    return np.stack([p[..., j, :] - p[..., i, :] for i, j in EDGES], axis=-2)


def _strain_from_metrics(G0: np.ndarray, G1: np.ndarray) -> np.ndarray:
    """``(R^-T G1 R^-1 - I) / 2`` with ``G0 = R^T R`` (R upper triangular); NaN where
    ``G0`` is not positive definite."""
    bad = ~np.isfinite(G0).all(axis=(-2, -1)) | ~np.isfinite(G1).all(axis=(-2, -1))
    g11, g12, g22 = G0[..., 0, 0], G0[..., 0, 1], G0[..., 1, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        r11 = np.sqrt(g11)
        r12 = g12 / r11
        r22 = np.sqrt(g22 - r12**2)
    bad |= ~(np.isfinite(r11) & np.isfinite(r22) & (r11 > 0) & (r22 > 0))
    one = np.ones_like(g11)
    r11, r12, r22 = (np.where(bad, v, w) for v, w in ((one, r11), (0 * one, r12), (one, r22)))
    Rinv = np.zeros(G0.shape)
    Rinv[..., 0, 0] = 1 / r11
    Rinv[..., 0, 1] = -r12 / (r11 * r22)
    Rinv[..., 1, 1] = 1 / r22
    G1 = np.where(bad[..., None, None], np.eye(2), G1)
    E = 0.5 * (np.swapaxes(Rinv, -1, -2) @ G1 @ Rinv - np.eye(2))
    E[bad] = np.nan
    return E


def fold_aware_strain(
    reference_px: np.ndarray,
    current_px: np.ndarray,
    triangles: np.ndarray,
    before: SurfaceMap,
    after: SurfaceMap,
    transform: Similarity,
    *,
    path: str = "geodesic",
    samples_per_pixel: int = SAMPLES_PER_PIXEL,
) -> dict[str, np.ndarray]:
    """Membrane strain of each triangle along the folding surface.

    Parameters
    ----------
    reference_px : (N, 2) float
        The camera's nodes on the reference frame (the frame ``before``
        shows), pixels.
    current_px : (N, 2) float
        The same nodes on the frame ``after`` shows (NaN where lost).
    triangles : (M, 3) int
    before, after : SurfaceMap
        The microscope's height maps of the two states.
    transform : Similarity
        Camera pixels to microscope micrometres (the same for both states:
        the camera and the microscope do not move relative to each other, or
        the maps were registered to the same frame).
    path : {"geodesic", "chord"}
        How an edge runs on the surface (:func:`surface_lengths`).

    Returns
    -------
    dict
        ``E`` (M, 2, 2): membrane strain on the surface (the reference
        surface's frame, first axis over projected x); ``E_projected`` (M, 2,
        2): the camera's 2D strain of the same triangles, and ``F`` (M, 2,
        2) its deformation gradient; ``L0``, ``L1`` (M,
        3): the edges' surface lengths before and after (um); ``P0``, ``P1``
        (M, 3): their projected lengths (um); ``G0``, ``G1`` (M, 2, 2): the
        surface metrics in reference projected pixels.  A triangle with an
        edge off either map, over a gap, or lost, has NaN.
    """
    from surface_strain import deformation_gradient, green_lagrange

    X = np.asarray(reference_px, float)
    x = np.asarray(current_px, float)
    tri = np.asarray(triangles, dtype=np.intp)
    ends = np.array(EDGES)
    i, j = tri[:, ends[:, 0]].ravel(), tri[:, ends[:, 1]].ravel()
    X_um, x_um = transform.apply(X), transform.apply(x)
    options = {"path": path, "samples_per_pixel": samples_per_pixel}
    L0 = surface_lengths(before, X_um[i], X_um[j], **options)
    L1 = surface_lengths(after, x_um[i], x_um[j], **options)
    M = len(tri)
    L0, L1 = L0.reshape(M, 3), L1.reshape(M, 3)
    D = _edge_vectors(X, tri)
    G0 = surface_metric(D, L0 / transform.scale)
    G1 = surface_metric(D, L1 / transform.scale)
    E = _strain_from_metrics(G0, G1)
    F = deformation_gradient(X, x, tri)
    E_proj = green_lagrange(F)
    filled = (
        np.maximum(_filled_share(before, X_um[i], X_um[j]), _filled_share(after, x_um[i], x_um[j]))
        .reshape(M, 3)
        .max(axis=1)
    )
    return {
        "E": E,
        "E_projected": E_proj,
        "F": F,
        "L0": L0,
        "L1": L1,
        "P0": np.hypot(*(X_um[j] - X_um[i]).T).reshape(M, 3),
        "P1": np.hypot(*(x_um[j] - x_um[i]).T).reshape(M, 3),
        "G0": G0,
        "G1": G1,
        "filled_share": filled,
    }


def _filled_share(surface, a: np.ndarray, b: np.ndarray, samples: int = 64) -> np.ndarray:
    """Per path, the share of its chord over heights the map filled in."""
    t = np.linspace(0.0, 1.0, samples)
    points = a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]
    return surface.filled(points).mean(axis=1)


@dataclass(frozen=True)
class Tortuosity:
    """How much longer the surface is than its projection, per direction.

    Attributes
    ----------
    angles_deg : (A,) float
        Directions in the microscope's x-y plane, 0 <= angle < 180.
    mean : (A,) float
        Mean surface length over projected length of the segments laid
        along each direction (1 on a flat surface).
    sd : (A,) float
        Their standard deviation over the field of view: how much one
        segment's tortuosity may differ from the mean.
    count : (A,) int
        Segments measured per direction.
    segment_um : float
        The segments' projected length.
    """

    angles_deg: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    count: np.ndarray
    segment_um: float

    def at(self, angle_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean and SD at any angles (periodic in 180 degrees, linear in between)."""
        a = np.mod(np.asarray(angle_deg, float), 180.0)
        grid = np.concatenate(
            [[self.angles_deg[-1] - 180.0], self.angles_deg, [self.angles_deg[0] + 180.0]]
        )

        def periodic(v: np.ndarray) -> np.ndarray:
            return np.concatenate([v[-1:], v, v[:1]])

        return np.interp(a, grid, periodic(self.mean)), np.interp(a, grid, periodic(self.sd))


def directional_tortuosity(
    surface: SurfaceMap,
    segment_um: float,
    *,
    angles_deg: Sequence[float] | None = None,
    spacing_um: float | None = None,
    samples_per_pixel: int = SAMPLES_PER_PIXEL,
) -> Tortuosity:
    """Tortuosity of the surface along each direction, from the whole map.

    Straight segments of projected length ``segment_um`` are laid side by
    side (``spacing_um`` apart, default a tenth of a segment, at least a
    pixel) and end to end over the map along each direction; each gives the
    ratio of its surface length to ``segment_um``.  Segments that leave the
    map or cross a gap are left out.

    Raises
    ------
    InputError
        When a direction has no segment on the map (``segment_um`` larger
        than the map).
    """
    segment = float(segment_um)
    if not (math.isfinite(segment) and segment > 0):
        raise InputError(f"the segment length must be positive, got {segment_um}")
    angles = np.arange(0.0, 180.0, 5.0) if angles_deg is None else np.asarray(angles_deg, float)
    if angles.ndim != 1 or angles.size == 0:
        raise InputError("give at least one direction")
    angles = np.unique(np.mod(angles, 180.0))
    spacing = max(segment / 10.0, max(surface.pixel_um)) if spacing_um is None else spacing_um
    x0, y0, x1, y1 = surface.bounds()
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    reach = 0.5 * math.hypot(x1 - x0, y1 - y0)
    means, sds, counts = [], [], []
    for angle in angles:
        a = math.radians(angle)
        u, v = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
        # at most about _MAX_SEGMENTS segments a direction: wider apart on a big map
        step = max(spacing, 2 * reach * 2 * reach / segment / _MAX_SEGMENTS)
        offsets = np.arange(-reach, reach + 1e-9, step)
        starts_along = np.arange(-reach, reach - segment + 1e-9, segment)
        if starts_along.size == 0:
            raise InputError(
                f"segments of {segment:g} um do not fit on the height map "
                f"({x1 - x0:g} x {y1 - y0:g} um)"
            )
        o, s = np.meshgrid(offsets, starts_along, indexing="ij")
        starts = centre + o.ravel()[:, None] * v + s.ravel()[:, None] * u
        ends = starts + segment * u
        inside = _inside(starts, x0, y0, x1, y1) & _inside(ends, x0, y0, x1, y1)
        starts, ends = starts[inside], ends[inside]
        lengths = surface_lengths(
            surface, starts, ends, path="chord", samples_per_pixel=samples_per_pixel
        )
        ratio = lengths[np.isfinite(lengths)] / segment
        if ratio.size == 0:
            raise InputError(
                f"no segment of {segment:g} um along {angle:g} deg lies on the height map's "
                "measured surface"
            )
        means.append(float(ratio.mean()))
        sds.append(float(ratio.std(ddof=1)) if ratio.size > 1 else 0.0)
        counts.append(int(ratio.size))
    return Tortuosity(angles, np.array(means), np.array(sds), np.array(counts), segment)


def _inside(p: np.ndarray, x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return (p[:, 0] >= x0) & (p[:, 0] <= x1) & (p[:, 1] >= y0) & (p[:, 1] <= y1)


def tortuosity_correction(
    F: np.ndarray,
    before: Tortuosity,
    after: Tortuosity,
    transform: Similarity,
) -> dict[str, np.ndarray]:
    """Each triangle's principal stretches scaled by the surface's tortuosity.

    A material line along the reference principal direction ``v`` has
    surface length ``tau_before(v) * p`` for projected length ``p``; after
    the deformation, its projection ``lambda * p`` runs along ``F v``, with
    surface length ``tau_after(F v) * lambda * p``.  Its stretch along the
    surface is therefore ``lambda * tau_after(F v) / tau_before(v)``.  The
    corrected tensor keeps the projected principal directions.

    Parameters
    ----------
    F : (M, 2, 2) float
        The camera's deformation gradients (pixels).
    before, after : Tortuosity
        Of the two height maps, in microscope directions.
    transform : Similarity
        Camera to microscope (its rotation and mirroring turn the camera's
        directions into the microscope's).

    Returns
    -------
    dict
        ``E`` (M, 2, 2): corrected strain in the camera's x-y frame;
        ``E_principal`` (M, 2) and its ``E_principal_sd`` (M, 2) from the
        tortuosities' spread; ``stretch_projected`` (M, 2) and ``factor``
        (M, 2), the ratio ``tau_after / tau_before`` per principal direction.
    """
    F = np.asarray(F, float)
    bad = ~np.isfinite(F).all(axis=(-2, -1))
    Fs = np.where(bad[:, None, None], np.eye(2), F)
    C = np.swapaxes(Fs, -1, -2) @ Fs
    w, V = np.linalg.eigh(C)  # ascending: E2 then E1
    w, V = w[:, ::-1], V[:, :, ::-1]
    stretch = np.sqrt(np.maximum(w, 0.0))
    A = transform.matrix / transform.scale  # rotation (and mirror): camera to microscope
    ref_dirs = np.einsum("ij,mjk->mik", A, V)
    cur_dirs = np.einsum("ij,mjk->mik", A, Fs @ V)
    ref_angle = np.degrees(np.arctan2(ref_dirs[:, 1, :], ref_dirs[:, 0, :]))
    cur_angle = np.degrees(np.arctan2(cur_dirs[:, 1, :], cur_dirs[:, 0, :]))
    tb, sb = before.at(ref_angle)
    ta, sa = after.at(cur_angle)
    factor = ta / tb
    corrected = stretch * factor
    E_principal = 0.5 * (corrected**2 - 1.0)
    relative = np.sqrt((sa / ta) ** 2 + (sb / tb) ** 2)
    E_sd = corrected**2 * relative
    E = np.einsum("mik,mk,mjk->mij", V, E_principal, V)
    for array in (E, E_principal, E_sd, stretch, factor):
        array[bad] = np.nan
    return {
        "E": E,
        "E_principal": E_principal,
        "E_principal_sd": E_sd,
        "stretch_projected": stretch,
        "factor": factor,
    }
