"""``python -m stereo`` on broken, hostile and conflicting input: every command ends with one
line naming the file or option and the problem (exit 2), leaves its inputs and anything of the
user's byte-identical, and writes nothing; Ctrl-C during a real run ends with exit 130 and no
output (see :mod:`tests.badinput`)."""

from __future__ import annotations

import copy
import json
import shutil
import signal
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

import tissue_core.resources as resources
from stereo.cli import main
from tests.badinput import (
    FAMILIES,
    WRITING,
    assert_refused,
    interrupt,
    killed,
    scratch_left,
    snapshot,
    stale_scratch,
    write,
)
from tests.filenames import assert_ran, assert_refused_process, latin1, shown, strict_json
from tests.stereo.conftest import SMALL_SIZE, SmallStereo, write_opencv_yaml
from tissue_core.outputs import atomic_dir

W, H = SMALL_SIZE


def run(argv: list[str]) -> int:
    """``main``, with argparse's own refusals (SystemExit) as an exit status too."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


# --------------------------------------------------------------------------- broken files


def cut(source: Path, tmp: Path, name: str | None = None) -> Path:
    """The first half of ``source`` (a copy cut short, as by a full disk or a killed copy)."""
    data = source.read_bytes()
    return write(tmp, name or source.name, data[: len(data) // 2])


def folder_with(source: Path, tmp: Path, name: str, change: Callable[[Path], None]) -> Path:
    """A copy of the frames folder ``source`` with ``change`` applied to it."""
    folder = tmp / name
    shutil.copytree(source, folder)
    change(folder)
    return folder


def calib_json(s: SmallStereo, tmp: Path, change: Callable[[dict], None], name="calib.json"):
    """The true calibration JSON with ``change`` applied to its dict."""
    data = json.loads(s.calib.read_text())
    change(data)
    return write(tmp, name, json.dumps(data, indent=2))


def calib_yml(s: SmallStereo, tmp: Path, change: Callable[[dict], None], name="stereo.yml"):
    """The true calibration as an OpenCV YAML file with ``change`` applied first."""
    data = copy.deepcopy(json.loads(s.calib.read_text()))
    change(data)
    path = tmp / name
    write_opencv_yaml(path, data)
    return path


def setter(path: tuple, value) -> Callable[[dict], None]:
    def change(d: dict) -> None:
        target = d
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return change


def points_csv(tmp: Path, text: str, name="points.csv") -> Path:
    return write(tmp, name, text)


def sheet_points(s: SmallStereo) -> list[str]:
    """Rows ``x,y`` of the sheet's points."""
    return [f"{x!r},{y!r}" for x, y in s.truth["left_px"][0]]


R2I = [[2.0, 0, 0], [0, 2.0, 0], [0, 0, 2.0]]
REFLECTION = [[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]]

# --------------------------------------------------------------------------- command lines


def base(command: str, s: SmallStereo, tmp: Path) -> dict:
    """The options of a command that would run, in order; positionals under ``_N`` keys."""
    if command == "calibrate":
        board = "checkerboard:9x6:10"
        out = tmp / "calib.json"
        return {"--left": s.views_left, "--right": s.views_right, "--board": board,
                "--out": out, "-q": True}  # fmt: skip
    if command == "import-calib":
        return {"_1": s.yml, "--out": tmp / "calib.json"}
    if command == "match":
        return {"_1": s.left0, "_2": s.right0, "--points": s.points, "--calib": s.calib,
                "--out": tmp / "matches.csv", "-q": True}  # fmt: skip
    return {"--calib": s.calib, "--left": s.left, "--right": s.right, "--points": s.points,
            "--out": tmp / "rec", "-q": True}  # fmt: skip


def command_line(command: str, options: dict) -> list[str]:
    argv = [command]
    for key, value in options.items():
        if value is None or value is False:
            continue
        if key.startswith("_"):
            argv += [str(v) for v in value] if isinstance(value, list) else [str(value)]
        elif value is True:
            argv.append(key)
        elif isinstance(value, list):
            argv += [key, *map(str, value)]
        else:
            argv += [key, str(value)]
    return argv


COMMANDS = ("calibrate", "import-calib", "match", "reconstruct")
CASES: list = []


def case(name: str):
    """Register the case ``COMMAND-FAMILY-CASE``: a function of (inputs, tmp_path) giving the
    options to change and the fragments the error line must hold (the file or option, and the
    problem)."""
    command = next(c for c in COMMANDS if name.startswith(f"{c}-"))
    rest = name[len(command) + 1 :]
    assert any(rest.startswith(f"{family}-") for family in FAMILIES), name

    def register(build: Callable[[SmallStereo, Path], tuple[dict, list[str]]]):
        CASES.append(pytest.param(command, build, id=name))
        return build

    return register


def user_file(tmp: Path, name: str) -> Path:
    return write(tmp, name, "my notes: do not lose them\n")


def user_folder(tmp: Path, name: str) -> Path:
    folder = tmp / name
    folder.mkdir()
    write(folder, "thesis.tex", "the work of years")
    return folder


def earlier_result_with_a_user_file(tmp: Path, name: str) -> Path:
    folder = tmp / name
    with atomic_dir(folder) as result:
        write(result, "points3d.csv", "frame,point,X,Y,Z,reproj_error,visible\n")
    write(folder, "my_notes.txt", "added by the user afterwards")
    return folder


def jpeg_copy(source: Path, tmp: Path, name: str) -> Path:
    import cv2

    path = tmp / name
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.imread(str(source), cv2.IMREAD_GRAYSCALE))
    return path


def resized_copy(source: Path, tmp: Path, size: tuple[int, int]) -> Path:
    import cv2

    path = tmp / "resized.png"
    cv2.imwrite(str(path), cv2.resize(cv2.imread(str(source), cv2.IMREAD_GRAYSCALE), size))
    return path


# ---- every command: output problems

OUTPUT_NAMES = {"calibrate": "calib.json", "import-calib": "calib.json", "match": "matches.csv"}
for command, name in OUTPUT_NAMES.items():

    @case(f"{command}-output-existing-user-file")
    def _(s, t, name=name):
        return {"--out": user_file(t, name)}, [name, "not a file this toolkit wrote"]

    @case(f"{command}-output-existing-user-file-overwrite")
    def _(s, t, name=name):
        changes = {"--out": user_file(t, name), "--overwrite": True}
        return changes, [name, "not a file this toolkit wrote"]

    @case(f"{command}-output-existing-folder")
    def _(s, t, name=name):
        return {"--out": user_folder(t, name)}, [name, "is a folder"]

    @case(f"{command}-output-existing-folder-overwrite")
    def _(s, t, name=name):
        return {"--out": user_folder(t, name), "--overwrite": True}, [name, "is a folder"]


