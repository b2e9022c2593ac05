"""``gdic``: global correlation over the whole surface, refined by local subsets.

Built for natural tissue texture (smooth mucosa, sparse vessels, fibres,
uneven and fading light) where a subset around each point alone may hold too
little texture to be matched. Every frame, in order:

1. **Initial guess.** The previous frame's field plus its velocity. On the
   first frame, and whenever that guess leaves a large residual at the
   coarsest level, a global one too: SIFT features of the reference matched
   to the frame (Lowe's ratio test) and a RANSAC affine transform (OpenCV);
   the guess with the lower residual wins. So a 20-degree turn or a jump
   between frames does not lose the grid.
2. **Global correlation** (:mod:`strain2d.trackers._lattice`): one
   displacement field over the region, bilinear on a lattice of nodes
   ``spacing`` px apart, with a brightness gain and offset per node, fitted
   to every pixel coarse-to-fine; a thin-plate penalty weighted by the
   measured image noise fills in where texture is weak; occluded cells stop
   counting.
3. **Local refinement.** From the global field, each point's subset (sized
   per point from its texture against the noise, and no larger than the
   field's curvature allows: :func:`subset_sizes`) is matched by IC-GN
   (:mod:`strain2d.trackers.dic`'s kernel) with an affine and with a
   quadratic warp; the Bayesian information criterion
   ``n ln(SSD / n) + k ln n`` picks the warp per point and frame. A local
   match is kept when it converged, correlates at least ``zncc_min``, and
   agrees with the global field within its uncertainty (at most
   ``max(2 px, 5 sigma)``); otherwise the global field's value is used.
4. **Visibility.** A point is ``visible = 0`` when it is out of the frame,
   or when its local match failed *and* the lattice cell under it stopped
   counting (an occluder, a blank patch): the field there is the penalty's
   interpolation, not a measurement, and is not reported as one.

Each point and frame gets an uncertainty (px, standard deviation per
coordinate): for a local match ``sqrt(s^2 (J'J)^-1)`` of IC-GN with ``s^2``
the residual variance of its subset, plus an affine warp's bias from the
field's curvature; for the global field the posterior
standard deviation of the lattice fit. ``quality`` is the ZNCC of the local
match (of the lattice cell's fit where only the global value is used).

Tracking is always against the reference frame, so errors do not accumulate.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from scipy import ndimage

from strain2d.errors import InputError
from strain2d.trackers import TrackerOption, register_tracker
from strain2d.trackers._lattice import LatticeSolver
from strain2d.trackers._series import FrameSeries
from strain2d.trackers.dic import _coefficients, _Correlator, _first_frame, _inside, _Subsets
from strain2d.tracks import Tracks

#: noise part of the local uncertainty (px) above which the field's estimate is blended in
#: (weak texture; a large misfit alone says the warp is imperfect, not that the field is better)
_FUSE_ABOVE = 0.1

#: budget for cached reference subsets (bytes); beyond it they are rebuilt each frame
_CACHE_BYTES = 256 * 2**20

#: subset sides that ``subset="auto"`` chooses from, smallest first
_SUBSETS = (31, 41, 51, 61, 81)

#: noise-limited standard deviation (px, along the subset's weakest direction) that
#: ``subset="auto"`` asks of a subset before it stops growing
_SIGMA_TARGET = 0.04

#: bias (px) that an affine subset warp may take from the field's curvature before the
#: subset is kept smaller: ``curvature half^2 / 6`` (a quadratic field over a square)
_BIAS_TARGET = 0.05

#: fraction of points matched locally in the last frame from which the global field
#: is fitted at the coarsest level only where the texture is strong (the subsets refine it)
_LOCAL_HOLDS = 0.98

#: lattice spacings over which the field's curvature is measured for ``_BIAS_TARGET``
_CURVATURE_SPAN = 4


def _gray8(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    lo, hi = np.percentile(a, [0.5, 99.5])
    return np.clip((a - lo) / max(hi - lo, 1e-9) * 255, 0, 255).astype(np.uint8)


class _FeatureGuess:
    """Node displacements of an affine fit (RANSAC) to SIFT matches between the reference
    and a frame; the reference's features are found once, inside the lattice's box."""

    def __init__(self, reference: np.ndarray, nodes: np.ndarray) -> None:
        import cv2

        self.nodes = nodes
        self.sift = cv2.SIFT_create(nfeatures=4000)
        mask = np.zeros(reference.shape, np.uint8)
        (x0, y0), (x1, y1) = nodes.min(axis=0).astype(int), nodes.max(axis=0).astype(int)
        mask[max(y0, 0) : y1, max(x0, 0) : x1] = 255
        self._reference = None
        self._image, self._mask = reference, mask

    def __call__(self, frame: np.ndarray) -> np.ndarray | None:
        import cv2

        if self._reference is None:  # on first use: most videos never need it again
            self._reference = self.sift.detectAndCompute(_gray8(self._image), self._mask)
        k1, d1 = self._reference
        k2, d2 = self.sift.detectAndCompute(_gray8(frame), None)
        if d1 is None or d2 is None or len(k1) < 8 or len(k2) < 8:
            return None
        pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(d1, d2, k=2)
        good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < 0.75 * n.distance]
        if len(good) < 8:
            return None
        src = np.float32([k1[m.queryIdx].pt for m in good])
        dst = np.float32([k2[m.trainIdx].pt for m in good])
        A, inliers = cv2.estimateAffine2D(src, dst, ransacReprojThreshold=3.0, maxIters=4000)
        if A is None or inliers is None or inliers.sum() < 8:
            return None
        return self.nodes @ A[:, :2].T + A[:, 2] - self.nodes


def _extrapolate(nodes: np.ndarray, before: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Node states one frame ahead: the last step's best-fit affine motion applied again
    (exact for steady rotation and stretch), plus the rest of the step's motion."""
    x0, x1 = nodes + before[:, :2], nodes + now[:, :2]
    A = np.column_stack([x0, np.ones(len(x0))])
    M, *_ = np.linalg.lstsq(A, x1, rcond=None)  # x1 ~ [x0 1] @ M
    rest = x1 - A @ M
    guess = now.copy()
    guess[:, :2] = np.column_stack([x1, np.ones(len(x1))]) @ M + rest - nodes
    return guess


