"""The microscope's surface on a stereo camera's surface: a 3D similarity, refined by ICP.

A stereo run (:mod:`stereo`) gives the tissue's surface in the camera's
frame (millimetres, say); ``mpm3d`` gives a patch of the same surface in the
microscope's micrometres, with its folds.  :class:`Similarity3D` maps the
microscope's points onto the camera's,

    x_camera = scale * Q @ x_microscope + shift,

where the microscope's point is ``(x, y, depth)`` in micrometres (``depth =
-height``: into the tissue, as the camera's z looks into the scene when both
look at the tissue from the same side, so that ``Q`` is a rotation; a
microscope that sees the tissue mirrored flips its x first, ``mirrored``).

It starts from landmark pairs (:meth:`Similarity3D.from_landmarks`, the
least-squares similarity of Umeyama, 1991, doi:10.1109/34.88573, with its
residual per pair) and is refined by :func:`refine_icp`: point-to-plane ICP
(Chen and Medioni, 1992, doi:10.1016/0262-8856(92)90066-C) of the microscope's
points onto the camera's triangle mesh (each point paired with its closest
point on the mesh; pairs much farther than the rest, or beyond the mesh's
border, left out), one damped Gauss-Newton step of the seven parameters
(rotation, shift, scale) at a time.

What the surfaces' shapes can fix, they fix; the rest stays where the
landmarks put it.  A patch of a smooth wall fixes its distance along the
normal and its two tilts, but not where it lies in the plane, its turn about
the normal, nor (without curvature) its scale: sliding it along the surface
changes no distance.  The step is damped in the directions the shapes do not
constrain, so those stay at the landmarks' values, and :class:`IcpResult`
says which of the seven the surfaces fixed (``fixed_by_surfaces``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from tissue_core.errors import InputError

if TYPE_CHECKING:
    from multimodal.geometry import SurfaceMap

__all__ = [
    "IcpResult",
    "Similarity3D",
    "closest_points_on_mesh",
    "heightmap_points",
    "mesh_index",
    "refine_icp",
]

#: the seven parameters of a step, in the surface's own frame: shifts along its two in-plane
#: axes and its normal, turns about them, and the scale
PARAMETERS = (
    "shift_u",
    "shift_v",
    "shift_normal",
    "tilt_about_u",
    "tilt_about_v",
    "turn_about_normal",
    "scale",
)
#: camera units per micrometre a 3D similarity may have: from kilometres to nanometres
PLAUSIBLE_SCALE = (1e-9, 1e3)
#: landmarks whose second spread is under this share of their first lie (nearly) on a line
LINE_SHARE = 1e-2
#: a direction counts as fixed by the surfaces when its curvature of the summed squared
#: distances is at least this share of the best-fixed direction's
FIXED_SHARE = 1e-3


@dataclass(frozen=True)
class Similarity3D:
    """``x_camera = scale * Q @ m(x_microscope) + shift``; ``m`` flips x when ``mirrored``.

    Attributes
    ----------
    scale : float
        Camera units per micrometre.
    rotation : (3, 3) float
        A rotation (determinant +1).
    shift : (3,) float
        Camera units.
    mirrored : bool
        The microscope sees the tissue mirrored (its x is flipped first).
    """

    scale: float
    rotation: np.ndarray
    shift: np.ndarray
    mirrored: bool = False

    def __post_init__(self) -> None:
        Q = np.asarray(self.rotation, dtype=float)
        t = np.asarray(self.shift, dtype=float)
        if Q.shape != (3, 3) or t.shape != (3,):
            raise InputError("a 3D similarity needs a 3 x 3 rotation and a shift of 3 values")
        if not (np.isfinite(Q).all() and np.isfinite(t).all() and np.abs(t).max() < 1e12):
            raise InputError("a 3D similarity's rotation and shift must be finite numbers")
        low, high = PLAUSIBLE_SCALE
        if not (math.isfinite(self.scale) and low <= self.scale <= high):
            raise InputError(
                f"a 3D similarity's scale of {self.scale:.3g} camera units per um is not "
                f"plausible ({low:g} to {high:g}; 0.001 for millimetres)"
            )
        # a rotation written with a few decimals: its nearest rotation (polar decomposition)
        if not np.allclose(Q @ Q.T, np.eye(3), atol=1e-3) or np.linalg.det(Q) < 0:
            raise InputError("a 3D similarity's rotation must be a rotation matrix")
        u, _, vt = np.linalg.svd(Q)
        Q = u @ vt
        object.__setattr__(self, "rotation", Q)
        object.__setattr__(self, "shift", t)
        object.__setattr__(self, "scale", float(self.scale))

    def _flip(self, points: np.ndarray) -> np.ndarray:
        p = np.array(points, dtype=float, copy=True).reshape(-1, 3)
        if self.mirrored:
            p[:, 0] *= -1
        return p

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Microscope ``(x, y, depth)`` um ``(N, 3)`` to camera coordinates ``(N, 3)``."""
        return self.scale * self._flip(points) @ self.rotation.T + self.shift

    def inverse(self, points: np.ndarray) -> np.ndarray:
        """Camera coordinates ``(N, 3)`` to microscope ``(x, y, depth)`` um."""
        p = (np.asarray(points, dtype=float).reshape(-1, 3) - self.shift) @ self.rotation
        p /= self.scale
        if self.mirrored:
            p[:, 0] *= -1
        return p

    @property
    def angle_deg(self) -> float:
        """The rotation's angle about its axis."""
        c = (np.trace(self.rotation) - 1) / 2
        return math.degrees(math.acos(min(1.0, max(-1.0, c))))

    @property
    def axis(self) -> np.ndarray:
        """The rotation's unit axis (x when the angle is 0)."""
        Q = self.rotation
        w = np.array([Q[2, 1] - Q[1, 2], Q[0, 2] - Q[2, 0], Q[1, 0] - Q[0, 1]])
        n = np.linalg.norm(w)
        if n > 1e-12:
            return w / n
        if self.angle_deg < 90:  # no rotation
            return np.array([1.0, 0.0, 0.0])
        vals, vecs = np.linalg.eigh((Q + np.eye(3)) / 2)  # a half turn: the axis is kept
        return vecs[:, np.argmax(vals)]

    def as_dict(self) -> dict:
        return {
            "scale_per_um": self.scale,
            "rotation": self.rotation.tolist(),
            "angle_deg": self.angle_deg,
            "axis": self.axis.tolist(),
            "shift": self.shift.tolist(),
            "mirrored": self.mirrored,
            "maps": "camera = scale * rotation @ (x, y, depth) + shift; depth = -height (um)",
        }

    @classmethod
    def from_dict(cls, d: dict) -> Similarity3D:
        """From :meth:`as_dict`'s keys: ``scale_per_um`` (a number), ``rotation`` (3 x 3
        numbers), ``shift`` (3 numbers), ``mirrored`` (true or false, default false)."""
        if not isinstance(d, dict):
            raise InputError("a 3D transform must be a JSON object")
        missing = [k for k in ("scale_per_um", "rotation", "shift") if k not in d]
        if missing:
            raise InputError(f"a 3D transform needs {', '.join(missing)}")
        mirrored = d.get("mirrored", False)
        if not isinstance(mirrored, bool):
            raise InputError(f"a 3D transform's mirrored must be true or false, got {mirrored!r}")
        values = {}
        for name, shape in (("scale_per_um", ()), ("rotation", (3, 3)), ("shift", (3,))):
            a = np.asarray(d[name], dtype=object)
            if a.shape != shape or not all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in a.ravel()
            ):
                size = " x ".join(map(str, shape)) or "one"
                raise InputError(f"a 3D transform's {name} must be {size} number(s)")
            try:
                values[name] = np.asarray(a, dtype=float)
            except OverflowError:
                raise InputError(f"a 3D transform's {name} is out of range") from None
        return cls(float(values["scale_per_um"]), values["rotation"], values["shift"], mirrored)

    @classmethod
    def from_landmarks(
        cls,
        microscope: np.ndarray,
        camera: np.ndarray,
        *,
        mirrored: bool = False,
        scale: float | None = None,
    ) -> tuple[Similarity3D, np.ndarray]:
        """The least-squares similarity through landmark pairs, and each pair's residual.

        Parameters
        ----------
        microscope : (K, 3) float
            ``(x, y, depth)`` in micrometres.
        camera : (K, 3) float
            The same points in the camera's frame.
        mirrored : bool, keyword-only
        scale : float, keyword-only
            Camera units per micrometre when known (the units' ratio, 1e-3
            for millimetres); fitted when None.

        Returns
        -------
        (Similarity3D, (K,) float)
            The transform and each pair's distance from it, in camera units.

        Raises
        ------
        InputError
            Fewer than 3 pairs, non-finite values, or pairs on one line.
        """
        src = np.asarray(microscope, dtype=float)
        dst = np.asarray(camera, dtype=float)
        if src.ndim != 2 or src.shape[1] != 3 or src.shape != dst.shape:
            raise InputError(
                f"landmark pairs must be (K, 3) on both sides, got {src.shape} and {dst.shape}"
            )
        if len(src) < 3:
            raise InputError(f"a 3D registration needs 3 landmark pairs or more, got {len(src)}")
        if not (np.isfinite(src).all() and np.isfinite(dst).all()):
            raise InputError("a landmark coordinate is not a finite number")
        if max(np.abs(src).max(), np.abs(dst).max()) >= 1e12:
            raise InputError("a landmark coordinate is beyond 1e12: not a plausible position")
        if scale is not None and not (
            math.isfinite(scale) and PLAUSIBLE_SCALE[0] <= scale <= PLAUSIBLE_SCALE[1]
        ):
            raise InputError(
                f"a scale of {scale:.3g} camera units per um is not plausible "
                f"({PLAUSIBLE_SCALE[0]:g} to {PLAUSIBLE_SCALE[1]:g}; 0.001 for millimetres)"
            )
        flipped = src.copy()
        if mirrored:
            flipped[:, 0] *= -1
        mu_s, mu_d = flipped.mean(axis=0), dst.mean(axis=0)
        a, b = flipped - mu_s, dst - mu_d
        for name, centred in (("microscope", a), ("camera", b)):
            s = np.linalg.svd(centred, compute_uv=False)
            if s[1] <= LINE_SHARE * max(s[0], 1e-300):
                raise InputError(
                    f"the {name} landmarks lie on one line, or nearly: a 3D registration needs "
                    "three pairs or more spread across the patch"
                )
        U, D, Vt = np.linalg.svd(b.T @ a / len(src))
        S = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0])
        Q = U @ S @ Vt
        fitted = float(np.trace(np.diag(D) @ S) / np.mean(np.sum(a**2, axis=1)))
        k = fitted if scale is None else float(scale)
        shift = mu_d - k * Q @ mu_s
        transform = cls(k, Q, shift, mirrored)
        residual = np.linalg.norm(transform.apply(src) - dst, axis=1)
        return transform, residual


