"""The lab's own signals beside the video: stimulus, force, pressure, volume, per frame.

A recording rarely comes alone: the stimulator's pulses, a force transducer,
a pressure or volume channel are sampled beside the camera, often faster.
``--signals FILE.csv`` attaches them to a run.  The CSV has a header and

* a ``frame`` column (the video's own frame numbers, 0 for its first frame),
  or a time column: ``time`` or ``time_s`` in seconds, ``time_ms`` in
  milliseconds (the video's first frame at time 0; ``--fps`` gives the
  frames' times); with both, the frame numbers are used;
* any number of other columns, each a signal (its header is its name; a
  unit in brackets or after an underscore is kept in the name: ``force_mN``).

Each signal is brought to the run's frames: frame ``k`` of the run is the
video's frame ``start + k * step`` (``--start``, ``--step``), shown from
``t_k - dt/2`` to ``t_k + dt/2`` (``dt`` the time between the frames used,
``step / fps``).  A signal is averaged over the samples in
that interval, or, for a pulse train (a column named ``stimulus``,
``trigger`` or ``pulse``), its largest sample there, so that a pulse far
shorter than a frame is not lost; a frame with no sample in its interval
gets the signal linearly interpolated at its time (NaN outside the
recording).  By frame number the same with the video's frames: a run frame
takes its own row, or with ``--step`` the rows of the frames it stands for.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from strain2d.errors import InputError

__all__ = ["PULSE_NAMES", "Signals", "read_signals"]

#: columns read as pulse trains (the largest sample within a frame, not the mean)
PULSE_NAMES = ("stimulus", "trigger", "pulse")
_TIME = {"time": 1.0, "time_s": 1.0, "time (s)": 1.0, "time_ms": 1e-3, "time (ms)": 1e-3}
#: the largest magnitude a signal's value may have (beyond it, sums overflow)
_LARGEST = 1e30


@dataclass(frozen=True)
class Signals:
    """Signals aligned to a run's frames.

    Attributes
    ----------
    names : list of str
    values : (T, S) float
        One row per frame of the run (NaN where the recording does not reach).
    source : str
    aligned_by : {"frame", "time"}
    samples : int
        Rows read from the file.
    """

    names: list[str]
    values: np.ndarray
    source: str
    aligned_by: str
    samples: int

    def column(self, name: str) -> np.ndarray:
        try:
            return self.values[:, self.names.index(name)]
        except ValueError:
            raise InputError(
                f"--trigger {name}: {self.source} has no signal of that name "
                f"(it has {', '.join(self.names)})"
            ) from None

    def summary(self) -> dict:
        """For ``summary.json``: the file, how it was aligned, each signal's range."""
        ranges = {}
        for k, name in enumerate(self.names):
            v = self.values[:, k]
            ok = np.isfinite(v)
            ranges[name] = (
                {"min": float(v[ok].min()), "max": float(v[ok].max()),
                 "frames_with_a_value": int(ok.sum())}
                if ok.any() else {"frames_with_a_value": 0}
            )  # fmt: skip
        return {
            "file": self.source,
            "aligned_by": self.aligned_by,
            "samples": self.samples,
            "signals": ranges,
        }


def _is_pulse(name: str) -> bool:
    """Whether a column is a pulse train (:data:`PULSE_NAMES`, with a unit or not)."""
    return name.lower().split("_")[0].split(" ")[0] in PULSE_NAMES


def _number(text: str, path, line: int, column: str) -> float:
    text = text.strip()
    if text.lower() in ("", "nan", "na", "none", "null"):
        return float("nan")
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{path}, line {line}: {column} must be a number, got {text!r}") from None
    if not abs(value) <= _LARGEST:
        raise InputError(
            f"{path}, line {line}: {column} is {text}, beyond what a measurement can be "
            f"(at most {_LARGEST:g} in magnitude; leave a cell empty where there is no value)"
        )
    return value