def subset_sizes(
    reference: np.ndarray,
    points: np.ndarray,
    noise: float,
    sizes: tuple[int, ...] = _SUBSETS,
    target: float = _SIGMA_TARGET,
) -> np.ndarray:
    """Per point, the smallest subset side whose texture pins the match to ``target`` px.

    The sum of squared intensity gradients (SSSIG) over a subset against the
    noise sets how precisely IC-GN can match it: the standard deviation of
    the displacement along a direction is ``sqrt(2 noise^2 / S)`` with ``S``
    the gradient energy along it (both frames' noise). The weakest direction
    is used (the smaller eigenvalue of the subset's gradient structure
    tensor), so a subset crossed by one vessel or fibre (the aperture
    problem) grows too. The gradients' own noise (a central difference of
    noise has variance ``noise^2 / 2``) is subtracted first. A point keeps
    the largest side that fits in the frame when none reaches ``target``.
    """
    image = np.asarray(reference, dtype=np.float64)
    H, W = image.shape
    gy, gx = np.gradient(image)
    tables = [np.pad(a.cumsum(0).cumsum(1), ((1, 0), (1, 0))) for a in (gx * gx, gy * gy, gx * gy)]
    c = np.rint(np.nan_to_num(points)).astype(int)
    room = np.minimum.reduce([c[:, 0], W - 1 - c[:, 0], c[:, 1], H - 1 - c[:, 1]]) - 2
    chosen = np.full(len(points), sizes[0])
    settled = np.zeros(len(points), bool)
    for size in sizes:
        half = size // 2
        fits = half <= room
        x0, x1 = np.clip(c[:, 0] - half, 0, W), np.clip(c[:, 0] + half + 1, 0, W)
        y0, y1 = np.clip(c[:, 1] - half, 0, H), np.clip(c[:, 1] + half + 1, 0, H)
        sxx, syy, sxy = (t[y1, x1] - t[y0, x1] - t[y1, x0] + t[y0, x0] for t in tables)
        own = size * size * noise**2 / 2
        sxx, syy = sxx - own, syy - own
        weakest = 0.5 * (sxx + syy) - np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
        sigma = np.sqrt(2 * noise**2 / np.maximum(weakest, 1e-12))
        grow = ~settled & fits
        chosen[grow] = size
        settled |= grow & (sigma <= target)
    return chosen


