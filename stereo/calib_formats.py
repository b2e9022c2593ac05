"""Calibration files of other stereo-DIC software: VIC-3D and DICe XML.

:func:`read_vic3d` and :func:`read_dice` convert a two-camera calibration to a
:class:`~stereo.calibration.Calibration` (OpenCV's camera model with the skew
``K[0, 1]``, see :mod:`stereo.camera`); :func:`write_vic3d` and
:func:`write_dice` write one back.  :func:`sniff` tells the formats apart;
:func:`stereo.calibration.load_calibration` reads them all.  A value the
toolkit's model cannot reproduce exactly is refused in one line naming the
file and the value, never approximated.

Conventions of each format
--------------------------
Both formats give each camera's pose as world -> camera, ``X_cam = R_i X +
t_i``; the rig is camera 1 seen from camera 0: ``R = R_1 R_0^T``, ``T = t_1 -
R t_0`` (exact for any world frame, the identity or VIC-3D's frame between the
cameras).  Camera 0 is the left camera.

VIC-3D (Correlated Solutions), the ``<calibration>`` block of a ``.cal`` or
project (``.z3d``) XML file::

    <camera id="0">cx cy fx fy fs kappa1 kappa2 kappa3<orientation>
      alpha beta gamma tx ty tz</orientation></camera>

* intrinsics in pixels; ``fs`` is the skew in pixels: ``u = fx xd + fs yd +
  cx``, ``v = fy yd + cy`` (the ``K[0, 1]`` of the toolkit's model).
* radial distortion of the ideal normalized point ``(x, y) = (X/Z, Y/Z)``:
  ``(xd, yd) = (x, y) (1 + kappa1 r^2 + kappa2 r^4 + kappa3 r^6)``, ``r^2 = x^2
  + y^2`` (Sutton, Orteu & Schreier 2009, section 3.2), no tangential terms:
  OpenCV's ``(k1, k2, p1, p2, k3) = (kappa1, kappa2, 0, 0, kappa3)``.  Note
  the order: VIC-3D's third coefficient is OpenCV's fifth.  (DICe's reader of
  VIC-3D files takes kappa1 and kappa2 as coefficients of ``r`` and ``r^2``, a
  reading its source marks as unconfirmed; the toolkit follows the book by
  VIC-3D's authors.)
* orientation: Cardan angles in degrees, ``R_i = Rz(gamma) Ry(beta)
  Rx(alpha)`` (the reading DICe uses for VIC-3D files), translation in the
  calibration's unit (mm).
* image size: ``<polygonmask width= height=>`` when the file has one, else
  ``--image-size``.

DICe (Sandia), a Teuchos ``ParameterList`` with sublists ``CAMERA 0`` and
``CAMERA 1``:

* ``CX CY FX FY`` (pixels), ``FS`` (skew), ``K1..K6 P1 P2 S1..S4 T1 T2``,
  ``LENS_DISTORTION_MODEL``, ``IMAGE_HEIGHT_WIDTH "{h, w}"``; ``TX TY TZ``
  and either ``ALPHA BETA GAMMA`` (degrees, as above) or a sublist
  ``rotation_3x3_matrix`` with ``ROW 0..2 "{r0, r1, r2}"``; missing values
  are 0.  With ``extrinsics_relative_camera_to_camera = true`` camera 1's
  pose is already relative to camera 0.
* ``LENS_DISTORTION_MODEL`` as DICe's ``Camera::sensor_to_image`` applies it.
  Its radial models move the radius ``r`` of the ideal normalized point to
  ``r + dr``; the factor on ``(x, y)`` is ``1 + dr / r``:

  - ``NO_LENS_DISTORTION``: none.
  - ``OPENCV_LENS_DISTORTION``: OpenCV's, ``(K1, K2, P1, P2, K3, K4, K5, K6,
    S1..S4)``; ``T1, T2`` (tilted sensor) are refused unless 0.
  - ``K1R3_K2R5_K3R7``: ``dr = K1 r^3 + K2 r^5 + K3 r^7``, the factor ``1 + K1
    r^2 + K2 r^4 + K3 r^6``: OpenCV's ``k1, k2, k3``.
  - ``K1R1_K2R2_K3R3``: factor ``1 + K1 + K2 r + K3 r^2 = s (1 + K3/s r^2)``
    with ``s = 1 + K1``: the focal lengths times ``s`` and OpenCV's ``k1 =
    K3 / s``; ``K2`` (odd in ``r``) must be 0.
  - ``VIC3D_LENS_DISTORTION``: factor ``1 + K1 + K2 r`` (DICe leaves ``K3``
    out) with the skew ``FS``: the focal lengths and skew times ``1 + K1``;
    ``K2`` must be 0.
  - ``K1R2_K2R4_K3R6``: factor ``1 + K1 r + K2 r^3 + K3 r^5``, odd powers
    only: refused unless all 0.

  DICe applies ``FS`` only in its VIC-3D model; with the others it ignores it,
  and so does the import (recorded in ``extra["notes"]``, with the pixels it
  would have moved).

:func:`write_dice` writes ``OPENCV_LENS_DISTORTION`` (skew as ``FS`` only when
it is 0, since that model ignores it; a skewed camera is refused) and
:func:`write_vic3d` refuses distortion VIC-3D cannot hold (tangential,
rational, thin-prism terms).

References
----------
M. A. Sutton, J.-J. Orteu, H. W. Schreier, Image Correlation for Shape,
Motion and Deformation Measurements, Springer 2009,
doi:10.1007/978-0-387-78747-3 (chapter 3: camera model, distortion).
D. Z. Turner, Digital Image Correlation Engine (DICe), Sandia National
Laboratories, https://github.com/dicengine/dice (``DICe_Camera.cpp``,
``DICe_CameraSystem.cpp``).
"""

