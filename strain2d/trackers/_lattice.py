"""Global digital image correlation on a regularized bilinear finite-element lattice.

The displacement of the whole region of interest is one field: bilinear on a
square lattice of nodes ``h`` pixels apart, with a brightness gain ``a`` and
offset ``b`` per node (the reference ``f`` is matched by
``(1 + a) (g(x + u) - m) + m + b``, with ``m`` the reference's mean over the
region, so light that changes across the image and over time does not bias
the motion; the gain scales contrast about the mean, so on smooth tissue it
does not trade against the offset). The field minimizes, over every pixel of the
region at once,

    sum_p w_c(p) r_p^2  +  lambda_u |D u|^2  +  lambda_a |D a|^2  +  lambda_b |D b|^2,

with ``D`` the second differences along x, y and xy on the lattice (a
thin-plate penalty: its null space is the affine fields, so homogeneous
deformations are not biased) and ``w_c`` a robust weight per lattice cell
(cells whose residual is far above the others', under an occluder or a
specular spot, stop counting). Where the texture is weak, the data term
vanishes and the penalty fills the field in from the neighbours.

The weights follow from the noise (a Bayesian reading): ``lambda = 2 sigma^2
/ tau^2``, with ``sigma`` the image noise measured on the reference frame
(Immerkaer's estimator) and ``tau = curvature h^2`` the expected second
difference of the motion between nodes, ``curvature`` in 1/px. So
regularization grows with the noise and matters only where the texture is
too weak for the data to decide; the posterior covariance
``2 sigma^2 (H + lambda D'D)^-1`` gives each point's uncertainty.

Gauss-Newton with the Hessian of the reference gradients (the "modified"
Gauss-Newton of global DIC), corrected per cell for the current deformation
gradient and gain: ``grad g(x + u) = F^-T grad f / (1 + a)``. The Hessian of
each cell is computed once per reference as a 16 x 16 block, so a frame costs
one cubic B-spline sampling of the region per iteration and a sparse solve;
the residual and the gradient per cell are compiled kernels
(:func:`strain2d.trackers._icgn_kernel.lattice_residual`,
:func:`~strain2d.trackers._icgn_kernel.lattice_gradient`) on every thread. A
level stops when its steps fall below the tolerance, or once they have not
shrunk for :data:`_STALLED` iterations (a few nodes cycling between robust
weights). Coarse-to-fine: the same lattice on blurred, subsampled images first, which
widens the basin of convergence. A finer level is held near the coarser
level's answer by a weak prior (``LEASH``): where texture is strong the data
outweigh it, where it is weak the field does not wander off.

References
----------
.. [1] Besnard, G., Hild, F., & Roux, S. (2006). "Finite-element"
   displacement fields analysis from digital images. Experimental Mechanics
   46, 789-803. https://doi.org/10.1007/s11340-006-9824-8
.. [2] Tomicevic, Z., Hild, F., & Roux, S. (2013). Mechanics-aided digital
   image correlation. J. Strain Analysis 48, 330-343.
   https://doi.org/10.1177/0309324713482457
.. [3] Immerkaer, J. (1996). Fast noise variance estimation. Computer Vision
   and Image Understanding 64, 300-302. https://doi.org/10.1006/cviu.1996.0060
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import linalg, ndimage, sparse

from strain2d.trackers.dic import _coefficients
from tissue_core.interrupt import deferred_interrupt

__all__ = ["Frame", "Lattice", "LatticeSolver", "noise_sigma"]


def noise_sigma(image: np.ndarray) -> float:
    """Standard deviation of additive noise in a gray image (Immerkaer 1996)."""
    image = np.asarray(image, dtype=np.float64)
    if min(image.shape) < 3:
        return 1.0
    kernel = np.array([[1, -2, 1], [-2, 4, -2], [1, -2, 1]], dtype=float)
    response = ndimage.convolve(image, kernel, mode="nearest")[1:-1, 1:-1]
    h, w = image.shape
    return float(np.sqrt(np.pi / 2) * np.abs(response).sum() / (6.0 * (w - 2) * (h - 2)))


def _blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian blur with mirror boundaries (OpenCV's; a wide one, 8 px or more, on a
    quarter-scale copy resized back: the smooth surroundings of a pixel, for detection)."""
    import cv2

    image = np.asarray(image, dtype=np.float64)
    H, W = image.shape
    if sigma >= 8 and min(H, W) >= 64:  # that smooth a result is made at a quarter scale
        small = cv2.resize(image, (W // 4, H // 4), interpolation=cv2.INTER_AREA)
        small = cv2.GaussianBlur(
            small, (0, 0), np.sqrt(sigma**2 - 1.25) / 4, borderType=cv2.BORDER_REFLECT_101
        )
        return cv2.resize(small, (W, H), interpolation=cv2.INTER_LINEAR)
    return cv2.GaussianBlur(image, (0, 0), sigma, borderType=cv2.BORDER_REFLECT_101)


#: px around a window that :func:`bright_blobs` reads for the surroundings and the growth
_BLOB_MARGIN = 100

#: iterations without a step 10 % smaller than the smallest so far after which a level's
#: Gauss-Newton stops, unconverged
_STALLED = 5

#: a cell with over this share of its pixels under a highlight does not count in the fit,
#: while under :data:`HIDDEN_CELLS` of the lattice's cells are that hidden (a highlight
#: over most of the field is the frame's lighting, not a spot to leave out)
HIDDEN_CELL = 0.3
HIDDEN_CELLS = 0.25

#: the kernel's "no highlight mask"
_NO_MASK = np.zeros((0, 0), dtype=bool)


def _percentile(a: np.ndarray, q: float) -> float:
    """``np.percentile(a, q)``, bit for bit (its linear interpolation),
    with one partition: the solvers ask it of small arrays on every iteration, where
    NumPy's general function costs several times the partition."""
    n = a.size
    if np.isnan(a).any():  # NumPy's answer: not a number
        return float(np.percentile(a, q))
    virtual = (n - 1) * (q / 100)
    lo = int(np.floor(virtual))
    hi = min(lo + 1, n - 1)
    part = np.partition(a, [lo, hi])
    below, above = float(part[lo]), float(part[hi])
    gamma = virtual - lo
    diff = above - below
    return above - diff * (1 - gamma) if gamma >= 0.5 else below + diff * gamma


def blob_window(reference_blobs: np.ndarray, motion, reach: int = 48) -> tuple | None:
    """Where a frame's blobs can matter to :func:`static_highlights`: the box of the
    reference's blobs, where they were and where the tissue's ``motion`` would have
    taken them, grown by ``reach`` px (None where the reference has none)."""
    if not reference_blobs.any():
        return None
    rows = np.flatnonzero(reference_blobs.any(axis=1))
    cols = np.flatnonzero(reference_blobs.any(axis=0))
    y0, y1, x0, x1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
    corners = np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]], float)
    u = np.nan_to_num(motion(corners))
    xs = np.concatenate([corners[:, 0], corners[:, 0] + u[:, 0]])
    ys = np.concatenate([corners[:, 1], corners[:, 1] + u[:, 1]])
    return (
        int(np.floor(ys.min())) - reach,
        int(np.ceil(ys.max())) + reach,
        int(np.floor(xs.min())) - reach,
        int(np.ceil(xs.max())) + reach,
    )