def heightmap_points(
    surface: SurfaceMap, *, step: int = 1, measured_only: bool = True
) -> np.ndarray:
    """A height map's points as ``(x, y, depth)`` um ``(N, 3)``, every ``step``-th pixel.

    ``surface`` is a :class:`multimodal.geometry.SurfaceMap`; ``depth`` is
    ``-height``.  Pixels without a height are left out, and so are those
    ``mpm3d`` filled in when ``measured_only``.
    """
    z = surface.height_um[::step, ::step]
    dy, dx = surface.pixel_um
    x0, y0 = surface.origin_um
    rows, cols = np.nonzero(np.isfinite(z))
    if measured_only and surface.measured is not None:
        keep = np.asarray(surface.measured)[::step, ::step][rows, cols]
        rows, cols = rows[keep], cols[keep]
    return np.column_stack([x0 + cols * step * dx, y0 + rows * step * dy, -z[rows, cols]]).astype(
        float
    )


def _closest_on_triangles(
    p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The closest point of each triangle ``(a, b, c)`` to ``p`` (all ``(n, 3)``), and where
    on the triangle it lies: 0 inside, 1 on edge ab, 2 on bc, 3 on ca, 4 at a, 5 at b, 6 at c.

    Ericson, Real-Time Collision Detection (2005), 5.1.5, vectorised."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    feature = np.zeros(len(p), np.int8)
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v = np.where(denom != 0, vb / denom, 0.0)
        w = np.where(denom != 0, vc / denom, 0.0)
        out = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        edges = (
            ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), b, c - b,
             (d4 - d3) / ((d4 - d3) + (d5 - d6)), 2),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a, ac, d2 / (d2 - d6), 3),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a, ab, d1 / (d1 - d3), 1),
        )  # fmt: skip
        for on, start, along, t, code in edges:
            out = np.where(on[:, None], start + along * t[:, None], out)
            feature[on] = code
    # corners last: they win over the edges they end
    for on, corner, code in (
        ((d6 >= 0) & (d5 <= d6), c, 6),
        ((d3 >= 0) & (d4 <= d3), b, 5),
        ((d1 <= 0) & (d2 <= 0), a, 4),
    ):
        out = np.where(on[:, None], corner, out)
        feature[on] = code
    return out, feature