for command, name in (*OUTPUT_NAMES.items(), ("reconstruct", "rec")):

    @case(f"{command}-output-missing-parent-folder")
    def _(s, t, name=name):
        return {"--out": t / "no" / "such" / name}, ["does not exist"]


@case("calibrate-output-out-is-an-input-image")
def _(s, t):
    image = s.views_left / "view_00.png"
    changes = {"--left": image, "--right": s.views_right / "view_00.png", "--out": image}
    return {**changes, "--overwrite": True}, ["would replace the input"]


@case("calibrate-output-inside-an-input-folder")
def _(s, t):
    return {"--out": s.views_left / "calib.json"}, ["inside the input folder"]


@case("import-calib-output-out-is-the-input")
def _(s, t):
    return {"_1": s.calib, "--out": s.calib, "--overwrite": True}, ["would replace the input"]


@case("match-output-out-is-the-points")
def _(s, t):
    return {"--out": s.points, "--overwrite": True}, ["would replace the input"]


@case("match-output-out-is-an-image")
def _(s, t):
    return {"--out": s.left0, "--overwrite": True}, ["would replace the input"]


@case("reconstruct-output-out-is-the-calibration")
def _(s, t):
    return {"--out": s.calib, "--overwrite": True}, ["would replace the input"]


@case("reconstruct-output-inside-the-left-folder")
def _(s, t):
    return {"--out": s.left / "rec"}, ["inside the input folder"]


@case("reconstruct-output-holds-the-left-folder")
def _(s, t):
    return {"--out": s.left.parent, "--overwrite": True}, ["would replace the input"]


@case("reconstruct-output-existing-user-folder")
def _(s, t):
    return {"--out": user_folder(t, "rec")}, ["not a result of this toolkit"]


@case("reconstruct-output-existing-user-folder-overwrite")
def _(s, t):
    return {"--out": user_folder(t, "rec"), "--overwrite": True}, ["not a result of this toolkit"]


@case("reconstruct-output-earlier-result-without-overwrite")
def _(s, t):
    return {"--out": earlier_result_with_a_user_file(t, "rec")}, ["--overwrite"]


@case("reconstruct-output-earlier-result-holding-a-user-file")
def _(s, t):
    out = earlier_result_with_a_user_file(t, "rec")
    return {"--out": out, "--overwrite": True}, ["my_notes.txt"]


@case("reconstruct-output-existing-file")
def _(s, t):
    return {"--out": user_file(t, "rec")}, ["is a file"]


@case("reconstruct-output-existing-file-overwrite")
def _(s, t):
    return {"--out": user_file(t, "rec"), "--overwrite": True}, ["is a file"]


# ---- calibrate: the target images


@case("calibrate-missing-left-glob-matches-nothing")
def _(s, t):
    return {"--left": f"{t}/none_*.png"}, ["--left", "matches no image files"]


@case("calibrate-missing-right-folder")
def _(s, t):
    return {"--right": t / "nowhere"}, ["--right", "matches no image files"]


@case("calibrate-empty-left-folder")
def _(s, t):
    (t / "left").mkdir()
    return {"--left": t / "left"}, ["--left", "matches no image files"]


@case("calibrate-empty-image-file")
def _(s, t):
    left = folder_with(s.views_left, t, "left", lambda f: (f / "view_02.png").write_bytes(b""))
    return {"--left": left}, ["view_02.png", "empty"]


@case("calibrate-truncated-png")
def _(s, t):
    left = folder_with(s.views_left, t, "left", lambda f: cut(f / "view_03.png", f))
    return {"--left": left}, ["view_03.png", "truncated"]


@case("calibrate-truncated-jpeg")
def _(s, t):
    for side, views in (("left", s.views_left), ("right", s.views_right)):
        for png in sorted(views.glob("*.png")):
            jpeg_copy(png, t / side, f"{png.stem}.jpg")
    cut(t / "left" / "view_01.jpg", t / "left")
    return {"--left": t / "left", "--right": t / "right"}, ["view_01.jpg", "truncated"]


@case("calibrate-wrong-type-text-as-png")
def _(s, t):
    left = folder_with(s.views_left, t, "left", lambda f: (f / "view_01.png").write_text("hello"))
    return {"--left": left}, ["view_01.png", "not an image"]


@case("calibrate-wrong-type-folder-as-png")
def _(s, t):
    def swap(folder: Path) -> None:
        (folder / "view_04.png").unlink()
        (folder / "view_04.png").mkdir()

    return {"--right": folder_with(s.views_right, t, "right", swap)}, ["view_04.png", "folder"]


@case("calibrate-empty-folder-without-images")
def _(s, t):
    write(t / "right", "notes.txt", "view 3 was blurred")
    return {"--right": t / "right"}, ["--right", "matches no image files"]


@case("calibrate-wrong-type-videos-as-images")
def _(s, t):
    return {"--left": s.left_video, "--right": s.right_video}, ["left.avi", "not an image"]


@case("calibrate-option-board-unknown-dictionary")
def _(s, t):
    return {"--board": "charuco:11x8:8:6:DICT_NOPE"}, ["DICT_NOPE"]


@case("calibrate-option-board-spec")
def _(s, t):
    return {"--board": "square:9x6"}, ["--board must be"]


@case("calibrate-option-board-negative-square")
def _(s, t):
    return {"--board": "checkerboard:9x6:-10"}, ["--board", "positive square"]


@case("calibrate-option-board-nan-square")
def _(s, t):
    return {"--board": "checkerboard:9x6:nan"}, ["--board", "positive square"]


@case("calibrate-option-board-2x2")
def _(s, t):
    return {"--board": "checkerboard:2x2:10"}, ["--board", "at least 3 x 3"]


@case("calibrate-option-charuco-marker-larger-than-square")
def _(s, t):
    return {"--board": "charuco:11x8:8:9:DICT_4X4_50"}, ["--board", "marker"]


@case("calibrate-option-unit-empty")
def _(s, t):
    return {"--unit": ""}, ["--unit"]


@case("calibrate-conflict-unequal-image-counts")
def _(s, t):
    right = folder_with(s.views_right, t, "right", lambda f: (f / "view_04.png").unlink())
    return {"--right": right}, ["unequal image counts", "5 left and 4 right"]


@case("calibrate-conflict-images-differ-in-size")
def _(s, t):
    import cv2

    for side, size in (("left", (64, 48)), ("right", (60, 48))):
        (t / side).mkdir()
        for k in range(2):
            cv2.imwrite(str(t / side / f"v{k}.png"), np.zeros(size[::-1], np.uint8))
    return {"--left": t / "left", "--right": t / "right"}, ["differ in size"]


# ---- calibrate: calibrations that cannot be physical