def read_signals(
    path: str | os.PathLike,
    n_frames: int,
    *,
    fps: float | None = None,
    start: int = 0,
    step: int = 1,
) -> Signals:
    """Read ``--signals`` and align it to a run's ``n_frames`` frames (module docstring).

    Raises
    ------
    InputError
        A file that is missing or not a text CSV, without a frame or time
        column or without signals, with text where numbers belong, times or
        frames that go back, a time column without ``fps``, or signals that
        reach none of the run's frames.
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"--signals {path} is a folder, not a CSV file")
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            header = [c.strip() for c in next(reader, [])]
            rows = [(reader.line_num, r) for r in reader if any(c.strip() for c in r)]
    except FileNotFoundError:
        raise InputError(f"--signals: no such file: {path}") from None
    except (UnicodeDecodeError, csv.Error):
        raise InputError(
            f"--signals {path} is not a UTF-8 text CSV file (save it as CSV UTF-8)"
        ) from None
    lower = [h.lower() for h in header]
    clocks = [i for i, h in enumerate(lower) if h == "frame" or h in _TIME]
    # the frame numbers where they are given (exact), else the time
    clock = next((i for i in clocks if lower[i] == "frame"), clocks[0] if clocks else None)
    if clock is None:
        raise InputError(
            f"--signals {path} needs a frame column (the video's frame numbers) or a time "
            f"column (time, t, time_s or time_ms); its header is {','.join(header) or 'empty'}"
        )
    names = [h for i, h in enumerate(header) if i not in clocks and h]
    repeated = sorted({h for h in names if names.count(h) > 1})
    if repeated:
        raise InputError(
            f"--signals {path}: the column {repeated[0]} is there twice; name each signal once"
        )
    if not names:
        raise InputError(f"--signals {path} has no signal beside its {header[clock]} column")
    if not rows:
        raise InputError(f"--signals {path} has a header and no rows")
    data = np.full((len(rows), len(header)), np.nan)
    for r, (line, cells) in enumerate(rows):
        if len(cells) != len(header):
            raise InputError(
                f"{path}, line {line}: {len(cells)} cells for the header's {len(header)} (a "
                "decimal comma makes one too many)"
            )
        for c, text in enumerate(cells):
            if header[c]:
                data[r, c] = _number(text, path, line, header[c])
    clock_values = data[:, clock]
    if not np.isfinite(clock_values).all():
        raise InputError(f"--signals {path}: every row needs its {header[clock]}")
    if np.any(np.diff(clock_values) <= 0):
        bad = int(np.flatnonzero(np.diff(clock_values) <= 0)[0]) + 1
        raise InputError(
            f"{path}, line {rows[bad][0]}: {header[clock]} {clock_values[bad]:g} does not follow "
            f"{clock_values[bad - 1]:g}: the rows must go forward in time"
        )
    columns = [i for i, h in enumerate(header) if i not in clocks and h]
    video_frames = start + step * np.arange(n_frames)
    values = np.full((n_frames, len(columns)), np.nan)
    if lower[clock] == "frame":
        if np.any(clock_values != np.round(clock_values)) or clock_values.min() < 0:
            raise InputError(f"--signals {path}: frame numbers are whole numbers from 0")
        # run frame k stands for the video's frames from start + k step - step/2 to
        # start + k step + step/2 (its own frame alone without --step)
        lo = np.searchsorted(clock_values, video_frames - step / 2, side="left")
        hi = np.searchsorted(clock_values, video_frames + step / 2, side="left")
        if step == 1:
            hi = np.searchsorted(clock_values, video_frames, side="right")
        for j, c in enumerate(columns):
            pulse = _is_pulse(header[c])
            for k in range(n_frames):
                window = data[lo[k] : hi[k], c]
                window = window[np.isfinite(window)]
                if window.size:
                    values[k, j] = window.max() if pulse else window.mean()
        aligned = "frame"
    else:
        if fps is None or not (math.isfinite(fps) and fps > 0):
            raise InputError(
                f"--signals {path} is in time ({header[clock]}): give the video's frame rate "
                "with --fps to place its frames in time"
            )
        seconds = clock_values * _TIME[lower[clock]]
        frame_time = video_frames / fps
        half = 0.5 * step / fps  # a run frame stands for step frames of the video
        for j, c in enumerate(columns):
            signal = data[:, c]
            ok = np.isfinite(signal)
            if not ok.any():
                continue
            pulse = _is_pulse(header[c])
            # the windows in the video's frames (rounded: a sample on the boundary between
            # two run frames goes to the later one, as it does by frame number)
            position = np.round(seconds * fps, 6)
            lo = np.searchsorted(position, video_frames - step / 2, side="left")
            hi = np.searchsorted(position, video_frames + step / 2, side="left")
            inside_recording = (frame_time >= seconds[ok][0] - half) & (
                frame_time <= seconds[ok][-1] + half
            )
            interp = np.interp(frame_time, seconds[ok], signal[ok])
            for k in range(n_frames):
                if not inside_recording[k]:
                    continue
                window = signal[lo[k] : hi[k]]
                window = window[np.isfinite(window)]
                if window.size:
                    values[k, j] = window.max() if pulse else window.mean()
                else:
                    values[k, j] = interp[k]
        aligned = "time"
    if not np.isfinite(data[:, columns]).any():
        raise InputError(f"--signals {path} holds no value in its signal columns")
    if not np.isfinite(values).any():
        span = (
            f"frames {int(clock_values[0])}-{int(clock_values[-1])}"
            if aligned == "frame"
            else f"{clock_values[0]:g}-{clock_values[-1]:g} {header[clock]}"
        )
        raise InputError(
            f"--signals {path} covers {span}, none of the run's frames "
            f"{int(video_frames[0])}-{int(video_frames[-1])}"
            + ("" if aligned == "frame" else f" ({frame_time[0]:g}-{frame_time[-1]:g} s)")
        )
    return Signals([header[c] for c in columns], values, str(path), aligned, len(rows))
