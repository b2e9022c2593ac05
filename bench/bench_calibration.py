"""Stereo calibration accuracy of a checkerboard and two dot grids on the same poses.

Renders synthetic stereo calibration views of three targets -- checkerboard
9 x 6, symmetric dot grid (circles) 9 x 6 and asymmetric dot grid (acircles)
4 x 11 -- with the default synthetic rig, the same seed (1) and the same
number of views, calibrates each with ``stereo.calibration.calibrate_stereo``
and prints a Markdown table of how far each calibration lies from the rig's
true parameters: views used, reprojection RMS, focal length error (worse
camera), baseline error, rotation error of R and principal point error
(worse camera and axis).  These are the numbers the stereo guide (docs/stereo.md) quotes; the test
``tests/stereo/test_calibration.py::test_dot_grids_calibrate_the_rig_at_least_as_well_as_a_checkerboard``
checks the same setting.

    python bench/bench_calibration.py [--views 8] [--size 512x384]
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from sample_data_synth.stereo import default_rig, render_calibration_views
from stereo.calibration import calibrate_stereo, parse_board

#: (label, target as rendered, target as calibrated): as in the test
TARGETS = (
    ("checkerboard 9x6", "checkerboard:9x6:10", "checkerboard:9x6:10"),
    ("dot grid circles 9x6", "circles:9x6:10:5", "circles:9x6:10"),
    ("dot grid acircles 4x11", "acircles:4x11:10:7", "acircles:4x11:10:7"),
)
SEED = 1


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must be WxH, got {text!r}") from None
    if width <= 0 or height <= 0:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    return width, height


def _errors(calib, rig) -> dict:
    """How far a calibration is from the rig's true parameters (as the test measures)."""
    focal = max(
        abs(calib.K_left[0, 0] / rig.K_left[0, 0] - 1),
        abs(calib.K_right[0, 0] / rig.K_right[0, 0] - 1),
    )
    pp = max(
        np.abs(calib.K_left[:2, 2] - rig.K_left[:2, 2]).max(),
        np.abs(calib.K_right[:2, 2] - rig.K_right[:2, 2]).max(),
    )
    angle = np.degrees(np.linalg.norm(cv2.Rodrigues(calib.R @ rig.R.T)[0]))
    return {
        "rms": calib.rms_px,
        "focal_pct": 100 * focal,
        "baseline_pct": 100 * abs(calib.baseline / rig.baseline - 1),
        "angle_deg": float(angle),
        "pp_px": float(pp),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=8, help="views per target (default 8)")
    parser.add_argument(
        "--size", type=_size, default=(512, 384), help="image size WxH (default 512x384)"
    )
    args = parser.parse_args()
    rig = default_rig(image_size=args.size)
    print(
        f"{args.views} synthetic views per target at {args.size[0]}x{args.size[1]} px, "
        f"seed {SEED}; errors against the rig's true parameters\n"
    )
    print(
        "| target | views used | RMS (px) | focal error (%) | baseline error (%) "
        "| rotation error (deg) | principal point error (px) |"
    )
    print("|---|---|---|---|---|---|---|")
    for label, synth, spec in TARGETS:
        views = render_calibration_views(rig, synth, n_views=args.views, rng=SEED)
        calib = calibrate_stereo(list(views.left), list(views.right), parse_board(spec))
        used = len(calib.extra["views"])
        e = _errors(calib, rig)
        print(
            f"| {label} | {used}/{args.views} | {e['rms']:.3f} | {e['focal_pct']:.3f} "
            f"| {e['baseline_pct']:.4f} | {e['angle_deg']:.3f} | {e['pp_px']:.2f} |"
        )


if __name__ == "__main__":
    main()