@case("calibrate-calibration-board-4x4-on-a-9x6-target")
def _(s, t):
    """OpenCV finds a 4 x 4 corner pattern inside the 9 x 6 board (the calibration came out
    at RMS 15 px and a 600 mm baseline for a 120 mm one)."""
    fragments = ["view_00.png", "--board checkerboard:4x4:10", "the images hold 9x6 inner corners",
                 "e.g. --board checkerboard:9x6:10"]  # fmt: skip
    return {"--board": "checkerboard:4x4:10"}, fragments


@case("calibrate-calibration-board-one-column-short")
def _(s, t):
    return {"--board": "checkerboard:8x6:10"}, ["the images hold 9x6 inner corners"]


@case("calibrate-calibration-left-and-right-the-same-folder")
def _(s, t):
    return {"--right": s.views_left}, ["--left", "--right", "name the same images", "view_00.png"]


@case("calibrate-calibration-left-and-right-globs-sharing-images")
def _(s, t):
    changes = {"--left": f"{s.views_left}/view_0[0-4].png", "--right": f"{s.views_left}/*.png"}
    return changes, ["name the same images", "and 4 more"]


@case("calibrate-calibration-copies-of-the-left-images-as-the-right")
def _(s, t):
    shutil.copytree(s.views_left, t / "right")
    return {"--right": t / "right"}, ["view_00.png / view_00.png", "the same picture"]


@case("calibrate-calibration-pairs-out-of-step")
def _(s, t):
    """The right images listed one place off (renamed, or sorted another way): each camera
    calibrates, the rig cannot."""
    files = sorted(s.views_right.glob("*.png"))
    (t / "right").mkdir()
    for source, target in zip(files, files[1:] + files[:1], strict=True):
        shutil.copy(source, t / "right" / target.name)
    return {"--right": t / "right"}, ["RMS reprojection error", "at most 5 px", "same moment"]


# ---- import-calib (and every reader of a calibration)


@case("import-calib-missing-file")
def _(s, t):
    return {"_1": t / "stereo.yml"}, ["stereo.yml", "not found"]


@case("import-calib-missing-second-file")
def _(s, t):
    return {"_1": [s.yml, t / "extrinsics.yml"]}, ["extrinsics.yml", "not found"]


@case("import-calib-empty-yml")
def _(s, t):
    return {"_1": write(t, "stereo.yml", b"")}, ["stereo.yml", "empty"]


@case("import-calib-empty-json")
def _(s, t):
    return {"_1": write(t, "in.json", b"")}, ["in.json", "empty"]


@case("import-calib-empty-json-object")
def _(s, t):
    return {"_1": write(t, "in.json", "{}")}, ["in.json", "image_size"]


@case("import-calib-empty-yml-without-matrices")
def _(s, t):
    return {"_1": write(t, "stereo.yml", "%YAML:1.0\n---\nname: rig\n")}, ["stereo.yml", "M1"]


@case("import-calib-truncated-yml")
def _(s, t):
    return {"_1": cut(s.yml, t)}, ["stereo.yml"]


@case("import-calib-truncated-json")
def _(s, t):
    return {"_1": cut(s.calib, t, "in.json")}, ["in.json", "not a valid calibration JSON"]


@case("import-calib-wrong-type-png-as-yml")
def _(s, t):
    path = write(t, "stereo.yml", s.left0.read_bytes())
    return {"_1": path}, ["stereo.yml", "not a readable calibration file"]


@case("import-calib-wrong-type-png-as-json")
def _(s, t):
    path = write(t, "in.json", s.left0.read_bytes())
    return {"_1": path}, ["in.json", "not a valid calibration JSON"]


@case("import-calib-wrong-type-folder")
def _(s, t):
    return {"_1": s.left}, [str(s.left), "folder"]


@case("import-calib-wrong-type-json-list")
def _(s, t):
    return {"_1": write(t, "in.json", "[1, 2, 3]")}, ["in.json", "object"]


@case("import-calib-wrong-type-json-nested-too-deep")
def _(s, t):
    return {"_1": write(t, "in.json", "{" + '"a": [' * 100_000)}, ["in.json"]


#: calibration contents: (name, change of the JSON dict, fragments of the error line)
BAD_CALIBRATIONS = [
    ("R-is-2I", setter(("R",), R2I), ["R", "rotation"]),
    ("R-is-a-reflection", setter(("R",), REFLECTION), ["R", "rotation"]),
    ("negative-focal-length", setter(("K_left", 0, 0), -1400.0), ["K_left", "focal"]),
    ("nan-in-K", setter(("K_left", 0, 2), float("nan")), ["K_left", "finite"]),
    ("inf-in-T", setter(("T", 1), float("inf")), ["T", "finite"]),
    ("string-in-R", setter(("R", 0, 0), "1"), ["R", "numbers"]),
    ("boolean-in-K", setter(("K_right", 2, 2), True), ["K_right", "numbers"]),
    ("K-2x3", setter(("K_left",), [[1400.0, 0, 256], [0, 1400, 192]]), ["K_left", "3 x 3"]),
    ("zero-focal-length", setter(("K_right", 1, 1), 0.0), ["K_right", "focal"]),
    ("K-last-row", setter(("K_left", 2), [0.0, 0.0, 2.0]), ["K_left", "[0, 0, 1]"]),
    ("distortion-of-6", setter(("dist_left",), [0.1, 0, 0, 0, 0, 0]), ["dist_left", "6"]),
    ("distortion-of-3", setter(("dist_right",), [0.1, 0, 0]), ["dist_right", "3"]),
    ("image-size-fraction", setter(("image_size",), [512.5, 384]), ["image_size"]),
    ("image-size-zero", setter(("image_size",), [0, 384]), ["image_size"]),
    ("image-size-three", setter(("image_size",), [512, 384, 3]), ["image_size"]),
    ("image-size-text", setter(("image_size",), "512x384"), ["image_size"]),
    ("T-zero", setter(("T",), [0.0, 0.0, 0.0]), ["T", "baseline"]),
    ("T-2-values", setter(("T",), [120.0, 0.0]), ["T", "3"]),
    ("rms-text", setter(("rms_px",), "small"), ["rms_px"]),
    ("unit-number", setter(("unit",), 5), ["unit"]),
    ("missing-R", lambda d: d.pop("R"), ["R", "missing"]),
]
for name, change, fragments in BAD_CALIBRATIONS:

    @case(f"import-calib-wrong-type-json-{name}")
    def _(s, t, change=change, fragments=fragments):
        return {"_1": calib_json(s, t, change, "in.json")}, ["in.json", *fragments]


