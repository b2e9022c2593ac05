"""``gdic``: subsets where the texture carries them, the global field where it does not.

Built for natural tissue texture (smooth mucosa, sparse vessels, fibres,
uneven and fading light) as well as speckle. The effort follows the data,
point by point and frame by frame: where a subset around a point holds
texture enough, the point costs what it costs in ``dic``; the global field is
fitted only on the frames, and for the points, that need it. Every frame, in
order:

1. **Initial guess.** Each point from its own last match, moved as the last
   step's best-fit affine motion of the whole grid moved it (exact for steady
   rotation and stretch), plus the rest of its own last step.
2. **Local match.** Each point's subset (sized per point from its texture
   against the noise, no larger than the field's curvature allows:
   :func:`subset_sizes`) is matched by IC-GN (:mod:`strain2d.trackers.dic`'s
   compiled kernel, in parallel over points) with an affine warp. A match is
   kept when it converged, correlates at least ``zncc_min``, stays in the
   frame, and moved as its neighbours did (the normalized median test).
   A subset that holds a **specular highlight** (a bright smooth blob seen to
   stay put in the image while the tissue moves) is matched again on the
   pixels that neither the highlight nor its halo covers, on the reference
   and on the frame, from its best matched neighbour's warp: it follows the
   tissue, not the light.
3. **Where it failed:** if most points failed (a jump, a turn of tens of
   degrees between frames), SIFT features of the reference matched to the
   frame and a RANSAC affine transform give every failed point a new start;
   then a failed point restarts from its best matched neighbour's warp, round
   after round while the matched region grows; the points still failing
   take their start from the **global field** (:mod:`strain2d.trackers._lattice`:
   one regularized displacement field over the region, fitted to every
   pixel coarse to fine, with a brightness gain and offset per node), built
   the first time it is needed and fitted only on those frames (a small
   field reads only the part of the frame its lattice samples). Where even
   that start gives no local match, the field's own value is reported if the
   lattice cell under the point counted in its fit; a point that a highlight
   found to stay put hides from the field (over 30 % of any cell that may
   hold it) gets no field: it could not be reported.
4. **Quadratic warp** where the field curves enough under a subset to bias
   an affine warp by half its noise or more: the Bayesian information criterion
   ``n ln(SSD / n) + k ln n`` picks the warp per point and frame.
5. **Visibility.** A point is ``visible = 0`` when it is out of the frame,
   so far under a highlight that its subset keeps too few pixels and the
   field does not see it, matched by neither its subset nor the field, or
   when it has no texture: a point farther than half the smallest subset
   from any texture (a blank background beside textured pieces:
   :func:`texture_distance`), or whose largest subset cannot pin a match to
   ``_TEXTURELESS`` px against the noise, is never reported as a
   measurement, whatever a larger subset or the field would extrapolate
   there.

Each point and frame gets an uncertainty (px, standard deviation per
coordinate). For a local match it is the noise's, ``c 2 sigma_n^2 (J'J)^-1``
of IC-GN: ``sigma_n^2`` the pixel noise as the subsets' residuals show it
(intensity-dependent, the interpolation's smoothing of the residual taken
out), the gradients' own noise taken out of ``J'J``, and ``c`` measured on
the video's own reference by matching two copies of it with fresh noise of
that level (the formula assumes a matcher that moves along the gradients it
uses; this one uses central differences while it moves along the spline, so
its scatter is smaller by a texture-dependent factor: :meth:`_Run._noise_scale`).
To it adds an affine warp's bias over a curving field: ``laplacian(u)
L^2 / 6`` over a subset of half-side ``L`` (the curvature from the
neighbours' quadratic fit, its share of their noise taken out), or, where
the quadratic warp was tried and not kept, the quadratic warp's shift from
the affine one, if larger. Residual that the tissue's changing appearance
leaves is not position noise: it shows in ``quality`` (the ZNCC), not in the
uncertainty. For the field's value it is the posterior standard deviation
of the lattice fit.

Tracking is always against the reference frame, so errors do not accumulate.
The tracks do not depend on the number of threads (``threads``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from strain2d.errors import InputError
from strain2d.trackers import TrackerOption, register_tracker
from strain2d.trackers._lattice import (
    HIDDEN_CELL,
    HIDDEN_CELLS,
    Frame,
    Lattice,
    LatticeSolver,
    blob_window,
    bright_blobs,
    dilated,
    noise_sigma,
    static_highlights,
    with_halos,
)
from strain2d.trackers._series import FrameSeries
from strain2d.trackers._threads import (
    THREADS_OPTION,
    parallel_map,
    prefetched,
    using_threads,
    worker_count,
)
from strain2d.trackers.dic import (
    SUBSET_FIELDS,
    _coefficients,
    _Correlator,
    _first_frame,
    _inside,
    _median_outliers,
    _Subsets,
)
from strain2d.tracks import Tracks

#: budget for cached reference subsets (bytes); beyond it they are rebuilt each frame
_CACHE_BYTES = 256 * 2**20

#: subset sides that ``subset="auto"`` chooses from, smallest first
_SUBSETS = (31, 41, 51, 61, 81)

#: noise-limited standard deviation (px, along the subset's weakest direction) that
#: ``subset="auto"`` asks of a subset before it stops growing
_SIGMA_TARGET = 0.04
#: the smaller subsets a point near the frame's edge falls back to (its subset would leave)
_EDGE_SUBSETS = (15, 21)

#: standard deviation (px) that the largest subset's texture allows, beyond which the point
#: holds no texture to measure (its subsets see nothing above the noise)
_TEXTURELESS = 0.5

#: side (px) of the window in which texture is told from noise, and the signal variance
#: (in units of the window's noise variance) above which it holds texture: about six
#: standard deviations of the variance a window of pure noise shows
_TEXTURE_WINDOW = 15
_TEXTURE_SIGNAL = 0.6

#: the lowest ZNCC at which a match that its measured neighbours predict is kept
_WEAK_ZNCC = 0.5
#: a match whose residual variance (over the noise model's, per pixel) is at most this is
#: clean: no blob under its subset disturbs it, and none needs deciding there
_CLEAN_RESIDUAL = 3.0

#: IC-GN's per-point tolerance, as a fraction of its subset's noise-limited standard
#: deviation (when that exceeds the fixed tolerance)
_SETTLE = 0.2

#: the most copies with fresh noise, the matches enough, and their seed, that measure how
#: the matches scatter against the noise
_NOISE_DRAWS = 2
_NOISE_MATCHES = 400
_NOISE_SEED = 20261126

#: a point farther than this (px) from any texture is on blank background, whatever a
#: larger subset reaches: half the smallest automatic subset
_TEXTURE_REACH = _SUBSETS[0] // 2

#: bias (px) that an affine subset warp may take from the field's curvature before the
#: subset is kept smaller: ``curvature half^2 / 6`` (a quadratic field over a square)
_BIAS_TARGET = 0.05

#: neighbours of each point for the median test, the restarts and the field's curvature
_NEIGHBOURS = 8

#: fraction of the textured points in view that must match from the motion guess; below
#: it the frame's features are matched to the reference for a new start (a jump, a turn)
_FEATURES_BELOW = 0.5

#: fraction of the textured points above which the points still failing share one field
#: over the whole region; fewer get a small field each, around them and their neighbours
_LOCAL_FIELDS_UP_TO = 0.1

#: the quadratic warp is tried where the affine one's bias from the curvature exceeds this
#: fraction of the match's noise
_QUADRATIC_BIAS = 0.5
#: and where the fitted curvature stands this many of its noise's standard deviations out
_CURVES = 1.5


def _gray8(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    lo, hi = np.percentile(a, [0.5, 99.5])
    return np.clip((a - lo) / max(hi - lo, 1e-9) * 255, 0, 255).astype(np.uint8)


class _FeatureGuess:
    """The affine map (RANSAC) of SIFT matches from the reference to a frame; the
    reference's features are found once, inside the box of the points (with a margin)."""

    def __init__(self, reference: np.ndarray, points: np.ndarray, margin: float) -> None:
        self._image = reference
        H, W = reference.shape
        (x0, y0), (x1, y1) = points.min(axis=0) - margin, points.max(axis=0) + margin
        self._box = (max(int(x0), 0), max(int(y0), 0), min(int(x1) + 1, W), min(int(y1) + 1, H))
        self._reference = None

    def __call__(self, frame: np.ndarray) -> np.ndarray | None:
        """``(2, 3)`` affine map ``x = A X + b`` as ``[A | b]``, or None when it cannot be told."""
        import cv2

        sift = cv2.SIFT_create(nfeatures=4000)
        if self._reference is None:  # on first use: most videos never need it
            mask = np.zeros(self._image.shape, np.uint8)
            x0, y0, x1, y1 = self._box
            mask[y0:y1, x0:x1] = 255
            self._reference = sift.detectAndCompute(_gray8(self._image), mask)
        k1, d1 = self._reference
        k2, d2 = sift.detectAndCompute(_gray8(frame), None)
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
        return A.astype(np.float64)


def _affine_fit(src: np.ndarray, dst: np.ndarray) -> np.ndarray | None:
    """Least-squares ``(2, 3)`` affine map ``[A | b]`` with ``dst ~ A src + b``, or None
    when fewer than 3 pairs (or collinear ones) are given."""
    if len(src) < 3:
        return None
    M = np.column_stack([src, np.ones(len(src))])
    if np.linalg.matrix_rank(M) < 3:
        return None
    coef, *_ = np.linalg.lstsq(M, dst, rcond=None)  # dst ~ M @ coef
    return coef.T


def _apply(affine: np.ndarray, x: np.ndarray) -> np.ndarray:
    return x @ affine[:, :2].T + affine[:, 2]


