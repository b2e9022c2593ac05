"""How tracks measure up: against exact truth, against another tracker, against scatter.

The tests and ``bench/bench_default_tracker.py`` judge trackers with these
functions, so both agree on what "kept", "within 10 % of dic" and "sigma
matches the scatter" mean. They take plain arrays (positions ``(T, N, 2)``
in px, ``visible (T, N)`` bool, ``uncertainty (T, N)`` px: 1 sigma per
coordinate) and import nothing of the trackers.

* :func:`score_tracks`: points kept and tracking error against the truth.
* :func:`compare_to_dic`: the verdict of the randomised variants.
* :func:`sigma_against_scatter`: reported sigma over measured error, per
  point (still videos: the error is the deviation from the reference; real
  videos: the disagreement with another tracker).
* :func:`rigid_score`: the turning pieces: error of the points on texture,
  and how many blank points were reported as measured.

Errors are Euclidean distances (px) unless a name says per coordinate.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "Comparison",
    "RigidScore",
    "Score",
    "SigmaCheck",
    "compare_to_dic",
    "in_view",
    "rigid_score",
    "score_tracks",
    "sigma_against_scatter",
]


def in_view(
    true_positions: np.ndarray, shape: tuple[int, int], *, margin: float = 0.0
) -> np.ndarray:
    """Whether each true position lies in the frame, ``margin`` px inside its edges.

    Parameters
    ----------
    true_positions : (T, N, 2) float
    shape : (H, W)
    margin : float, keyword-only

    Returns
    -------
    (T, N) bool
    """
    h, w = shape
    x, y = true_positions[..., 0], true_positions[..., 1]
    return (x >= margin) & (x <= w - 1 - margin) & (y >= margin) & (y <= h - 1 - margin)


@dataclass(frozen=True)
class Score:
    """Tracks against the truth.

    Attributes
    ----------
    in_view : int
        Points whose true position stays in the frame on every frame.
    kept : int
        Of those, the points visible on every frame.
    rmse : float
        Final-frame RMSE (px) over the points kept (NaN if none).
    worst : float
        Largest final-frame error (px) among the points kept.
    rmse_all : float
        RMSE (px) over every frame after the reference and every point kept.
    kept_points : (N,) bool or None
        Which points were kept (to score another tracker on the same points).
    """

    in_view: int
    kept: int
    rmse: float
    worst: float
    rmse_all: float
    kept_points: np.ndarray | None = field(default=None, compare=False, repr=False)

    @property
    def lost(self) -> int:
        """Points in view that were not kept."""
        return self.in_view - self.kept

    @property
    def keeps_all(self) -> bool:
        return self.kept == self.in_view


def score_tracks(
    positions: np.ndarray,
    visible: np.ndarray,
    true_positions: np.ndarray,
    *,
    shape: tuple[int, int] | None = None,
    margin: float = 0.0,
    among: np.ndarray | None = None,
) -> Score:
    """Points kept and tracking error against the truth.

    Parameters
    ----------
    positions : (T, N, 2) float
    visible : (T, N) bool
    true_positions : (T, N, 2) float
    shape : (H, W), keyword-only
        The frame; None counts every point as in view.
    margin : float, keyword-only
        See :func:`in_view`.
    among : (N,) bool, keyword-only
        Score these points alone (e.g. another tracker's ``kept_points``).
    """
    positions, true_positions = np.asarray(positions, float), np.asarray(true_positions, float)
    visible = np.asarray(visible, bool) & np.all(np.isfinite(positions), axis=-1)
    if shape is None:
        view = np.ones(visible.shape[1], bool)
    else:
        view = in_view(true_positions, shape, margin=margin).all(axis=0)
    if among is not None:
        view = view & np.asarray(among, bool)
    kept = view & visible.all(axis=0)
    error = np.linalg.norm(positions - true_positions, axis=-1)[:, kept]
    final = error[-1]
    return Score(
        in_view=int(view.sum()),
        kept=int(kept.sum()),
        rmse=float(np.sqrt(np.mean(final**2))) if final.size else float("nan"),
        worst=float(final.max()) if final.size else float("nan"),
        rmse_all=float(np.sqrt(np.mean(error[1:] ** 2))) if error[1:].size else float("nan"),
        kept_points=kept,
    )


@dataclass(frozen=True)
class Comparison:
    """A tracker's score against dic's on one video.

    Attributes
    ----------
    verdict : {"within", "worse", "keeps where dic loses", "loses points"}
    passed : bool
        ``within`` and ``keeps where dic loses`` pass.
    ratio : float
        The tracker's final-frame RMSE over dic's (NaN if either is).
    """

    verdict: str
    passed: bool
    ratio: float


def compare_to_dic(
    score: Score, dic: Score, *, tolerance: float = 0.10, atol_px: float = 0.0
) -> Comparison:
    """Whether a tracker does as well as dic: the randomised variants' rule.

    The tracker must keep every point in view. Where dic keeps every point
    too, its final-frame RMSE must be within ``tolerance`` of dic's or
    better: ``rmse <= (1 + tolerance) rmse_dic + atol_px``. Where dic loses
    points, keeping them is enough.

    Parameters
    ----------
    score, dic : Score
        Of the same video and points (:func:`score_tracks`).
    tolerance : float, keyword-only
    atol_px : float, keyword-only
        Allowance in px on top of the relative one (0: none).
    """
    ratio = score.rmse / dic.rmse if dic.rmse > 0 else float("nan")
    if not score.keeps_all:
        return Comparison("loses points", False, ratio)
    if not dic.keeps_all:
        return Comparison("keeps where dic loses", True, ratio)
    if score.rmse <= (1 + tolerance) * dic.rmse + atol_px:
        return Comparison("within", True, ratio)
    return Comparison("worse", False, ratio)


@dataclass(frozen=True)
class SigmaCheck:
    """Reported sigma against measured error, per point.

    Attributes
    ----------
    sigma : (N,) float
        RMS of the reported uncertainty (px, per coordinate) over the frames used.
    scatter : (N,) float
        RMS of the measured error (px, per coordinate) over the same frames.
    samples : (N,) int
        Frames used per point (NaN sigma and scatter below ``min_frames``).

    Notes
    -----
    On a still video every frame is matched against the same noisy reference,
    so a point's errors share the reference's noise and its scatter over 20
    frames is itself uncertain: for a tracker whose sigma is exactly right,
    ``pooled_ratio`` is 1.00, ``median_ratio`` 1.08 and ``within(1.5)`` 0.92
    (simulated: 21 frames, Gaussian noise).
    """

    sigma: np.ndarray
    scatter: np.ndarray
    samples: np.ndarray

    @property
    def ratio(self) -> np.ndarray:
        """``sigma / scatter`` per point: 1 is calibrated, above 1 too cautious."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.sigma / self.scatter

    @property
    def median_ratio(self) -> float:
        r = self.ratio[np.isfinite(self.ratio)]
        return float(np.median(r)) if r.size else float("nan")

    @property
    def pooled_ratio(self) -> float:
        """RMS sigma over RMS scatter of all the points together."""
        ok = np.isfinite(self.sigma) & np.isfinite(self.scatter)
        w = self.samples[ok]
        if not w.sum():
            return float("nan")
        s2 = np.sum(w * self.sigma[ok] ** 2) / w.sum()
        d2 = np.sum(w * self.scatter[ok] ** 2) / w.sum()
        return float(np.sqrt(s2 / d2)) if d2 > 0 else float("nan")

    def within(self, factor: float = 1.5) -> float:
        """Fraction of the points whose ratio lies within ``[1 / factor, factor]``."""
        r = self.ratio[np.isfinite(self.ratio)]
        return float(np.mean((r <= factor) & (r >= 1 / factor))) if r.size else float("nan")


def sigma_against_scatter(
    positions: np.ndarray,
    visible: np.ndarray,
    uncertainty: np.ndarray,
    reference_positions: np.ndarray,
    *,
    reference_visible: np.ndarray | None = None,
    reference_uncertainty: np.ndarray | None = None,
    min_frames: int = 3,
) -> SigmaCheck:
    """A tracker's reported sigma against the error it can be seen to make.

    The error of point ``i`` on frame ``k >= 1`` is ``positions - reference_positions``
    per coordinate: on a still video the reference is the true, unmoving
    position (then the scatter is the tracking error itself, including the
    reference frame's own noise that every frame shares); on a real video
    it is another tracker's positions (the disagreement), whose own sigma,
    when known, is added in quadrature to the expected spread:
    ``sqrt(sigma^2 + sigma_ref^2)``.

    Parameters
    ----------
    positions : (T, N, 2) float
    visible : (T, N) bool
    uncertainty : (T, N) float
        The tracker's sigma per coordinate (px); NaN where it has none.
    reference_positions : (T, N, 2) or (N, 2) float
        Truth (a still video: the reference grid) or the other tracker.
    reference_visible, reference_uncertainty : (T, N), keyword-only
        The other tracker's visibility and sigma, if any.
    min_frames : int, keyword-only
        Fewest frames a point needs to be compared.
    """
    positions = np.asarray(positions, float)
    reference = np.broadcast_to(np.asarray(reference_positions, float), positions.shape)
    sigma2 = np.asarray(uncertainty, float) ** 2
    use = np.asarray(visible, bool) & np.isfinite(sigma2)
    if reference_visible is not None:
        use &= np.asarray(reference_visible, bool)
    if reference_uncertainty is not None:
        extra = np.asarray(reference_uncertainty, float) ** 2
        use &= np.isfinite(extra)
        sigma2 = sigma2 + np.where(np.isfinite(extra), extra, 0.0)
    d2 = np.sum((positions - reference) ** 2, axis=-1) / 2  # per coordinate
    use &= np.isfinite(d2)
    use[0] = False  # the reference frame measures nothing
    n = use.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        sigma = np.sqrt(np.where(use, sigma2, 0.0).sum(axis=0) / n)
        scatter = np.sqrt(np.where(use, d2, 0.0).sum(axis=0) / n)
    few = n < min_frames
    sigma[few], scatter[few] = np.nan, np.nan
    return SigmaCheck(sigma, scatter, n)


@dataclass(frozen=True)
class RigidScore:
    """Tracks of the turning pieces against the rigid motion.

    Attributes
    ----------
    textured_rms : float
        RMS error (px) over the points on texture and the frames after the
        reference where they are visible.
    textured_kept, textured : int
        Points on texture visible on every frame, and how many there are.
    blank_measured, blank : int
        Points on the blank background reported visible on some frame after
        the reference, and how many there are.
    blank_point_frames : int
        Their visible point-frames after the reference.
    """

    textured_rms: float
    textured_kept: int
    textured: int
    blank_measured: int
    blank: int
    blank_point_frames: int


def rigid_score(
    positions: np.ndarray,
    visible: np.ndarray,
    true_positions: np.ndarray,
    on_texture: np.ndarray,
) -> RigidScore:
    """Error on the textured points, and blank points reported as measured.

    Parameters
    ----------
    positions, true_positions : (T, N, 2) float
    visible : (T, N) bool
    on_texture : (N,) bool
        ``truth.params["on_texture"]`` of
        :func:`sample_data_synth.pieces.make_rotation_pieces`.
    """
    on = np.asarray(on_texture, bool)
    visible = np.asarray(visible, bool) & np.all(np.isfinite(positions), axis=-1)
    error = np.linalg.norm(np.asarray(positions) - np.asarray(true_positions), axis=-1)
    seen = visible[1:, on]
    textured = error[1:, on][seen]
    blank = visible[1:, ~on]
    return RigidScore(
        textured_rms=float(np.sqrt(np.mean(textured**2))) if textured.size else float("nan"),
        textured_kept=int(visible[:, on].all(axis=0).sum()),
        textured=int(on.sum()),
        blank_measured=int(blank.any(axis=0).sum()),
        blank=int((~on).sum()),
        blank_point_frames=int(blank.sum()),
    )