from __future__ import annotations

import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from tissue_core.errors import InputError

__all__ = [
    "ImageSizeMissing",
    "euler_rotation",
    "parse_image_size",
    "read_dice",
    "read_vic3d",
    "sniff",
    "write_dice",
    "write_vic3d",
]

#: DICe's distortion models (upper case; the aliases its template comments use)
_DICE_MODELS = {
    "NO_LENS_DISTORTION": "none",
    "NONE": "none",
    "OPENCV_LENS_DISTORTION": "opencv",
    "OPENCV_DIS": "opencv",
    "VIC3D_LENS_DISTORTION": "vic3d",
    "VIC3D_DIS": "vic3d",
    "K1R1_K2R2_K3R3": "r1r2r3",
    "K1R2_K2R4_K3R6": "r2r4r6",
    "K1R3_K2R5_K3R7": "r3r5r7",
}
_DICE_INTRINSICS = (
    "CX", "CY", "FX", "FY", "FS", "K1", "K2", "K3", "K4", "K5", "K6",
    "P1", "P2", "S1", "S2", "S3", "S4", "T1", "T2",
)  # fmt: skip


def euler_rotation(alpha: float, beta: float, gamma: float) -> np.ndarray:
    """``Rz(gamma) @ Ry(beta) @ Rx(alpha)``, angles in degrees (VIC-3D's and DICe's).

    Examples
    --------
    >>> np.round(euler_rotation(0, 0, 90), 12).tolist()
    [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    """
    a, b, g = (math.radians(v) for v in (alpha, beta, gamma))
    rx = np.array([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    ry = np.array([[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]])
    rz = np.array([[math.cos(g), -math.sin(g), 0], [math.sin(g), math.cos(g), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _euler_angles(R: np.ndarray) -> tuple[float, float, float]:
    """The angles (degrees) of :func:`euler_rotation` for a rotation matrix."""
    beta = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    alpha = math.atan2(R[2, 1], R[2, 2])
    gamma = math.atan2(R[1, 0], R[0, 0])
    return math.degrees(alpha), math.degrees(beta), math.degrees(gamma)


def _parse(path: Path) -> ET.Element:
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise InputError(f"{path}: not a readable XML calibration ({exc})") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a readable XML calibration (not text)") from None


def sniff(path: str | os.PathLike) -> str | None:
    """``"vic3d"``, ``"dice"`` or None (not one of these XML formats)."""
    with open(path, "rb") as f:
        head = f.read(4096).lstrip(b"\xef\xbb\xbf \t\r\n")
    if not head.startswith(b"<"):
        return None
    low = head.lower()
    if b"<parameterlist" in low:
        return "dice"
    if b"<opencv_storage" in low:
        return None
    if b"<calibration" in low or b"<camera" in low or b"<project" in low:
        return "vic3d"
    return None


def _numbers(text: str | None, path: Path, what: str, count: int) -> list[float]:
    parts = (text or "").replace(",", " ").replace("{", " ").replace("}", " ").split()
    try:
        values = [float(v) for v in parts]
    except ValueError:
        raise InputError(f"{path}: {what} must be {count} numbers, got {text!r}") from None
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise InputError(f"{path}: {what} must be {count} finite numbers, got {len(values)}")
    return values


def _camera_matrix(fx: float, fy: float, cx: float, cy: float, skew: float) -> np.ndarray:
    return np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def _rig(poses: list[tuple[np.ndarray, np.ndarray]], relative: bool = False):
    (R0, t0), (R1, t1) = poses
    if relative:
        return R1, t1
    R = R1 @ R0.T
    return R, t1 - R @ t0


class ImageSizeMissing(InputError):
    """A calibration file that holds no image size, and none was given.

    ``stereo import-calib`` asks for ``--image-size``; ``stereo reconstruct``
    and ``stereo match`` take the size of the images they read.
    """


def _size(found, given, path: Path) -> tuple[int, int]:
    if found is not None and given is not None and tuple(found) != tuple(given):
        raise InputError(
            f"{path}: the file says the images are {found[0]}x{found[1]} px, "
            f"--image-size says {given[0]}x{given[1]}"
        )
    size = found if found is not None else given
    if size is None:
        raise ImageSizeMissing(
            f"{path}: the calibration holds no image size; give it with --image-size WxH"
        )
    return int(size[0]), int(size[1])


def _make(path: Path, fmt: str, size, cams, R, T, notes: list[str], unit: str | None):
    from stereo.calibration import Calibration, CalibrationValueError

    try:
        return Calibration(
            image_size=size,
            K_left=cams[0][0],
            dist_left=cams[0][1],
            K_right=cams[1][0],
            dist_right=cams[1][1],
            R=R,
            T=T,
            unit=unit or "mm",
            extra={"imported_format": fmt, "notes": notes},
        )
    except CalibrationValueError as exc:
        raise InputError(f"{path}: {exc}") from None


def _tag(element: ET.Element) -> str:
    return element.tag.rsplit("}", 1)[-1].lower() if isinstance(element.tag, str) else ""


def read_vic3d(path: str | os.PathLike, *, image_size=None, unit: str | None = None):
    """Read a VIC-3D calibration (a ``.cal`` file or a project's XML).

    Parameters
    ----------
    path : the XML file
    image_size : (width, height) px, keyword-only
        Needed when the file holds no ``<polygonmask width= height=>``.
    unit : str, keyword-only
        The unit of the file's lengths (default mm).

    Returns
    -------
    Calibration
        camera 0 as the left camera; ``extra["imported_format"] = "vic3d"``.

    Raises
    ------
    InputError
        The file holds no or several ``<calibration>`` elements, or a camera
        id twice within it.
    """
    path = Path(path)
    root = _parse(path)
    found_size = None
    for el in root.iter():
        if _tag(el) == "polygonmask" and found_size is None:
            try:
                found_size = (int(el.get("width")), int(el.get("height")))
            except (TypeError, ValueError):
                raise InputError(
                    f"{path}: polygonmask width and height must be whole numbers"
                ) from None
    blocks = [el for el in root.iter() if _tag(el) == "calibration"]
    if len(blocks) != 1:
        raise InputError(
            f"{path}: not a VIC-3D stereo calibration: need one <calibration> element, "
            f"found {len(blocks)}"
            + ("; keep the one that was used for this measurement" if blocks else "")
        )
    cameras = {}
    for el in blocks[0].iter():
        if _tag(el) != "camera":
            continue
        cid = el.get("id")
        if cid is None or not cid.strip().isdigit():
            raise InputError(f"{path}: a <camera> has no numeric id (id={cid!r})")
        if int(cid) in cameras:
            raise InputError(f'{path}: <camera id="{int(cid)}"> appears more than once')
        orientation = [c for c in el if _tag(c) == "orientation"]
        if len(orientation) != 1:
            raise InputError(f"{path}: camera {cid} has no <orientation> (6 numbers)")
        what = f"camera {cid}"
        values = _numbers(el.text, path, f"{what} (cx cy fx fy fs kappa1 kappa2 kappa3)", 8)
        pose = _numbers(
            orientation[0].text, path, f"{what} orientation (alpha beta gamma tx ty tz)", 6
        )
        cameras[int(cid)] = (values, pose)
    if sorted(cameras) != [0, 1]:
        raise InputError(
            f'{path}: not a VIC-3D stereo calibration: need <camera id="0"> and '
            f'<camera id="1">, found {sorted(cameras) or "no cameras"}'
        )
    cams, poses = [], []
    for i in (0, 1):
        (cx, cy, fx, fy, fs, k1, k2, k3), (a, b, g, tx, ty, tz) = cameras[i]
        cams.append((_camera_matrix(fx, fy, cx, cy, fs), [k1, k2, 0.0, 0.0, k3]))
        poses.append((euler_rotation(a, b, g), np.array([tx, ty, tz])))
    R, T = _rig(poses)
    return _make(path, "vic3d", _size(found_size, image_size, path), cams, R, T, [], unit)


def _dice_params(element: ET.Element) -> tuple[dict, dict]:
    """A ParameterList's parameters (name -> (type, value)) and sublists (name -> element)."""
    params, sublists = {}, {}
    for child in element:
        tag = _tag(child)
        name = (child.get("name") or "").strip()
        if tag == "parameter":
            params[name.upper()] = ((child.get("type") or "").lower(), child.get("value") or "")
        elif tag == "parameterlist":
            sublists[name.upper()] = child
    return params, sublists


def _dice_number(params: dict, name: str, path: Path, camera: str) -> float:
    if name not in params:
        return 0.0
    text = params[name][1]
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{path}: {camera} {name} must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{path}: {camera} {name} must be finite, got {text!r}")
    return value


def _dice_distortion(
    v: dict, model: str, path: Path, camera: str, notes: list[str]
) -> tuple[list, float, bool]:
    """OpenCV's coefficients for a DICe model, the focal scale it implies, whether DICe
    applies FS.

    DICe's radial models move the radius ``r`` of the ideal normalized point to
    ``r + K1 r^a + K2 r^b + K3 r^c`` (``Camera::sensor_to_image``): the factor on
    ``(x, y)`` is ``1 + K1 r^(a-1) + ...``.  Even powers of ``r`` in the factor are
    OpenCV's radial terms, a constant is a focal-length scale; odd powers are refused.
    """
    kind = _DICE_MODELS.get(model.upper())
    if kind is None:
        raise InputError(
            f"{path}: {camera} LENS_DISTORTION_MODEL {model!r} is not one of DICe's "
            f"({', '.join(sorted(_DICE_MODELS))})"
        )

    def refuse_unless_zero(names: tuple[str, ...], why: str) -> None:
        bad = [f"{n} = {v[n]:g}" for n in names if v[n] != 0]
        if bad:
            raise InputError(
                f"{path}: {camera} {model}: {', '.join(bad)} cannot be converted exactly: {why}"
            )

    def unused(names: tuple[str, ...]) -> None:
        bad = [f"{n} = {v[n]:g}" for n in names if v[n] != 0]
        if bad:
            notes.append(
                f"{camera}: {', '.join(bad)} not used by DICe's {model} model; imported "
                "without them, as DICe projects"
            )

    odd = "odd powers of r are not in OpenCV's model"
    if kind == "none":
        unused(_DICE_INTRINSICS[5:])
        return [0.0] * 5, 1.0, False
    if kind == "opencv":
        refuse_unless_zero(("T1", "T2"), "tilted-sensor (Scheimpflug) terms are not supported")
        names = ("K1", "K2", "P1", "P2", "K3", "K4", "K5", "K6", "S1", "S2", "S3", "S4")
        return [v[n] for n in names], 1.0, False
    unused(_DICE_INTRINSICS[8:])
    if kind == "r3r5r7":  # factor 1 + K1 r^2 + K2 r^4 + K3 r^6: OpenCV's k1, k2, k3
        return [v["K1"], v["K2"], 0.0, 0.0, v["K3"]], 1.0, False
    if kind == "r2r4r6":  # factor 1 + K1 r + K2 r^3 + K3 r^5
        refuse_unless_zero(("K1", "K2", "K3"), odd)
        return [0.0] * 5, 1.0, False
    if kind == "r1r2r3":  # factor 1 + K1 + K2 r + K3 r^2 = s (1 + K3 / s r^2)
        refuse_unless_zero(("K2",), odd)
        scale = 1.0 + v["K1"]
        if not scale > 0:
            raise InputError(
                f"{path}: {camera} {model}: K1 = {v['K1']:g} folds the image (1 + K1 <= 0)"
            )
        return [v["K3"] / scale, 0.0, 0.0, 0.0, 0.0], scale, False
    # VIC3D_LENS_DISTORTION: factor 1 + K1 + K2 r (DICe leaves K3 out), the skew applied
    refuse_unless_zero(("K2",), odd)
    unused(("K3",))
    scale = 1.0 + v["K1"]
    if not scale > 0:
        raise InputError(
            f"{path}: {camera} {model}: K1 = {v['K1']:g} folds the image (1 + K1 <= 0)"
        )
    return [0.0] * 5, scale, True


def read_dice(path: str | os.PathLike, *, image_size=None, unit: str | None = None):
    """Read a DICe XML calibration (``cal.xml``, a Teuchos ParameterList).

    Parameters
    ----------
    path : the XML file
    image_size : (width, height) px, keyword-only
        Needed when the cameras have no ``IMAGE_HEIGHT_WIDTH``.
    unit : str, keyword-only
        The unit of the file's lengths (default mm).

    Returns
    -------
    Calibration
        ``CAMERA 0`` as the left camera; ``extra["notes"]`` says what DICe
        itself ignores (a skew outside its VIC-3D model).
    """
    path = Path(path)
    root = _parse(path)
    if _tag(root) != "parameterlist":
        raise InputError(f"{path}: not a DICe calibration (no <ParameterList>)")
    top, lists = _dice_params(root)
    if "CAMERA 0" not in lists or "CAMERA 1" not in lists:
        raise InputError(
            f"{path}: not a DICe stereo calibration: need ParameterLists 'CAMERA 0' and 'CAMERA 1'"
        )
    if "CAMERA 2" in lists:
        raise InputError(f"{path}: holds more than two cameras; the toolkit takes a pair")
    relative = top.get("EXTRINSICS_RELATIVE_CAMERA_TO_CAMERA", ("", "false"))[1].strip().lower()
    cams, poses, sizes, notes = [], [], [], []
    for i in (0, 1):
        camera = f"CAMERA {i}"
        params, sub = _dice_params(lists[camera])
        v = {n: _dice_number(params, n, path, camera) for n in _DICE_INTRINSICS}
        model = params.get("LENS_DISTORTION_MODEL", ("", "NO_LENS_DISTORTION"))[1].strip()
        dist, scale, skewed = _dice_distortion(v, model, path, camera, notes)
        skew = v["FS"] if skewed else 0.0
        if v["FS"] != 0 and not skewed:
            notes.append(
                f"{camera}: FS = {v['FS']:g} is not applied by DICe's {model} model; "
                "imported without skew, as DICe projects"
            )
        K = _camera_matrix(scale * v["FX"], scale * v["FY"], v["CX"], v["CY"], scale * skew)
        cams.append((K, dist))
        angles = [n for n in ("ALPHA", "BETA", "GAMMA") if n in params]
        if angles and "ROTATION_3X3_MATRIX" in sub:
            raise InputError(f"{path}: {camera} gives both Euler angles and a rotation matrix")
        if "ROTATION_3X3_MATRIX" in sub:
            rows, _ = _dice_params(sub["ROTATION_3X3_MATRIX"])
            R = np.array(
                [
                    _numbers(rows.get(f"ROW {j}", ("", ""))[1], path, f"{camera} ROW {j}", 3)
                    for j in range(3)
                ]
            )
        else:
            names = ("ALPHA", "BETA", "GAMMA")
            R = euler_rotation(*(_dice_number(params, n, path, camera) for n in names))
        T = np.array([_dice_number(params, n, path, camera) for n in ("TX", "TY", "TZ")])
        poses.append((R, T))
        if "IMAGE_HEIGHT_WIDTH" in params:
            text = params["IMAGE_HEIGHT_WIDTH"][1]
            h, w = _numbers(text, path, f"{camera} IMAGE_HEIGHT_WIDTH", 2)
            sizes.append((w, h))
    if len(set(sizes)) > 1:
        raise InputError(
            f"{path}: the cameras' IMAGE_HEIGHT_WIDTH differ ({sizes[0][1]:g}, {sizes[0][0]:g} "
            f"and {sizes[1][1]:g}, {sizes[1][0]:g}); the toolkit needs one image size"
        )
    found = None
    if sizes:
        w, h = sizes[0]
        if w != round(w) or h != round(h) or w < 1 or h < 1:
            raise InputError(f"{path}: IMAGE_HEIGHT_WIDTH must be whole pixels > 0")
        found = (int(w), int(h))
    R, T = _rig(poses, relative == "true")
    return _make(path, "dice", _size(found, image_size, path), cams, R, T, notes, unit)


def _fmt(value: float) -> str:
    return repr(float(value))


def write_vic3d(calib, path: str | os.PathLike, *, overwrite: bool = False) -> None:
    """Write a calibration as VIC-3D's ``<calibration>`` XML (camera 0 at the identity).

    The file appears whole or not at all (:func:`tissue_core.outputs.atomic_file`);
    an existing one is replaced only with ``overwrite`` and only when the toolkit
    wrote it.

    Raises
    ------
    InputError
        Distortion VIC-3D cannot hold (tangential, rational, thin-prism terms).
    """
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<calibration>"]
    poses = [(np.eye(3), np.zeros(3)), (calib.R, calib.T)]
    for i, (K, d) in enumerate(((calib.K_left, calib.dist_left), (calib.K_right,
                                                                  calib.dist_right))):  # fmt: skip
        d = np.concatenate([np.asarray(d, float), np.zeros(12)])
        if np.any(d[[2, 3]] != 0) or np.any(d[5:12] != 0):
            raise InputError(
                f"camera {i}: VIC-3D holds radial distortion only (kappa1..3); this "
                "calibration has tangential, rational or thin-prism terms"
            )
        intr = [K[0, 2], K[1, 2], K[0, 0], K[1, 1], K[0, 1], d[0], d[1], d[4]]
        R, t = poses[i]
        pose = [*_euler_angles(np.asarray(R)), *np.asarray(t, float)]
        lines.append(
            f'  <camera id="{i}">{" ".join(map(_fmt, intr))}'
            f"<orientation>{' '.join(map(_fmt, pose))}</orientation></camera>"
        )
    w, h = calib.image_size
    lines += [f'  <polygonmask width="{w}" height="{h}"/>', "</calibration>", ""]
    _write_text(path, "\n".join(lines), overwrite=overwrite)


def write_dice(calib, path: str | os.PathLike, *, overwrite: bool = False) -> None:
    """Write a calibration as a DICe XML ``ParameterList`` (``OPENCV_LENS_DISTORTION``).

    Written like :func:`write_vic3d`: whole or not at all, replacing a file only
    with ``overwrite``.

    Raises
    ------
    InputError
        A skewed camera: DICe's OpenCV model ignores ``FS``.
    """
    names = ("K1", "K2", "P1", "P2", "K3", "K4", "K5", "K6", "S1", "S2", "S3", "S4")
    w, h = calib.image_size
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<ParameterList>",
        '  <Parameter name="xml_file_format" type="string" value="DICe_xml_camera_system_file" />',
        '  <Parameter name="system_type_3D" type="string" value="OPENCV" />',
        '  <Parameter name="extrinsics_relative_camera_to_camera" type="bool" value="false" />',
    ]
    poses = [(np.eye(3), np.zeros(3)), (np.asarray(calib.R), np.asarray(calib.T))]
    for i, (K, d) in enumerate(((calib.K_left, calib.dist_left), (calib.K_right,
                                                                  calib.dist_right))):  # fmt: skip
        if K[0, 1] != 0:
            raise InputError(
                f"camera {i}: skew {K[0, 1]:g} px: DICe's OPENCV_LENS_DISTORTION model ignores FS"
            )
        d = np.concatenate([np.asarray(d, float), np.zeros(12)])[:12]
        out.append(f'  <ParameterList name="CAMERA {i}">')
        for name, value in (("CX", K[0, 2]), ("CY", K[1, 2]), ("FX", K[0, 0]), ("FY", K[1, 1]),
                            *zip(names, d, strict=True)):  # fmt: skip
            out.append(f'    <Parameter name="{name}" type="double" value="{_fmt(value)}" />')
        out.append(
            '    <Parameter name="LENS_DISTORTION_MODEL" type="string" '
            'value="OPENCV_LENS_DISTORTION" />'
        )
        R, t = poses[i]
        for name, value in zip(("TX", "TY", "TZ"), t, strict=True):
            out.append(f'    <Parameter name="{name}" type="double" value="{_fmt(value)}" />')
        out.append('    <ParameterList name="rotation_3x3_matrix">')
        for j in range(3):
            row = ", ".join(map(_fmt, R[j]))
            out.append(f'      <Parameter name="ROW {j}" type="string" value="{{ {row} }}" />')
        out.append("    </ParameterList>")
        out.append(
            f'    <Parameter name="IMAGE_HEIGHT_WIDTH" type="string" value="{{ {h}, {w} }}" />'
        )
        out.append("  </ParameterList>")
    out += ["</ParameterList>", ""]
    _write_text(path, "\n".join(out), overwrite=overwrite)


def _write_text(path: str | os.PathLike, text: str, *, overwrite: bool) -> None:
    from tissue_core.outputs import atomic_file

    with atomic_file(path, overwrite=overwrite) as tmp:
        tmp.write_text(text, encoding="utf-8")


_SIZE = re.compile(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$")


def parse_image_size(text: str) -> tuple[int, int]:
    """``"WxH"`` -> ``(W, H)`` px.

    >>> parse_image_size("2448x2048")
    (2448, 2048)
    """
    m = _SIZE.match(str(text))
    if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
        raise InputError(
            f"--image-size must be WIDTHxHEIGHT in pixels, e.g. 2448x2048, got {text!r}"
        )
    return int(m.group(1)), int(m.group(2))