def bright_blobs(
    image: np.ndarray, noise: float, window: tuple[int, int, int, int] | None = None
) -> np.ndarray:
    """Candidate specular highlights: smooth bright blobs (bool mask).

    Cores: pixels more than ``max(30, 8 noise)`` gray levels above the Gaussian
    mean of their 20 px surroundings, in patches that survive an opening by a
    5 x 5 square (thin bright texture such as hairs does not), cover at least
    30 px and are smooth inside (fine detail at most 2.5 times the noise).
    Each core is grown over its halo, the connected pixels more than
    ``2.5 noise`` above the surroundings (up to 40 px), and by 3 px. Blobs
    over more than 5 % of the image are the background or the texture (the
    gaps of a speckle pattern), not highlights, and none is returned. Bright
    tissue can look like this too: :func:`static_highlights` keeps only the
    blobs that stay put while the tissue moves.

    ``window`` ``(y0, y1, x0, x1)`` looks only there (the rest of the mask is
    False): what is found inside is what the whole image gives there, the
    surroundings read from a margin around it, and the 5 % is of the image.
    """
    image = np.asarray(image, dtype=np.float64)
    if window is not None:
        H, W = image.shape
        y0, y1, x0, x1 = window
        y0, x0 = max(int(y0), 0), max(int(x0), 0)
        y1, x1 = min(int(y1), H), min(int(x1), W)
        out = np.zeros((H, W), bool)
        if y1 <= y0 or x1 <= x0:
            return out
        m = _BLOB_MARGIN
        Y0, Y1, X0, X1 = max(y0 - m, 0), min(y1 + m, H), max(x0 - m, 0), min(x1 + m, W)
        part = _blobs(image[Y0:Y1, X0:X1], noise)
        out[y0:y1, x0:x1] = part[y0 - Y0 : y1 - Y0, x0 - X0 : x1 - X0]
    else:
        out = _blobs(image, noise)
    # highlights are a few spots; bright blobs all over are background or texture
    return out if out.mean() < 0.05 else np.zeros_like(out)


def _blobs(image: np.ndarray, noise: float) -> np.ndarray:
    """:func:`bright_blobs` over the whole of ``image``, however many (OpenCV's
    morphology: the same masks as SciPy's, with zero borders, in a fraction of the time)."""
    import cv2

    excess = image - _blur(image, 20.0)
    core = excess > max(30.0, 8.0 * noise)
    if not core.any():
        return core
    zero = {"borderType": cv2.BORDER_CONSTANT, "borderValue": 0}
    square = np.ones((5, 5), np.uint8)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    opened = cv2.dilate(cv2.erode(core.astype(np.uint8), square, **zero), square, **zero)
    if not opened.any():
        return opened.astype(bool)
    # the patches are labelled in the box that holds them, and their fine detail read there
    # with the blur's reach around it (OpenCV's kernel: 4 standard deviations; its values
    # are the whole image's): each patch is kept or not on its own pixels
    H, W = core.shape
    (y0, y1), (x0, x1) = _box(opened)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        np.ascontiguousarray(opened[y0:y1, x0:x1]), connectivity=4
    )
    r = int(np.ceil(4 * 1.5))
    Y0, Y1, X0, X1 = max(y0 - r, 0), min(y1 + r, H), max(x0 - r, 0), min(x1 + r, W)
    near = np.ascontiguousarray(image[Y0:Y1, X0:X1])
    detail = (near - _blur(near, 1.5))[y0 - Y0 : y1 - Y0, x0 - X0 : x1 - X0]
    inside = labels > 0
    which = labels[inside]
    n = np.bincount(which, minlength=count).astype(float)
    mean = np.bincount(which, detail[inside], minlength=count) / np.maximum(n, 1)
    mean2 = np.bincount(which, detail[inside] ** 2, minlength=count) / np.maximum(n, 1)
    roughness = np.sqrt(np.maximum(mean2 - mean**2, 0.0))
    keep = (stats[:, cv2.CC_STAT_AREA] >= 30) & (roughness < 2.5 * noise)
    keep[0] = False
    core = np.zeros((H, W), bool)
    core[y0:y1, x0:x1] = keep[labels]
    if not core.any():
        return core
    # the cores grown over their halos (40 steps of 4-connected growth inside the bright
    # pixels) and by 3 px, in the box that holds them (the growth reaches 43 px at most)
    bright = (excess > 2.5 * noise).astype(np.uint8)
    blobs = np.zeros_like(core)
    (y0, y1), (x0, x1) = _box(core)
    y0, y1 = max(y0 - 44, 0), min(y1 + 44, H)
    x0, x1 = max(x0 - 44, 0), min(x1 + 44, W)
    grown = core[y0:y1, x0:x1].astype(np.uint8)
    allowed = bright[y0:y1, x0:x1] | grown
    for _ in range(40):
        wider = cv2.dilate(grown, cross, **zero) & allowed
        if np.array_equal(wider, grown):
            break
        grown = wider
    blobs[y0:y1, x0:x1] = cv2.dilate(grown, cross, iterations=3, **zero).astype(bool)
    return blobs


def _box(mask: np.ndarray) -> tuple[tuple[int, int], tuple[int, int]]:
    """The rows and columns (start, stop) of the box that holds ``mask``'s pixels (some)."""
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    return (int(rows[0]), int(rows[-1]) + 1), (int(cols[0]), int(cols[-1]) + 1)


