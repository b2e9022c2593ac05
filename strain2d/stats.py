"""Statistics of one run: the contraction endpoint and node-level paired tests.

:func:`contraction_endpoint` finds the frame where the tissue stops
deforming, which the source paper chose by eye.  :func:`paired_node_tests`
compares two strain components over the nodes of one run (the paper's paired
t-test between nodal Exx and Eyy), adds the Wilcoxon signed-rank test, an
effect size with a bootstrap confidence interval, and Moran's I of the
differences, because neighbouring nodes share triangles and are not
independent samples: node-level p-values overstate the evidence when the
differences are spatially correlated.

References
----------
* Student (W. S. Gosset), The probable error of a mean, Biometrika 6 (1908) 1-25.
* F. Wilcoxon, Individual comparisons by ranking methods, Biometrics Bulletin
  1 (1945) 80-83, doi:10.2307/3001968.
* J. Cohen, Statistical Power Analysis for the Behavioral Sciences, 2nd ed.,
  1988 (d_z for paired samples).
* B. Efron, R. Tibshirani, An Introduction to the Bootstrap, Chapman & Hall
  1993 (percentile intervals).
* P. A. P. Moran, Notes on continuous stochastic phenomena, Biometrika 37
  (1950) 17-23, doi:10.2307/2332142.
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from strain2d.errors import InputError

__all__ = ["contraction_endpoint", "morans_i", "paired_node_tests"]


def contraction_endpoint(
    curve: np.ndarray,
    *,
    times: np.ndarray | None = None,
    rate_tolerance: float | None = None,
    relative_tolerance: float = 0.05,
) -> int:
    """The first frame after which the strain stops changing.

    The strain rate into each frame is the backward difference of ``curve``
    (one or several components, e.g. mean nodal Exx and Eyy) over
    ``times``, its magnitude the largest over the components.  The endpoint
    is the frame after which the rate stays below the tolerance up to the
    last frame: ``rate_tolerance`` (strain per time unit), or by default
    ``relative_tolerance`` times the largest rate seen.

    Parameters
    ----------
    curve : (T,) or (T, K) float
    times : (T,) float, optional
        Frame times (default 0, 1, 2, ...).

    Returns
    -------
    int
        The endpoint frame; the last frame when the strain is still changing
        there (the contraction had not finished when the video ended).
        Frames where a component is NaN (lost) count as still changing.

    Examples
    --------
    >>> t = np.arange(31.0)
    >>> curve = -0.3 * np.minimum(t, 20) / 20  # contracts until frame 20, then holds
    >>> contraction_endpoint(curve)
    20
    """
    c = np.asarray(curve, np.float64)
    if c.ndim == 1:
        c = c[:, None]
    T = c.shape[0]
    if c.ndim != 2 or T < 3:
        raise InputError(f"the strain curve needs at least 3 frames, got shape {np.shape(curve)}")
    t = np.arange(T, dtype=np.float64) if times is None else np.asarray(times, np.float64)
    if t.shape != (T,) or not np.all(np.diff(t) > 0):
        raise InputError("times must increase, one per frame")
    c = np.where(np.isfinite(c), c, np.nan)
    # rate of the change arriving at each frame (backward differences)
    rate = np.zeros_like(c)
    rate[1:] = np.abs(np.diff(c, axis=0)) / np.diff(t)[:, None]
    known = np.isfinite(rate)
    # a rate that cannot be computed (a lost value next to the frame) is not
    # evidence that the tissue stopped: count it as still moving
    speed = np.where(known.all(axis=1), np.where(known, rate, 0.0).max(axis=1), np.inf)
    speed[0] = 0.0
    finite = speed[np.isfinite(speed)]
    top = float(finite.max()) if finite.size else 0.0
    tol = relative_tolerance * top if rate_tolerance is None else float(rate_tolerance)
    if top == 0.0 and rate_tolerance is None:
        tol = 0.0
    above = np.flatnonzero(speed > tol)
    # the last frame the strain was still moving into; after it, it stays put
    return int(above[-1]) if above.size else 0


def morans_i(
    values: np.ndarray, positions: np.ndarray, *, k: int = 4, permutations: int = 999, rng=0
) -> tuple[float, float]:
    """Moran's I of ``values`` at ``positions`` with k-nearest-neighbour weights.

    Returns ``(I, p)``: I near its expectation ``-1/(n-1)`` for spatially
    independent values, towards 1 when neighbours are alike; ``p`` is the
    one-sided permutation p-value for positive autocorrelation.
    """
    from scipy.spatial import cKDTree

    v = np.asarray(values, np.float64)
    pos = np.asarray(positions, np.float64)
    ok = np.isfinite(v) & np.isfinite(pos).all(axis=1)
    v, pos = v[ok], pos[ok]
    n = v.size
    if n < k + 2:
        return float("nan"), float("nan")
    _, nb = cKDTree(pos).query(pos, k + 1)
    nb = nb[:, 1:]
    z = v - v.mean()
    denom = float(z @ z)
    if denom == 0:
        return float("nan"), float("nan")

    def stat(zz: np.ndarray) -> float:
        return float(n / (n * k) * np.sum(zz[:, None] * zz[nb]) / denom)

    observed = stat(z)
    gen = np.random.default_rng(rng)
    count = sum(stat(gen.permutation(z)) >= observed for _ in range(permutations))
    return observed, (count + 1) / (permutations + 1)


#: relative spread of paired differences below which they count as identical
_ROUNDOFF = 1e-12


def paired_node_tests(
    a: np.ndarray,
    b: np.ndarray,
    *,
    positions: np.ndarray | None = None,
    n_boot: int = 2000,
    confidence: float = 0.95,
    rng=0,
) -> dict:
    """Node-level paired comparison of two strain components (e.g. Exx and Eyy).

    Parameters
    ----------
    a, b : (N,) float
        The two components at the same nodes (NaN pairs are left out).
    positions : (N, 2) or (N, 3) float, optional
        Node positions, for Moran's I of the differences.
    n_boot : int, keyword-only
        Resamples of the nodes for the percentile bootstrap intervals
        (:func:`scipy.stats.bootstrap`).

    Returns
    -------
    dict
        ``n``, ``mean_difference`` (a - b) with its bootstrap interval,
        ``t``, ``t_p`` (paired t-test), ``wilcoxon_p``, ``cohens_dz`` with its
        bootstrap interval, ``morans_i`` and ``morans_p`` (when positions are
        given), and ``note``: what the node-level tests assume.
    """
    from scipy import stats

    x = np.asarray(a, np.float64).ravel()
    y = np.asarray(b, np.float64).ravel()
    if x.shape != y.shape:
        raise InputError(f"the two components differ in length: {x.size} and {y.size}")
    ok = np.isfinite(x) & np.isfinite(y)
    d = x[ok] - y[ok]
    n = int(d.size)
    if n < 3:
        raise InputError(f"a paired test needs at least 3 nodes with both values, got {n}")
    sd = float(d.std(ddof=1))
    scale = float(max(np.abs(x[ok]).max(), np.abs(y[ok]).max()))
    # differences that do not vary beyond round-off have no t statistic or effect size
    spread = sd > _ROUNDOFF * scale
    if not spread:
        sd = 0.0
    t = stats.ttest_rel(x[ok], y[ok]) if spread else None
    nonzero = d[d != 0]
    w_p = float(stats.wilcoxon(nonzero).pvalue) if nonzero.size >= 1 else 1.0

    def mean_and_dz(sample: np.ndarray, axis: int = -1) -> np.ndarray:
        # d_z is undefined (NaN) for a resample without spread beyond round-off
        mean = sample.mean(axis=axis)
        sd = sample.std(axis=axis, ddof=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.stack([mean, np.where(sd > _ROUNDOFF * scale, mean / sd, np.nan)])

    with warnings.catch_warnings():
        # scipy warns when an interval comes out NaN: the d_z interval handled below
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        boot = stats.bootstrap(
            (d,),
            mean_and_dz,
            n_resamples=n_boot,
            confidence_level=confidence,
            method="percentile",
            rng=np.random.default_rng(rng),
        )
    (mean_lo, dz_lo), (mean_hi, dz_hi) = boot.confidence_interval
    dz_boot = boot.bootstrap_distribution[1]
    has_dz = np.isfinite(dz_boot)
    if has_dz.any() and not has_dz.all():
        # a handful of nodes: some resamples repeat one value; take the interval over the rest
        tail = (1 - confidence) / 2
        dz_lo, dz_hi = np.nanquantile(dz_boot, [tail, 1 - tail])
    result = {
        "n": n,
        "mean_difference": float(d.mean()),
        "mean_difference_ci": [float(mean_lo), float(mean_hi)],
        "t": float(t.statistic) if sd > 0 else float("nan"),
        "t_p": float(t.pvalue) if sd > 0 else float("nan"),
        "wilcoxon_p": w_p,
        "cohens_dz": float(d.mean() / sd) if sd > 0 else float("nan"),
        "cohens_dz_ci": [float(dz_lo), float(dz_hi)],
        "confidence": confidence,
        "note": (
            "node-level tests: the nodes of one specimen are treated as independent samples, "
            "which they are not (neighbours share triangles and tissue); p-values describe "
            "this field, not a population of specimens"
        ),
    }
    if positions is not None:
        pos = np.asarray(positions, np.float64)[ok]
        i, p = morans_i(d, pos, rng=rng)
        result["morans_i"] = i
        result["morans_p"] = p
        if math.isfinite(p) and p < 0.05:
            result["note"] += (
                f"; the differences are spatially correlated (Moran's I {i:.2f}, p {p:.3f}), "
                "so the effective number of independent nodes is smaller than n"
            )
    return result
