"""A microscope's height map of a patch of a stereo scene's surface, with exact truth.

A multiphoton microscope images a small patch (millimetres) of the wall a
stereo rig films (centimetres): :func:`microscope_patch` gives that patch's
height map on the microscope's own grid and axes (micrometres, turned by
``angle_deg`` about the surface's normal, its x-y origin and height datum
arbitrary), with folds finer than the cameras resolve (``fold_um`` high,
``wavelength_um`` apart, along the microscope's x), the exact similarity
that maps the microscope's ``(x, y, depth)`` (``depth = -height``) onto the
scene's world (mm), and landmark pairs as a user would pick them: points of
the height map and the same points on the reconstructed surface, off by
``landmark_mm`` (RMS, per axis). :func:`write_patch` writes it for
``python -m multimodal register3d``.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sample_data_synth._common import Rng, write_calibrated_tiff

__all__ = ["MicroscopePatch", "microscope_patch", "write_patch"]


@dataclass(frozen=True)
class MicroscopePatch:
    """A height map of a patch and its exact placement.

    Attributes
    ----------
    height_um : (Y, X) float32
    pixel_um : float
    scale, rotation, shift
        The truth: ``world_mm = scale * rotation @ (x, y, depth) + shift``.
    landmarks : (K, 6) float
        ``camera_x, camera_y, camera_z`` (mm, with the picking error) and
        ``microscope_x, microscope_y, microscope_z`` (um, z the height).
    params : dict
    """

    height_um: np.ndarray
    pixel_um: float
    scale: float
    rotation: np.ndarray
    shift: np.ndarray
    landmarks: np.ndarray
    params: dict

    def to_world(self, microscope: np.ndarray) -> np.ndarray:
        """Microscope ``(x, y, depth)`` um ``(N, 3)`` to world mm."""
        return self.scale * np.asarray(microscope, float) @ self.rotation.T + self.shift


def microscope_patch(
    scene,
    *,
    frame: int = 0,
    center: tuple[float, float] = (4.0, -3.0),
    size_um: float = 2000.0,
    pixel_um: float = 5.0,
    angle_deg: float = 25.0,
    fold_um: float = 15.0,
    wavelength_um: float = 170.0,
    landmarks: int = 4,
    landmark_mm: float = 0.05,
    rng: Rng = 0,
) -> MicroscopePatch:
    """The height map of a ``size_um`` square of ``scene``'s surface at ``frame``.

    Parameters
    ----------
    scene : sample_data_synth.stereo.StereoScene
    center : (float, float)
        The patch's centre in the surface's material coordinates (mm).
    angle_deg : float
        The microscope's x against the surface's first material axis, about
        the normal.
    fold_um, wavelength_um : float
        Folds added along the normal (height ``fold_um`` peak to peak);
        0 for none.
    landmarks, landmark_mm : int, float
        Landmark pairs near the patch's corners, the camera side off by
        ``landmark_mm`` per axis (RMS).
    """
    if not 3 <= int(landmarks) <= 5:
        raise ValueError(f"landmarks must be 3 to 5, got {landmarks}")
    n = round(size_um / pixel_um) + 1
    if not 16 <= n <= 2001:
        raise ValueError(f"size_um / pixel_um must make 16 to 2000 pixels a side, got {n - 1}")
    rng = np.random.default_rng(rng)
    c = np.asarray(center, dtype=float).reshape(1, 2)
    p0 = scene.positions(c, frame)[0]
    F = scene.gradient(c, frame)[0]  # (3, 2): the surface's tangents at the centre
    e1 = F[:, 0] / np.linalg.norm(F[:, 0])
    normal = np.cross(F[:, 0], F[:, 1])
    normal /= np.linalg.norm(normal)
    if normal[2] < 0:  # into the tissue: away from the cameras, as the cameras' z
        normal = -normal
    e2 = np.cross(normal, e1)
    a = math.radians(angle_deg)
    u = math.cos(a) * e1 + math.sin(a) * e2
    v = np.cross(normal, u)
    Q = np.column_stack([u, v, normal])
    scale = 1e-3  # mm per um
    origin = np.zeros(2)  # pixel (0, 0) at x = y = 0, as a height map's TIFF places it
    datum = -180.0  # depth of the patch's centre (um): heights around 180
    centre_um = np.array([*(origin + (n - 1) / 2 * pixel_um), datum])
    shift = p0 - scale * Q @ centre_um
    # each pixel's smooth surface point: the material point whose world position lies on the
    # pixel's line along the normal (fixed-point iterations in the tangent plane)
    cols, rows = np.meshgrid(np.arange(n), np.arange(n))
    xy = np.column_stack([origin[0] + cols.ravel() * pixel_um, origin[1] + rows.ravel() * pixel_um])
    target = (xy - centre_um[:2]) * scale  # mm along u, v from the centre
    step = np.linalg.inv(Q[:, :2].T @ F).T  # mm along u, v -> material mm, at the centre
    X = c + target @ step
    for _ in range(8):
        local = (scene.positions(X, frame) - p0) @ Q  # mm along u, v, normal
        X = X + (target - local[:, :2]) @ step
    local = (scene.positions(X, frame) - p0) @ Q
    depth = datum + local[:, 2] / scale
    if fold_um:
        depth = depth + 0.5 * fold_um * np.sin(2 * np.pi * (xy[:, 0] - origin[0]) / wavelength_um)
    height = (-depth).reshape(n, n).astype(np.float32)
    # landmarks: near the corners and the centre, the camera side off by the picking error
    inset, far = max(1, n // 5), n - 1 - max(1, n // 5)
    picks = [(inset, inset), (inset, far), (far, inset), (far, far), (n // 2, n // 3)]
    rows_cols = np.array(picks[: int(landmarks)])
    m = np.column_stack(
        [
            origin[0] + rows_cols[:, 1] * pixel_um,
            origin[1] + rows_cols[:, 0] * pixel_um,
            -height[rows_cols[:, 0], rows_cols[:, 1]].astype(float),
        ]
    )
    smooth = m.copy()
    smooth[:, 2] = (
        datum
        + ((scene.positions(X[rows_cols[:, 0] * n + rows_cols[:, 1]], frame) - p0) @ Q)[:, 2]
        / scale
    )  # the camera sees the smooth surface, not the folds
    camera = scale * smooth @ Q.T + shift + rng.normal(0.0, landmark_mm, (len(m), 3))
    table = np.column_stack([camera, m[:, 0], m[:, 1], -m[:, 2]])
    params = {
        "frame": frame,
        "center_mm": list(map(float, center)),
        "size_um": size_um,
        "pixel_um": pixel_um,
        "angle_deg": angle_deg,
        "fold_um": fold_um,
        "wavelength_um": wavelength_um,
        "landmark_mm": landmark_mm,
    }
    return MicroscopePatch(height, float(pixel_um), scale, Q, shift, table, params)


def write_patch(patch: MicroscopePatch, out: str | os.PathLike) -> dict[str, Path]:
    """Write ``heightmap.tif`` (float32 um, with its pixel size), ``landmarks3d.csv`` and
    ``truth.json`` (the similarity and the parameters) into folder ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "heightmap": out / "heightmap.tif",
        "landmarks": out / "landmarks3d.csv",
        "truth": out / "truth.json",
    }
    write_calibrated_tiff(paths["heightmap"], patch.height_um, patch.pixel_um)
    rows = ["camera_x,camera_y,camera_z,microscope_x,microscope_y,microscope_z"]
    rows += [",".join(f"{v:.6f}" for v in row) for row in patch.landmarks]
    paths["landmarks"].write_text("\n".join(rows) + "\n", encoding="utf-8")
    truth = {
        "maps": "world_mm = scale * rotation @ (x, y, depth) + shift; depth = -height (um)",
        "scale_per_um": patch.scale,
        "rotation": patch.rotation.tolist(),
        "shift": patch.shift.tolist(),
        "params": patch.params,
    }
    paths["truth"].write_text(json.dumps(truth, indent=2) + "\n", encoding="utf-8")
    return paths