BAD_YAML = [
    ("R-is-2I", setter(("R",), R2I), ["R", "rotation"]),
    ("negative-focal-length", setter(("K_right", 0, 0), -1400.0), ["M2", "focal"]),
    ("nan-in-K", setter(("K_left", 0, 2), float("nan")), ["M1", "finite"]),
    ("distortion-of-6", setter(("dist_left",), [0.1, 0, 0, 0, 0, 0]), ["D1", "6"]),
    ("image-size-inf", setter(("image_size",), [float("inf"), 384]), ["image_size"]),
    ("image-size-nan", setter(("image_size",), [512, float("nan")]), ["image_size"]),
    ("T-zero", setter(("T",), [0.0, 0.0, 0.0]), ["T", "baseline"]),
]
for name, change, fragments in BAD_YAML:

    @case(f"import-calib-wrong-type-yml-{name}")
    def _(s, t, change=change, fragments=fragments):
        return {"_1": calib_yml(s, t, change)}, ["stereo.yml", *fragments]


@case("import-calib-wrong-type-yml-pair-R-is-2I")
def _(s, t):
    """intrinsics.yml and extrinsics.yml, as OpenCV's stereo sample writes them: the error
    names the file that holds R."""
    import cv2

    data = json.loads(s.calib.read_text())
    intrinsics = cv2.FileStorage(str(t / "intrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    for key, name in (("K_left", "M1"), ("dist_left", "D1"), ("K_right", "M2"),
                      ("dist_right", "D2"), ("image_size", "image_size")):  # fmt: skip
        intrinsics.write(name, np.asarray(data[key], np.float64))
    intrinsics.release()
    extrinsics = cv2.FileStorage(str(t / "extrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    extrinsics.write("R", np.asarray(R2I))
    extrinsics.write("T", np.asarray(data["T"], np.float64))
    extrinsics.release()
    files = [t / "intrinsics.yml", t / "extrinsics.yml"]
    return {"_1": files}, ["extrinsics.yml", "R", "rotation"]


@case("import-calib-wrong-type-yml-R-is-text")
def _(s, t):
    text = s.yml.read_text().replace("R: !!opencv-matrix", 'R: "identity"\nX: !!opencv-matrix')
    return {"_1": write(t, "stereo.yml", text)}, ["stereo.yml", "R", "numbers"]


@case("import-calib-wrong-type-yml-without-image-size")
def _(s, t):
    write_opencv_yaml(t / "stereo.yml", json.loads(s.calib.read_text()), image_size=False)
    return {"_1": t / "stereo.yml"}, ["stereo.yml", "image size"]


@case("import-calib-conflict-json-and-yml")
def _(s, t):
    return {"_1": [s.calib, s.yml]}, ["one calibration JSON"]


@case("import-calib-conflict-yml-and-json")
def _(s, t):
    return {"_1": [s.yml, s.calib]}, ["one calibration JSON"]


@case("import-calib-option-unit-blank")
def _(s, t):
    return {"--unit": " "}, ["--unit"]


#: calibrations that cannot be physical, as every reader meets them: (name, file, fragments)
UNPHYSICAL = [
    ("T-half-a-mm", lambda s, t: calib_json(s, t, setter(("T",), [0.5, 0.0, 0.0]), "rig.json"),
     ["rig.json", "T gives the baseline |T| = 0.5 mm", "never closer than 1 mm"]),
    ("T-in-metres-read-as-mm", lambda s, t: calib_yml(
        s, t, lambda d: d.update(T=(np.asarray(d["T"]) / 1000).tolist())),
     ["stereo.yml", "T gives the baseline", "--unit"]),
    ("rms-15-px", lambda s, t: calib_json(s, t, setter(("rms_px",), 15.0), "rig.json"),
     ["rig.json", "rms_px is 15 px", "no real rig"]),
]  # fmt: skip
for name, make, fragments in UNPHYSICAL:

    @case(f"import-calib-calibration-{name}")
    def _(s, t, make=make, fragments=fragments):
        return {"_1": make(s, t)}, fragments

    for command in ("match", "reconstruct"):

        @case(f"{command}-calibration-{name}")
        def _(s, t, make=make, fragments=fragments):
            return {"--calib": make(s, t)}, fragments


@case("import-calib-calibration-unit-um-for-a-rig-in-mm")
def _(s, t):
    return {"--unit": "um"}, ["stereo.yml", "|T| = 120 um (0.12 mm)", "never closer than 1 mm"]


@case("reconstruct-calibration-cameras-2-mm-apart")
def _(s, t):
    """A rig whose cameras are 2 mm apart, 300 mm from the sheet: its calibration is right,
    but the rays to a point meet at 0.4 degrees and depth is not measured."""
    import dataclasses

    from sample_data_synth.stereo import default_rig, render_surface_scene, save_stereo_scene
    from stereo.calibration import load_calibration

    rig = default_rig(image_size=SMALL_SIZE)
    close = dataclasses.replace(rig, T=rig.T / np.linalg.norm(rig.T) * 2.0)
    scene = render_surface_scene(close, "stretch", n_frames=2, supersample=1, distance=300.0,
                                 rng=1)  # fmt: skip
    save_stereo_scene(t / "scene", scene)
    load_calibration(t / "scene" / "rig.json").save(t / "calib.json")
    changes = {"--calib": t / "calib.json", "--left": t / "scene" / "left",
               "--right": t / "scene" / "right"}  # fmt: skip
    return changes, ["the cameras are 2 mm apart for the surface", "depth is not measured"]


# ---- match and reconstruct: the calibration they read

for command in ("match", "reconstruct"):

    @case(f"{command}-missing-calibration")
    def _(s, t):
        return {"--calib": t / "calib.json"}, ["calib.json", "not found"]

    @case(f"{command}-empty-calibration")
    def _(s, t):
        return {"--calib": write(t, "calib.json", b"")}, ["calib.json", "empty"]

    @case(f"{command}-truncated-calibration")
    def _(s, t):
        return {"--calib": cut(s.calib, t)}, ["calib.json", "not a valid calibration JSON"]

    @case(f"{command}-wrong-type-png-as-calibration")
    def _(s, t):
        return {"--calib": write(t, "calib.json", s.left0.read_bytes())}, ["calib.json"]

    for name, change, fragments in BAD_CALIBRATIONS[:4]:

        @case(f"{command}-wrong-type-calibration-{name}")
        def _(s, t, change=change, fragments=fragments):
            return {"--calib": calib_json(s, t, change)}, ["calib.json", *fragments]

    @case(f"{command}-wrong-type-calibration-for-another-image-size")
    def _(s, t):
        path = calib_json(s, t, setter(("image_size",), [640, 480]))
        return {"--calib": path}, ["calib.json is for 640x480 images", f"is {W}x{H}"]

    @case(f"{command}-wrong-type-yml-calibration-R-is-2I")
    def _(s, t):
        return {"--calib": calib_yml(s, t, setter(("R",), R2I))}, ["stereo.yml", "rotation"]

    @case(f"{command}-conflict-calibration-json-and-yml")
    def _(s, t):
        return {"--calib": [s.calib, s.yml]}, ["one calibration JSON"]


# ---- match: the images and options


@case("match-missing-left-image")
def _(s, t):
    return {"_1": t / "left.png"}, ["left.png", "no such file"]


@case("match-missing-right-image")
def _(s, t):
    return {"_2": t / "right.png"}, ["right.png", "no such file"]


@case("match-empty-left-image")
def _(s, t):
    return {"_1": write(t, "left.png", b"")}, ["left.png", "empty"]


@case("match-truncated-left-png")
def _(s, t):
    return {"_1": cut(s.left0, t, "left.png")}, ["left.png", "truncated"]


def tiff_copy(png: Path, folder: Path, name: str) -> Path:
    """A PNG's gray image as a TIFF file."""
    import cv2
    import tifffile

    folder.mkdir(parents=True, exist_ok=True)
    tifffile.imwrite(folder / name, cv2.imread(str(png), cv2.IMREAD_GRAYSCALE))
    return folder / name


@case("match-truncated-left-tif")
def _(s, t):
    tif = tiff_copy(s.left0, t / "whole", "left.tif")
    return {"_1": cut(tif, t)}, ["left.tif is truncated", "runs to byte"]


@case("match-truncated-right-jpeg")
def _(s, t):
    jpeg = jpeg_copy(s.right0, t / "whole", "right.jpg")
    return {"_2": cut(jpeg, t)}, ["right.jpg", "truncated"]


@case("match-wrong-type-text-as-png")
def _(s, t):
    return {"_2": write(t, "right.png", "not an image")}, ["right.png", "not an image"]


@case("match-wrong-type-folder-as-image")
def _(s, t):
    return {"_1": s.left}, [str(s.left), "folder"]


@case("match-wrong-type-points-folder")
def _(s, t):
    return {"--points": s.left}, [str(s.left), "folder"]


@case("match-wrong-type-points-png")
def _(s, t):
    return {"--points": s.left0}, [s.left0.name]


@case("match-conflict-images-differ-in-size")
def _(s, t):
    return {"_2": resized_copy(s.right0, t, (W - 2, H))}, ["differ in size"]


for value, fragment in (("-1", "positive"), ("0", "positive"), ("nan", "positive"),
                        ("inf", "positive"), ("one", "invalid float")):  # fmt: skip

    @case(f"match-option-max-epipolar-{value}")
    def _(s, t, value=value, fragment=fragment):
        return {"--max-epipolar": value}, ["--max-epipolar", fragment]


for value in ("2", "-41", "40"):

    @case(f"match-option-match-subset-{value}")
    def _(s, t, value=value):
        return {"--match-subset": value}, ["--match-subset", "odd"]


@case("match-option-match-subset-larger-than-the-image")
def _(s, t):
    return {"--match-subset": 1001}, ["--match-subset", f"{W}x{H}"]


# ---- match and reconstruct: the points

#: (case, CSV text, fragments after the file name)
BAD_POINTS = [
    ("nan", "x,y\n300,150\nnan,200\n350,220\n", ["point 1", "finite"]),
    ("inf", "x,y\n300,150\n320,inf\n350,220\n", ["point 1", "finite"]),
    ("text", "x,y\n300,150\nabc,200\n350,220\n", ["numbers"]),
    ("empty-cell", "x,y\n300,150\n,200\n350,220\n", ["numbers"]),
    ("duplicate", "x,y\n300,150\n320,200\n300,150\n350,220\n", ["point 2", "twice"]),
    ("missing-column", "x,z\n300,150\n320,200\n", ["x,y"]),
    ("semicolons", "x;y\n300;150\n320;200\n", ["x,y"]),
    ("bom-and-missing-column", "\ufeffx\n300\n", ["x,y"]),
    ("empty-file", "", ["x,y"]),
    ("header-only", "x,y\n", ["no points"]),
    ("outside-the-image", f"x,y\n300,150\n{W + 5},200\n350,220\n", ["point 1", "outside"]),
    ("negative", "x,y\n300,150\n-3,200\n350,220\n", ["point 1", "outside"]),
    # a decimal comma (320,5 for 320.5) makes one cell too many; a cell missing
    ("ragged-decimal-comma", "x,y\n300,150\n320,5,200\n350,220\n",
     ["line 3: 3 cells where the header has 2 (a decimal comma?): 320,5,200"]),
    ("ragged-first-row", "x,y\n300,5,150\n320,200\n350,220\n", ["line 2: 3 cells"]),
    ("ragged-short-row", "x,y\n300,150\n320\n350,220\n",
     ["line 3: 1 cell where the header has 2"]),
]  # fmt: skip
for command in ("match", "reconstruct"):
    for name, text, fragments in BAD_POINTS:

        @case(f"{command}-csv-{name}")
        def _(s, t, text=text, fragments=fragments):
            return {"--points": write(t, "points.csv", text)}, ["points.csv", *fragments]

    @case(f"{command}-csv-not-utf8")
    def _(s, t):
        return {"--points": write(t, "points.csv", b"x,y\n\xff\xfe1,2\n")}, ["points.csv"]

    @case(f"{command}-missing-points")
    def _(s, t):
        return {"--points": t / "points.csv"}, ["points.csv"]


@case("reconstruct-csv-two-points")
def _(s, t):
    return {"--points": write(t, "points.csv", "x,y\n300,150\n320,200\n")}, ["at least 3"]


@case("reconstruct-csv-collinear")
def _(s, t):
    path = write(t, "points.csv", "x,y\n300,150\n310,160\n320,170\n")
    return {"--points": path}, ["points.csv", "collinear"]


# ---- reconstruct: the videos and options


@case("reconstruct-missing-left-folder")
def _(s, t):
    return {"--left": t / "left"}, [str(t / "left"), "no such file"]


@case("reconstruct-missing-right-video")
def _(s, t):
    return {"--left": s.left_video, "--right": t / "right.avi"}, ["right.avi", "no such file"]


@case("reconstruct-empty-left-folder")
def _(s, t):
    (t / "left").mkdir()
    return {"--left": t / "left"}, [str(t / "left"), "no images"]


@case("reconstruct-empty-right-video")
def _(s, t):
    return {"--left": s.left_video, "--right": write(t, "right.avi", b"")}, ["right.avi"]


@case("reconstruct-truncated-right-video")
def _(s, t):
    return {"--left": s.left_video, "--right": cut(s.right_video, t)}, ["right.avi"]


@case("reconstruct-truncated-tif-movie")
def _(s, t):
    import cv2
    import tifffile

    frames = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in sorted(s.right.glob("*.png"))]
    tifffile.imwrite(t / "whole.tif", np.stack(frames))
    data = (t / "whole.tif").read_bytes()
    right = write(t, "right.tif", data[: len(data) * 3 // 4])  # the first page is whole
    return {"--right": right}, ["right.tif is truncated"]


@case("reconstruct-truncated-png-in-the-left-folder")
def _(s, t):
    left = folder_with(s.left, t, "left", lambda f: cut(f / "frame_001.png", f))
    return {"--left": left}, ["frame_001.png"]


@case("reconstruct-wrong-type-text-as-png")
def _(s, t):
    right = folder_with(s.right, t, "right", lambda f: (f / "frame_001.png").write_text("text"))
    return {"--right": right}, ["frame_001.png"]


@case("reconstruct-wrong-type-png-as-video")
def _(s, t):
    return {"--left": write(t, "left.avi", s.left0.read_bytes())}, ["left.avi"]


@case("reconstruct-wrong-type-one-image-as-video")
def _(s, t):
    return {"--left": s.left0, "--right": s.right0}, ["frame_000.png", "at least 2"]


@case("reconstruct-conflict-frame-counts")
def _(s, t):
    def add(folder: Path) -> None:
        shutil.copy(folder / "frame_001.png", folder / "frame_002.png")

    return {"--right": folder_with(s.right, t, "right", add)}, ["2 in", "3 in", "right"]


@case("reconstruct-conflict-points-and-grid")
def _(s, t):
    return {"--grid": "7x7"}, ["give either --points or --grid/--roi, not both"]


@case("reconstruct-conflict-points-and-roi")
def _(s, t):
    return {"--roi": "250,130,420,250"}, ["give either --points or --grid/--roi, not both"]


@case("reconstruct-conflict-directions-without-strain")
def _(s, t):
    return {"--directions": "cylinder:0,0,0:0,1,0"}, ["--directions", "--strain"]


@case("reconstruct-conflict-tracker-imported")
def _(s, t):
    return {"--tracker": "imported"}, ["--tracker imported", "dic, klt"]


@case("reconstruct-conflict-shape-function-with-klt")
def _(s, t):
    return {"--tracker": "klt", "--shape-function": "affine"}, ["--shape-function", "dic"]


@case("reconstruct-conflict-subset-with-klt")
def _(s, t):
    return {"--tracker": "klt", "--subset": 31}, ["--subset", "dic"]


@case("reconstruct-option-tracker-unknown")
def _(s, t):
    return {"--tracker": "magic"}, ["--tracker", "magic", "dic, klt"]


@case("reconstruct-option-shape-function-unknown")
def _(s, t):
    return {"--shape-function": "cubic"}, ["--shape-function", "cubic"]


for option, value, fragment in (
    ("--max-epipolar", "-1", "positive"),
    ("--max-epipolar", "inf", "positive"),
    ("--match-subset", "2", "odd"),
    ("--max-reproj", "nan", "positive"),
    ("--max-reproj", "-0.5", "positive"),
    ("--max-reproj", "0", "positive"),
    ("--subset", "0", "odd"),
    ("--subset", "30", "odd"),
    ("--subset", "-31", "odd"),
    ("--subset", "31.5", "must be a whole number"),
):

    @case(f"reconstruct-option-{option[2:]}-{value}")
    def _(s, t, option=option, value=value, fragment=fragment):
        return {option: value}, [option, fragment]


@case("reconstruct-option-subset-larger-than-the-image")
def _(s, t):
    return {"--subset": 2001}, ["--subset", f"{W}x{H}"]


for option, value, fragment in (
    ("--grid", "1x1", "1x1"),
    ("--grid", "seven", "seven"),
    ("--grid", "7x0", "7x0"),
    ("--grid", "100000x100000", "100000x100000"),
    ("--roi", f"10,10,{W + 100},200", "outside"),
    ("--roi", "400,300,100,50", "X1 > X0"),
    ("--roi", "nan,10,200,200", "nan"),
    ("--roi", "10,10,200", "X0,Y0,X1,Y1"),
):

    @case(f"reconstruct-option-{option[2:]}-{value.replace(',', '_')}")
    def _(s, t, option=option, value=value, fragment=fragment):
        return {"--points": None, option: value}, [option, fragment]


def float_frames(source: Path, tmp: Path, name: str, bad: tuple[int, float]) -> Path:
    """The frames of the folder ``source`` as float32 TIFFs, frame ``bad[0]`` with the value
    ``bad[1]`` in nine pixels of a corner, far from every point."""
    import cv2
    import tifffile

    folder = tmp / name
    folder.mkdir()
    for k, png in enumerate(sorted(source.glob("*.png"))):
        frame = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE).astype(np.float32)
        if k == bad[0]:
            frame[-3:, -3:] = bad[1]
        tifffile.imwrite(folder / f"{png.stem}.tif", frame)
    return folder


@case("reconstruct-nonfinite-inf-in-the-right-view")
def _(s, t):
    return {"--right": float_frames(s.right, t, "right", (1, np.inf))}, [
        "frame_001.tif", "frame 1", "9 infinite pixel values"]  # fmt: skip


@case("reconstruct-nonfinite-nan-on-the-left-reference")
def _(s, t):
    return {"--left": float_frames(s.left, t, "left", (0, np.nan))}, [
        "frame_000.tif", "frame 0", "9 NaN pixel values"]  # fmt: skip


@case("calibrate-allocation-board-corners")
def _(s, t):
    board = "checkerboard:100000x100000:10"
    return {"--board": board}, [f"--board {board}", "px images can show", "at most"]


@case("reconstruct-allocation-grid-300x300")
def _(s, t):
    return {"--points": None, "--grid": "300x300"}, ["--grid 300x300", "px apart", "at most"]


@case("reconstruct-allocation-tracks-memory")
def _(s, t):
    return {}, ["points over 2 frames in each of 2 views", "of memory", "100 bytes", "--grid"]


#: the memory available, bytes, in the cases that ask for more than there is
SMALL_MEMORY = {"reconstruct-allocation-tracks-memory": 100}


for name, value, fragment in (
    ("parallel", "vectors:1,0,0:2,0,0", "parallel"),
    ("zero-vector", "vectors:0,0,0:0,1,0", "first vector has zero length"),
    ("zero-axis", "sphere:0,0,450:0,0,0", "axis A has zero length"),
):

    @case(f"reconstruct-option-directions-{name}")
    def _(s, t, value=value, fragment=fragment):
        return {"--strain": True, "--directions": value}, [f"--directions {value}", fragment]


@case("reconstruct-option-directions-unknown")
def _(s, t):
    return {"--strain": True, "--directions": "polar"}, ["--directions", "polar"]


@pytest.mark.parametrize(("command", "build"), CASES)
def test_bad_input(command, build, small_stereo, tmp_path, capsys, monkeypatch, request):
    memory = SMALL_MEMORY.get(request.node.callspec.id)
    if memory is not None:
        monkeypatch.setattr(resources, "available_memory", lambda: memory)
    changes, fragments = build(small_stereo, tmp_path)
    options = base(command, small_stereo, tmp_path)
    options.update(changes)
    argv = command_line(command, options)
    out = Path(options["--out"])
    inputs = [Path(a) for a in argv[1:] if a.strip() and Path(a) != out and Path(a).exists()]
    assert_refused(run, argv, capsys, prog="stereo", fragments=fragments, inputs=inputs, out=out)


def test_every_command_has_cases_of_every_family_that_applies():
    ids = [p.id for p in CASES]
    for command in ("calibrate", "import-calib", "match", "reconstruct"):
        for family in ("missing", "empty", "truncated", "wrong-type", "option", "conflict",
                       "output", "calibration"):  # fmt: skip
            assert any(i.startswith(f"{command}-{family}-") for i in ids), (command, family)
        if command in ("match", "reconstruct"):
            assert any(i.startswith(f"{command}-csv-") for i in ids), command


# --------------------------------------------------------------------------- Ctrl-C, SIGTERM


def _stereo_command(command: str, s: SmallStereo, tmp: Path, *, strain: bool = True):
    """``(argv, out, inputs)`` of a run of ``command`` on the small inputs."""
    if command == "batch":
        manifest = tmp / "specimens.csv"
        manifest.write_text(
            "specimen,left,right,calib\n"
            + "".join(f"{name},{s.left},{s.right},{s.calib}\n" for name in ("A", "B"))
        )
        argv = ["batch", manifest, "--workers", "1", "--grid", "5x4", "--roi", "280,150,400,240",
                "--out", tmp / "b"]  # fmt: skip
        return argv, tmp / "b", [s.left, s.right, s.calib]
    options = base(command, s, tmp)
    options.pop("-q", None)
    if command == "reconstruct" and strain:
        options["--strain"] = True
    argv = command_line(command, options)
    out = Path(options["--out"])
    return argv, out, [Path(a) for a in argv[1:] if Path(a).exists() and Path(a) != out]


#: Ctrl-C (SIGTERM, SIGHUP) ``after`` seconds after the step ``when`` was printed (None: after
#: the start; WRITING: once its temporary result holds something)
STAGES = [
    ("reconstruct", None, 0.3, signal.SIGINT, "reconstruct-interrupt-imports"),
    ("reconstruct", "matching", 0.05, signal.SIGINT, "reconstruct-interrupt-matching"),
    (
        "reconstruct",
        "tracking the left view",
        0.05,
        signal.SIGINT,
        "reconstruct-interrupt-tracking",
    ),
    ("reconstruct", "computing strain", 0.02, signal.SIGINT, "reconstruct-interrupt-strain"),
    ("reconstruct", "computing strain", 0.3, signal.SIGTERM, "reconstruct-terminate-strain"),
    (
        "reconstruct",
        "tracking the left",
        0.05,
        signal.SIGHUP,
        "reconstruct-terminate-sighup-tracking",
    ),
    ("calibrate", "detecting the target", 0.1, signal.SIGTERM, "calibrate-terminate-detecting"),
    ("import-calib", None, 0.1, signal.SIGTERM, "import-calib-terminate-imports"),
    ("match", None, 0.3, signal.SIGTERM, "match-terminate-start"),
    ("batch", WRITING, 0.05, signal.SIGTERM, "batch-terminate-first-run"),
    # the scratch of a run killed outright (SIGKILL), removed by the next run
    *(
        (command, "stale", None, None, f"{command}-stale-killed-run")
        for command in (*COMMANDS, "batch")
    ),
]


@pytest.mark.parametrize(
    ("command", "when", "after", "signum"), [s[:4] for s in STAGES], ids=[s[4] for s in STAGES]
)
def test_interrupt(command, when, after, signum, small_stereo, tmp_path, capsys):
    if when == "stale":
        _killed_then_run_again(command, small_stereo, tmp_path, capsys)
        return
    argv, out, inputs = _stereo_command(command, small_stereo, tmp_path)
    if command == "batch":  # a batch's result is its runs: watch the first one
        out = tmp_path / "b" / "runs" / "A"
    status, err = interrupt(["-m", "stereo", *argv], after=after, when=when, out=out,
                            inputs=inputs, signum=signum)  # fmt: skip
    assert status == 128 + signum, err
    if command == "batch":
        assert scratch_left(tmp_path / "b") == [] and not out.exists()


def _killed_then_run_again(command: str, s: SmallStereo, tmp_path: Path, capsys) -> None:
    """A run killed (SIGKILL) while it wrote; the next run removes what it left."""
    argv, out, _ = _stereo_command(command, s, tmp_path, strain=False)
    if command == "batch":  # killed while it wrote a run, and one killed writing its record
        assert killed(["-m", "stereo", *argv], out=out / "runs" / "A")
        stale_scratch(out / "batch.json", "replaced")
    else:
        stale_scratch(out, "dir" if command == "reconstruct" else "file")
    assert main(["-q", *map(str, argv)]) == 0, capsys.readouterr().err
    for folder in (tmp_path, out, out / "runs"):
        if folder.is_dir():
            assert scratch_left(folder) == [], folder


def test_every_command_has_terminate_and_stale_cases():
    ids = [s[4] for s in STAGES]
    for command in (*COMMANDS, "batch"):
        for family in ("terminate", "stale"):
            assert any(i.startswith(f"{command}-{family}-") for i in ids), (command, family)


def test_directions_no_surface_can_use_are_refused_before_the_tracking(
    small_stereo, tmp_path, capsys, monkeypatch
):
    """Zero or parallel vectors were refused only once both videos were tracked."""
    import stereo.reconstruct

    def not_now(*args, **kwargs):
        raise AssertionError("reconstruct ran")

    monkeypatch.setattr(stereo.reconstruct, "reconstruct", not_now)
    options = {**base("reconstruct", small_stereo, tmp_path), "--strain": True,
               "--directions": "vectors:0,1,0:0,-3,0"}  # fmt: skip
    assert run(command_line("reconstruct", options)) == 2
    assert "the two vectors are parallel" in capsys.readouterr().err


# --------------------------------------------------------------------------- names


# Names that are not UTF-8 (Windows-origin and shared drives) are read and written.  Each case
# is a real process given its names as bytes (OpenCV crashed the process on an OpenCV YAML file
# or a video so named): exit 0, the results of plainly named inputs, and every text file
# valid UTF-8 (names shown as \xNN).

RECONSTRUCT = ["--grid", "5x4", "--roi", "280,150,400,240", "--tracker", "klt"]


@pytest.fixture(scope="module")
def latin1_stereo(small_stereo, tmp_path_factory):
    """The small stereo inputs copied under Latin-1 names into a folder so named, with the
    points that ``reconstruct`` makes of the plainly named ones."""
    from types import SimpleNamespace

    s = small_stereo
    plain = tmp_path_factory.mktemp("plain")
    d = tmp_path_factory.mktemp(latin1("Stéréo"))
    n = SimpleNamespace(dir=d)
    n.left, n.right = d / latin1("gauche_é"), d / latin1("droite_é")
    shutil.copytree(s.left, n.left)
    shutil.copytree(s.right, n.right)
    n.left_video, n.right_video = d / latin1("gauche_é.avi"), d / latin1("droite_é.avi")
    shutil.copy(s.left_video, n.left_video)
    shutil.copy(s.right_video, n.right_video)
    n.calib, n.yml = d / latin1("calib_é.json"), d / latin1("stéréo.yml")
    shutil.copy(s.calib, n.calib)
    shutil.copy(s.yml, n.yml)
    n.points = d / latin1("pöints.csv")
    shutil.copy(s.points, n.points)
    n.views_left, n.views_right = d / latin1("vues_g_é"), d / latin1("vues_d_é")
    shutil.copytree(s.views_left, n.views_left)
    shutil.copytree(s.views_right, n.views_right)
    argv = ["reconstruct", "--calib", str(s.calib), "--left", str(s.left), "--right",
            str(s.right), *RECONSTRUCT, "--out", str(plain / "rec"), "-q"]  # fmt: skip
    assert main(argv) == 0
    n.points3d = (plain / "rec" / "points3d.csv").read_bytes()
    n.plain = plain
    return n


def _names_import_calib(s, n, tmp):
    out = tmp / latin1("calibration_é.json")
    assert_ran(["-m", "stereo", "import-calib", n.yml, "--out", out], out)
    assert main(["import-calib", str(s.yml), "--out", str(tmp / "plain.json"), "-q"]) == 0
    ours, theirs = strict_json(out), strict_json(tmp / "plain.json")
    assert ours.pop("imported_from") == ["st\\xe9r\\xe9o.yml"]
    assert theirs.pop("imported_from") == ["stereo.yml"]
    assert ours == theirs


def _names_calibrate(s, n, tmp):
    out = tmp / latin1("calibration_é.json")
    assert_ran(["-m", "stereo", "calibrate", "--left", n.views_left, "--right", n.views_right,
                "--board", "checkerboard:9x6:10", "--out", out], out)  # fmt: skip
    calib = strict_json(out)
    assert abs(calib["rms_px"]) < 1.0, calib.get("rms_px")


def _names_match(s, n, tmp):
    out = tmp / latin1("appariés.csv")
    left0, right0 = n.left / "frame_000.png", n.right / "frame_000.png"
    assert_ran(["-m", "stereo", "match", left0, right0, "--points", n.points, "--calib",
                n.calib, "--out", out], out)  # fmt: skip
    plain = tmp / "plain.csv"
    assert main(["match", str(s.left0), str(s.right0), "--points", str(s.points), "--calib",
                 str(s.calib), "--out", str(plain), "-q"]) == 0  # fmt: skip
    assert out.read_bytes() == plain.read_bytes()


def _names_reconstruct_folders(s, n, tmp):
    out = tmp / latin1("résultats")
    assert_ran(["-m", "stereo", "reconstruct", "--calib", n.calib, "--left", n.left, "--right",
                n.right, *RECONSTRUCT, "--strain", "--out", out], out)  # fmt: skip
    assert (out / "points3d.csv").read_bytes() == n.points3d
    assert len(list((out / "strain" / "strain").glob("*.vtp"))) == 2


def _names_reconstruct_videos(s, n, tmp):
    out = tmp / latin1("résultats")
    assert_ran(["-m", "stereo", "reconstruct", "--calib", n.calib, "--left", n.left_video,
                "--right", n.right_video, *RECONSTRUCT, "--out", out], out)  # fmt: skip
    assert (out / "points3d.csv").read_bytes() == n.points3d


def _names_batch(s, n, tmp):
    manifest = write(n.plain / latin1("lot_é"), "manifest.csv", "specimen,left,right\n"
                     f"feuille,{s.left},{s.right}\n")  # fmt: skip
    out = tmp / latin1("lot_é")
    argv = ["-m", "stereo", "batch", manifest, "--calib", n.calib, *RECONSTRUCT, "--workers",
            "1", "--out", out]  # fmt: skip
    assert_ran(argv, out)
    assert (out / "runs" / "feuille" / "points3d.csv").read_bytes() == n.points3d
    err = assert_ran(argv, out)  # the run's marker names the calibration readably
    assert "1 complete already, nothing to run" in err, err


def _names_damaged_yml(s, n, tmp):
    yml = write(tmp, latin1("abîmé.yml"), "%YAML:1.0\nM1: [1, 2\n")
    out = tmp / "calib.json"
    assert_refused_process(["-m", "stereo", "import-calib", yml, "--out", out],
                           fragments=["stereo import-calib: error:", shown(yml)])  # fmt: skip
    assert not out.exists()


NAME_CASES = {
    "import-calib-filename-damaged-yml": _names_damaged_yml,
    "import-calib-filename-yml-and-out": _names_import_calib,
    "calibrate-filename-views-and-out": _names_calibrate,
    "match-filename-images-points-and-out": _names_match,
    "reconstruct-filename-folders-and-out": _names_reconstruct_folders,
    "reconstruct-filename-videos": _names_reconstruct_videos,
    "batch-filename-manifest-and-out": _names_batch,
}


@pytest.mark.xdist_group("stereo_latin1_names")  # its names' folder made once, on one worker
class TestNamesNotUtf8:
    """The bad-input matrix's ``filename`` family: names that are not UTF-8 are read and
    written (``test_bad_input[COMMAND-filename-CASE]``, counted with the refusals)."""

    @pytest.mark.parametrize("case", list(NAME_CASES), ids=list(NAME_CASES))
    def test_bad_input(self, small_stereo, latin1_stereo, tmp_path, case):
        tmp = tmp_path / latin1("dossier_é")
        tmp.mkdir()
        before = snapshot(latin1_stereo.dir)
        NAME_CASES[case](small_stereo, latin1_stereo, tmp)
        assert snapshot(latin1_stereo.dir) == before  # inputs untouched
        assert scratch_left(tmp) == []