def _rim(triangles: np.ndarray, n_vertices: int) -> np.ndarray:
    """(M, 7) bool: whether each feature of each triangle (as :func:`_closest_on_triangles`
    numbers them) lies on the mesh's outer border."""
    T = np.asarray(triangles, np.intp)
    pairs = np.sort(T[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, inverse, counts = np.unique(pairs, axis=0, return_inverse=True, return_counts=True)
    on_edge = (counts[inverse.ravel()] == 1).reshape(-1, 3)  # ab, bc, ca
    rim_vertex = np.zeros(n_vertices, bool)
    rim_vertex[pairs[(counts[inverse.ravel()] == 1)].ravel()] = True
    out = np.zeros((len(T), 7), bool)
    out[:, 1:4] = on_edge
    out[:, 4:7] = rim_vertex[T]
    return out


def closest_points_on_mesh(
    points: np.ndarray,
    vertices: np.ndarray,
    triangles: np.ndarray,
    *,
    candidates: int = 8,
    index: tuple | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The closest point on a triangle mesh to each point.

    Each point is tried against the ``candidates`` triangles whose centroids
    are nearest (enough on a mesh of even triangles, as a tracked grid's).

    Returns
    -------
    closest : (N, 3) float
    distance : (N,) float
    triangle : (N,) int
        The triangle the closest point lies on.
    outside : (N,) bool
        The closest point lies on the mesh's outer border, not within it: the
        point lies beyond the mesh.

    ``index`` is :func:`mesh_index` of the mesh, made once for many calls.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    V = np.asarray(vertices, dtype=float)
    T = np.asarray(triangles, dtype=np.intp)
    tree, rim = index if index is not None else mesh_index(V, T)
    k = int(min(candidates, len(T)))
    _, near = tree.query(np.nan_to_num(p, nan=np.inf), k=k)
    near = np.asarray(near).reshape(len(p), k)
    near[near >= len(T)] = 0  # a point with no neighbour (not finite): any, its distance inf
    best = np.full(len(p), np.inf)
    closest = np.zeros_like(p)
    which = np.zeros(len(p), np.intp)
    where = np.zeros(len(p), np.int8)
    for j in range(k):
        t = near[:, j]
        q, feature = _closest_on_triangles(p, V[T[t, 0]], V[T[t, 1]], V[T[t, 2]])
        d = np.linalg.norm(q - p, axis=1)
        better = d < best  # NaN never is: such a point keeps an infinite distance
        best = np.where(better, d, best)
        closest[better] = q[better]
        which[better] = t[better]
        where[better] = feature[better]
    outside = rim[which, where]
    return closest, best, which, outside


def mesh_index(vertices: np.ndarray, triangles: np.ndarray) -> tuple:
    """What :func:`closest_points_on_mesh` needs of a mesh, made once: a k-d tree of the
    triangles' centroids and where the mesh's border is."""
    from scipy.spatial import cKDTree

    V = np.asarray(vertices, dtype=float)
    T = np.asarray(triangles, dtype=np.intp)
    return cKDTree(V[T].mean(axis=1)), _rim(T, len(V))


def _normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    V, T = np.asarray(vertices, float), np.asarray(triangles, np.intp)
    n = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return n / np.where(length > 0, length, 1.0)


def _rotation(omega: np.ndarray) -> np.ndarray:
    """Rodrigues: the rotation by ``|omega|`` about ``omega``."""
    angle = float(np.linalg.norm(omega))
    if angle < 1e-15:
        return np.eye(3)
    k = omega / angle
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


@dataclass(frozen=True)
class IcpResult:
    """What :func:`refine_icp` found.

    Attributes
    ----------
    transform : Similarity3D
    rms_before, rms_after : float
        RMS distance of the paired points from the camera's surface, in camera
        units, at the start and the end.
    fitness : float
        Share of the microscope's points paired at the end (over the mesh and
        not far off it).
    iterations : int
    converged : bool
    fixed_by_surfaces : dict
        Per parameter (:data:`PARAMETERS`, in the surface's frame: ``u``, ``v``
        in its plane, ``normal``), the share of it that the surfaces' shapes
        constrain (1: fully, 0: not at all; then it is the landmarks').
    distances : (N,) float
        Each microscope point's distance from the camera's surface at the end
        (camera units; NaN where not paired).
    """

    transform: Similarity3D
    rms_before: float
    rms_after: float
    fitness: float
    iterations: int
    converged: bool
    fixed_by_surfaces: dict
    distances: np.ndarray = field(repr=False)

    def as_dict(self) -> dict:
        return {
            "rms_before": self.rms_before,
            "rms_after": self.rms_after,
            "fitness": self.fitness,
            "iterations": self.iterations,
            "converged": self.converged,
            "fixed_by_surfaces": self.fixed_by_surfaces,
            "parameters_not_fixed": [k for k, v in self.fixed_by_surfaces.items() if v < 0.5],
        }


def _pairs(moved, vertices, triangles, normals, reject: float, floor: float, index=None):
    """Each moved point's closest point on the mesh, its distance, the normal there, and
    whether the pair counts: over the mesh, and within ``reject`` times the 90th percentile
    of the distances (or ``floor``), so that folds, whose crests lie farthest, all count."""
    closest, distance, which, outside = closest_points_on_mesh(
        moved, vertices, triangles, index=index
    )
    keep = ~outside & np.isfinite(distance)
    if keep.any():
        keep &= distance <= reject * max(float(np.quantile(distance[keep], 0.9)), floor)
    return closest, distance, normals[which], keep


def _patch_frame(y: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(3, 3): the patch's axes as rows, u and v in its plane and its normal (on the side of
    the mesh's normals), right-handed."""
    _, _, vt = np.linalg.svd(y - y.mean(axis=0), full_matrices=False)
    frame = vt.copy()
    if np.dot(frame[2], n.mean(axis=0)) < 0:
        frame[2] *= -1
    if np.linalg.det(frame) < 0:
        frame[1] *= -1
    return frame


def _jacobian(q, n, centre, frame, fit_scale: bool):
    """Rows: each pair's signed distance against the step's parameters, in the patch's
    frame; the turns and the scale times the patch's size (all in length units).

    The lever arms of the turns and the scale about ``centre`` are taken on the camera's
    surface (its closest points ``q``), not on the microscope's points: folds that the
    camera does not resolve then fix no turn and no scale (a scale fitted to them would
    flatten the folds onto the camera's smooth surface)."""
    d = q - centre
    length = float(np.sqrt(np.mean(np.sum(d**2, axis=1)))) or 1.0
    J = np.column_stack(
        [n @ frame.T, (np.cross(d, n) @ frame.T) / length, np.einsum("ij,ij->i", n, d) / length]
    )
    return (J if fit_scale else J[:, :6]), length


def refine_icp(
    microscope: np.ndarray,
    vertices: np.ndarray,
    triangles: np.ndarray,
    initial: Similarity3D,
    *,
    fit_scale: bool = True,
    max_iterations: int = 50,
    tolerance: float = 1e-7,
    reject: float = 3.0,
) -> IcpResult:
    """Refine ``initial`` by point-to-plane ICP of the microscope's points onto a mesh.

    Parameters
    ----------
    microscope : (N, 3) float
        ``(x, y, depth)`` um (:func:`heightmap_points`).
    vertices, triangles : (V, 3) float, (M, 3) int
        The camera's surface.
    initial : Similarity3D
        From the landmarks (:meth:`Similarity3D.from_landmarks`).
    fit_scale : bool, keyword-only
        Refine the scale too (where the shapes fix it).
    max_iterations : int, keyword-only
        Of each stage: rigid first, then with the scale (``fit_scale``).
    tolerance : float, keyword-only
        Stop when a step moves no point by more than this share of the
        patch's size.
    reject : float, keyword-only
        Pairs farther than this many times the 90th percentile of the distances
        are left out (a patch's folds lie off a smooth camera surface, and
        count).

    Raises
    ------
    InputError
        When fewer than 10 of the microscope's points lie over the camera's
        mesh at the start (the landmarks put the patch elsewhere).
    """
    P = np.asarray(microscope, dtype=float).reshape(-1, 3)
    V = np.asarray(vertices, dtype=float)
    T = np.asarray(triangles, dtype=np.intp)
    normals = _normals(V, T)
    index = mesh_index(V, T)
    current = initial
    moved = current.apply(P)
    size = float(np.sqrt(np.mean(np.sum((moved - moved.mean(axis=0)) ** 2, axis=1))))
    floor = 1e-6 * max(size, 1e-300)  # a perfect fit pairs every point
    _, distance, n, keep = _pairs(moved, V, T, normals, reject, floor, index)
    if keep.sum() < 10:
        raise InputError(
            f"only {int(keep.sum())} of the microscope's {len(P)} points lie over the camera's "
            "surface where the start (the landmarks, or --transform) puts them: check its "
            "units, which side is which, and the run's --frame"
        )
    rms_before = float(np.sqrt(np.mean(distance[keep] ** 2)))
    frame = _patch_frame(moved[keep], n[keep])
    converged = False
    iterations = 0
    # rigid first, then with the scale: a patch tilted against a flat surface moves as a
    # change of scale would, and the scale would take a share of the tilt's correction
    for scaled in dict.fromkeys([False, fit_scale]):
        converged = False
        for _ in range(max_iterations):
            iterations += 1
            closest, distance, n, keep = _pairs(moved, V, T, normals, reject, floor, index)
            if keep.sum() < 10:
                break
            y, q, n = moved[keep], closest[keep], n[keep]
            c = y.mean(axis=0)
            r = np.einsum("ij,ij->i", n, y - q)
            J, length = _jacobian(q, n, c, frame, scaled)
            evals, evecs = np.linalg.eigh(J.T @ J)
            fixed = evals >= FIXED_SHARE * max(float(evals[-1]), 1e-300)
            # the step in the directions the shapes fix; none in the others (the landmarks')
            step = -(evecs[:, fixed] @ ((evecs[:, fixed].T @ (J.T @ r)) / evals[fixed]))
            shift = frame.T @ step[:3]
            omega = frame.T @ (step[3:6] / length)
            sigma = step[6] / length if scaled else 0.0
            R = _rotation(omega)
            new_shift = (1 + sigma) * (R @ (current.shift - c)) + c + shift
            if not (np.isfinite(new_shift).all() and math.isfinite(sigma) and sigma > -0.5):
                raise InputError(
                    "ICP diverged: the start (the landmarks, or --transform) puts the patch "
                    "where the two surfaces do not match; check its units and the height "
                    "map's pixel size"
                )
            current = Similarity3D(
                current.scale * (1 + sigma), R @ current.rotation, new_shift, current.mirrored
            )
            before = moved
            moved = current.apply(P)
            if np.max(np.linalg.norm(moved - before, axis=1)) <= tolerance * max(size, 1e-300):
                converged = True
                break
    closest, distance, n, keep = _pairs(moved, V, T, normals, reject, floor, index)
    if keep.sum() < 10:
        raise InputError(
            f"ICP lost the camera's surface: {int(keep.sum())} of the microscope's points "
            "are paired at the end; check the start (the landmarks, or --transform)"
        )
    # what the shapes fix, at the end
    J, _ = _jacobian(closest[keep], n[keep], moved[keep].mean(axis=0), frame, fit_scale)
    evals, evecs = np.linalg.eigh(J.T @ J)
    constrained = evecs[:, evals >= FIXED_SHARE * max(float(evals[-1]), 1e-300)]
    share = np.sum(constrained**2, axis=1)
    fixed = {
        name: round(float(v), 3) for name, v in zip(PARAMETERS[: len(share)], share, strict=True)
    }
    if not fit_scale:
        fixed["scale"] = 0.0
    distances = np.where(keep, distance, np.nan)
    return IcpResult(
        transform=current,
        rms_before=rms_before,
        rms_after=float(np.sqrt(np.mean(distance[keep] ** 2))),
        fitness=float(keep.mean()),
        iterations=iterations,
        converged=converged,
        fixed_by_surfaces=fixed,
        distances=distances,
    )