def static_highlights(
    reference_blobs: np.ndarray, frame_blobs: np.ndarray, motion, *, with_tissue: bool = False
) -> tuple:
    """The blobs that stayed where they were in the image while the tissue moved.

    A blob of the reference is a highlight when the frame has a blob at the
    same image position that covers 60 % of it and overlaps it better (by 0.1
    of its area) than the blob would if it had moved with the tissue (``motion(points) -> (N, 2)``
    displacements), or whose centroid stayed where it was (:func:`_blob_shift`: a blob
    much larger than the motion overlaps its moved self nearly as well); where the
    tissue moved less than 2 px, nothing is decided.
    Returns the reference's and the frame's highlight masks, and with
    ``with_tissue`` the reference's blobs seen to move with the tissue (the
    other way round: bright tissue, never a highlight).
    """
    empty = np.zeros(reference_blobs.shape, bool)
    if not reference_blobs.any() or not frame_blobs.any():
        return (empty, empty, empty.copy()) if with_tissue else (empty, empty)
    H, W = reference_blobs.shape
    # the blobs are labelled in the box that holds them all (a few spots of a large frame):
    # each blob is decided on its own pixels, so the masks are those of the whole frame
    (y0, y1), (x0, x1) = _box(reference_blobs | frame_blobs)
    labels = np.zeros((H, W), np.int32)
    frame_labels = np.zeros((H, W), np.int32)
    labels[y0:y1, x0:x1] = ndimage.label(reference_blobs[y0:y1, x0:x1])[0]
    frame_labels[y0:y1, x0:x1] = ndimage.label(frame_blobs[y0:y1, x0:x1])[0]
    ref_mask, frame_mask, tissue = empty.copy(), empty.copy(), empty.copy()

    def shifted(boxes):  # the boxes of the labelled part, in the frame
        return [(slice(b[0].start + y0, b[0].stop + y0), slice(b[1].start + x0, b[1].stop + x0))
                for b in boxes]  # fmt: skip

    frame_boxes = shifted(ndimage.find_objects(frame_labels[y0:y1, x0:x1]))
    for k, box in enumerate(shifted(ndimage.find_objects(labels[y0:y1, x0:x1])), start=1):
        yy, xx = np.nonzero(labels[box] == k)
        yy, xx = yy + box[0].start, xx + box[1].start
        u = motion(np.array([[xx.mean(), yy.mean()]]))[0]
        if not np.all(np.isfinite(u)) or np.hypot(*u) < 2.0:
            continue
        same = frame_blobs[yy, xx].mean()
        mx = np.clip(np.rint(xx + u[0]).astype(int), 0, W - 1)
        my = np.clip(np.rint(yy + u[1]).astype(int), 0, H - 1)
        moved = frame_blobs[my, mx].mean()
        stays, goes = _blob_shift(frame_labels, frame_boxes, xx, yy, mx, my, u)
        if same > 0.6 and (same > moved + 0.1 or stays):
            ref_mask[yy, xx] = True
            hit = np.unique(frame_labels[yy, xx])
            frame_mask[y0:y1, x0:x1] |= np.isin(frame_labels[y0:y1, x0:x1], hit[hit > 0])
        elif moved > 0.6 and (moved > same + 0.1 or goes):
            tissue[yy, xx] = True
    return (ref_mask, frame_mask, tissue) if with_tissue else (ref_mask, frame_mask)


def with_halos(mask: np.ndarray) -> np.ndarray:
    """Each blob of ``mask`` grown by half its equivalent radius (``sqrt(area / pi)``): the
    light of a smooth highlight goes on beyond where :func:`bright_blobs` stops, a halo
    that stays put in the image as the highlight does (a Gaussian spot of sigma ``s`` and
    60 gray levels is found out to about ``1.7 s``; its light is still 2 gray levels at
    ``2.6 s``, and a static gradient of a fraction of a level pulls a subset's match)."""
    import cv2

    count, labels, stats, _ = cv2.connectedComponentsWithStats(
        mask.astype(np.uint8), connectivity=8
    )
    out = mask.copy()
    H, W = mask.shape
    for k in range(1, count):
        x, y, w, h, area = stats[k]
        grow = int(np.ceil(0.5 * np.sqrt(area / np.pi)))
        y0, y1 = max(y - grow, 0), min(y + h + grow, H)
        x0, x1 = max(x - grow, 0), min(x + w + grow, W)
        disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1))
        part = (labels[y0:y1, x0:x1] == k).astype(np.uint8)
        out[y0:y1, x0:x1] |= cv2.dilate(part, disk).astype(bool)
    return out


def _blob_shift(frame_labels, frame_boxes, xx, yy, mx, my, u) -> tuple[bool, bool]:
    """Whether the frame's blob over a reference blob (pixels ``xx, yy``; moved with the
    tissue, ``mx, my``; ``frame_boxes``: the boxes of the frame's labelled blobs) has its
    centroid where the reference blob was (it stayed) or where the tissue took it (it
    moved): within a third of the tissue's motion ``u`` of one and beyond two thirds of it
    from the other, and of a similar area (0.7-1.4 times).

    The overlaps :func:`static_highlights` compares change by the motion's share of the
    blob's size, which is small for a blob much larger than the motion; the centroid moves
    with the blob whatever its size."""
    hit = np.unique(np.concatenate([frame_labels[yy, xx], frame_labels[my, mx]]))
    hit = hit[hit > 0]
    if hit.size == 0:
        return False, False
    parts = []
    for label in hit:
        box = frame_boxes[label - 1]
        fy, fx = np.nonzero(frame_labels[box] == label)
        parts.append((fy + box[0].start, fx + box[1].start))
    fy = np.concatenate([a for a, _ in parts])
    fx = np.concatenate([b for _, b in parts])
    if not 0.7 <= fx.size / xx.size <= 1.4:  # merged with other blobs, or only a part
        return False, False
    c = np.array([fx.mean(), fy.mean()])
    ref = np.array([xx.mean(), yy.mean()])
    step = float(np.hypot(*u))
    to_ref, to_moved = np.hypot(*(c - ref)), np.hypot(*(c - ref - u))
    stays = to_ref <= step / 3 and to_moved >= 2 * step / 3
    goes = to_moved <= step / 3 and to_ref >= 2 * step / 3
    return bool(stays), bool(goes)


#: at the finer levels, how far (px) the field may stray from the coarser level's answer
#: where the data do not hold it (weak texture: a smooth ramp shifted looks like one
#: brightened, and the field would wander); gain and offset likewise, by 0.1 and 10 levels
LEASH = (2.0, 0.1, 10.0)


