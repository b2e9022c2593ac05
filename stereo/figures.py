"""Figures of a stereo reconstruction: the tracked points in both views, and in 3D.

Functions return :class:`matplotlib.figure.Figure` objects (no pyplot state).
"""

from __future__ import annotations

import numpy as np

__all__ = ["plot_points3d", "plot_quality", "plot_views"]


def _figure(width: float, height: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), dpi=100, layout="constrained")


def plot_views(left: np.ndarray, right: np.ndarray, rec, *, frame: int = -1):
    """The first left and right frames with the points, and where they went by ``frame``.

    Parameters
    ----------
    left, right : (H, W) images of frame 0
    rec : stereo.reconstruct.Reconstruction
    """
    fig = _figure(11, 4.6)
    axes = fig.subplots(1, 2)
    last = rec.n_frames - 1 if frame < 0 else frame
    for ax, image, tracks, name in zip(
        axes, (left, right), (rec.left, rec.right), ("left", "right"), strict=True
    ):
        ax.imshow(image, cmap="gray")
        ax.plot(
            tracks[0, :, 0], tracks[0, :, 1], "o", ms=4, mfc="none", mec="cyan", label="frame 0"
        )
        seen = rec.visible[last]
        ax.plot(
            tracks[last, seen, 0],
            tracks[last, seen, 1],
            "+",
            ms=6,
            color="orange",
            label=f"frame {last}",
        )
        pts = tracks[0][np.isfinite(tracks[0]).all(axis=1)]
        if len(pts):
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            pad = 0.25 * max(*(hi - lo), 50)
            ax.set_xlim(lo[0] - pad, hi[0] + pad)
            ax.set_ylim(hi[1] + pad, lo[1] - pad)
        ax.set_title(f"{name} view")
        ax.set_xlabel("x (px)")
        ax.set_ylabel("y (px)")
    axes[0].legend(loc="lower left", fontsize=8)
    return fig


def plot_points3d(rec, *, unit: str = "mm", frame: int = -1):
    """The points in 3D at frame 0 and at ``frame``, coloured by reprojection error."""
    fig = _figure(7, 5.6)
    ax = fig.add_subplot(projection="3d")
    last = rec.n_frames - 1 if frame < 0 else frame
    p0, p1 = rec.points[0], rec.points[last]
    ax.scatter(p0[:, 0], p0[:, 1], p0[:, 2], s=10, c="0.6", label="frame 0")
    sc = ax.scatter(
        p1[:, 0], p1[:, 1], p1[:, 2], s=18, c=rec.reproj_error[last], cmap="viridis",
        label=f"frame {last}",
    )  # fmt: skip
    fig.colorbar(sc, ax=ax, shrink=0.6, label="reprojection error (px)")
    ax.set_xlabel(f"X ({unit})")
    ax.set_ylabel(f"Y ({unit})")
    ax.set_zlabel(f"Z ({unit})")
    ax.invert_zaxis()  # depth grows away from the cameras: nearer is higher
    ax.view_init(elev=20, azim=-65)  # from the side, the cameras above
    ax.set_title("triangulated points (left-camera frame)")
    ax.legend(loc="upper left", fontsize=8)
    return fig


def plot_quality(
    per_frame: dict,
    *,
    max_reproj_px: float | None = None,
    quality_name="ZNCC",
    fps: float | None = None,
):
    """Reprojection error, tracking quality and points with a 3D position against the frame.

    Parameters
    ----------
    per_frame : dict of (T,) arrays
        :func:`stereo.report.frame_quality` of a reconstruction.
    max_reproj_px : float, optional
        The reprojection limit, drawn as a line.
    quality_name : str
        What the tracker's quality measures (the middle panel's axis).
    fps : float, optional
        Frame rate: the time axis in seconds instead of frames.
    """
    fig = _figure(7.5, 6.4)
    axes = fig.subplots(3, 1, sharex=True)
    frames = np.asarray(per_frame["frame"])
    if fps:
        frames = frames / fps
    marker = "o" if len(frames) <= 60 else None
    ax = axes[0]
    ax.plot(frames, per_frame["reproj_median_px"], marker=marker, ms=3, label="median")
    ax.plot(frames, per_frame["reproj_p95_px"], "--", marker=marker, ms=3,
            label="95th percentile")  # fmt: skip
    p95 = np.asarray(per_frame["reproj_p95_px"], float)
    top = float(np.nanmax(p95)) if np.isfinite(p95).any() else 1.0
    if max_reproj_px is not None and max_reproj_px <= 3 * top:
        ax.axhline(max_reproj_px, color="0.5", lw=0.8, ls=":", label="limit (--max-reproj)")
        top = max(top, max_reproj_px)
    elif max_reproj_px is not None:  # far above the data: said, not drawn
        ax.set_title(
            f"the limit (--max-reproj {max_reproj_px:g} px) is off the scale",
            fontsize=8,
            loc="right",
        )
    ax.set_ylabel("reprojection\nerror (px)")
    ax.set_ylim(0, 1.15 * top if top > 0 else 1.0)
    ax.legend(fontsize=8, loc="upper left")
    ax = axes[1]
    ax.plot(frames, per_frame["quality_left_median"], marker=marker, ms=3, label="left view")
    ax.plot(frames, per_frame["quality_right_median"], "--", marker="s" if marker else None,
            ms=3, label="right view")  # fmt: skip
    ax.set_ylabel(f"median tracking\n{quality_name} (-)")
    ax.legend(fontsize=8, loc="lower left")
    ax = axes[2]
    total = np.asarray(per_frame["points_3d"]) + np.asarray(per_frame["lost"])
    ax.plot(frames, 100.0 * np.asarray(per_frame["points_3d"]) / np.maximum(total, 1),
            marker=marker, ms=3, color="C2")  # fmt: skip
    ax.set_ylabel("points with a\n3D position (%)")
    ax.set_ylim(-2, 102)
    ax.set_xlabel("time (s)" if fps else "frame")
    if not fps:
        from matplotlib.ticker import MaxNLocator

        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    for ax in axes:
        ax.grid(True, lw=0.3)
    fig.suptitle("Quality of the reconstruction per frame")
    return fig
