"""Repeated contractions with exact truth: a muscle sheet that twitches again and again.

Real recordings hold several contractions (a light- or field-stimulated
muscle strip, beating cardiomyocytes, a loading protocol), of different sizes.
:func:`make_repeated_twitches` renders one: the twitching muscle sheet of
:mod:`sample_data_synth.sheet` (a contraction along the fibres, a smaller
widening across them, and a local hot spot), driven by a
:class:`~sample_data_synth.deformations.Twitches` profile of three twitches
of different amplitude with rest between them.  It comes with what a lab
records beside the video, a stimulus signal (a pulse :data:`STIMULUS_LEAD`
frames before each onset), and a tissue mask that is not a rectangle (an
ellipse over the sheet).

The truth is exact: ``truth.strain(points, k)`` at any frame, the onset, peak
and end of each twitch (``truth.time_profile.cycles``), each twitch's peak
strain that of ``t = amplitude``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sample_data_synth.cases import GroundTruth, SyntheticVideo
from sample_data_synth.deformations import Twitches
from sample_data_synth.sheet import render_sheet

__all__ = ["DEFAULT_TWITCHES", "STIMULUS_LEAD", "RepeatedTwitches", "make_repeated_twitches"]

#: (onset, peak, end, amplitude) of the default case's twitches: three, of different size
DEFAULT_TWITCHES = ((3, 8, 15, 1.0), (18, 22, 29, 0.55), (32, 37, 44, 0.8))
#: frames from a stimulus pulse to the onset of its twitch (the electromechanical delay)
STIMULUS_LEAD = 1


@dataclass(frozen=True)
class RepeatedTwitches:
    """The rendered case.

    Attributes
    ----------
    video : SyntheticVideo
        Frames and exact truth (``truth.time_profile`` the twitches).
    fps : float
        The frame rate the stimulus's times assume.
    stimulus : (T,) float
        1 on the frame of each pulse, 0 elsewhere.
    mask : (H, W) bool
        Where the tissue is: an ellipse over the sheet.
    """

    video: SyntheticVideo
    fps: float
    stimulus: np.ndarray
    mask: np.ndarray

    def stimulus_csv(self) -> str:
        """The stimulus as a lab's acquisition writes it: ``frame,time_s,stimulus``."""
        rows = [f"{k},{k / self.fps:.4f},{int(v)}" for k, v in enumerate(self.stimulus)]
        return "frame,time_s,stimulus\n" + "\n".join(rows) + "\n"


def make_repeated_twitches(
    *,
    shape: tuple[int, int] = (300, 400),
    n_frames: int = 48,
    twitches=DEFAULT_TWITCHES,
    peak: float = 0.1,
    fps: float = 10.0,
    read_noise: float = 1.0,
    shot_gain: float = 0.02,
    rng: int = 0,
    progress=None,
) -> RepeatedTwitches:
    """Render a muscle sheet that twitches several times (see the module docstring).

    Parameters
    ----------
    shape : (H, W), keyword-only
    n_frames : int, keyword-only
        At least the last twitch's end + 1.
    twitches : sequence of (onset, peak, end, amplitude), keyword-only
    peak : float, keyword-only
        The sheet's contraction ``1 - lx`` over 0.6 at amplitude 1 (as
        :func:`sample_data_synth.sheet.make_muscle_sheet`): 0.1 shortens the
        sheet by 6 % along its fibres.
    fps : float, keyword-only
        Frame rate of the stimulus's time column.
    read_noise, shot_gain, rng, progress : keyword-only
        As for :func:`sample_data_synth.sheet.make_muscle_sheet`.
    """
    h, w = (int(v) for v in shape)
    profile = Twitches(twitches)
    if n_frames <= profile.endpoint:
        raise ValueError(
            f"n_frames must exceed the last twitch's end ({profile.endpoint}), got {n_frames}"
        )
    if not 0 < peak < 0.3:
        raise ValueError(f"peak must be between 0 and 0.3, got {peak}")
    frames, deformation = render_sheet(
        (h, w),
        peak,
        [profile(k) for k in range(n_frames)],
        spot=(0.4, 0.5, 0.18),
        read_noise=read_noise,
        shot_gain=shot_gain,
        rng=rng,
        progress=progress,
    )
    center = ((w - 1) / 2, (h - 1) / 2)
    yy, xx = np.mgrid[:h, :w]
    mask = ((xx - center[0]) / (0.42 * w)) ** 2 + ((yy - center[1]) / (0.40 * h)) ** 2 <= 1.0
    stimulus = np.zeros(n_frames)
    for cycle in profile.cycles:
        stimulus[max(cycle["onset"] - STIMULUS_LEAD, 0)] = 1.0
    roi = (0.1 * (w - 1), 0.1 * (h - 1), 0.9 * (w - 1), 0.9 * (h - 1))
    params = {
        "description": f"muscle sheet twitching {len(profile.cycles)} times, {w}x{h} px",
        "suite": "repeated-twitches",
        "texture": "procedural skeletal muscle (wavy striated fibres)",
        "grid": [9, 7],
        "peak": peak,
        "fps": fps,
        "stimulus_lead_frames": STIMULUS_LEAD,
        "seed": rng,
        "read_noise": read_noise,
        "shot_gain": shot_gain,
    }
    truth = GroundTruth(
        "repeated-twitches", deformation, n_frames, (h, w), roi, params, time_profile=profile
    )
    return RepeatedTwitches(SyntheticVideo(frames, truth), float(fps), stimulus, mask)