@dataclass(frozen=True)
class Lattice:
    """Square lattice of ``(nx + 1) x (ny + 1)`` nodes, ``h`` px apart, from ``(x0, y0)``."""

    x0: int
    y0: int
    h: int
    nx: int
    ny: int

    @classmethod
    def around(cls, points: np.ndarray, shape: tuple[int, int], h: int) -> Lattice:
        """The lattice covering ``points`` with a margin of one cell, inside the frame."""
        H, W = shape
        lo = np.floor(points.min(axis=0)) - h
        hi = np.ceil(points.max(axis=0)) + h
        x0, y0 = int(max(lo[0], 2)), int(max(lo[1], 2))
        nx = max(1, int(np.ceil((min(hi[0], W - 3) - x0) / h)))
        ny = max(1, int(np.ceil((min(hi[1], H - 3) - y0) / h)))
        nx = max(1, min(nx, (W - 3 - x0) // h))
        ny = max(1, min(ny, (H - 3 - y0) // h))
        return cls(x0, y0, h, nx, ny)

    @property
    def n_nodes(self) -> int:
        return (self.nx + 1) * (self.ny + 1)

    @property
    def n_cells(self) -> int:
        return self.nx * self.ny

    def nodes(self) -> np.ndarray:
        """Node positions ``(n_nodes, 2)`` (row-major: x fastest)."""
        gx, gy = np.meshgrid(
            self.x0 + self.h * np.arange(self.nx + 1), self.y0 + self.h * np.arange(self.ny + 1)
        )
        return np.column_stack([gx.ravel(), gy.ravel()]).astype(float)

    def cell_nodes(self) -> np.ndarray:
        """Corner nodes ``(n_cells, 4)`` of each cell: (0,0), (1,0), (0,1), (1,1)."""
        j, i = np.divmod(np.arange(self.n_cells), self.nx)
        n0 = j * (self.nx + 1) + i
        return np.stack([n0, n0 + 1, n0 + self.nx + 1, n0 + self.nx + 2], axis=1)

    def cell_origins(self) -> np.ndarray:
        j, i = np.divmod(np.arange(self.n_cells), self.nx)
        return np.column_stack([self.x0 + self.h * i, self.y0 + self.h * j]).astype(float)

    def _cell_ij(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Column and row of the cell holding lattice coordinates ``s`` (clipped to it)."""
        i = np.clip(np.floor(s[:, 0]).astype(int), 0, self.nx - 1)
        j = np.clip(np.floor(s[:, 1]).astype(int), 0, self.ny - 1)
        return i, j

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        """Index of the cell holding each point (the nearest one outside the lattice)."""
        i, j = self._cell_ij((points - [self.x0, self.y0]) / self.h)
        return j * self.nx + i

    def interpolation(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bilinear weights at ``points``: node indices ``(N, 4)``, weights ``(N, 4)``,
        and the weights' x and y derivatives ``(N, 4, 2)`` (1/px)."""
        s = (points - [self.x0, self.y0]) / self.h
        i, j = self._cell_ij(s)
        xi, eta = s[:, 0] - i, s[:, 1] - j
        n0 = j * (self.nx + 1) + i
        idx = np.stack([n0, n0 + 1, n0 + self.nx + 1, n0 + self.nx + 2], axis=1)
        w = np.stack([(1 - xi) * (1 - eta), xi * (1 - eta), (1 - xi) * eta, xi * eta], axis=1)
        dx = np.stack([-(1 - eta), 1 - eta, -eta, eta], axis=1) / self.h
        dy = np.stack([-(1 - xi), -xi, 1 - xi, xi], axis=1) / self.h
        return idx, w, np.stack([dx, dy], axis=-1)

    def bending(self) -> sparse.csr_matrix:
        """``D'D`` of the second differences (xx, yy and twice xy) on the nodes."""
        nx, ny = self.nx + 1, self.ny + 1
        index = np.arange(nx * ny).reshape(ny, nx)
        rows, cols, vals = [], [], []
        r = 0

        def add(entries):
            nonlocal r
            for idx, v in entries:
                rows.append(np.full(idx.size, r) + np.arange(idx.size))
                cols.append(idx.ravel())
                vals.append(np.full(idx.size, v))
            r += entries[0][0].size

        if nx >= 3:
            add([(index[:, :-2], 1.0), (index[:, 1:-1], -2.0), (index[:, 2:], 1.0)])
        if ny >= 3:
            add([(index[:-2, :], 1.0), (index[1:-1, :], -2.0), (index[2:, :], 1.0)])
        s = np.sqrt(2.0)
        add([(index[:-1, :-1], s), (index[:-1, 1:], -s), (index[1:, :-1], -s), (index[1:, 1:], s)])
        D = sparse.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(r, nx * ny),
        )
        return (D.T @ D).tocsr()


def dilated(mask: np.ndarray, steps: int) -> np.ndarray:
    """``mask`` grown by ``steps`` pixels in the city-block sense: what
    ``scipy.ndimage.binary_dilation(mask, iterations=steps)`` gives (its cross, repeated:
    a diamond), in one pass of OpenCV's dilation (a tenth of the time on a full frame)."""
    if steps <= 0 or not mask.any():
        return mask.copy()
    import cv2

    r = np.arange(-steps, steps + 1)
    diamond = (np.abs(r)[:, None] + np.abs(r)[None, :] <= steps).astype(np.uint8)
    grown = cv2.dilate(
        mask.astype(np.uint8), diamond, borderType=cv2.BORDER_CONSTANT, borderValue=0
    )
    return grown.astype(bool)


def _grown(mask: np.ndarray, blur: float) -> np.ndarray:
    """A mask grown by the reach of a Gaussian blur (two standard deviations)."""
    return dilated(mask, int(np.ceil(2 * blur))) if blur else mask


def _shape_functions(h: int, stride: int) -> np.ndarray:
    o = np.arange(0, h, stride, dtype=float) / h
    eta, xi = np.meshgrid(o, o, indexing="ij")
    xi, eta = xi.ravel(), eta.ravel()
    return np.stack([(1 - xi) * (1 - eta), xi * (1 - eta), (1 - xi) * eta, xi * eta], axis=1)


#: px of the frame read around the positions a part's spline coefficients serve: the
#: spline's support (2), a blur's reach (OpenCV's kernel: 4 standard deviations) and the
#: B-spline prefilter's, whose pole (2 - sqrt 3) decays below 1e-13 in 24 px: there the
#: part's coefficients are the whole frame's to round-off
_PART_MARGIN = 2 + 24
#: px added around the positions asked for, so that the next iterations' steps stay inside
_PART_SLACK = 16
#: a part over this share of the frame is made as the whole frame
_PART_SHARE = 0.5


class Frame:
    """A frame and what the solvers fitted to it compute from it once: the spline
    coefficients of each blur (of the whole frame, or of the parts a small field samples),
    the bright blobs for each noise level."""

    def __init__(self, image: np.ndarray) -> None:
        self.image = np.asarray(image, dtype=np.float64)
        self._coefficients: dict[float, np.ndarray] = {}
        self._parts: dict[float, list] = {}
        self._blobs: dict[float, np.ndarray] = {}

    @classmethod
    def of(cls, frame) -> Frame:
        return frame if isinstance(frame, Frame) else cls(frame)

    def coefficients(self, blur: float) -> np.ndarray:
        """The spline coefficients of the whole frame blurred by ``blur`` px."""
        if blur not in self._coefficients:
            g = _blur(self.image, blur) if blur > 0 else self.image
            self._coefficients[blur] = _coefficients(g)
        return self._coefficients[blur]

    def part(self, blur: float, box) -> tuple[np.ndarray, np.ndarray]:
        """Spline coefficients of the frame blurred by ``blur`` px that serve every position
        in ``box`` (x0, y0, x1, y1; the frame's own where None), and where they start in
        the frame (x, y): a part of the frame around the box, whose coefficients there
        equal the whole frame's to round-off (see :data:`_PART_MARGIN`), or the whole
        frame's. A field over a few points of a large frame samples a small part of it."""
        H, W = self.image.shape
        origin = np.zeros(2, np.int64)
        # a blur of 8 px or more is made at a quarter scale (:func:`_blur`): not local
        if blur in self._coefficients or box is None or blur >= 8:
            return self.coefficients(blur), origin
        # the positions sampled lie in the frame (the kernel samples none nearer its edge)
        x0, x1 = (min(max(v, 1), W - 2) for v in (math.floor(box[0]), math.ceil(box[2])))
        y0, y1 = (min(max(v, 1), H - 2) for v in (math.floor(box[1]), math.ceil(box[3])))
        x1, y1 = max(x1, x0), max(y1, y0)
        for (X0, Y0, _, _), inner, coefficients in self._parts.get(blur, []):
            if inner[0] <= x0 and inner[1] <= y0 and x1 <= inner[2] and y1 <= inner[3]:
                return coefficients, np.array([X0, Y0], np.int64)
        reach = _PART_MARGIN + int(np.ceil(4 * blur)) + _PART_SLACK
        X0, Y0 = int(max(x0 - reach, 0)), int(max(y0 - reach, 0))
        X1, Y1 = int(min(x1 + reach + 1, W)), int(min(y1 + reach + 1, H))
        parts = self._parts.get(blur, [])
        made = sum((b[2] - b[0]) * (b[3] - b[1]) for b, _, _ in parts)
        # a large part, or parts that add up to the frame: the whole frame's
        if (X1 - X0) * (Y1 - Y0) > _PART_SHARE * H * W or made > H * W:
            return self.coefficients(blur), origin
        part = np.ascontiguousarray(self.image[Y0:Y1, X0:X1])
        coefficients = _coefficients(_blur(part, blur) if blur > 0 else part)
        # where the part's coefficients are the frame's: all of it along the frame's edges
        margin = _PART_MARGIN + int(np.ceil(4 * blur))
        inner = (
            1 if X0 == 0 else X0 + margin,
            1 if Y0 == 0 else Y0 + margin,
            W - 2 if X1 == W else X1 - 1 - margin,
            H - 2 if Y1 == H else Y1 - 1 - margin,
        )
        self._parts.setdefault(blur, []).append(((X0, Y0, X1, Y1), inner, coefficients))
        return coefficients, np.array([X0, Y0], np.int64)

    def blobs(self, noise: float, window: tuple | None = None) -> np.ndarray:
        key = (noise, window)
        if key not in self._blobs:
            self._blobs[key] = bright_blobs(self.image, noise, window)
        return self._blobs[key]


class _Level:
    """One resolution: the reference blurred by ``blur`` px and sampled every ``stride`` px."""

    def __init__(
        self, lattice: Lattice, reference: np.ndarray, blur: float, stride: int, mean: float
    ):
        self.lattice, self.blur, self.stride, self.mean = lattice, blur, stride, mean
        h, nx, ny = lattice.h, lattice.nx, lattice.ny
        # the lattice's box with the blur's reach and the gradient's pixel around it
        H, W = reference.shape
        reach = int(np.ceil(4 * blur)) + 2
        y0, x0 = max(lattice.y0 - reach, 0), max(lattice.x0 - reach, 0)
        y1, x1 = min(lattice.y0 + ny * h + reach, H), min(lattice.x0 + nx * h + reach, W)
        part = np.ascontiguousarray(reference[y0:y1, x0:x1])
        f = _blur(part, blur) if blur > 0 else part
        gy, gx = np.gradient(f)
        region = (
            slice(lattice.y0 - y0, lattice.y0 - y0 + ny * h, stride),
            slice(lattice.x0 - x0, lattice.x0 - x0 + nx * h, stride),
        )
        m = h // stride

        def blocks(a: np.ndarray) -> np.ndarray:
            return a[region].reshape(ny, m, nx, m).transpose(0, 2, 1, 3).reshape(ny * nx, m * m)

        self.f = blocks(f)
        self.blocks = blocks
        # the gain multiplies the image about its mean, so that gain and offset do not
        # trade against each other on smooth tissue
        self.q = np.stack([blocks(gx), blocks(gy), self.f - mean, np.ones_like(self.f)], axis=-1)
        self.N = _shape_functions(h, stride)  # (m*m, 4)
        o = np.arange(0, h, stride, dtype=float)
        oy, ox = np.meshgrid(o, o, indexing="ij")
        self.offsets = np.stack([ox.ravel(), oy.ravel()], axis=-1)  # (m*m, 2)
        # per cell, sum over its pixels of (N (x) q)(N (x) q)^T as (cell, node, comp, node, comp)
        H0 = np.empty((lattice.n_cells, 4, 4, 4, 4))
        for start in range(0, lattice.n_cells, 256):
            q = self.q[start : start + 256]
            A = (self.N[None, :, :, None] * q[:, :, None, :]).reshape(len(q), -1, 16)
            H0[start : start + 256] = (np.swapaxes(A, 1, 2) @ A).reshape(-1, 4, 4, 4, 4)
        self.H0 = H0
        # texture of each cell: mean squared gradient (gray levels^2 / px^2)
        self.texture = np.mean(self.q[..., 0] ** 2 + self.q[..., 1] ** 2, axis=1)
        self.variance = self.f.var(axis=1)

    def prepare(self, frame, mask: np.ndarray | None = None):
        """The frame (a :class:`Frame`, which keeps the spline coefficients of the blurred
        frame, or of its parts, for every solver fitted to it), and its highlight mask
        grown by the blur (or None)."""
        frame = Frame.of(frame)
        if mask is None or not mask.any():
            return frame, None
        return frame, _grown(mask, self.blur)


class LatticeSolver:
    """Regularized global DIC on one reference frame (see the module docstring).

    Parameters
    ----------
    reference : (H, W) float
    points : (N, 2)
        The points whose motion is wanted (the lattice covers them).
    spacing : int
        Lattice spacing ``h`` in pixels (a multiple of 4).
    curvature : float
        Expected curvature of the displacement field (1/px): the prior scale of
        its second derivatives. Smaller is smoother.
    noise : float or None
        Image noise (gray levels); measured on the reference when None.
    blobs : (H, W) bool or None
        The reference's bright blobs (:func:`bright_blobs`); found when None.
    """

    def __init__(
        self,
        reference: np.ndarray,
        points: np.ndarray,
        *,
        spacing: int = 16,
        curvature: float = 2e-3,
        noise: float | None = None,
        blobs: np.ndarray | None = None,
        levels: tuple[tuple[float, int], ...] = ((3.0, 4), (1.2, 2), (0.0, 1)),
        max_iterations: int = 25,
        tolerance: float = 1e-2,
    ) -> None:
        reference = np.asarray(reference, dtype=np.float64)
        self.shape = reference.shape
        self.lattice = Lattice.around(np.asarray(points, float), self.shape, spacing)
        self.cells = self.lattice.cell_nodes()
        self.origins = self.lattice.cell_origins()
        self.noise = max(noise_sigma(reference) if noise is None else float(noise), 0.5)
        self.reference_blobs = bright_blobs(reference, self.noise) if blobs is None else blobs
        lat = self.lattice
        self.mean = float(
            reference[lat.y0 : lat.y0 + lat.ny * lat.h, lat.x0 : lat.x0 + lat.nx * lat.h].mean()
        )
        self.levels = [_Level(lat, reference, b, s, self.mean) for b, s in levels]
        self.reference_highlights = self.frame_highlights = None
        self._hidden_reference = None  # per level, the reference's highlight pixels (blocks)
        self._static = np.zeros(self.shape, bool)
        self.max_iterations, self.tolerance = max_iterations, tolerance
        n = self.lattice.n_nodes
        tau = curvature * spacing**2  # prior scale of a second difference of u between nodes
        sigma2 = 2 * self.noise**2  # variance of f - g
        B = self.lattice.bending()
        # gain and offset vary slowly: light, not texture
        weights = np.array([sigma2 / tau**2, sigma2 / tau**2, sigma2 / 1e-3**2, sigma2 / 0.3**2])
        ridge = np.array([sigma2 / 100.0**2, sigma2 / 100.0**2, sigma2 / 0.5**2, sigma2 / 50.0**2])
        self.prior = (
            sparse.kron(B, sparse.diags(weights)) + sparse.diags(np.tile(ridge, n))
        ).tocsr()
        self.ridge = ridge
        self.sigma2 = sigma2
        # node-major unknowns: 4 per node (u, v, a, b); COO pattern of the cell blocks
        dof = (self.cells[:, :, None] * 4 + np.arange(4)).reshape(-1, 16)
        self._rows = np.repeat(dof, 16, axis=1).ravel()
        self._cols = np.tile(dof, (1, 16)).ravel()
        self._dof = dof
        # upper band storage (LAPACK): band[bw + i - j, j] = A[i, j] for i <= j
        prior = self.prior.tocoo()
        bw = int(max(np.max(self._cols - self._rows), np.max(prior.col - prior.row)))
        self._upper = (self._rows <= self._cols).reshape(-1, 256)[0]
        rows, cols = (
            self._rows.reshape(-1, 256)[:, self._upper],
            self._cols.reshape(-1, 256)[:, self._upper],
        )
        self._band_index = ((bw + rows - cols) * (4 * n) + cols).ravel()
        keep = prior.row <= prior.col
        self._prior_band = np.bincount(
            (bw + prior.row[keep] - prior.col[keep]) * (4 * n) + prior.col[keep],
            weights=prior.data[keep],
            minlength=(bw + 1) * 4 * n,
        ).reshape(bw + 1, 4 * n)
        self.state = np.zeros((n, 4))  # u, v, a, b per node
        self.weights = np.ones(self.lattice.n_cells)
        self.residual = np.zeros(self.lattice.n_cells)  # mean squared residual per cell
        self.outside = np.zeros(self.lattice.n_cells, bool)
        self._factors: dict = {}
        self._diagonals: dict = {}
        self._anchor = self.state.copy()
        self.fitted_level = len(self.levels) - 1  # of the last fit: 0 is the coarsest

    # ------------------------------------------------------------------ one frame

    def _transforms(self, state: np.ndarray) -> np.ndarray:
        """Per cell, ``T`` (4 x 4) mapping (f_x, f_y, f, 1) to the current Jacobian."""
        h = self.lattice.h
        U = state[self.cells]  # (cells, 4 corners, 4)
        dudx = 0.5 * ((U[:, 1, :2] - U[:, 0, :2]) + (U[:, 3, :2] - U[:, 2, :2])) / h
        dudy = 0.5 * ((U[:, 2, :2] - U[:, 0, :2]) + (U[:, 3, :2] - U[:, 1, :2])) / h
        F = np.eye(2) + np.stack([dudx, dudy], axis=-1)  # F[i, j] = d x_i / d X_j
        det = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
        bad = ~(det > 0.05)
        F[bad] = np.eye(2)
        Finv_T = np.linalg.inv(F).transpose(0, 2, 1)
        a = U[:, :, 2].mean(axis=1)
        b = U[:, :, 3].mean(axis=1)
        gain = 1.0 / np.maximum(1.0 + a, 0.05)
        T = np.zeros((len(U), 4, 4))
        T[:, :2, :2] = Finv_T
        T[:, 2, 2] = gain
        T[:, 2, 3] = -b * gain
        T[:, 3, 3] = 1.0
        return T

    def _residual(self, k: int, coefficients, state: np.ndarray):
        """Per sampled pixel of every cell, the residual, whether it left the frame, and
        per cell the share of its pixels under a highlight (None without highlights);
        computed by :func:`strain2d.trackers._icgn_kernel.lattice_residual`."""
        from strain2d.trackers._icgn_kernel import lattice_residual

        level = self.levels[k]
        frame, mask = coefficients
        coefficients, corner = frame.part(level.blur, self._sampled(state))
        with deferred_interrupt():  # Ctrl-C inside the kernel would surface as SystemError
            r, out, hidden = lattice_residual(
                coefficients,
                np.ascontiguousarray(state, dtype=np.float64),
                self.cells,
                self.origins,
                level.offsets,
                level.N,
                level.f,
                self.mean,
                _NO_MASK if mask is None else mask,
                corner,
                np.array(self.shape, np.int64),
            )
        if self._hidden_reference is not None:  # a highlight on the reference
            hidden |= self._hidden_reference[k]
        r[hidden] = 0.0
        masked = hidden.mean(axis=1) if hidden.any() else None
        return r, out.mean(axis=1) > 0.25, masked

    def _sampled(self, state: np.ndarray) -> tuple[float, float, float, float] | None:
        """The box (x0, y0, x1, y1) that holds every position the residual samples with the
        node states ``state`` (the lattice's box, moved by the nodes' least and largest
        displacement: a cell's pixels move by a mix of its corners'); None when no node's
        displacement is finite."""
        u = state[:, :2]
        lo, hi = u.min(axis=0), u.max(axis=0)
        if not (np.isfinite(lo).all() and np.isfinite(hi).all()):  # some node gone wrong
            finite = np.isfinite(u).all(axis=1)
            if not finite.any():
                return None
            lo, hi = u[finite].min(axis=0), u[finite].max(axis=0)
        lat = self.lattice
        return (lat.x0 + float(lo[0]), lat.y0 + float(lo[1]),
                lat.x0 + lat.nx * lat.h + float(hi[0]),
                lat.y0 + lat.ny * lat.h + float(hi[1]))  # fmt: skip

    def _factorize(self, k: int, level: _Level, T: np.ndarray, w: np.ndarray):
        """Banded Cholesky of ``H + prior`` at level k (the lattice's node order keeps the
        band narrow: 8 lattice columns and some)."""
        Hc = np.einsum("ckK,ciKjL,clL->cikjl", T, level.H0, T, optimize=True)
        # one pixel of every stride^2 is used: scaled to the full-resolution information
        Hc *= w[:, None, None, None, None] * float(level.stride**2)
        band = self._prior_band + np.bincount(
            self._band_index,
            weights=Hc.reshape(len(Hc), -1)[:, self._upper].ravel(),
            minlength=self._prior_band.size,
        ).reshape(self._prior_band.shape)
        band[-1] += self._leash(k)
        self._diagonals[k] = band[-1].copy()  # the normal matrix's diagonal (_settle)
        try:
            factor = linalg.cholesky_banded(band, lower=False, check_finite=False)
        except linalg.LinAlgError:
            factor = None
        self._factors[k] = (factor, T.copy(), w.copy())
        return factor

    def _settle(self, k: int, tolerance: float) -> np.ndarray:
        """Per node, the step (px) below which its fit at level ``k`` has settled: the
        level's ``tolerance``, or where larger the node's own noise-limited standard
        deviation ``sqrt(sigma^2 / H_ii)`` (of u and v, from the diagonal of the last
        normal matrix factorized: a lower bound of its posterior one). A step smaller than
        that moves the node within its noise: more iterations would not place it better,
        and on weak texture, where the frame's noise makes the objective rough at that
        scale, they wander there instead of converging."""
        n = self.lattice.n_nodes
        diagonal = self._diagonals.get(k)
        if diagonal is None:
            return np.full(n, tolerance)
        d = diagonal.reshape(n, 4)
        with np.errstate(divide="ignore"):
            var = 0.5 * (1.0 / d[:, 0] + 1.0 / d[:, 1])
        return np.maximum(tolerance, np.sqrt(self.sigma2 * np.nan_to_num(var, posinf=0.0)))

    def _leash(self, k: int) -> np.ndarray:
        """Per unknown, the weight that holds level ``k``'s displacement near where the
        coarser level left it (none at the coarsest level, which starts from a guess)."""
        if k == 0:
            return np.zeros(4 * self.lattice.n_nodes)
        scale = np.array([LEASH[0], LEASH[0], LEASH[1], LEASH[2]])
        return np.tile(self.sigma2 / scale**2, self.lattice.n_nodes)

    def _solve(self, k: int, rhs: np.ndarray) -> np.ndarray:
        factor = self._factors[k][0]
        if factor is None:
            return np.full(rhs.shape, np.nan)
        return linalg.cho_solve_banded((factor, False), rhs, check_finite=False)

    def _stale(self, k: int, T: np.ndarray, w: np.ndarray) -> bool:
        """Whether level k's Hessian was factorized for a deformation or weights unlike now."""
        if self._factors.get(k) is None:
            return True
        _, T0, w0 = self._factors[k]
        # the deformation and gain part (the offset column follows noise in flat cells)
        change = np.abs(T[:, :3, :3] - T0[:, :3, :3]).max(axis=(1, 2))
        # most cells, not the worst: margin cells of a blurred level are noisy
        return _percentile(change, 90) > 0.1 or np.mean(np.abs(w - w0) > 0.5) > 0.02

    def _solve_level(
        self, k: int, coefficients: np.ndarray, state: np.ndarray, tolerance: float
    ) -> tuple[np.ndarray, bool]:
        """Gauss-Newton at level k; the Hessian is refactorized only when stale."""
        from strain2d.trackers._icgn_kernel import lattice_gradient

        level = self.levels[k]
        n = self.lattice.n_nodes
        converged = False
        ridge = np.tile(self.ridge, n) * self._anchor.ravel()
        leash, start = self._leash(k), state.ravel().copy()
        best, since = np.inf, 0  # the smallest step so far, and the iterations since
        settle = None  # per node, the step below which it has settled (:meth:`_settle`)
        for _ in range(self.max_iterations):
            r, outside, masked = self._residual(k, coefficients, state)
            ms = np.mean(r**2, axis=1)
            w = self._robust_weights(ms, level, outside)
            if masked is not None and np.mean(masked > HIDDEN_CELL) < HIDDEN_CELLS:
                w[masked > HIDDEN_CELL] = 0.0  # cells mostly under a highlight do not count
            T = self._transforms(state)
            if self._stale(k, T, w):
                self._factorize(k, level, T, w)
                settle = None  # from the matrix just factorized
            if settle is None:
                settle = self._settle(k, tolerance)
            g0 = lattice_gradient(level.N, r, w, level.q, T, float(level.stride**2))
            rhs = np.bincount(self._dof.ravel(), weights=g0.ravel(), minlength=4 * n)
            rhs -= self.prior @ state.ravel() - ridge + leash * (state.ravel() - start)
            step = self._solve(k, rhs).reshape(n, 4)
            if not np.isfinite(step).all():
                return state, False
            # a trust region: no node moves further in one step than the level's blur
            # lets the linearization hold (weakly held margin nodes would swing)
            move = np.hypot(step[:, 0], step[:, 1])
            limit = 2.0 + 2.0 * level.blur
            step *= np.minimum(1.0, limit / np.maximum(move, 1e-12))[:, None]
            state = state + step
            cut = move.max() > limit  # a step the trust region cut has not settled
            move = np.minimum(move, limit) / settle
            size = _percentile(move, 99)
            if size < 1 and move.max() < 10 and not cut:
                converged = True
                break
            # stalled: the steps have not shrunk for a while (a few nodes cycling between
            # robust weights, or drifting where nothing holds them): more iterations of the
            # same would not converge either
            best, since = (size, 0) if size < 0.9 * best else (best, since + 1)
            if since >= _STALLED:
                break
        self.weights, self.outside, self.residual = w, outside, ms
        self.fitted_level = k
        return state, converged

    def _robust_weights(self, ms: np.ndarray, level: _Level, outside: np.ndarray) -> np.ndarray:
        """Cells whose residual is far above what noise and texture explain stop counting."""
        expected = self.sigma2 + 0.02 * level.texture  # noise, plus sub-pixel model error
        z = ms / expected
        typical = np.median(z[~outside]) if (~outside).any() else 1.0
        z = z / max(typical, 1.0)
        w = np.clip((16.0 - z) / 12.0, 0.0, 1.0)  # 1 below 4x, 0 above 16x
        w[outside] = 0.0
        return w

    def coarse(self, frame: np.ndarray, guess: np.ndarray) -> tuple[np.ndarray, float]:
        """Fit the coarsest level from ``guess``: the node states and the median cell
        residual (a cost to compare initial guesses by)."""
        self._anchor = np.array(guess, dtype=float)
        level = self.levels[0]
        frame = Frame.of(frame)
        if self.reference_blobs.any():
            self.reference_highlights, self.frame_highlights = static_highlights(
                self.reference_blobs,
                frame.blobs(self.noise, blob_window(self.reference_blobs, self._motion)),
                self._motion,
            )
        else:  # nothing on the reference could be a highlight
            self.reference_highlights = self.frame_highlights = np.zeros(self.shape, bool)
        # once found to stay put, a highlight stays one (its blob may blur or fade later)
        self._static |= self.reference_highlights
        self.reference_highlights = self._static.copy()
        if self.reference_highlights.any():
            self._hidden_reference = [
                lv.blocks(_grown(self.reference_highlights, lv.blur)) for lv in self.levels
            ]
        else:
            self._hidden_reference = self.frame_highlights = None
        state, _ = self._solve_level(
            0, level.prepare(frame, self.frame_highlights), self._anchor.copy(), 0.05
        )
        inside = ~self.outside
        cost = float(np.median(self.residual[inside])) if inside.any() else np.inf
        return state, cost

    def refine(self, frame: np.ndarray, state: np.ndarray, *, levels: int | None = None) -> bool:
        """Fit the finer levels from the coarse ``state``, up to ``levels`` levels in all
        (all of them when None; 1 keeps the coarse fit); True if the last level fitted
        converged (or no finer level was asked for)."""
        frame = Frame.of(frame)
        converged = True
        stop = len(self.levels) if levels is None else min(max(levels, 1), len(self.levels))
        for k in range(1, stop):
            last = k == stop - 1
            coefficients = self.levels[k].prepare(frame, self.frame_highlights)
            state, converged = self._solve_level(
                k, coefficients, state, self.tolerance if last else 0.05
            )
        self.state = state
        return converged

    # ------------------------------------------------------------------ results at points

    def displacement(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Displacement ``(N, 2)`` and its gradient ``(N, 2, 2)`` at reference ``points``."""
        idx, w, dw = self.lattice.interpolation(points)
        U = self.state[idx, :2]  # (N, 4, 2)
        u = np.einsum("ni,nik->nk", w, U)
        grad = np.einsum("nik,nil->nkl", U, dw)  # d u_k / d X_l
        return u, grad

    def cell_of(self, points: np.ndarray) -> np.ndarray:
        return self.lattice.cell_of(points)

    def seen(self, points: np.ndarray) -> np.ndarray:
        """Whether the cell under each point counted in the fit (not occluded, in the frame)."""
        c = self.cell_of(points)
        return (self.weights[c] > 0.5) & ~self.outside[c]

    def _motion(self, points: np.ndarray) -> np.ndarray:
        """Displacement at reference points of the best affine fit to this frame's starting
        guess: how the tissue around moves, even where a highlight holds the field."""
        nodes = self.lattice.nodes()
        A = np.column_stack([nodes, np.ones(len(nodes))])
        M, *_ = np.linalg.lstsq(A, self._anchor[:, :2], rcond=None)
        return np.column_stack([points, np.ones(len(points))]) @ M

    def cell_zncc(self, points: np.ndarray) -> np.ndarray:
        """ZNCC-like agreement ``1 - residual / (2 var f)`` of the cell under each point."""
        c = self.cell_of(points)
        return 1.0 - self.residual[c] / np.maximum(2 * self.levels[-1].variance[c], 1e-9)

    def uncertainty(self, points: np.ndarray) -> np.ndarray:
        """Standard deviation (px, per coordinate) of the displacement at ``points``.

        The posterior covariance ``s^2 (H + lambda D'D)^-1`` of the last fit,
        with ``s^2`` the residual variance of the cell under each point (at
        least the noise's), interpolated to the point.
        """
        level = self.fitted_level
        if self._factors.get(level) is None or len(points) == 0:
            return np.full(len(points), np.nan)
        idx, w, _ = self.lattice.interpolation(points)
        n = 4 * self.lattice.n_nodes
        out = np.empty(len(points))
        s2 = np.maximum(self.residual[self.cell_of(points)], self.sigma2)
        for start in range(0, len(points), 128):
            sl = slice(start, start + 128)
            k = len(idx[sl])
            E = np.zeros((n, 2 * k))
            cols = np.arange(k)
            for c in range(4):
                E[idx[sl, c] * 4, cols] += w[sl, c]
                E[idx[sl, c] * 4 + 1, k + cols] += w[sl, c]
            Z = self._solve(level, E)
            var = np.einsum("nk,nk->k", E, Z)
            out[sl] = np.sqrt(0.5 * (var[:k] + var[k:]) * s2[sl])
        return out