def _warps(points: np.ndarray, positions: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Affine IC-GN warps ``(N, 6)`` that move ``points`` to ``positions`` with gradients
    ``F`` ``(N, 2, 2)``: ``(u, v, du/dx, du/dy, dv/dx, dv/dy)``."""
    p = np.empty((len(points), 6))
    p[:, :2] = positions - points
    p[:, 2:] = (F - np.eye(2)).reshape(-1, 4)
    return p


def _gradient(p: np.ndarray) -> np.ndarray:
    """The deformation gradient ``(N, 2, 2)`` of affine warps ``(N, 6)``."""
    return np.eye(2) + p[:, 2:6].reshape(-1, 2, 2)


def subset_texture(
    reference: np.ndarray,
    points: np.ndarray,
    noise: float,
    sizes: tuple[int, ...] = _SUBSETS,
    target: float = _SIGMA_TARGET,
) -> tuple[np.ndarray, np.ndarray]:
    """Per point, the smallest subset side whose texture pins the match to ``target`` px,
    and the standard deviation (px) that subset's texture allows.

    The sum of squared intensity gradients (SSSIG) over a subset against the
    noise sets how precisely IC-GN can match it: the standard deviation of
    the displacement along a direction is ``sqrt(2 noise^2 / S)`` with ``S``
    the gradient energy along it (both frames' noise). The weakest direction
    is used (the smaller eigenvalue of the subset's gradient structure
    tensor), so a subset crossed by one vessel or fibre (the aperture
    problem) grows too. The gradients' own noise (a central difference of
    noise has variance ``noise^2 / 2``) is subtracted first. A point keeps
    the largest side that fits in the frame when none reaches ``target``;
    its standard deviation is infinite where no texture is left (a blank
    background: nothing above the noise).
    """
    image = np.asarray(reference, dtype=np.float64)
    H, W = image.shape
    gy, gx = np.gradient(image)
    tables = [_integral(a) for a in (gx * gx, gy * gy, gx * gy)]
    c = np.rint(np.nan_to_num(points)).astype(int)
    room = np.minimum.reduce([c[:, 0], W - 1 - c[:, 0], c[:, 1], H - 1 - c[:, 1]]) - 2
    chosen = np.full(len(points), sizes[0])
    chosen_sigma = np.full(len(points), np.inf)
    settled = np.zeros(len(points), bool)
    for size in sizes:
        half = size // 2
        fits = half <= room
        box = (c[:, 0] - half, c[:, 0] + half + 1, c[:, 1] - half, c[:, 1] + half + 1)
        sxx, syy, sxy = (_box_sum(t, *box) for t in tables)
        own = size * size * noise**2 / 2
        sxx, syy = sxx - own, syy - own
        weakest = 0.5 * (sxx + syy) - np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
        sigma = np.where(weakest > 0, np.sqrt(2 * noise**2 / np.maximum(weakest, 1e-300)), np.inf)
        grow = ~settled & fits
        chosen[grow] = size
        chosen_sigma[grow] = sigma[grow]
        settled |= grow & (sigma <= target)
    return chosen, chosen_sigma


def texture_distance(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per point, the distance (px) to the nearest texture: the nearest pixel whose
    :data:`_TEXTURE_WINDOW` window holds signal above the noise, on the image and on
    copies of it halved and quartered in size.

    The window's signal variance is its intensity variance less its noise
    variance, and the noise variance is measured in the same window (the
    5-point Laplacian of white noise has 20 times its variance; smooth
    texture barely adds to it), so a dark background with less shot noise
    than the tissue is judged against its own noise. Halving the image
    halves the noise's standard deviation and keeps smooth texture: weak,
    blurry texture that no window shows at full size shows there. A
    detection on a copy ``k`` times smaller places the texture only within
    the window's reach there, so its distance counts ``(k - 1)`` half-windows
    more. A point on blank background a subset's width from a textured edge is
    far from texture at every size even though a large subset would reach
    the edge: its displacement there would be extrapolated, not measured.
    """
    import cv2

    image = np.asarray(image, dtype=np.float64)
    H, W = image.shape
    c = np.rint(np.nan_to_num(points)).astype(int)
    c[:, 0], c[:, 1] = np.clip(c[:, 0], 0, W - 1), np.clip(c[:, 1], 0, H - 1)
    best = np.full(len(points), np.inf)
    w = _TEXTURE_WINDOW
    for k in (1, 2, 4):
        if min(H, W) // k < 2 * w:
            break
        if np.all(best <= (k - 1) * (w // 2)):  # no smaller copy can bring a point nearer
            break
        small = (
            image if k == 1 else cv2.resize(image, (W // k, H // k), interpolation=cv2.INTER_AREA)
        )
        texture = _texture_mask(small)
        if not texture.any():
            continue
        h, wd = texture.shape
        ck = np.minimum(c // k, [wd - 1, h - 1])
        on = texture[ck[:, 1], ck[:, 0]]
        if on.all():  # every point on texture: no distance to measure
            distance = np.zeros(len(points))
        else:
            field = ndimage.distance_transform_edt(~texture)
            distance = field[ck[:, 1], ck[:, 0]] * k
        best = np.minimum(best, distance + (k - 1) * (w // 2))
    return best


def _texture_mask(image: np.ndarray) -> np.ndarray:
    """Pixels whose :data:`_TEXTURE_WINDOW` window holds signal above its own noise (see
    :func:`texture_distance`)."""
    import cv2

    w = _TEXTURE_WINDOW

    def box(a: np.ndarray) -> np.ndarray:  # the w x w mean, mirror boundaries
        return cv2.boxFilter(a, -1, (w, w), normalize=True, borderType=cv2.BORDER_REFLECT)

    lap = cv2.Laplacian(image, cv2.CV_64F, ksize=1, borderType=cv2.BORDER_REFLECT)
    noise2 = box(lap * lap) / 20.0
    mean = box(image)
    var = box(image * image) - mean * mean
    return var - noise2 > _TEXTURE_SIGNAL * np.maximum(noise2, 1e-12)


def surrounded(image: np.ndarray, points: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """Per point, whether each quarter of its square subset (side ``sizes``) holds texture
    (:func:`_texture_mask`): a point on a plain patch with texture all round it (a brick's
    face inside its mortar) is measured by the subset from all sides, not extrapolated
    from one edge as a point on blank background beside a textured piece would be."""
    image = np.asarray(image, dtype=np.float64)
    table = _integral(_texture_mask(image).astype(np.uint8))
    c = np.rint(np.nan_to_num(points)).astype(int)
    half = np.asarray(sizes) // 2
    x, y = c[:, 0], c[:, 1]

    def any_in(x0, x1, y0, y1):  # texture in [x0, x1) x [y0, y1), clipped to the frame
        return _box_sum(table, x0, x1, y0, y1) > 0

    return (
        any_in(x - half, x, y - half, y)
        & any_in(x + 1, x + half + 1, y - half, y)
        & any_in(x - half, x, y + 1, y + half + 1)
        & any_in(x + 1, x + half + 1, y + 1, y + half + 1)
    )


def subset_sizes(
    reference: np.ndarray,
    points: np.ndarray,
    noise: float,
    sizes: tuple[int, ...] = _SUBSETS,
    target: float = _SIGMA_TARGET,
) -> np.ndarray:
    """Per point, the smallest subset side whose texture pins the match to ``target`` px
    (see :func:`subset_texture`)."""
    return subset_texture(reference, points, noise, sizes, target)[0]


def _quadratic_fits(
    points: np.ndarray,
    displacement: np.ndarray,
    valid: np.ndarray,
    near: np.ndarray,
    *,
    with_noise: bool = False,
):
    """Per point, the second derivatives ``(N, 2, 3)`` of the displacement (1/px):
    ``(d2u/dx2, d2u/dxdy, d2u/dy2)`` per component, from a least-squares quadratic
    through the displacements of the point and its valid neighbours (NaN where fewer
    than 6 are valid, or they do not span a quadratic).

    With ``with_noise``, also per point the variance of the fitted Laplacian
    (``d2/dx2 + d2/dy2``, 1/px^2) per unit variance of the displacements: what
    their noise alone puts into the curvature (NaN where not fitted).
    """
    n = len(points)
    out = np.full((n, 2, 3), np.nan)
    lap_var = np.full(n, np.nan)
    if n < 6 or near.shape[1] < 5:
        return (out, lap_var) if with_noise else out

    def build():  # what depends on the geometry and on which points are valid
        group = np.column_stack([np.arange(n), near])  # (N, k + 1)
        d = points[group] - points[:, None, :]  # (N, k + 1, 2)
        scale = np.maximum(np.abs(d).max(axis=(1, 2)), 1e-9)[:, None, None]
        d = d / scale
        dx, dy = d[..., 0], d[..., 1]
        basis = np.stack([np.ones_like(dx), dx, dy, 0.5 * dx * dx, dx * dy, 0.5 * dy * dy], -1)
        Bw = basis * valid[group].astype(float)[..., None]  # (N, k + 1, 6)
        normal = np.einsum("nki,nkj->nij", Bw, basis)  # (N, 6, 6)
        enough = valid[group].sum(axis=1) >= 6
        cond = np.full(n, np.inf)
        cond[enough] = np.linalg.cond(normal[enough])
        good = enough & (cond < 1e8)
        inverse = np.linalg.inv(normal[good]) if good.any() else None  # (n_good, 6, 6)
        return group, scale, Bw, good, inverse

    group, scale, Bw, good, inverse = _geometry("quadratic", points, near, valid, build)
    if good.any():
        rhs = np.einsum("nki,nkc->nic", Bw[good], displacement[group[good]])  # (n_good, 6, 2)
        coef = np.einsum("nij,njc->nic", inverse, rhs)  # (n_good, 6, 2)
        out[good] = np.swapaxes(coef[:, 3:6, :], 1, 2) / scale[good] ** 2
        lap_var[good] = (inverse[:, 3, 3] + inverse[:, 5, 5] + 2 * inverse[:, 3, 5]) / scale[
            good, 0, 0
        ] ** 4
    return (out, lap_var) if with_noise else out


#: the last few neighbourhood fits' geometry (:func:`_geometry`)
_GEOMETRY: dict = {}


def _geometry(kind: str, points: np.ndarray, near: np.ndarray, valid: np.ndarray, build):
    """``build()``, remembered for the same points, neighbours and valid points: from
    frame to frame the same points are mostly matched, and the neighbourhood fits'
    normal matrices and their inverses are the same."""
    key = (kind, points.shape, near.shape, hash(points.tobytes()), hash(near.tobytes()),
           hash(np.packbits(valid).tobytes()))  # fmt: skip
    hit = _GEOMETRY.get(key)
    if hit is None:
        while len(_GEOMETRY) >= 8:
            _GEOMETRY.pop(next(iter(_GEOMETRY)), None)
        hit = _GEOMETRY[key] = build()
    return hit


def _curvature_cap(second: np.ndarray) -> np.ndarray:
    """Per point, the largest subset side (of ``_SUBSETS``) over which the field's
    curvature (``second``, :func:`_quadratic_fits`) would bias an affine warp by at most
    ``_BIAS_TARGET`` px (every size where the curvature is not known).

    A subset that grows for texture must not grow across a heterogeneous
    field: its affine warp takes up ``curvature half^2 / 6``.
    """
    kappa = np.nan_to_num(np.abs(second[:, :, [0, 2]]).max(axis=(1, 2)), nan=0.0)
    cap = np.full(len(second), _SUBSETS[0])
    for size in _SUBSETS[1:]:
        cap[kappa * (size // 2) ** 2 / 6 <= _BIAS_TARGET] = size
    return cap


def _affine_bias(
    second: np.ndarray, half: np.ndarray, lap_noise2: np.ndarray | None = None
) -> np.ndarray:
    """Per point, the bias (px, root mean square of the two components) of an affine
    subset warp of half-side ``half`` over the field's curvature ``second``.

    For a displacement with second derivatives, an affine warp fitted over a
    square of half-side ``L`` takes up the mean of the second-order term,
    ``laplacian(u) L^2 / 6`` per component (the mixed derivative averages
    out). Zero where the curvature is not known. ``lap_noise2`` (per point,
    1/px^4) is the variance the displacements' noise puts into each fitted
    Laplacian: taken out of its square (an unbiased estimate of the true
    curvature's square), so that noisy fits of a field that does not curve
    (a still video) add no bias.
    """
    lap = second[:, :, 0] + second[:, :, 2]  # (N, 2)
    lap2 = lap**2
    if lap_noise2 is not None:
        lap2 = np.maximum(lap2 - np.nan_to_num(lap_noise2, nan=0.0)[:, None], 0.0)
    rms = np.nan_to_num(np.sqrt(np.mean(lap2, axis=1)), nan=0.0)
    return rms * np.asarray(half, float) ** 2 / 6


def _curves(second: np.ndarray, lap_noise2: np.ndarray) -> np.ndarray:
    """Per point, whether the fitted Laplacian (root mean square of the two components)
    exceeds :data:`_CURVES` times what the displacements' noise puts into it."""
    lap = second[:, :, 0] + second[:, :, 2]
    rms2 = np.nan_to_num(np.mean(lap**2, axis=1), nan=0.0)
    return rms2 > _CURVES**2 * np.nan_to_num(lap_noise2, nan=np.inf)


def _spline_kernel(offset: np.ndarray) -> np.ndarray:
    """The cubic B-spline interpolator (prefilter and weights) at sub-pixel ``offset``
    (1-D, in [0, 1)) as taps on the pixels: row ``k`` gives the value at ``offset[k]``
    as ``kernel[k] @ pixels``, with pixel ``24`` the one just before the offset."""
    n = 48
    impulses = ndimage.spline_filter1d(np.eye(n), order=3, axis=1, mode="mirror")
    x = n // 2 + np.asarray(offset, dtype=float).ravel()
    i = np.floor(x).astype(int)
    t = x - i
    # the cubic B-spline's weights for the 4 coefficients around x
    w = np.stack([(1 - t) ** 3, 3 * t**3 - 6 * t**2 + 4, -3 * t**3 + 3 * t**2 + 3 * t + 1, t**3])
    w /= 6.0
    return sum(w[k][:, None] * impulses[:, i + k - 1].T for k in range(4))  # (m, n)


def _spline_noise_gain(offset: np.ndarray) -> np.ndarray:
    """Variance of white noise after cubic B-spline interpolation at sub-pixel ``offset``
    (1-D, in [0, 1)), relative to the noise's own: 1 on the pixels, 0.756 halfway."""
    return np.sum(_spline_kernel(offset) ** 2, axis=1).reshape(np.shape(offset))


def _touches(mask: np.ndarray | None, centers: np.ndarray, half: int | np.ndarray) -> np.ndarray:
    """Whether the square subsets at ``centers`` hold any pixel of ``mask``."""
    if mask is None or not mask.any():
        return np.zeros(len(centers), bool)
    # the sums over the mask's own box (a few highlights: a small part of the frame)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    top, left = rows[0], cols[0]
    box = mask[top : rows[-1] + 1, left : cols[-1] + 1]
    table = _integral(box.astype(np.uint8))
    x, y = (np.rint(np.nan_to_num(centers)).astype(int) - [left, top]).T
    return _box_sum(table, x - half, x + half + 1, y - half, y + half + 1) > 0


def _integral(image: np.ndarray) -> np.ndarray:
    """The summed-area table with a leading row and column of zeros (``(H + 1, W + 1)``;
    OpenCV's: int32 sums of a uint8 mask, float64 sums otherwise)."""
    import cv2

    if image.dtype == np.uint8:
        return cv2.integral(image, sdepth=cv2.CV_32S)
    return cv2.integral(np.ascontiguousarray(image, dtype=np.float64), sdepth=cv2.CV_64F)


def _box_sum(table: np.ndarray, x0, x1, y0, y1) -> np.ndarray:
    """Sums over the boxes ``[x0, x1) x [y0, y1)`` (integer arrays), clipped to the image,
    from its summed-area table (:func:`_integral`)."""
    H, W = table.shape[0] - 1, table.shape[1] - 1
    x0, x1 = np.clip(x0, 0, W), np.clip(x1, 0, W)
    y0, y1 = np.clip(y0, 0, H), np.clip(y1, 0, H)
    return table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]


def _chunks(n: int, size: int) -> list[np.ndarray]:
    return [np.arange(a, min(a + size, n)) for a in range(0, n, max(size, 1))]


def _no_matches(m: int, n_params: int = 6):
    """What :meth:`_Run._match` returns for ``m`` rows before any is matched: warps of
    ``n_params`` zeros, ZNCC -1, none accepted, no residual, ``(J'J)^-1`` or pixels."""
    return (
        np.zeros((m, n_params)),
        np.full(m, -1.0),
        np.zeros(m, bool),
        np.full(m, np.nan),
        np.full((m, 2), np.nan),
        np.zeros(m),
    )


def _reference_subsets(corr: _Correlator, coefficients, centers: np.ndarray):
    """Reference subsets of many points, built 256 at a time (on every thread allowed)
    into float32 arrays (the float64 ones of a whole dense grid would not fit the cache
    budget twice)."""
    fields = SUBSET_FIELDS
    out = None
    chunks = _chunks(len(centers), 256)
    workers = worker_count()
    for group in range(0, len(chunks), 4 * workers):  # a few chunks in float64 at a time
        batch = chunks[group : group + 4 * workers]
        parts = parallel_map(lambda rows: corr.reference(coefficients, centers[rows], 0), batch)
        for rows, part in zip(batch, parts, strict=True):
            out = _store(out, fields, rows, part, len(centers))
    return _Subsets(*(out[k] for k in fields))


def _subsets(corr: _Correlator, coefficients, centers: np.ndarray, *, least: int = 64):
    """Reference subsets (float64) of a few points, split over the threads allowed from
    ``least`` points; the same subsets whatever the thread count (each point's are built
    alone)."""
    workers = min(worker_count(), len(centers))  # no thread without a point
    if workers <= 1 or len(centers) < max(least, 2):
        return corr.reference(coefficients, centers, 0)
    parts = np.array_split(np.arange(len(centers)), workers)
    built = parallel_map(lambda rows: corr.reference(coefficients, centers[rows], 0), parts)
    return _Subsets(*(np.concatenate([getattr(b, k) for b in built]) for k in SUBSET_FIELDS))


def _store(out: dict | None, fields, rows, part, n: int) -> dict:
    """``part``'s subsets into rows ``rows`` of ``out`` (made on the first part)."""
    if out is None:
        out = {}
        for k in fields:
            a = getattr(part, k)
            dtype = np.float32 if k in ("f", "G") else a.dtype
            out[k] = np.empty((n, *a.shape[1:]), dtype)
    for k in fields:
        out[k][rows] = getattr(part, k)
    return out


def _take(ref, rows: np.ndarray):
    return _Subsets(*(getattr(ref, k)[rows] for k in SUBSET_FIELDS))


def _bic_choice(ssd1, ssd2, n, ok1, ok2):
    """Per point, True where the quadratic warp (12 parameters) beats the affine one (6)
    by the Bayesian information criterion ``n ln(SSD / n) + k ln n``."""
    bic1 = n * np.log(ssd1 / n) + 6 * np.log(n)
    bic2 = n * np.log(ssd2 / n) + 12 * np.log(n)
    return ok2 & (~ok1 | (bic2 < bic1))


def _local_sigma(
    hinv: np.ndarray, n_px: np.ndarray, s2: np.ndarray, noise2: float
) -> tuple[np.ndarray, np.ndarray]:
    """IC-GN standard deviation (px per coordinate) of (u, v) for subsets of ``n_px``
    pixels with ``(J'J)^-1`` diagonal ``hinv`` ``(n, 2)`` (of u and v) and a residual
    that shows the noise variance ``s2`` ``(n,)`` per pixel (both frames' noise after
    interpolation), with ``noise2`` the frame's noise variance.

    ``s2 (J'J)^-1``, with the gradients' own noise taken out of ``J'J``: on
    weak texture the reference's gradients are partly noise (a central
    difference of noise of variance ``noise2`` has variance ``noise2 / 2``),
    which inflates ``J'J``, so the uncertainty grows as the texture fades into
    the noise instead of staying optimistic. Returns the standard deviation
    and the factor (>= 1) by which the correction raised the variance.
    """
    noise_energy = (n_px * noise2 / 2)[:, None]
    var = np.full(hinv.shape, np.inf)  # a textureless subset (singular Hessian) says nothing
    has = np.isfinite(hinv) & (hinv > 0)
    signal = np.where(has, 1.0 / np.where(has, hinv, 1.0) - noise_energy, 0.0)
    var[has] = np.where(
        signal[has] * hinv[has] > 0.1, 1.0 / np.maximum(signal[has], 1e-30), 10 * hinv[has]
    )
    variance = var.mean(axis=1)
    plain = hinv.mean(axis=1)
    inflation = np.ones(len(plain))
    good = np.isfinite(variance) & (plain > 0)
    inflation[good] = np.maximum(variance[good] / plain[good], 1.0)
    return np.sqrt(variance * s2), inflation


def _noise_model(variance: np.ndarray, intensity: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Per subset, the noise variance that sensor noise alone would leave, ``a + b I``
    (Poisson-Gaussian: read noise plus shot noise growing with the intensity ``I``),
    fitted to the ``variance`` the residuals of the ``use``d subsets show with the
    subsets whose residual lies far above the fit (the tissue changed its appearance
    there, or the warp does not fit) left out, in turn."""
    keep = use & np.isfinite(variance)
    if keep.sum() < 3:
        level = np.nanmedian(variance[keep]) if keep.any() else np.nan
        return np.full(len(variance), level)
    fit = np.full(len(variance), np.median(variance[keep]))
    for _ in range(4):
        level, v = intensity[keep], variance[keep]
        A = np.column_stack([np.ones_like(level), level])
        (a, b), *_ = np.linalg.lstsq(A, v, rcond=None)
        if b < 0 or a < 0:  # no growth with the intensity to be seen: one level
            a, b = float(np.median(v)), 0.0
        fit = a + b * intensity
        within = use & np.isfinite(variance) & (variance <= 1.5 * fit)
        if within.sum() < 3 or np.array_equal(within, keep):
            break
        keep = within
    return np.maximum(fit, 1e-12)


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
    description="subset correlation where the texture carries the points, a global "
    "regularized field (brightness per node, feature-based guess) for the points and "
    "frames that need it; warp chosen per point; reports an uncertainty per point",
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
        THREADS_OPTION,
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
    threads: int | None = None,
    progress: Callable[[int, int | None], None] | None = None,
) -> Tracks:
    """Track points by local subsets and, where they need it, the global field (see the
    module docstring).

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
        Prior scale of the global field's second derivatives (1/px); the
        regularization weight is ``2 noise^2 / (curvature spacing^2)^2`` with
        the noise measured on the reference frame. Smaller is smoother.
    shape_function : {"auto", "affine", "quadratic"}, keyword-only
        The local subset warp; ``auto`` chooses per point and frame (BIC).
    zncc_min : float, keyword-only
        Correlation below which a local match is not used.
    max_iterations, tolerance : keyword-only
        Of the local IC-GN.
    threads : int, keyword-only
        Threads to use (default: the environment's ``NUMBA_NUM_THREADS`` or
        ``OMP_NUM_THREADS``, else the cores); the tracks do not depend on it.
    progress : callable(done, total), keyword-only

    Returns
    -------
    Tracks
        With ``uncertainty`` (px); ``meta["local_fraction"]`` is the fraction
        of point-frames whose position is a local subset match,
        ``meta["field_frames"]`` the frames on which the global field was
        fitted, ``meta["textureless_points"]`` the points without texture to
        measure (never visible).
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
    with using_threads(threads):
        reference, rest, total = _first_frame(frames)
        shape = reference.shape
        smallest = _SUBSETS[0] if subset == "auto" else subset
        if smallest >= min(shape) or 2 * spacing >= min(shape):
            raise InputError(
                f"--subset {smallest} and 2 x --lattice-spacing {spacing} must be smaller "
                f"than the {shape[1]}x{shape[0]} frames"
            )
        run = _Run(
            reference,
            points,
            subset=subset,
            spacing=spacing,
            curvature=curvature,
            shape_function=shape_function,
            zncc_min=zncc_min,
            max_iterations=max_iterations,
            tolerance=tolerance,
        )
        done = FrameSeries(total, **run.first_row())
        if progress:
            progress(1, total)
        for t, frame in enumerate(prefetched(rest), start=1):
            done.append(**run.frame(frame, t))
            if progress:
                progress(len(done), total)
    if len(done) < 2:
        raise InputError("tracking needs at least 2 frames")
    T, n = len(done), len(points)
    series = done.arrays()
    options = {
        "subset": subset,
        "spacing": spacing,
        "curvature": curvature,
        "shape_function": shape_function,
        "zncc_min": zncc_min,
        "max_iterations": max_iterations,
        "tolerance": tolerance,
        "noise_gray_levels": run.noise,
        "interpolation": "cubic B-spline",
    }
    return Tracks(
        series["positions"],
        series["visible"],
        series["quality"],
        {
            "tracker": "gdic",
            "options": options,
            "local_fraction": run.local_count / max(n * (T - 1), 1),
            "quadratic_fraction": run.quadratic_count / max(n * (T - 1), 1),
            "field_frames": run.field_frames,
            "feature_frames": run.feature_frames,
            "textureless_points": np.flatnonzero(run.in_frame0 & ~run.textured).tolist(),
            "subset_sizes": {
                str(size): int((run.wanted[run.textured] == size).sum())
                for size in run.candidates
                if (run.wanted[run.textured] == size).any()
            },
        },
        series["sigma"],
    )


class _Run:
    """One video's tracking state: the reference's subsets and the last frame's matches."""

    def __init__(
        self,
        reference: np.ndarray,
        points: np.ndarray,
        *,
        subset,
        spacing: int,
        curvature: float,
        shape_function: str,
        zncc_min: float,
        max_iterations: int,
        tolerance: float,
    ) -> None:
        self.reference = reference
        self.points = points
        self.shape = H, W = reference.shape
        n = len(points)
        self.spacing, self.curvature = spacing, curvature
        self.zncc_min = zncc_min
        self.max_iterations, self.tolerance = max_iterations, tolerance
        x, y = points[:, 0], points[:, 1]
        self.in_frame0 = (x >= 0) & (x <= W - 1) & (y >= 0) & (y <= H - 1)
        self.noise = max(noise_sigma(reference), 0.5)
        self.auto = subset == "auto"
        self.candidates = _SUBSETS if self.auto else (int(subset),)
        # bright smooth blobs: specular highlights (which stay where the lamp puts them) or
        # bright tissue (saturated speckle, fat). A subset is matched on the images as they
        # are; one that holds a blob found to stay put while the tissue moves (a highlight)
        # is not kept, and the field (which leaves highlights out of its fit) decides there
        self.blobs = bright_blobs(reference, self.noise)
        # only a blob that a subset could hold matters
        reach = max(self.candidates) // 2 + 2
        (x0, y0), (x1, y1) = points.min(axis=0) - reach, points.max(axis=0) + reach
        near = np.zeros(self.shape, bool)
        near[max(int(y0), 0) : max(int(y1) + 1, 0), max(int(x0), 0) : max(int(x1) + 1, 0)] = True
        self.blobs &= near
        matched = reference
        self.static = np.zeros(self.shape, bool)  # the blobs found to stay put: highlights
        self.frame_highlights = np.zeros(self.shape, bool)  # and those of the last frame
        self.undecided = self.blobs.copy()  # the blobs not yet seen to stay put or to move
        self.blob_labels, self.n_blobs = ndimage.label(self.blobs)
        self.bright_tissue = np.zeros(self.shape, bool)  # the blobs seen to move with it
        self.wanted, texture = subset_texture(matched, points, self.noise, self.candidates)
        if self.auto:  # a point too near the edge for every size: a smaller subset, if it fits
            H, W = self.shape
            c = np.rint(np.nan_to_num(points)).astype(int)
            room = np.minimum.reduce([c[:, 0], W - 1 - c[:, 0], c[:, 1], H - 1 - c[:, 1]]) - 2
            edge = np.flatnonzero(room < self.candidates[0] // 2)
            if edge.size:
                size, sigma = subset_texture(matched, points[edge], self.noise, _EDGE_SUBSETS)
                fits = room[edge] >= size // 2
                self.wanted[edge[fits]], texture[edge[fits]] = size[fits], sigma[fits]
        # a point is tracked where texture lies near it (or all round it in its subset) and
        # its largest subset holds texture enough to pin a match; one far from any texture
        # is on blank background, and one whose subsets hold nothing above the noise would
        # only be interpolated: never reported as measured
        near_texture = texture_distance(matched, points) <= _TEXTURE_REACH
        far = ~near_texture
        if far.any():  # or texture all round it within its subset
            near_texture[far] = surrounded(matched, points[far], self.wanted[far])
        self.textured = self.in_frame0 & near_texture & (texture <= _TEXTURELESS)
        # IC-GN need not settle a subset's pixels more finely than its texture can place
        # them: a fifth of the noise-limited standard deviation (the fixed tolerance on
        # strong texture; weak texture's updates wander at the noise's scale and would
        # never meet it)
        self.tolerances = np.maximum(
            tolerance, _SETTLE * np.nan_to_num(texture, nan=0.0, posinf=0.0)
        )
        self.orders = {"auto": (1, 2), "affine": (1,), "quadratic": (2,)}[shape_function]
        self.correlators: dict = {}
        self.ref_coeff = _coefficients(matched)
        # per point, the residual variance noise leaves per unit noise variance: the B-spline
        # interpolation smooths it, the reference's at the point's fixed sub-pixel offset,
        # the frame's over offsets spread by the deformation
        frac = points - np.floor(points)
        mean_gain = np.mean(_spline_noise_gain(np.linspace(0, 1, 32, endpoint=False)))
        self.gain = _spline_noise_gain(frac[:, 0]) * _spline_noise_gain(frac[:, 1]) + mean_gain**2
        self.intensity = _box_mean(reference, points, self.candidates[0])
        k = min(_NEIGHBOURS + 1, n)
        self.near = (
            cKDTree(points).query(points, k)[1].reshape(n, k)[:, 1:]
            if n > 1
            else np.zeros((n, 0), int)
        )
        self.features = _FeatureGuess(
            reference, points[self.in_frame0] if self.in_frame0.any() else points, _SUBSETS[-1]
        )
        # the global fields: made the first time a point needs one
        self.fields: dict = {}
        # reference subsets kept for the whole video while they fit the budget
        members = {size: np.flatnonzero(self.textured & (self.wanted >= size)) for size in
                   self.candidates}  # fmt: skip
        self.members = {size: m for size, m in members.items() if m.size}
        per_point = {
            size: 4 * size * size * sum(6 * o + 1 for o in self.orders) for size in self.members
        }
        self.cache_all = (
            sum(per_point[size] * len(m) for size, m in self.members.items()) <= _CACHE_BYTES
        )
        self.cached: dict = {}
        self.cached_hinv: dict = {}
        self.built: dict = {}
        self._masked_samples: dict = {}  # (point, size): reference samples (_reference_samples)
        self._static_integral = None  # (pixels, integral image) of self.static (_under_highlight)
        # state carried from frame to frame
        self.p = np.zeros((n, 6))  # each point's last affine warp (relative to its reference)
        self.last = points.copy()  # each point's last position where it was measured
        self.before = points.copy()  # and the one before (for the motion of the last step)
        self.matched = self.textured.copy()  # measured on the last frame
        self.matched_before = np.zeros(n, bool)
        self.second = np.full((n, 2, 3), np.nan)  # the field's curvature at the last frame
        self.noise2 = self.noise**2
        self.local_count = self.quadratic_count = 0
        self.field_frames: list[int] = []
        self.feature_frames: list[int] = []
        self.noise_scale = self._noise_scale()

    def _noise_scale(self) -> float:
        """How the matches' own scatter compares with ``2 sigma_n^2 (J'J)^-1``, measured.

        The IC-GN formula is exact for a matcher whose gradients are those it
        moves along; this one takes central differences of the pixels while it
        moves along the spline, whose slope is steeper on fine texture, so its
        scatter is smaller than the formula's by a factor that depends on the
        texture's spectrum (0.63-0.73 in variance on photographs). It is
        measured on this video's own reference: up to 512 of its textured
        points are matched between two copies of the reference with fresh
        noise of the frame's level, again with two more (up to
        :data:`_NOISE_DRAWS` pairs) while fewer than :data:`_NOISE_MATCHES`
        matches were made (seeded: the result is the same run after run), and
        the mean square displacement over the formula's variance is the factor
        (1 where too few points match). Both copies need fresh noise: matched
        against the reference itself, a copy shares the reference's own noise
        as if it were texture, and on weak texture the factor comes out half
        what the frames show.
        """
        rows = np.flatnonzero(self.textured)
        if rows.size < 8:
            return 1.0
        rows = rows[np.linspace(0, rows.size - 1, min(rows.size, 512)).astype(int)]
        sizes = self.wanted
        rng = np.random.default_rng(_NOISE_SEED)
        moved, expected, matches = 0.0, 0.0, 0
        for _ in range(_NOISE_DRAWS):
            if matches >= _NOISE_MATCHES:
                break
            copies = [
                _coefficients(self.reference + rng.normal(0.0, self.noise, self.shape))
                for _ in range(2)
            ]
            for size in np.unique(sizes[rows]):
                k = rows[sizes[rows] == size]
                corr = self._correlator(int(size), 1)
                ref = _subsets(corr, copies[0], self.points[k], least=2)
                pk, _, ck = corr.match(
                    copies[1], ref, np.arange(len(k)), np.zeros((len(k), 6)), self.tolerances[k]
                )
                good = ck & (np.abs(pk[:, :2]) < 1.0).all(axis=1)
                hinv = np.einsum("nks,nks->nk", ref.G[good, :2], ref.G[good, :2])
                use = np.isfinite(hinv).all(axis=1)
                moved += float(np.sum(pk[good][use, :2] ** 2))
                matches += int(use.sum())
                expected += float(np.sum(2 * self.noise**2 * hinv[use]))
        if expected <= 0:
            return 1.0
        return float(np.clip(moved / expected, 0.25, 1.5))

    def first_row(self) -> dict:
        vis = self.in_frame0 & self.textured
        return {
            "positions": self.points,
            "visible": vis,
            "quality": np.where(vis, 1.0, 0.0),
            "sigma": np.where(vis, 0.0, np.nan),
        }

    # ------------------------------------------------------------------ subsets

    def _correlator(self, size: int, order: int) -> _Correlator:
        key = (size, order)
        if key not in self.correlators:
            self.correlators[key] = _Correlator(
                size, self.max_iterations, self.tolerance, self.zncc_min, order=order
            )
        return self.correlators[key]

    def _reference(self, size: int, order: int, rows: np.ndarray) -> _Subsets:
        """Reference subsets of ``rows`` (sorted), from the cache when it pays."""
        corr = self._correlator(size, order)
        members = self.members.get(size)
        if not self.cache_all or members is None or not np.isin(rows, members).all():
            return _subsets(corr, self.ref_coeff, self.points[rows])
        key = (size, order)
        # a warp tried on few points (the quadratic one, on a homogeneous field) is cached
        # for all only once building it point by point would have cost as much
        if key not in self.cached and self.built.get(key, 0) + len(rows) < len(members):
            self.built[key] = self.built.get(key, 0) + len(rows)
            return _subsets(corr, self.ref_coeff, self.points[rows])
        if key not in self.cached:
            self.cached[key] = _reference_subsets(corr, self.ref_coeff, self.points[members])
        ref = self.cached[key]
        return ref if len(rows) == len(members) else _take(ref, np.searchsorted(members, rows))

    def _hinv(self, size: int, order: int, rows: np.ndarray, ref) -> np.ndarray:
        """The two diagonal entries of ``(J'J)^-1`` of ``rows``' subsets ``ref`` (once per
        point for the cached reference subsets: they do not change from frame to frame)."""
        key, members = (size, order), self.members.get(size)
        if key in self.cached and np.isin(rows, members).all():
            if key not in self.cached_hinv:
                G = self.cached[key].G[:, :2]
                self.cached_hinv[key] = np.einsum("nks,nks->nk", G, G, dtype=float)
            return self.cached_hinv[key][np.searchsorted(members, rows)]
        G = ref.G[:, :2]
        return np.einsum("nks,nks->nk", G, G, dtype=float)

    def _match(self, coeff, rows: np.ndarray, p0: np.ndarray, sizes: np.ndarray, order: int):
        """IC-GN of ``rows`` from warps ``p0`` (6 or 12 columns): the warps, their ZNCC,
        whether each is accepted, and per row the residual variance per pixel, the two
        diagonal entries of ``(J'J)^-1`` and the subset's pixel count (for the
        uncertainty)."""
        m = len(rows)
        n_params = 6 if order == 1 else 12
        p, z, ok, s2, hinv, n_px = _no_matches(m, n_params)
        if m == 0:
            return p, z, ok, s2, hinv, n_px
        start = np.zeros((m, n_params))
        start[:, : min(p0.shape[1], n_params)] = p0[:, :n_params]
        for size in np.unique(sizes[rows]):
            sel = np.flatnonzero(sizes[rows] == size)
            per_row = 4 * size * size * (n_params + 1)
            chunk = len(sel) if self.cache_all else max(64, _CACHE_BYTES // (2 * per_row))
            for part in _chunks(len(sel), chunk):
                k = sel[part]
                corr = self._correlator(int(size), order)
                ref = self._reference(int(size), order, rows[k])
                pk, zk, ck = corr.match(
                    coeff, ref, np.arange(len(k)), start[k], self.tolerances[rows[k]]
                )
                inside = _inside(corr, self.points[rows[k]], pk, self.shape)
                p[k], z[k], ok[k] = pk, zk, ck & (zk >= self.zncc_min) & inside
                n_px[k] = size * size
                norm2 = ref.norm[:, 0].astype(float) ** 2
                s2[k] = np.maximum(2 * (1 - zk), 1e-12) * norm2 / max(size * size - n_params, 1)
                hinv[k] = self._hinv(int(size), order, rows[k], ref)
        return p, z, ok, s2, hinv, n_px

    # ------------------------------------------------------------------ one frame

    def frame(self, frame: np.ndarray, t: int) -> dict:
        """Track every point on frame ``t``; the frame's row of the tracks."""
        frame = np.asarray(frame, dtype=np.float64)
        H, W = self.shape
        if frame.shape != self.shape:
            raise InputError(f"frame {t} is {frame.shape[1]}x{frame.shape[0]}, not {W}x{H}")
        n = len(self.points)
        shared = Frame(frame)  # what the fields compute from the frame, computed once
        coeff = _coefficients(frame)
        sizes = self.wanted
        if self.auto:  # no larger than the field's curvature (at the last frame) allows
            sizes = np.minimum(self.wanted, _curvature_cap(self.second))
        active = self.textured
        rows = np.flatnonzero(active)
        step = _last_step(self.before, self.last, self.matched_before & self.matched)
        p0 = self._guess(step)
        # no larger than fits in the frame where the guess puts the point (a point near the
        # edge of a stretching frame keeps a subset, a smaller one)
        if self.auto:
            edge = (*_EDGE_SUBSETS, *self.candidates)
            sizes = np.minimum(sizes, _fitting(self.points, p0, self.shape, edge))
        # a point that the motion takes out of the frame (where the guess puts it) is out of
        # view on this frame: no restart, feature guess or field is spent on it, and it
        # does not count among the points that failed
        guess = self.points + p0[:, :2]
        leaving = ~((guess >= 0) & (guess <= [W - 1, H - 1])).all(axis=1)
        active = active & ~leaving
        rows = np.flatnonzero(active)

        # 1. every textured point from the motion guess (affine warp)
        p, z, ok, s2, hinv, n_px = _no_matches(n)

        def take(idx, result, better=None):
            pk, zk, okk, s2k, hk, nk = result
            use = okk if better is None else okk & better
            i = idx[use]
            p[i], z[i], ok[i] = pk[use, :6], zk[use], True
            s2[i], hinv[i], n_px[i] = s2k[use], hk[use], nk[use]
            return use

        result = self._match(coeff, rows, p0[rows], sizes, 1)
        # failures keep their correlation too (for the restart order)
        z[rows] = result[1]
        take(rows, result)
        first = {"rows": rows, "result": result}  # each point's own match from the guess
        # a match whose motion since the last frame disagrees with its neighbours' is suspect
        moved = self.points + p[:, :2] - self.last
        usable = ok & self.matched
        suspect = np.flatnonzero(usable & _median_outliers(moved, usable, self.near))
        own = (p[suspect].copy(), z[suspect].copy(), s2[suspect].copy(), hinv[suspect].copy(),
               n_px[suspect].copy())  # fmt: skip
        ok[suspect] = False

        # 2. a jump or a turn between frames: the frame's features give a new start
        if rows.size and ok[rows].mean() < _FEATURES_BELOW:
            affine = self.features(frame)
            if affine is not None:
                self.feature_frames.append(t)
                failed = rows[~ok[rows]]
                start = _warps(
                    self.points[failed],
                    _apply(affine, self.points[failed]),
                    np.broadcast_to(affine[:, :2], (len(failed), 2, 2)),
                )
                take(failed, self._match(coeff, failed, start, sizes, 1))
        # 3. restarts from the best matched neighbour, round after round
        self._propagate(coeff, active, sizes, p, z, ok, take)
        keep = ~ok[suspect] | (own[1] > z[suspect])
        keep &= np.isfinite(own[2])
        i = suspect[keep]
        p[i], z[i], s2[i], hinv[i], n_px[i] = (a[keep] for a in own)
        ok[i] = True
        # a match whose displacement the neighbours' does not predict has drifted
        ok &= ~_inconsistent(self.points, p[:, :2], ok, self.near)
        # highlights: blobs that stay put in the image while the tissue moves
        lit = np.zeros(n, bool)
        masked = np.zeros(n, bool)  # matched on the pixels the highlights leave
        fallback = np.zeros(n, bool)  # and of those, with the halos kept in
        if self.blobs.any():
            # a match whose residual is the noise's is not disturbed by a blob: only the
            # blobs under the other subsets need deciding on this frame
            clean = ok & (s2 / self.gain <= _CLEAN_RESIDUAL * self.noise2)
            lit = self._highlights(shared, p, ok, sizes, clean)
            matched_here = ok & lit  # their own match, a start for the masked subsets
            ok &= ~lit
            if lit.any():  # matched again on the pixels no highlight covers on either image
                idx, result, halo_kept = self._around_highlights(
                    coeff, lit & active, p0, p, matched_here, sizes, ok, z
                )
                taken = idx[take(idx, result)]
                fallback[idx[halo_kept]] = True
                # a masked match that its neighbours' motion does not predict, by more than
                # 3 of its own sigma (the residual's, with a halo left in), has drifted
                judged = np.zeros(n, bool)
                judged[taken] = True
                with np.errstate(invalid="ignore", divide="ignore"):
                    own = _local_sigma(hinv, n_px, 2 * self.noise_scale * self.noise2,
                                       self.noise2)[0]  # fmt: skip
                    excess = np.maximum(s2 / self.gain / self.noise2, 1.0)
                own = np.where(fallback, own * np.sqrt(excess), own)
                bar = np.maximum(0.3, 3 * np.where(np.isfinite(own), own, 0.0))
                drifted = _inconsistent(
                    self.points, p[:, :2], ok, self.near, judge=judged, floor=bar
                )
                ok &= ~drifted
                masked[taken] = ~drifted[taken]
                fallback &= masked
                lit &= ~ok

        # 3b. a point whose own match fell short of convergence or of zncc_min (weak texture,
        # fading light) is kept where it still correlates (ZNCC >= _WEAK_ZNCC) and its
        # measured neighbours' affine motion predicts it: it is measured, and the field
        # (far dearer) is left to the points that no local match explains
        weak = np.zeros(n, bool)
        fr, (pf, zf, _, s2f, hf, nf) = first["rows"], first["result"]
        near_miss = np.zeros(n, bool)
        near_miss[fr] = (zf >= _WEAK_ZNCC) & np.isfinite(s2f)
        near_miss &= active & ~ok & ~lit
        # not where a subset holds a bright blob that may be a highlight: a match that
        # follows the light is smooth and its neighbours may follow it too
        if near_miss.any() and self.blobs.any():
            near_miss &= ~_touches(self.blobs & ~self.bright_tissue, self.points + p0[:, :2],
                                   sizes // 2)  # fmt: skip
        if near_miss.any() and ok.sum() >= 5:
            u = p[:, :2].copy()
            at = np.searchsorted(fr, np.flatnonzero(near_miss))
            u[near_miss] = pf[at, :2]
            predicted = ~_inconsistent(self.points, u, ok, self.near, judge=near_miss)
            fits = np.zeros(n, bool)
            fits[np.flatnonzero(near_miss)] = _predictable(self.points, ok, self.near)[near_miss]
            weak = near_miss & predicted & fits
            i = np.flatnonzero(weak)
            k = np.searchsorted(fr, i)
            p[i], z[i], ok[i] = pf[k, :6], zf[k], True
            s2[i], hinv[i], n_px[i] = s2f[k], hf[k], nf[k]

        # 4. the global field, for the points still failing
        from_field = np.zeros(n, bool)
        field_sigma = np.full(n, np.nan)
        field_quality = np.zeros(n)
        need = np.flatnonzero(active & ~ok)
        # a point whose subset holds a highlight and which a highlight found to stay put
        # covers (a third of any cell of the field's lattice that may hold it) is seen by
        # neither: no field is fitted for it
        under = need[lit[need]]
        need = np.setdiff1d(need, under[self._under_highlight(under)])
        # a few points: a small field around each group of neighbours (with their own
        # neighbours); many: one field
        if need.size > _LOCAL_FIELDS_UP_TO * max(rows.size, 1):
            groups = [("all", need)]
        else:
            groups = [(tuple(g.tolist()), g) for g in _neighbour_groups(need, self.near)]
        for key, idx in groups:
            solver = self._field(key, shared, t, p, ok, step, p0)
            u, grad = solver.displacement(self.points[idx])
            start = _warps(self.points[idx], self.points[idx] + u, np.eye(2) + grad)
            result = self._match(coeff, idx, start, sizes, 1)
            gap = np.linalg.norm(result[0][:, :2] - u, axis=1)
            sigma_u = solver.uncertainty(self.points[idx])
            agrees = gap <= np.maximum(2.0, 5 * np.nan_to_num(sigma_u, nan=0.2))
            took = take(idx, result, agrees & ~lit[idx])
            rest = idx[~took]
            seen = solver.seen(self.points[rest])
            hold = rest[seen]
            from_field[hold] = True
            uh, gh = solver.displacement(self.points[hold])
            p[hold] = _warps(self.points[hold], self.points[hold] + uh, np.eye(2) + gh)
            field_sigma[hold] = solver.uncertainty(self.points[hold])
            field_quality[hold] = np.clip(solver.cell_zncc(self.points[hold]), 0.0, 1.0)
        if need.size:
            self.field_frames.append(t)
            # a field's value that its measured neighbours do not predict is not reported
            # (by more than the field's own 3 sigma, and 1 px: the field is smooth where the
            # local matches scatter, so it is held to a coarser bar than they are)
            bar = np.maximum(1.0, 3 * np.nan_to_num(field_sigma, nan=0.0))
            off = _inconsistent(self.points, p[:, :2], ok, self.near, judge=from_field, floor=bar)
            from_field &= ~off

        # the noise the residuals show, and the field's curvature from the matches
        noise2 = _noise_model(s2 / self.gain, self.intensity, ok)
        known = noise2[ok & np.isfinite(noise2)]
        level = np.median(known) if known.size else np.nan
        self.noise2 = float(level) if np.isfinite(level) else self.noise2
        # both frames' pixel noise (the model, never the residual: beyond the noise, the
        # residual is appearance, not noise), as the matches' own scatter scales it
        noise_s2 = 2 * self.noise_scale * noise2
        sigma, _ = _local_sigma(hinv, n_px, noise_s2, self.noise2)
        second, lap_var = _quadratic_fits(
            self.points, p[:, :2], ok | from_field, self.near, with_noise=True
        )
        # the displacements' noise in the curvature: each fit's from the typical sigma
        noise_sigma2 = np.where(ok, sigma, np.where(from_field, field_sigma, np.nan)) ** 2
        typical2 = np.nanmedian(noise_sigma2) if np.isfinite(noise_sigma2).any() else 0.0
        lap_noise2 = lap_var * typical2

        # 5. the quadratic warp, where the curvature biases an affine warp beyond its noise
        quadratic = np.zeros(n, bool)
        half = sizes // 2
        bias = _affine_bias(second, half, lap_noise2)
        if 2 in self.orders:
            # (not the subsets matched around a highlight: the quadratic warp would take
            # the highlight in again)
            if self.orders == (2,):
                tries = np.flatnonzero(active & (ok | from_field) & ~masked)
            else:
                # where the bias is large and the curvature that makes it stands out of
                # the displacements' noise (a flat field's noisy fits do not pass)
                tries = np.flatnonzero(ok & ~masked & (bias > _QUADRATIC_BIAS * sigma) &
                                       _curves(second, lap_noise2))  # fmt: skip
            if tries.size:
                pq, zq, okq, s2q, hq, nq = self._match(coeff, tries, p[tries], sizes, 2)
                if self.orders == (2,):
                    better = okq
                else:
                    better = _bic_choice(s2[tries] * n_px[tries], s2q * nq, nq, ok[tries], okq)
                    # where the affine warp stays, the quadratic one's shift from it measures
                    # the affine one's bias (per coordinate)
                    kept = ~better & okq & ok[tries]
                    shift = np.linalg.norm(pq[kept, :2] - p[tries[kept], :2], axis=1) / np.sqrt(2)
                    bias[tries[kept]] = np.maximum(bias[tries[kept]], shift)
                i = tries[better]
                p[i] = pq[better, :6]
                z[i], ok[i], quadratic[i] = zq[better], True, True
                from_field[i] = False
                s2[i], hinv[i], n_px[i] = s2q[better], hq[better], nq[better]
                noise_s2 = 2 * self.noise_scale * noise2
                sigma, _ = _local_sigma(hinv, n_px, noise_s2, self.noise2)
        # a subset matched with a highlight's halo left in holds some of its light: the
        # residual's excess over the noise model's is counted as position noise there
        with np.errstate(invalid="ignore", divide="ignore"):
            excess = np.maximum((s2 / self.gain) / noise2, 1.0)
        sigma = np.where(fallback & np.isfinite(excess), sigma * np.sqrt(excess), sigma)
        affine = ok & ~quadratic
        sigma = np.where(affine, np.sqrt(sigma**2 + bias**2), sigma)

        pos = self.points + p[:, :2]
        inside = (pos[:, 0] >= 0) & (pos[:, 0] <= W - 1) & (pos[:, 1] >= 0) & (pos[:, 1] <= H - 1)
        measured = ok | from_field
        vis = inside & active & measured
        pos = np.where(measured[:, None], pos, self.last)
        # the state for the next frame
        self.before = np.where(measured[:, None], self.last, self.before)
        self.matched_before = self.matched & measured
        # a point not measured moves on with the guess (the tissue's motion), so that one
        # the tissue carries out of the frame is seen to leave it
        self.last = np.where(measured[:, None], pos, self.points + p0[:, :2])
        self.matched = measured
        self.p = np.where(measured[:, None], p, p0)
        if np.isfinite(second).any():
            self.second = second
        self.local_count += int((ok & vis).sum())
        self.quadratic_count += int((quadratic & ok & vis).sum())
        return {
            "positions": pos,
            "visible": vis,
            "quality": np.where(vis, np.where(ok, np.clip(z, 0.0, 1.0), field_quality), 0.0),
            "sigma": np.where(vis, np.where(ok, sigma, field_sigma), np.nan),
        }

    def _guess(self, step: np.ndarray | None) -> np.ndarray:
        """Each point's starting warp: its last one, moved as the last step's best-fit affine
        motion of the grid moved it, plus the rest of its own last step."""
        F = _gradient(self.p)
        if step is None:
            return _warps(self.points, self.last, F)
        moved = _apply(step, self.last)
        both = self.matched_before & self.matched
        own = np.where(both[:, None], self.last - _apply(step, self.before), 0.0)
        return _warps(self.points, moved + own, step[:, :2] @ F)

    def _propagate(self, coeff, active, sizes, p, z, ok, take) -> None:
        """Restart failed points from their best matched neighbour's warp, evaluated at
        the point (exact for a homogeneous deformation), while the matched region grows."""
        from strain2d.trackers.dic import _best_neighbours

        tried = np.zeros(len(p), bool)
        for _ in range(len(p)):
            failed = np.flatnonzero(active & ~ok & ~tried)
            if failed.size == 0 or not ok.any():
                break
            f_idx, b_idx = _best_neighbours(self.near, failed, ok, z)
            if f_idx.size == 0:
                break
            d = self.points[f_idx] - self.points[b_idx]
            F = _gradient(p[b_idx])
            start = _warps(
                self.points[f_idx],
                self.points[b_idx] + p[b_idx, :2] + np.einsum("nij,nj->ni", F, d),
                F,
            )
            use = take(f_idx, self._match(coeff, f_idx, start, sizes, 1))
            tried[f_idx[~use]] = True
            if not use.any():  # the matched region stopped growing
                break

    def _highlights(self, frame: Frame, p, ok, sizes, clean) -> np.ndarray:
        """Points whose subset holds a specular highlight (a blob that stays put in the image
        while the tissue moves), where they were on the reference or are on this frame.

        Each blob of the reference is decided once: a highlight when it is seen to stay
        put, bright tissue when it is seen to move with the tissue; the frame's blobs are
        looked for only around the blobs not yet decided (none, once all are) that touch
        a subset whose match is not ``clean`` (a highlight that the tissue moved over
        leaves a residual well above the noise in every subset that holds it)."""
        n = len(self.points)
        motion = _affine_fit(self.points[ok], self.points[ok] + p[ok, :2])
        frame_mask = np.zeros(self.shape, bool)

        def moving(x: np.ndarray) -> np.ndarray:
            return _apply(motion, x) - x

        deciding = self._deciding(p, clean, sizes) if motion is not None else None
        if deciding is not None and self._can_tell(deciding, moving):
            ref_mask, frame_mask, tissue = static_highlights(
                deciding,
                frame.blobs(self.noise, blob_window(deciding, moving)),
                moving,
                with_tissue=True,
            )
            self.static |= ref_mask  # once found to stay put, a highlight stays one
            self.bright_tissue |= tissue
            # a blob seen to move with the tissue is tissue; one not yet seen to do either
            # may still show itself a highlight on a later frame (its outline on the
            # frame can differ while the light and the tissue move)
            self.undecided &= ~(ref_mask | tissue)
        # a highlight stays where it is in the image: on this frame as on the reference
        self.frame_highlights = frame_mask | self.static
        if not self.static.any() and not frame_mask.any():
            return np.zeros(n, bool)
        half = sizes // 2
        return _touches(self.static, self.points, half) | _touches(
            self.frame_highlights, self.points + p[:, :2], half
        )

    def _deciding(self, p, clean, sizes) -> np.ndarray | None:
        """The undecided blobs that touch the subset of a point whose match is not clean,
        where it was on the reference or is on this frame (None where there are none)."""
        if not self.undecided.any():
            return None
        suspect = np.flatnonzero(self.textured & ~clean)
        if suspect.size == 0:
            return None
        H, W = self.shape
        near = np.zeros(self.shape, bool)
        half = sizes[suspect] // 2
        for at in (self.points[suspect], self.points[suspect] + p[suspect, :2]):
            c = np.rint(np.nan_to_num(at)).astype(int)
            x0, x1 = np.clip(c[:, 0] - half, 0, W), np.clip(c[:, 0] + half + 1, 0, W)
            y0, y1 = np.clip(c[:, 1] - half, 0, H), np.clip(c[:, 1] + half + 1, 0, H)
            for a, b, e, f in zip(y0, y1, x0, x1, strict=True):
                near[a:b, e:f] = True
        chosen = np.unique(self.blob_labels[near & self.undecided])
        if chosen.size == 0:
            return None
        lut = np.zeros(self.n_blobs + 1, bool)
        lut[chosen] = True
        return lut[self.blob_labels] & self.undecided

    def _can_tell(self, blobs: np.ndarray, moving) -> bool:
        """Whether the tissue moved enough (2 px) anywhere over ``blobs`` for
        :func:`static_highlights` to tell a highlight from tissue (before looking for
        the frame's blobs)."""
        rows = np.flatnonzero(blobs.any(axis=1))
        cols = np.flatnonzero(blobs.any(axis=0))
        x = np.linspace(cols[0], cols[-1], 5)
        y = np.linspace(rows[0], rows[-1], 5)
        grid = np.stack(np.meshgrid(x, y), axis=-1).reshape(-1, 2)
        return bool(np.any(np.hypot(*moving(grid).T) >= 2.0))

    def _around_highlights(self, coeff, rows, guess, p, ok, sizes, measured, z):
        """Rows of points whose subsets hold a highlight, and their IC-GN matched (on the
        frame's spline coefficients ``coeff``) on the pixels that no highlight (of the
        reference or of this frame: they stay put) nor its halo covers on either image
        (:meth:`_masked_match`): the subset follows the tissue's texture around it, not
        the light. From their own match where they had one, else from their best
        ``measured`` neighbour's warp (``z``: the neighbours' ZNCC), evaluated at the
        point, else from the motion ``guess``. Returns the rows, the matches (as
        :meth:`_match` returns them) and which rows kept the halos in (their subsets
        matched with the blobs alone left out). The caller judges the matches by their
        neighbours' motion (a match that drifted is not kept)."""
        from strain2d.trackers.dic import _best_neighbours

        idx = np.flatnonzero(rows)
        start = np.where(ok[idx, None], p[idx], guess[idx])
        f_idx, b_idx = _best_neighbours(self.near, idx, measured, z)
        f_idx, b_idx = f_idx[~ok[f_idx]], b_idx[~ok[f_idx]]
        if f_idx.size:
            F = _gradient(p[b_idx])
            d = self.points[f_idx] - self.points[b_idx]
            at = self.points[b_idx] + p[b_idx, :2] + np.einsum("nij,nj->ni", F, d)
            start[np.searchsorted(idx, f_idx)] = _warps(self.points[f_idx], at, F)
        highlights = self.static | self.frame_highlights
        masks = (with_halos(highlights), dilated(highlights, 2))
        *result, which = self._masked_match(coeff, idx, start, sizes, masks)
        return idx, tuple(result), which == 1

    def _masked_match(self, coeff, rows, start, sizes, masks):
        """IC-GN (affine) of ``rows`` from warps ``start`` on the pixels of each subset that
        a mask of highlights (fixed in the image) leaves on both images: where the
        reference has them, and where the start's warp puts them on the frame (with 2 px
        more, for the match's own motion). The subset's mean, norm and Hessian are those of
        the pixels kept, so the correlation is the ZNCC over them alone.

        ``masks``: the highlights with their halos, then without; each subset takes the
        first that leaves it :data:`_MASKED_MIN_PIXELS` pixels (and
        :data:`_MASKED_MIN_SHARE` of its square), and is not matched where none does.
        Returns what :meth:`_match` returns, then per row the index of the mask it was
        matched with (-1 where none left it pixels enough)."""
        from strain2d.trackers._icgn_kernel import icgn
        from strain2d.trackers.dic import step_operator
        from tissue_core.interrupt import deferred_interrupt

        m = len(rows)
        p, z, ok, s2, hinv, n_px = _no_matches(m)
        H, W = self.shape
        which = np.full(m, -1)  # the mask each row was matched with (-1: none)
        masks = [(hidden, dilated(hidden, 2)) for hidden in masks]
        for j, i in enumerate(rows):
            size = int(sizes[i])
            corr = self._correlator(size, 1)
            cx, cy = self.points[i]
            ex, ey = corr.ex, corr.ey
            rx = np.clip(np.rint(cx + ex).astype(int), 0, W - 1)
            ry = np.clip(np.rint(cy + ey).astype(int), 0, H - 1)
            q = start[j]
            fxp = cx + q[0] + (1 + q[2]) * ex + q[3] * ey
            fyp = cy + q[1] + q[4] * ex + (1 + q[5]) * ey
            gx = np.clip(np.rint(fxp).astype(int), 0, W - 1)
            gy = np.clip(np.rint(fyp).astype(int), 0, H - 1)
            least = max(_MASKED_MIN_PIXELS, _MASKED_MIN_SHARE * size * size)
            for which[j], (hidden, wide) in enumerate(masks):  # the widest that leaves enough
                keep = ~hidden[ry, rx] & ~wide[gy, gx]
                count = int(keep.sum())
                if count >= least:
                    break
            else:
                which[j] = -1
                continue
            exk, eyk = ex[keep], ey[keep]
            f, right, left, down, up = self._reference_samples(i, corr)[:, keep]
            fx, fy = 0.5 * (right - left), 0.5 * (down - up)
            f_normed, norm, G = step_operator(f[None], fx[None], fy[None], exk, eyk)
            with deferred_interrupt():  # Ctrl-C inside the kernel would be a SystemError
                pk, zk, ck = icgn(
                    coeff, np.array([[cx, cy]]), f_normed, norm[:, 0], G,
                    q[None, :6].astype(np.float64), np.ascontiguousarray(exk),
                    np.ascontiguousarray(eyk), corr.half, self.tolerances[[i]],
                    self.max_iterations, self.zncc_min,
                )  # fmt: skip
            inside = _inside(corr, self.points[[i]], pk, self.shape)[0]
            p[j], z[j] = pk[0], zk[0]
            ok[j] = bool(ck[0]) and zk[0] >= self.zncc_min and inside
            n_px[j] = count
            s2[j] = max(2 * (1 - zk[0]), 1e-12) * float(norm[0, 0]) ** 2 / max(count - 6, 1)
            hinv[j] = np.einsum("ks,ks->k", G[0, :2], G[0, :2])
        return p, z, ok, s2, hinv, n_px, which

    def _under_highlight(self, rows: np.ndarray) -> np.ndarray:
        """Whether the highlights found to stay put cover over ``HIDDEN_CELL`` of every
        lattice cell (``spacing`` px square, in any placement in the frame) that holds each
        point of ``rows``, and over that share of under a quarter of the cells of a field
        around the point and its neighbours: such a field does not count that cell in its
        fit (:meth:`LatticeSolver.seen`), which it does only while under a quarter of its
        cells are that hidden (the frame's own highlights, the same spots where the image
        holds them, add to the count)."""
        out = np.zeros(len(rows), bool)
        h = self.spacing
        H, W = self.shape
        if not len(rows) or H < h or W < h or not self.static.any():
            return out
        # the highlights' pixel count in the box [x, x + h) x [y, y + h) from an integral
        # image, made again only when a highlight was added (the mask only grows)
        count = int(self.static.sum())
        if self._static_integral is None or self._static_integral[0] != count:
            S = np.zeros((H + 1, W + 1))
            S[1:, 1:] = self.static.cumsum(axis=0).cumsum(axis=1)
            self._static_integral = (count, S)
        S = self._static_integral[1]

        def shares(x0: np.ndarray, y0: np.ndarray) -> np.ndarray:
            count = S[y0 + h, x0 + h] - S[y0, x0 + h] - S[y0 + h, x0] + S[y0, x0]
            return count / (h * h)

        # a cell [x0, x0 + h) holds x where x0 is one of floor(x) - h + 1 .. floor(x)
        c = np.floor(self.points[rows]).astype(int)
        d = np.arange(h)
        x0 = c[:, 0, None, None] - d[None, None, :]  # (n, dy, dx) the cells' corners
        y0 = c[:, 1, None, None] - d[None, :, None]
        inside = (x0 >= 0) & (y0 >= 0) & (x0 + h <= W) & (y0 + h <= H)
        share = np.where(inside, shares(np.clip(x0, 0, W - h), np.clip(y0, 0, H - h)), np.inf).min(
            axis=(1, 2)
        )
        out = inside.any(axis=(1, 2)) & (share > HIDDEN_CELL)
        for j in np.flatnonzero(out):  # the field's cells that the highlights hide so
            # the field's lattice covers the points in the reference frame (as _field's)
            near = [i for i in (rows[j], *self.near[rows[j]]) if self.in_frame0[i]]
            around = self.points[near]
            lattice = Lattice.around(around[np.isfinite(around).all(axis=1)], self.shape, h)
            corners = lattice.cell_origins().astype(int)
            out[j] = np.mean(shares(corners[:, 0], corners[:, 1]) > HIDDEN_CELL) < HIDDEN_CELLS
        return out

    def _reference_samples(self, i: int, corr: _Correlator) -> np.ndarray:
        """The reference's spline at every pixel of point ``i``'s subset of ``corr``'s size
        and at its four neighbours (for central differences), ``(5, S^2)``: what a subset
        matched around highlights keeps some of, frame after frame (kept for
        :data:`_MASKED_SAMPLES` points, the last used)."""
        from strain2d.trackers.dic import _sample

        key = (int(i), corr.size)
        samples = self._masked_samples.pop(key, None)
        if samples is None:
            # the pixels and their four neighbours, in one call
            X, Y = self.points[i, 0] + corr.ex, self.points[i, 1] + corr.ey
            samples = _sample(
                self.ref_coeff,
                np.concatenate([X, X + 1, X - 1, X, X]),
                np.concatenate([Y, Y, Y, Y + 1, Y - 1]),
            ).reshape(5, -1)
        self._masked_samples[key] = samples  # the last used last
        while len(self._masked_samples) > _MASKED_SAMPLES:
            self._masked_samples.pop(next(iter(self._masked_samples)))
        return samples

    def _field(self, key, frame, t: int, p, ok, step, guess) -> LatticeSolver:
        """A global field fitted to frame ``t``: over every point (``key`` "all"), or over
        the points of ``key`` (a tuple) and their neighbours; from its own last fit when
        that was on the frame before, from this frame's local matches otherwise (and the
        motion ``guess`` of the points that failed, where fewer than 3 matched)."""
        if key not in self.fields:
            if key == "all":
                cover = self.textured
            else:
                cover = np.zeros(len(self.points), bool)
                cover[list(key)] = True
                cover[self.near[list(key)].ravel()] = True
                cover &= self.in_frame0
            solver = LatticeSolver(
                self.reference,
                self.points[cover] if cover.any() else self.points,
                spacing=self.spacing,
                curvature=self.curvature,
                noise=self.noise,
                blobs=self.blobs,
            )
            self.fields[key] = [solver, -1, None]  # the solver, its last frame, the state before
        field = self.fields[key]
        solver, last, before = field
        nodes = solver.lattice.nodes()
        previous = solver.state.copy()  # its fit of the last frame it was fitted to
        state = previous.copy()
        if key == "all" and last == t - 1 and before is not None:
            state = _extrapolate(nodes, before, previous)
        else:
            use = ok if ok.sum() >= 3 else self.textured
            u = np.where(ok[:, None], p[:, :2], guess[:, :2])
            state[:, :2] = _displacement_at(nodes, self.points[use], u[use], step)
        solver._static |= self.static  # the highlights found on the frames it did not see
        coarse, _ = solver.coarse(frame, state)
        solver.refine(frame, coarse)
        field[1], field[2] = t, (previous if last == t - 1 else None)
        return solver


#: a subset matched around highlights keeps at least this many pixels, and this share of
#: its square
_MASKED_MIN_PIXELS = 200
_MASKED_MIN_SHARE = 0.1
#: the points whose reference samples are kept for matching around highlights (about
#: 0.25 MB each for the largest subsets): the points near a highlight, frame after frame
_MASKED_SAMPLES = 64

#: px the warped subset keeps from the frame's edge beyond the spline margin (the motion
#: between the guess and the match)
_EDGE_ROOM = 3.0


def _room(points: np.ndarray, p: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Per point, the largest half-side (px) of a square subset that, warped by ``p``
    (affine, ``(N, 6)``), lies in the frame with :data:`_EDGE_ROOM` px to spare (-1
    where the warp is not finite)."""
    H, W = shape
    x = points + p[:, :2]
    F = _gradient(p)
    reach = np.abs(F).sum(axis=2)  # per axis, how far a corner at (h, h) reaches, per unit h
    room = np.stack([x[:, 0] - 1, W - 2 - x[:, 0], x[:, 1] - 1, H - 2 - x[:, 1]], axis=1)
    room = room - _EDGE_ROOM
    half = np.min(room / np.repeat(np.maximum(reach, 1e-6), 2, axis=1), axis=1)
    return np.nan_to_num(half, nan=-1.0)


def _fitting(points: np.ndarray, p: np.ndarray, shape: tuple[int, int], sizes) -> np.ndarray:
    """Per point, the largest subset side among ``sizes`` (ascending) whose square, warped
    by ``p`` (affine, ``(N, 6)``), lies in the frame with :data:`_EDGE_ROOM` px to spare;
    the smallest where none does."""
    sizes = np.asarray(sizes)
    fits = (sizes[None, :] // 2) <= _room(points, p, shape)[:, None]
    best = np.where(fits.any(axis=1), fits.shape[1] - 1 - np.argmax(fits[:, ::-1], axis=1), 0)
    return sizes[best]


def _predictable(points: np.ndarray, valid: np.ndarray, near: np.ndarray) -> np.ndarray:
    """Whether each point has at least 4 valid neighbours that span an affine field
    (so :func:`_inconsistent` can judge it)."""
    n = len(points)
    if n < 5 or near.shape[1] < 4:
        return np.zeros(n, bool)
    return valid[near].sum(axis=1) >= 4


def _neighbour_groups(idx: np.ndarray, near: np.ndarray) -> list[np.ndarray]:
    """``idx`` split into groups that are neighbours of one another (connected through
    ``near``), each sorted: one small field serves each group."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.asarray(idx)
    if idx.size <= 1:
        return [idx] if idx.size else []
    where = {int(i): k for k, i in enumerate(idx)}
    pairs = [(where[int(i)], where[int(j)]) for i in idx for j in near[i] if int(j) in where]
    a = np.array([i for i, _ in pairs], int)
    b = np.array([j for _, j in pairs], int)
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(idx.size, idx.size))
    _, label = connected_components(graph, directed=False)
    return [np.sort(idx[label == k]) for k in np.unique(label)]


def _inconsistent(
    points: np.ndarray,
    u: np.ndarray,
    valid: np.ndarray,
    near: np.ndarray,
    judge: np.ndarray | None = None,
    floor: float | np.ndarray = 0.3,
) -> np.ndarray:
    """Points (of ``judge``, the valid ones by default) whose displacement ``u`` the
    best-fit affine field of their valid neighbours does not predict: off by more than 4
    times the neighbours' own such misfit (at least ``floor`` px). A subset that slowly drifted
    (following a highlight or a shadow) still moves like its neighbours from frame to
    frame, not in all; a field's value is held to its measured neighbours the same way."""
    n = len(points)
    out = np.zeros(n, bool)
    if n < 5 or near.shape[1] < 4:
        return out
    judge = valid if judge is None else judge

    def build():  # what depends on the geometry and on which points are valid
        d = points[near] - points[:, None, :]  # (N, k, 2)
        scale = np.maximum(np.abs(d).max(axis=(1, 2)), 1e-9)[:, None, None]
        d = d / scale
        basis = np.concatenate([np.ones((*d.shape[:2], 1)), d], axis=-1)  # (N, k, 3)
        Bw = basis * valid[near].astype(float)[..., None]
        normal = np.einsum("nki,nkj->nij", Bw, basis)
        fits = valid[near].sum(axis=1) >= 4
        fits[fits] &= np.linalg.cond(normal[fits]) < 1e8
        # the fitted value at the point: row 0 of the inverse, per point
        first = np.zeros((n, 3))
        if fits.any():
            first[fits] = np.linalg.inv(normal[fits])[:, 0, :]
        return Bw, fits, first

    Bw, fits, first = _geometry("affine", points, near, valid, build)
    enough = (valid | judge) & fits
    misfit = np.full(n, np.nan)
    if enough.any():
        rhs = np.einsum("nki,nkc->nic", Bw[enough], u[near[enough]])  # (m, 3, 2)
        value = np.einsum("ni,nic->nc", first[enough], rhs)  # the fit's value at the point
        misfit[enough] = np.linalg.norm(u[enough] - value, axis=1)
    own = np.where(valid, misfit, np.nan)
    around = np.where(valid[near], own[near], np.nan)
    has = np.isfinite(around).any(axis=1)
    typical = np.zeros(n)
    typical[has] = np.nanmedian(around[has], axis=1)
    out = judge & enough & (misfit > np.maximum(4 * typical, floor))
    return out


def _last_step(before: np.ndarray, last: np.ndarray, both: np.ndarray) -> np.ndarray | None:
    """The best-fit affine map of the last step, ``before -> last``, over the points
    measured on both frames (None when fewer than 3 were)."""
    return _affine_fit(before[both], last[both])


def _extrapolate(nodes: np.ndarray, before: np.ndarray, now: np.ndarray) -> np.ndarray:
    """Node states one frame ahead: the last step's best-fit affine motion applied again
    (exact for steady rotation and stretch), plus the rest of the step's motion."""
    x0, x1 = nodes + before[:, :2], nodes + now[:, :2]
    A = _affine_fit(x0, x1)
    guess = now.copy()
    if A is None:
        return guess
    rest = x1 - _apply(A, x0)
    guess[:, :2] = _apply(A, x1) + rest - nodes
    return guess


def _displacement_at(
    where: np.ndarray, points: np.ndarray, u: np.ndarray, step: np.ndarray | None
) -> np.ndarray:
    """Displacements ``(M, 2)`` at ``where`` from those ``u`` of ``points``: their best-fit
    affine field plus the rest, weighted by inverse squared distance over the 4 nearest
    points."""
    if len(points) < 3:
        if step is None:
            return np.zeros((len(where), 2))
        return _apply(step, where) - where
    affine = _affine_fit(points, points + u)
    if affine is None:
        return np.broadcast_to(np.median(u, axis=0), (len(where), 2)).copy()
    rest = points + u - _apply(affine, points)
    k = min(4, len(points))
    distance, nearest = cKDTree(points).query(where, k)
    distance, nearest = distance.reshape(len(where), k), nearest.reshape(len(where), k)
    w = 1.0 / np.maximum(distance, 1e-6) ** 2
    inner = np.einsum("mk,mkc->mc", w, rest[nearest]) / w.sum(axis=1)[:, None]
    return _apply(affine, where) - where + inner


def _box_mean(image: np.ndarray, points: np.ndarray, size: int) -> np.ndarray:
    """Mean of ``image`` over the square of side ``size`` around each point (clipped)."""
    H, W = image.shape
    x, y = np.rint(np.nan_to_num(points)).astype(int).T
    half = size // 2
    x0, x1 = np.clip(x - half, 0, W), np.clip(x + half + 1, 0, W)
    y0, y1 = np.clip(y - half, 0, H), np.clip(y + half + 1, 0, H)
    area = np.maximum((x1 - x0) * (y1 - y0), 1)
    return _box_sum(_integral(image), x0, x1, y0, y1) / area