def _second_derivatives(solver: LatticeSolver, span: int) -> tuple[np.ndarray, np.ndarray]:
    """``d2u/dx2`` and ``d2u/dy2`` (1/px) at the lattice nodes, ``(ny + 1, nx + 1, 2)``
    each, from second differences over ``span`` spacings (longer spans read less of the
    nodes' noise). Past the edges the field is extrapolated linearly, so a homogeneous
    field has no curvature there."""
    lat, k = solver.lattice, span
    U = solver.state[:, :2].reshape(lat.ny + 1, lat.nx + 1, 2)
    P = np.pad(U, ((k, k), (k, k), (0, 0)), mode="reflect", reflect_type="odd")
    c = P[k:-k, k:-k]
    scale = (k * lat.h) ** 2
    uxx = (P[k:-k, 2 * k :] - 2 * c + P[k:-k, : -2 * k]) / scale
    uyy = (P[2 * k :, k:-k] - 2 * c + P[: -2 * k, k:-k]) / scale
    return uxx, uyy


def _curvature_cap(solver: LatticeSolver, points: np.ndarray) -> np.ndarray:
    """Per point, the largest subset side (of ``_SUBSETS``) over which the global field's
    curvature would bias an affine warp by at most ``_BIAS_TARGET`` px.

    A subset that grows for texture must not grow across a heterogeneous
    field. The curvature is the largest second difference of the field over
    ``_CURVATURE_SPAN`` lattice spacings (shorter spans measure the nodes'
    noise more than the field), the largest within reach of the biggest
    subset around the point.
    """
    lat = solver.lattice
    uxx, uyy = _second_derivatives(solver, _CURVATURE_SPAN)
    kappa = np.max(np.abs(np.stack([uxx, uyy])), axis=(0, 3))
    reach = 2 * int(np.ceil(_SUBSETS[-1] / 2 / lat.h)) + 1
    kappa = ndimage.maximum_filter(kappa, size=reach, mode="nearest").ravel()
    around = kappa[lat.cell_nodes()[lat.cell_of(points)]].max(axis=1)
    cap = np.full(len(points), _SUBSETS[0])
    for size in _SUBSETS[1:]:
        cap[around * (size // 2) ** 2 / 6 <= _BIAS_TARGET] = size
    return cap


def _affine_bias(solver: LatticeSolver, points: np.ndarray, half: np.ndarray) -> np.ndarray:
    """Per point, the bias (px, root mean square of the two components) of an affine
    subset warp of half-side ``half`` over the global field's curvature.

    For a displacement with second derivatives, an affine warp fitted over a
    square of half-side ``L`` takes up the mean of the second-order term,
    ``laplacian(u) L^2 / 6`` per component (the mixed derivative averages
    out). The Laplacian is the field's, over two lattice spacings, the
    largest at the nodes of the point's cell.
    """
    lat = solver.lattice
    uxx, uyy = _second_derivatives(solver, 2)
    lap = np.sqrt(np.mean((uxx + uyy) ** 2, axis=2)).ravel()
    around = lap[lat.cell_nodes()[lat.cell_of(points)]].max(axis=1)
    return around * half.astype(float) ** 2 / 6


def _spline_noise_gain(offset: np.ndarray) -> np.ndarray:
    """Variance of white noise after cubic B-spline interpolation at sub-pixel ``offset``
    (1-D, in [0, 1)), relative to the noise's own: 1 on the pixels, 0.756 halfway."""
    n = 48
    impulses = ndimage.spline_filter1d(np.eye(n), order=3, axis=1, mode="mirror")
    x = n // 2 + np.asarray(offset, dtype=float).ravel()
    i = np.floor(x).astype(int)
    t = x - i
    # the cubic B-spline's weights for the 4 coefficients around x
    w = np.stack([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3])
    w /= 6.0
    kernel = sum(w[k][:, None] * impulses[:, i + k - 1].T for k in range(4))  # (m, n)
    return np.sum(kernel**2, axis=1).reshape(np.shape(offset))


def _touches(mask: np.ndarray | None, centers: np.ndarray, half: int | np.ndarray) -> np.ndarray:
    """Whether the square subsets at ``centers`` hold any pixel of ``mask``."""
    if mask is None or not mask.any():
        return np.zeros(len(centers), bool)
    table = np.pad(mask.astype(np.int32).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    H, W = mask.shape
    c = np.rint(np.nan_to_num(centers)).astype(int)
    x0, x1 = np.clip(c[:, 0] - half, 0, W), np.clip(c[:, 0] + half + 1, 0, W)
    y0, y1 = np.clip(c[:, 1] - half, 0, H), np.clip(c[:, 1] + half + 1, 0, H)
    return (table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]) > 0


def _chunks(n: int, size: int) -> list[np.ndarray]:
    return [np.arange(a, min(a + size, n)) for a in range(0, n, max(size, 1))]


def _reference_subsets(corr: _Correlator, coefficients, centers: np.ndarray):
    """Reference subsets of many points, built 1024 at a time into float32 arrays (the
    float64 ones of a whole dense grid would not fit the cache budget twice)."""
    fields = ("centers", "frame", "f", "norm", "G", "template")
    out = None
    for rows in _chunks(len(centers), 1024):
        part = corr.reference(coefficients, centers[rows], 0)
        if out is None:
            out = {}
            for k in fields:
                a = getattr(part, k)
                dtype = np.float32 if k in ("f", "G") else a.dtype
                out[k] = np.empty((len(centers), *a.shape[1:]), dtype)
        for k in fields:
            out[k][rows] = getattr(part, k)
    return _Subsets(*(out[k] for k in fields))


def _take(ref, rows: np.ndarray):
    return _Subsets(
        *(getattr(ref, k)[rows] for k in ("centers", "frame", "f", "norm", "G", "template"))
    )


def _bic_choice(ssd1, ssd2, n, ok1, ok2):
    """Per point, True where the quadratic warp (12 parameters) beats the affine one (6)
    by the Bayesian information criterion ``n ln(SSD / n) + k ln n``."""
    bic1 = n * np.log(ssd1 / n) + 6 * np.log(n)
    bic2 = n * np.log(ssd2 / n) + 12 * np.log(n)
    return ok2 & (~ok1 | (bic2 < bic1))


def _local_sigma(
    corr: _Correlator, ref, rows, zncc, noise: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IC-GN standard deviation (px per coordinate) of (u, v) at ``rows``.

    ``s^2 (J'J)^-1`` with ``s^2`` the subset's residual variance. On weak
    texture the reference's gradients are partly noise (a central difference
    of noise of variance ``noise^2`` has variance ``noise^2 / 2``), which
    inflates ``J'J``: that part is taken out, so the uncertainty grows as the
    texture fades into the noise instead of staying optimistic. Residual
    beyond the noise (``s^2 - 2 noise^2``, both frames' noise) is a misfit of
    the warp, and its size in pixels (residual over the mean squared
    gradient) is added as a bias term. Returns the standard deviation, the
    factor (>= 1) by which the noise correction raised the variance (the
    global field's uncertainty at the point shares it), and the noise part
    of the standard deviation alone (how weak the subset's texture is).
    """
    G = ref.G[rows]  # H^-1 J^T, so G G^T = H^-1
    n = G.shape[2]
    noise_energy = n * noise**2 / 2
    variances, plain = [], []
    for k in (0, 1):
        hinv = np.einsum("nk,nk->n", G[:, k], G[:, k])
        var = np.full(len(hinv), np.inf)  # a textureless subset (singular Hessian) says nothing
        has = hinv > 0
        signal = 1.0 / hinv[has] - noise_energy
        var[has] = np.where(
            signal * hinv[has] > 0.1, 1.0 / np.maximum(signal, 1e-30), 10 * hinv[has]
        )
        variances.append(var)
        plain.append(hinv)
    norm2 = ref.norm[rows, 0] ** 2
    s2 = np.maximum(2 * (1 - zncc), 0) * norm2 / max(n - corr.n_params, 1)
    variance = 0.5 * (variances[0] + variances[1])
    hinv = 0.5 * (plain[0] + plain[1])
    # residual beyond the noise is misfit of the warp (model error, interpolation bias):
    # a residual r over gradients g is a misregistration of about r / g, added as a bias
    misfit = np.maximum(s2 - 2 * noise**2, 0.0) * n * hinv
    inflation = np.ones(len(hinv))
    has = np.isfinite(variance) & (hinv > 0)
    inflation[has] = np.maximum(variance[has] / hinv[has], 1.0)
    return np.sqrt(variance * s2 + misfit), inflation, np.sqrt(variance * s2)


def _subset_option(text: str) -> int | str:
    """``--subset``: auto, or a whole number of pixels."""
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise ValueError(f"must be auto or a whole number of pixels, got {text!r}") from None


@register_tracker(
    "gdic",
    description="global DIC over the surface (regularized finite-element lattice, brightness "
    "per node, feature-based initial guess), refined by local subsets with the warp "
    "chosen per point; reports an uncertainty per point",
    options=[
        TrackerOption(
            "subset",
            "--subset",
            "subset side in px, or auto (default: sized per point from the texture against "
            "the noise, 31-81 px)",
            type=_subset_option,
        ),
        TrackerOption(
            "shape_function",
            "--shape-function",
            "subset warp, first or second order, or chosen per point and frame",
            choices=("auto", "affine", "quadratic"),
        ),
        TrackerOption(
            "spacing",
            "--lattice-spacing",
            "node spacing of the global field in px",
            type=int,
        ),
        TrackerOption(
            "curvature",
            "--curvature",
            "prior scale of the field's second derivatives in 1/px; smaller is smoother ",
            type=float,
        ),
        TrackerOption(
            "zncc_min",
            "--zncc-min",
            "correlation below which a local match is not used and the global field's value "
            "stands in",
            type=float,
        ),
    ],
)
def track_gdic(
    frames: Iterable[np.ndarray],
    points: np.ndarray,
    *,
    subset: int | str = "auto",
    spacing: int = 16,
    curvature: float = 2e-3,
    shape_function: str = "auto",
    zncc_min: float = 0.75,
    max_iterations: int = 30,
    tolerance: float = 1e-3,
    progress: Callable[[int, int | None], None] | None = None,
) -> Tracks:
    """Track points by global and local correlation (see the module docstring).

    Parameters
    ----------
    frames : iterable of (H, W) float
        Frame 0 is the reference.
    points : (N, 2) float
        Reference positions (x, y) in pixels.
    subset : int or "auto", keyword-only
        Side of the local subsets in pixels (odd, >= 15), or ``"auto"``: per
        point the smallest of 31, 41, 51, 61 and 81 px whose texture holds
        the match to about 0.04 px against the measured noise (see
        :func:`subset_sizes`), so weak texture gets larger subsets.
    spacing : int, keyword-only
        Lattice spacing of the global field in pixels (a multiple of 4, >= 8).
    curvature : float, keyword-only
        Prior scale of the field's second derivatives (1/px); the
        regularization weight is ``2 noise^2 / (curvature spacing^2)^2`` with
        the noise measured on the reference frame. Smaller is smoother.
    shape_function : {"auto", "affine", "quadratic"}, keyword-only
        The local subset warp; ``auto`` chooses per point and frame (BIC).
    zncc_min : float, keyword-only
        Correlation below which a local match is not used.
    max_iterations, tolerance : keyword-only
        Of the local IC-GN.
    progress : callable(done, total), keyword-only

    Returns
    -------
    Tracks
        With ``uncertainty`` (px); ``meta["local_fraction"]`` is the fraction
        of point-frames whose position is a local subset match.
    """
    if shape_function not in ("auto", "affine", "quadratic"):
        raise InputError(
            f"--shape-function must be auto, affine or quadratic, got {shape_function!r}"
        )
    if subset != "auto" and (
        isinstance(subset, str) or int(subset) != subset or subset < 15 or subset % 2 == 0
    ):
        raise InputError(f"--subset must be auto or an odd number >= 15 for gdic, got {subset}")
    if spacing < 8 or spacing % 4:
        raise InputError(f"--lattice-spacing must be a multiple of 4 and >= 8 px, got {spacing}")
    if not (np.isfinite(curvature) and curvature > 0):
        raise InputError(f"--curvature must be a positive number, got {curvature}")
    if not -1 < zncc_min < 1:
        raise InputError(f"--zncc-min must lie between -1 and 1, got {zncc_min}")
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    n = len(points)
    reference, it, total = _first_frame(frames)
    shape = reference.shape
    smallest = _SUBSETS[0] if subset == "auto" else subset
    if smallest >= min(shape) or 2 * spacing >= min(shape):
        raise InputError(
            f"--subset {smallest} and 2 x --lattice-spacing {spacing} must be smaller than the "
            f"{shape[1]}x{shape[0]} frames"
        )
    H, W = shape
    in_frame0 = (points[:, 0] >= 0) & (points[:, 0] <= W - 1) & (points[:, 1] >= 0)
    in_frame0 &= points[:, 1] <= H - 1
    solver = LatticeSolver(
        reference,
        points[in_frame0] if in_frame0.any() else points,
        spacing=spacing,
        curvature=curvature,
    )
    nodes = solver.lattice.nodes()
    feature_guess = _FeatureGuess(reference, nodes)

    orders = {"auto": (1, 2), "affine": (1,), "quadratic": (2,)}[shape_function]
    # each point's subset: as large as its texture needs (fixed), but no larger than the
    # field's curvature allows (every frame)
    if subset == "auto":
        wanted = subset_sizes(reference, points, solver.noise)
    else:
        wanted = np.full(n, int(subset))
    # the points that may use each size (the curvature only ever makes a subset smaller)
    candidates = _SUBSETS if subset == "auto" else (int(subset),)
    capped = subset == "auto" and bool((wanted > _SUBSETS[0]).any())  # the cap can bind
    groups = {size: np.flatnonzero(wanted >= size) for size in candidates if (wanted >= size).any()}
    correlators = {
        (size, o): _Correlator(size, max_iterations, tolerance, zncc_min, order=o)
        for size in groups
        for o in (1, 2)
    }
    ref_coeff = _coefficients(reference)
    # per point, the residual variance that noise alone leaves in a matched subset: the
    # B-spline interpolation of both frames smooths it, the reference's at the point's
    # fixed sub-pixel offset, the frame's over offsets spread by the deformation
    frac = points - np.floor(points)
    noise_floor = solver.noise**2 * (
        _spline_noise_gain(frac[:, 0]) * _spline_noise_gain(frac[:, 1])
        + np.mean(_spline_noise_gain(np.linspace(0, 1, 32, endpoint=False))) ** 2
    )

    # reference subsets are kept in float32 while both warps' fit the budget; otherwise
    # (dense grids) they are rebuilt every frame in chunks, so memory stays bounded
    def per_point(size: int) -> int:
        return 4 * size * size * sum(correlators[size, o].n_params + 1 for o in orders)

    cache_all = sum(per_point(size) * len(m) for size, m in groups.items()) <= _CACHE_BYTES
    cached = {}
    built = dict.fromkeys(correlators, 0)  # subsets built outside the cache so far

    def _reference(size: int, order: int, rows: np.ndarray):
        corr = correlators[size, order]
        members = groups[size]
        # the quadratic warp is tried where the affine one leaves model error: on a
        # homogeneous field a handful of points, so it is cached for the whole grid only
        # once building it point by point would have cost as much
        if not cache_all:
            return corr.reference(ref_coeff, points[rows], 0)
        if (size, order) not in cached and built[size, order] + len(rows) < len(members):
            built[size, order] += len(rows)
            return corr.reference(ref_coeff, points[rows], 0)
        if (size, order) not in cached:
            cached[size, order] = _reference_subsets(corr, ref_coeff, points[members])
        ref = cached[size, order]
        return ref if len(rows) == len(members) else _take(ref, np.searchsorted(members, rows))

    def _local(corr, ref, rows, u, grad):
        p0 = np.zeros((len(rows), corr.n_params))
        p0[:, :2] = u[rows]
        p0[:, 2:6] = grad[rows].reshape(len(rows), 4)  # du/dx, du/dy, dv/dx, dv/dy
        # a point matched locally last frame continues from its own warp, moved as the
        # field moved since (the field alone can be a less precise start on fine texture)
        before = rows[carried[rows]]
        if before.size:
            k = np.flatnonzero(carried[rows])
            p0[k, :6] = last_p[before] + np.column_stack(
                [u[before] - last_u[before], (grad[before] - last_grad[before]).reshape(-1, 4)]
            )
        p, z, conv = corr.match(coeff, ref, np.arange(len(rows)), p0)
        ok = conv & (z >= zncc_min) & _inside(corr, points[rows], p, shape)
        sd, infl, noisy = _local_sigma(corr, ref, np.arange(len(rows)), z, solver.noise)
        ssd = np.maximum(2 * (1 - z), 1e-12) * ref.norm[:, 0] ** 2
        return p, z, ok, sd, infl, ssd, noisy

    carried = np.zeros(n, bool)  # matched locally (affine) on the last frame
    last_p = np.zeros((n, 6))
    last_u, last_grad = np.zeros((n, 2)), np.zeros((n, 2, 2))
    local_last = 0.0  # fraction of points matched locally in the last frame

    done = FrameSeries(
        total,
        positions=points,
        visible=in_frame0,
        quality=np.where(in_frame0, 1.0, 0.0),
        sigma=np.where(in_frame0, 0.0, np.nan),
    )
    local_count = quadratic_count = 0
    state = np.zeros((solver.lattice.n_nodes, 4))
    previous_state = state.copy()
    typical_cost = None
    if progress:
        progress(1, total)
    for t, frame in enumerate(it, start=1):
        frame = np.asarray(frame, dtype=np.float64)
        if frame.shape != shape:
            raise InputError(f"frame {t} is {frame.shape[1]}x{frame.shape[0]}, not {W}x{H}")
        # 1. initial guess
        guess = _extrapolate(nodes, previous_state, state)
        coarse, cost = solver.coarse(frame, guess) if t > 1 else (None, np.inf)
        if typical_cost is None or cost > 4 * typical_cost:
            moved = feature_guess(frame)
            if moved is not None:
                alternative = state.copy()
                alternative[:, :2] = moved
                other_state, other = solver.coarse(frame, alternative)
                if other < cost:
                    coarse, cost = other_state, other
                else:
                    coarse, cost = solver.coarse(frame, guess)  # its weights and residuals
            elif coarse is None:  # first frame, no features: start from rest
                coarse, cost = solver.coarse(frame, guess)
        # 2. global correlation, as fine as the local subsets need: all levels where they
        # could not carry the grid in the last frame (weak texture). Where they carried
        # nearly all of it on strong texture (no subset grown, so none for the field's
        # curvature to cap), the coarse field is start enough: they give full resolution
        if local_last >= _LOCAL_HOLDS and not capped:
            depth = 1
        else:
            depth = 2 if local_last >= 0.9 else None
        solver.refine(frame, coarse, levels=depth)
        typical_cost = cost if typical_cost is None else min(max(cost, 1e-9), 4 * typical_cost)
        previous_state, state = state, solver.state.copy()
        u, grad = solver.displacement(points)

        # 3. local refinement from the global field: affine everywhere, quadratic where
        #    the affine warp leaves more residual than the noise explains
        coeff = _coefficients(frame)
        p_loc = np.zeros((n, 6))
        z_loc = np.full(n, -1.0)
        s_loc = np.full(n, np.nan)
        quadratic = np.zeros(n, bool)
        ok_loc = np.zeros(n, bool)
        inflation = np.ones(n)
        s_noise = np.full(n, np.nan)  # the noise part of the local uncertainty
        sizes = np.minimum(wanted, _curvature_cap(solver, points)) if subset == "auto" else wanted
        for size in groups:
            members = np.flatnonzero(sizes == size)
            n_px = size * size
            chunk = len(members) if cache_all else max(64, _CACHE_BYTES // (8 * per_point(size)))
            for part in _chunks(len(members), chunk):
                rows = members[part]
                first = _reference(size, orders[0], rows)
                corr = correlators[size, orders[0]]
                p, z, ok, sd, infl, ssd, noisy = _local(corr, first, rows, u, grad)
                p_loc[rows], z_loc[rows], ok_loc[rows], s_loc[rows] = p[:, :6], z, ok, sd
                s_noise[rows], inflation[rows] = noisy, infl
                if len(orders) < 2:
                    continue
                # the BIC can prefer 12 parameters only where the 6 leave model error:
                # residual beyond what the noise leaves after interpolation (by 20 %: on a
                # uniform stretch 99 % of subsets stay below 1.16 times it, so none is tried)
                excess = ssd / max(n_px - 6, 1) > 1.2 * noise_floor[rows]
                try_rows = rows[excess | ~ok]
                if try_rows.size:
                    ref2 = _reference(size, 2, try_rows)
                    corr2 = correlators[size, 2]
                    p2, z2, ok2, sd2, _, ssd2, _ = _local(corr2, ref2, try_rows, u, grad)
                    in_rows = np.searchsorted(rows, try_rows)
                    quad = _bic_choice(ssd[in_rows], ssd2, n_px, ok_loc[try_rows], ok2)
                    take = try_rows[quad]
                    p_loc[take], z_loc[take], s_loc[take] = p2[quad, :6], z2[quad], sd2[quad]
                    ok_loc[take] = True
                    quadratic[take] = True
        # a local match far from the global field must agree with it within its uncertainty
        gap = np.linalg.norm(p_loc[:, :2] - u, axis=1)
        far = np.flatnonzero(ok_loc & (gap > 2.0))
        if far.size:
            sigma_far = solver.uncertainty(points[far]) * np.sqrt(inflation[far])
            ok_loc[far[gap[far] > 5 * np.nan_to_num(sigma_far, nan=0.2)]] = False
        carried = ok_loc.copy()
        last_p = np.where(ok_loc[:, None], p_loc, last_p)
        last_u, last_grad = u.copy(), grad.copy()
        # a subset under a highlight would follow the light, not the tissue
        half = sizes // 2
        lit = _touches(solver.reference_highlights, points, half)
        lit |= _touches(solver.frame_highlights, points + u, half)
        ok_loc &= ~lit
        local_count += int(ok_loc.sum())
        quadratic_count += int((quadratic & ok_loc).sum())
        local_last = float(ok_loc.mean()) if n else 1.0
        # where a local match failed, the field's own value is reported: after a coarse
        # fit alone that needs the finer levels too (the coarse field is a start, not a
        # measurement: 0.1-0.6 px off where subsets leave a stretching frame)
        if depth == 1 and (in_frame0 & ~ok_loc).any():
            solver.refine(frame, coarse)
            u, grad = solver.displacement(points)

        # an affine warp over a curved field is biased by the mean of its second-order
        # term over the subset: laplacian(u) half^2 / 6 per component
        affine = ok_loc & ~quadratic
        if affine.any():
            bias = _affine_bias(solver, points[affine], sizes[affine] // 2)
            s_loc[affine] = np.sqrt(s_loc[affine] ** 2 + bias**2)
        disp = np.where(ok_loc[:, None], p_loc[:, :2], u)
        # where the subset's texture is weak, the field (which also draws on the
        # neighbours through the prior) adds information: inverse-variance weighting
        weak = np.flatnonzero(ok_loc & (s_noise > _FUSE_ABOVE) & solver.seen(points))
        if weak.size:
            s_g = solver.uncertainty(points[weak]) * np.sqrt(inflation[weak])
            good = np.isfinite(s_g) & (s_g > 0)
            weak, s_g = weak[good], s_g[good]
            w_l, w_g = 1 / s_loc[weak] ** 2, 1 / s_g**2
            disp[weak] = (w_l[:, None] * disp[weak] + w_g[:, None] * u[weak]) / (w_l + w_g)[:, None]
            # both estimates draw on the same pixels, so the blend is not trusted beyond
            # the better of the two
            s_loc[weak] = np.minimum(s_loc[weak], s_g)
        pos = points + disp
        inside = (pos[:, 0] >= 0) & (pos[:, 0] <= W - 1) & (pos[:, 1] >= 0) & (pos[:, 1] <= H - 1)
        vis = inside & in_frame0 & (ok_loc | solver.seen(points))
        cell_quality = np.clip(solver.cell_zncc(points), 0.0, 1.0)
        sigma_g = np.full(n, np.nan)
        need = np.flatnonzero(vis & ~ok_loc)
        if need.size:
            sigma_g[need] = solver.uncertainty(points[need]) * np.sqrt(inflation[need])
        done.append(
            positions=pos,
            visible=vis,
            quality=np.where(vis, np.where(ok_loc, np.clip(z_loc, 0, 1), cell_quality), 0.0),
            sigma=np.where(vis, np.where(ok_loc, s_loc, sigma_g), np.nan),
        )
        if progress:
            progress(len(done), total)
    if len(done) < 2:
        raise InputError("tracking needs at least 2 frames")
    options = {
        "subset": subset,
        "spacing": spacing,
        "curvature": curvature,
        "shape_function": shape_function,
        "zncc_min": zncc_min,
        "max_iterations": max_iterations,
        "tolerance": tolerance,
        "noise_gray_levels": solver.noise,
        "interpolation": "cubic B-spline",
    }
    T = len(done)
    series = done.arrays()
    return Tracks(
        series["positions"],
        series["visible"],
        series["quality"],
        {
            "tracker": "gdic",
            "options": options,
            "local_fraction": local_count / max(n * (T - 1), 1),
            "quadratic_fraction": quadratic_count / max(n * (T - 1), 1),
            "subset_sizes": {str(size): int((wanted == size).sum()) for size in groups},
        },
        series["sigma"],
    )
