"""The lab's signals beside the strain: over time, and the strain against each."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure

from strain2d.figures._curves import _time_label
from strain2d.figures._style import _label
from strain2d.signals import PULSE_NAMES

__all__ = ["plot_strain_and_signals"]


def plot_strain_and_signals(
    times: np.ndarray,
    strain: np.ndarray,
    component: str,
    names: Sequence[str],
    values: np.ndarray,
    *,
    time_unit: str = "frame",
) -> Figure:
    """One row per signal: the signal and the mean strain over time (left, two y axes),
    and the mean strain against the signal, frame by frame (right: a loop where one lags
    the other).

    Parameters
    ----------
    times : (T,) float
    strain : (T,) float
        The run's mean strain of ``component`` per frame.
    names : sequence of str
    values : (T, S) float
        The signals aligned to the frames (:func:`strain2d.signals.read_signals`).
    """
    t = np.asarray(times, dtype=float)
    strain = np.asarray(strain, dtype=float)
    values = np.asarray(values, dtype=float).reshape(len(t), -1)
    rows = len(names)
    fig = Figure(figsize=(9.0, 2.6 * rows + 0.6), layout="constrained")
    axes = np.atleast_2d(fig.subplots(rows, 2, width_ratios=(2.2, 1)))
    label = f"mean {_label(component)} (-)"
    for r, name in enumerate(names):
        left, right = axes[r]
        signal = values[:, r]
        left.plot(t, signal, color="0.25", lw=1.2, label=name)
        left.set_ylabel(name)
        left.set_xlabel(_time_label(time_unit))
        twin = left.twinx()
        twin.plot(t, strain, color="C0", lw=1.2)
        twin.set_ylabel(label, color="C0")
        twin.tick_params(axis="y", colors="C0")
        left.grid(alpha=0.3)
        if name.lower().split("_")[0].split(" ")[0] in PULSE_NAMES:  # no loop to show
            right.set_axis_off()
            right.text(0.5, 0.5, f"{name}: a pulse train", ha="center", va="center",
                       transform=right.transAxes, color="0.4")  # fmt: skip
            continue
        ok = np.isfinite(signal) & np.isfinite(strain)
        right.plot(signal[ok], strain[ok], "-", color="0.7", lw=0.8)
        right.scatter(signal[ok], strain[ok], c=t[ok], cmap="viridis", s=10, zorder=3)
        right.set_xlabel(name)
        right.set_ylabel(label)
        right.grid(alpha=0.3)
    axes[0, 0].set_title("signal (grey) and mean strain (blue) per frame", fontsize=9)
    axes[0, 1].set_title("strain vs signal (colour: time)", fontsize=9)
    return fig
