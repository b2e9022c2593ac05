"""Figures of a stereo reconstruction: the tracked points in both views, and in 3D.

Functions return :class:`matplotlib.figure.Figure` objects (no pyplot state).
"""

from __future__ import annotations

import numpy as np

__all__ = ["plot_points3d", "plot_views"]


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
