"""Repeated contractions: each cycle's onset, peak and end, its timing, and the ensemble.

The same for 2D runs (``strain2d analyze``) and 3D runs (``surface_strain
compute``, ``stereo reconstruct --strain``): they find their cycles with
:func:`find_run_cycles` and write them with :func:`write_cycles_csv`.

A recording may hold many contractions (a stimulated muscle strip, beating
cardiomyocytes, a cyclic loading protocol), of different sizes.
:func:`detect_cycles` finds them in the tissue's mean strain, or cuts them
at the pulses of a stimulus signal recorded beside the video:

* **Activity.** The mean strain component that moves most (of Exx, Eyy),
  signed so that the contraction (or stretch) rises: its value at the frame
  farthest from the reference, where the strain is 0, gives the sign.
* **Noise.** Where the tracker measures its uncertainty, what that
  uncertainty makes of the mean strain (:func:`mean_strain_noise`); else
  the spread of the activity's second differences (a robust standard
  deviation, 1.4826 MAD, over sqrt(6)) over the frames at rest (near the
  lowest activity), where the contractions' own curvature does not count:
  what frame-to-frame noise alone makes of the curve.
* **Peaks.** The local maxima whose prominence (how far they rise above the
  valleys on either side, as :func:`scipy.signal.find_peaks` measures it) exceeds
  ``min_prominence``: by default 8 noise SDs and 15 % of the largest
  excursion, so that noise and a wobble at rest are not cycles.
* **Onset and end.** Before each peak the valley since the cycle before (its
  lowest frame) is the cycle's rest level; the onset is the last frame before
  the peak within ``rest_share`` of the rise (at least 3 noise SDs) of that
  level, and the end the first frame after the peak back within it of the
  rest level after the peak (None when the video ends before).
* **With a stimulus** (one value per frame): a cycle starts at each pulse
  (where the stimulus first rises past half its range) and runs to the next;
  its peak is the largest activity in it, its onset and end as above.  A
  pulse whose response rises less than 3 noise SDs and 15 % of the largest
  excursion is reported, without a peak.

:func:`cycle_statistics` gives each cycle's times (time to peak, time to 50 %
relaxation, relaxation time) and its peak strains, and the ensemble cycle:
the cycles' mean strain curves aligned at their onsets, averaged, with their
spread.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from tissue_core.errors import InputError

__all__ = [
    "CYCLE_COMPONENTS",
    "Cycle",
    "activity",
    "cycle_statistics",
    "detect_cycles",
    "find_run_cycles",
    "mean_strain_noise",
    "stimulus_pulses",
    "write_cycles_csv",
]

#: the components cycles are found in and reported
CYCLE_COMPONENTS = ("Exx", "Eyy", "Exy")

#: the least prominence of a cycle's peak, in noise SDs and as a share of the largest excursion
NOISE_SDS = 8.0
LARGEST_SHARE = 0.15


@dataclass(frozen=True)
class Cycle:
    """One contraction: frames (``end`` None when the video ends first) and its rise.

    ``amplitude`` is the activity's rise from the rest level before it to the
    peak (strain, > 0); ``stimulus`` the frame of the pulse that started it.
    """

    onset: int
    peak: int | None
    end: int | None
    amplitude: float
    stimulus: int | None = None

    def to_dict(self) -> dict:
        return asdict(self)


def activity(curves: np.ndarray, components) -> tuple[np.ndarray, str, float]:
    """The signal cycles are found in: ``(activity (T,), component, sign)``.

    ``curves`` are the mean strains ``(T, K)`` of ``components``; the
    component is the normal one (Exx or Eyy, else any) with the largest
    excursion from 0, the sign that of that excursion (-1: a contraction).
    """
    curves = np.asarray(curves, dtype=float)
    names = list(components)
    normal = [j for j, c in enumerate(names) if c in ("Exx", "Eyy")] or list(range(len(names)))
    reach = [float(np.nanmax(np.abs(curves[:, j]))) if np.isfinite(curves[:, j]).any() else 0.0
             for j in normal]  # fmt: skip
    j = normal[int(np.argmax(reach))]
    values = curves[:, j]
    far = int(np.nanargmax(np.abs(values))) if np.isfinite(values).any() else 0
    sign = -1.0 if values[far] < 0 else 1.0
    return sign * values, names[j], sign


#: frames within this share of the activity's range above its lowest count as at rest
_REST_SHARE = 0.2


def _noise(a: np.ndarray) -> float:
    """The activity's noise SD from its second differences (1.4826 MAD / sqrt 6): over the
    frames at rest (three in a row within :data:`_REST_SHARE` of the range above the
    lowest), where the contractions' own curvature does not count as noise, when five or
    more such triples exist; over every frame otherwise."""
    a = a[np.isfinite(a)]
    second = np.diff(a, 2)
    if second.size < 3:
        return 0.0
    low, high = float(a.min()), float(a.max())
    rest = a <= low + _REST_SHARE * (high - low)
    calm = rest[:-2] & rest[1:-1] & rest[2:]
    if calm.sum() >= 5:
        second = second[calm]
    mad = np.median(np.abs(second - np.median(second)))
    return float(1.4826 * mad / np.sqrt(6.0))


def _prominent_peaks(a: np.ndarray, min_prominence: float) -> np.ndarray:
    """The local maxima of ``a`` (the middle frame of a flat top) whose prominence is at
    least ``min_prominence``: the height above the higher of the lowest points between
    the peak and the nearest higher sample on each side (or the ends), as
    :func:`scipy.signal.find_peaks` measures it (without importing scipy.signal, which
    takes longer to load than a run's cycles take to find)."""
    n = a.size
    peaks = []
    i = 1
    while i < n - 1:
        if a[i - 1] < a[i]:
            j = i
            while j + 1 < n and a[j + 1] == a[i]:  # a flat top
                j += 1
            if j + 1 < n and a[j + 1] < a[i]:
                peaks.append((i + j) // 2)
            i = j + 1
        else:
            i += 1
    kept = []
    for p in peaks:
        left = p
        lowest_left = a[p]
        while left > 0 and a[left - 1] <= a[p]:
            left -= 1
            lowest_left = min(lowest_left, a[left])
        right = p
        lowest_right = a[p]
        while right < n - 1 and a[right + 1] <= a[p]:
            right += 1
            lowest_right = min(lowest_right, a[right])
        if a[p] - max(lowest_left, lowest_right) >= min_prominence:
            kept.append(p)
    return np.asarray(kept, dtype=int)


def stimulus_pulses(stimulus: np.ndarray) -> np.ndarray:
    """The frames where a stimulus first rises past half its range (none when it is flat)."""
    s = np.asarray(stimulus, dtype=float)
    if s.ndim != 1:
        raise InputError("the stimulus must be one value per frame")
    ok = np.isfinite(s)
    if not ok.any() or np.nanmax(s) <= np.nanmin(s):
        return np.zeros(0, dtype=int)
    half = (np.nanmin(s) + np.nanmax(s)) / 2
    high = np.where(ok, s > half, False)
    rises = np.flatnonzero(high & ~np.r_[False, high[:-1]])
    return rises


def detect_cycles(
    curves: np.ndarray,
    components=("Exx", "Eyy"),
    *,
    stimulus: np.ndarray | None = None,
    min_prominence: float | None = None,
    rest_share: float = 0.02,
    noise: float | None = None,
) -> dict:
    """Find the contraction cycles in a run's mean strains (see the module docstring).

    Parameters
    ----------
    curves : (T, K) float
        Mean strain per frame of each of ``components`` (NaN where unknown).
    components : sequence of str
    stimulus : (T,) float, keyword-only
        A stimulus signal aligned to the frames: cycles start at its pulses.
    min_prominence : float, keyword-only
        Least rise of a peak above the valleys beside it (strain); default
        the larger of 8 noise SDs and 15 % of the largest excursion.
    rest_share : float, keyword-only
        Share of a cycle's rise within which the tissue counts as at rest
        (at least 3 noise SDs).
    noise : float, keyword-only
        The activity's noise SD when it is known (from the tracker's
        uncertainty: :func:`mean_strain_noise`); default estimated from the
        activity's second differences, which counts as noise what changes
        faster than the frame rate resolves (beats two or three frames apart).

    Returns
    -------
    dict
        ``cycles`` (list of :class:`Cycle`), ``component`` and ``sign`` of the
        activity, ``noise`` (its SD), ``min_prominence`` and ``trigger``
        ("strain" or "stimulus").
    """
    a, component, sign = activity(curves, components)
    T = a.size
    finite = np.isfinite(a)
    noise = _noise(a) if noise is None else float(noise)
    filled = np.where(finite, a, np.interp(np.arange(T), np.flatnonzero(finite), a[finite])
                      if finite.any() else 0.0)  # fmt: skip
    low = min(float(np.min(filled)), 0.0)
    excursion = float(np.max(filled)) - low
    if min_prominence is None:
        # found in the strain, a peak must stand out of the noise; cut at a stimulus (where
        # a contraction is expected), a response need only rise out of it
        sds = NOISE_SDS if stimulus is None else 3.0
        min_prominence = max(sds * noise, LARGEST_SHARE * excursion)
    out = {
        "component": component,
        "sign": sign,
        "noise": noise,
        "min_prominence": float(min_prominence),
        "trigger": "strain" if stimulus is None else "stimulus",
        "cycles": [],
    }
    if excursion <= 0 or not finite.any():
        return out
    if stimulus is None:
        # the padding lets a peak on the first or last frame count
        peaks = _prominent_peaks(np.r_[low, filled, low], min_prominence) - 1
        starts = [None] * len(peaks)
    else:
        stimulus = np.asarray(stimulus, dtype=float)
        if stimulus.shape != (T,):
            raise InputError(f"the stimulus has {stimulus.size} values for {T} frames")
        pulses = stimulus_pulses(stimulus)
        peaks, starts = [], []
        for i, pulse in enumerate(pulses):
            stop = pulses[i + 1] if i + 1 < len(pulses) else T
            window = filled[pulse:stop]
            k = int(pulse + np.argmax(window))
            rise = float(window.max() - min(filled[pulse], window.min()))
            peaks.append(k if rise >= min_prominence else -1)
            starts.append(int(pulse))
    cycles = []
    previous_end = 0
    for i, p in enumerate(peaks):
        start = starts[i] if starts[i] is not None else previous_end
        if p < 0:  # a pulse without a response
            cycles.append(Cycle(start, None, None, 0.0, start))
            continue
        left = filled[start : p + 1]
        valley = start + int(np.argmin(left))
        rest = float(filled[valley])
        rise = float(filled[p]) - rest
        tol = max(3 * noise, rest_share * rise)
        before = np.flatnonzero(filled[valley:p] <= rest + tol)
        onset = valley + int(before[-1]) if before.size else valley
        # the rest after the peak: the valley before the next cycle, or (the last cycle,
        # whose valley may be the video's end) the rest level before it
        following = [q for q in peaks[i + 1 :] if q >= 0]
        if starts[i] is not None and i + 1 < len(starts):
            stop, has_next = starts[i + 1], True
        else:
            stop, has_next = (following[0], True) if following else (T - 1, False)
        after = filled[p : stop + 1]
        settled = float(after.min()) if has_next else rest
        back = np.flatnonzero(after <= settled + tol)
        end = int(p) + int(back[0]) if back.size and back[0] > 0 else None
        cycles.append(Cycle(int(onset), int(p), end, rise, starts[i]))
        previous_end = end if end is not None else p
    out["cycles"] = cycles
    return out


def mean_strain_noise(
    reference: np.ndarray, triangles: np.ndarray, sigma_px: float, *, draws: int = 64, rng=0
) -> float:
    """The SD of a mesh's mean nodal strain (the largest over Exx, Eyy, Exy) when every
    point's position has independent noise of ``sigma_px`` per coordinate (the tracker's
    uncertainty): ``draws`` noisy copies of the reference, their mean strains' spread."""
    from surface_strain import compute_strain, nodal_scalars

    reference = np.asarray(reference, dtype=float)
    ok = np.isfinite(reference).all(axis=1)
    if not (np.isfinite(sigma_px) and sigma_px > 0) or ok.sum() < 3 or len(triangles) == 0:
        return 0.0
    gen = np.random.default_rng(rng)
    start = np.where(ok[:, None], reference, 0.0)
    noisy = start[None] + gen.normal(0.0, sigma_px, (draws, *reference.shape))
    field = compute_strain(start, noisy, np.asarray(triangles))
    node = nodal_scalars(field)
    with _quiet():
        spread = [np.nanstd(np.nanmean(node[c], axis=1), ddof=1) for c in ("Exx", "Eyy", "Exy")]
    return float(np.nanmax(spread))


def _crossing(a: np.ndarray, t: np.ndarray, start: int, level: float) -> float | None:
    """The time after frame ``start`` at which ``a`` first falls to ``level`` (linear
    between frames), or None."""
    for k in range(start, a.size - 1):
        if a[k] >= level >= a[k + 1] and a[k] != a[k + 1]:
            return float(t[k] + (a[k] - level) / (a[k] - a[k + 1]) * (t[k + 1] - t[k]))
    return None


def cycle_statistics(
    found: dict, curves: np.ndarray, components, times: np.ndarray, nodal=None
) -> dict:
    """Each cycle's times and peak strains, and the ensemble cycle.

    Parameters
    ----------
    found : dict
        :func:`detect_cycles`' result for ``curves``.
    curves : (T, K) float
        The mean strains of ``components``.
    times : (T,) float
    nodal : callable(frame) -> dict of (N,) arrays, optional
        The nodal strains of a frame by component: each cycle's peak values
        per node (``peak_nodes``).

    Returns
    -------
    dict
        ``cycles``: per cycle ``onset``, ``peak``, ``end`` (frames), their
        ``*_time``, ``time_to_peak``, ``rt50`` (peak to 50 % relaxation),
        ``relaxation_time`` (peak to end), ``amplitude`` and ``peak_mean``
        (mean strains at the peak); ``ensemble``: ``frames_since_onset``,
        ``time_since_onset``, per component ``mean`` and ``sd`` over the
        complete cycles (aligned at their onsets), ``n_cycles``; ``largest``
        (index of the cycle of largest amplitude, or None).
    """
    curves = np.asarray(curves, dtype=float)
    t = np.asarray(times, dtype=float)
    names = list(components)
    sign = found["sign"]
    j = names.index(found["component"])
    a = sign * curves[:, j]
    rows, peaks_nodes = [], []
    for c in found["cycles"]:
        row = {"onset": c.onset, "peak": c.peak, "end": c.end, "stimulus": c.stimulus,
               "amplitude": c.amplitude}  # fmt: skip
        row["onset_time"] = float(t[c.onset])
        if c.peak is None:
            rows.append(row)
            continue
        row["peak_time"] = float(t[c.peak])
        row["end_time"] = None if c.end is None else float(t[c.end])
        row["time_to_peak"] = float(t[c.peak] - t[c.onset])
        half = a[c.peak] - c.amplitude / 2
        crossed = _crossing(a, t, c.peak, half)
        row["rt50"] = None if crossed is None else crossed - float(t[c.peak])
        row["relaxation_time"] = None if c.end is None else float(t[c.end] - t[c.peak])
        row["peak_mean"] = {name: float(curves[c.peak, k]) for k, name in enumerate(names)}
        rows.append(row)
        if nodal is not None:
            peaks_nodes.append((len(rows) - 1, nodal(c.peak)))
    complete = [c for c in found["cycles"] if c.peak is not None and c.end is not None]
    ensemble = None
    if complete:
        length = max(c.end - c.onset for c in complete) + 1
        stack = np.full((len(complete), length, len(names)), np.nan)
        for i, c in enumerate(complete):
            stop = min(c.onset + length, curves.shape[0])
            stack[i, : stop - c.onset] = curves[c.onset : stop]
        dt = float(np.median(np.diff(t))) if t.size > 1 else 1.0
        with np.errstate(invalid="ignore"), _quiet():
            mean = np.nanmean(stack, axis=0)
            sd = np.nanstd(stack, axis=0, ddof=1) if len(complete) > 1 else np.zeros_like(mean)
        ensemble = {
            "n_cycles": len(complete),
            "frames_since_onset": list(range(length)),
            "time_since_onset": [k * dt for k in range(length)],
            "mean": {name: mean[:, k].tolist() for k, name in enumerate(names)},
            "sd": {name: sd[:, k].tolist() for k, name in enumerate(names)},
        }
    with_peak = [i for i, c in enumerate(found["cycles"]) if c.peak is not None]
    largest = max(with_peak, key=lambda i: found["cycles"][i].amplitude) if with_peak else None
    return {"cycles": rows, "ensemble": ensemble, "largest": largest, "peak_nodes": peaks_nodes}


class _quiet:
    """No RuntimeWarning for the ensemble's frames that only some cycles reach."""

    def __enter__(self):
        import warnings

        self._catch = warnings.catch_warnings()
        self._catch.__enter__()
        warnings.simplefilter("ignore", RuntimeWarning)

    def __exit__(self, *exc):
        self._catch.__exit__(*exc)


def find_run_cycles(
    curves: np.ndarray,
    times: np.ndarray,
    *,
    stimulus: np.ndarray | None = None,
    noise: float | None = None,
) -> dict | None:
    """A run's contraction cycles from its mean strains ``curves`` ``(T, 3)`` of
    :data:`CYCLE_COMPONENTS`, or None when there is none (and no stimulus).  A single
    contraction is one cycle; only repeated ones (``repeated``: two or more) move the
    run's endpoint to a cycle's peak.

    Returns the detection (``component``, ``sign``, ``noise``, ``noise_from``,
    ``min_prominence``, ``trigger``), :func:`cycle_statistics`' ``cycles``
    (numbered from 1 in ``cycle``), ``ensemble`` and ``largest``, and the
    ``curves``.
    """
    found = detect_cycles(curves, CYCLE_COMPONENTS, stimulus=stimulus, noise=noise)
    responses = [c for c in found["cycles"] if c.peak is not None]
    if not responses and stimulus is None:
        return None
    stats = cycle_statistics(found, curves, CYCLE_COMPONENTS, times)
    for n, row in enumerate(stats["cycles"], start=1):
        row["cycle"] = n
    info = {k: found[k] for k in ("component", "sign", "noise", "min_prominence", "trigger")}
    info["noise_from"] = "tracking uncertainty" if noise is not None else "second differences"
    info["repeated"] = len(responses) >= 2
    return {**info, "cycles": stats["cycles"], "ensemble": stats["ensemble"],
            "largest": stats["largest"], "curves": curves}  # fmt: skip


def write_cycles_csv(folder, cycles: dict, field, *, node: dict | None = None) -> list:
    """``cycles.csv`` (a row per cycle) and ``cycles_nodes.csv`` (each cycle's peak strains
    per node) in ``folder``; ``node``, the field's nodal scalars when they are at hand."""
    from pathlib import Path

    from surface_strain.field import nodal_scalars
    from tissue_core.csvtext import csv_writer, number_cell
    from tissue_core.outputs import replaced_on_success

    folder = Path(folder)
    columns = ["cycle", "onset", "peak", "end", "onset_time", "peak_time", "end_time",
               "time_to_peak", "rt50", "relaxation_time", "amplitude"]  # fmt: skip
    table = folder / "cycles.csv"
    with replaced_on_success(table) as tmp, open(tmp, "w", newline="") as f:
        writer = csv_writer(f, lineterminator="\n")
        writer.writerow([*columns, *(f"{c}_peak_mean" for c in CYCLE_COMPONENTS)])
        for row in cycles["cycles"]:
            means = row.get("peak_mean") or {}
            writer.writerow([number_cell(row.get(c)) for c in columns]
                            + [number_cell(means.get(c)) for c in CYCLE_COMPONENTS])  # fmt: skip
    node = nodal_scalars(field) if node is None else node
    names = ("Exx", "Eyy", "Exy", "E1", "E2")
    nodes = folder / "cycles_nodes.csv"
    with replaced_on_success(nodes) as tmp, open(tmp, "w", newline="") as f:
        writer = csv_writer(f, lineterminator="\n")
        writer.writerow(["cycle", "peak", "point", *names])
        for row in cycles["cycles"]:
            if row["peak"] is None:
                continue
            k = int(row["peak"])
            values = [np.asarray(node[c][k]) for c in names]
            for i in range(field.n_points):
                writer.writerow([row["cycle"], k, i, *(number_cell(v[i]) for v in values)])
    return [table, nodes]
