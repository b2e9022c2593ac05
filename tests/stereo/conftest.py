"""Small stereo inputs shared by the stereo tests: rendered once per session.

A 512 x 384 px rig looking at a stretching sheet (two frames, as image
folders and as videos), its calibration as the toolkit's JSON and as an
OpenCV YAML file, the sheet's points, and a few checkerboard views of the
same rig.  They are read-only: a test that needs a broken copy makes it in
its own ``tmp_path``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from sample_data_synth.stereo import (
    default_rig,
    render_calibration_views,
    render_surface_scene,
    save_calibration_views,
    save_stereo_scene,
)

#: the rig's image size (width, height), small so the commands run in a second
SMALL_SIZE = (512, 384)


@dataclass(frozen=True)
class SmallStereo:
    """Paths of the shared small inputs."""

    root: Path
    left: Path  # folder of frames
    right: Path
    left0: Path  # the first frame of each view (PNG)
    right0: Path
    left_video: Path  # the same frames as videos (AVI)
    right_video: Path
    calib: Path  # the true calibration, as `stereo calibrate` writes it
    yml: Path  # the same as an OpenCV YAML file (M1, D1, M2, D2, R, T, image_size)
    points: Path  # CSV x,y of the 7 x 7 grid on the sheet (left reference frame)
    views_left: Path  # checkerboard views for `stereo calibrate`
    views_right: Path
    truth: dict


def write_opencv_yaml(path: Path, calib: dict, *, image_size=True) -> None:
    """Write a calibration dict as OpenCV's stereo sample writes it (M1, D1, ...)."""
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, name in (("K_left", "M1"), ("dist_left", "D1"), ("K_right", "M2"),
                      ("dist_right", "D2"), ("R", "R"), ("T", "T")):  # fmt: skip
        fs.write(name, np.asarray(calib[key], np.float64))
    if image_size:
        fs.write("image_size", np.asarray(calib["image_size"], np.float64))
    fs.release()


def _write_video(path: Path, folder: Path) -> None:
    import cv2

    frames = [cv2.imread(str(f), cv2.IMREAD_GRAYSCALE) for f in sorted(folder.glob("*.png"))]
    h, w = frames[0].shape
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10, (w, h), isColor=False)
    for frame in frames:
        writer.write(frame)
    writer.release()


@pytest.fixture(scope="session")
def small_stereo(tmp_path_factory) -> SmallStereo:
    from stereo.calibration import load_calibration

    root = tmp_path_factory.mktemp("small_stereo")
    rig = default_rig(image_size=SMALL_SIZE)
    scene = render_surface_scene(rig, "stretch", n_frames=2, supersample=1, distance=300.0, rng=1)
    save_stereo_scene(root / "scene", scene)
    truth = dict(np.load(root / "scene" / "truth.npz"))
    points = root / "points.csv"
    np.savetxt(points, truth["left_px"][0], delimiter=",", header="x,y", comments="")
    calib = root / "calib.json"
    load_calibration(root / "scene" / "rig.json").save(calib)
    yml = root / "stereo.yml"
    write_opencv_yaml(yml, json.loads(calib.read_text()))
    for side in ("left", "right"):
        _write_video(root / f"{side}.avi", root / "scene" / side)
    views = render_calibration_views(rig, "checkerboard:9x6:10", n_views=5, supersample=1, rng=3)
    save_calibration_views(root / "views", views)
    return SmallStereo(
        root=root,
        left=root / "scene" / "left",
        right=root / "scene" / "right",
        left0=root / "scene" / "left" / "frame_000.png",
        right0=root / "scene" / "right" / "frame_000.png",
        left_video=root / "left.avi",
        right_video=root / "right.avi",
        calib=calib,
        yml=yml,
        points=points,
        views_left=root / "views" / "left",
        views_right=root / "views" / "right",
        truth=truth,
    )
